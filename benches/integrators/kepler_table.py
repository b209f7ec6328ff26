"""Kepler work-precision (WORKLOADS.md §4): GM = 1, a = 1, e = 0.5, 2D test particle around a
pinned unit mass, start at pericentre; 100 orbits. For each integrator and dt = P/n: maximum
over all steps of |E/E0 - 1|, |r(t_end) - r0|, and the wall time of the integration without
diagnostics (median of 3)."""
from __future__ import annotations

import argparse
import statistics
import time

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc



def run(integrator: str, n: int, orbits: int):
    scene = pc.scenes.kepler(e=0.5, mass_ratio=0.0, steps_per_orbit=n, integrator=integrator)
    e0 = scene.energy().total
    r0 = scene.positions[1].copy()
    worst = 0.0
    total = n * orbits
    for _ in range(total):
        scene.step(1)
        worst = max(worst, abs(scene.energy().total / e0 - 1.0))
    err = float(np.linalg.norm(scene.positions[1] - r0))
    times = []
    for _ in range(3):
        s = pc.scenes.kepler(e=0.5, mass_ratio=0.0, steps_per_orbit=n, integrator=integrator)
        t0 = time.perf_counter()
        s.step(total)
        times.append(time.perf_counter() - t0)
    return worst, err, statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps-per-orbit", default="200,1000,5000")
    ap.add_argument("--orbits", type=int, default=100)
    args = ap.parse_args()
    require_release()
    rows = []
    for name in ("euler", "semi_implicit_euler", "verlet", "rk4"):
        for n in map(int, args.steps_per_orbit.split(",")):
            worst, err, wall = run(name, n, args.orbits)
            rows.append([name, f"P/{n}", f"{worst:.2e}", f"{err:.2e}", f"{wall * 1e3:.1f}"])
    print(header())
    print(table(["integrator", "dt", "max abs(E/E0-1)", "abs(r(t_end)-r0)", "wall ms"], rows))


if __name__ == "__main__":
    main()
