"""Potential fields fixed in space: PointMasses, PointCharges, HarmonicTrap, PotentialGrid.

Each is checked against its analytic solution (trap frequency, Kepler orbit, Coulomb's law,
interpolation of sampled fields) at the convergence order the integrator or the interpolation
predicts, plus the energy books, thread-count independence, argument checks and save/load.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

import physcore as pc

TAU = 2.0 * np.pi


def _one_euler_step_acceleration(scene: pc.Scene) -> np.ndarray:
    """The acceleration at the current state: one explicit Euler step from rest gives
    v = a dt exactly (the scene is a probe, used once)."""
    assert scene.integrator == "euler" and not np.any(scene.velocities)
    scene.step(1)
    return scene.velocities / scene.dt


# ------------------------------------------------------------------------------ harmonic trap
@pytest.mark.parametrize("dim", [2, 3])
def test_trap_oscillates_as_verlets_discrete_oscillator(dim):
    # Velocity Verlet on x'' = -ω² x from rest is exactly x_n = x0 cos(n θ) with
    # cos θ = 1 - (ω dt)²/2 (the discrete method's own frequency), to round-off.
    k, m, dt = 8.0, 2.0, 1e-2
    w = np.sqrt(k / m)
    s = pc.Scene(dim=dim, integrator="verlet", dt=dt, threads=1)
    x0 = np.array([0.7, -0.2, 0.4][:dim])
    s.add_particles([x0 + 1.0], masses=[m])
    s.add(pc.HarmonicTrap(k, center=1.0))
    theta = np.arccos(1.0 - 0.5 * (w * dt) ** 2)
    for n in range(1, 2001):
        s.step(1)
        if n % 97 == 0:
            assert np.allclose(s.positions[0] - 1.0, x0 * np.cos(n * theta), rtol=0, atol=1e-11), n
    e = s.energy()
    assert e.potential["harmonic_trap"] == pytest.approx(0.5 * k * np.sum((s.positions[0] - 1.0) ** 2), rel=1e-14)


def test_trap_phase_error_is_second_order_in_dt():
    # After ten periods 2π/ω the phase error of Verlet is n(θ - ω dt) ≈ ω³ dt² t / 24.
    k, m = 9.0, 1.0
    w = np.sqrt(k / m)
    errs = []
    for steps in (200, 400, 800):
        dt = TAU / w / steps
        s = pc.Scene(dim=2, integrator="verlet", dt=dt, threads=1)
        s.add_particles([[1.0, 0.0]], masses=[m])
        s.add(pc.HarmonicTrap(k))
        s.step(10 * steps)
        errs.append(np.arctan2(-s.velocities[0, 0] / w, s.positions[0, 0]))  # the phase gained
    orders = np.log2(np.array(errs[:-1]) / errs[1:])
    assert np.all(np.abs(orders - 2.0) < 0.01), orders
    t = 10 * TAU / w
    assert errs[0] == pytest.approx(w**3 * (TAU / w / 200) ** 2 * t / 24, rel=0.01)


def test_each_particle_oscillates_at_its_own_frequency_and_axes_at_theirs():
    # Anisotropic stiffness (1, 4, 16) N/m on masses 1 and 4 kg: ω = √(k_a/m), per axis.
    k = np.array([1.0, 4.0, 16.0])
    s = pc.Scene(dim=3, integrator="rk4", dt=1e-3, threads=1)
    s.add_particles([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]], masses=[1.0, 4.0])
    s.add(pc.HarmonicTrap(k, center=[0.0, 0.0, 0.0]))
    s.step(3000)
    w = np.sqrt(k[None, :] / np.array([1.0, 4.0])[:, None])
    assert np.allclose(s.positions, np.cos(w * s.time), rtol=0, atol=1e-10)


def test_trap_books_and_suggested_step():
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles([[3.0, 1.0], [0.0, 0.0], [5.0, 5.0]], masses=[2.0, 0.5, 1.0], pinned=[False, False, True])
    trap = s.add(pc.HarmonicTrap([2.0, 8.0], center=[1.0, 0.0], name="trap"))
    assert trap == pc.HarmonicTrap([2.0, 8.0], center=[1.0, 0.0], name="trap")
    # The pinned particle holds no potential energy.
    assert s.energy().potential["trap"] == pytest.approx(0.5 * (2.0 * 4.0 + 8.0 * 1.0) + 0.5 * 2.0 * 1.0)
    # 0.5 / ω_max with ω_max² = k_max / m_min = 8 / 0.5.
    assert s.suggest_dt() == pytest.approx(0.5 / 4.0)
    e0 = s.energy().total
    s.step(5000)
    assert abs(s.energy().total - e0) < 1e-4 * abs(e0)


def test_a_scalar_trap_is_stored_per_axis():
    s = pc.Scene(dim=3, threads=1)
    stored = s.add(pc.HarmonicTrap(2.0))
    assert np.array_equal(stored.k, [2.0, 2.0, 2.0]) and np.array_equal(stored.center, [0.0, 0.0, 0.0])
    assert s.terms == (stored,)


# ------------------------------------------------------------------------------ point sources
def _kepler(integrator: str, steps: int, dim: int = 3) -> tuple[pc.Scene, float, float, np.ndarray]:
    # e = 0.5, a = 1, GM = 1 (G = 0.01, M = 100): from pericentre r = 0.5 at v = √3, period 2π.
    s = pc.Scene(dim=dim, integrator=integrator, dt=TAU / steps, threads=1)
    v = [0.0, np.sqrt(3.0) * 0.8, np.sqrt(3.0) * 0.6] if dim == 3 else [0.0, np.sqrt(3.0)]
    s.add_particles([[0.5, 0.0, 0.0][:dim]], [v], masses=[0.01])
    s.add(pc.PointMasses(np.zeros(dim), 100.0, G=0.01, name="sun"))
    return s, s.energy().total, np.copy(s.angular_momentum()), s.positions[0]


@pytest.mark.parametrize("integrator, order", [("verlet", 2), ("rk4", 4)])
def test_kepler_orbit_closes_at_the_integrators_order(integrator, order):
    errs, drifts = [], []
    for steps in (1000, 2000, 4000):
        s, e0, _, x0 = _kepler(integrator, steps)
        worst = 0.0
        for _ in range(10):
            s.step(steps // 10)
            worst = max(worst, abs(s.energy().total - e0) / abs(e0))
        errs.append(np.linalg.norm(s.positions[0] - x0))
        drifts.append(worst)
    # Energy: E = -GMm/(2a) from the books.
    assert e0 == pytest.approx(-0.5 * 0.01, rel=1e-14)
    for series in (errs, drifts):
        orders = np.log2(np.array(series[:-1]) / series[1:])
        assert np.all(np.abs(orders - order) < 0.1), (series, orders)
    assert errs[-1] < (2e-4 if integrator == "verlet" else 1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_verlet_keeps_angular_momentum_about_a_single_source_to_round_off(dim):
    s, e0, l0, _ = _kepler("verlet", 1000, dim)
    s.step(5000)  # five orbits
    assert np.allclose(s.angular_momentum(), l0, rtol=1e-13, atol=1e-16)
    # Energy bounded: no secular drift over five orbits (the error at one orbit's end repeats).
    assert abs(s.energy().total - e0) < 1e-4 * abs(e0)


def _coulomb_reference(x, q, m, src, Q, k, eps):
    d = x[:, None, :] - src[None, :, :]
    r2 = np.sum(d**2, axis=2) + eps**2
    f = k * q[:, None] * np.sum(Q[None, :, None] * d / r2[..., None] ** 1.5, axis=1)
    u = k * np.sum(q[:, None] * Q[None, :] / np.sqrt(r2))
    return f / m[:, None], u


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("eps", [0.0, 0.3])
def test_point_charges_follow_coulombs_law(dim, eps):
    rng = np.random.default_rng(dim)
    x, src = rng.normal(size=(40, dim)), rng.normal(size=(5, dim))
    m, q, Q = rng.uniform(0.5, 2.0, 40), rng.normal(size=40) * 1e-6, rng.normal(size=5) * 1e-6
    s = pc.Scene(dim=dim, integrator="euler", dt=1e-6, threads=1)
    s.add_particles(x, masses=m)
    s.set_attribute("charge", q)
    s.add(pc.PointCharges(src, Q, softening=eps, name="fixed"))
    a_ref, u_ref = _coulomb_reference(x, q, m, src, Q, 8.9875517923e9, eps)
    assert s.energy().potential["fixed"] == pytest.approx(u_ref, rel=1e-12)
    a = _one_euler_step_acceleration(s)
    assert np.allclose(a, a_ref, rtol=1e-12, atol=1e-12 * np.abs(a_ref).max())


def test_like_charges_repel_and_unlike_attract():
    s = pc.Scene(dim=2, integrator="euler", dt=1e-3, threads=1)
    s.add_particles([[2.0, 0.0], [0.0, 2.0]], masses=[1.0, 1.0])
    s.set_attribute("charge", [1e-6, -1e-6])
    s.add(pc.PointCharges([0.0, 0.0], 1e-6))
    a = _one_euler_step_acceleration(s)
    f = 8.9875517923e9 * 1e-12 / 4.0  # k q Q / r²
    assert np.allclose(a, [[f, 0.0], [0.0, -f]], rtol=1e-14, atol=0)


def test_point_masses_follow_newtons_law_with_softening():
    rng = np.random.default_rng(5)
    x, src = rng.normal(size=(30, 3)), rng.normal(size=(4, 3))
    m, M = rng.uniform(0.5, 2.0, 30), rng.uniform(0.5, 3.0, 4)
    s = pc.Scene(dim=3, integrator="euler", dt=1e-6, threads=1)
    s.add_particles(x, masses=m)
    s.add(pc.PointMasses(src, M, G=6.674e-11, softening=0.1))
    # Gravity is Coulomb with k q Q -> -G m M.
    a_ref, u_ref = _coulomb_reference(x, m, m, src, M, -6.674e-11, 0.1)
    assert s.energy().potential["point_masses"] == pytest.approx(u_ref, rel=1e-12)
    assert np.allclose(_one_euler_step_acceleration(s), a_ref, rtol=1e-12, atol=1e-12 * np.abs(a_ref).max())


def test_point_sources_suggest_the_free_fall_time():
    s = pc.Scene(dim=2, threads=1)
    s.add_particles([[2.0, 0.0], [0.0, 4.0]], masses=[1.0, 1.0])
    s.add(pc.PointMasses([0.0, 0.0], 2.0, G=1.0))
    assert s.suggest_dt() == pytest.approx(0.5 * np.sqrt(2.0**3 / 2.0))


# ------------------------------------------------------------------------------ grid potential
def _sample(f, lo, hi, n, dim):
    axes = [np.linspace(lo, hi, n)] * dim
    return f(*np.meshgrid(*axes, indexing="ij")), axes, (hi - lo) / (n - 1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("coupling", ["mass", "charge"])
def test_a_linear_potential_gives_the_exact_uniform_force(dim, coupling):
    g = np.array([3.0, -2.0, 0.5][:dim])
    phi, _, h = _sample(lambda *X: 1.0 + sum(gk * xk for gk, xk in zip(g, X, strict=False)), -8.0, 8.0, 33, dim)
    rng = np.random.default_rng(0)
    x0, v0, m = rng.uniform(-1, 1, (20, dim)), rng.normal(size=(20, dim)), rng.uniform(0.5, 2, 20)
    c = m if coupling == "mass" else rng.normal(size=20)
    s = pc.Scene(dim=dim, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles(x0, v0, masses=m)
    if coupling == "charge":
        s.set_attribute("charge", c)
    s.add(pc.PotentialGrid(phi, spacing=h, origin=-8.0, coupling=coupling))
    s.step(1000)  # crossing several cells of 0.5 m
    assert np.abs(s.positions).max() < 8.0
    a = -(c / m)[:, None] * g
    t = s.time
    assert np.allclose(s.positions, x0 + v0 * t + 0.5 * a * t**2, rtol=0, atol=1e-11)
    assert np.allclose(s.velocities, v0 + a * t, rtol=0, atol=1e-11)
    u = np.sum(c * (1.0 + s.positions @ g))
    assert s.energy().potential["potential_grid"] == pytest.approx(u, rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_books_and_forces_match_an_independent_interpolant(dim):
    # scipy's RegularGridInterpolator(method="linear") is bi/trilinear interpolation: the books
    # hold Σ m φ̃(x) and the force is -m ∇φ̃ (central differences of scipy's φ̃ inside cells).
    phi, axes, h = _sample(lambda *X: np.sin(2 * X[0]) * np.cos(X[1]) + X[-1] ** 2, -2.0, 2.0, 17, dim)
    ref = RegularGridInterpolator(axes, phi, method="linear")
    rng = np.random.default_rng(dim)
    cells = rng.integers(0, 16, (50, dim))
    x = -2.0 + (cells + rng.uniform(0.05, 0.95, (50, dim))) * h  # clear of the cell faces
    m = rng.uniform(0.5, 2.0, 50)
    s = pc.Scene(dim=dim, integrator="euler", dt=1e-9, threads=1)
    s.add_particles(x, masses=m)
    s.add(pc.PotentialGrid(phi, h, origin=-2.0))
    assert s.energy().potential["potential_grid"] == pytest.approx(np.sum(m * ref(x)), rel=1e-13)
    d = 1e-6
    grad = np.stack([(ref(x + d * e) - ref(x - d * e)) / (2 * d) for e in np.eye(dim)], axis=1)
    assert np.allclose(_one_euler_step_acceleration(s), -grad, rtol=0, atol=1e-8)


def test_a_sampled_parabola_converges_to_the_harmonic_oscillator():
    # φ = ½ ω² x² sampled every h. The interpolant is within ω²h²/8 of φ (order 2); its
    # piecewise-constant force within ω²h/2 of -ω² x (order 1); the period, for a turning point
    # on a node, within O(h^1.5) of 2π/ω (the turning point's square-root singularity in
    # T = ∮ dx / v weighs the O(h²) error of the last cell by h^-1/2).
    w, amp = 2.0, 0.5
    errs_u, errs_f, errs_t = [], [], []
    for n in (21, 41, 81, 161):
        phi, axes, h = _sample(lambda X, Y: 0.5 * w**2 * X**2 + 0 * Y, -1.0, 1.0, n, 2)
        probe = pc.Scene(dim=2, integrator="euler", dt=1e-9, threads=1)
        xs = np.linspace(-0.9, 0.9, 397)
        probe.add_particles(np.stack([xs, np.zeros_like(xs)], axis=1), masses=np.ones_like(xs))
        probe.add(pc.PotentialGrid(phi, h, origin=-1.0))
        u = probe.energy().potential["potential_grid"]
        errs_u.append((u - np.sum(0.5 * w**2 * xs**2)) / xs.size)  # mean interpolation error
        errs_f.append(np.abs(_one_euler_step_acceleration(probe)[:, 0] + w**2 * xs).max())
        # The half period from rest at x = amp (a node) to the turning point at -amp.
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
        errs_t.append(2 * (t0 + s.dt * -v0 / (v1 - v0)) / (TAU / w) - 1)
    assert 0 < errs_u[0] < w**2 * (2.0 / 20) ** 2 / 8  # φ̃ ≥ φ for a convex φ
    for series, order in ((errs_u, 2.0), (errs_f, 1.0), (errs_t, 1.5)):
        orders = np.log2(np.array(series[:-1]) / series[1:])
        assert np.all(np.abs(orders - order) < 0.1), (series, orders)
    assert 0 < errs_t[-1] < 1e-3


def _bumpy_well(dim, n=41, lo=-2.0, hi=2.0):
    def f(*X):
        p = 0.5 * sum(x**2 for x in X) + 0.3 * np.cos(2.1 * X[0]) * np.sin(1.7 * X[1] + 0.3)
        return p + 0.15 * np.sin(3.3 * X[0] - 2.2 * X[1]) + (0.2 * np.cos(1.3 * X[2] + X[0]) if dim == 3 else 0.0)

    return _sample(f, lo, hi, n, dim)


@pytest.mark.parametrize("dim", [2, 3])
def test_energy_books_balance_over_thousands_of_cell_crossings(dim):
    # 200 particles in a bumpy well on a 40-cell grid, 20 s: each crosses hundreds of cells. The
    # force jumps at cell faces, so each crossing costs Verlet an energy error ~ |jump| |v| dt of
    # either sign: the books stay balanced to ~1e-4 and the error falls with dt (order ≈ 1, not
    # the 2 of a smooth force).
    phi, _, h = _bumpy_well(dim)
    rng = np.random.default_rng(1)
    x0, v0 = rng.uniform(-0.6, 0.6, (200, dim)), rng.normal(0, 0.5, (200, dim))
    worst = []
    for dt in (4e-3, 1e-3, 2.5e-4):
        s = pc.Scene(dim=dim, integrator="verlet", dt=dt, threads=1)
        s.add_particles(x0, v0, masses=np.ones(200))
        s.add(pc.PotentialGrid(phi, h, origin=-2.0))
        e = s.energy()
        scale = e.kinetic + abs(e.potential["potential_grid"])
        errs = []
        for _ in range(100):
            s.step(round(0.2 / dt))
            errs.append(abs(s.energy().total - e.total) / scale)
        worst.append(max(errs))
    assert worst[0] < 1e-3 and worst[-1] < 2e-5, worst
    assert worst[0] / worst[-1] > 8, worst  # 16x smaller steps: at least order 0.75


def test_outside_the_grid_the_normal_force_vanishes_and_the_books_stay_balanced():
    # φ = x² + y on [0, 1]²: a particle leaving through x = 1 keeps its x velocity; along y it
    # still feels -∂φ/∂y = -1 (the boundary's gradient), and the books balance throughout.
    phi, _, h = _sample(lambda X, Y: X**2 + Y, 0.0, 1.0, 11, 2)
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles([[0.5, 0.5]], [[2.0, 1.0]], masses=[1.0])
    s.add(pc.PotentialGrid(phi, h))
    e0 = s.energy().total
    while s.positions[0, 0] <= 1.0:
        s.step(1)
    vx = s.velocities[0, 0]
    s.step(400)
    assert s.velocities[0, 0] == vx  # no force along x out there
    assert s.energy().potential["potential_grid"] == pytest.approx(1.0 + s.positions[0, 1], abs=1e-12)
    assert abs(s.energy().total - e0) < 1e-3 * abs(e0)
    # Beyond the corner (out along both axes) nothing acts at all.
    s.step(2000)
    assert s.positions[0, 1] > 1.0
    v = s.velocities
    s.step(100)
    assert np.array_equal(s.velocities, v)


def test_advance_moves_no_particle_more_than_one_cell_per_substep():
    # φ = 3x + 4y (slope 5 m/s²) on cells of 0.1 m, |v| = 2 m/s: |v| dt + ½·5·dt² = 0.1.
    phi, _, h = _sample(lambda X, Y: 3.0 * X + 4.0 * Y, -10.0, 10.0, 201, 2)
    s = pc.Scene(dim=2, integrator="verlet", dt=1.0, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 1.0]], [[0.0, 2.0], [50.0, 0.0]], masses=[2.0, 1.0], pinned=[False, True])
    s.add(pc.PotentialGrid(phi, h, origin=-10.0))
    want = 0.2 / (2.0 + np.sqrt(4.0 + 2 * 5.0 * 0.1))
    assert 2.0 * want + 2.5 * want**2 == pytest.approx(0.1, rel=1e-15)
    assert s.auto_dt() == pytest.approx(want, rel=1e-14) and s.suggest_dt() == pytest.approx(want, rel=1e-14)
    n = s.advance(1.0)
    assert n == int(np.ceil(1.0 / want)) and s.dt == pytest.approx(1.0 / n, rel=1e-15)


def test_charge_coupling_without_charges_does_nothing_and_pinned_particles_are_skipped():
    phi, _, h = _sample(lambda X, Y: 5.0 * X + Y, 0.0, 1.0, 3, 2)
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles([[0.5, 0.5], [0.2, 0.2]], masses=[1.0, 1.0], pinned=[False, True])
    s.add(pc.PotentialGrid(phi, h, coupling="charge", name="volts"))
    s.add(pc.PointCharges([0.0, 0.0], 1.0, name="q"))
    with pytest.warns(pc.UnchargedWarning, match=r"PotentialGrid, PointCharges: no particle has a charge \(no charge attribute\)"):
        s.step(10)
    assert np.array_equal(s.positions, [[0.5, 0.5], [0.2, 0.2]])
    assert s.energy().potential == {"volts": 0.0, "q": 0.0}
    s.set_attribute("charge", [2.0, 3.0])
    assert s.energy().potential["volts"] == pytest.approx(2.0 * 3.0)  # the pinned charge holds none


def test_the_grid_suggests_a_step_from_its_curvature():
    # φ = ½ ω² |x|² with ω = 3: the bound from second differences is ω² itself. (Cells of 0.25 m
    # keep the one-cell-per-step limit, here √(2h/|∇φ|max) = 0.19 s, above 0.5/ω.)
    phi, _, h = _sample(lambda X, Y, Z: 4.5 * (X**2 + Y**2 + Z**2), -1.0, 1.0, 9, 3)
    s = pc.Scene(dim=3, threads=1)
    s.add_particles([[0.1, 0.2, 0.3]], masses=[1.0])
    s.add(pc.PotentialGrid(phi, h, origin=-1.0))
    assert s.suggest_dt() == pytest.approx(0.5 / 3.0, rel=1e-9)


# ------------------------------------------------------------------------------ all of them
def _everything(threads: int, n: int = 10_000, dim: int = 3) -> pc.Scene:
    rng = np.random.default_rng(7)
    s = pc.Scene(dim=dim, integrator="verlet", dt=1e-3, threads=threads)
    s.add_particles(rng.uniform(-1, 1, (n, dim)), rng.normal(size=(n, dim)), masses=rng.uniform(0.5, 2, n))
    s.set_attribute("charge", rng.normal(size=n))
    s.add(pc.PointMasses(rng.normal(size=(3, dim)), [1.0, 2.0, 3.0], softening=0.1))
    s.add(pc.PointCharges(rng.normal(size=(2, dim)), [1.0, -1.0], k=0.5, softening=0.2))
    s.add(pc.HarmonicTrap(np.arange(1.0, dim + 1.0)))
    phi, _, h = _bumpy_well(dim, n=17)
    s.add(pc.PotentialGrid(phi, h, origin=-2.0, coupling="charge"))
    return s


@pytest.mark.parametrize("dim", [2, 3])
def test_thread_count_does_not_change_the_bits(dim):
    runs = []
    for threads in (1, 2, 3):
        s = _everything(threads, dim=dim)
        s.step(20)
        e = s.energy()
        runs.append((s.positions, s.velocities, e.total, e.potential))
    for r in runs[1:]:
        assert np.array_equal(r[0], runs[0][0]) and np.array_equal(r[1], runs[0][1])
        assert r[2] == runs[0][2] and r[3] == runs[0][3]


def test_save_and_load_continue_bit_for_bit(tmp_path):
    s = _everything(1, n=300)
    s.step(10)
    s.save(tmp_path / "p.npz")
    back = pc.Scene.load(tmp_path / "p.npz")
    assert back.terms == s.terms
    s.step(50)
    back.step(50)
    assert np.array_equal(back.positions, s.positions) and np.array_equal(back.velocities, s.velocities)
    assert back.energy() == s.energy()
    # The grid's samples travel as an array member, not inside the JSON.
    with np.load(tmp_path / "p.npz") as z:
        meta = json.loads(str(z["meta"]))
        k = [t["type"] for t in meta["terms"]].index("potential_grid")
        assert z[f"term{k}_phi"].shape == (17**3,) and len(str(z["meta"])) < 4000
        assert meta["terms"][k]["shape"] == [17, 17, 17]


def _rewrite(src, dst, edit):
    with np.load(src) as z:
        arrays = {name: z[name] for name in z.files}
    meta = json.loads(str(arrays["meta"]))
    edit(meta, arrays)
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(dst, **arrays)


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda m, a: m["terms"][0].update(shape=[4, 5]), "term0_phi"),
        (lambda m, a: m["terms"][0].update(shape=[4.5, 4]), "meta.terms[0].shape"),
        (lambda m, a: m["terms"][0].update(shape=[1, 16]), "meta.terms[0].shape"),
        (lambda m, a: m["terms"][0].update(shape=[4, 4, 1]), "meta.terms[0].shape"),
        (lambda m, a: m["terms"][0].update(spacing=[0.0, 1.0]), "meta.terms[0].spacing"),
        (lambda m, a: m["terms"][0].update(coupling="spin"), "meta.terms[0].coupling"),
        (lambda m, a: a.update(term0_phi=np.zeros(15)), "term0_phi"),
        (lambda m, a: m["terms"][1].update(G=-1.0), "meta.terms[1].G"),
        (lambda m, a: a.update(term1_masses=-a["term1_masses"]), "term1_masses"),
        (lambda m, a: a.update(term1_positions=np.zeros((2, 3))), "term1_positions"),
        (lambda m, a: m["terms"][2].update(k=[1.0, -1.0]), "meta.terms[2].k"),
    ],
)
def test_a_tampered_file_names_the_field(tmp_path, edit, field):
    s = pc.Scene(dim=2, threads=1)
    s.add_particles([[0.5, 0.5]], masses=[1.0])
    s.add(pc.PotentialGrid(np.arange(16.0).reshape(4, 4), 0.5))
    s.add(pc.PointMasses([[0.0, 0.0], [1.0, 1.0]], [1.0, 2.0]))
    s.add(pc.HarmonicTrap(1.0))
    s.save(tmp_path / "ok.npz")
    _rewrite(tmp_path / "ok.npz", tmp_path / "bad.npz", edit)
    with pytest.raises(pc.SceneFileError) as info:
        pc.Scene.load(tmp_path / "bad.npz")
    assert f": {field}: " in str(info.value), str(info.value)


# ------------------------------------------------------------------------------ bad input
GRID = np.zeros((4, 4))


@pytest.mark.parametrize(
    "call, exc, arg",
    [
        (lambda s: pc.PotentialGrid(np.array([[0.0, np.nan], [0.0, 0.0]]), 1.0), pc.InvalidInputError, "phi"),
        (lambda s: pc.PotentialGrid(np.zeros(4), 1.0), pc.InvalidInputError, "phi"),
        (lambda s: pc.PotentialGrid(np.zeros((1, 4)), 1.0), pc.InvalidInputError, "phi"),
        (lambda s: pc.PotentialGrid(np.zeros((2, 2, 2, 2)), 1.0), pc.InvalidInputError, "phi"),
        (lambda s: pc.PotentialGrid([["a", "b"], ["c", "d"]], 1.0), TypeError, "phi"),
        (lambda s: pc.PotentialGrid(GRID, 0.0), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, -1.0), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, [1.0, 0.0]), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, [1.0, 1.0, 1.0]), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, 1e-320), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, 1e308), pc.InvalidInputError, "spacing"),
        (lambda s: pc.PotentialGrid(GRID, 1.0, origin=np.inf), pc.InvalidInputError, "origin"),
        (lambda s: pc.PotentialGrid(GRID, 1.0, coupling="spin"), pc.InvalidInputError, "coupling"),
        (lambda s: pc.PotentialGrid(GRID, 1.0, coupling=1), TypeError, "coupling"),
        (lambda s: s.add(pc.PotentialGrid(np.zeros((2, 2, 2)), 1.0)), pc.InvalidInputError, "phi"),
        (lambda s: pc.HarmonicTrap(-1.0), pc.InvalidInputError, "k"),
        (lambda s: pc.HarmonicTrap([1.0, -1.0]), pc.InvalidInputError, "k"),
        (lambda s: pc.HarmonicTrap(np.nan), pc.InvalidInputError, "k"),
        (lambda s: pc.HarmonicTrap("stiff"), TypeError, "k"),
        (lambda s: pc.HarmonicTrap([[1.0, 1.0]]), pc.InvalidInputError, "k"),
        (lambda s: pc.HarmonicTrap([1.0, 1.0], center=[0.0, 0.0, 0.0]), pc.InvalidInputError, "center"),
        (lambda s: s.add(pc.HarmonicTrap([1.0, 1.0, 1.0])), pc.InvalidInputError, "k"),
        (lambda s: s.add(pc.HarmonicTrap(1.0, center=[0.0, 0.0, 0.0])), pc.InvalidInputError, "center"),
        (lambda s: pc.PointMasses([0.0, 0.0], -1.0), pc.InvalidInputError, "masses"),
        (lambda s: pc.PointMasses([0.0, 0.0], [1.0, 2.0]), pc.InvalidInputError, "masses"),
        (lambda s: pc.PointMasses([[0.0, np.nan]], 1.0), pc.InvalidInputError, "positions"),
        (lambda s: pc.PointMasses([0.0], 1.0), pc.InvalidInputError, "positions"),
        (lambda s: pc.PointMasses([0.0, 0.0], 1.0, G=0.0), pc.InvalidInputError, "G"),
        (lambda s: pc.PointMasses([0.0, 0.0], 1.0, softening=-1.0), pc.InvalidInputError, "softening"),
        (lambda s: pc.PointMasses([0.0, 0.0], 1e300, G=1e10), pc.InvalidInputError, "masses"),
        (lambda s: pc.PointCharges([0.0, 0.0], np.nan), pc.InvalidInputError, "charges"),
        (lambda s: pc.PointCharges([0.0, 0.0], 1.0, k=-1.0), pc.InvalidInputError, "k"),
        (lambda s: pc.PointCharges([0.0, 0.0], True), TypeError, "charges"),
        (lambda s: s.add(pc.PointCharges([0.0, 0.0, 0.0], 1.0)), pc.InvalidInputError, "positions"),
    ],
)
def test_bad_input_names_the_argument_and_changes_nothing(call, exc, arg):
    s = pc.Scene(dim=2, threads=1)
    s.add_particles([[0.5, 0.5]], masses=[1.0])
    terms = s.terms
    with pytest.raises(exc) as info:
        call(s)
    assert str(info.value).startswith(arg + ":"), str(info.value)
    assert s.terms == terms


def test_negative_source_charges_and_zero_masses_are_fine():
    s = pc.Scene(dim=2, threads=1)
    s.add_particles([[0.5, 0.5]], masses=[1.0])
    s.set_attribute("charge", [1.0])
    s.add(pc.PointCharges([[0.0, 0.0], [1.0, 0.0]], [-1.0, 1.0]))
    s.add(pc.PointMasses([0.0, 0.0], 0.0))
    s.add(pc.HarmonicTrap([0.0, 1.0]))
    s.dt = s.auto_dt()  # Coulomb's constant pulls the particle in within microseconds
    s.step(10)
    assert len(s.terms) == 3


# ------------------------------------------------------------------------------ hostile arguments
def _rows(v):
    try:
        return np.ones(np.shape(v)[0]) if np.ndim(v) == 2 else 1.0
    except (ValueError, TypeError):
        return 1.0


FUZZ = {
    "phi": ("phi", lambda v: pc.PotentialGrid(v, 0.5), "points"),
    "spacing": ("spacing", lambda v: pc.PotentialGrid(GRID, v), "scalar"),
    "origin": ("origin", lambda v: pc.PotentialGrid(GRID, 1.0, origin=v), "scalar"),
    "coupling": ("coupling", lambda v: pc.PotentialGrid(GRID, 1.0, coupling=v), "scalar"),
    "trap k": ("k", lambda v: pc.HarmonicTrap(v), "scalar"),
    "trap center": ("center", lambda v: pc.HarmonicTrap(1.0, center=v), "points"),
    "mass positions": ("positions", lambda v: pc.PointMasses(v, _rows(v)), "points"),
    "masses": ("masses", lambda v: pc.PointMasses([0.0, 0.0], v), "scalar"),
    "G": ("G", lambda v: pc.PointMasses([0.0, 0.0], 1.0, G=v), "scalar"),
    "softening": ("softening", lambda v: pc.PointMasses([0.0, 0.0], 1.0, softening=v), "scalar"),
    "charges": ("charges", lambda v: pc.PointCharges([0.0, 0.0], v), "scalar"),
    "coulomb k": ("k", lambda v: pc.PointCharges([0.0, 0.0], 1.0, k=v), "scalar"),
}


def _fuzz_case():
    from hypothesis import strategies as st
    from test_fuzz_hostile import hostile, hostile_points

    pick = {"scalar": hostile, "points": hostile_points}
    return st.sampled_from(sorted(FUZZ)).flatmap(lambda key: st.tuples(st.just(key), pick[FUZZ[key][2]]))


def test_fuzz_hostile_arguments_are_refused_by_name_or_run_with_honest_books():
    from hypothesis import given, settings
    from test_fuzz_hostile import FAST, _books_are_honest, _call, _state

    @settings(max_examples=FAST, deadline=None)
    @given(_fuzz_case())
    def check(case):
        key, value = case
        arg, make, _ = FUZZ[key]
        s = pc.Scene(dim=2, dt=1e-3, threads=1)
        s.add_particles([[0.5, 0.5], [1.0, 0.2]], [[0.1, 0.0], [0.0, -0.1]], masses=[1.0, 2.0])
        s.set_attribute("charge", [1e-6, -1e-6])
        before = _state(s)
        term = _call(arg, lambda: make(value))
        if term is not None and _call(arg, lambda: s.add(term)) is not None:
            _books_are_honest(s)
        else:
            assert _state(s) == before, "refused, but the scene changed"

    check()
