#!/usr/bin/env python3
"""BENCHMARKS.md's "Self-contact outcomes" table: the folding scenes with
self-contact on and off, 200 steps each, monitored every step, one
Markdown row per scene, path and grid.

    python3 scripts/self_contact_outcomes.py [--cpu 32,64,128] [--gpu 32,64] [--out DIR]

It runs `target/release/wgcloth` (build it first: `cargo build --release`),
keeps each run's CSV, JSON and log in DIR (a new temporary folder unless
given) and prints the rows. About 25 minutes on 2 cores with lavapipe.
"""

import argparse
import csv
import json
import pathlib
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
BINARY = ROOT / "target" / "release" / "wgcloth"
SCENES = ["thesis", "drape", "pleat"]
HEAD = (
    "| scene | path | grid | crossing pairs (most) | deepest in the body as a step ends, mm "
    "| most strain (self-contact off; bound) | largest energy gain in a step, J "
    "| failsafe share (last-resort steps) | PCG iterations mean | ms/step |\n"
    "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
)


def run(backend, grid, config, tag, out):
    """One run of 200 steps; its monitor rows and report."""
    cmd = [str(BINARY), "run", "--backend", backend, "--config", str(config),
           "--grid", str(grid), "--steps", "200", "--monitor", str(out / f"{tag}.csv"),
           "--monitor-every", "1", "--report", str(out / f"{tag}.json")]
    with open(out / f"{tag}.log", "w") as log:
        if subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT).returncode != 0:
            sys.exit(f"{' '.join(cmd)} failed: see {out / tag}.log")
    rows = list(csv.DictReader(open(out / f"{tag}.csv")))
    return rows, json.load(open(out / f"{tag}.json"))


def row(scene, path, grid, on, off):
    (rows, report), (off_rows, _) = on, off
    strain = 100 * max(float(r["max_strain"]) for r in rows)
    strain_off = 100 * max(float(r["max_strain"]) for r in off_rows)
    bound = max(1.25 * strain_off, 30.0)
    energy = [float(r["energy_j"]) for r in rows]
    gain = max(b - a for a, b in zip(energy, energy[1:]))
    gained = "—" if scene != "drape" else (f"{gain:.4f}" if gain > 0 else "none")
    sc = report.get("self_contact") or {}
    if path == "gpu":
        path = "lavapipe" if "llvmpipe" in report["adapter"] else report["adapter"]
    return (
        f"| {scene} | {path} | {grid}² | {max(int(r['self_intersections']) for r in rows)} "
        f"| {1e3 * max(float(r['body_depth']) for r in rows):.2f} "
        f"| {strain:.1f} % ({strain_off:.1f} %; {bound:.1f} %) | {gained} "
        f"| {100 * sc.get('failsafe_share', 0):.3f} % ({sc.get('last_resort_steps', 0)}) "
        f"| {report['cg_iterations_mean']:.1f} | {report['ms_per_step']:.1f} |"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    grids = lambda text: [int(g) for g in text.split(",") if g]
    parser.add_argument("--cpu", type=grids, default=[32, 64, 128])
    parser.add_argument("--gpu", type=grids, default=[32, 64])
    parser.add_argument("--out", type=pathlib.Path)
    args = parser.parse_args()
    if not BINARY.exists():
        sys.exit(f"{BINARY} is missing: run `cargo build --release` first")
    out = args.out or pathlib.Path(tempfile.mkdtemp(prefix="self_contact_outcomes."))
    out.mkdir(parents=True, exist_ok=True)
    for scene in SCENES:
        text = (ROOT / "scenes" / f"{scene}.toml").read_text()
        if "enabled = true" not in text:
            sys.exit(f"scenes/{scene}.toml does not turn self-contact on")
        (out / f"{scene}_off.toml").write_text(text.replace("enabled = true", "enabled = false"))
    print(HEAD)
    for backend, path, chosen in [("cpu", "CPU", args.cpu), ("gpu", "gpu", args.gpu)]:
        for grid in chosen:
            for scene in SCENES:
                on = run(backend, grid, ROOT / "scenes" / f"{scene}.toml", f"{backend}_{scene}_on_{grid}", out)
                off = run(backend, grid, out / f"{scene}_off.toml", f"{backend}_{scene}_off_{grid}", out)
                print(row(scene, path, grid, on, off), flush=True)
    print(f"runs: {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
