"""The CUDA peer of the GPU wave bench: the same leapfrog step in CUDA C (CuPy), timed on the same
card in the same call, so the wave's speed has a ratio as Gray–Scott's has
(``../shared/gpu/cuda_reference.py`` has no wave kernel).

    python benches/gpu/cuda_wave.py [--n 4096] [--steps 200]      # on a machine with CuPy and CUDA
    python benches/gpu/cuda_wave.py --selftest                       # the numpy reference alone

The step is ``bench_gpu_grids.py``'s wave (undamped, free faces, k = (c dt/dx)² = 0.9²/2):
u⁺ = 2u − u⁻ + k L u, L the 5-point Laplacian with the ghost of a free face equal to the cell;
u⁺ is written over u⁻ and the two buffers swap roles, as physcore's kernel does (12 bytes a
cell-step in f32: u read, u⁻ read, u⁺ written; the neighbours come from the cache). One thread
a cell, blocks of 32 × 8, no books and no finiteness check (physcore's step books nothing when
undamped and checks once per submission). Before timing, 50 steps on a 96² grid are checked
against a numpy float64 run of the same scheme.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

SRC = r"""
extern "C" __global__ void
wave(const REAL* __restrict__ u, REAL* __restrict__ up, const int nx, const int ny, const REAL k)
{
    const int x = blockIdx.x * blockDim.x + threadIdx.x;
    const int y = blockIdx.y * blockDim.y + threadIdx.y;
    if (x >= nx || y >= ny) return;
    const int c = y * nx + x;
    const REAL uc = u[c];
    const REAL l = (x > 0 ? u[c - 1] : uc) + (x + 1 < nx ? u[c + 1] : uc)
                 + (y > 0 ? u[c - nx] : uc) + (y + 1 < ny ? u[c + nx] : uc) - (REAL)4 * uc;
    up[c] = (REAL)2 * uc - up[c] + k * l;
}
"""
K = 0.9 * 0.9 / 2.0


def start(n: int) -> np.ndarray:
    x = (np.arange(n) + 0.5) / n
    r2 = (x[None, :] - 0.4) ** 2 + (x[:, None] - 0.55) ** 2
    return 0.01 * np.exp(-r2 / 0.002)


def reference(n: int, steps: int) -> np.ndarray:
    """numpy float64, the same scheme (u⁻ = u at the start: at rest)."""
    u = start(n)
    um = u.copy()
    for _ in range(steps):
        p = np.pad(u, 1, mode="edge")
        lap = p[1:-1, :-2] + p[1:-1, 2:] + p[:-2, 1:-1] + p[2:, 1:-1] - 4.0 * u
        u, um = 2.0 * u - um + K * lap, u
    return u


class Sim:
    """The bump on an n × n grid in `prec`, on the GPU, stepped by `step()`; `u()` reads it back."""

    def __init__(self, cp, n: int, prec: str):
        real = {"f32": "float", "f64": "double"}[prec]
        self.dt = {"f32": np.float32, "f64": np.float64}[prec]
        self.kern = cp.RawKernel(f"#define REAL {real}\n" + SRC, "wave")
        self.cp, self.n, self.cur = cp, n, 0
        self.buf = [cp.asarray(start(n).astype(self.dt)), cp.asarray(start(n).astype(self.dt))]

    def step(self) -> None:
        c, n = self.cur, self.n
        self.kern(((n + 31) // 32, (n + 7) // 8), (32, 8), (self.buf[c], self.buf[1 - c], np.int32(n), np.int32(n), self.dt(K)))
        self.cur = 1 - c

    def u(self) -> np.ndarray:
        return self.cp.asnumpy(self.buf[self.cur])


def timed(cp, n: int, steps: int, prec: str) -> float:
    """Median seconds of 3 runs of `steps` steps, after 10 steps of warm-up."""
    sim = Sim(cp, n, prec)
    for _ in range(10):
        sim.step()
    times = []
    for _ in range(3):
        cp.cuda.Device().synchronize()
        t = time.perf_counter()
        for _ in range(steps):
            sim.step()
        cp.cuda.Device().synchronize()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", default="4096")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--selftest", action="store_true", help="the numpy reference only (no GPU)")
    args = ap.parse_args()
    ref = reference(96, 50)
    if args.selftest:
        print(f"numpy reference: 96², 50 steps, max |u| = {np.abs(ref).max():.6g}")
        return
    import cupy as cp

    print(f"# CUDA wave: {cp.cuda.runtime.getDeviceProperties(0)['name'].decode()}")
    for prec in ("f32", "f64"):
        # the check: 50 steps from the bump against numpy f64, before any timing
        check = Sim(cp, 96, prec)
        for _ in range(50):
            check.step()
        err = float(np.abs(check.u() - ref).max() / np.abs(ref).max())
        for n in (int(v) for v in args.n.split(",")):
            secs = timed(cp, n, args.steps, prec)
            rate = n * n * args.steps / secs
            print(f"cuda wave {prec}: N={n}x{n}, {rate:.4g} cells*steps per second, "
                  f"{1e3 * secs / args.steps:.4f} ms/step, check (96², 50 steps) max rel error {err:.1e}", flush=True)


if __name__ == "__main__":
    main()
