"""The double-pendulum fan (``scenes.double_pendulum``): its small-amplitude normal modes against
the linearised closed form, energy conserved to velocity Verlet's order, and chaos pulling
pendulums started 1e-6 rad apart into a fan."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc

G = 9.81


def _angles(scene: pc.Scene) -> tuple[np.ndarray, np.ndarray]:
    """(n,) θ1 and θ2 of every pendulum (from the downward vertical)."""
    x = scene.positions
    p1, p2 = x[1::2], x[2::2]
    d2 = p2 - p1
    return np.arctan2(p1[:, 0], -p1[:, 1]), np.arctan2(d2[:, 0], -d2[:, 1])


def _period(theta: np.ndarray, dt: float) -> float:
    """Mean period of a sampled oscillation from its upward zero crossings (linear interpolation)."""
    s = np.sign(theta)
    k = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    t = (k + theta[k] / (theta[k] - theta[k + 1])) * dt
    return float((t[-1] - t[0]) / (len(t) - 1))


@pytest.mark.parametrize("mode, sign", [("slow", 1.0), ("fast", -1.0)])
def test_small_oscillations_follow_the_normal_modes(mode, sign):
    # Equal masses and lengths: ω² = (g/l)(2 ∓ √2), θ2/θ1 = ±√2 (Landau & Lifshitz, Mechanics §23).
    length, a = 0.7, 2e-3
    omega = math.sqrt(G / length * (2 - sign * math.sqrt(2)))
    s = pc.scenes.double_pendulum(n=1, angles=(a, sign * math.sqrt(2) * a), spread=0.0, length=length)
    samples, every = [], 20
    steps = int(8 * 2 * math.pi / omega / s.dt) // every
    for _ in range(steps):
        s.step(every)
        t1, t2 = _angles(s)
        samples.append((t1[0], t2[0]))
    th = np.array(samples)
    period = _period(th[:, 0], every * s.dt)
    # Measured 3.6e-6 (slow) and 6e-7 (fast) relative; the rods' compliance ((ω/ω_rod)² ≈ 1e-5)
    # and the amplitude's anharmonic shift (a²/16 ≈ 3e-7) are both below 1e-4 here.
    assert period == pytest.approx(2 * math.pi / omega, rel=1e-4)
    # The mode keeps its shape: θ2/θ1 stays at ±√2 (the other mode is not excited).
    big = np.abs(th[:, 0]) > 0.5 * a
    np.testing.assert_allclose(th[big, 1] / th[big, 0], sign * math.sqrt(2), rtol=1e-3)  # measured 7e-5


def _max_energy_error(dt: float, t_end: float = 2.0) -> float:
    s = pc.scenes.double_pendulum(n=1, dt=dt)
    e0 = s.energy().total
    worst, every = 0.0, max(1, round(0.01 / dt))
    for _ in range(round(t_end / dt) // every):
        s.step(every)
        worst = max(worst, abs(s.energy().total - e0))
    return worst / abs(e0)


def test_energy_error_is_bounded_and_second_order():
    # Velocity Verlet on a chaotic swing: the energy error is bounded and falls 4× per halving
    # of dt (measured: 8.0e-7 and 2.0e-7 over 2 s, ratio 4.06).
    dt = pc.scenes.double_pendulum(n=1).dt
    coarse, fine = _max_energy_error(2 * dt), _max_energy_error(dt)
    assert fine < 1e-6
    assert coarse / fine == pytest.approx(4.0, rel=0.2)


def test_chaos_fans_the_pendulums_out():
    # 20 pendulums 1e-6 rad apart (1.9e-5 in all) move as one for a while, then spread over
    # radians (measured spread of θ2: 1.8e-4 at t = 2 s, 0.65 at 8 s, 12.9 at 12 s).
    s = pc.scenes.double_pendulum(n=20)
    _, t2 = _angles(s)
    assert np.ptp(t2) == pytest.approx(19e-6, rel=1e-6)
    s.step(round(2.0 / s.dt))
    _, t2 = _angles(s)
    early = np.ptp(np.unwrap(t2))
    assert early < 0.05  # still together at t = 2 s
    s.step(round(10.0 / s.dt))
    _, t2 = _angles(s)
    late = np.ptp(np.unwrap(t2))
    assert late > 1.0  # fanned out by t = 12 s
    # The rods stay rigid to 0.1 %.
    x = s.positions
    np.testing.assert_allclose(np.linalg.norm(x[1::2] - x[0], axis=1), 1.0, rtol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(x[2::2] - x[1::2], axis=1), 1.0, rtol=1e-3)


def test_double_pendulum_refuses_bad_arguments():
    with pytest.raises(ValueError, match=r"\bn\b"):
        pc.scenes.double_pendulum(n=0)
    with pytest.raises(TypeError, match="angles"):
        pc.scenes.double_pendulum(angles=1.0)
    with pytest.raises(ValueError, match="angles"):
        pc.scenes.double_pendulum(angles=(1.0, math.nan))
    with pytest.raises(ValueError, match="spread"):
        pc.scenes.double_pendulum(spread=-1.0)
    with pytest.raises(ValueError, match="length"):
        pc.scenes.double_pendulum(length=0.0)
    with pytest.raises(ValueError, match="stiffness"):
        pc.scenes.double_pendulum(stiffness=-5.0)
    with pytest.raises(ValueError, match="spread"):  # found by a fuzz: the angles overflowed
        pc.scenes.double_pendulum(spread=1e308)
    with pytest.raises(ValueError, match="stiffness"):  # the step 0.2/√(2k/m) underflows
        pc.scenes.double_pendulum(stiffness=8.98846567431158e307)


def test_double_pendulum_renders_with_rods_in_each_pendulums_colour(tmp_path):
    s = pc.scenes.double_pendulum(n=2, spread=1.0)  # two pendulums far apart: two hues
    img = next(pc.render.frames(s, frames=1, size=(200, 200)))
    colours = {tuple(c) for c in img.reshape(-1, 3)}
    rgb = s.render_defaults["colors"]
    # Each pendulum's own colour shows (its bobs), and so do its rods (a blend towards it).
    assert tuple(rgb[1]) in colours and tuple(rgb[3]) in colours
