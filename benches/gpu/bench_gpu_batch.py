"""A batch of three-body problems on the GPU path beside the CPU batch: ``Batch.from_scene(
pc.scenes.figure_eight(), M, device=...)`` (Yoshida 4, pairwise gravity inside each member), the
CPU batch's fused kernel (float64, all threads, the best SIMD level) against the device batch
(f32 and, where the adapter has it, f64: one dispatch per stage for all members).

    python benches/gpu/bench_gpu_batch.py [--device gpu|gpu:lavapipe] [--m 1024,16384] [--steps 1000] [--cpu-max 16384]

Prints the median of three timed calls of ``--steps`` steps (after a warm-up call: the build on
the device, the shaders' compilation) as particle-steps/s (3 particles a member), the ratio to
the CPU, and the largest position difference from the CPU batch after the same steps. The
members' state stays on the device between calls (a call reads the state back into the
batch's mirror once and writes no member: a member is written back when it is used), so the
figures include the read-back but not a write into every member. Beside them, what the host
pays: ``from_scene``'s time to build the f32 batch, and the median of five calls of one step
(the host's work around the device, and one step of it). On lavapipe (Mesa's CPU
Vulkan) they show the path works and agrees, not GPU speed. Target (issue "GPU fluids, grains
and batches"): 16,384 worlds at ≥ 5e9 particle-steps/s on an H100.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import header, require_release  # noqa: E402
from gpu_timing import device_of  # noqa: E402

import physcore as pc  # noqa: E402


def fan(m: int, device: str = "cpu", precision: str | None = None) -> pc.Batch:
    return pc.Batch.from_scene(pc.scenes.figure_eight(), m, positions=lambda k, x: x * (1 + 1e-6 * k),
                               device=device, precision=precision)


def one_step_call(b: pc.Batch) -> float:
    """The median of five calls of one step, s."""
    times = []
    for _ in range(5):
        t = time.perf_counter()
        b.step(1)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def timed(b: pc.Batch, steps: int) -> float:
    b.step(1)
    times = []
    for _ in range(3):
        t = time.perf_counter()
        b.step(steps)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device")
    ap.add_argument("--m", default="256,4096,16384")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--cpu-max", type=int, default=16384, help="largest M also run on the CPU")
    a = ap.parse_args()
    require_release()
    device = device_of(a.device)
    f64 = any(x["f64"] for x in pc.gpu_adapters() if device == "gpu" or "llvmpipe" in x["name"])
    print(header())
    print("| worlds | CPU f64 p-steps/s | device f32 p-steps/s | ratio | Δx f32 | device f64 p-steps/s | Δx f64 "
          "| f32 from_scene s | f32 call of 1 step ms |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for m in (int(v) for v in a.m.split(",")):
        row: dict[str, str] = {}
        cpu = None
        if m <= a.cpu_max:
            cpu = fan(m)
            row["cpu"] = f"{3 * m * a.steps / timed(cpu, a.steps):.3e}"
        for precision in ("f32", "f64") if f64 else ("f32",):
            t = time.perf_counter()
            g = fan(m, device, precision)
            built = time.perf_counter() - t
            row[precision] = f"{3 * m * a.steps / timed(g, a.steps):.3e}"
            if cpu is not None:
                row["dx" + precision] = f"{np.abs(g.positions - cpu.positions).max():.1e}"
            if precision == "f32":  # after the comparison: these steps put it ahead of the CPU batch
                row["build"], row["call"] = f"{built:.2f}", f"{1e3 * one_step_call(g):.1f}"
        ratio = f"{float(row['f32']) / float(row['cpu']):.2f}" if "cpu" in row else "—"
        print(f"| {m} | {row.get('cpu', '—')} | {row['f32']} | {ratio} | {row.get('dxf32', '—')} | "
              f"{row.get('f64', '—')} | {row.get('dxf64', '—')} | {row['build']} | {row['call']} |")


if __name__ == "__main__":
    main()
