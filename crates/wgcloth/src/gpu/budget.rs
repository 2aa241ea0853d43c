//! How many PCG iterations a GPU step records, from the iterations recent
//! steps took (read back asynchronously, `StepState::last_iterations`): the
//! run loop of `wgcloth run` and the browser demo use it, and so may an app
//! that records steps with [`GpuSim::encode_step`].

use crate::config::SolverConfig;
#[cfg(not(target_arch = "wasm32"))]
use crate::error::Result;
#[cfg(any(doc, not(target_arch = "wasm32")))]
use crate::gpu::GpuSim;
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::layout::StepState;
#[cfg(not(target_arch = "wasm32"))]
use crate::scene::Scene;

/// How many PCG iterations the next GPU step records: half again the
/// most any of the last [`CgBudget::WINDOW`] steps took, plus
/// [`CgBudget::MARGIN`], never more than `solver.cg_iters`; the whole cap
/// until a step has been read back. Converged iterations dispatch no work,
/// but each recorded one costs its dispatches' overhead (about 48 µs each
/// on lavapipe, 6–8 µs on an H200), so recording more than a step needs costs
/// time, and recording fewer costs the step's repeat.
///
/// A step the budget cuts short of the tolerance ([`CgBudget::cut`]) can
/// be handled two ways:
/// - a loop that keeps each step's start state (`wgcloth run`) solves it
///   again from there with the whole cap, so every step converges, and a
///   cut costs that repeat and the steps in flight behind it;
/// - a loop that cannot (the browser demo) keeps the cut step, and
///   [`CgBudget::observe`] sends the next steps back to the whole cap.
pub struct CgBudget {
    cap: u32,
    tol: f32,
    recent: std::collections::VecDeque<u32>,
}

impl CgBudget {
    /// Steps whose iterations count. With [`CgBudget::MARGIN`] and the
    /// half, chosen by replaying the thesis scene's iterations per step
    /// (200 steps, 32² to 512²) against the costs measured on lavapipe and
    /// an H200: about a tenth off the step against twice the most of 32
    /// steps, with fewer cuts (BENCHMARKS.md "A step the budget cut").
    pub const WINDOW: usize = 4;
    /// Iterations recorded beyond the recent most and its half.
    pub const MARGIN: u32 = 16;

    /// A budget of at most `cap` (`solver.cg_iters`) for steps solved to
    /// `tol` (`solver.cg_tol`).
    pub fn new(cap: u32, tol: f32) -> CgBudget {
        CgBudget {
            cap,
            tol,
            recent: Default::default(),
        }
    }

    /// A budget of at most `solver.cg_iters` for steps solved to
    /// `solver.cg_tol`.
    pub fn for_solver(solver: &SolverConfig) -> CgBudget {
        Self::new(solver.cg_iters, solver.cg_tol)
    }

    /// Iterations for the next step to record ([`GpuSim::set_cg_budget`]).
    pub fn next(&self) -> u32 {
        match self.recent.iter().max() {
            Some(&most) => (most + most / 2 + Self::MARGIN).min(self.cap),
            None => self.cap,
        }
    }

    /// Whether a step has been counted ([`CgBudget::observe`]): until one
    /// has, [`CgBudget::next`] is the whole cap.
    pub fn informed(&self) -> bool {
        !self.recent.is_empty()
    }

    /// The whole cap: what a step solved again records.
    pub fn cap(&self) -> u32 {
        self.cap
    }

    /// Whether a step that took `iterations` of a budget of `budget` and
    /// ended at relative residual `residual` was cut short of the
    /// tolerance by the budget (a budget at the cap cuts nothing).
    pub fn cut(&self, iterations: u32, budget: u32, residual: f32) -> bool {
        iterations >= budget && residual > self.tol && budget < self.cap
    }

    /// Counts a step that took `iterations` of a budget of `budget` and
    /// ended at relative residual `residual` towards the next budgets;
    /// true when the budget cut it ([`CgBudget::cut`]). A step that ran out
    /// (cut, or unsolved at the cap) counts as needing the whole cap.
    pub fn observe(&mut self, iterations: u32, budget: u32, residual: f32) -> bool {
        let cut = self.cut(iterations, budget, residual);
        let ran_out = iterations >= budget && residual > self.tol;
        if self.recent.len() == Self::WINDOW {
            self.recent.pop_front();
        }
        self.recent
            .push_back(if ran_out { self.cap } else { iterations });
        cut
    }
}

/// Steps that wait for each other (native only): what a loop of
/// [`GpuSim::step`] does, with each step's PCG iterations recorded by a
/// [`CgBudget`] instead of the whole cap, and a step the budget cut short
/// of the tolerance solved again from its start with the cap, as
/// `wgcloth run` does without waiting (where each solve runs whole,
/// `GpuSim::solved_whole`, the budget is the cap and nothing is cut).
/// Iterations after convergence
/// change nothing, so each step ends bit for bit where one recording the
/// cap ends, for the dispatches it records. `wgcloth validate`, the
/// viewer and the tests step this way. It keeps the start of the step it runs on the
/// device (positions, velocities and [`StepState`]), in buffers of its own.
#[cfg(not(target_arch = "wasm32"))]
pub struct SolvedSteps {
    budget: CgBudget,
    start: [wgpu::Buffer; 4],
    resolved: u32,
}

#[cfg(not(target_arch = "wasm32"))]
impl SolvedSteps {
    /// Steps of `sim`, which holds `scene`, with its solver's cap and
    /// tolerance.
    pub fn for_scene(sim: &GpuSim, scene: &Scene) -> SolvedSteps {
        Self::new(sim, CgBudget::for_solver(&scene.config.solver))
    }

    /// Steps of `sim` with `budget`.
    pub fn new(sim: &GpuSim, budget: CgBudget) -> SolvedSteps {
        let start = sim.step_start().map(|b| {
            sim.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some("step start"),
                size: b.size(),
                usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        SolvedSteps {
            budget,
            start,
            resolved: 0,
        }
    }

    /// Runs one step to the tolerance and waits for it: its [`StepState`].
    pub fn step(&mut self, sim: &GpuSim) -> Result<StepState> {
        let (mut state, mut budget) = self.run(sim, self.budget.next(), true)?;
        if self
            .budget
            .cut(state.last_iterations, budget, state.last_residual)
        {
            self.resolved += 1;
            (state, budget) = self.run(sim, self.budget.cap(), false)?;
        }
        // The repeat, not the cut step, counts towards the next budgets.
        self.budget
            .observe(state.last_iterations, budget, state.last_residual);
        Ok(state)
    }

    /// Steps recording `budget` iterations, from the state `sim` holds
    /// (kept first) or from the kept start: its state, and the budget it
    /// recorded (the cap where the solve runs whole).
    fn run(&self, sim: &GpuSim, budget: u32, keep: bool) -> Result<(StepState, u32)> {
        let mut encoder = sim.device().create_command_encoder(&Default::default());
        for (live, kept) in sim.step_start().into_iter().zip(&self.start) {
            let (from, to) = if keep { (live, kept) } else { (kept, live) };
            encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
        }
        sim.set_cg_budget(budget);
        sim.encode_step(&mut encoder);
        sim.queue().submit([encoder.finish()]);
        Ok((sim.read_state()?, sim.cg_budget()))
    }

    /// Steps the budget cut and [`Self::step`] solved again.
    pub fn resolved(&self) -> u32 {
        self.resolved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The budget records the recent most, half of it again and the margin,
    /// within the cap; a step that ran out sends the next back to the cap,
    /// and the window forgets.
    #[test]
    fn the_iteration_budget_follows_recent_steps() {
        let mut b = CgBudget::new(200, 1e-3);
        assert_eq!(b.next(), 200, "no step seen yet");
        assert!(!b.informed());
        assert!(!b.observe(3, 200, 5e-4));
        assert!(b.informed());
        assert_eq!(b.next(), 4 + CgBudget::MARGIN);
        b.observe(40, 200, 9e-4);
        assert_eq!(b.next(), 60 + CgBudget::MARGIN);
        // Out of budget above the tolerance: the whole cap.
        assert!(b.cut(76, 76, 2e-3));
        assert!(b.observe(76, 76, 2e-3), "a cut step");
        assert_eq!(b.next(), 200);
        // Converged on the budget's last iteration is not running out.
        let mut b = CgBudget::new(200, 1e-3);
        assert!(!b.cut(30, 30, 8e-4));
        assert!(!b.observe(30, 30, 8e-4));
        assert_eq!(b.next(), 45 + CgBudget::MARGIN);
        // Only the last WINDOW steps count.
        for _ in 0..CgBudget::WINDOW {
            b.observe(4, 60, 1e-4);
        }
        assert_eq!(b.next(), 6 + CgBudget::MARGIN);
        // Never past the cap.
        b.observe(150, 200, 1e-4);
        assert_eq!(b.next(), 200);
        // The thesis's solve (tolerance 0) never converges early: the cap.
        let mut b = CgBudget::new(25, 0.0);
        assert!(!b.cut(25, 25, 0.1), "the cap cuts nothing");
        assert!(!b.observe(25, 25, 0.1));
        assert_eq!(b.next(), 25);
    }
}
