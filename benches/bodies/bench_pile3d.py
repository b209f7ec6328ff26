"""A pile of boxes falling into a container (3D), physcore's rigid bodies (rapier3d-f64) against
rapier's own Python bindings (``rapier3d`` on the package index, single precision), side by side
in one run.

    python benches/bodies/bench_pile3d.py            # 1000 and 3000 boxes
    python benches/bodies/bench_pile3d.py 5000

Both get the same scene: N cubes 0.2 m (density 1, friction 0.5, restitution 0.1) in a grid
above a container 4 × 4 m (floor and four walls, fixed), gravity 9.81 m/s², dt = 1/60 s,
4 solver iterations (rapier's default in both), no sleeping, no CCD. Each is timed over
3 blocks of 60 steps after 60 steps of fall (the pile forms during the blocks), median
reported. physcore's rapier is its deterministic build (``enhanced-determinism``, no threads
of its own: the thread count does not change this time); the bindings are timed with their
pool at 1 thread and at their default. The precision differs (f64 against f32): physcore's own
overhead at one precision is what ``cargo run --release --features examples --example pile3d`` measures (physcore's
step against the bare rapier3d-f64 pipeline on this scene).
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

from _common import header, require_release  # first: sets up the environment before numpy loads
import numpy as np
from bench_pile import _median  # the 2D bench's timing (this folder): the same blocks and median

import physcore as pc

DT = 1 / 60
HALF = 0.1
WIDTH = 4.0
WALLS = [((0.0, 0.0, -0.1), (WIDTH / 2, WIDTH / 2, 0.1))] + [
    ((sx * (WIDTH / 2 + 0.1), 0.0, 2.0), (0.1, WIDTH / 2, 2.0)) for sx in (-1, 1)] + [
    ((0.0, sy * (WIDTH / 2 + 0.1), 2.0), (WIDTH / 2, 0.1, 2.0)) for sy in (-1, 1)]


def _grid(n: int) -> np.ndarray:
    cols = int(WIDTH / (2.6 * HALF)) - 1
    k = np.arange(n)
    x = -WIDTH / 2 + 2 * HALF + (k % cols) * 2.6 * HALF
    y = -WIDTH / 2 + 2 * HALF + ((k // cols) % cols) * 2.6 * HALF
    z = 0.5 + (k // (cols * cols)) * 2.6 * HALF
    return np.stack([x, y, z], 1)


def physcore_pile(n: int) -> pc.Scene:
    s = pc.Scene(3, integrator="semi_implicit_euler", dt=DT)
    s.add(pc.Gravity([0.0, 0.0, -9.81]))
    s.add(pc.Bodies("box", size=[h for _, h in WALLS], positions=[c for c, _ in WALLS], kind="fixed", friction=0.5))
    s.add(pc.Bodies("box", size=(HALF, HALF, HALF), positions=_grid(n), density=1.0, friction=0.5, restitution=0.1))
    return s


def rapier_pile(n: int, threads: int | None):
    import rapier3d as r

    world = r.PhysicsWorld(gravity=(0.0, 0.0, -9.81))
    world.integration_parameters.dt = DT
    if threads is not None:
        world.set_num_threads(threads)
    for c, h in WALLS:
        world.add_collider(r.Collider.cuboid(*h).translation(r.Vec3(*c)).friction(0.5))
    for x, y, z in _grid(n):
        world.add_body(r.RigidBody.dynamic(translation=(float(x), float(y), float(z))).can_sleep(False),
                       colliders=[r.Collider.cuboid(HALF, HALF, HALF).density(1.0).friction(0.5).restitution(0.1)])
    return world


def main(sizes: list[int]) -> None:
    require_release()
    import rapier3d

    print(header())
    print(f"rapier3d (Python bindings) {getattr(rapier3d, '__version__', '?')}, f32; physcore: rapier3d-f64 0.36")
    print()
    print("| boxes | physcore f64 (ms/step) | rapier3d f32, 1 thread (ms/step) | rapier3d f32, default threads (ms/step) | "
          "1-thread ratio rapier3d / physcore |")
    print("|---|---|---|---|---|")
    for n in sizes:
        s = physcore_pile(n)
        t_pc = _median(s.step)
        out = []
        for threads in (1, None):
            world = rapier_pile(n, threads)

            def rs(k: int, world=world) -> None:
                for _ in range(k):
                    world.step()

            out.append(_median(rs))
        print(f"| {n} | {1e3 * t_pc:.2f} | {1e3 * out[0]:.2f} | {1e3 * out[1]:.2f} | {out[0] / t_pc:.2f}× |")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1000, 3000])
