"""Linear stability limits of the fixed-step integrators, measured through the Python API: the
pytest twin of the cargo test ``stability_limits_match_theory`` (rust_core/src/integration_tests/integrators.rs).

Model problem: the undamped harmonic oscillator x'' = -ω² x, a free particle of mass m tied by
a zero-rest-length spring of stiffness k = m ω² to a pinned anchor (the force is exactly -k x,
see rust_core/src/terms/springs.rs), in 2D. In scaled phase-space coordinates (x, u = v/ω) one
step of every method is a fixed 2×2 matrix of h = ω·dt alone (Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, §I.5 and §XIII; Hairer & Wanner, *Solving ODEs II*, §IV.2):

=====================  ==========================================  ==============================
integrator             one-step map on (x, u)                      stable on the imaginary axis
=====================  ==========================================  ==============================
euler                  [[1, h], [-h, 1]]: |λ| = sqrt(1 + h²)        never (limit 0)
semi_implicit_euler    kick then drift: [[1 - h², h], [-h, 1]]     h < 2
verlet                 [[1 - h²/2, h], [-h(1 - h²/4), 1 - h²/2]]   h < 2
rk4                    R(z) = 1 + z + z²/2 + z³/6 + z⁴/24, z = ih  h ≤ 2√2
boris                  no magnetic field: velocity Verlet's         h < 2
yoshida4               V(w₁h) V(w₀h) V(w₁h), V Verlet's (Yoshida    h < 1.5734019474 (first
                       1990, eq. 4.14)                              |tr| = 2: tr = +2 there)
xpbd                   `substeps` s semi-implicit Euler substeps    h < 2s (20 at s = 10)
                       of h/s (no constraints: no projection)
implicit_euler         (1/(1 + h²)) [[1, h], [-h, 1]]:              every h (A-stable)
                       |λ| = 1/sqrt(1 + h²)
=====================  ==========================================  ==============================

A symplectic 2×2 map M (det M = 1) is stable while |tr M| < 2 and leaves the imaginary axis
where |tr M| = 2: Verlet and semi-implicit Euler at tr = -2 (eigenvalues through -1), Yoshida's
composition at tr = +2 (through +1: its middle substep runs backwards). Its invariant quadratic
form is Q = [[-c, (a - d)/2], [(a - d)/2, b]] for M = [[a, b], [c, d]] (MᵀQM = Q), the
"modified energy" the map conserves exactly. Yoshida's limit has no closed form here: it is the
root of tr M(h) = 2 found from the matrix (1.5734019474), not from the code.

Every test runs at every SIMD level this CPU has (the ``simd_level`` fixture; the others are
skipped, saying so), on two scenes: one oscillator tied to an anchor (a spring slice of 8 lanes
with 6 padding lanes) and 8 oscillators (particles 0..7, one full slice) around one anchor
(particle 8). The spring kernel takes 1/L from the level's fast reciprocal square root (hardware
estimate + Newton steps, a few ulp from a square root and a division); the limits must not care.

What test_integrators.py already covers (one point each side of each limit, RK4's |R(ih)| over 20
steps, the shadow energy at h = 0.7, Euler's factor at h = 0.1) is not repeated here; this file
*measures* the limits by bisection and checks the growth rates just either side of them.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import numpy as np
import pytest

import physcore as pc

OMEGA = 4.0  # rad/s: m = 0.5 kg, k = m ω² = 8 N/m (so ω·dt = h exercises the units, not just ω = 1)
MASS = 0.5
STIFFNESS = MASS * OMEGA**2
ROOT8 = 2.0 * math.sqrt(2.0)

N_STEPS = 2000  # steps per bisection run
GAIN = 10.0  # a run is "unstable" if some oscillator's amplitude ends above GAIN × its start
BISECT_REL = 1e-9  # bisection stops when the bracket is this narrow (relative to the limit)
PATHS = ("one", "slice")

# --------------------------------------------------------------------------------- theory
#: Theoretical stability limit of h = ω·dt, and the bisection bracket (stable end, unstable end).
#: Yoshida's weights (Yoshida 1990, eq. 4.14), as in rust_core/src/integrators/yoshida.rs.
YOSHIDA_W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
YOSHIDA_W0 = 1.0 - 2.0 * YOSHIDA_W1
#: pc.XPBD's default substeps (the scenes below pass integrator="xpbd": the defaults).
XPBD_SUBSTEPS = 10
LIMIT = {"euler": 0.0, "semi_implicit_euler": 2.0, "verlet": 2.0, "rk4": ROOT8, "boris": 2.0, "xpbd": 2.0 * XPBD_SUBSTEPS}
BRACKET = {
    "euler": (1e-3, 1.0),
    "semi_implicit_euler": (1.0, 3.0),
    "verlet": (1.0, 3.0),
    "rk4": (1.0, 3.0),
    "boris": (1.0, 3.0),
    "yoshida4": (1.0, 2.0),
    "xpbd": (10.0, 30.0),
}
#: Phase-space start (x, u) of the bisection runs: for the symplectic maps the long axis of the
#: invariant ellipse (Verlet: u² + (1 - h²/4) x² = const, long axis along x; semi-implicit Euler:
#: x² + u² - h x u = const, long axis along x = u), the same direction for every h < 2. Starting
#: there the amplitude never exceeds its start below the limit, so "ends above GAIN × start"
#: cannot fire on the stable side however eccentric the ellipse gets as h → 2 (from a generic
#: start the amplitude reaches ~1/sqrt(2 - h) × start, which would bias the measured limit low).
START = {
    "euler": (1.0, 0.0),
    "semi_implicit_euler": (2**-0.5, 2**-0.5),
    "verlet": (1.0, 0.0),
    "rk4": (0.6, 0.8),
    "boris": (1.0, 0.0),
    "xpbd": (2**-0.5, 2**-0.5),  # semi-implicit Euler's, substep by substep
}
#: The symplectic maps: stable while |tr M| < 2 (see the module docstring).
SYMPLECTIC = ("semi_implicit_euler", "verlet", "boris", "yoshida4", "xpbd")


def step_matrix(name: str, h: float) -> np.ndarray:
    """The method's one-step matrix on (x, u = v/ω) at h = ω·dt (order as in the Rust code)."""
    if name == "euler":  # x' = x + h u, u' = u - h x (both from the old state)
        return np.array([[1.0, h], [-h, 1.0]])
    if name == "semi_implicit_euler":  # kick u' = u - h x, then drift x' = x + h u'
        return np.array([[1.0 - h * h, h], [-h, 1.0]])
    if name == "verlet":  # kick h/2, drift h, kick h/2
        return np.array([[1.0 - h * h / 2, h], [-h * (1.0 - h * h / 4), 1.0 - h * h / 2]])
    if name == "rk4":  # R(z) on x + i u with z = -ih (u' = -x, x' = u): a scaled rotation
        r = np.polyval([1 / 24, 1 / 6, 1 / 2, 1.0, 1.0], -1j * h)
        return np.array([[r.real, -r.imag], [r.imag, r.real]])
    if name == "boris":  # the Boris push with no magnetic term is velocity Verlet
        return step_matrix("verlet", h)
    if name == "yoshida4":  # V(w₁h), then V(w₀h), then V(w₁h) (symmetric: either order)
        v1, v0 = step_matrix("verlet", YOSHIDA_W1 * h), step_matrix("verlet", YOSHIDA_W0 * h)
        return v1 @ v0 @ v1
    if name == "xpbd":  # s substeps of semi-implicit Euler at h/s; nothing to project
        return np.linalg.matrix_power(step_matrix("semi_implicit_euler", h / XPBD_SUBSTEPS), XPBD_SUBSTEPS)
    if name == "implicit_euler":  # (I - hA)⁻¹ with A = [[0, 1], [-1, 0]]
        return np.array([[1.0, h], [-h, 1.0]]) / (1.0 + h * h)
    raise KeyError(name)


def trace_limit(name: str, lo: float, hi: float) -> float:
    """The first h in (lo, hi) where the symplectic map's |tr M(h)| reaches 2 (bisection to 1e-15)."""
    a, b = bisect(lambda h: abs(np.trace(step_matrix(name, h))) > 2.0, lo, hi, 1e-15)
    return 0.5 * (a + b)


def edge_start(name: str) -> tuple[float, float]:
    """The eigenvector of M(h0) at the limit (M ∓ I is nilpotent there): the long axis of the
    invariant ellipse as h → h0, from where no run grows below the limit (see START)."""
    m = step_matrix(name, LIMIT[name])
    a = m - np.sign(np.trace(m)) * np.eye(2)
    p, q = a[np.argmax(np.abs(a).sum(axis=1))]  # its larger row; the null vector is normal to it
    return float(-q / math.hypot(p, q)), float(p / math.hypot(p, q))


def trace_slope(name: str) -> float:
    """|d tr M / dh| at the limit (central difference; 4 for Verlet, exactly 2h)."""
    h0, e = LIMIT[name], 1e-6 * LIMIT[name]
    return abs(np.trace(step_matrix(name, h0 + e)) - np.trace(step_matrix(name, h0 - e))) / (2 * e)


def spectral_radius(name: str, h: float) -> float:
    if name == "rk4":
        return float(abs(np.polyval([1 / 24, 1 / 6, 1 / 2, 1.0, 1.0], 1j * h)))
    return float(np.abs(np.linalg.eigvals(step_matrix(name, h))).max())


def finite_run_offset(name: str, n: int, gain: float) -> float:
    """How far above the true limit a run of n steps first sees growth by ``gain`` (leading order).

    * euler: amplitude × sqrt(1 + h²) per step, so (1 + h²)^(n/2) = gain at h = sqrt(gain^(2/n) - 1)
      (0.048 for n = 2000: the measured "limit" of explicit Euler is this, → 0 like n^(-1/2)).
    * semi-implicit Euler, Verlet: at h = 2 + δ the trace is 2 - h² = -2cosh μ with μ ≈ 2√δ
      (so |λ| ≈ 1 + 2√δ: growth ~ √δ per step, as the eigenvalues leave the unit circle at -1
      through a double root). From the long-axis start (the eigenvector at h = 2) the amplitude
      after n steps is cosh(nμ) (plus an O(√δ) sinh term), so the threshold is
      δ_n = (arccosh(gain) / 2n)² = 5.6e-7 for n = 2000, gain = 10.
    * rk4: |R(ih)|² = 1 - h⁶/72 + h⁸/576, d|R|²/dh = h⁵/36 at h = 2√2, so ln|R| ≈ h⁵δ/72 and
      n ln|R| = ln gain at δ_n = 72 ln(gain) / (n (2√2)⁵) = 4.6e-4 for n = 2000.
    """
    if name == "euler":
        return math.sqrt(gain ** (2.0 / n) - 1.0)
    if name in ("semi_implicit_euler", "verlet"):
        return (math.acosh(gain) / (2.0 * n)) ** 2
    if name in SYMPLECTIC:
        # The same argument for any symplectic map: |tr M| = 2 + |T'| δ, 2 cosh μ = |tr M|, so
        # μ ≈ sqrt(|T'| δ) and cosh(nμ) = gain at δ_n = (arccosh(gain) / n)² / |T'| (T' = 4 above).
        return (math.acosh(gain) / n) ** 2 / trace_slope(name)
    if name == "rk4":
        return 72.0 * math.log(gain) / (n * ROOT8**5)
    raise KeyError(name)


def model_growth(name: str, h: float, n: int) -> float:
    """|M(h)^n s0| / |s0| for the theoretical one-step matrix (inf/nan on overflow)."""
    s0 = np.array(START[name], float)
    with np.errstate(over="ignore", invalid="ignore"):
        return float(np.linalg.norm(np.linalg.matrix_power(step_matrix(name, h), n) @ s0) / np.linalg.norm(s0))


def bisect(unstable: Callable[[float], bool], lo: float, hi: float, rel: float) -> tuple[float, float]:
    """Narrow [lo, hi] (lo stable, hi unstable) until hi - lo <= rel * hi; returns (lo, hi)."""
    while hi - lo > rel * hi:
        mid = 0.5 * (lo + hi)
        if unstable(mid):
            hi = mid
        else:
            lo = mid
    return lo, hi


LIMIT["yoshida4"] = trace_limit("yoshida4", *BRACKET["yoshida4"])
START["yoshida4"] = edge_start("yoshida4")  # (0, 1): M - I = [[0, 0], [-1.78, 0]] at h0


# --------------------------------------------------------------------------------- scenes
def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def oscillators(name: str, h: float, path: str, start: tuple[float, float]) -> tuple[pc.Scene, slice]:
    """Scene of independent oscillators (ω = OMEGA) at dt = h/ω, each starting at phase-space
    point a·start along its own direction in the plane; returns (scene, slice of oscillators).

    ``path="one"``: anchor + 1 oscillator (2 particles, a padded spring slice).
    ``path="slice"``: 8 oscillators of amplitudes 1..2.75 in 8 directions (particles 0..7: one
    full spring slice) + the anchor (particle 8); the map is linear and isotropic, so each behaves
    as the single one, scaled.
    """
    count = 1 if path == "one" else 8
    amps = 1.0 + 0.25 * np.arange(count)
    dirs = np.array([_unit(0.3 + 0.7 * j) for j in range(count)])
    x = (amps * start[0])[:, None] * dirs
    v = (amps * start[1] * OMEGA)[:, None] * dirs
    s = pc.Scene(2, integrator=name, dt=h / OMEGA, threads=1)
    anchor = np.zeros((1, 2))
    if path == "one":
        s.add_particles(np.vstack([anchor, x]), np.vstack([anchor, v]), masses=MASS, pinned=[True, False])
        s.add(pc.Springs([0], [1], stiffness=STIFFNESS, rest_length=0.0))
        return s, slice(1, 2)
    s.add_particles(np.vstack([x, anchor]), np.vstack([v, anchor]), masses=MASS, pinned=[False] * count + [True])
    s.add(pc.Springs(np.arange(count), np.full(count, count), stiffness=STIFFNESS, rest_length=0.0))
    return s, slice(0, count)


def phase(s: pc.Scene, osc: slice) -> tuple[np.ndarray, np.ndarray]:
    """Signed components (x, u) of each oscillator along its own direction (anchor at origin)."""
    x, v = s.positions[osc], s.velocities[osc]
    n = len(x)
    dirs = np.array([_unit(0.3 + 0.7 * j) for j in range(n)])
    return np.einsum("ij,ij->i", x, dirs), np.einsum("ij,ij->i", v, dirs) / OMEGA


def amplitude(s: pc.Scene, osc: slice) -> np.ndarray:
    """sqrt(|x|² + |v|²/ω²) of each oscillator."""
    x, v = s.positions[osc], s.velocities[osc]
    return np.sqrt((x**2).sum(axis=1) + (v**2).sum(axis=1) / OMEGA**2)


def trajectory(name: str, h: float, path: str, start: tuple[float, float], n: int):
    """(x, u) of each oscillator after 0..n steps, arrays of shape (n + 1, oscillators)."""
    s, osc = oscillators(name, h, path, start)
    xs, us = [], []
    for k in range(n + 1):
        if k:
            s.step(1)
        x, u = phase(s, osc)
        xs.append(x)
        us.append(u)
    return np.array(xs), np.array(us)


def _params(names):
    """Parametrize over pc.INTEGRATORS; adaptive/unknown ones are skipped with the reason."""
    out = []
    for d in pc.INTEGRATORS:
        n = d["name"]
        if n == "dopri5":
            out.append(pytest.param(n, marks=pytest.mark.skip(reason="dopri5 is adaptive: its step is error-controlled, no fixed-h stability limit")))
        elif n == "wisdom_holman":
            reason = "wisdom_holman steps only Kepler problems (a PairwiseGravity scene), no oscillator: its Kepler part is exact"
            out.append(pytest.param(n, marks=pytest.mark.skip(reason=reason)))
        elif n == "implicit_euler":
            reason = "implicit_euler has no limit (A-stable): test_implicit_euler_energy_shrinks_by_exactly_one_over_one_plus_h_squared"
            out.append(pytest.param(n, marks=pytest.mark.skip(reason=reason)))
        elif n not in LIMIT:
            out.append(pytest.param(n, marks=pytest.mark.skip(reason=f"no stability theory for {n!r} in this file")))
        elif n not in names:
            out.append(pytest.param(n, marks=pytest.mark.skip(reason=f"{n}: not applicable (no stable range)" if n == "euler" else "n/a")))
        else:
            out.append(n)
    return out


ALL = ("euler", "semi_implicit_euler", "verlet", "rk4", "boris", "yoshida4", "xpbd")
WITH_STABLE_RANGE = ("semi_implicit_euler", "verlet", "rk4", "boris", "yoshida4", "xpbd")


# --------------------------------------------------------------------------------- 1. bisection
def _code_unstable(name: str, path: str, n: int) -> Callable[[float], bool]:
    def unstable(h: float) -> bool:
        s, osc = oscillators(name, h, path, START[name])
        a0 = amplitude(s, osc)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", pc.StabilityWarning)
            try:
                s.step(n)
            except pc.SimulationDiverged:
                return True
            finally:
                # The step's StabilityWarning is never a false alarm: only past the limit.
                warned = any(issubclass(w.category, pc.StabilityWarning) for w in caught)
                assert not warned or h > LIMIT[name], f"{name}: warned at ω·dt = {h}, inside the stable range"
        return bool(np.any(amplitude(s, osc) > GAIN * a0))

    return unstable


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", _params(ALL))
def test_measured_stability_limit_matches_theory(name, path, record_property, simd_level):
    lo, hi = BRACKET[name]
    h0 = LIMIT[name]
    runs = [N_STEPS, 4 * N_STEPS] if name == "euler" else [N_STEPS]  # Euler: the "limit" → 0 like n^(-1/2)
    for n in runs:
        unstable = _code_unstable(name, path, n)
        assert not unstable(lo) and unstable(hi), f"{name}: bracket [{lo}, {hi}] does not straddle the limit"
        a, b = bisect(unstable, lo, hi, BISECT_REL)
        measured = 0.5 * (a + b)
        res = b - a  # bisection resolution
        # Tolerance from the step count: a run of n steps cannot see instability closer than
        # δ_n above the true limit (finite_run_offset), and from the long-axis start it sees
        # no growth at all below it. So the measured limit must lie in [h0, h0 + δ_n] (up to the
        # bisection resolution; 1 % on δ_n covers the leading-order formula, exact to 1e-7 here).
        delta_n = finite_run_offset(name, n, GAIN)
        msg = (
            f"{name} ({path}, {simd_level}, {n} steps, gain {GAIN:g}): measured limit ω·dt = {measured:.10f}, "
            f"theory {h0:.10f}, offset {measured - h0:+.3e}, finite-run resolution δ_n = {delta_n:.3e}"
        )
        print("\n" + msg)
        record_property(f"measured_limit_{n}", measured)
        assert h0 - res <= measured <= h0 + 1.01 * delta_n + res, msg
        # And it is where the theoretical one-step matrix first grows by GAIN in n steps (not
        # merely somewhere below it): the core's map is that matrix, near the limit too.
        if name == "rk4":  # |R(ih)|^n = gain solved from the closed form (exact, no matrix power)
            m_lo, m_hi = bisect(lambda h, n=n: n * math.log(spectral_radius(name, h)) > math.log(GAIN), 2.5, 3.0, 1e-13)
        else:
            m_lo, m_hi = bisect(lambda h, n=n: not model_growth(name, h, n) <= GAIN, lo, hi, 1e-13)
        predicted = 0.5 * (m_lo + m_hi)
        assert abs(measured - predicted) <= res + 1e-12, f"{msg}; one-step-matrix theory predicts {predicted:.10f}"
        assert abs((predicted - h0) / delta_n - 1) < 0.01, "the δ_n formula itself (leading order)"


# --------------------------------------------------------------------------------- 2. either side
#: Invariant quadratic form ("modified energy") of each symplectic map, on (x, u).
def shadow_form(name: str, h: float) -> np.ndarray:
    if name == "verlet":  # u² + (1 - h²/4) x²
        return np.array([[1.0 - h * h / 4, 0.0], [0.0, 1.0]])
    if name == "semi_implicit_euler":  # x² + u² - h x u (u after the kick)
        return np.array([[1.0, -h / 2], [-h / 2, 1.0]])
    # Any other symplectic map: Q = [[-c, (a - d)/2], [(a - d)/2, b]] (the two above, scaled by
    # h), signed positive definite inside the limit.
    (a, b), (c, d) = step_matrix(name, h)
    q = np.array([[-c, (a - d) / 2], [(a - d) / 2, b]])
    return q / np.sign(np.trace(q))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", _params(WITH_STABLE_RANGE))
def test_just_inside_the_limit_the_amplitude_stays_bounded(name, path, simd_level):
    h = 0.99 * LIMIT[name]
    if name == "rk4":
        # |R(ih)| = 0.93 < 1 at h = 0.99·2√2: every step shrinks the amplitude by exactly |R|.
        n = 400
        x, u = trajectory(name, h, path, START[name], n)
        a = np.hypot(x, u)
        r = spectral_radius(name, h)
        assert r < 1
        assert np.all(a[1:] < a[:-1]), "rk4 amplitude must decrease at every step inside the limit"
        np.testing.assert_allclose(a / a[0], np.broadcast_to(r ** np.arange(n + 1)[:, None], a.shape), rtol=1e-10)
        return
    # Symplectic: from a generic start the orbit lies on the ellipse Q(x, u) = Q0 of the shadow
    # energy, conserved exactly by the map (to round-off); the amplitude is bounded by the
    # ellipse's semi-major axis sqrt(Q0 / λ_min(Q)) for all time (no secular growth), and the orbit
    # reaches that bound (so the bound is the sharp one). From (x, u) = (0.6, -0.8) at h = 1.98 it
    # is 5.7× the start for Verlet and 14× for semi-implicit Euler (λ_min = 0.0199 and 0.01).
    n = 4000
    Q = shadow_form(name, h)
    start = (0.6, -0.8)
    if name not in ("verlet", "semi_implicit_euler"):
        # From the ellipse's short axis the amplitude sweeps the whole ratio sqrt(λmax/λmin) of
        # Q's eigenvalues (Yoshida's ellipse at 0.99 h0 is 5.9:1; from (0.6, -0.8) only 3.6).
        start = tuple(np.linalg.eigh(Q)[1][:, 1])
    x, u = trajectory(name, h, path, start, n)
    q = Q[0, 0] * x * x + 2 * Q[0, 1] * x * u + Q[1, 1] * u * u
    np.testing.assert_allclose(q, np.broadcast_to(q[0], q.shape), rtol=1e-11)
    bound = np.sqrt(q[0] / np.linalg.eigvalsh(Q)[0])
    a = np.hypot(x, u)
    assert np.all(a <= bound * (1 + 1e-10))
    assert np.all(a.max(axis=0) >= 0.99 * bound), (a.max(axis=0), bound)
    assert np.all(bound > 4 * a[0]), "the test is vacuous unless the ellipse is eccentric"


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", _params(WITH_STABLE_RANGE))
def test_just_outside_the_limit_growth_matches_the_eigenvalue(name, path, record_property, simd_level):
    h = 1.01 * LIMIT[name]
    lam = spectral_radius(name, h)  # |λ|max of the one-step matrix (numpy eigvals / |R(ih)|)
    if name == "rk4":
        # A scaled rotation: the amplitude is multiplied by exactly |R(ih)| = 1.073 every step.
        n0, n1 = 0, 2000
    elif name == "xpbd":
        # Ten semi-implicit Euler substeps at 2.02 each: |λ| = 1.33^10 = 16.9 a step, so the
        # decaying mode is 16.9^-20 ≈ 3e-25 of the growing one after 10 steps (and 30 more
        # steps grow by 7e36, within range).
        n0, n1 = 10, 40
    else:
        # Two real eigenvalues -|λ|, -1/|λ| (|λ| = 1.33 at h = 2.02; Yoshida's: +1.35, +1/1.35
        # at 1.01 h0): after n0 = 100 steps the decaying mode is |λ|^-200 ≈ 1e-25 of the growing
        # one, so the amplitude grows by exactly |λ| per step from then on (before that, by a
        # start-dependent prefactor).
        n0, n1 = 100, 400
    x, u = trajectory(name, h, path, START[name] if name == "rk4" else (0.6, 0.8), n1)
    a = np.hypot(x, u)
    growth = a[n1] / a[n0]
    per_step = growth ** (1.0 / (n1 - n0))
    msg = f"{name} ({path}, {simd_level}) at ω·dt = {h:.6f}: measured growth per step {per_step[0]:.12f}, theory |λ| = {lam:.12f}"
    print("\n" + msg)
    record_property("growth_per_step", float(per_step[0]))
    # Round-off makes each step's amplitude relatively wrong by ~1e-16, so over 300..2000 steps the
    # growth matches |λ|^n to ~n·1e-16 (measured: 3e-14 .. 3e-13); assert 1e-11, not "a few %".
    np.testing.assert_allclose(growth, lam ** (n1 - n0), rtol=1e-11, err_msg=msg)
    assert lam > 1.05


# --------------------------------------------------------------------------------- 3. explicit Euler
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("h", [1e-3, 1e-2, 0.3, 1.0])
def test_explicit_euler_energy_grows_by_exactly_one_plus_h_squared(h, path, simd_level):
    # MᵀM = (1 + h²) I for M = [[1, h], [-h, 1]]: every state's energy (½ k x² + ½ m v²) is
    # multiplied by exactly 1 + h² each step, in any direction, at every dt > 0.
    if "euler" not in [d["name"] for d in pc.INTEGRATORS]:
        pytest.skip("no explicit Euler")
    n = 200
    s, _ = oscillators("euler", h, path, (0.6, 0.8))
    e = [s.energy().total]
    for _ in range(n):
        s.step(1)
        e.append(s.energy().total)
    e = np.array(e)
    ratio = e[1:] / e[:-1]
    assert np.all(ratio > 1.0), "explicit Euler must gain energy at every step"
    np.testing.assert_allclose(ratio, 1.0 + h * h, rtol=1e-12, atol=0)
    # Over n steps: log E_n/E_0 = n log1p(h²) up to round-off, at most a few ulp of E per step
    # (measured: below 0.03·n·eps, the errors do not accumulate coherently).
    assert abs(math.log(e[-1] / e[0]) - n * math.log1p(h * h)) <= 4 * n * np.finfo(float).eps


# --------------------------------------------------------------------------------- 4. implicit Euler
@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("h", [1e-3, 0.3, 1.0, 10.0, 1e3, 1e5])
def test_implicit_euler_energy_shrinks_by_exactly_one_over_one_plus_h_squared(h, path, simd_level):
    # Backward Euler's map M = (I - hA)⁻¹ = [[1, h], [-h, 1]] / (1 + h²) has MᵀM = I / (1 + h²):
    # every state's energy is multiplied by exactly 1/(1 + h²) each step, at every dt (A-stable,
    # no limit to find). The spring is linear, so the Baraff–Witkin step (one Newton iteration
    # of backward Euler) is backward Euler itself, and with every oscillator tied to a pinned
    # anchor its system matrix is (m + k dt²) I: Jacobi-preconditioned CG solves it exactly.
    n = 30
    s, _ = oscillators("implicit_euler", h, path, (0.6, 0.8))
    e = [s.energy().total]
    for _ in range(n):
        s.step(1)
        e.append(s.energy().total)
    e = np.array(e)
    assert np.all(e[1:] < e[:-1]), "backward Euler must lose energy at every step"
    # Rounding: v' = v0 + Δv cancels to 1/(1 + h²) of v0, so each step's state is relatively
    # wrong by ~(1 + h²) ulp (measured 9e-11 at h = 1e3; 8 ulp of that is the bound).
    np.testing.assert_allclose(e[1:] / e[:-1], 1.0 / (1.0 + h * h), rtol=8 * (1.0 + h * h) * np.finfo(float).eps, atol=0)
    stats = s.integrator_stats
    assert stats["cg_unconverged"] == 0 and stats["cg_iterations"] == stats["cg_solves"] == n, stats


# --------------------------------------------------------------------------------- kernel edge case
@pytest.mark.parametrize("length", [1e-150, 1e-155, 1e-160])
def test_spring_kernels_handle_lengths_below_1e_154(length, simd_level):
    # Regression: found by the bisection above. RK4 runs deep inside the stable range decayed to
    # ~1e-155 m and then "diverged" in the 8-oscillator (AVX-512) scene only: the kernel's Newton
    # step for 1/L computed h·(y·y), and y·y = 1/L² overflowed. Zero rest length, one Verlet step.
    result = {}
    for path in PATHS:
        s, osc = oscillators("verlet", 0.5, path, (length, 0.0))
        s.step(1)
        result[path] = phase(s, osc)[0][0]
    # (AVX2 takes its estimate in float32, whose range ends at 1e-38: those lanes go exact.)
    for path in PATHS:
        assert result[path] == pytest.approx(length * (1 - 0.5**2 / 2), rel=1e-12, abs=0), path


# --------------------------------------------------------------------------------- the step's warning
#: The integrators Scene.step warns past their stability interval (StabilityWarning), with the
#: interval's ω·dt; the others are stable at any dt on what sets their step (implicit Euler,
#: XPBD, Boris in a magnetic field), or pick it themselves (dopri5, Wisdom–Holman's Kepler part).
WARNED = {"euler": 2.0, "semi_implicit_euler": 2.0, "verlet": 2.0, "rk4": ROOT8, "yoshida4": LIMIT["yoshida4"]}


@pytest.mark.parametrize("name", [d["name"] for d in pc.INTEGRATORS])
def test_the_step_warns_past_the_interval_and_never_inside_it(name):
    # The anchored oscillator's Gershgorin ω is √2 ω (the spring's row counts the pinned anchor),
    # and the warning allows auto_dt's ω up to twice the true one: so it fires from ω·dt = √2 h.
    if name in ("dopri5", "wisdom_holman"):
        pytest.skip(f"{name}: no oscillator step of a fixed h (adaptive, or Kepler problems only)")
    h = WARNED.get(name, 2.0)
    inside, _ = oscillators(name, 0.99 * h, "one", (0.6, 0.8))
    inside.step(3)  # filterwarnings = error: a warning here fails the test
    past, _ = oscillators(name, 1.5 * h, "one", (0.6, 0.8))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", pc.StabilityWarning)
        try:
            past.step(3)
        except pc.SimulationDiverged:
            pass
    names = [str(w.message) for w in caught if issubclass(w.category, pc.StabilityWarning)]
    if name in WARNED:
        assert len(names) == 1 and names[0].startswith("dt: ") and repr(name) in names[0], names
        past.step(1)  # once per dt value
    else:
        assert names == [], names


def test_a_spring_chain_and_a_fluid_far_past_their_steps_warn_and_their_books_show_it():
    from physcore import scenes

    chain = scenes.spring_chain()
    chain.dt = 50 * chain.suggest_dt()
    with pytest.warns(pc.StabilityWarning, match=r"^dt: .* is 50x auto_dt"):
        try:
            chain.step(200)
        except pc.SimulationDiverged:
            pass
    assert chain.step_count == 0 or abs(chain.energy_drift()) > 0.1
    tank = scenes.dam_break(n=8)
    tank.dt = 100 * tank.auto_dt()
    with pytest.warns(pc.StabilityWarning, match="'semi_implicit_euler'"):
        try:
            tank.step(5)
        except pc.SimulationDiverged:
            pass
    calm = scenes.spring_chain()  # its own dt, a quarter of the suggested one: no warning
    calm.step(10)
    calm.dt = calm.suggest_dt()
    calm.step(10)
