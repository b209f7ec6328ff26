"""physcore's DFSPH beside SPlisHSPlasH's (Bender et al., the DFSPH paper's own library, the
``pysplishsplash`` wheel from PyPI) on the dam break of ``physcore render dam_break``, in the same
run on the same machine, runs alternated.

Workload, both codes: a water column W = 1 m wide and 2 m high at rest in the corner of a 4 m × 3 m
tank (3D: 1 m deep, the column spanning it), gravity 9.81 m/s², particle spacing Δx = W / nx, from
rest to T* = t √(2g/W) = 4 (t = 0.903 s: the collapse, the surge and its impact on the far wall),
DFSPH (Bender & Koschier 2017) with density and divergence tolerances of 0.1 % (mean), at most 100
iterations per solve, steps by the CFL condition.

* physcore: ``pc.scenes.dam_break(dim, n=nx, method="dfsph")`` (f64; cubic spline, h the fluid's default,
  1.3 Δx in 2D and 1.0 Δx in 3D, or ``--smoothing``;
  3 layers of wall particles, Akinci et al. 2012; Monaghan viscosity α = 0.05; dt = 0.4 h/|v|max
  and the viscous and force limits), advanced frame by frame as a render does (bench_dfsph.run).
* SPlisHSPlasH 2.19 (``pip install pysplishsplash``): the same geometry as a scene file (fluid
  block sampled on the same lattice, particle radius Δx/2; the tank a box mesh sampled as one layer
  of Akinci 2012 boundary particles, its default for particle walls); its cubic spline kernel
  (support 4r = 2Δx, against physcore's 2h = 2.6Δx); DFSPH with ``maxError = maxErrorV = 0.1``
  (percent) and its default ``minIterations = 2``; standard viscosity 0.01; its CFL step with
  ``cflFactor = 1.3`` so that both codes' CFL step is 0.52 Δx/|v|max (its step is
  0.4 cflFactor · 2r/|v|max), capped at the force limit physcore uses (0.15 √(h/g)).
  Run in a child process (``--splishsplash-python``, default this interpreter), with
  ``LD_PRELOAD`` of the system's libGLdispatch where there is one: the wheel's own copy crashed at
  import beside Debian's libGLX (a segmentation fault in ``__glDispatchInit``).

Reported per code: particles, steps, wall time to T* = 4, ms per step, density and divergence
iterations per step (SPlisHSPlasH's from its own counters), and the surge front / W at T* = 1, 2, 3
(Martin & Moyce 1952: ≈ 1.44 at T* = 1.19, 2.1 at 1.83, 3.0 at 2.51). The codes differ in the
kernel's reach, the viscosity and the walls, so the per-step cost is a like-for-like figure only
to that extent; the wall time to the same physical time at the same resolution and tolerance is
what a user compares.

Usage: python benches/fluids/peer_splishsplash.py [--nx 72] [--dim 2] [--threads 2] [--rounds 2]
       [--splishsplash-python /path/to/python]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release, table  # first: sets up the environment

G = 9.81
MARKS = (1.0, 2.0, 3.0, 4.0)
T_END = 4.0 / math.sqrt(2.0 * G)
GL_DISPATCH = "/lib/x86_64-linux-gnu/libGLdispatch.so.0"

# The child: runs SPlisHSPlasH on the scene file argv[1] and prints one JSON line of results.
CHILD = r'''
import json, sys, time
import numpy as np
import pysplishsplash as sph

scene_file, out_dir, t_end, scale, dim = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
marks = [1.0, 2.0, 3.0]
rec = {"fronts": {}, "it_d": 0, "it_v": 0, "steps": 0}

def front(fm):
    n = fm.numActiveParticles()
    x = np.array([fm.getPosition(i) for i in range(n)])
    # Largest x among particles with at least 4 others within 2 spacings (spray does not count).
    r = sph.Simulation.getCurrent().getParticleRadius()
    from scipy.spatial import cKDTree
    tree = cKDTree(x)
    counts = np.array([len(c) - 1 for c in tree.query_ball_point(x, 4.0 * r)])
    return float(x[counts >= 4, 0].max())

def cb():
    sim = sph.Simulation.getCurrent()
    ts = sim.getTimeStep()
    rec["steps"] += 1
    rec["it_d"] += ts.getValueInt(ts.SOLVER_ITERATIONS)
    rec["it_v"] += ts.getValueInt(ts.SOLVER_ITERATIONS_V)
    t = sph.TimeManager.getCurrent().getTime() * scale
    for m in marks:
        if m not in rec["fronts"] and t >= m:
            t0 = time.perf_counter()
            rec["fronts"][m] = front(sim.getFluidModel(0))
            rec["excluded"] = rec.get("excluded", 0.0) + time.perf_counter() - t0
    rec["N"] = sim.getFluidModel(0).numActiveParticles()

base = sph.Exec.SimulatorBase()
base.init(["SPlisHSPlasH", "--no-gui", "--no-initial-pause", "--output-dir", out_dir, scene_file], "SPlisHSPlasH")
base.setValueFloat(base.STOP_AT, t_end)
base.setTimeStepCB(cb)
t0 = time.perf_counter()
base.run()
rec["wall"] = time.perf_counter() - t0 - rec.get("excluded", 0.0)
print("RESULT " + json.dumps(rec), flush=True)
'''


def splish_scene(nx: int, dim: int) -> dict:
    """The dam break as a SPlisHSPlasH scene (y up; 3D depth along z)."""
    dx = 1.0 / nx
    r = 0.5 * dx
    h = 1.3 * dx
    depth = 1.0
    return {
        "Configuration": {
            "sim2D": dim == 2, "particleRadius": r, "simulationMethod": 4,  # DFSPH
            "gravitation": [0, -G, 0], "cflMethod": 1, "cflFactor": 1.3,
            "cflMaxTimeStepSize": 0.15 * math.sqrt(h / G), "boundaryHandlingMethod": 0,  # Akinci 2012
            "enablePartioExport": False, "enableVTKExport": False,
            "DFSPH": {"minIterations": 2, "maxIterations": 100, "maxError": 0.1,
                      "maxIterationsV": 100, "maxErrorV": 0.1, "enableDivergenceSolver": True},
        },
        "Materials": [{"id": "Fluid", "density0": 1000, "viscosityMethod": 1, "viscosity": 0.01, "vorticityMethod": 0}],
        "RigidBodies": [{
            "geometryFile": "UnitBox.obj", "translation": [2.0, 1.5, 0.5 * depth if dim == 3 else 0.0],
            "rotationAxis": [1, 0, 0], "rotationAngle": 0, "scale": [4.0, 3.0, depth if dim == 3 else 1.0],
            "isDynamic": False, "isWall": True, "mapInvert": True, "mapThickness": 0.0, "mapResolution": [40, 30, 10],
        }],
        # A block is sampled at start + 2r(i + 1), round((end - start)/2r) - 1 particles a row
        # (SPlisHSPlasH's regular sampling). Its scenes keep the fluid 3r from the walls'
        # boundary particles (DamBreakModel_2D.json: the block moved in by r); physcore's lattice,
        # r from its wall's face, put the fluid within reach of SPlisHSPlasH's single layer of
        # samples and the first steps threw it off the wall (dt 1e-4 s, 27 s for 0.1 s). So: the
        # column from 3r to W - r (its free side), nx - 1 particles across, Δx from the wall.
        "FluidBlocks": [{"denseMode": 0, "start": [r, r, r if dim == 3 else -1.0], "end": [1.0 + r, 2.0 + r, depth - r if dim == 3 else 1.0],
                         "translation": [0, 0, 0], "scale": [1, 1, 1]}],
    }


UNIT_BOX = """v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 4 7 3
f 4 8 7
f 1 5 8
f 1 8 4
f 2 3 7
f 2 7 6
"""


def run_splish(nx: int, dim: int, threads: int, python: str) -> dict:
    with tempfile.TemporaryDirectory() as d:
        with open(os.path.join(d, "UnitBox.obj"), "w") as f:
            f.write(UNIT_BOX)
        scene_file = os.path.join(d, "dam.json")
        with open(scene_file, "w") as f:
            json.dump(splish_scene(nx, dim), f)
        env = dict(os.environ, OMP_NUM_THREADS=str(threads))
        if os.path.exists(GL_DISPATCH):
            env["LD_PRELOAD"] = GL_DISPATCH
        p = subprocess.run([python, "-c", CHILD, scene_file, d, repr(T_END), repr(math.sqrt(2 * G)), str(dim)],
                           capture_output=True, text=True, env=env)
    out = p.stdout
    line = next((ln for ln in out.splitlines() if ln.startswith("RESULT ")), None)
    if p.returncode != 0 or line is None:
        sys.exit(f"SPlisHSPlasH failed (exit {p.returncode}):\n{out[-2000:]}\n{p.stderr[-2000:]}")
    rec = json.loads(line[len("RESULT "):])
    rec["fronts"] = {float(k): v for k, v in rec["fronts"].items()}
    sim_ms = re.search(r"Time sum: SimStep: ([0-9.e+-]+) ms", out)
    rec["simstep_s"] = float(sim_ms.group(1)) / 1e3 if sim_ms else float("nan")
    return rec


def run_physcore(nx: int, dim: int, threads: int, frames: bool, smoothing: float | None) -> dict:
    """physcore from rest to T* = 4: one ``advance`` per mark (T* = 1, 2, 3, 4), as SPlisHSPlasH
    steps freely between them, or with ``frames`` one per frame of T* = 4/120 as a render does
    (``bench_dfsph.run``: each frame a whole number of equal steps, up to twice as many)."""
    import time

    import bench_dfsph
    import physcore as pc

    if frames:
        if smoothing is not None:
            sys.exit("--frames runs bench_dfsph.run, at the default smoothing only")
        r = bench_dfsph.run(nx, "dfsph", threads, dim=dim)
        r["it_d"], r["it_v"] = r["it_d"] * r["steps"], r["it_v"] * r["steps"]  # totals, as SPlisHSPlasH's
        return r
    scene = pc.scenes.dam_break(dim=dim, n=nx, method="dfsph", pass_precision="f64", threads=threads, smoothing=smoothing)
    h = scene.fluids[0].h
    scale = math.sqrt(2.0 * G)
    steps, wall, fronts = 0, 0.0, {}
    for mark in MARKS:
        t0 = time.perf_counter()
        steps += scene.advance(mark / scale - scene.time)
        wall += time.perf_counter() - t0
        fronts[mark] = bench_dfsph.front(scene.positions, h)
    st = scene.solver_stats()
    return dict(N=scene.n_particles, steps=steps, wall=wall, fronts=fronts, smoothing=scene.fluids[0].smoothing,
                it_d=st["density_iterations"], it_v=st["divergence_iterations"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=72, help="particles across the column (2D 72: 10,368 in physcore)")
    ap.add_argument("--dim", type=int, default=2, choices=(2, 3))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=2, help="alternated rounds of both codes")
    ap.add_argument("--splishsplash-python", default=sys.executable, help="a Python with pysplishsplash (and scipy)")
    ap.add_argument("--frames", action="store_true", help="advance physcore frame by frame, as a render does")
    ap.add_argument("--smoothing", type=float, default=None,
                    help="physcore's h/Δx (default the fluid's: 1.0 in 3D, SPlisHSPlasH's reach, 1.3 in 2D)")
    args = ap.parse_args()
    require_release()
    runs: dict[str, list[dict]] = {"physcore": [], "SPlisHSPlasH": []}
    for k in range(args.rounds):
        runs["physcore"].append(run_physcore(args.nx, args.dim, args.threads, args.frames, args.smoothing))
        print(f"round {k + 1}: physcore {runs['physcore'][-1]['wall']:.1f} s", file=sys.stderr, flush=True)
        runs["SPlisHSPlasH"].append(run_splish(args.nx, args.dim, args.threads, args.splishsplash_python))
        print(f"round {k + 1}: SPlisHSPlasH {runs['SPlisHSPlasH'][-1]['wall']:.1f} s", file=sys.stderr, flush=True)
    rows = []
    walls = {}
    for name, rs in runs.items():
        w = sorted(r["wall"] for r in rs)
        walls[name] = w[len(w) // 2] if len(w) % 2 else 0.5 * (w[len(w) // 2 - 1] + w[len(w) // 2])
        r = rs[0]
        rows.append([name, f"{r['N']:,}", r["steps"], " / ".join(f"{x['wall']:.1f}" for x in rs),
                     f"{1e3 * walls[name] / r['steps']:.2f}", f"{r['it_d'] / r['steps']:.2f} / {r['it_v'] / r['steps']:.2f}",
                     ", ".join(f"{r['fronts'][m]:.2f}" for m in MARKS[:3])])
    print(header(args.threads))
    print(f"dam break {args.dim}D, {args.nx} particles across, from rest to T* = 4 (t = {T_END:.3f} s), DFSPH at 0.1 %; "
          f"physcore h = {runs['physcore'][0].get('smoothing', 'the default')} Δx{', frame by frame' if args.frames else ''}; {args.rounds} alternated rounds\n")
    print(table(["code", "fluid particles", "steps", "wall to T*=4 (s), each round", "ms/step (median)",
                 "density / divergence it/step", "front/W at T* = 1, 2, 3"], rows))
    print(f"\nSPlisHSPlasH / physcore, wall time (medians): {walls['SPlisHSPlasH'] / walls['physcore']:.1f}×")


if __name__ == "__main__":
    main()
