"""Stable fluids 512², side by side with a parallel numba implementation of the same step, same
run, same threads (issue "Fields on grids", item 5).

Both sides step a smoke plume in a 1 m box of n × n cells, free-slip walls, no obstacle, no
tracers, no viscosity: a vent (density 1, temperature 1, upward velocity 0.3 m/s) blends in
its disc each step; buoyancy β = 4 lifts the warm smoke; vorticity confinement ε = 0.3
(Fedkiw, Stam & Jensen 2001, eq. 8–11); density, temperature and velocity are advected
semi-Lagrangian (RK2 backtrace, bilinear interpolation on the MAC grid); the pressure Poisson
equation is solved by conjugate gradients preconditioned with one multigrid V-cycle (MGPCG,
McAdams, Sifakis & Teran 2010: damped Jacobi ω = 0.8, 2 sweeps before and after, piecewise-
constant transfers, coarse operator ½ of Galerkin, 32 sweeps on the coarsest level), warm-
started from the last pressure.

**Equal solver work:** physcore runs to its relative tolerance and reports how many CG
iterations each step took; the numba side then takes exactly that many iterations in the same
step (and reports the relative residual it reached, to show its V-cycle is as strong). So both
sides do the same number of preconditioned iterations per step; the comparison is of the cost
per step.

    python benches/grids/peer_numba_fluid.py [--n 512] [--steps 20] [--warmup 10]
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

import _common  # noqa: F401 - sets thread variables before numpy

import argparse
import statistics
import time

import numba
import numpy as np

import physcore as pc

numba.config.THREADING_LAYER = "workqueue"
OMEGA, SWEEPS, COARSE_SWEEPS, COARSE_SCALE, COARSEST = 0.8, 2, 32, 0.5, 4

# ----------------------------------------------------------------------------- advection
# Layout: u[i, j] on x-faces (nx + 1, ny), v[i, j] on y-faces (nx, ny + 1), cell fields (nx, ny).


@numba.njit(inline="always")
def _bilerp(f, x, y):
    """f sampled at integer nodes (index space), clamped to the array."""
    nx, ny = f.shape
    x = min(max(x, 0.0), nx - 1.0)
    y = min(max(y, 0.0), ny - 1.0)
    i = min(int(x), nx - 2)
    j = min(int(y), ny - 2)
    fx, fy = x - i, y - j
    return (1 - fy) * ((1 - fx) * f[i, j] + fx * f[i + 1, j]) + fy * ((1 - fx) * f[i, j + 1] + fx * f[i + 1, j + 1])


@numba.njit(inline="always")
def _vel(u, v, x, y):
    """Velocity (cells/s in index units times dx is applied by the caller) at point (x, y) in cell units."""
    return _bilerp(u, x, y - 0.5), _bilerp(v, x - 0.5, y)


@numba.njit(parallel=True, cache=True)
def advect_cells(q, out, u, v, k):
    """q at cell centres; k = dt/dx."""
    nx, ny = q.shape
    for i in numba.prange(nx):
        for j in range(ny):
            x, y = i + 0.5, j + 0.5
            a, b = _vel(u, v, x, y)
            xm, ym = x - 0.5 * k * a, y - 0.5 * k * b
            a, b = _vel(u, v, xm, ym)
            out[i, j] = _bilerp(q, x - k * a - 0.5, y - k * b - 0.5)


@numba.njit(parallel=True, cache=True)
def advect_velocity(u, v, u2, v2, k):
    nxu, ny = u.shape
    nx = nxu - 1
    for i in numba.prange(1, nx):
        for j in range(ny):
            x, y = float(i), j + 0.5
            a, b = _vel(u, v, x, y)
            a, b = _vel(u, v, x - 0.5 * k * a, y - 0.5 * k * b)
            u2[i, j] = _bilerp(u, x - k * a, y - k * b - 0.5)
    for i in numba.prange(nx):
        for j in range(1, ny):
            x, y = i + 0.5, float(j)
            a, b = _vel(u, v, x, y)
            a, b = _vel(u, v, x - 0.5 * k * a, y - 0.5 * k * b)
            v2[i, j] = _bilerp(v, x - k * a - 0.5, y - k * b)


# ----------------------------------------------------------------------------- forces


@numba.njit(parallel=True, cache=True)
def forces(u, v, temp, dens, w, dt, dx, alpha, beta, eps):
    nx, ny = temp.shape
    # Vorticity at cell centres from face velocities.
    for i in numba.prange(nx):
        for j in range(ny):
            jm, jp = max(j - 1, 0), min(j + 1, ny - 1)
            im, ip = max(i - 1, 0), min(i + 1, nx - 1)
            dvdx = 0.5 * (v[ip, j] + v[ip, j + 1] - v[im, j] - v[im, j + 1]) / ((ip - im) * dx)
            dudy = 0.5 * (u[i, jp] + u[i + 1, jp] - u[i, jm] - u[i + 1, jm]) / ((jp - jm) * dx)
            w[i, j] = dvdx - dudy
    for i in numba.prange(nx):
        for j in range(ny):
            jm, jp = max(j - 1, 0), min(j + 1, ny - 1)
            im, ip = max(i - 1, 0), min(i + 1, nx - 1)
            gx = (abs(w[ip, j]) - abs(w[im, j])) / ((ip - im) * dx)
            gy = (abs(w[i, jp]) - abs(w[i, jm])) / ((jp - jm) * dx)
            g = np.sqrt(gx * gx + gy * gy) + 1e-20
            fx = eps * dx * (gy / g) * w[i, j]
            fy = -eps * dx * (gx / g) * w[i, j]
            fy += beta * temp[i, j] - alpha * dens[i, j]
            # Half to each face of the cell (walls stay at 0).
            if i > 0:
                u[i, j] += 0.5 * dt * fx
            if i + 1 < nx:
                u[i + 1, j] += 0.5 * dt * fx
            if j > 0:
                v[i, j] += 0.5 * dt * fy
            if j + 1 < ny:
                v[i, j + 1] += 0.5 * dt * fy


@numba.njit(cache=True)
def sources(u, v, dens, temp, cells, vy):
    for c in range(cells.shape[0]):
        i, j = cells[c, 0], cells[c, 1]
        dens[i, j] = 1.0
        temp[i, j] = 1.0
        v[i, j] = vy
        v[i, j + 1] = vy


# ----------------------------------------------------------------------------- MGPCG
# Padded unknowns p[i + 1, j + 1]; link weights we[i, j] (to i + 1), wn[i, j] (to j + 1), 0 at walls;
# diag = count (pinned cell: identity row).


def _apply(x, we, wn, diag, s, out):
    nx, ny = diag.shape
    for i in numba.prange(nx):
        for j in range(ny):
            acc = we[i, j] * x[i + 2, j + 1] + (we[i - 1, j] * x[i, j + 1] if i > 0 else 0.0)
            acc += wn[i, j] * x[i + 1, j + 2] + (wn[i, j - 1] * x[i + 1, j] if j > 0 else 0.0)
            out[i + 1, j + 1] = diag[i, j] * x[i + 1, j + 1] - s * acc


def _jacobi(x, b, we, wn, diag, s, out):
    nx, ny = diag.shape
    for i in numba.prange(nx):
        for j in range(ny):
            acc = we[i, j] * x[i + 2, j + 1] + (we[i - 1, j] * x[i, j + 1] if i > 0 else 0.0)
            acc += wn[i, j] * x[i + 1, j + 2] + (wn[i, j - 1] * x[i + 1, j] if j > 0 else 0.0)
            r = b[i + 1, j + 1] - (diag[i, j] * x[i + 1, j + 1] - s * acc)
            out[i + 1, j + 1] = x[i + 1, j + 1] + OMEGA * r / diag[i, j]


def _residual_restrict(x, b, we, wn, diag, s, rc):
    """r = b − A x on the fine level, summed over 2 × 2 blocks into the coarse right-hand side."""
    nx, ny = diag.shape
    ncx, ncy = rc.shape[0] - 2, rc.shape[1] - 2
    for ic in numba.prange(ncx):
        for jc in range(ncy):
            tot = 0.0
            for dj in range(2):
                for di in range(2):
                    i, j = 2 * ic + di, 2 * jc + dj
                    if i < nx and j < ny:
                        acc = we[i, j] * x[i + 2, j + 1] + (we[i - 1, j] * x[i, j + 1] if i > 0 else 0.0)
                        acc += wn[i, j] * x[i + 1, j + 2] + (wn[i, j - 1] * x[i + 1, j] if j > 0 else 0.0)
                        tot += b[i + 1, j + 1] - (diag[i, j] * x[i + 1, j + 1] - s * acc)
            rc[ic + 1, jc + 1] = tot


def _prolong_add(xc, x):
    nxp, nyp = x.shape
    for i in numba.prange(nxp - 2):
        for j in range(nyp - 2):
            x[i + 1, j + 1] += xc[i // 2 + 1, j // 2 + 1]


@numba.njit(parallel=True, cache=True)
def axpy_dot(a, x, y, out_y, r_for_dot):
    """out_y = y + a x over the interior; returns Σ r_for_dot² afterwards (row partials)."""
    nxp, nyp = x.shape
    part = np.zeros(nxp)
    for i in numba.prange(1, nxp - 1):
        acc = 0.0
        for j in range(1, nyp - 1):
            out_y[i, j] = y[i, j] + a * x[i, j]
            acc += r_for_dot[i, j] * r_for_dot[i, j]
        part[i] = acc
    return part.sum()


@numba.njit(parallel=True, cache=True)
def dot(a, b):
    nxp, nyp = a.shape
    part = np.zeros(nxp)
    for i in numba.prange(1, nxp - 1):
        acc = 0.0
        for j in range(1, nyp - 1):
            acc += a[i, j] * b[i, j]
        part[i] = acc
    return part.sum()


def _both(f):
    """A kernel parallel over rows (fine levels) and serial (coarse levels: a parallel launch costs
    more than their work)."""
    return numba.njit(parallel=True, cache=True)(f), numba.njit(cache=True)(f)


apply, jacobi, residual_restrict, prolong_add = (_both(f) for f in (_apply, _jacobi, _residual_restrict, _prolong_add))


class Level:
    def __init__(self, we, wn, diag, s):
        self.we, self.wn, self.diag, self.s = we, wn, diag, s
        nx, ny = diag.shape
        self.k = 0 if nx * ny >= 128 * 128 else 1  # which variant of each kernel
        self.x = np.zeros((nx + 2, ny + 2))
        self.t = np.zeros((nx + 2, ny + 2))
        self.b = np.zeros((nx + 2, ny + 2))


def coarsen(we, wn, scale):
    """Piecewise-constant Galerkin coarse links (scaled): the sum of the fine links crossing each coarse face."""
    nx, ny = we.shape
    ncx, ncy = (nx + 1) // 2, (ny + 1) // 2
    cwe, cwn = np.zeros((ncx, ncy)), np.zeros((ncx, ncy))
    for ic in range(ncx):
        for jc in range(ncy):
            i = 2 * ic + 1
            if i < nx:
                cwe[ic, jc] = we[i, 2 * jc] + (we[i, 2 * jc + 1] if 2 * jc + 1 < ny else 0.0)
            j = 2 * jc + 1
            if j < ny:
                cwn[ic, jc] = wn[2 * ic, j] + (wn[2 * ic + 1, j] if 2 * ic + 1 < nx else 0.0)
    cwe *= scale
    cwn *= scale
    diag = cwe.copy() + cwn
    diag[1:, :] += cwe[:-1, :]
    diag[:, 1:] += cwn[:, :-1]
    return cwe, cwn, diag


class MGPCG:
    def __init__(self, nx, ny):
        we, wn = np.ones((nx, ny)), np.ones((nx, ny))
        we[-1, :] = 0.0
        wn[:, -1] = 0.0
        diag = we + wn
        diag[1:, :] += we[:-1, :]
        diag[:, 1:] += wn[:, :-1]
        diag[0, 0] += 1.0  # pin: the Neumann problem is singular
        self.levels = [Level(we, wn, diag, 1.0)]
        while min(self.levels[-1].diag.shape) > COARSEST:
            lv = self.levels[-1]
            cwe, cwn, cd = coarsen(lv.we * lv.s, lv.wn * lv.s, COARSE_SCALE)
            cd[0, 0] += 1.0
            self.levels.append(Level(cwe, cwn, cd, 1.0))
        shape = (nx + 2, ny + 2)
        self.r, self.z, self.p, self.ap = (np.zeros(shape) for _ in range(4))

    def vcycle(self, b, x):
        """x = V-cycle(b), from x = 0."""
        lv0 = self.levels[0]
        lv0.b, lv0.x = b, x
        x[:] = 0.0
        for k, lv in enumerate(self.levels):
            sweeps = COARSE_SWEEPS if k == len(self.levels) - 1 else SWEEPS
            if k > 0:
                lv.x[:] = 0.0
            for _ in range(sweeps // 2):
                jacobi[lv.k](lv.x, lv.b, lv.we, lv.wn, lv.diag, lv.s, lv.t)
                jacobi[lv.k](lv.t, lv.b, lv.we, lv.wn, lv.diag, lv.s, lv.x)
            if k + 1 < len(self.levels):
                residual_restrict[lv.k](lv.x, lv.b, lv.we, lv.wn, lv.diag, lv.s, self.levels[k + 1].b)
        for k in range(len(self.levels) - 2, -1, -1):
            lv = self.levels[k]
            prolong_add[lv.k](self.levels[k + 1].x, lv.x)
            for _ in range(SWEEPS // 2):
                jacobi[lv.k](lv.x, lv.b, lv.we, lv.wn, lv.diag, lv.s, lv.t)
                jacobi[lv.k](lv.t, lv.b, lv.we, lv.wn, lv.diag, lv.s, lv.x)

    def solve(self, b, x, iterations):
        """`iterations` MGPCG iterations from x (warm start); returns ‖r‖/‖b‖."""
        lv = self.levels[0]
        apply[lv.k](x, lv.we, lv.wn, lv.diag, lv.s, self.ap)
        bb = dot(b, b)
        axpy_dot(-1.0, self.ap, b, self.r, self.ap)
        self.vcycle(self.r, self.z)
        self.p[:] = self.z
        rz = dot(self.r, self.z)
        rr = dot(self.r, self.r)
        for _ in range(iterations):
            apply[lv.k](self.p, lv.we, lv.wn, lv.diag, lv.s, self.ap)
            alpha = rz / dot(self.p, self.ap)
            axpy_dot(alpha, self.p, x, x, self.p)
            rr = axpy_dot(-alpha, self.ap, self.r, self.r, self.r)
            self.vcycle(self.r, self.z)
            rz2 = dot(self.r, self.z)
            axpy_dot(rz2 / rz, self.p, self.z, self.p, self.z)
            rz = rz2
        return float(np.sqrt(rr / max(bb, 1e-300)))


@numba.njit(parallel=True, cache=True)
def divergence(u, v, b, inv_dt_dx):
    """b = −∇·u · dx / dt (the right-hand side of A p = b with A the unscaled −Laplacian · dx²)."""
    nx, ny = b.shape[0] - 2, b.shape[1] - 2
    for i in numba.prange(nx):
        for j in range(ny):
            b[i + 1, j + 1] = -(u[i + 1, j] - u[i, j] + v[i, j + 1] - v[i, j]) * inv_dt_dx


@numba.njit(parallel=True, cache=True)
def subtract_gradient(u, v, p, k):
    nx, ny = p.shape[0] - 2, p.shape[1] - 2
    for i in numba.prange(1, nx):
        for j in range(ny):
            u[i, j] -= k * (p[i + 1, j + 1] - p[i, j + 1])
    for i in numba.prange(nx):
        for j in range(1, ny):
            v[i, j] -= k * (p[i + 1, j + 1] - p[i + 1, j])


class NumbaSmoke:
    def __init__(self, n, dx, dt, vent, alpha, beta, eps):
        self.n, self.dx, self.dt = n, dx, dt
        self.u, self.v = np.zeros((n + 1, n)), np.zeros((n, n + 1))
        self.u2, self.v2 = self.u.copy(), self.v.copy()
        self.dens, self.temp = np.zeros((n, n)), np.zeros((n, n))
        self.q2, self.w = np.zeros((n, n)), np.zeros((n, n))
        self.p, self.b = np.zeros((n + 2, n + 2)), np.zeros((n + 2, n + 2))
        self.solver = MGPCG(n, n)
        (cx, cy), r, self.vy = vent
        x = (np.arange(n) + 0.5) * dx
        ii, jj = np.nonzero((x[:, None] - cx) ** 2 + (x[None, :] - cy) ** 2 <= r * r)
        self.cells = np.stack([ii, jj], axis=1).astype(np.int64)
        self.alpha, self.beta, self.eps = alpha, beta, eps

    def step(self, iterations):
        k = self.dt / self.dx
        advect_cells(self.dens, self.q2, self.u, self.v, k)
        self.dens, self.q2 = self.q2, self.dens
        advect_cells(self.temp, self.q2, self.u, self.v, k)
        self.temp, self.q2 = self.q2, self.temp
        sources(self.u, self.v, self.dens, self.temp, self.cells, self.vy)
        forces(self.u, self.v, self.temp, self.dens, self.w, self.dt, self.dx, self.alpha, self.beta, self.eps)
        self.u2[:] = 0.0
        self.v2[:] = 0.0
        advect_velocity(self.u, self.v, self.u2, self.v2, k)
        self.u, self.u2 = self.u2, self.u
        self.v, self.v2 = self.v2, self.v
        divergence(self.u, self.v, self.b, self.dx / self.dt)
        res = self.solver.solve(self.b, self.p, iterations)
        subtract_gradient(self.u, self.v, self.p, self.dt / self.dx)
        return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=10)
    a = ap.parse_args()
    _common.require_release()
    threads = numba.get_num_threads()
    print(_common.header(threads))
    n, dt, dx = a.n, 5e-3, 1.0 / a.n
    vent = ((0.5, 0.08), 0.06, 0.3)
    scene = pc.Scene(2, dt=dt)
    src = pc.Source(density=1.0, temperature=1.0, velocity=(0.0, vent[2]), center=vent[0], radius=vent[1])
    f = scene.add(pc.StableFluid((n, n), dx, buoyancy=(0.0, 4.0), vorticity=0.3, advection="semi_lagrangian",
                                 projection="chorin",  # the peer's step: the pressure only at the end
                                 sources=[src], tracers=0, tolerance=1e-6, name="smoke"))
    peer = NumbaSmoke(n, dx, dt, vent, 0.0, 4.0, 0.3)
    its_pc, t_pc, t_nb, res_nb = [], [], [], []
    for s in range(a.warmup + a.steps):
        t0 = time.perf_counter()
        scene.step()
        t1 = time.perf_counter()
        it = int(f.books()["pressure_iterations"])
        res = peer.step(it)
        t2 = time.perf_counter()
        if s >= a.warmup:
            its_pc.append(it)
            t_pc.append(t1 - t0)
            t_nb.append(t2 - t1)
            res_nb.append(res)
    mp, mn = statistics.median(t_pc), statistics.median(t_nb)
    print(f"stable fluids {n}², semi-Lagrangian, MGPCG to 1e-6 (physcore) / the same iteration count (numba)")
    print(f"  CG iterations per step: median {statistics.median(its_pc):.0f} (range {min(its_pc)}–{max(its_pc)}); "
          f"numba's relative residual after them: median {statistics.median(res_nb):.1e}")
    print(f"  physcore {mp * 1e3:7.1f} ms/step   numba {mn * 1e3:7.1f} ms/step   physcore / numba speed {mn / mp:.2f}")
    print(f"  cell-updates/s: physcore {n * n / mp / 1e6:.0f} M, numba {n * n / mn / 1e6:.0f} M")


if __name__ == "__main__":
    main()
