"""Walls of every shape for the grains (physcore.Contacts(walls=...)): a bowl, a ball, a capsule
and an oriented box as well as planes, through the geometry layer's closest surface point.
A grain at rest on (or in) each one, restitution off the curved and the turned ones, rolling on
a tilted block, save/load and thread counts bit for bit, and bad walls refused by name. Every
expected value comes from mechanics, not from a stored run."""
from __future__ import annotations

import dataclasses
import io
import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

import physcore as pc

G = 9.81
M, R, K = 0.01, 0.01, 1e4  # a grain's mass (kg), radius (m); the linear stiffness (N/m)
OVERLAP = M * G / K  # the linear law's overlap at rest under gravity, m


def _grain(dim: int, x, v=None, *, walls, gravity: bool = True, e: float = 0.5, friction: float = 0.5,
           drag: float = 0.0, threads: int = 1) -> pc.Scene:
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", threads=threads)
    x = np.atleast_2d(np.asarray(x, dtype=float))
    s.add_particles(x, None if v is None else np.atleast_2d(np.asarray(v, dtype=float)), masses=M)
    s.set_attribute("radius", np.full(len(x), R))
    if gravity:
        s.add(pc.Gravity([0.0] * (dim - 1) + [-G]))
    if drag:
        s.add(pc.Drag(drag))
    s.add(pc.Contacts(stiffness=K, restitution=e, friction=friction, walls=walls))
    s.dt = s.suggest_dt()
    return s


def _settle(s: pc.Scene, seconds: float) -> None:
    """Run `seconds` at the automatic step, then a little at a tenth of it: the overlap at rest
    is m g/k (1 + hγ), hγ the dashpot's share of a step (ζπ/50 at the automatic step, about
    1 %; a tenth of it at a tenth of the step), so the depth can be held to m g/k within 0.5 %."""
    s.advance(seconds)
    s.dt = s.suggest_dt() / 10.0
    s.step(int(0.05 / s.dt))


def _up(dim: int) -> np.ndarray:
    u = np.zeros(dim)
    u[-1] = 1.0
    return u


# ------------------------------------------------------------------------------ at rest
@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_settles_at_the_bottom_of_a_bowl(dim):
    # Released off centre, halfway up a bowl of radius 0.1 m, it rolls to and fro (drag takes
    # its energy: near critical) and comes to rest at the bottom, its centre r - m g/k above it.
    bowl_r = 0.1
    centre = _up(dim) * bowl_r
    start = centre + (np.eye(dim)[0] * math.sin(0.5) - _up(dim) * math.cos(0.5)) * (bowl_r - R)
    s = _grain(dim, start, walls=pc.Sphere(centre, bowl_r, inside=True, restitution=0.5, friction=0.5), drag=0.2)
    _settle(s, 4.0)
    x = s.positions[0]
    assert np.abs(x[:-1]).max() < 1e-5, f"not at the bottom: {x}"
    depth = R - x[-1]
    assert abs(depth - OVERLAP) < 5e-3 * OVERLAP, f"overlap {depth} m, want m g/k = {OVERLAP} m"
    assert s.contact_count() == 1
    assert np.abs(s.velocities).max() < 1e-6


def _obstacles(dim: int) -> dict[str, tuple[object, float, np.ndarray]]:
    """Obstacles whose top is at height 0.1 m right under the point (0.02, ..., top): each
    (wall, top, x of the drop)."""
    top = 0.1
    over = np.zeros(dim)
    over[0] = 0.02
    over[-1] = top
    c = over.copy()
    ball = pc.Sphere(c - _up(dim) * 0.05, 0.05, restitution=0.3, friction=0.5)
    # A rod along the first axis, its axis 0.02 below the top.
    a, b = c - _up(dim) * 0.02, c - _up(dim) * 0.02
    a[0], b[0] = -0.1, 0.1
    rod = pc.Capsule(a, b, 0.02, restitution=0.3, friction=0.5)
    # A block turned so that one face is level: a quarter turn about the vertical in 3D, in 2D
    # a quarter turn with its half extents swapped (its local x is then vertical).
    if dim == 2:
        block = pc.OrientedBox(c - _up(dim) * 0.03, [0.03, 0.2], math.pi / 2, restitution=0.3, friction=0.5)
    else:
        block = pc.OrientedBox(c - _up(dim) * 0.03, [0.2, 0.1, 0.03], [0.0, 0.0, math.pi / 2], restitution=0.3, friction=0.5)
    return {"ball": (ball, top, over), "capsule": (rod, top, over), "oriented box": (block, top, over)}


@pytest.mark.parametrize("shape", ["ball", "capsule", "oriented box"])
@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_dropped_on_an_obstacle_rests_on_its_top(dim, shape):
    # Dropped 5 mm onto the obstacle straight above its top, it bounces, settles and rests
    # there: centre at top + r - m g/k.
    wall, top, over = _obstacles(dim)[shape]
    s = _grain(dim, over + _up(dim) * (R + 0.005), walls=[wall])
    _settle(s, 1.0)
    x = s.positions[0]
    assert np.abs(x[:-1] - over[:-1]).max() < 1e-9, f"{shape}: moved sideways to {x}"
    height = top + R - OVERLAP
    assert abs(x[-1] - height) < 5e-3 * OVERLAP, f"{shape}: rests at {x[-1]} m, want {height} m"
    assert s.contact_count() == 1


# ------------------------------------------------------------------------------ restitution
def _restitution_cases(dim: int) -> dict[str, tuple[object, np.ndarray, np.ndarray]]:
    """(wall, start, unit normal of the surface where the grain hits it): each grain starts 5 mm
    off the surface and moves straight at it."""
    rng = np.random.default_rng(1)
    if dim == 2:
        ob_rot, capsule_axis = 0.5, np.array([math.cos(0.3), math.sin(0.3)])
    else:
        ob_rot = np.array([0.3, -0.4, 0.5])
        capsule_axis = rng.normal(size=3)
        capsule_axis /= np.linalg.norm(capsule_axis)
    out = {}
    # The capsule's side: the normal perpendicular to its axis.
    n = np.zeros(dim)
    n[1] = 1.0
    n -= n.dot(capsule_axis) * capsule_axis
    n /= np.linalg.norm(n)
    cap = pc.Capsule(-0.2 * capsule_axis, 0.2 * capsule_axis, 0.03, restitution=0.6, friction=0.3)
    out["capsule side"] = (cap, 0.05 * capsule_axis + n * (0.03 + R + 0.005), n)
    # Its cap, hit along the axis.
    out["capsule end"] = (cap, capsule_axis * (0.2 + 0.03 + R + 0.005), capsule_axis)
    # A turned block's face, along that face's normal (its local y axis).
    block = pc.OrientedBox(np.zeros(dim), [0.1, 0.05, 0.08][:dim], ob_rot, restitution=0.6, friction=0.3)
    u = _axes(block)[1]
    out["oriented box face"] = (block, u * (0.05 + R + 0.005), u)
    return out


def _axes(block: pc.OrientedBox) -> np.ndarray:
    """The block's local axes as rows, from two of its corners' differences."""
    c = block.corners()
    dim = c.shape[1]
    rows = [c[1 << (dim - 1 - j)] - c[0] for j in range(dim)]
    return np.array([r / np.linalg.norm(r) for r in rows])


@pytest.mark.parametrize("case", ["capsule side", "capsule end", "oriented box face"])
@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_bounces_off_a_capsule_and_an_oriented_box_with_their_restitution(dim, case):
    # No gravity, a head-on impact at 1 m/s: the rebound speed over the impact speed is the
    # wall's restitution (0.6, not the grains' 0.5) within 2 %, and the grain leaves along the
    # normal it came in on.
    wall, start, n = _restitution_cases(dim)[case]
    s = _grain(dim, start, -n, walls=[wall], gravity=False, e=0.5)
    s.advance(0.05)
    assert s.contact_count() == 0
    v = s.velocities[0]
    assert abs(v.dot(n) - 0.6) < 0.02 * 0.6, f"{case}: rebound {v.dot(n)} m/s from 1 m/s"
    assert np.linalg.norm(v - v.dot(n) * n) < 1e-9, f"{case}: tangential speed {v}"


# ------------------------------------------------------------------------------ rolling
@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_rolls_down_a_tilted_oriented_box(dim):
    # A block tilted 20° (about z in 2D, about y in 3D); a grain set on its top face rolls down
    # without slipping (μ = 0.5 > tan 20°·β/(1 + β)): the contact point at rest, ω a = v with
    # the lever a = r - δ/2, and the acceleration g sin θ/(1 + β) (β = ½ a disc, ⅖ a sphere).
    theta = math.radians(20.0)
    rotation = theta if dim == 2 else [0.0, -theta, 0.0]
    block = pc.OrientedBox(np.zeros(dim), [0.5, 0.1, 0.3][:dim] if dim == 3 else [0.5, 0.1],
                           rotation, restitution=0.3, friction=0.5)
    if dim == 3:
        block = pc.OrientedBox(np.zeros(3), [0.5, 0.3, 0.1], rotation, restitution=0.3, friction=0.5)
    axes = _axes(block)
    down_slope, normal = -axes[0], axes[-1]
    assert normal[-1] > 0.9 and down_slope[-1] < 0.0
    half_normal = 0.1
    start = normal * (half_normal + R - OVERLAP * math.cos(theta))
    s = _grain(dim, start, walls=[block], friction=0.5)
    t = 0.3
    s.advance(t)
    v = s.velocities[0]
    beta = 0.5 if dim == 2 else 0.4
    speed = v.dot(down_slope)
    assert abs(speed - G * math.sin(theta) / (1 + beta) * t) < 0.01 * speed, f"speed {speed} m/s"
    assert abs(v.dot(normal)) < 1e-3 * speed, "left the face"
    lever = R - 0.5 * OVERLAP * math.cos(theta)
    if dim == 2:
        omega = np.array([0.0, 0.0, s.particle_field("angular_velocity")[0]])
    else:
        omega = np.array([s.particle_field(f"angular_velocity_{c}")[0] for c in "xyz"])
    n3 = np.append(normal, 0.0) if dim == 2 else normal
    v3 = np.append(v, 0.0) if dim == 2 else v
    contact_velocity = v3 + np.cross(omega, -n3 * lever)
    assert np.linalg.norm(omega) * lever == pytest.approx(speed, rel=0.01)
    assert np.linalg.norm(contact_velocity) < 0.01 * speed, f"slipping at {contact_velocity} m/s"


# ------------------------------------------------------------------------------ files, threads
def _every_shape(dim: int, n: int, threads: int = 1, rolling: float = 0.0) -> pc.Scene:
    """`n` grains placed at random, none overlapping, in a bowl of radius 0.1 m that holds a ball,
    a capsule, a turned block, a box's faces and a tilted plane (walls 0-3: bowl, ball, capsule,
    block), moving at random under gravity; radii about a tenth of the room (2D: area, 3D:
    volume) over `n`."""
    rng = np.random.default_rng(5)
    up, ex = _up(dim), np.eye(dim)[0]
    c = up * 0.1
    ball_c, ball_r = c - up * 0.06 + ex * 0.03, 0.015
    cap_a, cap_b, cap_r = c - up * 0.03 - ex * 0.06, c - up * 0.02, 0.008
    ob_c, ob_h = c - up * 0.03 + ex * 0.06, 0.012
    lower, upper = -0.09 * (1 - up) + up * 0.005, 0.09 * (1 - up) + up * 0.2
    p0, pn = c - up * 0.085, (ex * 0.1 + up) / math.hypot(0.1, 1.0)
    walls = [
        pc.Sphere(c, 0.1, inside=True, restitution=0.4, friction=0.6),
        pc.Sphere(ball_c, ball_r, restitution=0.7, friction=0.2),
        pc.Capsule(cap_a, cap_b, cap_r, restitution=0.5, friction=0.4),
        pc.OrientedBox(ob_c, [ob_h] * dim, 0.3 if dim == 2 else [0.1, 0.2, 0.3], restitution=0.3, friction=0.5),
        pc.Box(lower, upper, restitution=0.5, friction=0.5),
        pc.Plane(p0, pn, restitution=0.6, friction=0.3),
    ]
    ob_axes = _axes(walls[3])
    r0 = 0.1 * (0.1 / n) ** (1.0 / dim)
    x, r = np.zeros((n, dim)), rng.uniform(0.8 * r0, 1.2 * r0, n)
    k = 0
    while k < n:
        y, rk = c + rng.uniform(-0.1, 0.1, dim), r[k]
        t = np.clip((y - cap_a).dot(cap_b - cap_a) / (cap_b - cap_a).dot(cap_b - cap_a), 0.0, 1.0)
        clear = (np.linalg.norm(y - c) < 0.1 - rk and np.linalg.norm(y - ball_c) > ball_r + rk
                 and np.linalg.norm(y - cap_a - t * (cap_b - cap_a)) > cap_r + rk
                 and np.linalg.norm(np.maximum(np.abs(ob_axes @ (y - ob_c)) - ob_h, 0.0)) > rk
                 and np.all(y > lower + rk) and np.all(y < upper - rk) and (y - p0).dot(pn) > rk
                 and np.all(np.linalg.norm(x[:k] - y, axis=1) > r[:k] + rk))
        if clear:
            x[k] = y
            k += 1
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", threads=threads)
    s.add_particles(x, rng.normal(0.0, 0.3, (n, dim)), masses=rng.uniform(1e-4, 2e-4, n))
    s.set_attribute("radius", r)
    s.add(pc.Gravity(-G * up))
    s.add(pc.Contacts(stiffness=2e3, restitution=0.5, friction=0.5, rolling_friction=rolling, walls=walls))
    s.dt = s.suggest_dt()
    return s


def _walls_in_contact(s: pc.Scene) -> set[int]:
    """The walls some grain touches now, from the contact term's history (a contact's partner
    n + w is wall w)."""
    h = s.state()["term1_history"]
    n, a = int(h[0]), 1 if s.dim == 2 else 3
    width = 3 + s.dim + (a + 1 if s.terms[1].rolling_friction > 0 else 0)
    records = h[1 + n * (a + 1) + 2 :].reshape(-1, width)
    return {int(j) - n for j in records[:, 1] if j >= n}


def _state(s: pc.Scene) -> list[np.ndarray]:
    spin = ("angular_velocity", "angle") if s.dim == 2 else tuple(f"angular_velocity_{c}" for c in "xyz")
    return [s.positions.copy(), s.velocities.copy(), *(s.particle_field(f).copy() for f in spin),
            np.array(list(s.energy().dissipated.values()))]


def _same_walls(a: tuple, b: tuple) -> bool:
    """Wall records equal field by field, arrays bit for bit (a Plane's dataclass == cannot
    compare its arrays)."""
    def same(x, y) -> bool:
        if isinstance(x, np.ndarray):
            return isinstance(y, np.ndarray) and x.shape == y.shape and np.array_equal(x.view(np.uint64), y.view(np.uint64))
        return type(x) is type(y) and x == y
    return len(a) == len(b) and all(
        type(u) is type(w) and all(same(getattr(u, f.name), getattr(w, f.name)) for f in dataclasses.fields(u)) for u, w in zip(a, b, strict=True))


def _same_bits(a: list[np.ndarray], b: list[np.ndarray]) -> bool:
    return all(x.shape == y.shape and np.array_equal(x.view(np.uint64), y.view(np.uint64)) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("rolling", [0.0, 0.2])
@pytest.mark.parametrize("dim", [2, 3])
def test_save_and_load_carry_every_wall_shape_bit_for_bit(tmp_path, dim, rolling):
    s = _every_shape(dim, 300, rolling=rolling)
    touched: set[int] = set()
    for _ in range(40):
        s.step(500)
        touched |= _walls_in_contact(s)
    term = s.terms[-1]
    assert {0, 1, 2, 3} <= touched, f"only walls {touched} touched: the test would prove less than it says"
    assert _walls_in_contact(s) & {0, 1, 2, 3}, "no spring on a curved wall to carry through the file"
    path = s.save(tmp_path / "shapes.npz")
    loaded = pc.Scene.load(path)
    assert _same_walls(loaded.terms[-1].walls, term.walls)  # each record by value: shapes, coefficients
    assert [type(w).__name__ for w in term.walls] == ["Sphere", "Sphere", "Capsule", "OrientedBox"] + ["Plane"] * (2 * dim + 1)
    assert _same_bits(_state(loaded), _state(s))
    s.step(1000)
    loaded.step(1000)
    assert _same_bits(_state(loaded), _state(s)), "the runs parted after the load"
    # The walls are records in the file's meta: every float as it was.
    meta = _meta(path)
    rec = meta["terms"][-1]
    assert [w["type"] for w in rec["walls"]][:4] == ["sphere", "sphere", "capsule", "oriented_box"]
    assert rec["walls"][3]["rotation"] == np.atleast_1d(term.walls[3].rotation).tolist()


def test_a_file_with_plane_walls_only_is_written_as_before(tmp_path):
    # Planes (and boxes, their faces) alone: no "walls" records, the wall_* arrays hold them, as
    # files of physcore before the other shapes did (which therefore load as they always did).
    s = _grain(2, [0.1, 0.05], walls=[pc.Box([0.0, 0.0], [0.3, 0.3], restitution=0.5, friction=0.5)])
    s.step(10)
    path = s.save(tmp_path / "planes.npz")
    rec = _meta(path)["terms"][-1]
    assert "walls" not in rec
    with np.load(path) as z:
        assert z["term1_wall_points"].shape == (4, 2) and z["term1_wall_normals"].shape == (4, 2)
    loaded = pc.Scene.load(path)
    assert _same_walls(loaded.terms[-1].walls, s.terms[-1].walls)
    s.step(200)
    loaded.step(200)
    assert _same_bits(_state(loaded), _state(s))


@pytest.mark.parametrize("dim", [2, 3])
def test_one_and_two_threads_give_the_same_bits(dim):
    # Enough grains for the passes to split across threads (4096 and more).
    runs = []
    for threads in (1, 2):
        s = _every_shape(dim, 5000, threads=threads, rolling=0.2)
        touched: set[int] = set()
        for _ in range(10):
            s.step(20)
            touched |= _walls_in_contact(s)
        assert {0, 1, 2, 3} <= touched, f"only walls {touched} touched"
        runs.append(_state(s))
    assert _same_bits(runs[0], runs[1])


# ------------------------------------------------------------------------------ bad input
def test_walls_of_the_wrong_dimension_are_refused_before_anything_changes():
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=1)
    s.add_particles([[0.0, 0.0]])
    s.set_attribute("radius", [0.01])
    for wall in (pc.Sphere([0, 0, 0], 1.0), pc.Capsule([0, 0, 0], [1, 0, 0], 0.1), pc.OrientedBox([0, 0, 0], [1, 1, 1])):
        with pytest.raises(pc.PhyscoreError, match=r"^walls: wall 1 \(.*\) has 3 components, the scene is 2D"):
            s.add(pc.Contacts(stiffness=1.0, walls=[pc.Plane([0, 0], [0, 1]), wall]))
        assert s.terms == ()
    with pytest.raises(TypeError, match="^walls: entry 0 is a Drag"):
        pc.Contacts(stiffness=1.0, walls=[pc.Drag(1.0)])
    with pytest.raises(ValueError, match="^walls"):
        pc.Contacts(stiffness=1.0, walls=pc.Capsule([0, 0], [1, 0], 0.1, restitution=0.0))


def test_non_finite_geometry_is_refused_by_the_core_naming_the_wall():
    # The records refuse NaN themselves; one forced past them (a frozen record overwritten) is
    # refused by the core, naming walls, and the scene is left as it was.
    ball = pc.Sphere([0.0, 0.0], 1.0)
    object.__setattr__(ball, "radius", float("nan"))
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=1)
    s.add_particles([[0.0, 2.0]])
    s.set_attribute("radius", [0.01])
    with pytest.raises(pc.PhyscoreError, match=r"^walls: wall 0 \(sphere\)"):
        s.add(pc.Contacts(stiffness=1.0, walls=ball))
    assert s.terms == ()


def _meta(path: Path) -> dict:
    with zipfile.ZipFile(path) as zf:
        return json.loads(str(np.lib.format.read_array(io.BytesIO(zf.read("meta.npy")))))


def _with_meta(path: Path, out: Path, edit) -> Path:
    meta = _meta(path)
    edit(meta)
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array(json.dumps(meta)))
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            dst.writestr(info, buf.getvalue() if info.filename == "meta.npy" else src.read(info))
    return out


def _set(k: int, key: str, value):
    def edit(meta):
        meta["terms"][-1]["walls"][k][key] = value
    return edit


@pytest.mark.parametrize(
    "edit, message",
    [
        (_set(1, "radius", float("nan")), r"wall 1 \(sphere\): radius: must be finite"),
        (_set(1, "center", [0.0, float("inf")]), r"wall 1 \(sphere\): center: must be finite"),
        (_set(1, "center", [0.1, 0.2, 0.3]), r"wall 1 \(sphere\) has 3 components, the scene is 2D"),
        (_set(2, "a", [0.0, 0.0, 0.0]), r"wall 2 \(capsule\): b: has 2 components, a has 3"),
        (_set(3, "rotation", [0.1, 0.2, 0.3]), r"wall 3 \(oriented_box\): rotation"),
        (_set(3, "half_extents", [0.1, -0.2]), r"wall 3 \(oriented_box\): half_extents: must be > 0"),
        (_set(0, "inside", 1), r"wall 0 \(sphere\): inside"),
        (_set(0, "radius", "1"), r"wall 0 \(sphere\): radius"),
        (_set(0, "type", "cone"), r"wall 0 has type 'cone'"),
        (_set(0, "colour", "red"), r"wall 0 \(sphere\) has keys"),
        (_set(4, "restitution", 0.0), r"wall 4 \(plane\) has restitution 0.0"),
        (lambda meta: meta["terms"][-1]["walls"].__setitem__(0, [1.0]), r"wall 0 must be an object"),
    ],
)
def test_hostile_wall_records_in_a_file_are_refused_naming_walls(tmp_path, edit, message):
    s = _every_shape(2, 20)
    s.step(5)
    path = s.save(tmp_path / "ok.npz")
    bad = _with_meta(path, tmp_path / "bad.npz", edit)
    with pytest.raises(pc.SceneFileError, match=rf"meta\.terms\[1\]\.walls: {message}"):
        pc.Scene.load(bad)


def test_a_file_with_both_records_and_plane_arrays_is_refused(tmp_path):
    s = _every_shape(2, 20)
    path = s.save(tmp_path / "ok.npz")
    planes = _grain(2, [0.1, 0.05], walls=[pc.Plane([0.0, 0.0], [0.0, 1.0])]).save(tmp_path / "planes.npz")
    with zipfile.ZipFile(planes) as p:
        arrays = {n: p.read(n) for n in p.namelist() if n.startswith("term1_wall_")}
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(tmp_path / "both.npz", "w") as dst:
        for info in src.infolist():
            dst.writestr(info, arrays.get(info.filename, src.read(info)))
    with pytest.raises(pc.SceneFileError, match="walls"):
        pc.Scene.load(tmp_path / "both.npz")


def test_a_recording_draws_the_walls_as_their_colliders(tmp_path):
    # A ball wall is drawn as a sphere collider is, a capsule as its rod, a 2D block as its filled
    # rectangle (as an OrientedBox collider), a plane as a plane: the recording holds them (and a
    # GIF of it renders).
    walls = [pc.Plane([0.0, 0.0], [0.0, 1.0]), pc.Sphere([0.1, 0.05], 0.03, inside=False),
             pc.Capsule([-0.1, 0.05], [-0.05, 0.08], 0.01), pc.OrientedBox([0.0, 0.1], [0.02, 0.01], 0.3)]
    s = _grain(2, [0.0, 0.2], walls=walls)
    rec = pc.render.record(s, frames=2, steps_per_frame=5)
    assert [(c.tolist(), r, inside) for c, r, inside in rec.spheres] == [([0.1, 0.05], 0.03, False)]
    assert len(rec.rods) == 1  # the capsule
    assert np.array_equal(rec.rods[0][0], [-0.1, 0.05]) and rec.rods[0][2] == 0.01
    assert len(rec.polygons) == 1 and rec.polygons[0].shape == (4, 2)  # the block
    assert np.allclose(rec.polygons[0].mean(axis=0), [0.0, 0.1])  # about the block's centre, m
    assert len(rec.planes) == 1
    pc.render.gif(rec, tmp_path / "walls.gif", size=(80, 60))
    assert (tmp_path / "walls.gif").stat().st_size > 0
