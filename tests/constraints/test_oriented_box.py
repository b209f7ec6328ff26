"""The oriented box collider (``physcore.OrientedBox``): the collider added through the shape
layer alone (``rust_core/src/geometry/oriented_box.rs``, its registration
``rust_core/src/constraints/oriented_box.rs``, ``python/physcore/terms/oriented_box.py``, this
file).

Checked against closed forms and invariants: a ball of particles dropped on a tilted block ends
with none inside it; a bounce off a rotated face leaves along that face's normal at e times the
normal speed; save and load continue bit for bit; bad input is refused naming the argument."""
from __future__ import annotations

import io
import json
import math
import zipfile

import numpy as np
import pytest

import physcore as pc

G = 9.81


def _local(box: pc.OrientedBox, x: np.ndarray) -> np.ndarray:
    """Local coordinates (N, dim) of points x, from the box's corners (not its own axes code):
    corner 0 is (−h, …), corner 2**(dim−1−j) differs from it along axis j only."""
    c = box.corners()
    dim = box.center.shape[0]
    axes = np.array([(c[1 << (dim - 1 - j)] - c[0]) / (2.0 * box.half_extents[j]) for j in range(dim)])
    return (np.asarray(x) - box.center) @ axes.T


@pytest.mark.parametrize("dim", [2, 3])
def test_a_ball_of_particles_dropped_on_a_tilted_block_ends_outside_it(dim):
    """A ball of 200 particles joined by nothing falls onto a block tilted by 25° (2D) or about
    a skew axis by 27° (3D), with e = 0.3 and μ = 0.8 (above tan 27°, so they stay): every 0.1 s
    for 1.5 s none is inside the block (beyond round-off); at the end many rest on its surface
    and what the landings took out is booked."""
    rng = np.random.default_rng(dim)
    rot = math.radians(25.0) if dim == 2 else [0.2, -0.3, 0.3]
    box = pc.OrientedBox([0.0] * dim, [0.6, 0.2] + [0.4] * (dim - 2), rot, restitution=0.3, friction=0.8)
    d = rng.normal(size=(200, dim))
    x = d / np.linalg.norm(d, axis=1)[:, None] * 0.15 * rng.uniform(0.0, 1.0, (200, 1)) ** (1.0 / dim)
    x[:, -1] += 0.8
    s = pc.Scene(dim, integrator="semi_implicit_euler", dt=1e-3)
    s.add_particles(x, masses=np.full(200, 0.01))
    s.add(pc.Gravity([0.0] * (dim - 1) + [-G]))
    s.add(box)
    for _ in range(15):
        s.step(100)
        depth = np.min(box.half_extents - np.abs(_local(box, s.positions)), axis=1)  # > 0: inside
        assert depth.max() < 1e-12, f"t = {s.time}: {(depth > 1e-12).sum()} inside, deepest {depth.max()}"
    on = np.abs(depth) < 1e-9
    assert on.sum() > 100, f"only {on.sum()} of 200 rest on the block"
    assert s.energy().dissipated["collisions"] > 0.0


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_a_bounce_off_a_rotated_face_keeps_e_times_the_normal_speed(e):
    """Aimed straight down at the top face of a block turned by 30°, no gravity: after the
    bounce the velocity along the face's normal is e times the incoming speed along it, the
    part along the face unchanged (no friction)."""
    theta = math.radians(30.0)
    n = np.array([-math.sin(theta), math.cos(theta)])
    box = pc.OrientedBox([0.0, 0.0], [1.0, 0.5], theta, restitution=e)
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-4)
    v0 = np.array([0.0, -1.0])
    s.add_particles([n * 0.6], [v0])
    s.add(box)
    s.step(2000)
    vn0 = float(v0 @ n)
    assert float(s.velocities[0] @ n) == pytest.approx(-e * vn0, abs=1e-12)
    assert s.velocities[0] - n * float(s.velocities[0] @ n) == pytest.approx(v0 - n * vn0, abs=1e-12)
    assert float((s.positions[0] - box.center) @ n) >= 0.5 * (1 - 1e-12)


def test_save_and_load_continue_bit_for_bit(tmp_path):
    box = pc.OrientedBox([0.0, 0.0, 0.0], [0.5, 0.3, 0.2], [0.0, 0.4, 0.1], restitution=0.4, friction=0.3)
    s = pc.Scene(3, integrator="semi_implicit_euler", dt=1e-3)
    s.add_particles([[0.1, 0.0, 0.8], [-0.2, 0.1, 0.9]])
    s.add(pc.Gravity([0.0, 0.0, -G]))
    s.add(box)
    s.step(400)
    path = s.save(tmp_path / "block.npz")
    with zipfile.ZipFile(path) as z:
        meta = json.loads(str(np.load(io.BytesIO(z.read("meta.npy")), allow_pickle=False)))
    assert meta["colliders"] == [{"type": "oriented_box", "center": [0.0, 0.0, 0.0], "half_extents": [0.5, 0.3, 0.2],
                                  "rotation": [0.0, 0.4, 0.1], "restitution": 0.4, "friction": 0.3}]
    copy = pc.Scene.load(path)
    assert copy.colliders == [box] and hash(copy.colliders[0]) == hash(box)
    for c in (s, copy):
        c.step(400)
    assert np.array_equal(copy.positions, s.positions) and np.array_equal(copy.velocities, s.velocities)
    assert copy.energy().dissipated["collisions"] == s.energy().dissipated["collisions"] > 0.0


def test_a_2d_box_saves_its_angle_and_loads_back(tmp_path):
    box = pc.OrientedBox([0.0, -1.0], [2.0, 1.0], 0.3)
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.5]])
    s.add(box)
    copy = pc.Scene.load(s.save(tmp_path / "ramp.npz"))
    assert copy.colliders == [box] and copy.colliders[0].rotation.tolist() == [0.3]


@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"center": [0.0, float("nan")]}, "center"),
        ({"half_extents": [1.0, 0.0]}, "half_extents"),
        ({"half_extents": [1.0, -0.5]}, "half_extents"),
        ({"half_extents": [1.0, 0.5, 0.5]}, "half_extents"),
        ({"rotation": [0.0, 0.0, 0.3]}, "rotation"),
        ({"rotation": float("inf")}, "rotation"),
        ({"restitution": 1.5}, "restitution"),
        ({"friction": -1.0}, "friction"),
    ],
)
def test_bad_input_names_the_argument(kwargs, arg):
    args = {"center": [0.0, 0.0], "half_extents": [1.0, 0.5]} | kwargs
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.OrientedBox(**args)


def test_a_box_of_another_dimension_is_refused_before_anything_changes():
    s = pc.Scene(3)
    s.add_particles([[0.0, 0.0, 0.0]])
    with pytest.raises(pc.InvalidInputError, match="center: has 2 components"):
        s.add(pc.OrientedBox([0.0, 0.0], [1.0, 1.0]))
    assert s.colliders == []
    with pytest.raises(TypeError, match="rotation"):
        pc.OrientedBox([0.0, 0.0], [1.0, 1.0], "steep")


def test_corners_and_drawn_edges():
    """The corners of a box turned by 90° are those of the unturned box with its sides swapped;
    it is drawn as a filled rectangle (its corners in order around) in 2D, as its 12 edges in
    3D."""
    box = pc.OrientedBox([1.0, 2.0], [0.5, 0.25], math.pi / 2)
    c = box.corners()
    want = {(1.25, 1.5), (1.25, 2.5), (0.75, 1.5), (0.75, 2.5)}
    assert {tuple(np.round(p, 12)) for p in c} == want
    assert box.drawn_rods() == []
    (poly,) = box.drawn_polygons()
    assert {tuple(np.round(p, 12)) for p in poly} == want
    sides = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)  # around it, not across
    np.testing.assert_allclose(sides, [0.5, 1.0, 0.5, 1.0] if sides[0] < 0.75 else [1.0, 0.5, 1.0, 0.5], atol=1e-12)
    cube = pc.OrientedBox([0.0] * 3, [1.0] * 3)
    assert len(cube.drawn_rods()) == 12 and cube.drawn_polygons() == []


def test_a_2d_box_is_drawn_filled():
    """A 2D recording holds the box as one polygon (no rods); the frame's background fills it,
    with the edge line the sphere's disc has, and leaves the outside alone, also where a
    rectangle's corner stands out past its sides' lines. A 3D recording holds its 12 edges."""
    from physcore.render._raster import _BACKGROUND, _PLANE_FILL, _PLANE_LINE, _background, _Camera

    box = pc.OrientedBox([0.0, 0.0], [0.5, 0.2], math.radians(30))
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-3)
    s.add_particles([[0.0, 0.8]])
    s.add(box)
    rec = pc.render.record(s, frames=1, frame_time=0.01)
    assert rec.rods == () and len(rec.polygons) == 1
    cam = _Camera(2, (0.0, 0.0), (200, 200))
    cam.fit(np.array([-1.0, -1.0]), np.array([1.0, 1.0]), pad=0)  # 100 px/m, the origin centred
    img = _background(cam, [], np.zeros(2), (), (), rec.polygons)
    u, v = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))]), np.array([-0.5, math.sqrt(3) / 2])

    def at(p):
        col, row = cam.pixels(np.array([p]))
        return img[int(row[0]), int(col[0])]

    assert at(0.4 * u + 0.15 * v) == _PLANE_FILL and at(-0.4 * u - 0.15 * v) == _PLANE_FILL
    assert at(0.5 * u) == _PLANE_LINE  # on the short side's middle
    assert at(0.55 * u) == _BACKGROUND and at(0.25 * v) == _BACKGROUND and at(0.52 * u + 0.22 * v) == _BACKGROUND
    s3 = pc.Scene(3)
    s3.add_particles([[0.0, 0.0, 1.0]])
    s3.add(pc.OrientedBox([0.0] * 3, [0.5, 0.2, 0.1], [0.0, 0.0, 0.5]))
    rec3 = pc.render.record(s3, frames=1, frame_time=0.01)
    assert len(rec3.rods) == 12 and rec3.polygons == ()
