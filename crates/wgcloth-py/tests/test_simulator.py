"""Scenes and simulators through the Python API, checked against the
`wgcloth` command and against each world run alone."""

import json

import numpy as np
import pytest

import wgcloth

STEPS = 40  # the sphere reaches the 16² cloth between steps 20 and 40


def small(**overrides):
    return wgcloth.Scene(model="friction", cloth={"grid": [16, 16]}, **overrides)


def cloth_vertices(obj_path, count):
    """The cloth's vertices of a frame the command wrote (`o cloth` first)."""
    rows = [l.split()[1:] for l in obj_path.read_text().splitlines() if l.startswith("v ")]
    return np.array(rows[:count], dtype=np.float64).astype(np.float32)


def test_positions_are_the_frames_the_command_writes(cli, tmp_path):
    scene = small()
    sim = wgcloth.Simulator(scene, backend="cpu")
    start = sim.positions
    sim.step(STEPS)
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    out = tmp_path / "frames"
    cli("run", "--config", tmp_path / "scene.toml", "--backend", "cpu", "--steps", STEPS,
        "--out", out, "--every", STEPS, "--export", "obj")
    expected = cloth_vertices(out / "frame_0001.obj", scene.vertices)
    assert sim.positions.shape == (1, scene.vertices, 3)
    assert sim.positions.dtype == np.float32
    assert not np.array_equal(start[0], expected), "the cloth moved"
    np.testing.assert_array_equal(sim.positions[0], expected)
    assert sim.report()["worlds"][0]["contacts_mean"] > 0


def worlds():
    return [small(contact={"mu": 0.1}), small(contact={"mu": 0.6}, solver={"gravity": [0, -5, 0]})]


def check_each_world_alone(backend):
    batch = wgcloth.Simulator(worlds(), backend=backend)
    assert (batch.backend, batch.worlds) == (backend, 2)
    batch.step(STEPS)
    x, v = batch.positions, batch.velocities
    assert not np.array_equal(x[0], x[1]), "the worlds differ"
    for k, scene in enumerate(worlds()):
        alone = wgcloth.Simulator(scene, backend=backend)
        alone.step(STEPS)
        np.testing.assert_array_equal(x[k], alone.positions[0])
        np.testing.assert_array_equal(v[k], alone.velocities[0])
    report = batch.report()
    assert [w["steps"] for w in report["worlds"]] == [STEPS, STEPS]
    assert all(w["contacts_mean"] > 0 and w["finite"] for w in report["worlds"])


def test_each_world_of_a_cpu_batch_is_its_scene_alone():
    check_each_world_alone("cpu")


def test_each_world_of_a_gpu_batch_is_its_scene_alone(gpu):
    check_each_world_alone(gpu)


def test_run_returns_the_report_the_command_writes(cli, tmp_path):
    """The plumbing: both sides run `wgcloth_cli::run::run`, and a batch
    (`worlds`) returns `run --worlds`'s report."""
    scene = small()
    report = wgcloth.run(scene, steps=STEPS, backend="cpu")
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    cli("run", "--config", tmp_path / "scene.toml", "--backend", "cpu", "--steps", STEPS,
        "--report", tmp_path / "report.json")
    expected = json.loads((tmp_path / "report.json").read_text())
    for key in ("steps", "energy_final", "cg_iterations_mean", "contacts_mean", "max_penetration"):
        assert report[key] == expected[key], key
    assert report["contacts_mean"] > 0
    batch = wgcloth.run(scene, steps=2, worlds=1, backend="cpu")
    assert [w["steps"] for w in batch["worlds"]] == [2]


def test_scenes_from_a_file_a_dict_and_keywords_agree(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('model = "friction"\n[contact]\nmu = 0.4\n[cloth]\ngrid = [8, 8]\n')
    from_file = wgcloth.Scene(path)
    from_dict = wgcloth.Scene({"model": "friction", "contact.mu": 0.4, "cloth.grid": [8, 8]})
    from_keywords = wgcloth.Scene(model="friction", contact={"mu": 0.4}, cloth={"grid": [8, 8]})
    assert from_file.config == from_dict.config == from_keywords.config
    assert from_file.config["contact"]["mu"] == pytest.approx(0.4)
    assert from_file.config != wgcloth.Scene().config
    # a dotted key and its section's table merge
    both = wgcloth.Scene({"contact": {"kt": 7.0}, "contact.mu": 0.2})
    assert both.config["contact"]["kt"] == 7.0 and both.config["contact"]["mu"] == pytest.approx(0.2)
    assert from_file.triangles.shape == (2 * 7 * 7, 3) and from_file.vertices == 64
    assert from_file.triangles.max() == 63


@pytest.mark.parametrize(
    "make, error, names",
    [
        (lambda: wgcloth.Scene({"contact.muu": 1}), wgcloth.WgclothError, "muu"),
        (lambda: wgcloth.Scene(contact={"mu": -1}), wgcloth.WgclothError, "contact.mu"),
        (lambda: wgcloth.Scene(cloth={"grid": "big"}), wgcloth.WgclothError, "grid"),
        (lambda: wgcloth.Scene("no/such/scene.toml"), wgcloth.WgclothError, "no/such/scene.toml"),
        (lambda: wgcloth.Scene(3), TypeError, "TOML file"),
        (lambda: wgcloth.Simulator(small(), backend="tpu"), ValueError, "tpu"),
        (lambda: wgcloth.Simulator(small(), worlds=0), ValueError, "at least 1"),
        (lambda: wgcloth.Simulator([small(), small()], worlds=3), ValueError, "worlds is 3"),
        (lambda: wgcloth.Simulator([small(), wgcloth.Scene(cloth={"grid": [8, 8]})]), ValueError, "share a grid"),
        (lambda: wgcloth.Simulator("scene"), TypeError, "Scene"),
    ],
)
def test_bad_arguments_raise_one_error_naming_what_is_wrong(make, error, names):
    with pytest.raises(error, match=names.replace(".", r"\.")):
        make()


def test_a_gpu_batch_the_gpu_cannot_run_is_refused_and_auto_runs_it_on_the_cpu(gpu, capsys):
    self_contact = small(self_contact={"enabled": True})
    with pytest.raises(wgcloth.WgclothError, match="self_contact"):
        wgcloth.Simulator(self_contact, worlds=2, backend=gpu)
    sim = wgcloth.Simulator(self_contact, worlds=2, backend="auto")
    assert sim.backend == "cpu" and sim.notices
    assert sim.notices[-1] in capsys.readouterr().err
