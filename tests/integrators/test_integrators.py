"""Integrators: observed order of convergence, cost accounting and linear stability limits, all
on the undamped harmonic oscillator whose exact solution and stability theory are known."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import INTEGRATOR_NAMES, fit_slope, oscillator, oscillator_exact, phase_norm

import physcore as pc

# ---------------------------------------------------------------------------- order of accuracy

#: Expected global order and the dt ladder (4 values, 3 halvings) over which it is measured.
#: RK4's ladder is coarser so that its error (∝ dt⁴) stays far above round-off.
ORDER_CASES = {
    "euler": (1, [0.02, 0.01, 0.005, 0.0025]),
    "semi_implicit_euler": (1, [0.02, 0.01, 0.005, 0.0025]),
    "verlet": (2, [0.04, 0.02, 0.01, 0.005]),
    "yoshida4": (4, [0.1, 0.05, 0.025, 0.0125]),
    "rk4": (4, [0.1, 0.05, 0.025, 0.0125]),
    # Tolerances so loose that every output step is one accepted Dormand–Prince step of dt:
    # this measures the order of the tableau itself (its error control is tested below).
    "dopri5": (5, [0.4, 0.2, 0.1, 0.05]),
    # Without a magnetic field the Boris push is velocity Verlet (tests/forces/test_charges.py has its
    # order with one).
    "boris": (2, [0.04, 0.02, 0.01, 0.005]),
    # Without constraints each of its 10 substeps is semi-implicit Euler.
    "xpbd": (1, [0.02, 0.01, 0.005, 0.0025]),
    "implicit_euler": (1, [0.02, 0.01, 0.005, 0.0025]),
}
T_FINAL = 2.0


def _error_at(integrator: str, dt: float) -> float:
    s = oscillator(integrator, dt)
    if integrator == "dopri5":
        s.rtol, s.atol = 0.5, 1e6
    n = round(T_FINAL / dt)
    s.step(n)
    xe, ve = oscillator_exact(n * dt)
    x, v = s.positions[1], s.velocities[1]
    return float(np.linalg.norm(np.concatenate([x - xe, v - ve])))


@pytest.mark.parametrize("name", INTEGRATOR_NAMES)
def test_observed_order_of_convergence(name):
    order, dts = ORDER_CASES[name]
    errs = [_error_at(name, dt) for dt in dts]
    # Errors must shrink monotonically, and stay far above double-precision round-off.
    assert all(a > b for a, b in zip(errs, errs[1:], strict=False)), errs
    assert min(errs) > 1e-11
    slope = fit_slope(np.log(dts), np.log(errs))
    assert abs(slope - order) < 0.2, f"{name}: observed order {slope:.3f}, expected {order}"


def test_order_table_matches_reported_orders():
    # The table that tells users the order must agree with the order ladder above (and, for the
    # Wisdom–Holman map, with the one measured on planets in test_wisdom_holman.py).
    for d in pc.INTEGRATORS:
        if d["name"] not in INTEGRATOR_NAMES:
            continue
        assert d["order"] == ORDER_CASES[d["name"]][0]


# ---------------------------------------------------------------------------- the table and cost
def test_integrator_table():
    expected = {
        "euler": (1, False, 1),
        "semi_implicit_euler": (1, True, 1),
        "verlet": (2, True, 1),
        "yoshida4": (4, True, 3),
        "rk4": (4, False, 4),
        "dopri5": (5, False, 6),
        "wisdom_holman": (2, True, 1),
        "boris": (2, False, 1),
        "xpbd": (1, False, 10),
        "implicit_euler": (1, False, 1),
    }
    got = {d["name"]: (d["order"], d["symplectic"], d["force_evals_per_step"]) for d in pc.INTEGRATORS}
    assert got == expected
    assert all(set(d) == {"name", "order", "symplectic", "force_evals_per_step"} for d in pc.INTEGRATORS)
    for d in pc.INTEGRATORS:
        s = pc.Scene(2, integrator=d["name"])
        assert s.integrator_info == d


@pytest.mark.parametrize("name", [n for n in INTEGRATOR_NAMES if n != "dopri5"])
def test_force_evaluations_per_step(name):
    per_step = next(d["force_evals_per_step"] for d in pc.INTEGRATORS if d["name"] == name)
    s = oscillator(name, 0.01)
    assert s.force_evaluations == 0
    s.step(1)
    first = s.force_evaluations
    # Velocity Verlet evaluates the force once at the start ("first same as last" afterwards).
    assert first == per_step + (1 if name in ("verlet", "yoshida4", "boris") else 0)
    for k in (1, 10, 100):
        before = s.force_evaluations
        s.step(k)
        assert s.force_evaluations - before == per_step * k


def test_dopri5_force_evaluations_are_six_per_internal_step():
    s = oscillator("dopri5", 0.5)
    s.step(1)
    st = s.integrator_stats
    # One evaluation at the start (first same as last afterwards) and one for the starting step.
    assert s.force_evaluations == 2 + 6 * (st["accepted"] + st["rejected"])
    for k in (1, 10):
        before, b = s.force_evaluations, s.integrator_stats
        s.step(k)
        a = s.integrator_stats
        assert a["accepted"] - b["accepted"] >= k
        assert s.force_evaluations - before == 6 * (a["accepted"] - b["accepted"] + a["rejected"] - b["rejected"])
    assert pc.Scene(2).integrator_stats is None


@pytest.mark.parametrize("rtol", [1e-4, 1e-6, 1e-8, 1e-10])
def test_dopri5_error_is_proportional_to_tolerance(rtol):
    # Global error over 5 periods within a small multiple of rtol (tolerance proportionality,
    # Hairer, Nørsett & Wanner I, §II.4), and well above it would mean the control is slack.
    s = oscillator("dopri5", 0.25)
    s.rtol, s.atol = rtol, rtol * 1e-3
    n = round(10 * math.pi / 0.25)
    s.step(n)
    xe, ve = oscillator_exact(n * 0.25)
    err = float(np.linalg.norm(np.concatenate([s.positions[1] - xe, s.velocities[1] - ve])))
    assert 1e-2 * rtol < err < 100 * rtol, f"rtol {rtol:g}: global error {err:.2e}"
    assert s.time == n * 0.25


def test_dopri5_lands_on_output_times_and_adapts():
    # A Kepler orbit with e = 0.9: the internal step near pericentre is far below the output
    # step, and the controller rejects only a few percent of its attempts.
    s = pc.scenes.kepler(e=0.9, mass_ratio=0.0, integrator="dopri5", dt=2 * math.pi / 8)
    s.rtol, s.atol = 1e-9, 1e-12
    s.step(8 * 5)
    st = s.integrator_stats
    assert st["accepted"] > 5 * 8 * 5
    assert st["rejected"] < 0.1 * st["accepted"]
    assert s.energy_drift() < 1e-7


def test_verlet_force_cache_is_dropped_when_state_changes():
    s = oscillator("verlet", 0.01)
    s.step(5)
    before = s.force_evaluations
    s.positions = s.positions  # an outside change invalidates the cached force
    s.step(5)
    assert s.force_evaluations - before == 5 + 1


# ---------------------------------------------------------------------------- stability
def _amplitudes(name: str, h: float, n_steps: int):
    """Phase-space amplitude of the ω = 1 oscillator (dt = h) after each step; None if the
    library reported divergence."""
    s = oscillator(name, h)
    a = [phase_norm(s)]
    try:
        for _ in range(n_steps):
            s.step(1)
            a.append(phase_norm(s))
    except pc.SimulationDiverged:
        return None
    return np.array(a)


def test_explicit_euler_energy_grows_by_one_plus_h_squared():
    # For x' = v, v' = -x explicit Euler multiplies x² + v² by exactly (1 + h²) per step.
    h, n = 0.1, 200
    s = oscillator("euler", h)
    e0 = s.energy().total
    energies = [e0]
    for _ in range(n):
        s.step(1)
        energies.append(s.energy().total)
    energies = np.array(energies)
    assert np.all(np.diff(energies) > 0), "explicit Euler must gain energy every step"
    ratio = energies[1:] / energies[:-1]
    np.testing.assert_allclose(ratio, 1 + h * h, rtol=1e-9)
    assert energies[-1] / e0 == pytest.approx((1 + h * h) ** n, rel=1e-8)


@pytest.mark.parametrize("name", ["semi_implicit_euler", "verlet"])
def test_symplectic_stable_below_two(name):
    # Both have the Störmer–Verlet stability interval ω·dt < 2. At 1.9 the orbit stays on an
    # invariant ellipse: the amplitude is bounded (for these maps at most ~4.5× the start).
    a = _amplitudes(name, 1.9, 2000)
    assert a is not None
    assert np.all(np.isfinite(a))
    assert a.max() < 10 * a[0]
    q = len(a) // 4
    assert a[-q:].max() <= 1.01 * a[:q].max()


@pytest.mark.parametrize("name", ["semi_implicit_euler", "verlet"])
def test_symplectic_unstable_above_two(name):
    # At ω·dt = 2.1 the amplification matrix has an eigenvalue of modulus
    # (2.41 + sqrt(2.41² - 4))/2 ≈ 1.88: exponential growth (or a reported divergence).
    a = _amplitudes(name, 2.1, 300)
    if a is not None:
        assert a[-1] > 1e6 * a[0]


def _rk4_factor(h: float) -> float:
    # |R(ih)| for R(z) = 1 + z + z²/2 + z³/6 + z⁴/24: |R|² = 1 - h⁶/72 + h⁸/576.
    return math.sqrt(1 - h**6 / 72 + h**8 / 576)


def test_rk4_stability_limit_is_two_root_two():
    assert _rk4_factor(2.7) < 1 < _rk4_factor(2.9)  # the theory the test relies on
    stable = _amplitudes("rk4", 2.7, 300)
    assert stable is not None
    assert stable[-1] < stable[0]
    unstable = _amplitudes("rk4", 2.9, 300)
    if unstable is not None:
        assert unstable[-1] > 1e6 * unstable[0]


@pytest.mark.parametrize("h", [0.5, 1.5, 2.7, 2.9])
def test_rk4_amplification_factor_matches_theory(h):
    # The RK4 map of the isotropic oscillator is a scaled rotation: the phase-space amplitude
    # is multiplied by exactly |R(ih)| each step.
    a = _amplitudes("rk4", h, 20)
    assert a is not None
    np.testing.assert_allclose(a[1:] / a[:-1], _rk4_factor(h), rtol=1e-9)


@pytest.mark.parametrize("name", ["semi_implicit_euler", "verlet"])
def test_symplectic_conserves_modified_energy_exactly(name):
    # Both symplectic maps conserve a quadratic "shadow" energy of the oscillator exactly:
    #   velocity Verlet:         v² + (1 - h²/4) x²
    #   semi-implicit Euler (kick then drift, v after the kick): x² + v² - h x·v
    # (ω = 1, m = 1). Checking it pins down which scheme is implemented, not just its order.
    h = 0.7
    s = oscillator(name, h)

    def shadow():
        x, v = s.positions[1], s.velocities[1]
        if name == "verlet":
            return v @ v + (1 - h * h / 4) * (x @ x)
        return x @ x + v @ v - h * (x @ v)

    q0 = shadow()
    for _ in range(500):
        s.step(1)
        assert shadow() == pytest.approx(q0, rel=1e-11)


# ---------------------------------------------------------------------------- Yoshida's composition
_W1 = 1 / (2 - 2 ** (1 / 3))
_W0 = 1 - 2 * _W1


def _yoshida_matrix(h: float) -> np.ndarray:
    """The exact one-step map of yoshida4 on x'' = -x: velocity Verlet over w1·h, w0·h, w1·h
    (Yoshida 1990, eq. 4.14), each kick–drift–kick."""

    def verlet(k: float) -> np.ndarray:
        kick, drift = np.array([[1, 0], [-k / 2, 1]]), np.array([[1, k], [0, 1]])
        return kick @ drift @ kick

    return verlet(_W1 * h) @ verlet(_W0 * h) @ verlet(_W1 * h)


def test_yoshida_conserves_the_invariant_of_its_map():
    # A 2×2 symplectic map [[a, b], [c, d]] with |a + d| < 2 keeps Q = c x² + (d − a) x v − b v²
    # exactly; the map is built from the scheme's definition, so this pins the implementation
    # (the weights, their order, the backward middle substep), not just its order.
    h = 0.9
    (a, b), (c, d) = _yoshida_matrix(h)
    s = oscillator("yoshida4", h)

    def q():
        x, v = s.positions[1], s.velocities[1]
        return c * (x @ x) + (d - a) * (x @ v) - b * (v @ v)

    q0 = q()
    for _ in range(500):
        s.step(1)
        assert q() == pytest.approx(q0, rel=1e-11)


def test_yoshida_stability_limit():
    # The composed map is stable while |trace| < 2: for ω·dt below 1.5734 (root of trace = 2,
    # from the map above), a shorter interval than Verlet's 2 because the middle substep is
    # 1.70 dt long. Bounded just below, exponential growth (or a reported divergence) above.
    assert abs(np.trace(_yoshida_matrix(1.55))) < 2 < abs(np.trace(_yoshida_matrix(1.6)))
    a = _amplitudes("yoshida4", 1.55, 2000)
    assert a is not None and np.all(np.isfinite(a))
    assert a.max() < 20 * a[0]
    b = _amplitudes("yoshida4", 1.6, 300)
    if b is not None:
        assert b[-1] > 1e6 * b[0]
