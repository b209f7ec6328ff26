"""The Wisdom–Holman map ("wisdom_holman"): exact on a Kepler orbit about a fixed centre, second
order with an error proportional to the planets' masses on a planetary system, the integrals of
motion it must keep, its determinism and restarts, and the scenes it refuses."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc

TWO_PI = 2.0 * math.pi
EPS = np.finfo(np.float64).eps


def _kepler_state(a: float, e: float, mu: float, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Pericentre position and velocity of an orbit of semi-major axis a and eccentricity e."""
    x, v = np.zeros(dim), np.zeros(dim)
    x[0] = a * (1 - e)
    v[1] = math.sqrt(mu * (1 + e) / (a * (1 - e)))
    return x, v


def _planets(mu: float, dim: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit-mass star and two planets of mass `mu` (a = 1 and 1.6, e = 0.05 and 0.1, the
    second a little inclined in 3D), in the centre-of-mass frame; G = 1, the inner period 2π."""
    x, v, m = [np.zeros(dim)], [np.zeros(dim)], [1.0]
    for a, e, ang in ((1.0, 0.05, 0.0), (1.6, 0.1, 2.0)):
        r, s = a * (1 - e), math.sqrt((1 + mu) * (1 + e) / (a * (1 - e)))
        xi, vi = np.zeros(dim), np.zeros(dim)
        xi[:2] = r * math.cos(ang), r * math.sin(ang)
        vi[:2] = -s * math.sin(ang), s * math.cos(ang)
        if dim == 3:
            vi[2] = 0.02 * s
        x.append(xi), v.append(vi), m.append(mu)
    x, v, m = np.array(x), np.array(v), np.array(m)
    return x - m @ x / m.sum(), v - m @ v / m.sum(), m


def _scene(x, v, m, integrator="wisdom_holman", dt=TWO_PI / 20, threads=1, **particles) -> pc.Scene:
    s = pc.Scene(x.shape[1], integrator=integrator, dt=dt, threads=threads)
    s.add_particles(x, v, masses=m, **particles)
    s.add(pc.PairwiseGravity(G=1.0))
    return s


def _energy_error(s: pc.Scene, steps: int, samples: int = 40) -> float:
    e0, worst = s.energy().total, 0.0
    for _ in range(samples):
        s.step(steps // samples)
        worst = max(worst, abs(s.energy().total / e0 - 1.0))
    return worst


# ------------------------------------------------------------------------------- exactness
def _kepler_position(t: float, e: float) -> np.ndarray:
    """Position at time t on the orbit a = 1, μ = 1 started at pericentre on +x, moving +y:
    Kepler's equation M = E − e sin E solved by Newton's method to rounding."""
    m = math.fmod(t, TWO_PI)
    ea = m if e < 0.8 else math.pi
    for _ in range(60):
        ea -= (ea - e * math.sin(ea) - m) / (1 - e * math.cos(ea))
    return np.array([math.cos(ea) - e, math.sqrt(1 - e * e) * math.sin(ea)])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize(("e", "bound"), [(0.5, 1e-10), (0.9, 1e-8)])
def test_an_orbit_about_a_fixed_centre_is_exact_at_any_step(dim, e, bound):
    # A pinned star is a fixed centre: the map is then the Kepler flow itself, so an orbit
    # stepped at P/7.3 (e = 0.9: its pericentre passed within one step) is where Kepler's
    # equation puts it after 700 steps, to rounding: at e = 0.9, float64 holds the state's energy
    # to some 1e-14 at pericentre, and 700 such roundings move it by 4e-10 of the orbit. Velocity
    # Verlet at the same step is nowhere near.
    x0, v0 = _kepler_state(1.0, e, 1.0, dim)
    x, v = np.array([np.zeros(dim), x0]), np.array([np.zeros(dim), v0])
    dt = TWO_PI / 7.3
    expected = np.zeros(dim)
    expected[:2] = _kepler_position(700 * dt, e)
    gaps = {}
    for integrator in ("wisdom_holman", "verlet"):
        s = _scene(x, v, [1.0, 1e-3], integrator, dt=dt, pinned=[True, False])
        s.step(700)
        gaps[integrator] = np.linalg.norm(s.positions[1] - expected)
        assert np.array_equal(s.positions[0], np.zeros(dim))
    assert gaps["wisdom_holman"] < bound, gaps
    assert gaps["verlet"] > 1e-2, gaps


def test_a_pinned_star_is_the_centre_beside_a_body_of_its_own_mass():
    # scenes.kepler(mass_ratio=0)'s layout reversed: the test body (mass 1) first, the pinned
    # star (mass 1) second. The pinned one of the heaviest is the fixed centre.
    x0, v0 = _kepler_state(1.0, 0.5, 1.0, 2)
    s = _scene(np.array([x0, [0.0, 0.0]]), np.array([v0, [0.0, 0.0]]), [1.0, 1.0], dt=TWO_PI / 7.3,
               pinned=[False, True])
    s.step(73)
    assert np.linalg.norm(s.positions[0] - _kepler_position(73 * TWO_PI / 7.3, 0.5)) < 1e-11


def test_a_body_on_the_star_is_a_divergence():
    x, v, m = _planets(1e-3)
    x[2] = x[0]
    s = _scene(x, v, m)
    before = s.positions.copy()
    with pytest.raises(pc.SimulationDiverged):
        s.step(1)
    assert np.array_equal(s.positions, before)


def test_a_hyperbolic_flyby_agrees_with_a_fine_yoshida4_run():
    # A light body passing the star on a hyperbola (e = 1.5) beside a planet: the Kepler solver's
    # hyperbolic branch, against Yoshida's fourth order at a step 200 times finer.
    x0, v0 = _kepler_state(-2.0, 1.5, 1.0, 3)  # a < 0: hyperbolic, pericentre 1
    xs = np.array([np.zeros(3), [0.0, 3.0, 0.0], x0 - 4.0 * v0])
    vs = np.array([np.zeros(3), [-math.sqrt(1 / 3.0), 0.0, 0.0], v0])
    m = np.array([1.0, 1e-3, 1e-8])
    runs = {}
    for integrator, div in (("wisdom_holman", 50), ("yoshida4", 10000)):
        s = _scene(xs, vs, m, integrator, dt=TWO_PI / div)
        s.step(8 * div)  # 8 time units: in, round the pericentre, out
        runs[integrator] = s.positions.copy()
    assert np.linalg.norm(runs["wisdom_holman"][2]) > 5.0  # it left
    assert np.abs(runs["wisdom_holman"] - runs["yoshida4"]).max() < 1e-6


# ------------------------------------------------------------------------------ its error
def test_energy_error_is_second_order():
    errs = [_energy_error(_scene(*_planets(1e-4), dt=TWO_PI / div), 20 * div) for div in (20, 40, 80)]
    slopes = [math.log2(a / b) for a, b in zip(errs, errs[1:], strict=False)]
    assert all(abs(p - 2.0) < 0.2 for p in slopes), (errs, slopes)


def test_energy_error_scales_with_the_planets_masses():
    # The map's error is of order (m_planet / m_star) dt² (Wisdom & Holman 1991): ten times
    # lighter planets, ten times smaller relative error at the same step.
    light, heavy = (_energy_error(_scene(*_planets(mu)), 400) for mu in (1e-6, 1e-5))
    assert 8.0 < heavy / light < 12.0, (light, heavy)


def test_a_thousand_times_better_than_verlet_at_the_same_step():
    wh, verlet = (_energy_error(_scene(*_planets(1e-3), integrator=i), 400) for i in ("wisdom_holman", "verlet"))
    assert wh < 1e-5 and verlet > 500 * wh, (wh, verlet)


@pytest.mark.parametrize("dim", [2, 3])
def test_momentum_and_angular_momentum_are_kept_to_rounding(dim):
    # Every factor of the map (kick, jump, Kepler drift) keeps both exactly, so what is left is
    # rounding: a few roundings a step (4 ε of |L| a step bounds it), where an error of the
    # method would change L by order (m/M) dt², 1e-3 of it here.
    s = _scene(*_planets(1e-2, dim))
    p0, l0 = s.momentum(), np.atleast_1d(s.angular_momentum())
    s.step(2000)
    assert np.abs(s.momentum() - p0).max() < 1e-16
    assert np.abs(np.atleast_1d(s.angular_momentum()) - l0).max() < 2000 * 4 * EPS * np.abs(l0).max()


# ------------------------------------------------------------------ determinism, restarts
def test_threads_give_the_same_bits():
    # 4,600 bodies: past the core's parallel threshold, so the chunked passes and sums run.
    rng = np.random.default_rng(3)
    n = 4600
    r = rng.uniform(1.0, 3.0, n)
    ang = rng.uniform(0.0, TWO_PI, n)
    x = np.c_[r * np.cos(ang), r * np.sin(ang), rng.normal(0.0, 0.01, n)]
    v = np.c_[-np.sin(ang), np.cos(ang), np.zeros(n)] / np.sqrt(r)[:, None]
    x[0], v[0] = 0.0, 0.0
    m = np.full(n, 1e-9)
    m[0] = 1.0
    runs = []
    for threads in (1, 2):
        s = _scene(x, v, m, threads=threads)
        s.step(3)
        runs.append((s.positions.copy(), s.velocities.copy()))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_save_load_continues_bit_for_bit(tmp_path):
    straight = _scene(*_planets(1e-3))
    straight.step(40)
    s = _scene(*_planets(1e-3))
    s.step(20)
    s.save(tmp_path / "planets.npz")
    again = pc.Scene.load(tmp_path / "planets.npz")
    assert again.integrator == "wisdom_holman"
    again.step(20)
    assert np.array_equal(again.positions, straight.positions)
    assert np.array_equal(again.velocities, straight.velocities)


# ------------------------------------------------------------------------------ refusals
def _refused(scene: pc.Scene, match: str) -> None:
    before = (scene.positions.copy(), scene.velocities.copy(), scene.time)
    with pytest.raises(pc.InvalidInputError, match=match) as info:
        scene.step(1)
    assert "integrator" in str(info.value) and "wisdom_holman" in str(info.value)
    assert np.array_equal(scene.positions, before[0]) and np.array_equal(scene.velocities, before[1])
    assert scene.time == before[2]


def test_scenes_it_cannot_split_are_refused_before_a_step():
    x, v, m = _planets(1e-3)

    def bare():
        s = pc.Scene(3, integrator="wisdom_holman", dt=0.1)
        s.add_particles(x, v, masses=m)
        return s

    s = bare()
    _refused(s, "has none")
    s = bare()
    s.add(pc.TreeGravity(G=1.0, theta=0.0))
    _refused(s, "has none")
    s = bare()
    s.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    _refused(s, "softening")
    s = bare()
    s.add(pc.PairwiseGravity(G=1.0))
    s.add(pc.PairwiseGravity(G=2.0, name="more"))
    _refused(s, "has 2")
    s = _scene(x, v, m)
    s.add(pc.Drag(0.1))
    _refused(s, "depends on velocity")
    # Only the heaviest body may be pinned (a fixed centre).
    _refused(_scene(x, v, m, pinned=[False, True, False]), "particle 1 is pinned")


def test_a_scene_switched_to_it_is_checked_at_its_next_step():
    s = pc.scenes.spring_chain()
    s.integrator = "wisdom_holman"  # accepted: the check is the step's
    _refused(s, "has none")
    s.integrator = "verlet"
    s.step(1)
