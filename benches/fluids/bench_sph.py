"""SPH throughput on the SPH-2D dam-break workload of WORKLOADS.md §1 (and a 3D variant).

Workload (identical physics to the reference): water column W = 1 m × H = 2 m at rest in the
lower-left corner of a [0, 4] × [0, 3] m tank, lattice spacing dx = W/nx, N = 2 nx², m = ρ0 dx²,
ρ0 = 1000, cubic spline with h = 1.3 dx, summation density (self included), Tait γ = 7 with
c0 = 10 √(2gH) and p ≥ 0, symmetric pressure force + Monaghan viscosity α = 0.05, gravity,
semi-implicit Euler at dt = 0.2 h/c0, walls that clamp positions into the tank and reflect the
outward velocity with factor 0.5 (physcore: an axis-aligned box collider, restitution 0.5). The
neighbour search (physcore's cell list, counting sort by cell, particles gathered into cell order)
is rebuilt every step. physcore keeps positions and velocities in float64 and runs the density and
force passes in the chosen precision ("f32": the workload's float32 arithmetic).

Protocol "from rest": 1 warm-up step + 19 steps, then 3 blocks of S = 800 (10k), 200 (40k),
50 (160k) steps; the median block time gives particle-steps/s = N·S/median. The split between
cell list (+ gather into cell order), density pass, force pass and the rest (integration, walls,
bookkeeping) comes from physcore's own phase clocks over the timed blocks; bytes per particle are
the heap bytes of the particle state and the SPH buffers divided by N.

3D: a 1 × 2 × 0.5 m column in a [0, 4] × [0, 3] × [0, 0.5] m tank (N = nx³ with nx = 46: 97k),
same physics with the 3D cubic spline, blocks of S = 20.

``--peer`` also runs benches/fluids/peer_numba_sph.py (numba, parallel=True, same workload, float32) in
the same process, alternating with physcore, and prints the ratio.

Usage: python benches/fluids/bench_sph.py [--sizes 10k 40k 160k] [--threads 1 2] [--precision f32 f64]
       [--3d] [--peer]
"""
from __future__ import annotations

import argparse
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment

import physcore as pc
from physcore.fluids import lattice

SIZES = {"10k": (72, 800), "40k": (144, 200), "160k": (288, 50)}
G = 9.81


def build(nx: int, precision: str = "f32", threads=None, dim: int = 2) -> pc.Scene:
    """The SPH-2D workload (or its 3D variant) as a physcore scene."""
    dx = 1.0 / nx
    h = 1.3 * dx
    c0 = 10.0 * math.sqrt(2.0 * G * 2.0)
    scene = pc.Scene(dim, integrator="semi_implicit_euler", threads=threads)
    if dim == 2:
        scene.add(pc.Gravity([0.0, -G]))
        block, tank = ([0, 0], [1, 2]), ([0.0, 0.0], [4.0, 3.0])
    else:
        scene.add(pc.Gravity([0.0, -G, 0.0]))
        block, tank = ([0, 0, 0], [1, 2, 0.5]), ([0.0, 0.0, 0.0], [4.0, 3.0, 0.5])
    x = lattice(*block, dx)
    scene.add_fluid(x, spacing=dx, mass=1000.0 * dx**dim, sound_speed=c0, alpha=0.05, pass_precision=precision)
    scene.add(pc.Box(*tank, restitution=0.5))
    scene.dt = 0.2 * h / c0
    return scene


def measure(scene: pc.Scene, steps: int) -> dict:
    scene.step(1)
    scene.step(19)
    clock0, _ = scene._sim.fluid_profile()
    t = median_block_time(scene, steps)
    clock1, nbytes = scene._sim.fluid_profile()
    n = scene.n_particles
    spent = [b - a for a, b in zip(clock0, clock1, strict=False)]
    total = 3 * t  # the three blocks (median ≈ mean here; the split is a fraction)
    state = n * (2 * scene.dim * 8 + scene.dim * 8 + 16)  # x, v, forces, mass + 1/mass
    return {
        "N": n,
        "rate": n * steps / t,
        "split": [s / total for s in spent] + [max(0.0, 1 - sum(spent) / total)],
        "bytes": (state + nbytes) / n,
    }


def main() -> int:
    require_release()
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES))
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--precision", nargs="+", default=["f32", "f64"], choices=["f32", "f64"])
    ap.add_argument("--3d", dest="three_d", action="store_true", help="also the 3D variant (~97k particles)")
    ap.add_argument("--peer", action="store_true", help="run the numba peer in the same process")
    args = ap.parse_args()

    peer = None
    if args.peer:
        import peer_numba_sph as peer  # noqa: F811 - optional dependency (numba)

    rows = []
    for size in args.sizes:
        nx, steps = SIZES[size]
        for prec in args.precision:
            for th in args.threads:
                r = measure(build(nx, prec, th), steps)
                rows.append([f"2D {size}", r["N"], prec, th, si(r["rate"])] + [f"{100 * s:.0f} %" for s in r["split"]] + [f"{r['bytes']:.0f}"])
                print(rows[-1], flush=True)
    if args.three_d:
        for prec in args.precision:
            for th in args.threads:
                r = measure(build(46, prec, th, dim=3), 20)
                rows.append(["3D 97k", r["N"], prec, th, si(r["rate"])] + [f"{100 * s:.0f} %" for s in r["split"]] + [f"{r['bytes']:.0f}"])
                print(rows[-1], flush=True)
    print()
    print(header(args.threads))
    print(table(["workload", "N", "precision", "threads", "particle-steps/s", "cell list", "density", "forces", "rest", "bytes/particle"], rows))

    if peer is not None:
        th = max(args.threads)
        print(f"\nSide by side, {th} threads, float32 (alternating, medians of 3 blocks each):\n")
        prow = []
        for size in args.sizes:
            nx, steps = SIZES[size]
            ours, theirs = [], []
            for _ in range(2):
                ours.append(measure(build(nx, "f32", th), steps)["rate"])
                sim = peer.NumbaSPH2D(nx, threads=th)
                sim.step(1)
                sim.step(19)
                theirs.append(sim.n * steps / median_block_time(sim.step, steps))
            a, b = max(ours), max(theirs)
            prow.append([size, si(a), si(b), f"{a / b:.2f}x"])
            print(prow[-1], flush=True)
        print()
        print(header(th) + " · numba at its native ISA")
        print(table(["size", "physcore f32", "numba f32", "ratio"], prow))
    return 0


if __name__ == "__main__":
    sys.exit(main())
