//! The interactive viewer: a winit window whose wgpu app embeds the
//! simulator and draws straight from its buffers (`render::Pipelines` over
//! `render::Source::gpu`), no copy through the host.
//!
//! `cargo run --release --features viewer --example viewer [-- --grid N] [--frames K]`
//!
//! Drag with the left button to orbit, scroll to zoom. Space pauses, N
//! steps once while paused, M switches the collision model (each of
//! `ModelKind::ALL` in turn, from friction-net), W toggles the wireframe and F the
//! force segments; Esc quits. `--frames K` quits after K frames (for
//! smoke tests). Without a display it says so and exits with code 2.

use std::process::ExitCode;
use std::sync::Arc;

use glam::Vec3;
use wgcloth::config::ModelKind;
use wgcloth::gpu::{GpuContext, GpuSim, SolvedSteps};
use wgcloth::render::{Camera, Pipelines, Source, Style, depth_target};
use wgcloth::{Config, Scene};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

/// The window and the device it draws with.
struct Gfx {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    depth: wgpu::TextureView,
    ctx: GpuContext,
    pipelines: Pipelines,
}

/// The scene being simulated on the window's device.
struct Running {
    scene: Scene,
    sim: GpuSim,
    /// Each frame waits for its step anyway: a step records the PCG
    /// iterations recent ones took, not the whole cap.
    solved: SolvedSteps,
}

/// An orbit around the scene's framing target.
struct Orbit {
    camera: Camera,
    yaw: f32,
    pitch: f32,
    distance: f32,
}

impl Orbit {
    fn new(camera: Camera) -> Orbit {
        let d = camera.eye - camera.target;
        Orbit {
            camera,
            yaw: d.x.atan2(d.z),
            pitch: (d.y / d.length()).asin(),
            distance: d.length(),
        }
    }

    fn camera(&self) -> Camera {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Camera {
            eye: self.camera.target + self.distance * Vec3::new(cp * sy, sp, cp * cy),
            ..self.camera
        }
    }
}

struct App {
    instance: wgpu::Instance,
    config: Config,
    gfx: Option<Gfx>,
    running: Option<Running>,
    orbit: Option<Orbit>,
    /// The collision model running: `ModelKind::ALL[model]`.
    model: usize,
    paused: bool,
    step_once: bool,
    style: Style,
    dragging: bool,
    cursor: Option<(f64, f64)>,
    frames_left: Option<u64>,
    error: Option<String>,
}

impl App {
    fn open(&mut self, el: &ActiveEventLoop) -> Result<Gfx, String> {
        let attributes = Window::default_attributes()
            .with_title("wgcloth")
            .with_inner_size(winit::dpi::PhysicalSize::new(900u32, 900u32));
        let window = Arc::new(
            el.create_window(attributes)
                .map_err(|e| format!("cannot open a window: {e}"))?,
        );
        let surface = self
            .instance
            .create_surface(window.clone())
            .map_err(|e| format!("cannot draw into the window: {e}"))?;
        let adapter =
            pollster::block_on(self.instance.request_adapter(&wgpu::RequestAdapterOptions {
                compatible_surface: Some(&surface),
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            }))
            .map_err(|e| format!("no GPU adapter for the window: {e}"))?;
        let ctx = GpuContext::from_adapter(&adapter, wgcloth::gpu::OPTIONAL_FEATURES)
            .map_err(|e| e.to_string())?;
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or("the window's surface does not suit the adapter")?;
        let formats = surface.get_capabilities(&adapter).formats;
        if let Some(srgb) = formats.iter().copied().find(|f| f.is_srgb()) {
            config.format = srgb;
        }
        config.present_mode = wgpu::PresentMode::AutoVsync;
        surface.configure(&ctx.device, &config);
        // Compiled here, so a window that cannot run them fails at once.
        ctx.kernels().map_err(|e| e.to_string())?;
        Ok(Gfx {
            depth: depth_target(&ctx.device, config.width, config.height),
            pipelines: Pipelines::new(&ctx.device, config.format),
            window,
            surface,
            config,
            ctx,
        })
    }

    /// (Re)builds the scene with the current model on the window's device.
    fn start(&mut self) -> Result<(), String> {
        let gfx = self.gfx.as_ref().expect("window open");
        let config = Config {
            model: ModelKind::ALL[self.model],
            ..self.config.clone()
        };
        let scene = Scene::new(&config).map_err(|e| e.to_string())?;
        let kernels = gfx.ctx.kernels().map_err(|e| e.to_string())?;
        let sim = GpuSim::with_kernels(&kernels, &gfx.ctx.device, &gfx.ctx.queue, &scene)
            .map_err(|e| e.to_string())?;
        if self.orbit.is_none() {
            let period = scene.config.rigid.motion.period;
            self.orbit = Some(Orbit::new(Camera::framing(&scene, period)));
        }
        gfx.window
            .set_title(&format!("wgcloth: {}", config.model.name()));
        let solved = SolvedSteps::for_scene(&sim, &scene);
        self.running = Some(Running { scene, sim, solved });
        Ok(())
    }

    fn redraw(&mut self) -> Result<(), String> {
        let (Some(gfx), Some(run), Some(orbit)) = (&self.gfx, &mut self.running, &self.orbit)
        else {
            return Ok(());
        };
        if !self.paused || self.step_once {
            run.solved.step(&run.sim).map_err(|e| e.to_string())?;
            self.step_once = false;
        }
        let frame = match gfx.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                gfx.surface.configure(&gfx.ctx.device, &gfx.config);
                return Ok(());
            }
            _ => return Ok(()),
        };
        let view = frame.texture.create_view(&Default::default());
        let (device, queue) = (&gfx.ctx.device, &gfx.ctx.queue);
        let mut encoder = device.create_command_encoder(&Default::default());
        run.sim.record_force_lines(&mut encoder);
        let aspect = gfx.config.width as f32 / gfx.config.height as f32;
        let source = Source::gpu(&run.sim, &run.scene);
        let target = (&view, &gfx.depth, aspect);
        let camera = orbit.camera();
        gfx.pipelines.record(
            device,
            queue,
            &mut encoder,
            target,
            &source,
            &camera,
            self.style,
        );
        queue.submit([encoder.finish()]);
        gfx.window.pre_present_notify();
        queue.present(frame);
        gfx.ctx.finish().map_err(|e| e.to_string())?;
        gfx.window.request_redraw();
        Ok(())
    }

    fn key(&mut self, key: Key) -> Result<bool, String> {
        match key {
            Key::Named(NamedKey::Escape) => return Ok(false),
            Key::Named(NamedKey::Space) => self.paused = !self.paused,
            Key::Character(c) => match c.as_str() {
                "n" => self.step_once = true,
                "w" => self.style.wireframe = !self.style.wireframe,
                "f" => self.style.forces = !self.style.forces,
                "m" => {
                    self.model = (self.model + 1) % ModelKind::ALL.len();
                    self.start()?;
                }
                _ => {}
            },
            _ => {}
        }
        Ok(true)
    }

    fn fail(&mut self, el: &ActiveEventLoop, e: String) {
        self.error = Some(e);
        el.exit();
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.gfx.is_some() {
            return;
        }
        match self.open(el) {
            Ok(gfx) => {
                gfx.window.request_redraw();
                self.gfx = Some(gfx);
                if let Err(e) = self.start() {
                    self.fail(el, e);
                }
            }
            Err(e) => self.fail(el, e),
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                if let Some(gfx) = self.gfx.as_mut() {
                    gfx.config.width = size.width;
                    gfx.config.height = size.height;
                    gfx.surface.configure(&gfx.ctx.device, &gfx.config);
                    gfx.depth = depth_target(&gfx.ctx.device, size.width, size.height);
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw() {
                    return self.fail(el, e);
                }
                if let Some(left) = self.frames_left.as_mut() {
                    *left = left.saturating_sub(1);
                    if *left == 0 {
                        el.exit();
                    }
                }
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                match self.key(event.logical_key) {
                    Ok(true) => {}
                    Ok(false) => el.exit(),
                    Err(e) => self.fail(el, e),
                }
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => self.dragging = state == ElementState::Pressed,
            WindowEvent::CursorMoved { position, .. } => {
                let now = (position.x, position.y);
                if let (true, Some(before), Some(orbit)) =
                    (self.dragging, self.cursor, self.orbit.as_mut())
                {
                    orbit.yaw -= 0.01 * (now.0 - before.0) as f32;
                    orbit.pitch = (orbit.pitch + 0.01 * (now.1 - before.1) as f32).clamp(-1.5, 1.5);
                }
                self.cursor = Some(now);
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                if let Some(orbit) = self.orbit.as_mut() {
                    orbit.distance *= 0.9f32.powf(lines);
                }
            }
            _ => {}
        }
    }
}

/// `--name VALUE` from the command line.
fn flag<T: std::str::FromStr>(args: &[String], name: &str) -> Result<Option<T>, String> {
    match args.iter().position(|a| a == name) {
        None => Ok(None),
        Some(i) => args
            .get(i + 1)
            .and_then(|v| v.parse().ok())
            .map(Some)
            .ok_or_else(|| format!("{name} needs a number")),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let (grid, frames) = match (flag::<u32>(&args, "--grid"), flag::<u64>(&args, "--frames")) {
        (Ok(g), Ok(f)) => (g, f),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("error: viewer: {e}");
            return ExitCode::from(2);
        }
    };
    let event_loop = match EventLoop::new() {
        Ok(el) => el,
        Err(_) => {
            eprintln!(
                "error: viewer: no display to open a window on (neither DISPLAY nor WAYLAND_DISPLAY works); `wgcloth run --out DIR` renders frames headless"
            );
            return ExitCode::from(2);
        }
    };
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut config = Config::default();
    if let Some(n) = grid {
        config.cloth.grid = [n, n];
    }
    let mut app = App {
        instance: wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
            Box::new(event_loop.owned_display_handle()),
        )),
        config,
        gfx: None,
        running: None,
        orbit: None,
        model: (ModelKind::ALL.iter())
            .position(|&m| m == ModelKind::FrictionNet)
            .unwrap_or(0),
        paused: false,
        step_once: false,
        style: Style {
            wireframe: false,
            forces: true,
        },
        dragging: false,
        cursor: None,
        frames_left: frames,
        error: None,
    };
    if let Err(e) = event_loop.run_app(&mut app) {
        app.error
            .get_or_insert(format!("the window's event loop failed: {e}"));
    }
    match app.error {
        None => ExitCode::SUCCESS,
        Some(e) => {
            eprintln!("error: viewer: {e}");
            ExitCode::from(2)
        }
    }
}
