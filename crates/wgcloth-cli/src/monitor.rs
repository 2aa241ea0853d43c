//! Samples of a run taken every K steps (`run --monitor FILE.csv`): the
//! state's energy, fastest vertex and most-strained spring, the cloth
//! triangle pairs that pass through each other, the deepest cloth vertex
//! inside the body, the process's resident memory and the GPU allocator's
//! bytes. A soak reads them to show the run stays finite, its
//! energy bounded and its memory flat.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;

use wgcloth::error::{Error, Result};
use wgcloth::scene::Scene;
use wgcloth::{cpu, intersections};

/// One row of the monitor file.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Sample {
    pub step: u64,
    /// Wall time since the monitor was created, s.
    pub seconds: f64,
    /// Which path computed the state: "cpu" or "gpu".
    pub backend: &'static str,
    /// Kinetic + gravitational + elastic energy of the cloth, J.
    pub energy: f64,
    pub kinetic: f64,
    /// The fastest vertex's speed, m/s.
    pub max_speed: f32,
    /// The most-stretched spring's (l − L) / L, 0 when none is longer than
    /// at rest (`cpu::springs::max_strain`).
    pub max_strain: f32,
    pub finite: bool,
    /// Cloth triangle pairs that share no vertex and intersect
    /// (`wgcloth::intersections`).
    pub self_intersections: usize,
    /// How deep the deepest cloth vertex is inside the body's surface as
    /// the step ends, m (0 outside, or with no body).
    pub body_depth: f32,
    /// Resident set size of this process (Linux `VmRSS`), bytes.
    pub rss_bytes: Option<u64>,
    /// Device memory the GPU allocator has handed out and has reserved
    /// from the driver, bytes (backends with an allocator report).
    pub gpu_allocated_bytes: Option<u64>,
    pub gpu_reserved_bytes: Option<u64>,
}

const HEADER: &str = "step,seconds,backend,energy_j,kinetic_j,max_speed,max_strain,finite,self_intersections,body_depth,rss_bytes,gpu_allocated_bytes,gpu_reserved_bytes";

impl Sample {
    fn csv(&self) -> String {
        let opt = |v: Option<u64>| v.map(|b| b.to_string()).unwrap_or_default();
        format!(
            "{},{:.3},{},{:.9e},{:.9e},{:.6e},{:.6e},{},{},{:.6e},{},{},{}",
            self.step,
            self.seconds,
            self.backend,
            self.energy,
            self.kinetic,
            self.max_speed,
            self.max_strain,
            self.finite,
            self.self_intersections,
            self.body_depth,
            opt(self.rss_bytes),
            opt(self.gpu_allocated_bytes),
            opt(self.gpu_reserved_bytes)
        )
    }
}

/// Writes a [`Sample`] every `every` steps, one CSV line each, flushed at
/// once so a run that is killed keeps what it measured.
pub struct Monitor {
    every: u64,
    path: PathBuf,
    out: BufWriter<File>,
    start: Instant,
    pub samples: Vec<Sample>,
}

impl Monitor {
    /// Creates (or replaces) `path` and writes the header.
    pub fn create(path: &Path, every: u64) -> Result<Monitor> {
        if every == 0 {
            return Err(Error::config("--monitor-every", "must be at least 1"));
        }
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut monitor = Monitor {
            every,
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            start: Instant::now(),
            samples: Vec::new(),
        };
        monitor.line(HEADER)?;
        Ok(monitor)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the state after `step` steps is sampled.
    pub fn due(&self, step: u64) -> bool {
        step.is_multiple_of(self.every)
    }

    fn line(&mut self, text: &str) -> Result<()> {
        writeln!(self.out, "{text}")
            .and_then(|_| self.out.flush())
            .map_err(|e| Error::io(&self.path, e))
    }

    /// Samples the state `x`, `v` after `step` steps; `device` adds the GPU
    /// allocator's figures.
    pub fn record(
        &mut self,
        step: u64,
        scene: &Scene,
        x: &[Vec3],
        v: &[Vec3],
        device: Option<&wgpu::Device>,
    ) -> Result<()> {
        let energy = cpu::energy(scene, x, v);
        let allocator = device.and_then(|d| d.generate_allocator_report());
        let sample = Sample {
            step,
            seconds: self.start.elapsed().as_secs_f64(),
            backend: if device.is_some() { "gpu" } else { "cpu" },
            energy: energy.total(),
            kinetic: energy.kinetic,
            max_speed: v.iter().map(|v| v.length()).fold(0.0, f32::max),
            max_strain: cpu::springs::max_strain(&scene.cloth, x),
            finite: x.iter().chain(v).all(|p| p.is_finite()),
            self_intersections: intersections::intersecting_pairs(x, &scene.cloth.triangles).len(),
            body_depth: body_depth(scene, step, x),
            rss_bytes: resident_bytes(),
            gpu_allocated_bytes: allocator.as_ref().map(|r| r.total_allocated_bytes),
            gpu_reserved_bytes: allocator.as_ref().map(|r| r.total_reserved_bytes),
        };
        self.line(&sample.csv())?;
        self.samples.push(sample);
        Ok(())
    }

    /// Energy range and memory at the first and last sample, for the run
    /// summary.
    pub fn summary(&self) -> String {
        let (Some(first), Some(last)) = (self.samples.first(), self.samples.last()) else {
            return format!("monitor      no samples in {}", self.path.display());
        };
        let (lo, hi) = self
            .samples
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                (lo.min(s.energy), hi.max(s.energy))
            });
        let mib = |b: Option<u64>| {
            b.map(|b| format!("{:.1} MiB", b as f64 / (1 << 20) as f64))
                .unwrap_or_else(|| "n/a".into())
        };
        let strained = self
            .samples
            .iter()
            .max_by(|a, b| a.max_strain.total_cmp(&b.max_strain))
            .unwrap_or(first);
        let max_rss = self.samples.iter().filter_map(|s| s.rss_bytes).max();
        let worst = self.samples.iter().map(|s| s.self_intersections).max();
        let worst = worst.unwrap_or(0);
        let crossed = self
            .samples
            .iter()
            .filter(|s| s.self_intersections > 0)
            .count();
        let deepest = self
            .samples
            .iter()
            .max_by(|a, b| a.body_depth.total_cmp(&b.body_depth))
            .unwrap_or(first);
        format!(
            "monitor      {} samples in {}: energy {lo:.4} to {hi:.4} J, springs strained up to {:.2} % (step {}), {}\n\
             self         {crossed} samples with intersecting cloth triangle pairs, at most {worst}\n\
             body         deepest inside the body as a step ends {:.2} mm (step {})\n\
             memory       resident {} at step {} → {} at step {} (max {}); GPU allocated {} → {}",
            self.samples.len(),
            self.path.display(),
            100.0 * strained.max_strain,
            strained.step,
            if self.samples.iter().all(|s| s.finite) {
                "all finite"
            } else {
                "NOT all finite"
            },
            1e3 * deepest.body_depth,
            deepest.step,
            mib(first.rss_bytes),
            first.step,
            mib(last.rss_bytes),
            last.step,
            mib(max_rss),
            mib(first.gpu_allocated_bytes),
            mib(last.gpu_allocated_bytes),
        )
    }
}

/// How deep the deepest cloth vertex `x` is inside the scene's body, placed
/// where it is after `step` steps, m.
fn body_depth(scene: &Scene, step: u64, x: &[Vec3]) -> f32 {
    let Some(body) = &scene.rigid else {
        return 0.0;
    };
    let mut frame = cpu::rigid::RigidFrame::default();
    let t = (step as f64 * scene.config.solver.dt as f64) as f32;
    cpu::rigid::transform(body, t, &mut frame);
    x.iter()
        .map(|&p| cpu::measure::penetration_depth(body, &frame, p))
        .fold(0.0, f32::max)
}

/// This process's resident set size (`VmRSS` of /proc/self/status);
/// `None` where there is no procfs.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
