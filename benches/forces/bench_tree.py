"""Barnes–Hut tree gravity (pc.TreeGravity) against the direct sum (pc.PairwiseGravity).

(a) theta table: a 3D Plummer sphere (G = M = a = 1, cut at r = 20; numpy default_rng(0)) of N
    bodies, Plummer ε = 0.01: median and 99th-percentile relative force error against the direct
    sum, and the time of one evaluation (a velocity Verlet step: one force evaluation; median of 3
    blocks of S steps after 2 warm-up steps), for theta in 0.2, 0.3, 0.5, 0.7, 1.0.
(b) cost against N, tree (theta 0.5) and direct sum, 2 threads: ms per step and the N at which
    the tree becomes cheaper (log-log interpolation between the measured sizes).
(c) one velocity Verlet step of 10^6 bodies (the Plummer sphere, theta 0.5): the first step
    (which also evaluates the initial forces), then the median of 3 single steps, and the peak
    resident memory of the process (ru_maxrss) before and after.

Forces for (a) are read from one explicit Euler step of dt = 1 from rest (v₁ = a)."""
from __future__ import annotations

import argparse
import math
import os
import resource
import time

import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc


def plummer(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    r = np.minimum(1.0 / np.sqrt(rng.uniform(0, 1, n) ** (-2.0 / 3.0) - 1.0), 20.0)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return r[:, None] * u, np.full(n, 1.0 / n)


def accelerations(x, m, term, threads):
    s = pc.Scene(3, integrator="euler", dt=1.0, threads=threads)
    s.add_particles(x, np.zeros_like(x), masses=m)
    s.add(term)
    s.step(1)
    return s.velocities


def step_time(x, m, term, threads, steps):
    s = pc.Scene(3, integrator="verlet", dt=1e-4, threads=threads)
    s.add_particles(x, masses=m)
    s.add(term)
    s.step(2)
    return median_block_time(s, steps) / steps


def steps_for(seconds_per_step: float) -> int:
    """Steps per timing block: about 0.3 s of work, at least 1."""
    return max(1, min(200, round(0.3 / max(seconds_per_step, 1e-6))))


def theta_table(n: int, threads: int, thetas) -> None:
    x, m = plummer(n)
    eps = 0.01
    t0 = time.perf_counter()
    ref = accelerations(x, m, pc.PairwiseGravity(softening=eps), threads)
    t_direct = time.perf_counter() - t0
    rows = []
    for theta in thetas:
        term = pc.TreeGravity(softening=eps, theta=theta)
        a = accelerations(x, m, term, threads)
        e = np.linalg.norm(a - ref, axis=1) / np.linalg.norm(ref, axis=1)
        t1 = time.perf_counter()
        accelerations(x, m, term, threads)
        guess = time.perf_counter() - t1
        t = step_time(x, m, term, threads, steps_for(guess))
        rows.append([theta, f"{np.median(e):.2e}", f"{np.percentile(e, 99):.2e}", f"{e.max():.2e}", f"{t * 1e3:.1f}"])
    t = step_time(x, m, pc.PairwiseGravity(softening=eps), threads, steps_for(t_direct))
    rows.append(["direct", "0", "0", "0", f"{t * 1e3:.1f}"])
    print(f"\n(a) 3D Plummer sphere, N = {n}, ε = 0.01, {threads} threads")
    print(table(["theta", "median rel. error", "99th pct", "max", "ms/step"], rows))


def crossover(sizes, threads: int, theta: float) -> None:
    rows, tree, direct = [], [], []
    for n in sizes:
        x, m = plummer(n)
        t_tree = step_time(x, m, pc.TreeGravity(softening=0.01, theta=theta), threads, steps_for(2e-6 * n))
        t_dir = step_time(x, m, pc.PairwiseGravity(softening=0.01), threads, steps_for(1e-9 * n * n))
        tree.append(t_tree)
        direct.append(t_dir)
        rows.append([n, f"{t_tree * 1e3:.2f}", f"{t_dir * 1e3:.2f}", f"{t_dir / t_tree:.2f}"])
    print(f"\n(b) cost against N, 3D Plummer sphere, theta = {theta}, {threads} threads")
    print(table(["N", "tree ms/step", "direct ms/step", "direct / tree"], rows))
    ratio = [math.log(d / t) for d, t in zip(direct, tree, strict=True)]
    for k in range(1, len(sizes)):
        if ratio[k - 1] < 0 <= ratio[k]:
            a, b = math.log(sizes[k - 1]), math.log(sizes[k])
            n_x = math.exp(a + (b - a) * (-ratio[k - 1]) / (ratio[k] - ratio[k - 1]))
            print(f"crossover: the tree is cheaper from N ≈ {n_x:,.0f} (between {sizes[k - 1]} and {sizes[k]})")
            return
    if ratio and ratio[0] >= 0:
        print(f"crossover: the tree is already cheaper at N = {sizes[0]}")
    else:
        print("crossover: not reached in these sizes")


def million(n: int, threads: int, theta: float) -> None:
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    x, m = plummer(n)
    s = pc.Scene(3, integrator="verlet", dt=1e-4, threads=threads)
    s.add_particles(x, masses=m)
    s.add(pc.TreeGravity(softening=0.01, theta=theta))
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    s.step(1)
    first = time.perf_counter() - t0
    t = median_block_time(s, 1)
    rss2 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\n(c) velocity Verlet, 3D Plummer sphere, N = {n:,}, theta = {theta}, {threads} threads")
    print(table(
        ["N", "first step s (3 evaluations: energy baseline, initial and new forces)", "step s (median of 3)", "peak RSS before MB", "peak RSS after MB"],
        [[f"{n:,}", f"{first:.2f}", f"{t:.2f}", f"{rss1:.0f}", f"{rss2:.0f}"]],
    ))
    print(f"(peak RSS at start: {rss0:.0f} MB; load average now " + ", ".join(f"{v:.2f}" for v in os.getloadavg()) + ")")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--table-sizes", default="10000", help="N of the theta table(s), comma-separated")
    ap.add_argument("--thetas", default="0.2,0.3,0.5,0.7,1.0")
    ap.add_argument("--sizes", default="1000,2000,4000,8000,16000,32000", help="N for the crossover")
    ap.add_argument("--million", type=int, default=1_000_000, help="N of part (c); 0 skips it")
    ap.add_argument("--parts", default="abc")
    args = ap.parse_args()
    require_release()
    print(header(args.threads))
    # The machine may be shared: its load says how much of the timings is contention.
    print("load average (1, 5, 15 min): " + ", ".join(f"{v:.2f}" for v in os.getloadavg()))
    if "a" in args.parts:
        for n in map(int, args.table_sizes.split(",")):
            theta_table(n, args.threads, [float(t) for t in args.thetas.split(",")])
    if "b" in args.parts:
        crossover([int(n) for n in args.sizes.split(",")], args.threads, 0.5)
    if "c" in args.parts and args.million:
        million(args.million, args.threads, 0.5)


if __name__ == "__main__":
    main()
