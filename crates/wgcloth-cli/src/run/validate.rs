//! `wgcloth validate`: the GPU against the CPU on the same scene.

use wgcloth::cpu::CpuSim;
use wgcloth::error::Result;
use wgcloth::gpu::{GpuContext, GpuSim, SolvedSteps, context::describe};
use wgcloth::scene::Scene;
use wgcloth::sensitivity::{Reference, Sensitivity, largest_distance};

/// GPU against CPU on the same scene: the largest position deviation (m)
/// after `steps` steps, and the contact totals of each. The GPU waits for
/// each step, and records the PCG iterations a run loop would
/// ([`SolvedSteps`]): each step ends where one recording the whole cap
/// ends. `each_step` sees both after every step (its number from 1);
/// `progress` is called before each step of every run: the GPU's and the
/// CPU's together, then the two of [`Sensitivity::measure`].
///
/// A faithful GPU does not end where the CPU does: rounding grows in
/// contact, and each solve stops elsewhere within its tolerance.
/// `sensitivity` measures how far two faithful CPU runs end apart;
/// [`Sensitivity::faithful`] says what the adapter's run may differ by.
pub struct Validation {
    pub max_deviation: f32,
    pub sensitivity: Sensitivity,
    pub cpu_contacts: u64,
    pub gpu_contacts: u64,
    pub adapter: String,
}

pub fn validate(
    ctx: &GpuContext,
    scene: Scene,
    steps: u64,
    mut each_step: impl FnMut(u64, &GpuSim, &CpuSim),
    mut progress: impl FnMut(),
) -> Result<Validation> {
    let kernels = ctx.kernels()?;
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene)?;
    let mut solved = SolvedSteps::for_scene(&gpu, &scene);
    let mut cpu = CpuSim::new(scene.clone());
    let mut cpu_contacts = 0;
    for k in 0..steps {
        progress();
        solved.step(&gpu)?;
        cpu_contacts += cpu.step().contacts as u64;
        each_step(k + 1, &gpu, &cpu);
    }
    ctx.finish()?;
    let x = gpu.read_positions()?;
    let reference = Reference {
        x: &cpu.state.x,
        contacts: cpu_contacts,
    };
    Ok(Validation {
        max_deviation: largest_distance(&x, &cpu.state.x),
        sensitivity: Sensitivity::measure(&scene, steps, reference, progress),
        cpu_contacts,
        gpu_contacts: gpu.read_state()?.contacts_total as u64,
        adapter: describe(&ctx.adapter),
    })
}
