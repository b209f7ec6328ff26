"""The capsule collider (``physcore.Capsule``): the part added to show that a new kind of part
touches its own files only (``rust_core/src/constraints/capsule.rs`` and its ``mod`` line,
``python/physcore/terms/capsule.py`` and three lines of the package's ``__init__``, this file).

Checked against closed forms: a particle resting on the rod sits at its radius from the axis;
a bounce off the side and off the cap leaves along the surface normal at e times the normal
speed; the energy books hold the restitution's loss; save, load and pickle continue bit for
bit; a scene without a capsule writes no ``colliders`` section."""
from __future__ import annotations

import io
import json
import math
import pickle
import zipfile

import numpy as np
import pytest

import physcore as pc

G = 9.81


def _meta(path) -> dict:
    with zipfile.ZipFile(path) as z:
        return json.loads(str(np.load(io.BytesIO(z.read("meta.npy")), allow_pickle=False)))


def _drop(x0, v0, capsule, dim=3, dt=1e-4):
    s = pc.Scene(dim, integrator="semi_implicit_euler", dt=dt)
    s.add_particles([x0], [v0], masses=[0.2])
    s.add(capsule)
    return s


@pytest.mark.parametrize("dim", [2, 3])
def test_a_particle_comes_to_rest_on_top_of_the_rod(dim):
    """Dropped onto a horizontal rod with e = 0, a particle ends at rest a radius above the
    axis (up to the one step of gravity a projection leaves, g dt²)."""
    z = [0.0] * (dim - 1)
    rod = pc.Capsule([-0.5, *z[:-1], 0.3] if dim == 3 else [-0.5, 0.3], [0.5, *z[:-1], 0.3] if dim == 3 else [0.5, 0.3],
                     0.05, restitution=0.0)
    s = _drop([0.1, *z[:-1], 0.6] if dim == 3 else [0.1, 0.6], [0.0] * dim, rod, dim)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-G]))
    s.step(6000)
    assert abs(s.positions[0, -1] - 0.35) <= G * s.dt**2
    assert abs(s.positions[0, 0] - 0.1) < 1e-12
    assert np.linalg.norm(s.velocities[0]) <= G * s.dt


@pytest.mark.parametrize("e", [0.0, 0.4, 1.0])
def test_a_bounce_off_the_side_and_off_the_cap_keeps_e_times_the_normal_speed(e):
    """Aimed at the side (normal −x) and at an end cap (a normal at 45° in the x–z plane), with
    no gravity: after the bounce the normal speed is e times the incoming one, the tangential
    part unchanged (no friction), and the particle sits on the surface."""
    rod = pc.Capsule([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.1, restitution=e)
    # The side: moving +x into the rod's side at z = 0.5, with a tangential speed along z.
    s = _drop([-0.15, 0.0, 0.5], [2.0, 0.0, 0.3], rod)
    s.step(500)
    assert s.velocities[0] == pytest.approx([-2.0 * e, 0.0, 0.3], abs=1e-12)
    assert math.hypot(s.positions[0, 0], s.positions[0, 1]) >= 0.1 * (1 - 1e-12)
    # The cap above b: moving down along the 45° line through b.
    n = np.array([1.0, 0.0, 1.0]) / math.sqrt(2)
    start = np.array([0.0, 0.0, 1.0]) + n * 0.2
    s = _drop(start, -n * 1.0, rod)
    s.step(2000)
    assert s.velocities[0] == pytest.approx(n * e, abs=1e-12)
    if e > 0:
        assert np.linalg.norm(s.positions[0] - [0.0, 0.0, 1.0]) > 0.1


def test_the_energy_books_hold_the_collisions():
    """A particle bouncing on the rod under gravity (e = 0.6, μ = 0.2): what the bounces take out
    is booked under "collisions", and the books' total stays put (semi-implicit Euler's error
    only: drift below 1e-3 of the initial energy)."""
    rod = pc.Capsule([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.1, restitution=0.6, friction=0.2)
    s = _drop([0.03, 0.02, 0.5], [0.2, 0.0, 0.0], rod, dt=2e-5)
    s.add(pc.Gravity([0.0, 0.0, -G]))
    for _ in range(10):
        s.step(2000)
    e = s.energy()
    assert e.dissipated["collisions"] > 0.2 * 0.2 * G * 0.3  # most of the drop's 0.4 m taken out
    assert abs(s.energy_drift()) < 1e-3, s.energy_drift()


def test_save_load_and_pickle_continue_bit_for_bit(tmp_path):
    rod = pc.Capsule([-1.0, 0.0], [1.0, 0.2], 0.1, restitution=0.5, friction=0.1)
    s = _drop([0.0, 0.5], [0.3, 0.0], rod, dim=2, dt=1e-3)
    s.add(pc.Gravity([0.0, -G]))
    s.step(300)
    path = s.save(tmp_path / "rod.npz")
    meta = _meta(path)
    assert meta["colliders"] == [
        {"type": "capsule", "a": [-1.0, 0.0], "b": [1.0, 0.2], "radius": 0.1, "restitution": 0.5, "friction": 0.1}
    ]
    copies = [pc.Scene.load(path), pickle.loads(pickle.dumps(s))]
    assert all(c.colliders == [rod] for c in copies) and hash(copies[0].colliders[0]) == hash(rod)
    for c in (s, *copies):
        c.step(300)
    for c in copies:
        assert np.array_equal(c.positions, s.positions) and np.array_equal(c.velocities, s.velocities)
        assert c.energy().dissipated["collisions"] == s.energy().dissipated["collisions"]


def test_a_scene_without_a_capsule_writes_no_colliders_section(tmp_path):
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.0]])
    s.add(pc.Sphere([0.0, -1.0], 0.5))
    assert "colliders" not in _meta(s.save(tmp_path / "plain.npz"))


@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"a": [0.0, float("nan")]}, "a"),
        ({"a": [0.0, 0.0, 0.0]}, "b"),
        ({"b": [1e200, 1e200]}, "b"),
        ({"radius": 0.0}, "radius"),
        ({"radius": 1e200}, "radius"),
        ({"restitution": 1.5}, "restitution"),
        ({"friction": -1.0}, "friction"),
    ],
)
def test_bad_input_names_the_argument(kwargs, arg):
    args = {"a": [0.0, 0.0], "b": [1.0, 0.0], "radius": 0.1} | kwargs
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.Capsule(**args)


def test_a_capsule_of_another_dimension_is_refused_before_anything_changes():
    s = pc.Scene(3)
    s.add_particles([[0.0, 0.0, 0.0]])
    with pytest.raises(pc.InvalidInputError, match="a: has 2 components"):
        s.add(pc.Capsule([0.0, 0.0], [1.0, 0.0], 0.1))
    assert s.colliders == []
    with pytest.raises(TypeError, match="radius"):
        pc.Capsule([0.0, 0.0], [1.0, 0.0], "wide")


def test_a_file_with_an_unknown_or_broken_collider_is_refused_naming_the_field(tmp_path):
    s = _drop([0.0, 0.5], [0.0, 0.0], pc.Capsule([-1.0, 0.0], [1.0, 0.0], 0.1), dim=2)
    path = s.save(tmp_path / "ok.npz")

    def edited(edit, name):
        dst = tmp_path / name
        with zipfile.ZipFile(path) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_STORED) as zout:
            for info in zin.infolist():
                data = zin.read(info.filename)
                if info.filename == "meta.npy":
                    meta = json.loads(str(np.load(io.BytesIO(data), allow_pickle=False)))
                    edit(meta)
                    buf = io.BytesIO()
                    np.save(buf, np.array(json.dumps(meta)))
                    data = buf.getvalue()
                zout.writestr(info, data)
        return dst

    with pytest.raises(pc.SceneFileError, match=r"meta\.colliders\[0\]\.type.*unknown collider type 'cone'"):
        pc.Scene.load(edited(lambda m: m["colliders"][0].update(type="cone"), "cone.npz"))
    with pytest.raises(pc.SceneFileError, match=r"meta\.colliders\[0\]\.radius"):
        pc.Scene.load(edited(lambda m: m["colliders"][0].pop("radius"), "noradius.npz"))
    with pytest.raises(pc.SceneFileError, match=r"meta\.colliders\[0\]"):
        pc.Scene.load(edited(lambda m: m["colliders"][0].update(radius=-1.0), "negative.npz"))


def test_a_capsule_is_drawn():
    """The render draws what ``drawn_rods()`` gives, the capsule itself: in a 2D frame the pixels
    on its axis are the colliders' fill, those a radius and more away are not; a 3D recording
    holds the rod for the shaded surface's depth pass."""
    from physcore.render._raster import _PLANE_FILL, _background, _Camera

    rod = pc.Capsule([-0.5, 0.0], [0.5, 0.0], 0.1)
    assert [tuple(map(np.ndarray.tolist, r[:2])) + (r[2],) for r in rod.drawn_rods()] == [([-0.5, 0.0], [0.5, 0.0], 0.1)]
    s = _drop([0.0, 0.5], [0.0, 0.0], rod, dim=2)
    rec = pc.render.record(s, frames=1, frame_time=0.01)
    assert len(rec.rods) == 1 and rec.spheres == ()
    cam = _Camera(2, (0.0, 0.0), (200, 200))
    cam.fit(np.array([-1.0, -1.0]), np.array([1.0, 1.0]), pad=0)  # 100 px/m, the origin centred
    img = _background(cam, [], np.zeros(2), (), rec.rods)

    def at(x, y):
        col, row = cam.pixels(np.array([[x, y]]))
        return img[int(row[0]), int(col[0])]

    assert at(0.0, 0.0) == _PLANE_FILL and at(0.55, 0.0) == _PLANE_FILL  # on the axis, in a cap
    assert at(0.0, 0.15) != _PLANE_FILL and at(0.65, 0.0) != _PLANE_FILL
