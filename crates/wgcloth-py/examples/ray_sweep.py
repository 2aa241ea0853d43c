"""A friction sweep on Ray: how far the sphere drags the cloth against μ and
k_t. Runs unchanged on a laptop (a local Ray is started) and on a cluster
(``RAY_ADDRESS=host:6379 python examples/ray_sweep.py``).

    python examples/ray_sweep.py --out sweep    # sweep/sweep.csv, sweep/drag.png
"""

import argparse
import pathlib

import ray

import wgcloth
import wgcloth.sweep as sweep

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("sweep"))
parser.add_argument("--grid", type=int, default=32, help="N×N cloth")
parser.add_argument("--steps", type=int, default=200, help="one sphere period")
parser.add_argument("--mu", type=float, nargs="+", default=[0.1, 0.3, 0.5, 0.7])
parser.add_argument("--kt", type=float, nargs="+", default=[50, 200, 800])
parser.add_argument("--worlds-per-task", type=int, default=16)
parser.add_argument("--backend", default="auto", choices=["auto", "gpu", "cpu"])
args = parser.parse_args()

ray.init()  # joins RAY_ADDRESS when it is set, else starts Ray here
scene = wgcloth.Scene(model="friction", cloth={"grid": [args.grid, args.grid]})
points = sweep.grid({"contact.mu": args.mu, "contact.kt": args.kt})
rows = sweep.run(scene, points, steps=args.steps, worlds_per_task=args.worlds_per_task,
                 backend=args.backend)
args.out.mkdir(parents=True, exist_ok=True)
sweep.write_csv(rows, args.out / "sweep.csv")
sweep.plot(rows, "contact.mu", "contact.kt", "drag", args.out / "drag.png")
print(f"{len(rows)} worlds in {len(ray.nodes())} Ray node(s): {args.out / 'sweep.csv'}, {args.out / 'drag.png'}")
