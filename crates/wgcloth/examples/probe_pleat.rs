use wgcloth::config::Config;
use wgcloth::cpu::CpuSim;
use wgcloth::scene::Scene;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let text = std::fs::read_to_string(&args[1]).unwrap();
    let mut config = Config::from_toml(&text, std::path::Path::new(&args[1])).unwrap();
    let n: u32 = args[2].parse().unwrap();
    config.cloth.grid = [n, n];
    let steps: usize = args[3].parse().unwrap();
    let scene = Scene::new(&config).unwrap();
    let mut sim = CpuSim::new(scene);
    let mut prev: Vec<glam::Vec3> = sim.state.x.clone();
    for s in 0..steps {
        sim.step();
        if s + 1 >= steps - 3 {
            let c = &sim.scene.cloth;
            let mut worst: Vec<(f32, usize)> = c
                .springs
                .iter()
                .enumerate()
                .map(|(k, [a, b])| {
                    let l = (sim.state.x[*a as usize] - sim.state.x[*b as usize]).length();
                    (l / c.rest_lengths[k] - 1.0, k)
                })
                .collect();
            worst.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap());
            println!(
                "step {} max abs z {:.3e}",
                s + 1,
                sim.state.x.iter().map(|p| p.z.abs()).fold(0.0f32, f32::max)
            );
            for &(e, k) in worst.iter().take(4) {
                let [a, b] = c.springs[k];
                let (a, b) = (a as usize, b as usize);
                println!(
                    "  strain {:.3} {:?} a=({},{}) pinned {} moved {:.2e} x {:?} | b=({},{}) pinned {} moved {:.2e} x {:?}",
                    e,
                    c.spring_kinds[k],
                    a as u32 % n,
                    a as u32 / n,
                    c.pinned[a],
                    (sim.state.x[a] - prev[a]).length(),
                    sim.state.x[a],
                    b as u32 % n,
                    b as u32 / n,
                    c.pinned[b],
                    (sim.state.x[b] - prev[b]).length(),
                    sim.state.x[b]
                );
            }
        }
        prev = sim.state.x.clone();
    }
}
