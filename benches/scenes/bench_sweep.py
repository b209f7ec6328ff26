"""How a physcore.sweep scales: runs per second for a sweep of 64 short runs, in a plain loop in
this process and on a Dask LocalCluster of 1 and 2 worker processes (one core thread per run),
and the overhead per task against the plain loop. Median of 3 repeats, alternating the modes so
that load on a shared machine hits all alike; the clusters are started (and warmed with one
sweep) before the clock starts, and their start-up time is reported on its own.

    python benches/scenes/bench_sweep.py [--runs 64] [--repeats 3] [--part tasks|steps|both]

The second part (``--part steps``) times a sweep that steps its runs itself (``steps=``, small
runs of one structure stepped together as a Batch, many runs a task) against today's sweep
where ``measure`` steps: 1,000 three-body runs (figure_eight, positions scaled by 1 + 1e-6 i),
1,000 steps each, in this process (``client="serial"``, also with ``threads=2``: a batch's
members side by side on 2 cores) and on a LocalCluster of 2 workers; all give the same rows bit
for bit (checked).

Three workloads: "medium" runs (a 32x32 spring cloth, 1500 steps: ~0.1 s each), "short" runs
(24x24, 300 steps: ~10 ms, the size of a quick dt or stiffness study) and "tiny" runs (10 steps
of 3 bodies: the per-task overhead alone). Overhead per task is the core-time a task costs
beyond the plain loop: (workers × sweep wall − loop wall) / runs (on a 2-core machine the
scheduler and this client share the cores with the workers, so it includes that contention).
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common

import argparse
import logging
import statistics
import time

import physcore as pc


def build_short(k: float, seed: int | None = None) -> pc.Scene:
    return pc.scenes.cloth(n=24, stiffness=k)


def measure_short(scene: pc.Scene) -> dict:
    scene.step(300)
    return {"energy": scene.energy().total}


def build_medium(k: float, seed: int | None = None) -> pc.Scene:
    return pc.scenes.cloth(n=32, stiffness=k)


def measure_medium(scene: pc.Scene) -> dict:
    scene.step(1500)
    return {"energy": scene.energy().total}


def build_tiny(k: float, seed: int | None = None) -> pc.Scene:
    return pc.scenes.figure_eight(steps_per_period=int(k))


def measure_tiny(scene: pc.Scene) -> dict:
    scene.step(10)
    return {"x": float(scene.positions[0, 0])}


THREE_BODY_STEPS = 1000


def build_three(i: int, seed: int | None = None) -> pc.Scene:
    s = pc.scenes.figure_eight()
    s.positions = s.positions * (1 + 1e-6 * i)
    return s


def look_three(scene: pc.Scene) -> dict:
    return {"x": float(scene.positions[0, 0]), "drift": scene.energy_drift()}


def step_look_three(scene: pc.Scene) -> dict:
    scene.step(THREE_BODY_STEPS)
    return look_three(scene)


WORKLOADS = {"medium": (build_medium, measure_medium, lambda i: 1000.0 + 10.0 * i),
             "short": (build_short, measure_short, lambda i: 1000.0 + 10.0 * i),
             "tiny": (build_tiny, measure_tiny, lambda i: 1000.0 + i)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--part", choices=["tasks", "steps", "both"], default="both")
    ap.add_argument("--steps-runs", type=int, default=1000, help="runs of the steps= part")
    args = ap.parse_args()
    _common.require_release()
    if args.part in ("tasks", "both"):
        tasks(args)
    if args.part in ("steps", "both"):
        steps_part(args)


def _cluster(workers: int):
    import distributed

    t0 = time.perf_counter()
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                                       silence_logs=logging.ERROR)
    client = distributed.Client(cluster)
    return client, cluster, time.perf_counter() - t0


def steps_part(args) -> None:
    """Today's sweep (measure steps, one task a run) against steps= (the sweep steps, batched)."""
    params = {"i": list(range(args.steps_runs))}
    client, cluster, start = _cluster(2)
    pc.sweep(build_three, {"i": [0, 1]}, measure=look_three, steps=1, client=client, progress=False)  # warm the workers
    n = THREE_BODY_STEPS
    modes = [("serial", "measure steps", "serial", None, 1), ("serial", "steps=", "serial", n, 1),
             ("serial", "steps=, threads=2", "serial", n, 2),
             ("dask, 2 workers", "measure steps", client, None, 1), ("dask, 2 workers", "steps=", client, n, 1)]
    walls: dict[tuple[str, str], list[float]] = {(w, h): [] for w, h, *_ in modes}
    frames = {}
    for _ in range(args.repeats):
        for where, how, c, steps, threads in modes:
            measure = step_look_three if steps is None else look_three
            t0 = time.perf_counter()
            df = pc.sweep(build_three, params, measure=measure, steps=steps, client=c, threads=threads, progress=False)
            walls[(where, how)].append(time.perf_counter() - t0)
            print(f"{where:16s} {how:14s} {walls[(where, how)][-1]:.3f} s", file=sys.stderr, flush=True)
            assert df["error"].isna().all(), df["error"].dropna().tolist()
            frames[(where, how)] = df[["x", "drift"]]
    ref = frames[("serial", "measure steps")]
    for k, df in frames.items():
        assert df.equals(ref), f"{k}: rows differ from the serial sweep where measure steps"
    print(_common.header(threads="1, 2"))
    print(f"\n{args.steps_runs} three-body runs (figure_eight, {THREE_BODY_STEPS} steps) per sweep, median of "
          f"{args.repeats}; LocalCluster start {start:.2f} s, not counted; every mode gives the same rows bit for bit\n")
    rows = []
    for where, how, *_ in modes:
        base = statistics.median(walls[(where, "measure steps")])
        wall = statistics.median(walls[(where, how)])
        rows.append([where, how, f"{wall:.3f}", f"{args.steps_runs / wall:.0f}", f"{base / wall:.2f}×"])
    print(_common.table(["where", "who steps", "sweep wall, s", "runs/s", "vs measure steps"], rows))
    client.close()
    cluster.close()
    sys.stdout.flush()


def tasks(args) -> None:
    import distributed

    clients = {}
    for w in (1, 2):
        t0 = time.perf_counter()
        cluster = distributed.LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=":0",
                                           silence_logs=logging.ERROR)
        client = distributed.Client(cluster)
        start = time.perf_counter() - t0
        b, m, v = WORKLOADS["tiny"]
        pc.sweep(b, {"k": [v(0)]}, measure=m, client=client, progress=False)  # imports physcore on the workers
        clients[w] = (client, cluster, start)

    modes = [("loop", "serial"), ("dask, 1 worker", clients[1][0]), ("dask, 2 workers", clients[2][0])]
    workers = {"loop": 1, "dask, 1 worker": 1, "dask, 2 workers": 2}
    print(_common.header(threads=1))
    print(f"{args.runs} runs per sweep, median of {args.repeats}; LocalCluster start: "
          f"{clients[1][2]:.2f} s (1 worker), {clients[2][2]:.2f} s (2 workers), not counted below\n")
    rows = []
    for name, (b, m, v) in WORKLOADS.items():
        params = {"k": [v(i) for i in range(args.runs)]}
        walls: dict[str, list[float]] = {label: [] for label, _ in modes}
        run_s: dict[str, list[float]] = {label: [] for label, _ in modes}
        for _ in range(args.repeats):
            for label, client in modes:
                t0 = time.perf_counter()
                df = pc.sweep(b, params, measure=m, client=client, progress=False)
                walls[label].append(time.perf_counter() - t0)
                print(f"{name:6s} {label:16s} {walls[label][-1]:.3f} s", file=sys.stderr, flush=True)
                run_s[label].append(float(df["wall_s"].sum()))
                assert df["error"].isna().all(), df["error"].dropna().tolist()
        loop = statistics.median(walls["loop"])
        for label, _ in modes:
            wall = statistics.median(walls[label])
            rows.append([name, label, f"{wall:.3f}", f"{args.runs / wall:.1f}", f"{loop / wall:.2f}×",
                         f"{1e3 * (workers[label] * wall - loop) / args.runs:+.2f}" if label != "loop" else "–",
                         f"{1e3 * statistics.median(run_s[label]) / args.runs:.2f}"])
    print(_common.table(["workload", "where", "sweep wall, s", "runs/s", "vs loop",
                         "overhead per task, ms", "mean run (build+measure), ms"], rows))
    for client, cluster, _ in clients.values():
        client.close()
        cluster.close()
    sys.stdout.flush()


if __name__ == "__main__":
    main()
