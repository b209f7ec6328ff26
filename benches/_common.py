"""Shared timing protocol for the benchmarks (see benches/README.md): blocks of S consecutive steps,
3 blocks in a row, median reported; the state keeps evolving between blocks."""
from __future__ import annotations

import os

# numpy's OpenBLAS worker threads spin after a BLAS call and steal cycles from the stepping
# threads on a 2-core machine; the benchmarks do no BLAS work.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import statistics
import sys
import time

import physcore as pc


def require_release() -> None:
    if pc._core.build_profile != "release":
        sys.exit("benchmarks refuse to run on a debug build of physcore._core; reinstall with `pip install .`")


def median_block_time(scene, steps: int, blocks: int = 3) -> float:
    """Median wall time (s) of `blocks` consecutive blocks of `steps` steps each. `scene` is a
    physcore Scene or any callable `step(n)` that advances a peer implementation."""
    step = scene.step if hasattr(scene, "step") else scene
    times = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        step(steps)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def table(headers, rows) -> str:
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---:" if k else "---" for k in range(len(headers))) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def si(x: float) -> str:
    for unit, f in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(x) >= f:
            return f"{x / f:.2f} {unit}"
    return f"{x:.3g}"
