//! The browser demo: the thesis scene stepped by the wgcloth library on the
//! page's WebGPU device and drawn from the library's own buffers in the
//! page's render pass (no copy through the CPU). Built by
//! `scripts/build-web.sh` into `target/web/` with `web/index.html`.
//!
//! The page asks for WebGPU's default limits, steps once per animation
//! frame, and reports in `<pre id="status">` one JSON object a frame:
//! `{"steps", "finite", "model", "adapter", "error", ...}`, with `error` a
//! string once anything failed (a panic included), also shown on screen.
//! Query parameters choose the model and grid (`?model=friction&grid=32`).
#![cfg(target_arch = "wasm32")]

use std::cell::RefCell;
use std::rc::Rc;

use wasm_bindgen::prelude::*;
use wgcloth::config::ModelKind;
use wgcloth::cpu::State;
use wgcloth::gpu::layout::StepState;
use wgcloth::gpu::{CgBudget, GpuSim, Kernels, Readback};
use wgcloth::render::{Camera, Pipelines, Source, Style, depth_target};
use wgcloth::{Config, Scene};

/// The model the page runs unless its query names another.
const DEFAULT_MODEL: ModelKind = ModelKind::FrictionNet;
/// Grid sides the page accepts: large enough to fold, small enough for a
/// default-limits device and a software adapter.
const GRIDS: std::ops::RangeInclusive<u32> = 8..=128;

/// What `<pre id="status">` shows, kept between frames.
#[derive(Default)]
struct Status {
    steps: u32,
    finite: bool,
    model: String,
    adapter: String,
    error: Option<String>,
    steps_per_second: f64,
    contacts: u32,
    residual: f32,
    deepest: f32,
}

/// The page's controls, set by the exported functions.
#[derive(Default)]
struct Control {
    paused: bool,
    reset: bool,
}

thread_local! {
    static STATUS: RefCell<Status> = RefCell::default();
    static CONTROL: RefCell<Control> = RefCell::default();
}

fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out += "\\\"",
            '\\' => out += "\\\\",
            c if (c as u32) < 0x20 => out += &format!("\\u{:04x}", c as u32),
            c => out.push(c),
        }
    }
    out + "\""
}

impl Status {
    fn json(&self) -> String {
        let text = |s: &str| match s.is_empty() {
            true => "null".to_string(),
            false => json_string(s),
        };
        format!(
            "{{\"steps\": {}, \"finite\": {}, \"model\": {}, \"adapter\": {}, \"error\": {}, \"steps_per_second\": {:.2}, \"contacts\": {}, \"residual\": {:e}, \"deepest\": {:e}}}",
            self.steps,
            self.finite,
            text(&self.model),
            text(&self.adapter),
            self.error.as_deref().map_or("null".into(), json_string),
            self.steps_per_second,
            self.contacts,
            self.residual,
            self.deepest,
        )
    }
}

fn element(id: &str) -> Option<web_sys::Element> {
    web_sys::window()?.document()?.get_element_by_id(id)
}

/// Writes the status to the page: the JSON, the stats line, and any error
/// where a person sees it.
fn show() {
    STATUS.with_borrow(|s| {
        if let Some(pre) = element("status") {
            pre.set_text_content(Some(&s.json()));
        }
        if let Some(stats) = element("stats") {
            stats.set_text_content(Some(&format!(
                "{}: {} steps, {:.1} steps/s, {} contacts, residual {:.1e}",
                s.model, s.steps, s.steps_per_second, s.contacts, s.residual
            )));
        }
        if let (Some(message), Some(error)) = (element("message"), &s.error) {
            message.set_text_content(Some(error));
        }
    });
}

/// Records the first error. From the panic hook the status may be
/// borrowed already; then the message still reaches the screen.
fn fail(error: String) {
    let recorded = STATUS.with(|status| match status.try_borrow_mut() {
        Ok(mut s) => {
            s.finite = s.finite && s.steps > 0;
            s.error.get_or_insert(error.clone());
            true
        }
        Err(_) => false,
    });
    match recorded {
        true => show(),
        false => {
            if let Some(message) = element("message") {
                message.set_text_content(Some(&error));
            }
        }
    }
}

/// Pauses or resumes the stepping; returns whether it is paused now.
#[wasm_bindgen]
pub fn toggle_pause() -> bool {
    CONTROL.with_borrow_mut(|c| {
        c.paused = !c.paused;
        c.paused
    })
}

/// Puts the cloth back at rest and the body at its start.
/// The models the page offers (every one), by their command-line names,
/// the default first.
#[wasm_bindgen]
pub fn models() -> Vec<String> {
    let rest = ModelKind::ALL.into_iter().filter(|&m| m != DEFAULT_MODEL);
    (std::iter::once(DEFAULT_MODEL).chain(rest))
        .map(|m| m.name().to_string())
        .collect()
}

#[wasm_bindgen]
pub fn reset() {
    CONTROL.with_borrow_mut(|c| c.reset = true);
}

#[wasm_bindgen(start)]
pub fn start() {
    std::panic::set_hook(Box::new(|info| fail(format!("panic: {info}"))));
    wasm_bindgen_futures::spawn_local(async {
        match App::open().await {
            Ok(app) => run(app),
            Err(e) => fail(e),
        }
    });
}

/// The model and grid from the page's query (`?model=…&grid=…`).
fn choices() -> Result<(ModelKind, u32), String> {
    let search = web_sys::window()
        .ok_or("no window")?
        .location()
        .search()
        .map_err(|_| "cannot read the page's address")?;
    let query = web_sys::UrlSearchParams::new_with_str(&search)
        .map_err(|_| "cannot parse the page's query")?;
    let model = match query.get("model") {
        None => DEFAULT_MODEL,
        Some(name) => *ModelKind::ALL
            .iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| format!("model={name}: expected one of {}", models().join(", ")))?,
    };
    let grid = match query.get("grid") {
        None => 32,
        Some(text) => text
            .parse()
            .ok()
            .filter(|g| GRIDS.contains(g))
            .ok_or_else(|| {
                format!(
                    "grid={text}: expected a whole number from {} to {}",
                    GRIDS.start(),
                    GRIDS.end()
                )
            })?,
    };
    Ok((model, grid))
}

struct App {
    device: wgpu::Device,
    queue: wgpu::Queue,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// The sRGB view of the canvas's texture the frames are drawn into.
    view_format: wgpu::TextureFormat,
    depth: wgpu::TextureView,
    pipelines: Pipelines,
    scene: Scene,
    sim: GpuSim,
    camera: Camera,
    readback: Readback,
    /// PCG iterations a step records, from those recent steps took (as
    /// `wgcloth run` does): each recorded one costs a dispatch's overhead.
    budget: CgBudget,
    performance: web_sys::Performance,
    /// (time in ms, steps) when the rate was last measured.
    mark: (f64, u32),
}

impl App {
    async fn open() -> Result<App, String> {
        let (model, grid) = choices()?;
        STATUS.with_borrow_mut(|s| {
            s.model = model.name().into();
            s.finite = true;
        });
        let canvas: web_sys::HtmlCanvasElement = element("canvas")
            .ok_or("the page has no <canvas id=\"canvas\">")?
            .dyn_into()
            .map_err(|_| "#canvas is not a canvas")?;
        let (width, height) = (canvas.width().max(1), canvas.height().max(1));
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::BROWSER_WEBGPU,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let surface = instance
            .create_surface(wgpu::SurfaceTarget::Canvas(canvas))
            .map_err(|e| format!("cannot draw into the canvas: {e}"))?;
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                compatible_surface: Some(&surface),
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|e| format!("no WebGPU adapter: {e}"))?;
        let info = adapter.get_info();
        // Browsers may leave the name empty (it identifies the machine).
        let name = [&info.name, &info.driver, &info.driver_info]
            .into_iter()
            .find(|n| !n.is_empty())
            .map_or("unnamed", |n| n.as_str());
        STATUS.with_borrow_mut(|s| {
            s.adapter = format!("{name} ({:?}, {:?})", info.device_type, info.backend);
        });
        // WebGPU's default limits: what any browser gives any page.
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor::default())
            .await
            .map_err(|e| format!("cannot open a WebGPU device: {e}"))?;
        device.on_uncaptured_error(std::sync::Arc::new(|e: wgpu::Error| {
            fail(format!("WebGPU: {e}"))
        }));
        let mut config = surface
            .get_default_config(&adapter, width, height)
            .ok_or("the canvas cannot be drawn with this adapter")?;
        // A canvas takes no sRGB format itself, only an sRGB view of its
        // texture: the shading is linear, as in the native frames.
        let view_format = config.format.add_srgb_suffix();
        config.view_formats = vec![view_format];
        surface.configure(&device, &config);

        let mut cfg = Config {
            model,
            ..Config::default()
        };
        cfg.cloth.grid = [grid, grid];
        let scene = Scene::new(&cfg).map_err(|e| e.to_string())?;
        let kernels = Kernels::create(&device).await.map_err(|e| e.to_string())?;
        let sim = GpuSim::create_with_kernels(&kernels, &device, &queue, &scene)
            .await
            .map_err(|e| e.to_string())?;
        let camera = Camera::framing(&scene, scene.config.rigid.motion.period);
        let performance = web_sys::window()
            .and_then(|w| w.performance())
            .ok_or("no performance clock")?;
        Ok(App {
            depth: depth_target(&device, config.width, config.height),
            pipelines: Pipelines::new(&device, view_format),
            view_format,
            readback: Readback::new(&device, size_of::<StepState>() as u64, 3),
            budget: CgBudget::for_solver(&cfg.solver),
            mark: (performance.now(), 0),
            performance,
            device,
            queue,
            surface,
            config,
            scene,
            sim,
            camera,
        })
    }

    /// One animation frame: a step (unless paused), the frame drawn from
    /// the simulator's buffers, and the statistics read back when ready.
    fn frame(&mut self) {
        let (paused, reset) = CONTROL.with_borrow_mut(|c| (c.paused, std::mem::take(&mut c.reset)));
        if reset {
            self.sim.upload_state(&State::initial(&self.scene));
        }
        let mut encoder = self.device.create_command_encoder(&Default::default());
        if !paused {
            self.sim.encode_step(&mut encoder);
        }
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => Some(t),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.device, &self.config);
                None
            }
            _ => None,
        };
        if let Some(texture) = &texture {
            let view = texture.texture.create_view(&wgpu::TextureViewDescriptor {
                format: Some(self.view_format),
                ..Default::default()
            });
            let aspect = self.config.width as f32 / self.config.height as f32;
            self.pipelines.record(
                &self.device,
                &self.queue,
                &mut encoder,
                (&view, &self.depth, aspect),
                &Source::gpu(&self.sim, &self.scene),
                &self.camera,
                Style::default(),
            );
        }
        self.readback
            .encode_copy(&mut encoder, self.sim.statistics());
        self.queue.submit([encoder.finish()]);
        self.readback.submitted();
        if let Some(texture) = texture {
            self.queue.present(texture);
        }
        if let Some(state) = self
            .readback
            .try_take::<StepState>()
            .and_then(|s| s.first().copied())
        {
            self.update(&state);
        }
        show();
    }

    fn update(&mut self, state: &StepState) {
        // The copy may be a frame or two old, so the budget it ran under
        // is taken as the current one: a step may be counted against a
        // budget it did not run under, cut or not.
        if state.steps > 0 {
            self.budget.observe(
                state.last_iterations,
                self.sim.cg_budget(),
                state.last_residual,
            );
            self.sim.set_cg_budget(self.budget.next());
        }
        let now = self.performance.now();
        let (then, steps_then) = self.mark;
        STATUS.with_borrow_mut(|s| {
            s.steps = state.steps;
            s.finite = state.health & wgcloth::health::NOT_FINITE == 0;
            s.contacts = state.contacts_last;
            s.residual = state.last_residual;
            s.deepest = f32::from_bits(state.max_penetration_bits);
            if now - then >= 1000.0 {
                s.steps_per_second =
                    (state.steps.saturating_sub(steps_then)) as f64 * 1000.0 / (now - then);
            }
        });
        if now - then >= 1000.0 {
            self.mark = (now, state.steps);
        }
    }
}

/// The animation-frame callback, which asks for the next frame itself.
type Tick = Rc<RefCell<Option<Closure<dyn FnMut()>>>>;

/// Calls `frame` on every animation frame until an error is reported.
fn run(app: App) {
    let app = Rc::new(RefCell::new(app));
    let tick: Tick = Rc::default();
    let next = tick.clone();
    *tick.borrow_mut() = Some(Closure::new(move || {
        app.borrow_mut().frame();
        if STATUS.with_borrow(|s| s.error.is_none()) {
            request_frame(next.borrow().as_ref().expect("set before the first frame"));
        }
    }));
    request_frame(tick.borrow().as_ref().expect("just set"));
}

fn request_frame(f: &Closure<dyn FnMut()>) {
    if let Some(window) = web_sys::window() {
        let _ = window.request_animation_frame(f.as_ref().unchecked_ref());
    }
}
