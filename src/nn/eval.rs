//! Accuracy of a friction network (`wgcloth eval-net`): the thesis's
//! measure, standardised MSE (prediction and target divided by the file's
//! output std), on held-out data and on fresh uniform samples of the
//! declared domain, and the error of its position Jacobian against the
//! analytic one.

use glam::{Mat3, Vec3};

use crate::cpu::contact::{Coefficients, friction};
use crate::nn::dataset::{Dataset, Rng, uniform_sample};
use crate::nn::mlp::Mlp;
use crate::nn::weights::WeightsFile;

#[derive(Clone, Debug)]
pub struct Evaluation {
    pub held_out_mse: Option<f64>,
    pub uniform_mse: f64,
    pub uniform_samples: usize,
    /// Median over in-contact uniform samples of |(J_net − J) n| / |J n|,
    /// J = ∂g/∂c: the position Jacobian (J n) nᵀ that enters K_c.
    pub jacobian_median_relative_error: f64,
}

pub fn standardised_mse(net: &Mlp, std: &[f32], data: &Dataset) -> f64 {
    let sum: f64 = data
        .inputs
        .iter()
        .zip(&data.targets)
        .map(|(x, y)| {
            let p = net.forward(x);
            (0..3)
                .map(|o| (((p[o] - y[o]) / std[o]) as f64).powi(2))
                .sum::<f64>()
        })
        .sum();
    sum / (3 * data.len()) as f64
}

/// The network's ∂g/∂c at one input.
pub fn network_dc(net: &Mlp, x: &[f32; 10]) -> Mat3 {
    let (_, j) = net.forward_jacobian(x, 3);
    // j is row-major [3 outputs × 3 tangents]; Mat3 wants columns.
    Mat3::from_cols(
        Vec3::new(j[0], j[3], j[6]),
        Vec3::new(j[1], j[4], j[7]),
        Vec3::new(j[2], j[5], j[8]),
    )
}

pub fn evaluate(
    file: &WeightsFile,
    held_out: Option<&Dataset>,
    samples: usize,
    seed: u64,
) -> Evaluation {
    let net = file.folded();
    let mut rng = Rng::new(seed);
    let mut uniform = Dataset::default();
    let mut errors = Vec::new();
    for _ in 0..samples {
        let s = uniform_sample(&mut rng);
        let x = s.0;
        let (c, v) = (Vec3::new(x[0], x[1], x[2]), Vec3::new(x[3], x[4], x[5]));
        let k = Coefficients {
            kn: x[6],
            kd: x[7],
            kt: x[8],
            mu: x[9],
        };
        let exact = friction(c, v, &k);
        if exact.force != Vec3::ZERO {
            let n = -c.normalize();
            let want = exact.d_c * n;
            let got = network_dc(&net, &x) * n;
            errors.push(((got - want).length() / want.length().max(1e-12)) as f64);
        }
        uniform.push(s);
    }
    errors.sort_by(f64::total_cmp);
    Evaluation {
        held_out_mse: held_out.map(|d| standardised_mse(&net, &file.output_std, d)),
        uniform_mse: standardised_mse(&net, &file.output_std, &uniform),
        uniform_samples: samples,
        jacobian_median_relative_error: errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN),
    }
}
