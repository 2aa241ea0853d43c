//! Many independent worlds stepped together on the CPU (issue 67): each a
//! [`CpuSim`] of its own scene, the worlds spread over rayon's threads. A
//! world never reads another's state. Grids may differ: a thread takes
//! whole worlds, so nothing is packed.

use rayon::prelude::*;

use crate::cpu::{CpuSim, StepStats};
use crate::scene::Scene;

/// The worlds of a batch, stepped together.
pub struct CpuWorlds {
    worlds: Vec<CpuSim>,
}

impl CpuWorlds {
    /// A world for each of `scenes`, each at rest at time 0.
    pub fn new(scenes: Vec<Scene>) -> CpuWorlds {
        CpuWorlds {
            worlds: scenes.into_iter().map(CpuSim::new).collect(),
        }
    }

    /// One step of every world; each world's statistics, in order.
    pub fn step(&mut self) -> Vec<StepStats> {
        self.worlds.par_iter_mut().map(CpuSim::step).collect()
    }

    /// One step of the worlds `stepped` picks by their index (the others
    /// stay where they are, e.g. one that diverged); the statistics of
    /// those stepped.
    pub fn step_where(&mut self, stepped: impl Fn(usize) -> bool + Sync) -> Vec<Option<StepStats>> {
        (self.worlds.par_iter_mut().enumerate())
            .map(|(k, sim)| stepped(k).then(|| sim.step()))
            .collect()
    }

    /// The worlds, in the order of their scenes.
    pub fn worlds(&self) -> &[CpuSim] {
        &self.worlds
    }

    /// The worlds, to read or replace a world's state.
    pub fn worlds_mut(&mut self) -> &mut [CpuSim] {
        &mut self.worlds
    }
}
