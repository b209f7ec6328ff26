"""Rasterisation speed of physcore.render: milliseconds per frame for 1e5 particles.

Run: python benches/bench_render.py [N]
Times, on a jittered square grid of N particles with springs to grid neighbours (a cloth), in 2D
and 3D: the per-frame work inside `physcore.render.gif` (projection, spring lines and discs into
the uint8 index buffer, camera already fitted) and the public `render_frame` (which also fits the
camera and expands the result to RGB).
"""
from __future__ import annotations

import sys
import time

from _common import header  # first: sets up the environment before numpy loads
import numpy as np

from physcore import render


def _best_ms(fn, repeat: int) -> float:
    fn()  # warm up
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def _cloth(n: int, dim: int, rng: np.random.Generator):
    side = max(2, int(round(n ** 0.5)))
    g = np.arange(side, dtype=np.float64)
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    x = np.stack([gx, gy] + ([0.1 * np.sin(gx / 7)] if dim == 3 else []), axis=1)
    x += rng.normal(scale=0.05, size=x.shape)
    v = rng.normal(size=x.shape)
    idx = np.arange(side * side).reshape(side, side)
    i = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    j = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    return x, v, (i, j, np.ones(i.size))


def main(n: int = 100_000, size=(480, 360)) -> None:
    print(header(1) + " (rasterisation is numpy, single-threaded; the SIMD level does not apply)")
    rng = np.random.default_rng(0)
    for dim in (2, 3):
        x, v, springs = _cloth(n, dim, rng)
        i, j, rest = springs
        for with_springs in (False, True):
            for radius in (None, 2):
                rec = render.Recording(
                    positions=x.astype(np.float32)[None],
                    origin=np.zeros(dim),
                    speeds=render._row_norms(v).astype(np.float32)[None],
                    pairs=(i, j) if with_springs else None,
                    strain=render._strain(x, i, j, rest).astype(np.float32)[None] if with_springs else None,
                    pinned=np.zeros(len(x), dtype=bool),
                    planes=[],
                )
                ras = render._Rasteriser(rec, size, "speed", radius, render.DEFAULT_VIEW)
                t_frame = _best_ms(lambda: ras.frame(0), 20)
                sp = springs if with_springs else False
                t_public = _best_ms(
                    lambda: render.render_frame(x, velocities=v, springs=sp, size=size, radius=radius), 5
                )
                what = f"{len(x)} particles" + (f" + {i.size} springs" if with_springs else "")
                print(
                    f"{dim}D {what}, {size[0]}x{size[1]}, radius {ras.radius}: "
                    f"gif frame {t_frame:.1f} ms, render_frame {t_public:.1f} ms"
                )


def glow(n: int = 100_000, size=(640, 480)) -> None:
    """The issue's budget: one frame of 1e5 particles with glow (color_by="density") at 640x480,
    a Gaussian cloud (2D and 3D), and with the clock and scale bar drawn (as gif() draws it)."""
    rng = np.random.default_rng(1)
    for dim in (2, 3):
        x = rng.standard_normal((n, dim))
        rec = render.Recording(positions=x.astype(np.float32)[None], origin=np.zeros(dim), speeds=None, pairs=None,
                               strain=None, pinned=np.zeros(n, dtype=bool), planes=[], times=np.zeros(1))
        for radius in (0, 2):
            ras = render._Rasteriser(rec, size, "density", radius, render.DEFAULT_VIEW, annotate=True)
            print(f"{dim}D {n} particles, glow (color_by='density'), {size[0]}x{size[1]}, radius {radius}: "
                  f"gif frame {_best_ms(lambda: ras.frame(0), 10):.1f} ms (best of 10)")


if __name__ == "__main__":
    glow()
    main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000)
