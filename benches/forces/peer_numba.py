"""physcore next to well-written numba implementations of the cloth (WORKLOADS.md §2) and
direct-sum N-body (§3) reference workloads, measured in the same run on the same machine.

numba kernels: ``@njit(parallel=True, fastmath=False, cache=False)``, ``prange`` over particles,
gather only (each particle computes its own force; no atomics, no races).

* Cloth: G×G grid, structural+shear+bend springs (k = 100 N/m), kd = 0.1·sqrt(k m), gravity
  (0, 0, -9.81), row y = 0 pinned, semi-implicit Euler at dt = 0.25·sqrt(m/k). Per-particle CSR
  neighbour list (other index + rest length); every spring is evaluated from both ends. float32
  and float64 variants (all arithmetic in the array dtype). 20 warm-up steps (the first call
  compiles), then 3 blocks of S = 1000 (G=128) / 250 (G=256) steps; median. Metric: particle-steps/s.
* N-body: masses 1/N, G = 1, Plummer ε = 0.01, uniform ball at rest (bench_nbody.initial),
  leapfrog KDK at dt = 1e-3, one force evaluation per step (the end-of-step acceleration is kept
  for the next step's first kick, as physcore's Verlet does). 5 warm-up steps, then 3 blocks of
  S = 400 (N=1024) / 40 (N=4096); median. Metric: pair interactions/s credited N² per step.
  float64 and float32 variants: one kernel, compiled per dtype; every constant comes from a
  vector of the state's dtype (a Python float would promote float32 arithmetic to float64).

physcore runs the identical scene built by bench_cloth.build (float64) / bench_nbody.build
(float64, and precision="f32" for the N-body) with the same thread count. The ratio column
compares the same precision only (physcore f64 / numba f64, physcore f32 / numba f32; "—" where
physcore has no row of that precision). Before timing, physcore and numba are stepped from the
same initial state and their positions compared (cloth: 50 steps, N-body: 20 steps).

Usage: python benches/forces/peer_numba.py [--only cloth|nbody] [--sizes ...] [--threads 2]
Needs numba: ``pip install numba`` (or ``pip install ".[bench]"``).
"""
from __future__ import annotations

import argparse
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment before numpy loads
import numpy as np

try:
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover - optional dependency
    sys.exit('peer_numba.py needs numba: `pip install numba` (or `pip install ".[bench]"` from the repo root)')

import bench_cloth
import bench_nbody
from physcore.scenes import cloth_springs

JIT = dict(parallel=True, fastmath=False, cache=False)  # the prange kernels
DRIVER = dict(parallel=False, fastmath=False, cache=False)  # step loops that call the kernels (no prange of their own)


# --------------------------------------------------------------------------------------------
# Cloth
# --------------------------------------------------------------------------------------------
# p = [k, kd, dt, 1/m, g_z, 0, 1], an array of the state's dtype, so that every constant in the
# kernel is already float32 for the float32 variant (a Python float literal would promote the
# arithmetic to float64 in numba).


@njit(**JIT)
def _cloth_step(x, v, xn, vn, indptr, nbr, rest, pinned, p):
    """One semi-implicit Euler step, reading (x, v) and writing (xn, vn): each particle gathers
    its spring forces from its own CSR row, then kicks and drifts. Double buffering keeps the
    single parallel loop race-free."""
    k = p[0]
    kd = p[1]
    dt = p[2]
    inv_m = p[3]
    gz = p[4]
    zero = p[5]
    one = p[6]
    n = x.shape[0]
    for i in prange(n):
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        xi2 = x[i, 2]
        if pinned[i]:
            xn[i, 0] = xi0
            xn[i, 1] = xi1
            xn[i, 2] = xi2
            vn[i, 0] = zero
            vn[i, 1] = zero
            vn[i, 2] = zero
        else:
            vi0 = v[i, 0]
            vi1 = v[i, 1]
            vi2 = v[i, 2]
            fx = zero
            fy = zero
            fz = zero
            for e in range(indptr[i], indptr[i + 1]):
                j = nbr[e]
                dx = x[j, 0] - xi0
                dy = x[j, 1] - xi1
                dz = x[j, 2] - xi2
                l2 = dx * dx + dy * dy + dz * dz
                if l2 > zero:  # coincident endpoints: axis undefined, no force (as physcore)
                    ln = np.sqrt(l2)
                    il = one / ln
                    nx = dx * il
                    ny = dy * il
                    nz = dz * il
                    vrel = (v[j, 0] - vi0) * nx + (v[j, 1] - vi1) * ny + (v[j, 2] - vi2) * nz
                    mag = k * (ln - rest[e]) + kd * vrel
                    fx += mag * nx
                    fy += mag * ny
                    fz += mag * nz
            v0 = vi0 + dt * (fx * inv_m)
            v1 = vi1 + dt * (fy * inv_m)
            v2 = vi2 + dt * (fz * inv_m + gz)
            vn[i, 0] = v0
            vn[i, 1] = v1
            vn[i, 2] = v2
            xn[i, 0] = xi0 + dt * v0
            xn[i, 1] = xi1 + dt * v1
            xn[i, 2] = xi2 + dt * v2


# Block driver: the S-step loop runs inside one (serial) njit call that calls the prange kernel,
# ping-ponging between the two buffers. Measured against a Python loop over the jitted step on the
# 2-core machine (best of 4 blocks): G=128 f32 21.9 vs 17.7 M particle-steps/s, f64 19.7 vs 17.9;
# G=256 f32 20.5 vs 20.3, f64 19.9 vs 18.1. The in-njit loop is never slower, so it is used.
@njit(**DRIVER)
def _cloth_block(x, v, xb, vb, indptr, nbr, rest, pinned, p, steps):
    for _ in range(steps // 2):
        _cloth_step(x, v, xb, vb, indptr, nbr, rest, pinned, p)
        _cloth_step(xb, vb, x, v, indptr, nbr, rest, pinned, p)
    if steps % 2:
        _cloth_step(x, v, xb, vb, indptr, nbr, rest, pinned, p)
        x[:, :] = xb
        v[:, :] = vb


class NumbaCloth:
    """The §2 cloth with the state in `dtype`; after step(s) the state is in self.x / self.v."""

    def __init__(self, g: int, dtype=np.float32):
        n = g * g
        m = 1.0 / n
        k = 100.0
        s = 1.0 / (g - 1)
        gx, gy = np.meshgrid(np.arange(g) * s, np.arange(g) * s)  # same construction as bench_cloth.build
        x64 = np.stack([gx.ravel(), gy.ravel(), np.zeros(n)], axis=1)
        a, b = cloth_springs(g)
        rest64 = np.linalg.norm(x64[b] - x64[a], axis=1)  # rest length = initial distance
        # CSR: row i lists every spring touching i (other end + rest length).
        src = np.concatenate([a, b])
        order = np.argsort(src, kind="stable")
        # Unsigned indices: numba adds a negative-index wraparound fix-up to every signed index; with
        # uint64 the inner loop loses ~20 instructions per spring (checked in the assembly) and ran
        # 5-20 % faster.
        self.nbr = np.concatenate([b, a])[order].astype(np.uint64)
        self.rest = np.concatenate([rest64, rest64])[order].astype(dtype)
        self.indptr = np.zeros(n + 1, dtype=np.uint64)
        np.cumsum(np.bincount(src, minlength=n), out=self.indptr[1:])
        self.n_springs = len(a)
        self.pinned = np.zeros(n, dtype=np.bool_)
        self.pinned[:g] = True
        self.x = np.ascontiguousarray(x64, dtype=dtype)
        self.v = np.zeros((n, 3), dtype=dtype)
        self.xb = np.empty_like(self.x)
        self.vb = np.empty_like(self.v)
        self.p = np.array([k, 0.1 * math.sqrt(k * m), 0.25 * math.sqrt(m / k), 1.0 / m, -9.81, 0.0, 1.0], dtype=dtype)
        self.dt = float(self.p[2])

    def step(self, steps: int) -> None:
        _cloth_block(self.x, self.v, self.xb, self.vb, self.indptr, self.nbr, self.rest, self.pinned, self.p, steps)


# --------------------------------------------------------------------------------------------
# N-body
# --------------------------------------------------------------------------------------------


# Receivers are processed in tiles of TILE consecutive particles (one prange iteration per tile).
# For each source j the innermost loop runs over the tile's receivers: element-wise, no
# reduction, so LLVM vectorises it (4-wide AVX2 div/sqrt) without fastmath. Each receiver still
# sums over j = 0..N-1 in order, so the result is bit-identical to the naive loop
# (`_nbody_accel_naive`, whose reduction over j cannot vectorise without fastmath); the tiled
# kernel was 2.5-3x faster than the naive one on the 2-core machine. TILE = 32..256 all measured
# the same; 64 keeps 16 tiles (8 per thread) at N = 1024.
TILE = 64


# p = [ε², G, dt, dt/2, 0], an array of the state's dtype (as the cloth's p): with float32 state
# every operand is float32 and no Python float literal promotes the arithmetic to float64.
P_EPS2, P_G, P_DT, P_HALF, P_ZERO = range(5)


@njit(**JIT)
def _nbody_accel(px, py, pz, m, ax, ay, az, p):
    """a_i = G Σ_j m_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2}, all N² terms (the self term is 0
    since ε > 0); prange over tiles of receivers i, structure-of-arrays positions; all arithmetic
    in the dtype of the arrays."""
    n = px.shape[0]
    eps2 = p[P_EPS2]
    gconst = p[P_G]
    for b in prange((n + TILE - 1) // TILE):
        i0 = b * TILE
        w = min(TILE, n - i0)
        xi = px[i0:i0 + w].copy()
        yi = py[i0:i0 + w].copy()
        zi = pz[i0:i0 + w].copy()
        sx = np.zeros_like(xi)  # the state's dtype (np.zeros(w) would be float64)
        sy = np.zeros_like(xi)
        sz = np.zeros_like(xi)
        for j in range(n):
            xj = px[j]
            yj = py[j]
            zj = pz[j]
            mj = m[j]
            for q in range(w):
                dx = xj - xi[q]
                dy = yj - yi[q]
                dz = zj - zi[q]
                r2 = dx * dx + dy * dy + dz * dz + eps2
                s = mj / (r2 * np.sqrt(r2))
                sx[q] += s * dx
                sy[q] += s * dy
                sz[q] += s * dz
        for q in range(w):
            ax[i0 + q] = gconst * sx[q]
            ay[i0 + q] = gconst * sy[q]
            az[i0 + q] = gconst * sz[q]


@njit(**JIT)
def _nbody_accel_naive(px, py, pz, m, ax, ay, az, p):
    """The textbook kernel: prange over i, scalar reduction over j (shown for reference)."""
    n = px.shape[0]
    eps2 = p[P_EPS2]
    gconst = p[P_G]
    zero = p[P_ZERO]
    for i in prange(n):
        xi = px[i]
        yi = py[i]
        zi = pz[i]
        sx = zero
        sy = zero
        sz = zero
        for j in range(n):
            dx = px[j] - xi
            dy = py[j] - yi
            dz = pz[j] - zi
            r2 = dx * dx + dy * dy + dz * dz + eps2
            s = m[j] / (r2 * np.sqrt(r2))
            sx += s * dx
            sy += s * dy
            sz += s * dz
        ax[i] = gconst * sx
        ay[i] = gconst * sy
        az[i] = gconst * sz


def _make_nbody_block(accel):
    @njit(**DRIVER)
    def block(px, py, pz, vx, vy, vz, ax, ay, az, m, p, steps):
        """`steps` leapfrog KDK steps; (ax, ay, az) hold the acceleration at the current positions
        on entry and on exit, so each step costs one force evaluation. The O(N) kick/drift loops
        are serial: at N <= 4096 they take microseconds, less than starting a parallel region."""
        dt = p[P_DT]
        half = p[P_HALF]
        n = px.shape[0]
        for _ in range(steps):
            for i in range(n):
                vx[i] += half * ax[i]
                vy[i] += half * ay[i]
                vz[i] += half * az[i]
                px[i] += dt * vx[i]
                py[i] += dt * vy[i]
                pz[i] += dt * vz[i]
            accel(px, py, pz, m, ax, ay, az, p)
            for i in range(n):
                vx[i] += half * ax[i]
                vy[i] += half * ay[i]
                vz[i] += half * az[i]

    return block


_nbody_block = {"tiled": _make_nbody_block(_nbody_accel), "naive": _make_nbody_block(_nbody_accel_naive)}


class NumbaNBody:
    """The §3 N-body with the state (and all arithmetic) in `dtype`."""

    def __init__(self, n: int, kernel: str = "tiled", dtype=np.float64):
        self.block = _nbody_block[kernel]
        x = bench_nbody.initial(n)
        self.px, self.py, self.pz = (np.ascontiguousarray(x[:, d], dtype=dtype) for d in range(3))
        self.vx, self.vy, self.vz = (np.zeros(n, dtype) for _ in range(3))
        self.ax, self.ay, self.az = (np.zeros(n, dtype) for _ in range(3))
        self.m = np.full(n, 1.0 / n, dtype)
        dt = 1e-3
        self.p = np.array([0.01**2, 1.0, dt, 0.5 * dt, 0.0], dtype)
        self.dt = float(self.p[P_DT])
        self.accel = _nbody_accel if kernel == "tiled" else _nbody_accel_naive
        self.accel(self.px, self.py, self.pz, self.m, self.ax, self.ay, self.az, self.p)

    @property
    def positions(self) -> np.ndarray:
        return np.stack([self.px, self.py, self.pz], axis=1)

    def step(self, steps: int) -> None:
        self.block(self.px, self.py, self.pz, self.vx, self.vy, self.vz, self.ax, self.ay, self.az,
                   self.m, self.p, steps)


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


def run_cloth(sizes, threads, rows, checks) -> None:
    for g in sizes:
        n = g * g
        steps = 1000 if g <= 128 else 250
        # correctness: 50 steps from the same initial state
        ref = bench_cloth.build(g, threads)
        ref.step(50)
        nb = NumbaCloth(g, np.float64)
        nb.step(50)
        d64 = float(np.abs(ref.positions - nb.x).max())
        nb32 = NumbaCloth(g, np.float32)
        nb32.step(50)
        d32 = float(np.abs(ref.positions - nb32.x).max())
        sag = float(-ref.positions[:, 2].min())
        checks.append(f"cloth {g}², 50 steps: max |x_physcore − x_numba-f64| = {d64:.2e} m, "
                      f"vs numba-f32 = {d32:.2e} m (max sag {sag:.2e} m)")
        del ref, nb, nb32

        rates = {}
        scene = bench_cloth.build(g, threads)
        scene.step(20)
        t = median_block_time(scene.step, steps)
        assert np.isfinite(scene.positions).all()
        rates["physcore f64"] = n * steps / t
        del scene
        for label, dt in (("numba f64", np.float64), ("numba f32", np.float32)):
            c = NumbaCloth(g, dt)
            c.step(20)  # first call compiles (for this dtype); excluded
            t = median_block_time(c.step, steps)
            assert np.isfinite(c.x).all()
            rates[label] = n * steps / t
        _add_rows(rows, "cloth", f"{g}² (N={n})", "particle-steps/s", rates)


def run_nbody(sizes, threads, rows, checks) -> None:
    for n in sizes:
        steps = 400 if n <= 1024 else 40
        # correctness: 20 steps from the same initial state, each precision against the other code
        # and against float64
        x = {}
        for label, make in (("physcore f64", lambda: bench_nbody.build(n, threads)),
                            ("physcore f32", lambda: bench_nbody.build(n, threads, "f32")),
                            ("numba f64", lambda: NumbaNBody(n)),
                            ("numba f64, naive loop", lambda: NumbaNBody(n, "naive")),
                            ("numba f32", lambda: NumbaNBody(n, dtype=np.float32))):
            sim = make()
            sim.step(20)
            x[label] = np.asarray(sim.positions, dtype=np.float64)
            del sim

        def d(a, b, x=x):
            return float(np.abs(x[a] - x[b]).max())

        moved = float(np.abs(x["physcore f64"] - bench_nbody.initial(n)).max())
        checks.append(f"N-body N={n}, 20 steps: max |x_physcore − x_numba-f64| = {d('physcore f64', 'numba f64'):.2e} "
                      f"(max displacement {moved:.2e}); numba tiled vs naive kernel: "
                      f"{d('numba f64', 'numba f64, naive loop'):.1e}")
        checks.append(f"N-body N={n}, 20 steps, float32: max |x_physcore-f32 − x_numba-f32| = "
                      f"{d('physcore f32', 'numba f32'):.2e}; vs float64: physcore-f32 − physcore-f64 "
                      f"{d('physcore f32', 'physcore f64'):.2e}, numba-f32 − numba-f64 {d('numba f32', 'numba f64'):.2e}")
        del x

        rates = {}
        for label, make in (("physcore f64", lambda: bench_nbody.build(n, threads)),
                            ("numba f64", lambda: NumbaNBody(n)),
                            ("numba f64, naive loop", lambda: NumbaNBody(n, "naive")),
                            ("physcore f32", lambda: bench_nbody.build(n, threads, "f32")),
                            ("numba f32", lambda: NumbaNBody(n, dtype=np.float32))):
            sim = make()
            sim.step(5)
            t = median_block_time(sim.step, steps)
            assert np.isfinite(sim.positions).all()
            rates[label] = n * n * steps / t
            del sim
        _add_rows(rows, "N-body", f"N={n}", "pair interactions/s", rates)
    if sizes:
        ops = {**f64_instructions(_nbody_accel), **f64_instructions(_nbody_block["tiled"])}
        checks.append("numba f32 N-body kernel and driver: "
                      + ("no double-precision arithmetic in the generated code" if not ops else
                         f"DOUBLE-PRECISION INSTRUCTIONS in the generated code (promoted to float64): {ops}"))


def f64_instructions(dispatcher, dtype=numba.float32) -> dict:
    """Double-precision arithmetic / conversion instructions (x86 `...sd`/`...pd` mnemonics, with the
    parallel gufuncs included) in the code numba generated for the signatures of `dispatcher` whose
    array arguments are all `dtype`: empty when nothing was promoted to float64. Other ISAs: {}."""
    import platform
    import re
    from collections import Counter

    if platform.machine().lower() not in ("x86_64", "amd64"):
        return {}
    found: Counter = Counter()
    for sig in dispatcher.signatures:
        arrays = [a for a in sig if isinstance(a, numba.types.Array)]
        if not arrays or any(a.dtype != dtype for a in arrays):
            continue
        asm = dispatcher.inspect_asm(sig)
        found.update(re.findall(r"\b(v?(?:add|sub|mul|div|sqrt|min|max|f[n]?m(?:add|sub)\w*|cvtss2|cvtsi2)(?:sd|pd))\b", asm))
    return dict(found)


def _add_rows(rows, workload, size, metric, rates) -> None:
    """Ratio = physcore / this at the same precision (f64 vs f64, f32 vs f32); "—" for the physcore
    rows and where physcore has no row of that precision."""
    import re

    for label, r in rates.items():
        prec = re.search(r"\bf(32|64)\b", label)
        ref = rates.get(f"physcore {prec.group(0)}") if prec else None
        ratio = "—" if label.startswith("physcore") or ref is None else f"{ref / r:.2f}"
        rows.append([workload, size, label, f"{si(r)} {metric}", ratio])


def numba_cpu() -> str:
    """The CPU numba compiles for (its native ISA unless NUMBA_CPU_NAME says otherwise)."""
    try:
        import llvmlite.binding as ll

        return numba.config.CPU_NAME or ll.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - informational only
        return "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=["cloth", "nbody"])
    ap.add_argument("--sizes", help="comma-separated; G for the cloth (default 128,256), N for the N-body "
                    "(default 1024,4096); with both workloads selected, values < 512 go to the cloth")
    ap.add_argument("--threads", type=int, default=2, help="threads for physcore and numba (default 2)")
    args = ap.parse_args()
    require_release()
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))

    cloth_sizes, nbody_sizes = [128, 256], [1024, 4096]
    if args.sizes:
        vals = [int(s) for s in args.sizes.split(",")]
        if args.only == "cloth":
            cloth_sizes, nbody_sizes = vals, []
        elif args.only == "nbody":
            cloth_sizes, nbody_sizes = [], vals
        else:
            cloth_sizes = [v for v in vals if v < 512]
            nbody_sizes = [v for v in vals if v >= 512]
    if args.only == "cloth":
        nbody_sizes = []
    elif args.only == "nbody":
        cloth_sizes = []

    rows, checks = [], []
    if cloth_sizes:
        run_cloth(cloth_sizes, args.threads, rows, checks)
    if nbody_sizes:
        run_nbody(nbody_sizes, args.threads, rows, checks)

    print(f"numba {numba.__version__} (LLVM target {numba_cpu()}: numba at its native ISA), threading layer "
          f"{numba.threading_layer()}, {numba.get_num_threads()} numba threads; physcore threads={args.threads}; "
          f"os.cpu_count()={os.cpu_count()}\n")
    print(header(args.threads))
    print(table(["workload", "size", "implementation", "rate", "physcore / this (same precision)"], rows))
    print("(ratio: physcore / this at the same precision; — on physcore's rows and where physcore has no row "
          "of that precision)")
    print("\nCorrectness (same initial state, same number of steps):")
    for c in checks:
        print("  " + c)


if __name__ == "__main__":
    main()
