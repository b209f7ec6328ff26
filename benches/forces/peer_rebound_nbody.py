"""Direct-sum N-body, physcore vs REBOUND, same problem (bench_nbody.py's workload).

N equal masses 1/N in the unit ball at rest (numpy default_rng(42)), G = 1, Plummer eps = 0.01,
float64, dt = 1e-3. physcore: PairwiseGravity + "verlet" (KDK); REBOUND: gravity="basic",
integrator="leapfrog" (DKD), softening = 0.01. Both: one force evaluation per step.

Part 0 (N = 256): (a) accelerations of both at t = 0 against a numpy direct sum; (b) trajectories
after 20 steps: REBOUND's DKD leapfrog is conjugate to KDK (Phi_DKD^n = D(h/2)K(h/2) Phi_KDK^n
[D(h/2)K(h/2)]^-1), so REBOUND is started from K(h/2)-then-D(h/2) of the initial state and the
inverse is applied at the end (numpy half kicks); then x, v must agree to round-off.
Part 1: timing. Codes alternate block by block (pc th=1, pc th=2, REBOUND, repeated R times);
each block ~0.25 s; medians of steps/s. Pair interactions credited N^2 per step for both.

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

from bench_nbody import initial  # the same bodies as physcore's own bench

EPS, DT = 0.01, 1e-3


def np_acc(x, m):
    d = x[None, :, :] - x[:, None, :]  # x_j - x_i
    r2 = (d * d).sum(-1) + EPS * EPS
    inv = r2 ** -1.5
    np.fill_diagonal(inv, 0.0)
    return (d * (m[None, :] * inv)[:, :, None]).sum(1)


def pc_scene(x, v, n, threads, integrator="verlet", dt=DT):
    s = pc.Scene(3, integrator=integrator, dt=dt, threads=threads)
    s.add_particles(x, v, masses=1.0 / n)
    s.add(pc.PairwiseGravity(G=1.0, softening=EPS))
    return s


def reb_sim(x, v, n):
    sim = rebound.Simulation()
    sim.G = 1.0
    sim.softening = EPS
    sim.gravity = "basic"
    sim.integrator = "leapfrog"
    sim.dt = DT
    xv = np.ascontiguousarray(np.hstack([x, v]))
    for row in xv:
        sim.add(m=1.0 / n, x=row[0], y=row[1], z=row[2], vx=row[3], vy=row[4], vz=row[5])
    return sim


def reb_state(sim):
    a = np.zeros((sim.N, 6))
    sim.serialize_particle_data(xyzvxvyvz=a)
    return a[:, :3].copy(), a[:, 3:].copy()


def check(n=256, steps=200):
    x0 = initial(n)
    v0 = np.zeros_like(x0)
    m = np.full(n, 1.0 / n)
    ref = np_acc(x0, m)
    # physcore acceleration: one explicit Euler step of dt = 1 from rest gives v1 = a
    s = pc_scene(x0, v0, n, 1, integrator="euler", dt=1.0)
    s.step(1)
    a_pc = np.asarray(s.velocities)
    sim = reb_sim(x0, v0, n)
    rebound.clibrebound.reb_simulation_update_acceleration(byref(sim))
    a_rb = np.array([[p.ax, p.ay, p.az] for p in sim.particles])
    def rel(a, b):
        return float(np.max(np.linalg.norm(a - b, axis=1) / np.linalg.norm(b, axis=1)))

    print(f"accelerations N={n}: max rel |a_pc - a_numpy| = {rel(a_pc, ref):.2e}, |a_rb - a_numpy| = {rel(a_rb, ref):.2e}, |a_pc - a_rb| = {rel(a_pc, a_rb):.2e}")
    # trajectories: physcore KDK vs REBOUND DKD conjugated
    s = pc_scene(x0, v0, n, 1)
    s.step(steps)
    xp, vp = np.asarray(s.positions), np.asarray(s.velocities)
    h = DT
    v1 = v0 + 0.5 * h * np_acc(x0, m)
    x1 = x0 + 0.5 * h * v1
    sim = reb_sim(x1, v1, n)
    sim.steps(steps)
    xr, vr = reb_state(sim)
    xr = xr - 0.5 * h * vr
    vr = vr - 0.5 * h * np_acc(xr, m)
    dxr = float(np.max(np.abs(xr - xp)) / np.max(np.abs(xp - x0)))
    dvr = float(np.max(np.abs(vr - vp)) / np.max(np.abs(vp)))
    print(f"trajectory after {steps} steps: max|x_pc - x_rb| / max|x - x0| = {dxr:.2e}, max|v_pc - v_rb| / max|v| = {dvr:.2e}, "
          f"max|x_pc - x_rb| = {np.max(np.abs(xr - xp)):.2e}")
    # and the same without the conjugation, to show it matters
    sim = reb_sim(x0, v0, n)
    sim.steps(steps)
    xr2, _ = reb_state(sim)
    print(f"  (unconjugated DKD vs KDK: max|dx| / max|x - x0| = {np.max(np.abs(xr2 - xp)) / np.max(np.abs(xp - x0)):.2e})")


def timing(sizes, rounds, block_s):
    rows = []
    for n in sizes:
        x0 = initial(n)
        v0 = np.zeros_like(x0)
        runners = {}
        s1 = pc_scene(x0, v0, n, 1)
        s2 = pc_scene(x0, v0, n, None)
        sim = reb_sim(x0, v0, n)
        runners["physcore th=1"] = s1.step
        runners[f"physcore th={pc.info()['threads']} (default)"] = s2.step
        runners["REBOUND (1 thread)"] = sim.steps
        steps = {}
        for name, f in runners.items():  # warm-up and calibration
            f(2)
            k = 1
            while True:
                t0 = time.perf_counter()
                f(k)
                t = time.perf_counter() - t0
                if t > 0.05 or k > 100000:
                    break
                k *= 4
            steps[name] = max(1, int(k * block_s / t))
        rates = {name: [] for name in runners}
        for _ in range(rounds):
            for name, f in runners.items():
                t0 = time.perf_counter()
                f(steps[name])
                t = time.perf_counter() - t0
                rates[name].append(steps[name] / t)
        base = statistics.median(rates["REBOUND (1 thread)"])
        for name in runners:
            r = statistics.median(rates[name])
            spread = (min(rates[name]) / r, max(rates[name]) / r)
            rows.append((n, name, 1e3 / r, r * n, r * n * n, r / base, spread, steps[name]))
        print(f"N={n} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr, flush=True)
    print("\n| N | code | ms/step | particle-steps/s | pair interactions/s (N^2 credited) | vs REBOUND | min/max of blocks | steps/block |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for n, name, ms, ps, pi, ratio, sp, k in rows:
        print(f"| {n} | {name} | {ms:.3f} | {ps / 1e6:.2f} M | {pi / 1e9:.3f} G | {ratio:.2f}x | {sp[0]:.2f}-{sp[1]:.2f} | {k} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="256,1024,4096")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--block", type=float, default=0.25)
    ap.add_argument("--skip-check", action="store_true")
    a = ap.parse_args()
    require_release()
    print(header("1,2"))
    print(f"physcore {pc.__version__} simd {pc.simd_level()} default threads {pc.info()['threads']}; REBOUND {rebound.__version__} (wheel without OpenMP); load {os.getloadavg()}")
    if not a.skip_check:
        check()
    timing([int(s) for s in a.sizes.split(",")], a.rounds, a.block)


if __name__ == "__main__":
    main()
