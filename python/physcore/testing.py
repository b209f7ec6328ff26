"""Helpers for property-based tests of physcore scenes: hypothesis strategies that build random
valid scenes, and assertions on the conservation laws.

Needs `hypothesis` (``pip install "physcore[test]"``) for the strategies; the assertions work
without it.

Examples
--------
The strategies step at ``dt = suggest_dt()/4 ≤ 1/(8 ω_max)``, where velocity Verlet's energy
swings by up to ``(ω dt)²/4 ≈ 4e-3`` of the total (the modified-energy argument for a harmonic
mode; Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2006, §IX.3); hence 1e-2:

>>> from hypothesis import given, settings
>>> import physcore.testing as pt
>>> @settings(max_examples=5, deadline=None)
... @given(pt.spring_networks(integrator="verlet"))
... def test_springs_conserve_energy(scene):
...     pt.assert_energy_conserved(scene, steps=200, rtol=1e-2)
>>> test_springs_conserve_energy()
"""
from __future__ import annotations

import numpy as np

from . import _check
from ._errors import InvalidInputError, InvalidTypeError
from .scene import Scene
from .terms import Gravity, PairwiseGravity, Springs

__all__ = [
    "spring_networks",
    "nbody_systems",
    "particle_clouds",
    "assert_energy_conserved",
    "assert_momentum_conserved",
]


def _st():
    try:
        from hypothesis import strategies
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError('physcore.testing strategies need hypothesis: pip install "physcore[test]"') from exc
    return strategies


def _positions(draw, st, n: int, dim: int, spread: float) -> np.ndarray:
    flat = draw(st.lists(st.floats(-spread, spread, allow_nan=False), min_size=n * dim, max_size=n * dim))
    return np.asarray(flat, dtype=np.float64).reshape(n, dim)


def spring_networks(*, dim: int | None = None, max_particles: int = 12, integrator: str = "verlet", damping: bool = False):
    """Strategy for scenes of 2..max_particles particles joined by random Hookean springs (rest
    length = initial length ≥ 0.2 m, stiffness 1..1e3 N/m, masses 0.1..10 kg, optional dashpots), with
    random initial velocities (never all zero), no gravity, no pins, and ``dt = suggest_dt()/4``:
    stable for every explicit integrator in the library except ``"euler"``.

    Springs never join a particle to itself, and no spring can pass near zero length (where its
    direction, hence the force, turns arbitrarily fast): the velocities are scaled so that the
    kinetic energy E ≤ k L_min²/8, and since a spring's potential ½ k ΔL² never exceeds the
    energy of the (conservative or damped) network, every spring keeps ``|ΔL| ≤ L_min/2``.

    Raises TypeError / InvalidInputError naming the argument (``dim`` not None, 2 or 3;
    ``max_particles`` not an int ≥ 2; an unknown ``integrator``) when called, not when the test runs.
    """
    dim = _dim(dim)
    max_particles = _check.int_in_range("max_particles", max_particles, 2)
    integrator = _integrator(integrator)
    st = _st()

    @st.composite
    def build(draw):
        d = draw(st.sampled_from([2, 3])) if dim is None else dim
        n = draw(st.integers(2, max_particles))
        x = _positions(draw, st, n, d, 1.0)
        # A chain through all particles, plus random extra springs.
        pairs = {(k, k + 1) for k in range(n - 1)}
        extra = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=2 * n))
        pairs |= {(min(a, b), max(a, b)) for a, b in extra if a != b}
        # Rest lengths ≥ 0.2 m, and (below) an energy too small to take any spring near zero
        # length, where its direction flips faster than any error bound at this dt covers.
        pairs = sorted(p for p in pairs if np.linalg.norm(x[p[0]] - x[p[1]]) > 0.2)
        if not pairs:
            x[1] = x[0] + 0.5
            pairs = [(0, 1)]
        i, j = (np.array(c, dtype=np.int64) for c in zip(*pairs, strict=False))
        k = draw(st.floats(1.0, 1e3))
        c = draw(st.floats(0.0, 1.0)) if damping else 0.0
        m = np.asarray(draw(st.lists(st.floats(0.1, 10.0), min_size=n, max_size=n)))
        v = _positions(draw, st, n, d, 0.3)
        v[0, 0] += 0.2  # some motion: a network at exact rest has no energy scale to compare to
        # Soft springs between heavy masses (k = 1 N/m, m = 10 kg) at 0.3 m/s once compressed to
        # 5 % of their rest length, where rk4's error at a dt set by ω alone reached 2e-3.
        l_min = min(float(np.linalg.norm(x[a] - x[b])) for a, b in pairs)
        e_kin = 0.5 * float(np.sum(m[:, None] * v * v))
        if e_kin > 0:
            v *= min(1.0, np.sqrt(k * l_min**2 / 8 / e_kin))
        scene = Scene(d, integrator=integrator)
        scene.add_particles(x, v, m)
        scene.add(Springs(i, j, stiffness=k, damping=c))
        scene.dt = scene.suggest_dt() / 4
        return scene

    return build()


def nbody_systems(*, dim: int = 3, max_bodies: int = 8, integrator: str = "verlet", softening: float = 0.1):
    """Strategy for self-gravitating systems (G = 1) of 2..max_bodies bodies with masses
    0.1..1, positions in the unit cube, small random velocities and Plummer softening ε (default
    0.1). The step resolves the closest possible encounter, not only the current separations:
    ``dt = min(suggest_dt(), 0.05 √(ε³/(G M))) / 4`` with M the total mass.

    Raises TypeError / InvalidInputError naming the argument (``dim`` not 2 or 3,
    ``max_bodies`` not an int ≥ 2, ``softening`` not > 0, an unknown ``integrator``)."""
    if _dim(dim) is None:
        raise InvalidInputError("dim: must be 2 or 3, got None")
    max_bodies = _check.int_in_range("max_bodies", max_bodies, 2)
    integrator = _integrator(integrator)
    if not _check.real("softening", softening) > 0:
        raise InvalidInputError("softening: must be > 0 (the step is chosen from the softened encounter time)")
    st = _st()

    @st.composite
    def build(draw):
        n = draw(st.integers(2, max_bodies))
        x = _positions(draw, st, n, dim, 1.0)
        v = 0.3 * _positions(draw, st, n, dim, 1.0)
        m = np.asarray(draw(st.lists(st.floats(0.1, 1.0), min_size=n, max_size=n)))
        scene = Scene(dim, integrator=integrator)
        scene.add_particles(x, v, m)
        scene.add(PairwiseGravity(1.0, softening=softening))
        scene.dt = min(scene.suggest_dt(), 0.05 * np.sqrt(softening**3 / m.sum())) / 4
        return scene

    return build()


def particle_clouds(*, dim: int | None = None, max_particles: int = 50, gravity: bool = True, integrator: str = "verlet"):
    """Strategy for free particles (random positions, velocities and masses) under uniform
    gravity (or none): the motion is exactly ballistic, so every integrator of order ≥ 2 is
    exact up to round-off.

    Raises TypeError / InvalidInputError naming the argument (``dim`` not None, 2 or 3;
    ``max_particles`` not an int ≥ 1; an unknown ``integrator``)."""
    dim = _dim(dim)
    max_particles = _check.int_in_range("max_particles", max_particles, 1)
    gravity = _check.flag("gravity", gravity)
    integrator = _integrator(integrator)
    st = _st()

    @st.composite
    def build(draw):
        d = draw(st.sampled_from([2, 3])) if dim is None else dim
        n = draw(st.integers(1, max_particles))
        x = _positions(draw, st, n, d, 10.0)
        v = _positions(draw, st, n, d, 5.0)
        m = np.asarray(draw(st.lists(st.floats(1e-3, 1e3), min_size=n, max_size=n)))
        scene = Scene(d, integrator=integrator, dt=draw(st.floats(1e-4, 1e-2)))
        scene.add_particles(x, v, m)
        if gravity:
            g = np.zeros(d)
            g[-1] = -9.81
            scene.add(Gravity(g))
        return scene

    return build()


def _dim(dim: object) -> int | None:
    if dim is None:
        return None
    d = _check.int_in_range("dim", dim, 2, 3)
    return d


def _integrator(name: object) -> str:
    from .scene import INTEGRATOR_ALIASES, INTEGRATORS

    names = [d["name"] for d in INTEGRATORS]
    return _check.choice("integrator", name, [*names, *INTEGRATOR_ALIASES])


def _check_scene(scene: object) -> None:
    if not isinstance(scene, Scene):
        raise InvalidTypeError(f"scene: expected a physcore.Scene, got {type(scene).__name__}")


def assert_energy_conserved(scene: Scene, steps: int, rtol: float, *, samples: int = 10) -> float:
    """Step ``scene`` ``steps`` times and assert that the energy books balance:
    ``|scene.energy_drift()| <= rtol`` at ``samples`` evenly spaced checks (so a transient
    excursion is caught, not only the end value). Returns the largest ``|drift|`` seen.

    ``energy_drift()`` is the change of the books' total over the energy in play,
    ``max(abs(E0), S0, S)`` (S: the sum of the magnitudes of the kinetic and potential parts), not the
    conventional ``(E - E0) / abs(E0)``: a bound system whose parts are larger than its total reads
    smaller (a Kepler orbit at e = 0.8 started at pericentre: 1/19 of the conventional error),
    and it never exceeds 1, so an rtol of 1 or more cannot fail and is refused. For the
    conventional measure, compare ``scene.energy().total`` with its value at the start.

    Raises
    ------
    AssertionError
        With the step and the drift where the books first failed to balance.
    TypeError, ValueError
        ``scene`` is not a Scene; ``steps`` or ``samples`` is not an int ≥ 1; ``rtol`` is not
        a number in (0, 1) (named in the message).
    """
    _check_scene(scene)
    steps = _check.int_in_range("steps", steps, 1)
    samples = _check.int_in_range("samples", samples, 1)
    rtol = _check.real("rtol", rtol)
    if not 0.0 < rtol < 1.0:
        raise InvalidInputError(f"rtol: must be in (0, 1), got {rtol:g} (energy_drift() is at most 1: an rtol of 1 or more cannot fail)")
    worst = 0.0
    done = 0
    for k in range(1, samples + 1):
        target = steps * k // samples
        if target > done:
            scene.step(target - done)
            done = target
        drift = scene.energy_drift()
        worst = max(worst, abs(drift))
        assert abs(drift) <= rtol, f"energy drift {drift:.3e} exceeds rtol {rtol:g} after {done} of {steps} steps ({scene!r})"
    return worst


def assert_momentum_conserved(scene: Scene, steps: int, rtol: float = 1e-10) -> None:
    """Step ``scene`` ``steps`` times and assert that the linear momentum changed only by the
    impulse of its uniform fields (:class:`~physcore.Gravity`): ``|p1 − p0 − M g t| <= rtol·S``,
    with ``S = Σ m |v|`` (before and after) ``+ M |g| t`` the momentum scale in play. Scenes with
    pinned particles or colliders exchange momentum with the outside and are refused.

    Raises
    ------
    TypeError, ValueError
        ``scene`` is not a Scene; ``steps`` is not an int ≥ 1; ``rtol`` is not a finite number
        > 0; the scene has pinned particles or colliders.
    AssertionError
        With the momentum error.
    """
    _check_scene(scene)
    steps = _check.int_in_range("steps", steps, 1)
    rtol = _check.positive_float("rtol", rtol)
    if scene.pinned.any() or scene.colliders:
        raise InvalidInputError("scene: pinned particles and colliders exchange momentum with the outside")
    g = sum((t.g for t in scene.terms if isinstance(t, Gravity)), np.zeros(scene.dim))
    m = scene.masses
    p0 = scene.momentum()
    s0 = float((m * np.linalg.norm(scene.velocities, axis=1)).sum())
    t0 = scene.time
    scene.step(steps)
    t = scene.time - t0
    expected = p0 + m.sum() * g * t
    p1 = scene.momentum()
    scale = s0 + float((m * np.linalg.norm(scene.velocities, axis=1)).sum()) + m.sum() * float(np.linalg.norm(g)) * t
    err = float(np.linalg.norm(p1 - expected))
    assert err <= rtol * max(scale, np.finfo(float).tiny), f"momentum error {err:.3e} exceeds {rtol:g} × scale {scale:.3e} after {steps} steps"
