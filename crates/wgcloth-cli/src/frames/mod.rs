//! What `wgcloth run --out` writes: each frame drawn by the library's
//! offscreen [`Renderer`] (or, with no adapter at all, by the CPU
//! rasteriser of [`raster`]) as a PNG, the animated GIF, and with
//! `--export obj,usd` the geometry as OBJ frames and one USD file.

pub mod obj;
pub mod output;
pub mod raster;
pub mod usd;

use glam::Vec3;
use wgcloth::cpu::CpuSim;
use wgcloth::error::{Error, Result};
use wgcloth::gpu::{GpuContext, GpuSim};
use wgcloth::render::lines::force_lines;
use wgcloth::render::{Camera, HostScene, MAX_FRAME_SIZE, Renderer, Source, Style};
use wgcloth::scene::Scene;

/// What `wgcloth run --out` records.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    pub dir: std::path::PathBuf,
    pub size: u32,
    /// A frame every this many steps (and one of the initial state).
    pub every: u64,
    pub style: Style,
    /// The geometry files besides the frames (`--export obj,usd`).
    pub exports: output::Exports,
    pub force: bool,
}

impl RecordOptions {
    /// The checks that need no GPU, done first: the frame interval and the
    /// directory, which it prepares for the run's frames.
    pub fn prepare(&self, scene: &Scene, steps: u64) -> Result<output::FrameWriter> {
        if self.every == 0 {
            return Err(Error::config("--every", "must be at least 1 step"));
        }
        // Before the directory exists; `Renderer::new` checks the adapter's
        // own (possibly lower) limit once there is a device.
        if !(1..=MAX_FRAME_SIZE).contains(&self.size) {
            return Err(Error::config(
                "--size",
                format!(
                    "must be 1 to {MAX_FRAME_SIZE} pixels per side, got {}",
                    self.size
                ),
            ));
        }
        let frames = 1 + (steps / self.every) as usize;
        let delay_ms = (1e3 * scene.config.solver.dt * self.every as f32) as u32;
        output::FrameWriter::create(&self.dir, frames, (delay_ms, self.exports), self.force)
    }
}

/// The frames of a run, rendered on a GPU context (for a CPU run too: the
/// CPU path uploads its state), or on the CPU where there is none, and
/// written as they come.
pub struct Recording<'a> {
    drawing: Drawing<'a>,
    camera: Camera,
    style: Style,
    size: u32,
    every: u64,
    writer: output::FrameWriter,
}

/// Where frames are drawn.
enum Drawing<'a> {
    Gpu(Box<OnGpu<'a>>),
    /// By [`raster::render`], from the host's copy of the state.
    Cpu,
}

/// What drawing on a GPU needs.
struct OnGpu<'a> {
    ctx: &'a GpuContext,
    renderer: Renderer,
    /// The CPU path's state on the GPU (unused by a GPU run).
    host: HostScene,
}

impl<'a> Recording<'a> {
    /// Checks the frame size before any step runs; `writer` comes from
    /// `options.prepare`. With no context, frames are drawn on the CPU.
    pub fn new(
        ctx: Option<&'a GpuContext>,
        scene: &Scene,
        steps: u64,
        (options, writer): (&RecordOptions, output::FrameWriter),
    ) -> Result<Recording<'a>> {
        let drawing = match ctx {
            Some(ctx) => Drawing::Gpu(Box::new(OnGpu {
                ctx,
                renderer: Renderer::new(&ctx.device, options.size, options.size)?,
                host: HostScene::new(&ctx.device, scene),
            })),
            None => Drawing::Cpu,
        };
        Ok(Recording {
            drawing,
            camera: Camera::framing(scene, steps as f32 * scene.config.solver.dt),
            style: options.style,
            size: options.size,
            every: options.every,
            writer,
        })
    }

    /// Renders `x` at `time` with force segments `lines` on the CPU and
    /// writes the frame.
    fn draw_cpu(
        &mut self,
        scene: &Scene,
        (x, time): (&[Vec3], f32),
        lines: &[[f32; 4]],
    ) -> Result<()> {
        let body = scene.rigid.as_ref();
        let placed = body.map(|b| b.placed_vertices(time)).unwrap_or_default();
        let geometry = raster::Geometry {
            cloth: x,
            grid: [scene.cloth.nx, scene.cloth.ny],
            triangles: &scene.cloth.triangles,
            body: &placed,
            body_triangles: body.map_or(&[][..], |b| &b.mesh.triangles[..]),
            lines,
        };
        let frame = raster::render(&geometry, &self.camera, self.style, [self.size; 2]);
        self.writer.write(&frame)
    }

    /// Whether the state after step `step` is drawn.
    pub fn due(&self, step: u64) -> bool {
        step.is_multiple_of(self.every)
    }

    /// After step `step` of a CPU run (0: the initial state).
    pub fn cpu(&mut self, step: u64, sim: &CpuSim) -> Result<()> {
        if !self.due(step) {
            return Ok(());
        }
        let time = sim.state.time as f32;
        self.writer.write_geometry(&sim.scene, &sim.state.x, step)?;
        let lines = force_lines(sim, sim.scene.metres_per_force());
        match &self.drawing {
            Drawing::Gpu(on) => {
                (on.host).upload(&on.ctx.queue, &sim.scene, (&sim.state.x, time), &lines);
                let view = (&self.camera, self.style);
                draw_gpu(on, &on.host.source(), view, &mut self.writer)
            }
            Drawing::Cpu => self.draw_cpu(&sim.scene, (&sim.state.x, time), &lines),
        }
    }

    /// After step `step` of a GPU run: draws from the simulator's buffers,
    /// except the initial state, drawn from the scene (the simulator places
    /// the body only as it steps).
    pub fn gpu(&mut self, step: u64, sim: &GpuSim, scene: &Scene) -> Result<()> {
        if !self.due(step) {
            return Ok(());
        }
        if step == 0 {
            self.writer
                .write_geometry(scene, &scene.cloth.rest_positions, 0)?;
        } else if self.writer.wants_geometry() {
            self.writer
                .write_geometry(scene, &sim.read_positions()?, step)?;
        }
        let Drawing::Gpu(on) = &self.drawing else {
            return Err(Error::Gpu(
                "a GPU run's frames are drawn on its context: make the recording with it".into(),
            ));
        };
        let view = (&self.camera, self.style);
        if step == 0 {
            let start = (&scene.cloth.rest_positions[..], 0.0);
            on.host.upload(&on.ctx.queue, scene, start, &[]);
            return draw_gpu(on, &on.host.source(), view, &mut self.writer);
        }
        let mut encoder = on.ctx.device.create_command_encoder(&Default::default());
        sim.record_force_lines(&mut encoder);
        on.ctx.queue.submit([encoder.finish()]);
        draw_gpu(on, &Source::gpu(sim, scene), view, &mut self.writer)
    }

    /// What the run wrote.
    pub fn finish(self, scene: &Scene) -> Result<output::Written> {
        self.writer.finish(scene)
    }
}

/// Renders `source` on the GPU and writes the frame.
fn draw_gpu(
    on: &OnGpu,
    source: &Source,
    (camera, style): (&Camera, Style),
    writer: &mut output::FrameWriter,
) -> Result<()> {
    let (device, queue) = (&on.ctx.device, &on.ctx.queue);
    let frame = on.renderer.render(device, queue, source, camera, style)?;
    on.ctx.finish()?;
    writer.write(&frame)
}
