"""Work-precision on the outer Solar System: physcore vs REBOUND, identical initial conditions.

Sun + Jupiter, Saturn, Uranus, Neptune (solar.py: fixed elements -> barycentric Cartesian,
G = 1, AU, time unit yr/2pi), PairwiseGravity without softening, float64, over T years (default
1e4, 843 Jupiter orbits). Energy sampled S = 100 times evenly; error = max |E/E0 - 1| over the
samples (both codes' E0 agree to the last bit). Wall time = the stepping only (the chunks between
samples, with WHFast's synchronize at outputs, which applies its corrector, as physcore's
``step`` call applies its own; energy calls excluded), median of R rounds in
which every configuration runs once, in a fixed interleaved order (physcore and REBOUND rows
alternate), so load changes hit both.

physcore: wisdom_holman (the Wisdom–Holman map in Jacobi coordinates, "wh jacobi", with the
symplectic corrector of order N, "wh jacobi cN", and in democratic heliocentric ones, "wh dh"), verlet, yoshida4, rk4 (fixed dt), dopri5 (rtol sweep, atol = 1e-3 rtol, dt = output
interval); all threads = 1. REBOUND: leapfrog (the same KDK/DKD method as verlet), WHFast
(Jacobi, safe_mode=1, no corrector: "wh" default), WHFast with the 17th-order corrector and
safe_mode = 0 (keep_unsynchronized = 1: outputs do not perturb the run, as physcore's corrector
keeps its state between calls), IAS15 (epsilon 1e-9).

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

import numpy as np
import physcore as pc
import rebound

from _solar import YEAR, initial_state

X, V, M = initial_state()
PJ = 2 * np.pi * 5.2026 ** 1.5  # Jupiter's period, time units (~11.86 yr)


class PcRun:
    code = "physcore"

    def __init__(self, integrator, dt=None, rtol=None, coordinates="jacobi", corrector=0):
        self.integrator, self.dt, self.rtol, self.coordinates = integrator, dt, rtol, coordinates
        self.corrector = corrector

    def label(self):
        if self.rtol:
            return f"{self.integrator} rtol={self.rtol:g}"
        name = self.integrator
        if name == "wisdom_holman":
            name = f"wh {'jacobi' if self.coordinates == 'jacobi' else 'dh'}" + (f" c{self.corrector}" if self.corrector else "")
        return f"{name} dt=P_J/{PJ / self.dt:.0f}"

    def run(self, T, S):
        if self.rtol:
            s = pc.Scene(3, integrator="dopri5", dt=T / S, rtol=self.rtol, atol=1e-3 * self.rtol, threads=1)
            per = 1
        else:
            per = max(1, round(T / S / self.dt))
            s = pc.Scene(3, integrator=self.integrator, dt=T / S / per, threads=1, wh_coordinates=self.coordinates,
                         wh_corrector=self.corrector)
        s.add_particles(X, V, masses=M)
        s.add(pc.PairwiseGravity(G=1.0))
        e0 = s.energy().total
        worst, wall = 0.0, 0.0
        for _ in range(S):
            t0 = time.perf_counter()
            s.step(per)
            wall += time.perf_counter() - t0
            worst = max(worst, abs(s.energy().total / e0 - 1.0))
        return worst, wall, per * S, s.force_evaluations


class RbRun:
    code = "REBOUND"

    def __init__(self, integrator, dt=None, corrector=0, safe=1):
        self.integrator, self.dt, self.corrector, self.safe = integrator, dt, corrector, safe

    def label(self):
        if self.integrator == "ias15":
            return "ias15 eps=1e-9"
        name = self.integrator
        if self.integrator == "whfast":
            name = f"whfast c{self.corrector} safe={self.safe}"
        return f"{name} dt=P_J/{PJ / self.dt:.0f}"

    def run(self, T, S):
        sim = rebound.Simulation()
        sim.G = 1.0
        sim.integrator = self.integrator
        for i in range(len(M)):
            sim.add(m=M[i], x=X[i, 0], y=X[i, 1], z=X[i, 2], vx=V[i, 0], vy=V[i, 1], vz=V[i, 2])
        if self.integrator == "whfast":
            sim.integrator.corrector = self.corrector
            sim.integrator.safe_mode = self.safe
            sim.integrator.keep_unsynchronized = 0 if self.safe else 1
        e0 = sim.energy()
        worst, wall = 0.0, 0.0
        if self.integrator == "ias15":
            sim.dt = 0.1
            for k in range(1, S + 1):
                t0 = time.perf_counter()
                sim.integrate(k * T / S, exact_finish_time=1)
                wall += time.perf_counter() - t0
                worst = max(worst, abs(sim.energy() / e0 - 1.0))
            return worst, wall, sim.steps_done, sim.steps_done * 8
        per = max(1, round(T / S / self.dt))
        sim.dt = T / S / per
        for _ in range(S):
            t0 = time.perf_counter()
            sim.steps(per)
            if self.integrator == "whfast" and not self.safe:
                sim.synchronize()  # the corrector's output transformation: timed, as physcore's is
            wall += time.perf_counter() - t0
            worst = max(worst, abs(sim.energy() / e0 - 1.0))
        return worst, wall, per * S, per * S * (1 if self.integrator != 'ias15' else 8)


def configs(full: bool):
    f = [PJ / 100, PJ / 300, PJ / 1000, PJ / 3000] + ([PJ / 10000] if full else [])
    w = [PJ / 10, PJ / 20, PJ / 50, PJ / 100]
    pc_runs = ([PcRun("wisdom_holman", dt) for dt in w]
               + [PcRun("wisdom_holman", dt, coordinates="democratic_heliocentric") for dt in w]
               + [PcRun("wisdom_holman", dt, corrector=c) for c in (3, 5, 11, 17) for dt in w]
               + [PcRun("verlet", dt) for dt in f[1:]] + [PcRun("yoshida4", dt) for dt in [PJ / 30] + f[:3]]
               + [PcRun("rk4", dt) for dt in f[:3]] + [PcRun("dopri5", rtol=r) for r in (1e-8, 1e-10, 1e-12)])
    rb_runs = ([RbRun("whfast", dt) for dt in w] + [RbRun("whfast", dt, corrector=17, safe=0) for dt in w]
               + [RbRun("leapfrog", dt) for dt in f[1:3]] + [RbRun("ias15")])
    # interleave: physcore, REBOUND, physcore, ...
    out = []
    for i in range(max(len(pc_runs), len(rb_runs))):
        out += [r for r in (pc_runs[i] if i < len(pc_runs) else None, rb_runs[i] if i < len(rb_runs) else None) if r]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--years", type=float, default=1e4)
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--full", action="store_true", help="also verlet at P_J/10000")
    ap.add_argument("--only", default="", help="comma-separated label prefixes")
    a = ap.parse_args()
    require_release()
    print(header(1))
    T = a.years * YEAR
    print(f"physcore {pc.__version__} simd {pc.simd_level()} threads 1; REBOUND {rebound.__version__}; T = {a.years:g} yr = {a.years / (PJ / YEAR):.0f} P_J; load {os.getloadavg()}")
    runs = configs(a.full)
    if a.only:
        runs = [r for r in runs if any(r.label().startswith(p) for p in a.only.split(","))]
    res = {id(r): [] for r in runs}
    for k in range(a.rounds):
        for r in runs:
            res[id(r)].append(r.run(T, a.samples))
        print(f"round {k + 1} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr, flush=True)
    print("\n| code | integrator | steps | force evals | max abs(E/E0-1) | wall s (median) | us/step |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in runs:
        v = res[id(r)]
        err = v[0][0]
        wall = statistics.median(x[1] for x in v)
        n = v[0][2]
        print(f"| {r.code} | {r.label()} | {n} | {v[0][3]} | {err:.2e} | {wall:.4f} | {wall / n * 1e6:.3f} |")


if __name__ == "__main__":
    main()
