"""The sphere collider against closed forms, its API and scene file, and the cloth_on_ball scene.

Tolerances are the measured errors with a margin: the apex of a bounce is within 3.4e-4 of
e²·h (velocity Verlet, dt = 1e-4 s), the energy books close to 6e-14 of the energy (the
projection work of uniform gravity is booked exactly), a sliding particle stops within 1e-3 of
v0²/(2 μ g), and a projected particle lies on the surface to 1.1e-16 m (the rounding of
c + r·u).
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import physcore as pc

G = 9.81


def _ball_scene(positions, velocities=None, masses=None, *, radius=0.5, e=0.5, mu=0.0, dt=1e-4, threads=1):
    s = pc.Scene(3, integrator="verlet", dt=dt, threads=threads)
    s.add_particles(positions, velocities, masses=1.0 if masses is None else masses)
    s.add(pc.Gravity([0.0, 0.0, -G]))
    s.add(pc.Sphere([0.0, 0.0, 0.0], radius, restitution=e, friction=mu))
    return s


def test_a_particle_dropped_on_the_top_bounces_to_e_squared_of_its_height():
    e, r, h = 0.7, 0.5, 1.0
    s = _ball_scene([[0.0, 0.0, r + h]], masses=[2.0], radius=r, e=e)
    e0 = s.energy().total
    apex, prev = [], 0.0
    for _ in range(12_000):
        s.step(1)
        x, vz = s.positions[0], s.velocities[0, 2]
        assert np.linalg.norm(x) >= r * (1 - 1e-15), x
        if prev > 0 >= vz:
            apex.append(x[2] - r)
        prev = vz
    assert apex, "no bounce"
    assert abs(apex[0] - e * e * h) < 2e-3 * e * e * h, (apex[0], e * e * h)
    en = s.energy()
    # Each impact removes (1 - e²) of the kinetic energy: after the first, (1 - e²) m g h.
    assert en.dissipated["collisions"] >= (1 - e * e) * 2.0 * G * h * (1 - 1e-3)
    assert abs(en.total - e0) < 1e-12 * e0, (en.total, e0)


def test_rain_on_a_ball_ends_outside_it_and_the_books_balance():
    rng = np.random.default_rng(1)
    n, c, r = 400, np.array([0.0, 0.0, 0.3]), 0.3
    s = pc.Scene(3, integrator="verlet", dt=2e-4, threads=2)
    s.add_particles(rng.uniform([-0.4, -0.4, 0.7], [0.4, 0.4, 1.5], (n, 3)), rng.normal(0.0, 0.5, (n, 3)),
                    masses=rng.uniform(0.5, 2.0, n))
    s.add(pc.Gravity([0.0, 0.0, -G]))
    s.add(pc.Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], restitution=0.3, friction=0.2))
    s.add(pc.Sphere(c, r, restitution=0.4, friction=0.3))
    e0 = s.energy()
    worst = 0.0
    for _ in range(100):
        s.step(50)
        d = np.linalg.norm(s.positions - c, axis=1) - r
        assert d.min() >= -1e-14, d.min()
        worst = max(worst, abs(s.energy().total - e0.total))
    en = s.energy()
    # Most of the energy went into the collisions; what they took is booked to round-off.
    assert en.dissipated["collisions"] > 0.5 * e0.total
    assert worst < 1e-12 * e0.total, worst / e0.total


def test_friction_stops_a_slide_at_the_coulomb_distance():
    # A particle sliding over the top of a big ball (1 km: locally a floor) with e = 0: each
    # step's impact takes μ g dt of tangential speed, so it stops after v0²/(2 μ g).
    v0, mu, r = 2.0, 0.4, 1000.0
    s = _ball_scene([[0.0, 0.0, r]], [[v0, 0.0, 0.0]], radius=r, e=0.0, mu=mu)
    s.step(7000)  # 0.7 s; it stops at v0/(μ g) = 0.51 s
    stop = v0**2 / (2 * mu * G)
    assert abs(s.positions[0, 0] - stop) < 5e-3 * stop, (s.positions[0, 0], stop)
    assert abs(s.velocities[0, 0]) < 1e-9, "friction never reverses the slide"
    # Frictionless, the particle keeps its speed, gaining only what its drop over the curve gives.
    s = _ball_scene([[0.0, 0.0, r]], [[v0, 0.0, 0.0]], radius=r, e=0.0, mu=0.0)
    e0 = s.energy().total
    s.step(7000)
    x, v = s.positions[0], s.velocities[0]
    drop = r - x[2]
    assert abs(np.linalg.norm(v) - np.sqrt(v0**2 + 2 * G * drop)) < 1e-6, (v, drop)
    assert abs(s.energy().total - e0) < 1e-12 * e0


def test_inside_keeps_particles_in_a_bowl():
    rng = np.random.default_rng(2)
    s = pc.Scene(2, integrator="verlet", dt=1e-4, threads=1)
    s.add_particles(rng.uniform(-0.3, 0.3, (50, 2)), rng.normal(0.0, 1.0, (50, 2)))
    s.add(pc.Gravity([0.0, -G]))
    s.add(pc.Sphere([0.0, 0.0], 0.5, restitution=0.5, friction=0.1, inside=True))
    e0 = s.energy().total
    s.step(5000)
    assert np.linalg.norm(s.positions, axis=1).max() <= 0.5 * (1 + 1e-15)
    assert abs(s.energy().total - e0) < 1e-12 * abs(e0) + 1e-12


@pytest.mark.parametrize(
    "kwargs, arg, err",
    [
        (dict(center=[0.0, float("nan")], radius=1.0), "center", pc.InvalidInputError),
        (dict(center=[0.0], radius=1.0), "center", pc.InvalidInputError),
        (dict(center=["a", "b"], radius=1.0), "center", TypeError),
        (dict(center=[0.0, 0.0], radius=0.0), "radius", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius=-1.0), "radius", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius=float("inf")), "radius", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius=1e200), "radius", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius="1"), "radius", TypeError),
        (dict(center=[0.0, 0.0], radius=1.0, restitution=1.5), "restitution", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius=1.0, friction=-0.1), "friction", pc.InvalidInputError),
        (dict(center=[0.0, 0.0], radius=1.0, inside=1), "inside", TypeError),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, arg, err):
    with pytest.raises(err, match=f"^{arg}"):
        pc.Sphere(**kwargs)


def test_a_sphere_of_the_wrong_dimension_is_refused_before_anything_changes():
    s = pc.Scene(3, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0, 0.0]])
    with pytest.raises(pc.InvalidInputError, match="^center"):
        s.add(pc.Sphere([0.0, 0.0], 1.0))
    assert s.spheres == []
    stored = s.add(pc.Sphere([0.0, 0.0, -2.0], 1.0, friction=0.2))
    assert s.spheres == [stored] and stored.friction == 0.2


def _cloth(n=10):
    return pc.scenes.cloth_on_ball(n=n, threads=1)


def test_save_load_and_pickle_continue_bit_identically(tmp_path):
    a = _cloth()
    a.advance(0.4)  # on the ball: the sphere is in play
    b = pc.Scene.load(a.save(tmp_path / "cb.npz"))
    c = pickle.loads(pickle.dumps(a))
    for other in (b, c):
        assert [(sp.center.tolist(), sp.radius, sp.restitution, sp.friction, sp.inside) for sp in other.spheres] == [
            (sp.center.tolist(), sp.radius, sp.restitution, sp.friction, sp.inside) for sp in a.spheres
        ]
    for s in (a, b, c):
        s.step(500)
    for other in (b, c):
        assert np.array_equal(a.positions, other.positions)
        assert np.array_equal(a.velocities, other.velocities)
        assert a.energy().total == other.energy().total


def test_cloth_drapes_over_the_ball_and_slides_off():
    s = pc.scenes.cloth_on_ball()
    (sp,) = s.spheres
    z0 = s.positions[:, 2].mean()
    e0 = s.energy().total
    touched = np.zeros(s.n_particles, dtype=bool)
    for _ in range(24):  # 2.4 s, the default animation
        s.advance(0.1)
        d = np.linalg.norm(s.positions - sp.center, axis=1) - sp.radius
        assert d.min() >= -1e-14, d.min()
        touched |= d < 0.01 * sp.radius
    x = s.positions
    assert touched.mean() > 0.1, "the cloth lay on the ball"
    assert x[:, 2].mean() < 0.25 * z0, "the cloth ends low, on the floor"
    on = np.linalg.norm(x - sp.center, axis=1) - sp.radius < 0.01 * sp.radius
    assert on.mean() < 0.5, "most of the cloth is off the ball"
    # Off-centre, the sheet slides off the side away from the ball's centre (x < 0).
    assert x[:, 0].mean() < sp.center[0] - sp.radius
    # Dashpots, drag and collisions: the books balance to the error of the projection work,
    # first order in the springs' forces over a projection (measured 1.7e-3 of the energy).
    assert abs(s.energy().total - e0) < 5e-3 * e0, (s.energy().total - e0) / e0


def test_the_ball_is_drawn_shaded_and_hidden_by_the_cloth_in_front():
    from physcore.render._raster import _Rasteriser
    from physcore.render._recording import record

    s = _cloth(12)
    rec = record(s, frames=1, steps_per_frame=1)
    from physcore.render._mesh import _BALL, Mesh

    ball = _BALL["light"]
    mesh = Mesh.grid(12, 12)
    # Looking down: the sheet above the ball hides it; from below, the ball hides the sheet.
    for elevation, sheet_in_front in ((80.0, True), (-80.0, False)):
        ras = _Rasteriser(rec, (160, 120), "none", None, (0.0, elevation), mesh=mesh)
        img = ras.frame_rgb(0).astype(float) / 255
        hue = img / np.maximum(img.sum(axis=2, keepdims=True), 1e-9)
        # The ball's hue, lit (brighter than the labels, which share its grey-blue).
        target = np.array(ball) / sum(ball)
        lit_ball = (np.abs(hue - target).max(axis=2) < 0.02) & (img.sum(axis=2) > 1.0)
        if sheet_in_front:
            assert not lit_ball.any(), lit_ball.sum()
        else:
            assert lit_ball.mean() > 0.02, lit_ball.mean()


def test_a_3d_floor_is_drawn_under_the_mesh_with_a_shadow_under_the_ball():
    # The floor plane shows as a checked patch (two shades, not the background) in the same depth
    # pass as the cloth and ball, darker just under the ball (its contact shadow).
    from physcore.render._mesh import _FLOOR, _floor_geometry

    s = pc.scenes.cloth_on_ball(n=8)
    img = next(pc.render.frames(s, frames=1, size=(240, 180))).astype(int)
    bg = np.array([255, 255, 255])
    assert (np.abs(img - bg).sum(axis=2) > 30).mean() > 0.5  # most of the picture is floor, ball, cloth
    lo, hi = np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0])
    v, n, f, rgb = _floor_geometry([(np.zeros(3), np.array([0.0, 0.0, 1.0]))], lo, hi, "light",
                                   [(np.array([0.0, 0.0, 0.3]), 0.3)])
    assert np.all(v[:, 2] < 0) and np.allclose(n, [0.0, 0.0, 1.0]) and f.max() < len(v)
    light = np.array(_FLOOR["light"])
    near = np.linalg.norm(v[:, :2], axis=1) < 0.15
    far = np.linalg.norm(v[:, :2], axis=1) > 1.0
    assert rgb[near].sum(axis=1).max() < light.sum(axis=1).min() * 0.8  # shadowed
    assert np.allclose(np.sort(np.unique(rgb[far].round(4), axis=0).sum(axis=1)), np.sort(light.sum(axis=1)), atol=1e-3)


def test_the_scene_books_converge_with_the_step():
    # Over 3 s (the drop, the slide and the rest on the floor) the books' drift is the collider
    # projections' first-order work estimate (and the cloth's Verlet error): it shrinks with dt,
    # 3.4–4× a halving (n = 12, measured 2.7e-3, 8.0e-4, 2.0e-4 at dt, dt/2, dt/4; the default
    # n = 36: 4.9e-3, 1.6e-3, 5.1e-4).
    drifts = []
    for f in (1.0, 0.5):
        s = pc.scenes.cloth_on_ball(n=12)
        s.dt = s.dt * f
        s.step(int(round(3.0 / s.dt)))
        drifts.append(abs(s.energy_drift()))
    assert drifts[0] < 1e-2
    assert drifts[1] < 0.5 * drifts[0]
