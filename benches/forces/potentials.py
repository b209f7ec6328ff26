"""Potential fields (docs/potentials.md): accuracy tables, figures and throughput.

* harmonic trap, k = 9 N/m, m = 1 kg: Verlet's phase error after 10 periods vs steps per period;
* Kepler orbit around a fixed point mass (e = 0.5, GM = 1): |x(P) - x(0)| and max |ΔE/E| over
  one orbit vs steps per orbit, Verlet and RK4;
* φ = ½ω²x² (ω = 2) sampled every h on [-1, 1]²: mean interpolation error of the books, max
  force error, period error from a turning point on a node;
* 200 particles in a bumpy well on a 40-cell grid, 20 s of Verlet: max |ΔE| / (K + |U|) vs dt;
* ns per particle per force evaluation (Verlet step, N = 2·10⁵ in 3D) for each term, threads 1, 2.

Writes docs/potentials_convergence.png and docs/potentials_orbits.png (with --figures).
Run: ``python benches/forces/potentials.py [--figures]``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, table  # first: sets up the environment
import numpy as np

import physcore as pc

TAU = 2 * np.pi


def trap_phase(steps: int) -> float:
    w = 3.0
    s = pc.Scene(dim=2, integrator="verlet", dt=TAU / w / steps, threads=1)
    s.add_particles([[1.0, 0.0]], masses=[1.0])
    s.add(pc.HarmonicTrap(9.0))
    s.step(10 * steps)
    return float(np.arctan2(-s.velocities[0, 0] / w, s.positions[0, 0]))


def kepler(integrator: str, steps: int, record: bool = False, orbits: int = 1):
    s = pc.Scene(dim=2, integrator=integrator, dt=TAU / steps, threads=1)
    s.add_particles([[0.5, 0.0]], [[0.0, np.sqrt(3.0)]], masses=[1.0])
    s.add(pc.PointMasses([0.0, 0.0], 1.0))
    e0 = s.energy().total
    worst, path, errs = 0.0, [], []
    for _ in range(steps * orbits):
        s.step(1)
        de = abs(s.energy().total / e0 - 1)
        worst = max(worst, de)
        if record:
            path.append(s.positions[0].copy())
            errs.append(de)
    return float(np.linalg.norm(s.positions[0] - [0.5, 0.0])), worst, np.array(path), np.array(errs)


def parabola(n: int, w: float = 2.0, amp: float = 0.5):
    ax = np.linspace(-1.0, 1.0, n)
    h = ax[1] - ax[0]
    phi = 0.5 * w**2 * ax[:, None] ** 2 + 0 * ax[None, :]
    xs = np.linspace(-0.9, 0.9, 397)
    probe = pc.Scene(dim=2, integrator="euler", dt=1e-9, threads=1)
    probe.add_particles(np.stack([xs, 0 * xs], 1), masses=np.ones_like(xs))
    probe.add(pc.PotentialGrid(phi, h, origin=-1.0))
    du = (probe.energy().potential["potential_grid"] - np.sum(0.5 * w**2 * xs**2)) / xs.size
    probe.step(1)
    df = np.abs(probe.velocities[:, 0] / probe.dt + w**2 * xs).max()
    s = pc.Scene(dim=2, integrator="verlet", dt=2e-5, threads=1)
    s.add_particles([[amp, 0.0]], masses=[1.0])
    s.add(pc.PotentialGrid(phi, h, origin=-1.0))
    s.step(int(0.45 * TAU / w / s.dt))
    v0, t0 = s.velocities[0, 0], s.time
    while True:
        s.step(1)
        if s.velocities[0, 0] >= 0:
            break
        v0, t0 = s.velocities[0, 0], s.time
    v1 = s.velocities[0, 0]
    dt_ = 2 * (t0 + s.dt * -v0 / (v1 - v0)) / (TAU / w) - 1
    return h, du, df, dt_


def bumpy(dim: int, n: int = 41):
    ax = np.linspace(-2.0, 2.0, n)
    X = np.meshgrid(*([ax] * dim), indexing="ij")
    p = 0.5 * sum(x**2 for x in X) + 0.3 * np.cos(2.1 * X[0]) * np.sin(1.7 * X[1] + 0.3)
    p = p + 0.15 * np.sin(3.3 * X[0] - 2.2 * X[1]) + (0.2 * np.cos(1.3 * X[2] + X[0]) if dim == 3 else 0.0)
    return p, ax[1] - ax[0]


def crossings(dim: int, dt: float, record: bool = False):
    phi, h = bumpy(dim)
    rng = np.random.default_rng(1)
    s = pc.Scene(dim=dim, integrator="verlet", dt=dt, threads=1)
    s.add_particles(rng.uniform(-0.6, 0.6, (200, dim)), rng.normal(0, 0.5, (200, dim)), masses=np.ones(200))
    s.add(pc.PotentialGrid(phi, h, origin=-2.0))
    e = s.energy()
    scale = e.kinetic + abs(e.potential["potential_grid"])
    errs = []
    for _ in range(100):
        s.step(round(0.2 / dt))
        errs.append((s.energy().total - e.total) / scale)
    return np.array(errs)


def throughput(n: int = 200_000) -> list[list[str]]:
    rng = np.random.default_rng(0)
    x, v = rng.uniform(-1, 1, (n, 3)), rng.normal(0, 0.01, (n, 3))
    ax = np.linspace(-1.2, 1.2, 65)
    g65 = np.sin(ax)[:, None, None] * np.cos(ax)[None, :, None] + ax[None, None, :] ** 2
    ax2 = np.linspace(-1.2, 1.2, 257)
    g257 = np.sin(ax2)[:, None, None] * np.cos(ax2)[None, :, None] + ax2[None, None, :] ** 2
    cases = {
        "(no term: the Verlet step itself)": None,
        "HarmonicTrap": lambda: pc.HarmonicTrap([1.0, 2.0, 3.0]),
        "PointMasses, S = 1": lambda: pc.PointMasses([0.0, 0.0, 0.0], 1.0, softening=0.1),
        "PointMasses, S = 16": lambda: pc.PointMasses(rng.normal(size=(16, 3)), np.ones(16), softening=0.1),
        "PotentialGrid 65³ (2 MB)": lambda: pc.PotentialGrid(g65, ax[1] - ax[0], origin=-1.2),
        "PotentialGrid 257³ (136 MB)": lambda: pc.PotentialGrid(g257, ax2[1] - ax2[0], origin=-1.2),
    }
    rows = []
    base = {}
    for name, make in cases.items():
        row = [name]
        for threads in (1, 2):
            s = pc.Scene(dim=3, integrator="verlet", dt=1e-4, threads=threads)
            s.add_particles(x, v)
            if make is not None:
                s.add(make())
            s.step(2)
            t = median_block_time(s, 10) / 10 / n * 1e9
            if make is None:
                base[threads] = t
                row.append(f"{t:.1f}")
            else:
                row.append(f"{t:.1f} ({t - base[threads]:.1f})")
        rows.append(row)
    return rows


def figures(path_prefix: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(13, 4))
    hs, du, df, dt_ = np.array([parabola(n) for n in (21, 41, 81, 161, 321)]).T
    ax = axs[0]
    ax.loglog(hs, np.abs(du), "o-", label="mean |φ̃ − φ| (books)")
    ax.loglog(hs, df, "s-", label="max |F/m + ω²x|")
    ax.loglog(hs, np.abs(dt_), "^-", label="|T/T₀ − 1| (turning point on a node)")
    for p, c, y0 in ((2, "C0", np.abs(du)[0]), (1, "C1", df[0]), (1.5, "C2", np.abs(dt_)[0])):
        ax.loglog(hs, y0 * (hs / hs[0]) ** p, ":", color=c, label=f"h^{p:g}")
    ax.set(xlabel="grid spacing h (m)", title="φ = ½ω²x² sampled on a grid", ylabel="error")
    ax.legend(fontsize=7)
    ax = axs[1]
    t = np.arange(1, 101) * 0.2
    for dt in (4e-3, 1e-3, 2.5e-4):
        ax.plot(t, crossings(2, dt), label=f"dt = {dt:g} s")
    ax.set(xlabel="t (s)", ylabel="ΔE / (K + |U|)", title="200 particles crossing cells (2D, 40² cells)")
    ax.legend(fontsize=8)
    ax = axs[2]
    ks = np.array([125, 250, 500, 1000, 2000])
    for integ, mk in (("verlet", "o-"), ("rk4", "s-")):
        errs = np.array([kepler(integ, k)[0] for k in ks])
        ax.loglog(ks, errs, mk, label=f"{integ}: |x(P) − x(0)|")
    ax.loglog(ks, 0.5 * (ks / ks[0]) ** -2.0, ":", color="C0", label="∝ n⁻²")
    ax.loglog(ks, 1e-3 * (ks / ks[0]) ** -4.0, ":", color="C1", label="∝ n⁻⁴")
    ax.set_xticks(ks, [str(k) for k in ks], minor=False)
    ax.set_xticks([], minor=True)
    ax.set(xlabel="steps per orbit", title="Kepler e = 0.5 around PointMasses", ylabel="error")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{path_prefix}_convergence.png", dpi=90)

    fig, axs = plt.subplots(1, 2, figsize=(9, 4))
    _, _, path, errs = kepler("verlet", 200, record=True, orbits=5)
    ax = axs[0]
    ax.plot(path[:, 0], path[:, 1], lw=1)
    ax.plot([0], [0], "k*", ms=10)
    ax.set_aspect("equal")
    ax.set(title="5 orbits, Verlet, 200 steps per orbit", xlabel="x", ylabel="y")
    ax = axs[1]
    ax.semilogy(np.arange(1, errs.size + 1) / 200, errs + 1e-17)
    ax.set(xlabel="t / P", ylabel="|E/E₀ − 1|", title="energy error over 5 orbits (bounded)")
    fig.tight_layout()
    fig.savefig(f"{path_prefix}_orbits.png", dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--figures", action="store_true", help="write docs/potentials_*.png")
    ap.add_argument("--no-throughput", action="store_true")
    args = ap.parse_args()
    require_release()
    print(header((1, 2)))
    print()
    rows = []
    prev = None
    for steps in (100, 200, 400, 800):
        e = trap_phase(steps)
        rows.append([steps, f"{e:.3e}", "" if prev is None else f"{np.log2(prev / e):.3f}"])
        prev = e
    print("Harmonic trap, Verlet: phase error after 10 periods (theory ω³dt²t/24)")
    print(table(["steps/period", "phase error (rad)", "order"], rows))
    print()
    rows = []
    for integ in ("verlet", "rk4"):
        prev = None
        for steps in (250, 500, 1000, 2000):
            err, worst, _, _ = kepler(integ, steps)
            rows.append([integ, steps, f"{err:.2e}", f"{worst:.2e}", "" if prev is None else f"{np.log2(prev / err):.2f}"])
            prev = err
    print("Kepler e = 0.5 around a fixed PointMasses: one orbit")
    print(table(["integrator", "steps/orbit", "|x(P) − x(0)|", "max |ΔE/E|", "order"], rows))
    print()
    rows = []
    prev = None
    for n in (21, 41, 81, 161, 321):
        h, du, df, dt_ = parabola(n)
        o = "" if prev is None else " / ".join(f"{np.log2(a / b):.2f}" for a, b in zip(prev, (du, df, dt_), strict=True))
        rows.append([f"{h:.5f}", f"{du:.2e}", f"{df:.2e}", f"{dt_:.2e}", o])
        prev = (du, df, dt_)
    print("φ = ½ω²x² (ω = 2) sampled every h: interpolation, force and period errors")
    print(table(["h (m)", "mean φ̃ − φ (J/kg)", "max |F/m + ω²x|", "T/T₀ − 1", "orders"], rows))
    print()
    rows = []
    for dim in (2, 3):
        prev = None
        for dt in (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4):
            w = np.abs(crossings(dim, dt)).max()
            rows.append([dim, dt, f"{w:.2e}", "" if prev is None else f"{np.log2(prev / w):.2f}"])
            prev = w
    print("200 particles in a bumpy well, 40 cells per axis, 20 s of Verlet: max |ΔE| / (K + |U|)")
    print(table(["dim", "dt (s)", "max energy error", "order"], rows))
    print()
    if not args.no_throughput:
        print("ns per particle per Verlet step (one force evaluation), N = 2·10⁵, 3D; (term alone)")
        print(table(["term", "threads 1", "threads 2"], throughput()))
        print()
    if args.figures:
        t0 = time.perf_counter()
        figures(str(Path(__file__).resolve().parents[2] / "docs" / "potentials"))
        print(f"figures written in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
