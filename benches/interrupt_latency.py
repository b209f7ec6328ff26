"""Ctrl-C latency: time from SIGINT to KeyboardInterrupt raised by a long step(n), median of 3.

Cases: (a) 2·10^5 particles under uniform gravity, step(10^7), every integrator; (b) the stiff
rk45 cloth of tests/test_interrupt.py (48², dt = 0.5 s, rtol = 1e-10), whose every output step is
thousands of internal steps; (c) pairwise gravity N = 5000 with verlet, where one step is one
O(N²) force evaluation, which is not interrupted: it bounds the latency from below. Each case
runs with threads=None (rayon's global pool) and threads=2. "step" is the wall time of one
output step (of one internal attempt for (b)), for comparison. The SIGINT is sent 0.3-0.34 s
into the call by a timer thread (a seeded random delay, so that it does not keep one phase
with the 20 ms signal polling); the latency includes the rollback of the state.
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import statistics
import threading
import time

from _common import require_release, table  # first: sets up the environment before numpy loads
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
    scene = pc.scenes.cloth(n=48, integrator="rk45", dt=0.5, threads=threads)
    scene.rtol = 1e-10
    return scene


def nbody_scene(threads, n: int):
    rng = np.random.default_rng(2)
    scene = pc.Scene(3, integrator="verlet", dt=1e-4, threads=threads)
    scene.add_particles(rng.random((n, 3)), 0.1 * rng.normal(size=(n, 3)), masses=np.full(n, 1.0 / n))
    scene.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    return scene


def ms(t: float) -> str:
    return f"{1e3 * t:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n-gravity", type=int, default=200_000)
    ap.add_argument("--n-nbody", type=int, default=5000)
    ap.add_argument("--cases", default="abc", help="which cases to run, e.g. 'c'")
    args = ap.parse_args()
    require_release()
    rows = []

    def measure(label, integrator, threads, scene, call, step):
        lat = [latency(lambda: call(scene)) for _ in range(args.repeats)]
        rows.append([label, integrator, str(threads), ms(step), ms(statistics.median(lat)), ms(max(lat))])
        print(" | ".join(rows[-1]), flush=True)

    names = [d["name"] for d in pc.INTEGRATORS] if "a" in args.cases else []
    for threads in (None, 2):
        for integrator in names:
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
            measure("(b) rk45 cloth 48²", "rk45", threads, scene, lambda s: s.step(200), t / (st["accepted"] + st["rejected"]))
        if "c" in args.cases:
            scene = nbody_scene(threads, args.n_nbody)
            scene.step(1)
            measure(f"(c) pairwise N={args.n_nbody}", "verlet", threads, scene, lambda s: s.step(10**6), step_time(scene, 3))
    print()
    print(table(["case", "integrator", "threads", "step (ms)", "latency median (ms)", "max (ms)"], rows))


if __name__ == "__main__":
    main()
