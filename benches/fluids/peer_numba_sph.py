"""numba peer for the SPH-2D dam break (WORKLOADS.md §1), the optional comparison for
benches/fluids/bench_sph.py, which imports this module and runs both in one process.

Physics (exactly the §1 reference; float32 storage *and* arithmetic: every constant the kernels
use comes from one float32 vector, so no Python float literal promotes anything to float64, and the
generated code was checked to contain no double-precision instruction):

* fluid column W = 1 m × H = 2 m in the lower-left corner of the tank [0, 4] × [0, 3] m, at rest;
  nx × 2nx lattice, dx = W/nx, particle (i, j) at ((i+½)dx, (j+½)dx); N = 2 nx²; m = ρ0 dx², ρ0 = 1000.
* 2D cubic spline (M4), h = 1.3 dx, support 2h, σ = 10/(7πh²), W = σ[¼(2−q)₊³ − (1−q)₊³].
* density by summation over all j within 2h (self included), every step; Tait EOS
  p = B[(ρ/ρ0)^7 − 1], B = ρ0 c0²/7, c0 = 10 √(2gH), clamped to p ≥ 0.
* dv_i/dt = −Σ_j m (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_iW_ij + g, Monaghan Π_ij = −α c0 μ_ij / ρ̄_ij,
  μ_ij = h v_ij·r_ij / (r_ij² + 0.01h²) for v_ij·r_ij < 0 (else Π = 0), α = 0.05, β = 0.
* fixed dt = 0.2 h/c0; semi-implicit Euler v += dt a, x += dt v; walls: clamp x into [0, 4] and
  y into [0, 3], and on a clamped axis an outward velocity component becomes −0.5 of itself.

Algorithm (one step = neighbour rebuild + density/pressure pass + force pass + integrate + walls):

1. ``_sort``: stable parallel counting sort of the particles into a uniform grid of cell size 2h
   (row-major, padded with one empty ring of cells so that every 3×3 block exists and no bounds
   test is needed). Each thread histograms its contiguous chunk of particles, one serial prefix
   sum over (cell, chunk) gives every chunk its own write offsets, and each thread scatters its
   chunk (x, y, vx, vy, id, cell key) into cell order. Particles are thus reordered into cell order
   every step; since last step's order is nearly sorted already, the scatter is nearly sequential.
2. ``_density``: ``prange`` over particles; the three cells of each of the three neighbouring rows
   are adjacent in cell order, so a particle's candidates are three contiguous index ranges. Stores
   ρ_i and p_i/ρ_i².
3. ``_force_integrate``: ``prange`` over particles, same three ranges; gathers the pressure and
   viscous terms (each pair is evaluated from both ends: gather only, no atomics, no races), then
   integrates and applies the walls, writing the new state into the buffers the next step's sort
   reads from (double buffering, so the loop never reads a value it wrote).

All kernels are ``@njit(parallel=True, fastmath=False)``; the S-step block loop runs in one serial
njit driver. Neighbour sums are plain scalar loops in neighbour order (strict IEEE; no
reassociation). Cell keys, cell offsets and hence all neighbour indices are uint64: numba adds a
negative-index wraparound fix-up to every signed index, and dropping it made the density pass
~1.9x and the force pass ~1.3x faster on the 2-core machine (same results bit for bit).
The test r < 2h stays a branch (evaluating sqrt and divides for all ~58 candidates branch-free was
~1.8x slower at rest, ~1.2x faster once the flow has developed); the viscosity switch v_ij·r_ij < 0
is branch-free (``min(vr, 0)``), which made the developed-flow force pass ~1.4x faster.

Surge front (``front()``): the largest x over all particles (the Martin & Moyce definition; the
tongue is a few particles thick, so this is the tip of the surge), returned in metres.

Usage: python benches/fluids/peer_numba_sph.py [--sizes 10k 40k 160k] [--threads 2] [--check]
Needs numba: ``pip install numba`` (or ``pip install ".[bench]"``).
"""
from __future__ import annotations

import argparse
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, median_block_time, si, table  # first: sets up the environment before numpy loads
import numpy as np

try:
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover - optional dependency
    sys.exit('peer_numba_sph.py needs numba: `pip install numba` (or `pip install ".[bench]"` from the repo root)')

JIT = dict(parallel=True, fastmath=False, cache=False)  # the prange kernels
DRIVER = dict(parallel=False, fastmath=False, cache=False)  # the block loop calling them

RHO0 = 1000.0
GRAV = 9.81
COL_W, COL_H = 1.0, 2.0
TANK_X, TANK_Y = 4.0, 3.0
SIZES = {"10k": 72, "40k": 144, "160k": 288}  # name -> nx
BLOCK = {"10k": 800, "40k": 200, "160k": 50}  # S, steps per timed block

# Slots of the float32 constant vector `c`.
(C_SUPP2, C_INVH, C_MSIG, C_B, C_INVRHO0, C_FORCE, C_VISC, C_EPSH2, C_DT, C_GY, C_XMAX, C_YMAX,
 C_INVCS, C_ZERO, C_ONE, C_TWO, C_THREE, C_QUARTER, C_3QUARTER, C_MHALF, NCONST) = range(21)


@njit(**JIT)
def _sort(x, y, vx, vy, ids, xs, ys, vxs, vys, idss, ks, tkey, counts, cellstart, c, ncx1, ncy1, gx, u1):
    """Stable parallel counting sort (x, y, vx, vy, ids) -> (xs, ys, vxs, vys, idss) in cell order;
    ks = cell key of each sorted particle; cellstart[k] = first sorted index in cell k
    (cellstart[-1] = N). ncx1/ncy1 = number of real cells − 1 per axis, gx = padded row length;
    all integers are uint64 (u1 = 1)."""
    n = x.shape[0]
    nchunks = counts.shape[0]
    ncell = cellstart.shape[0] - 1
    inv_cs = c[C_INVCS]
    chunk = (n + nchunks - 1) // nchunks
    for t in prange(nchunks):
        cnt = counts[t]
        cnt[:] = 0
        for i in range(t * chunk, min(n, (t + 1) * chunk)):
            ix = min(np.uint64(x[i] * inv_cs), ncx1)  # x >= 0 always (walls)
            iy = min(np.uint64(y[i] * inv_cs), ncy1)
            k = (iy + u1) * gx + ix + u1
            tkey[i] = k
            cnt[k] += u1
    off = np.uint64(0)
    for k in range(ncell):
        cellstart[k] = off
        for t in range(nchunks):
            m = counts[t, k]
            counts[t, k] = off
            off += m
    cellstart[ncell] = off
    for t in prange(nchunks):
        cnt = counts[t]
        for i in range(t * chunk, min(n, (t + 1) * chunk)):
            k = tkey[i]
            d = cnt[k]
            cnt[k] = d + u1
            xs[d] = x[i]
            ys[d] = y[i]
            vxs[d] = vx[i]
            vys[d] = vy[i]
            idss[d] = ids[i]
            ks[d] = k


@njit(**JIT)
def _density(x, y, ks, cellstart, rho, pr, c, gx, u1, u2):
    """rho_i = Σ_j m W_ij over the 3×3 cells (self included); pr_i = p_i / rho_i² (Tait, p >= 0)."""
    n = x.shape[0]
    supp2 = c[C_SUPP2]
    invh = c[C_INVH]
    zero = c[C_ZERO]
    one = c[C_ONE]
    two = c[C_TWO]
    quarter = c[C_QUARTER]
    msig = c[C_MSIG]
    invrho0 = c[C_INVRHO0]
    bb = c[C_B]
    for i in prange(n):
        xi = x[i]
        yi = y[i]
        k = ks[i]
        s = zero
        for kr in (k - gx, k, k + gx):  # rows below, at, above; cells kr-1..kr+1 are contiguous
            for j in range(cellstart[kr - u1], cellstart[kr + u2]):
                dx = xi - x[j]
                dy = yi - y[j]
                r2 = dx * dx + dy * dy
                if r2 < supp2:
                    q = np.sqrt(r2) * invh
                    a = two - q
                    b = max(one - q, zero)
                    s += quarter * a * a * a - b * b * b
        rhoi = msig * s
        rr = rhoi * invrho0
        rr2 = rr * rr
        rr7 = rr2 * rr2 * rr2 * rr
        p = max(bb * (rr7 - one), zero)
        rho[i] = rhoi
        pr[i] = p / (rhoi * rhoi)


@njit(**JIT)
def _force_integrate(x, y, vx, vy, idss, ks, cellstart, rho, pr, xo, yo, vxo, vyo, ido, c, gx, u1, u2):
    """a_i = −Σ_j m (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_iW_ij + g, then v += dt a, x += dt v and the
    walls. Reads the sorted state, writes the new one to (xo, yo, vxo, vyo, ido)."""
    n = x.shape[0]
    supp2 = c[C_SUPP2]
    invh = c[C_INVH]
    zero = c[C_ZERO]
    one = c[C_ONE]
    two = c[C_TWO]
    three = c[C_THREE]
    q3 = c[C_3QUARTER]
    visc = c[C_VISC]  # 2 α c0 h (the 2 turns ρ̄ into ρ_i + ρ_j)
    epsh2 = c[C_EPSH2]
    fc = c[C_FORCE]  # m σ / h
    dt = c[C_DT]
    gy = c[C_GY]
    xmax = c[C_XMAX]
    ymax = c[C_YMAX]
    mhalf = c[C_MHALF]
    for i in prange(n):
        xi = x[i]
        yi = y[i]
        vxi = vx[i]
        vyi = vy[i]
        rhoi = rho[i]
        pri = pr[i]
        k = ks[i]
        ax = zero
        ay = zero
        for kr in (k - gx, k, k + gx):
            for j in range(cellstart[kr - u1], cellstart[kr + u2]):
                dx = xi - x[j]
                dy = yi - y[j]
                r2 = dx * dx + dy * dy
                if r2 < supp2 and r2 > zero:  # r = 0: self (∇W = 0)
                    r = np.sqrt(r2)
                    q = r * invh
                    a = two - q
                    b = max(one - q, zero)
                    dwdq = three * b * b - q3 * a * a  # dW/dq / σ
                    vr = (vxi - vx[j]) * dx + (vyi - vy[j]) * dy
                    # Π_ij only for approaching pairs; min(vr, 0) instead of a branch: the sign of
                    # vr is random once the flow develops, and the mispredicted branch cost more
                    # than the divide (same result bit for bit: the term is exactly −0 otherwise).
                    coef = pri + pr[j] - visc * min(vr, zero) / ((r2 + epsh2) * (rhoi + rho[j]))
                    f = coef * dwdq / r
                    ax += f * dx
                    ay += f * dy
        nvx = vxi - dt * (fc * ax)
        nvy = vyi + dt * (gy - fc * ay)
        nx = xi + dt * nvx
        ny = yi + dt * nvy
        if nx < zero:
            nx = zero
            if nvx < zero:
                nvx *= mhalf
        elif nx > xmax:
            nx = xmax
            if nvx > zero:
                nvx *= mhalf
        if ny < zero:
            ny = zero
            if nvy < zero:
                nvy *= mhalf
        elif ny > ymax:
            ny = ymax
            if nvy > zero:
                nvy *= mhalf
        xo[i] = nx
        yo[i] = ny
        vxo[i] = nvx
        vyo[i] = nvy
        ido[i] = idss[i]


@njit(**DRIVER)
def _block(x, y, vx, vy, ids, xs, ys, vxs, vys, idss, ks, tkey, counts, cellstart, rho, pr, c,
           ncx1, ncy1, gx, u1, u2, steps):
    """`steps` full steps; the state lives in (x, y, vx, vy, ids) on entry and on exit."""
    for _ in range(steps):
        _sort(x, y, vx, vy, ids, xs, ys, vxs, vys, idss, ks, tkey, counts, cellstart, c, ncx1, ncy1, gx, u1)
        _density(xs, ys, ks, cellstart, rho, pr, c, gx, u1, u2)
        _force_integrate(xs, ys, vxs, vys, idss, ks, cellstart, rho, pr, x, y, vx, vy, ids, c, gx, u1, u2)


@njit(**JIT)
def _neighbour_count(x, y, ks, cellstart, c, gx, u1, u2):
    """(mean neighbours within 2h incl. self, mean candidates in the 3×3 cells) per particle."""
    n = x.shape[0]
    supp2 = c[C_SUPP2]
    tot = 0
    cand = 0
    for i in prange(n):
        k = ks[i]
        for kr in (k - gx, k, k + gx):
            lo = cellstart[kr - u1]
            hi = cellstart[kr + u2]
            cand += np.int64(hi - lo)
            for j in range(lo, hi):
                dx = x[i] - x[j]
                dy = y[i] - y[j]
                if dx * dx + dy * dy < supp2:
                    tot += 1
    return tot / n, cand / n


class NumbaSPH2D:
    """The §1 dam break with nx particles across the column (N = 2 nx²). The state after step()
    is in self.x / self.y / self.vx / self.vy (float32, in the current cell order); self.ids maps
    that order back to the lattice index (i + nx j) of the initial state."""

    def __init__(self, nx: int, threads: int | None = None):
        if threads is not None:
            numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        self.threads = numba.get_num_threads()
        f32 = np.float32
        self.nx = nx
        dx = COL_W / nx
        self.dx = dx
        n = 2 * nx * nx
        ii, jj = np.meshgrid(np.arange(nx), np.arange(2 * nx), indexing="xy")  # id = i + nx j
        self.x = ((ii.ravel() + 0.5) * dx).astype(f32)
        self.y = ((jj.ravel() + 0.5) * dx).astype(f32)
        self.vx = np.zeros(n, f32)
        self.vy = np.zeros(n, f32)
        self.ids = np.arange(n, dtype=np.int64)
        self.xs, self.ys, self.vxs, self.vys, self.rho, self.pr = (np.empty(n, f32) for _ in range(6))
        self.idss = np.empty(n, np.int64)
        self.ks = np.empty(n, np.uint64)
        self.tkey = np.empty(n, np.uint64)

        h = 1.3 * dx
        c0 = 10.0 * math.sqrt(2.0 * GRAV * COL_H)
        m = RHO0 * dx * dx
        sigma = 10.0 / (7.0 * math.pi * h * h)
        c = np.zeros(NCONST)
        c[C_SUPP2] = (2.0 * h) ** 2
        c[C_INVH] = 1.0 / h
        c[C_MSIG] = m * sigma
        c[C_B] = RHO0 * c0 * c0 / 7.0
        c[C_INVRHO0] = 1.0 / RHO0
        c[C_FORCE] = m * sigma / h
        c[C_VISC] = 2.0 * 0.05 * c0 * h
        c[C_EPSH2] = 0.01 * h * h
        c[C_DT] = 0.2 * h / c0
        c[C_GY] = -GRAV
        c[C_XMAX] = TANK_X
        c[C_YMAX] = TANK_Y
        c[C_INVCS] = 1.0 / (2.0 * h)
        c[C_ONE] = 1.0
        c[C_TWO] = 2.0
        c[C_THREE] = 3.0
        c[C_QUARTER] = 0.25
        c[C_3QUARTER] = 0.75
        c[C_MHALF] = -0.5
        self.c = c.astype(f32)
        self.h = h
        self.c0 = c0
        self.mass = m
        self.dt = float(self.c[C_DT])

        # Grid of cells of size 2h covering the tank (x = 4 falls in the last cell), plus one empty
        # ring of padding cells. Cell index computed in float32 exactly as in _sort.
        ncx = int(np.uint64(f32(TANK_X) * self.c[C_INVCS])) + 1
        ncy = int(np.uint64(f32(TANK_Y) * self.c[C_INVCS])) + 1
        self.ncx1, self.ncy1 = np.uint64(ncx - 1), np.uint64(ncy - 1)
        self.gx = np.uint64(ncx + 2)
        ncell = (ncx + 2) * (ncy + 2)
        self.cellstart = np.zeros(ncell + 1, np.uint64)
        self.counts = np.zeros((self.threads, ncell), np.uint64)  # one histogram per chunk/thread
        self.u1, self.u2 = np.uint64(1), np.uint64(2)
        self.nsteps = 0

    @property
    def n(self) -> int:
        return self.x.shape[0]

    @property
    def time(self) -> float:
        return self.nsteps * self.dt

    def step(self, n: int = 1) -> None:
        _block(self.x, self.y, self.vx, self.vy, self.ids, self.xs, self.ys, self.vxs, self.vys, self.idss,
               self.ks, self.tkey, self.counts, self.cellstart, self.rho, self.pr, self.c,
               self.ncx1, self.ncy1, self.gx, self.u1, self.u2, int(n))
        self.nsteps += int(n)

    def _original_order(self, a, b) -> np.ndarray:
        out = np.empty((self.n, 2), np.float32)
        out[self.ids, 0] = a
        out[self.ids, 1] = b
        return out

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) float32, row p = the particle that started at lattice index p = i + nx j."""
        return self._original_order(self.x, self.y)

    @property
    def velocities(self) -> np.ndarray:
        return self._original_order(self.vx, self.vy)

    def front(self) -> float:
        """Surge front (m): the largest particle x (starts at W − dx/2)."""
        return float(self.x.max())

    def neighbour_stats(self) -> tuple[float, float]:
        """(mean neighbours within 2h incl. self, mean candidates in the 3×3 cells) at the current
        state (sorts into the scratch buffers; the state itself is not changed)."""
        _sort(self.x, self.y, self.vx, self.vy, self.ids, self.xs, self.ys, self.vxs, self.vys, self.idss,
              self.ks, self.tkey, self.counts, self.cellstart, self.c, self.ncx1, self.ncy1, self.gx, self.u1)
        return _neighbour_count(self.xs, self.ys, self.ks, self.cellstart, self.c, self.gx, self.u1, self.u2)


def run(sizes=("10k", "40k", "160k"), threads=2) -> list[dict]:
    """Protocol "from rest": 1 warm-up step (compile) + 19 steps, then 3 blocks of S steps; median."""
    rows = []
    for size in sizes:
        sim = NumbaSPH2D(SIZES[size], threads)
        sim.step(1)
        sim.step(19)
        s = BLOCK[size]
        t = median_block_time(sim.step, s)
        assert np.isfinite(sim.x).all() and np.isfinite(sim.vx).all()
        rows.append(dict(size=size, N=sim.n, S=s, median_s=t, particle_steps_per_s=sim.n * s / t))
        del sim
    return rows


def check(threads=2, t_star=1.0) -> dict:
    """10k from rest to T* = t √(2g/W) = t_star: front / W and neighbour statistics."""
    sim = NumbaSPH2D(SIZES["10k"], threads)
    nb0, cand0 = sim.neighbour_stats()
    steps = int(round(t_star / math.sqrt(2.0 * GRAV / COL_W) / sim.dt))
    sim.step(steps)
    nb1, cand1 = sim.neighbour_stats()
    return dict(steps=steps, t=sim.time, t_star=sim.time * math.sqrt(2.0 * GRAV / COL_W),
                front_over_W=sim.front() / COL_W, neighbours_initial=nb0, candidates_initial=cand0,
                neighbours_final=nb1, candidates_final=cand1,
                finite=bool(np.isfinite(sim.x).all() and np.isfinite(sim.vx).all()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", choices=list(SIZES), default=list(SIZES))
    ap.add_argument("--threads", type=int, default=2, help="numba threads (default 2)")
    ap.add_argument("--check", action="store_true", help="run 10k from rest to T* = 1 and print x_front/W "
                    "(reference ≈ 1.49) and the neighbour counts (reference ≈ 20.6 within 2h)")
    args = ap.parse_args()
    numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
    if args.check:
        r = check(args.threads)
        print(f"10k, {r['steps']} steps, t = {r['t']:.4f} s, T* = {r['t_star']:.3f}: x_front/W = "
              f"{r['front_over_W']:.3f} (reference ≈ 1.49)")
        print(f"neighbours within 2h (incl. self): {r['neighbours_initial']:.2f} at rest, "
              f"{r['neighbours_final']:.2f} at T* (reference ≈ 20.6); candidates in 3×3 cells: "
              f"{r['candidates_initial']:.1f} / {r['candidates_final']:.1f} (reference ≈ 61); finite: {r['finite']}")
        return
    rows = run(args.sizes, args.threads)
    print(f"numba {numba.__version__}, threading layer {numba.threading_layer()}, {numba.get_num_threads()} "
          f"threads, os.cpu_count()={os.cpu_count()}; SPH-2D dam break, float32, protocol 'from rest'\n")
    print(header(args.threads) + " (physcore does not run here; numba runs at its native ISA)")
    print(table(["size", "N", "S", "median block (s)", "particle-steps/s"],
                [[r["size"], f"{r['N']:,}", r["S"], f"{r['median_s']:.3f}", si(r["particle_steps_per_s"])]
                 for r in rows]))


if __name__ == "__main__":
    main()
