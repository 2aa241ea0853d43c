//! How many PCG iterations a GPU step records, from the iterations recent
//! steps took (read back asynchronously, `StepState::last_iterations`): the
//! run loop of `wgcloth run` and the browser demo use it, and so may an app
//! that records steps with [`GpuSim::encode_step`].

#[cfg(doc)]
use crate::gpu::GpuSim;

/// How many PCG iterations the next GPU step records: enough for twice
/// the most any of the last [`CgBudget::WINDOW`] steps took, never more
/// than `solver.cg_iters`, the whole cap for the first step. Converged
/// iterations dispatch no work, but each recorded one costs its
/// dispatches' overhead (about 90 µs each on lavapipe, 6–8 µs on an H200),
/// so recording the whole cap every step costs more than most steps'
/// solve.
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
    /// Steps whose iterations count.
    pub const WINDOW: usize = 32;
    /// The fewest iterations a step records.
    pub const LEAST: u32 = 12;

    /// A budget of at most `cap` (`solver.cg_iters`) for steps solved to
    /// `tol` (`solver.cg_tol`).
    pub fn new(cap: u32, tol: f32) -> CgBudget {
        CgBudget {
            cap,
            tol,
            recent: Default::default(),
        }
    }

    /// Iterations for the next step to record ([`GpuSim::set_cg_budget`]).
    pub fn next(&self) -> u32 {
        match self.recent.iter().max() {
            Some(&most) => (2 * most).max(Self::LEAST).min(self.cap),
            None => self.cap,
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The budget records twice the recent most, within [LEAST, cap]; a step
    /// that ran out sends the next back to the cap, and the window forgets.
    #[test]
    fn the_iteration_budget_follows_recent_steps() {
        let mut b = CgBudget::new(100, 1e-3);
        assert_eq!(b.next(), 100, "no step seen yet");
        assert!(!b.observe(3, 100, 5e-4));
        assert_eq!(b.next(), CgBudget::LEAST);
        b.observe(20, 100, 9e-4);
        assert_eq!(b.next(), 40);
        // Out of budget above the tolerance: the whole cap.
        assert!(b.cut(40, 40, 2e-3));
        assert!(b.observe(40, 40, 2e-3), "a cut step");
        assert_eq!(b.next(), 100);
        // Converged on the budget's last iteration is not running out.
        let mut b = CgBudget::new(100, 1e-3);
        assert!(!b.cut(30, 30, 8e-4));
        assert!(!b.observe(30, 30, 8e-4));
        assert_eq!(b.next(), 60);
        // Only the last WINDOW steps count.
        for _ in 0..CgBudget::WINDOW {
            b.observe(5, 60, 1e-4);
        }
        assert_eq!(b.next(), CgBudget::LEAST);
        // The thesis's solve (tolerance 0) never converges early: the cap.
        let mut b = CgBudget::new(25, 0.0);
        assert!(!b.cut(25, 25, 0.1), "the cap cuts nothing");
        assert!(!b.observe(25, 25, 0.1));
        assert_eq!(b.next(), 25);
    }
}
