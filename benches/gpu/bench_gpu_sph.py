"""WCSPH or DFSPH (``--method dfsph``) on the GPU path beside the CPU path, at the scene level:
the dam break (``pc.scenes.dam_break(method="wcsph", n=N)``, 2D: 2N² water particles in a 3-layer tank; 3D with
``--dim 3``: 2N³·depth/width) stepped on the CPU (float64, all threads, the best SIMD level) and
on the device (f32, the scene's precision on a GPU).

    python benches/gpu/bench_gpu_sph.py [--device gpu|gpu:lavapipe] [--n 72,144,720] [--steps 20] [--cpu-max 144] [--dim 2] [--method wcsph|dfsph]

Prints the median of three timed calls of ``--steps`` steps (after a warm-up call: the move to
the device, the shaders' compilation) as particle-steps/s, the ratio to the CPU, the read-back
of one frame (positions), and the largest position difference from the CPU run after the same
steps (relative to the tank's length). Each call of steps also checkpoints the state (one
read-back), as every `Scene.step` does. On lavapipe (Mesa's CPU Vulkan) the figures show the
path works and agrees, not GPU speed. ``rust_core/gpu/tests/sph_bench.rs`` times the bare device
step (no checkpoint) at 4M (2D) and 1M (3D).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import header, require_release  # noqa: E402
from gpu_timing import device_of, timed  # noqa: E402

import physcore as pc  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device")
    ap.add_argument("--n", default="24,72,144")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--cpu-max", type=int, default=144, help="largest N also run on the CPU")
    ap.add_argument("--dim", type=int, default=2)
    ap.add_argument("--method", default="wcsph", choices=["wcsph", "dfsph"])
    a = ap.parse_args()
    require_release()
    device = device_of(a.device)
    print(header())
    print(f"{a.method.upper()} dam break, {a.dim}D")
    print("| N across | particles | CPU f64 p-steps/s | device f32 p-steps/s | ratio | read ms | Δx |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in (int(v) for v in a.n.split(",")):
        row: dict[str, str] = {}
        cpu = None
        if n <= a.cpu_max:
            cpu = pc.scenes.dam_break(dim=a.dim, n=n, method=a.method)
            t_cpu, _ = timed(cpu, a.steps, lambda s=cpu: s.positions)
            row["cpu"] = f"{cpu.n_particles * a.steps / t_cpu:.3e}"
        s = pc.scenes.dam_break(dim=a.dim, n=n, method=a.method, device=device)
        t, r = timed(s, a.steps, lambda s=s: s.positions)
        rate = s.n_particles * a.steps / t
        row["f32"], row["read"], row["N"] = f"{rate:.3e}", f"{r * 1e3:.1f}", str(s.n_particles)
        row["ratio"] = f"{rate / float(row['cpu']):.2f}" if "cpu" in row else "—"
        if cpu is not None and s.step_count == cpu.step_count:
            row["dx"] = f"{np.abs(s.positions - cpu.positions).max() / 4.0:.1e}"  # over the tank's length
        print(f"| {n} | {row['N']} | {row.get('cpu', '—')} | {row['f32']} | {row['ratio']} | {row['read']} | {row.get('dx', '—')} |")


if __name__ == "__main__":
    main()
