"""Frames drawn side by side on threads, handed on in order.

A frame of a big liquid (10⁶ particles) takes about 0.13 s to draw on one core, most of it in
numpy and in the core's raster kernels, which both release the GIL; drawing 120 such frames one
after another left a many-core machine idle for 16 s after the simulation (GPU or CPU) was done.
Frames whose drawing keeps no state from one frame to the next (all but a glow and a shaded
mesh: see ``_Rasteriser.frames_independent``) are drawn here by a small pool of threads, at most
``2 · workers`` ahead of the consumer, and handed on in frame order: the same images, bit for
bit, as drawn one by one (each frame is a function of its index alone; the caches the drawing
fills on the way are the same whatever frame fills them), so the file's bytes do not depend on
the thread count (tested).
"""
from __future__ import annotations

import collections
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from .. import _core

T = TypeVar("T")

#: Frames in flight at most: each holds its own temporaries (about 100 MB for 10⁶ particles).
MAX_WORKERS = 8


def workers() -> int:
    """Threads that draw frames: the core's default (all cores, or ``RAYON_NUM_THREADS``), or
    the thread count a caller set for scenes made in this context (``physcore.sweep`` sets 1 in
    each run), at most MAX_WORKERS."""
    from ..scene import DEFAULT_THREADS

    n = DEFAULT_THREADS.get()
    if n is None:
        n = _core.default_threads()
    return max(1, min(int(n), MAX_WORKERS))


def in_order(draw: Callable[[int], T], count: int, parallel: bool = True) -> Iterator[T]:
    """``draw(0), draw(1), …, draw(count − 1)`` in that order; with `parallel`, frame 0 alone
    (it fills the drawing's caches) and then the rest by :func:`workers` threads, at most
    ``2 · workers`` frames ahead of the reader. An error in a frame is raised when its turn
    comes; closing the iterator early (or Ctrl-C while it waits) cancels the frames not begun
    and waits for those being drawn (a fraction of a second)."""
    n = workers() if parallel else 1
    if n <= 1 or count <= 2:
        for k in range(count):
            yield draw(k)
        return
    yield draw(0)
    pool = ThreadPoolExecutor(n, thread_name_prefix="physcore-draw")
    pending: collections.deque[Any] = collections.deque()
    try:
        k = 1
        while k < count or pending:
            while k < count and len(pending) < 2 * n:
                pending.append(pool.submit(draw, k))
                k += 1
            yield pending.popleft().result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def map_frames(fn: Callable[[int], T], count: int, parallel: bool = True) -> list[T]:
    """``[fn(0), …, fn(count − 1)]``, computed by :func:`workers` threads (for reductions over
    frames whose result does not depend on the order, such as bounds); one after another
    without `parallel` (work too small to hand to a thread)."""
    n = workers() if parallel else 1
    if n <= 1 or count <= 1:
        return [fn(k) for k in range(count)]
    with ThreadPoolExecutor(n, thread_name_prefix="physcore-draw") as pool:
        return list(pool.map(fn, range(count)))
