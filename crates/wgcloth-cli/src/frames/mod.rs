//! What `wgcloth run --out` writes: each frame drawn by the library's
//! offscreen [`Renderer`] as a PNG, the animated GIF, and with
//! `--export obj` each frame's geometry as OBJ.

pub mod obj;
pub mod output;

use wgcloth::cpu::CpuSim;
use wgcloth::error::{Error, Result};
use wgcloth::gpu::{GpuContext, GpuSim};
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
    /// Also each frame's geometry as OBJ (`--export obj`).
    pub obj: bool,
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
        output::FrameWriter::create(&self.dir, frames, (delay_ms, self.obj), self.force)
    }
}

/// The frames of a run, rendered on a GPU context (for a CPU run too: the
/// CPU path uploads its state) and written as they come; without one,
/// only the OBJ frames of `--export obj`.
pub struct Recording<'a> {
    drawing: Option<Drawing<'a>>,
    every: u64,
    writer: output::FrameWriter,
}

/// What drawing frames needs.
struct Drawing<'a> {
    ctx: &'a GpuContext,
    renderer: Renderer,
    camera: Camera,
    style: Style,
    /// The CPU path's state on the GPU (unused by a GPU run).
    host: HostScene,
}

impl Drawing<'_> {
    /// Renders `source` and writes the frame.
    fn draw(&self, source: &Source, writer: &mut output::FrameWriter) -> Result<()> {
        let frame = self.renderer.render(
            &self.ctx.device,
            &self.ctx.queue,
            source,
            &self.camera,
            self.style,
        )?;
        self.ctx.finish()?;
        writer.write(&frame)
    }
}

impl<'a> Recording<'a> {
    /// Checks the frame size before any step runs; `writer` comes from
    /// `options.prepare`. With no context, frames are not drawn.
    pub fn new(
        ctx: Option<&'a GpuContext>,
        scene: &Scene,
        steps: u64,
        (options, writer): (&RecordOptions, output::FrameWriter),
    ) -> Result<Recording<'a>> {
        let drawing = match ctx {
            Some(ctx) => Some(Drawing {
                ctx,
                renderer: Renderer::new(&ctx.device, options.size, options.size)?,
                camera: Camera::framing(scene, steps as f32 * scene.config.solver.dt),
                style: options.style,
                host: HostScene::new(&ctx.device, scene),
            }),
            None => None,
        };
        Ok(Recording {
            drawing,
            every: options.every,
            writer,
        })
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
        self.writer
            .write_obj(&sim.scene, &sim.state.x, sim.state.time as f32)?;
        let Some(d) = &self.drawing else {
            return Ok(());
        };
        d.host
            .upload_sim(&d.ctx.queue, sim, sim.scene.metres_per_force());
        d.draw(&d.host.source(), &mut self.writer)
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
                .write_obj(scene, &scene.cloth.rest_positions, 0.0)?;
        } else if self.writer.wants_obj() {
            let time = step as f32 * scene.config.solver.dt;
            self.writer.write_obj(scene, &sim.read_positions()?, time)?;
        }
        let Some(d) = &self.drawing else {
            return Ok(());
        };
        if step == 0 {
            let start = (&scene.cloth.rest_positions[..], 0.0);
            d.host.upload(&d.ctx.queue, scene, start, &[]);
            return d.draw(&d.host.source(), &mut self.writer);
        }
        let mut encoder = d.ctx.device.create_command_encoder(&Default::default());
        sim.record_force_lines(&mut encoder);
        d.ctx.queue.submit([encoder.finish()]);
        d.draw(&Source::gpu(sim, scene), &mut self.writer)
    }

    /// What the run wrote.
    pub fn finish(self) -> output::Written {
        self.writer.finish()
    }
}
