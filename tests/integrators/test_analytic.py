"""Closed-form solutions: free motion, constant acceleration, Kepler orbits, a hanging spring."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import EPS, INTEGRATOR_NAMES

import physcore as pc

# dt = 2⁻¹⁰ s is exact in binary, so t = n·dt is exact and only arithmetic round-off remains.
DT_EXACT = 2.0**-10


# ----------------------------------------------------------------------------- free particle
@pytest.mark.parametrize("name", INTEGRATOR_NAMES)
@pytest.mark.parametrize("dim", [2, 3])
def test_free_particles_move_in_straight_lines(name, dim):
    rng = np.random.default_rng(dim)
    x0 = rng.uniform(-5, 5, size=(7, dim))
    v0 = rng.uniform(-3, 3, size=(7, dim))
    s = pc.Scene(dim, integrator=name, dt=DT_EXACT, threads=1)
    s.add_particles(x0, v0, masses=rng.uniform(0.1, 10, size=7))
    n = 3000
    s.step(n)
    t = n * DT_EXACT
    assert s.time == t
    # No force: the velocity is untouched bit for bit, the position advances linearly.
    np.testing.assert_array_equal(s.velocities, v0)
    scale = np.abs(x0) + np.abs(v0) * t
    assert np.all(np.abs(s.positions - (x0 + v0 * t)) <= 4 * n * EPS * scale)


# ----------------------------------------------------------------------------- projectile
def _projectile(name: str, n: int):
    g = np.array([0.0, -9.81, 0.0])
    x0 = np.array([[1.0, 2.0, -0.5]])
    v0 = np.array([[3.0, 12.0, 0.7]])
    s = pc.Scene(3, integrator=name, dt=DT_EXACT, threads=1)
    s.add_particles(x0, v0, masses=2.5)
    s.add(pc.Gravity(g))
    s.step(n)
    t = n * DT_EXACT
    exact_x = x0 + v0 * t + 0.5 * g * t * t
    exact_v = v0 + g * t
    scale = np.abs(x0) + np.abs(v0) * t + 0.5 * np.abs(g) * t * t
    return s, t, g, exact_x, exact_v, scale


@pytest.mark.parametrize("name", ["verlet", "rk4"])
def test_projectile_exact_for_second_and_fourth_order(name):
    # Both methods integrate constant acceleration exactly (the solution is a quadratic).
    n = 2048
    s, t, g, ex, ev, scale = _projectile(name, n)
    assert np.all(np.abs(s.positions - ex) <= 4 * n * EPS * scale)
    assert np.all(np.abs(s.velocities - ev) <= 4 * n * EPS * (np.abs(ev) + np.abs(g) * t))


@pytest.mark.parametrize("name, sign", [("semi_implicit_euler", +1), ("euler", -1)])
def test_projectile_first_order_offset(name, sign):
    # Kick-then-drift gives x_n = x0 + v0 t + g t²/2 + g t dt/2; drift-then-kick gives the same
    # with -g t dt/2. Velocities are exact (v_n = v0 + n g dt) for both.
    n = 2048
    s, t, g, ex, ev, scale = _projectile(name, n)
    offset = sign * 0.5 * g * t * DT_EXACT
    assert np.all(np.abs(s.positions - (ex + offset)) <= 4 * n * EPS * scale)
    assert np.all(np.abs(s.velocities - ev) <= 4 * n * EPS * (np.abs(ev) + np.abs(g) * t))
    # and the offset is the whole error, bounded by g t dt:
    assert np.all(np.abs(s.positions - ex) <= np.abs(g) * t * DT_EXACT + 4 * n * EPS * scale)


def test_projectile_scene_matches_closed_form():
    s = pc.scenes.projectile(n=4, speed=15.0, ground=False, integrator="verlet", dt=DT_EXACT)
    v0 = s.velocities.copy()
    speeds = np.linalg.norm(v0, axis=1)
    angles = np.arctan2(v0[:, 1], v0[:, 0])
    np.testing.assert_allclose(speeds, 15.0, rtol=1e-14)
    np.testing.assert_allclose(np.degrees(angles), np.linspace(20.0, 70.0, 4), rtol=1e-12)
    n = 1500
    s.step(n)
    t = n * DT_EXACT
    x = np.stack([15.0 * np.cos(angles) * t, 15.0 * np.sin(angles) * t - 0.5 * 9.81 * t * t], axis=1)
    np.testing.assert_allclose(s.positions, x, rtol=0, atol=1e-11)


# ----------------------------------------------------------------------------- Kepler
def _kepler_return_error(steps_per_orbit: int, orbits: int) -> float:
    s = pc.scenes.kepler(e=0.5, mass_ratio=0.0, integrator="rk4", steps_per_orbit=steps_per_orbit)
    x0, v0 = s.positions[1].copy(), s.velocities[1].copy()
    s.step(orbits * steps_per_orbit)
    assert s.time == pytest.approx(orbits * 2 * math.pi, rel=1e-12)
    return float(np.linalg.norm(np.concatenate([s.positions[1] - x0, s.velocities[1] - v0])))


def test_kepler_test_particle_returns_after_whole_orbits():
    # P = 2π sqrt(a³/(GM)) = 2π: after 10 orbits the particle is back where it started.
    assert _kepler_return_error(1000, 10) < 1e-5
    assert _kepler_return_error(1000, 1) < 1e-6


def test_kepler_return_error_is_fourth_order():
    e1 = _kepler_return_error(1000, 1)
    e2 = _kepler_return_error(2000, 1)
    assert math.log2(e1 / e2) == pytest.approx(4.0, abs=0.3)


def test_kepler_initial_conditions():
    e, a = 0.5, 2.0
    s = pc.scenes.kepler(e=e, a=a, mass_ratio=0.0)
    x, v = s.positions, s.velocities
    assert s.pinned.tolist() == [True, False]
    np.testing.assert_array_equal(x[0], [0.0, 0.0])
    assert x[1] == pytest.approx([a * (1 - e), 0.0])
    # Vis-viva at pericentre: v² = GM (2/r - 1/a).
    assert v[1] @ v[1] == pytest.approx(2 / (a * (1 - e)) - 1 / a, rel=1e-14)
    assert s.energy().total == pytest.approx(-1 / (2 * a), rel=1e-14)


@pytest.mark.parametrize("mass_ratio", [0.3, 1.0])
def test_two_body_period(mass_ratio):
    # Two free bodies, G = 1, total mass 1, a = 2: the relative orbit has P = 2π sqrt(8).
    a, e, dt = 2.0, 0.4, 1e-3
    s = pc.scenes.kepler(e=e, a=a, mass_ratio=mass_ratio, integrator="rk4", dt=dt)
    m = s.masses
    assert m.sum() == pytest.approx(1.0, rel=1e-15)
    assert m[1] / m[0] == pytest.approx(mass_ratio, rel=1e-14)
    p = s.momentum()
    assert np.all(np.abs(p) <= 1e-15)
    period = 2 * math.pi * math.sqrt(a**3)
    # Time the relative vector's passages through the +x axis (pericentre), interpolating.
    crossings = []
    r_prev = s.positions[1] - s.positions[0]
    t_prev = s.time
    while len(crossings) < 2:
        s.step(1)
        r = s.positions[1] - s.positions[0]
        if r_prev[1] < 0 <= r[1] and r[0] > 0:
            crossings.append(t_prev + (s.time - t_prev) * (-r_prev[1]) / (r[1] - r_prev[1]))
        r_prev, t_prev = r, s.time
        assert s.time < 3 * period, "no pericentre passage found"
    assert crossings[0] == pytest.approx(period, rel=1e-6)
    assert crossings[1] - crossings[0] == pytest.approx(period, rel=1e-6)
    # Apocentre distance a(1+e), pericentre a(1-e), and the centre of mass stays put.
    s2 = pc.scenes.kepler(e=e, a=a, mass_ratio=mass_ratio, integrator="rk4", dt=dt)
    com0 = (s2.masses[:, None] * s2.positions).sum(axis=0)
    s2.step(round(period / 2 / dt))
    r = s2.positions[1] - s2.positions[0]
    assert np.linalg.norm(r) == pytest.approx(a * (1 + e), rel=1e-5)
    com = (s2.masses[:, None] * s2.positions).sum(axis=0)
    assert np.all(np.abs(com - com0) <= 1e-12)


# ----------------------------------------------------------------------------- hanging spring
@pytest.mark.parametrize("name", ["semi_implicit_euler", "verlet", "rk4"])
def test_hanging_spring_settles_at_mg_over_k(name):
    m, k, g, rest, b = 0.5, 80.0, 9.81, 0.3, 4.0
    s = pc.Scene(2, integrator=name, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0], [0.0, -rest]], masses=[1.0, m], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=k, rest_length=rest))
    s.add(pc.Gravity([0.0, -g]))
    s.add(pc.Drag(b))
    # Damping rate b/(2m) = 4/s: after 8 s transients are down by e^-32.
    s.step(8000)
    x = s.positions[1]
    assert x[0] == 0.0
    assert x[1] == pytest.approx(-(rest + m * g / k), rel=1e-10)
    assert np.all(np.abs(s.velocities[1]) < 1e-10)
    # At rest, the books: potential = ½ k (mg/k)² - m g y; what was lost went to drag.
    e = s.energy()
    ext = m * g / k
    assert e.potential["springs"] == pytest.approx(0.5 * k * ext**2, rel=1e-9)
    assert e.potential["gravity"] == pytest.approx(m * g * x[1], rel=1e-12)
    assert e.dissipated["drag"] > 0
