"""Charged particles: the Coulomb force, uniform and gridded electric and magnetic fields, and the
Boris push. Expectations are closed-form: the cyclotron frequency and radius (and Boris's
discrete ones), the E×B drift, Coulomb's law for two charges, conservation laws."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import EPS, fit_slope
from hypothesis import given
from hypothesis import strategies as st

import physcore as pc

# dt = 2⁻¹⁰: dividing a velocity by it is exact.
DT_EXACT = 2.0**-10


def _one(dim, q=1.0, m=1.0, v=None, integrator="boris", dt=1e-3, x=None):
    s = pc.Scene(dim=dim, integrator=integrator, dt=dt, threads=1)
    s.add_particles([x if x is not None else [0.0] * dim], [v if v is not None else [0.0] * dim], masses=[m])
    s.set_attribute("charge", [q])
    return s


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares circle through points (P, 2): centre, radius, largest |distance − radius|."""
    a = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy**2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(a, b, rcond=None)
    centre = np.array([cx, cy])
    r = math.sqrt(c + cx * cx + cy * cy)
    return centre, r, float(np.abs(np.linalg.norm(xy - centre, axis=1) - r).max())


def _turning(v0: np.ndarray, v1: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Signed angles from rows of v0 to rows of v1 about the unit ``axis`` (3D rows)."""
    p0 = v0 - np.outer(v0 @ axis, axis)
    p1 = v1 - np.outer(v1 @ axis, axis)
    return np.arctan2(np.cross(p0, p1) @ axis, np.einsum("ij,ij->i", p0, p1))


# ------------------------------------------------------------------------------ cyclotron motion
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("wdt", [0.01, 0.3, 1.0, 2.5])
def test_boris_turns_by_its_discrete_angle_on_its_discrete_circle(dim, wdt):
    # q = -2, m = 0.5, |B| = 1.5: ω_c = 6. Each step turns v by 2 arctan(ω_c dt/2) (clockwise
    # about B for q > 0, so counter-clockwise here), and the positions lie on a circle of radius
    # r_L √(1 + (ω_c dt/2)²), both to round-off.
    q, m, bmag, vperp = -2.0, 0.5, 1.5, 0.8
    wc = abs(q) * bmag / m
    dt = wdt / wc
    if dim == 2:
        B, axis, v0 = bmag, np.array([0.0, 0.0, 1.0]), [vperp, 0.0]
    else:
        axis = np.array([1.0, -2.0, 2.0]) / 3.0
        e1 = np.cross(axis, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        B, v0 = bmag * axis, vperp * e1 + 0.3 * axis  # a parallel part: a helix
    s = _one(dim, q, m, v0, dt=dt)
    s.add(pc.MagneticField(B))
    xs, vs = [s.positions[0].copy()], [s.velocities[0].copy()]
    for _ in range(60):
        s.step()
        xs.append(s.positions[0].copy())
        vs.append(s.velocities[0].copy())
    xs, vs = np.array(xs), np.array(vs)
    if dim == 2:
        xs3, vs3 = np.column_stack([xs, np.zeros(len(xs))]), np.column_stack([vs, np.zeros(len(vs))])
    else:
        xs3, vs3 = xs, vs
    theta = 2 * math.atan(0.5 * wc * dt)
    turn = _turning(vs3[:-1], vs3[1:], axis)
    assert np.abs(turn - theta).max() < 1e-13, (turn[:3], theta)  # q < 0: positive sense about B
    # The orbit projected across B: a circle of the discrete radius.
    e1 = vs3[0] - axis * (vs3[0] @ axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    _, r, resid = _circle(np.column_stack([xs3 @ e1, xs3 @ e2]))
    r_l = m * vperp / (abs(q) * bmag)
    assert r == pytest.approx(r_l * math.sqrt(1 + (0.5 * wc * dt) ** 2), rel=1e-12)
    assert resid < 1e-12 * r
    # Along B the particle drifts at its parallel speed, untouched.
    along = xs3 @ axis
    assert np.allclose(np.diff(along), (vs3[0] @ axis) * dt, rtol=0, atol=1e-15)


def test_boris_converges_to_the_cyclotron_frequency_and_larmor_radius_at_second_order():
    # ω_c = |q|B/m and r_L = m v⊥/(|q|B): the discrete ones differ by (ω_c dt)²/12 and
    # (ω_c dt)²/8 (relative), so the errors fall 4× per halving of dt.
    q, m, B, v = 1.5, 3.0, 2.0, 0.7
    wc, r_l = abs(q) * B / m, m * v / (abs(q) * B)
    errs_w, errs_r = [], []
    dts = [0.2 / wc, 0.1 / wc, 0.05 / wc, 0.025 / wc]
    for dt in dts:
        s = _one(2, q, m, [v, 0.0], dt=dt)
        s.add(pc.MagneticField(B))
        n = round(2 * math.pi / (wc * dt)) * 3
        xs, vs = [s.positions[0].copy()], [s.velocities[0].copy()]
        for _ in range(n):
            s.step()
            xs.append(s.positions[0].copy())
            vs.append(s.velocities[0].copy())
        xs, vs = np.array(xs), np.array(vs)
        # Frequency from the unwrapped phase of v over the run, radius from a circle fit.
        phase = np.unwrap(np.arctan2(vs[:, 1], vs[:, 0]))
        w = -(phase[-1] - phase[0]) / (n * dt)  # q > 0 in B_z > 0: clockwise
        _, r, _ = _circle(xs)
        errs_w.append(abs(w / wc - 1))
        errs_r.append(abs(r / r_l - 1))
        assert w / wc - 1 == pytest.approx(2 * math.atan(0.5 * wc * dt) / (wc * dt) - 1, rel=1e-9, abs=1e-14)
    for errs in (errs_w, errs_r):
        assert abs(fit_slope(np.log(dts), np.log(errs)) - 2) < 0.05, errs
    assert errs_w[-1] < 1e-4 and errs_r[-1] < 1e-4


@given(
    wdt=st.floats(0.01, 10.0),
    q=st.floats(-5.0, 5.0).filter(lambda q: abs(q) > 1e-3),
    m=st.floats(0.1, 10.0),
    b=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3).filter(lambda b: np.linalg.norm(b) > 1e-2),
    v=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v[:2]) > 1e-3),
    dim=st.sampled_from([2, 3]),
)
def test_boris_keeps_the_speed_to_round_off_in_a_pure_magnetic_field(wdt, q, m, b, v, dim):
    # From ω_c dt = 0.01 to 10. Round-off: the rotation's coefficients are rounded once, and in a
    # uniform field the same rounded rotation applies every step, so |v|² drifts linearly, by
    # a few ε a step (measured: up to 2.9 ε; the classic one-rotation Boris push, up to 4.1 ε).
    # Bound: 4ε a step, i.e. < 1e-13 after 100 steps and < 9e-13 after 1000.
    B = np.array(b) if dim == 3 else b[2] if abs(b[2]) > 1e-2 else 1.0
    wc = abs(q) * np.linalg.norm(B) / m
    s = _one(dim, q, m, v[:dim], dt=wdt / wc)
    s.add(pc.MagneticField(B))
    k0 = float(s.velocities[0] @ s.velocities[0])
    for k in range(1, 11):
        s.step(100)
        vv = s.velocities[0]
        drift = abs(float(vv @ vv) / k0 - 1)
        assert drift <= 4 * EPS * 100 * k, (k, drift)
        if k == 1:
            assert drift < 1e-13
    assert s.energy().kinetic == pytest.approx(0.5 * m * k0, rel=1e-12)


# ------------------------------------------------------------------------------ E×B drift
@pytest.mark.parametrize("wdt", [0.05, 0.5, 2.0])
def test_boris_gives_the_exact_e_cross_b_drift(wdt):
    # Uniform E ⊥ B: the guiding centre moves at E×B/B². Boris's drift is exact for any dt: the
    # positions less u·t lie on one fixed circle to round-off, and the mean velocity over whole
    # gyrations is u within the gyration's own size over the time (2 r / T).
    q, m = 2.0, 0.5
    B = np.array([0.0, 0.0, 1.25])
    E = np.array([0.4, -0.3, 0.0])
    u = np.cross(E, B) / (B @ B)
    wc = abs(q) * np.linalg.norm(B) / m
    dt = wdt / wc
    s = _one(3, q, m, [0.5, 0.2, 0.0], dt=dt)
    s.add(pc.MagneticField(B))
    s.add(pc.ElectricField(E))
    n = 400
    xs = [s.positions[0].copy()]
    for _ in range(n):
        s.step()
        xs.append(s.positions[0].copy())
    xs = np.array(xs)
    t = dt * np.arange(n + 1)
    _, r, resid = _circle((xs - np.outer(t, u))[:, :2])
    assert resid < 1e-12 * max(r, 1.0)
    # Whole discrete gyrations: the number of steps closest to a multiple of 2π/θ.
    theta = 2 * math.atan(0.5 * wc * dt)
    k = int(n * theta / (2 * math.pi))
    steps = round(k * 2 * math.pi / theta)
    mean = (xs[steps] - xs[0]) / (steps * dt)
    assert np.linalg.norm(mean - u) <= 2 * r / (steps * dt) + 1e-12
    # Along B nothing moves (E ⊥ B, no parallel velocity).
    assert np.abs(xs[:, 2]).max() == 0.0


def test_e_cross_b_drift_of_many_particles_in_2d():
    # In 2D, E in the plane and B_z: every particle, whatever its speed, drifts at E×B/B²
    # averaged over a long time.
    rng = np.random.default_rng(3)
    n, q, m, bz = 20, 1.0, 1.0, 2.0
    E = np.array([1.0, 0.5])
    u = np.array([E[1] * bz, -E[0] * bz]) / bz**2  # E × (B_z ẑ) / B²
    s = pc.Scene(dim=2, integrator="boris", dt=0.05, threads=1)
    s.add_particles(rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), masses=np.full(n, m))
    s.set_attribute("charge", np.full(n, q))
    s.add(pc.MagneticField(bz))
    s.add(pc.ElectricField(E))
    x0 = s.positions
    s.step(4000)
    mean = (s.positions - x0) / s.time
    # Gyration radii here are below 2 m/s·(1/ω_c) ~ 1.5 m; over T = 200 s: 2r/T < 0.02.
    assert np.abs(mean - u).max() < 0.02


# ------------------------------------------------------------------------------ the other integrators
@pytest.mark.parametrize(
    "integrator, order",
    [("boris", 2), ("verlet", 2), ("rk4", 4), ("semi_implicit_euler", 1), ("euler", 1)],
)
def test_every_integrator_converges_to_the_gyration_at_its_order(integrator, order):
    # q v × B as a velocity-dependent force: after one cyclotron period (t = 2π/ω_c) the charge
    # is back where it started; each integrator's error falls at its order.
    q, m, B, v = 1.0, 1.0, 1.0, 1.0
    period = 2 * math.pi * m / (q * B)
    errs = []
    dts = [period / 64, period / 128, period / 256, period / 512]
    if integrator == "rk4":
        dts = [period / 16, period / 32, period / 64, period / 128]
    for dt in dts:
        s = _one(2, q, m, [v, 0.0], integrator=integrator, dt=dt)
        s.add(pc.MagneticField(B))
        s.step(round(period / dt))
        errs.append(float(np.linalg.norm(s.positions[0])) + float(np.linalg.norm(s.velocities[0] - [v, 0.0])))
    slope = fit_slope(np.log(dts), np.log(errs))
    assert abs(slope - order) < 0.2, (integrator, slope, errs)


def test_dopri5_follows_the_gyration_to_its_tolerance():
    s = _one(3, 1.0, 1.0, [1.0, 0.0, 0.2], integrator="dopri5", dt=0.5)
    s.rtol, s.atol = 1e-10, 1e-12
    s.add(pc.MagneticField([0.0, 0.0, 1.0]))
    s.step(round(4 * math.pi / 0.5))
    t = s.time
    want = [math.sin(t), math.cos(t) - 1, 0.2 * t]  # q = m = B = 1: clockwise from +x
    assert np.allclose(s.positions[0], want, rtol=0, atol=1e-7)


def test_magnetic_books_hold_no_potential_and_no_dissipation():
    s = _one(2, 1.0, 2.0, [1.0, 0.5])
    s.add(pc.MagneticField(3.0, name="b"))
    s.step(1000)
    e = s.energy()
    assert "b" not in e.potential and "b" not in e.dissipated
    assert e.total == pytest.approx(0.5 * 2.0 * 1.25, rel=1e-13)
    assert s.energy_drift() < 1e-13


def test_drag_with_a_magnetic_field_under_boris_books_its_dissipation_at_second_order():
    # Velocity-dependent forces besides the magnetic one (drag) are evaluated at the step's
    # end with a predicted velocity: the books still balance at second order.
    drifts = []
    for dt in (0.02, 0.01, 0.005):
        s = _one(3, 1.0, 1.0, [1.0, 0.0, 0.3], dt=dt)
        s.add(pc.MagneticField([0.0, 0.5, 2.0]))
        s.add(pc.Drag(0.3))
        s.add(pc.ElectricField([0.1, 0.0, 0.0]))
        s.step(round(5.0 / dt))
        drifts.append(abs(s.energy_drift()))
    assert drifts[0] < 1e-3
    assert 3.0 < drifts[0] / drifts[1] < 5.0 and 3.0 < drifts[1] / drifts[2] < 5.0, drifts


def test_uncharged_particles_ignore_every_field():
    s = pc.Scene(dim=3, integrator="boris", dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    s.add(pc.MagneticField([0.0, 0.0, 5.0]))
    s.add(pc.Coulomb(k=1.0))
    s.add(pc.GridElectricField(np.ones((2, 2, 2, 3)), [-5.0, -5.0, -5.0], spacing=10.0))
    with pytest.warns(pc.UnchargedWarning, match="MagneticField, Coulomb, GridElectricField: no particle has a charge") as caught:
        s.step(50)
        s.step(50)  # once after each change, not at every step
    assert len(caught) == 1
    assert np.allclose(s.positions, [[0.1, 0.0, 0.0], [1.0, 0.1, 0.0]], rtol=0, atol=1e-15)
    assert s.energy().potential["coulomb"] == 0.0
    # Charge 0 on one particle: it neither pushes nor is pushed.
    s.set_attribute("charge", [1.0, 0.0])
    v = s.velocities
    s.step(100)
    assert np.array_equal(s.velocities[1], v[1])


# ------------------------------------------------------------------------------ Coulomb
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("q1, q2", [(2.0, 3.0), (2.0, -3.0), (-1.0, -0.5)])
def test_two_charges_feel_coulombs_law(dim, q1, q2):
    k, eps, m1, m2 = 4.0, 0.1, 1.0, 2.0
    x1 = np.array([0.5, -0.25, 1.0][:dim])
    x2 = np.array([1.5, 1.75, -1.0][:dim])
    s = pc.Scene(dim=dim, integrator="euler", dt=DT_EXACT, threads=1)
    s.add_particles([x1, x2], masses=[m1, m2])
    s.set_attribute("charge", [q1, q2])
    s.add(pc.Coulomb(k, softening=eps))
    d = x1 - x2
    r2 = d @ d + eps**2
    f1 = k * q1 * q2 * d / r2**1.5
    assert s.energy().potential["coulomb"] == pytest.approx(k * q1 * q2 / math.sqrt(r2), rel=1e-14)
    s.step()
    a = s.velocities / DT_EXACT  # explicit Euler from rest: v = a dt
    assert np.allclose(a[0] * m1, f1, rtol=1e-13, atol=0)
    assert np.allclose(a[1] * m2, -f1, rtol=1e-13, atol=0)
    # Like charges repel (particle 1 pushed away from 2), unlike attract.
    assert (a[0] @ d > 0) == (q1 * q2 > 0)


def test_default_constant_is_si():
    assert pc.Coulomb().k == 8.9875517923e9
    s = pc.Scene(dim=3, integrator="euler", dt=DT_EXACT, threads=1)
    e = 1.602176634e-19
    s.add_particles([[0.0, 0.0, 0.0], [1e-10, 0.0, 0.0]], masses=[1.67262192e-27, 1.67262192e-27])
    s.set_attribute("charge", [e, -e])
    s.add(pc.Coulomb())
    assert s.energy().potential["coulomb"] == pytest.approx(-8.9875517923e9 * e * e / 1e-10, rel=1e-14)


def test_pinned_charges_push_but_do_not_move():
    s = pc.Scene(dim=2, integrator="euler", dt=DT_EXACT, threads=1)
    s.add_particles([[0.0, 0.0], [2.0, 0.0]], masses=[1.0, 1.0], pinned=[True, False])
    s.set_attribute("charge", [1.0, 1.0])
    s.add(pc.Coulomb(k=1.0))
    s.step()
    assert np.array_equal(s.positions[0], [0.0, 0.0]) and np.array_equal(s.velocities[0], [0.0, 0.0])
    assert s.velocities[1] / DT_EXACT == pytest.approx([0.25, 0.0], rel=1e-14)


def _plasma(n, dim, integrator="verlet", dt=1e-3, threads=1, seed=0, eps=0.05):
    rng = np.random.default_rng(seed)
    s = pc.Scene(dim=dim, integrator=integrator, dt=dt, threads=threads)
    s.add_particles(rng.uniform(-1, 1, size=(n, dim)), 0.1 * rng.normal(size=(n, dim)), masses=rng.uniform(0.5, 2.0, n))
    q = np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * rng.uniform(0.5, 1.0, n)
    s.set_attribute("charge", q / n)
    s.add(pc.Coulomb(k=1.0, softening=eps))
    return s


@pytest.mark.parametrize("dim", [2, 3])
def test_a_softened_plasma_conserves_energy_at_second_order_with_verlet(dim):
    drifts = []
    for dt in (2e-3, 1e-3):
        s = _plasma(40, dim, dt=dt)
        s.step(round(2.0 / dt))
        drifts.append(abs(s.energy_drift()))
    # Measured 1.9e-9 (2D) and 3.9e-9 (3D) at dt = 2e-3, ratio 4.00.
    assert drifts[0] < 1e-8, drifts
    assert 3.6 < drifts[0] / drifts[1] < 4.4, drifts


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("n", [300, 1500])  # the direct sum; the symmetric one from 1024
def test_coulomb_conserves_momentum_to_round_off(dim, n):
    s = _plasma(n, dim, dt=1e-3, threads=2)
    p0 = s.momentum()
    scale = np.abs(s.masses[:, None] * s.velocities).sum()
    s.step(20)
    scale = max(scale, np.abs(s.masses[:, None] * s.velocities).sum())
    assert np.abs(s.momentum() - p0).max() < 1e-13 * scale


@pytest.mark.parametrize("integrator", ["boris", "verlet"])
def test_results_do_not_depend_on_the_thread_count(integrator):
    runs = []
    for threads in (1, 2, 3):
        s = _plasma(1100, 3, integrator=integrator, threads=threads, seed=5)
        s.add(pc.MagneticField([0.2, 0.0, 1.0]))
        b = np.zeros((3, 3, 3, 3))
        b[..., 2] = np.linspace(0.0, 1.0, 3)[:, None, None]
        s.add(pc.GridMagneticField(b, [-2.0, -2.0, -2.0], spacing=2.0))
        s.add(pc.GridElectricField(np.ones((2, 3, 2, 3)), [-2.0, -2.0, -2.0], spacing=[4.0, 2.0, 4.0]))
        s.step(5)
        runs.append((s.positions, s.velocities, s.energy().total))
    for other in runs[1:]:
        assert np.array_equal(other[0], runs[0][0]) and np.array_equal(other[1], runs[0][1])
        assert other[2] == runs[0][2]


def test_coulomb_time_scale_sets_the_suggested_step():
    # Two free unit charges at distance 1 (k = 1, m = 1): sqrt(r³ / (k q² (1/m + 1/m))) = 1/√2.
    s = pc.Scene(dim=2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, 1.0])
    s.set_attribute("charge", [1.0, -1.0])
    s.add(pc.Coulomb(k=1.0))
    assert s.suggest_dt() == pytest.approx(0.5 / math.sqrt(2), rel=1e-14)
    # A magnetic field adds the gyration time m/(|q|B).
    s.add(pc.MagneticField(4.0))
    assert s.suggest_dt() == pytest.approx(0.5 / 4.0, rel=1e-14)


# ------------------------------------------------------------------------------ grid fields
@pytest.mark.parametrize("dim", [2, 3])
def test_a_uniform_grid_field_is_the_uniform_field_to_the_bit(dim):
    E = np.array([0.3, -1.1, 0.7][:dim])
    B = np.array([0.5, 0.25, 2.0]) if dim == 3 else 2.0
    shape = (4, 3, 5)[:dim]
    runs = []
    for grid in (False, True):
        s = _plasma(30, dim, integrator="boris", seed=2)
        if grid:
            # Both grids span [-3, 3] on every axis.
            s.add(pc.GridElectricField(np.broadcast_to(E, (*shape, dim)), [-3.0] * dim, spacing=[2.0, 3.0, 1.5][:dim]))
            bv = np.broadcast_to(np.atleast_1d(B), (*shape, 3 if dim == 3 else 1))
            s.add(pc.GridMagneticField(bv, [-3.0] * dim, spacing=[2.0, 3.0, 1.5][:dim]))
        else:
            s.add(pc.ElectricField(E))
            s.add(pc.MagneticField(B))
        s.step(200)
        runs.append(s.positions)
    assert np.abs(runs[1]).max() < 3.0  # still inside the grids at the end (they move slowly)
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.parametrize("dim", [2, 3])
def test_a_linear_grid_field_is_interpolated_exactly_and_is_zero_outside(dim):
    rng = np.random.default_rng(1)
    A = rng.normal(size=(dim, dim))
    c = rng.normal(size=dim)
    origin = np.array([-1.0, 0.5, 2.0][:dim])
    spacing = np.array([0.25, 0.5, 0.125][:dim])
    shape = (5, 4, 6)[:dim]
    nodes = origin + np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1) * spacing
    E = nodes @ A.T + c
    far = origin + (np.array(shape) - 1) * spacing
    inside = origin + rng.uniform(0, 1, size=(200, dim)) * (far - origin)
    outside = np.array([origin - 0.01, far + 0.01, np.where(np.arange(dim) == 0, far + 1e-9, origin)])
    x = np.concatenate([inside, outside, [origin, far]])
    s = pc.Scene(dim=dim, integrator="euler", dt=DT_EXACT, threads=1)
    s.add_particles(x, masses=np.ones(len(x)))
    s.set_attribute("charge", np.ones(len(x)))
    s.add(pc.GridElectricField(E, origin, spacing=spacing))
    s.step()
    got = s.velocities / DT_EXACT  # q = m = 1: a = E(x)
    want = x @ A.T + c
    scale = np.abs(E).max()
    assert np.abs(got[:200] - want[:200]).max() < 1e-14 * scale * 10
    assert np.array_equal(got[200:203], np.zeros((3, dim)))
    assert np.allclose(got[203:], want[203:], rtol=0, atol=1e-14 * scale * 10)  # the corners are inside


def test_a_charge_leaving_the_magnetic_grid_flies_straight():
    # B_z = 1 on [0, 1]²: a charge starting inside circles only while inside; outside the
    # field is zero and it flies straight at its (kept) speed.
    s = _one(2, 1.0, 1.0, [2.0, 0.0], dt=1e-3, x=[0.5, 0.5])
    s.add(pc.GridMagneticField(np.ones((3, 3)), [0.0, 0.0], spacing=0.5))
    s.step(3000)
    v1 = s.velocities[0].copy()
    x1 = s.positions[0].copy()
    assert not np.all((x1 >= 0) & (x1 <= 1))
    s.step(100)
    assert np.allclose(s.velocities[0], v1, rtol=0, atol=0)
    assert np.allclose(s.positions[0], x1 + 100 * 1e-3 * v1, rtol=0, atol=1e-12)
    assert np.linalg.norm(v1) == pytest.approx(2.0, rel=1e-13)


def test_nonuniform_magnetic_field_keeps_the_speed_under_boris():
    # A magnetic bottle-like B(x) along z varying in x and y: Boris still only turns v.
    x = np.linspace(-2, 2, 9)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    B = np.stack([-0.5 * X * Z / 4, -0.5 * Y * Z / 4, 1 + Z**2 / 4], axis=-1)
    s = _one(3, 1.0, 1.0, [0.5, 0.0, 0.3], dt=0.05, x=[0.3, 0.0, 0.0])
    s.add(pc.GridMagneticField(B, [-2.0, -2.0, -2.0], spacing=0.5))
    k0 = s.energy().kinetic
    s.step(2000)
    assert np.all(np.abs(s.positions[0]) < 2)
    assert s.energy().kinetic == pytest.approx(k0, rel=1e-13)


# ------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "make, err, match",
    [
        (lambda: pc.Coulomb(k=0.0), pc.InvalidInputError, "k: must be > 0"),
        (lambda: pc.Coulomb(k=-1.0), pc.InvalidInputError, "k: must be > 0"),
        (lambda: pc.Coulomb(k=float("nan")), pc.InvalidInputError, "k: must be finite"),
        (lambda: pc.Coulomb(softening=-0.1), pc.InvalidInputError, "softening: must be >= 0"),
        (lambda: pc.Coulomb(k="1"), pc.InvalidTypeError, "k"),
        (lambda: pc.MagneticField([1.0, 2.0]), pc.InvalidInputError, "B: expected a number"),
        (lambda: pc.MagneticField([[1.0, 2.0, 3.0]]), pc.InvalidInputError, "B: expected a number"),
        (lambda: pc.MagneticField(float("nan")), pc.InvalidInputError, "B: must be finite"),
        (lambda: pc.MagneticField([0.0, float("inf"), 1.0]), pc.InvalidInputError, "B: must be finite"),
        (lambda: pc.MagneticField("strong"), pc.InvalidTypeError, "B"),
        (lambda: pc.GridElectricField(np.zeros((3, 3, 3)), [0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"E: expected shape \(nx, ny, 2\)"),
        (lambda: pc.GridElectricField(np.zeros((3, 3, 2)), [0.0, 0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"E: expected shape \(nx, ny, nz, 3\)"),
        (lambda: pc.GridElectricField(np.zeros((1, 3, 2)), [0.0, 0.0], spacing=1.0), pc.InvalidInputError, "E: a grid needs at least 2 nodes"),
        (lambda: pc.GridElectricField(np.full((2, 2, 2), np.nan), [0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"E: entry \(0, 0, 0\) is nan"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2)), [0.0, 0.0], spacing=0.0), pc.InvalidInputError, "spacing: must be finite and > 0"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2)), [0.0, 0.0], spacing=[1.0, -1.0]), pc.InvalidInputError, "spacing: must be finite and > 0"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2)), [0.0, 0.0], spacing=[1.0, 1.0, 1.0]), pc.InvalidInputError, "spacing: expected a number or shape"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2)), [0.0, np.nan], spacing=1.0), pc.InvalidInputError, "origin: must be finite"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2)), [0.0], spacing=1.0), pc.InvalidInputError, "origin: expected shape"),
        (lambda: pc.GridElectricField(np.zeros((2, 2, 2), dtype=complex), [0.0, 0.0], spacing=1.0), pc.InvalidTypeError, "E"),
        (lambda: pc.GridMagneticField(np.zeros((3, 3, 2)), [0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"B: expected shape \(nx, ny, 1\)"),
        (lambda: pc.GridMagneticField(np.zeros((3, 3, 3, 1)), [0.0, 0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"B: expected shape \(nx, ny, nz, 3\)"),
        (lambda: pc.GridMagneticField(np.zeros((3, 3, 3)), [0.0, 0.0, 0.0], spacing=1.0), pc.InvalidInputError, r"B: expected shape \(nx, ny, nz, 3\)"),
    ],
)
def test_bad_arguments_are_refused_by_name(make, err, match):
    with pytest.raises(err, match=match):
        make()


def test_the_scene_checks_what_depends_on_its_dimension():
    s2 = pc.Scene(dim=2, threads=1)
    s3 = pc.Scene(dim=3, threads=1)
    with pytest.raises(pc.InvalidInputError, match=r"B: in 2D only B_z .* \[1.0, 0.0\]"):
        s2.add(pc.MagneticField([1.0, 0.0, 2.0]))
    with pytest.raises(pc.InvalidInputError, match="B: has 1 component, the scene is 3D"):
        s3.add(pc.MagneticField(2.0))
    with pytest.raises(pc.InvalidInputError, match="origin: has 3 components, the scene is 2D"):
        s2.add(pc.GridElectricField(np.zeros((2, 2, 2, 3)), [0.0, 0.0, 0.0], spacing=1.0))
    with pytest.raises(pc.InvalidInputError, match="origin: has 2 components, the scene is 3D"):
        s3.add(pc.GridMagneticField(np.zeros((2, 2)), [0.0, 0.0], spacing=1.0))
    # A grid whose far corner overflows float64 is refused by the core, naming spacing.
    with pytest.raises(pc.InvalidInputError, match="spacing: the grid's far corner"):
        s2.add(pc.GridElectricField(np.zeros((3, 2, 2)), [1e308, 0.0], spacing=[1e308, 1.0]))
    assert s2.terms == () and s3.terms == ()
    # [0, 0, Bz] in 2D is B_z.
    assert s2.add(pc.MagneticField([0.0, 0.0, 2.0])) == pc.MagneticField(2.0, name="magnetic_field")


def test_records_compare_by_value_and_names_are_keyword_only():
    E = np.ones((2, 3, 2))
    assert pc.GridElectricField(E, [0, 0], spacing=1) == pc.GridElectricField(E.copy(), [0.0, 0.0], spacing=[1.0, 1.0])
    assert pc.GridElectricField(E, [0, 0], spacing=1) != pc.GridElectricField(2 * E, [0, 0], spacing=1)
    assert hash(pc.Coulomb(1.0, softening=0.1)) == hash(pc.Coulomb(1.0, softening=0.1)) and pc.Coulomb(1.0) != pc.Coulomb(2.0)
    assert pc.MagneticField(2) == pc.MagneticField([2.0])
    for make in (
        lambda: pc.Coulomb(1.0, 0.0, "c"),
        lambda: pc.MagneticField(1.0, "b"),
        lambda: pc.GridElectricField(E, [0, 0], 1.0, "g"),
        lambda: pc.GridMagneticField(np.ones((2, 2)), [0, 0], 1.0, "g"),
    ):
        with pytest.raises(TypeError, match="positional argument"):
            make()


# ------------------------------------------------------------------------------ files
@pytest.mark.parametrize("dim", [2, 3])
def test_save_and_load_continue_the_run_bit_for_bit(tmp_path, dim):
    def build():
        s = _plasma(12, dim, integrator="boris", seed=9)
        s.add(pc.MagneticField([0.0, 0.3, 1.0] if dim == 3 else 1.0, name="b"))
        s.add(pc.Drag(0.01))
        shape = (3, 4, 2)[:dim]
        e = np.random.default_rng(4).normal(size=(*shape, dim))
        s.add(pc.GridElectricField(e, [-2.0] * dim, spacing=[2.0, 4 / 3, 4.0][:dim], name="ge"))
        b = np.random.default_rng(5).normal(size=(*shape, 3)) if dim == 3 else np.random.default_rng(5).normal(size=shape)
        s.add(pc.GridMagneticField(b, [-2.0] * dim, spacing=2.0, name="gb"))
        return s

    a, b = build(), build()
    a.step(50)
    b.step(50)
    path = a.save(tmp_path / "charges.npz")
    c = pc.Scene.load(path)
    assert c.terms == a.terms and c.integrator == "boris"
    b.step(50)
    c.step(50)
    assert np.array_equal(b.positions, c.positions) and np.array_equal(b.velocities, c.velocities)
    assert b.energy() == c.energy()


def test_integrator_table_lists_boris():
    row = next(d for d in pc.INTEGRATORS if d["name"] == "boris")
    assert row == {"name": "boris", "order": 2, "symplectic": False, "force_evals_per_step": 1}
    s = _one(2, 1.0, 1.0, [1.0, 0.0])
    s.add(pc.MagneticField(1.0))
    s.add(pc.ElectricField([0.1, 0.0]))
    s.step(1)
    first = s.force_evaluations
    s.step(10)
    assert first == 2 and s.force_evaluations - first == 10
