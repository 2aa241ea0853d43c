//! The CPU solver's PCG iterations at every step of the default scene (the
//! thesis sphere, friction-net, solved to 1e-3), one line per grid:
//! `grid: n1 n2 ...`. `scripts/budget_replay.py` replays GPU iteration
//! budgets against these (docs/iterations_per_step.txt):
//!
//! `cargo run --release --example iterations_per_step -- 32 64 128 256 512`

use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};

fn main() -> wgcloth::error::Result<()> {
    let mut grids: Vec<u32> = Vec::new();
    for arg in std::env::args().skip(1) {
        match arg.parse() {
            Ok(grid) => grids.push(grid),
            Err(_) => {
                return Err(wgcloth::error::Error::config(
                    "grid",
                    "must be a whole number",
                ));
            }
        }
    }
    for grid in grids {
        let mut config = Config::default();
        config.cloth.grid = [grid, grid];
        let mut sim = CpuSim::new(Scene::new(&config)?);
        let steps = config.solver.steps;
        let iterations: Vec<String> = (0..steps)
            .map(|_| sim.step().pcg.iterations.to_string())
            .collect();
        println!("{grid}: {}", iterations.join(" "));
    }
    Ok(())
}
