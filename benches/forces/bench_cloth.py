"""Cloth mass-spring workload (WORKLOADS.md §2): G×G grid, structural+shear+bend springs (k = 100
N/m), kd = 0.1·sqrt(k m), gravity, row y = 0 pinned, semi-implicit Euler at dt = 0.25·sqrt(m/k).
20 warm-up steps, then 3 blocks of S = 1000 (G=128) / 250 (G=256) steps; median.

physcore runs float64 (its only precision today); the peer figures in WORKLOADS.md are float32.
"""
from __future__ import annotations

import argparse
import math

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc
from physcore.scenes import cloth_springs



def build(g: int, threads: int) -> pc.Scene:
    n = g * g
    m = 1.0 / n
    k = 100.0
    s = 1.0 / (g - 1)
    gx, gy = np.meshgrid(np.arange(g) * s, np.arange(g) * s)
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(n)], axis=1)
    pinned = np.zeros(n, dtype=bool)
    pinned[:g] = True
    scene = pc.Scene(3, integrator="semi_implicit_euler", dt=0.25 * math.sqrt(m / k), threads=threads)
    scene.add_particles(x, masses=m, pinned=pinned)
    i, j = cloth_springs(g)
    scene.add(pc.Springs(i, j, stiffness=k, damping=0.1 * math.sqrt(k * m)))
    scene.add(pc.Gravity([0.0, 0.0, -9.81]))
    return scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="128,256")
    ap.add_argument("--threads", default="1,2")
    args = ap.parse_args()
    require_release()
    rows = []
    for g in map(int, args.sizes.split(",")):
        steps = 1000 if g <= 128 else 250
        for th in map(int, args.threads.split(",")):
            scene = build(g, th)
            n_springs = len(scene.spring_pairs()[0])
            scene.step(20)
            t = median_block_time(scene, steps)
            rows.append([f"{g}²", g * g, n_springs, th, f"{t / steps * 1e3:.3f}", si(g * g * steps / t), si(n_springs * steps / t)])
            assert np.isfinite(scene.positions).all()
    print(header(args.threads))
    print(table(["cloth", "N", "springs", "threads", "ms/step", "particle-steps/s", "spring-evals/s"], rows))


if __name__ == "__main__":
    main()
