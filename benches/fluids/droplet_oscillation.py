"""Mode-2 oscillation of a DFSPH drop with surface tension (``Fluid(surface_tension=σ)``):
frequency and damping rate against Rayleigh's inviscid law and the viscous rate the fluid's
artificial viscosity stands for.

    python benches/fluids/droplet_oscillation.py [--dim 2] [--n 24,40] [--nu 0,1.6e-5,6.4e-5]
                                          [--eps 0.1] [--periods 2] [--seeds 1]

A drop of radius R (12 mm in 2D, 6 mm in 3D; water: ρ0 = 1000, σ = 0.072) is cut from the
lattice as an ellipse (ellipsoid) of axes R(1 + ε), R/(1 + ε) (3D: R(1 + ε), R/√(1 + ε) twice,
the same area or volume), at rest, no gravity. The signed mode-2 amplitude
``s = (I_xx − I_yy)/(I_xx + I_yy)`` (3D: ``(I_xx − (I_yy + I_zz)/2)/tr I``, from the
particles' second moments about the centre; ≈ 2ε at the start) is sampled 40 times a Rayleigh
period and fitted with ``c + A e^(−γt) cos(ωt + φ)`` over ``--periods`` periods.

* Rayleigh (1879), inviscid: 2D (a cylinder's cross-section, mode n) ``ω² = n(n² − 1) σ/(ρ0 R³)``;
  3D (mode l) ``ω² = l(l − 1)(l + 2) σ/(ρ0 R³)``; n = l = 2.
* Viscous amplitude decay for weak viscosity, from the dissipation of the potential flow
  (Lamb, Hydrodynamics, 1932, §355; Landau & Lifshitz, Fluid Mechanics, §25):
  3D ``γ = (l − 1)(2l + 1) ν/R²`` (5ν/R²); 2D, the same calculation with ``φ = A r^n cos nθ``
  (mean dissipation ``2π μ n²(n − 1) A² R^(2n−2)`` over the mode's energy
  ``½ π ρ0 n A² R^(2n)``, halved for the amplitude): ``γ = 2n(n − 1) ν/R²`` (4ν/R²), which
  tends to the plane wave's ``2νk²`` (k = n/R) for large n (derived here: no published 2D
  formula was found to cite).
* ``ν = α c0 h/(2(d + 2))`` (α c0 h/8 in 2D, /10 in 3D; Monaghan 2005), the kinematic viscosity the
  fluid's docstring gives its artificial viscosity. Each row's ν is set through the sound speed
  ``c0 = 2(d + 2) ν/(α h)`` with α = 0.1 (in DFSPH c0 only scales the viscosity), so rows at
  two resolutions have the same ν; ν = 0 runs with α = 0.

Columns: N particles across the diameter, R/h, the fitted ω over Rayleigh's, the fitted γ,
the viscous γ, their ratio; ``γ − γ₀`` over the viscous γ (γ₀: the row with ν = 0): the damping
the viscosity adds, against what its ν should add; the work of the viscosity (the Monaghan term,
recomputed here from positions and velocities) on the affine part of the flow (the mode-2
potential flow is a uniform strain) over ``2ρ0ν∫e:e`` of that strain, both summed over the run
(400 samples a period): 1 would be the continuum's dissipation of the mode; the kinetic energy of
the velocities' non-affine rest (particle-scale jitter) over the affine part's, summed over the
run; the kinetic energy the pressure projections removed over the run (``Scene.solver_stats``)
over the largest kinetic energy of the affine part; and the fitted constant c over s(0), the
deformation the drop keeps. With ``--seeds k`` each row gives the median and the range over k
drops whose lattices differ by 1e-9 m. Prints a Markdown table.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common

import argparse
import math
import time

import numpy as np
from scipy.optimize import curve_fit

import physcore as pc
from physcore.fluids import kernel_w, lattice

SIGMA = 0.072
RHO0 = 1000.0
ALPHA = 0.1
RADIUS = {2: 0.012, 3: 0.006}


def drop(dim: int, n: int, nu: float, eps: float, threads: int | None, seed: int = 0) -> tuple[pc.Scene, float]:
    """The elliptic (ellipsoidal) drop at rest, and its equivalent radius R; the lattice moved by
    1e-9 m at random with ``seed`` (0: not moved), as the Laplace tests' droplets."""
    r0 = RADIUS[dim]
    dx = 2 * r0 / n
    axes = np.array([1 + eps] + [(1 + eps) ** (-1 / (dim - 1))] * (dim - 1)) * r0
    half = axes[0] + 2 * dx
    x = lattice([-half] * dim, [half] * dim, dx)
    x = x[((x / axes) ** 2).sum(axis=1) <= 1.0]
    x = x - x.mean(axis=0)
    if seed:
        x = x + np.random.default_rng(seed).normal(0.0, 1e-9, x.shape)
    h = 1.3 * dx
    alpha = ALPHA if nu > 0 else 0.0
    c0 = 2 * (dim + 2) * nu / (ALPHA * h) if nu > 0 else 1.0
    scene = pc.Scene(dim, integrator="semi_implicit_euler", threads=threads)
    scene.add_fluid(x, spacing=dx, density=RHO0, sound_speed=c0, alpha=alpha, method="dfsph",
                    surface_tension=SIGMA)
    vol = len(x) * dx**dim
    r = math.sqrt(vol / math.pi) if dim == 2 else (3 * vol / (4 * math.pi)) ** (1 / 3)
    return scene, r


def mode2(positions: np.ndarray) -> float:
    """Signed mode-2 amplitude from the second moments about the centre."""
    p = positions - positions.mean(axis=0)
    m = (p**2).mean(axis=0)
    return float((m[0] - m[1:].mean()) / m.sum())


def rayleigh(dim: int, r: float) -> float:
    k = 6.0 if dim == 2 else 8.0  # n(n² − 1), l(l − 1)(l + 2) at 2
    return math.sqrt(k * SIGMA / (RHO0 * r**3))


def viscous_rate(dim: int, nu: float, r: float) -> float:
    return (4.0 if dim == 2 else 5.0) * nu / r**2  # 2n(n − 1), (l − 1)(2l + 1) at 2


def damped(t, c, a, gamma, omega, phase):
    return c + a * np.exp(-gamma * t) * np.cos(omega * t + phase)


def fit(t: np.ndarray, s: np.ndarray, omega0: float) -> tuple[float, float, float, float, float]:
    """(ω, γ, σ_ω, σ_γ, c/s(0)): least squares of ``damped``, started at Rayleigh's ω; c is the
    deformation the drop keeps."""
    p0 = (0.0, s[0], 1.0, omega0, 0.0)
    p, cov = curve_fit(damped, t, s, p0=p0, maxfev=20000)
    err = np.sqrt(np.diag(cov))
    c, _, gamma, omega, _ = p
    return abs(omega), gamma, err[3], err[2], c / s[0]


def affine_fit(x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares affine velocity field ``v ≈ G (x − x̄) + u`` (translation, rotation and
    the uniform strain that is the mode-2 potential flow): (its values at x, G)."""
    a = np.hstack([x - x.mean(axis=0), np.ones((len(x), 1))])
    coef, *_ = np.linalg.lstsq(a, v, rcond=None)
    return a @ coef, coef[:-1].T


def viscous_work_on_mode(scene: pc.Scene, v_aff: np.ndarray) -> float:
    """Power of the fluid's artificial viscosity (the Monaghan term of ``fluids.py``, approaching
    pairs only, densities by summation) on the affine part ``v_aff`` of the velocities, W."""
    f = scene.fluids[0]
    h, m, visc = f.h, f.particle_mass(), f.alpha * f.sound_speed
    x, v = scene.positions, scene.velocities
    i, j = pc.neighbors(x, 2.0 * h)
    d = x[i] - x[j]
    r2 = (d**2).sum(axis=1)
    r = np.sqrt(r2)
    w = m * kernel_w(r / h, h, scene.dim)
    rho = np.full(len(x), m * kernel_w(np.zeros(1), h, scene.dim)[0])
    rho += np.bincount(i, w, len(x)) + np.bincount(j, w, len(x))
    q = r / h
    sigma = 10 / (7 * math.pi * h**2) if scene.dim == 2 else 1 / (math.pi * h**3)
    dw = sigma / h * (-0.75 * np.clip(2 - q, 0, None) ** 2 + 3 * np.clip(1 - q, 0, None) ** 2)  # cubic spline W'
    vr = np.minimum(((v[i] - v[j]) * d).sum(axis=1), 0.0)
    pi = -visc * h * vr / ((r2 + 0.01 * h * h) * 0.5 * (rho[i] + rho[j]))
    # force on i: −m² Π ∇_i W_ij, on j the opposite; their power on v_aff, taken out as dissipation
    return float((m * m * pi * dw / r * ((v_aff[i] - v_aff[j]) * d).sum(axis=1)).sum())


def measure(dim: int, n: int, nu: float, eps: float, periods: float, threads: int | None, seed: int = 0) -> dict:
    scene, r = drop(dim, n, nu, eps, threads, seed)
    w_ray = rayleigh(dim, r)
    period = 2 * math.pi / w_ray
    ts, ss = [0.0], [mode2(scene.positions)]
    k_mode, k_jitter, p_visc, p_cont = [], [], [], []
    mass = scene.fluids[0].particle_mass()
    volume = len(scene.positions) * scene.fluids[0].spacing ** dim
    t0 = time.perf_counter()
    # The viscosity's power on the mode swings in sign with the jitter from one step to the next:
    # it is sampled 400 times a period (the shape 40 times).
    for k in range(1, int(round(400 * periods)) + 1):
        scene.advance(k * period / 400 - scene.time)
        v = scene.velocities
        v_aff, g = affine_fit(scene.positions, v)
        k_mode.append(0.5 * mass * (v_aff**2).sum())
        k_jitter.append(0.5 * mass * ((v - v_aff) ** 2).sum())
        if nu > 0:
            e = 0.5 * (g + g.T)
            p_cont.append(2 * RHO0 * nu * (e**2).sum() * volume)  # 2ρν∫e:e of the uniform strain
            p_visc.append(viscous_work_on_mode(scene, v_aff))
        if k % 10 == 0:
            ts.append(scene.time)
            ss.append(mode2(scene.positions))
    wall = time.perf_counter() - t0
    omega, gamma, d_omega, d_gamma, kept = fit(np.array(ts), np.array(ss), w_ray)
    st = scene.solver_stats()
    return {"dim": dim, "n": n, "particles": scene.n_particles, "R/h": r / scene.fluids[0].h, "nu": nu,
            "omega": omega, "omega_rayleigh": w_ray, "d_omega": d_omega, "gamma": gamma, "d_gamma": d_gamma,
            "gamma_visc": viscous_rate(dim, nu, r), "steps": scene.step_count, "wall_s": wall,
            "jitter": sum(k_jitter) / sum(k_mode), "kept": kept, "visc_share": sum(p_visc) / sum(p_cont) if p_cont else math.nan,
            "projections": (st["dissipated_density_solver"] + st["dissipated_divergence_solver"]) / max(k_mode),
            "unconverged": st["unconverged"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dim", type=int, default=2, choices=(2, 3))
    ap.add_argument("--n", default="24,40", help="resolutions: particles across the diameter")
    ap.add_argument("--nu", default="0,1.6e-5,6.4e-5", help="kinematic viscosities ν, m²/s (0: α = 0)")
    ap.add_argument("--eps", type=float, default=0.1, help="initial deformation ε (axes R(1 ± ε))")
    ap.add_argument("--periods", type=float, default=2.0, help="Rayleigh periods to run and fit")
    ap.add_argument("--seeds", type=int, default=1, help="drops per row, lattices moved by 1e-9 m at random (seed 0: not moved)")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    _common.require_release()
    print(_common.header(args.threads))
    print()
    print(f"{args.dim}D, σ = {SIGMA} N{'/m' if args.dim == 3 else ''}, ρ0 = {RHO0:g}, R = {RADIUS[args.dim] * 1e3:g} mm, "
          f"ε = {args.eps}, {args.periods:g} periods fitted, {args.seeds} seed(s) a row: median (range)")
    print()
    print("| N across | particles | R/h | ν (m²/s) | ω/ω_Rayleigh | γ (1/s) | γ_visc (1/s) | γ/γ_visc "
          "| (γ − γ₀)/γ_visc | viscosity's work on the mode / 2ρν∫e:e | K_jitter/K_mode | projections' dissipation / K_mode,max | c/s₀ "
          "| wall (s) |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")

    def spread(values: list[float], fmt: str) -> str:
        """The median, and the range over the seeds when there are several."""
        med = format(float(np.median(values)), fmt)
        return med if len(values) == 1 else f"{med} ({format(min(values), fmt)}–{format(max(values), fmt)})"

    for n in (int(v) for v in args.n.split(",")):
        gamma0 = None
        for nu in (float(v) for v in args.nu.split(",")):
            ms = [measure(args.dim, n, nu, args.eps, args.periods, args.threads, seed) for seed in range(args.seeds)]
            gammas = [m["gamma"] for m in ms]
            if nu == 0:
                gamma0 = float(np.median(gammas))
            m = ms[0]
            gv = m["gamma_visc"]
            row = [str(n), str(m["particles"]), f"{m['R/h']:.1f}", f"{nu:.2g}",
                   spread([m["omega"] / m["omega_rayleigh"] for m in ms], ".2f"), spread(gammas, ".2f"), f"{gv:.2f}"]
            if gv > 0:
                row.append(spread([g / gv for g in gammas], ".1f"))
                row.append(spread([(g - gamma0) / gv for g in gammas], ".1f") if gamma0 is not None else "–")
                row.append(spread([m["visc_share"] for m in ms], ".2f"))
            else:
                row += ["–", "–", "–"]
            row.append(spread([m["jitter"] for m in ms], ".1f"))
            row.append(spread([m["projections"] for m in ms], ".0f"))
            row.append(spread([m["kept"] for m in ms], "+.2f"))
            row.append(f"{sum(m['wall_s'] for m in ms):.0f}")
            print("| " + " | ".join(row) + " |", flush=True)

if __name__ == "__main__":
    main()
