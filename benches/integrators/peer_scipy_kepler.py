"""WORKLOADS.md §4 (Kepler work-precision), adaptive references: physcore's ``"dopri5"`` against
scipy's ``solve_ivp`` with ``RK45`` (the same Dormand–Prince 5(4) pair) and ``DOP853`` at equal
tolerances, on the e = 0.5 orbit (GM = 1, a = 1, test particle around a pinned unit mass) over
100 orbits. Energy sampled 20× per orbit (physcore's output interval, scipy's ``t_eval``);
position error |r(t_end) − r0|; wall time of the integration alone, median of 3 (physcore:
without sampling). scipy's right-hand side is Python, as in the workload definition.

    pip install ".[bench]"     # numba and scipy
    python benches/integrators/peer_scipy_kepler.py
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release  # first: sets up the environment before numpy loads

import math
import statistics
import time

import numpy as np
import scipy
from scipy.integrate import solve_ivp

import physcore as pc
P = 2 * math.pi
def energy(x, v): return 0.5 * (v @ v) - 1 / math.sqrt(x @ x)
def run_pc(rtol, atol):
    def go(sample):
        s = pc.Scene(2, integrator="dopri5", dt=P / 20, rtol=rtol, atol=atol, threads=1)
        s.add_particles([[0, 0], [0.5, 0]], [[0, 0], [0, math.sqrt(3)]], masses=[1.0, 1e-300], pinned=[True, False])
        s.add(pc.PairwiseGravity(G=1.0, softening=0.0))
        errs = []
        t0 = time.perf_counter()
        if sample:
            for _ in range(2000):
                s.step(1)
                errs.append(abs(energy(s.positions[1], s.velocities[1]) / -0.5 - 1))
        else:
            s.step(2000)
        return time.perf_counter() - t0, s, errs
    wall = statistics.median(go(False)[0] for _ in range(3))
    _, s, errs = go(True)
    return wall, max(errs), float(np.linalg.norm(s.positions[1] - [0.5, 0])), s.force_evaluations
def run_scipy(method, rtol, atol):
    def f(t, y):
        x, v = y[:2], y[2:]
        r3 = (x @ x) ** 1.5
        return np.concatenate([v, -x / r3])
    y0 = np.array([0.5, 0, 0, math.sqrt(3)])
    ts = np.linspace(0, 100 * P, 2001)
    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        sol = solve_ivp(f, (0, 100 * P), y0, method=method, rtol=rtol, atol=atol, t_eval=ts)
        walls.append(time.perf_counter() - t0)
    e = max(abs(energy(sol.y[:2, k], sol.y[2:, k]) / -0.5 - 1) for k in range(len(ts)))
    return statistics.median(walls), e, float(np.linalg.norm(sol.y[:2, -1] - [0.5, 0])), sol.nfev
def main() -> None:
    require_release()
    print(header(1) + f" · scipy {scipy.__version__}\n")
    print("| code | method | rtol / atol | max abs(E/E0-1) | abs(r(t_end)-r0) | force evaluations | wall s | physcore faster |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for rtol, atol in [(1e-6, 1e-9), (1e-10, 1e-12)]:
        w, e, d, n = run_pc(rtol, atol)
        print(f"| physcore | dopri5 | {rtol:g} / {atol:g} | {e:.2e} | {d:.2e} | {n} | {w:.4f} | |")
        for m in ("RK45", "DOP853"):
            ws, es, ds, ns = run_scipy(m, rtol, atol)
            print(f"| scipy {scipy.__version__} | {m} | {rtol:g} / {atol:g} | {es:.2e} | {ds:.2e} | {ns} | {ws:.4f} | {ws / w:.0f}× |")


if __name__ == "__main__":
    main()
