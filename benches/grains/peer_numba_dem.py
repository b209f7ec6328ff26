"""numba peer for the DEM workload "10^5 discs in a box" (benches/grains/bench_dem.py), measured in the
same run on the same machine as physcore's ``Contacts`` term (when this physcore has one).

numba kernels: ``@njit(parallel=True, fastmath=False, cache=False)``, ``prange`` over particles,
gather only (each disc computes its own contacts from its own side; no atomics, no races).

Contact model (2D discs, float64)
---------------------------------
Per disc: position x, velocity v, angular velocity ω (a scalar, about z), radius r, mass m
(pinned discs: 1/m = 0, they never move or rotate), moment of inertia I = ½ m r².

* Pair (i, j) is in contact when 0 < d = |x_j − x_i| < r_i + r_j. n = (x_j − x_i)/d (from i to j),
  overlap δ = r_i + r_j − d, m_eff = 1/(1/m_i + 1/m_j), levers a_i = r_i − δ/2, a_j = r_j − δ/2.
* Relative velocity of the contact point: v_c = v_i − v_j + (a_i ω_i + a_j ω_j) perp(n), with
  perp(n) = (−n_y, n_x) (ω × n for a scalar ω).
* Normal: v_n = v_c·n (> 0 approaching); f_n = k_n δ + γ_n v_n, γ_n = 2ζ√(k_n m_eff); f_n < 0 is
  set to 0 (never attractive).
* Tangential (Cundall & Strack 1979, tangential spring): each side keeps its own history ξ
  (a 2-vector) per partner, 0 when the contact first appears, deleted when it ends. At a force
  evaluation ξ is first rotated into the current tangent plane, ξ ← ξ − (ξ·n) n, and rescaled to
  its old length (a projection of length 0 stays 0). v_t = v_c − v_n n. Trial
  f_t = −k_t ξ − γ_t v_t, k_t = (2/7) k_n, γ_t = 2ζ√(k_t m_eff). If |f_t| > μ f_n:
  f_t ← μ f_n f_t/|f_t| and ξ ← −(f_t + γ_t v_t)/k_t (the spring slips).
* Force on i: F_i = −f_n n + f_t; torque on i: τ_i = a_i (n × f_t) = a_i (n_x f_t,y − n_y f_t,x).
  From j's side every quantity is the exact (bitwise) negative, so each disc gathers its own
  contacts and Newton's third law holds to round-off.
* Walls: half-planes {x : (x − p)·n_w ≥ 0} with inward normal n_w. Contact when
  s = (x_i − p)·n_w < r_i; n = −n_w, δ = r_i − s, m_eff = m_i, a_i = r_i − δ/2, wall velocity 0,
  own history per (disc, wall), the same formulas with the wall's own e and μ.
* Damping ratio ζ from the restitution e so that a head-on collision of this clamped model
  returns exactly e (``restitution_of_zeta`` / ``zeta_of_restitution``): for ζ < 1,
  w = √(1 − ζ²), φ = atan2(2ζw, ζ² − w²), e = exp(−ζφ/w)·|cos φ − (ζ/w) sin φ|; ζ = 1: e = exp(−2);
  ζ > 1: κ = √(ζ² − 1), ψ = atanh(2ζκ/(ζ² + κ²)), e = exp(−ζψ/κ)·|cosh ψ − (ζ/κ) sinh ψ|.
  e(ζ) falls monotonically from 1 at ζ = 0; it is inverted by bisection.

Time step (semi-implicit Euler): all forces and torques from the step's start (x, v, ω, ξ); then
v ← v + dt (F/m + g), ω ← ω + dt τ/I, x ← x + dt v; then every contact that still exists at the new
positions updates its history with the new velocities, ξ ← ξ_capped + dt v_t(new) (v_t from the new
v, ω, normal and levers); contacts that ended are deleted.

Algorithm (one step = grid + one force/integrate pass):

1. Cell list, rebuilt every step: a uniform grid over the particles' bounding box, cell size
   2 r_max (enlarged if the box would need more than ~4N cells), padded with one empty ring of
   cells so that every 3×3 block exists; a parallel stable counting sort of the particle indices
   (per-chunk histograms, one serial prefix sum, per-chunk scatter; the particles themselves are
   not reordered). The three cells of a row of the 3×3 block are adjacent in cell order, so a
   disc's candidates are three index ranges.
2. ``_force_integrate``: ``prange`` over discs; gathers every contact (pairs from the grid, then
   the walls), looks each partner up in its own history (K = 8 slots per disc: partner index,
   −1 empty, walls as N + wall index, and ξ), writes the capped ξ to the other history buffer,
   and integrates into the other state buffer (double buffering: the loop never reads what it
   wrote). A disc with more than K contacts at once is an error (``RuntimeError``), never dropped.
   The history update of the time step, ξ ← ξ_capped + dt v_t(new), is deferred to the next
   force evaluation: v_t(new) is computed from the state at the end of the step, which is the
   state that evaluation reads, with the same arithmetic it uses for its own v_t, so the stored
   ξ_capped gets its increment dt v_t first there. A separate history pass after the step gave
   bit-identical trajectories and took 5.7 ms per step next to the force pass's 17.4 ms
   (N = 10^5, 1 thread). A contact that ended is not found by the next evaluation and so is
   deleted; a new one starts at ξ = 0 with no increment. Pairs of two pinned discs are counted
   but get no force and no history.

Cell keys, cell offsets and the sorted indices are uint64 (partner indices in the histories stay
int64, −1 = empty): numba adds a negative-index wraparound fix-up to every signed index, and
dropping it on the neighbour loop made the step ~13 % faster at N = 10^5 on the 2-core machine
(1 thread; bit-identical results). The S-step block loop runs in one serial njit driver that
swaps the buffers. Contacts per step (pairs once, from the disc with the lower index, plus
disc–wall contacts) are summed at each force evaluation, as physcore's ``contact_count()``.

Benchmark (default): the workload of bench_dem.build_initial, 1 untimed warm-up step (compiles),
then 3 blocks of S = 50 steps, median; particle-steps/s and contacts/s. physcore rows only where
``pc.Contacts`` exists (the same scene from bench_dem.build, the same thread count); then, before
timing, both are stepped 200 steps from the same state and their positions compared.

``--check``: e(ζ(e)) = e; head-on collisions of two free discs (μ = 0, no gravity, no walls) at
dt = contact duration / 50, the duration measured as the time the discs overlap; a disc dropped
on a floor (bounce height ratio e²); a sliding disc that ends rolling at ⅔ of its speed; total
momentum of the free gas (no gravity, no walls); the contact count against brute force.

Usage: python benches/grains/peer_numba_dem.py [--n-x 400] [--n-y 250] [--threads 2] [--check]
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
    sys.exit('peer_numba_dem.py needs numba: `pip install numba` (or `pip install ".[bench]"` from the repo root)')

import bench_dem

import physcore as pc

JIT = dict(parallel=True, fastmath=False, cache=False)  # the prange kernels
DRIVER = dict(parallel=False, fastmath=False, cache=False)  # the block loop calling them

K = 8  # history slots per disc

# Slots of the float64 parameter vector p.
P_KN, P_KT, P_ZETA, P_MU, P_DT, P_GX, P_GY, P_CELL, P_RT, NPARAM = range(10)


# --------------------------------------------------------------------------------------------
# Restitution ↔ damping ratio
# --------------------------------------------------------------------------------------------


def restitution_of_zeta(zeta: float) -> float:
    """Restitution of a head-on collision of the clamped linear spring-dashpot (f_n ≥ 0) with
    damping ratio ζ = γ / (2√(k m_eff))."""
    if zeta <= 0.0:
        return 1.0
    if zeta < 1.0:
        w = math.sqrt(1.0 - zeta * zeta)
        phi = math.atan2(2.0 * zeta * w, zeta * zeta - w * w)
        return math.exp(-zeta * phi / w) * abs(math.cos(phi) - zeta / w * math.sin(phi))
    if zeta == 1.0:
        return math.exp(-2.0)
    kappa = math.sqrt(zeta * zeta - 1.0)
    psi = math.atanh(2.0 * zeta * kappa / (zeta * zeta + kappa * kappa))
    return math.exp(-zeta * psi / kappa) * abs(math.cosh(psi) - zeta / kappa * math.sinh(psi))


def zeta_of_restitution(e: float) -> float:
    """The damping ratio ζ ≥ 0 with restitution_of_zeta(ζ) = e, by bisection (e(ζ) decreases
    monotonically from 1 at ζ = 0); e = 1 gives ζ = 0."""
    if not 0.0 < e <= 1.0:
        raise ValueError(f"restitution must be in (0, 1], got {e}")
    if e == 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while restitution_of_zeta(hi) > e:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if restitution_of_zeta(mid) > e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def check_zeta() -> float:
    """max |e(ζ(e)) − e| over e in 0.05..1 (asserted < 1e-12)."""
    err = max(abs(restitution_of_zeta(zeta_of_restitution(e)) - e) for e in np.linspace(0.05, 1.0, 96))
    assert err < 1e-12, err
    return err


# --------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------


@njit(inline="always")
def _contact_force(nx, ny, delta, ai, vcx, vcy, xix, xiy, inc, meff, kn, kt, zeta, mu, rt):
    """Force (fx, fy) and torque on i of one contact, and i's capped history (ξx, ξy); see the
    module docstring. (xix, xiy): the stored history, ξ_capped of the previous step; inc = dt for a
    contact that has one (its pending increment dt v_t is added first), 0 for a new contact.
    rt = √(k_t/k_n), so γ_t = rt γ_n (one square root per contact, not two)."""
    vn = vcx * nx + vcy * ny
    gn = 2.0 * zeta * np.sqrt(kn * meff)
    fn = kn * delta + gn * vn
    if fn < 0.0:
        fn = 0.0
    vtx = vcx - vn * nx
    vty = vcy - vn * ny
    xix = xix + inc * vtx
    xiy = xiy + inc * vty
    old2 = xix * xix + xiy * xiy
    if old2 > 0.0:  # rotate into the tangent plane, keep the length
        dn = xix * nx + xiy * ny
        px = xix - dn * nx
        py = xiy - dn * ny
        p2 = px * px + py * py
        if p2 > 0.0:
            sc = np.sqrt(old2 / p2)
            xix = px * sc
            xiy = py * sc
        else:
            xix = 0.0
            xiy = 0.0
    gt = rt * gn
    ftx = -kt * xix - gt * vtx
    fty = -kt * xiy - gt * vty
    lim = mu * fn
    ft2 = ftx * ftx + fty * fty
    if ft2 > lim * lim:  # Coulomb: the spring slips
        sc = lim / np.sqrt(ft2)
        ftx *= sc
        fty *= sc
        xix = -(ftx + gt * vtx) / kt
        xiy = -(fty + gt * vty) / kt
    fx = -fn * nx + ftx
    fy = -fn * ny + fty
    tau = ai * (nx * fty - ny * ftx)
    return fx, fy, tau, xix, xiy


@njit(**JIT)
def _bounds(x, out):
    """out[t] = (min x, max x, min y, max y) over chunk t of the particles (nchunks = len(out))."""
    n = x.shape[0]
    nchunks = out.shape[0]
    chunk = (n + nchunks - 1) // nchunks
    for t in prange(nchunks):
        a = min(n, t * chunk)
        b = min(n, (t + 1) * chunk)
        lo0 = np.inf
        hi0 = -np.inf
        lo1 = np.inf
        hi1 = -np.inf
        for i in range(a, b):
            lo0 = min(lo0, x[i, 0])
            hi0 = max(hi0, x[i, 0])
            lo1 = min(lo1, x[i, 1])
            hi1 = max(hi1, x[i, 1])
        out[t, 0] = lo0
        out[t, 1] = hi0
        out[t, 2] = lo1
        out[t, 3] = hi1


@njit(**JIT)
def _sort(x, key, order, counts, cellstart, lo0, lo1, inv_cs, ncx1, ncy1, gx):
    """Parallel counting sort of the particle indices into cell order: key[i] = padded cell of i,
    order = indices by cell (ascending i within a cell, whatever the number of chunks),
    cellstart[k] = first position of cell k in order (cellstart[-1] = N). Each chunk of particles
    histograms its keys, one serial prefix sum over (cell, chunk) gives each chunk its offsets,
    each chunk scatters its indices."""
    n = x.shape[0]
    nchunks = counts.shape[0]
    ncell = cellstart.shape[0] - 1
    chunk = (n + nchunks - 1) // nchunks
    for t in prange(nchunks):
        cnt = counts[t]
        cnt[:] = 0
        for i in range(t * chunk, min(n, (t + 1) * chunk)):
            ix = min(np.int64((x[i, 0] - lo0) * inv_cs), ncx1)
            iy = min(np.int64((x[i, 1] - lo1) * inv_cs), ncy1)
            k = (iy + 1) * gx + ix + 1
            key[i] = k
            cnt[k] += 1
    off = 0
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
            k = key[i]
            order[cnt[k]] = i
            cnt[k] += 1


@njit(**JIT)
def _force_integrate(x, v, w, r, invm, invi, hp, hx, xo, vo, wo, hpo, hxo, nslot, npair, nwall,
                     order, cellstart, key, gx, wall_p, wall_n, wall_c, p):
    """Forces, torques and the capped histories at (x, v, w, hp, hx) (hx: the previous step's
    ξ_capped, whose increment dt v_t is added here first); writes the new state to (xo, vo, wo)
    and the histories to (hpo, hxo). nslot[i]: contacts of i (> K: overflow); npair[i]: pairs
    (i, j > i) in contact; nwall[i]: wall contacts of i. gx: padded grid row length (uint64)."""
    n = x.shape[0]
    nw = wall_p.shape[0]
    kn = p[P_KN]
    kt = p[P_KT]
    zeta = p[P_ZETA]
    mu = p[P_MU]
    rt = p[P_RT]
    dt = p[P_DT]
    gxc = p[P_GX]
    gyc = p[P_GY]
    u1 = np.uint64(1)
    u2 = np.uint64(2)
    for i in prange(n):
        iu = np.uint64(i)
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        vi0 = v[i, 0]
        vi1 = v[i, 1]
        wi = w[i]
        ri = r[i]
        imi = invm[i]
        fx = 0.0
        fy = 0.0
        tq = 0.0
        ns = 0
        cp = 0
        for s in range(K):
            hpo[i, s] = -1
        k = key[i]
        for kr in (k - gx, k, k + gx):
            for q in range(cellstart[kr - u1], cellstart[kr + u2]):
                j = order[q]
                if j == iu:
                    continue
                dx = x[j, 0] - xi0
                dy = x[j, 1] - xi1
                d2 = dx * dx + dy * dy
                rs = ri + r[j]
                if d2 >= rs * rs or d2 == 0.0:
                    continue
                d = np.sqrt(d2)
                if d >= rs:
                    continue
                if j > iu:
                    cp += 1
                im = imi + invm[j]
                if im == 0.0:  # two pinned discs: no force, no history
                    continue
                inv_d = 1.0 / d
                nx = dx * inv_d
                ny = dy * inv_d
                ji = np.int64(j)
                delta = rs - d
                ai = ri - 0.5 * delta
                aj = r[j] - 0.5 * delta
                rot = ai * wi + aj * w[j]
                vcx = vi0 - v[j, 0] - rot * ny
                vcy = vi1 - v[j, 1] + rot * nx
                xix = 0.0
                xiy = 0.0
                inc = 0.0
                for s in range(K):
                    if hp[i, s] == ji:
                        xix = hx[i, s, 0]
                        xiy = hx[i, s, 1]
                        inc = dt
                        break
                    if hp[i, s] < 0:
                        break
                cfx, cfy, ctq, xix, xiy = _contact_force(nx, ny, delta, ai, vcx, vcy, xix, xiy, inc, 1.0 / im,
                                                         kn, kt, zeta, mu, rt)
                fx += cfx
                fy += cfy
                tq += ctq
                if ns < K:
                    hpo[i, ns] = ji
                    hxo[i, ns, 0] = xix
                    hxo[i, ns, 1] = xiy
                ns += 1
        cw = 0
        if imi > 0.0:
            for b in range(nw):
                nwx = wall_n[b, 0]
                nwy = wall_n[b, 1]
                sd = (xi0 - wall_p[b, 0]) * nwx + (xi1 - wall_p[b, 1]) * nwy
                if sd >= ri:
                    continue
                cw += 1
                nx = -nwx
                ny = -nwy
                delta = ri - sd
                ai = ri - 0.5 * delta
                rot = ai * wi
                vcx = vi0 - rot * ny
                vcy = vi1 + rot * nx
                jw = n + b
                xix = 0.0
                xiy = 0.0
                inc = 0.0
                for s in range(K):
                    if hp[i, s] == jw:
                        xix = hx[i, s, 0]
                        xiy = hx[i, s, 1]
                        inc = dt
                        break
                    if hp[i, s] < 0:
                        break
                cfx, cfy, ctq, xix, xiy = _contact_force(nx, ny, delta, ai, vcx, vcy, xix, xiy, inc, 1.0 / imi,
                                                         kn, kt, wall_c[b, 0], wall_c[b, 1], rt)
                fx += cfx
                fy += cfy
                tq += ctq
                if ns < K:
                    hpo[i, ns] = jw
                    hxo[i, ns, 0] = xix
                    hxo[i, ns, 1] = xiy
                ns += 1
        else:  # pinned: still counts its wall contacts
            for b in range(nw):
                sd = (xi0 - wall_p[b, 0]) * wall_n[b, 0] + (xi1 - wall_p[b, 1]) * wall_n[b, 1]
                if sd < ri:
                    cw += 1
        nslot[i] = ns
        npair[i] = cp
        nwall[i] = cw
        if imi > 0.0:
            v0 = vi0 + dt * (fx * imi + gxc)
            v1 = vi1 + dt * (fy * imi + gyc)
            wo[i] = wi + dt * (tq * invi[i])
            vo[i, 0] = v0
            vo[i, 1] = v1
            xo[i, 0] = xi0 + dt * v0
            xo[i, 1] = xi1 + dt * v1
        else:
            wo[i] = wi
            vo[i, 0] = vi0
            vo[i, 1] = vi1
            xo[i, 0] = xi0
            xo[i, 1] = xi1


@njit(**JIT)
def _tally(nslot, npair, nwall):
    """(contacts this step: pairs once + wall contacts, discs with more than K contacts)."""
    tot = 0
    bad = 0
    for i in prange(nslot.shape[0]):
        tot += npair[i] + nwall[i]
        if nslot[i] > K:
            bad += 1
    return tot, bad


@njit(**DRIVER)
def _block(x, v, w, r, invm, invi, hp, hx, xb, vb, wb, hpb, hxb, nslot, npair, nwall, key, order,
           wall_p, wall_n, wall_c, p, steps):
    """`steps` steps; the state ends in (x, v, w, hp, hx). Returns (contacts summed over the
    steps' force evaluations, steps done): fewer steps than asked when a disc had more than K
    contacts (that step's result is discarded)."""
    n = x.shape[0]
    cs = p[P_CELL]
    total = 0
    done = 0
    a_x, a_v, a_w, a_hp, a_hx = x, v, w, hp, hx
    b_x, b_v, b_w, b_hp, b_hx = xb, vb, wb, hpb, hxb
    nchunks = max(1, numba.get_num_threads())
    box = np.empty((nchunks, 4))
    for _ in range(steps):
        _bounds(a_x, box)
        lo0 = box[:, 0].min()
        hi0 = box[:, 1].max()
        lo1 = box[:, 2].min()
        hi1 = box[:, 3].max()
        if not (np.isfinite(lo0) and np.isfinite(hi0) and np.isfinite(lo1) and np.isfinite(hi1)):
            raise ValueError("non-finite position")
        c = cs
        while ((hi0 - lo0) / c + 1.0) * ((hi1 - lo1) / c + 1.0) > 4.0 * n + 16.0:
            c *= 2.0
        ncx = np.int64((hi0 - lo0) / c) + 1
        ncy = np.int64((hi1 - lo1) / c) + 1
        gx = ncx + 2
        ncell = gx * (ncy + 2)
        cellstart = np.empty(ncell + 1, dtype=np.uint64)
        counts = np.empty((nchunks, ncell), dtype=np.int64)
        _sort(a_x, key, order, counts, cellstart, lo0, lo1, 1.0 / c, ncx - 1, ncy - 1, gx)
        _force_integrate(a_x, a_v, a_w, r, invm, invi, a_hp, a_hx, b_x, b_v, b_w, b_hp, b_hx, nslot, npair, nwall,
                         order, cellstart, key, np.uint64(gx), wall_p, wall_n, wall_c, p)
        tot, bad = _tally(nslot, npair, nwall)
        if bad > 0:
            break
        total += tot
        a_x, b_x = b_x, a_x
        a_v, b_v = b_v, a_v
        a_w, b_w = b_w, a_w
        a_hp, b_hp = b_hp, a_hp
        a_hx, b_hx = b_hx, a_hx
        done += 1
    if done % 2 == 1:
        x[:, :] = a_x
        v[:, :] = a_v
        w[:] = a_w
        hp[:, :] = a_hp
        hx[:, :, :] = a_hx
    return total, done


# --------------------------------------------------------------------------------------------
# The simulation object
# --------------------------------------------------------------------------------------------


class NumbaDEM:
    """A DEM system of discs (float64). x, v: (N, 2) m, m/s; r, m: (N,) m, kg (m = inf: pinned);
    walls: sequence of (point (2,), inward normal (2,), restitution, friction); grains share
    (stiffness k_n N/m, restitution, friction). After step(s) the state is in self.x, self.v,
    self.omega; self.contacts: contacts summed over all force evaluations so far."""

    def __init__(self, x, v, r, m, *, stiffness=bench_dem.K_N, restitution=bench_dem.RESTITUTION,
                 friction=bench_dem.FRICTION, gravity=bench_dem.GRAVITY, dt=bench_dem.DT, walls=(), omega=None):
        n = len(x)
        self.x = np.array(x, dtype=np.float64, order="C").reshape(n, 2)
        self.v = np.array(v, dtype=np.float64, order="C").reshape(n, 2)
        self.omega = np.zeros(n) if omega is None else np.array(omega, dtype=np.float64)
        self.r = np.ascontiguousarray(np.broadcast_to(np.asarray(r, dtype=np.float64), (n,)))
        m = np.broadcast_to(np.asarray(m, dtype=np.float64), (n,))
        self.invm = np.where(np.isinf(m), 0.0, 1.0 / m)
        self.invi = 2.0 * self.invm / self.r**2  # I = ½ m r²
        self.hp = np.full((n, K), -1, dtype=np.int64)
        self.hx = np.zeros((n, K, 2))
        self.xb, self.vb, self.wb = np.empty_like(self.x), np.empty_like(self.v), np.empty_like(self.omega)
        self.hpb, self.hxb = np.empty_like(self.hp), np.empty_like(self.hx)
        self.nslot, self.npair, self.nwall = (np.zeros(n, dtype=np.int64) for _ in range(3))
        self.key = np.zeros(n, dtype=np.uint64)
        self.order = np.zeros(n, dtype=np.uint64)
        nw = len(walls)
        self.wall_p = np.zeros((nw, 2))
        self.wall_n = np.zeros((nw, 2))
        self.wall_c = np.zeros((nw, 2))  # (ζ, μ)
        for b, (pt, nrm, e, mu) in enumerate(walls):
            nrm = np.asarray(nrm, dtype=np.float64)
            self.wall_p[b] = pt
            self.wall_n[b] = nrm / np.linalg.norm(nrm)
            self.wall_c[b] = (zeta_of_restitution(e), mu)
        p = np.zeros(NPARAM)
        p[P_KN] = stiffness
        p[P_KT] = 2.0 / 7.0 * stiffness
        p[P_ZETA] = zeta_of_restitution(restitution)
        p[P_MU] = friction
        p[P_DT] = dt
        p[P_GX], p[P_GY] = gravity
        p[P_CELL] = 2.0 * float(self.r.max())
        p[P_RT] = math.sqrt(2.0 / 7.0)
        self.p = p
        self.dt = dt
        self.contacts = 0
        self.steps = 0

    @classmethod
    def workload(cls, n_x=400, n_y=250, seed=42, **kw) -> NumbaDEM:
        """bench_dem's workload: the lattice in the box with its four walls."""
        ini = bench_dem.build_initial(n_x, n_y, seed)
        (x0, y0), (x1, y1) = ini.lower, ini.upper
        e, mu = kw.pop("restitution", bench_dem.RESTITUTION), kw.pop("friction", bench_dem.FRICTION)
        walls = [((x0, y0), (1.0, 0.0), e, mu), ((x1, y0), (-1.0, 0.0), e, mu),
                 ((x0, y0), (0.0, 1.0), e, mu), ((x0, y1), (0.0, -1.0), e, mu)]
        return cls(ini.x, ini.v, ini.r, ini.m, walls=walls, restitution=e, friction=mu, **kw)

    def step(self, steps: int = 1) -> int:
        """Advance `steps` steps; returns the contacts summed over their force evaluations.
        RuntimeError if a disc has more than K contacts at once (the state is that of the last
        complete step)."""
        total, done = _block(self.x, self.v, self.omega, self.r, self.invm, self.invi, self.hp, self.hx,
                             self.xb, self.vb, self.wb, self.hpb, self.hxb, self.nslot, self.npair, self.nwall,
                             self.key, self.order, self.wall_p, self.wall_n, self.wall_c, self.p, steps)
        self.contacts += total
        self.steps += done
        if done < steps:
            worst = int(self.nslot.max())
            raise RuntimeError(f"disc {int(self.nslot.argmax())} has {worst} contacts at once, more than the "
                               f"K = {K} history slots per disc (step {self.steps + 1}); raise K in peer_numba_dem.py")
        return total

    @property
    def positions(self) -> np.ndarray:
        return self.x

    @property
    def velocities(self) -> np.ndarray:
        return self.v

    @property
    def n(self) -> int:
        return len(self.x)


# --------------------------------------------------------------------------------------------
# Checks (--check)
# --------------------------------------------------------------------------------------------


def _head_on(e: float, v0: float = 0.1, dt: float | None = None) -> tuple[float, float, int]:
    """Two free discs (r = 1e-3 m, m = 1e-5 kg, k_n = 1e3 N/m, μ = 0, no gravity, no walls) meet head
    on at relative speed v0. Returns (measured restitution, time in contact in s, steps in contact)."""
    r, m = bench_dem.RADIUS, bench_dem.MASS
    if dt is None:
        dt = math.pi * math.sqrt(0.5 * m / bench_dem.K_N) / 50.0
    gap = 0.37 * v0 * dt  # first touch inside a step, not on a step boundary
    x = [[-r - gap / 2, 0.0], [r + gap / 2, 0.0]]
    v = [[v0 / 2, 0.0], [-v0 / 2, 0.0]]
    sim = NumbaDEM(x, v, r, m, restitution=e, friction=0.0, gravity=(0.0, 0.0), dt=dt)
    in_contact = 0
    for _ in range(100_000):
        c = sim.step(1)
        in_contact += c > 0
        if in_contact and c == 0:
            break
    vrel = sim.v[1, 0] - sim.v[0, 0]
    return vrel / v0, in_contact * dt, in_contact


def _drop(e: float = 0.5, h0: float = 0.02) -> tuple[float, float]:
    """A disc (r = 1e-3 m, m = 1e-5 kg) released at rest with its bottom h0 above a floor (μ = 0.3,
    restitution e), gravity 9.81. Returns (h1/h0, e²): h1 = apex height of the bottom after the
    first bounce."""
    r, m = bench_dem.RADIUS, bench_dem.MASS
    sim = NumbaDEM([[0.0, r + h0]], [[0.0, 0.0]], r, m, restitution=e, walls=[((0.0, 0.0), (0.0, 1.0), e, 0.3)])
    touched = False
    apex = -np.inf
    for _ in range(200_000):
        c = sim.step(1)
        touched |= c > 0
        if touched and c == 0:
            apex = max(apex, sim.x[0, 1])
            if sim.v[0, 1] < 0.0:
                break
    return (apex - r) / h0, e * e


def _roll(v0: float = 0.1, steps: int = 6000) -> tuple[float, float]:
    """A disc (r = 1e-3 m, m = 1e-5 kg, I = ½ m r²) resting on a floor (μ = 0.3, e = 0.5) under
    gravity, given v = (v0, 0) and ω = 0: friction brakes it and spins it up until it rolls, at
    v = v0 / (1 + m r²/I) = ⅔ v0. Returns (v_x/v0 after `steps` steps, slip (v_x + ω a)/v0 of the
    contact point, lever a = r − δ/2)."""
    r, m = bench_dem.RADIUS, bench_dem.MASS
    y0 = r - m * 9.81 / bench_dem.K_N  # static overlap
    sim = NumbaDEM([[0.0, y0]], [[v0, 0.0]], r, m, restitution=0.5, walls=[((0.0, 0.0), (0.0, 1.0), 0.5, 0.3)])
    sim.step(steps)
    a = r - 0.5 * (r - sim.x[0, 1])
    return sim.v[0, 0] / v0, (sim.v[0, 0] + sim.omega[0] * a) / v0


def _momentum(n_side: int = 40, steps: int = 400) -> tuple[float, int, int]:
    """bench_dem's lattice (n_side²), no gravity, no walls, e = 0.8, μ = 0.3: |ΔP| / Σ m|v| after
    `steps` steps, contacts at the first step, brute-force pair count of the initial state."""
    ini = bench_dem.build_initial(n_side, n_side)
    sim = NumbaDEM(ini.x, ini.v, ini.r, ini.m, gravity=(0.0, 0.0))
    p0 = (ini.m[:, None] * ini.v).sum(axis=0)
    scale = float((ini.m * np.linalg.norm(ini.v, axis=1)).sum())
    first = sim.step(1)
    sim.step(steps - 1)
    p1 = (ini.m[:, None] * sim.v).sum(axis=0)
    d = np.linalg.norm(ini.x[:, None, :] - ini.x[None, :, :], axis=2)
    rs = ini.r[:, None] + ini.r[None, :]
    brute = int(np.triu((d < rs) & (d > 0.0), 1).sum())
    return float(np.linalg.norm(p1 - p0)) / scale, first, brute


def check() -> None:
    print(f"ζ(e) self-check: max |e(ζ(e)) − e| over e in 0.05..1 = {check_zeta():.1e}")
    print("Head-on collision of two free discs (μ = 0, no gravity, no walls), dt = contact duration / 50:")
    for e in (0.1, 0.5, 0.9, 1.0):
        _, tc, _ = _head_on(e)  # first guess of dt from π√(m_eff/k_n); measure the duration
        e_meas, tc2, nc = _head_on(e, dt=tc / 50.0)
        err = e_meas / e - 1.0
        print(f"  e = {e:.1f} (ζ = {zeta_of_restitution(e):.4f}): measured {e_meas:.5f} (error {100 * err:+.2f} %, "
              f"{'within' if abs(err) <= 0.01 else 'NOT within'} 1 %), contact duration {tc2 * 1e6:.1f} µs = {nc} steps "
              f"of dt = {tc / 50 * 1e6:.2f} µs")
    # The error is the first-order time-step error of semi-implicit Euler (largest for the strongly
    # overdamped e = 0.1, ζ ≈ 1.24): it halves with dt.
    _, tc, _ = _head_on(0.1)
    conv = [(f, _head_on(0.1, dt=tc / f)[0]) for f in (50, 100, 200, 400)]
    print("  e = 0.1 against dt: " + ", ".join(f"dt = duration/{f}: {100 * (em / 0.1 - 1):+.2f} %" for f, em in conv))
    ratio, e2 = _drop()
    print(f"Disc dropped from 2 cm on a floor, e = 0.5, dt = {bench_dem.DT:g} s: bounce height ratio "
          f"{ratio:.5f} vs e² = {e2:.5f} (error {100 * (ratio / e2 - 1):+.2f} %)")
    vr, slip = _roll()
    print(f"Disc sliding at 0.1 m/s on a floor (μ = 0.3), 6000 steps = 24 ms: v/v0 = {vr:.5f} vs ⅔ = {2 / 3:.5f} "
          f"(error {100 * (vr * 1.5 - 1):+.3f} %), contact-point slip (v + ω a)/v0 = {slip:.1e}")
    ang = np.linspace(0.0, 2.0 * np.pi, K + 2, endpoint=False)  # K + 2 discs around one: K + 2 contacts
    ring = np.concatenate([[[0.0, 0.0]], 1.9e-3 * np.stack([np.cos(ang), np.sin(ang)], axis=1)])
    try:
        NumbaDEM(ring, np.zeros_like(ring), 1e-3, 1e-5, gravity=(0.0, 0.0)).step(1)
        print(f"More than K = {K} contacts on one disc: NOT REPORTED")
    except RuntimeError as e:
        print(f"More than K = {K} contacts on one disc: RuntimeError: {e}")
    drift, first, brute = _momentum()
    print(f"Free gas 40×40 (no gravity, no walls), 400 steps: |ΔP| / Σ m|v| = {drift:.1e}; contacts at step 1: "
          f"{first} (brute-force pair count {brute})")


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


def numba_cpu() -> str:
    """The CPU numba compiles for (its native ISA unless NUMBA_CPU_NAME says otherwise)."""
    try:
        import llvmlite.binding as ll

        return numba.config.CPU_NAME or ll.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - informational only
        return "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-x", type=int, default=400)
    ap.add_argument("--n-y", type=int, default=250)
    ap.add_argument("--threads", type=int, default=2, help="threads for physcore and numba (default 2)")
    ap.add_argument("--check", action="store_true", help="run the model checks (restitution, bounce, momentum) and exit")
    args = ap.parse_args()
    numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
    if args.check:
        check()
        return
    nx, ny = args.n_x, args.n_y
    n = nx * ny
    steps = bench_dem.STEPS
    notes = []
    has_pc = hasattr(pc, "Contacts")
    if has_pc:
        require_release()
        try:
            ref = bench_dem.build(nx, ny, args.threads)
        except pc.PhyscoreError as e:  # a facade ahead of its compiled core
            has_pc = False
            notes.append(f"physcore has pc.Contacts but could not build the scene ({e}): numba alone")
    if has_pc:  # agreement: 200 steps from the same state
        ref.step(200)
        nb = NumbaDEM.workload(nx, ny)
        nb.step(200)
        diff = float(np.abs(np.asarray(ref.positions) - nb.x).max()) / bench_dem.RADIUS
        notes.append(f"200 steps from the same state: max |x_physcore − x_numba| = {diff:.2e} r")
        del ref, nb
    else:
        notes.append("physcore in this build has no contact term (pc.Contacts): numba alone")

    rows, rates = [], {}
    if has_pc:
        scene = bench_dem.build(nx, ny, args.threads)
        scene.step(1)  # warm-up
        t, cps = bench_dem.timed_blocks(scene, steps)
        assert np.isfinite(scene.positions).all()
        rates["physcore"] = (t, cps)
        del scene
    sim = NumbaDEM.workload(nx, ny)
    sim.step(1)  # compiles; untimed
    c0, s0 = sim.contacts, sim.steps
    t = median_block_time(sim.step, steps, bench_dem.BLOCKS)
    assert np.isfinite(sim.x).all()
    rates["numba"] = (t, (sim.contacts - c0) / (sim.steps - s0))
    for label, (t, cps) in rates.items():
        ratio = "—" if label == "physcore" or "physcore" not in rates else f"{t / rates['physcore'][0]:.2f}"
        rows.append(["DEM discs in a box", f"{nx}×{ny} (N={n})", label, f"{cps:.0f}", f"{t / steps * 1e3:.2f}",
                     f"{si(n * steps / t)} particle-steps/s", f"{si(cps * steps / t)} contacts/s", ratio])

    print(header(args.threads))
    print(table(["workload", "size", "implementation", "contacts/step", "ms/step", "rate", "contacts",
                 "physcore / this (speed)"], rows))
    print(f"numba {numba.__version__} (LLVM target {numba_cpu()}), threading layer {numba.threading_layer()}, "
          f"{numba.get_num_threads()} numba threads; physcore threads={args.threads}; os.cpu_count()={os.cpu_count()}; "
          f"float64; 1 warm-up step, then median of {bench_dem.BLOCKS} blocks of S = {steps} steps")
    for s in notes:
        print("  " + s)


if __name__ == "__main__":
    main()
