"""The colliders' energy books: a particle resting on a collider, and one bouncing on it, keep
kinetic + potential + dissipated to the scheme's bounded error."""
from __future__ import annotations

import pytest

import physcore as pc


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "euler", "implicit_euler", "verlet"])
@pytest.mark.parametrize("collider", ["plane", "box", "sphere"])
def test_a_particle_resting_on_a_collider_keeps_its_books(integrator, collider):
    """Under gravity each step of a kick-then-drift scheme sinks a resting particle by g dt²,
    which the collider then lifts back: the scheme's own error ½dt F·(v0 − v') no longer
    telescopes, since the collider resets v every step. The colliders book their share of it
    (`projection_kick`): before, the collisions book fell by ½ m g² dt² a step without bound
    (semi-implicit Euler: energy_drift -1.0 after 1 s at dt = 1e-3; explicit Euler +1.0)."""
    s = pc.Scene(dim=2, integrator=integrator, dt=1e-3)
    s.add_particles([[0.3, 0.0]], masses=2.0)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add({"plane": lambda: pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.5, friction=0.3),
           "box": lambda: pc.Box([-1.0, 0.0], [1.0, 2.0], restitution=0.5, friction=0.3),
           "sphere": lambda: pc.Sphere([0.3, 1.0], 1.0, inside=True, restitution=0.5, friction=0.3)}[collider]())
    unit = 2.0 * 9.81**2 * 1e-3**2  # m g² dt²: the size of one step's error
    s.step(1000)
    t1 = s.energy().total
    s.step(1000)
    rep = s.energy()
    assert abs(s.positions[0, 1]) < 1e-4  # still resting
    # It started at rest on y = 0 (total 0): the books hold the scheme's bounded error, and do
    # not drift (before: -500 units per 1000 steps).
    assert abs(rep.total) < 5.0 * unit, (rep.total / unit, rep.dissipated)
    assert abs(rep.total - t1) < 1e-6 * unit, (rep.total - t1) / unit


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "euler"])
def test_a_ball_bouncing_on_a_plane_keeps_its_books_to_the_schemes_bounded_error(integrator):
    # Dropped from 0.5 m, e = 0.8, 3 s of bounces and then rest: the books' residual is the
    # scheme's bounded ½dt F·(v0 − v_N), not a drift (before: -1.8 % for semi-implicit Euler).
    s = pc.Scene(dim=2, integrator=integrator, dt=1e-3)
    s.add_particles([[0.0, 0.5]], masses=1.0)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.8))
    e0 = s.energy().total
    s.step(3000)
    rep = s.energy()
    assert rep.dissipated["collisions"] > 0.5 * e0  # most of it went into the bounces
    bound = 0.5 * 1e-3 * 9.81 * (abs(s.velocities[0, 1]) + 0.0) + 1e-12
    assert abs(rep.total - e0) <= bound + 1e-9, (rep.total - e0, bound)
