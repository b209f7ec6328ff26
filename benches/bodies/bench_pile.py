"""A pile of boxes falling into a container (2D), physcore's rigid bodies (rapier2d-f64) against
pymunk (Chipmunk 2D, double precision), side by side in one run.

    python benches/bodies/bench_pile.py            # 1000 and 3000 boxes
    python benches/bodies/bench_pile.py 5000

Both engines get the same scene: N boxes 0.2 × 0.2 m (density 1, friction 0.5, restitution
0.1) in a grid above a container 8 m wide (floor and two walls, fixed), gravity 9.81 m/s²,
dt = 1/60 s, 4 solver iterations (rapier's default; pymunk's is 10, set to 4 here), no sleeping.
Each is timed over 3 blocks of 60 steps after 60 steps of fall (the pile forms during the
blocks, so the blocks do the contact work of a settling pile), median reported. rapier has no
threads here (its deterministic build); physcore's thread count does not change this time.
"""
from __future__ import annotations

import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

from _common import header, require_release  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc

DT = 1 / 60
HALF = 0.1
WIDTH = 8.0


def _grid(n: int) -> np.ndarray:
    cols = int(WIDTH / (2.6 * HALF)) - 2
    k = np.arange(n)
    x = -WIDTH / 2 + 3 * HALF + (k % cols) * 2.6 * HALF
    y = 0.5 + (k // cols) * 2.6 * HALF
    return np.stack([x, y], 1)


def physcore_pile(n: int) -> tuple[pc.Scene, object]:
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=DT)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Bodies("box", size=[(WIDTH / 2, 0.1), (0.1, 4.0), (0.1, 4.0)],
                    positions=[(0.0, -0.1), (-WIDTH / 2 - 0.1, 4.0), (WIDTH / 2 + 0.1, 4.0)], kind="fixed", friction=0.5))
    boxes = s.add(pc.Bodies("box", size=(HALF, HALF), positions=_grid(n), density=1.0, friction=0.5, restitution=0.1))
    return s, boxes


def pymunk_pile(n: int):
    import pymunk

    space = pymunk.Space()
    space.gravity = (0.0, -9.81)
    space.iterations = 4
    for a, b in (((-WIDTH / 2, 0), (WIDTH / 2, 0)), ((-WIDTH / 2, 0), (-WIDTH / 2, 8)), ((WIDTH / 2, 0), (WIDTH / 2, 8))):
        seg = pymunk.Segment(space.static_body, a, b, 0.0)
        seg.friction = 0.5
        space.add(seg)
    for x, y in _grid(n):
        body = pymunk.Body()
        body.position = (float(x), float(y))
        shape = pymunk.Poly.create_box(body, (2 * HALF, 2 * HALF))
        shape.density, shape.friction, shape.elasticity = 1.0, 0.5, 0.1
        space.add(body, shape)
    return space


def _median(step, blocks: int = 3, steps: int = 60) -> float:
    step(60)
    times = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        step(steps)
        times.append((time.perf_counter() - t0) / steps)
    return statistics.median(times)


def main(sizes: list[int]) -> None:
    require_release()
    print(header())
    print("| boxes | physcore (ms/step) | pymunk (ms/step) | pymunk / physcore |")
    print("|---|---|---|---|")
    for n in sizes:
        s, _ = physcore_pile(n)
        t_pc = _median(s.step)
        space = pymunk_pile(n)

        def pm(k: int, space=space) -> None:
            for _ in range(k):
                space.step(DT)

        t_pm = _median(pm)
        print(f"| {n} | {1e3 * t_pc:.2f} | {1e3 * t_pm:.2f} | {t_pm / t_pc:.2f}× |")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1000, 3000])
