//! Accuracy of a network (`wgcloth eval-net`): the thesis's measure,
//! standardised MSE (prediction and target divided by the file's output
//! std), on held-out data and on fresh uniform samples of the declared
//! domain, and the error of its position Jacobian against the analytic one.
//! Friction networks are scored on g in the world frame whatever frame
//! they compute in.

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::domain::{Rng, random_coefficients, resting_sample, uniform_sample};
use wgcloth::config::ContactConfig;
use wgcloth::cpu::contact::{Coefficients, friction, friction_net};
use wgcloth::nn::weights::{NetKind, Network, WeightsFile};

#[derive(Clone, Debug)]
pub struct Evaluation {
    pub held_out_mse: Option<f64>,
    pub uniform_mse: f64,
    pub uniform_samples: usize,
    /// Median over in-contact uniform samples of |(J_net − J) n| / |J n|,
    /// with J = ∂g/∂c for the friction networks (the position Jacobian
    /// (J n) nᵀ that enters K_c) and ∂f/∂p in the local frame (n = +z) for
    /// the naive one.
    pub jacobian_median_relative_error: f64,
    /// A friction network's force over the resting regime, against eqs.
    /// 8–9 (None for the naive network).
    pub resting: Option<Resting>,
    /// Uniform samples where eqs. 8–9 push and the network's g_n ≤ 0.
    pub not_pushing: usize,
    /// Uniform samples whose friction points along the slide (g·ṫ > 0).
    pub along_slide: usize,
}

/// The relative error |g_net − g| / |g| of a friction network's force,
/// as the step applies it (in the contact frame, inside the cone), over
/// samples of the resting regime where eqs. 8–9 push.
#[derive(Clone, Copy, Debug)]
pub struct Resting {
    pub samples: usize,
    /// At the default coefficients (`[contact]` of a default config).
    pub default_median: f64,
    pub default_p95: f64,
    /// With coefficients uniform over the declared domain.
    pub domain_median: f64,
    pub domain_p95: f64,
}

fn coefficients(x: &[f32]) -> Coefficients {
    Coefficients {
        kn: x[6],
        kd: x[7],
        kt: x[8],
        mu: x[9],
    }
}

fn matrix(j: &[f32]) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(j[0], j[3], j[6]),
        Vec3::new(j[1], j[4], j[7]),
        Vec3::new(j[2], j[5], j[8]),
    )
}

/// The network's output for each sample of `data` in the data's frame,
/// with its Jacobian along c (friction) or p (naive).
fn predict(net: &Network, data: &Dataset) -> Vec<(Vec3, Mat3)> {
    if net.kind == NetKind::Naive {
        let (y, j) = net
            .mlp
            .forward_jacobian_parallel(&data.inputs, net.kind.wrt());
        return (0..data.len())
            .map(|i| (Vec3::from_slice(&y[3 * i..]), matrix(&j[9 * i..])))
            .collect();
    }
    // Friction networks as the simulation runs them: in the contact frame.
    (0..data.len())
        .into_par_iter()
        .map(|i| {
            let x = data.input(i);
            let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
            let fj = friction_net(&net.mlp, net.kind, c, v, &coefficients(x));
            (fj.force, fj.d_c)
        })
        .collect()
}

/// The std each world output is divided by: the file's, or for the
/// contact-frame network, whose outputs are its form's logits, the world
/// components' shared √(E|g|²/3) over `data`.
fn world_std(file: &WeightsFile, data: &Dataset) -> [f32; 3] {
    match file.kind {
        NetKind::FrictionContact => {
            let power: f64 = data
                .targets
                .iter()
                .map(|g| Vec3::from_array(*g).length_squared() as f64)
                .sum();
            [((power / (3 * data.len().max(1)) as f64).sqrt().max(1e-6)) as f32; 3]
        }
        _ => [0, 1, 2].map(|o| file.output_std[o]),
    }
}

/// Median and 95th percentile of `errors`.
fn quantiles(mut errors: Vec<f64>) -> (f64, f64) {
    errors.sort_by(f64::total_cmp);
    let at = |q: f64| {
        errors
            .get(((errors.len() as f64 * q) as usize).min(errors.len().saturating_sub(1)))
            .copied()
            .unwrap_or(f64::NAN)
    };
    (at(0.5), at(0.95))
}

/// [`Resting`] from `samples` resting-regime samples of each kind.
fn resting(net: &Network, samples: usize, rng: &mut Rng) -> Resting {
    let default = ContactConfig::default().coefficients();
    let mut errors = |k: &mut dyn FnMut(&mut Rng) -> Coefficients| {
        let data: Vec<_> = (0..samples)
            .map(|_| {
                let k = k(rng);
                (resting_sample(rng, &k), k)
            })
            .collect();
        quantiles(
            data.par_iter()
                .filter_map(|((x, g), k)| {
                    let g = Vec3::from_array(*g);
                    let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
                    let got = friction_net(&net.mlp, net.kind, c, v, k).force;
                    (g != Vec3::ZERO).then(|| ((got - g).length() / g.length()) as f64)
                })
                .collect(),
        )
    };
    let (default_median, default_p95) = errors(&mut |_| default);
    let (domain_median, domain_p95) = errors(&mut random_coefficients);
    Resting {
        samples,
        default_median,
        default_p95,
        domain_median,
        domain_p95,
    }
}

fn standardised_mse(predicted: &[(Vec3, Mat3)], std: [f32; 3], data: &Dataset) -> f64 {
    let sum: f64 = predicted
        .iter()
        .zip(&data.targets)
        .map(|((p, _), y)| {
            (0..3)
                .map(|o| (((p[o] - y[o]) / std[o]) as f64).powi(2))
                .sum::<f64>()
        })
        .sum();
    sum / (3 * data.len()) as f64
}

/// (network, analytic) position Jacobian along the contact normal at
/// inputs x, from the network's Jacobian `network`; None out of contact.
fn normal_jacobians(kind: NetKind, x: &[f32], network: Mat3) -> Option<(Vec3, Vec3)> {
    match kind {
        NetKind::Naive => Some((network * Vec3::Z, -Vec3::Z)),
        // f = −pz e_z: ∂f/∂p e_z = −e_z.
        NetKind::Friction | NetKind::FrictionContact => {
            let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
            let exact = friction(c, v, &coefficients(x));
            let n = -c.normalize_or_zero();
            (exact.force != Vec3::ZERO).then(|| (network * n, exact.d_c * n))
        }
    }
}

pub fn evaluate(
    file: &WeightsFile,
    held_out: Option<&Dataset>,
    samples: usize,
    seed: u64,
) -> Evaluation {
    let net = file.network();
    let mut rng = Rng::new(seed);
    let mut uniform = Dataset::new(file.kind.data());
    for _ in 0..samples {
        uniform.push(uniform_sample(file.kind, &mut rng));
    }
    let predicted = predict(&net, &uniform);
    let mut errors: Vec<f64> = predicted
        .iter()
        .enumerate()
        .filter_map(|(i, (_, j))| normal_jacobians(file.kind, uniform.input(i), *j))
        .map(|(got, want)| ((got - want).length() / want.length().max(1e-12)) as f64)
        .collect();
    errors.sort_by(f64::total_cmp);
    let std = world_std(file, &uniform);
    let friction = file.kind != NetKind::Naive;
    // Of the uniform samples, those where eqs. 8–9 push but the network
    // does not, and those whose friction points along the slide.
    let (mut not_pushing, mut along_slide) = (0, 0);
    for (i, (got, _)) in predicted.iter().enumerate().filter(|_| friction) {
        let x = uniform.input(i);
        let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
        let n = -c.normalize_or_zero();
        let slide = v - v.dot(n) * n;
        let pushes = Vec3::from_array(uniform.targets[i]).dot(n) > 0.0;
        not_pushing += usize::from(pushes && got.dot(n) <= 0.0);
        along_slide += usize::from(got.dot(slide) > 0.0);
    }
    Evaluation {
        held_out_mse: held_out.map(|d| standardised_mse(&predict(&net, d), std, d)),
        uniform_mse: standardised_mse(&predicted, std, &uniform),
        uniform_samples: samples,
        jacobian_median_relative_error: errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN),
        resting: friction.then(|| resting(&net, samples, &mut rng)),
        not_pushing,
        along_slide,
    }
}
