"""physcore.Batch against a Python loop over the same scenes (issue "Many small worlds at once").

Each workload is M members of one ready-made scene, perturbed (positions scaled by 1 + 1e-3 k),
stepped S steps: as a Python loop (``for s in scenes: s.step(S)``: one call per member, each
member's own pool) and as one ``Batch.step(S)`` at 1 and 2 threads (the Batch built before the
clock starts, as the loop's scenes are; the first step's energy references are in both). Wall time, median of
``--repeats`` (modes alternated so that load on a shared machine hits all alike), on fresh
copies each time; member-steps per second and the ratio to the loop.

    python benches/scenes/bench_batch.py [--repeats 3] [--quick] [--dask]

With ``--dask`` the three-body workload also runs as today's sweep on Dask (``pc.sweep`` over
the member index, ``measure`` stepping the scene, a LocalCluster of 2 workers, one run a task)
and as the sweep stepping the runs itself (``steps=``: batches on each worker), once each (the
cluster's start is not counted). Run it once per SIMD level (``PHYSCORE_SIMD=scalar`` ...).

Workloads: 10,000 three-body problems (figure_eight, 4th-order Yoshida) for 1,000 steps; 1,000
double pendulums (XPBD rods) for 1,000 steps; 256 cloths of 16×16 for 200 steps.
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common

import _common

import argparse
import pickle
import statistics
import time

import physcore as pc


def members(make, m: int) -> list[pc.Scene]:
    return list(pc.Batch.from_scene(make(), m, positions=lambda k, x: x * (1 + 1e-3 * k)).members)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="a tenth of the members: checks the script works")
    ap.add_argument("--dask", action="store_true", help="the three-body workload through pc.sweep on Dask too")
    a = ap.parse_args()
    _common.require_release()
    q = 10 if a.quick else 1
    workloads = [
        ("three-body (figure_eight, yoshida4)", lambda: pc.scenes.figure_eight(integrator="yoshida4"), 10_000 // q, 1000),
        ("double pendulum (XPBD)", pc.scenes.double_pendulum, 1000 // q, 1000),
        ("cloth 16x16", lambda: pc.scenes.cloth(n=16), 256 // q, 200),
    ]
    print(_common.header(threads=2))
    print("| workload | M × steps | loop | batch 1 thread | batch 2 threads | batch 2 / loop |")
    print("|---|---|---|---|---|---|")
    for name, make, m, steps in workloads:
        blob = pickle.dumps(members(make, m))
        times: dict[str, list[float]] = {"loop": [], "b1": [], "b2": []}
        for _ in range(a.repeats):
            for mode in times:
                scenes = pickle.loads(blob)
                # Built before the clock starts, as the loop's scenes are (the Batch checks its
                # members' structure: ~5 µs a member).
                batch = None if mode == "loop" else pc.Batch(scenes, threads=1 if mode == "b1" else 2)
                t0 = time.perf_counter()
                if batch is None:
                    for s in scenes:
                        s.step(steps)
                else:
                    batch.step(steps)
                times[mode].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) for k, v in times.items()}
        rate = {k: m * steps / v for k, v in med.items()}
        print(f"| {name} | {m} × {steps} | {med['loop']:.2f} s ({rate['loop']:.3g}/s) | {med['b1']:.2f} s "
              f"({rate['b1']:.3g}/s) | {med['b2']:.2f} s ({rate['b2']:.3g}/s) | {med['loop'] / med['b2']:.2f}× |", flush=True)
        if a.dask and name.startswith("three-body"):
            dask_rows(m, steps, med["b2"])
    short_calls(a.repeats)


def short_calls(repeats: int) -> None:
    """One step a call, as a renderer or a notebook drives a batch: the call's own cost. M
    figure-eight members, 1,000 calls of ``step(1)``, µs a call (median of `repeats`), against a
    loop of the members' own ``step(1)``. Short calls (at most 4,096 element-steps in all) run
    without a watching thread; before, each started one and, at a thread count given, a pool
    of its own: 410 µs a call for 2 one-particle members on 2 cores (now 33 µs)."""
    print("\n| one step a call | loop of scenes | batch 1 thread | batch, default pool |")
    print("|---|---|---|---|")
    for m in (2, 64):
        blob = pickle.dumps(members(pc.scenes.figure_eight, m))
        times: dict[str, list[float]] = {"loop": [], "b1": [], "bd": []}
        for _ in range(repeats):
            for mode in times:
                scenes = pickle.loads(blob)
                batch = None if mode == "loop" else pc.Batch(scenes, threads=1 if mode == "b1" else None)
                step = (lambda: [s.step(1) for s in scenes]) if batch is None else (lambda: batch.step(1))
                step()  # the books' reference, taken at the first step
                t0 = time.perf_counter()
                for _ in range(1000):
                    step()
                times[mode].append((time.perf_counter() - t0) / 1000 * 1e6)
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f"| {m} members | {med['loop']:.0f} µs | {med['b1']:.0f} µs | {med['bd']:.0f} µs |", flush=True)


def _three_body(k: int) -> pc.Scene:
    s = pc.scenes.figure_eight(integrator="yoshida4")
    s.positions = s.positions * (1 + 1e-3 * k)
    return s


def _energy(scene: pc.Scene, steps: int = 0) -> dict:
    if steps:
        scene.step(steps)
    return {"e": scene.energy()["total"]}


def dask_rows(m: int, steps: int, batch2: float) -> None:
    """The three-body workload as today's Dask sweep and as the sweep stepping runs itself."""
    import functools

    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, Client(cluster) as client:
        client.run(lambda: __import__("physcore"))  # workers warm
        params = {"k": list(range(m))}
        t0 = time.perf_counter()
        pc.sweep(_three_body, params, measure=functools.partial(_energy, steps=steps), client=client, progress=False)
        per_task = time.perf_counter() - t0
        t0 = time.perf_counter()
        pc.sweep(_three_body, params, measure=_energy, steps=steps, client=client, progress=False)
        batched = time.perf_counter() - t0
    print(f"| three-body through pc.sweep on Dask (2 workers) | {m} × {steps} | one run a task: {per_task:.2f} s "
          f"| steps= (batches a worker): {batched:.2f} s | batch 2 threads in-process is {per_task / batch2:.0f}× "
          f"the one-run-a-task sweep |", flush=True)


if __name__ == "__main__":
    main()
