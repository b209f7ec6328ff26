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
    from PIL import Image as PILImage

    def broken_save(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(PILImage.Image, "save", broken_save)
    with pytest.raises(OSError, match="disk full"):
        render.gif(pendulum_pair(), tmp_path / "x.gif", frames=2, size=(32, 32))
    assert list(tmp_path.iterdir()) == []
