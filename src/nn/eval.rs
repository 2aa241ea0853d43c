//! Accuracy of a network (`wgcloth eval-net`): the thesis's measure,
//! standardised MSE (prediction and target divided by the file's output
//! std), on held-out data and on fresh uniform samples of the declared
//! domain, and the error of its position Jacobian against the analytic one.

use std::ops::Range;

use glam::{Mat3, Vec3};

use crate::cpu::contact::{Coefficients, friction};
use crate::nn::dataset::Dataset;
use crate::nn::domain::{Rng, uniform_sample};
use crate::nn::mlp::Mlp;
use crate::nn::weights::{NetKind, WeightsFile};

#[derive(Clone, Debug)]
pub struct Evaluation {
    pub held_out_mse: Option<f64>,
    pub uniform_mse: f64,
    pub uniform_samples: usize,
    /// Median over in-contact uniform samples of |(J_net − J) n| / |J n|,
    /// with J = ∂g/∂c for the friction network (the position Jacobian
    /// (J n) nᵀ that enters K_c) and ∂f/∂p in the local frame (n = +z) for
    /// the naive one.
    pub jacobian_median_relative_error: f64,
}

pub fn standardised_mse(net: &Mlp, std: &[f32], data: &Dataset) -> f64 {
    let (predicted, _) = net.forward_jacobian_parallel(&data.inputs, 0..0);
    let sum: f64 = predicted
        .chunks_exact(3)
        .zip(&data.targets)
        .map(|(p, y)| {
            (0..3)
                .map(|o| (((p[o] - y[o]) / std[o]) as f64).powi(2))
                .sum::<f64>()
        })
        .sum();
    sum / (3 * data.len()) as f64
}

/// The inputs along which `eval-net` checks the Jacobian: c for the
/// friction network, p for the naive one.
fn jacobian_inputs(kind: NetKind) -> Range<usize> {
    match kind {
        NetKind::Friction => 0..3,
        NetKind::Naive => 4..7,
    }
}

/// (network, analytic) position Jacobian along the contact normal at
/// inputs x, the network's Jacobian j along `jacobian_inputs` (row-major
/// [3 outputs × 3]); None out of contact.
fn normal_jacobians(kind: NetKind, x: &[f32], j: &[f32]) -> Option<(Vec3, Vec3)> {
    let network = Mat3::from_cols(
        Vec3::new(j[0], j[3], j[6]),
        Vec3::new(j[1], j[4], j[7]),
        Vec3::new(j[2], j[5], j[8]),
    );
    match kind {
        NetKind::Friction => {
            let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
            let k = Coefficients {
                kn: x[6],
                kd: x[7],
                kt: x[8],
                mu: x[9],
            };
            let exact = friction(c, v, &k);
            let n = -c.normalize_or_zero();
            (exact.force != Vec3::ZERO).then(|| (network * n, exact.d_c * n))
        }
        // f = −pz e_z: ∂f/∂p e_z = −e_z.
        NetKind::Naive => Some((network * Vec3::Z, -Vec3::Z)),
    }
}

pub fn evaluate(
    file: &WeightsFile,
    held_out: Option<&Dataset>,
    samples: usize,
    seed: u64,
) -> Evaluation {
    let net = file.folded();
    let mut rng = Rng::new(seed);
    let mut uniform = Dataset::new(file.kind);
    for _ in 0..samples {
        uniform.push(uniform_sample(file.kind, &mut rng));
    }
    let (_, jacobians) = net.forward_jacobian_parallel(&uniform.inputs, jacobian_inputs(file.kind));
    let mut errors: Vec<f64> = (0..uniform.len())
        .filter_map(|i| normal_jacobians(file.kind, uniform.input(i), &jacobians[9 * i..]))
        .map(|(got, want)| ((got - want).length() / want.length().max(1e-12)) as f64)
        .collect();
    errors.sort_by(f64::total_cmp);
    Evaluation {
        held_out_mse: held_out.map(|d| standardised_mse(&net, &file.output_std, d)),
        uniform_mse: standardised_mse(&net, &file.output_std, &uniform),
        uniform_samples: samples,
        jacobian_median_relative_error: errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN),
    }
}
