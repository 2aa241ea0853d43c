"""Contact data and weights files through the Python API, checked against
the `wgcloth` command's own files and figures."""

import re

import numpy as np
import pytest
from safetensors.numpy import load_file

import wgcloth


def test_gen_data_is_the_file_the_command_writes(cli, tmp_path):
    """The plumbing: both sides call `wgcloth_learn::dataset::generate`."""
    data = wgcloth.gen_data("friction", recorded=300, uniform=200, resting=50, seed=3)
    cli("gen-data", "--out", tmp_path / "d.safetensors", "--recorded", 300, "--uniform", 200,
        "--resting", 50, "--seed", 3)
    expected = load_file(tmp_path / "d.safetensors")
    assert data["inputs"].shape == (550, 10) and data["inputs"].dtype == np.float32
    assert data["input_names"] == ["cx", "cy", "cz", "vx", "vy", "vz", "kn", "kd", "kt", "mu"]
    assert data["target_names"] == ["gx", "gy", "gz"]
    np.testing.assert_array_equal(data["inputs"], expected["inputs"])
    np.testing.assert_array_equal(data["targets"], expected["targets"])


def leaky(x, slope):
    return np.where(x > 0, x, slope * x)


def test_a_network_trained_in_numpy_scores_in_the_command_as_in_numpy(cli, tmp_path):
    """A naive network fitted here (random features, least squares), written
    with write_weights: `wgcloth eval-net` must score it on held-out data as
    numpy's own forward pass does, so the file's layout, scalings and
    activation mean what the simulator reads."""
    train = wgcloth.gen_data("naive", recorded=0, uniform=4000, seed=5)
    x, y = train["inputs"].astype(np.float64), train["targets"].astype(np.float64)
    lo, hi = x.min(0), x.max(0)
    hi = np.where(hi > lo, hi, lo + 1)  # cz is 0 in the local frame
    mean, std = y.mean(0), y.std(0)
    std = np.where(std > 0, std, 1)
    u, z = (x - lo) / (hi - lo), (y - mean) / std
    rng = np.random.default_rng(0)
    w0, b0 = rng.normal(size=(32, 7)), rng.normal(size=32)
    h = leaky(u @ w0.T + b0, wgcloth.NEGATIVE_SLOPE)
    fit, *_ = np.linalg.lstsq(np.hstack([h, np.ones((len(h), 1))]), z, rcond=None)
    w1, b1 = fit[:-1].T, fit[-1]
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)
    layers = [(f32(w0), f32(b0)), (f32(w1), f32(b1))]
    path = tmp_path / "naive.safetensors"
    # As numpy made them: float64, w1 a transposed (non-contiguous) view.
    wgcloth.write_weights(path, "naive", [(w0, b0), (w1, b1)], lo, hi, mean, std)

    back = wgcloth.read_weights(path)
    assert back["model"] == "naive" and len(back["layers"]) == 2
    np.testing.assert_array_equal(back["layers"][1][0], f32(w1))
    np.testing.assert_array_equal(back["input_max"], f32(hi))

    cli("gen-data", "--model", "naive", "--out", tmp_path / "held.safetensors",
        "--recorded", 0, "--uniform", 3000, "--seed", 9)
    held = load_file(tmp_path / "held.safetensors")
    hx, hy = held["inputs"].astype(np.float64), held["targets"].astype(np.float64)
    # numpy's forward pass in the file's own float32 values
    p = [(a.astype(np.float64), b.astype(np.float64)) for a, b in layers]
    hu = (hx - f32(lo)) / (f32(hi) - f32(lo))
    out = leaky(hu @ p[0][0].T + p[0][1], wgcloth.NEGATIVE_SLOPE) @ p[1][0].T + p[1][1]
    predicted = out * f32(std) + f32(mean)
    ours = np.mean(((predicted - hy) / f32(std)) ** 2)
    printed = cli("eval-net", path, "--data", tmp_path / "held.safetensors", "--samples", 1000).stdout
    theirs = float(re.search(r"held-out\s+standardised MSE (\S+)", printed).group(1))
    assert ours < 0.5, "the fit learned something"
    assert theirs == pytest.approx(ours, rel=2e-4)

    # the simulator takes it as a scene's network
    scene = wgcloth.Scene(model="naive-net", contact={"weights": str(path)})
    assert scene.config["contact"]["weights"] == str(path)


def test_weights_the_simulator_would_refuse_are_never_written(tmp_path):
    w, b = np.zeros((3, 7), np.float32), np.zeros(3, np.float32)
    ranges = (np.zeros(7, np.float32), np.ones(7, np.float32), np.zeros(3, np.float32), np.ones(3, np.float32))
    path = tmp_path / "w.safetensors"
    with pytest.raises(ValueError, match="bias of 2 values"):
        wgcloth.write_weights(path, "naive", [(w, b[:2])], *ranges)
    with pytest.raises(wgcloth.WgclothError, match="input"):
        wgcloth.write_weights(path, "naive", [(w, b)], ranges[0][:6], *ranges[1:])
    with pytest.raises(ValueError, match="model"):
        wgcloth.write_weights(path, "perceptron", [(w, b)], *ranges)
    assert not path.exists()
    wgcloth.write_weights(path, "naive", [(w, b)], *ranges)
    before = path.read_bytes()
    with pytest.raises(wgcloth.WgclothError, match="already exists"):
        wgcloth.write_weights(path, "naive", [(w, b + 1)], *ranges)
    assert path.read_bytes() == before
