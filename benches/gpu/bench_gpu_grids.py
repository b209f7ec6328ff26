"""Gray–Scott reaction–diffusion on the GPU path beside the CPU path: cell-steps per second and
agreement.

    python benches/gpu/bench_gpu_grids.py [--device gpu|gpu:lavapipe] [--n 512,2048] [--steps 50]

Each n × n periodic grid (Pearson's maze, seeded) is stepped on the CPU (float64, all threads, the
best SIMD level) and on the device (f32, and f64 where the adapter has it), after one warm-up
call (which moves the grid to the device and compiles the kernel). Prints the median of three
timed calls of ``--steps`` steps as cell-steps/s, the ratio to the CPU, and the largest
difference of u and v from the CPU run after the same steps. Where no device machine is lent,
run it on lavapipe (Mesa's CPU Vulkan): its figures show the path works and agrees, not GPU
speed. ``../shared/gpu/cuda_reference.py --only gs --grid N`` times the same stencil in CUDA.
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


def scene(n: int, device: str, precision: str | None) -> tuple[pc.Scene, pc.grids.GrayScott]:
    s = pc.Scene(dim=2, dt=1.0, device=device, precision=precision)
    g = s.add(pc.grids.GrayScott((n, n), 2.5 / 256, preset="maze"))
    g.seed(1, squares=8, size=0.1)
    return s, g


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="gpu or gpu:NAME (default: gpu, else gpu:lavapipe)")
    ap.add_argument("--n", default="512", help="comma-separated grid sides")
    ap.add_argument("--steps", type=int, default=50)
    args = ap.parse_args()
    require_release()
    print(header())
    device = device_of(args.device)
    print(f"# device: {device}; Gray-Scott (maze), dt = 1, median of 3 calls of {args.steps} steps (the read-back after them timed apart)")
    print("| n × n | path | precision | cell-steps/s | ms/step | vs CPU | read-back ms | max |u - u_cpu|, |v - v_cpu| |")
    print("|---:|---|---|---:|---:|---:|---:|---:|")
    for n in (int(v) for v in args.n.split(",")):
        steps = args.steps
        cpu, gc = scene(n, "cpu", None)
        t_cpu, r_cpu = timed(cpu, steps, gc.books)
        print(f"| {n}² | CPU ({pc.simd_level()}) | f64 | {n * n * steps / t_cpu:.3g} | {1e3 * t_cpu / steps:.3g} | 1.00 | {1e3 * r_cpu:.3g} | 0 |", flush=True)
        for precision in ("f32", "f64"):
            s, g = scene(n, device, precision)
            try:
                t, r = timed(s, steps, g.books)
            except pc.InvalidInputError as e:
                print(f"| {n}² | {device} | {precision} | refused: {e} | | | | |")
                continue
            d = max(float(np.abs(g.field(f) - gc.field(f)).max()) for f in ("u", "v"))
            print(f"| {n}² | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | {t_cpu / t:.2f} | {1e3 * r:.3g} | {d:.1e} |", flush=True)


if __name__ == "__main__":
    main()
