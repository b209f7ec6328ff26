"""Three-body scenes against published results: the figure-eight choreography (Chenciner &
Montgomery 2000, Simó's initial conditions) and Burrau's Pythagorean problem (Szebehely &
Peters 1967), and Yoshida's fourth order against Verlet at equal cost."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc


def _pair_energy(s: pc.Scene, i: int, j: int) -> float:
    m, x, v = s.masses, s.positions, s.velocities
    mu = m[i] * m[j] / (m[i] + m[j])
    return 0.5 * mu * float(np.sum((v[i] - v[j]) ** 2)) - m[i] * m[j] / float(np.linalg.norm(x[i] - x[j]))


def test_figure_eight_closes_after_one_period():
    s = pc.scenes.figure_eight()
    x0, v0 = s.positions, s.velocities
    assert s.energy().total == pytest.approx(-1.2871419917663258, rel=1e-9)
    np.testing.assert_allclose(s.momentum(), 0.0, atol=1e-8)  # Simó's values to 8 digits
    s.step(2100)  # one period T = 6.32591398 in steps of T/2100
    # Measured 2.3e-8: the error of the 8-digit initial conditions and of the step.
    assert np.abs(s.positions - x0).max() < 1e-7
    assert np.abs(s.velocities - v0).max() < 1e-7
    assert abs(s.energy_drift()) < 1e-10


def test_figure_eight_is_a_choreography():
    # Each body runs one curve a third of a period behind the next: after T/3 the three bodies
    # sit where the others started (as a set), with their velocities.
    s = pc.scenes.figure_eight(steps_per_period=3000)
    x0, v0 = s.positions, s.velocities
    s.step(1000)
    x, v = s.positions, s.velocities
    for k in range(3):
        j = int(np.argmin(np.linalg.norm(x0 - x[k], axis=1)))
        assert j != k
        assert np.linalg.norm(x[k] - x0[j]) < 1e-6 and np.linalg.norm(v[k] - v0[j]) < 1e-6


def test_yoshida_beats_verlet_at_equal_force_evaluations():
    # Yoshida's step costs three Verlet steps; at the same number of force evaluations its
    # error after one period of the figure eight is still far smaller (4th order against 2nd).
    def error(integrator: str, steps: int) -> tuple[float, int]:
        s = pc.scenes.figure_eight(steps_per_period=steps, integrator=integrator)
        x0 = s.positions
        s.step(steps)
        return float(np.abs(s.positions - x0).max()), s.force_evaluations

    ev, nv = error("verlet", 1800)
    ey, ny = error("yoshida4", 600)
    assert abs(nv - ny) <= 1
    assert ey < ev / 20, (ey, ev)


def test_pythagorean_problem_ejects_the_lightest_body():
    # Szebehely & Peters (1967): after close encounters the mass-3 body escapes (near t = 60)
    # and masses 4 and 5 leave as a bound binary in the opposite direction.
    s = pc.scenes.pythagorean()
    assert s.energy().total == pytest.approx(-769 / 60, rel=1e-12)  # −G Σ mᵢmⱼ/rᵢⱼ at rest
    s.step(700)  # t = 70
    com = (s.masses[:, None] * s.positions).sum(0) / s.masses.sum()
    r = np.linalg.norm(s.positions - com, axis=1)
    # The binary recoils with 3/9 of the escaper's distance (momentum is zero).
    assert r[0] > 25 and max(r[1], r[2]) < 0.4 * r[0]
    assert np.linalg.norm(s.positions[1] - s.positions[2]) < 1.0
    assert _pair_energy(s, 1, 2) < 0  # the binary is bound
    e_escape = 0.5 * 3.0 * float(np.sum(s.velocities[0] ** 2)) - 3.0 * 9.0 / float(np.linalg.norm(s.positions[0] - (4 * s.positions[1] + 5 * s.positions[2]) / 9))
    assert e_escape > 0  # and the single body is unbound from it
    assert abs(s.energy_drift()) < 1e-6
    np.testing.assert_allclose(s.momentum(), 0.0, atol=1e-8)


def test_pythagorean_render_frames_the_dance_and_ends_with_the_ejection():
    # The default animation (physcore render pythagorean) holds the dance in its still camera
    # (its `extent` box) and ends with the ejection read: at its last frame the mass-3 body is
    # unbound from the 4-5 pair (two-body energy > 0), moving away, and out of the frame (it
    # left by the top), while the binary, recoiling the other way, is still in it (at its
    # bottom edge).
    s = pc.scenes.pythagorean()
    d = pc.scenes.pythagorean.render_defaults
    lo, hi = (np.array(c) for c in d["extent"])
    t_end = (d["frames"] - 1) * d["frame_time"]
    while s.time < 58.5 - 1e-9:
        s.step(1)
        assert np.all((s.positions >= lo) & (s.positions <= hi)), s.time  # the dance, all in view
    while s.time < t_end - 1e-9:
        s.step(1)
    x, v = s.positions, s.velocities
    xb, vb = (4 * x[1] + 5 * x[2]) / 9, (4 * v[1] + 5 * v[2]) / 9
    r = float(np.linalg.norm(x[0] - xb))
    assert 0.5 * (3 * 9 / 12) * float(np.sum((v[0] - vb) ** 2)) - 3 * 9 / r > 0  # measured +39.6
    assert float(np.dot(x[0] - xb, v[0] - vb)) > 0
    assert x[0, 1] > hi[1]  # gone by the top (y = 12.8 against 3.2)
    assert np.all((xb >= lo) & (xb <= hi)) and xb[1] < lo[1] + 1.0  # the binary at the bottom edge (-4.3)


@pytest.mark.parametrize("name", ["figure_eight", "pythagorean"])
def test_three_body_scenes_render_with_trails(tmp_path, name):
    from PIL import Image

    path = pc.render.gif(pc.scenes.REGISTRY[name](), tmp_path / "t.gif", frames=8, size=(120, 100))
    with Image.open(path) as im:
        assert im.n_frames >= 2


def test_themes_swap_the_palette_only(tmp_path):
    from PIL import Image

    def corner_and_indices(theme):
        # Hard-edged discs coloured by speed: the fixed palette's indices (soft ones, and the scene's
        # own per-body colours, are mapped to a fitted palette).
        path = pc.render.gif(pc.scenes.figure_eight(), tmp_path / f"{theme}.gif", frames=3, size=(96, 64), theme=theme,
                             antialias=False, color_by="speed")
        with Image.open(path) as im:
            idx = np.asarray(im)  # palette indices of frame 0
            return np.asarray(im.convert("RGB"))[-1, 0], idx

    (light, li), (dark, di) = corner_and_indices("light"), corner_and_indices("dark")
    assert light.min() > 240 and dark.max() < 40  # white against night blue
    assert np.array_equal(li, di)  # the same picture, drawn in other colours
    with pytest.raises(ValueError, match="theme"):
        pc.render.gif(pc.scenes.figure_eight(), tmp_path / "x.gif", frames=2, theme="neon")
