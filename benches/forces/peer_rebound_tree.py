"""Barnes-Hut tree gravity, physcore TreeGravity vs REBOUND gravity="tree", same problem.

bench_tree.py's workload: 3D Plummer sphere (G = M = a = 1, cut at r = 20, numpy
default_rng(0)), equal masses 1/N, Plummer eps = 0.01, float64. REBOUND: one root box of side 42
(open boundary), opening_angle2 = theta^2 (its criterion: open a cell when w > theta * r_com;
monopoles unless built with -DQUADRUPOLE). physcore: TreeGravity(theta) (criterion
d > max(l/theta, l*sqrt(3)/2) + delta, group walk, monopoles).

(a) N = 1e4: relative acceleration error |a - a_direct| / |a_direct| (median, 99th pct, max) per
    theta, a_direct from physcore's PairwiseGravity (checked against REBOUND's basic gravity).
(b) time per step (one force evaluation: physcore verlet KDK, REBOUND leapfrog DKD incl. its tree
    update), dt = 1e-4, codes alternating block by block (pc th=1, pc th=2, REBOUND), median.

Install the peer with ``pip install .[bench]`` (REBOUND's wheel; it has no OpenMP, so it runs
on one thread). docs/guide/orbits_charges_attractors.md quotes this bench's tables.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

from _common import header, require_release  # first: sets up the environment before numpy loads
import argparse
import statistics
import time
from ctypes import byref

import numpy as np
import physcore as pc
import rebound

EPS = 0.01


def plummer(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    r = np.minimum(1.0 / np.sqrt(rng.uniform(0, 1, n) ** (-2.0 / 3.0) - 1.0), 20.0)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return r[:, None] * u, np.full(n, 1.0 / n)


def pc_acc(x, m, term, threads=None):
    s = pc.Scene(3, integrator="euler", dt=1.0, threads=threads)
    s.add_particles(x, np.zeros_like(x), masses=m)
    s.add(term)
    s.step(1)
    return np.asarray(s.velocities)


def reb_sim(x, m, gravity, theta=0.5, dt=1e-4):
    sim = rebound.Simulation()
    sim.G = 1.0
    sim.softening = EPS
    sim.gravity = gravity
    sim.integrator = "leapfrog"
    sim.dt = dt
    if gravity == "tree":
        sim.root_size = 42.0
        sim.N_root_x = sim.N_root_y = sim.N_root_z = 1
        sim.boundary = "open"
        sim.opening_angle2 = theta * theta
    for p, mi in zip(x, m, strict=True):
        sim.add(m=mi, x=p[0], y=p[1], z=p[2])
    return sim


def reb_acc(sim):
    rebound.clibrebound.reb_simulation_update_acceleration(byref(sim))
    a = np.empty((sim.N, 3))
    for i, p in enumerate(sim.particles):
        a[i] = (p.ax, p.ay, p.az)
    return a


def errstats(a, ref):
    e = np.linalg.norm(a - ref, axis=1) / np.linalg.norm(ref, axis=1)
    return float(np.median(e)), float(np.percentile(e, 99)), float(e.max())


def pc_stepper(x, m, theta, threads):
    s = pc.Scene(3, integrator="verlet", dt=1e-4, threads=threads)
    s.add_particles(x, masses=m)
    s.add(pc.TreeGravity(G=1.0, softening=EPS, theta=theta) if theta is not None else pc.PairwiseGravity(G=1.0, softening=EPS))
    return s.step


def time_alternating(runners, rounds, block_s):
    steps = {}
    for name, f in runners.items():
        f(1)
        t0 = time.perf_counter()
        f(1)
        t = time.perf_counter() - t0
        steps[name] = max(1, round(block_s / t))
    per = {name: [] for name in runners}
    for _ in range(rounds):
        for name, f in runners.items():
            t0 = time.perf_counter()
            f(steps[name])
            per[name].append((time.perf_counter() - t0) / steps[name])
    return {name: statistics.median(v) for name, v in per.items()}, steps


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--thetas", default="0.2,0.3,0.5,0.7,1.0")
    ap.add_argument("--reb-extra", default="0.25,0.35", help="extra REBOUND thetas (accuracy match)")
    ap.add_argument("--big", type=int, default=100_000)
    ap.add_argument("--big-thetas", default="0.5")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--block", type=float, default=0.3)
    a = ap.parse_args()
    require_release()
    print(header("1,2"))
    th_default = pc.info()["threads"]
    print(f"physcore {pc.__version__} simd {pc.simd_level()} threads 1/{th_default}; REBOUND {rebound.__version__} 1 thread; load {os.getloadavg()}")
    n = a.n
    x, m = plummer(n)
    ref = pc_acc(x, m, pc.PairwiseGravity(G=1.0, softening=EPS))
    rb_direct = reb_acc(reb_sim(x, m, "basic"))
    print(f"N={n}: direct sums agree: max rel |a_pc - a_rebound_basic| = {errstats(rb_direct, ref)[2]:.1e}")
    rb0 = reb_acc(reb_sim(x, m, "tree", theta=1e-3))
    print(f"REBOUND tree at theta=1e-3: max rel err {errstats(rb0, ref)[2]:.1e} (checks the tree data is built)")
    rows = []
    pc_thetas = [float(t) for t in a.thetas.split(",")]
    reb_thetas = sorted(set(pc_thetas + [float(t) for t in a.reb_extra.split(",") if t]))
    for th in sorted(set(pc_thetas + reb_thetas)):
        runners = {}
        errs = {}
        if th in pc_thetas:
            errs["physcore"] = errstats(pc_acc(x, m, pc.TreeGravity(G=1.0, softening=EPS, theta=th)), ref)
            runners["physcore th=1"] = pc_stepper(x, m, th, 1)
            runners[f"physcore th={th_default}"] = pc_stepper(x, m, th, None)
        errs["REBOUND"] = errstats(reb_acc(reb_sim(x, m, "tree", theta=th)), ref)
        runners["REBOUND"] = reb_sim(x, m, "tree", theta=th).steps
        t, _ = time_alternating(runners, a.rounds, a.block)
        for name, v in t.items():
            e = errs["REBOUND" if name == "REBOUND" else "physcore"]
            rows.append((n, th, name, *e, v * 1e3))
        print(f"theta {th} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr, flush=True)
    # the direct sum for scale
    t, _ = time_alternating({"physcore direct th=1": pc_stepper(x, m, None, 1), "REBOUND basic": reb_sim(x, m, "basic").steps}, 1, a.block)
    for name, v in t.items():
        rows.append((n, "direct", name, 0, 0, 0, v * 1e3))
    if a.big:
        xb, mb = plummer(a.big)
        for th in [float(t) for t in a.big_thetas.split(",")]:
            runners = {"physcore th=1": pc_stepper(xb, mb, th, 1), f"physcore th={th_default}": pc_stepper(xb, mb, th, None),
                       "REBOUND": reb_sim(xb, mb, "tree", theta=th).steps}
            t, _ = time_alternating(runners, a.rounds, a.block)
            for name, v in t.items():
                rows.append((a.big, th, name, float("nan"), float("nan"), float("nan"), v * 1e3))
            print(f"N={a.big} theta {th} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr, flush=True)
    print("\n| N | theta | code | median rel. err | 99th pct | max | ms/step |")
    print("|---:|---:|---|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2e} | {r[4]:.2e} | {r[5]:.2e} | {r[6]:.1f} |")


if __name__ == "__main__":
    main()
