"""Shared timing protocol for the benchmarks (see benches/README.md): blocks of S consecutive steps,
3 blocks in a row, median reported; the state keeps evolving between blocks."""
from __future__ import annotations

import os

# numpy's OpenBLAS worker threads spin after a BLAS call and steal cycles from the stepping
# threads on a 2-core machine; the benchmarks do no BLAS work.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import platform
import statistics
import sys
import time
from pathlib import Path

import physcore as pc

# The benches sit in one folder per capability (README.md) and import each other by module name
# (levels.py every folder's workload, interrupt_latency.py the SPH dam break): every folder is on
# the path once a bench has imported this module.
for _folder in sorted(Path(__file__).resolve().parent.iterdir()):
    if _folder.is_dir() and not _folder.name.startswith(("_", ".")) and str(_folder) not in sys.path:
        sys.path.append(str(_folder))


def require_release() -> None:
    if pc._core.build_profile != "release":
        sys.exit("benchmarks refuse to run on a debug build of physcore._core; reinstall with `pip install .`")


def header(threads=None) -> str:
    """One line naming what the numbers below were measured on, printed above every table:
    "CPU: AMD EPYC · SIMD level: avx512 (available: scalar, avx2, avx512) · threads 2 ·
    physcore 0.1.0 release". `threads`: the thread count(s) the table used (an int, a string such
    as "1,2", or a sequence); default physcore's default thread count. A level forced by
    PHYSCORE_SIMD is marked as such."""
    get = getattr(pc, "info", None)
    try:
        info = get() if get is not None else {}
    except Exception as e:  # noqa: BLE001 - a header must never stop a benchmark
        info = {"simd_level": f"unknown ({e})"}
    cpu = info.get("cpu") or platform.processor() or platform.machine()
    level = info.get("simd_level", "unknown (this physcore has no info())")
    notes = []
    if info.get("simd_levels"):
        notes.append("available: " + ", ".join(info["simd_levels"]))
    forced = os.environ.get("PHYSCORE_SIMD", "").strip()
    if forced and forced.lower() != "auto":
        notes.append(f"set by PHYSCORE_SIMD={forced}")
    if threads is None:
        threads = info.get("threads", "?")
    elif not isinstance(threads, (int, str)):
        threads = ",".join(str(t) for t in threads)
    version = info.get("version", getattr(pc, "__version__", "?"))
    build = info.get("build", getattr(getattr(pc, "_core", None), "build_profile", "?"))
    parts = [f"CPU: {cpu}", f"SIMD level: {level}" + (f" ({'; '.join(notes)})" if notes else ""),
             f"threads {threads}", f"physcore {version} {build}"]
    return " · ".join(parts)


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
