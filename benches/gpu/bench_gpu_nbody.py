"""Direct N-body on the GPU path beside the CPU path: pairs per second and agreement.

    python benches/gpu/bench_gpu_nbody.py [--device gpu|gpu:lavapipe] [--n 4096,16384] [--steps 10]

Each size is stepped with velocity Verlet on the CPU (float64, all threads) and on the device
(f32, and f64 where the adapter has it), after one warm-up call (which moves the particles to the
device and compiles the kernels). Prints the median of three timed calls of ``--steps`` steps as
pairs/s (N² per step), the ratio to the CPU, and the largest position difference from the CPU
run after the same steps. Where no device machine is lent, run it on lavapipe (Mesa's CPU
Vulkan): its figures show the path works and agrees, not GPU speed.
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


def scene(n: int, device: str, precision: str | None) -> pc.Scene:
    rng = np.random.default_rng(0)
    s = pc.Scene(dim=3, integrator="verlet", dt=1e-4, device=device, precision=precision)
    s.add_particles(rng.normal(size=(n, 3)), 0.1 * rng.normal(size=(n, 3)), masses=1.0 / n)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    return s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="gpu or gpu:NAME (default: gpu, else gpu:lavapipe)")
    ap.add_argument("--n", default="4096", help="comma-separated sizes")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--cpu-max", type=int, default=16384, help="largest N also run on the CPU (its N² takes long)")
    args = ap.parse_args()
    require_release()
    print(header())
    device = device_of(args.device)
    print(f"# device: {device}; velocity Verlet, softening 0.05, median of 3 calls of {args.steps} steps (the read-back after them timed apart)")
    print("| N | path | precision | pairs/s | ms/step | vs CPU | read-back ms | max |x - x_cpu| (m) |")
    print("|---:|---|---|---:|---:|---:|---:|---:|")
    for n in (int(v) for v in args.n.split(",")):
        steps = args.steps
        cpu = scene(n, "cpu", None) if n <= args.cpu_max else None
        t_cpu, r_cpu = timed(cpu, steps, lambda: cpu.positions) if cpu is not None else (float("nan"), float("nan"))
        if cpu is not None:
            print(f"| {n} | CPU | f64 | {n * n * steps / t_cpu:.3g} | {1e3 * t_cpu / steps:.3g} | 1.00 | {1e3 * r_cpu:.3g} | 0 |", flush=True)
        for precision in ("f32", "f64"):
            s = scene(n, device, precision)
            try:
                t, r = timed(s, steps, lambda: s.positions)
            except pc.InvalidInputError as e:
                print(f"| {n} | {device} | {precision} | refused: {e} | | | | |")
                continue
            dx = float(np.abs(s.positions - cpu.positions).max()) if cpu is not None else float("nan")
            print(f"| {n} | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | {t_cpu / t:.2f} | {1e3 * r:.3g} | {dx:.1e} |", flush=True)


if __name__ == "__main__":
    main()
