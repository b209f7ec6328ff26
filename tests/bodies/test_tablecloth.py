"""The tablecloth scene (3D rigid bodies, cloth, pins, the particle coupling together): the
weighted hem pulls the cloth off the table, the dishes are moved by the cloth under them, and
the energy books balance to rounding (the coupling books what its moves change in the springs'
and gravity's potential as well as in kinetic energy)."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc


def _drift(dt_factor: float, seconds: float) -> tuple[float, pc.Scene]:
    s = pc.scenes.tablecloth(n=16, bar=0.0, dishes=False)
    s.dt = s.dt * dt_factor
    e0 = s.energy().total
    s.step(int(round(seconds / s.dt)))
    return (s.energy().total - e0) / e0, s


def test_the_weighted_hem_pulls_the_cloth_off_and_the_plate_along():
    s = pc.scenes.tablecloth()  # the default n = 24 (coarser sheets stick at the edge longer)
    s.dt = 2 * s.dt  # suggest_dt itself: the motion, not the books' fine print, is checked here
    plate = next(g for g in s.bodies if g.name == "plate")
    x0, p0 = s.positions.copy(), plate.positions[0].copy()
    s.step(int(round(2.5 / s.dt)))
    # The cloth went over the +x edge (the bar's side) and down.
    assert s.positions[:, 0].mean() > x0[:, 0].mean() + 0.4
    assert s.positions[:, 2].min() < 0.3
    # The plate was dragged towards the edge by the cloth under it.
    assert plate.positions[0, 0] > p0[0] + 0.05
    assert s.energy().dissipated["bodies ⇄ particles"] > 0


def test_the_books_drift_only_by_the_integrator_and_converge():
    """The coupling books every change it makes (kinetic energy, and the potential of gravity and
    the springs its moves change): what is left is velocity Verlet's error where the contacts
    move the particles between steps, which shrinks with dt (measured, the cloth draping on the
    table for 1 s, n = 16: −4.7e-3, −3.0e-4, 4.3e-5 at 2, 1 and ½ × suggest_dt)."""
    coarse, _ = _drift(2.0, 1.0)
    fine, _ = _drift(1.0, 1.0)
    assert abs(fine) < 0.25 * abs(coarse)
    assert abs(fine) < 1e-3


def test_without_the_bar_the_cloth_stays_on_the_table():
    s = pc.scenes.tablecloth(n=12, bar=0.0, dishes=False)
    x0 = s.positions.copy()
    s.step(int(round(1.5 / s.dt)))
    assert abs(s.positions[:, 0].mean() - x0[:, 0].mean()) < 0.05
    assert s.positions[:, 2].min() > 0.3  # hanging over the edges, not fallen


@pytest.mark.parametrize(("kwargs", "arg"), [({"size": 0.1}, "size"), ({"bar": -1.0}, "bar"), ({"n": 2}, "n"),
                                             ({"friction": np.nan}, "friction")])
def test_bad_arguments_are_refused_by_name(kwargs, arg):
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.scenes.tablecloth(**kwargs)
