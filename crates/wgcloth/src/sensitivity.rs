//! How far two faithful runs of a scene end apart: what a GPU run is held
//! to against the CPU's where the two do not compute alike (`wgcloth
//! validate`, the parity tests on a hardware GPU).
//!
//! Two things let a faithful run end elsewhere, and each is measured by a
//! CPU run against the CPU's own:
//! - rounding: fused multiply-adds and WGSL's looser division and square
//!   root change a step by ulps, which contact grows (a vertex entering the
//!   band gets k_d ḋ at once; friction turns between stick and slip). A run
//!   whose vertices start [`PERTURBATION`] m away
//!   ([`State::nudge`](crate::cpu::State::nudge)) shows
//!   how much;
//! - the solve's tolerance: CG stops anywhere its relative residual is at
//!   most `solver.cg_tol`, and a system stiff with contacts leaves the
//!   velocities far less accurate than that. Two solves of the same step
//!   of the thesis scene to 1e-3 (the patch smoother against block Jacobi)
//!   differed by 1.7e-3 to 2.6e-2 m/s from the first contact on; after 16
//!   steps of a fast sphere they ended 1.8 cm apart, where a nudged start
//!   ends 0.36 mm away (BENCHMARKS.md "What a faithful run may differ
//!   by"). A run whose solves go on to a hundredth of the tolerance shows
//!   how much.

use glam::Vec3;

use crate::cpu::{CpuSim, PERTURBATION};
use crate::scene::Scene;

/// How the tighter run's tolerance compares with the scene's.
pub const TIGHTER: f32 = 0.01;

/// How far one run ended from another.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spread {
    /// The largest distance between the two runs' final positions, m.
    pub drift: f32,
    /// The relative difference of their contact totals, |c / c_ref − 1|
    /// (infinite where only the reference has none).
    pub contacts: f64,
}

impl Spread {
    /// The larger of each measure.
    pub fn max(self, other: Spread) -> Spread {
        Spread {
            drift: self.drift.max(other.drift),
            contacts: self.contacts.max(other.contacts),
        }
    }
}

/// The CPU's own run of a scene, which the others are measured against.
#[derive(Clone, Copy, Debug)]
pub struct Reference<'a> {
    /// Its final positions.
    pub x: &'a [Vec3],
    /// Its contacts, summed over the steps.
    pub contacts: u64,
}

impl Reference<'_> {
    /// How far `run`, after `steps` steps, ends from this one.
    fn spread(&self, mut run: CpuSim, steps: u64, each_step: &mut impl FnMut()) -> Spread {
        let contacts: u64 = (0..steps)
            .map(|_| {
                each_step();
                run.step().contacts as u64
            })
            .sum();
        Spread {
            drift: largest_distance(&run.state.x, self.x),
            contacts: match (self.contacts, contacts) {
                (0, 0) => 0.0,
                (0, _) => f64::INFINITY,
                (c, n) => (n as f64 / c as f64 - 1.0).abs(),
            },
        }
    }
}

/// What two faithful runs of a scene may differ by, each way measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sensitivity {
    /// A run started [`PERTURBATION`] m away.
    pub nudged: Spread,
    /// A run solved to [`TIGHTER`] times `solver.cg_tol` (zero when the
    /// solve runs a fixed count of iterations, `cg_tol` = 0).
    pub tolerance: Spread,
}

impl Sensitivity {
    /// Runs the two CPU runs of `scene` for `steps` steps against
    /// `reference`, the CPU's own run of it; `each_step` is called before
    /// each of their steps (2 × `steps` calls, or `steps` for a fixed
    /// count of iterations).
    pub fn measure(
        scene: &Scene,
        steps: u64,
        reference: Reference,
        mut each_step: impl FnMut(),
    ) -> Sensitivity {
        let mut nudged = CpuSim::new(scene.clone());
        nudged.state.nudge(PERTURBATION);
        let nudged = reference.spread(nudged, steps, &mut each_step);
        let tolerance = match scene.config.solver.cg_tol > 0.0 {
            true => {
                // The same cap: a solve it stops short ended elsewhere too.
                let mut tighter = scene.clone();
                tighter.config.solver.cg_tol *= TIGHTER;
                reference.spread(CpuSim::new(tighter), steps, &mut each_step)
            }
            false => Spread::default(),
        };
        Sensitivity { nudged, tolerance }
    }

    /// The larger of the two runs' spreads, each measure.
    pub fn largest(&self) -> Spread {
        self.nudged.max(self.tolerance)
    }

    /// What a run on an adapter may differ by: the nudged run's spread
    /// where the adapter computes as the CPU does
    /// ([`computes_as_the_cpu`](crate::gpu::context::computes_as_the_cpu):
    /// its solves stop where the CPU's do), the larger elsewhere.
    pub fn faithful(&self, adapter: &wgpu::AdapterInfo) -> Spread {
        match crate::gpu::context::computes_as_the_cpu(adapter) {
            true => self.nudged,
            false => self.largest(),
        }
    }
}

/// The largest distance between matching points of `a` and `b`; infinite
/// where either is not a number.
pub fn largest_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(
            0.0f32,
            |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
        )
}
