"""WCSPH fluids (``Scene.add_fluid``) checked against analytic and published results.

* hydrostatics: a settled layer has p = ρ0 g (surface − y) and stays within 1 % of ρ0;
* the dam break of Martin & Moyce (1952): the surge front against their measurements;
* exact mass, containment by the boundary-particle walls;
* conservation: the pair forces conserve linear and angular momentum to round-off;
* energy books: the drift is the integrator's error (first order for semi-implicit Euler,
  second for Verlet, through a wall impact);
* thread-count determinism, both kernels, 3D, the scenes, bad input.

Resolutions are coarse (the whole file runs in well under a minute on 2 cores); the tolerances
were chosen from measured errors at these resolutions, with margin, and each says why.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import physcore as pc
from physcore.fluids import Fluid, lattice, tank_walls

G = 9.81
RHO0 = 1000.0

#: Martin, J. C. & Moyce, W. J. (1952), "An experimental study of the collapse of liquid
#: columns on a rigid horizontal plane", Phil. Trans. R. Soc. Lond. A 244, 312–324, Tables 2
#: and 6: surge front of a column of width a and height 2a (n² = 2). Pairs (T, Z) with
#: T = t·√(2g/a) and Z = x/a, x measured from the back wall.
MARTIN_MOYCE_1952 = (
    (0.41, 1.11), (0.84, 1.22), (1.19, 1.44), (1.43, 1.67), (1.63, 1.89), (1.83, 2.11), (1.98, 2.33),
    (2.20, 2.56), (2.32, 2.78), (2.51, 3.00), (2.65, 3.22), (2.83, 3.44), (2.98, 3.67),
)
#: The experiment's time origin lags the instant of release: the columns were held by a
#: diaphragm that takes a finite time to clear the water, while the simulation releases the
#: column instantly. Comparisons with Martin & Moyce therefore commonly shift the simulated time by
#: +0.175 (Z_sim(T − 0.175) against Z_exp(T)); we do, and we print the unshifted errors too.
#: Unshifted, the simulated front leads the measurements by 10–17 % at T ≈ 1–1.5, more at finer
#: resolution, which is the gate's delay, not a resolution error.
MM_TIME_SHIFT = 0.175

#: Filled by test_dam_break_front_matches_martin_and_moyce for the report (kernel → rows).
MM_TABLES: dict = {}


# --------------------------------------------------------------------------- helpers
def column_scene(
    n: int,
    *,
    dim: int = 2,
    a: float = 0.25,
    tank=(5.0, 2.5),
    depth: float = 1.0,
    top: bool = False,
    precision: str = "f32",
    kernel: str = "cubic_spline",
    viscosity: float = 0.05,
    integrator: str = "semi_implicit_euler",
    threads=None,
):
    """A dam break: a column a × 2a (× depth·a in 3D) at rest in the corner of a tank
    tank[0]·a long and tank[1]·a tall, n particles across the column. Returns (scene, dx, upper
    corner of the tank)."""
    dx = a / n
    scene = pc.Scene(dim, integrator=integrator, threads=threads)
    g = [0.0] * dim
    g[-1] = -G
    scene.add(pc.Gravity(g))
    if dim == 2:
        lo, hi, up = [0, 0], [a, 2 * a], [tank[0] * a, tank[1] * a]
    else:
        lo, hi, up = [0, 0, 0], [a, depth * a, 2 * a], [tank[0] * a, depth * a, tank[1] * a]
    scene.add_fluid(
        lattice(lo, hi, dx),
        spacing=dx,
        boundary=tank_walls([0.0] * dim, up, dx, layers=3, top=top),
        pass_precision=precision,
        kernel=kernel,
        alpha=viscosity,
    )
    return scene, dx, np.array(up, dtype=float)


def front(x: np.ndarray, h: float, min_neighbours: int = 4) -> float:
    """The surge front: the largest x among particles with at least ``min_neighbours``
    neighbours within the kernel support 2h (so a lone spray particle does not count)."""
    i, j = pc.neighbors(x, 2.0 * h)
    count = np.bincount(i, minlength=len(x)) + np.bincount(j, minlength=len(x))
    return float(x[count >= min_neighbours, 0].max())


def penetration(x: np.ndarray, upper: np.ndarray, top: bool) -> float:
    """How far (m) any particle is past a wall face of the tank [0, upper] (open top unless
    ``top``); 0 if all are inside."""
    out = np.maximum(-x, 0.0)  # past the lower faces
    over = np.maximum(x - upper, 0.0)
    if not top:
        over[:, -1] = 0.0
    return float(max(out.max(), over.max()))


# --------------------------------------------------------------------------- hydrostatics
def test_hydrostatic_layer_pressure_and_density():
    """A water layer (0.5 × 0.5 m, 2D, 24 × 24 particles) settles in a tank; its time-averaged
    pressure then follows p = ρ0 g (surface − y) within 5 % (measured ≤ 2.5 %, slope 1 %) and its
    density stays within 1 % of ρ0 (measured: mean −0.4 %, bulk ≤ 0.4 %).

    Settling: the layer starts on the lattice at exactly ρ0 and falls into compression, which
    rings as sound waves of amplitude ~ρ0 c0 v. The artificial viscosity is raised to α = 0.5 (the
    physics stays the same; only the acoustic ringing decays faster), the layer rings down for
    1 s (≈ 60 acoustic transits of the layer), and pressure and positions are averaged over the
    next 1 s so the residual ringing averages out. Nothing else damps the motion.

    Compared: bins of two particle rows from 4h above the floor to 3h below the surface. Near the
    floor the boundary-particle wall term (Akinci 2012, eq. 10: p_i/ρ_i² only, no mirrored
    pressure) makes the first row's pressure 2–2.5× hydrostatic, a property of that model; near
    the surface the kernel is truncated and the pressure is clamped at 0.
    """
    W, H, n = 0.5, 0.5, 24
    dx = H / n
    h = 1.3 * dx
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(
        lattice([0, 0], [W, H], dx), spacing=dx, boundary=tank_walls([0, 0], [W, H + 0.1], dx),
        alpha=0.5, pass_precision="f32",
    )
    mass0 = scene.masses.sum()
    scene.advance(1.0)
    ps, xs, rhos = [], [], []
    for _ in range(100):
        scene.advance(0.01)
        ps.append(scene.pressure())
        xs.append(scene.positions)
        rhos.append(scene.density())
    p, x, rho = np.mean(ps, axis=0), np.mean(xs, axis=0), np.mean(rhos, axis=0)
    assert scene.masses.sum() == mass0
    assert abs(scene.energy().kinetic) < 1e-3 * RHO0 * G * H * H * W / 2  # settled: KE ≪ PE scale

    surface = x[:, 1].max() + dx / 2
    inner = (x[:, 0] > 3 * dx) & (x[:, 0] < W - 3 * dx)
    edges = np.arange(4 * h, surface - 3 * h, 2 * dx)
    assert len(edges) >= 6

    # Density: weakly compressible: on average within 1 % of ρ0, and so is every particle of the
    # bulk (the first rows on the floor reach +1.3 %, the wall-term effect above).
    rel = rho / RHO0 - 1.0
    bulk = inner & (x[:, 1] >= edges[0]) & (x[:, 1] < edges[-1])
    assert abs(rel.mean()) < 0.01, rel.mean()
    assert np.abs(rel[bulk]).max() < 0.01, np.abs(rel[bulk]).max()
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=False):
        m = inner & (x[:, 1] >= lo) & (x[:, 1] < hi)
        y = x[m, 1].mean()
        expect = RHO0 * G * (surface - y)
        rows.append((y, p[m].mean(), expect, p[m].mean() / expect - 1.0))
    table = "\n".join(f"  y={y:.4f} p={pm:8.1f} ρ0g(s−y)={pe:8.1f} err={e:+.3%}" for y, pm, pe, e in rows)
    slope = np.polyfit(x[bulk, 1], p[bulk], 1)[0]
    print(
        f"\nhydrostatic layer, surface {surface:.4f} m; density: mean error {rel.mean():+.3%}, bulk "
        f"max |error| {np.abs(rel[bulk]).max():.3%}; dp/dy = {slope:.1f} Pa/m "
        f"({-slope / (RHO0 * G) - 1:+.2%} from −ρ0 g):\n{table}"
    )
    worst = max(abs(r[3]) for r in rows)
    assert worst < 0.05, f"binned pressure off by {worst:.1%}:\n{table}"
    # Slope of p(y) over the same region: −ρ0 g within 5 %.
    assert abs(-slope / (RHO0 * G) - 1.0) < 0.05, slope


# --------------------------------------------------------------------------- dam break
@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland_c2"])
def test_dam_break_front_matches_martin_and_moyce(kernel):
    """Martin & Moyce (1952), column a × 2a, 20 particles across a: the front position over
    T = 0..3 within 15 % of every measured point (with the gate shift, see MM_TIME_SHIFT).
    Measured worst error at this resolution: 10 % (the first point, T = 0.41, where the gate
    matters most); the others are within 5 %. Also: mass exact, nothing leaves the tank."""
    a, n = 0.25, 20
    scene, dx, upper = column_scene(n, a=a, kernel=kernel)
    h = 1.3 * dx
    mass0 = scene.masses.sum()
    tscale = math.sqrt(2 * G / a)
    ts, zs = [0.0], [1.0]
    worst_pen = 0.0
    while ts[-1] < MARTIN_MOYCE_1952[-1][0] + 0.05:
        scene.advance(0.05 / tscale)
        x = scene.positions
        ts.append(scene.time * tscale)
        zs.append(front(x, h) / a)
        worst_pen = max(worst_pen, penetration(x, upper, top=False))
    assert scene.masses.sum() == mass0
    assert np.isfinite(scene.positions).all()
    # The front never reaches the far wall (Z = 5) within T = 3.
    assert max(zs) < upper[0] / a - 0.5
    # No particle leaves the tank. Walls repel through p_i (Akinci 2012), so a free-surface
    # particle with clamped p = 0 can sink into the first wall layer (half a spacing past the
    # face) before its density builds up; measured ≤ 0.4 dx; none may reach 1 dx.
    assert worst_pen < dx, f"a particle went {worst_pen / dx:.2f} spacings past a wall face"

    t_exp = np.array([T for T, _ in MARTIN_MOYCE_1952])
    z_exp = np.array([Z for _, Z in MARTIN_MOYCE_1952])
    z_sim = np.interp(t_exp - MM_TIME_SHIFT, ts, zs)
    z_raw = np.interp(t_exp, ts, zs)
    err = z_sim / z_exp - 1.0
    err_raw = z_raw / z_exp - 1.0
    MM_TABLES[kernel] = list(zip(t_exp, z_exp, z_sim, err, z_raw, err_raw, strict=False))
    table = "\n".join(
        f"  {T:5.2f} {ze:5.2f} {zs_:6.3f} {e:+7.2%}   {zr:6.3f} {er:+7.2%}"
        for T, ze, zs_, e, zr, er in MM_TABLES[kernel]
    )
    print(
        f"\nMartin & Moyce 1952 vs {kernel}, n={n} ({scene.n_particles} particles):\n"
        f"      T Z_exp  Z_sim(T-{MM_TIME_SHIFT}) err   Z_sim(T) err(unshifted)\n{table}"
    )
    assert np.abs(err).max() < 0.15, f"worst {np.abs(err).max():.1%}:\n{table}"
    # The surge really moves: ~4a over the window, not stuck or exploding.
    assert 3.0 < zs[-1] < 4.6


def test_dam_break_impact_in_a_closed_tank_keeps_mass_and_particles():
    """A dam break that hits the far wall, runs up it and splashes onto the lid (T = 0..8):
    total mass exact and no particle through a wall (closed tank, 4a × 3a)."""
    a, n = 0.25, 16
    scene, dx, upper = column_scene(n, a=a, tank=(4.0, 3.0), top=True)
    mass0 = scene.masses.copy()
    tscale = math.sqrt(2 * G / a)
    worst_pen, reached = 0.0, 0.0
    while scene.time * tscale < 8.0 - 1e-9:
        scene.advance(0.1 / tscale)
        x = scene.positions
        worst_pen = max(worst_pen, penetration(x, upper, top=True))
        reached = max(reached, x[:, 0].max())
    assert np.array_equal(scene.masses, mass0)
    assert reached > upper[0] - 2 * dx  # it did hit the far wall
    # The wall is 3 layers (3 dx) thick. Spray hitting the lid has clamped p = 0 and meets no
    # wall force until its density builds up inside the first layer: measured 0.5–0.93 dx past
    # the face for 14–20 particles across, f32 and f64. None may reach the second layer (1.5 dx).
    assert worst_pen < 1.5 * dx, f"a particle went {worst_pen / dx:.2f} spacings past a wall face"
    assert abs(scene.energy_drift()) < 5e-3


# --------------------------------------------------------------------------- conservation
def _blob(dim, precision, viscosity, *, gravity=False, seed=1, integrator="semi_implicit_euler"):
    """A free blob of fluid (no walls) with random velocities; sound speed given."""
    rng = np.random.default_rng(seed)
    dx = 0.05
    x = lattice([0.0] * dim, [0.5 if dim == 2 else 0.3] * dim, dx)
    x = x + rng.uniform(-0.1, 0.1, x.shape) * dx
    v = rng.normal(scale=0.5, size=x.shape)
    scene = pc.Scene(dim, integrator=integrator, dt=5e-4)
    if gravity:
        g = [0.0] * dim
        g[-1] = -G
        scene.add(pc.Gravity(g))
    scene.add_fluid(x, velocities=v, spacing=dx, sound_speed=10.0, alpha=viscosity, pass_precision=precision)
    return scene


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("viscosity", [0.0, 0.5])
@pytest.mark.parametrize("precision", ["f64", "f32"])
def test_pair_forces_conserve_linear_and_angular_momentum(dim, viscosity, precision):
    """Pressure and artificial viscosity are pairwise, antisymmetric and central: with no walls
    and no gravity, total momentum and angular momentum stay at their initial values to
    round-off over 300 violent steps (measured 1e-17 relative in f64, 1e-10 in f32, whose pass
    arithmetic rounds each particle's force sum to 24 bits)."""
    scene = _blob(dim, precision, viscosity)
    scale_p = float((scene.masses[:, None] * np.abs(scene.velocities)).sum())
    r = np.linalg.norm(scene.positions, axis=1)
    scale_l = float((scene.masses * r * np.linalg.norm(scene.velocities, axis=1)).sum())
    p0, l0 = scene.momentum(), np.asarray(scene.angular_momentum())
    scene.step(300)
    tol = 1e-13 if precision == "f64" else 1e-8
    assert np.abs(scene.momentum() - p0).max() < tol * scale_p
    assert np.abs(np.asarray(scene.angular_momentum()) - l0).max() < tol * scale_l * 10
    # The fluid did something: density changed, and viscosity dissipated where on.
    assert np.ptp(scene.density()) > 1.0
    if viscosity:
        assert scene.energy().dissipated["fluid"] > 0


@pytest.mark.parametrize("precision", ["f64", "f32"])
def test_with_gravity_momentum_changes_only_by_the_gravity_impulse(precision):
    scene = _blob(2, precision, 0.1, gravity=True)
    p0 = scene.momentum()
    scale = float((scene.masses[:, None] * np.abs(scene.velocities)).sum())
    scene.step(300)
    impulse = scene.masses.sum() * np.array([0.0, -G]) * scene.time
    tol = 1e-12 if precision == "f64" else 1e-8
    assert np.abs(scene.momentum() - p0 - impulse).max() < tol * (scale + np.abs(impulse).max())


# --------------------------------------------------------------------------- energy books
def _max_drift(integrator: str, refine: int, t_end_T: float = 5.0) -> float:
    """Largest |energy_drift| over a dam break (a = 0.25 m, 12 across, tank 4a) to
    T = t_end_T, i.e. through the impact on the far wall (T ≈ 3.3), at dt = CFL / refine."""
    a = 0.25
    scene, _, _ = column_scene(12, a=a, tank=(4.0, 3.0), precision="f64", integrator=integrator)
    scene.dt = scene.dt / refine
    steps = int(round(t_end_T / math.sqrt(2 * G / a) / scene.dt))
    worst = 0.0
    for _ in range(10):
        scene.step(steps // 10)
        worst = max(worst, abs(scene.energy_drift()))
    assert scene.energy().dissipated["fluid"] > 0.05 * scene.energy().kinetic  # viscosity at work
    return worst


def test_energy_drift_is_second_order_for_verlet():
    """The books balance to the integrator's error: for velocity Verlet the worst drift over the
    run falls as dt², through the wall impact. Measured (max over the run) at dt = CFL, CFL/2,
    CFL/4: 9.65e-5, 2.83e-5, 7.1e-6 (observed order 1.9), alike at scalar, avx2 and avx512
    (2026-12-03; the guards were 3e-4 on the first alone until then)."""
    d = [_max_drift("verlet", k) for k in (1, 2, 4)]
    order = math.log2(d[0] / d[2]) / 2
    print(f"\nverlet dam-break max |drift| at dt = CFL, CFL/2, CFL/4: {d} (order {order:.2f})")
    assert d[0] < 1.5e-4 and d[2] < 1.2e-5, d
    assert 1.6 < order < 2.4, d
    assert d[0] / d[1] > 2.5 and d[1] / d[2] > 2.5, d  # each halving: far better than first order


def test_energy_drift_is_first_order_for_semi_implicit_euler():
    """Semi-implicit Euler: the worst drift halves with dt. Measured 5.13e-4, 2.30e-4 (order
    1.2), alike at scalar, avx2 and avx512 (2026-12-03; the guard was 2e-3 on the first alone)."""
    d = [_max_drift("semi_implicit_euler", k) for k in (1, 2)]
    order = math.log2(d[0] / d[1])
    print(f"\nsemi-implicit Euler dam-break max |drift| at dt = CFL, CFL/2: {d} (order {order:.2f})")
    assert d[0] < 8e-4 and d[1] < 4e-4, d
    assert 0.7 < order < 1.5, d


# --------------------------------------------------------------------------- determinism
@pytest.mark.parametrize(
    "dim, precision, kernel",
    [
        (2, "f32", "cubic_spline"),
        (2, "f64", "cubic_spline"),
        (2, "f32", "wendland_c2"),
        (2, "f64", "wendland_c2"),
        (3, "f32", "cubic_spline"),
        (3, "f64", "wendland_c2"),
    ],
)
def test_thread_count_does_not_change_a_single_bit(dim, precision, kernel):
    """4608 (2D) or 4096 (3D) particles, above the parallel threshold, after 40 steps of a dam
    break: threads=1 and threads=2 agree bit for bit, energy books included."""
    n = 48 if dim == 2 else 16
    runs = []
    for threads in (1, 2):
        scene, _, _ = column_scene(n, dim=dim, depth=0.5, tank=(4.0, 3.0), precision=precision, kernel=kernel, threads=threads)
        assert scene.threads == threads and scene.n_particles >= 4096
        x0 = scene.positions
        scene.step(40)
        runs.append((scene.positions, scene.velocities, scene.energy(), scene.density(), scene.pressure()))
    (x1, v1, e1, r1, p1), (x2, v2, e2, r2, p2) = runs
    assert not np.array_equal(x1, x0)  # it moved
    assert np.array_equal(x1, x2) and np.array_equal(v1, v2)
    assert np.array_equal(r1, r2) and np.array_equal(p1, p2)
    assert e1 == e2


# --------------------------------------------------------------------------- 3D
@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland_c2"])
def test_3d_dam_break_front_mass_and_walls(kernel):
    """The column a × a/2 × 2a spanning the tank's depth (free-slip side walls, so the flow is the
    2D one): 8 particles across a. The front against Martin & Moyce within 10 % from T = 0.84 on
    (measured ≤ 6 %) and 20 % at T = 0.41 (14 %); mass exact; nothing leaves the tank (measured
    ≤ 0.7 dx past a face at this coarse resolution, the thin front sinking into the floor's first
    wall layer; the second layer, 1.5 dx, is never reached)."""
    a, n = 0.25, 8
    scene, dx, upper = column_scene(n, dim=3, a=a, tank=(5.0, 2.5), depth=0.5, kernel=kernel)
    assert scene.n_particles == n * (n // 2) * 2 * n
    h = 1.3 * dx
    mass0 = scene.masses.sum()
    tscale = math.sqrt(2 * G / a)
    ts, zs, worst_pen = [0.0], [1.0], 0.0
    while ts[-1] < 3.05:
        scene.advance(0.05 / tscale)
        x = scene.positions
        ts.append(scene.time * tscale)
        zs.append(front(x, h) / a)
        worst_pen = max(worst_pen, penetration(x, upper, top=False))
    assert scene.masses.sum() == mass0
    assert worst_pen < 1.5 * dx, f"{worst_pen / dx:.2f} spacings past a face"  # not to the 2nd layer
    z_sim = np.interp([T - MM_TIME_SHIFT for T, _ in MARTIN_MOYCE_1952], ts, zs)
    err = z_sim / np.array([Z for _, Z in MARTIN_MOYCE_1952]) - 1.0
    assert abs(err[0]) < 0.20, err
    assert np.abs(err[1:]).max() < 0.10, err
    assert abs(scene.energy_drift()) < 1e-3


def test_3d_blob_falls_freely_and_keeps_its_density():
    """A free 3D blob under gravity, no walls: its centre of mass falls as g t²/2 exactly (internal
    forces cancel) and its particles stay near ρ0 (it is at rest internally)."""
    dx = 0.05
    scene = pc.Scene(3, integrator="verlet")
    scene.add(pc.Gravity([0.0, 0.0, -G]))
    ids = scene.add_fluid(lattice([0, 0, 0], [0.3, 0.3, 0.3], dx), spacing=dx, kernel="wendland_c2")
    z0 = scene.positions[:, 2].mean()
    scene.advance(0.2)
    z = scene.positions[:, 2].mean()
    assert math.isclose(z0 - z, 0.5 * G * scene.time**2, rel_tol=1e-9)
    assert len(ids) == 216
    rho = scene.density()
    assert rho.max() < 1.01 * RHO0  # no compression (pressure clamped at 0 at the free surface)


# --------------------------------------------------------------------------- the scenes
def test_dam_break_scene():
    s = pc.scenes.dam_break(n=12)
    assert s.n_particles == 2 * 12 * 12
    assert s.integrator == "semi_implicit_euler"
    f = s.fluids[0]
    assert f.pass_precision == "f32" and f.kernel == "cubic_spline" and f.method == "dfsph"
    assert math.isclose(f.sound_speed, 10 * math.sqrt(2 * G * 2.0), rel_tol=1e-12)
    walls = s.boundary_points()
    assert walls[:, 0].min() < 0 and walls[:, 0].max() > 4.0 and walls[:, 1].min() < 0
    assert walls[:, 1].max() > 3.0  # closed by a lid by default
    assert pc.scenes.dam_break(n=12, lid=False).boundary_points()[:, 1].max() < 3.0
    x = s.positions
    assert x[:, 0].max() < 1.0 and x[:, 1].max() < 2.0 and x.min() > 0
    m = s.masses.sum()
    s.advance(0.2)
    assert s.masses.sum() == m
    assert s.positions[:, 0].max() > 1.2  # the surge is on its way
    assert "water" in s.energy().potential
    d = pc.scenes.dam_break.render_defaults
    assert d["frames"] / d["fps"] >= 4.0
    assert d["substeps"] == "auto" and d["color_by"] == "speed"
    # 120 frames cover T = t·√(2g/width) = 0..4 for the default width 1 m: past the impact on
    # the far wall (T ≈ 3.3), within a few minutes of rendering.
    assert 3.5 < d["frames"] * d["frame_time"] * math.sqrt(2 * G) < 9.0


def test_dam_break_scene_3d_and_options():
    s = pc.scenes.dam_break(dim=3, n=6, depth=0.5, kernel="wendland_c2", pass_precision="f64", threads=1)
    assert s.dim == 3 and s.n_particles == 6 * 3 * 12
    assert s.fluids[0].kernel == "wendland_c2" and s.threads == 1
    assert s.positions[:, 1].max() < 0.5
    s.advance(0.05)
    assert np.isfinite(s.positions).all()
    s2 = pc.scenes.dam_break(n=8, dt=1e-5, integrator="verlet", sound_speed=30.0, method="wcsph")
    assert s2.dt == 1e-5 and s2.integrator == "verlet" and s2.fluids[0].sound_speed == 30.0


def test_drop_scene():
    s = pc.scenes.drop(n=40)
    dx = 2.0 / 40
    x = s.positions
    pool = x[:, 1] < 0.6
    assert pool.sum() == 40 * 12
    assert (~pool).sum() == 8 * 8  # the block, above the pool
    assert x[~pool, 1].min() > 0.6 + 0.6 - dx
    s.advance(0.45)  # the block has fallen 0.6 m and hit the pool
    assert s.positions[:, 1].max() < 1.6
    assert s.pressure().max() > 0
    assert pc.scenes.drop.render_defaults["surface"]  # the water drawn as one surface
    s3 = pc.scenes.drop(dim=3, n=12)
    assert s3.dim == 3 and s3.n_particles > 0
    dry = pc.scenes.drop(n=20, pool=0.0)
    assert dry.n_particles == 4 * 4
    # method="dfsph": the same water, incompressible; the block hits the pool as it does in
    # WCSPH (it falls freely: within a spacing of the same lowest point at 0.3 s), in fewer steps.
    assert s.fluids[0].method == "dfsph"  # the default with the default integrator
    w, d = pc.scenes.drop(n=40, method="wcsph"), pc.scenes.drop(n=40)
    assert d.fluids[0].method == "dfsph" and d.n_particles == w.n_particles
    steps = [sc.advance(0.3) for sc in (w, d)]
    assert steps[1] < steps[0] / 4
    block = np.arange(w.n_particles) >= 40 * 12
    assert abs(w.positions[block, 1].min() - d.positions[block, 1].min()) < dx
    with pytest.raises(ValueError, match="method"):
        pc.scenes.drop(n=20, method="iisph")
    with pytest.raises(ValueError, match="semi_implicit_euler"):
        pc.scenes.drop(n=20, method="dfsph", integrator="verlet")


def test_fluid_scenes_are_registered_and_their_examples_run():
    import doctest

    assert pc.scenes.REGISTRY["dam_break"] is pc.scenes.dam_break
    assert pc.scenes.REGISTRY["drop"] is pc.scenes.drop
    result = doctest.testmod(pc.scenes, verbose=False)
    assert result.failed == 0 and result.attempted >= 2


@pytest.mark.parametrize(
    "fn, kwargs, exc, arg",
    [
        ("dam_break", {"dim": 4}, ValueError, "dim"),
        ("dam_break", {"dim": 2.0}, TypeError, "dim"),
        ("dam_break", {"n": 1}, ValueError, "n"),
        ("dam_break", {"n": 10.5}, TypeError, "n"),
        ("dam_break", {"width": 0.0}, ValueError, "width"),
        ("dam_break", {"height": -1.0}, ValueError, "height"),
        ("dam_break", {"width": 5.0}, ValueError, "tank"),
        ("dam_break", {"height": 4.0}, ValueError, "tank"),
        ("dam_break", {"tank": (4.0,)}, ValueError, "tank"),
        ("dam_break", {"tank": "wide"}, TypeError, "tank"),
        ("dam_break", {"tank": (4.0, float("nan"))}, ValueError, "tank"),
        ("dam_break", {"dim": 3, "depth": 0.0}, ValueError, "depth"),
        ("dam_break", {"n": 4, "pass_precision": "f16"}, ValueError, "pass_precision"),
        ("dam_break", {"n": 4, "kernel": "gauss"}, ValueError, "kernel"),
        ("dam_break", {"n": 4, "alpha": -1.0}, ValueError, "alpha"),
        ("dam_break", {"n": 4, "sound_speed": 0.0}, ValueError, "sound_speed"),
        ("dam_break", {"n": 4, "integrator": "leapfrog"}, ValueError, "integrator"),
        ("dam_break", {"lid": "yes"}, TypeError, "lid"),
        ("drop", {"pool": -0.1}, ValueError, "pool"),
        ("drop", {"fall": float("inf")}, ValueError, "fall"),
        ("drop", {"block": 3.0}, ValueError, "block"),
        ("drop", {"pool": 1.5}, ValueError, "tank"),
        ("drop", {"n": 2}, ValueError, "n"),
    ],
)
def test_fluid_scene_arguments_are_validated(fn, kwargs, exc, arg):
    with pytest.raises(exc) as info:
        getattr(pc.scenes, fn)(**kwargs)
    assert re.search(rf"\b{arg}\b", str(info.value)), f"message does not name {arg!r}: {info.value}"


# --------------------------------------------------------------------------- bad input
def _tank_scene():
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-3)
    s.add(pc.Gravity([0.0, -G]))
    s.add_fluid(lattice([0, 0], [0.1, 0.1], 0.01), spacing=0.01, boundary=tank_walls([0, 0], [0.2, 0.2], 0.01))
    s.step(3)
    return s


def _state(s):
    return (s.n_particles, s.positions.tobytes(), s.velocities.tobytes(), s.masses.tobytes(),
            tuple(t.name for t in s.terms), s.dt, s.step_count, s.energy(), len(s.boundary_points()))


GOOD = {"positions": lattice([0.0, 0.12], [0.05, 0.17], 0.01), "spacing": 0.01}


@pytest.mark.parametrize(
    "change, exc, arg",
    [
        ({"positions": [[0.0, np.nan]]}, ValueError, "positions"),
        ({"positions": np.zeros((3, 4))}, ValueError, "positions"),
        ({"positions": np.zeros((3, 3))}, ValueError, "positions"),  # 3D fluid in a 2D scene
        ({"positions": [["a", "b"]]}, TypeError, "positions"),
        ({"positions": np.zeros((2, 2), dtype=bool)}, TypeError, "positions"),
        ({"spacing": 0.0}, ValueError, "spacing"),
        ({"spacing": -0.01}, ValueError, "spacing"),
        ({"spacing": np.inf}, ValueError, "spacing"),
        ({"spacing": "0.01"}, TypeError, "spacing"),
        ({"velocities": np.zeros((3, 2))}, ValueError, "velocities"),
        ({"velocities": np.full((25, 2), np.nan)}, ValueError, "velocities"),
        ({"density": 0.0}, ValueError, "density"),
        ({"density": np.nan}, ValueError, "density"),
        ({"sound_speed": -5.0}, ValueError, "sound_speed"),
        ({"sound_speed": "fast"}, TypeError, "sound_speed"),
        ({"alpha": -0.1}, ValueError, "alpha"),
        ({"alpha": None}, TypeError, "alpha"),
        ({"smoothing": 0.0}, ValueError, "smoothing"),
        ({"kernel": "gaussian"}, ValueError, "kernel"),
        ({"kernel": 3}, ValueError, "kernel"),
        ({"gamma": 0}, ValueError, "gamma"),
        ({"gamma": 16}, ValueError, "gamma"),
        ({"gamma": 7.0}, TypeError, "gamma"),
        ({"clamp_pressure": "yes"}, TypeError, "clamp_pressure"),
        ({"mass": 0.0}, ValueError, "mass"),
        ({"boundary": np.zeros((4, 3))}, ValueError, "boundary"),
        ({"boundary": [[0.0, np.inf]]}, ValueError, "boundary"),
        ({"boundary": np.zeros((4, 2)), "boundary_volume": "mirror"}, ValueError, "boundary_volume"),
        ({"boundary": np.zeros((4, 2)), "boundary_volume": -1.0}, ValueError, "boundary_volume"),
        ({"boundary": np.zeros((4, 2)), "boundary_volume": np.ones(3)}, ValueError, "boundary_volume"),
        ({"boundary": np.zeros((4, 2)), "boundary_volume": ["a"] * 4}, TypeError, "boundary_volume"),
        ({"pass_precision": "f16"}, ValueError, "pass_precision"),
        ({"name": ""}, TypeError, "name"),
        ({"bogus": 1}, TypeError, "bogus"),
    ],
)
def test_add_fluid_bad_input_raises_before_anything_changes(change, exc, arg):
    s = _tank_scene()
    before = _state(s)
    kwargs = {**GOOD, **change}
    positions = kwargs.pop("positions")
    with pytest.raises(exc) as info:
        s.add_fluid(positions, **kwargs)
    assert re.search(rf"\b{arg}\b", str(info.value)), f"message does not name {arg!r}: {info.value}"
    assert _state(s) == before
    # The same through Fluid + Scene.add: refused when the Fluid is made (or added).
    with pytest.raises(exc):
        s.add(Fluid(positions, **kwargs))
    assert _state(s) == before
    s.step(1)  # and the scene still works


def test_fluid_at_rest_without_gravity_needs_a_sound_speed():
    s = pc.Scene(2)
    with pytest.raises(ValueError, match="sound_speed"):
        s.add_fluid(lattice([0, 0], [0.1, 0.1], 0.01), spacing=0.01)
    assert s.n_particles == 0 and not s.terms
    s.add_fluid(lattice([0, 0], [0.1, 0.1], 0.01), spacing=0.01, sound_speed=5.0)
    assert s.n_particles == 100


def test_advance_bad_duration():
    s = _tank_scene()
    before = _state(s)
    for bad, exc in ((0.0, ValueError), (-1.0, ValueError), (np.nan, ValueError), ("1", TypeError), (True, TypeError)):
        with pytest.raises(exc, match="duration"):
            s.advance(bad)
    assert _state(s) == before


def test_one_fluid_does_not_warn():
    scene = pc.Scene(dim=2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -9.81]))
    scene.add_fluid(lattice([0, 0], [0.1, 0.1], 0.02), spacing=0.02)  # filterwarnings = error
    assert len(scene.fluids) == 1
