"""The reproducibility contract, measured: which results are bit-identical across thread counts,
SIMD levels, save/load and pickling, and by how much the others differ.

    python benches/robustness/reproducibility.py [--write docs/reproducibility.md] [CASE ...]

Each case is a scene (every gallery scene at its defaults, plus one row per integrator and the
large workloads that take the parallel and SIMD paths) stepped a fixed number of steps. Its state
is the whole scene file (:meth:`physcore.Scene.save`'s arrays: positions, velocities, grid
fields, flow points, contact springs, energy books, clock), so a difference anywhere shows.

A cell reads ``=`` when every array is bit-identical, else the largest relative difference
``max |a - b| / max |b|`` over the state's arrays. ``tests/robustness/test_reproducibility.py`` holds the
published table to what the library does: ``=`` exactly, a figure within 10× (another CPU of the
same level runs the same instructions; the slack covers a different libm).
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import platform
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import physcore as pc
from physcore.scenes import REGISTRY

STEPS = 60
#: Gallery scenes whose steps are slow get fewer (the per-step cost is in the docs' gallery table).
FEWER = {"xpbd_cloth": 15, "shape_matched_boxes": 20}


def _grains(dim: int, threads: int | None) -> pc.Scene:
    """A pile of grains in a box past the contact pass's parallel threshold (2D linear with equal
    masses, 3D Hertz with unequal ones), some grains pinned."""
    rng = np.random.default_rng(5 + dim)
    n = 4500 if dim == 2 else 1500
    size = 0.25 if dim == 2 else 0.06
    x = rng.uniform(0.0, size, (n, dim))
    r = np.full(n, 0.002) if dim == 2 else rng.uniform(0.002, 0.003, n)
    s = pc.Scene(dim, integrator="semi_implicit_euler", dt=1e-5, threads=threads)
    s.add_particles(x, rng.normal(0.0, 0.2, (n, dim)), masses=1e-3 * (r / 0.002) ** dim,
                    pinned=rng.uniform(size=n) < 0.03)
    s.set_attribute("radius", r)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    s.add(pc.Contacts(stiffness=1e4 if dim == 2 else 1e6, restitution=0.5, friction=0.4,
                      law="linear" if dim == 2 else "hertz",
                      walls=pc.Box([0.0] * dim, [size] * dim, restitution=0.7, friction=0.3)))
    s.dt = s.suggest_dt()
    return s


def _nbody(precision: str, threads: int | None) -> pc.Scene:
    rng = np.random.default_rng(3)
    s = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads, precision=precision)
    s.add_particles(rng.normal(size=(1500, 3)), rng.normal(0.0, 0.1, (1500, 3)), masses=1.0 / 1500)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    return s


def _chain(integrator: str, threads: int | None) -> pc.Scene:
    """The integrators' rows: an undamped, stretchy spring chain (24 particles, 2000 N/m, at
    half its suggested step: ``spring_chain``'s defaults until issue 65 made the gallery's rope
    stiffer and lightly damped), so that each row shows its integrator alone and the rows
    measured on other CPUs (neon, aarch64) stay those of the same scene."""
    s = pc.scenes.spring_chain(24, stiffness=2000.0, damping=0.0, integrator=integrator, threads=threads)
    s.dt = 2.0 * s.dt  # the scene's default is a quarter of the suggested step; exact in binary
    return s


def _solar(integrator: str, threads: int | None) -> pc.Scene:
    """The Sun and the four giant planets (their masses, M_sun) on circular orbits at their
    distances (AU; G = 1, time in yr/2π), a little inclined, in the centre-of-mass frame, at
    P_Jupiter/20: built here, so the bench needs no peer code (benches/integrators/_solar.py
    takes REBOUND to turn real elements into positions)."""
    planets = ((9.547919e-4, 5.2026, 20.0), (2.858860e-4, 9.5549, 317.0), (4.366244e-5, 19.2184, 142.0),
               (5.151389e-5, 30.1104, 256.0))
    x, v, m = [np.zeros(3)], [np.zeros(3)], [1.0]
    for k, (mass, a, deg) in enumerate(planets):
        ang, tilt, speed = np.radians(deg), 0.01 * (k + 1), np.sqrt((1.0 + mass) / a)
        x.append(a * np.array([np.cos(ang), np.sin(ang), 0.0]))
        v.append(speed * np.array([-np.sin(ang) * np.cos(tilt), np.cos(ang) * np.cos(tilt), np.sin(tilt)]))
        m.append(mass)
    x, v, m = np.array(x), np.array(v), np.array(m)
    x, v = x - m @ x / m.sum(), v - m @ v / m.sum()
    s = pc.Scene(3, integrator=integrator, dt=2 * np.pi * 5.2026**1.5 / 20, threads=threads)
    s.add_particles(x, v, masses=m)
    s.add(pc.PairwiseGravity(G=1.0))
    return s


def cases() -> dict[str, tuple[Callable[[int | None], pc.Scene], int]]:
    """name → (build(threads), steps)."""
    out: dict[str, tuple[Callable[[int | None], pc.Scene], int]] = {}
    for name, fn in REGISTRY.items():
        out[name] = ((lambda t, fn=fn: fn(threads=t)), FEWER.get(name, STEPS))
    for integ in ("euler", "semi_implicit_euler", "verlet", "yoshida4", "rk4", "dopri5", "implicit_euler"):
        out[f"spring_chain/{integ}"] = ((lambda t, i=integ: _chain(i, t)), STEPS)
    # The Wisdom–Holman map steps planetary systems only: the Sun and the four giant planets.
    out["solar/wisdom_holman"] = ((lambda t: _solar("wisdom_holman", t)), STEPS)
    for integ in ("verlet", "rk4"):
        # 5184 particles: past the springs' parallel threshold.
        out[f"cloth n=72/{integ}"] = ((lambda t, i=integ: pc.scenes.cloth(n=72, integrator=i, threads=t)), 20)
    for method in ("euler", "heun", "dopri5"):
        out[f"lorenz/{method}"] = ((lambda t, m=method: pc.scenes.lorenz(integrator=m, threads=t)), STEPS)
    out["nbody 1500/f64"] = ((lambda t: _nbody("f64", t)), 10)
    out["nbody 1500/f32"] = ((lambda t: _nbody("f32", t)), 10)
    out["dam_break/wcsph f64"] = ((lambda t: pc.scenes.dam_break(pass_precision="f64", method="wcsph", threads=t)), STEPS)
    out["dam_break/wcsph f32"] = ((lambda t: pc.scenes.dam_break(pass_precision="f32", method="wcsph", threads=t)), STEPS)
    out["dam_break 3D/dfsph"] = ((lambda t: pc.scenes.dam_break(dim=3, n=10, method="dfsph", threads=t)), 20)
    out["grains 2D linear"] = ((lambda t: _grains(2, t)), STEPS)
    out["grains 3D hertz"] = ((lambda t: _grains(3, t)), STEPS)
    return out


def _leaves(x: object, path: str = "") -> list[tuple[str, object]]:
    if isinstance(x, dict):
        return [leaf for k in sorted(x) for leaf in _leaves(x[k], f"{path}.{k}")]
    if isinstance(x, list):
        return [leaf for i, v in enumerate(x) for leaf in _leaves(v, f"{path}[{i}]")]
    return [(path, x)]


def state(scene: pc.Scene) -> dict[str, np.ndarray]:
    """Every array of the scene file; the JSON record's numbers (clock, books' baseline) become
    one float array, its other leaves one string, and the thread count (a setting, not state)
    is left out."""
    arrays = {k: np.asarray(v) for k, v in scene._file_arrays().items()}
    meta = json.loads(str(arrays.pop("meta")))
    meta.pop("threads", None)
    leaves = _leaves(meta)
    numbers = [(k, v) for k, v in leaves if isinstance(v, float)]
    arrays["meta.numbers"] = np.array([v for _, v in numbers], dtype=np.float64)
    arrays["meta.rest"] = np.array(json.dumps([(k, v) for k, v in leaves if not isinstance(v, float)]))
    return arrays


def difference(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> float:
    """0.0 when bit-identical, else the largest relative difference over the float arrays
    (``inf`` when the layouts differ or a non-float array differs)."""
    if a.keys() != b.keys():
        return float("inf")
    worst = 0.0
    for k in a:
        x, y = a[k], b[k]
        if x.shape != y.shape or x.dtype != y.dtype:
            return float("inf")
        if x.tobytes() == y.tobytes():
            continue
        if x.dtype.kind not in "fc":
            return float("inf")
        if k.endswith("_state"):
            # The rigid bodies' solver state: bytes packed 6 to a float, not a quantity (one bit
            # off turns a packed value into another integer). Differing bits count; the figure
            # comes from the bodies' own arrays (positions, velocities, ...) beside it.
            worst = max(worst, np.finfo(np.float64).tiny)
            continue
        wide = np.complex128 if x.dtype.kind == "c" else np.float64
        x64, y64 = x.astype(wide), y.astype(wide)
        diff = np.abs(x64 - y64)
        diff = diff[np.isfinite(diff)] if np.isfinite(diff).any() else diff
        scale = np.abs(y64[np.isfinite(y64)]).max(initial=0.0)
        d = float(diff.max(initial=0.0)) / scale if scale > 0 else float("inf")
        worst = max(worst, d if d > 0 else np.finfo(np.float64).tiny)  # bits differ: never report 0
    return worst


def run(build: Callable[[int | None], pc.Scene], steps: int, threads: int | None = 1) -> dict[str, np.ndarray]:
    s = build(threads)
    s.step(steps)
    return state(s)


def measure(name: str, levels: list[str] | None = None) -> dict[str, float]:
    """The row of one case: threads (1 vs 2 vs 3), each SIMD level vs scalar (1 thread), save/load
    and pickle restarts vs the uninterrupted run (at the level in force)."""
    build, steps = cases()[name]
    here = pc.simd_level()
    row: dict[str, float] = {}
    ref = run(build, steps, 1)
    row["threads"] = max(difference(run(build, steps, t), ref) for t in (2, 3))
    pc.set_simd_level("scalar")
    try:
        scalar = run(build, steps, 1)
    finally:
        pc.set_simd_level(here)
    for level in levels if levels is not None else pc.simd_levels():
        if level == "scalar":
            continue
        pc.set_simd_level(level)
        try:
            row[level] = difference(run(build, steps, 1), scalar)
        finally:
            pc.set_simd_level(here)
    half = steps // 2
    s = build(1)
    s.step(half)
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"physcore_repro_{os.getpid()}.npz"
    s.save(path)
    try:
        loaded = pc.Scene.load(path)
    finally:
        path.unlink()
    loaded.step(steps - half)
    row["save/load"] = difference(state(loaded), ref)
    s2 = build(1)
    s2.step(half)
    s2 = pickle.loads(pickle.dumps(s2))
    s2.step(steps - half)
    row["pickle"] = difference(state(s2), ref)
    return row


def cell(d: float) -> str:
    if d == 0.0:
        return "="
    if not np.isfinite(d):
        return "differs"
    return f"{d:.0e}"


def parse(text: str) -> dict[str, dict[str, str]]:
    """The published table: case → column → cell."""
    rows: dict[str, dict[str, str]] = {}
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    if not lines:
        return rows
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    for ln in lines[2:]:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        rows[cells[0].strip("`")] = dict(zip(head[1:], cells[1:], strict=True))
    return rows


BEGIN, END = "<!-- table -->", "<!-- /table -->"


def _file(d: Path, name: str, level: str) -> Path:
    return d / (re.sub(r"[^A-Za-z0-9_.=-]+", "_", name) + f"@{level}.npz")


def dump(names: list[str], out: Path) -> None:
    """Write each case's final state at every level of this machine (1 thread), for
    :func:`against` on another machine."""
    out.mkdir(parents=True, exist_ok=True)
    here = pc.simd_level()
    for name in names:
        build, steps = cases()[name]
        for level in pc.simd_levels():
            pc.set_simd_level(level)
            try:
                np.savez(_file(out, name, level), **run(build, steps, 1))
            finally:
                pc.set_simd_level(here)
        print(f"dumped {name}", flush=True)


def against(name: str, other: Path) -> dict[str, float]:
    """Columns from another machine's dump: its NEON level against its scalar one, and its scalar
    state against this machine's."""
    row: dict[str, float] = {}
    scalar = _file(other, name, "scalar")
    if not scalar.exists():
        return row
    theirs = dict(np.load(scalar))
    neon = _file(other, name, "neon")
    if neon.exists():
        row["neon"] = difference(dict(np.load(neon)), theirs)
    here = pc.simd_level()
    pc.set_simd_level("scalar")
    try:
        row["aarch64"] = difference(theirs, run(*cases()[name], 1))
    finally:
        pc.set_simd_level(here)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", help="cases (default: all)")
    ap.add_argument("--write", help="replace the table between the markers in this Markdown file")
    ap.add_argument("--dump", type=Path, help="only write each case's final state at every level to this folder")
    ap.add_argument("--against", type=Path, help="add the neon and aarch64 columns from a --dump made on aarch64")
    args = ap.parse_args(argv)
    names = args.names or list(cases())
    t0 = time.perf_counter()
    if args.dump:
        dump(names, args.dump)
        print(f"# {len(names)} cases in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        return 0
    levels = [lv for lv in pc.simd_levels() if lv != "scalar"]
    cols = ["threads", *levels, *(["neon", "aarch64"] if args.against else []), "save/load", "pickle"]
    out = ["| case | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for name in names:
        row = measure(name, levels)
        if args.against:
            row.update(against(name, args.against))
        out.append(f"| `{name}` | " + " | ".join(cell(row[c]) if c in row else "–" for c in cols) + " |")
        print(out[-1], flush=True)
    info = pc.info()
    print(f"# {len(names)} cases in {time.perf_counter() - t0:.0f} s on {info.get('cpu', platform.processor())}, "
          f"levels {', '.join(pc.simd_levels())}", file=sys.stderr)
    if args.write:
        p = Path(args.write)
        text = p.read_text()
        table = "\n".join(out)
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: f"{BEGIN}\n{table}\n{END}", text, flags=re.S)
        p.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
