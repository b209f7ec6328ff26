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
