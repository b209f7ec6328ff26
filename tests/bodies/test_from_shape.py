"""Bodies.from_shape: the collider records (OrientedBox, Sphere, Capsule, Plane, Box) as rigid
bodies (parry's shapes), so one shape serves particles, grains, fluids and bodies. A ball dropped
on each comes to rest on the record's surface; rotations carry over; bad records are refused by
name."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import physcore as pc

G, R = 9.81, 0.05


def _drop_on(record, dim: int, extent: float | None = None, x0: float = 0.0) -> np.ndarray:
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", dt=1 / 240)
    g = [0.0] * dim
    g[-1] = -G
    s.add(pc.Gravity(g))
    s.add(pc.Bodies.from_shape(record, extent=extent))
    p = [0.0] * dim
    p[0], p[-1] = x0, 1.0
    ball = s.add(pc.Bodies("ball", size=R, positions=[p], restitution=0.0, friction=0.8))
    s.step(600)
    return ball.positions[0]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize(
    ("make", "top", "extent"),
    [
        (lambda d: pc.OrientedBox([0.0] * d, [0.5] * (d - 1) + [0.2], 0.0 if d == 2 else [0.0, 0.0, 0.3]), 0.2, None),
        (lambda d: pc.Capsule([-0.5] + [0.0] * (d - 1), [0.5] + [0.0] * (d - 1), 0.1), 0.1, None),
        (lambda d: pc.Sphere([0.0] * d, 0.3), 0.3, None),
        (lambda d: pc.Plane([0.0] * (d - 1) + [0.1], [0.0] * (d - 1) + [1.0]), 0.1, 2.0),
        (lambda d: pc.Box([-1.0] * d, [1.0] * (d - 1) + [2.0]), -1.0, None),
    ],
    ids=["oriented_box", "capsule", "sphere", "plane", "box_tank"],
)
def test_a_ball_rests_on_the_records_surface(make, top, extent, dim):
    """The ball's centre ends a radius above the record's top (rapier's contact softness: within
    0.1 mm), over its centre line."""
    x = _drop_on(make(dim), dim, extent)
    assert x[-1] == pytest.approx(top + R, abs=1e-4)
    assert np.abs(x[:-1]).max() < 1e-6


def test_a_tilted_plane_holds_a_ball_rolling_down_it_at_its_radius():
    """A 30° plane as a slab: a disc rolls down it, its centre a radius above the plane (within
    rapier's slop, 0.005 length units, the length unit being the disc's 0.1 m diameter: 0.5 mm),
    1 s down the slope at a = g sin θ / (1 + 1/2) (a rolling disc)."""
    theta = math.radians(30)
    n = np.array([-math.sin(theta), math.cos(theta)])
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", dt=1 / 240)
    s.add(pc.Gravity([0.0, -G]))
    s.add(pc.Bodies.from_shape(pc.Plane([0.0, 0.0], n), extent=5.0))
    ball = s.add(pc.Bodies("ball", size=R, positions=[R * n], restitution=0.0, friction=0.8))
    s.step(240)
    x = ball.positions[0]
    assert float(x @ n) == pytest.approx(R, abs=5e-4)
    assert x[0] == pytest.approx(-0.5 * G * math.sin(theta) / 1.5 * math.cos(theta), rel=0.02)


def test_rotations_and_restitution_carry_over():
    rot = np.array([0.1, 0.2, 0.3])
    b = pc.Bodies.from_shape(pc.OrientedBox([1.0, 2.0, 3.0], [0.5, 0.4, 0.2], rot, restitution=0.7, friction=0.2))
    pc.Scene(dim=3).add(b)
    assert Rotation.from_quat(b.orientations[0]).as_rotvec() == pytest.approx(rot, abs=1e-12)
    assert b.restitution == 0.7 and b.friction == 0.2 and b.kind == "fixed"
    cap = pc.Bodies.from_shape(pc.Capsule([0.0, 0.0, 0.0], [0.0, 0.0, 2.0], 0.1), kind="dynamic")
    pc.Scene(dim=3).add(cap)
    axis = Rotation.from_quat(cap.orientations[0]).apply([1.0, 0.0, 0.0])
    assert axis == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert cap.positions[0] == pytest.approx([0.0, 0.0, 1.0])
    assert cap.masses[0] == pytest.approx(1000.0 * (math.pi * 0.01 * 2.0 + 4 / 3 * math.pi * 1e-3), rel=1e-6)


@pytest.mark.parametrize(
    ("record", "kwargs", "arg", "error"),
    [
        (pc.Sphere([0.0, 0.0], 1.0, inside=True), {}, "shape", pc.InvalidInputError),
        (pc.Plane([0.0, 0.0], [0.0, 1.0]), {}, "extent", pc.InvalidInputError),
        (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": -1.0}, "extent", pc.InvalidInputError),
        (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": float("nan")}, "extent", pc.InvalidInputError),
        ("box", {}, "shape", pc.InvalidTypeError),
        (pc.Capsule([0.0, 0.0], [1.0, 0.0], 0.1), {"kind": "floating"}, "kind", pc.InvalidInputError),
    ],
)
def test_bad_records_are_refused_by_name(record, kwargs, arg, error):
    with pytest.raises(error, match=f"^{arg}"):
        pc.Bodies.from_shape(record, **kwargs)
