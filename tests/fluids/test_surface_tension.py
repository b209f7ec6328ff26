"""Surface tension and adhesion of DFSPH fluids (``Fluid(surface_tension=, adhesion=)``;
Akinci, Akinci & Teschner, ACM TOG 32(6) 182, 2013; ``rust_core/src/sph/surface.rs``):

* a square blob relaxes to a circle (2D), a cube to a sphere (3D), with the books balanced;
* the Laplace pressure at the centre of droplets at rest against σ/R (2D) and 2σ/R (3D), at a σ,
  ρ0 and spacing other than those the model's factor was measured at: 2D droplets of R = 6 H
  within a factor of 2 each and 30 % on average, a 3D droplet of R = 2.9 H within 50 %;
* adhesion makes a drop spread on the floor; nothing goes through the walls;
* a 2D drop released as an ellipse rings near Rayleigh's frequency and damps 4–8 times faster than
  its viscosity explains: the model's limit, pinned (``docs/surface_tension.md``);
* determinism for 1 and 2 threads, save/load, bad input, and the two scenes.

Water-like units: ρ0 = 1000 kg/m³ (kg/m² in 2D), σ in N/m (N in 2D), millimetre drops.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore.fluids import lattice, tank_walls

RHO0 = 1000.0


def blob(n, *, dim=2, dx=1e-3, sigma=0.072, round_=False, threads=None, alpha=0.1, rho0=RHO0, c0=1.0,
         seed=0, **fluid):
    """A square (cube) of n particles a side, or the disc (ball) inside it, centred at 0, at rest,
    no gravity; the lattice moved by 1e-9 m at random with ``seed`` (0: not moved). Returns
    (scene, equivalent radius R)."""
    side = n * dx
    x = lattice([0.0] * dim, [side] * dim, dx) - side / 2
    if round_:
        x = x[np.linalg.norm(x, axis=1) <= side / 2]
    if seed:
        x = x + np.random.default_rng(seed).normal(0.0, 1e-9, x.shape)
    scene = pc.Scene(dim, integrator="semi_implicit_euler", threads=threads)
    # c0 only scales the viscosity (α c0 h) of a DFSPH fluid: 1 m/s gives ν ≈ 1.6e-5 m²/s.
    scene.add_fluid(x, spacing=dx, density=rho0, sound_speed=c0, alpha=alpha, method="dfsph",
                    surface_tension=sigma, **fluid)
    vol = len(x) * dx**dim
    r = math.sqrt(vol / math.pi) if dim == 2 else (3 * vol / (4 * math.pi)) ** (1 / 3)
    return scene, r


def shape(scene):
    """(largest/smallest principal second moment, outer radius spread): the outermost particle's
    distance from the centre in 16 (2D) or 26 (3D) directions, (max − min)/mean."""
    p = scene.positions - scene.positions.mean(axis=0)
    w = np.linalg.eigvalsh(p.T @ p / len(p))
    r = np.linalg.norm(p, axis=1)
    if p.shape[1] == 2:
        ang = np.arange(16) * 2 * np.pi / 16
        dirs = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    else:
        g = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)], float)
        dirs = g / np.linalg.norm(g, axis=1)[:, None]
    cos = (p / np.maximum(r, 1e-300)[:, None]) @ dirs.T
    outer = np.array([r[cos[:, k] > 0.95].max() for k in range(len(dirs))])
    return w.max() / w.min(), (outer.max() - outer.min()) / outer.mean()


# --------------------------------------------------------------------------- shapes
@pytest.mark.slow  # 10 s or more (tests/README.md)
@pytest.mark.parametrize("dim, n", [(2, 20), (3, 12)])
def test_a_square_relaxes_to_a_circle_and_a_cube_to_a_sphere(dim, n):
    """A 20 × 20 square (12³ cube) of water, 1 mm spacing, σ = 0.072, α = 0.5 (to damp the
    oscillation): its corners stick out by 41 % (73 %) of the inscribed radius at the start, a
    spread of 0.30 (0.47) of the outermost particles' distance over 16 (26) directions. Averaged
    over 0.5, 0.6, …, 1.0 s (one instant's spread moves by a particle's jitter: the 10³ cube
    this test first took read 2.0–4.5 % from one 0.1 s to the next) the spread is below 4 %
    (measured 2.2 % and 2.3 %) and the principal second moments within 6 % (measured 4.0 % and
    1.9 %: the drops freeze a little elongated). The energy the surface releases is booked (the
    surface forces' work against the solvers' and the viscosity's dissipation): the books
    balance to round-off, as there is no potential here for semi-implicit Euler to miss
    (measured 1e-13)."""
    scene, r = blob(n, dim=dim, alpha=0.5)
    _, spread0 = shape(scene)
    assert spread0 > 0.25  # the corners stick out
    shapes = []
    while scene.time < 1.0 - 1e-9:
        scene.advance(0.1)
        if scene.time > 0.5 - 1e-9:
            shapes.append(shape(scene))
    assert len(shapes) == 6
    aniso, spread = np.mean(shapes, axis=0)
    assert aniso < 1.06 and spread < 0.04, shapes
    assert abs(scene.energy_drift()) < 1e-9, scene.energy_drift()
    st = scene.solver_stats()
    assert st["unconverged"] == 0 and st["density_error_max"] <= 1e-3


def test_a_drop_conserves_momentum_and_the_surface_does_not_push_it():
    """Surface tension is a sum of pair forces (cohesion along x_ij, curvature along n_i − n_j,
    both antisymmetric with K_ij symmetric): a drop moving at 0.1 m/s keeps its momentum and its
    centre of mass moves uniformly while its shape oscillates."""
    scene, _ = blob(16, round_=True)
    scene.velocities = scene.velocities + np.array([0.1, 0.0])
    p0 = (scene.velocities.sum(axis=0)).copy()
    c0 = scene.positions.mean(axis=0)
    scene.advance(0.2)
    np.testing.assert_allclose(scene.velocities.sum(axis=0), p0, atol=1e-9 * len(scene.positions))
    np.testing.assert_allclose(scene.positions.mean(axis=0), c0 + np.array([0.1, 0.0]) * scene.time, atol=1e-9)


# --------------------------------------------------------------------------- Laplace
def core_pressure(scene, r, t_settle, t_end):
    """Mean pressure of the particles within R/2 of the centre, averaged over every step in
    [t_settle, t_end] (the solves' reading cycles over about 3 steps: sampling every few steps
    aliases it). ``Scene.pressure()`` of a fluid with surface tension is the mechanical
    pressure: the solvers' plus the surface forces' virial."""
    scene.advance(t_settle)
    ps = []
    while scene.time < t_end:
        scene.step(1)
        p = scene.positions
        core = np.linalg.norm(p - p.mean(axis=0), axis=1) < 0.5 * r
        ps.append(scene.pressure()[core].mean())
    return float(np.mean(ps))


def droplet_reading(dim, n, seed, *, sigma=0.03, dx=5e-4, rho0=800.0):
    """The disc (ball) of ``blob(n, round_=True, seed=seed)`` at rest, no gravity: the pressure
    at its centre averaged from 4 to 10 capillary times √(ρ0 R³/σ), over Laplace's σ/R (2D) or
    2σ/R (3D); and R/H (H = 2h = 2.6 Δx)."""
    scene, r = blob(n, dim=dim, dx=dx, sigma=sigma, round_=True, rho0=rho0, c0=0.5, seed=seed)
    tc = math.sqrt(rho0 * r**3 / sigma)  # capillary time
    p = core_pressure(scene, r, 4 * tc, 10 * tc)
    return p * r / ((1 if dim == 2 else 2) * sigma), r / (2.6 * dx)


@pytest.mark.slow  # 10 s or more (tests/README.md)
def test_laplace_pressure_of_2d_droplets():
    """Six 2D droplets of R = 6.2 H (32 particles across; σ = 0.03 N, 0.5 mm spacing, ρ0 = 800,
    a σ, ρ0 and spacing other than those the Laplace factor was measured at), started 1e-9 m
    apart: each reads σ/R within a factor of 2 and their geometric mean within 30 %.

    Measured: seeds 0–5 read 0.968, 1.002, 1.007, 1.079, 1.079, 0.892 (geometric mean 1.002;
    measured again 2026-11-30: the readings of an earlier build, 1.28, 1.23, 1.08, 0.96, 0.92,
    1.23, mean 1.11, had stood here); 13 droplets of this size 0.86–1.28, mean 1.10, and 4 of
    R = 8.5 H 0.93–1.17 (that earlier build). Each droplet freezes
    into its own packing, whose stress the reading carries: the Laplace pressure is the small
    difference of the solvers' pressure and the surface forces' virial, each 30 to 70 times
    σ/R (the cohesion's bulk tension), so a packing that changes either by 1 % moves the reading
    by half σ/R. Smaller droplets read high: R = 4.6 H 0.71–1.58 (16 droplets, mean 1.22),
    R = 3.1 H 0.86–2.58 (6, mean 1.54)."""
    readings = [droplet_reading(2, 32, seed)[0] for seed in range(6)]
    assert all(0.5 < q < 2.0 for q in readings), readings
    assert 1 / 1.3 < math.exp(np.mean(np.log(readings))) < 1.3, readings


@pytest.mark.slow  # 10 s or more (tests/README.md)
def test_laplace_pressure_of_a_3d_droplet():
    """A 3D droplet of R = 2.9 H (15 particles across, the 2D test's σ, ρ0 and spacing): 2σ/R
    within a factor of 1.5 (measured 1.13, and 1.11 on 2026-12-01; 3D has its own Laplace factor,
    measured on a droplet of R = 5.6 H; the fluid takes h = 1.3 Δx, a surface fluid's default,
    ``default_smoothing``). Smaller 3D droplets read high, as small 2D ones do: R = 2.2 H 1.49,
    R = 3.7 H 1.02. Two 3D droplets started 1e-9 m apart read within 1 % of each other (1.64
    and 1.65 with the 2D factor): a 3D droplet's core averages many more particles."""
    q, _ = droplet_reading(3, 15, 0)
    assert 1 / 1.5 < q < 1.5, q


# --------------------------------------------------------------------------- adhesion and walls
def drop_on_floor(adhesion, n=12, dx=2.5e-4):
    """A drop of radius n/2 spacings resting on the floor of a box under gravity, after 0.15 s:
    its contact width (the span of its bottom-row particles) and lowest particle height."""
    box = (40 * dx, 24 * dx)
    centre = np.array([box[0] / 2, n / 2 * dx + 1.5 * dx])
    x = lattice(centre - n / 2 * dx, centre + n / 2 * dx, dx)
    x = x[np.linalg.norm(x - centre, axis=1) <= n / 2 * dx]
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -9.81]))
    scene.add_fluid(x, spacing=dx, boundary=tank_walls([0, 0], box, dx, layers=3, top=True), method="dfsph",
                    alpha=0.1, sound_speed=0.5, surface_tension=0.072, adhesion=adhesion)
    scene.advance(0.15)
    p = scene.positions
    bottom = p[p[:, 1] < p[:, 1].min() + 0.5 * dx]
    return np.ptp(bottom[:, 0]), p[:, 1].min(), scene


def test_adhesion_spreads_a_drop_on_the_floor():
    """σ = 0.072: a 3 mm drop on the floor without adhesion sits on a narrow base; with
    adhesion = σ (complete wetting in the continuum) it spreads to a base at least 1.5 times
    wider. Neither goes into the wall (lowest particle at least a quarter spacing above the
    floor's top layer of wall particles)."""
    dx = 2.5e-4
    w0, low0, _ = drop_on_floor(0.0, dx=dx)
    w1, low1, s1 = drop_on_floor(0.072, dx=dx)
    assert w1 > 1.5 * w0, (w0, w1)
    # The floor's top wall layer is at −dx/2; adhesion draws the drop closer than the lattice's
    # first row (+dx/2), the mirrored pressure keeps it off the layer.
    assert min(low0, low1) > -0.25 * dx, (low0, low1)
    assert np.isfinite(s1.energy().total)


# --------------------------------------------------------------------------- determinism, files
def test_threads_give_the_same_bits_and_save_load_continues_exactly(tmp_path):
    runs = []
    for threads in (1, 2):
        scene, _ = blob(24, threads=threads)
        scene.advance(0.05)
        runs.append((scene.positions, scene.pressure(), scene.energy()))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]
    scene, _ = blob(12)
    scene.advance(0.02)
    path = scene.save(tmp_path / "drop.npz")
    copy = pc.Scene.load(path)
    assert copy.terms[0].surface_tension == 0.072
    scene.step(20)
    copy.step(20)
    np.testing.assert_array_equal(scene.positions, copy.positions)
    np.testing.assert_array_equal(scene.pressure(), copy.pressure())


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "kwargs, arg",
    [
        ({"surface_tension": -1.0}, "surface_tension"),
        ({"surface_tension": math.nan}, "surface_tension"),
        ({"adhesion": math.inf}, "adhesion"),
        ({"surface_tension": 0.07, "method": "wcsph"}, "surface_tension"),
        ({"adhesion": 0.07, "method": "wcsph"}, "adhesion"),
    ],
)
def test_bad_surface_arguments_are_refused_by_name(kwargs, arg):
    kw = {"method": "dfsph"} | kwargs
    with pytest.raises(ValueError, match=arg):
        pc.Fluid(lattice([0, 0], [0.01, 0.01], 1e-3), 1e-3, **kw)
    with pytest.raises(TypeError, match="surface_tension"):
        pc.Fluid(lattice([0, 0], [0.01, 0.01], 1e-3), 1e-3, method="dfsph", surface_tension="0.07")


def test_the_capillary_step_limit_applies():
    """0.25 √(ρ0 h³/(2π σ)) (Brackbill et al. 1992): quadrupling σ halves the step of a drop at
    rest without gravity (where nothing else limits it)."""
    dts = []
    for sigma in (0.02, 0.08):
        scene, _ = blob(8, sigma=sigma, alpha=0.0)
        dts.append(scene.suggest_dt())
    h = 1.3e-3
    assert dts[0] == pytest.approx(0.25 * math.sqrt(RHO0 * h**3 / (2 * math.pi * 0.02)), rel=1e-12)
    assert dts[1] == pytest.approx(dts[0] / 2, rel=1e-12)


# --------------------------------------------------------------------------- scenes
@pytest.mark.parametrize("name", ["droplets", "crown"])
def test_surface_tension_scenes(name):
    """Coarse versions of the two scenes run through their impacts: finite, the walls hold, the
    solvers converge, and they refuse integrators other than semi-implicit Euler by name."""
    fn = getattr(pc.scenes, name)
    scene = fn(n=80)
    t_end = 0.05 if name == "droplets" else 0.01
    while scene.time < t_end - 1e-12:
        scene.advance(t_end / 10)
    p = scene.positions
    assert np.isfinite(p).all()
    # The walls' innermost layer lies 2 spacings inside their outermost.
    # Two spacings of the droplets tank (0.04 m long); for the crown (0.07 m) a looser bound.
    lo = scene.boundary_points().min(axis=0) + 2 * 0.04 / 80
    assert (p > lo).all()
    st = scene.solver_stats()
    assert st["unconverged"] == 0
    with pytest.raises(ValueError, match="integrator"):
        fn(n=80, integrator="rk4")
    with pytest.raises(ValueError, match="radius"):
        fn(n=80, radius=1.0)
    if name == "droplets":  # drops side by side that would overlap (a reviewer's case)
        with pytest.raises(ValueError, match="drops"):
            fn(drops=20, radius=0.00145, tank=(0.06, 0.0059))


def test_a_drop_at_rest_without_gravity_needs_no_sound_speed():
    """With surface tension a fluid at rest still moves (capillary speed √(σ/(ρ0 h))): the sound
    speed, which a DFSPH fluid uses only to scale its viscosity, is estimated from it as
    10 × that speed, where without surface tension it must be given."""
    x = lattice([0, 0], [0.01, 0.01], 5e-4)
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add_fluid(x, spacing=5e-4, method="dfsph", surface_tension=0.072)
    h = 1.3 * 5e-4
    assert scene.fluids[0].sound_speed == pytest.approx(10 * math.sqrt(0.072 / (RHO0 * h)), rel=1e-12)
    with pytest.raises(ValueError, match="sound_speed"):
        pc.Scene(2, integrator="semi_implicit_euler").add_fluid(x, spacing=5e-4, method="dfsph")


# --------------------------------------------------------------------------- oscillation
def fit_damped(t, s, omega0):
    """(ω, γ) of the least-squares fit ``c + e^(−γt)(a cos ωt + b sin ωt)`` to s(t): the linear
    coefficients are solved for every (ω, γ) of a 41 × 41 grid (ω in [0.5, 1.5] ω0, γ in
    [0, 2 ω0]), and the grid is narrowed around the best point 6 times (to 1e-5 ω0)."""
    w_lo, w_hi, g_lo, g_hi = 0.5 * omega0, 1.5 * omega0, 0.0, 2.0 * omega0
    for _ in range(7):
        ws, gs = np.linspace(w_lo, w_hi, 41), np.linspace(g_lo, g_hi, 41)
        w, g = (a.ravel() for a in np.meshgrid(ws, gs, indexing="ij"))
        e = np.exp(-g[:, None] * t)
        basis = np.stack([np.ones_like(e), e * np.cos(w[:, None] * t), e * np.sin(w[:, None] * t)], axis=-1)
        bt = basis.transpose(0, 2, 1)
        coef = np.linalg.solve(bt @ basis, (bt @ s)[..., None])
        k = int(np.argmin((((basis @ coef)[..., 0] - s) ** 2).sum(axis=1)))
        dw, dg = 2 * (ws[1] - ws[0]), 2 * (gs[1] - gs[0])
        w_lo, w_hi, g_lo, g_hi = w[k] - dw, w[k] + dw, max(g[k] - dg, 0.0), g[k] + dg
    return float(w[k]), float(g[k])


def oscillating_drop(n, *, eps=0.1, seed=0, periods=2.0, alpha=0.1, c0=1.0, dx=1e-3, sigma=0.072):
    """A 2D drop of n particles across (σ = 0.072 N, ρ0 = 1000, Δx = 1 mm, α = 0.1, c0 = 1 m/s:
    ν = α c0 h/8 = 1.6e-5 m²/s), cut from the lattice as the ellipse of axes R(1 + ε), R/(1 + ε), at
    rest, no gravity; its mode-2 amplitude ``(I_xx − I_yy)/(I_xx + I_yy)`` sampled 40 times a
    Rayleigh period over ``periods`` and fitted (`fit_damped`). Returns (ω over Rayleigh's
    ``√(6σ/(ρ0 R³))``, γ over the viscous ``4ν/R²``), R the equivalent radius. See
    ``benches/fluids/droplet_oscillation.py`` and ``docs/surface_tension.md``."""
    r0 = n * dx / 2
    axes = np.array([r0 * (1 + eps), r0 / (1 + eps)])
    half = axes[0] + 2 * dx
    x = lattice([-half] * 2, [half] * 2, dx)
    x = x[((x / axes) ** 2).sum(axis=1) <= 1.0]
    x = x - x.mean(axis=0)
    if seed:
        x = x + np.random.default_rng(seed).normal(0.0, 1e-9, x.shape)
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add_fluid(x, spacing=dx, density=RHO0, sound_speed=c0, alpha=alpha, method="dfsph",
                    surface_tension=sigma)
    r = math.sqrt(len(x) * dx**2 / math.pi)
    omega_r = math.sqrt(6 * sigma / (RHO0 * r**3))
    gamma_v = 4 * alpha * c0 * 1.3 * dx / 8 / r**2

    def amplitude():
        m = ((scene.positions - scene.positions.mean(axis=0)) ** 2).mean(axis=0)
        return (m[0] - m[1]) / m.sum()

    period = 2 * math.pi / omega_r
    ts, ss = [0.0], [amplitude()]
    for k in range(1, int(round(40 * periods)) + 1):
        scene.advance(k * period / 40 - scene.time)
        ts.append(scene.time)
        ss.append(amplitude())
    omega, gamma = fit_damped(np.array(ts), np.array(ss), omega_r)
    return omega / omega_r, gamma / gamma_v


def test_a_2d_drop_oscillates_near_rayleigh_and_damps_about_six_times_faster_than_its_viscosity():
    """The model's limit, measured and pinned (``Fluid`` docstring, ``docs/surface_tension.md``): a
    2D drop of 24 particles across (R = 9.2 h), released as an ellipse of axes R(1 ± 0.1), rings
    at about Rayleigh's ``ω² = 6σ/(ρ0 R³)`` but its mode-2 amplitude decays 4–8 times faster than
    the viscous ``γ = 4ν/R²`` of its ``ν = α c0 h/8`` (cylinder analogue of Lamb 1932, §355).

    Measured over 30 drops (seeds 0–29, `oscillating_drop`): ω/ω_Rayleigh 0.71–1.03 (mean 0.91,
    sd 0.08), γ/γ_visc 4.4–8.1 (mean 5.9, sd 0.8); the median of three drops has sd 0.053 and
    0.49. Asserted on the median of seeds 1–3 (measured 0.92 and 5.1) about 3 of those sd either
    side of the mean: ω/ω_Rayleigh in [0.75, 1.1], γ/γ_visc in [4, 8]. Damping as physical as
    the viscosity's (γ/γ_visc near 1, or below 4) fails the test, as it should: the docstring's
    figures would then be wrong."""
    runs = [oscillating_drop(24, seed=seed) for seed in (1, 2, 3)]
    omega, gamma = np.median(runs, axis=0)
    assert 0.75 < omega < 1.1, runs
    assert 4.0 < gamma < 8.0, runs
