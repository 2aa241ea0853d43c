use wgcloth::{Config, Scene, cpu::CpuSim};
fn main() {
    let mut c = Config::default();
    let a: Vec<String> = std::env::args().collect();

    if a.len() > 1 && a[1] == "naive" {
        c.model = wgcloth::config::ModelKind::Naive;
    }
    if a.len() > 2 {
        c.solver.cg_iters = a[2].parse().unwrap();
    }
    let mut sim = CpuSim::new(Scene::new(&c).unwrap());
    for k in 0..400 {
        let s = sim.step();
        let vmax = sim
            .state
            .v
            .iter()
            .map(|v| v.length())
            .fold(0.0f32, f32::max);
        if k % 20 == 0 || s.max_penetration > 0.01 {
            let e = sim.energy();
            println!(
                "step {k} pen {:.4} vmax {vmax:.2} KE {:.4} total {:.4} contacts {} res {:.2e}",
                s.max_penetration,
                e.kinetic,
                e.total(),
                s.contacts,
                s.pcg.relative_residual
            );
        }
    }
}
