//! The `wgcloth` command line (names fixed by docs/DESIGN.md).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use wgcloth::config::{ModelKind, Preconditioner, SceneKind, Shape, Smoother};
use wgcloth::gpu::layout::VectorLayout;
use wgcloth::gpu::{GpuContext, GpuSim};
use wgcloth::nn::weights::NetKind;
use wgcloth::{Config, Error, Result, Scene};
use wgcloth_cli::run::{self, Backend, Chosen, check_diverged, choose_backend};
use wgcloth_learn::train::thesis_hidden;

/// A flag whose values are the names of a library enum's variants.
fn choice<T: Copy + Send + Sync + 'static>(
    all: &'static [T],
    name: fn(T) -> &'static str,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(all.iter().map(|&v| name(v)))
        .map(move |s| *all.iter().find(|&&v| name(v) == s).expect("a listed name"))
}

#[derive(Parser)]
#[command(
    name = "wgcloth",
    version,
    about = "Implicit mass-spring cloth with learned collision response"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scene and print a summary.
    Run(RunArgs),
    /// Run the same scene on the GPU and the CPU and compare the results.
    Validate(ValidateArgs),
    /// Record contacts and sample the domain: training data for a network.
    GenData(GenDataArgs),
    /// Train a network (candle) and write its weights file.
    Train(TrainArgs),
    /// Accuracy of a network's weights file.
    EvalNet(EvalNetArgs),
    /// The benchmark table: every backend × model × grid, the networks'
    /// throughput, and seconds per sphere period.
    Bench(BenchArgs),
}

#[derive(Args)]
struct BenchArgs {
    /// Two grids and fewer repeats: a few minutes on lavapipe.
    #[arg(long)]
    quick: bool,
    /// Only the CPU solver iteration of each preconditioner against its
    /// memory-traffic floor, 128² to 1024² (a minute or two).
    #[arg(long, conflicts_with = "quick")]
    iterations: bool,
    /// Only the batched-worlds rows: 1 to 1,024 worlds of the default run
    /// at 32² as one batch and as separate simulators (CPU).
    #[arg(long, conflicts_with_all = ["quick", "iterations"])]
    worlds: bool,
    /// Only the GPU's rows, with 512² and 1024² on a hardware GPU (what
    /// scripts/bench-gpu.sh runs); an error where there is no adapter.
    #[arg(long, conflicts_with = "iterations")]
    gpu_only: bool,
    /// Only the CPU's rows, 32² to 256² (10 minutes on 2 cores, most of it
    /// the 256² rows solved to 1e-3); no GPU adapter is opened.
    #[arg(long, conflicts_with_all = ["iterations", "gpu_only"])]
    cpu_only: bool,
    /// Solves a step of the rows solved to 1e-3 [default: 0, the scene's
    /// own: those that keep the body within half the cloth's spacing];
    /// the thesis's rows take one.
    #[arg(long, value_name = "N", conflicts_with = "iterations")]
    substeps: Option<u32>,
    /// Write the table as JSON.
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Draw ms/step against particle count (log-log) with the per-stage
    /// breakdown, as a PNG.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Write the tables as Markdown (what BENCHMARKS.md quotes).
    #[arg(long, value_name = "FILE.md")]
    markdown: Option<PathBuf>,
}

#[derive(Args)]
struct GenDataArgs {
    /// The data file to write (safetensors, `wgcloth-contacts/1`).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Which network the data trains.
    #[arg(long, default_value = "friction", value_parser = choice(&NetKind::DATA, NetKind::name))]
    model: NetKind,
    /// Contacts recorded from randomised sphere runs.
    #[arg(long, default_value_t = 200_000)]
    recorded: usize,
    /// Uniform samples of the declared input domain.
    #[arg(long, default_value_t = 800_000)]
    uniform: usize,
    /// Samples of the resting regime (depth 0.1–5 mm, slide up to 5 cm/s,
    /// approach within ±1 cm/s; friction data only).
    #[arg(long, default_value_t = 0)]
    resting: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Replace an existing file.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
struct TrainArgs {
    /// Training data from `wgcloth gen-data`.
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// The weights file to write [default: the shipped file of the data's
    /// network, crates/wgcloth/weights/friction_mlp.safetensors or naive_mlp.safetensors].
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Hidden layer widths [default: the thesis's, 256,256,128,128,128,128,128
    /// for friction and 16,16,16,16,16 for naive].
    #[arg(long, value_delimiter = ',')]
    hidden: Option<Vec<usize>>,
    #[arg(long, default_value_t = 60)]
    epochs: usize,
    #[arg(long, default_value_t = 512)]
    batch: usize,
    #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true)]
    lr: f64,
    #[arg(long, default_value_t = 10)]
    patience: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Loss curve (PNG).
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Continue from these weights (same architecture).
    #[arg(long, value_name = "FILE.safetensors")]
    init: Option<PathBuf>,
    /// Train the friction network in the contact frame (model
    /// `friction-contact`, the shipped small network's kind).
    #[arg(long)]
    contact_frame: bool,
    /// Replace an existing weights file.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
struct EvalNetArgs {
    /// The weights file.
    file: PathBuf,
    /// Held-out data (a `gen-data` file not used for training).
    #[arg(long, value_name = "FILE")]
    data: Option<PathBuf>,
    /// Fresh uniform samples of the declared domain.
    #[arg(long, default_value_t = 200_000)]
    samples: usize,
    #[arg(long, default_value_t = 12345)]
    seed: u64,
}

#[derive(Args)]
struct RunArgs {
    #[command(flatten)]
    scene: SceneArgs,
    #[arg(long, default_value = "auto")]
    backend: Backend,
    /// Open the GPU device without subgroup operations, so the solver's
    /// workgroup sums go through workgroup memory alone (to compare).
    #[arg(long)]
    no_subgroups: bool,
    /// How the GPU solver lays out its vectors [default: packed, three
    /// floats a vertex; vec4 on a CPU adapter such as lavapipe] (to compare).
    #[arg(long, value_name = "packed|vec4", value_parser = vector_layout)]
    vectors: Option<VectorLayout>,
    /// Write the run report as JSON.
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Render frames into DIR: frame_NNNN.png and animation.gif.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// With --out: a frame every K steps (and one of the start).
    #[arg(long, value_name = "K", default_value_t = 4)]
    every: u64,
    /// With --out: frames of N×N pixels.
    #[arg(long, value_name = "N", default_value_t = wgcloth::render::DEFAULT_SIZE)]
    size: u32,
    /// With --out: draw the cloth's triangle edges.
    #[arg(long)]
    wireframe: bool,
    /// With --out: leave out the green contact-force segments.
    #[arg(long)]
    no_forces: bool,
    /// With --out: also write the geometry (`obj`: each frame's,
    /// frame_NNNN.obj, objects `cloth` and `body`, for Blender; `usd`: the
    /// whole run, animation.usda, meshes /World/cloth and /World/body with
    /// time-sampled points); both: `--export obj,usd`.
    #[arg(long, value_name = "FORMAT", value_delimiter = ',')]
    export: Vec<Export>,
    /// With --out: replace frames already in DIR.
    #[arg(long)]
    force: bool,
    /// If the run diverges, write the state before the diverging step
    /// here (OBJ, objects `cloth` and `body`).
    #[arg(long, value_name = "FILE.obj")]
    last_good: Option<PathBuf>,
    /// Write a CSV row every --monitor-every steps: energy, fastest
    /// vertex, resident memory and GPU allocator bytes (for soaks).
    #[arg(long, value_name = "FILE.csv")]
    monitor: Option<PathBuf>,
    /// Run N worlds of the scene as one batch, a summary line each and one
    /// for the batch (CPU path; each world its own --sweep values).
    #[arg(long, value_name = "N")]
    worlds: Option<usize>,
    /// With or instead of --worlds: each world's configuration values, a
    /// TOML file of [[world]] tables or a CSV file with dotted keys
    /// (`contact.mu`) as its header and a row a world.
    #[arg(long, value_name = "FILE.toml|FILE.csv")]
    sweep: Option<PathBuf>,
    /// With --monitor: a row every K steps (and one of the start).
    #[arg(long, value_name = "K", default_value_t = 1000)]
    monitor_every: u64,
}

/// `run --vectors`: a [`VectorLayout`] by its name.
fn vector_layout(name: &str) -> std::result::Result<VectorLayout, String> {
    VectorLayout::named(name).ok_or_else(|| {
        let names: Vec<&str> = VectorLayout::ALL.iter().map(|l| l.name()).collect();
        format!("expected one of {}", names.join(", "))
    })
}

/// Geometry formats `run --export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Export {
    Obj,
    Usd,
}

#[derive(Args)]
struct ValidateArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Allowed GPU–CPU position difference beyond what two faithful CPU
    /// runs of the scene differ by (the printed `sensitivity` and
    /// `solve`), m.
    #[arg(
        long,
        value_name = "M",
        default_value_t = 1e-4,
        allow_negative_numbers = true
    )]
    tolerance: f32,
}

/// The flags that define a scene and its run.
#[derive(Args)]
struct SceneArgs {
    /// sphere: a rigid body moving through the hanging cloth; hang: cloth alone.
    #[arg(long, value_parser = choice(&SceneKind::ALL, SceneKind::name))]
    scene: Option<SceneKind>,
    /// Collision model [default: friction-net, the shipped distilled network].
    #[arg(long, value_parser = choice(&ModelKind::ALL, ModelKind::name))]
    model: Option<ModelKind>,
    /// N×N particles.
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    grid: Option<u32>,
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    steps: Option<u64>,
    /// Time step in seconds.
    #[arg(long, value_name = "H", allow_negative_numbers = true)]
    dt: Option<f32>,
    /// Backward Euler solves per step [default: 0, the fewest that keep
    /// the rigid body within half the cloth's spacing in each].
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    substeps: Option<u32>,
    /// Maximum PCG iterations per step.
    #[arg(long, value_name = "I", allow_negative_numbers = true)]
    cg_iters: Option<u32>,
    /// PCG relative tolerance |S r| / |S b|; 0 runs every iteration.
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    cg_tol: Option<f32>,
    /// PCG preconditioner [default: multigrid; the thesis's: jacobi].
    #[arg(long, value_parser = choice(&Preconditioner::ALL, Preconditioner::name))]
    preconditioner: Option<Preconditioner>,
    /// Multigrid's smoother [default: patches].
    #[arg(long, value_parser = choice(&Smoother::ALL, Smoother::name))]
    smoother: Option<Smoother>,
    /// On the GPU, solve a multigrid step of a cloth of at most N vertices
    /// whole, in one dispatch of one workgroup [default: 4096, a 64²
    /// cloth]; 0 never.
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    whole_solve_nodes: Option<u32>,
    /// Speed (m/s) beyond which a vertex stops the run as diverging.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    max_speed: Option<f32>,
    /// TOML configuration; flags override its values.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// OBJ mesh for the rigid body.
    #[arg(long, value_name = "FILE.obj")]
    mesh: Option<PathBuf>,
    /// Weights of the network model [default: the built-in copy of
    /// crates/wgcloth/weights/friction_mlp_small.safetensors for friction-net,
    /// crates/wgcloth/weights/naive_mlp.safetensors for naive-net].
    #[arg(long, value_name = "FILE.safetensors")]
    weights: Option<PathBuf>,
}

impl SceneArgs {
    fn config(&self) -> Result<Config> {
        let mut c = match &self.config {
            Some(path) => Config::load(path)?,
            None => Config::default(),
        };
        if let Some(s) = self.scene {
            c.scene = s;
        }
        if let Some(m) = self.model {
            c.model = m;
        }
        if let Some(n) = self.grid {
            c.cloth.grid = [n, n];
        }
        if let Some(k) = self.steps {
            c.solver.steps = k;
        }
        if let Some(h) = self.dt {
            c.solver.dt = h;
        }
        if let Some(n) = self.substeps {
            c.solver.substeps = n;
        }
        if let Some(i) = self.cg_iters {
            c.solver.cg_iters = i;
        }
        if let Some(t) = self.cg_tol {
            c.solver.cg_tol = t;
        }
        if let Some(p) = self.preconditioner {
            c.solver.preconditioner = p;
        }
        if let Some(s) = self.smoother {
            c.solver.smoother = s;
        }
        if let Some(n) = self.whole_solve_nodes {
            c.solver.whole_solve_nodes = n;
        }
        if let Some(m) = self.max_speed {
            c.solver.max_speed = m;
        }
        if let Some(w) = &self.weights {
            c.contact.weights = Some(w.clone());
        }
        if let Some(mesh) = &self.mesh {
            if c.scene == SceneKind::Hang {
                return Err(Error::config(
                    "--mesh",
                    "scene `hang` has no rigid body; use --scene sphere",
                ));
            }
            c.rigid.shape = Shape::Obj;
            c.rigid.mesh = Some(mesh.clone());
        }
        Ok(c)
    }
}

fn progress_bar(steps: u64) -> ProgressBar {
    ProgressBar::new(steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {per_sec}, {eta} left")
            .expect("static template"),
    )
}

fn run(args: &RunArgs) -> Result<()> {
    let config = args.scene.config()?;
    if args.worlds.is_some() || args.sweep.is_some() {
        return run_worlds(args, config);
    }
    for path in args
        .report
        .iter()
        .chain(&args.last_good)
        .chain(&args.monitor)
    {
        writable(path)?;
    }
    if args.monitor_every == 0 {
        return Err(Error::config("--monitor-every", "must be at least 1"));
    }
    let scene = Scene::new(&config)?;
    // Kept to write the last good state.
    let run_scene = scene.clone();
    let mut optional = wgcloth::gpu::OPTIONAL_FEATURES;
    if args.no_subgroups {
        optional.remove(wgpu::Features::SUBGROUP);
    }
    let (mut chosen, notice) = choose_backend(args.backend, optional)?;
    if let Some(n) = notice {
        eprintln!("{n}");
    }
    match &mut chosen {
        Chosen::Gpu { ctx, .. } => {
            if let Some(layout) = args.vectors {
                **ctx = ctx.clone().with_vectors(layout);
            }
        }
        Chosen::Cpu => {
            let gpu_only = [
                (args.no_subgroups, "--no-subgroups"),
                (args.vectors.is_some(), "--vectors"),
            ];
            for (_, flag) in gpu_only.iter().filter(|(given, _)| *given) {
                eprintln!("notice: {flag} sets up the GPU solver; this run is on the CPU");
            }
        }
    }
    let steps = config.solver.steps;
    if !args.export.is_empty() && args.out.is_none() {
        return Err(Error::config(
            "--export",
            "writes into the frame directory: give --out DIR",
        ));
    }
    let options = args
        .out
        .as_ref()
        .map(|dir| wgcloth_cli::frames::RecordOptions {
            dir: dir.clone(),
            size: args.size,
            every: args.every,
            style: wgcloth::render::Style {
                wireframe: args.wireframe,
                forces: !args.no_forces,
            },
            exports: wgcloth_cli::frames::output::Exports {
                obj: args.export.contains(&Export::Obj),
                usd: args.export.contains(&Export::Usd),
            },
            force: args.force,
        });
    // The directory first: its errors need no GPU.
    let writer = match &options {
        Some(o) => Some(o.prepare(&scene, steps)?),
        None => None,
    };
    // A CPU run's frames are drawn by any adapter there is (the CPU path
    // uploads its state), lavapipe included; without one, by the CPU
    // rasteriser, as the main job goes on without a GPU.
    let own_context;
    let render_context = match (&writer, &chosen) {
        (None, _) => None,
        (Some(_), Chosen::Gpu { ctx, .. }) => Some(&**ctx),
        (Some(_), Chosen::Cpu) => match GpuContext::headless() {
            Ok(ctx) => {
                own_context = ctx;
                Some(&own_context)
            }
            Err(e) => {
                eprintln!(
                    "notice: no GPU adapter to draw frames ({e}); drawing them with the CPU rasteriser"
                );
                None
            }
        },
    };
    let mut recording = match (options, writer) {
        (Some(options), Some(writer)) => Some(wgcloth_cli::frames::Recording::new(
            render_context,
            &scene,
            steps,
            (&options, writer),
        )?),
        _ => None,
    };
    let mut monitor = match &args.monitor {
        Some(path) => Some(wgcloth_cli::monitor::Monitor::create(
            path,
            args.monitor_every,
        )?),
        None => None,
    };
    let bar = progress_bar(steps);
    let report = run::run(
        &chosen,
        scene,
        run::Steps::all(steps),
        run::Observers {
            progress: Some(&mut |k| bar.set_position(k)),
            notice: Some(&mut |line| bar.suspend(|| eprintln!("{line}"))),
            recording: recording.as_mut(),
            monitor: monitor.as_mut(),
        },
    )?;
    bar.finish_and_clear();
    println!("{}", report.summary());
    if let Some(monitor) = &monitor {
        println!("{}", monitor.summary());
    }
    if let Some(recording) = recording {
        let written = recording.finish(&run_scene)?;
        let dir = written.dir.display();
        if written.frames > 0 {
            println!("frames       {} in {dir}", written.frames);
        }
        if written.objs > 0 {
            println!("obj frames   {} in {dir}", written.objs);
        }
        if let Some(gif) = &written.gif {
            println!("animation    {}", gif.display());
        }
        if let Some(usd) = &written.usd {
            println!("usd          {}", usd.display());
        }
    }
    if let Some(path) = &args.report {
        write_json(path, &report)?;
        println!("report       {}", path.display());
    }
    if let (Some(path), Some(good)) = (&args.last_good, &report.last_good) {
        wgcloth_cli::frames::obj::write_obj(path, &run_scene, &good.x, good.time as f32)?;
        println!("last good    step {} in {}", good.step, path.display());
    }
    check_diverged(&report)
}

/// `run --worlds N` / `--sweep FILE`: a batch of worlds, on the GPU where
/// `--backend` chooses it (`auto`: a hardware adapter), else the CPU path.
fn run_worlds(args: &RunArgs, config: Config) -> Result<()> {
    let one_world = [
        (args.out.is_some(), "--out"),
        (args.monitor.is_some(), "--monitor"),
        (args.last_good.is_some(), "--last-good"),
        (args.vectors.is_some(), "--vectors"),
        (args.no_subgroups, "--no-subgroups"),
        (!args.export.is_empty(), "--export"),
    ];
    if let Some((_, flag)) = one_world.iter().find(|(given, _)| *given) {
        return Err(Error::config(
            *flag,
            "takes a run of one world; leave out --worlds and --sweep",
        ));
    }
    if let Some(path) = &args.report {
        writable(path)?;
    }
    let configs = match &args.sweep {
        Some(path) => wgcloth_cli::sweep::read(path, &config)?,
        None => Vec::new(),
    };
    let count = match (args.worlds, configs.len()) {
        (Some(0), _) => return Err(Error::config("--worlds", "must be at least 1")),
        (Some(n), 0) => n,
        (None, m) => m,
        (Some(n), m) if n == m => n,
        (Some(n), m) => {
            return Err(Error::config(
                "--worlds",
                format!("is {n} but the sweep names {m} worlds; give one or make them agree"),
            ));
        }
    };
    let set: Vec<String> = (configs.iter())
        .map(|(values, _)| wgcloth_cli::sweep::describe(values))
        .collect();
    let scenes = match configs.is_empty() {
        true => vec![Scene::new(&config)?; count],
        false => (configs.iter().map(|(_, c)| c).enumerate())
            .map(|(k, c)| {
                Scene::new(c).map_err(|e| Error::config("--sweep", format!("world {}: {e}", k + 1)))
            })
            .collect::<Result<Vec<_>>>()?,
    };
    let steps = config.solver.steps;
    // Refused before a device is opened; one world runs alone, as any scene.
    if args.backend == Backend::Gpu && scenes.len() > 1 {
        GpuSim::batchable(&scenes[0])?;
    }
    let (chosen, notice) = run::choose_backend(args.backend, wgcloth::gpu::OPTIONAL_FEATURES)?;
    if let Some(notice) = notice {
        eprintln!("{notice}");
    }
    let batch = run::batch_on(&chosen, scenes, &set, |n| eprintln!("{n}"))?;
    let bar = progress_bar(steps);
    let report = run::run_batch(batch, steps, |k| bar.set_position(k))?;
    bar.finish_and_clear();
    println!("{}", report.summary());
    if let Some(path) = &args.report {
        write_json(path, &report)?;
        println!("report       {}", path.display());
    }
    match report
        .worlds
        .iter()
        .find_map(|w| Some((w.world, w.divergence.as_ref()?)))
    {
        Some((w, d)) => Err(Error::Diverged {
            step: d.step,
            vertex: d.vertex,
            reason: format!("world {w}: {}; the other worlds ran to the end", d.reason),
        }),
        None => Ok(()),
    }
}

fn bench(args: &BenchArgs) -> Result<()> {
    // Fail before minutes of measuring, not after.
    for path in args.report.iter().chain(&args.plot).chain(&args.markdown) {
        writable(path)?;
    }
    if let Some(plot) = &args.plot {
        wgcloth_cli::plot::check_png(plot)?;
    }
    let options = match (args.quick, args.iterations, args.worlds) {
        (true, _, _) => wgcloth_cli::bench::BenchOptions::quick(),
        (_, true, _) => wgcloth_cli::bench::BenchOptions::iterations(),
        (_, _, true) => wgcloth_cli::bench::BenchOptions::worlds(),
        _ => wgcloth_cli::bench::BenchOptions::full(),
    };
    let options = match (args.gpu_only, args.cpu_only) {
        (true, _) => options.gpu_only(),
        (_, true) => options.cpu_only(),
        _ => options,
    };
    let options = wgcloth_cli::bench::BenchOptions {
        substeps: args.substeps.unwrap_or(options.substeps),
        ..options
    };
    let spinner = ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(200));
    // Without a terminal (a log, a remote machine) each step of the
    // measurement is a line, so a bench cut short still says how far it got.
    let start = std::time::Instant::now();
    let report = wgcloth_cli::bench::bench(&options, |what| match spinner.is_hidden() {
        true => eprintln!("[{:7.1} s] {what}", start.elapsed().as_secs_f64()),
        false => spinner.set_message(what.to_string()),
    })?;
    spinner.finish_and_clear();
    print!("{}", report.table());
    if let Some(path) = &args.report {
        write_json(path, &report)?;
        println!("report: {}", path.display());
    }
    if let Some(path) = &args.plot {
        wgcloth_cli::bench::plot::write(&report, path)?;
        println!("plot: {}", path.display());
    }
    if let Some(path) = &args.markdown {
        std::fs::write(path, report.markdown()).map_err(|e| Error::io(path, e))?;
        println!("markdown: {}", path.display());
    }
    Ok(())
}

fn gen_data(args: &GenDataArgs) -> Result<()> {
    refuse_existing(&args.out, args.force)?;
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{msg} {bar:40} {percent}%").expect("static template"),
    );
    let data = wgcloth_learn::dataset::generate(
        args.model,
        wgcloth_learn::dataset::Counts {
            recorded: args.recorded,
            uniform: args.uniform,
            resting: args.resting,
        },
        args.seed,
        |what, f| {
            bar.set_message(what.to_string());
            bar.set_position((f * 1000.0) as u64);
        },
    )?;
    bar.finish_and_clear();
    let meta = [
        ("seed".to_string(), args.seed.to_string()),
        ("recorded".to_string(), args.recorded.to_string()),
        ("uniform".to_string(), args.uniform.to_string()),
        ("resting".to_string(), args.resting.to_string()),
    ]
    .into();
    data.write(&args.out, meta, args.force)?;
    println!(
        "{}: {} {} samples ({} recorded, {} uniform, {} resting), seed {}",
        args.out.display(),
        data.len(),
        args.model.name(),
        args.recorded,
        args.uniform,
        args.resting,
        args.seed
    );
    Ok(())
}

fn write_json(path: &std::path::Path, value: &impl serde::Serialize) -> Result<()> {
    let json = serde_json::to_string_pretty(value).expect("reports serialise");
    std::fs::write(path, json + "\n").map_err(|e| Error::io(path, e))
}

/// Fails early when `path` cannot be written, leaving an existing file's
/// contents alone and no new file behind.
fn writable(path: &std::path::Path) -> Result<()> {
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

fn refuse_existing(path: &std::path::Path, force: bool) -> Result<()> {
    match path.exists() && !force {
        true => Err(Error::file(
            path,
            "already exists; pass --force to replace it",
        )),
        false => Ok(()),
    }
}

fn train(args: &TrainArgs) -> Result<()> {
    if let Some(out) = &args.out {
        refuse_existing(out, args.force)?;
    }
    if let Some(plot) = &args.plot {
        wgcloth_cli::plot::check_png(plot)?;
        writable(plot)?;
    }
    let data = wgcloth_learn::dataset::Dataset::read(&args.data)?;
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "crates/wgcloth/weights/{}_mlp.safetensors",
            data.kind.name()
        ))
    });
    refuse_existing(&out, args.force)?;
    let opts = wgcloth_learn::train::TrainOptions {
        hidden: (args.hidden.clone()).unwrap_or_else(|| thesis_hidden(data.kind)),
        epochs: args.epochs,
        batch: args.batch,
        learning_rate: args.lr,
        patience: args.patience,
        seed: args.seed,
        checkpoint: Some(out.with_extension("checkpoint.safetensors")),
        init: args
            .init
            .as_deref()
            .map(wgcloth::nn::weights::WeightsFile::read)
            .transpose()?,
        contact_frame: args.contact_frame,
        ..Default::default()
    };
    let bar = progress_bar(opts.epochs as u64).with_style(
        ProgressStyle::with_template("{bar:40} epoch {pos}/{len} {msg} {eta} left")
            .expect("static template"),
    );
    let trained = wgcloth_learn::train::train(&data, &opts, |epoch, t, v| {
        bar.set_position(epoch as u64);
        bar.set_message(format!("train {t:.3e} validation {v:.3e}"));
        eprintln!("epoch {epoch}: train {t:.4e}, validation {v:.4e}");
    })?;
    bar.finish_and_clear();
    trained.weights.write(&out, args.force)?;
    let _ = std::fs::remove_file(out.with_extension("checkpoint.safetensors"));
    if let Some(plot) = &args.plot {
        wgcloth_cli::loss_plot::loss_curve(&trained.curve, plot)?;
    }
    println!(
        "{}: best validation MSE {:.4e} (standardised) after {} epochs, {:.0} s, {} samples",
        out.display(),
        trained.best_validation,
        trained.curve.len(),
        trained.seconds,
        data.len()
    );
    Ok(())
}

fn eval_net(args: &EvalNetArgs) -> Result<()> {
    if args.samples == 0 {
        return Err(Error::config("--samples", "must be at least 1"));
    }
    let file = wgcloth::nn::weights::WeightsFile::read(&args.file)?;
    let held_out = args
        .data
        .as_deref()
        .map(wgcloth_learn::dataset::Dataset::read)
        .transpose()?;
    if let (Some(d), Some(path)) = (&held_out, &args.data)
        && d.kind != file.kind.data()
    {
        return Err(Error::file(
            path,
            format!(
                "holds {} data; {} is a {} network",
                d.kind.name(),
                args.file.display(),
                file.kind.name()
            ),
        ));
    }
    let e = wgcloth_learn::eval::evaluate(&file, held_out.as_ref(), args.samples, args.seed);
    let net = file.network();
    println!(
        "eval-net: {} ({}, {} layers, {} multiply-adds per contact)",
        args.file.display(),
        file.kind.name(),
        net.mlp.layers.len(),
        net.multiply_adds()
    );
    if let Some(m) = e.held_out_mse {
        println!("held-out     standardised MSE {m:.4e}");
    }
    println!(
        "uniform      standardised MSE {:.4e} ({} fresh samples of the declared domain)",
        e.uniform_mse, e.uniform_samples
    );
    println!(
        "jacobian     median relative error of the position Jacobian {:.3e}",
        e.jacobian_median_relative_error
    );
    if let Some(r) = e.resting {
        println!(
            "resting      force error relative to eqs. 8–9, median / p95: {:.3} / {:.3} at the default coefficients, {:.3} / {:.3} over the domain's ({} samples each)",
            r.default_median, r.default_p95, r.domain_median, r.domain_p95, r.samples
        );
        println!(
            "cone         of the uniform samples, {} where eqs. 8–9 push and g_n ≤ 0, {} with friction along the slide",
            e.not_pushing, e.along_slide
        );
    }
    Ok(())
}

/// Exit code 1: the GPU and CPU disagree (the check ran, and failed).
struct Mismatch(String);

fn validate(args: &ValidateArgs) -> Result<std::result::Result<(), Mismatch>> {
    let config = args.scene.config()?;
    if !args.tolerance.is_finite() || args.tolerance <= 0.0 {
        return Err(Error::config(
            "--tolerance",
            format!("must be > 0, got {}", args.tolerance),
        ));
    }
    let scene = Scene::new(&config)?;
    let ctx = GpuContext::headless()?;
    let steps = config.solver.steps;
    // The GPU and CPU run side by side, then two more CPU runs.
    let bar = progress_bar(3 * steps);
    let v = run::validate(&ctx, scene, steps, |_, _, _| {}, || bar.inc(1))?;
    bar.finish_and_clear();
    // A faithful GPU may end as far from the CPU as another faithful CPU
    // run does (wgcloth::sensitivity).
    let s = v.sensitivity;
    let allowed = args.tolerance + 4.0 * s.faithful(&ctx.adapter).drift;
    let rule = match wgcloth::gpu::context::computes_as_the_cpu(&ctx.adapter) {
        true => "the sensitivity: a CPU adapter's solves stop where the CPU's do",
        false => "the larger",
    };
    println!(
        "validate: scene {:?}, model {:?}, grid {}x{}, {steps} steps\n\
         gpu          {}\n\
         deviation    {:.3e} m largest |x_gpu − x_cpu|\n\
         sensitivity  {:.3e} m largest |x_cpu − x_cpu'| with x_cpu' nudged {:.0e} m at the start\n\
         solve        {:.3e} m largest |x_cpu − x_cpu'| with x_cpu' solved to {} × solver.cg_tol\n\
         allowed      {:.3e} m = --tolerance {:.1e} + 4 × {rule}\n\
         contacts     {} on the GPU, {} on the CPU (the two CPU runs: {:.2} % and {:.2} % apart)",
        config.scene,
        config.model,
        config.cloth.grid[0],
        config.cloth.grid[1],
        v.adapter,
        v.max_deviation,
        s.nudged.drift,
        wgcloth::cpu::PERTURBATION,
        s.tolerance.drift,
        wgcloth::sensitivity::TIGHTER,
        allowed,
        args.tolerance,
        v.gpu_contacts,
        v.cpu_contacts,
        100.0 * s.nudged.contacts,
        100.0 * s.tolerance.contacts,
    );
    if v.max_deviation <= allowed {
        Ok(Ok(()))
    } else {
        Ok(Err(Mismatch(format!(
            "GPU and CPU differ by {:.3e} m, more than the {allowed:.3e} m allowed",
            v.max_deviation
        ))))
    }
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Run(args) => run(args).map(Ok),
        Command::Validate(args) => validate(args),
        Command::GenData(args) => gen_data(args).map(Ok),
        Command::Train(args) => train(args).map(Ok),
        Command::EvalNet(args) => eval_net(args).map(Ok),
        Command::Bench(args) => bench(args).map(Ok),
    };
    match result {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(Mismatch(why))) => {
            eprintln!("validation failed: {why}");
            ExitCode::from(1)
        }
        Err(e) => {
            // The library names the limit; the flag that fixes it is ours.
            let hint = match &e {
                Error::Limit { what, .. } if what.ends_with(" worlds") => {
                    " (use fewer worlds or a smaller --grid)"
                }
                Error::Limit { .. } => " (use a smaller --grid)",
                _ => "",
            };
            eprintln!("error: {e}{hint}");
            ExitCode::from(2)
        }
    }
}
