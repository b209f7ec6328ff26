"""The notebook widget's kernel side: frames a second that :func:`physcore.widget` makes (ticks
due, drawing, JPEG encoding) and how fast its scene then runs against real time, at 480 × 360.

    python benches/render/bench_widget.py [SECONDS]

Scenes: the default cloth (1,600 particles) and the default dam break (10,368 particles). Each
runs `SECONDS` of wall time (default 5) with foreground stepping (``background=False``: ticks
and frames in turn, as the window does) and with background stepping (the default: ticks on a
thread, frames paced at ``max_fps`` = 30). The browser's side (receiving and drawing JPEGs) is
printed, not asserted, by ``tests/render/test_widget_browser.py``'s run (``-s`` shows it): a
frame rate in a test fails on a busy machine and proves nothing about correctness.
"""
from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

from _common import header, require_release  # first: sets up the environment before numpy loads

import physcore as pc
from physcore.notebook import widget


def measure(name: str, background: bool, seconds: float) -> tuple[float, float]:
    """(frames per wall second, simulated seconds per wall second)."""
    scene = pc.scenes.REGISTRY[name]()
    w = widget(scene, size=(480, 360), fallback=False, background=background, playing=False)
    try:
        w.play()
        t_sim0, n, t0 = w.time, 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            w.produce_frame()
            n += 1
            if background:  # paced as the front end's credits pace it: at most max_fps
                time.sleep(max(0.0, n / 30.0 - (time.perf_counter() - t0)))
        wall = time.perf_counter() - t0
        return n / wall, (w.time - t_sim0) / wall
    finally:
        w.close()


def main(seconds: float) -> None:
    require_release()
    print(header())
    print("| scene | stepping | frames/s | simulated s per wall s |")
    print("|---|---|---|---|")
    for name in ("cloth", "dam_break"):
        for background in (False, True):
            fps, rate = measure(name, background, seconds)
            print(f"| {name} | {'background' if background else 'foreground'} | {fps:.1f} | {rate:.2f} |")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 5.0)
