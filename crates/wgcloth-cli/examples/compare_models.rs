//! The thesis scene with the analytic friction force and with the friction
//! network side by side on the CPU: RMS and largest vertex deviation, wall
//! time per sphere period of each, and whether the network run stays
//! finite and out of the sphere.
//!
//! `cargo run --release --example compare_models -- [PERIODS] [GRID] [WEIGHTS]`

use std::time::Instant;

use wgcloth::config::ModelKind;
use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let periods: u32 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let grid: u32 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(32);
    let mut config = Config::default();
    config.cloth.grid = [grid, grid];
    let weights = args.get(3).map(std::path::PathBuf::from);
    let steps_per_period = (config.rigid.motion.period / config.solver.dt).round() as u64;
    let mut sims = [ModelKind::Friction, ModelKind::FrictionNet].map(|model| {
        let mut config = Config {
            model,
            ..config.clone()
        };
        if model.is_network() {
            config.contact.weights = weights.clone();
        }
        Scene::new(&config).map(CpuSim::new)
    });
    let [Ok(analytic), Ok(net)] = &mut sims else {
        return Err("could not build the scenes (is the weights file there?)".into());
    };
    let mut seconds = [0.0f64; 2];
    let mut deepest = [0.0f32; 2];
    for period in 1..=periods {
        let (mut sum_sq, mut worst) = (0.0f64, 0.0f32);
        for _ in 0..steps_per_period {
            for (k, sim) in [&mut *analytic, &mut *net].into_iter().enumerate() {
                let start = Instant::now();
                deepest[k] = deepest[k].max(sim.step().max_penetration);
                seconds[k] += start.elapsed().as_secs_f64();
            }
            for (a, b) in analytic.state.x.iter().zip(&net.state.x) {
                let d = (*a - *b).length();
                sum_sq += (d * d) as f64;
                worst = worst.max(d);
            }
        }
        let rms = (sum_sq / (steps_per_period as f64 * analytic.state.x.len() as f64)).sqrt();
        println!(
            "period {period}: RMS deviation {rms:.4e} m, largest {worst:.4e} m; network state {}",
            if net.is_finite() {
                "finite"
            } else {
                "NOT FINITE"
            }
        );
        if !net.is_finite() {
            break;
        }
    }
    println!(
        "deepest penetration: analytic {:.4} m, network {:.4} m; wall time per period: analytic {:.2} s, network {:.2} s ({:.2}×)",
        deepest[0],
        deepest[1],
        seconds[0] / periods as f64,
        seconds[1] / periods as f64,
        seconds[1] / seconds[0]
    );
    Ok(())
}
