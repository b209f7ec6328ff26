"""A cloud of points on the Lorenz attractor (physcore.Flow, RK4) beside a parallel numba RK4 of
the same flow, same run, same threads, float64: point-steps per second (median of 5 blocks,
alternating physcore and numba so that load on a shared machine hits both alike).

    python benches/grids/bench_flows.py [--n 100000] [--steps 100] [--threads 2]

Run it at each SIMD level: PHYSCORE_SIMD=avx2 python benches/grids/bench_flows.py
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common  # noqa: F401 - sets thread variables before numpy

import argparse
import statistics
import time

import numba
import numpy as np

import physcore as pc

numba.config.THREADING_LAYER = "workqueue"


@numba.njit(parallel=True, fastmath=False, cache=True)
def lorenz_rk4(x, y, z, h, steps, s=10.0, r=28.0, b=8.0 / 3.0):
    """Classic RK4 on the Lorenz flow, every point in parallel, `steps` steps of `h`."""
    for _ in range(steps):
        for i in numba.prange(x.size):
            X, Y, Z = x[i], y[i], z[i]
            k1x, k1y, k1z = s * (Y - X), X * (r - Z) - Y, X * Y - b * Z
            X2, Y2, Z2 = X + 0.5 * h * k1x, Y + 0.5 * h * k1y, Z + 0.5 * h * k1z
            k2x, k2y, k2z = s * (Y2 - X2), X2 * (r - Z2) - Y2, X2 * Y2 - b * Z2
            X3, Y3, Z3 = X + 0.5 * h * k2x, Y + 0.5 * h * k2y, Z + 0.5 * h * k2z
            k3x, k3y, k3z = s * (Y3 - X3), X3 * (r - Z3) - Y3, X3 * Y3 - b * Z3
            X4, Y4, Z4 = X + h * k3x, Y + h * k3y, Z + h * k3z
            k4x, k4y, k4z = s * (Y4 - X4), X4 * (r - Z4) - Y4, X4 * Y4 - b * Z4
            x[i] = X + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
            y[i] = Y + h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y)
            z[i] = Z + h / 6 * (k1z + 2 * k2z + 2 * k3z + k4z)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    _common.require_release()
    numba.set_num_threads(args.threads)
    scene = pc.Scene(dim=3, dt=0.005, threads=args.threads)
    cloud = scene.add(pc.Flow("lorenz", points=args.n, spread=0.5, seed=7))
    p = cloud.points
    x, y, z = (np.ascontiguousarray(p[:, k]) for k in range(3))
    scene.step(1)
    lorenz_rk4(x, y, z, 0.005, 1)  # compile
    ours, peer = [], []
    for _ in range(5):
        t = time.perf_counter()
        scene.step(args.steps)
        ours.append(time.perf_counter() - t)
        t = time.perf_counter()
        lorenz_rk4(x, y, z, 0.005, args.steps)
        peer.append(time.perf_counter() - t)
    a, b = statistics.median(ours), statistics.median(peer)
    print(_common.header(args.threads))
    print(f"Lorenz RK4, {args.n} points, {args.steps} steps per block, f64")
    print("| code | M point-steps/s | physcore / numba |")
    print("|---|---:|---:|")
    print(f"| physcore | {args.n * args.steps / a / 1e6:.1f} | {b / a:.2f} |")
    print(f"| numba | {args.n * args.steps / b / 1e6:.1f} | |")


if __name__ == "__main__":
    main()
