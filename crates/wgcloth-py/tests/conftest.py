"""Shared fixtures: the `wgcloth` command the package is checked against,
and whether the GPU tests may be skipped (WGCLOTH_NO_GPU_TESTS=1, as in
the Rust suite; otherwise a missing adapter fails them)."""

import os
import pathlib
import subprocess

import pytest

import wgcloth

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def cli():
    """Runs the `wgcloth` command built beside the package (WGCLOTH_BIN)."""
    binary = os.environ.get("WGCLOTH_BIN", str(ROOT / "target" / "release" / "wgcloth"))
    if not os.path.exists(binary):
        pytest.fail(f"no wgcloth command at {binary}: cargo build --release, or set WGCLOTH_BIN")

    def run(*args):
        return subprocess.run([binary, *map(str, args)], check=True, capture_output=True, text=True)

    return run


@pytest.fixture(scope="session")
def gpu():
    """The GPU backend's name once an adapter is known to open."""
    try:
        wgcloth.Simulator(wgcloth.Scene(cloth={"grid": [2, 2]}, scene="hang"), backend="gpu")
    except wgcloth.WgclothError as e:
        if os.environ.get("WGCLOTH_NO_GPU_TESTS") == "1":
            pytest.skip(f"no GPU adapter, and WGCLOTH_NO_GPU_TESTS=1: {e}")
        raise
    return "gpu"
