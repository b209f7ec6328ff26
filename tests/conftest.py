"""Shared fixtures and helpers for the physics and API tests.

Everything here builds scenes from the public API only; expectations in the tests come from
closed-form physics (harmonic oscillator, Kepler problem, constant acceleration), never from
numbers copied out of a previous run.
"""
from __future__ import annotations

import math
import os
import signal
import warnings
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

import physcore as pc

# When a property test fails, hypothesis imports its patch writer (libcst), whose import emits a
# DeprecationWarning (mypy_extensions.TypedDict); under ``filterwarnings = error`` that turns a
# readable failure into an INTERNALERROR. Import it once here, quietly, so it is cached.
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    try:
        import hypothesis.extra._patching  # noqa: F401
    except Exception:  # noqa: BLE001 - pragma: no cover - optional dependency of hypothesis
        pass

# Ctrl-C as a user's terminal delivers it. A process started in the background by a shell
# without job control (`pytest &`, `nohup`, some CI runners) inherits SIGINT ignored, and Python
# then keeps it ignored instead of installing its KeyboardInterrupt handler: every test that
# sends itself SIGINT (tests/robustness/test_interrupt.py, test_every_kind.py, the GPU and
# batch Ctrl-C tests) would then wait for ever for a step(10**9) to end. Python's own handler,
# in each worker's main thread (conftest is imported there), as a foreground run has it.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

settings.register_profile(
    "ci",
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
# A heavier profile for hunting flaky tolerances: HYPOTHESIS_PROFILE=stress pytest tests
settings.register_profile("stress", parent=settings.get_profile("ci"), max_examples=400)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

#: The integrators that step any scene (oscillators, chains, free particles), as the library
#: reports them: all but "wisdom_holman", which steps planetary systems only (one heavy body under
#: pairwise gravity) and has its own tests (tests/integrators/test_wisdom_holman.py).
PLANETARY_ONLY: tuple[str, ...] = ("wisdom_holman",)
INTEGRATOR_NAMES: tuple[str, ...] = tuple(d["name"] for d in pc.INTEGRATORS if d["name"] not in PLANETARY_ONLY)
SYMPLECTIC: tuple[str, ...] = ("semi_implicit_euler", "verlet", "yoshida4")

EPS = np.finfo(np.float64).eps

#: Every SIMD level the kernels are written for; a test taking the ``simd_level`` fixture runs once
#: per level this CPU has and is skipped, saying so, for the others.
SIMD_LEVELS: tuple[str, ...] = ("scalar", "avx2", "avx512", "neon")


@pytest.fixture(params=SIMD_LEVELS)
def simd_level(request):
    """Runs the test with the kernels forced to one SIMD level (restored afterwards)."""
    level = request.param
    have = pc.simd_levels()
    if level not in have:
        pytest.skip(f"{level}: this CPU cannot run it (it has {', '.join(have)}); not claimed as tested here")
    pc.set_simd_level(level)
    try:
        assert pc.simd_level() == level
        yield level
    finally:
        pc.set_simd_level(None)


# --------------------------------------------------------------------------- scene builders
def oscillator(
    integrator: str,
    dt: float,
    *,
    omega: float = 1.0,
    mass: float = 1.0,
    x0: Sequence[float] = (1.0, 0.0),
    v0: Sequence[float] = (0.0, 0.5),
) -> pc.Scene:
    """Isotropic 2D harmonic oscillator: a free particle tied to a pinned one at the origin by a
    spring of rest length 0, so the force is exactly ``-k x`` (k = m ω²).

    Particle 1 is the oscillator; x(t) = x0 cos ωt + (v0/ω) sin ωt.
    """
    s = pc.Scene(2, integrator=integrator, dt=dt, threads=1)
    s.add_particles([[0.0, 0.0], list(x0)], [[0.0, 0.0], list(v0)], masses=[1.0, mass], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=mass * omega**2, rest_length=0.0))
    return s


def oscillator_exact(t: float, omega: float = 1.0, x0=(1.0, 0.0), v0=(0.0, 0.5)) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (x, v) of :func:`oscillator` at time t."""
    x0, v0 = np.asarray(x0, float), np.asarray(v0, float)
    c, s = math.cos(omega * t), math.sin(omega * t)
    return x0 * c + v0 / omega * s, -x0 * omega * s + v0 * c


def random_network(
    seed: int,
    n: int,
    *,
    dim: int = 2,
    n_springs: int | None = None,
    n_pinned: int = 0,
    speed: float = 0.3,
    integrator: str = "verlet",
    dt: float = 1e-3,
    damping: float = 0.0,
) -> pc.Scene:
    """A random conservative spring network: random positions (kept apart), random springs with
    rest length None (taken from the initial geometry), random masses and velocities.

    The first ``n_pinned`` particles are pinned. Each particle gets at least one spring.
    """
    rng = np.random.default_rng(seed)
    x = _separated_points(rng, n, dim, min_dist=0.2, box=1.5)
    v = rng.normal(scale=speed, size=(n, dim))
    m = rng.uniform(0.5, 2.0, size=n)
    pinned = np.zeros(n, dtype=bool)
    pinned[:n_pinned] = True
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    order = rng.permutation(len(pairs))
    want = n_springs if n_springs is not None else max(n, int(1.5 * n))
    chosen: list[tuple[int, int]] = []
    covered = set()
    # Guarantee every particle is attached to something, then add random extra springs.
    for p in range(n):
        if p in covered:
            continue
        q = int(rng.integers(0, n - 1))
        q = q if q < p else q + 1
        e = (min(p, q), max(p, q))
        if e not in chosen:
            chosen.append(e)
        covered.update(e)
    for k in order:
        if len(chosen) >= want:
            break
        e = pairs[k]
        if e not in chosen:
            chosen.append(e)
    i = np.array([a for a, _ in chosen], dtype=np.int64)
    j = np.array([b for _, b in chosen], dtype=np.int64)
    stiff = rng.uniform(1.0, 10.0, size=len(chosen))
    s = pc.Scene(dim, integrator=integrator, dt=dt, threads=1)
    s.add_particles(x, v, masses=m, pinned=pinned)
    s.add(pc.Springs(i, j, stiffness=stiff, damping=damping))
    return s


def random_cloud(seed: int, n: int, *, dim: int = 3, speed: float = 0.3, box: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random (positions, velocities, masses) of n free particles, kept apart."""
    rng = np.random.default_rng(seed)
    x = _separated_points(rng, n, dim, min_dist=0.1 * box, box=box)
    v = rng.normal(scale=speed, size=(n, dim))
    m = rng.uniform(0.5, 2.0, size=n)
    return x, v, m


def _separated_points(rng: np.random.Generator, n: int, dim: int, *, min_dist: float, box: float) -> np.ndarray:
    pts: list[np.ndarray] = []
    tries = 0
    while len(pts) < n:
        p = rng.uniform(-box, box, size=dim)
        tries += 1
        if all(np.linalg.norm(p - q) >= min_dist for q in pts) or tries > 10_000:
            pts.append(p)
    return np.array(pts)


# --------------------------------------------------------------------------- measurements
def sample(scene: pc.Scene, n_steps: int, every: int, f: Callable[[pc.Scene], object]) -> list:
    """Step ``n_steps`` in chunks of ``every``; return ``[f(scene)]`` at the start and after each chunk."""
    out = [f(scene)]
    done = 0
    while done < n_steps:
        k = min(every, n_steps - done)
        scene.step(k)
        done += k
        out.append(f(scene))
    return out


def total_energy(scene: pc.Scene) -> float:
    return scene.energy().total


def phase_norm(scene: pc.Scene, particle: int = 1, omega: float = 1.0) -> float:
    """sqrt(ω²|x|² + |v|²) of one particle (the oscillator's amplitude in phase space)."""
    x = scene.positions[particle]
    v = scene.velocities[particle]
    return float(math.sqrt(omega**2 * x @ x + v @ v))


def fit_slope(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Least-squares slope of ys against xs."""
    return float(np.polyfit(np.asarray(xs, float), np.asarray(ys, float), 1)[0])


def busy_uses(run: Callable[[], None], uses: Sequence[Callable[[], object]], tries: int = 3) -> tuple[list, list]:
    """Runs `run` (a long stepping call) on a thread and meanwhile calls each of `uses` from this
    one until `tries` of them raised SceneBusyError or `run` ended: (the SceneBusyErrors seen here,
    the exceptions `run` raised)."""
    import threading
    import time

    started = threading.Event()
    errors: list = []

    def target() -> None:
        started.set()
        try:
            run()
        except Exception as e:  # noqa: BLE001 - returned to the caller
            errors.append(e)

    t = threading.Thread(target=target)
    t.start()
    started.wait()
    time.sleep(0.05)  # let the call begin (if it loses the race, it reports SceneBusyError)
    seen: list = []
    deadline = time.monotonic() + 10.0
    while t.is_alive() and time.monotonic() < deadline and len(seen) < tries:
        for use in uses:
            try:
                use()
            except pc.SceneBusyError as e:
                seen.append(e)
        time.sleep(0.005)
    t.join()
    return seen, errors


def batch_uses_say_busy(batch: pc.Batch, run: Callable[[], None]) -> bool:
    """`busy_uses` of `run` (a long call of `batch`) while this thread reads member 1's
    positions, steps member 0 and reads the batch's positions: asserts that the call raised
    nothing but SceneBusyError, and that each use refused raised SceneBusyError naming another
    thread. False, with nothing more asserted, where the batch lost the race to a member's step
    (it said so itself): the caller runs its test again."""
    members = batch.members
    seen, errors = busy_uses(run, (lambda: members[1].positions, lambda: members[0].step(1), lambda: batch.positions))
    assert all(isinstance(e, pc.SceneBusyError) for e in errors), errors
    if errors:
        return False
    assert seen, "the batch's call ended before another thread could use a member"
    assert all("another thread" in str(e) for e in seen)
    return True
