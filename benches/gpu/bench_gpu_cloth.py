"""A hanging cloth (springs with dashpots) on the GPU path beside the CPU path: particle-steps per
second, time per step and agreement.

    python benches/gpu/bench_gpu_cloth.py [--device gpu|gpu:lavapipe] [--n 64,256] [--steps 50]

Each n × n sheet (structural, shear and bend springs, k = 2000 N/m, dashpots, gravity, linear
drag, two corners pinned: the ``cloth`` scene's parts) is stepped with velocity Verlet on the CPU
(float64, all threads, the best SIMD level) and on the device (f32, and f64 where the adapter has
it), after one warm-up call (the move to the device, the shaders' compilation). Prints the median
of three timed calls of ``--steps`` steps as particle-steps/s and milliseconds per step, the ratio
to the CPU, and the largest position difference from the CPU run after the same steps. The time
per step at small n is the device's floor (the submissions' latency): where it crosses the CPU's
is where a GPU starts to pay for a cloth. Where no device machine is lent, run it on lavapipe:
its figures show the path works and agrees, not GPU speed.
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
    s_ = 1.0 / (n - 1)
    gx, gy = np.meshgrid(np.arange(n) * s_, np.arange(n) * s_)
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], axis=1)
    pinned = np.zeros(n * n, dtype=bool)
    pinned[[0, n - 1]] = True
    m = 1.0 / (n * n)
    # 1/ω_max for k = 2000 N/m at this mass (half velocity Verlet's limit, as the cloth scene)
    dt = 1.0 / np.sqrt(16 * 2000.0 / m)
    s = pc.Scene(dim=3, integrator="verlet", dt=dt, device=device, precision=precision)
    s.add_particles(x, masses=m, pinned=pinned)
    i, j = pc.shapes.cloth_springs(n)
    s.add(pc.Springs(i, j, stiffness=2000.0, damping=100.0 * m))  # dashpot rate c/m = 100 1/s at every n
    s.add(pc.Gravity([0.0, 0.0, -9.81]))
    s.add(pc.Drag(0.5 * m))
    return s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="gpu or gpu:NAME (default: gpu, else gpu:lavapipe)")
    ap.add_argument("--n", default="32,128", help="comma-separated sheet sides")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--cpu-max", type=int, default=1 << 30,
                    help="run the CPU beside the device only up to this side (above it: no ratio, no difference)")
    args = ap.parse_args()
    require_release()
    print(header())
    device = device_of(args.device)
    print(f"# device: {device}; velocity Verlet, springs + dashpots + gravity + drag, median of 3 calls of {args.steps} steps (the read-back after them timed apart)")
    print("| n × n | springs | path | precision | particle-steps/s | ms/step | vs CPU | read-back ms | max |x - x_cpu| (m) |")
    print("|---:|---:|---|---|---:|---:|---:|---:|---:|")
    for n in (int(v) for v in args.n.split(",")):
        steps = args.steps
        ns = 6 * n * n - 10 * n + 2
        cpu = None
        if n <= args.cpu_max:
            cpu = scene(n, "cpu", None)
            t_cpu, r_cpu = timed(cpu, steps, lambda: cpu.positions)
            print(f"| {n}² | {ns} | CPU | f64 | {n * n * steps / t_cpu:.3g} | {1e3 * t_cpu / steps:.3g} | 1.00 | {1e3 * r_cpu:.3g} | 0 |", flush=True)
        for precision in ("f32", "f64"):
            s = scene(n, device, precision)
            try:
                t, r = timed(s, steps, lambda: s.positions)
            except pc.InvalidInputError as e:
                print(f"| {n}² | {ns} | {device} | {precision} | refused: {e} | | | | |")
                continue
            if cpu is None:
                print(f"| {n}² | {ns} | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | | {1e3 * r:.3g} | (no CPU run) |", flush=True)
                continue
            dx = float(np.abs(s.positions - cpu.positions).max())
            print(f"| {n}² | {ns} | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | {t_cpu / t:.2f} | {1e3 * r:.3g} | {dx:.1e} |", flush=True)


if __name__ == "__main__":
    main()
