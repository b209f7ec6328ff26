"""Work-precision diagrams (Hairer & Wanner, Solving ODEs I §II.1): error against cost for every
integrator in ``pc.INTEGRATORS`` on three problems, float64 and (where the core has it) float32
state.

Regenerate everything (CSV, markdown table, plot in ``docs/``) with one command::

    python benches/integrators/work_precision.py

It takes about 4 minutes on the project's 2-core machine (``--quick``: a few seconds, any build;
``--problems kepler,chain,cloth`` picks problems; ``--out DIR`` moves the outputs).
``--stiff-cloth`` prints only the stiff-cloth table (implicit against semi-implicit Euler, each
at its automatic step; see `stiff_cloth`).

Problems
--------
kepler_e0, kepler_e0.5, kepler_e0.9
    A light particle (mass 1e-6) around a pinned unit mass, PairwiseGravity without softening,
    G = M = 1, semi-major axis a = 1, started at pericentre, 100 orbits. The initial state is
    rounded to float32-representable values for every run (so f32 and f64 integrate the same
    orbit) and the period P = 2π a^1.5 is computed from that state; with the star pinned the
    exact solution is periodic, so the position error |x(100 P) − x(0)| / a needs no reference.
    dt = P/N, N = 32 … 96000 (factors of ~3). Energy sampled 32 times per orbit (at pericentre
    among others); error = max |E(t) − E(0)| / |E(0)|.
chain
    32 particles (total mass 1 kg) joined by 31 undamped springs (k = 1e4 N/m, ω_max ≈ 1.1e3 /s),
    first one pinned, released horizontally under gravity, 1 s (ω_max·T ≈ 1.1e3). The chain is a
    chaotic multi-pendulum: past ~1.5 s a 1e-12 perturbation grows to 1e-5 (the whip at the end
    of the swing), so the span stops at 1 s where the problem is still well conditioned.
cloth
    64×64 sheet (pc.scenes.cloth geometry: 1 m, 1 kg, k = 2000 N/m structural + shear + bend,
    row y = 0 pinned, gravity), with dashpots and air drag off, 0.5 s (ω_max ≤ 1.4e4 /s, the bound
    of suggest_dt).

For chain and cloth the position error is the RMS over free particles of |x − x_ref| divided by
the chain length / cloth size, against rk4 at half the smallest dt of the sweep; its own error
is estimated as |x_ref − x_rk4(2 h)| / 15 (Richardson) and printed in the table headers (rows
with status ``reference`` in the CSV). Their energy at t = 0 is zero (rest, zero potential
references), so the energy error is max |E(t) − E(0)| over samples every 5 ms (chain) / 10 ms
(cloth) divided by the energy scale in play, as ``Scene.energy_drift`` does: the largest
kinetic + Σ |potential| + Σ |dissipated| of the reference run (a fixed scale, so that a blow-up
shows as errors > 1). ``dopri5`` sweeps rtol (atol = 1e-3 · rtol · length scale) with dt = the
sampling interval (its output interval). f32 runs (precision column) use a subset of the sweep.

Cost: force evaluations (``scene.force_evaluations``) and wall time of the stepping alone
(``time.perf_counter`` around ``step``; runs under 0.2 s are repeated without sampling as one
``step`` call on a fresh scene, median of 3). Kepler and chain run on 1 thread, cloth on the
default thread count (the ``threads`` column). Divergent runs (``pc.SimulationDiverged``) are
rows with status ``diverged`` and infinite errors; a sweep stops after 3 consecutive
divergences, when the position error falls below 1e-13, when the next run is predicted to take
over the cost cap, or when a run hits the time guard (status ``timeout``).

Outputs: ``work_precision.csv`` (every run), ``work_precision.md`` (tables; also printed),
``work_precision.png`` (position and energy error against wall time, one column per problem,
f32 dashed).

Which integrator when: see "Work-precision: which integrator when" in docs/guide/integrators.md, written
from the results of this script.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import inspect
import math
import os
import platform
import signal
import statistics
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Callable
from collections.abc import Sequence

_BENCHES = Path(__file__).resolve().parents[1]  # benches/: _common, which puts every bench folder on the path
if str(_BENCHES) not in sys.path:
    sys.path.insert(0, str(_BENCHES))

from _common import header, require_release, table  # noqa: E402  first: sets up the environment before numpy loads

import numpy as np  # noqa: E402

import physcore as pc  # noqa: E402
from physcore._atomic import atomic_write  # noqa: E402
from physcore.scenes import cloth_springs  # noqa: E402

DEFAULT_OUT = _BENCHES.parent / "docs"
REPEAT_BELOW_S = 0.2  # runs shorter than this are timed again, median of 3
STOP_BELOW = 1e-13  # a sweep stops once the position error is below this
CSV_FIELDS = [
    "problem", "integrator", "precision", "dt", "rtol", "atol", "steps", "rejected", "force_evals",
    "wall_s", "max_rel_energy_error", "position_error", "threads", "status",
]


def integrator_names(prob: Problem | None = None) -> list[str]:
    """Every integrator, or those that can step `prob`: the Wisdom–Holman map steps the Kepler
    problems only (a planetary system), where it follows the orbit exactly, to rounding."""
    names = [d["name"] for d in pc.INTEGRATORS]
    if prob is not None and not prob.name.startswith("kepler"):
        names = [n for n in names if n != "wisdom_holman"]
    return names


def has_precision() -> bool:
    return "precision" in inspect.signature(pc.Scene.__init__).parameters


def _f32(x: Any) -> np.ndarray:
    """The nearest float32 values, as float64 (so float32 and float64 runs start identically)."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


# --------------------------------------------------------------------------- stiff cloth
STIFF_CLOTH_CASES = ((16, 10), (32, 10))  # (n, stiffness / the cloth scene's default)


def stiff_cloth(cases: Sequence[tuple[int, int]] = STIFF_CLOTH_CASES, repeats: int = 3) -> str:
    """Wall time to simulate 1 s of a stiff hanging cloth (pc.scenes.cloth, stiffness ≥ 10× its
    default 2000 N/m, dashpots and air drag as the scene sets them) with implicit Euler at its
    automatic step against semi-implicit Euler at its own, in the same run: median of `repeats`
    fresh runs each. dt = 1 s / ⌈1 s / auto_dt⌉. Also: the step's ω_max·dt (Gershgorin bound),
    CG iterations per step, the energy books' residual at 1 s (energy_drift: for implicit Euler
    its numerical damping) and the RMS distance (m) of the free particles from the semi-implicit
    run at 1 s (semi-implicit Euler's own error at its step is far smaller)."""
    rows = []
    for n, mult in cases:
        k = 2000.0 * mult
        runs: dict[str, Any] = {}
        for integ, factor in (("semi_implicit_euler", 1.0), ("implicit_euler", 1.0), ("implicit_euler", 2.5), ("implicit_euler", 5.0)):
            walls = []
            for _ in range(repeats):
                scene = pc.scenes.cloth(n=n, stiffness=k, integrator=integ)
                tau = 2.0 * scene.suggest_dt()  # 1/ω_max (springs' bound; drag is slower)
                steps = math.ceil(1.0 / (factor * scene.auto_dt()))
                scene.dt = 1.0 / steps
                scene.energy_drift()  # sets the reference energy outside the timing
                t0 = time.perf_counter()
                scene.step(steps)
                walls.append(time.perf_counter() - t0)
            label = integ if factor == 1.0 else f"{integ} ×{factor:g}"
            runs[label] = scene
            st = scene.integrator_stats
            rows.append([
                n, f"{k:.0e}", label, f"{scene.dt:.2e}", f"{scene.dt / tau:.3g}", steps, f"{statistics.median(walls):.3f}",
                f"{st['cg_iterations'] / st['cg_solves']:.1f}" if st else "–",
                f"{scene.energy_drift():+.1e}", "",
            ])
        ref = runs["semi_implicit_euler"]
        free = ~ref.pinned
        for r in rows[-4:]:
            x = runs[r[2]].positions[free]
            r[-1] = "–" if r[2] == "semi_implicit_euler" else f"{float(np.sqrt(np.mean(np.sum((x - ref.positions[free]) ** 2, axis=1)))):.1e}"
            print(" | ".join(str(c) for c in r), file=sys.stderr, flush=True)  # progress
    headers = ["n", "k N/m", "integrator", "dt s", "ω_max·dt", "steps", "wall s (median of 3)", "CG it./step", "energy drift", "RMS Δx vs semi m"]
    return header() + "\n\n" + table(headers, rows)


# --------------------------------------------------------------------------- problems
@dataclass
class Problem:
    name: str
    family: str
    title: str
    build: Callable[..., pc.Scene]  # keyword arguments of pc.Scene
    n_samples: int  # energy samples (= dopri5 output steps) over the run
    sample: float  # sampling interval, s; dt = sample / m
    ms: Sequence[int]  # fixed-step sweep: steps per sampling interval
    f32_ms: Sequence[int]
    rtols: Sequence[float]
    f32_rtols: Sequence[float]
    threads: int | None
    length: float  # position error normalisation, m
    periodic: bool  # Kepler: error |x(T) - x(0)|, no reference
    period: float = 0.0  # Kepler: P, for the dt labels
    free: np.ndarray | None = field(default=None, repr=False)  # mask of free particles
    ref: np.ndarray | None = field(default=None, repr=False)
    energy_scale: float = 0.0  # chain, cloth: energy errors are relative to this, J
    ref_note: str = ""

    @property
    def span(self) -> float:
        return self.n_samples * self.sample

    def dt_label(self, dt: float) -> str:
        if self.periodic:
            return f"P/{round(self.period / dt)}"
        return f"{dt:.1e}"

    def position_error(self, x: np.ndarray, x0: np.ndarray) -> float:
        if self.periodic:
            return float(np.linalg.norm(x[1] - x0[1])) / self.length
        free = self.free
        d = x[free] - self.ref[free]
        return float(np.sqrt(np.mean(np.sum(d * d, axis=1)))) / self.length


def kepler_problem(e: float, orbits: int, ns: Sequence[int], f32_ns: Sequence[int], rtols, f32_rtols) -> Problem:
    per_orbit = 32  # energy samples per orbit; N must be a multiple
    rp = float(_f32(1.0 - e))
    vp = float(_f32(math.sqrt((1.0 + e) / (1.0 - e))))
    a = 1.0 / (2.0 / rp - vp * vp)  # vis-viva with GM = 1, for the rounded state
    period = 2.0 * math.pi * a**1.5

    def build(**kw: Any) -> pc.Scene:
        s = pc.Scene(2, **kw)
        s.add_particles([[0.0, 0.0], [rp, 0.0]], [[0.0, 0.0], [0.0, vp]], masses=[1.0, 1e-6], pinned=[True, False])
        s.add(pc.PairwiseGravity(G=1.0))
        return s

    return Problem(
        name=f"kepler_e{e:g}", family="kepler",
        title=f"Kepler e = {e:g}, {orbits} orbits; position error |x(T) − x(0)|/a, energy error vs |E0|",
        build=build, n_samples=orbits * per_orbit, sample=period / per_orbit,
        ms=[n // per_orbit for n in ns], f32_ms=[n // per_orbit for n in f32_ns],
        rtols=rtols, f32_rtols=f32_rtols, threads=1, length=a, periodic=True, period=period,
    )


def chain_problem(span: float, ms, f32_ms, rtols, f32_rtols, n: int = 32, stiffness: float = 1e4) -> Problem:
    x = np.zeros((n, 2))
    x[:, 0] = _f32(np.linspace(0.0, 1.0, n))
    rest = np.linalg.norm(x[1:] - x[:-1], axis=1)
    pinned = np.zeros(n, dtype=bool)
    pinned[0] = True

    def build(**kw: Any) -> pc.Scene:
        s = pc.Scene(2, **kw)
        s.add_particles(x, masses=1.0 / n, pinned=pinned)
        s.add(pc.Springs(np.arange(n - 1), np.arange(1, n), stiffness=stiffness, damping=0.0, rest_length=rest))
        s.add(pc.Gravity([0.0, -9.81]))
        return s

    sample = 0.005
    p = Problem(
        name="chain", family="chain",
        title=(f"spring chain, {n} particles, k = {stiffness:g} N/m, undamped, {span:g} s "
               f"(ω_max·T ≈ {2 * math.sqrt(stiffness * n) * span:.0f}); position error RMS/L vs reference"),
        build=build, n_samples=round(span / sample), sample=sample, ms=ms, f32_ms=f32_ms,
        rtols=rtols, f32_rtols=f32_rtols, threads=1, length=1.0, periodic=False,
    )
    p.free = ~pinned
    return p


def cloth_problem(g: int, span: float, ms, f32_ms, rtols, f32_rtols, stiffness: float = 2000.0) -> Problem:
    s_ = 1.0 / (g - 1)
    gx, gy = np.meshgrid(np.arange(g) * s_, np.arange(g) * s_)
    x = _f32(np.stack([gx.ravel(), gy.ravel(), np.zeros(g * g)], axis=1))
    pinned = np.zeros(g * g, dtype=bool)
    pinned[:g] = True
    i, j = cloth_springs(g)
    rest = np.linalg.norm(x[j] - x[i], axis=1)

    def build(**kw: Any) -> pc.Scene:
        s = pc.Scene(3, **kw)
        s.add_particles(x, masses=1.0 / (g * g), pinned=pinned)
        s.add(pc.Springs(i, j, stiffness=stiffness, damping=0.0, rest_length=rest))
        s.add(pc.Gravity([0.0, 0.0, -9.81]))
        return s

    sample = 0.01 if span >= 0.2 else 0.005
    p = Problem(
        name="cloth", family="cloth",
        title=f"cloth {g}×{g}, k = {stiffness:g} N/m, no dashpots or drag, {span:g} s; position error RMS/size vs reference",
        build=build, n_samples=round(span / sample), sample=sample, ms=ms, f32_ms=f32_ms,
        rtols=rtols, f32_rtols=f32_rtols, threads=None, length=1.0, periodic=False,
    )
    p.free = ~pinned
    return p


def make_problems(quick: bool) -> list[Problem]:
    if quick:
        kq = dict(orbits=2, ns=[64, 128, 256], f32_ns=[128], rtols=[1e-4, 1e-8], f32_rtols=[1e-4])
        return [kepler_problem(e, **kq) for e in (0.0, 0.5, 0.9)] + [
            chain_problem(0.2, ms=[6, 12, 24], f32_ms=[12], rtols=[1e-4, 1e-8], f32_rtols=[1e-4]),
            cloth_problem(16, 0.05, ms=[10, 20, 40], f32_ms=[20], rtols=[1e-4], f32_rtols=[1e-4]),
        ]
    ns = [32, 96, 320, 960, 3200, 9600, 32000, 96000]
    rtols = [10.0**-k for k in range(3, 13)]
    f32_rtols = [1e-3, 1e-5, 1e-7, 1e-9]
    kf = dict(orbits=100, ns=ns, f32_ns=ns[1::2], rtols=rtols, f32_rtols=f32_rtols)
    chain_ms = [3 * 2**k for k in range(10)]  # dt = 1.7e-3 (Verlet's limit 1.8e-3) … 3.3e-6
    return [kepler_problem(e, **kf) for e in (0.0, 0.5, 0.9)] + [
        chain_problem(1.0, ms=chain_ms, f32_ms=chain_ms[1::2], rtols=rtols, f32_rtols=f32_rtols),
        # dt = 1.7e-4 … 1.6e-5 (suggest_dt's bound puts Verlet's limit at 1.4e-4; measured, it is above 1.7e-4)
        cloth_problem(64, 0.5, ms=[60, 80, 160, 320, 640], f32_ms=[80, 320],
                      rtols=[1e-3, 1e-5, 1e-7, 1e-9], f32_rtols=[1e-3]),
    ]


# --------------------------------------------------------------------------- running
class _Deadline(BaseException):
    """Raised by the time guard's SIGALRM handler (the core polls signals while stepping)."""


class deadline:
    """Raise _Deadline after `seconds` (POSIX main thread only; otherwise no guard)."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds = seconds
        self.armed = False
        self.usable = (seconds is not None and hasattr(signal, "setitimer")
                       and threading.current_thread() is threading.main_thread())

    def _fire(self, signum, frame) -> None:
        if self.armed:
            raise _Deadline()

    def __enter__(self) -> deadline:
        if self.usable:
            self.old = signal.signal(signal.SIGALRM, self._fire)
            self.armed = True
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.usable:
            self.armed = False
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.old)


def _scene_kwargs(prob: Problem, integrator: str, precision: str, dt: float, rtol: float | None) -> dict[str, Any]:
    kw: dict[str, Any] = dict(integrator=integrator, dt=dt, threads=prob.threads)
    if rtol is not None:
        kw.update(rtol=rtol, atol=1e-3 * rtol * prob.length)
    if precision != "f64":
        kw["precision"] = precision
    return kw


def _scale(e) -> float:
    return abs(e.kinetic) + sum(abs(u) for u in e.potential.values()) + sum(abs(d) for d in e.dissipated.values())


def simulate(prob: Problem, integrator: str, precision: str, m: int, rtol: float | None,
             guard_s: float | None) -> dict[str, Any]:
    """One run: sampled energy error, final positions, cost. Position error is filled by the caller."""
    dt = prob.sample / m
    steps_per_call = 1 if rtol is not None else m
    kw = _scene_kwargs(prob, integrator, precision, dt, rtol)
    scene = prob.build(**kw)
    scene.step(0)  # fixes the reference energy outside the timed region
    e = scene.energy()
    e0, scale = e.total, _scale(e)
    x0 = np.asarray(scene.positions, dtype=np.float64).copy()
    worst, wall, status = 0.0, 0.0, "ok"
    t0 = time.perf_counter()
    try:
        with deadline(guard_s):
            for _ in range(prob.n_samples):
                t0 = time.perf_counter()
                scene.step(steps_per_call)
                wall += time.perf_counter() - t0
                t0 = None
                e = scene.energy()
                worst = max(worst, abs(e.total - e0))
                scale = max(scale, _scale(e))
    except pc.SimulationDiverged:
        status = "diverged"
        wall += time.perf_counter() - t0 if t0 is not None else 0.0
    except _Deadline:
        status = "timeout"
        wall += time.perf_counter() - t0 if t0 is not None else 0.0
    if status == "ok" and wall < REPEAT_BELOW_S:
        times = [wall]
        for _ in range(3):
            s = prob.build(**kw)
            s.step(0)
            t = time.perf_counter()
            s.step(prob.n_samples * steps_per_call)
            times.append(time.perf_counter() - t)
        wall = statistics.median(times[1:])
    stats = scene.integrator_stats if rtol is not None else None
    denom = abs(e0) if prob.periodic else (prob.energy_scale or max(abs(e0), scale))
    ok = status == "ok"
    threads = prob.threads or int(os.environ.get("RAYON_NUM_THREADS") or os.cpu_count() or 1)
    return {
        "problem": prob.name, "integrator": integrator, "precision": precision, "dt": dt,
        "rtol": rtol, "atol": kw.get("atol"),
        "steps": stats["accepted"] if stats else scene.step_count,
        "rejected": stats["rejected"] if stats else None,
        "force_evals": scene.force_evaluations, "wall_s": wall,
        "max_rel_energy_error": (worst / denom if denom > 0 else 0.0) if ok else math.inf,
        "position_error": math.inf, "threads": threads, "status": status,
        "_x": np.asarray(scene.positions, dtype=np.float64).copy() if ok else None, "_x0": x0, "_scale": scale,
    }


def _progress(row: dict[str, Any], prob: Problem) -> None:
    r = f" rtol={row['rtol']:.0e}" if row["rtol"] is not None else ""
    print(f"{prob.name:11s} {row['integrator']:19s} {row['precision']} dt={prob.dt_label(row['dt']):>9s}{r:11s} "
          f"evals={row['force_evals']:>9d} wall={row['wall_s']:8.3f}s dE={row['max_rel_energy_error']:.1e} "
          f"dx={row['position_error']:.1e} {row['status']}", file=sys.stderr, flush=True)


def make_reference(prob: Problem, cache: dict[tuple, dict[str, Any]]) -> list[dict[str, Any]]:
    """rk4 (float64) at half the smallest dt of the sweep; error estimate from the smallest dt."""
    names = integrator_names()
    ref_integ = "rk4" if "rk4" in names else max(pc.INTEGRATORS, key=lambda d: (d["order"], d["name"] != "dopri5"))["name"]
    m = 2 * max(prob.ms)
    fine = simulate(prob, ref_integ, "f64", m, None, None)
    prob.energy_scale = fine["_scale"]
    coarse = simulate(prob, ref_integ, "f64", m // 2, None, None)
    if fine["status"] != "ok" or coarse["status"] != "ok":
        raise RuntimeError(f"{prob.name}: the reference run diverged")
    prob.ref = fine["_x"]
    coarse["position_error"] = prob.position_error(coarse["_x"], coarse["_x0"])
    cache[(ref_integ, "f64", m // 2, None)] = coarse
    est = coarse["position_error"] / 15.0  # Richardson, order 4
    fine["position_error"] = est
    fine["status"] = "reference"
    prob.ref_note = (f"reference: {ref_integ} f64 at dt = {fine['dt']:.2e} ({fine['force_evals']} force evaluations, "
                     f"{fine['wall_s']:.1f} s); vs dt = {coarse['dt']:.2e}: {coarse['position_error']:.1e}, "
                     f"so its own error ≈ {est:.1e}. Energy errors are relative to the reference run's energy scale "
                     f"max(kinetic + Σ|potential|) = {prob.energy_scale:.3g} J.")
    print(f"{prob.name}: {prob.ref_note}", file=sys.stderr, flush=True)
    return [fine]


def sweep(prob: Problem, cap_s: float, guard_s: float, cache: dict[tuple, dict[str, Any]]) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    precisions = ["f64"] + (["f32"] if has_precision() else [])
    for integ in integrator_names(prob):
        for prec in precisions:
            adaptive = integ == "dopri5"
            if adaptive:
                values = prob.rtols if prec == "f64" else prob.f32_rtols
            else:
                values = prob.ms if prec == "f64" else prob.f32_ms
            prev: tuple[float, float] | None = None  # (value, wall)
            diverged_run = 0
            for v in values:
                key = (integ, prec, 1 if adaptive else v, v if adaptive else None)
                row = cache.get(key)
                if row is None and prev is not None:
                    ratio = (prev[0] / v) ** 0.2 if adaptive else v / prev[0]
                    if prev[1] * ratio > cap_s:
                        print(f"{prob.name:11s} {integ:19s} {prec} skipping the rest of the sweep "
                              f"(next run predicted {prev[1] * ratio:.0f} s > cap {cap_s:g} s)", file=sys.stderr)
                        break
                if row is None:
                    row = simulate(prob, integ, prec, *key[2:], guard_s)
                    if row["status"] == "ok":
                        row["position_error"] = prob.position_error(row["_x"], row["_x0"])
                _progress(row, prob)
                rows.append(row)
                prev = (v, row["wall_s"])
                if row["status"] == "timeout":
                    break
                diverged_run = diverged_run + 1 if row["status"] == "diverged" else 0
                if diverged_run >= 3 or row["position_error"] < STOP_BELOW:
                    break
    return rows


def _sweep_measure(prob: Problem, p: dict[str, Any]) -> dict[str, Any]:
    """One run as a physcore.sweep measure (``build`` hands it the parameters themselves)."""
    row = simulate(prob, p["integrator"], p["precision"], p["m"], p["rtol"], None)  # no signal guard off the main thread
    if row["status"] == "ok":
        row["position_error"] = prob.position_error(row["_x"], row["_x0"])
    row["step_wall_s"] = row.pop("wall_s")  # the sweep's own wall_s is build + measure
    return {k: v for k, v in row.items() if not k.startswith("_") and k not in p and k != "threads"}


def _sweep_params(**p: Any) -> dict[str, Any]:
    return p


def sweep_on_dask(prob: Problem, client: Any) -> list[dict[str, Any]]:
    """Every (integrator, precision, step or rtol) of `prob` as one physcore.sweep, each run one
    task on one core thread; no early stops (the sequential sweep's cost cap and divergence
    stops need the previous run), so pair it with --quick or a cheap problem."""
    import functools

    params = []
    for integ in integrator_names(prob):
        for prec in ["f64"] + (["f32"] if has_precision() else []):
            adaptive = integ == "dopri5"
            if adaptive:
                values = prob.rtols if prec == "f64" else prob.f32_rtols
            else:
                values = prob.ms if prec == "f64" else prob.f32_ms
            params += [{"integrator": integ, "precision": prec, "m": 1 if adaptive else v, "rtol": v if adaptive else None}
                       for v in values]
    df = pc.sweep(_sweep_params, params, measure=functools.partial(_sweep_measure, prob), client=client)
    rows = []
    for rec in df.to_dict("records"):
        if rec["error"] is not None and not (isinstance(rec["error"], float) and math.isnan(rec["error"])):
            print(f"{prob.name}: {rec['integrator']} {rec['precision']} failed: {rec['error']}", file=sys.stderr)
            continue
        rec["threads"] = 1
        rec["wall_s"] = rec.pop("step_wall_s")
        rows.append({k: v for k, v in rec.items() if k not in ("run", "m", "seed", "error", "diverged_step", "worker", "run_key")})
        _progress(rows[-1], prob)
    return rows


# --------------------------------------------------------------------------- outputs
def _atomic_write(path: Path, write: Callable[[Any], None], binary: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, write, binary=binary)


def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "inf"
    return v


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    def w(f):
        wr = csv.writer(f)
        wr.writerow(CSV_FIELDS)
        for r in rows:
            wr.writerow([_csv_value(r[k]) for k in CSV_FIELDS])
    _atomic_write(path, w)


def _sci(x: float | None) -> str:
    if x is None:
        return ""
    return f"{x:.1e}" if math.isfinite(x) else "—"


def markdown(problems: list[Problem], rows: list[dict[str, Any]], command: str) -> str:
    import physcore
    ver = getattr(physcore, "__version__", "?")
    profile = getattr(pc._core, "build_profile", "?")
    lines = [
        # The day in the title: the docs keep several of these pages (one a machine or a set).
        f"# Work-precision results, {datetime.datetime.now().astimezone().strftime('%Y-%m-%d')}",
        "",
        f"- machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores ({platform.platform()})",
        f"- date: {datetime.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}",
        f"- physcore {ver} ({profile} build), Python {platform.python_version()}",
        f"- {header(sorted({r['threads'] for r in rows}) or None)} (per run: the threads column)",
        f"- command: `{command}`",
        "- errors: max relative energy error over the samples; position error relative to the length scale "
        "(see the script's docstring); — = diverged or stopped; 2 significant digits",
        "",
    ]
    headers = ["integrator", "precision", "dt", "rtol", "steps", "force evals", "wall s", "energy error", "position error", "status"]
    for prob in problems:
        lines += [f"## {prob.name}: {prob.title}", ""]
        if prob.ref_note:
            lines += [prob.ref_note, ""]
        body = []
        for r in rows:
            if r["problem"] != prob.name or r["status"] == "reference":
                continue
            body.append([
                r["integrator"], r["precision"], prob.dt_label(r["dt"]), _sci(r["rtol"]), r["steps"],
                f"{r['force_evals']:.1e}", f"{r['wall_s']:.1e}", _sci(r["max_rel_energy_error"]),
                _sci(r["position_error"]), r["status"],
            ])
        lines += [table(headers, body), ""]
    return "\n".join(lines)


def plot(path: Path, problems: list[Problem], rows: list[dict[str, Any]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    names = integrator_names()
    colours = {n: plt.get_cmap("tab10")(k % 10) for k, n in enumerate(names)}
    markers = "osD^vP*Xh"
    ncol = max(1, len(problems))
    fig, axes = plt.subplots(2, ncol, figsize=(4.2 * ncol, 7.6), squeeze=False)
    for c, prob in enumerate(problems):
        for r_, (key, label) in enumerate((("position_error", "position error"), ("max_rel_energy_error", "max rel. energy error"))):
            ax = axes[r_][c]
            any_data, ymin, ymax = False, math.inf, 0.0
            for k, integ in enumerate(names):
                for prec in ("f64", "f32"):
                    pts = [(r["wall_s"], r[key]) for r in rows
                           if r["problem"] == prob.name and r["integrator"] == integ and r["precision"] == prec
                           and r["status"] == "ok" and r["wall_s"] > 0 and 0 < r[key] < math.inf]
                    if not pts:
                        continue
                    any_data = True
                    xs, ys = zip(*pts, strict=False)
                    ymin, ymax = min(ymin, *ys), max(ymax, *ys)
                    ax.plot(xs, ys, linestyle="--" if prec == "f32" else "-", marker=markers[k % len(markers)],
                            markersize=4, color=colours[integ], mfc="none" if prec == "f32" else colours[integ],
                            label=f"{integ}" + (" f32" if prec == "f32" else ""))
            if any_data:
                ax.set_xscale("log")
                ax.set_yscale("log")
                # exploding euler runs (errors up to 1e190) would squash the rest: clip at 1e2
                ax.set_ylim(ymin / 3, min(ymax * 3, 1e2))
                ax.xaxis.set_minor_formatter(NullFormatter())
                ax.yaxis.set_minor_formatter(NullFormatter())
            ax.grid(True, which="major", alpha=0.3)
            if r_ == 0:
                ax.set_title(prob.name)
            else:
                ax.set_xlabel("wall time of the run, s")
            if c == 0:
                ax.set_ylabel(label)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=False):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 10), fontsize=8, frameon=False)
    fig.suptitle("physcore work-precision: error vs wall time (f32 dashed)")
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    _atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110), binary=True)
    plt.close(fig)


# --------------------------------------------------------------------------- main
def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny sweep (seconds; any build)")
    ap.add_argument("--problems", default="kepler,chain,cloth",
                    help="comma-separated: kepler, chain, cloth (or kepler_e0, kepler_e0.5, kepler_e0.9)")
    ap.add_argument("--out", default=str(DEFAULT_OUT), help="output directory (default: docs/)")
    ap.add_argument("--cap", type=float, default=None, help="skip runs predicted to take longer than this, s "
                    "(default 15; the guard stops a run at twice this)")
    ap.add_argument("--dask", nargs="?", const="local", default=None, metavar="ADDRESS",
                    help="run each problem's whole grid as one physcore.sweep on Dask: a LocalCluster ('local', the "
                         "default) or a scheduler address; no early stops, so pair it with --quick or one problem")
    ap.add_argument("--stiff-cloth", action="store_true",
                    help="only the stiff-cloth table: 1 s of cloth (k = 10× and 100× the default) with implicit "
                         "Euler at its auto dt against semi-implicit Euler at its own, wall time median of 3")
    args = ap.parse_args(None if argv is None else [str(a) for a in argv])
    if not args.quick:
        require_release()
    if args.stiff_cloth:
        print(stiff_cloth(((8, 10),) if args.quick else STIFF_CLOTH_CASES, 1 if args.quick else 3))
        return 0
    cap = args.cap if args.cap is not None else (2.0 if args.quick else 15.0)
    guard = 2.0 * cap
    wanted = {w.strip() for w in args.problems.split(",") if w.strip()}
    problems = [p for p in make_problems(args.quick) if p.family in wanted or p.name in wanted]
    known = {p.family for p in make_problems(True)} | {p.name for p in make_problems(True)}
    if not problems or wanted - known:
        ap.error(f"--problems: unknown {sorted(wanted - known)}; choose from {sorted(known)}")
    out = Path(args.out)
    command = " ".join(["python benches/integrators/work_precision.py", *(sys.argv[1:] if argv is None else [str(a) for a in argv])])
    t_start = time.perf_counter()
    rows: list[dict[str, Any]] = []
    for prob in problems:
        cache: dict[tuple, dict[str, Any]] = {}
        if not prob.periodic:
            rows += make_reference(prob, cache)
        if args.dask is not None:
            rows += sweep_on_dask(prob, None if args.dask == "local" else args.dask)
        else:
            rows += sweep(prob, cap, guard, cache)
    write_csv(out / "work_precision.csv", rows)
    md = markdown(problems, rows, command)
    md += f"\nTotal time of the command: {time.perf_counter() - t_start:.0f} s.\n"
    _atomic_write(out / "work_precision.md", lambda f: f.write(md))
    plot(out / "work_precision.png", problems, rows)
    print(md)
    print(f"wrote {out / 'work_precision.csv'}, .md, .png in {time.perf_counter() - t_start:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
