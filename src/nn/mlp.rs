//! The collision network as the simulator evaluates it: dense layers with
//! LeakyReLU between them, in plain physical units (the file's min-max
//! input and standard output scaling are folded into the first and last
//! layers by `weights::load`), and its input Jacobian by forward mode.

use std::ops::Range;

/// One dense layer: y = W x + b, W row-major [outputs × inputs].
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    pub layers: Vec<Layer>,
    pub negative_slope: f32,
}

impl Mlp {
    pub fn inputs(&self) -> usize {
        self.layers[0].inputs
    }

    pub fn outputs(&self) -> usize {
        self.layers[self.layers.len() - 1].outputs
    }

    /// Multiply-adds of one forward evaluation.
    pub fn multiply_adds(&self) -> usize {
        self.layers.iter().map(|l| l.inputs * l.outputs).sum()
    }

    fn is_hidden(&self, k: usize) -> bool {
        k + 1 < self.layers.len()
    }

    /// The network's output at `x`.
    pub fn forward(&self, x: &[f32]) -> Vec<f32> {
        self.forward_jacobian(x, 0..0).0
    }

    /// The output and its Jacobian with respect to the inputs `wrt`,
    /// row-major [outputs × wrt.len()]. Forward mode: row 0 carries the
    /// activations and row 1 + j their derivatives along input
    /// wrt.start + j; each layer maps every row through W (the bias only
    /// on row 0) and scales the derivative rows by σ'(z) of row 0, the
    /// chain rule T ← diag(σ'(z)) W T. The rows stay contiguous so each
    /// output is one vectorised dot product.
    pub fn forward_jacobian(&self, x: &[f32], wrt: Range<usize>) -> (Vec<f32>, Vec<f32>) {
        let rows = 1 + wrt.len();
        let mut width = x.len();
        // Row 0: the inputs; row 1 + j: the unit seed of input wrt.start + j.
        let mut a = vec![0.0f32; rows * width];
        a[..width].copy_from_slice(x);
        for (j, i) in wrt.enumerate() {
            a[(1 + j) * width + i] = 1.0;
        }
        let mut z = Vec::new();
        for (k, layer) in self.layers.iter().enumerate() {
            z.clear();
            z.resize(rows * layer.outputs, 0.0);
            for (o, w) in layer.weight.chunks_exact(layer.inputs).enumerate() {
                z[o] = layer.bias[o] + dot(w, &a[..width]);
                for r in 1..rows {
                    z[r * layer.outputs + o] = dot(w, &a[r * width..(r + 1) * width]);
                }
            }
            if self.is_hidden(k) {
                for o in 0..layer.outputs {
                    if z[o] < 0.0 {
                        for r in 0..rows {
                            z[r * layer.outputs + o] *= self.negative_slope;
                        }
                    }
                }
            }
            std::mem::swap(&mut a, &mut z);
            width = layer.outputs;
        }
        // Row-major [outputs × tangents] from the derivative rows.
        let tangents = rows - 1;
        let mut jacobian = vec![0.0f32; width * tangents];
        for j in 0..tangents {
            for o in 0..width {
                jacobian[o * tangents + j] = a[(1 + j) * width + o];
            }
        }
        a.truncate(width);
        (a, jacobian)
    }
}

/// a · b in eight independent partial sums, which the compiler keeps in
/// vector registers.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0f32; 8];
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    acc.iter().sum::<f32>() + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small random network (deterministic).
    pub fn random(sizes: &[usize], seed: u64) -> Mlp {
        let mut s = seed;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let layers = sizes
            .windows(2)
            .map(|w| Layer {
                inputs: w[0],
                outputs: w[1],
                weight: (0..w[0] * w[1])
                    .map(|_| next() / (w[0] as f32).sqrt())
                    .collect(),
                bias: (0..w[1]).map(|_| 0.1 * next()).collect(),
            })
            .collect();
        Mlp {
            layers,
            negative_slope: 0.01,
        }
    }

    #[test]
    fn jacobian_of_an_inner_input_range_matches_the_full_one() {
        let net = random(&[7, 16, 16, 3], 4);
        let x: Vec<f32> = (0..7).map(|i| 0.2 * (i as f32 * 2.3).cos()).collect();
        let (_, full) = net.forward_jacobian(&x, 0..7);
        let (_, tail) = net.forward_jacobian(&x, 4..7);
        for o in 0..3 {
            assert_eq!(&full[o * 7 + 4..o * 7 + 7], &tail[o * 3..o * 3 + 3]);
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let net = random(&[10, 32, 24, 16, 3], 9);
        let x: Vec<f32> = (0..10).map(|i| 0.3 * (i as f32 * 1.7).sin()).collect();
        let (y, jac) = net.forward_jacobian(&x, 0..6);
        assert_eq!(y, net.forward(&x));
        let h = 1e-3;
        for j in 0..6 {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let (yp, ym) = (net.forward(&xp), net.forward(&xm));
            for o in 0..3 {
                let fd = (yp[o] - ym[o]) / (2.0 * h);
                let got = jac[o * 6 + j];
                assert!(
                    (fd - got).abs() <= 1e-3 * got.abs().max(1.0),
                    "∂y{o}/∂x{j}: {got} vs {fd}"
                );
            }
        }
    }
}
