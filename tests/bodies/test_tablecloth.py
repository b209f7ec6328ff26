"""The tablecloth scene (3D rigid bodies, cloth, pins, the particle coupling together): the
weighted hem pulls the cloth off the table, the dishes are moved by the cloth under them, and
the energy books balance to rounding (the coupling books what its moves change in the springs'
and gravity's potential as well as in kinetic energy)."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc


def _drift(dt_factor: float, seconds: float, integrator: str = "verlet") -> tuple[float, pc.Scene]:
    s = pc.scenes.tablecloth(n=16, bar=0.0, dishes=False, integrator=integrator)
    s.dt = s.dt * dt_factor
    e0 = s.energy().total
    s.step(int(round(seconds / s.dt)))
    return (s.energy().total - e0) / e0, s


def test_the_weighted_hem_pulls_the_cloth_off_and_the_plate_along():
    s = pc.scenes.tablecloth()  # the default n = 24 (coarser sheets stick at the edge longer)
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
    the springs its moves change): what is left is the integrator's error where the contacts
    move the particles between steps, which shrinks with dt. Velocity Verlet, the cloth draping
    on the table for 1 s (n = 16), measured: −7.1e-3, −8.8e-4 and −1.1e-4 at 2, 1 and ½ ×
    suggest_dt (third order); RK4, the scene's default: −3.8e-6 at suggest_dt."""
    coarse, _ = _drift(1.0, 1.0)
    fine, _ = _drift(0.5, 1.0)
    assert abs(fine) < 0.25 * abs(coarse)
    assert abs(fine) < 3e-4
    rk4, _ = _drift(1.0, 1.0, "rk4")
    assert abs(rk4) < 0.1 * abs(fine)


def test_a_coupling_that_moves_particles_leaves_no_stale_force_to_verlet():
    """Dishes resting on the cloth push its particles every step (the coupling moves them and
    changes their velocities after the step). Velocity Verlet keeps the force at the step's end
    for the next step's first kick; kept across those moves, it was the force at positions the
    particles no longer had, and the books drifted by the dishes' weight: +1.25e-2 in 0.5 s
    (n = 24 at the then default dt, ½ suggest_dt), and by other amounts at other SIMD levels
    (the scene is chaotic), which made the scene's books gate pass on AVX2 only. The coupling
    now drops the cached force when it moves anything: −8e-5 (n = 24), −4.2e-5 (n = 16, here),
    the same at every level."""
    s = pc.scenes.tablecloth(n=16, bar=0.0, integrator="verlet")
    s.dt = 0.5 * s.dt
    s.step(int(round(0.5 / s.dt)))
    assert abs(s.energy_drift()) < 2e-4, f"drift {s.energy_drift():.2e}"
    assert s.energy().dissipated["bodies ⇄ particles"] > 0  # the dishes did press on the cloth


def test_without_the_bar_the_cloth_stays_on_the_table():
    s = pc.scenes.tablecloth(n=12, bar=0.0, dishes=False)
    x0 = s.positions.copy()
    s.step(int(round(1.5 / s.dt)))
    assert abs(s.positions[:, 0].mean() - x0[:, 0].mean()) < 0.05
    assert s.positions[:, 2].min() > 0.3  # hanging over the edges, not fallen


@pytest.mark.parametrize(("kwargs", "arg"), [({"size": 0.1}, "size"), ({"bar": -1.0}, "bar"), ({"bar": 1e-320}, "bar"), ({"n": 2}, "n"),
                                             ({"friction": np.nan}, "friction")])
def test_bad_arguments_are_refused_by_name(kwargs, arg):
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.scenes.tablecloth(**kwargs)
