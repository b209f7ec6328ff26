"""DFSPH beside WCSPH on the dam break of ``physcore render dam_break`` (and beside a numba DFSPH).

Workload: ``physcore.scenes.dam_break(n=nx)``: water column 1 m × 2 m at rest in the corner of a
4 m × 3 m tank with a lid, 3 layers of wall particles, cubic spline h = 1.3 dx, Monaghan
viscosity α = 0.05 with c0 = 10 √(2gH) = 62.6 m/s, gravity, semi-implicit Euler. WCSPH: Tait
γ = 7, f32 passes, steps at its CFL limit (the sound speed's). DFSPH (``method="dfsph"``): f64,
density and divergence tolerances 0.1 %, steps at the flow's CFL limit 0.4 h / |v|max (and the
viscous and force limits, which bind only near rest).
Both are advanced as a render does it, ``Scene.advance`` per frame of T* = 4/120, from rest to
T* = t √(2g/W) = 4 (t = 0.903 s: the collapse, the surge and its impact on the far wall).

Reported: wall time to T* = 4 and per step, split by the fluid's own phase clocks into neighbour
search (DFSPH: cell list + pair and gradient precompute + density; WCSPH: cell list + gather),
solver iterations (DFSPH: both solves; WCSPH: the density pass) and the rest (DFSPH: viscosity,
integration, bookkeeping; WCSPH: force pass + integration); solver iterations per step; the surge
front / W at T* = 1, 2, 3 (Martin & Moyce 1952: ≈ 1.44 at T* = 1.19, 2.1 at 1.83, 3.0 at 2.51).

``--peer`` also runs benches/fluids/peer_numba_dfsph.py (parallel numba, the same DFSPH, float64) in the
same process after physcore, JIT-compiled beforehand.

Usage: python benches/fluids/bench_dfsph.py [--nx 144] [--threads 2] [--no-wcsph] [--peer]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release, table  # first: sets up the environment

import physcore as pc

G = 9.81
MARKS = (1.0, 2.0, 3.0, 4.0)


def front(x, h: float) -> float:
    """Largest x among particles with at least 4 neighbours within 2h (spray does not count)."""
    import numpy as np

    i, j = pc.neighbors(x, 2.0 * h)
    count = np.bincount(i, minlength=len(x)) + np.bincount(j, minlength=len(x))
    return float(x[count >= 4, 0].max())


def run(nx: int, method: str, threads: int | None, dim: int = 2) -> dict:
    """From rest to T* = 4, one advance per frame of T* = 4/120; returns the figures."""
    precision = "f32" if method == "wcsph" else "f64"
    scene = pc.scenes.dam_break(dim=dim, n=nx, method=method, pass_precision=precision, threads=threads)
    h = scene.fluids[0].h
    scale = math.sqrt(2.0 * G / 1.0)
    frame = 4.0 / 120 / scale
    steps, wall, fronts = 0, 0.0, {}
    for mark in MARKS:
        t0 = time.perf_counter()
        while scene.time * scale < mark - 1e-9:
            t_next = min(mark / scale, scene.time + frame)
            steps += scene.advance(max(t_next - scene.time, 1e-12))
        wall += time.perf_counter() - t0
        fronts[mark] = front(scene.positions, h)
    (nb, solve, _), _ = scene._sim.fluid_profile()
    out = dict(method=method, N=scene.n_particles, steps=steps, wall=wall, fronts=fronts,
               nb=nb / steps, solve=solve / steps, rest=(wall - nb - solve) / steps)
    if method == "dfsph":
        st = scene.solver_stats()
        out.update(it_d=st["density_iterations"] / st["steps"], it_v=st["divergence_iterations"] / st["steps"],
                   err=st["density_error_max"], measured=st["measured_density_error_max"])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=144, help="particles across the column (144: 41,472, the render's size)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-wcsph", action="store_true", help="skip the WCSPH run (about 90 s at nx = 144)")
    ap.add_argument("--peer", action="store_true", help="also run the numba DFSPH (benches/fluids/peer_numba_dfsph.py)")
    args = ap.parse_args()
    require_release()
    rows = []
    for method in ("dfsph",) if args.no_wcsph else ("dfsph", "wcsph"):
        r = run(args.nx, method, args.threads)
        print(f"physcore {method}: {r['steps']} steps, {r['wall']:.1f} s", file=sys.stderr, flush=True)
        rows.append([f"physcore {method}", f"{r['N']:,}", r["steps"], f"{r['wall']:.1f}", f"{1e3 * r['wall'] / r['steps']:.2f}",
                     f"{1e3 * r['nb']:.2f}", f"{1e3 * r['solve']:.2f}", f"{1e3 * r['rest']:.2f}",
                     f"{r['it_d']:.2f} / {r['it_v']:.2f}" if method == "dfsph" else "–",
                     ", ".join(f"{r['fronts'][m]:.2f}" for m in MARKS[:3])])
    if args.peer:
        import numba
        import peer_numba_dfsph as peer

        numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
        peer.compile_all(args.threads)
        r = peer.run(args.nx, args.threads)
        rows.append(["numba dfsph", f"{r['N']:,}", r["steps"], f"{r['wall_s']:.1f}", f"{1e3 * r['wall_s'] / r['steps']:.2f}",
                     f"{r['ms_neighbours']:.2f}", f"{r['ms_solvers']:.2f}", f"{r['ms_rest']:.2f}",
                     f"{r['it_density']:.2f} / {r['it_divergence']:.2f}",
                     ", ".join(f"{r['fronts'][m]:.2f}" for m in MARKS[:3])])
    print(header(args.threads))
    print(f"dam break, {args.nx} particles across, from rest to T* = 4 (t = {4 / math.sqrt(2 * G):.3f} s)\n")
    print(table(["run", "N", "steps", "wall to T*=4 (s)", "ms/step", "neighbours", "solver", "rest",
                 "density / divergence it/step", "front/W at T* = 1, 2, 3"], rows))
    print("\nphyscore DFSPH split: neighbours = cell list + pairs + density and factor, solver = both solves, "
          "rest = viscosity + integration + Python; WCSPH: neighbours = cell list + gather, solver = density "
          "pass, rest = force pass + integration + Python.")


if __name__ == "__main__":
    main()
