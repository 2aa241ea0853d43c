#!/usr/bin/env python3
"""Replays GPU PCG iteration budgets (`gpu::CgBudget`) against recorded
iterations per step (docs/iterations_per_step.txt, from
`cargo run --release --example iterations_per_step -- 32 64 128 256 512`).

A budget records B iterations for a step that needs A. The model of a
step's cost: F (the rest of the step) + A real iterations + (B - A) empty
ones when A <= B. When A > B the run loop solves the step again from its
start with the whole cap: the cut attempt (F + B real iterations), the
DEPTH steps in flight behind it, thrown away, and the repeat (F + A real
+ cap - A empty). The budget for step s sees the steps up to s - LAG: the
run loop sets it before it waits for step s - 3, the oldest in flight, so
at worst it has read up to s - 4. Every policy is replayed under the run
loop as it is now (a cut step solved again).

Costs in ms (real iteration, empty iteration, rest of the step):
  h200:     1024² on an H200 (BENCHMARKS.md "Hardware GPU": 0.89, 0.16, ~4)
  lavapipe: 64² on this workplace's lavapipe (about 2.5, 0.5, 8)
Each policy's cost is printed against the ideal (no empty iteration, no
cut): 1.00 is every step recording exactly what it needs.

usage: scripts/budget_replay.py [docs/iterations_per_step.txt]
"""
import sys

DEPTH, LAG, CAP = 3, 4, 200
COSTS = {"h200": (0.89, 0.16, 4.0), "lavapipe": (2.5, 0.5, 8.0)}


def budget(seen, window, factor, margin):
    recent = seen[-window:]
    if not recent:
        return CAP
    most = max(recent)
    return min(CAP, int(most * factor) + margin)


def replay(needs, policy, cost):
    real, empty, rest = cost
    total, cuts = 0.0, 0
    for s, need in enumerate(needs):
        b = budget(needs[: max(0, s - LAG + 1)], *policy)
        if need <= b:
            total += rest + need * real + (b - need) * empty
            continue
        cuts += 1
        total += rest + b * real
        for later in needs[s + 1 : s + 1 + DEPTH]:
            total += rest + min(later, b) * real + max(0, b - later) * empty
        total += rest + need * real + (CAP - need) * empty
    ideal = sum(rest + need * real for need in needs)
    return total / ideal, cuts


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else "docs/iterations_per_step.txt"
    runs = {}
    for line in open(path):
        grid, numbers = line.split(":")
        runs[int(grid)] = [int(n) for n in numbers.split()]
    shipped, before = (4, 1.5, 16), (32, 2.0, 0)
    policies = [before, shipped] + [
        (w, f, m)
        for w in (2, 3, 4, 6, 8, 16, 32)
        for f in (1.25, 1.5, 1.75, 2.0)
        for m in (0, 8, 16, 24)
    ]
    rows = []
    for policy in policies:
        ratios, cuts = [], 0
        for cost in COSTS.values():
            for needs in runs.values():
                ratio, c = replay(needs, policy, cost)
                ratios.append(ratio)
                cuts += c
        rows.append((sum(ratios) / len(ratios), max(ratios), cuts // len(COSTS), policy))
    print("window  × most  + margin   cost/ideal mean  worst   cuts (all grids)")
    def show(r, note=""):
        mean, worst, cuts, (w, f, m) = r
        print(f"{w:>6}  {f:>6}  {m:>8}   {mean:>15.3f}  {worst:>5.3f}  {cuts:>5}  {note}")
    show(rows[0], "before: twice the most of 32")
    show(rows[1], "shipped")
    print("the best by the worst grid:")
    for r in sorted(rows[2:], key=lambda r: (r[1], r[0]))[:5]:
        show(r)
    print("per grid, before → shipped (h200 costs):")
    for grid, needs in runs.items():
        a, ca = replay(needs, before, COSTS["h200"])
        b, cb = replay(needs, shipped, COSTS["h200"])
        print(f"  {grid}²: {a:.3f} ({ca} cuts) → {b:.3f} ({cb} cuts)")


main()
