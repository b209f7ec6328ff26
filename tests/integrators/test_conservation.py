"""Conservation laws and energy books: property tests on random spring networks, Kepler orbits,
momentum and angular momentum, dissipative terms, and a bouncing ball."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SYMPLECTIC, random_cloud, random_network, sample, total_energy
from hypothesis import given
from hypothesis import strategies as st

import physcore as pc

seeds = st.integers(min_value=0, max_value=2**32 - 1)

# ----------------------------------------------------------------------------- spring networks
#: ω_max·dt for the network tests: suggest_dt() is 1/(2 ω_max) for a Gershgorin bound of ω_max.
H_NET = 0.1


def _network_drift(seed: int, n: int, n_pinned: int, dim: int, integrator: str, speed: float, n_steps: int = 12_000):
    # About 3 springs per particle: mostly rigid networks (few floppy mechanisms).
    s = random_network(seed, n, dim=dim, n_pinned=n_pinned, integrator=integrator, speed=speed, n_springs=min(3 * n, n * (n - 1) // 2))
    s.dt = H_NET * 2 * s.suggest_dt()
    e = np.array(sample(s, n_steps, 10, total_energy))
    # Springs start at their rest length, so E0 is the (positive) kinetic energy.
    assert e[0] > 0
    return (e - e[0]) / e[0]


def _max_error_bound(integrator: str) -> float:
    # Backward error analysis: |ΔE|/E = O(h^p), p the order, h = ω_max·dt = 0.1.
    return H_NET ** (2 if integrator == "verlet" else 1)


def _grows(d: np.ndarray) -> bool:
    """Whether the error in the last quarter of the run exceeds 3x that of the first quarter (a
    secular drift c·t gives 4x; a bounded quasi-periodic error does not grow)."""
    q = len(d) // 4
    return bool(np.abs(d[-q:]).max() >= 3 * np.abs(d[1 : q + 1]).max() + 1e-12)


@pytest.mark.parametrize("integrator", SYMPLECTIC)
@given(seed=seeds, n=st.integers(3, 8), n_pinned=st.integers(0, 2), dim=st.sampled_from([2, 3]))
def test_symplectic_energy_error_bounded_without_drift(integrator, seed, n, n_pinned, dim):
    # Small oscillations (near-linear, quasi-periodic motion): a secular drift would show as a
    # larger error in the last quarter of the run than in the first.
    args = (seed, n, min(n_pinned, n - 2), dim, integrator)
    d = _network_drift(*args, speed=0.05)
    assert np.all(np.isfinite(d))
    assert np.abs(d).max() < _max_error_bound(integrator)
    if _grows(d):
        # Two modes of nearly equal frequency beat more slowly than the run: the error's envelope
        # can then rise through the whole run (seed 108986615, n = 6, 1 pinned, 2D, yoshida4:
        # first quarter 3.5e-8, last 1.3e-7), and fall again later (over a run 4x as long its
        # largest error is in the first quarter). A drift keeps growing over the longer run.
        d = _network_drift(*args, speed=0.05, n_steps=48_000)
        assert np.abs(d).max() < _max_error_bound(integrator)
        assert not _grows(d)


def test_drift_criterion_detects_explicit_euler():
    # The same criterion must flag a non-symplectic method that gains energy: explicit Euler
    # multiplies each normal mode's energy by (1 + (ω dt)²) per step.
    s = random_network(7, 6, dim=2, integrator="euler", speed=0.05, n_springs=15)
    s.dt = H_NET * 2 * s.suggest_dt()
    e = np.array(sample(s, 4000, 10, total_energy))
    d = (e - e[0]) / e[0]
    assert _grows(d)
    assert d[-1] > 0


# ----------------------------------------------------------------------------- Kepler orbits
STEPS_PER_ORBIT = 1000
N_ORBITS = 10


def _kepler_energy_error(e: float, mass_ratio: float, integrator: str):
    s = pc.scenes.kepler(e=e, mass_ratio=mass_ratio, integrator=integrator, steps_per_orbit=STEPS_PER_ORBIT)
    m1, m2 = (1.0, 1.0) if mass_ratio == 0 else (1 / (1 + mass_ratio), mass_ratio / (1 + mass_ratio))
    e_exact = -m1 * m2 / 2.0  # -G m1 m2 / (2a), G = a = 1
    energies = np.array(sample(s, N_ORBITS * STEPS_PER_ORBIT, 2, total_energy))
    assert energies[0] == pytest.approx(e_exact, rel=1e-13)
    return (energies - energies[0]) / abs(energies[0])


@pytest.mark.parametrize("integrator", SYMPLECTIC)
@given(e=st.floats(0.0, 0.7), mass_ratio=st.sampled_from([0.0, 1e-3, 0.3, 1.0]))
def test_kepler_energy_error_bounded(integrator, e, mass_ratio):
    d = _kepler_energy_error(e, mass_ratio, integrator)
    per_orbit = STEPS_PER_ORBIT // 2 + 1  # samples every 2 steps
    first_orbit = np.abs(d[:per_orbit]).max()
    last_orbit = np.abs(d[-per_orbit:]).max()
    # Bounded: a symplectic method's energy error repeats orbit after orbit (it peaks at each
    # pericentre passage), so the last orbit looks like the first: no secular growth.
    assert last_orbit <= 1.5 * first_orbit + 1e-12
    if integrator == "verlet":
        assert abs(d[-1]) <= 1.01 * first_orbit + 1e-12
        assert first_orbit < 1e-2
    else:
        assert first_orbit < 1e-1


def test_kepler_rk4_energy_drifts_secularly_but_slowly():
    # RK4 is not symplectic: its energy error accumulates (a contrast with the test above), but
    # at 1000 steps/orbit it is far smaller than Verlet's.
    d = _kepler_energy_error(0.6, 0.0, "rk4")
    per_orbit = STEPS_PER_ORBIT // 2 + 1
    assert np.abs(d[-per_orbit:]).max() > 2 * np.abs(d[:per_orbit]).max()
    assert np.abs(d).max() < 1e-6


# ----------------------------------------------------------------------------- momentum
def _free_cloud_scene(seed: int, n: int, dim: int, integrator: str) -> pc.Scene:
    x, v, m = random_cloud(seed, n, dim=dim)
    s = pc.Scene(dim, integrator=integrator, dt=1e-3, threads=1)
    s.add_particles(x, v, masses=m)
    rng = np.random.default_rng(seed + 1)
    k = max(1, n - 1)
    i = rng.integers(0, n, size=k)
    j = (i + rng.integers(1, n, size=k)) % n  # never equal to i
    s.add(pc.Springs(i, j, stiffness=rng.uniform(1.0, 10.0, size=k)))
    # Weak, strongly softened gravity: smooth forces whose time scale is not far below the springs'.
    s.add(pc.PairwiseGravity(G=0.05, softening=0.3))
    s.dt = H_NET * 2 * s.suggest_dt()
    return s


def _momentum_scale(s: pc.Scene) -> float:
    return float((s.masses[:, None] * np.abs(s.velocities)).sum())


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit_euler", "verlet", "rk4"])
@given(seed=seeds, n=st.integers(2, 10), dim=st.sampled_from([2, 3]))
def test_linear_momentum_conserved_to_round_off(integrator, seed, n, dim):
    s = _free_cloud_scene(seed, n, dim, integrator)
    p0 = s.momentum()
    samples = sample(s, 2000, 100, lambda s: (s.momentum(), _momentum_scale(s)))
    scale = max(sc for _, sc in samples)
    for p, _ in samples:
        assert np.all(np.abs(p - p0) <= 1e-12 * scale)


def _angular_scale(s: pc.Scene) -> float:
    x, v, m = s.positions, s.velocities, s.masses
    return float((m * np.linalg.norm(x, axis=1) * np.linalg.norm(v, axis=1)).sum())


@pytest.mark.parametrize("integrator", SYMPLECTIC)
@given(seed=seeds, n=st.integers(2, 10), dim=st.sampled_from([2, 3]))
def test_angular_momentum_conserved_by_symplectic_methods(integrator, seed, n, dim):
    # Kick (central pair forces: Σ x_i × f_i = 0) and drift (Σ m v × v = 0) each conserve L
    # exactly, so only round-off remains.
    s = _free_cloud_scene(seed, n, dim, integrator)
    l0 = np.atleast_1d(s.angular_momentum())
    samples = sample(s, 2000, 100, lambda s: (np.atleast_1d(s.angular_momentum()), _angular_scale(s)))
    scale = max(sc for _, sc in samples)
    for am, _ in samples:
        assert np.all(np.abs(am - l0) <= 1e-10 * scale)


def test_explicit_euler_does_not_conserve_angular_momentum():
    # Contrast: explicit Euler changes L by dt² Σ v × f per step, so the check above can fail.
    s = _free_cloud_scene(3, 6, 3, "euler")
    l0 = s.angular_momentum()
    s.step(2000)
    assert np.abs(s.angular_momentum() - l0).max() > 1e-6 * _angular_scale(s)


def test_kepler_angular_momentum_exact_for_verlet():
    s = pc.scenes.kepler(e=0.6, mass_ratio=0.0, integrator="verlet")
    l0 = s.angular_momentum()
    assert isinstance(l0, float)
    # Test particle of mass 1 at pericentre r = a(1-e) with speed sqrt((1+e)/(a(1-e))).
    assert l0 == pytest.approx(math.sqrt(1 - 0.6**2), rel=1e-14)
    s.step(5000)
    assert s.angular_momentum() == pytest.approx(l0, rel=1e-12)


# ----------------------------------------------------------------------------- dissipation
def _damped_network(seed: int, integrator: str) -> pc.Scene:
    s = random_network(seed, 6, dim=3, n_pinned=seed % 2, integrator=integrator, damping=0.5, speed=1.0)
    s.add(pc.Drag(0.3))
    s.dt = H_NET * 2 * s.suggest_dt()
    return s


@given(seed=seeds)
def test_dissipation_books_balance_rk4(seed):
    s = _damped_network(seed, "rk4")
    reports = sample(s, 4000, 10, lambda s: s.energy())
    total = np.array([r.total for r in reports])
    mech = np.array([r.mechanical for r in reports])
    # The total (mechanical + dissipated) is conserved by the exact dynamics: RK4 with its own
    # quadrature of the dissipated power keeps it to O(h⁴).
    assert np.abs(total - total[0]).max() < H_NET**4 * abs(total[0])
    # Mechanical energy decreases (dissipation is the only thing happening to it)...
    assert np.all(np.diff(mech) <= 1e-12 * mech[0])
    assert mech[-1] < 0.5 * mech[0]
    # ...and every dissipation account starts at 0, is never negative and never decreases.
    assert set(reports[0].dissipated) == {"springs", "drag"}
    for name in ("springs", "drag"):
        d = np.array([r.dissipated[name] for r in reports])
        assert d[0] == 0.0
        assert np.all(d >= 0)
        assert np.all(np.diff(d) >= 0)
        assert d[-1] > 0
    # The books add up: what mechanical energy lost went into the dissipation accounts.
    lost = mech[0] - mech[-1]
    assert sum(reports[-1].dissipated.values()) == pytest.approx(lost, rel=H_NET**4)


@pytest.mark.parametrize("integrator", ["verlet", "semi_implicit_euler"])
def test_dissipation_books_balance_first_order_methods(integrator):
    # Verlet evaluates velocity-dependent forces at the half-step velocity (and the Euler
    # variants are first order anyway): the books then balance to O(h), not better.
    for seed in range(3):
        s = _damped_network(seed, integrator)
        reports = sample(s, 4000, 10, lambda s: s.energy())
        total = np.array([r.total for r in reports])
        assert np.abs(total - total[0]).max() < H_NET * abs(total[0])
        for r0, r1 in zip(reports, reports[1:], strict=False):
            for name in r0.dissipated:
                assert 0 <= r0.dissipated[name] <= r1.dissipated[name]


def test_drag_decays_velocity_exponentially():
    # A free particle with linear drag b: v(t) = v0 exp(-b t / m); energy dissipated = ½ m v0² (1 - e^{-2bt/m}).
    m, b, v0, dt = 2.0, 0.5, 3.0, 1e-3
    s = pc.Scene(2, integrator="rk4", dt=dt, threads=1)
    s.add_particles([[0.0, 0.0]], [[v0, 0.0]], masses=m)
    s.add(pc.Drag(b))
    s.step(2000)
    t = s.time
    assert s.velocities[0, 0] == pytest.approx(v0 * math.exp(-b * t / m), rel=1e-10)
    assert s.positions[0, 0] == pytest.approx(v0 * m / b * (1 - math.exp(-b * t / m)), rel=1e-10)
    assert s.energy().dissipated["drag"] == pytest.approx(0.5 * m * v0**2 * (1 - math.exp(-2 * b * t / m)), rel=1e-10)


# ----------------------------------------------------------------------------- collisions
@pytest.mark.parametrize("integrator", ["verlet", "rk4"])
@pytest.mark.parametrize("e", [0.5, 0.8])
def test_bouncing_ball_apex_heights_and_books(integrator, e):
    g, h0, dt = 9.81, 1.0, 1e-4
    s = pc.Scene(2, integrator=integrator, dt=dt, threads=1)
    s.add_particles([[0.0, h0]], [[0.3, 0.0]], masses=1.5)
    s.add(pc.Gravity([0.0, -g]))
    s.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=e))
    e0 = s.energy()
    ys, vys = [], []
    n_bounces = 4
    t_end = sum(2 * math.sqrt(2 * h0 * e ** (2 * k) / g) for k in range(n_bounces + 1))  # a little past bounce 4's apex
    for _ in range(int(t_end / dt)):
        s.step(1)
        ys.append(s.positions[0, 1])
        vys.append(s.velocities[0, 1])
    ys, vys = np.array(ys), np.array(vys)
    assert ys.min() >= 0.0  # never left below the plane after a step
    top = np.flatnonzero((vys[:-1] > 0) & (vys[1:] <= 0))
    apex = np.maximum(ys[top], ys[top + 1])
    assert len(apex) >= n_bounces
    # Each bounce scales the normal speed by e, hence the apex height by e².
    np.testing.assert_allclose(apex[:n_bounces], h0 * e ** (2 * np.arange(1, n_bounces + 1)), rtol=0.02)
    np.testing.assert_allclose(apex[1:n_bounces] / apex[: n_bounces - 1], e**2, atol=0.01)
    # Books: Verlet and RK4 are exact under constant gravity and the collider books the
    # projection work exactly, so the total is conserved and "collisions" holds the loss.
    r = s.energy()
    assert set(r.dissipated) == {"collisions"}
    assert r.total == pytest.approx(e0.total, rel=1e-9)
    assert r.dissipated["collisions"] == pytest.approx(e0.mechanical - r.mechanical, rel=1e-9)
    assert r.dissipated["collisions"] > 0.5 * e0.mechanical * (1 - e**2)


def test_plane_friction_never_reverses_tangential_velocity():
    # A ball sliding into a plane with huge friction: the tangential speed stops at zero.
    s = pc.Scene(2, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.01]], [[1.0, -5.0]])
    s.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.5, friction=10.0))
    s.step(10)
    assert s.velocities[0, 0] == 0.0
    assert s.velocities[0, 1] > 0  # bounced
    assert s.energy().dissipated["collisions"] > 0
