"""numba peer for physcore's DFSPH (divergence-free SPH, Bender & Koschier, IEEE TVCG 23 (2017)
1193-1206) on the 2D dam break: the speed reference for physcore's own DFSPH, same physics, float64.

Physics (float64 storage and arithmetic):

* fluid column W = 1 m × H = 2 m in the lower-left corner of the tank [0, 4] × [0, 3] m, at rest;
  nx × 2nx lattice, dx = W/nx, particle (i, j) at ((i+½)dx, (j+½)dx); N = 2 nx²; ρ0 = 1000.
* 2D cubic spline (M4), h = 1.3 dx, support 2h, σ = 10/(7πh²), q = r/h, W = σ[¼(2−q)₊³ − (1−q)₊³];
  ∇_iW_ij = (σ/h²) g(q) r_ij, g = −3 + 2.25q (q < 1), −0.75(2−q)²/q (1 ≤ q < 2), r_ij = x_i − x_j.
* m = ρ0 / S, S = Σ W over the infinite square lattice of spacing dx around a particle (self
  included), so that the rest lattice has ρ = ρ0 exactly.
* walls: static boundary particles, the lattice points ((i+½)dx, (j+½)dx) of the box
  [−3dx, 4+3dx] × [−3dx, 3+3dx] that are not strictly inside (0, 4) × (0, 3) (3 layers on all four
  sides, lid included), each with Ψ_b = m (Akinci et al. 2012). They add Ψ_b W_ib to ρ_i and
  Ψ_b ∇_iW_ib to gw_i; no wall viscosity.
* non-pressure acceleration: gravity (0, −9.81) + Monaghan viscosity a_i = −Σ_j m Π_ij ∇_iW_ij,
  Π_ij = −α c0 μ_ij / ρ̄_ij, μ_ij = h v_ij·r_ij / (r_ij² + 0.01h²) for v_ij·r_ij < 0 (else Π = 0),
  ρ̄_ij = (ρ_i + ρ_j)/2, α = 0.05, c0 = 10 √(2gH) = 62.64 m/s.
* dt = min(0.4 h / v_max, 0.125 h²/ν, 0.25 √(h/g)), ν = α c0 h/(2(d+2)) (Monaghan's), v_max = max |v|
  at the start of the step (physcore's limit).

One DFSPH step (everything at the positions x_n, one neighbour search per step):

1. neighbour search at x_n; per particle its fluid neighbours j (r < 2h, j ≠ i) with
   grad_ij = m ∇_iW_ij (stored, reused by every solver iteration), ρ_i (self, fluid and walls),
   gw_i = Σ_b Ψ_b ∇_iW_ib, n_i = fluid + wall neighbours (self excluded),
   D_i = max((Σ_j grad_ij + 2gw_i)·(Σ_j grad_ij + gw_i) + Σ_j |grad_ij|², Σ_j |grad_ij|²),
   dinv_i = 1/D_i (0 if D_i = 0) (walls mirror the pressure, as in physcore).
2. divergence solve on v: div_i = max(Σ_j (v_i − v_j)·grad_ij + v_i·gw_i, 0), div_i = 0 where
   n_i < NMIN (12); k_i = div_i dinv_i / dt. Warm start: k_i = ½ Kv_i where k_i > 0, else 0,
   applied once; then repeat: err = mean(div) dt/ρ0; stop if err ≤ tol_div (1e-3) after at least
   1 update (MIN_IT_DIVERGENCE), or after max_iter (100) updates; else
   v_i −= dt (Σ_j (k_i + k_j) grad_ij + 2 k_i gw_i) (Jacobi: all k first, then all v; the wall
   term mirrors the particle's pressure, p_b = p_i, as physcore's does).
   Kv_i = Σ of the k_i applied (warm start included) goes to the next step.
3. v* = v + dt (g + a_visc(x_n, v)).
4. density solve on v*: e_i = max(ρ_i + dt (Σ_j (v_i − v_j)·grad_ij + v_i·gw_i) − ρ0, 0),
   k_i = e_i dinv_i / dt², err = mean(e)/ρ0, tolerance tol (1e-3), at least 2 updates
   (MIN_IT_DENSITY); warm start, iteration and Kd_i as in 2.
5. x_{n+1} = x_n + dt v*, v_{n+1} = v*; a particle that left the tank is clamped back into
   [0, 4] × [0, 3] and counted.

The warm start and the fewest iterations are physcore's (rust_core/src/sph/dfsph/): half the
last step's k total (k = κ/ρ = p/ρ², which does not scale with dt, so the total is kept as is),
only where the particle compresses at the solve's start. Iterations are counted as velocity
updates, the warm start not counted. (With D_i the exact diagonal, k_i = e_i/(dt² D_i) removes
e_i in one update if the neighbours stood still.)

The walls act only through the density and divergence constraints, which are one-sided and
stop on a mean over all particles: a particle short of neighbours (the thin surge tongue,
ρ ≈ 0.8 ρ0) is not held off the wall lattice, and the bottom row settles half a spacing down into
the pockets of the wall's top row, so the clamp in 5 does fire, mostly on the floor (reported:
about 20 particles a step at nx = 24, 100 at nx = 144).

Algorithm:

* ``_sort``: stable parallel counting sort of the fluid into a uniform grid of cell size 2h
  (row-major, padded with one ring of cells), as in benches/fluids/peer_numba_sph.py; Kv, Kd move with
  their particle. The wall particles are binned once into the same grid (clamped into the padding
  ring, which is where every wall particle within 2h of the tank lies) and never move.
* ``_neighbours``: ``prange`` over particles in cell order; the 3×3 cells are three contiguous
  index ranges, fluid and walls alike. Fluid pairs go into a padded list (MAXNB slots per particle,
  indices + m∇W interleaved) that the solvers then stream through.
* solvers: one pass computes the error and k_i, another applies k (gather only: each pair is seen
  from both ends, no atomics). Error sums and clamp counts are summed per fixed chunk of CHUNK
  particles, then the chunk sums in order, so results do not depend on the thread count.
* the per-step loop is one serial njit driver; its phase clocks (perf_counter through
  ``objmode``) split the time into neighbour search (sort + pair/gradient precompute), solvers
  (both, warm starts included) and the rest (viscosity, integration).

Benchmark: from rest to T* = t √(2g/W) = 4 (t = 0.9032 s), JIT compiled beforehand on a tiny run.
The steps land on T* = 1, 2, 3, 4: the time left to the next mark is cut into equal steps no
longer than the CFL step, recomputed every step. The surge front (largest fluid x, / W) at
T* = 1, 2, 3 is a sanity check against Martin & Moyce (1952): roughly 1.45, 2.1, 3.0.

Usage: python benches/fluids/peer_numba_dfsph.py [--nx 144 [72 ...]] [--threads 2] [--tol 1e-3] [--warm 0.5]
Needs numba: ``pip install numba`` (or ``pip install ".[bench]"``).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, table  # first: sets up the environment before numpy loads
import numpy as np

try:
    import numba
    from numba import njit, objmode, prange
except ImportError:  # pragma: no cover - optional dependency
    sys.exit('peer_numba_dfsph.py needs numba: `pip install numba` (or `pip install ".[bench]"` from the repo root)')

JIT = dict(parallel=True, fastmath=False, cache=False)  # the prange kernels
DRIVER = dict(parallel=False, fastmath=False, cache=False)  # the step loop calling them

RHO0 = 1000.0
GRAV = 9.81
COL_W, COL_H = 1.0, 2.0
TANK_X, TANK_Y = 4.0, 3.0
ALPHA = 0.05
C0 = 10.0 * math.sqrt(2.0 * GRAV * COL_H)
WALL_LAYERS = 3
NMIN = 12  # divergence solve: particles with fewer neighbours (free surface) are left alone
# Warm start: each solve first applies this share of the particle's k total of the last step, and
# only where the particle compresses at the solve's start (physcore's rust_core/src/sph/dfsph/,
# WARM_START). Both solves are one-sided (they only remove compression), so a warm-start push that
# over-expands is never taken back. Applied everywhere with the whole total (rescaled by the dt
# ratio²), a total can only grow, and the dam break blew up within 10 steps (nx = 24); with the mask
# but the whole total it runs, with the front 6 % ahead of the half total's at T* = 1 and 2.
WARM_START = 0.5
# Fewest updates per solve (paper, Algorithms 2 and 3; physcore likewise): the stop test is a mean
# over all particles, which hides the growing compression of a thin bottom layer while the column
# free-falls from rest; with no minimum, nx = 72 had its bottom row 7 % compressed before the first
# update (vmax 6 m/s in the kick that followed), and nx = 144 blew up before T* = 1. With it,
# nx = 144 runs through, but its first step that needs more (step 12) still stops at max_iter.
MIN_IT_DENSITY = 2
MIN_IT_DIVERGENCE = 1
MAXNB = 48  # fluid-neighbour slots per particle (about 20 at rest); exceeding it raises
CHUNK = 256  # particles per reduction chunk (fixed: the sums do not depend on the thread count)
T_STAR_END = 4.0

# Slots of the float64 constant vector `c`.
(C_SUPP2, C_INVH, C_MSIG, C_PSIG, C_MGS, C_PGS, C_INVCS, C_RHO0, C_VISC, C_EPSH2, C_GY,
 C_XMAX, C_YMAX, C_DT_V, C_DT_H, C_DT_CAP, C_TOL_DEN, C_TOL_DIV, NCONST) = range(19)

# Slots of the float64 accumulator vector `acc` (running totals over all steps so far).
(A_TIME, A_STEPS, A_IT_DIV, A_IT_DEN, A_ERR_DEN, A_ERR_DIV, A_CLAMPED, A_T_NB, A_T_SOLVE, A_T_REST,
 A_MAXIT_DEN, A_MAXIT_DIV, A_NB_MAX, NACC) = range(14)


@njit
def _now():
    with objmode(t="float64"):
        t = time.perf_counter()
    return t


@njit(**JIT)
def _sort(x, y, vx, vy, ids, kv, kd, xs, ys, vxs, vys, idss, kvs, kds, ks, tkey, counts, cellstart, v2max,
          c, ncx1, ncy1, gx, u1):
    """Stable parallel counting sort of the fluid state into cell order (the *s arrays); ks = cell
    key of each sorted particle; cellstart[k] = first sorted index in cell k (cellstart[-1] = N).
    Also v2max[t] = max |v|² over chunk t. All grid integers are uint64 (u1 = 1)."""
    n = x.shape[0]
    nchunks = counts.shape[0]
    ncell = cellstart.shape[0] - 1
    inv_cs = c[C_INVCS]
    chunk = (n + nchunks - 1) // nchunks
    for t in prange(nchunks):
        cnt = counts[t]
        cnt[:] = 0
        vm = 0.0
        for i in range(t * chunk, min(n, (t + 1) * chunk)):
            ix = min(np.uint64(x[i] * inv_cs), ncx1)  # x >= 0 always (clamped into the tank)
            iy = min(np.uint64(y[i] * inv_cs), ncy1)
            k = (iy + u1) * gx + ix + u1
            tkey[i] = k
            cnt[k] += u1
            vm = max(vm, vx[i] * vx[i] + vy[i] * vy[i])
        v2max[t] = vm
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
            kvs[d] = kv[i]
            kds[d] = kd[i]
            ks[d] = k


@njit(**JIT)
def _neighbours(x, y, ks, cellstart, wx, wy, wcellstart, nbr, grad, cnt, nn, rho, gwx, gwy, dinv, ipart,
                c, gx, u1, u2):
    """Step 1 at the sorted positions: fluid neighbour list nbr/grad (m ∇_iW_ij)/cnt, n_i, ρ_i, gw_i,
    dinv_i; ipart[chunk] = the largest fluid-neighbour count in the chunk (checked by the caller;
    slots past MAXNB are not written)."""
    n = x.shape[0]
    maxnb = nbr.shape[1]
    supp2 = c[C_SUPP2]
    invh = c[C_INVH]
    msig = c[C_MSIG]
    psig = c[C_PSIG]
    mgs = c[C_MGS]  # m σ / h²
    pgs = c[C_PGS]  # Ψ σ / h²
    for ch in prange(ipart.shape[0]):
        most = 0
        for i in range(ch * CHUNK, min(n, (ch + 1) * CHUNK)):
            iu = np.uint64(i)
            xi = x[i]
            yi = y[i]
            k = ks[i]
            sw = 0.0  # Σ W/σ over fluid (self included)
            sgx = 0.0  # Σ_j grad_ij
            sgy = 0.0
            sg2 = 0.0  # Σ_j |grad_ij|²
            m = 0
            for kr in (k - gx, k, k + gx):  # rows below, at, above; cells kr-1..kr+1 are contiguous
                for j in range(cellstart[kr - u1], cellstart[kr + u2]):
                    dx = xi - x[j]
                    dy = yi - y[j]
                    r2 = dx * dx + dy * dy
                    if r2 < supp2:
                        q = np.sqrt(r2) * invh
                        a = 2.0 - q
                        b = max(1.0 - q, 0.0)
                        sw += 0.25 * a * a * a - b * b * b
                        if j != iu:
                            g = -3.0 + 2.25 * q if q < 1.0 else -0.75 * a * a / q
                            gxij = mgs * g * dx
                            gyij = mgs * g * dy
                            if m < maxnb:
                                nbr[i, m] = j
                                grad[i, m, 0] = gxij
                                grad[i, m, 1] = gyij
                            m += 1
                            sgx += gxij
                            sgy += gyij
                            sg2 += gxij * gxij + gyij * gyij
            bw = 0.0  # Σ W/σ over walls
            bgx = 0.0  # Σ_b g r_ib
            bgy = 0.0
            nw = 0
            for kr in (k - gx, k, k + gx):
                for b_ in range(wcellstart[kr - u1], wcellstart[kr + u2]):
                    dx = xi - wx[b_]
                    dy = yi - wy[b_]
                    r2 = dx * dx + dy * dy
                    if r2 < supp2:
                        q = np.sqrt(r2) * invh
                        a = 2.0 - q
                        b = max(1.0 - q, 0.0)
                        bw += 0.25 * a * a * a - b * b * b
                        g = -3.0 + 2.25 * q if q < 1.0 else -0.75 * a * a / q
                        bgx += g * dx
                        bgy += g * dy
                        nw += 1
            wgx = pgs * bgx
            wgy = pgs * bgy
            rho[i] = msig * sw + psig * bw
            gwx[i] = wgx
            gwy[i] = wgy
            cnt[i] = m
            nn[i] = m + nw
            tx = sgx + wgx
            ty = sgy + wgy
            # Walls mirror the pressure (2 k_i gw_i in _apply), so D_i = (S + 2gw)·(S + gw) + Σ|g|²,
            # taken no smaller than Σ|g|² (physcore's rule).
            d = max((sgx + 2.0 * wgx) * tx + (sgy + 2.0 * wgy) * ty + sg2, sg2)
            dinv[i] = 1.0 / d if d > 0.0 else 0.0
            most = max(most, m)
        ipart[ch] = most


@njit(**JIT)
def _warm(kk, k, ksum, f):
    """Warm start, after an error pass has put this step's k into `k`: k_i = f K_i where the
    particle compresses now (k_i > 0), else 0; the solve's k total restarts from 0."""
    for i in prange(k.shape[0]):
        k[i] = f * kk[i] if k[i] > 0.0 else 0.0
        ksum[i] = 0.0


@njit(**JIT)
def _apply(k, ksum, nbr, grad, cnt, gwx, gwy, vx, vy, dt):
    """v_i −= dt (Σ_j (k_i + k_j) grad_ij + 2 k_i gw_i); ksum_i += k_i. Reads only k, writes only
    v_i: in place without races."""
    for i in prange(k.shape[0]):
        ki = k[i]
        ax = 0.0
        ay = 0.0
        for s in range(cnt[i]):
            kij = ki + k[nbr[i, s]]
            ax += kij * grad[i, s, 0]
            ay += kij * grad[i, s, 1]
        ax += 2.0 * ki * gwx[i]  # walls mirror the pressure: p_b = p_i
        ay += 2.0 * ki * gwy[i]
        vx[i] -= dt * ax
        vy[i] -= dt * ay
        ksum[i] += ki


@njit(**JIT)
def _div_error(vx, vy, nbr, grad, cnt, nn, gwx, gwy, dinv, k, part, dt):
    """div_i = max(Σ_j v_ij·grad_ij + v_i·gw_i, 0) (0 where n_i < NMIN); k_i = div_i dinv_i / dt;
    part[chunk] = Σ div_i over the chunk."""
    n = vx.shape[0]
    inv_dt = 1.0 / dt
    for ch in prange(part.shape[0]):
        acc = 0.0
        for i in range(ch * CHUNK, min(n, (ch + 1) * CHUNK)):
            vxi = vx[i]
            vyi = vy[i]
            s = 0.0
            for t in range(cnt[i]):
                j = nbr[i, t]
                s += (vxi - vx[j]) * grad[i, t, 0] + (vyi - vy[j]) * grad[i, t, 1]
            s += vxi * gwx[i] + vyi * gwy[i]
            div = max(s, 0.0) if nn[i] >= NMIN else 0.0
            k[i] = div * dinv[i] * inv_dt
            acc += div
        part[ch] = acc


@njit(**JIT)
def _density_error(vx, vy, nbr, grad, cnt, gwx, gwy, rho, dinv, k, part, dt, rho0):
    """e_i = max(ρ_i + dt (Σ_j v_ij·grad_ij + v_i·gw_i) − ρ0, 0); k_i = e_i dinv_i / dt²;
    part[chunk] = Σ e_i over the chunk."""
    n = vx.shape[0]
    inv_dt2 = 1.0 / (dt * dt)
    for ch in prange(part.shape[0]):
        acc = 0.0
        for i in range(ch * CHUNK, min(n, (ch + 1) * CHUNK)):
            vxi = vx[i]
            vyi = vy[i]
            s = 0.0
            for t in range(cnt[i]):
                j = nbr[i, t]
                s += (vxi - vx[j]) * grad[i, t, 0] + (vyi - vy[j]) * grad[i, t, 1]
            s += vxi * gwx[i] + vyi * gwy[i]
            e = max(rho[i] + dt * s - rho0, 0.0)
            k[i] = e * dinv[i] * inv_dt2
            acc += e
        part[ch] = acc


@njit(**JIT)
def _nonpressure(x, y, vx, vy, rho, nbr, grad, cnt, vxo, vyo, c, dt):
    """v*_i = v_i + dt (g − Σ_j Π_ij grad_ij) into (vxo, vyo) (Jacobi: reads v, writes v*)."""
    visc = c[C_VISC]  # 2 α c0 h (the 2 turns ρ̄ into ρ_i + ρ_j)
    epsh2 = c[C_EPSH2]
    gy = c[C_GY]
    for i in prange(x.shape[0]):
        xi = x[i]
        yi = y[i]
        vxi = vx[i]
        vyi = vy[i]
        rhoi = rho[i]
        ax = 0.0
        ay = 0.0
        for s in range(cnt[i]):
            j = nbr[i, s]
            dx = xi - x[j]
            dy = yi - y[j]
            vr = (vxi - vx[j]) * dx + (vyi - vy[j]) * dy
            # −Π_ij = α c0 h min(vr, 0) / ((r² + 0.01h²) ρ̄): branch-free (the sign of vr is random
            # once the flow develops); exactly −0 for separating pairs.
            f = visc * min(vr, 0.0) / ((dx * dx + dy * dy + epsh2) * (rhoi + rho[j]))
            ax += f * grad[i, s, 0]
            ay += f * grad[i, s, 1]
        vxo[i] = vxi + dt * ax
        vyo[i] = vyi + dt * (gy + ay)


@njit(**JIT)
def _integrate(xs, ys, vxs, vys, idss, ksv, ksd, x, y, vx, vy, ids, kv, kd, ipart, c, dt):
    """x += dt v*, clamp into the tank (ipart[chunk] = particles clamped); writes the new state,
    with the k totals Kv, Kd of both solves, to the buffers the next sort reads."""
    n = xs.shape[0]
    xmax = c[C_XMAX]
    ymax = c[C_YMAX]
    for ch in prange(ipart.shape[0]):
        clamped = 0
        for i in range(ch * CHUNK, min(n, (ch + 1) * CHUNK)):
            px = xs[i] + dt * vxs[i]
            py = ys[i] + dt * vys[i]
            if px < 0.0 or px > xmax or py < 0.0 or py > ymax:
                px = min(max(px, 0.0), xmax)
                py = min(max(py, 0.0), ymax)
                clamped += 1
            x[i] = px
            y[i] = py
            vx[i] = vxs[i]
            vy[i] = vys[i]
            ids[i] = idss[i]
            kv[i] = ksv[i]
            kd[i] = ksd[i]
        ipart[ch] = clamped


@njit(**DRIVER)
def _advance(x, y, vx, vy, ids, kv, kd, xs, ys, vxs, vys, idss, kvs, kds, ks, tkey, counts, cellstart, v2max,
             wx, wy, wcellstart, nbr, grad, cnt, nn, rho, gwx, gwy, dinv, k, ksv, ksd, vx2, vy2, part, ipart,
             c, ncx1, ncy1, gx, u1, u2, warm, max_iter, max_steps, t_end, acc):
    """Up to `max_steps` DFSPH steps, stopping when t reaches t_end (the steps land on it: the
    interval left is cut into equal steps no longer than the CFL step). The state lives in
    (x, y, vx, vy, ids, kv, kd) on entry and on exit; totals go into `acc`."""
    n = x.shape[0]
    rho0 = c[C_RHO0]
    for _ in range(max_steps):
        if acc[A_TIME] >= t_end:
            break
        t0 = _now()
        # 1. neighbour search + per-pair gradients at x_n
        _sort(x, y, vx, vy, ids, kv, kd, xs, ys, vxs, vys, idss, kvs, kds, ks, tkey, counts, cellstart, v2max,
              c, ncx1, ncy1, gx, u1)
        vmax = np.sqrt(v2max.max())
        speed = vmax + c[C_DT_V]
        dt = min(c[C_DT_H] / speed, c[C_DT_CAP]) if speed > 0.0 else c[C_DT_CAP]
        left = t_end - acc[A_TIME]
        steps_left = np.ceil(left / dt)  # inf for step(n)
        if steps_left < np.inf:
            dt = left / steps_left
        _neighbours(xs, ys, ks, cellstart, wx, wy, wcellstart, nbr, grad, cnt, nn, rho, gwx, gwy, dinv, ipart,
                    c, gx, u1, u2)
        most = ipart.max()
        acc[A_NB_MAX] = max(acc[A_NB_MAX], most)
        if most > nbr.shape[1]:
            raise RuntimeError("more fluid neighbours than MAXNB slots")
        t1 = _now()
        # 2. divergence solve on v
        if warm > 0.0:
            _div_error(vxs, vys, nbr, grad, cnt, nn, gwx, gwy, dinv, k, part, dt)
            _warm(kvs, k, ksv, warm)
            _apply(k, ksv, nbr, grad, cnt, gwx, gwy, vxs, vys, dt)
        else:
            ksv[:] = 0.0
        it = 0
        while True:
            _div_error(vxs, vys, nbr, grad, cnt, nn, gwx, gwy, dinv, k, part, dt)
            s = 0.0
            for ch in range(part.shape[0]):
                s += part[ch]
            err = s / n * dt / rho0
            if (err <= c[C_TOL_DIV] and it >= min(MIN_IT_DIVERGENCE, max_iter)) or it >= max_iter:
                break
            _apply(k, ksv, nbr, grad, cnt, gwx, gwy, vxs, vys, dt)
            it += 1
        acc[A_IT_DIV] += it
        acc[A_MAXIT_DIV] = max(acc[A_MAXIT_DIV], it)
        acc[A_ERR_DIV] = max(acc[A_ERR_DIV], err)
        t2 = _now()
        # 3. gravity + viscosity at (x_n, v): v* into (vx2, vy2)
        _nonpressure(xs, ys, vxs, vys, rho, nbr, grad, cnt, vx2, vy2, c, dt)
        t3 = _now()
        # 4. density solve on v*
        if warm > 0.0:
            _density_error(vx2, vy2, nbr, grad, cnt, gwx, gwy, rho, dinv, k, part, dt, rho0)
            _warm(kds, k, ksd, warm)
            _apply(k, ksd, nbr, grad, cnt, gwx, gwy, vx2, vy2, dt)
        else:
            ksd[:] = 0.0
        it = 0
        while True:
            _density_error(vx2, vy2, nbr, grad, cnt, gwx, gwy, rho, dinv, k, part, dt, rho0)
            s = 0.0
            for ch in range(part.shape[0]):
                s += part[ch]
            err = s / n / rho0
            if (err <= c[C_TOL_DEN] and it >= min(MIN_IT_DENSITY, max_iter)) or it >= max_iter:
                break
            _apply(k, ksd, nbr, grad, cnt, gwx, gwy, vx2, vy2, dt)
            it += 1
        acc[A_IT_DEN] += it
        acc[A_MAXIT_DEN] = max(acc[A_MAXIT_DEN], it)
        acc[A_ERR_DEN] = max(acc[A_ERR_DEN], err)
        t4 = _now()
        # 5. positions, back into the sort's input buffers
        _integrate(xs, ys, vx2, vy2, idss, ksv, ksd, x, y, vx, vy, ids, kv, kd, ipart, c, dt)
        acc[A_CLAMPED] += ipart.sum()
        t5 = _now()
        # the last step lands on t_end exactly (a rounding remainder would make a tiny extra step)
        acc[A_TIME] = t_end if steps_left <= 1.0 else acc[A_TIME] + dt
        acc[A_STEPS] += 1.0
        acc[A_T_NB] += t1 - t0
        acc[A_T_SOLVE] += (t2 - t1) + (t4 - t3)
        acc[A_T_REST] += (t3 - t2) + (t5 - t4)


def _lattice_mass(dx: float, h: float) -> float:
    """m = ρ0 / Σ W over the infinite square lattice of spacing dx (self included)."""
    r = math.ceil(2.0 * h / dx) + 1
    o = np.arange(-r, r + 1) * dx
    q = np.hypot(*np.meshgrid(o, o)).ravel() / h
    sigma = 10.0 / (7.0 * math.pi * h * h)
    w = sigma * (0.25 * np.maximum(2.0 - q, 0.0) ** 3 - np.maximum(1.0 - q, 0.0) ** 3)
    return RHO0 / w.sum()


class NumbaDFSPH2D:
    """The dam break with nx particles across the column (N = 2 nx²), DFSPH. The state after step()
    is in self.x / self.y / self.vx / self.vy (float64, in the last cell order); self.ids maps
    that order back to the lattice index (i + nx j) of the initial state."""

    def __init__(self, nx: int, threads: int | None = None, tol: float = 1e-3, tol_div: float = 1e-3,
                 max_iter: int = 100, warm: float = WARM_START):
        if threads is not None:
            numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        self.threads = numba.get_num_threads()
        self.nx = nx
        dx = COL_W / nx
        h = 1.3 * dx
        self.dx, self.h = dx, h
        n = 2 * nx * nx
        ii, jj = np.meshgrid(np.arange(nx), np.arange(2 * nx), indexing="xy")  # id = i + nx j
        self.x = (ii.ravel() + 0.5) * dx
        self.y = (jj.ravel() + 0.5) * dx
        self.vx = np.zeros(n)
        self.vy = np.zeros(n)
        self.ids = np.arange(n, dtype=np.int64)
        self.kv = np.zeros(n)  # Kv, Kd: warm-start totals, carried with the particle
        self.kd = np.zeros(n)
        self.xs, self.ys, self.vxs, self.vys, self.kvs, self.kds = (np.empty(n) for _ in range(6))
        self.rho, self.gwx, self.gwy, self.dinv, self.k, self.ksv, self.ksd, self.vx2, self.vy2 = (
            np.empty(n) for _ in range(9))
        self.idss = np.empty(n, np.int64)
        self.ks = np.empty(n, np.uint64)
        self.tkey = np.empty(n, np.uint64)
        self.nbr = np.zeros((n, MAXNB), np.uint32)
        self.grad = np.zeros((n, MAXNB, 2))
        self.cnt = np.zeros(n, np.int64)
        self.nn = np.zeros(n, np.int64)
        nchunk = (n + CHUNK - 1) // CHUNK
        self.part = np.zeros(nchunk)
        self.ipart = np.zeros(nchunk, np.int64)

        self.mass = m = _lattice_mass(dx, h)
        psi = m  # wall particles: Ψ_b = m
        sigma = 10.0 / (7.0 * math.pi * h * h)
        c = np.zeros(NCONST)
        c[C_SUPP2] = (2.0 * h) ** 2
        c[C_INVH] = 1.0 / h
        c[C_MSIG] = m * sigma
        c[C_PSIG] = psi * sigma
        c[C_MGS] = m * sigma / (h * h)
        c[C_PGS] = psi * sigma / (h * h)
        c[C_INVCS] = 1.0 / (2.0 * h)
        c[C_RHO0] = RHO0
        c[C_VISC] = 2.0 * ALPHA * C0 * h
        c[C_EPSH2] = 0.01 * h * h
        c[C_GY] = -GRAV
        c[C_XMAX] = TANK_X
        c[C_YMAX] = TANK_Y
        c[C_DT_V] = 0.0  # physcore's limit: λh/|v|max, no viscous term in the CFL ...
        c[C_DT_H] = 0.4 * h
        # ... the explicit viscosity's limit 0.125 h²/ν, ν = α c0 h/(2(d + 2)), and the force criterion.
        c[C_DT_CAP] = min(0.25 * math.sqrt(h / GRAV), 0.125 * 2.0 * (2 + 2) * h / (ALPHA * C0))
        c[C_TOL_DEN] = tol
        c[C_TOL_DIV] = tol_div
        self.c = c
        self.max_iter = int(max_iter)
        self.warm = float(warm)

        # Grid of cells of size 2h covering the tank (x = 4 falls in the last cell), plus one ring of
        # padding cells that holds the walls. Cell index computed exactly as in _sort.
        ncx = int(TANK_X * c[C_INVCS]) + 1
        ncy = int(TANK_Y * c[C_INVCS]) + 1
        self.ncx1, self.ncy1 = np.uint64(ncx - 1), np.uint64(ncy - 1)
        self.gx = np.uint64(ncx + 2)
        ncell = (ncx + 2) * (ncy + 2)
        self.cellstart = np.zeros(ncell + 1, np.uint64)
        self.counts = np.zeros((self.threads, ncell), np.uint64)  # one histogram per chunk/thread
        self.v2max = np.zeros(self.threads)
        self.u1, self.u2 = np.uint64(1), np.uint64(2)

        # Walls: lattice points of the grown box not strictly inside the tank (integer test: the
        # tank is 4nx × 3nx lattice cells), binned once; a wall beyond the neighbouring cell of the
        # tank's edge cells is clamped into the ring (it is then farther than 2h from all fluid).
        L = WALL_LAYERS
        wi, wj = np.meshgrid(np.arange(-L, 4 * nx + L), np.arange(-L, 3 * nx + L), indexing="xy")
        wi, wj = wi.ravel(), wj.ravel()
        out = (wi < 0) | (wi >= 4 * nx) | (wj < 0) | (wj >= 3 * nx)
        wx = (wi[out] + 0.5) * dx
        wy = (wj[out] + 0.5) * dx
        cx = np.clip(np.floor(wx * c[C_INVCS]), -1, ncx).astype(np.int64) + 1
        cy = np.clip(np.floor(wy * c[C_INVCS]), -1, ncy).astype(np.int64) + 1
        key = cy * (ncx + 2) + cx
        order = np.argsort(key, kind="stable")
        self.wx, self.wy = np.ascontiguousarray(wx[order]), np.ascontiguousarray(wy[order])
        self.wcellstart = np.searchsorted(key[order], np.arange(ncell + 1)).astype(np.uint64)
        self.acc = np.zeros(NACC)

    @property
    def n(self) -> int:
        return self.x.shape[0]

    @property
    def n_walls(self) -> int:
        return self.wx.shape[0]

    @property
    def time(self) -> float:
        return float(self.acc[A_TIME])

    @property
    def steps(self) -> int:
        return int(self.acc[A_STEPS])

    def _advance(self, max_steps: int, t_end: float) -> None:
        _advance(self.x, self.y, self.vx, self.vy, self.ids, self.kv, self.kd, self.xs, self.ys, self.vxs,
                 self.vys, self.idss, self.kvs, self.kds, self.ks, self.tkey, self.counts, self.cellstart,
                 self.v2max, self.wx, self.wy, self.wcellstart, self.nbr, self.grad, self.cnt, self.nn, self.rho,
                 self.gwx, self.gwy, self.dinv, self.k, self.ksv, self.ksd, self.vx2, self.vy2, self.part,
                 self.ipart, self.c, self.ncx1, self.ncy1, self.gx, self.u1, self.u2, self.warm, self.max_iter,
                 int(max_steps), float(t_end), self.acc)

    def step(self, n: int = 1) -> None:
        self._advance(n, math.inf)

    def advance_to(self, t: float) -> None:
        """Step until time t, landing on it (the steps before it are shortened evenly)."""
        self._advance(2**62, t)

    def _original_order(self, a, b) -> np.ndarray:
        out = np.empty((self.n, 2))
        out[self.ids, 0] = a
        out[self.ids, 1] = b
        return out

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) float64, row p = the particle that started at lattice index p = i + nx j."""
        return self._original_order(self.x, self.y)

    @property
    def velocities(self) -> np.ndarray:
        return self._original_order(self.vx, self.vy)

    def front(self) -> float:
        """Surge front (m): the largest fluid x (starts at W − dx/2)."""
        return float(self.x.max())

    def stats(self) -> dict:
        a = self.acc
        s = max(1, self.steps)
        return dict(
            steps=self.steps, t=self.time, it_density=a[A_IT_DEN] / s, it_divergence=a[A_IT_DIV] / s,
            max_it_density=int(a[A_MAXIT_DEN]), max_it_divergence=int(a[A_MAXIT_DIV]),
            max_err_density=a[A_ERR_DEN], max_err_divergence=a[A_ERR_DIV], clamped=int(a[A_CLAMPED]),
            max_fluid_neighbours=int(a[A_NB_MAX]), ms_neighbours=1e3 * a[A_T_NB] / s,
            ms_solvers=1e3 * a[A_T_SOLVE] / s, ms_rest=1e3 * a[A_T_REST] / s)


def compile_all(threads=2) -> float:
    """Compile every kernel on a tiny run (both code paths of the driver); returns the seconds."""
    t0 = time.perf_counter()
    NumbaDFSPH2D(8, threads).step(3)
    NumbaDFSPH2D(8, threads).advance_to(0.01)
    return time.perf_counter() - t0


def run(nx=144, threads=2, tol=1e-3, tol_div=1e-3, max_iter=100, warm=WARM_START, progress=None) -> dict:
    """From rest to T* = 4 (JIT compiled beforehand): wall time, solver statistics, fronts / W at
    T* = 1, 2, 3 (the steps land on each). `progress(line)` is called at each mark."""
    sim = NumbaDFSPH2D(nx, threads, tol, tol_div, max_iter, warm)
    scale = math.sqrt(2.0 * GRAV / COL_W)  # T* = t scale
    fronts = {}
    wall = 0.0
    for ts in (1.0, 2.0, 3.0, T_STAR_END):
        t0 = time.perf_counter()
        sim.advance_to(ts / scale)
        wall += time.perf_counter() - t0
        fronts[ts] = sim.front() / COL_W
        if progress is not None:
            progress(f"nx = {nx}: T* = {ts:g} after {sim.steps} steps, {wall:.1f} s, front/W = {fronts[ts]:.3f}")
    assert np.isfinite(sim.x).all() and np.isfinite(sim.vx).all()
    return dict(nx=nx, N=sim.n, walls=sim.n_walls, wall_s=wall, t_star=sim.time * scale, fronts=fronts,
                **sim.stats())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, nargs="+", default=[144], help="particles across the column "
                    "(72, 144, 288: N = 10k, 41k, 166k; default 144)")
    ap.add_argument("--threads", type=int, default=2, help="numba threads (default 2)")
    ap.add_argument("--tol", type=float, default=1e-3, help="density solver tolerance, mean relative (1e-3)")
    ap.add_argument("--tol-div", type=float, default=1e-3, help="divergence solver tolerance (1e-3)")
    ap.add_argument("--max-iter", type=int, default=100, help="iterations per solve at most (100)")
    ap.add_argument("--warm", type=float, default=WARM_START, help="warm-start share of the last step's "
                    f"k totals ({WARM_START}; 0: no warm start)")
    args = ap.parse_args()
    numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
    compile_s = compile_all(args.threads)
    def log(line):
        print(line, file=sys.stderr, flush=True)

    rows = [run(nx, args.threads, args.tol, args.tol_div, args.max_iter, args.warm, log) for nx in args.nx]
    print(f"numba {numba.__version__}, threading layer {numba.threading_layer()}, {numba.get_num_threads()} "
          f"threads, os.cpu_count()={os.cpu_count()}; DFSPH-2D dam break, float64, from rest to T* = 4 "
          f"(JIT compile {compile_s:.1f} s, excluded)\n")
    print(header(args.threads) + " (physcore does not run here; numba runs at its native ISA)")
    print(table(["nx", "N", "steps", "wall to T*=4 (s)", "ms/step", "neighbours", "solvers", "rest",
                 "density it/step", "divergence it/step", "max density err", "front/W T*=1, 2, 3", "clamped"],
                [[r["nx"], f"{r['N']:,}", r["steps"], f"{r['wall_s']:.2f}", f"{1e3 * r['wall_s'] / r['steps']:.2f}",
                  f"{r['ms_neighbours']:.2f}", f"{r['ms_solvers']:.2f}", f"{r['ms_rest']:.2f}",
                  f"{r['it_density']:.2f} (max {r['max_it_density']})",
                  f"{r['it_divergence']:.2f} (max {r['max_it_divergence']})", f"{r['max_err_density']:.2e}",
                  ", ".join(f"{r['fronts'][ts]:.2f}" for ts in (1.0, 2.0, 3.0)), r["clamped"]] for r in rows]))
    print("\nms/step split: neighbours = sort + pair/gradient precompute, solvers = divergence + density "
          "(warm starts included), rest = viscosity + integration. Martin & Moyce (1952): front/W ≈ 1.45, "
          "2.1, 3.0 at T* = 1, 2, 3.")


if __name__ == "__main__":
    main()
