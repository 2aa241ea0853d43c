//! The `wgcloth` command line (names fixed by DESIGN.md).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use wgcloth::config::{ModelKind, SceneKind, Shape};
use wgcloth::run::{Backend, resolve_backend, run_cpu};
use wgcloth::{Config, Error, Result, Scene};

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
}

#[derive(Args)]
struct RunArgs {
    /// sphere: a rigid body moving through the hanging cloth; hang: cloth alone.
    #[arg(long)]
    scene: Option<SceneKind>,
    /// Collision model.
    #[arg(long)]
    model: Option<ModelKind>,
    #[arg(long, default_value = "auto")]
    backend: Backend,
    /// N×N particles.
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    grid: Option<u32>,
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    steps: Option<u64>,
    /// Time step in seconds.
    #[arg(long, value_name = "H", allow_negative_numbers = true)]
    dt: Option<f32>,
    /// Maximum PCG iterations per step.
    #[arg(long, value_name = "I", allow_negative_numbers = true)]
    cg_iters: Option<u32>,
    /// PCG relative tolerance; 0 runs every iteration.
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    cg_tol: Option<f32>,
    /// TOML configuration; flags override its values.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// OBJ mesh for the rigid body.
    #[arg(long, value_name = "FILE.obj")]
    mesh: Option<PathBuf>,
    /// Write the run report as JSON.
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
}

impl RunArgs {
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
        if let Some(i) = self.cg_iters {
            c.solver.cg_iters = i;
        }
        if let Some(t) = self.cg_tol {
            c.solver.cg_tol = t;
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

fn run(args: &RunArgs) -> Result<()> {
    let config = args.config()?;
    let scene = Scene::new(&config)?;
    let (_backend, notice) = resolve_backend(args.backend)?;
    if let Some(n) = notice {
        eprintln!("{n}");
    }
    let steps = config.solver.steps;
    let bar = ProgressBar::new(steps).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {per_sec}, {eta} left")
            .expect("static template"),
    );
    let (report, outcome) = run_cpu(scene, steps, |k| bar.set_position(k));
    bar.finish_and_clear();
    println!("{}", report.summary());
    if let Some(path) = &args.report {
        let json = serde_json::to_string_pretty(&report).expect("report serialises");
        std::fs::write(path, json + "\n").map_err(|e| Error::io(path, e))?;
        println!("report       {}", path.display());
    }
    outcome
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Run(args) => run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
