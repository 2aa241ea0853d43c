//! The weights file: round trip, folded scaling, and every malformed file
//! rejected with one clear error.

mod common;

use std::path::Path;

use common::Rng;
use wgcloth::nn::Layer;
use wgcloth::nn::weights::{FRICTION_INPUTS, NetKind, WeightsFile};

fn random_file(sizes: &[usize], seed: u64) -> WeightsFile {
    let mut rng = Rng(seed);
    let layers = sizes
        .windows(2)
        .map(|w| Layer {
            inputs: w[0],
            outputs: w[1],
            weight: (0..w[0] * w[1]).map(|_| rng.range(-0.5, 0.5)).collect(),
            bias: (0..w[1]).map(|_| rng.range(-0.1, 0.1)).collect(),
        })
        .collect();
    WeightsFile {
        kind: NetKind::Friction,
        layers,
        negative_slope: 0.01,
        input_min: (0..10).map(|k| -(k as f32) - 1.0).collect(),
        input_max: (0..10).map(|k| 2.0 * k as f32 + 1.0).collect(),
        output_mean: vec![0.5, -1.0, 2.0],
        output_std: vec![3.0, 0.5, 7.0],
        notes: [("recipe".to_string(), "test".to_string())].into(),
    }
}

fn parse(bytes: &[u8]) -> Result<WeightsFile, String> {
    WeightsFile::parse(bytes, Path::new("net.safetensors")).map_err(|e| e.to_string())
}

#[test]
fn round_trip_keeps_everything() {
    let f = random_file(&[10, 16, 8, 3], 1);
    assert_eq!(parse(&f.to_bytes()).unwrap(), f);
}

#[test]
fn folded_network_equals_explicit_scaling() {
    let f = random_file(&[10, 16, 8, 3], 2);
    let raw = wgcloth::nn::Mlp {
        layers: f.layers.clone(),
        negative_slope: f.negative_slope,
    };
    let folded = f.folded();
    let mut rng = Rng(3);
    for _ in 0..20 {
        let x: Vec<f32> = (0..10)
            .map(|k| rng.range(f.input_min[k], f.input_max[k]))
            .collect();
        let u: Vec<f32> = (0..10)
            .map(|k| (x[k] - f.input_min[k]) / (f.input_max[k] - f.input_min[k]))
            .collect();
        let y = raw.forward(&u);
        let g: Vec<f32> = (0..3)
            .map(|o| y[o] * f.output_std[o] + f.output_mean[o])
            .collect();
        let got = folded.forward(&x);
        for o in 0..3 {
            assert!(
                (got[o] - g[o]).abs() <= 1e-4 * g[o].abs().max(1.0),
                "{got:?} vs {g:?}"
            );
        }
    }
}

/// Rebuilds the file with one tensor replaced (name, dtype, shape, bytes).
fn with_tensor(
    f: &WeightsFile,
    name: &str,
    dtype: safetensors::Dtype,
    shape: Vec<usize>,
    data: Vec<u8>,
) -> Vec<u8> {
    let bytes = f.to_bytes();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let mut owned: Vec<(String, safetensors::Dtype, Vec<usize>, Vec<u8>)> = st
        .tensors()
        .into_iter()
        .filter(|(n, _)| n != name)
        .map(|(n, v)| (n, v.dtype(), v.shape().to_vec(), v.data().to_vec()))
        .collect();
    owned.push((name.to_string(), dtype, shape, data));
    let views: Vec<(String, safetensors::tensor::TensorView)> = owned
        .iter()
        .map(|(n, d, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(*d, s.clone(), b).unwrap(),
            )
        })
        .collect();
    safetensors::serialize(views, header.metadata().clone()).unwrap()
}

fn with_meta(f: &WeightsFile, key: &str, value: &str) -> Vec<u8> {
    let mut g = f.clone();
    // Standard keys are written from the struct: rewrite the bytes instead.
    let bytes = g.to_bytes();
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let mut meta = header.metadata().clone().unwrap();
    meta.insert(key.into(), value.into());
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    g.notes.clear();
    safetensors::serialize(st.tensors(), Some(meta)).unwrap()
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

#[test]
fn malformed_files_are_rejected_naming_the_problem() {
    use safetensors::Dtype;
    let f = random_file(&[10, 16, 8, 3], 4);
    let good = f.to_bytes();
    let mut absurd = good.clone();
    absurd[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let mut nan = f.clone();
    nan.layers[1].weight[5] = f32::NAN;
    let mut unchained = f.clone();
    unchained.layers[1] = Layer {
        inputs: 7,
        outputs: 8,
        weight: vec![0.0; 56],
        bias: vec![0.0; 8],
    };
    let mut bad_range = f.clone();
    bad_range.input_max[3] = bad_range.input_min[3];
    // Finite, but 3e38 over an input range of 0.01 is not an f32.
    let mut overflow = f.clone();
    overflow.input_max[2] = overflow.input_min[2] + 0.01;
    overflow.layers[0].weight[2] = 3e38;
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "not a safetensors file"),
        (
            "truncated",
            good[..good.len() / 2].to_vec(),
            "not a safetensors file",
        ),
        ("absurd header length", absurd, "not a safetensors file"),
        (
            "wrong dtype",
            with_tensor(&f, "layer1.bias", Dtype::F64, vec![8], vec![0; 64]),
            "layer1.bias",
        ),
        (
            "wrong bias shape",
            with_tensor(
                &f,
                "layer0.bias",
                Dtype::F32,
                vec![15],
                f32_bytes(&[0.0; 15]),
            ),
            "layer0.bias",
        ),
        ("layers do not chain", unchained.to_bytes(), "layer1.weight"),
        ("non-finite value", nan.to_bytes(), "non-finite"),
        ("max ≤ min", bad_range.to_bytes(), "max ≤ min"),
        (
            "folds to non-finite",
            overflow.to_bytes(),
            "layer 0 overflows f32",
        ),
        ("wrong format", with_meta(&f, "format", "pytorch"), "format"),
        ("wrong model", with_meta(&f, "model", "cloth"), "model"),
        (
            "wrong input names",
            with_meta(&f, "inputs", &FRICTION_INPUTS[..9].join(",")),
            "inputs",
        ),
        (
            "bad slope",
            with_meta(&f, "negative_slope", "nan"),
            "negative_slope",
        ),
        (
            "gap in layers",
            with_tensor(&f, "layer7.bias", Dtype::F32, vec![1], f32_bytes(&[0.0])),
            "unexpected tensors",
        ),
    ];
    for (case, bytes, expect) in cases {
        let err = parse(&bytes).expect_err(case);
        assert!(
            err.contains(expect) && err.contains("net.safetensors"),
            "{case}: {err}"
        );
        assert_eq!(err.lines().count(), 1, "{case}: {err}");
    }
}

#[test]
fn writing_never_replaces_a_file_without_force() {
    let dir = std::env::temp_dir().join(format!("wgcloth-weights-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("net.safetensors");
    std::fs::write(&path, b"precious").unwrap();
    let f = random_file(&[10, 4, 3], 5);
    let err = f.write(&path, false).unwrap_err().to_string();
    assert!(err.contains("--force"), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), b"precious");
    f.write(&path, true).unwrap();
    assert_eq!(WeightsFile::read(&path).unwrap(), f);
    std::fs::remove_dir_all(&dir).unwrap();
}
