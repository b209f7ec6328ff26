"""Grid systems side by side with parallel numba implementations of the same schemes, same run,
same threads: wave leapfrog (u⁺ written over u⁻, the two-array form physcore uses) and Gray–Scott
forward Euler, periodic. Cell-updates per second (median of 5 blocks) and the fraction of a
measured memory bandwidth (numpy copy of a large array: read + write) that the scheme's minimum
traffic reaches.

    python benches/grids/bench_grids.py [--n-wave 2048] [--n-gs 1024] [--steps 20]

Run it at each SIMD level: PHYSCORE_SIMD=avx2 python benches/grids/bench_grids.py
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
def wave_step(u, up, k):
    """Leapfrog, fixed edges (odd ghosts), u⁺ over u⁻ in place."""
    ny, nx = u.shape
    for j in numba.prange(ny):
        for i in range(nx):
            c = u[j, i]
            left = u[j, i - 1] if i > 0 else -c
            right = u[j, i + 1] if i < nx - 1 else -c
            south = u[j - 1, i] if j > 0 else -c
            north = u[j + 1, i] if j < ny - 1 else -c
            up[j, i] = 2.0 * c - up[j, i] + k * (left + right + south + north - 4.0 * c)


@numba.njit(parallel=True, fastmath=False, cache=True)
def gs_step(u, v, un, vn, du, dv, dt, f, fk):
    ny, nx = u.shape
    for j in numba.prange(ny):
        jm, jp = (j - 1) % ny, (j + 1) % ny
        for i in range(nx):
            im, ip = (i - 1) % nx, (i + 1) % nx
            lu = u[j, im] + u[j, ip] + u[jm, i] + u[jp, i] - 4.0 * u[j, i]
            lv = v[j, im] + v[j, ip] + v[jm, i] + v[jp, i] - 4.0 * v[j, i]
            uvv = u[j, i] * v[j, i] * v[j, i]
            un[j, i] = u[j, i] + du * lu + dt * (f * (1.0 - u[j, i]) - uvv)
            vn[j, i] = v[j, i] + dv * lv + dt * (uvv - fk * v[j, i])


def median_rate(run, cells: int, steps: int, blocks: int = 5) -> float:
    run(1)
    times = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        run(steps)
        times.append(time.perf_counter() - t0)
    return cells * steps / statistics.median(times)


def bandwidth() -> float:
    a = np.ones(1 << 25)
    b = np.empty_like(a)
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        np.copyto(b, a)
        ts.append(time.perf_counter() - t0)
    return 2 * a.nbytes / min(ts)  # bytes/s, read + write


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--n-wave", type=int, default=2048)
    p.add_argument("--n-gs", type=int, default=1024)
    p.add_argument("--steps", type=int, default=20)
    a = p.parse_args()
    _common.require_release()
    threads = numba.get_num_threads()
    print(_common.header(threads))
    bw = bandwidth()
    print(f"memory bandwidth (numpy copy, read + write): {bw / 1e9:.1f} GB/s")
    rows = []

    n = a.n_wave
    scene = pc.Scene(dim=2)
    w = scene.add(pc.Wave((n, n), 1.0 / n, c=1.0))
    x = (np.arange(n) + 0.5) / n
    w.u = np.exp(-((x[:, None] - 0.5) ** 2 + (x[None, :] - 0.5) ** 2) / 0.002)
    scene.dt = 0.9 * w.cfl_limit
    r_pc = median_rate(scene.step, n * n, a.steps)
    u, up = w.u.T.copy(), (w.u - scene.dt * w.velocity).T.copy()
    k = (scene.dt * n) ** 2

    def nb_wave(s):
        nonlocal u, up
        for _ in range(s):
            wave_step(u, up, k)
            u, up = up, u

    r_nb = median_rate(nb_wave, n * n, a.steps)
    rows.append((f"wave {n}²", r_pc, r_nb, 24))

    n = a.n_gs
    scene = pc.Scene(dim=2, dt=1.0)
    g = scene.add(pc.GrayScott((n, n), 2.5 / 256, preset="maze"))
    g.seed(1, squares=20)
    r_pc = median_rate(scene.step, n * n, a.steps)
    u, v = g.u.T.copy(), g.v.T.copy()
    un, vn = np.empty_like(u), np.empty_like(v)
    du, dv = g.du / g.spacing**2, g.dv / g.spacing**2

    def nb_gs(s):
        nonlocal u, v, un, vn
        for _ in range(s):
            gs_step(u, v, un, vn, du, dv, 1.0, g.feed, g.feed + g.kill)
            u, un = un, u
            v, vn = vn, v

    r_nb = median_rate(nb_gs, n * n, a.steps)
    rows.append((f"Gray–Scott {n}²", r_pc, r_nb, 32))

    print(f"{'workload':<18}{'physcore Mcell/s':>18}{'numba Mcell/s':>15}{'ratio':>8}{'bandwidth used':>16}")
    for name, rp, rn, bytes_per_cell in rows:
        print(f"{name:<18}{rp / 1e6:>18.0f}{rn / 1e6:>15.0f}{rp / rn:>8.2f}{rp * bytes_per_cell / bw:>15.0%}")
    print("bandwidth used: a single step's minimum traffic (wave: read u, u⁻, write u⁻: 24 B/cell; "
          "Gray–Scott: read u, v, write u⁺, v⁺: 32 B/cell) over the measured copy bandwidth; above 100 %, "
          "the run moved fewer bytes than single steps must (physcore fuses up to 6 steps per sweep)")


if __name__ == "__main__":
    main()
