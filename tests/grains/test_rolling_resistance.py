"""Rolling resistance of physcore.Contacts (issue 44, item 16): the elastic–plastic
spring–dashpot of Ai, Chen, Rotter & Ooi (2011, model C), and the tangential stiffness default
(item 17). Every expected value comes from mechanics, not from a stored run:

* a grain rolling without slipping on a floor at v₀ has kinetic energy ½(1 + β) m v²; a rolling
  torque at its limit μ_r R* f_n = μ_r r m g takes it out at the rate μ_r r m g · ω =
  μ_r m g v, so the grain decelerates at μ_r g/(1 + β) and stops after
  s = (1 + β) v₀² / (2 μ_r g), plus the rolling spring's give (≈ m g /(2.25 k μ_r), 4e-5 m
  here, 0.02 % of s);
* on a slope θ the spring holds the grain while tan θ ≤ μ_r (the friction force m g sin θ at the
  contact needs a torque m g sin θ · r, the limit being μ_r r m g cos θ); past it the grain
  rolls down at g (sin θ − μ_r cos θ)/(1 + β).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_contacts import _gas as _contacts_gas

import physcore as pc

G = 9.81
R, M, K = 0.01, 0.01, 1e4


def _floor(dim: int, mu_r: float, v0: float, *, law: str = "linear", threads: int = 1,
           integrator: str = "semi_implicit_euler") -> pc.Scene:
    """One grain resting on a floor (static overlap: no bounce), rolling without slipping at v0."""
    k = K if law == "linear" else 3e6
    d0 = M * G / k if law == "linear" else (M * G / k) ** (2 / 3)
    x = np.zeros((1, dim))
    x[0, 1] = R - d0
    v = np.zeros((1, dim))
    v[0, 0] = v0
    s = pc.Scene(dim=dim, integrator=integrator, threads=threads, xpbd_substeps=10)
    s.add_particles(x, v, masses=M)
    s.set_attribute("radius", [R])
    g = np.zeros(dim)
    g[1] = -G
    s.add(pc.Gravity(g))
    s.add(pc.Contacts(stiffness=k, restitution=0.5, friction=0.5, law=law, rolling_friction=mu_r,
                      walls=pc.Plane(np.zeros(dim), np.eye(dim)[1], restitution=0.5, friction=0.5)))
    # Rolling without slipping along +x: ω = −v0/a about z, a = r − δ/2 the lever to the
    # contact point (the term's history: n, ω, angle, the two books).
    a = R - 0.5 * d0
    w = [-v0 / a] if dim == 2 else [0.0, 0.0, -v0 / a]
    s._sim.set_term_history("contacts", np.array([1.0, *w, 0.0, 0.0, 0.0]))
    return s


def _beta(dim: int) -> float:
    return 0.5 if dim == 2 else 0.4


@pytest.mark.parametrize("law", ["linear", "hertz"])
@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_rolling_on_a_floor_stops_where_its_rolling_friction_says(dim, law):
    mu_r, v0 = 0.1, 0.5
    beta = _beta(dim)
    s = _floor(dim, mu_r, v0, law=law)
    e0 = s.energy()
    want = (1 + beta) * v0**2 / (2 * mu_r * G)  # 0.191 m (disc), 0.178 m (sphere)
    t_stop = v0 * (1 + beta) / (mu_r * G)
    s.advance(0.5 * t_stop)
    # Half way in time, three quarters of the way: constant deceleration (measured: within
    # 1.1e-4 of it).
    assert abs(float(s.positions[0, 0]) - 0.75 * want) < 2e-3 * want
    s.advance(0.5 * t_stop + 0.2)
    travelled = float(s.positions[0, 0])
    # Measured: 3.6e-4 to 5.3e-4 short of s. The formula takes the lever to the contact point
    # as r; the model's is r − δ/2 (δ/r = 1e-3 here), worth −1.6e-4; the rest is the rolling
    # spring's give and the steps' first-order error.
    assert abs(travelled - want) < 2e-3 * want, (travelled, want)
    assert np.abs(s.velocities[0]).max() < 1e-3 * v0  # at rest
    s.advance(0.3)
    assert abs(float(s.positions[0, 0]) - travelled) < 1e-4 * want  # and stays
    # The energy books: what the grain lost (its kinetic energy, ½(1 + β) m v0² to 3.4e-4: the
    # spin is v0/(r − δ/2)) is in the friction ledger, and kinetic + potential + dissipated is
    # conserved (measured: both to 2.5e-10 of the kinetic energy).
    rep = s.energy()
    lost = rep.dissipated["contacts (friction)"]
    assert abs(lost - e0.kinetic) < 1e-6 * e0.kinetic, (lost, e0.kinetic)
    assert abs(lost - 0.5 * (1 + beta) * M * v0**2) < 2e-3 * lost, lost
    assert abs(rep.total - e0.total) < 1e-6 * e0.kinetic, (rep.total, e0.total)


@pytest.mark.parametrize("dim", [2, 3])
def test_rolling_friction_acts_in_xpbd_substeps_too(dim):
    # Under "xpbd" the contacts are its external forces in every substep; the rolling springs
    # follow the spins once a substep has ended (after the projections). Measured: 5.4e-4 and
    # 6.2e-4 short of s, the books to 1.2e-9 of the kinetic energy.
    mu_r, v0 = 0.1, 0.5
    s = _floor(dim, mu_r, v0, integrator="xpbd")
    e0 = s.energy()
    s.dt = 4e-4  # 10 substeps of 4e-5 s: under a 50th of a contact
    s.step(3000)
    want = (1 + _beta(dim)) * v0**2 / (2 * mu_r * G)
    assert abs(float(s.positions[0, 0]) - want) < 2e-3 * want
    assert np.abs(s.velocities[0]).max() < 1e-3 * v0
    rep = s.energy()
    assert abs(rep.dissipated["contacts (friction)"] - e0.kinetic) < 1e-6 * e0.kinetic
    assert abs(rep.total - e0.total) < 1e-6 * e0.kinetic


@pytest.mark.parametrize("dim", [2, 3])
def test_without_rolling_friction_a_grain_rolls_on(dim):
    v0 = 0.5
    s = _floor(dim, 0.0, v0)
    s.advance(1.0)
    # Measured: 1.9e-6 of v0 lost in 1 s (the dashpots' response to the steps' jitter).
    assert abs(float(s.velocities[0, 0]) - v0) < 1e-5 * v0
    assert abs(float(s.positions[0, 0]) - v0 * 1.0) < 1e-5


def _slope(theta_deg: float, mu_r: float, dim: int = 2) -> tuple[pc.Scene, np.ndarray]:
    th = math.radians(theta_deg)
    normal = np.zeros(dim)
    normal[0], normal[1] = math.sin(th), math.cos(th)  # slope going down towards +x
    down = np.zeros(dim)
    down[0], down[1] = math.cos(th), -math.sin(th)
    r, m, k = 0.05, 0.1, 1e5
    x = (r - m * G * math.cos(th) / k) * normal
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", threads=1)
    s.add_particles(x[None, :], masses=m)
    s.set_attribute("radius", [r])
    g = np.zeros(dim)
    g[1] = -G
    s.add(pc.Gravity(g))
    s.add(pc.Contacts(stiffness=k, restitution=0.5, friction=0.8, rolling_friction=mu_r,
                      walls=pc.Plane(np.zeros(dim), normal, restitution=0.5, friction=0.8)))
    return s, down


@pytest.mark.parametrize("dim", [2, 3])
def test_rolling_friction_holds_a_grain_on_a_slope_below_its_angle(dim):
    # tan 10° = 0.176 < μ_r = 0.2: the rolling spring holds the grain. It gives way by its
    # static angle m g sinθ r / k_r (3.8e-4 rad: 1.9e-5 m at r = 0.05) and the tangential
    # spring's stretch (5e-6 m); released at once it swings past them, and the first swing,
    # asking for more than the limiting torque (9.5e-3 N·m against 8.5e-3 N·m held), slips a
    # little: measured 5.9e-5 m (2D) and 6.2e-5 m (3D), then not a bit further.
    s, down = _slope(10.0, 0.2, dim)
    x0 = s.positions[0].copy()
    s.advance(0.5)
    moved = float((s.positions[0] - x0) @ down)
    assert 0.0 < moved < 1.5e-4, moved
    s.advance(0.5)
    assert abs(float((s.positions[0] - x0) @ down) - moved) < 1e-6


@pytest.mark.parametrize("dim", [2, 3])
def test_past_its_angle_a_grain_rolls_down_slowed_by_rolling_friction(dim):
    # tan 30° = 0.577 > μ_r = 0.2: a = g (sinθ − μ_r cosθ)/(1 + β).
    s, down = _slope(30.0, 0.2, dim)
    ts, ds = [], []
    x0 = s.positions[0].copy()
    for _ in range(12):
        s.advance(0.05)
        ts.append(s.time)
        ds.append(float((s.positions[0] - x0) @ down))
    a = 2.0 * np.polyfit(ts, ds, 2)[0]
    th = math.radians(30.0)
    want = G * (math.sin(th) - 0.2 * math.cos(th)) / (1 + _beta(dim))
    assert abs(a - want) < 0.005 * want, (a, want)


def _gas(n: int, seed: int, mu_r: float, dim: int = 2, threads: int = 1) -> pc.Scene:
    """test_contacts' granular gas (friction 0.5, restitution 0.7) with rolling resistance μ_r."""
    return _contacts_gas(n, seed, 0.5, 0.7, dim, threads, rolling_friction=mu_r)


@pytest.mark.parametrize("dim", [2, 3])
def test_rolling_friction_conserves_momentum_and_angular_momentum(dim):
    # The rolling torques are couples (+M on one grain, −M on the other): L is conserved to
    # round-off, as without them.
    s = _gas(300 if dim == 2 else 216, seed=3, mu_r=0.3, dim=dim)
    p0, l0 = s.momentum(), np.atleast_1d(s.angular_momentum())
    s.step(3000)
    p_scale = float(np.sum(s.masses[:, None] * np.abs(s.velocities))) + 1e-300
    l_scale = p_scale * float(np.abs(s.positions).max())
    assert np.abs(s.momentum() - p0).max() < 1e-13 * max(p_scale, 1.0)
    assert np.abs(np.atleast_1d(s.angular_momentum()) - l0).max() < 1e-12 * max(l_scale, 1.0)


def test_the_energy_books_of_a_gas_with_rolling_friction_balance():
    # As test_contacts' books test: each torque's power at a step's end is taken as applied,
    # so the books balance to rounding, the rolling springs included (measured 0.0; through
    # the new normal's rolling part and levers they drifted 4.1e-4 in these 800 steps).
    s = _gas(60, seed=5, mu_r=0.3)
    e0 = s.energy().total
    s.step(800)
    rep = s.energy()
    assert sum(rep.dissipated.values()) > 0.05 * e0
    assert abs(rep.total - e0) / e0 < 1e-13


def test_one_and_two_threads_give_bit_identical_rolling_grains():
    runs = []
    for threads in (1, 2):
        s = _gas(6000, seed=9, mu_r=0.2, threads=threads)
        s.add(pc.Gravity([0.0, -G]))
        s.step(60)
        runs.append((s.positions.copy(), s.velocities.copy(), s.particle_field("angular_velocity"), s.energy().total))
    for a, b in zip(*runs, strict=True):
        assert np.array_equal(a, b)


def test_rolling_springs_save_load_and_step_in_pieces_bit_for_bit(tmp_path):
    a = _gas(150, seed=11, mu_r=0.2)
    a.add(pc.Gravity([0.0, -G]))
    a.step(400)
    b = pc.Scene.load(a.save(tmp_path / "g.npz"))
    assert b.terms[0].rolling_friction == 0.2 or b.terms[1].rolling_friction == 0.2
    a.step(300)
    for _ in range(300):
        b.step(1)
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.particle_field("angular_velocity"), b.particle_field("angular_velocity"))
    assert a.energy().total == b.energy().total


@pytest.mark.parametrize("arg", ["rolling_friction", "rolling_damping"])
@pytest.mark.parametrize("value, error", [(-0.1, ValueError), (math.nan, ValueError), (math.inf, ValueError),
                                          ("0.1", TypeError), (None, TypeError)])
def test_bad_rolling_parameters_are_refused_by_name(arg, value, error):
    with pytest.raises(error, match=f"^{arg}") as info:
        pc.Contacts(stiffness=1.0, **{arg: value})
    assert isinstance(info.value, pc.PhyscoreError)


def test_a_zero_tangential_ratio_is_refused_with_how_to_turn_friction_off():
    with pytest.raises(pc.InvalidInputError, match=r"^tangential_ratio.*friction=0"):
        pc.Contacts(stiffness=1.0, tangential_ratio=0.0)


@pytest.mark.parametrize("dim, ratio", [(2, 1 / 3), (3, 2 / 7)])
def test_the_tangential_ratio_default_equalises_the_periods_of_the_dimensions_grains(dim, ratio):
    # β/(1 + β): 1/3 for a disc (β = ½), 2/7 for a sphere (β = ⅖) — see Contacts' docstring.
    assert pc.Contacts(stiffness=1.0).tangential_ratio is None
    assert pc.Contacts(stiffness=1.0).rolling_friction == 0.0
    assert pc.Contacts(stiffness=1.0).rolling_damping == 0.3
    beta = _beta(dim)
    assert ratio == pytest.approx(beta / (1 + beta), rel=1e-15)
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler")
    s.add_particles(np.zeros((1, dim)), masses=1.0)
    s.set_attribute("radius", [0.1])
    term = s.add(pc.Contacts(stiffness=1.0))
    assert term.tangential_ratio == ratio
