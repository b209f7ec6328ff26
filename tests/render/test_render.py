"""GIF rendering (physcore.render): file format, fixed camera, colours, argument checks, atomicity.

Scenes are built from the public API; images are checked through Pillow only (frame count, size,
duration, and where coloured pixels are), never against stored reference images.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

import physcore as pc
from physcore import render
from physcore.render import _palette

WHITE = np.array([255, 255, 255])


# --------------------------------------------------------------------------- helpers
def falling_scene(n_extra: int = 0) -> pc.Scene:
    """One particle falling from rest under gravity (plus optional resting spectators far away)."""
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    s.add_particles(np.array([[0.0, 0.0]]))
    if n_extra:
        s.add_particles(np.column_stack([np.linspace(5.0, 6.0, n_extra), np.zeros(n_extra)]), pinned=np.ones(n_extra, bool))
    s.add(pc.Gravity([0.0, -9.81]))
    return s


def pendulum_pair(dim: int = 2) -> pc.Scene:
    """A pinned particle and a free one joined by a spring, swinging under gravity."""
    s = pc.Scene(dim=dim, integrator="verlet", dt=1e-3)
    x = np.zeros((2, dim))
    x[1, 0] = 1.0
    s.add_particles(x, pinned=np.array([True, False]))
    g = np.zeros(dim)
    g[-1] = -9.81
    s.add(pc.Gravity(g))
    s.add(pc.Springs(np.array([0]), np.array([1]), stiffness=100.0, damping=0.0))
    return s


def grid_cloth(n: int, dim: int = 3) -> pc.Scene:
    """An n x n sheet of springs, top corners pinned, falling under gravity."""
    g = np.arange(n) * 0.1
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    x = np.column_stack([gx, gy] + ([np.zeros(n * n)] if dim == 3 else []))
    idx = np.arange(n * n).reshape(n, n)
    i = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    j = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    pinned = np.zeros(n * n, dtype=bool)
    pinned[[0, n - 1]] = True
    s = pc.Scene(dim=dim, integrator="verlet", dt=1e-3)
    s.add_particles(x, masses=0.01, pinned=pinned)
    s.add(pc.Springs(i, j, stiffness=50.0, damping=0.0))
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    return s


def frames_rgb(path) -> list:
    with Image.open(path) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB")))
        return out


def ink(img: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that are not background."""
    return np.any(img != img[0, 0], axis=-1)


# --------------------------------------------------------------------------- file format
def test_gif_frames_size_and_duration(tmp_path):
    scene = pendulum_pair()
    path = render.gif(scene, tmp_path / "a.gif", frames=7, steps_per_frame=20, fps=25, size=(96, 64))
    assert path == tmp_path / "a.gif"
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.mode == "P"
        assert im.size == (96, 64)
        assert im.n_frames == 7
        for k in range(im.n_frames):
            im.seek(k)
            assert abs(im.info["duration"] - 1000 / 25) <= 10
        assert im.info.get("loop") == 0
    # Frame 0 is the state before stepping; the scene ends at the last frame.
    assert math.isclose(scene.time, 6 * 20 * 1e-3, rel_tol=1e-9)
    assert [p.name for p in tmp_path.iterdir()] == ["a.gif"]


def test_gif_single_frame_does_not_step(tmp_path):
    scene = pendulum_pair()
    render.gif(scene, tmp_path / "one.gif", frames=1, size=(32, 32))
    assert scene.time == 0.0
    with Image.open(tmp_path / "one.gif") as im:
        assert im.n_frames == 1


def test_camera_is_fixed_so_a_falling_particle_moves_down(tmp_path):
    scene = falling_scene()
    path = render.gif(scene, tmp_path / "fall.gif", frames=6, steps_per_frame=50, size=(64, 96), color_by="none")
    rows, cols = [], []
    for img in frames_rgb(path):
        r, c = np.nonzero(ink(img))
        assert r.size > 0
        rows.append(r.mean())
        cols.append(c.mean())
    assert np.all(np.diff(rows) > 0), rows  # strictly down the image, frame after frame
    assert np.ptp(cols) < 1.0
    # The fitted view holds the whole fall: first near the top, last near the bottom.
    assert rows[0] < 96 * 0.3 and rows[-1] > 96 * 0.7


def test_color_by_speed_uses_a_fixed_scale(tmp_path):
    # A falling particle gets faster; on a scale fixed over the animation its colour changes.
    path = render.gif(falling_scene(), tmp_path / "s.gif", frames=5, steps_per_frame=50, size=(48, 64))
    colours = []
    for img in frames_rgb(path):
        px = img[ink(img)]
        colours.append(tuple(np.median(px, axis=0)))
    assert len(set(colours)) == len(colours)


def test_springs_can_be_hidden(tmp_path):
    scene = pendulum_pair()
    with_springs = render.gif(scene, tmp_path / "a.gif", frames=2, size=(64, 64), radius=1)
    scene2 = pendulum_pair()
    without = render.gif(scene2, tmp_path / "b.gif", frames=2, size=(64, 64), radius=1, springs=False)
    assert ink(frames_rgb(with_springs)[0]).sum() > ink(frames_rgb(without)[0]).sum() + 20


def test_progress_bar_goes_to_stderr(tmp_path, capsys):
    render.gif(pendulum_pair(), tmp_path / "p.gif", frames=3, size=(32, 32), progress=True)
    captured = capsys.readouterr()
    assert "3/3" in captured.err
    assert captured.out == ""


def test_cloth_gif_is_small(tmp_path):
    path = render.gif(grid_cloth(32), tmp_path / "cloth.gif", frames=90, steps_per_frame=5)
    assert path.stat().st_size < 5_000_000
    with Image.open(path) as im:
        assert im.n_frames == 90


def test_3d_scene_renders(tmp_path):
    path = render.gif(grid_cloth(6, dim=3), tmp_path / "c3.gif", frames=4, steps_per_frame=20, size=(80, 60))
    imgs = frames_rgb(path)
    assert len(imgs) == 4
    assert all(ink(img).sum() > 30 for img in imgs)
    # Another view gives another picture of the same state.
    a = render.render_frame(grid_cloth(6, dim=3), size=(80, 60))
    b = render.render_frame(grid_cloth(6, dim=3), size=(80, 60), view=(30, 60))
    assert a.shape == b.shape == (60, 80, 3)
    assert not np.array_equal(a, b)


def test_2d_planes_are_drawn(tmp_path):
    scene = falling_scene()
    scene.add(pc.Plane([0.0, -0.2], [0.0, 1.0]))
    img = render.render_frame(scene, size=(64, 64), color_by="none")
    # Rows well below the particle (which sits just above the floor's line) are the floor's fill.
    assert np.all(img[-2] != WHITE)
    assert np.all(img[1] == WHITE)


# --------------------------------------------------------------------------- render_frame
def test_render_frame_shape_and_dtype():
    img = render.render_frame(np.random.default_rng(0).normal(size=(50, 2)), size=(40, 30))
    assert img.shape == (30, 40, 3)
    assert img.dtype == np.uint8


@pytest.mark.parametrize("collider", [
    pc.Sphere([0.0, -0.5], 0.3), pc.Capsule([-0.5, -0.5], [0.5, -0.4], 0.1), pc.OrientedBox([0.0, -0.5], [0.5, 0.1], 0.2),
])
def test_render_frame_draws_a_2d_scenes_colliders_as_gif_does(collider):
    """Issue 62: every collider of a 2D scene is drawn by render_frame too (it drew planes only):
    the colliders' fill shows, in view (the camera fits the collider, as gif's does)."""
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.5], [0.2, 0.6]])
    s.add(collider)
    fill = _palette._PALETTE[_palette._PLANE_FILL]
    img = render.render_frame(s, size=(160, 120))
    assert (img == fill).all(axis=2).sum() > 200
    bare = render.render_frame(s.positions, size=(160, 120))
    assert not (bare == fill).all(axis=2).any()


@pytest.mark.parametrize("x", [np.zeros((1, 2)), np.ones((5, 2)), np.full((3, 3), 2.5), np.zeros((0, 2))])
def test_render_frame_degenerate_extent(x):
    # A single particle, or all at one point: the camera falls back to a unit box around it.
    img = render.render_frame(x, size=(32, 32), radius=2)
    if len(x):
        r, c = np.nonzero(ink(img))
        assert abs(r.mean() - 16) <= 1 and abs(c.mean() - 16) <= 1
    else:
        assert not ink(img).any()


def _line_colour(rest: float, length: float = 1.0) -> np.ndarray:
    x = np.array([[0.0, 0.0], [length, 0.0]])
    img = render.render_frame(x, springs=([0], [1], [rest]), color_by="none", radius=0, size=(64, 32))
    particle = render.render_frame(x, springs=False, color_by="none", radius=0, size=(64, 32))
    line = ink(img) & ~ink(particle)
    assert line.sum() > 20
    return img[line].mean(axis=0)


def test_strain_colours():
    red, green, blue = _line_colour(rest=0.5)  # stretched by 100 %
    assert red > blue + 80
    red, green, blue = _line_colour(rest=2.0)  # compressed by 50 %
    assert blue > red + 80
    rgb = _line_colour(rest=1.0)  # at rest: grey
    assert np.ptp(rgb) < 10
    # Half the saturation strain gives an in-between red.
    mid = _line_colour(rest=1.0 / (1 + render.STRAIN_SATURATION / 2))
    full = _line_colour(rest=0.5)
    assert full[0] - full[2] > mid[0] - mid[2] > 0


def test_pinned_particles_are_distinct():
    x = np.array([[0.0, 0.0], [1.0, 0.0]])
    img = render.render_frame(x, pinned=[True, False], color_by="none", radius=3, size=(64, 32))
    left, right = img[16, :32][ink(img)[16, :32]], img[16, 32:][ink(img)[16, 32:]]
    assert not np.array_equal(left[0], right[0])


def test_3d_painters_order():
    # Two particles on one line of sight: the nearer one must cover the farther one.
    az, el = np.radians(-60.0), np.radians(25.0)
    toward = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    near_free = np.array([[0.0, 0.0, 0.0], toward])  # particle 1 is nearer
    a = render.render_frame(near_free, pinned=[True, False], color_by="none", radius=4, size=(32, 32))
    b = render.render_frame(near_free, pinned=[False, True], color_by="none", radius=4, size=(32, 32))
    free_colour = a[16, 16]
    pinned_colour = b[16, 16]
    assert not np.array_equal(free_colour, pinned_colour)
    # Same colours as when each is drawn alone.
    alone = render.render_frame(near_free[1:], pinned=[False], color_by="none", radius=4, size=(32, 32))
    assert np.array_equal(alone[16, 16], free_colour)


def test_render_frame_bad_shapes():
    with pytest.raises(ValueError, match="positions"):
        render.render_frame(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="pinned"):
        render.render_frame(np.zeros((3, 2)), pinned=[True])
    with pytest.raises(ValueError, match="springs"):
        render.render_frame(np.zeros((3, 2)), springs=([0], [5], [1.0]))


# --------------------------------------------------------------------------- argument checks
@pytest.mark.parametrize(
    "kwargs, exc, name",
    [
        ({"frames": 0}, ValueError, "frames"),
        ({"frames": 2.0}, TypeError, "frames"),
        ({"frames": True}, TypeError, "frames"),
        ({"steps_per_frame": 0}, ValueError, "steps_per_frame"),
        ({"fps": 0}, ValueError, "fps"),
        ({"fps": float("nan")}, ValueError, "fps"),
        ({"fps": "30"}, TypeError, "fps"),
        ({"size": (8, 100)}, ValueError, "size"),
        ({"size": (100,)}, ValueError, "size"),
        ({"size": "480x360"}, TypeError, "size"),
        ({"color_by": "mass"}, ValueError, "color_by.*'speed'.*'none'|color_by.*'none'.*'speed'"),
        ({"radius": -1}, ValueError, "radius"),
        ({"view": (1.0,)}, ValueError, "view"),
    ],
)
def test_bad_arguments_raise_before_anything_happens(tmp_path, kwargs, exc, name):
    scene = pendulum_pair()
    with pytest.raises(exc, match=name):
        render.gif(scene, tmp_path / "x.gif", **kwargs)
    assert list(tmp_path.iterdir()) == []
    assert scene.time == 0.0


def test_bad_paths(tmp_path):
    scene = pendulum_pair()
    with pytest.raises(ValueError, match=r"path.*\.gif"):
        render.gif(scene, tmp_path / "x.png")
    with pytest.raises(ValueError, match="path.*does not exist"):
        render.gif(scene, tmp_path / "missing" / "x.gif")
    with pytest.raises(TypeError, match="path"):
        render.gif(scene, 42)
    assert list(tmp_path.iterdir()) == []
    assert scene.time == 0.0


# --------------------------------------------------------------------------- divergence / atomicity
def diverging_scene() -> pc.Scene:
    # 1e308 m/s overflows the position to inf on the first step.
    s = pc.Scene(dim=2, integrator="verlet", dt=10.0)
    s.add_particles(np.array([[0.0, 0.0]]), np.array([[1e308, 0.0]]))
    return s


def test_divergence_leaves_no_file(tmp_path):
    scene = diverging_scene()
    with pytest.raises(pc.SimulationDiverged):
        render.gif(scene, tmp_path / "boom.gif", frames=5)
    assert list(tmp_path.iterdir()) == []


def test_divergence_keeps_an_existing_file(tmp_path):
    target = tmp_path / "old.gif"
    target.write_bytes(b"previous contents")
    with pytest.raises(pc.SimulationDiverged):
        render.gif(diverging_scene(), target, frames=5)
    assert target.read_bytes() == b"previous contents"
    assert list(tmp_path.iterdir()) == [target]


def test_existing_file_is_replaced(tmp_path):
    target = tmp_path / "old.gif"
    target.write_bytes(b"previous contents")
    render.gif(pendulum_pair(), target, frames=2, size=(32, 32))
    with Image.open(target) as im:
        assert im.n_frames == 2
    assert list(tmp_path.iterdir()) == [target]


def test_failure_while_writing_removes_the_temporary_file(tmp_path, monkeypatch):
    from physcore.render import _gif

    real = _gif._lzw

    def broken_lzw(pixels):  # the GIF writer's frame data: fails once the temporary file is open
        if any(tmp_path.iterdir()):
            raise OSError("disk full")
        return real(pixels)

    monkeypatch.setattr(_gif, "_lzw", broken_lzw)
    with pytest.raises(OSError, match="disk full"):
        render.gif(pendulum_pair(), tmp_path / "x.gif", frames=2, size=(32, 32))
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- fluid-scene features
# The SPH scenes are not needed to test the renderer's side of the contract: a real Scene behind a
# thin wrapper supplies the optional methods a fluid scene has (pressure, boundary_points,
# advance), each with a simple, known behaviour.
RHO_G = 1000.0 * 9.81  # Pa per metre of depth
SURFACE = 1.0  # m, height of the pretend free surface


class FluidLike:
    """A physcore.Scene plus ``pressure()`` (hydrostatic below SURFACE), ``boundary_points()`` and
    ``advance(duration)`` (ceil(duration / dt) steps of dt, the count returned).

    Attributes named in `hide` behave as if missing (AttributeError), like on a plain scene.
    """

    def __init__(self, scene, walls=None, hide=()):
        self.scene = scene
        self.walls = np.zeros((0, scene.dim)) if walls is None else np.asarray(walls, dtype=float)
        self.hide = set(hide)
        self.advanced = []  # durations passed to advance()
        self.pressure_calls = 0

    def __getattribute__(self, name):
        if name in object.__getattribute__(self, "hide"):
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return object.__getattribute__(self, name)

    def __getattr__(self, name):  # everything else: the real scene
        if name in object.__getattribute__(self, "hide"):
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(self.scene, name)

    def pressure(self):
        self.pressure_calls += 1
        return np.maximum(RHO_G * (SURFACE - self.scene.positions[:, -1]), 0.0)

    def boundary_points(self):
        return self.walls

    def advance(self, duration):
        k = max(1, math.ceil(duration / self.scene.dt - 1e-9))
        self.scene.step(k)
        self.advanced.append(duration)
        return k


def tank_walls(width: float = 2.0, height: float = 1.5, spacing: float = 0.05) -> np.ndarray:
    """A U-shaped tank of wall points: floor at y = -0.1, walls at x = -0.1 and x = width."""
    ys = np.arange(-0.1, height, spacing)
    xs = np.arange(-0.1, width + spacing / 2, spacing)
    return np.concatenate([
        np.column_stack([np.full_like(ys, -0.1), ys]),
        np.column_stack([np.full_like(ys, width), ys]),
        np.column_stack([xs, np.full_like(xs, -0.1)]),
    ])


def falling_block(walls=True, hide=()) -> FluidLike:
    """A 6 x 6 block of free particles (y in [0.5, 1]) falling into a tank."""
    g = np.linspace(0.0, 0.5, 6)
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    s.add_particles(np.column_stack([gx + 0.2, gy + 0.5]))
    s.add(pc.Gravity([0.0, -9.81]))
    return FluidLike(s, tank_walls() if walls else None, hide=hide)


def palette_rgb(start: int, count: int) -> set:
    return {tuple(int(v) for v in c) for c in render._PALETTE[start:start + count]}


PRESSURE_RGB = palette_rgb(render._PRESSURE0, render._N_PRESSURE)
SPEED_RGB = palette_rgb(render._SPEED0, render._N_SPEED)
WALL_RGB = np.asarray(render._PALETTE[render._WALL])
TEXT_RGB = np.asarray(render._PALETTE[render._TEXT])
PLAIN_RGB = np.asarray(render._PALETTE[_palette._PLAIN])  # color_by="none"


def colours_of(img: np.ndarray) -> set:
    return {tuple(int(v) for v in c) for c in np.unique(img.reshape(-1, 3), axis=0)}


def band(img: np.ndarray, rows: int = 16, cols: int = 180) -> np.ndarray:
    """The top-right corner where the colour bar goes."""
    return img[:rows, -cols:]


def test_pressure_maps_zero_to_the_bottom_and_the_scale_to_the_top():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    img = render.render_frame(
        x, pressures=[-1.5e4, 0.0, 3e4], pressure_scale=2e4, color_by="pressure", radius=2, size=(96, 32), colorbar=False
    )
    row = img[16]
    cols = np.nonzero(ink(img)[16])[0]
    lo, zero, top = row[cols.min()], row[48], row[cols.max()]  # the particles at 0, 1 and 2 m
    assert tuple(zero) == tuple(render._PALETTE[render._PRESSURE0])  # 0 Pa: bottom of the map
    assert tuple(lo) == tuple(zero)  # negative pressure: clipped to the bottom
    assert tuple(top) == tuple(render._PALETTE[render._PRESSURE0 + render._N_PRESSURE - 1])  # above the scale: top
    assert tuple(top) in PRESSURE_RGB and tuple(top) not in SPEED_RGB


def test_pressure_gif_colours_follow_depth_on_a_fixed_scale(tmp_path):
    scene = falling_block(walls=False)
    path = render.gif(scene, tmp_path / "p.gif", frames=5, frame_time=0.05, size=(64, 80), color_by="pressure")
    imgs = frames_rgb(path)
    assert len(imgs) == 5
    tops = []
    for img in imgs:
        particle = ink(img)
        found = colours_of(img[particle])
        assert found <= PRESSURE_RGB, found - PRESSURE_RGB  # only pressure colours (no bar at 64 px)
        # The deepest particles (lowest rows) carry the highest pressure: the colour of the
        # bottom-most ink row is later on the map than that of the top-most one.
        r = np.nonzero(particle.any(axis=1))[0]
        levels = {c: k for k, c in enumerate(sorted(PRESSURE_RGB, key=lambda c: _pressure_index(c)))}
        top_row = [levels[tuple(c)] for c in img[r[0]][particle[r[0]]]]
        bottom_row = [levels[tuple(c)] for c in img[r[-1]][particle[r[-1]]]]
        assert min(bottom_row) > max(top_row)
        tops.append(max(bottom_row))
    # The block falls deeper, so its pressure (on one scale for the whole animation) rises.
    assert tops[-1] > tops[0]
    assert scene.pressure_calls == 5  # read once per frame


def _pressure_index(rgb) -> int:
    pal = render._PALETTE[render._PRESSURE0:render._PRESSURE0 + render._N_PRESSURE]
    return int(np.nonzero(np.all(pal == np.asarray(rgb), axis=1))[0][0])


@pytest.mark.parametrize("wrapper", ["hidden", "plain"])
def test_pressure_without_a_pressure_method_raises_before_stepping(tmp_path, wrapper):
    if wrapper == "hidden":
        scene = falling_block(hide=("pressure",))
    else:
        # An object whose pressure() itself raises AttributeError.
        scene = falling_block()
        scene.pressure = lambda: (_ for _ in ()).throw(AttributeError("no fluid here"))
    with pytest.raises(ValueError, match="color_by"):
        render.gif(scene, tmp_path / "x.gif", frames=3, color_by="pressure", progress=True)
    assert scene.time == 0.0 and scene.step_count == 0
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="color_by"):
        render.render_frame(np.zeros((3, 2)), color_by="pressure")


def test_pressure_of_the_wrong_shape_raises_before_stepping(tmp_path):
    scene = falling_block()
    scene.pressure = lambda: np.zeros(3)
    with pytest.raises(ValueError, match="pressure"):
        render.gif(scene, tmp_path / "x.gif", frames=3, color_by="pressure")
    assert scene.time == 0.0
    assert list(tmp_path.iterdir()) == []


def moving_pair():
    x = np.array([[0.0, 0.0], [1.0, 0.5]])
    v = np.array([[0.0, 0.0], [3.2, 0.0]])
    return x, v


def test_colorbar_is_drawn_when_on_and_absent_when_off():
    x, v = moving_pair()
    on = render.render_frame(x, velocities=v, radius=3)
    off = render.render_frame(x, velocities=v, radius=3, colorbar=False)
    none = render.render_frame(x, velocities=v, radius=3, color_by="none")
    assert on.shape == off.shape == (360, 480, 3)
    # On: labels in the text colour and the gradient strip, in the top-right corner.
    corner = band(on)
    assert np.all(corner == TEXT_RGB, axis=-1).sum() > 60
    strip = colours_of(corner) & SPEED_RGB
    assert len(strip) >= 48  # (nearly) the whole map, in a 96-pixel strip
    # The strip runs from the bottom of the map (left) to the top (right).
    row = corner[8]
    is_map = np.array([tuple(c) in SPEED_RGB for c in row])
    cols = np.nonzero(is_map)[0]
    assert tuple(row[cols[0]]) == tuple(render._PALETTE[render._SPEED0])
    assert tuple(row[cols[-1]]) == tuple(render._PALETTE[render._SPEED0 + render._N_SPEED - 1])
    # Off, and for color_by="none": nothing there.
    assert not ink(band(off)).any()
    assert not ink(band(none)).any()
    # The particles are drawn either way, and none of them inside the bar's band, even where the
    # usual margin is narrower than the band (19 rows at this size: a 13-pixel font).
    from physcore.render._colorbar import _colorbar_layout

    top = _colorbar_layout((480, 360), "speed 0", "3.2 m/s").band
    assert ink(on[top:]).sum() == ink(off).sum() > 0
    corner = np.array([[0.0, 0.0], [1.0, 0.5], [0.5, 0.25]])
    vel = np.array([[1.0, 0.0], [2.0, 0.0], [0.0, 0.0]])
    on = render.render_frame(corner, velocities=vel, radius=2, size=(200, 100))
    off = render.render_frame(corner, velocities=vel, radius=2, size=(200, 100), colorbar=False)
    assert np.all(band(on) == TEXT_RGB, axis=-1).any()
    assert ink(off[:16]).any()  # without the bar, the top particle sits in those rows
    assert ink(on[16:]).sum() == ink(off).sum() == 3 * 21  # three whole discs of radius 2 (5x5 less corners)
    # Nothing moving: the scale's top is 0 and there is no bar.
    still = render.render_frame(x, velocities=np.zeros_like(v), radius=3)
    assert not ink(band(still)).any()


def test_colorbar_labels_and_units():
    assert render._colorbar_labels("speed", 3.2) == ("0", "3.2 m/s")
    assert render._colorbar_labels("speed", 1234.5) == ("0", "1234 m/s")
    assert render._colorbar_labels("pressure", 19620.0) == ("0", "19.6 kPa")
    assert render._colorbar_labels("pressure", 512.0) == ("0", "512 Pa")
    assert render._colorbar_labels("pressure", 999.9) == ("0", "1 kPa")  # rounds up into kPa
    assert render._colorbar_labels("pressure", 2.5e6) == ("0", "2.5 MPa")
    # Different ranges give different labels, so the drawn bar differs too.
    x, v = moving_pair()
    a = render.render_frame(x, velocities=v, radius=3, speed_scale=3.2)
    b = render.render_frame(x, velocities=v, radius=3, speed_scale=12.0)
    assert not np.array_equal(band(a), band(b))


def test_colorbar_is_left_out_of_tiny_images():
    x, v = moving_pair()
    small = render.render_frame(x, velocities=v, size=(64, 64), radius=1)
    assert not np.any(np.all(small == TEXT_RGB, axis=-1))


def test_colorbar_in_the_gif_is_fixed_over_the_animation(tmp_path):
    scene = falling_block()
    on = render.gif(scene, tmp_path / "on.gif", frames=4, frame_time=0.05, color_by="pressure", size=(240, 180))
    off = render.gif(falling_block(), tmp_path / "off.gif", frames=4, frame_time=0.05, color_by="pressure",
                     size=(240, 180), colorbar=False)
    on_imgs, off_imgs = frames_rgb(on), frames_rgb(off)
    for img in on_imgs:
        assert np.array_equal(band(img, cols=150), band(on_imgs[0], cols=150))
        assert np.all(band(img, cols=150) == TEXT_RGB, axis=-1).sum() > 40
        assert len(colours_of(band(img, cols=150)) & PRESSURE_RGB) >= 20
    for img in off_imgs:
        assert not np.any(np.all(band(img, cols=150) == TEXT_RGB, axis=-1))


def test_clock_in_the_bottom_left_corner_counts_simulated_time(tmp_path):
    """Particle animations carry the simulated time ("t = 0.05 s") bottom left, drawn in the
    text colour over a box of background; it changes as time runs and is the only text there."""
    out = render.gif(falling_block(), tmp_path / "t.gif", frames=4, frame_time=0.05, size=(240, 180), colorbar=False)
    imgs = frames_rgb(out)
    corners = [img[-20:, :90] for img in imgs]
    for c in corners:
        assert np.all(c == TEXT_RGB, axis=-1).sum() > 20
    assert not np.array_equal(corners[1], corners[2])  # t = 0.05 s, then 0.1 s
    assert not np.any(np.all(imgs[0][:-20] == TEXT_RGB, axis=-1))  # no text elsewhere
    # The clock reads what the frame's time is: the same text drawn alone matches it.
    from physcore.render._colorbar import _text_mask

    mask = _text_mask("t = 0.1 s")
    h = imgs[2].shape[0]
    ink = np.all(imgs[2][h - 4 - mask.shape[0] : h - 4, 4 : 4 + mask.shape[1]] == TEXT_RGB, axis=-1)
    assert np.array_equal(ink, mask)


def test_scale_bar_measures_the_scene(tmp_path):
    """Two particles 1 m apart: the scale bar (bottom right, a 1, 2 or 5 × 10^k length near a
    sixth of the width) is as many pixels long as its length is metres times the pixels between
    the two discs' centres; its label says the length."""
    scene = pc.Scene(dim=2)
    scene.add_particles([[0.0, 0.0], [1.0, 0.0]])
    out = render.gif(scene, tmp_path / "s.gif", frames=1, size=(240, 180), color_by="none", radius=3, colorbar=False)
    img = frames_rgb(out)[0]
    h, w = img.shape[:2]
    discs = np.all(img == PLAIN_RGB, axis=-1)
    cols = np.nonzero(discs.any(axis=0))[0]
    left, right = cols[cols < w // 2], cols[cols >= w // 2]
    metre_px = 0.5 * (right.min() + right.max()) - 0.5 * (left.min() + left.max())
    bar = np.nonzero(np.all(img[h - 6] == TEXT_RGB, axis=-1))[0]
    bar_px = bar.max() - bar.min()
    from physcore.render._raster import _scale_bar_length

    length = _scale_bar_length(metre_px, w / 6.0)
    assert length in (0.1, 0.2, 0.5, 1.0, 2.0)
    assert abs(bar_px - length * metre_px) <= 1.5
    from physcore.render._colorbar import _text_mask

    label = f"{round(length * 100)} cm" if length < 1 else f"{length:g} m"
    mask = _text_mask(label)
    band = np.all(img[h - 30 : h - 6] == TEXT_RGB, axis=-1)
    assert band.sum() >= mask.sum()  # the label's ink is there (plus the ticks)


def test_boundary_points_are_grey_static_and_in_the_camera_fit(tmp_path):
    scene = falling_block()
    path = render.gif(scene, tmp_path / "w.gif", frames=4, frame_time=0.05, color_by="none", size=(160, 120))
    imgs = frames_rgb(path)
    walls = [np.all(img == WALL_RGB, axis=-1) for img in imgs]
    for w in walls:
        # The tank is in view: its two side walls and its floor, near the image's edges (the
        # floor above the band kept free at the bottom for the clock and the scale bar).
        r, c = np.nonzero(w)
        assert c.min() < 20 and c.max() > 140 and r.max() > 90
        assert w[:, :20].sum() > 40 and w[:, -20:].sum() > 40
    # Static: the wall pixels not covered by a particle stay the same.
    assert np.array_equal(walls[0][:, -20:], walls[-1][:, -20:])
    # Without boundary points the free particles fill the view instead.
    plain = render.gif(falling_block(walls=False), tmp_path / "p.gif", frames=1, color_by="none", size=(160, 120))
    assert not np.any(np.all(frames_rgb(plain)[0] == WALL_RGB, axis=-1))


def test_boundary_points_of_a_2d_tank_draw_a_solid_wall():
    """The wall particles of a 2D tank (three layers on a lattice) are drawn as one solid band,
    not as a perforated grid of particle-sized dots: along the middle of the left wall, every
    pixel column of the left wall is the wall's grey from floor to top. (Particle-sized dots
    left 26 gaps in each column here, 97 in some at the default n and 480 × 360.)"""
    for n, size in ((40, (240, 180)), (None, (480, 360))):
        scene = pc.scenes.dam_break() if n is None else pc.scenes.dam_break(n=n)
        assert scene.boundary_points().shape[0] > 1000  # many wall particles, not a drawn line
        wall = np.all(next(render.frames(scene, frames=1, size=size)) == WALL_RGB, axis=-1)
        cols = np.flatnonzero(wall.sum(axis=0) > 0.5 * wall.sum(axis=0).max())
        left = cols[cols < size[0] // 4]
        assert left.size >= 3  # the band is several pixels wide
        for c in left[1:-1]:  # the band's inside (its outer columns are the discs' scalloped rims)
            rows = np.flatnonzero(wall[:, c])
            assert rows.size > 0.8 * size[1] and np.all(np.diff(rows) == 1), (n, size, c, "gaps in the wall")


def test_boundary_points_lie_under_the_particles():
    x = np.array([[0.0, 0.0], [1.0, 0.0]])
    img = render.render_frame(x, boundary=x.copy(), color_by="none", radius=3, size=(64, 32), colorbar=False)
    assert not np.any(np.all(img == WALL_RGB, axis=-1))  # each wall point is covered by a particle
    walls_only = render.render_frame(np.zeros((0, 2)), boundary=x, radius=3, size=(64, 32))
    assert np.all(walls_only == WALL_RGB, axis=-1).sum() > 20
    with pytest.raises(ValueError, match="boundary"):
        render.render_frame(x, boundary=np.zeros((4, 3)))


def test_boundary_points_in_3d():
    g = np.linspace(-1.0, 1.0, 5)
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    floor = np.column_stack([gx, gy, np.full(gx.size, -1.0)])
    img = render.render_frame(np.zeros((1, 3)), boundary=floor, radius=2, size=(80, 60), color_by="none")
    assert np.all(img == WALL_RGB, axis=-1).sum() > 25
    # An empty set of boundary points changes nothing.
    a = render.render_frame(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), boundary=np.zeros((0, 3)), size=(80, 60))
    b = render.render_frame(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), size=(80, 60))
    assert np.array_equal(a, b)


def test_frame_time_drives_advance(tmp_path, capsys):
    scene = falling_block()
    path = render.gif(scene, tmp_path / "f.gif", frames=6, frame_time=0.02, size=(64, 64), progress=True)
    assert scene.advanced == [0.02] * 5  # once per frame after the first, with frame_time
    assert scene.step_count == 5 * 20  # what advance() chose: ceil(0.02 / 1e-3) substeps each
    assert math.isclose(scene.time, 5 * 0.02, rel_tol=1e-9)
    with Image.open(path) as im:
        assert im.n_frames == 6
    err = capsys.readouterr().err
    assert "6/6" in err and "substeps=20" in err


def test_frame_time_none_keeps_fixed_steps(tmp_path):
    scene = falling_block()
    render.gif(scene, tmp_path / "f.gif", frames=3, steps_per_frame=7, size=(32, 32))
    assert scene.advanced == []
    assert scene.step_count == 14
    scene = falling_block()
    render.gif(scene, tmp_path / "g.gif", frames=3, size=(32, 32))
    # The default: 1/30 s of simulated time per frame (real time at 30 fps), as fixed steps:
    # round((1/30) / 1e-3) = 33 steps of dt a frame.
    assert scene.advanced == [] and scene.step_count == 66


@pytest.mark.parametrize(
    "kwargs, exc, name",
    [
        ({"frame_time": 0.0}, ValueError, "frame_time"),
        ({"frame_time": -0.01}, ValueError, "frame_time"),
        ({"frame_time": float("nan")}, ValueError, "frame_time"),
        ({"frame_time": float("inf")}, ValueError, "frame_time"),
        ({"frame_time": "0.1"}, TypeError, "frame_time"),
        ({"frame_time": True}, TypeError, "frame_time"),
        ({"frame_time": 0.01, "steps_per_frame": 5}, ValueError, "steps_per_frame.*frame_time"),
        ({"frame_time": 0.01, "color_by": "pressure", "fps": 0}, ValueError, "fps"),
    ],
)
def test_bad_frame_time_raises_before_stepping(tmp_path, kwargs, exc, name):
    scene = falling_block()
    with pytest.raises(exc, match=name):
        render.gif(scene, tmp_path / "x.gif", frames=3, **kwargs)
    assert scene.advanced == [] and scene.time == 0.0 and scene.step_count == 0
    assert list(tmp_path.iterdir()) == []


def test_frame_time_needs_advance(tmp_path):
    scene = falling_block(hide=("advance",))
    with pytest.raises(ValueError, match="frame_time"):
        render.gif(scene, tmp_path / "x.gif", frames=3, frame_time=0.01)
    assert scene.time == 0.0
    assert list(tmp_path.iterdir()) == []


def test_gif_fixed_substeps_per_frame(tmp_path):
    s = pc.scenes.spring_chain(n=5, threads=1)
    pc.render.gif(s, tmp_path / "a.gif", frames=4, frame_time=0.01, substeps=5, size=(32, 32))
    assert s.step_count == 3 * 5
    assert s.dt == pytest.approx(0.01 / 5, rel=1e-15)
    auto = pc.scenes.spring_chain(n=5, threads=1)
    pc.render.gif(auto, tmp_path / "b.gif", frames=4, frame_time=0.01, size=(32, 32))
    assert auto.step_count == 3 * math.ceil(0.01 / auto.auto_dt() - 1e-9)
    for kw, exc in [({"substeps": 0}, ValueError), ({"substeps": "fast"}, ValueError), ({"substeps": 2.5}, TypeError)]:
        with pytest.raises(exc, match="substeps"):
            pc.render.gif(s, tmp_path / "c.gif", frames=2, frame_time=0.01, **kw)
    with pytest.raises(ValueError, match="substeps needs frame_time"):
        pc.render.gif(s, tmp_path / "c.gif", frames=2, substeps=3)
    assert not (tmp_path / "c.gif").exists()


# ----------------------------------------------------------------------------- record / gif split
def test_gif_of_a_recording_is_the_gif_of_the_scene(tmp_path):
    # Producing apart from presenting: gif(scene, ...) is gif(record(scene, ...), ...), byte for byte.
    args = {"frames": 6, "steps_per_frame": 15}
    a = pc.render.gif(pc.scenes.spring_chain(n=6), tmp_path / "a.gif", size=(96, 72), **args)
    rec = pc.render.record(pc.scenes.spring_chain(n=6), **args)
    b = pc.render.gif(rec, tmp_path / "b.gif", size=(96, 72))
    assert a.read_bytes() == b.read_bytes()
    # One recording, several drawings, no stepping.
    c = pc.render.gif(rec, tmp_path / "c.gif", size=(64, 48), color_by="none", springs=False)
    assert c.read_bytes() != b.read_bytes()


def test_record_calls_on_frame_once_per_frame_with_the_substeps():
    seen = []
    scene = pc.scenes.spring_chain(n=4)
    rec = pc.render.record(
        scene, frames=4, frame_time=0.01, on_frame=lambda k, s, n: seen.append((k, s is scene, n, s.time))
    )
    assert [k for k, *_ in seen] == [0, 1, 2, 3]
    assert all(same for _, same, _, _ in seen)
    assert seen[0][2] is None and all(isinstance(n, int) and n >= 1 for _, _, n, _ in seen[1:])
    assert np.array_equal(rec.times, [t for *_, t in seen])
    assert rec.times[-1] == pytest.approx(0.03, rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, arg",
    [({"frames": 3}, "frames"), ({"frame_time": 0.1}, "frame_time"), ({"color_by": "pressure"}, "color_by")],
)
def test_a_recording_refuses_simulation_arguments(tmp_path, kwargs, arg):
    rec = pc.render.record(pc.scenes.spring_chain(n=4), frames=2)
    with pytest.raises(pc.InvalidInputError, match=f"^{arg}: "):
        pc.render.gif(rec, tmp_path / "x.gif", **kwargs)
    assert not (tmp_path / "x.gif").exists()


def test_record_refuses_a_bad_callback_before_stepping():
    scene = pc.scenes.spring_chain(n=4)
    with pytest.raises(pc.InvalidTypeError, match="^on_frame: "):
        pc.render.record(scene, frames=2, on_frame="print")
    assert scene.step_count == 0


def _cloud(n: int, dim: int = 2, seed: int = 0) -> pc.Scene:
    rng = np.random.default_rng(seed)
    scene = pc.Scene(dim=dim)
    scene.add_particles(rng.standard_normal((n, dim)))
    return scene


def test_density_glow_uses_its_own_ramp_and_brightens_with_density(tmp_path):
    """color_by="density": only the background, the glow ramp and the clock's text appear; a
    pixel with more particles is brighter (dark theme: towards white)."""
    glow = {tuple(int(v) for v in c) for c in render._palette._DARK_PALETTE[_palette._GLOW0 :]}
    other = {tuple(int(v) for v in render._palette._DARK_PALETTE[i]) for i in (_palette._BACKGROUND, _palette._TEXT)}
    rng = np.random.default_rng(1)
    x = np.concatenate([0.05 * rng.standard_normal((400, 2)) + [-1.0, 0.0], 0.05 * rng.standard_normal((40, 2)) + [1.0, 0.0]])
    scene = pc.Scene(dim=2)
    scene.add_particles(x)
    out = render.gif(scene, tmp_path / "g.gif", frames=1, size=(240, 180), color_by="density", theme="dark")
    img = frames_rgb(out)[0]
    colours = {tuple(int(v) for v in c) for c in np.unique(img.reshape(-1, 3), axis=0)}
    assert colours <= glow | other and len(colours & glow) > 10
    lum = img.astype(float).sum(axis=2)
    left, right = lum[:, :120].max(), lum[:, 120:].max()
    assert left > right > lum[5, 5]  # ten times the particles: brighter; both above the sky


def test_density_glow_is_independent_of_particle_order_in_3d(tmp_path):
    a = _cloud(3000, dim=3)
    perm = np.random.default_rng(2).permutation(3000)
    b = pc.Scene(dim=3)
    b.add_particles(a.positions[perm])
    fa = render.frames(a, frames=1, size=(160, 120), color_by="density")
    fb = render.frames(b, frames=1, size=(160, 120), color_by="density")
    assert np.array_equal(next(fa), next(fb))  # additive: no depth order to get wrong


def test_density_glow_shows_sub_pixel_motion():
    """Bilinear splatting: moving one particle by a third of a pixel changes the picture (discs
    snap to whole pixels)."""
    def frame(shift):
        x = np.array([[0.0, 0.0], [10.0, 7.5], [shift, 5.0]])
        return render.render_frame(x, size=(200, 150), color_by="density", extent=([-1.0, -1.0], [11.0, 8.5]))

    assert not np.array_equal(frame(3.0), frame(3.0 + 0.02))  # 0.02 m is ~1/3 pixel here


@pytest.mark.parametrize("r", [1, 2, 3, 7])
def test_glow_box_blur_is_a_moving_average(r):
    """Both ways the box blur is computed (shifted slices for small windows, a cumulative sum for
    wide ones) give the mean over 2r + 1 pixels with zeros beyond the edges."""
    from physcore.render._raster import _box_blur

    a = np.random.default_rng(r).random((9, 31)).astype(np.float32)
    want = np.stack([np.convolve(row, np.ones(2 * r + 1) / (2 * r + 1), mode="same") for row in a])
    np.testing.assert_allclose(_box_blur(a, r, 1), want, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(_box_blur(a.T.copy(), r, 0), want.T, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("shape, r", [((9, 31), 1), ((40, 23), 2), ((360, 480), 3), ((5, 3), 7), ((1, 200), 12)])
def test_the_cores_blur_is_the_numpy_box_blurs_bit_for_bit(shape, r):
    """`_blur` of a float32 image runs in the core (`_core.blur`); it is three numpy
    `_box_blur` passes each way, bit for bit, at narrow and wide windows, at images smaller than
    the window, and with the signed zeros and large values a frame can hold; a float64 image
    stays in numpy. A bad array is refused naming it."""
    from physcore import _core
    from physcore.render._raster import _blur, _box_blur

    rng = np.random.default_rng(r)
    a = (rng.random(shape) * rng.choice([1e-3, 1.0, 3e4], shape)).astype(np.float32)
    a[rng.random(shape) < 0.1] = -0.0
    want = a
    for _ in range(3):
        want = _box_blur(_box_blur(want, r, 0), r, 1)
    got = _blur(a, r)
    assert got.dtype == np.float32 and got.shape == shape
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert np.array_equal(_core.blur(np.asfortranarray(a) if min(shape) == 1 else a, r).view(np.uint32), want.view(np.uint32))
    a64 = a.astype(np.float64)
    want64 = a64
    for _ in range(3):
        want64 = _box_blur(_box_blur(want64, r, 0), r, 1)
    assert np.array_equal(_blur(a64, r), want64)
    if min(shape) > 1:
        with pytest.raises(ValueError, match="a: array must be C-contiguous"):
            _core.blur(np.asfortranarray(a), r)


def test_the_core_refuses_fortran_ordered_point_arrays():
    """A Fortran-ordered (N, 2) array is contiguous, but its memory holds the columns: the core's
    point arrays refuse it (the facade hands them C order), rather than read x as y."""
    from physcore import _core

    x = np.random.default_rng(0).random((50, 2))
    with pytest.raises(ValueError, match="C-contiguous"):
        _core.neighbors(np.asfortranarray(x), 0.2)
    assert all(np.array_equal(p, q) for p, q in zip(_core.neighbors(x, 0.2), pc.neighbors(np.asfortranarray(x), 0.2), strict=True))


def test_glow_splat_keeps_every_particle_inside_the_image():
    """Bilinear splatting conserves the count: a particle in the image adds exactly 1 in all
    (its four weights), one outside adds nothing, a NaN is dropped; the centre of mass of a
    particle's weights is where it is."""
    from physcore.render._raster import _splat

    col = np.array([10.5, 3.25, 30.9, -5.0, np.nan, 15.0])
    row = np.array([4.5, 7.75, 1.2, 3.0, 2.0, 200.0])
    d = _splat(col, row, (20, 40)).astype(np.float64)
    assert abs(d.sum() - 3.0) < 1e-6
    one = _splat(col[1:2], row[1:2], (20, 40)).astype(np.float64)
    yy, xx = np.mgrid[0:20, 0:40] + 0.5
    assert abs((one * xx).sum() - 3.25) < 1e-6 and abs((one * yy).sum() - 7.75) < 1e-6


def _numpy_splat(col, row, shape, weights=None):
    """The renderer's splat as numpy computed it before it moved into the core (`_core.splat`
    keeps its arithmetic): the four corners' weights concatenated, added up by bincount."""
    h, w = shape
    fx, fy = col - 0.5, row - 0.5
    ok = (fx > -1) & (fx < w) & (fy > -1) & (fy < h)
    fx, fy = fx[ok], fy[ok]
    x0, y0 = np.floor(fx), np.floor(fy)
    ax, ay = (fx - x0).astype(np.float32), (fy - y0).astype(np.float32)
    wp = w + 2
    base = (y0.astype(np.int64) + 1) * wp + (x0.astype(np.int64) + 1)
    bx = 1.0 - ax
    idx = np.concatenate([base, base + 1, base + wp, base + wp + 1])
    wgt = np.concatenate([bx * (1.0 - ay), ax * (1.0 - ay), bx * ay, ax * ay])
    if weights is not None:
        wgt = wgt * np.tile(weights[ok].astype(np.float32), 4)
    return np.bincount(idx, weights=wgt, minlength=(h + 2) * wp).reshape(h + 2, wp)[1 : h + 1, 1 : w + 1].astype(np.float32)


def test_the_cores_splat_is_numpys_bit_for_bit():
    """`_core.splat` against the numpy version it replaced (the same corners in the same order
    of addition): crowded points (many in one pixel, so the order of the additions shows),
    points on pixel edges, just inside and outside the image's border, negative fractions,
    NaN and infinities, with and without weights."""
    from physcore.render._raster import _splat

    rng = np.random.default_rng(7)
    n = 200_000
    col = np.concatenate([rng.normal(20.0, 3.0, n), rng.uniform(-2.0, 42.0, 1000), [0.0, 0.5, -0.5, -0.49, 40.5, 40.49,
                                                                                  39.5, 1.0, np.nan, np.inf, -np.inf]])
    row = np.concatenate([rng.normal(10.0, 2.0, n), rng.uniform(-2.0, 22.0, 1000), [0.0, 0.5, 3.0, 3.0, 3.0, 3.0,
                                                                                  20.49, 20.5, 1.0, 2.0, 3.0]])
    weights = rng.uniform(0.0, 2.0, col.size).astype(np.float32)
    for w in (None, weights):
        ours, numpy = _splat(col, row, (20, 40), w), _numpy_splat(col, row, (20, 40), w)
        assert ours.dtype == np.float32 and np.array_equal(ours, numpy)
        assert ours.sum() > 0.9 * n


def test_title_top_left_and_checked(tmp_path):
    """A title is drawn top left in the text colour and kept clear of particles; a long one is
    cut before the colour bar; a non-str or multi-line title is refused naming it."""
    from physcore.render._colorbar import _text_mask

    scene = pc.Scene(dim=2)
    scene.add_particles([[0.0, 0.0], [1.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]])
    img = frames_rgb(render.gif(scene, tmp_path / "t.gif", frames=1, size=(240, 180), title="Two balls"))[0]
    mask = _text_mask("Two balls")
    ink = np.all(img[3 : 3 + mask.shape[0], 4 : 4 + mask.shape[1]] == TEXT_RGB, axis=-1)
    assert np.array_equal(ink, mask)
    long = frames_rgb(render.gif(scene, tmp_path / "l.gif", frames=1, size=(240, 180), title="x" * 120))[0]
    bar = np.nonzero(np.all(long[:14] == TEXT_RGB, axis=-1).any(axis=0))[0]
    assert bar.max() > 200  # the colour bar is still there, at the right
    render.gif(scene, tmp_path / "u.gif", frames=1, size=(240, 180), title="σ = 10, ρ = 28")  # drawn as "?"
    with pytest.raises(TypeError, match="title"):
        render.gif(scene, tmp_path / "x.gif", frames=1, title=3)
    with pytest.raises(ValueError, match="title"):
        render.gif(scene, tmp_path / "x.gif", frames=1, title="a\nb")


def test_a_recording_draws_as_its_scene_would(tmp_path):
    """record() keeps the colouring it recorded and the scene's render_defaults, so gif(rec)
    with no options draws what gif(scene) would: the galaxies' glow on the dark theme (a
    recording without speeds used to be refused for the default colour_by='speed')."""
    rec = render.record(pc.scenes.galaxies(n=400), frames=3)
    assert rec.color_by == "density" and rec.speeds is None and rec.defaults["theme"] == "dark"
    img = frames_rgb(render.gif(rec, tmp_path / "g.gif"))[0]
    dark = tuple(int(v) for v in render._palette._DARK_PALETTE[_palette._BACKGROUND])
    assert tuple(int(v) for v in img[2, 2]) == dark
    assert img.shape[:2] == (400, 480)  # the scene's size, (480, 400)
    none = render.record(pc.scenes.kepler(), frames=2, color_by="none")
    render.gif(none, tmp_path / "k.gif")  # draws with one colour, as recorded


# ----------------------------------------------------------- GIF writer: frame differences
def _decoded_gif(path, tick_ms=None):
    """The GIF's frames as int RGB arrays; with `tick_ms`, each repeated for as many ticks as it
    shows (a frame without change lengthens the previous one instead of being stored)."""
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        out = [(np.asarray(f.convert("RGB")).astype(int), f.info["duration"]) for f in ImageSequence.Iterator(im)]
    if tick_ms is None:
        return [f for f, _ in out]
    return [f for f, ms in out for _ in range(round(ms / tick_ms))]


def _moving_square_frames(n=10, size=(80, 64)):
    """A static ramp (every column its own index) with two 6-pixel squares moving over it in
    opposite corners (so the box of each frame's changes is most of the frame)."""
    w, h = size
    base = np.tile((np.arange(w) * 200 // w).astype(np.uint8), (h, 1))
    out = []
    for k in range(n):
        f = base.copy()
        f[2:8, 2 + k : 8 + k] = 250
        f[h - 8 : h - 2, w - 8 - k : w - 2 - k] = 251
        out.append(f)
    return out


def test_gif_writer_stores_frame_differences_and_decodes_to_the_frames(tmp_path, monkeypatch):
    from physcore.render import _gif

    colours = np.stack([np.arange(256), 255 - np.arange(256), np.full(256, 90)], axis=1).astype(np.uint8)
    frames = _moving_square_frames()
    _gif._write_gif(tmp_path / "diff.gif", iter(frames), [40] * len(frames), colours, tolerance=0)
    decoded = _decoded_gif(tmp_path / "diff.gif")
    assert len(decoded) == len(frames)
    for f, d in zip(frames, decoded, strict=True):
        assert np.array_equal(colours[f].astype(int), d)  # exactly the frames drawn
    # No free index for the transparent pixels: each frame stored whole in the box of its
    # changes (as before frame differences), the same pictures in more bytes.
    monkeypatch.setattr(_gif, "_transparent_slot", lambda frames, colours: None)
    _gif._write_gif(tmp_path / "whole.gif", iter(frames), [40] * len(frames), colours, tolerance=0)
    assert all(np.array_equal(a, b) for a, b in zip(decoded, _decoded_gif(tmp_path / "whole.gif"), strict=True))
    assert (tmp_path / "diff.gif").stat().st_size < 0.6 * (tmp_path / "whole.gif").stat().st_size


def test_gif_writer_tolerance_bounds_the_error_and_never_accumulates(tmp_path):
    from physcore.render import _gif

    grey = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, axis=1)
    rng = np.random.default_rng(4)
    # A field creeping up by one or two levels a frame, with one-level flicker: each step is
    # within the tolerance of 4, the drift over the run far beyond it.
    frames = [np.clip(100 + 2 * k + rng.integers(-1, 2, (40, 48)), 0, 255).astype(np.uint8) for k in range(20)]
    _gif._write_gif(tmp_path / "t.gif", iter(frames), [40] * len(frames), grey, tolerance=4)
    decoded = _decoded_gif(tmp_path / "t.gif", tick_ms=40)
    assert len(decoded) == len(frames)
    errors = [np.abs(grey[f].astype(int) - d).max() for f, d in zip(frames, decoded, strict=True)]
    assert max(errors) <= 4 and max(errors) > 0  # lagging by up to the tolerance, never more
    assert np.abs(decoded[-1] - decoded[0]).mean() > 30  # the drift shows


def test_full_colour_gif_keeps_a_transparent_slot_and_the_frames(tmp_path):
    # Soft discs: an adaptive palette of 255 colours, the 256th transparent; the decoded frames
    # are those drawn up to that palette (as before), every frame kept.
    rec = pc.render.record(pc.scenes.kepler(e=0.6), frames=10)
    drawn = list(pc.render.frames(rec, size=(96, 72)))
    decoded = _decoded_gif(pc.render.gif(rec, tmp_path / "k.gif", size=(96, 72)))
    assert len(decoded) == len(drawn)
    for a, b in zip(drawn, decoded, strict=True):
        assert np.abs(a.astype(int) - b).mean() < 1.0


def test_field_gif_is_its_frames_up_to_the_field_tolerance(tmp_path):
    from physcore.render._gif import FIELD_GIF_TOLERANCE

    rec = pc.render.record(pc.scenes.ripple(n=48), frames=10, frame_time=0.04)
    drawn = list(pc.render.frames(rec, size=(96, 96), fps=25))
    decoded = _decoded_gif(pc.render.gif(rec, tmp_path / "t.gif", size=(96, 96), fps=25), tick_ms=40)
    assert len(decoded) == len(drawn)
    assert np.abs(decoded[-1] - decoded[0]).max() > 50  # the ripples move
    for a, b in zip(drawn, decoded, strict=True):
        assert np.abs(a.astype(int) - b).max() <= FIELD_GIF_TOLERANCE


def test_field_labels_dimensionless_clock_and_a_scale_from_zero():
    from physcore.render._fields import FieldRasteriser

    f = np.random.default_rng(0).random((3, 16, 16)).astype(np.float32) * 0.9 + 0.001  # >= 0, low end ~0
    times = np.array([0.0, 1.0, 2.0])
    gs = FieldRasteriser(f, "turing", (100, 100), None, (1.0, 1.0), times=times, label="v")
    assert gs.time_unit == "" and gs.lo == 0.0  # Gray–Scott: no unit; a non-negative field from 0
    speed = FieldRasteriser(f, "turing", (100, 100), None, (1.0, 1.0), times=times, label="speed m/s")
    assert speed.time_unit == "s" and speed.lo == 0.0
    shifted = FieldRasteriser(f + 5.0, "turing", (100, 100), None, (1.0, 1.0), times=times, label="T")
    assert shifted.lo > 5.0  # far from 0: the scale keeps its low percentile


def test_a_colour_scale_ends_on_a_round_number_within_two_percent():
    # The scale's end is a percentile of the run's field: a smoke concentration of at most 1
    # gave "0.999", which reads as an error. Raised to a round number within 2 %, else kept.
    from physcore.render._fields import FieldRasteriser, _round_top

    rng = np.random.default_rng(1)
    for top, want in ((0.999, 1.0), (0.0493, 0.05), (7.9, 8.0), (0.0487, 0.0487), (2.37, 2.37), (1.0, 1.0)):
        f = (rng.random((2, 32, 32)) * top).astype(np.float64)
        f[:, :, :8] = top  # a quarter of the field at its top: the 99.5th percentile is `top`
        for style in ("smoke", "turing", "signed"):
            r = FieldRasteriser(f, style, (100, 100), None, (1.0, 1.0))
            assert r.hi == pytest.approx(want, rel=1e-12), (top, style, r.hi)
            assert r.hi >= top * (1 - 1e-12)  # never clips the field's top
    assert _round_top(0.0) == 0.0 and np.isnan(_round_top(float("nan")))


def test_a_stable_fluids_scalar_is_labelled_smoke_or_dye_not_density():
    """The fluid's `density` is a passive 0..1 scalar: the colour bar calls it smoke where
    buoyancy lifts it and dye otherwise (the cavity's bands, the vortex street's streaks)."""
    from physcore.render._recording import _field_label

    def label(scene, field="density"):
        return _field_label({"field": field, "grid": scene.grids[0]})

    assert label(pc.scenes.smoke(n=16)) == "smoke"
    assert label(pc.scenes.cavity(n=16)) == "dye"
    assert label(pc.scenes.vortex_street(n=4)) == "dye"
    assert label(pc.scenes.cavity(n=16), "speed") == "speed (m/s)"


def test_a_segment_wholly_outside_the_image_draws_nothing():
    """A line from inside the image to a point beyond float32's pixels (a scene about to diverge)
    draws its part inside; one wholly outside draws nothing (neither fails)."""
    from physcore.render._raster import _draw_lines

    buf = np.zeros((360, 480), np.uint8)
    _draw_lines(buf, np.array([38.0]), np.array([173.0]), np.array([3.1e39]), np.array([1.6e38]), np.array([3], np.uint8))
    rows, cols = np.nonzero(buf)
    # What is drawn is the part inside the image: from (38, 173) towards the far point (its
    # direction, slope 1.6/31), one pixel a column.
    assert set(np.unique(buf)) == {0, 3} and cols.min() <= 39 and cols.max() >= 478
    assert np.allclose(rows, 173 + (cols - 38) * 1.6e38 / 3.1e39, atol=1.5)
    rgb = np.zeros((20, 20, 3), np.uint8)
    _draw_lines(rgb, np.array([-50.0]), np.array([-50.0]), np.array([-40.0]), np.array([-60.0]), np.array([[255, 0, 0]], np.uint8))
    assert not rgb.any()


def test_a_recording_whose_books_blew_up_warns_and_a_sound_one_does_not():
    """A cloth at three substeps a frame (some 200 times its stable step) reaches 1e45 J in ten
    frames with every value finite, so nothing raises: the recording warns, naming the step
    that would hold; the default scene's books close and say nothing."""
    import warnings

    with pytest.warns(pc.EnergyBooksWarning, match=r"off by \+1 of the energy in play.*suggest_dt\(\) = 5.71e-05 s"):
        pc.render.record(pc.scenes.cloth(), frames=10, frame_time=1 / 30, substeps=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", pc.EnergyBooksWarning)
        pc.render.record(pc.scenes.cloth(), frames=10)


@pytest.mark.parametrize("scene", [None, "cloth", 3])
def test_what_is_no_scene_is_refused_naming_the_argument(tmp_path, scene):
    """``gif(None, ...)`` failed deep inside: AttributeError "'NoneType' object has no attribute 'dim'"."""
    with pytest.raises(pc.InvalidTypeError, match=r"^scene: expected a physcore Scene, Batch or Recording, got "):
        pc.render.gif(scene, tmp_path / "x.gif")
    assert list(tmp_path.iterdir()) == []


def test_a_lead_in_steps_as_the_frames_do():
    """A scene of fixed steps with a lead-in: ``advance`` set its dt to one of its own (1.785e-4
    s for the double pendulum's 1.01e-4), and the frames, counted in steps of the dt before,
    then lay 1.77 frame times apart. The lead-in now takes fixed steps too."""
    s = pc.scenes.double_pendulum(n=2)
    dt = s.dt
    rec = pc.render.record(s, frames=4)
    assert s.dt == dt
    assert rec.times[0] == pytest.approx(3.0, abs=dt)
    np.testing.assert_allclose(np.diff(rec.times), 1 / 30, atol=dt)


def test_dither_mixes_the_shades_of_a_ramp_and_is_checked_by_name(tmp_path):
    """``dither=True`` rounds each pixel of a field up or down by Bayer's ordered dither: a smooth
    ramp drawn in few shades (the cavity's dye had visible steps) then has the ramp's value on
    average over every 8 × 8 tile, two shades mixed where it lies between them, the same
    pixels every time and in every frame where the field stands still; a value that is no bool
    is refused naming `dither`, from the call or from the scene's render_defaults."""
    from physcore.render._fields import FieldRasteriser, _image, palette

    scene = pc.Scene(2, dt=1e-2)
    fluid = scene.add(pc.StableFluid((64, 8), 1 / 64, name="tank"))
    # A slow ramp (0.3 to 0.45 over 40 cells, a few shades) between patches of 0 and 1 (the scale).
    ramp = np.concatenate([np.zeros(12), np.linspace(0.3, 0.45, 40), np.ones(12)])
    fluid.density = np.broadcast_to(ramp[:, None], (64, 8)).copy()
    scene.render_defaults = {"style": "turing", "field": "density"}
    rec = render.record(scene, frames=2, frame_time=0.05)  # at rest: the field stands still
    index = {tuple(c): k for k, c in enumerate(palette("turing")[:255])}

    def drawn(**kw):
        frames = [f for f in render.frames(rec, size=(256, 32), colorbar=False, **kw)]
        assert frames[0].shape == (32, 256, 3)
        return [np.array([[index[tuple(p)] for p in row] for row in f], dtype=float) / 254 for f in frames]

    plain, dithered = drawn(dither=False), drawn(dither=True)
    assert np.array_equal(dithered[0], dithered[1])  # a still field stays still: nothing to store
    # The ramp as drawn before its shades are rounded, per 8 × 8 tile (the mean over the tile).
    fr = FieldRasteriser(rec.fields, "turing", (256, 32), None, rec.field_extent)
    ramp = np.clip((_image(rec.fields[0], (256, 32)) - fr.lo) / (fr.hi - fr.lo), 0.0, 1.0)

    def tiles(a):
        return a.reshape(4, 8, 32, 8).mean(axis=(1, 3))

    want = tiles(ramp)
    mid = slice(8, 24)  # the tiles over the ramp's middle, away from the patches' edges
    err_plain = np.abs(tiles(plain[0]) - want)[:, mid].mean()
    err_dith = np.abs(tiles(dithered[0]) - want)[:, mid].mean()
    assert err_dith < 0.25 * err_plain, (err_dith, err_plain)
    # Locally two shades where the ramp lies between them; undithered, flat bands.
    mixed = [np.mean([len(np.unique(t)) > 1 for t in f[0].reshape(4, 8, 32, 8).transpose(0, 2, 1, 3)[:, mid].reshape(-1, 64)])
             for f in (plain, dithered)]
    assert mixed[1] > 0.8 and mixed[0] < 0.3, mixed
    # Deterministic: the same GIF, byte for byte.
    a = render.gif(rec, tmp_path / "a.gif", size=(256, 32), dither=True).read_bytes()
    b = render.gif(rec, tmp_path / "b.gif", size=(256, 32), dither=True).read_bytes()
    assert a == b and a != render.gif(rec, tmp_path / "c.gif", size=(256, 32)).read_bytes()
    # The scene's default: on for the cavity, off elsewhere; a bad value refused by name.
    assert pc.scenes.cavity.render_defaults["dither"] is True and "dither" not in pc.scenes.smoke.render_defaults
    scene.render_defaults["dither"] = True
    assert render.gif(scene, tmp_path / "d.gif", frames=2, frame_time=0.05, size=(256, 32)).read_bytes() == a
    t = scene.time
    for bad in ("yes", 1, None):
        scene.render_defaults["dither"] = bad
        with pytest.raises(pc.PhyscoreError, match="dither"):
            render.gif(scene, tmp_path / "e.gif", frames=2, size=(256, 32))
        with pytest.raises(pc.PhyscoreError, match="dither"):
            render.gif(rec, tmp_path / "e.gif", size=(256, 32), dither=bad if bad is not None else "on")
    assert not (tmp_path / "e.gif").exists() and scene.time == t  # refused before a step


def _glow(h: int, w: int) -> np.ndarray:
    """(h, w, 3) float64: a warm glow fading over a dark background, a blue wedge over its left
    half and a flat strip of background on top: over 255 colours in all, so some fall between
    a GIF palette's (the look of kepler's sun under its swept areas)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    bg = np.array([12, 14, 24], dtype=np.float64)
    glow = np.exp(-((x - 128) ** 2 + (y - 48) ** 2) / (2 * 40.0**2))[..., None]
    frame = bg + glow * (np.array([255, 214, 120]) - bg)
    frame[:, : w // 2] = 0.6 * frame[:, : w // 2] + 0.4 * np.array([40, 90, 160])
    frame[:8] = bg
    return frame


def test_dither_of_full_colour_frames_mixes_a_glows_colours_and_keeps_the_flat_ones_exact():
    """Full-colour frames are put on one palette of 255 colours: a smooth glow over colours the
    palette cannot all hold drew rings (Kepler's sun under the swept areas). With ``dither``
    each 8 × 8 tile of the glow has on average the colours drawn, much closer than the nearest
    colours alone; the flat colours (the background, a disc) stay exact, and the same frames
    give the same indices."""
    from physcore.render._gif import _palette_frames

    h, w = 96, 256
    frame = _glow(h, w)
    frame[40:56, 120:136] = [255, 214, 120]  # a flat disc
    frame = frame.round().astype(np.uint8)
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 600

    def decoded(dither: bool) -> np.ndarray:
        images, colours = _palette_frames([frame, frame], n_colours=255, dither=dither)
        pal = np.frombuffer(colours, np.uint8).reshape(-1, 3)
        a, b = (np.asarray(im) for im in images)
        assert np.array_equal(a, b)  # the same frame: the same indices
        return pal[a].astype(np.float64)

    def tile_error(img: np.ndarray) -> float:
        t = lambda a: a.reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))  # noqa: E731
        return float(np.abs(t(img) - t(frame.astype(np.float64))).mean())

    plain, dithered = decoded(False), decoded(True)
    assert tile_error(dithered) < 0.25 * tile_error(plain), (tile_error(dithered), tile_error(plain))
    for img in (plain, dithered):  # the flat colours exact
        assert np.array_equal(img[40:56, 120:136], frame[40:56, 120:136].astype(np.float64))
        assert np.array_equal(img[:8], frame[:8].astype(np.float64))


@pytest.mark.parametrize("grey", [0, 64, 128, 200, 255])
def test_ordered_dither_between_two_colours_has_the_mean_of_the_colour_drawn(grey):
    """On a palette of black and white, each 8 × 8 tile of a flat grey g takes white at the
    pixels whose Bayer threshold is below g/255: round(64 g / 255) of 64 (to within the
    thresholds' spacing), so the tile's mean is g to within 4 levels; a palette of one colour
    gives that colour everywhere (nothing to mix), not an error."""
    from physcore.render._gif import _ordered_indices

    frame = np.full((16, 24, 3), grey, dtype=np.uint8)
    pal = np.array([[0, 0, 0], [255, 255, 255]], dtype=np.uint8)
    idx = _ordered_indices(frame, pal)
    assert idx.shape == (16, 24) and set(np.unique(idx)) <= {0, 1}
    tiles = pal[idx][..., 0].astype(np.float64).reshape(2, 8, 3, 8).mean(axis=(1, 3))
    assert np.all(np.abs(tiles - grey) <= 4.0), tiles
    assert np.array_equal(_ordered_indices(frame, pal[:1]), np.zeros((16, 24), dtype=np.uint8))


def test_dither_of_full_colour_frames_leaves_no_lone_specks_and_keeps_thin_lines_solid():
    """A glow fading into a dark background is drawn by mixing close shades only: no pixel of a
    smooth region is more than 16 levels off the colour drawn (mixing in a far colour at a small
    ratio left lone bright specks on kepler's glow edge: 50 levels off). A thin antialiased line
    (an edge: over DITHER_EDGE levels from its neighbours) takes its nearest colour, pixel for
    pixel, so it reads solid, not dotted."""
    from physcore.render._gif import DITHER_EDGE, _edges, _palette_frames

    h, w = 96, 256
    frame = _glow(h, w)
    frame[20, 10:240] = 0.5 * frame[20, 10:240] + 0.5 * np.array([235, 235, 235])  # half a pixel's cover
    frame = frame.round().astype(np.uint8)
    images, colours = _palette_frames([frame], n_colours=255, dither=True)
    pal = np.frombuffer(colours, np.uint8).reshape(-1, 3)[:255].astype(np.float64)
    idx = np.asarray(images[0])
    off = np.abs(pal[idx] - frame).max(axis=2)
    edge = _edges(frame, DITHER_EDGE)
    assert edge[20, 10:240].all() and not edge[30:90, 20:120].any() and not edge[30:90, 136:236].any()
    assert off[~edge].max() <= 16, np.percentile(off[~edge], [99, 99.9, 100])
    line = frame[20, 10:240].astype(np.float64)
    nearest = ((line[:, None] - pal[None]) ** 2).sum(axis=2).min(axis=1)
    assert np.array_equal(((pal[idx[20, 10:240]] - line) ** 2).sum(axis=1), nearest)


def test_extent_errors_name_what_is_wrong(tmp_path):
    x = np.array([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(pc.InvalidInputError, match=r"extent: lower must be <= upper on every axis, got lower \[3.0, 3.0\]"):
        render.render_frame(x, extent=((3, 3), (-3, -3)))
    with pytest.raises(pc.InvalidInputError, match=r"extent: expected \(lower, upper\), two finite points of 2 coordinates, got shape \(3,\)"):
        render.render_frame(x, extent=(0, 1, 2))
    # The drawing is float32: ±1e308 overflowed in a cast with numpy's bare RuntimeWarning.
    scene = pc.Scene(3)
    scene.add_particles(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 1]]))
    with pytest.raises(pc.InvalidInputError, match=r"^extent: coordinates must be within ±1e38 m"):
        render.gif(scene, tmp_path / "e.gif", frames=2, size=(32, 32), extent=([-1e308] * 3, [1e308] * 3))
    assert scene.time == 0.0 and not (tmp_path / "e.gif").exists()
    with pytest.raises(pc.InvalidInputError, match=r"path must end in \.gif, got .*; pc\.render\.save\(scene, 'x\.mp4'\) writes \.mp4"):
        render.gif(pc.scenes.projectile(), tmp_path / "x.mp4")
