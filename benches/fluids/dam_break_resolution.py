"""A dam-break resolution study run through physcore.sweep: the surge front of WCSPH
(``pc.scenes.dam_break``, column a × 2a) against Martin & Moyce (1952) as the particle count
across the column grows, one run per task on a Dask LocalCluster (or any scheduler).

    python benches/fluids/dam_break_resolution.py [--n 8,12,16,24,32] [--dask ADDRESS] [--out FILE.csv]

For each resolution n (particles across the column width a = 1 m): the front Z = x/a (the
largest x among particles with >= 4 neighbours within 2h, so lone spray does not count) at
T = t·√(2g/a) = 0.41 … 2.98, compared with the measurements shifted by the gate's delay
ΔT = 0.175 (see tests/fluids/test_sph.py), and the wall time of the run. With --out the rows stream to
a CSV and an interrupted study resumes where it stopped.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common

import argparse
import math

import numpy as np

import physcore as pc

#: Martin & Moyce (1952), Phil. Trans. R. Soc. A 244, 312–324, Tables 2 and 6 (n² = 2): (T, Z).
MARTIN_MOYCE_1952 = (
    (0.41, 1.11), (0.84, 1.22), (1.19, 1.44), (1.43, 1.67), (1.63, 1.89), (1.83, 2.11), (1.98, 2.33),
    (2.20, 2.56), (2.32, 2.78), (2.51, 3.00), (2.65, 3.22), (2.83, 3.44), (2.98, 3.67),
)
SHIFT = 0.175
G = 9.81


def build(n: int) -> pc.Scene:
    return pc.scenes.dam_break(n=int(n), width=1.0, height=2.0, tank=(5.0, 2.5), lid=False)


def measure(scene: pc.Scene) -> dict:
    a = 1.0
    tscale = math.sqrt(2 * G / a)
    h = scene.fluids[0].h
    ts, zs = [0.0], [1.0]
    while ts[-1] < MARTIN_MOYCE_1952[-1][0] + 0.05:
        scene.advance(0.05 / tscale)
        x = np.asarray(scene.positions, dtype=np.float64)
        i, j = pc.neighbors(x, 2.0 * h)
        count = np.bincount(i, minlength=len(x)) + np.bincount(j, minlength=len(x))
        ts.append(scene.time * tscale)
        zs.append(float(x[count >= 4, 0].max()) / a)
    t_exp = np.array([t for t, _ in MARTIN_MOYCE_1952])
    z_exp = np.array([z for _, z in MARTIN_MOYCE_1952])
    err = np.interp(t_exp - SHIFT, ts, zs) / z_exp - 1.0
    return {"particles": scene.n_particles, "steps": scene.step_count, "worst_error": float(np.abs(err).max()),
            "mean_error": float(np.abs(err).mean()), "error_T1.43": float(err[3]), "error_T2.98": float(err[-1]),
            "front_T3": float(zs[-1])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", default="8,12,16,24,32", help="resolutions: particles across the column")
    ap.add_argument("--dask", default=None, metavar="ADDRESS", help="a scheduler address (default: a LocalCluster)")
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: one per core)")
    ap.add_argument("--out", default=None, help="stream the rows to this .csv (and resume from it)")
    args = ap.parse_args()
    _common.require_release()
    ns = [int(v) for v in args.n.split(",")]
    df = pc.sweep(build, {"n": ns}, measure=measure, client=args.dask, workers=args.workers, out=args.out)
    print(_common.header(threads=1))
    print(f"Dam break (a = 1 m column, 2a tall, WCSPH defaults of pc.scenes.dam_break) against Martin & Moyce "
          f"1952, time shifted by {SHIFT}\n")
    rows = [[row["n"], row["particles"], row["steps"], f"{row['worst_error']:.1%}", f"{row['mean_error']:.1%}",
             f"{row['error_T1.43']:+.1%}", f"{row['front_T3']:.2f}", f"{row['wall_s']:.1f}", row["error"] or ""]
            for row in df.to_dict("records")]
    print(_common.table(["n", "particles", "steps", "worst |error|", "mean |error|", "error at T = 1.43",
                         "Z at T ≈ 3", "wall, s", "error"], rows))


if __name__ == "__main__":
    main()
