"""Gray–Scott reaction–diffusion, the wave equation and the stable fluid on the GPU path beside the
CPU path: cell-steps per second and agreement.

    python benches/gpu/bench_gpu_grids.py [--device gpu|gpu:lavapipe] [--n 512,2048] [--steps 50] [--kinds gs,wave,fluid]

Each n × n grid (Gray–Scott: periodic, Pearson's maze, seeded; wave: a 1 m square of free faces,
c = 1 m/s, undamped, a Gaussian bump at the CFL step, 0.9 of the limit; the fluid: ``fluid`` below) is stepped on the CPU (float64, all threads, the
best SIMD level) and on the device (f32, and f64 where the adapter has it), after one warm-up
call (which moves the grid to the device and compiles the kernel). Prints the median of three
timed calls of ``--steps`` steps as cell-steps/s, the ratio to the CPU, and the largest
difference of u and v from the CPU run after the same steps. Where no device machine is lent,
run it on lavapipe (Mesa's CPU Vulkan): its figures show the path works and agrees, not GPU
speed. ``../shared/gpu/cuda_reference.py --only gs --grid N`` times the same Gray–Scott stencil
in CUDA (it has no wave kernel, and no fluid; benches/gpu/cuda_wave.py is the wave's).
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


def wave(n: int, device: str, precision: str | None) -> tuple[pc.Scene, pc.grids.Wave]:
    s = pc.Scene(dim=2, device=device, precision=precision)
    w = s.add(pc.grids.Wave((n, n), 1.0 / n, c=1.0, edges="free", name="pond"))
    x = (np.arange(n) + 0.5) / n
    r2 = (x[:, None] - 0.4) ** 2 + (x[None, :] - 0.55) ** 2
    w.u = 0.01 * np.exp(-r2 / 0.002)
    s.dt = s.auto_dt()
    return s, w


def fluid(n: int, device: str, precision: str | None) -> tuple[pc.Scene, pc.grids.StableFluid]:
    """A smoke plume in a 1 m square: a vent, buoyancy, vorticity confinement, MacCormack and the
    incremental projection (the defaults), the pressure to 1e-5, dt = 1/n s (CFL 1 at 1 m/s)."""
    from physcore.grids import Source, StableFluid
    s = pc.Scene(dim=2, dt=1.0 / n, device=device, precision=precision)
    vent = Source(density=1.0, temperature=1.0, velocity=(0.0, 0.3), center=(0.5, 0.1), radius=0.06)
    f = s.add(StableFluid((n, n), 1.0 / n, buoyancy=(0.0, 4.0), vorticity=0.3, tolerance=1e-5, sources=[vent], name="smoke"))
    return s, f


# What each kind reads after its steps (timed apart): Gray–Scott its books (the amounts, summed
# over the fields read back), the wave its displacement u.
KINDS = {
    "gs": ("Gray-Scott (maze), dt = 1", scene, ("u", "v"), lambda g: g.books()),
    "wave": ("wave (free faces, undamped, CFL 0.9)", wave, ("u",), lambda g: g.field("u")),
    "fluid": ("stable fluid (smoke plume, MGPCG to 1e-5)", fluid, ("density", "u", "v"), lambda g: g.field("density")),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="gpu or gpu:NAME (default: gpu, else gpu:lavapipe)")
    ap.add_argument("--n", default="512", help="comma-separated grid sides")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--kinds", default="gs,wave", help="comma-separated: gs, wave, fluid")
    ap.add_argument("--cpu-max", type=int, default=1 << 30,
                    help="run the CPU beside the device only up to this side (above it: no ratio, no difference)")
    args = ap.parse_args()
    require_release()
    print(header())
    device = device_of(args.device)
    for kind in args.kinds.split(","):
        what, make, names, read = KINDS[kind]
        print(f"\n# device: {device}; {what}; median of 3 calls of {args.steps} steps (the read-back after them timed apart)")
        print("| n × n | path | precision | cell-steps/s | ms/step | vs CPU | read-back ms | max difference of the fields from the CPU's |")
        print("|---:|---|---|---:|---:|---:|---:|---:|")
        for n in (int(v) for v in args.n.split(",")):
            steps = args.steps
            gc = None
            if n <= args.cpu_max:
                cpu, gc = make(n, "cpu", None)
                t_cpu, r_cpu = timed(cpu, steps, lambda gc=gc: read(gc))
                print(f"| {n}² | CPU ({pc.simd_level()}) | f64 | {n * n * steps / t_cpu:.3g} | {1e3 * t_cpu / steps:.3g} | 1.00 | {1e3 * r_cpu:.3g} | 0 |", flush=True)
            for precision in ("f32", "f64"):
                s, g = make(n, device, precision)
                try:
                    t, r = timed(s, steps, lambda g=g: read(g))
                except pc.InvalidInputError as e:
                    print(f"| {n}² | {device} | {precision} | refused: {e} | | | | |")
                    continue
                if gc is None:
                    print(f"| {n}² | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | | {1e3 * r:.3g} | (no CPU run) |", flush=True)
                    continue
                d = max(float(np.abs(g.field(f) - gc.field(f)).max()) for f in names)
                print(f"| {n}² | {device} | {precision} | {n * n * steps / t:.3g} | {1e3 * t / steps:.3g} | {t_cpu / t:.2f} | {1e3 * r:.3g} | {d:.1e} |", flush=True)

if __name__ == "__main__":
    main()
