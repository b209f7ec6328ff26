"""Implicit (backward) Euler for springs (Baraff & Witkin 1998): its damping factor on the
oscillator, first-order convergence, stiff cloth at steps far beyond the explicit limit settling
where the explicit integrator settles, pinned particles, determinism, the CG options and their
books, and Ctrl-C inside one long solve.

Every expectation comes from the theory of the method (backward Euler's amplification factor,
the static equilibrium every consistent integrator shares), never from a previous run's numbers.
"""
from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from conftest import EPS, fit_slope, oscillator
from test_interrupt import _interrupt

import physcore as pc

NAME = "implicit_euler"


# ------------------------------------------------------------------ the oscillator: exact theory
def _amplitude(s: pc.Scene, omega: float) -> float:
    """‖(ω x, v)‖ of the oscillator's particle: backward Euler's step matrix is a scaled rotation
    in these coordinates, so this shrinks by exactly 1/√(1 + ω²h²) a step."""
    return float(np.sqrt(np.sum((omega * s.positions[1]) ** 2) + np.sum(s.velocities[1] ** 2)))


@pytest.mark.parametrize("limits", [0.05, 1.0, 50.0])
def test_amplitude_ratio_is_backward_eulers(limits):
    # h = `limits` × the explicit (semi-implicit Euler, Verlet) stability limit 2/ω. The spring
    # has rest length 0, so the force is exactly −k x and the linearised step is the exact
    # backward Euler step; one free particle makes the Jacobi preconditioner exact (CG converges
    # in one iteration), so the ratio is the theory's to round-off. That round-off grows with
    # ωh: x' = x + h v' cancels all but 1/(1 + ω²h²) of x, losing that many digits, so the
    # bound is a few tens of ulps times 1 + ω²h² (2e-12 at ωh = 100).
    omega = 40.0
    h = limits * 2.0 / omega
    s = oscillator(NAME, h, omega=omega)
    theory = 1.0 / math.sqrt(1.0 + (omega * h) ** 2)
    ratios = []
    for _ in range(4):
        a0 = _amplitude(s, omega)
        s.step(1)
        ratios.append(_amplitude(s, omega) / a0)
    rtol = 50 * EPS * (1.0 + (omega * h) ** 2)
    assert np.allclose(ratios, theory, rtol=rtol, atol=0), (ratios, theory, rtol)
    assert s.integrator_stats["cg_unconverged"] == 0


def test_explicit_integrator_diverges_where_implicit_decays():
    omega, h = 40.0, 50 * 2.0 / 40.0
    with pytest.warns(pc.StabilityWarning), pytest.raises(pc.SimulationDiverged):
        oscillator("semi_implicit_euler", h, omega=omega).step(200)
    s = oscillator(NAME, h, omega=omega)  # unconditionally stable: not warned
    s.step(200)
    assert np.isfinite(s.positions).all() and _amplitude(s, omega) < 1e-100


def test_energy_books_show_the_numerical_damping():
    # Energy ½ m (ω²x² + v²) shrinks by exactly 1/(1 + ω²h²) a step and no term books any
    # dissipation: the books' residual (energy_drift) is the integrator's damping.
    omega, h, n = 3.0, 0.1, 10
    s = oscillator(NAME, h, omega=omega)
    s.step(n)
    expected = (1.0 + (omega * h) ** 2) ** -n - 1.0
    assert s.energy().dissipated == {}
    assert s.energy_drift() == pytest.approx(expected, rel=1e-10)


# ------------------------------------------------------------------ order of convergence
def _spring_pendulum(integrator: str, dt: float) -> pc.Scene:
    """A smooth nonlinear problem: a mass on a damped spring of rest length 1 swinging under
    gravity from the horizontal (pivot pinned at the origin)."""
    s = pc.Scene(2, integrator=integrator, dt=dt)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 0.5]], masses=[1.0, 1.0], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=50.0, damping=0.5, rest_length=1.0))
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Drag(0.2))
    return s


def test_observed_order_is_one():
    t_end = 1.0
    ref = _spring_pendulum("rk4", 1e-4)
    ref.step(round(t_end / 1e-4))
    y_ref = np.concatenate([ref.positions[1], ref.velocities[1]])
    dts = [0.02, 0.01, 0.005, 0.0025]
    errs = []
    for dt in dts:
        s = _spring_pendulum(NAME, dt)
        s.step(round(t_end / dt))
        errs.append(float(np.linalg.norm(np.concatenate([s.positions[1], s.velocities[1]]) - y_ref)))
    assert all(a > b for a, b in zip(errs, errs[1:], strict=False)), errs
    slope = fit_slope(np.log(dts), np.log(errs))
    assert abs(slope - 1.0) < 0.1, f"observed order {slope:.3f} (errors {errs})"


# ------------------------------------------------------------------ stiff cloth
N_CLOTH = 8
STIFFNESS = 20 * 2000.0  # 20× the cloth scene's default
AIR_DRAG = 8.0  # 1/s: about critical for the sheet's swing about its pinned edge
T_SETTLE = 8.0  # s


def _cloth(integrator: str, *, dt_factor: float = 1.0, threads: int | None = 1, n: int = N_CLOTH) -> pc.Scene:
    """The hanging cloth (one edge pinned: `pin="edge"`, the scene's default before it pinned two
    corners) at `dt_factor` × semi-implicit Euler's automatic step."""
    s = pc.scenes.cloth(n=n, stiffness=STIFFNESS, air_drag=AIR_DRAG, integrator="semi_implicit_euler",
                        threads=threads, pin="edge")
    s.dt = dt_factor * s.auto_dt()
    s.integrator = integrator
    return s


def test_auto_dt_is_twenty_times_the_explicit_one():
    s = _cloth("semi_implicit_euler")
    explicit = s.auto_dt()
    s.integrator = NAME
    assert s.auto_dt() == pytest.approx(20.0 * explicit, rel=1e-14)


def test_stiff_cloth_at_fifty_times_the_explicit_step_settles_where_the_explicit_one_does():
    """The static sag is the same for both integrators: at rest (v = 0) semi-implicit Euler's
    step is the identity exactly where f(x) + m g = 0, and so is the implicit step (Δv = 0 solves
    its system exactly when its right-hand side h (f + m g) is 0). Only the path differs. After
    T_SETTLE each run is still moving at speed v_max (measured); in the slowest mode, the swing
    about the pinned edge (ω ≈ √(3g/2L) = 3.8 rad/s for the sheet, L = 1 m) with air drag
    a = 8/s, the distance to the equilibrium decays at λ = (a − √(a² − 4ω²))/2 ≥ 2.5/s and is
    v/λ. So the two equilibria must agree within (v_a + v_b)/λ, plus round-off far below it."""
    semi = _cloth("semi_implicit_euler")
    implicit = _cloth(NAME, dt_factor=50.0)
    omega_max_dt = 0.5 * 50.0  # the explicit auto step has ω_max·dt = 0.5
    assert omega_max_dt == 25.0
    x0 = implicit.positions
    for s in (semi, implicit):
        s.step(round(T_SETTLE / s.dt))
        assert np.isfinite(s.positions).all()
    st = implicit.integrator_stats
    assert st["cg_unconverged"] == 0, st
    v_max = [float(np.abs(s.velocities).max()) for s in (semi, implicit)]
    lam = 2.5
    tol = sum(v_max) / lam + 1e-9
    assert tol < 1e-5, f"not settled: speeds {v_max}"
    # The sheet hangs: the free edge is about one sheet length below the pinned one.
    sag = [float(-s.positions[-N_CLOTH:, 2].mean()) for s in (semi, implicit)]
    assert 0.99 < sag[0] < 1.1, sag
    assert abs(sag[1] - sag[0]) <= tol, f"sag {sag[1]:.9f} m vs {sag[0]:.9f} m (tolerance {tol:.2e} m)"
    assert np.abs(implicit.positions - semi.positions).max() <= tol
    # Pinned particles never moved.
    assert np.array_equal(implicit.positions[:N_CLOTH], x0[:N_CLOTH])
    assert not implicit.velocities[:N_CLOTH].any()


def test_threads_do_not_change_a_bit():
    # 70 × 70 = 4900 particles: above the size at which the loops fork onto the pool.
    runs = []
    for threads in (1, 2):
        s = _cloth(NAME, dt_factor=30.0, threads=threads, n=70)
        s.step(5)
        runs.append((s.positions, s.velocities, s.integrator_stats))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_an_iteration_limit_too_low_is_counted():
    s = _cloth(NAME, dt_factor=50.0)
    # The first step from the flat sheet at rest is trivial: gravity is normal to every spring,
    # and a spring at its rest length has no transverse stiffness, so CG converges at once.
    s.step(1)
    assert s.integrator_stats["cg_iterations"] == 1
    s.cg_max_iter = 2
    s.step(3)
    st = s.integrator_stats
    assert (st["cg_solves"], st["cg_iterations"], st["cg_max_iterations"], st["cg_unconverged"]) == (4, 7, 2, 3)
    assert s.cg_tol < st["cg_worst_residual"] < 1.0


def test_force_evaluations_are_one_per_step():
    s = _cloth(NAME, dt_factor=20.0)
    s.step(7)
    assert s.force_evaluations == 7
    assert s.integrator_info == {"name": NAME, "order": 1, "symplectic": False, "force_evals_per_step": 1}


# ------------------------------------------------------------------ options, errors, files
@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"cg_tol": 0.0}, "cg_tol"),
        ({"cg_tol": 1.0}, "cg_tol"),
        ({"cg_tol": -1e-8}, "cg_tol"),
        ({"cg_tol": math.nan}, "cg_tol"),
        ({"cg_max_iter": 0}, "cg_max_iter"),
        ({"cg_max_iter": 10**6 + 1}, "cg_max_iter"),
        ({"cg_max_iter": 2**64}, "cg_max_iter"),
    ],
)
def test_bad_cg_options_raise_value_error_naming_them(kwargs, arg):
    with pytest.raises(ValueError, match=arg):
        pc.Scene(2, integrator=NAME, **kwargs)
    s = pc.Scene(2, integrator=NAME)
    with pytest.raises(ValueError, match=arg):
        setattr(s, arg, next(iter(kwargs.values())))
    assert (s.cg_tol, s.cg_max_iter) == (1e-8, 200)


def test_cg_options_have_stated_defaults_and_survive_a_change_of_integrator():
    s = pc.Scene(2)
    assert (s.cg_tol, s.cg_max_iter) == (1e-8, 200)
    s.cg_tol, s.cg_max_iter = 1e-6, 50
    s.integrator = NAME
    assert (s.cg_tol, s.cg_max_iter) == (1e-6, 50)
    assert "cg_tol=1e-06, cg_max_iter=50" in repr(s)
    with pytest.raises(TypeError, match="cg_max_iter"):
        s.cg_max_iter = "many"


def test_save_and_load_continue_bit_for_bit(tmp_path):
    a = _cloth(NAME, dt_factor=40.0)
    a.cg_tol, a.cg_max_iter = 1e-9, 300
    a.step(3)
    b = pc.Scene.load(a.save(tmp_path / "c.npz"))
    assert (b.integrator, b.cg_tol, b.cg_max_iter) == (NAME, 1e-9, 300)
    a.step(4)
    b.step(4)
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.velocities, b.velocities)


# ------------------------------------------------------------------ Ctrl-C inside one solve
@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_keyboard_interrupt_inside_one_long_solve():
    # One step whose CG would run up to a million iterations (a residual of 1e-14 at
    # ω_max·h ≈ 5·10⁴ on 25,600 particles, minutes of work): the flag is read at every
    # iteration, so the call is abandoned inside the solve (no solve is booked) and undone.
    s = pc.scenes.cloth(n=160, stiffness=STIFFNESS, integrator=NAME, threads=2)
    s.step(2)  # off the flat start, where the solve is trivial
    s.dt = 1e5 * s.suggest_dt()
    s.cg_tol, s.cg_max_iter = 1e-14, 10**6
    x0, v0 = s.positions, s.velocities
    _interrupt(lambda: s.step(1), 0.3)
    assert s.integrator_stats["cg_solves"] == 2
    assert np.array_equal(s.positions, x0) and np.array_equal(s.velocities, v0)
    assert s.step_count == 2


@pytest.mark.parametrize("dt", [1.35e154, 1e155, 1e300])
def test_a_step_whose_square_overflows_is_refused_naming_dt(dt):
    # Issue 44 item 6: the solve scales the Jacobians by h². With h² = inf every diagonal of A
    # was infinite (the preconditioner 0) and the right-hand side NaN (inf · J v0 with v0 = 0),
    # so CG stopped at Δv = 0 and a body at rest silently stayed where it was.
    s = oscillator(NAME, 1.0, omega=40.0, v0=(0.0, 0.0))
    x0 = s.positions
    s.dt = dt
    with pytest.raises(pc.InvalidInputError, match=r"^dt: .*dt² overflows float64"):
        s.step(1)
    assert s.step_count == 0 and np.array_equal(s.positions, x0)
    # Just inside the range the step works: backward Euler puts the spring at rest length 0.
    s.dt = 1e150
    s.step(1)
    assert np.all(np.isfinite(s.positions)) and np.linalg.norm(s.positions[1]) < 1e-6


def test_a_step_whose_square_underflows_is_refused_naming_dt():
    # Below √(smallest normal) ≈ 1.49e-154 s the Jacobians drop out of A: not implicit any more.
    s = oscillator(NAME, 1e-160, omega=40.0)
    with pytest.raises(pc.InvalidInputError, match=r"^dt: .*dt² underflows"):
        s.step(1)
    assert s.step_count == 0
