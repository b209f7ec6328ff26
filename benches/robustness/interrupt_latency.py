"""Ctrl-C latency: time from SIGINT to KeyboardInterrupt raised by a long step(n), median and
max of --repeats tries.

Cases: (a) 2·10^5 particles under uniform gravity, step(10^7), every integrator; (b) the stiff
dopri5 cloth of tests/robustness/test_interrupt.py (48², dt = 0.5 s, rtol = 1e-10), whose every output step is
thousands of internal steps; (d) every integrator × term: pairwise gravity (N = 2·10^4, one
evaluation ~2·10^8 pair interactions), a springs cloth (1000², 10^6 particles) and an SPH fluid
(the 2D dam break of bench_sph.py at 10^6 particles, f64), where one force evaluation is a
large part of a second: the kernels poll the stop flag inside it. (a) and (b) run with
threads=None (the default pool) and threads=2, (d) with threads=None. "eval" is the wall time
of one force evaluation (one semi-implicit Euler step), for comparison. The SIGINT is sent
0.3-0.34 s into the call by a timer thread (a seeded random delay, so that it does not keep one
phase with the 20 ms signal polling); the latency includes the rollback of the state.
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import statistics
import threading
import time

import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc


_delays = random.Random(0)


def latency(call) -> float:
    """Seconds from SIGINT (sent 0.3-0.34 s into `call()`) to the KeyboardInterrupt."""
    delay = 0.3 + 0.04 * _delays.random()
    sent = []

    def fire():
        sent.append(time.perf_counter())
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Timer(delay, fire)
    timer.start()
    try:
        call()
    except KeyboardInterrupt:
        caught = time.perf_counter()
    else:
        raise RuntimeError("the call ended before it was interrupted; make it longer")
    finally:
        timer.cancel()
    return caught - sent[0]


def step_time(scene, n: int = 1) -> float:
    t0 = time.perf_counter()
    scene.step(n)
    return (time.perf_counter() - t0) / n


def gravity_scene(integrator: str, threads, n: int):
    rng = np.random.default_rng(1)
    scene = pc.Scene(3, integrator=integrator, dt=1e-3, threads=threads)
    scene.add_particles(rng.random((n, 3)), rng.normal(size=(n, 3)))
    scene.add(pc.Gravity([0.0, 0.0, -9.81]))
    return scene


def cloth_scene(threads):
    scene = pc.scenes.cloth(n=48, integrator="dopri5", dt=0.5, threads=threads)
    scene.rtol = 1e-10
    return scene


def nbody_scene(threads, n: int):
    rng = np.random.default_rng(2)
    scene = pc.Scene(3, integrator="verlet", dt=1e-4, threads=threads)
    scene.add_particles(rng.random((n, 3)), 0.1 * rng.normal(size=(n, 3)), masses=np.full(n, 1.0 / n))
    scene.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    return scene


def big_cloth_scene(n: int):
    return pc.scenes.cloth(n=n, integrator="semi_implicit_euler", dt=1e-4)


def fluid_scene(nx: int):
    from bench_sph import build

    return build(nx, precision="f64")


def ms(t: float) -> str:
    return f"{1e3 * t:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n-gravity", type=int, default=200_000)
    ap.add_argument("--n-nbody", type=int, default=20_000)
    ap.add_argument("--n-cloth", type=int, default=1000, help="cloth side (n² particles)")
    ap.add_argument("--nx-fluid", type=int, default=710, help="fluid lattice (2 nx² particles)")
    ap.add_argument("--cases", default="abd", help="which cases to run, e.g. 'd'")
    args = ap.parse_args()
    require_release()
    rows = []
    names = [d["name"] for d in pc.INTEGRATORS]

    def measure(label, integrator, threads, scene, call, t_eval):
        lat = [latency(lambda: call(scene)) for _ in range(args.repeats)]
        rows.append([label, integrator, str(threads), ms(t_eval), ms(statistics.median(lat)), ms(max(lat))])
        print(" | ".join(rows[-1]), flush=True)

    for threads in (None, 2):
        for integrator in names if "a" in args.cases else []:
            scene = gravity_scene(integrator, threads, args.n_gravity)
            scene.step(2)
            measure(f"(a) gravity N={args.n_gravity}", integrator, threads, scene, lambda s: s.step(10**7), step_time(scene, 3))
        if "b" in args.cases:
            scene = cloth_scene(threads)
            # One internal attempt: the output step's wall time over its attempts (from a short run).
            probe = cloth_scene(threads)
            probe.dt = 0.01
            t = step_time(probe)
            st = probe.integrator_stats
            measure("(b) dopri5 cloth 48²", "dopri5", threads, scene, lambda s: s.step(200), t / (st["accepted"] + st["rejected"]))
    if "d" in args.cases:
        terms = [
            (f"(d) pairwise N={args.n_nbody}", lambda: nbody_scene(None, args.n_nbody)),
            (f"(d) springs cloth N={args.n_cloth ** 2}", lambda: big_cloth_scene(args.n_cloth)),
            (f"(d) SPH fluid N={2 * args.nx_fluid ** 2}", lambda: fluid_scene(args.nx_fluid)),
        ]
        for label, make in terms:
            scene = make()
            scene.integrator = "semi_implicit_euler"  # one evaluation per step
            scene.step(1)
            t_eval = step_time(scene, 2)
            for integrator in names:
                scene.integrator = integrator
                measure(label, integrator, None, scene, lambda s: s.step(10**7), t_eval)
            del scene
    print()
    print(header())
    print(table(["case", "integrator", "threads", "eval or step (ms)", "latency median (ms)", "max (ms)"], rows))


if __name__ == "__main__":
    main()
