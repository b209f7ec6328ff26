"""Direct-sum N-body workload (WORKLOADS.md §3): N equal masses 1/N in the unit ball at rest
(numpy default_rng(42)), G = 1, Plummer ε = 0.01, leapfrog (KDK velocity Verlet) at dt = 1e-3,
float64 (``--precision f64,f32`` adds the single-precision state, whose pair sums run in float32).
5 warm-up steps, 3 blocks of S = 400 (N=1024) / 40 (N=4096); pair interactions credited N² per
step. Precisions alternate within each size and thread count, so they are compared side by side."""
from __future__ import annotations

import argparse

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc



def initial(n: int) -> np.ndarray:
    rng = np.random.default_rng(42)
    r = rng.random(n) ** (1 / 3)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * r[:, None]


def build(n: int, threads: int, precision: str = "f64") -> pc.Scene:
    scene = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads, precision=precision)
    scene.add_particles(initial(n), masses=1.0 / n)
    scene.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    return scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="1024,4096")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--precision", default="f64", help="comma-separated: f64, f32")
    args = ap.parse_args()
    require_release()
    rows = []
    for n in map(int, args.sizes.split(",")):
        steps = 400 if n <= 1024 else 40
        for th in map(int, args.threads.split(",")):
            for prec in args.precision.split(","):
                scene = build(n, th, prec)
                scene.step(5)
                t = median_block_time(scene, steps)
                rows.append([n, th, prec, f"{t / steps * 1e3:.3f}", f"{steps / t:.1f}", si(n * n * steps / t)])
    print(header(args.threads))
    print(table(["N", "threads", "precision", "ms/step", "steps/s", "pair interactions/s"], rows))


if __name__ == "__main__":
    main()
