"""Rasterisation speed of physcore.render: milliseconds per frame for 1e5 particles, with glow
and trails, and for shaded cloth meshes up to 256².

Run: python benches/render/bench_render.py [N]
Times, on a jittered square grid of N particles with springs to grid neighbours (a cloth), in 2D
and 3D: the per-frame work inside `physcore.render.gif` (projection, spring lines and discs into
the uint8 index buffer, camera already fitted) and the public `render_frame` (which also fits the
camera and expands the result to RGB).
"""
from __future__ import annotations

import sys
import time

import os

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

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


def glow_trails(n: int = 100_000, size=(640, 480), trail: int = 30, frames: int = 40) -> None:
    """The issue's budget with trails: 1e5 particles of a rotating Gaussian cloud, glow with a
    `trail` of fading history, frames drawn in order as gif() draws them (median per frame)."""
    rng = np.random.default_rng(2)
    x0 = rng.standard_normal((n, 2))
    ang = np.linspace(0.0, 1.0, frames)
    pos = np.stack([x0 @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) for a in ang]).astype(np.float32)
    rec = render.Recording(positions=pos, origin=np.zeros(2), speeds=None, pairs=None, strain=None,
                           pinned=np.zeros(n, dtype=bool), planes=[], times=np.linspace(0, 1, frames))
    ras = render._Rasteriser(rec, size, "density", 2, render.DEFAULT_VIEW, annotate=True, trail=trail)
    times = []
    for k in range(frames):
        t0 = time.perf_counter()
        ras.frame(k)
        times.append(time.perf_counter() - t0)
    print(f"2D {n} particles, glow with trail={trail}, {size[0]}x{size[1]}: "
          f"gif frame {1e3 * float(np.median(times[1:])):.1f} ms (median of {frames - 1}, in order)")


def mesh(side: int = 256, size=(640, 480)) -> None:
    """The issue's budget: a shaded side² cloth (Mesh.grid, 2·(side−1)² triangles) at 640x480,
    a hanging, rippled sheet seen by the default 3D camera, with the clock and scale bar; and
    the same for the default 40² cloth. Lighting is numpy per vertex; normals and rasterisation
    (2×2 supersamples, depth buffer) are in the core, on the default thread pool."""
    for n in (40, 128, side):
        g = np.linspace(0.0, 1.0, n)
        u, v = (a.ravel() for a in np.meshgrid(g, g))
        x = np.stack([u, 0.3 * v + 0.05 * np.sin(9 * u), -0.8 * v + 0.1 * np.sin(6 * u + 3 * v)], axis=1)
        rec = render.Recording(positions=x.astype(np.float32)[None], origin=np.zeros(3), speeds=None, pairs=None,
                               strain=None, pinned=v == 0, planes=[], times=np.zeros(1))
        ras = render._Rasteriser(rec, size, "none", None, render.DEFAULT_VIEW, annotate=True,
                                 mesh=render.Mesh.grid(n, n))
        times = []
        for _ in range(15):
            t0 = time.perf_counter()
            ras.frame_rgb(0)
            times.append(time.perf_counter() - t0)
        print(f"3D shaded cloth {n}x{n} ({2 * (n - 1) ** 2} triangles), {size[0]}x{size[1]}: "
              f"frame {1e3 * float(np.median(times)):.1f} ms (median of 15), best {1e3 * min(times):.1f} ms")


def fluid_surface(ns=(40, 60, 79)) -> None:
    """A 3D dam break drawn as a liquid surface (its default look), N = 2n³ particles: gif()'s
    time a frame for 4 frames one step apart (the camera's fit, the spray's count, the splats
    and the blur), the GPU scene's question: is a 10⁶-particle GIF the simulation's time or the
    drawing's? (986,078 particles: 0.25 s a frame on the project's Xeon, 2026-11-29.)"""
    import physcore as pc

    for n in ns:
        s = pc.scenes.dam_break(dim=3, n=n, method="wcsph")
        rec = pc.render.record(s, frames=4, steps_per_frame=1)
        path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "_surface_bench.gif")
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            pc.render.gif(rec, path)
            times.append((time.perf_counter() - t0) / 4)
        os.remove(path)
        print(f"3D dam break surface, {s.n_particles} particles, 4 frames: {1e3 * min(times):.0f} ms a frame (best of 2)")


if __name__ == "__main__":
    fluid_surface()
    mesh()
    glow_trails()
    glow()
    main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000)
