"""Parameter sweeps: each task a batch of worlds, spread over a Ray cluster.

A sweep is a list of points, each a dict of dotted configuration keys
(``{"contact.mu": 0.3, "contact.kt": 200}``), set over a base scene.
``run_batch`` steps one batch of them in one ``Simulator`` and measures
each world; ``run`` cuts the points into batches and runs each as a Ray
task, on whatever cluster ``ray.init()`` joined (this machine by default,
the cluster at ``RAY_ADDRESS`` when it is set). The rows gather into one
table (``write_csv``) and a plot of a measure over two swept keys
(``plot``)::

    import ray, wgcloth, wgcloth.sweep as sweep
    ray.init()
    points = sweep.grid({"contact.mu": [0.1, 0.3, 0.5], "contact.kt": [50, 200, 800]})
    rows = sweep.run(wgcloth.Scene(), points, steps=200)
    sweep.write_csv(rows, "sweep.csv")
    sweep.plot(rows, "contact.mu", "contact.kt", "drag", "drag.png")

Ray and matplotlib come with ``pip install "./crates/wgcloth-py[ray]"``.
"""

from __future__ import annotations

import csv
import itertools
import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

import wgcloth

#: What each row holds besides the point's own keys, in this order.
MEASURES = (
    "drag",
    "max_penetration",
    "contacts_mean",
    "energy_final",
    "cg_iterations_mean",
    "steps",
    "finite",
)


def grid(axes: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the axes' values, the last key varying fastest."""
    keys = list(axes)
    return [dict(zip(keys, values)) for values in itertools.product(*(axes[k] for k in keys))]


def run_batch(
    scene: wgcloth.Scene,
    points: Sequence[Mapping[str, Any]],
    steps: int | None = None,
    backend: str = "auto",
) -> list[dict[str, Any]]:
    """Steps ``points`` set over ``scene`` as one batch of worlds for ``steps``
    steps (the scene's ``solver.steps`` by default) and returns a row a
    world: the point's values, then ``MEASURES``. ``drag`` is how far the
    cloth moved along the body's motion (z) on average, m; the rest come
    from the run's report."""
    sim = wgcloth.Simulator([scene.replace(dict(p)) for p in points], backend=backend)
    start = sim.positions
    sim.step(steps if steps is not None else scene.config["solver"]["steps"])
    moved = (sim.positions - start)[:, :, 2].astype(np.float64).mean(axis=1)
    rows = []
    for point, drag, world in zip(points, moved, sim.report()["worlds"]):
        row = dict(point)
        row["drag"] = float(drag)
        row.update({k: world[k] for k in MEASURES[1:]})
        rows.append(row)
    return rows


def run(
    scene: wgcloth.Scene,
    points: Sequence[Mapping[str, Any]],
    steps: int | None = None,
    worlds_per_task: int = 16,
    backend: str = "auto",
    num_cpus: float = 1,
) -> list[dict[str, Any]]:
    """``run_batch`` over ``points`` in batches of ``worlds_per_task``, each a
    Ray task of ``num_cpus`` CPUs on the cluster ``ray.init()`` joined
    (started here if it has not been); the rows come back in the points'
    order."""
    import ray

    if worlds_per_task < 1:
        raise ValueError(f"worlds_per_task: at least 1, not {worlds_per_task}")
    if not ray.is_initialized():
        ray.init()
    task = ray.remote(num_cpus=num_cpus)(run_batch)
    batches = [points[i : i + worlds_per_task] for i in range(0, len(points), worlds_per_task)]
    done = ray.get([task.remote(scene, batch, steps, backend) for batch in batches])
    return [row for rows in done for row in rows]


def write_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike[str]) -> None:
    """The rows as one CSV table, a column a key (the first row's order)."""
    rows = list(rows)
    if not rows:
        raise ValueError("no rows to write")
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def read_csv(paths: Iterable[str | os.PathLike[str]]) -> list[dict[str, Any]]:
    """The rows of CSV tables ``write_csv`` wrote (a Slurm array's, say), in
    the files' order, numbers read back as numbers."""

    def value(cell: str) -> Any:
        for kind in (int, float):
            try:
                return kind(cell)
            except ValueError:
                pass
        return {"True": True, "False": False}.get(cell, cell)

    rows = []
    for path in paths:
        with open(path, newline="") as f:
            rows.extend({k: value(v) for k, v in row.items()} for row in csv.DictReader(f))
    return rows


def plot(
    rows: Sequence[Mapping[str, Any]],
    x: str,
    series: str,
    measure: str,
    path: str | os.PathLike[str],
) -> None:
    """``measure`` against ``x``, a line for each value of ``series``, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for value in sorted({r[series] for r in rows}):
        line = sorted((r[x], r[measure]) for r in rows if r[series] == value)
        ax.plot(*zip(*line), marker="o", label=f"{series} = {value}")
    ax.set_xlabel(x)
    ax.set_ylabel(measure)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
