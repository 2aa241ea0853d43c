//! The collision network as the simulator evaluates it: dense layers with
//! LeakyReLU between them, in plain physical units (the file's min-max
//! input and standard output scaling are folded into the first and last
//! layers by `weights::load`), and its input Jacobian by reverse mode.

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

    /// Multiply-adds of `forward_jacobian` with a Jacobian: the forward
    /// pass and one reverse pass per output.
    pub fn jacobian_multiply_adds(&self) -> usize {
        self.multiply_adds() * (1 + self.outputs())
    }

    fn is_hidden(&self, k: usize) -> bool {
        k + 1 < self.layers.len()
    }

    /// The network's output at `x`.
    pub fn forward(&self, x: &[f32]) -> Vec<f32> {
        self.forward_jacobian(x, 0..0).0
    }

    /// The output and its Jacobian with respect to the inputs `wrt`,
    /// row-major [outputs × wrt.len()]. Reverse mode: one forward pass
    /// keeps each hidden unit's slope σ'(z), then the rows of ∂y/∂a are
    /// carried back through the layers, Δ ← (Δ diag(σ'(z))) W. That costs
    /// one forward pass plus one per output (4 for the friction network)
    /// where forward mode costs one plus one per input (7).
    pub fn forward_jacobian(&self, x: &[f32], wrt: Range<usize>) -> (Vec<f32>, Vec<f32>) {
        // σ'(z) of every unit, layer after layer (1 on the linear output).
        let mut slopes = Vec::with_capacity(self.layers.iter().map(|l| l.outputs).sum());
        let (mut a, mut z) = (x.to_vec(), Vec::new());
        for (k, layer) in self.layers.iter().enumerate() {
            z.clear();
            z.extend(
                layer
                    .weight
                    .chunks_exact(layer.inputs)
                    .zip(&layer.bias)
                    .map(|(w, b)| b + dot(w, &a)),
            );
            let hidden = self.is_hidden(k);
            for zo in &mut z {
                let slope = if hidden && *zo < 0.0 {
                    self.negative_slope
                } else {
                    1.0
                };
                *zo *= slope;
                slopes.push(slope);
            }
            std::mem::swap(&mut a, &mut z);
        }
        if wrt.is_empty() {
            return (a, Vec::new());
        }
        // Δ = ∂y/∂a_k, one row per output, starting from the identity.
        let outputs = a.len();
        let (mut delta, mut next) = (vec![0.0f32; outputs * outputs], Vec::new());
        for o in 0..outputs {
            delta[o * outputs + o] = 1.0;
        }
        let mut end = slopes.len();
        for layer in self.layers.iter().rev() {
            let slope = &slopes[end - layer.outputs..end];
            end -= layer.outputs;
            next.clear();
            next.resize(outputs * layer.inputs, 0.0);
            // Row by row of W, so each weight row is read once for all
            // outputs; the updates are vectorised axpys.
            for (o, w) in layer.weight.chunks_exact(layer.inputs).enumerate() {
                for r in 0..outputs {
                    let d = delta[r * layer.outputs + o] * slope[o];
                    let row = &mut next[r * layer.inputs..(r + 1) * layer.inputs];
                    for (n, wi) in row.iter_mut().zip(w) {
                        *n += d * wi;
                    }
                }
            }
            std::mem::swap(&mut delta, &mut next);
        }
        let width = x.len();
        let jacobian = (0..outputs)
            .flat_map(|r| {
                delta[r * width + wrt.start..r * width + wrt.end]
                    .iter()
                    .copied()
            })
            .collect();
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
