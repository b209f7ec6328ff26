"""10^6 free particles under uniform gravity alone (velocity Verlet, float64): the floor cost of a
step (memory traffic, the parallel loops, the per-step finiteness check). 3 blocks of 20 steps."""
from __future__ import annotations

import argparse

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--steps", type=int, default=20)
    args = ap.parse_args()
    require_release()
    rng = np.random.default_rng(0)
    x = rng.random((args.n, 3))
    v = rng.normal(size=(args.n, 3))
    rows = []
    for th in map(int, args.threads.split(",")):
        scene = pc.Scene(3, integrator="verlet", dt=1e-3, threads=th)
        scene.add_particles(x, v)
        scene.add(pc.Gravity([0.0, 0.0, -9.81]))
        scene.step(1)
        t = median_block_time(scene, args.steps)
        rows.append([args.n, th, f"{t / args.steps * 1e3:.2f}", si(args.n * args.steps / t)])
    print(header(args.threads))
    print(table(["N", "threads", "ms/step", "particle-steps/s"], rows))


if __name__ == "__main__":
    main()
