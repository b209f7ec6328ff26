"""Rasterisation speed of physcore.render: milliseconds per frame for 1e5 particles.

Run: python benches/bench_render.py [N]
Times the per-frame work of `physcore.render.gif` (projection, springs, discs into the uint8
index buffer) on a random 2D cloud and a 3D cloud, and the public `render_frame` (which also fits
the camera and expands to RGB).
"""
from __future__ import annotations

import sys
import time

import numpy as np

from physcore import render


def _time(fn, repeat: int = 20) -> float:
    fn()  # warm up
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def main(n: int = 100_000) -> None:
    rng = np.random.default_rng(0)
    for dim in (2, 3):
        x = rng.normal(size=(n, dim))
        v = rng.normal(size=(n, dim))
        # A chain of springs through all particles, so lines are drawn too.
        i = np.arange(n - 1)
        springs = (i, i + 1, np.full(n - 1, 0.05))
        rec = render._Recording(
            positions=x.astype(np.float32)[None],
            origin=np.zeros(dim),
            speeds=np.linalg.norm(v, axis=1).astype(np.float32)[None],
            pairs=None,
            strain=None,
            pinned=np.zeros(n, dtype=bool),
            planes=[],
        )
        ras = render._Rasteriser(rec, (480, 360), "speed", None, render.DEFAULT_VIEW)
        t_frame = _time(lambda: ras.frame(0))
        t_public = _time(lambda: render.render_frame(x, velocities=v), repeat=5)
        t_springs = _time(lambda: render.render_frame(x, velocities=v, springs=springs), repeat=5)
        print(
            f"{dim}D, {n} particles, 480x360, radius {ras.radius}: "
            f"gif frame {t_frame:.1f} ms, render_frame {t_public:.1f} ms, "
            f"render_frame + {n - 1} springs {t_springs:.1f} ms"
        )


if __name__ == "__main__":
    main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000)
