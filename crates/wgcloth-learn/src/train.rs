//! Training the networks with candle (thesis 2.4, 2.6–2.7): min-max
//! input scaling (the declared domain's bounds), standardised outputs, Adam
//! on minibatches with a cosine learning-rate decay, a held-out validation
//! split, early stopping that keeps the best weights, checkpoints, and the
//! loss curve.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use candle_nn::{Linear, Module, Optimizer, VarBuilder, VarMap};
use glam::Vec3;

use crate::dataset::Dataset;
use crate::domain::{Rng, bounds};
use wgcloth::cpu::contact::{Coefficients, ContactFrame, STICK_LOG_MAX, cone_load};
use wgcloth::error::{Error, Result};
use wgcloth::nn::mlp::Layer;
use wgcloth::nn::weights::{NetKind, WeightsFile};

/// The thesis's architecture (2.7): 10 → 256, 256, 128 ×5 → 3.
pub const THESIS_HIDDEN: [usize; 7] = [256, 256, 128, 128, 128, 128, 128];
/// The thesis's naive network (2.4): 7 → 16 ×5 → 3.
pub const THESIS_NAIVE_HIDDEN: [usize; 5] = [16; 5];

/// The thesis's architecture for a network kind.
pub fn thesis_hidden(kind: NetKind) -> Vec<usize> {
    match kind {
        NetKind::Friction | NetKind::FrictionContact => THESIS_HIDDEN.to_vec(),
        NetKind::Naive => THESIS_NAIVE_HIDDEN.to_vec(),
    }
}
pub const NEGATIVE_SLOPE: f32 = 0.01;

#[derive(Clone, Debug)]
pub struct TrainOptions {
    pub hidden: Vec<usize>,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    /// Epochs without a better validation loss before stopping.
    pub patience: usize,
    pub validation_fraction: f32,
    pub seed: u64,
    /// Where the best weights so far are written after each improvement.
    pub checkpoint: Option<PathBuf>,
    /// Start from these weights (same architecture; their scalers are kept).
    pub init: Option<WeightsFile>,
    /// Train the contact-frame friction network (`NetKind::FrictionContact`)
    /// on friction data.
    pub contact_frame: bool,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            hidden: THESIS_HIDDEN.to_vec(),
            epochs: 60,
            batch: 512,
            learning_rate: 1e-3,
            patience: 10,
            validation_fraction: 0.1,
            seed: 1,
            checkpoint: None,
            init: None,
            contact_frame: false,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Trained {
    pub weights: WeightsFile,
    /// Validation MSE of the untrained network.
    pub initial_validation: f64,
    /// (train, validation) standardised MSE per epoch.
    pub curve: Vec<(f64, f64)>,
    pub best_validation: f64,
    pub seconds: f64,
}

fn candle(e: candle_core::Error) -> Error {
    Error::Unsupported(format!("training failed: {e}"))
}

struct Net {
    layers: Vec<Linear>,
    /// The contact-frame network's structure (`ContactFrame`).
    frame: Option<FrameRows>,
}

/// How the contact-frame network's rows are formed from the scaled input
/// x at +slide: x ⊙ flip + shift is the row at −slide and x ⊙ still +
/// rest the row at slide 0. Its training rows carry two more columns after
/// the network's inputs, k_t s / L and μ, so the output's form
/// (`cpu::contact::cone`) can be written divided by the load L:
/// (g_n, g_t) / L = (softplus(y_n(0)), −min(k_t s e^w / L, μ softplus(y_n(0)))),
/// w the even part of the second output.
struct FrameRows {
    flip: Tensor,
    shift: Tensor,
    still: Tensor,
    rest: Tensor,
}

/// The columns of a contact-frame training row after the network's
/// inputs: k_t s / L and μ.
const FRAME_EXTRA: usize = 2;

fn softplus(y: &Tensor) -> candle_core::Result<Tensor> {
    y.relu()? + y.abs()?.neg()?.exp()?.affine(1.0, 1.0)?.log()?
}

impl Net {
    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let Some(f) = &self.frame else {
            return self.layers(x);
        };
        let width = x.dim(1)? - FRAME_EXTRA;
        let (inputs, rate, mu) = (
            x.narrow(1, 0, width)?,
            x.narrow(1, width, 1)?,
            x.narrow(1, width + 1, 1)?,
        );
        let y = self.layers(&inputs)?;
        let mirrored = self.layers(&inputs.broadcast_mul(&f.flip)?.broadcast_add(&f.shift)?)?;
        let at_rest = self.layers(&inputs.broadcast_mul(&f.still)?.broadcast_add(&f.rest)?)?;
        let share = softplus(&at_rest.narrow(1, 0, 1)?)?;
        let w =
            ((y.narrow(1, 1, 1)? + mirrored.narrow(1, 1, 1)?)? * 0.5)?.minimum(STICK_LOG_MAX)?;
        let friction = (rate * w.exp()?)?.minimum(&(mu * &share)?)?.neg()?;
        Tensor::cat(&[share, friction], 1)
    }

    fn layers(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut a = x.clone();
        for (k, l) in self.layers.iter().enumerate() {
            a = l.forward(&a)?;
            if k + 1 < self.layers.len() {
                a = candle_nn::ops::leaky_relu(&a, NEGATIVE_SLOPE as f64)?;
            }
        }
        Ok(a)
    }
}

fn rows(t: &Tensor, idx: &[u32]) -> candle_core::Result<Tensor> {
    t.index_select(&Tensor::new(idx, t.device())?, 0)
}

/// Standardised MSE of `net` on (x, y), in batches, per output: the
/// thesis's measure for the world-frame networks; for the contact-frame
/// network the error of (g_n, g_t) relative to the load L.
fn evaluate(net: &Net, x: &Tensor, y: &Tensor, batch: usize) -> candle_core::Result<f64> {
    let n = x.dim(0)?;
    let mut sum = 0.0;
    for start in (0..n).step_by(batch) {
        let len = batch.min(n - start);
        let d = (net.forward(&x.narrow(0, start, len)?)? - y.narrow(0, start, len)?)?;
        sum += d.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
    }
    Ok(sum / (n * y.dim(1)?) as f64)
}

fn snapshot(varmap: &VarMap, n_layers: usize) -> candle_core::Result<Vec<Layer>> {
    let vars = varmap.data().lock().expect("varmap lock");
    (0..n_layers)
        .map(|i| {
            let w = vars[&format!("layer{i}.weight")]
                .as_tensor()
                .to_vec2::<f32>()?;
            let b = vars[&format!("layer{i}.bias")]
                .as_tensor()
                .to_vec1::<f32>()?;
            Ok(Layer {
                inputs: w[0].len(),
                outputs: w.len(),
                weight: w.into_iter().flatten().collect(),
                bias: b,
            })
        })
        .collect()
}

/// Training rows for a network of `kind` from `data`: inputs and targets,
/// [n × outputs]. The contact-frame network learns (g_n, g_t) / L at
/// +slide of each friction sample, L = k_n r + k_d max(a, 0) the load of
/// its output's form (`cpu::contact::cone`), so a millinewton contact at
/// rest weighs as much as a deep one; its rows carry k_t s / L and μ after
/// the inputs (a sample at c = 0 has no frame).
fn rows_for(kind: NetKind, data: &Dataset) -> (Vec<f32>, Vec<f32>) {
    if kind != NetKind::FrictionContact {
        return (data.inputs.clone(), data.targets.concat());
    }
    let (mut inputs, mut targets) = (Vec::new(), Vec::new());
    for (i, g) in data.targets.iter().enumerate() {
        let x = data.input(i);
        let k = Coefficients {
            kn: x[6],
            kd: x[7],
            kt: x[8],
            mu: x[9],
        };
        if let Some(frame) =
            ContactFrame::new(Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]))
        {
            let row = &frame.inputs(kind, &k)[..7];
            let (depth, approach, slide) = (row[0], row[1], row[2]);
            let load = cone_load(depth, approach, &k);
            inputs.extend(row);
            inputs.extend([k.kt * slide / load, k.mu]);
            targets.extend(frame.targets(Vec3::from_array(*g)).map(|t| t / load));
        }
    }
    (inputs, targets)
}

/// The output scaler (mean, std) from training targets [n × outputs]. The
/// contact-frame network's outputs are the logits of its output's form,
/// unscaled.
fn output_scaler(kind: NetKind, targets: &[f32], outputs: usize) -> (Vec<f32>, Vec<f32>) {
    if kind == NetKind::FrictionContact {
        return (vec![0.0; outputs], vec![1.0; outputs]);
    }
    let n = (targets.len() / outputs) as f64;
    let mut mean = vec![0.0f64; outputs];
    let mut var = vec![0.0f64; outputs];
    for y in targets.chunks_exact(outputs) {
        for o in 0..outputs {
            mean[o] += y[o] as f64 / n;
        }
    }
    for y in targets.chunks_exact(outputs) {
        for o in 0..outputs {
            var[o] += (y[o] as f64 - mean[o]).powi(2) / n;
        }
    }
    // An output that never varies (the naive frame's fx, fy) is scaled by
    // the largest std instead of being blown up by its own.
    let widest = var.iter().fold(0.0f64, |a, v| a.max(v.sqrt())).max(1e-6);
    let std = var
        .iter()
        .map(|v| v.sqrt().max(1e-3 * widest) as f32)
        .collect();
    (mean.iter().map(|m| *m as f32).collect(), std)
}

/// The initial layers, uniform in ±1/√inputs (PyTorch's and candle's
/// default) but drawn from our seeded generator, so a run is repeatable.
fn seeded_layers(sizes: &[usize], seed: u64) -> Vec<Layer> {
    let mut rng = Rng::new(seed ^ 0x5eed_1a7e);
    sizes
        .windows(2)
        .map(|w| {
            let bound = 1.0 / (w[0] as f32).sqrt();
            let mut draw =
                |n: usize| -> Vec<f32> { (0..n).map(|_| rng.range((-bound, bound))).collect() };
            Layer {
                inputs: w[0],
                outputs: w[1],
                weight: draw(w[0] * w[1]),
                bias: draw(w[1]),
            }
        })
        .collect()
}

pub fn train(
    data: &Dataset,
    opts: &TrainOptions,
    mut progress: impl FnMut(usize, f64, f64),
) -> Result<Trained> {
    if data.len() < 20 {
        return Err(Error::config(
            "--data",
            format!("{} samples are too few to train on", data.len()),
        ));
    }
    for (flag, value) in [("--epochs", opts.epochs), ("--batch", opts.batch)] {
        if value == 0 {
            return Err(Error::config(flag, "must be at least 1"));
        }
    }
    if opts.hidden.contains(&0) {
        return Err(Error::config(
            "--hidden",
            format!("every width must be at least 1, got {:?}", opts.hidden),
        ));
    }
    if !(opts.learning_rate.is_finite() && opts.learning_rate > 0.0) {
        return Err(Error::config(
            "--lr",
            format!("must be a positive number, got {}", opts.learning_rate),
        ));
    }
    let kind = match (opts.contact_frame, data.kind) {
        (false, kind) => kind,
        (true, NetKind::Friction) => NetKind::FrictionContact,
        (true, kind) => {
            return Err(Error::config(
                "--contact-frame",
                format!("is for friction data; the data is {}", kind.name()),
            ));
        }
    };
    let start = Instant::now();
    let dev = Device::Cpu;
    let (lo, hi) = bounds(kind);
    let (width, outputs) = (kind.inputs().len(), kind.outputs().len());
    let (inputs, targets) = rows_for(kind, data);
    let len = targets.len() / outputs;
    let n_val = ((len as f32 * opts.validation_fraction) as usize).max(1);
    let n_train = len - n_val;
    // Output scaler from the training part.
    let (mut mean, mut std) = output_scaler(kind, &targets[..n_train * outputs], outputs);
    if let Some(init) = &opts.init {
        // A warm start keeps the scaling its weights were trained with.
        (mean, std) = (init.output_mean.clone(), init.output_std.clone());
    }
    // The contact-frame rows' extra columns pass unscaled.
    let row = width
        + if kind == NetKind::FrictionContact {
            FRAME_EXTRA
        } else {
            0
        };
    let scaled_x: Vec<f32> = inputs
        .chunks_exact(row)
        .flat_map(|x| {
            (0..row).map(|k| match k < width {
                true => (x[k] - lo[k]) / (hi[k] - lo[k]),
                false => x[k],
            })
        })
        .collect();
    let scaled_y: Vec<f32> = targets
        .chunks_exact(outputs)
        .flat_map(|y| (0..outputs).map(|o| (y[o] - mean[o]) / std[o]))
        .collect();
    let x_all = Tensor::from_vec(scaled_x, (len, row), &dev).map_err(candle)?;
    let y_all = Tensor::from_vec(scaled_y, (len, outputs), &dev).map_err(candle)?;
    let (x_train, y_train) = (
        x_all.narrow(0, 0, n_train).map_err(candle)?,
        y_all.narrow(0, 0, n_train).map_err(candle)?,
    );
    let (x_val, y_val) = (
        x_all.narrow(0, n_train, n_val).map_err(candle)?,
        y_all.narrow(0, n_train, n_val).map_err(candle)?,
    );

    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &dev);
    let mut sizes = vec![width];
    sizes.extend(&opts.hidden);
    sizes.push(outputs);
    let frame = (kind == NetKind::FrictionContact)
        .then(|| {
            // slide is scaled over [−max, max]: −s is 1 − u, and 0 is ½.
            let (mut flip, mut shift) = ([1.0f32; 7], [0.0f32; 7]);
            (flip[2], shift[2]) = (-1.0, 1.0);
            let (mut still, mut rest) = ([1.0f32; 7], [0.0f32; 7]);
            (still[2], rest[2]) = (0.0, 0.5);
            Ok::<_, candle_core::Error>(FrameRows {
                flip: Tensor::new(&flip, &dev)?,
                shift: Tensor::new(&shift, &dev)?,
                still: Tensor::new(&still, &dev)?,
                rest: Tensor::new(&rest, &dev)?,
            })
        })
        .transpose()
        .map_err(candle)?;
    let net = Net {
        frame,
        layers: sizes
            .windows(2)
            .enumerate()
            .map(|(i, w)| candle_nn::linear(w[0], w[1], vb.pp(format!("layer{i}"))))
            .collect::<candle_core::Result<_>>()
            .map_err(candle)?,
    };
    let initial = match &opts.init {
        Some(init) => {
            if init.kind != kind {
                return Err(Error::config(
                    "--init",
                    format!(
                        "is a {} network; the data is for a {} one",
                        init.kind.name(),
                        kind.name()
                    ),
                ));
            }
            let widths: Vec<usize> = init.layers.iter().map(|l| l.outputs).collect();
            if init.layers.len() != net.layers.len()
                || widths[..widths.len() - 1] != opts.hidden[..]
            {
                return Err(Error::config(
                    "--init",
                    format!(
                        "its layers {widths:?} do not match --hidden {:?}",
                        opts.hidden
                    ),
                ));
            }
            init.layers.clone()
        }
        None => seeded_layers(&sizes, opts.seed),
    };
    let vars = varmap.data().lock().expect("varmap lock");
    for (i, l) in initial.iter().enumerate() {
        let w = Tensor::from_vec(l.weight.clone(), (l.outputs, l.inputs), &dev).map_err(candle)?;
        let b = Tensor::from_vec(l.bias.clone(), l.outputs, &dev).map_err(candle)?;
        vars[&format!("layer{i}.weight")].set(&w).map_err(candle)?;
        vars[&format!("layer{i}.bias")].set(&b).map_err(candle)?;
    }
    drop(vars);
    let mut opt = candle_nn::AdamW::new(
        varmap.all_vars(),
        candle_nn::ParamsAdamW {
            lr: opts.learning_rate,
            weight_decay: 0.0,
            ..Default::default()
        },
    )
    .map_err(candle)?;

    let initial_validation = evaluate(&net, &x_val, &y_val, 4096).map_err(candle)?;
    let mut rng = Rng::new(opts.seed);
    let mut order: Vec<u32> = (0..n_train as u32).collect();
    let mut curve = Vec::new();
    let mut best = (f64::INFINITY, Vec::new());
    let mut since_best = 0;
    let file = |layers: Vec<Layer>, notes: BTreeMap<String, String>| WeightsFile {
        kind,
        layers,
        negative_slope: NEGATIVE_SLOPE,
        input_min: lo.clone(),
        input_max: hi.clone(),
        output_mean: mean.clone(),
        output_std: std.clone(),
        notes,
    };
    // A warm start ramps the rate up over its first epoch, the usual guard
    // against Adam's fresh moment estimates taking full-size steps from
    // trained weights.
    let warmup = if opts.init.is_some() {
        order.len().div_ceil(opts.batch)
    } else {
        0
    };
    let mut step = 0;
    for epoch in 0..opts.epochs {
        // Cosine decay to 1/100 of the initial rate over the planned epochs.
        let phase = epoch as f64 / opts.epochs as f64;
        let rate =
            opts.learning_rate * (0.01 + 0.99 * 0.5 * (1.0 + (std::f64::consts::PI * phase).cos()));
        for k in (1..order.len()).rev() {
            order.swap(k, (rng.next_u64() % (k as u64 + 1)) as usize);
        }
        let mut train_sum = 0.0;
        for chunk in order.chunks(opts.batch) {
            step += 1;
            opt.set_learning_rate(rate * (step as f64 / warmup.max(1) as f64).min(1.0));
            let (xb, yb) = (
                rows(&x_train, chunk).map_err(candle)?,
                rows(&y_train, chunk).map_err(candle)?,
            );
            let loss =
                candle_nn::loss::mse(&net.forward(&xb).map_err(candle)?, &yb).map_err(candle)?;
            opt.backward_step(&loss).map_err(candle)?;
            train_sum += loss.to_scalar::<f32>().map_err(candle)? as f64 * chunk.len() as f64;
        }
        let train_mse = train_sum / n_train as f64;
        let val_mse = evaluate(&net, &x_val, &y_val, 4096).map_err(candle)?;
        curve.push((train_mse, val_mse));
        progress(epoch + 1, train_mse, val_mse);
        if val_mse < best.0 {
            best = (val_mse, snapshot(&varmap, sizes.len() - 1).map_err(candle)?);
            since_best = 0;
            if let Some(path) = &opts.checkpoint {
                file(best.1.clone(), BTreeMap::new()).write(path, true)?;
            }
        } else {
            since_best += 1;
            if since_best >= opts.patience {
                break;
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let notes = BTreeMap::from([
        (
            "recipe".to_string(),
            format!(
                "hidden={:?} epochs={} batch={} lr={} cosine-to-1% adamw patience={} validation={} seed={} samples={}",
                opts.hidden,
                curve.len(),
                opts.batch,
                opts.learning_rate,
                opts.patience,
                opts.validation_fraction,
                opts.seed,
                data.len()
            ),
        ),
        ("validation_mse".to_string(), format!("{:.4e}", best.0)),
        ("train_seconds".to_string(), format!("{seconds:.0}")),
    ]);
    Ok(Trained {
        weights: file(best.1, notes),
        initial_validation,
        curve,
        best_validation: best.0,
        seconds,
    })
}
