"""Frames drawn side by side on threads (physcore.render._threads): a liquid's frames come out the
same, bit for bit, whatever the number of drawing threads; they come in frame order; an error in
a frame is raised at its turn; closing the frames early stops the drawing."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import physcore as pc
from physcore.render import _threads


@pytest.fixture(scope="module")
def liquids():
    """A 3D (lit surface, glass walls) and a 2D (blurred density) liquid, 16 frames each, moving
    from the first frame (a dam break collapsing)."""
    three = pc.render.record(pc.scenes.dam_break(dim=3, n=8), frames=16, frame_time=0.02)
    two = pc.render.record(pc.scenes.dam_break(n=24), frames=16, frame_time=0.02)
    return three, two


def _drawn(rec, workers, monkeypatch, **options):
    monkeypatch.setattr(_threads, "workers", lambda: workers)
    return np.stack(list(pc.render.frames(rec, size=(240, 180), **options)))


@pytest.mark.parametrize("which", [0, 1], ids=["3d", "2d"])
def test_a_liquids_frames_do_not_depend_on_the_drawing_threads(liquids, which, monkeypatch):
    rec = liquids[which]
    one = _drawn(rec, 1, monkeypatch)
    assert len({f.tobytes() for f in one}) == len(one)  # every frame differs: a mix-up would show
    for n in (2, 5):
        assert np.array_equal(_drawn(rec, n, monkeypatch), one), n


def test_the_gif_bytes_do_not_depend_on_the_drawing_threads(monkeypatch, tmp_path):
    rec = pc.render.record(pc.scenes.dam_break(dim=3, n=8), frames=8, frame_time=0.03, color_by="pressure")
    files = []
    for n in (1, 3):
        monkeypatch.setattr(_threads, "workers", lambda n=n: n)
        files.append(pc.render.gif(rec, tmp_path / f"{n}.gif", size=(240, 180), color_by="pressure").read_bytes())
    assert files[0] == files[1]


def test_only_frames_drawn_from_their_index_alone_are_drawn_side_by_side(liquids, monkeypatch):
    # A liquid's surface and discs are; a glow (color_by="density": with trails each frame
    # decays the last one's) and a cloth (its mesh shader keeps what it drew for the shadows
    # after it) are drawn one frame after another.
    asked = []
    original = _threads.in_order

    def in_order(draw, count, parallel=True):
        asked.append(parallel)
        return original(draw, count, parallel)

    monkeypatch.setattr(_threads, "in_order", in_order)
    rec = liquids[1]
    list(pc.render.frames(rec, size=(120, 90)))
    list(pc.render.frames(rec, size=(120, 90), surface=False, antialias=True))
    list(pc.render.frames(rec, size=(120, 90), surface=False, antialias=False))
    glow = pc.render.record(pc.scenes.galaxies(n=200), frames=4, color_by="density")
    list(pc.render.frames(glow, size=(120, 90), trail=3))
    cloth = pc.render.record(pc.scenes.cloth(n=6), frames=3, frame_time=0.02)
    list(pc.render.frames(cloth, size=(120, 90)))
    assert asked == [True, True, True, False, False]


def test_in_order_keeps_the_order_and_raises_a_frames_error_at_its_turn(monkeypatch):
    monkeypatch.setattr(_threads, "workers", lambda: 4)

    def draw(k):
        time.sleep(0.02 * ((7 * k) % 5))  # later frames often finish first
        if k == 9:
            raise ValueError("frame 9")
        return k

    got = []
    with pytest.raises(ValueError, match="frame 9"):
        for k in _threads.in_order(draw, 20):
            got.append(k)
    assert got == list(range(9))
    assert list(_threads.in_order(lambda k: k * k, 30)) == [k * k for k in range(30)]
    assert list(_threads.in_order(lambda k: k, 30, parallel=False)) == list(range(30))


def test_closing_the_frames_early_stops_the_drawing(monkeypatch):
    monkeypatch.setattr(_threads, "workers", lambda: 3)
    started = []
    lock = threading.Lock()

    def draw(k):
        with lock:
            started.append(k)
        time.sleep(0.01)
        return k

    it = _threads.in_order(draw, 1000)
    assert [next(it) for _ in range(5)] == [0, 1, 2, 3, 4]
    it.close()  # waits for the frames being drawn, cancels the rest
    n = len(started)
    time.sleep(0.1)
    assert len(started) == n  # nothing more was drawn after the close
    assert n <= 5 + 2 * 3  # at most two frames a thread ahead of the reader
    assert not [t for t in threading.enumerate() if t.name.startswith("physcore-draw")]


def test_the_drawing_threads_follow_the_threads_set_for_the_context(monkeypatch):
    from physcore.scene import DEFAULT_THREADS

    token = DEFAULT_THREADS.set(1)
    try:
        assert _threads.workers() == 1
    finally:
        DEFAULT_THREADS.reset(token)
    monkeypatch.setattr(pc._core, "default_threads", lambda: 64)
    assert _threads.workers() == _threads.MAX_WORKERS
    monkeypatch.setattr(pc._core, "default_threads", lambda: 3)
    assert _threads.workers() == 3


@pytest.mark.parametrize("name", sorted(pc.scenes.REGISTRY))
def test_every_scenes_frames_are_the_same_drawn_side_by_side(name, monkeypatch):
    """Each ready-made scene's first frames (its own look, a smaller image), drawn one by one and
    by three threads: the same pixels. Guards :attr:`_Rasteriser.frames_independent` against a
    drawing path that keeps state from one frame to the next."""
    rec = pc.render.record(pc.scenes.REGISTRY[name](), frames=6)
    one = _drawn(rec, 1, monkeypatch)
    assert np.array_equal(_drawn(rec, 3, monkeypatch), one)


# --------------------------------------------------------------------------- bodies' polygons
def test_the_cores_polygon_fill_is_the_numpy_reference_byte_for_byte():
    """``_core.fill_polygons`` (the 2D bodies, all of a frame in one call) against
    ``_bodies._fill`` (numpy, one polygon at a time) on random convex polygons over a textured
    image: boxes, many-sided balls, slivers, ones reaching past the edges, a repeated vertex, a
    degenerate one, overlapping in order."""
    from physcore.render._bodies import _fill

    rng = np.random.default_rng(5)
    h, w = 90, 120
    base = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    polys, colours = [], []
    for k in range(60):
        sides = int(rng.choice([3, 4, 4, 6, 16, 24]))
        centre = rng.uniform([-10, -10], [w + 10, h + 10])
        radius = rng.uniform(0.3, 30.0)
        ang = np.sort(rng.uniform(0, 2 * np.pi, sides))
        stretch = rng.uniform(0.2, 1.0)
        poly = centre + np.stack([radius * np.cos(ang), stretch * radius * np.sin(ang)], axis=1)
        if k % 7 == 0:
            poly = np.concatenate([poly[:1], poly])  # a repeated vertex: a zero-length edge
        if k % 11 == 0:
            poly = poly[::-1]  # the other winding
        polys.append(poly)
        colours.append(rng.integers(0, 256, 3, dtype=np.uint8))
    polys.append(np.array([[10.0, 10.0], [20.0, 10.0], [30.0, 10.0]]))  # degenerate: a line
    colours.append(np.array([255, 0, 0], np.uint8))
    ref = base.copy()
    for poly, c in zip(polys, colours, strict=True):
        _fill(ref, poly, c)
    got = base.copy()
    starts = np.concatenate([[0], np.cumsum([len(p) for p in polys])]).astype(np.uint64)
    pc._core.fill_polygons(got, np.concatenate(polys), starts, np.stack(colours))
    assert not np.array_equal(ref, base)  # something was drawn
    assert np.array_equal(got, ref), int(np.abs(got.astype(int) - ref).max())


def test_the_polygon_fill_refuses_inconsistent_arrays():
    img = np.zeros((4, 4, 3), np.uint8)
    v = np.zeros((3, 2))
    with pytest.raises(pc.InvalidInputError, match="starts"):
        pc._core.fill_polygons(img, v, np.array([0, 2], np.uint64), np.zeros((1, 3), np.uint8))
    with pytest.raises(pc.InvalidInputError, match="colours"):
        pc._core.fill_polygons(img, v, np.array([0, 3], np.uint64), np.zeros((2, 3), np.uint8))
    with pytest.raises(pc.InvalidInputError, match="starts"):  # 2 · 2⁶³ vertices would wrap to 0
        pc._core.fill_polygons(img, np.zeros((0, 2)), np.array([0, 2**63], np.uint64), np.zeros((1, 3), np.uint8))
    with pytest.raises(pc.InvalidInputError, match="verts"):
        pc._core.fill_polygons(img, np.zeros((3, 3)), np.array([0, 3], np.uint64), np.zeros((1, 3), np.uint8))
