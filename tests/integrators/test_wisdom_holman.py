"""The Wisdom–Holman map ("wisdom_holman"), in Jacobi and democratic heliocentric coordinates:
exact on a Kepler orbit about a fixed centre (and, in Jacobi coordinates, on any two-body
problem), second order with an error proportional to the planets' masses on a planetary system,
the integrals of motion it must keep, its determinism and restarts, its option and the scenes it
refuses."""
from __future__ import annotations

import math
import warnings

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


def _planets(mu: float, dim: int = 3, outer: float = 1.6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit-mass star and two planets of mass `mu` (a = 1 and `outer`, e = 0.05 and 0.1, the
    second a little inclined in 3D), in the centre-of-mass frame; G = 1, the inner period 2π."""
    x, v, m = [np.zeros(dim)], [np.zeros(dim)], [1.0]
    for a, e, ang in ((1.0, 0.05, 0.0), (outer, 0.1, 2.0)):
        r, s = a * (1 - e), math.sqrt((1 + mu) * (1 + e) / (a * (1 - e)))
        xi, vi = np.zeros(dim), np.zeros(dim)
        xi[:2] = r * math.cos(ang), r * math.sin(ang)
        vi[:2] = -s * math.sin(ang), s * math.cos(ang)
        if dim == 3:
            vi[2] = 0.02 * s
        x.append(xi), v.append(vi), m.append(mu)
    x, v, m = np.array(x), np.array(v), np.array(m)
    return x - m @ x / m.sum(), v - m @ v / m.sum(), m


COORDINATES = ("jacobi", "democratic_heliocentric")


def _scene(x, v, m, integrator="wisdom_holman", dt=TWO_PI / 20, threads=1, coordinates="jacobi", corrector=0,
           **particles) -> pc.Scene:
    # The split's options only where they are used (another integrator warns of them).
    options = {"wh_coordinates": coordinates, "wh_corrector": corrector} if integrator == "wisdom_holman" else {}
    s = pc.Scene(x.shape[1], integrator=integrator, dt=dt, threads=threads, **options)
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


@pytest.mark.parametrize("coordinates", COORDINATES)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize(("e", "bound"), [(0.5, 1e-10), (0.9, 1e-8)])
def test_an_orbit_about_a_fixed_centre_is_exact_at_any_step(dim, e, bound, coordinates):
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
        s = _scene(x, v, [1.0, 1e-3], integrator, dt=dt, coordinates=coordinates, pinned=[True, False])
        with warnings.catch_warnings():
            # Verlet at e = 0.9 is warned that the step is far past the pericentre's free fall
            # (not at e = 0.5); Wisdom–Holman never is.
            warnings.simplefilter("ignore" if integrator == "verlet" else "error", pc.StabilityWarning)
            s.step(700)
        gaps[integrator] = np.linalg.norm(s.positions[1] - expected)
        assert np.array_equal(s.positions[0], np.zeros(dim))
    assert gaps["wisdom_holman"] < bound, gaps
    assert gaps["verlet"] > 1e-2, gaps


@pytest.mark.parametrize("e", [0.5, 0.9])
def test_a_planet_of_a_free_star_is_exact_in_jacobi_coordinates(e):
    # Two free bodies: in Jacobi coordinates the whole Hamiltonian is the relative orbit's Kepler
    # part (μ = G(m_0 + m_1)) and the centre of mass's drift, so the map is the exact flow and
    # the kick is the full force less the Kepler one, 0 to rounding. In democratic heliocentric
    # coordinates the Sun's reflex (the jump) does not commute with the Kepler drift: an error of
    # order (m_1/m_0) dt², far above rounding, that shows the comparison can fail.
    mu, m1 = 1.0 + 1e-3, 1e-3
    x0, v0 = _kepler_state(1.0, e, mu, 3)
    m = np.array([1.0, m1])
    x, v = np.array([-m1 * x0, x0]) / mu, np.array([-m1 * v0, v0]) / mu  # barycentric
    dt = TWO_PI / math.sqrt(mu) / 7.3
    expected = np.zeros(3)
    expected[:2] = _kepler_position(700 * dt * math.sqrt(mu), e)
    gaps = {}
    for coordinates in COORDINATES:
        s = _scene(x, v, m, dt=dt, coordinates=coordinates)
        s.step(700)
        p = s.positions
        gaps[coordinates] = np.linalg.norm(p[1] - p[0] - expected)
    # The bounds of the fixed centre's test: 700 steps' roundings of the orbit's energy.
    assert gaps["jacobi"] < (1e-10 if e == 0.5 else 1e-8), gaps
    assert gaps["democratic_heliocentric"] > 1e-6, gaps


def test_a_pinned_star_is_the_centre_beside_a_body_of_its_own_mass():
    # scenes.kepler(mass_ratio=0)'s layout reversed: the test body (mass 1) first, the pinned
    # star (mass 1) second. The pinned one of the heaviest is the fixed centre.
    x0, v0 = _kepler_state(1.0, 0.5, 1.0, 2)
    s = _scene(np.array([x0, [0.0, 0.0]]), np.array([v0, [0.0, 0.0]]), [1.0, 1.0], dt=TWO_PI / 7.3,
               pinned=[False, True])
    s.step(73)
    assert np.linalg.norm(s.positions[0] - _kepler_position(73 * TWO_PI / 7.3, 0.5)) < 1e-11


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_a_body_on_the_star_is_a_divergence(coordinates):
    x, v, m = _planets(1e-3)
    x[2] = x[0]
    s = _scene(x, v, m, coordinates=coordinates)
    before = s.positions.copy()
    with pytest.raises(pc.SimulationDiverged):
        s.step(1)
    assert np.array_equal(s.positions, before)


def test_a_hyperbolic_flyby_agrees_with_a_fine_yoshida4_run():
    # A light body passing the star on a hyperbola (e = 1.5) beside a planet: the Kepler solver's
    # hyperbolic branch, against Yoshida's fourth order at a step 200 times finer. Heliocentric
    # coordinates: the body, listed after the planet, passes inside its orbit, where Jacobi
    # coordinates (which take it about the star and planet's centre of mass) lose their edge
    # (8e-6 here; measured).
    x0, v0 = _kepler_state(-2.0, 1.5, 1.0, 3)  # a < 0: hyperbolic, pericentre 1
    xs = np.array([np.zeros(3), [0.0, 3.0, 0.0], x0 - 4.0 * v0])
    vs = np.array([np.zeros(3), [-math.sqrt(1 / 3.0), 0.0, 0.0], v0])
    m = np.array([1.0, 1e-3, 1e-8])
    runs = {}
    for integrator, div in (("wisdom_holman", 50), ("yoshida4", 10000)):
        s = _scene(xs, vs, m, integrator, dt=TWO_PI / div, coordinates="democratic_heliocentric")
        s.step(8 * div)  # 8 time units: in, round the pericentre, out
        runs[integrator] = s.positions.copy()
    assert np.linalg.norm(runs["wisdom_holman"][2]) > 5.0  # it left
    assert np.abs(runs["wisdom_holman"] - runs["yoshida4"]).max() < 1e-6


# ------------------------------------------------------------------------------ its error
@pytest.mark.parametrize("coordinates", COORDINATES)
def test_energy_error_is_second_order(coordinates):
    errs = [_energy_error(_scene(*_planets(1e-4), dt=TWO_PI / div, coordinates=coordinates), 20 * div) for div in (20, 40, 80)]
    slopes = [math.log2(a / b) for a, b in zip(errs, errs[1:], strict=False)]
    assert all(abs(p - 2.0) < 0.2 for p in slopes), (errs, slopes)


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_energy_error_scales_with_the_planets_masses(coordinates):
    # The map's error is of order (m_planet / m_star) dt² (Wisdom & Holman 1991): ten times
    # lighter planets, ten times smaller relative error at the same step.
    light, heavy = (_energy_error(_scene(*_planets(mu), coordinates=coordinates), 400) for mu in (1e-6, 1e-5))
    assert 8.0 < heavy / light < 12.0, (light, heavy)


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_a_thousand_times_better_than_verlet_at_the_same_step(coordinates):
    wh, verlet = (_energy_error(_scene(*_planets(1e-3), integrator=i, coordinates=coordinates), 400)
                  for i in ("wisdom_holman", "verlet"))
    assert wh < 1e-5 and verlet > 500 * wh, (wh, verlet)


@pytest.mark.parametrize("coordinates", COORDINATES)
@pytest.mark.parametrize("dim", [2, 3])
def test_momentum_and_angular_momentum_are_kept_to_rounding(dim, coordinates):
    # Every factor of the map (kick, jump, Kepler drift) keeps both exactly, so what is left is
    # rounding: a few roundings a step (4 ε of |L| a step bounds it), where an error of the
    # method would change L by order (m/M) dt², 1e-3 of it here. The heliocentric map sets the
    # star's velocity from the momentum; the Jacobi one sums it from the Jacobi velocities, and
    # its kick adds to it the difference of two terms of the planets' pull: a few roundings of
    # the star's momentum a step (4 ε of max m|v| a step bounds it).
    # Planets of 1e-2 at a = 1 and 2.5: at 1 and 1.6 they are closer than 2√3 mutual Hill radii,
    # and are thrown out within 2000 steps (to 5000 times their distance), where the hyperbolic
    # Kepler drift amplifies the rounding of L to 1e-12 in either coordinate set (measured).
    s = _scene(*_planets(1e-2, dim, outer=2.5), coordinates=coordinates)
    p0, l0 = s.momentum(), np.atleast_1d(s.angular_momentum())
    star = np.linalg.norm(s.velocities, axis=1)[0] * s.masses[0]
    s.step(2000)
    bound = 1e-16 if coordinates == "democratic_heliocentric" else 2000 * 4 * EPS * star
    assert np.abs(s.momentum() - p0).max() < bound
    assert np.abs(np.atleast_1d(s.angular_momentum()) - l0).max() < 2000 * 4 * EPS * np.abs(l0).max()


def test_jacobi_coordinates_beat_heliocentric_ones_on_a_hierarchical_system():
    # In heliocentric coordinates each planet's kick holds the star's reflex to the other
    # planets' pull; in Jacobi coordinates the outer planet orbits the inner pair's centre of
    # mass, and what is left is smaller the wider apart the orbits (Wisdom & Holman 1991).
    # Measured, 100 inner orbits at P/20: 0.065 of the heliocentric error at a = 1 and 4,
    # 0.39 at 1 and 2.5, 0.56 at 1 and 1.6.
    errs = {c: _energy_error(_scene(*_planets(1e-3, outer=4.0), coordinates=c), 2000) for c in COORDINATES}
    assert errs["jacobi"] < 0.2 * errs["democratic_heliocentric"], errs


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_the_star_may_be_listed_anywhere(coordinates):
    # The heaviest particle is the centre wherever it is listed, and the Jacobi chain takes the
    # others in their order: the star listed last steps the same map (the same bodies, the same
    # order of planets) to rounding.
    x, v, m = _planets(1e-3)
    first = _scene(x, v, m, coordinates=coordinates)
    last = _scene(np.roll(x, -1, axis=0), np.roll(v, -1, axis=0), np.roll(m, -1), coordinates=coordinates)
    first.step(400)
    last.step(400)
    gap = np.abs(np.roll(last.positions, 1, axis=0) - first.positions).max()
    assert gap < 1e-12, gap


def test_a_scene_switched_to_the_other_coordinates_steps_their_map():
    # The carried forces are the other split's: a switch between steps must not kick with them.
    for first, second in (COORDINATES, COORDINATES[::-1]):
        straight = _scene(*_planets(1e-3), coordinates=second)
        straight.step(20)
        s = _scene(*_planets(1e-3), coordinates=first)
        s.step(10)
        again = _scene(s.positions, s.velocities, _planets(1e-3)[2], coordinates=second)
        s.wh_coordinates = second
        s.step(10)
        again.step(10)
        assert np.array_equal(s.positions, again.positions) and np.array_equal(s.velocities, again.velocities)
        assert not np.array_equal(s.positions, straight.positions)  # the first 10 steps differ


# ------------------------------------------------------------------ determinism, restarts
def _thread_runs(seed: int, steps: int, **scene) -> list[tuple[np.ndarray, np.ndarray]]:
    """4,600 light bodies on circles about a unit star (past the core's parallel threshold, so
    the chunked passes and sums run), stepped `steps` on one and on two threads: the states."""
    rng = np.random.default_rng(seed)
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
        s = _scene(x, v, m, threads=threads, **scene)
        s.step(steps)
        runs.append((s.positions.copy(), s.velocities.copy()))
    return runs


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_threads_give_the_same_bits(coordinates):
    runs = _thread_runs(3, 3, coordinates=coordinates)
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


@pytest.mark.parametrize("coordinates", COORDINATES)
def test_save_load_continues_bit_for_bit(tmp_path, coordinates):
    straight = _scene(*_planets(1e-3), coordinates=coordinates)
    straight.step(40)
    s = _scene(*_planets(1e-3), coordinates=coordinates)
    s.step(20)
    s.save(tmp_path / "planets.npz")
    again = pc.Scene.load(tmp_path / "planets.npz")
    assert again.integrator == "wisdom_holman" and again.wh_coordinates == coordinates
    again.step(20)
    assert np.array_equal(again.positions, straight.positions)
    assert np.array_equal(again.velocities, straight.velocities)


def test_files_hold_the_coordinates_where_they_matter(tmp_path):
    # A wisdom_holman scene's file names its coordinates; another scene's names them only when
    # set off the default, so files of every other scene keep their bytes (the naming tests
    # compare saved files with stored ones). Without the key a wisdom_holman file was written
    # before the option: it stepped, and goes on with, the democratic heliocentric split.
    import json

    def meta(path):
        with np.load(path) as z:
            return json.loads(str(z["meta"]))

    for integrator, coords, written in [("wisdom_holman", "jacobi", True), ("verlet", "jacobi", False),
                                        ("verlet", "democratic_heliocentric", True)]:
        if integrator == "wisdom_holman":
            s = _scene(*_planets(1e-3), coordinates=coords)
        else:  # kept beside another integrator, which warns where it is off the default
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", pc.UnusedOptionWarning)
                s = pc.Scene(3, integrator=integrator, dt=TWO_PI / 20, threads=1, wh_coordinates=coords)
            s.add_particles(*_planets(1e-3)[:2], masses=_planets(1e-3)[2])
            s.add(pc.PairwiseGravity(G=1.0))
        path = s.save(tmp_path / f"{integrator}_{coords}.npz")
        assert ("wh_coordinates" in meta(path)) == written, (integrator, coords)
        assert pc.Scene.load(path).wh_coordinates == coords
    # An old wisdom_holman file: the key removed.
    s = _scene(*_planets(1e-3), coordinates="democratic_heliocentric")
    s.step(5)
    path = s.save(tmp_path / "old.npz")
    with np.load(path) as z:
        members = {k: z[k] for k in z.files}
    m = meta(path)
    del m["wh_coordinates"]
    members["meta"] = np.array(json.dumps(m))
    np.savez(tmp_path / "old2.npz", **members)
    old = pc.Scene.load(tmp_path / "old2.npz")
    assert old.wh_coordinates == "democratic_heliocentric"
    old.step(5)
    s.step(5)
    assert np.array_equal(old.positions, s.positions)


# -------------------------------------------------------------------------------- option
def test_the_default_is_jacobi_and_the_record_is_the_keyword():
    assert pc.WisdomHolman().coordinates == "jacobi" == pc.Scene().wh_coordinates
    s = pc.Scene(integrator=pc.WisdomHolman(coordinates="democratic_heliocentric"))
    assert s.integrator == "wisdom_holman" and s.wh_coordinates == "democratic_heliocentric"
    with pytest.raises(pc.InvalidInputError, match="^wh_coordinates: .* conflicts with integrator="):
        pc.Scene(integrator=pc.WisdomHolman(coordinates="jacobi"), wh_coordinates="democratic_heliocentric")


@pytest.mark.parametrize("bad", ["heliocentric", "Jacobi", ""])
def test_unknown_coordinates_are_refused_naming_the_argument(bad):
    with pytest.raises(pc.InvalidInputError, match="^coordinates: must be one of 'jacobi', 'democratic_heliocentric'"):
        pc.WisdomHolman(coordinates=bad)
    with pytest.raises(pc.InvalidInputError, match="^wh_coordinates: must be one of"):
        pc.Scene(integrator="wisdom_holman", wh_coordinates=bad)
    s = pc.Scene(integrator="wisdom_holman")
    with pytest.raises(pc.InvalidInputError, match="^wh_coordinates: must be one of"):
        s.wh_coordinates = bad
    assert s.wh_coordinates == "jacobi"


@pytest.mark.parametrize("bad", [None, 1, True, ["jacobi"]])
def test_coordinates_not_a_str_are_a_type_error_naming_the_argument(bad):
    with pytest.raises(pc.InvalidTypeError, match="^coordinates: expected one of"):
        pc.WisdomHolman(coordinates=bad)


# ------------------------------------------------------------------------------ refusals
def _refused(scene: pc.Scene, match: str) -> str:
    """A step of `scene` refused (the message matching `match`), the scene as before; the message."""
    before = (scene.positions.copy(), scene.velocities.copy(), scene.time)
    with pytest.raises(pc.InvalidInputError, match=match) as info:
        scene.step(1)
    assert "integrator" in str(info.value) and "wisdom_holman" in str(info.value)
    assert np.array_equal(scene.positions, before[0]) and np.array_equal(scene.velocities, before[1])
    assert scene.time == before[2]
    return str(info.value)


#: What every refusal offers instead.
REMEDY = "use 'yoshida4' or 'verlet'"


def test_scenes_it_cannot_split_are_refused_before_a_step():
    x, v, m = _planets(1e-3)

    def bare():
        s = pc.Scene(3, integrator="wisdom_holman", dt=0.1)
        s.add_particles(x, v, masses=m)
        return s

    said = []
    s = bare()
    said.append(_refused(s, "has none"))
    s = bare()
    s.add(pc.TreeGravity(G=1.0, theta=0.0))
    said.append(_refused(s, "has none"))
    s = bare()
    s.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    said.append(_refused(s, "softening"))
    s = bare()
    s.add(pc.PairwiseGravity(G=1.0))
    s.add(pc.PairwiseGravity(G=2.0, name="more"))
    said.append(_refused(s, "has 2"))
    s = _scene(x, v, m)
    s.add(pc.Drag(0.1))
    said.append(_refused(s, "depends on velocity"))
    # Only the heaviest body may be pinned (a fixed centre).
    said.append(_refused(_scene(x, v, m, pinned=[False, True, False]), "particle 1 is pinned"))
    assert all(REMEDY in m for m in said), said


def test_a_scene_switched_to_it_is_checked_at_its_next_step():
    s = pc.scenes.spring_chain()
    s.integrator = "wisdom_holman"  # accepted: the check is the step's
    assert REMEDY in _refused(s, "has none")
    s.integrator = "verlet"
    s.step(1)
