"""XPBD constraints and the "xpbd" integrator (Macklin, Müller & Chentanez 2016; Macklin et al.
2019) and shape matching (Müller et al. 2005): physical stiffness, agreement with springs,
pins, area and volume, rigid bodies, determinism, bad input.

Every figure a tolerance is set from is printed (run with -s to see them).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore.scenes import cloth_springs

G = 9.81


def hanging_mass(alpha: float, dt: float, substeps: int, iterations: int, seconds: float = 30.0) -> float:
    """A 0.5 kg bob on one distance constraint of compliance alpha (m/N) under a pinned point,
    settled by drag: its stretch divided by the physical m g alpha."""
    m = 0.5
    s = pc.Scene(dim=2, integrator="xpbd", dt=dt, xpbd_substeps=substeps, xpbd_iterations=iterations, threads=1)
    s.add_particles([[0.0, 0.0], [0.0, -1.0]], masses=[1.0, m], pinned=[True, False])
    s.add(pc.Gravity([0.0, -G]))
    s.add(pc.Drag(1.0))
    s.add(pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=alpha))
    s.step(int(round(seconds / dt)))
    return (-s.positions[1, 1] - 1.0) / (m * G * alpha)


@pytest.mark.parametrize(
    ("dt", "substeps", "iterations"),
    [(1e-2, 1, 1), (1e-2, 1, 10), (1e-2, 10, 1), (1e-2, 2, 5), (4e-2, 1, 1), (4e-2, 1, 40), (1e-3, 1, 1)],
)
def test_stretch_is_m_g_alpha_for_any_step_and_iteration_count(dt, substeps, iterations):
    # The paper's claim: the compliance is a material constant. A per-iteration λ reset would
    # give a stretch that shrinks with the iteration count (see the Rust test
    # xpbd_resetting_lambda_each_iteration_changes_the_stiffness).
    for alpha in (1e-4, 1e-2):
        ratio = hanging_mass(alpha, dt, substeps, iterations)
        print(f"dt {dt:g} substeps {substeps} iterations {iterations} alpha {alpha:g}: stretch / (m g alpha) = {ratio:.10f}")
        assert abs(ratio - 1.0) < 1e-6


@pytest.mark.parametrize("kind", ["distance", "pins"])
def test_a_compliance_past_float64_over_h_squared_is_no_constraint(kind):
    # alpha / h² overflows to inf for alpha = 1e308: infinitely soft, so the bob falls freely
    # as with no constraint, to round-off (the velocity is then (x − x_prev)/h); the
    # projection's ∞/∞ made it NaN and "diverged".
    def run(constrained: bool) -> np.ndarray:
        s = pc.Scene(dim=2, integrator="xpbd", dt=1e-2, xpbd_substeps=4, threads=1)
        s.add_particles([[0.0, 0.0], [0.0, -1.0]], [[0.0, 0.0], [0.3, 0.0]], pinned=[True, False])
        s.add(pc.Gravity([0.0, -G]))
        if constrained and kind == "distance":
            s.add(pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=1e308))
        elif constrained:
            s.add(pc.XpbdConstraints(pins=[1], pin_targets=[[0.0, -1.0]], pin_compliance=1e308))
        s.step(50)
        return s.positions

    free, soft = run(False), run(True)
    assert np.isfinite(soft).all() and soft[1, 1] < -1.0 - 0.9 * 0.5 * G * 0.5**2  # it fell (0.5 s)
    np.testing.assert_allclose(soft, free, rtol=1e-11, atol=0)  # measured 2.9e-13: 200 substeps of (x − x_prev)/h


def spring_cloth_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = cloth_springs(n)
    return i, j


def settled_cloths(n: int = 8, k: float = 2000.0, dt: float = 1e-2, substeps: int = 20):
    """The same n×n sheet (edge pinned) with physcore's springs (cloth's structural, shear and
    bend springs, stiffness k) and with XPBD distance constraints on the same pairs (compliance
    1/k, the same rest lengths), each settled by drag."""
    springs = pc.scenes.cloth(n=n, stiffness=k, damping=0.5, air_drag=2.0, pin="edge", threads=1)
    springs.step(int(round(30.0 / springs.dt)))
    x0 = pc.scenes.cloth(n=n, threads=1).positions
    xp = pc.Scene(3, integrator="xpbd", dt=dt, xpbd_substeps=substeps, threads=1)
    mass = 1.0 / (n * n)
    xp.add_particles(x0, masses=mass, pinned=springs.pinned)
    xp.add(pc.Gravity([0.0, 0.0, -G]))
    xp.add(pc.Drag(2.0 * mass))
    i, j = cloth_springs(n)
    xp.add(pc.XpbdConstraints(distance=np.stack([i, j], 1), distance_compliance=1.0 / k))
    xp.step(int(round(30.0 / dt)))
    return springs, xp


def test_xpbd_cloth_sags_like_the_spring_cloth():
    n, k, dt, substeps = 8, 2000.0, 1e-2, 20
    springs, xp = settled_cloths(n, k, dt, substeps)
    assert np.abs(springs.velocities).max() < 1e-6 and np.abs(xp.velocities).max() < 1e-6
    sag_springs = -springs.positions[:, 2].min()
    sag_xpbd = -xp.positions[:, 2].min()
    diff = np.abs(springs.positions - xp.positions).max()
    # Both minimise the same energy (gravity + Σ ½k(L − L0)² = Σ C²/2α), so the only difference
    # is XPBD's fixed point: with one Gauss–Seidel sweep per substep the constraints are met at
    # the positions the sweep sees, which differ from the end of the substep by at most one
    # substep's fall, g h², per row of constraints between a particle and the pinned edge
    # (n - 1 rows): |Δx| ≤ (n - 1) g h².
    h = dt / substeps
    bound = (n - 1) * G * h * h
    print(f"sag: springs {sag_springs:.6f} m, xpbd {sag_xpbd:.6f} m; max |Δx| {diff:.2e} m, bound (n-1) g h² = {bound:.2e} m")
    assert diff < bound
    # ... and that difference is the substep's: it shrinks as h² (to a quarter at half the h).
    _, finer = settled_cloths(n, k, dt, 2 * substeps)
    diff2 = np.abs(springs.positions - finer.positions).max()
    print(f"at h/2: max |Δx| {diff2:.2e} m (ratio {diff / diff2:.2f})")
    assert 3.0 < diff / diff2 < 5.0


def test_pins_hold_exactly_and_compliant_pins_stretch_by_m_g_alpha():
    s = pc.Scene(3, integrator="xpbd", dt=1e-2, xpbd_substeps=10, threads=1)
    n = 6
    x0 = pc.scenes.cloth(n=n, threads=1).positions
    s.add_particles(x0, masses=0.1)
    s.add(pc.Gravity([0.0, 0.0, -G]))
    s.add(pc.Drag(0.2))
    i, j = cloth_springs(n)
    s.add(pc.XpbdConstraints(distance=np.stack([i, j], 1), distance_compliance=1e-4, pins=np.arange(n)))
    s.step(300)
    held = np.abs(s.positions[:n] - x0[:n]).max()
    print(f"exact pins: max |x - target| = {held:.1e} m while the cloth swings")
    assert held < 1e-12
    # One 0.5 kg bob on a compliant pin: a zero-length spring of stiffness 1/alpha.
    alpha = 1e-3
    b = pc.Scene(2, integrator="xpbd", dt=1e-2, xpbd_substeps=4, threads=1)
    b.add_particles([[0.0, 0.0]], masses=0.5)
    b.add(pc.Gravity([0.0, -G]))
    b.add(pc.Drag(1.0))
    b.add(pc.XpbdConstraints(pins=[0], pin_targets=[[0.0, 0.0]], pin_compliance=alpha))
    b.step(3000)
    ratio = -b.positions[0, 1] / (0.5 * G * alpha)
    print(f"compliant pin: offset / (m g alpha) = {ratio:.10f}")
    assert abs(ratio - 1) < 1e-6


def square_mesh(k: int, size: float):
    """A 2D k×k grid of points cut into triangles (render.Mesh.grid), positively oriented."""
    g = np.arange(k) * size / (k - 1)
    gx, gy = np.meshgrid(g, g)
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    tri = np.array(pc.render.Mesh.grid(k, k).faces)
    e1, e2 = pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return pts, tri


def test_area_constraints_keep_a_soft_squares_area_while_it_squashes():
    # A soft square (distance constraints of compliance 0.1 m/N on every triangle edge, exact
    # area constraints on every triangle) thrown together: its particles start converging on
    # its centre at up to 2 m/s and spinning, so the edges compress and shear.
    x, tri = square_mesh(6, 0.4)
    c0 = x.mean(0)
    r = x - c0
    v = -5.0 * r + 3.0 * np.stack([-r[:, 1], r[:, 0]], 1)
    s = pc.Scene(2, integrator="xpbd", dt=1 / 60, xpbd_substeps=20, threads=1)
    s.add_particles(x, v, masses=0.01)
    edges, _ = pc.scenes.mesh_edges_and_hinges(tri)
    c = s.add(pc.XpbdConstraints(distance=edges, distance_compliance=0.1, area=tri))

    def area(p):
        a, b, d = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
        return 0.5 * ((b - a)[:, 0] * (d - a)[:, 1] - (b - a)[:, 1] * (d - a)[:, 0])

    a0 = area(x)
    worst_total, worst_tri, worst_shape = 0.0, 0.0, 0.0
    for _ in range(120):
        s.step(1)
        p = s.positions
        worst_total = max(worst_total, abs(area(p).sum() / a0.sum() - 1))
        worst_tri = max(worst_tri, np.abs(area(p) / a0 - 1).max())
        # How much it deforms: the largest change of an edge's length.
        ln = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1) / c.rest_length
        worst_shape = max(worst_shape, np.abs(ln - 1).max())
    print(f"2D area error: total {worst_total:.2e}, worst triangle {worst_tri:.2e}, while edges change length by up to {worst_shape:.1%}")
    assert worst_shape > 0.1  # it does deform
    assert worst_total < 1e-3 and worst_tri < 1e-2


def cube_tets(k: int, size: float):
    """A k×k×k lattice of points cut into tetrahedra (6 per cell), positively oriented."""
    g = np.arange(k) * size / (k - 1)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange(k**3).reshape(k, k, k)
    tets = []
    for a in range(k - 1):
        for b in range(k - 1):
            for c in range(k - 1):
                v = [idx[a + i, b + j, c + q] for i in (0, 1) for j in (0, 1) for q in (0, 1)]
                # Kuhn's 6 tetrahedra around the cell's diagonal v0–v7.
                for p in ((1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)):
                    t = [v[0], v[p[0]], v[p[1]], v[7]]
                    tets.append(t)
    tets = np.array(tets)
    e1, e2, e3 = (x[tets[:, i]] - x[tets[:, 0]] for i in (1, 2, 3))
    neg = np.einsum("ij,ij->i", e1, np.cross(e2, e3)) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return x, tets


def test_volume_constraints_keep_a_soft_cubes_volume_while_it_squashes():
    # The 3D analogue: a soft cube of 162 tetrahedra thrown together, spinning.
    x, tets = cube_tets(4, 0.3)
    r = x - x.mean(0)
    v = -5.0 * r + np.cross([0.0, 1.0, 3.0], r)
    s = pc.Scene(3, integrator="xpbd", dt=1 / 60, xpbd_substeps=20, threads=1)
    s.add_particles(x, v, masses=0.01)
    pairs = {(min(a, b), max(a, b)) for t in tets.tolist() for a in t for b in t if a != b}
    edges = np.array(sorted(pairs))
    c = s.add(pc.XpbdConstraints(distance=edges, distance_compliance=0.1, volume=tets))

    def volume(p):
        e1, e2, e3 = (p[tets[:, i]] - p[tets[:, 0]] for i in (1, 2, 3))
        return np.einsum("ij,ij->i", e1, np.cross(e2, e3)) / 6

    v0 = volume(x)
    worst_total, worst_tet, worst_shape = 0.0, 0.0, 0.0
    for _ in range(120):
        s.step(1)
        p = s.positions
        worst_total = max(worst_total, abs(volume(p).sum() / v0.sum() - 1))
        worst_tet = max(worst_tet, np.abs(volume(p) / v0 - 1).max())
        ln = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1) / c.rest_length
        worst_shape = max(worst_shape, np.abs(ln - 1).max())
    print(f"3D volume error: total {worst_total:.2e}, worst tetrahedron {worst_tet:.2e}, while edges change length by up to {worst_shape:.1%}")
    assert worst_shape > 0.05
    assert worst_total < 1e-3 and worst_tet < 1e-2


def test_one_and_two_threads_agree_bit_for_bit():
    # n = 128: 16384 particles and colours of several thousand constraints, so both the
    # particle loops and the constraint colours run in parallel chunks on 2 threads.
    runs = []
    for threads in (1, 2):
        s = pc.scenes.xpbd_cloth(n=128, substeps=4, threads=threads)
        s.step(3)
        runs.append((s.positions.copy(), s.velocities.copy(), s.energy().dissipated["cloth"]))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def rigid_cluster(dim: int, n: int = 12, seed: int = 3):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, dim)) * [0.5, 0.3, 0.2][:dim]
    m = rng.uniform(0.5, 2.0, n)
    x -= (m[:, None] * x).sum(0) / m.sum()
    if dim == 2:
        v = 3.0 * np.stack([-x[:, 1], x[:, 0]], 1)
    else:
        v = np.cross([1.0, 2.0, 3.0], x)
    return x, v, m


def spin(dim: int, substeps: int, seconds: float = 2.0, dt: float = 1e-2):
    """A free rigid cluster (shape matching) spinning for `seconds`: relative change of L, the
    turn of its direction (rad), the largest change of a pair distance (m)."""
    x, v, m = rigid_cluster(dim)
    s = pc.Scene(dim, integrator="xpbd", dt=dt, xpbd_substeps=substeps, threads=1)
    s.add_particles(x, v, masses=m)
    s.add(pc.XpbdConstraints(shapes=[np.arange(len(x))]))
    l0 = np.atleast_1d(s.angular_momentum()).astype(float)
    s.step(int(round(seconds / dt)))
    l1 = np.atleast_1d(s.angular_momentum()).astype(float)
    drift = np.linalg.norm(l1 - l0) / np.linalg.norm(l0)
    turn = math.acos(min(1.0, float(l0 @ l1) / (np.linalg.norm(l0) * np.linalg.norm(l1))))
    d0 = np.linalg.norm(x[:, None] - x[None], axis=-1)
    d1 = np.linalg.norm(s.positions[:, None] - s.positions[None], axis=-1)
    return drift, turn, np.abs(d1 - d0).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_torque_free_rigid_cluster_keeps_its_angular_momentum(dim):
    # The projection onto the rigid shape exerts no torque at the predicted positions (R^T A_pq
    # is symmetric, so Σ m p × (R q) = 0), but XPBD's velocity (x − x_prev)/h is a chord: each
    # substep pulls the straight-line prediction back onto the circle and loses about (ω h)² of
    # L. That is XPBD's first-order damping: |ΔL|/|L| ≈ ω² h T (ω ≈ 3 to 4 rad/s here, T = 2 s),
    # halving with h, while the direction of L and the shape are kept.
    coarse, _, _ = spin(dim, 50)
    drift, turn, shape = spin(dim, 100)
    h = 1e-2 / 100
    print(f"{dim}D: |ΔL|/|L| = {drift:.2e} at h = {h:g} s ({coarse:.2e} at 2h, ratio {coarse / drift:.2f}); L turned {turn:.1e} rad; rigidity error {shape:.1e} m")
    assert drift < 16 * h * 2.0  # ω² h T with ω² ≤ 16 (rad/s)²
    assert 1.8 < coarse / drift < 2.2
    assert turn < 1e-3
    assert shape < 1e-9


def test_rigid_boxes_collide_through_their_grains_and_stack():
    # Two shape-matched boxes whose particles are grains (pc.Contacts, acting in every XPBD
    # substep): one dropped 0.3 m onto the other lands on it and comes to rest on top, and the
    # grains of the two boxes never sink into each other by more than the impact's overlap
    # (v/ω for the four grains that land: about 6 % of a radius).
    k, size, m = 4, 0.4, 1.0 / 16
    spacing = size / (k - 1)
    r = 0.45 * spacing
    g = (np.arange(k) / (k - 1) - 0.5) * size
    local = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    lower = local + [0.0, 0.5 * size + r]
    upper = local + [0.1, 1.5 * size + 3 * r + 0.3]
    dt, substeps = 1 / 120, 200
    s = pc.Scene(2, integrator="xpbd", dt=dt, xpbd_substeps=substeps, threads=1)
    s.add_particles(np.concatenate([lower, upper]), masses=m)
    s.set_attribute("radius", np.full(2 * k * k, r))
    s.add(pc.Gravity([0.0, -G]))
    s.add(pc.XpbdConstraints(shapes=[np.arange(k * k), np.arange(k * k, 2 * k * k)]))
    stiffness = 0.5 * m * (math.pi / (60 * dt / substeps)) ** 2  # a contact lasts 60 substeps
    floor = pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.3, friction=0.5)
    # k_t = (2/7) k, as this landing was set up with (the 2D default is now 1/3, at which the
    # dropped box slides off the other: grains that cannot turn have no period-matching ratio).
    s.add(pc.Contacts(stiffness=stiffness, restitution=0.3, friction=0.5, inertia_factor=1e6, walls=[floor],
                      tangential_ratio=2 / 7))
    closest, landed = np.inf, False
    for _ in range(240):  # 2 s
        s.step(1)
        x = s.positions
        gap = np.linalg.norm(x[: k * k, None] - x[None, k * k:], axis=-1).min()
        closest = min(closest, gap)
        landed |= s.contact_count() >= k + 2  # the floor's k contacts, and the boxes touch
    ya, yb = x[: k * k, 1].mean(), x[k * k:, 1].mean()
    print(f"stacked {yb - ya:.4f} m apart (size + 2r = {size + 2 * r:.4f}, nested {size + math.sqrt(4 * r * r - spacing**2 / 4):.4f}); closest grains {closest / (2 * r):.3f} of 2r; "
          f"speed left {np.abs(s.velocities).max():.2e} m/s")
    assert landed
    # Resting on top: the upper box's bottom row on the lower's top row, its grains on top of
    # those below (rows 2r apart) or nested in the hollows between them (√(4r² − s²/4)).
    assert size + math.sqrt(4 * r * r - spacing**2 / 4) - 0.05 * r < yb - ya < size + 2 * r + 0.05 * r
    assert closest > 1.85 * r
    assert np.abs(s.velocities).max() < 0.05
    assert x[:, 1].min() > 0.9 * r  # nothing sank through the floor
    # The contacts close their books before each substep's projections (which the shapes book):
    # measured 2.4e-5 of the energy here (shape_matched_boxes: 3e-5; closing after them: 2.6e-2).
    print(f"energy drift {s.energy_drift():.1e}")
    assert abs(s.energy_drift()) < 1e-3


def _period(angle, times, dt: float) -> float:
    """The mean time between downward zero crossings of ``angle`` (linear interpolation)."""
    angle, times = np.asarray(angle), np.asarray(times)
    idx = np.flatnonzero((angle[:-1] > 0) & (angle[1:] <= 0))
    tc = times[idx] + dt * angle[idx] / (angle[idx] - angle[idx + 1])
    return float(np.diff(tc).mean())


def test_physical_pendulum_period():
    # A rigid bar of 6 particles (0.1 kg each, 0.1 m apart) swinging about the pinned first one.
    k, m, a = 6, 0.1, 0.1
    r = np.arange(k) * a
    theta0 = 0.05
    x = np.stack([r * math.sin(theta0), -r * math.cos(theta0)], 1)
    dt = 1e-3
    s = pc.Scene(2, integrator="xpbd", dt=dt, xpbd_substeps=10, threads=1)
    s.add_particles(x, masses=m, pinned=[True] + [False] * (k - 1))
    s.add(pc.Gravity([0.0, -G]))
    s.add(pc.XpbdConstraints(shapes=[np.arange(k)]))
    inertia = (m * r[1:] ** 2).sum()
    mass = m * (k - 1)
    d = (m * r[1:]).sum() / mass
    t0 = 2 * math.pi * math.sqrt(inertia / (mass * G * d))
    angle, times = [], []
    for _ in range(int(3 * t0 / dt)):
        s.step(1)
        p = s.positions[-1]
        angle.append(math.atan2(p[0], -p[1]))
        times.append(s.time)
    period = _period(angle, times, dt)
    # The finite amplitude lengthens the period by θ0²/16 (3e-4 relative at 0.05 rad).
    expected = t0 * (1 + theta0**2 / 16)
    err = period / expected - 1
    print(f"pendulum: period {period:.6f} s, 2π√(I/mgd)·(1+θ0²/16) = {expected:.6f} s, relative error {err:.1e}")
    # The pivot is exact (the cluster turns about its pinned particle) and the bar rigid to
    # round-off, so what is left is XPBD's first-order damping, which shrinks the amplitude
    # (shortening the period by θ²/16, a few 1e-7 here) but changes the period itself only at
    # second order: measured 5e-7. Allow 1e-5.
    assert abs(err) < 1e-5


def test_pins_that_fix_a_cluster_hold_it_rigidly():
    # Two pins fix a rigid body in 2D, three not on a line in 3D: a rigid shape (stiffness 1)
    # under gravity must not move at all. (The rotation was once fitted to the free particles
    # alone and turned about the pins' mean: the free particles swung 1.1 m in 0.5 s and the
    # "rigid" cluster stretched from 0.5 to 0.93 m.)
    for dim, x, pinned in [
        (2, [[0, 0], [1, 0], [1.5, 0.0], [1.5, 0.2]], [True, True, False, False]),
        (3, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1.5, 0.3, 0.0], [1.5, 0.2, 0.4]], [True, True, True, False, False]),
    ]:
        s = pc.Scene(dim, integrator="xpbd", dt=1e-3, xpbd_substeps=10, threads=1)
        s.add_particles(x, masses=[1.0] * (len(x) - 2) + [0.5, 0.5], pinned=pinned)
        s.add(pc.Gravity([0.0] * (dim - 1) + [-G]))
        s.add(pc.XpbdConstraints(shapes=[np.arange(len(x))]))
        s.step(500)
        moved = np.abs(s.positions - np.array(x, float)).max()
        print(f"{dim}D: largest move {moved:.1e} m")
        assert moved < 1e-12, dim  # the goals are the rest shape itself: rounding only


def test_pins_on_a_line_make_a_hinge_in_3d():
    # Two pins on the x axis leave a 3D cluster one turn, about that axis: a bar of 5 particles
    # hanging from the axis (in the y-z plane, 0.1 m apart, starting at x = 0.3 and 0.7) swings
    # as a physical pendulum, each particle keeping its x and its distance to the axis, with the
    # period 2π√(I/(M g d)) (1 + θ0²/16) of the 2D test above.
    k, m, a, theta0 = 5, 0.1, 0.1, 0.05
    r = (1 + np.arange(k)) * a
    xs = np.where(np.arange(k) % 2 == 0, 0.3, 0.7)
    free = np.stack([xs, r * math.sin(theta0), -r * math.cos(theta0)], 1)
    x = np.vstack([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], free])
    dt = 1e-3
    s = pc.Scene(3, integrator="xpbd", dt=dt, xpbd_substeps=10, threads=1)
    s.add_particles(x, masses=m, pinned=[True, True] + [False] * k)
    s.add(pc.Gravity([0.0, 0.0, -G]))
    s.add(pc.XpbdConstraints(shapes=[np.arange(k + 2)]))
    inertia, mass = (m * r**2).sum(), m * k
    d = (m * r).sum() / mass
    t0 = 2 * math.pi * math.sqrt(inertia / (mass * G * d))
    angle, times, worst = [], [], 0.0
    for _ in range(int(3 * t0 / dt)):
        s.step(1)
        p = s.positions[2:]
        worst = max(worst, np.abs(p[:, 0] - xs).max(), np.abs(np.hypot(p[:, 1], p[:, 2]) - r).max())
        angle.append(math.atan2(p[-1, 1], -p[-1, 2]))
        times.append(s.time)
    period = _period(angle, times, dt)
    expected = t0 * (1 + theta0**2 / 16)
    err = period / expected - 1
    print(f"hinge: period {period:.6f} s, expected {expected:.6f} s, relative error {err:.1e}; largest drift off the hinge's circles {worst:.1e} m")
    assert worst < 1e-12
    assert abs(err) < 1e-5  # as the 2D pendulum: XPBD's damping, second order in the period


def test_bad_input_raises_value_error_naming_the_argument_before_anything_changes():
    s = pc.Scene(2, integrator="xpbd", threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 0.0]])
    cases = [
        (dict(distance=[[0, 1]], distance_compliance=-1.0), "distance_compliance"),
        (dict(distance=[[0, 7]]), "distance"),
        (dict(distance=[[0, 0]]), "distance"),
        (dict(area=[[0, 1, 3]]), "area"),  # collinear: zero rest area
        (dict(bending=[[0, 1, 2]], bending_compliance=float("nan")), "bending_compliance"),
        (dict(pins=[1], pin_compliance=-1e-3), "pin_compliance"),
        (dict(shapes=[[1]]), "shapes"),
        (dict(shapes=[[0, 1]], shape_stiffness=1.5), "shape_stiffness"),
        (dict(shapes=[[0, 1]], shape_rest=[[1.0, 1.0], [1.0, 1.0]]), "shapes"),  # degenerate rest shape
        (dict(volume=[[0, 1, 2, 3]]), "volume"),  # 2D scene
    ]
    for kwargs, arg in cases:
        with pytest.raises(ValueError, match=f"^{arg}:"):
            s.add(pc.XpbdConstraints(**kwargs))
    assert s.terms == ()
    t = pc.Scene(3, integrator="xpbd", threads=1)
    t.add_particles([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match="^volume:"):
        t.add(pc.XpbdConstraints(volume=[[0, 1, 2, 3]]))  # flat: zero rest volume
    t.add_particles([[2.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="^bending:"):
        t.add(pc.XpbdConstraints(bending=[[0, 1, 4, 2]]))  # wing 4 lies on the edge 0-1: no dihedral angle
    with pytest.raises(ValueError, match="^xpbd_substeps:"):
        pc.Scene(2, integrator="xpbd", xpbd_substeps=0)
    assert t.terms == ()


def test_energy_books_and_save_load():
    s = pc.scenes.xpbd_cloth(n=10)
    s.step(60)
    e = s.energy()
    assert e.potential["cloth"] >= 0 and e.dissipated["cloth"] > 0
    print(f"xpbd_cloth after 1 s: dissipated by the projection {e.dissipated['cloth']:.4f} J, drift {s.energy_drift():.1e}")
    import pickle

    t = pickle.loads(pickle.dumps(s))
    assert t.xpbd_substeps == s.xpbd_substeps == 20 and t.terms == s.terms
    s.step(10)
    t.step(10)
    assert np.array_equal(s.positions, t.positions)


def test_xpbd_rods_are_drawn_like_springs():
    # A pendulum of two XPBD rods: the recording holds its rods as lines (with their strain), and
    # the image shows ink between the bobs, not floating balls.
    s = pc.Scene(2, integrator="xpbd", dt=1e-3)
    s.add_particles([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], masses=1.0, pinned=[True, False, False])
    s.add(pc.XpbdConstraints(distance=[[0, 1], [1, 2]]))
    rec = pc.render.record(s, frames=2)
    np.testing.assert_array_equal(rec.pairs[0], [0, 1])
    np.testing.assert_array_equal(rec.pairs[1], [1, 2])
    img = next(pc.render.frames(s, frames=1, size=(200, 120), radius=2, color_by="none", colorbar=False))
    row = img[np.argmax((img != img[0, 0]).any(axis=2).sum(axis=1))]  # the row through the rods
    ink = (row != img[0, 0]).any(axis=1)
    c = np.flatnonzero(ink)
    assert ink[c.min() : c.max() + 1].mean() > 0.95  # a continuous line from pivot to tip


@pytest.mark.parametrize("substeps", [1, 10, 100])
def test_a_compliant_constraint_damps_exactly_as_implicit_euler(substeps):
    # The docstring's figure: XPBD's numerical damping of a mode ω = 1/√(α m) is implicit
    # Euler's, amplitude decay γ = ln(1 + ω²h²)/(2h) per second (0.4975, 0.05, 0.005 at ω = 10).
    alpha, a, dt = 1e-2, 0.01, 1e-2
    s = pc.Scene(dim=2, integrator="xpbd", dt=dt, xpbd_substeps=substeps)
    s.add_particles([[0.0, 0.0], [1.0 + a, 0.0]], [[0.0, 0.0], [0.0, 0.0]], masses=[1.0, 1.0], pinned=[True, False])
    s.add(pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=alpha, rest_length=[1.0]))
    omega, h = 1.0 / np.sqrt(alpha), dt / substeps
    n = int(round(20 * 2 * np.pi / omega / dt))  # 20 periods
    s.step(n)
    x, v = s.positions[1], s.velocities[1]
    energy = 0.5 * v @ v + 0.5 / alpha * (np.linalg.norm(x) - 1.0) ** 2
    gamma = -np.log(energy / (0.5 / alpha * a * a)) / (2 * n * dt)
    assert gamma == pytest.approx(np.log1p((omega * h) ** 2) / (2 * h), rel=1e-3)


def test_other_integrators_refuse_xpbd_constraints_naming_the_integrator():
    # They add no force: under Verlet a "pendulum" held by a distance constraint fell freely
    # (to y = -5.9 m in a second), silently. Now refused when added, and an xpbd scene refuses
    # to change its integrator, both before anything changes.
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    s.add_particles([[0.0, 0.0], [0.0, -1.0]], pinned=[True, False])
    with pytest.raises(pc.InvalidInputError, match="integrator"):
        s.add(pc.XpbdConstraints(distance=[[0, 1]]))
    assert s.terms == ()
    s = pc.Scene(dim=2, integrator="xpbd", dt=1e-3)
    s.add_particles([[0.0, 0.0], [0.0, -1.0]], pinned=[True, False])
    s.add(pc.XpbdConstraints(distance=[[0, 1]]))
    for other in ("verlet", "semi_implicit_euler", "rk4", "implicit_euler"):
        with pytest.raises(pc.InvalidInputError, match="integrator"):
            s.integrator = other
        assert s.integrator == "xpbd"
    with pytest.raises(pc.InvalidInputError, match="integrator"):
        pc.scenes.xpbd_cloth(integrator="verlet")


def test_advance_takes_substeps_set_by_the_compliant_constraints():
    # auto_dt under "xpbd" takes compliant constraints as implicit Euler takes springs: ω_max·h
    # = 10 per substep, ω_max² = 2/(α m) (Gershgorin). Before, only the other terms set it: the
    # xpbd_cloth scene's drag gave 50 s, one substep per advance() call.
    def scene(alpha):
        s = pc.Scene(dim=2, integrator="xpbd", dt=1e-2, xpbd_substeps=5)
        s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, 2.0], pinned=[True, False])
        s.add(pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=alpha))
        s.add(pc.Drag(1e-3))
        return s

    assert scene(1e-2).auto_dt() == pytest.approx(10 * 5 / np.sqrt(2 / (1e-2 * 2.0)), rel=1e-12)
    drag_only = scene(0.0).auto_dt()  # a stiff constraint has no oscillation to resolve
    assert drag_only > 1.0
    cloth = pc.scenes.xpbd_cloth()
    assert cloth.auto_dt() < 0.1 and cloth.advance(0.1) >= 2
