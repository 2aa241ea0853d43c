//! The collision network as the simulator evaluates it: dense layers with
//! LeakyReLU between them, in plain physical units (the file's min-max
//! input and standard output scaling are folded into the first and last
//! layers by `weights::load`), and its input Jacobian by reverse mode.

use std::ops::Range;

use rayon::prelude::*;

/// One dense layer: y = W x + b, W row-major [outputs × inputs].
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// Input width.
    pub inputs: usize,
    /// Output width.
    pub outputs: usize,
    /// W, row-major [outputs × inputs].
    pub weight: Vec<f32>,
    /// b, one value per output.
    pub bias: Vec<f32>,
}

/// A multilayer perceptron: LeakyReLU after every layer but the last, which
/// is linear.
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    /// The layers, input side first; each one's inputs are the previous
    /// one's outputs.
    pub layers: Vec<Layer>,
    /// LeakyReLU's slope for negative pre-activations (thesis: 0.01).
    pub negative_slope: f32,
}

impl Mlp {
    /// The network's input width.
    pub fn inputs(&self) -> usize {
        self.layers[0].inputs
    }

    /// The network's output width.
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

    /// The output at `x` and its Jacobian with respect to the inputs
    /// `wrt`, row-major [outputs × wrt.len()].
    pub fn forward_jacobian(&self, x: &[f32], wrt: Range<usize>) -> (Vec<f32>, Vec<f32>) {
        self.forward_jacobian_batch(x, wrt)
    }

    /// `forward_jacobian` for a batch of inputs, row-major [n × inputs]:
    /// the outputs [n × outputs] and the Jacobians [n × outputs × |wrt|].
    ///
    /// Reverse mode: one forward pass keeps each hidden unit's slope σ'(z),
    /// then the rows of ∂y/∂a are carried back through the layers,
    /// Δ ← (Δ diag(σ'(z))) W. That costs one forward pass plus one per
    /// output (2 for the contact-frame friction network) where forward mode
    /// costs one plus one per input of `wrt` (3). The batch runs in blocks of `LANES` inputs
    /// side by side, so each weight is read once per block and every
    /// multiply-add is vectorised across the block.
    pub fn forward_jacobian_batch(&self, xs: &[f32], wrt: Range<usize>) -> (Vec<f32>, Vec<f32>) {
        self.forward_jacobian_rows(xs, wrt, 0..self.outputs())
    }

    /// `forward_jacobian_batch` with only the Jacobian's rows `rows` (of
    /// the outputs), [n × |rows| × |wrt|]: each row is one reverse pass, so
    /// a caller that needs one output's gradient pays for one.
    pub fn forward_jacobian_rows(
        &self,
        xs: &[f32],
        wrt: Range<usize>,
        rows: Range<usize>,
    ) -> (Vec<f32>, Vec<f32>) {
        let (n_in, outs) = (self.inputs(), self.outputs());
        let per_jacobian = rows.len() * wrt.len();
        let n = xs.len() / n_in;
        let (mut values, mut jacobians) = (vec![0.0; n * outs], vec![0.0; n * per_jacobian]);
        let mut scratch = Scratch::new(self);
        let wanted = Wanted { wrt, rows };
        for (b, block) in xs.chunks(LANES * n_in).enumerate() {
            let lanes = block.len() / n_in;
            let y = &mut values[b * LANES * outs..(b * LANES + lanes) * outs];
            let j = &mut jacobians[b * LANES * per_jacobian..(b * LANES + lanes) * per_jacobian];
            let io = Block {
                xs: block,
                values: y,
                jacobians: j,
            };
            self.block(io, &wanted, &mut scratch);
        }
        (values, jacobians)
    }

    /// `forward_jacobian_batch` with the blocks spread over the rayon
    /// threads, for large batches.
    pub fn forward_jacobian_parallel(&self, xs: &[f32], wrt: Range<usize>) -> (Vec<f32>, Vec<f32>) {
        let (n_in, outs, t) = (self.inputs(), self.outputs(), wrt.len());
        let n = xs.len() / n_in;
        // One float per output when there is no Jacobian keeps the chunks
        // nonempty; it is dropped below.
        let per_jacobian = outs * t.max(1);
        let (mut values, mut jacobians) = (vec![0.0; n * outs], vec![0.0; n * per_jacobian]);
        let wanted = Wanted { wrt, rows: 0..outs };
        xs[..n * n_in]
            .par_chunks(LANES * n_in)
            .zip(values.par_chunks_mut(LANES * outs))
            .zip(jacobians.par_chunks_mut(LANES * per_jacobian))
            .for_each_init(
                || Scratch::new(self),
                |scratch, ((x, y), j)| {
                    let io = Block {
                        xs: x,
                        values: y,
                        jacobians: j,
                    };
                    self.block(io, &wanted, scratch)
                },
            );
        jacobians.truncate(n * outs * t);
        (values, jacobians)
    }

    /// One block of at most `LANES` inputs, with fused multiply-adds on
    /// 8-wide vectors where the CPU has them (AVX2 and FMA). The build's
    /// baseline (x86-64: SSE2) has neither, and the multiply-adds are nearly
    /// all of the block's work.
    fn block(&self, io: Block, wanted: &Wanted, scratch: &mut Scratch) {
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU has both features, checked just above.
            return unsafe { self.block_avx2_fma(io, wanted, scratch) };
        }
        self.block_with::<false>(io, wanted, scratch)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn block_avx2_fma(&self, io: Block, wanted: &Wanted, scratch: &mut Scratch) {
        self.block_with::<true>(io, wanted, scratch)
    }

    /// `block`, each multiply-add fused where `FUSED`; activations are
    /// stored lane-minor (unit k of every input side by side).
    #[inline(always)]
    fn block_with<const FUSED: bool>(&self, io: Block, wanted: &Wanted, scratch: &mut Scratch) {
        let n_in = self.inputs();
        let Block {
            xs,
            values,
            jacobians,
        } = io;
        let lanes = xs.len() / n_in;
        let Scratch {
            a,
            z,
            slopes,
            delta,
            next,
        } = scratch;
        a.clear();
        a.extend(
            (0..n_in)
                .map(|k| std::array::from_fn(|l| if l < lanes { xs[l * n_in + k] } else { 0.0 })),
        );
        // σ'(z) of every unit, layer after layer (1 on the linear output).
        slopes.clear();
        for (k, layer) in self.layers.iter().enumerate() {
            z.clear();
            let n = layer.inputs;
            let slope = match self.is_hidden(k) {
                true => self.negative_slope,
                false => 1.0,
            };
            let mut o = 0;
            while o < layer.outputs {
                let a = &a[..n];
                if layer.outputs - o >= TILE {
                    let rows: [&[f32]; TILE] =
                        std::array::from_fn(|t| &layer.weight[(o + t) * n..][..n]);
                    let bias = std::array::from_fn(|t| layer.bias[o + t]);
                    let terms = a.iter().enumerate();
                    let terms = terms.map(|(k, ak)| (std::array::from_fn(|t| rows[t][k]), ak));
                    for acc in dot_tile::<TILE, FUSED>(bias, terms) {
                        activate(acc, slope, z, slopes);
                    }
                    o += TILE;
                } else {
                    let row = &layer.weight[o * n..][..n];
                    let terms = row.iter().zip(a).map(|(w, ak)| ([*w], ak));
                    let [acc] = dot_tile::<1, FUSED>([layer.bias[o]], terms);
                    activate(acc, slope, z, slopes);
                    o += 1;
                }
            }
            std::mem::swap(a, z);
        }
        let outs = a.len();
        for l in 0..lanes {
            for o in 0..outs {
                values[l * outs + o] = a[o][l];
            }
        }
        let Wanted { wrt, rows } = wanted;
        if wrt.is_empty() {
            return;
        }
        // Δ[u · outs + r] = ∂y_{rows.start + r}/∂a_u, from here on with
        // outs = |rows|, starting from the identity's columns `rows`.
        let outs = rows.len();
        delta.clear();
        delta.extend((0..a.len() * outs).map(|e| {
            [if e / outs == rows.start + e % outs {
                1.0
            } else {
                0.0
            }; LANES]
        }));
        let mut end = slopes.len();
        for layer in self.layers.iter().rev() {
            let slope = &slopes[end - layer.outputs..end];
            end -= layer.outputs;
            for (o, s) in slope.iter().enumerate() {
                for d in &mut delta[o * outs..(o + 1) * outs] {
                    // A new array, not a lane loop in place: the loop
                    // compiled to scalar multiplies.
                    *d = std::array::from_fn(|l| d[l] * s[l]);
                }
            }
            next.clear();
            next.resize(layer.inputs * outs, [0.0; LANES]);
            let mut i = 0;
            while i < layer.inputs {
                let tile = if layer.inputs - i >= TILE { TILE } else { 1 };
                for r in 0..outs {
                    // Over the layer's outputs o: W's columns i.. on row o,
                    // and ∂y_r/∂z_o.
                    let terms = || {
                        let w_rows = layer.weight.chunks_exact(layer.inputs);
                        w_rows
                            .map(|w| &w[i..i + tile])
                            .zip(delta.chunks_exact(outs).map(|d| &d[r]))
                    };
                    if tile == TILE {
                        let terms = terms().map(|(w, d)| (w.try_into().unwrap(), d));
                        let acc = dot_tile::<TILE, FUSED>([0.0; TILE], terms);
                        for (t, acc) in acc.into_iter().enumerate() {
                            next[(i + t) * outs + r] = acc;
                        }
                    } else {
                        let terms = terms().map(|(w, d)| ([w[0]], d));
                        [next[i * outs + r]] = dot_tile::<1, FUSED>([0.0], terms);
                    }
                }
                i += tile;
            }
            std::mem::swap(delta, next);
        }
        let t = wrt.len();
        for l in 0..lanes {
            for r in 0..outs {
                for (j, i) in wrt.clone().enumerate() {
                    jacobians[(l * outs + r) * t + j] = delta[i * outs + r][l];
                }
            }
        }
    }
}

/// LeakyReLU of one unit's pre-activations `acc` (`negative_slope` 1 on
/// the linear output layer), appended to `z`, with σ' to `slopes`. Selects,
/// not branches: a lane's sign is a coin toss, and a branch per lane
/// mispredicted more time than the layer's multiply-adds took. Inlined, so
/// that it is compiled with the vector width of the block calling it (as
/// a closure it was not, and took a sixth of the network's time).
#[inline(always)]
fn activate(acc: Lanes, negative_slope: f32, z: &mut Vec<Lanes>, slopes: &mut Vec<Lanes>) {
    let slope = acc.map(|z| if z < 0.0 { negative_slope } else { 1.0 });
    z.push(std::array::from_fn(|l| acc[l] * slope[l]));
    slopes.push(slope);
}

/// Whether this CPU has AVX2 and FMA, which [`Mlp`] then uses (the x86-64
/// baseline the build targets has neither).
pub fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Outputs computed together: one output alone is a single chain of
/// dependent multiply-adds per lane, which waits on each one's latency;
/// `TILE` of them keep both FMA pipes busy.
const TILE: usize = 4;

/// For T outputs at once, over every lane: init[t] + Σ_k w_k[t] a_k over
/// the terms (w_k, a_k), the sum in their order whatever T.
#[inline(always)]
fn dot_tile<'a, const T: usize, const FUSED: bool>(
    init: [f32; T],
    terms: impl Iterator<Item = ([f32; T], &'a Lanes)>,
) -> [Lanes; T] {
    let mut acc = init.map(|b| [b; LANES]);
    for (wk, ak) in terms {
        for (t, acc) in acc.iter_mut().enumerate() {
            let wk = wk[t];
            for l in 0..LANES {
                acc[l] = multiply_add::<FUSED>(wk, ak[l], acc[l]);
            }
        }
    }
    acc
}

/// a b + c, rounded once where `FUSED` (only where the CPU has FMA: without
/// it `mul_add` is a slow library call).
#[inline(always)]
fn multiply_add<const FUSED: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FUSED { a.mul_add(b, c) } else { a * b + c }
}

/// A block's inputs, at most `LANES` rows, and where its outputs and
/// Jacobians go.
struct Block<'a> {
    xs: &'a [f32],
    values: &'a mut [f32],
    jacobians: &'a mut [f32],
}

/// What a block computes the Jacobian of: the outputs `rows` with respect
/// to the inputs `wrt`.
struct Wanted {
    wrt: Range<usize>,
    rows: Range<usize>,
}

/// A block's activations, slopes and reverse-mode rows, kept from one block
/// to the next so that a batch allocates them once.
struct Scratch {
    a: Vec<Lanes>,
    z: Vec<Lanes>,
    slopes: Vec<Lanes>,
    delta: Vec<Lanes>,
    next: Vec<Lanes>,
}

impl Scratch {
    /// Room for `net`'s widest layer and all its rows carried back, so a
    /// block never grows them: a contact block runs the network twice, and
    /// growing five vectors from empty each time cost it about a tenth of
    /// its time in the allocator.
    fn new(net: &Mlp) -> Scratch {
        let widest = net.layers.iter().map(|l| l.inputs.max(l.outputs));
        let widest = widest.max().unwrap_or(0);
        let units = net.layers.iter().map(|l| l.outputs).sum();
        let rows = || Vec::with_capacity(widest * net.outputs());
        Scratch {
            a: Vec::with_capacity(widest),
            z: Vec::with_capacity(widest),
            slopes: Vec::with_capacity(units),
            delta: rows(),
            next: rows(),
        }
    }
}

/// Inputs evaluated side by side in `Mlp::forward_jacobian_batch`.
pub const LANES: usize = 16;

/// One value per lane.
type Lanes = [f32; LANES];

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
    fn a_range_of_jacobian_rows_is_those_rows_of_the_full_one() {
        // 21 inputs: a full block and a partial one, 4 outputs.
        let net = random(&[6, 20, 9, 4], 5);
        let xs: Vec<f32> = (0..21 * 6).map(|i| (i as f32 * 0.53).cos()).collect();
        let (y, full) = net.forward_jacobian_batch(&xs, 1..5);
        for rows in [0..1, 1..3, 3..4] {
            let (yr, part) = net.forward_jacobian_rows(&xs, 1..5, rows.clone());
            assert_eq!(y, yr, "outputs, rows {rows:?}");
            for (i, (f, p)) in full.chunks(16).zip(part.chunks(rows.len() * 4)).enumerate() {
                assert_eq!(
                    &f[rows.start * 4..rows.end * 4],
                    p,
                    "input {i}, rows {rows:?}"
                );
            }
        }
    }

    #[test]
    fn a_batch_is_each_input_on_its_own() {
        // 37 inputs: two full blocks and a partial one.
        let net = random(&[10, 24, 17, 3], 3);
        let xs: Vec<f32> = (0..37 * 10).map(|i| (i as f32 * 0.37).sin()).collect();
        let (y, j) = net.forward_jacobian_batch(&xs, 0..6);
        for (i, x) in xs.chunks(10).enumerate() {
            let (yi, ji) = net.forward_jacobian(x, 0..6);
            assert_eq!(&y[3 * i..3 * i + 3], &yi[..], "output {i}");
            assert_eq!(&j[18 * i..18 * i + 18], &ji[..], "Jacobian {i}");
        }
    }

    #[test]
    fn fused_and_unfused_multiply_adds_agree_to_rounding() {
        // `block` picks the fused path where the CPU has FMA; the unfused
        // one runs elsewhere, so both are checked here against each other.
        let net = random(&[7, 48, 48, 2], 11);
        let xs: Vec<f32> = (0..LANES * 7).map(|i| (i as f32 * 0.61).sin()).collect();
        let run = |fused: bool| {
            let (mut y, mut j) = (vec![0.0; LANES * 2], vec![0.0; LANES * 2 * 3]);
            let (wanted, scratch) = (
                &Wanted {
                    wrt: 0..3,
                    rows: 0..2,
                },
                &mut Scratch::new(&net),
            );
            let io = Block {
                xs: &xs,
                values: &mut y,
                jacobians: &mut j,
            };
            if fused {
                net.block_with::<true>(io, wanted, scratch);
            } else {
                net.block_with::<false>(io, wanted, scratch);
            }
            (y, j)
        };
        let ((y1, j1), (y0, j0)) = (run(true), run(false));
        for (a, b) in y1.iter().chain(&j1).zip(y0.iter().chain(&j0)) {
            assert!((a - b).abs() <= 1e-5 * a.abs().max(1.0), "{a} against {b}");
        }
        assert_ne!((y1, j1), (y0, j0), "a fused multiply-add rounds once");
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
