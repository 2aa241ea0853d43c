"""Sweeps on Ray: a local head and one worker started here, as a cluster
would be, and every task's rows checked against the same world run
directly in this process."""

import os
import pathlib
import secrets
import socket
import subprocess
import sys

import numpy as np
import pytest

import wgcloth
import wgcloth.sweep as sweep

from conftest import ROOT

RAY = str(pathlib.Path(sys.executable).with_name("ray"))


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    """A Ray head and one worker node on this machine, one CPU each, with
    token authentication (Ray's default) on a token of their own, which
    this process and its children hand the cluster through the environment
    (read when Ray is imported, so it is imported after)."""
    port = free_port()
    address = f"127.0.0.1:{port}"
    saved = {k: os.environ.get(k) for k in ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN")}
    os.environ.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    common = ["--num-cpus=1", "--disable-usage-stats"]

    def start(*args):
        done = subprocess.run([RAY, "start", *args, *common], capture_output=True, text=True)
        assert done.returncode == 0, f"ray start {' '.join(args)}: {done.stdout}{done.stderr}"

    try:
        start("--head", f"--port={port}", "--include-dashboard=false")
        start(f"--address={address}")
        import ray

        yield address
        ray.shutdown()
    finally:
        subprocess.run([RAY, "stop", "--force"], capture_output=True)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def small():
    return wgcloth.Scene(model="friction", cloth={"grid": [16, 16]})


def test_every_task_of_a_sweep_is_its_world_run_directly(cluster):
    import ray

    ray.init(address=cluster)
    assert sum(n["Alive"] for n in ray.nodes()) == 2
    points = sweep.grid({"contact.mu": [0.1, 0.6], "contact.kt": [50.0, 800.0]})
    rows = sweep.run(small(), points, steps=40, worlds_per_task=3, backend="cpu")
    assert [{k: r[k] for k in points[0]} for r in rows] == points
    for point, row in zip(points, rows):
        alone = wgcloth.Simulator(small().replace(point), backend="cpu")
        start = alone.positions[0]
        alone.step(40)
        world = alone.report()["worlds"][0]
        assert row["drag"] == float((alone.positions[0] - start)[:, 2].astype(np.float64).mean())
        for key in sweep.MEASURES[1:]:
            assert row[key] == world[key], key
    assert all(r["contacts_mean"] > 0 and r["finite"] for r in rows)
    assert len({r["drag"] for r in rows}) == len(rows), "each world moves its own way"
    ray.shutdown()


def test_the_example_sweeps_on_the_cluster_unchanged(cluster, tmp_path):
    example = ROOT / "crates" / "wgcloth-py" / "examples" / "ray_sweep.py"
    out = tmp_path / "sweep"
    printed = subprocess.run(
        [sys.executable, example, "--out", out, "--grid", "12", "--steps", "20",
         "--mu", "0.2", "0.5", "--kt", "100", "--worlds-per-task", "1", "--backend", "cpu"],
        env={**os.environ, "RAY_ADDRESS": cluster}, check=True, capture_output=True, text=True,
    ).stdout
    assert "2 worlds in 2 Ray node(s)" in printed
    rows = sweep.read_csv([out / "sweep.csv"])
    assert [(r["contact.mu"], r["contact.kt"]) for r in rows] == [(0.2, 100.0), (0.5, 100.0)]
    assert (out / "drag.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_scene_travels_to_another_process_as_its_configuration():
    import pickle

    scene = small().replace({"contact.mu": 0.45, "solver.gravity": [0, -3, 0]})
    back = pickle.loads(pickle.dumps(scene))
    assert back.config == scene.config and back.config != small().config
