"""Rigid bodies in 3D (physcore.bodies on rapier3d-f64) against closed forms: free fall, friction
on an incline, the large-amplitude pendulum on a revolute and on a spherical joint, a ball
resting on a triangle-mesh floor and on a convex hull; the world's promises in 3D (threads,
save/load bit for bit, the books); particles pinned to bodies (Pins); bad input by name."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk
from test_bodies import _rebound

import physcore as pc

G = 9.81


def _scene(dt: float = 1 / 240, threads: int | None = None, gravity: bool = True) -> pc.Scene:
    s = pc.Scene(dim=3, integrator="semi_implicit_euler", dt=dt, threads=threads)
    if gravity:
        s.add(pc.Gravity([0.0, 0.0, -G]))
    return s


def _about_y(theta: float) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a turn by theta about y."""
    return (0.0, math.sin(theta / 2), 0.0, math.cos(theta / 2))


def test_a_ball_falls_freely_and_the_state_reads_back():
    s = _scene(dt=1e-3, gravity=True)
    ball = s.add(pc.Bodies("ball", size=0.1, positions=[(0.0, 0.0, 10.0)], velocities=[(1.0, 0.0, 0.0)],
                           angular_velocities=[(0.0, 0.0, 2.0)]))
    assert ball.dim == 3
    s.step(1000)
    x = ball.positions[0]
    assert x[0] == pytest.approx(1.0, abs=1e-9) and x[2] == pytest.approx(10.0 - G / 2, abs=G * 1e-3)
    assert ball.angular_velocities[0] == pytest.approx([0.0, 0.0, 2.0])
    q = ball.orientations[0]  # turned by 2 rad about z in 1 s (rapier's per-step quaternion
    # update, renormalised, errs by 1.8e-8 here: its first-order rotation integrator)
    assert q == pytest.approx([0.0, 0.0, math.sin(1.0), math.cos(1.0)], abs=1e-7)
    assert ball.masses[0] == pytest.approx(1000.0 * 4 / 3 * math.pi * 1e-3)
    assert ball.inertia[0] == pytest.approx([0.4 * ball.masses[0] * 0.01] * 3)


def _incline(theta: float, mu: float) -> tuple[pc.Scene, pc.Bodies]:
    """A box on a fixed ramp turned by theta about y (downhill: +x), friction mu, restitution 0."""
    s = _scene(dt=1 / 600)
    q = _about_y(theta)  # turns the box's z onto the ramp's normal n: the ramp rises towards −x
    n = np.array([math.sin(theta), 0.0, math.cos(theta)])
    s.add(pc.Bodies("box", size=[(4.0, 1.0, 0.1)], positions=[-0.1 * n], orientations=[q], kind="fixed", friction=mu,
                    restitution=0.0))
    block = s.add(pc.Bodies("box", size=[(0.1, 0.1, 0.1)], positions=[0.1 * n], orientations=[q], friction=mu,
                            restitution=0.0))
    return s, block


def test_block_on_incline_sticks_below_the_friction_angle():
    s, block = _incline(math.radians(20.0), 0.5)  # tan 20° = 0.364 < 0.5
    x0 = block.positions[0].copy()
    s.step(600)
    assert np.linalg.norm(block.positions[0] - x0) < 1e-3
    assert np.linalg.norm(block.velocities[0]) < 1e-3


@pytest.mark.parametrize("deg", [30.0, 40.0])
def test_block_on_incline_slides_with_coulomb_acceleration(deg):
    theta, mu = math.radians(deg), 0.3
    s, block = _incline(theta, mu)
    down = np.array([math.cos(theta), 0.0, -math.sin(theta)])
    s.step(60)
    v0, t0 = float(block.velocities[0] @ down), s.time
    s.step(300)
    a = (float(block.velocities[0] @ down) - v0) / (s.time - t0)
    assert a == pytest.approx(G * (math.sin(theta) - mu * math.cos(theta)), rel=0.02)


def _period(kind: str) -> tuple[float, float, pc.Bodies]:
    """A small ball on a joint at the origin released from (L, 0, 0) (90°), swinging in the xz
    plane: its measured period, the exact one, 4 K(sin²(θ0/2))/ω0 with ω0² = m g L / I_pivot
    (Landau & Lifshitz, Mechanics §11), and the ball."""
    L, r, theta0 = 1.0, 0.02, math.pi / 2
    s = _scene(dt=1 / 2000)
    bob = s.add(pc.Bodies("ball", size=[r], positions=[(L, 0.0, 0.0)], friction=0.0))
    opts = {"axis": (0.0, 1.0, 0.0)} if kind == "revolute" else {}
    s.add(pc.Joints(kind, None, bob[0], anchors=(0.0, 0.0, 0.0), **opts))
    m = float(bob.masses[0])
    w0 = math.sqrt(m * G * L / (m * (L * L + 0.4 * r * r)))
    exact = 4 * ellipk(math.sin(theta0 / 2) ** 2) / w0
    t_prev, x_prev, crossings = 0.0, L, []
    while len(crossings) < 5:
        s.step(5)
        x = float(bob.positions[0, 0])
        if (x_prev > 0) != (x > 0):
            crossings.append(t_prev + (s.time - t_prev) * x_prev / (x_prev - x))
        t_prev, x_prev = s.time, x
    return (crossings[4] - crossings[0]) / 2, exact, bob


@pytest.mark.parametrize("kind", ["revolute", "spherical"])
def test_pendulum_keeps_the_large_amplitude_period(kind):
    measured, exact, bob = _period(kind)
    assert measured == pytest.approx(exact, rel=0.005)
    assert np.linalg.norm(bob.positions[0]) == pytest.approx(1.0, abs=1e-3)
    assert abs(bob.positions[0, 1]) < 1e-9  # it stays in its plane


def _top(dt: float, theta: float, spin: float, steady: bool, floor: float | None = None, threads: int | None = None):
    """A heavy top: a 0.2 × 0.2 × 0.04 m plate whose centre is l = 0.1 m from a spherical joint to
    the world at the origin along its short axis (body z), tilted theta from the vertical, spun
    at `spin` about that axis; `steady`: with the precession rate Ω of steady precession (the
    slow root of m g l = Ω (I₃ω₃ − I₁′ Ω cos θ), I₁′ = I₁ + m l²: Goldstein, Poole and Safko,
    *Classical Mechanics*, 3rd ed., §5.7), else released without precession. Returns the scene,
    the body, m, I₁′, I₃, Ω."""
    s = _scene(dt=dt, threads=threads)
    if floor is not None:
        s.add(pc.Bodies("box", size=[(1.0, 1.0, 0.05)], positions=[(0.0, 0.0, floor - 0.05)], kind="fixed"))
    e3 = np.array([math.sin(theta), 0.0, math.cos(theta)])
    top = s.add(pc.Bodies("box", size=[(0.1, 0.1, 0.02)], positions=[0.1 * e3], orientations=[_about_y(theta)]))
    s.add(pc.Joints("spherical", None, top[0], anchors=(0.0, 0.0, 0.0)))
    m, (i1, _, i3) = top.masses[0], top.inertia[0]
    i1p = i1 + m * 0.01
    a = i1p * math.cos(theta)
    om = (i3 * spin - math.sqrt((i3 * spin) ** 2 - 4 * a * m * G * 0.1)) / (2 * a) if steady else 0.0
    w = om * np.array([0.0, 0.0, 1.0]) + (spin - om * math.cos(theta)) * e3
    top.angular_velocities = [w]
    top.velocities = [np.cross(w, 0.1 * e3)]
    return s, top, m, i1p, i3, om


def _axis_and_energy(top: pc.Bodies, m: float) -> tuple[np.ndarray, float]:
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_quat(top.orientations[0])
    wb = rot.inv().apply(top.angular_velocities[0])
    v = top.velocities[0]
    k = 0.5 * m * v @ v + 0.5 * wb @ (top.inertia[0] * wb)
    return rot.apply([0.0, 0.0, 1.0]), k + m * G * top.positions[0, 2]


@pytest.mark.parametrize(("dt", "tilt_tol", "rate_tol"), [(1e-3, 2e-5, 2e-5), (1 / 240, 3e-4, 3e-4), (1 / 60, 5e-3, 5e-3)])
def test_a_top_in_steady_precession_stays_level_and_keeps_its_energy(dt, tilt_tol, rate_tol):
    """Issue 64 item 4: a top started in steady precession (tilt 0.5 rad, 60 rad/s, Ω = 2.662
    rad/s) keeps its tilt and its precession rate over two precession periods, its energy to
    a bounded error. Before, on rapier's joint, it sank 0.022 / 0.098 / 0.46 rad a period at
    these steps (first order) and gained energy; the top's own splitting (second order, its
    tilt error bounded: measured 9.8e-6 / 1.7e-4 / 2.7e-3 rad) keeps it level."""
    theta = 0.5
    s, top, m, _, _, om = _top(dt, theta, 60.0, steady=True)
    assert om == pytest.approx(2.662, abs=1e-3)
    _, e0 = _axis_and_energy(top, m)
    n = round(2 * 2 * math.pi / om / dt)
    tilt, phase = np.empty(n), np.empty(n)
    for k in range(n):
        s.step(1)
        ax, _ = _axis_and_energy(top, m)
        tilt[k], phase[k] = math.acos(ax[2]), math.atan2(ax[1], ax[0])
    ax, e1 = _axis_and_energy(top, m)
    assert np.abs(tilt - theta).max() < tilt_tol
    # The mean tilt over the last tenth: no sinking (rapier's joint: 0.04 rad at 1e-3 by then).
    assert abs(tilt[-n // 10:].mean() - theta) < tilt_tol / 2
    rate = (np.unwrap(phase)[-1] - phase[0]) / ((n - 1) * dt)
    assert rate == pytest.approx(om, rel=rate_tol)
    assert abs(e1 - e0) < 1e-3 * abs(e0) * (dt / 1e-3) ** 2
    assert np.linalg.norm(top.positions[0] - 0.1 * ax) < 1e-12  # the joint holds exactly


def test_a_released_top_nutates_to_the_closed_form_turning_point_at_second_order():
    """A top released at tilt θ₀ = 0.5 rad without precession falls and nutates between θ₀
    and θ₁, where u₁ = cos θ₁ is the other root of β(1 − u²) = a²(u₀ − u), a = I₃ω₃/I₁′,
    β = 2 m g l / I₁′ (Goldstein, Poole and Safko, §5.7, eq. 5.64 with θ̇ = φ̇ = 0 at θ₀). The
    deepest tilt over three nutations matches θ₁, its error falling as dt² (second order)."""
    theta, spin = 0.5, 60.0
    errs = []
    for dt in (1 / 240, 1 / 960):
        s, top, m, i1p, i3, _ = _top(dt, theta, spin, steady=False)
        a, beta, u0 = i3 * spin / i1p, 2 * m * G * 0.1 / i1p, math.cos(theta)
        u1 = (a * a - math.sqrt(a**4 - 4 * beta * (a * a * u0 - beta))) / (2 * beta)
        _, e0 = _axis_and_energy(top, m)
        deepest = 0.0
        for _ in range(round(3 * 2 * math.pi / a / dt)):  # three nutations (period ≈ 2π/a)
            s.step(1)
            ax, _ = _axis_and_energy(top, m)
            deepest = max(deepest, math.acos(ax[2]))
        _, e1 = _axis_and_energy(top, m)
        depth = math.acos(u1) - theta
        errs.append(abs(deepest - math.acos(u1)) / depth)
        assert abs(e1 - e0) < 5e-5 * abs(e0)  # measured 1.2e-5 at dt = 1/240
    assert errs[1] < 5e-4  # measured 7.4e-5 (0.0074 %) at dt = 1/960
    assert errs[0] / errs[1] > 8  # second order: 16 for a step 4× smaller (sampling adds a little)


def test_a_top_that_falls_onto_the_floor_rests_on_it():
    """A top that stops being free (it touches the floor) is stepped by rapier's contact solve:
    a slow top tilted 0.6 rad, its joint 0.08 m above the floor, falls over and comes to rest on it, its
    plate not through it."""
    s, top, m, *_ = _top(1 / 240, 0.6, 2.0, steady=False, floor=-0.08)
    from scipy.spatial.transform import Rotation

    low = np.inf
    for _ in range(480):
        s.step(1)
        z = Rotation.from_quat(top.orientations[0]).as_matrix()[2]  # the body axes' heights
        # The plate's lowest corner: its centre less its half-extents' reach down.
        low = min(low, top.positions[0, 2] - np.abs(z) @ [0.1, 0.1, 0.02])
    assert low > -0.08 - 2e-3
    assert np.linalg.norm(top.angular_velocities[0]) < 0.5


def test_tops_repeat_bit_for_bit_across_threads_and_a_save_and_load(tmp_path):
    """Two tops, one falling onto a floor (its own step, then rapier's contacts), one spinning
    free: the same bits with 1 and 2 threads, and a scene saved mid-fall and loaded continues
    bit for bit with the books balanced."""

    def scene(threads):
        s, *_ = _top(1 / 240, 0.6, 2.0, steady=False, floor=-0.08, threads=threads)
        e3 = np.array([math.sin(0.5), 0.0, math.cos(0.5)])
        b = s.add(pc.Bodies("box", size=[(0.1, 0.1, 0.02)], positions=[(1.0, 0.0, 0.0) + 0.1 * e3],
                            orientations=[_about_y(0.5)], angular_velocities=[60.0 * e3]))
        s.add(pc.Joints("spherical", None, b[0], anchors=(1.0, 0.0, 0.0)))
        return s

    one, two = scene(1), scene(2)
    e0 = one.energy()
    one.step(30)
    two.step(30)
    one.save(tmp_path / "tops.npz")
    again = pc.Scene.load(tmp_path / "tops.npz")
    for s in (one, two, again):
        s.step(150)  # the first top is on the floor by then
    for g1, g2, g3 in zip(one.bodies, two.bodies, again.bodies, strict=True):
        for name in ("positions", "orientations", "velocities", "angular_velocities"):
            assert np.array_equal(getattr(g1, name), getattr(g2, name)), name
            assert np.array_equal(getattr(g1, name), getattr(g3, name)), name
    assert one.energy().total == again.energy().total
    assert one.energy().total == pytest.approx(e0.total, rel=1e-9)


@pytest.mark.parametrize("e", [0.3, 0.6, 0.9])
def test_restitution_of_a_box_dropped_on_its_corner(e):
    """A cube dropped from 0.5 m corner first, its body diagonal upright (the impulse through
    the centre of mass) onto a fixed floor, both of restitution e: it leaves at e times its
    speed without spin (measured: e to 1e-15)."""
    s = _scene(dt=1 / 1000)
    s.add(pc.Bodies("box", size=[(2.0, 2.0, 0.1)], positions=[(0.0, 0.0, -0.1)], kind="fixed", restitution=e,
                    friction=0.0))
    a = np.arccos(1 / np.sqrt(3))  # turns the corner (-1, -1, -1) straight down
    q = [*(np.sin(a / 2) * np.array([1.0, -1.0, 0.0]) / np.sqrt(2)), np.cos(a / 2)]
    box = s.add(pc.Bodies("box", size=[(0.1, 0.1, 0.1)], positions=[(0.0, 0.0, 0.6)], orientations=[q],
                          restitution=e, friction=0.0))
    assert _rebound(s, box, 2) == pytest.approx(e, rel=0.02)
    assert np.abs(box.angular_velocities[0]).max() < 1e-9


def test_a_ball_rests_on_a_mesh_floor_and_a_hull_rests_on_a_box():
    s = _scene()
    verts = [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)]
    s.add(pc.Bodies("mesh", vertices=verts, triangles=[(0, 1, 2), (0, 2, 3)], kind="fixed"))
    ball = s.add(pc.Bodies("ball", size=0.1, positions=[(0.0, 0.0, 0.5)], restitution=0.0))
    tetra = [(0.1, 0.1, 0.1), (-0.1, -0.1, 0.1), (-0.1, 0.1, -0.1), (0.1, -0.1, -0.1)]
    s.add(pc.Bodies("box", size=[(0.3, 0.3, 0.05)], positions=[(1.0, 0.0, 0.05)], kind="fixed"))
    hull = s.add(pc.Bodies("hull", vertices=tetra, positions=[(1.0, 0.0, 0.6)], restitution=0.0))
    s.step(480)
    assert ball.positions[0, 2] == pytest.approx(0.1, abs=2e-3)
    assert np.linalg.norm(hull.velocities[0]) < 1e-3
    assert 0.1 + 0.05 < hull.positions[0, 2] < 0.1 + 0.1 + 0.05  # on the box: its centre above its lowest corner
    assert hull.masses[0] == pytest.approx(1000.0 * (0.2**3) / 3)  # the regular tetrahedron in a 0.2 m cube


def _falling_pile(threads: int | None) -> pc.Scene:
    s = _scene(threads=threads)
    s.add(pc.Bodies("box", size=[(2.0, 2.0, 0.1)], positions=[(0.0, 0.0, -0.1)], kind="fixed"))
    rng = np.random.default_rng(5)
    pos = np.stack([rng.uniform(-0.5, 0.5, 30), rng.uniform(-0.5, 0.5, 30), 0.3 + np.arange(30) * 0.25], 1)
    q = rng.normal(size=(30, 4))
    s.add(pc.Bodies("box", size=[(0.1, 0.07, 0.05)], positions=pos, orientations=q))
    s.add(pc.Bodies("capsule", size=(0.08, 0.04), positions=pos[:8] + [0.0, 0.0, 8.0]))
    return s


def test_bit_identical_for_one_and_two_threads():
    a, b = _falling_pile(1), _falling_pile(2)
    a.step(300)
    b.step(300)
    for ga, gb in zip(a.bodies, b.bodies, strict=True):
        assert np.array_equal(ga.positions, gb.positions) and np.array_equal(ga.orientations, gb.orientations)


def test_save_and_load_continue_bit_for_bit_and_the_books_balance(tmp_path):
    s = _falling_pile(None)
    e0 = s.energy()
    s.step(200)
    s.save(tmp_path / "pile.npz")
    r = pc.Scene.load(tmp_path / "pile.npz")
    s.step(200)
    r.step(200)
    for ga, gb in zip(s.bodies, r.bodies, strict=True):
        assert np.array_equal(ga.positions, gb.positions) and np.array_equal(ga.orientations, gb.orientations)
        assert np.array_equal(ga.angular_velocities, gb.angular_velocities)
    e1 = s.energy()
    assert e1.total == r.energy().total
    assert e1.total == pytest.approx(e0.total, rel=1e-9)
    assert e1.dissipated["bodies: contacts and joints"] > 0


_BRICK = (0.2, 0.1, 0.05)  # half-extents, m: principal moments in the ratio 1 : 3.4 : 4 (x smallest, z largest)


def _spun_brick(dt: float, omega: tuple[float, float, float]) -> tuple[pc.Scene, pc.Bodies, np.ndarray]:
    """A free brick (no gravity, nothing to touch) turning at `omega` (rad/s, its own axes) and
    its principal moments, kg m²."""
    s = _scene(dt=dt, gravity=False)
    brick = s.add(pc.Bodies("box", size=[_BRICK], positions=[(0.0, 0.0, 0.0)], angular_velocities=[omega]))
    a, b, c = _BRICK
    m = float(brick.masses[0])
    moments = m / 3 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert brick.inertia[0] == pytest.approx(moments, rel=1e-12)
    return s, brick, moments


def _own_axes(brick: pc.Bodies) -> np.ndarray:
    """The brick's angular velocity in its own (principal) axes, rad/s."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(brick.orientations[0]).inv().apply(brick.angular_velocities[0])


@pytest.mark.parametrize("dt", [1e-3, 1 / 60])
@pytest.mark.parametrize("axis", [2, 0], ids=["largest", "smallest"])
def test_a_spin_about_the_largest_or_smallest_axis_stays_stable(axis, dt):
    """Euler's torque-free equations have stable centres about the largest and smallest axes: a
    small wobble stays small for ever. The gyroscopic term is taken by the implicit midpoint
    rule, which keeps the kinetic energy and |L| exactly, so the wobble keeps its size (rapier's
    explicit step grew it by 6 % in 40 s at dt = 1e-3 and by 166 % at 1/60, and a brick spun
    about its largest axis tumbled onto another within two minutes)."""
    omega = [0.05, 0.05, 0.05]
    omega[axis] = 5.0
    s, brick, _ = _spun_brick(dt, tuple(omega))
    wobble = []
    for _ in range(400):
        s.step(round(0.1 / dt))  # 40 s
        w = _own_axes(brick)
        wobble.append(np.linalg.norm(np.delete(w, axis)) / abs(w[axis]))
    first, last = max(wobble[:50]), max(wobble[-50:])
    assert last == pytest.approx(first, rel=0.10)
    assert first < 0.02  # still the small wobble it started with


@pytest.mark.parametrize(("dt", "rel"), [(1e-3, 1e-4), (1 / 60, 2e-3)])
def test_the_intermediate_axis_flips_with_the_exact_period_keeping_energy_and_momentum(dt, rel):
    """The tennis-racket (Dzhanibekov) flip: spun about its middle axis, the brick turns over
    periodically. The time between flips against Euler's equations solved by scipy at 1e-12;
    kinetic energy and |L| kept to rounding (measured 3.403255 s, the exact one, at dt = 1e-3
    and 3.403236 s at 1/60, the midpoint rule in each of rapier's substeps; rapier's own step
    gave 3.4148 s and 3.5786 s, losing 5e-5 of the energy)."""
    from scipy.integrate import solve_ivp

    w0 = (0.1, 5.0, 0.0)
    s, brick, moments = _spun_brick(dt, w0)

    def flips(t: np.ndarray, wy: np.ndarray) -> np.ndarray:
        k = np.nonzero(np.sign(wy[1:]) != np.sign(wy[:-1]))[0]
        return t[k] + (t[k + 1] - t[k]) * wy[k] / (wy[k] - wy[k + 1])

    exact = solve_ivp(lambda t, w: np.cross(moments * w, w) / moments, [0, 15], w0, rtol=1e-12, atol=1e-14,
                      dense_output=True, max_step=0.01)
    t = np.linspace(0, 15, 150001)
    period = np.diff(flips(t, exact.sol(t)[1])).mean()
    ts, wy, energy, momentum = [], [], [], []
    for _ in range(round(15 / dt)):
        s.step(1)
        w = _own_axes(brick)
        ts.append(s.time)
        wy.append(w[1])
        energy.append(0.5 * w @ (moments * w))
        momentum.append(np.linalg.norm(moments * w))
    measured = flips(np.array(ts), np.array(wy))
    assert len(measured) >= 4
    assert np.diff(measured).mean() == pytest.approx(period, rel=rel)
    assert np.ptp(energy) < 1e-10 * energy[0] and np.ptp(momentum) < 1e-10 * momentum[0]


def _world_momentum(body: pc.Bodies) -> np.ndarray:
    """Body 0's angular momentum about its centre of mass in the world frame, R I Rᵀ ω (its
    principal axes its own: a box), kg m²/s."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_quat(body.orientations[0]).as_matrix()
    return rot @ (body.inertia[0] * (rot.T @ body.angular_velocities[0]))


_TUMBLE = (0.3, -0.2, 0.5), (1.0, 3.0, 2.0)  # a rotation vector (rad) and ω (rad/s, world): no principal axis


def _tumbling_brick(dt: float) -> tuple[pc.Scene, pc.Bodies]:
    from scipy.spatial.transform import Rotation

    s = _scene(dt=dt, gravity=False)
    return s, s.add(pc.Bodies("box", size=[_BRICK], orientations=[Rotation.from_rotvec(_TUMBLE[0]).as_quat()],
                              angular_velocities=[_TUMBLE[1]]))


@pytest.mark.parametrize("dt", [1e-3, 1 / 60])
def test_a_tumbling_brick_keeps_its_angular_momentum_in_the_world(dt):
    """Torque-free, the world's angular momentum is fixed. Each substep takes L₁ = Cay(−h Ŵ) L₀
    (the implicit midpoint rule in the principal frame, W = I⁻¹(L₀ + L₁)/2) and turns the body
    by Cay(h Ŵ), so R L is kept to rounding at any step (turned about the end-of-step ω
    instead, L turned by 0.013° in 5 s at dt = 1e-3, at first order: 2.3e-4 of |L|)."""
    s, brick = _tumbling_brick(dt)
    l0, k0 = _world_momentum(brick), s.energy().kinetic
    s.step(round(5 / dt))
    assert np.linalg.norm(_world_momentum(brick) - l0) < 1e-12 * np.linalg.norm(l0)
    assert s.energy().kinetic == pytest.approx(k0, rel=1e-12)


def test_a_tumbling_brick_turns_at_second_order():
    """The brick's orientation after 5 s against Euler's equations and Ṙ = R [ω]× (ω in the
    body's axes) solved by scipy at 1e-12: the error falls 4× when dt halves (measured 7.3e-6
    and 1.8e-6 rad at dt = 2e-3 and 1e-3; the end-of-step turn gave 4.5e-4 and 2.3e-4)."""
    from scipy.integrate import solve_ivp
    from scipy.spatial.transform import Rotation

    turned = {}
    for dt in (2e-3, 1e-3):
        s, brick = _tumbling_brick(dt)
        moments = brick.inertia[0]
        s.step(round(5 / dt))
        turned[dt] = Rotation.from_quat(brick.orientations[0])

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        rot, w = y[:9].reshape(3, 3), y[9:]
        cross = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.concatenate([(rot @ cross).ravel(), np.cross(moments * w, w) / moments])

    r0 = Rotation.from_rotvec(_TUMBLE[0]).as_matrix()
    y = solve_ivp(rhs, (0, 5), np.concatenate([r0.ravel(), r0.T @ np.array(_TUMBLE[1])]), rtol=1e-12, atol=1e-12).y[:, -1]
    exact = Rotation.from_matrix(y[:9].reshape(3, 3))
    coarse, fine = ((turned[dt] * exact.inv()).magnitude() for dt in (2e-3, 1e-3))
    assert coarse / fine == pytest.approx(4.0, rel=0.1)
    assert fine < 1e-5


def test_a_tumbling_box_bouncing_on_a_frictionless_floor_keeps_its_vertical_angular_momentum():
    """Frictionless contacts push along the floor's normal, z, so their moments about the box's
    centre of mass have no z part: L_z is kept through every bounce and at rest (the rapier
    solver's angular impulse is added to the momentum, not to the turned velocity). Measured:
    to 1e-13; the end-of-step turn lost 27 % at dt = 1/240. The box comes to rest on a face."""
    from scipy.spatial.transform import Rotation

    s = _scene(dt=1 / 240)
    s.add(pc.Bodies("box", size=[(5.0, 5.0, 0.5)], positions=[(0.0, 0.0, -0.5)], kind="fixed", friction=0.0,
                    restitution=0.5))
    box = s.add(pc.Bodies("box", size=[_BRICK], positions=[(0.0, 0.0, 1.0)], friction=0.0, restitution=0.5,
                          orientations=[Rotation.from_rotvec(_TUMBLE[0]).as_quat()], angular_velocities=[_TUMBLE[1]]))
    lz = _world_momentum(box)[2]
    s.step(720)
    assert _world_momentum(box)[2] == pytest.approx(lz, rel=1e-10)
    assert min(abs(box.positions[0, 2] - h) for h in _BRICK) < 1e-3  # on a face
    assert np.abs(box.velocities[0]).max() < 1e-3


def test_inertia_is_about_each_bodys_own_axes():
    """`inertia` is the diagonal of the inertia tensor in the body's own axes. A capsule's axis
    is its x: a cylinder (mass m_c, half-length l) and two hemispheres (together m_s), each
    with its centroid 3r/8 from its flat side, so I_x = m_c r²/2 + 2 m_s r²/5 and
    I_y = I_z = m_c (3r² + 4l²)/12 + m_s (2r²/5 + l² + 3lr/4) by parallel axes (parry's
    frame put the axis on y, and the moments came as (I_y, I_x, I_z)); spun about x at ω its
    kinetic energy is ½ I_x ω². A hull's principal axes are its own affair: the hull of a box
    turned by φ about z reads cos²φ I_a + sin²φ I_b, sin²φ I_a + cos²φ I_b, I_c."""
    s = _scene(gravity=False)
    half, r, rho, w = 0.2, 0.1, 1000.0, 10.0
    cap = s.add(pc.Bodies("capsule", size=[(half, r)], positions=[(0.0, 0.0, 0.0)], angular_velocities=[(w, 0.0, 0.0)]))
    m_c, m_s = rho * math.pi * r * r * 2 * half, rho * 4 / 3 * math.pi * r**3
    axial = m_c * r * r / 2 + 0.4 * m_s * r * r
    across = m_c * (3 * r * r + 4 * half**2) / 12 + m_s * (0.4 * r * r + half**2 + 0.75 * half * r)
    assert cap.inertia[0] == pytest.approx([axial, across, across], rel=1e-12)
    assert s.energy().kinetic == pytest.approx(0.5 * axial * w * w, rel=1e-12)
    a, b, c = _BRICK
    phi = 0.5
    corners = np.array([(x, y, z) for x in (-a, a) for y in (-b, b) for z in (-c, c)])
    turn = np.array([[math.cos(phi), -math.sin(phi), 0.0], [math.sin(phi), math.cos(phi), 0.0], [0.0, 0.0, 1.0]])
    hull = s.add(pc.Bodies("hull", vertices=corners @ turn.T, positions=[(2.0, 0.0, 0.0)]))
    m = rho * 8 * a * b * c
    i_a, i_b, i_c = m / 3 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    co, si = math.cos(phi) ** 2, math.sin(phi) ** 2
    assert hull.inertia[0] == pytest.approx([co * i_a + si * i_b, si * i_a + co * i_b, i_c], rel=1e-9)


def test_a_group_without_positions_takes_its_dimension_from_its_velocities():
    """Without positions, 3-component velocities or angular velocities make a 3D group (they
    were read as a 2D one's and refused); widths that disagree are refused naming both."""
    s = _scene(gravity=False)
    spun = s.add(pc.Bodies("ball", size=0.1, angular_velocities=[(0.0, 0.0, 5.0)]))
    moving = s.add(pc.Bodies("ball", size=0.1, velocities=[(1.0, 0.0, 0.0)]))
    assert spun.dim == moving.dim == 3
    assert np.array_equal(spun.angular_velocities, [[0.0, 0.0, 5.0]])
    assert np.array_equal(moving.positions, [[0.0, 0.0, 0.0]]) and np.array_equal(moving.velocities, [[1.0, 0.0, 0.0]])
    assert pc.Bodies("ball", size=0.1, angular_velocities=(0.0, 0.0, 5.0)).dim == 3  # one vector for the group
    with pytest.raises(pc.InvalidInputError, match=r"angular_velocities: 3 components say a 3D group, but velocities says 2D"):
        pc.Bodies("ball", size=0.1, velocities=[(1.0, 0.0)], angular_velocities=[(0.0, 0.0, 1.0)])
    with pytest.raises(pc.InvalidInputError, match=r"velocities: 2 components say a 2D group, but orientations says 3D"):
        pc.Bodies("ball", size=0.1, orientations=[(0.0, 0.0, 0.0, 1.0)], velocities=[(1.0, 0.0)])
    # Three balls of the plane, one spin each: a 2D group still.
    flat = pc.Scene(dim=2).add(pc.Bodies("ball", size=[0.1, 0.2, 0.3], angular_velocities=[1.0, 2.0, 3.0]))
    assert flat.dim == 2 and np.array_equal(flat.angular_velocities, [1.0, 2.0, 3.0])


def test_orientations_set_and_read_back_normalised():
    s = _scene(gravity=False)
    g = s.add(pc.Bodies("box", size=(0.1, 0.2, 0.3), positions=[(0, 0, 0), (1, 0, 0)]))
    g.orientations = [(0.0, 0.0, 2.0, 0.0), (1.0, 1.0, 0.0, 0.0)]
    assert np.allclose(g.orientations, [(0, 0, 1, 0), (math.sqrt(0.5), math.sqrt(0.5), 0, 0)], rtol=0, atol=1e-15)
    with pytest.raises(pc.InvalidInputError, match="orientations"):
        g.orientations = [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)]
    assert g.orientations[1] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0, 0])  # unchanged
    with pytest.raises(pc.InvalidInputError, match="angles"):
        _ = g.angles


def test_a_particle_pinned_to_a_free_box_keeps_momentum_and_moves_with_it():
    """No gravity: a box moving at 1 m/s with a particle at rest pinned to its corner. The pin's
    impulses are equal and opposite: the total momentum is kept, and the particle stays on the
    corner."""
    s = _scene(gravity=False)
    box = s.add(pc.Bodies("box", size=(0.1, 0.1, 0.1), positions=[(0.0, 0.0, 0.0)], velocities=[(1.0, 0.0, 0.0)],
                          density=100.0))
    s.add_particles([[0.1, 0.1, 0.1]], masses=[0.05])
    s.add(pc.Pins([0], box[0]))
    p0 = float(box.masses[0]) * np.array([1.0, 0.0, 0.0])
    s.step(240)
    p1 = 0.05 * s.velocities[0] + box.masses[0] * box.velocities[0]
    assert np.allclose(p1, p0, rtol=0, atol=1e-12)
    assert np.linalg.norm(box.angular_velocities[0]) > 0  # pulled at the corner: it turns
    # Still on the corner, wherever the box has gone.
    x, q = box.positions[0], box.orientations[0]
    from scipy.spatial.transform import Rotation

    corner = x + Rotation.from_quat(q).apply([0.1, 0.1, 0.1])
    assert s.positions[0] == pytest.approx(corner, abs=1e-12)


def test_cloth_hung_from_a_kinematic_bar_is_carried_along():
    s = _scene()
    n = 6
    gx, gy = np.meshgrid(np.arange(n) * 0.1, np.arange(n) * 0.1)
    x = np.stack([gx.ravel(), np.zeros(n * n), -gy.ravel()], 1)
    s.add_particles(x, masses=0.01)
    i, j = pc.shapes.cloth_springs(n)
    s.add(pc.Springs(i, j, stiffness=200.0, damping=0.01))
    bar = s.add(pc.Bodies("box", size=(0.3, 0.02, 0.02), positions=[(0.25, 0.0, 0.0)], kind="kinematic",
                          velocities=[(0.5, 0.0, 0.0)]))
    s.add(pc.Pins(np.arange(n), bar[0]))
    s.step(240)
    assert s.positions[:n, 0] == pytest.approx(x[:n, 0] + 0.5, abs=1e-9)
    assert s.positions[n:, 0].mean() > x[n:, 0].mean() + 0.3  # the rest followed


@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"shape": "box", "positions": [(0, 0, 0)], "angles": 0.3}, "angles"),
        ({"shape": "box", "positions": [(0, 0, 0)], "orientations": [(0, 0, 0, 0)]}, "orientations"),
        ({"shape": "box", "size": [(0.1, 0.1, -0.1)]}, "size"),
        ({"shape": "hull", "vertices": [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]}, "vertices"),
        ({"shape": "mesh", "vertices": [(0, 0, 0), (1, 0, 0), (0, 1, 0)], "triangles": [(0, 1, 2)]}, "kind"),
        ({"shape": "mesh", "vertices": [(0, 0, 0), (1, 0, 0), (0, 1, 0)], "triangles": [(0, 1, 3)], "kind": "fixed"},
         "triangles"),
        ({"shape": "hull", "positions": [(0, 0)], "vertices": [(0, 0), (1, 0), (0, 1)]}, "shape"),
        ({"shape": "ball", "positions": [(0, 0, 0)], "angular_velocities": [1.0, 2.0]}, "angular_velocities"),
        # Ragged lists (issue 64's hostile run: numpy's bare ValueError, naming nothing).
        ({"shape": "ball", "positions": [(0, 0, 0), (1, 2)]}, "positions"),
        ({"shape": "ball", "positions": [(0, 0, 0), (1, 2, 3)], "velocities": [(0, 0, 0), (1,)]}, "velocities"),
        ({"shape": "ball", "positions": [(0, 0, 0)], "angular_velocities": [(0, 0), (1,)]}, "angular_velocities"),
    ],
)
def test_bad_bodies_are_refused_by_name(kwargs, arg):
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.Bodies(**kwargs)


def test_refused_joints_and_pins_change_nothing():
    s = _scene()
    g = s.add(pc.Bodies("ball", size=0.1, positions=[(0, 0, 0), (1, 0, 0)]))
    with pytest.raises(pc.InvalidInputError, match="kind"):
        pc.Joints("spherical", None, g[0], anchors=(0.0, 0.0))
    with pytest.raises(pc.InvalidInputError, match="anchors"):
        s.add(pc.Joints("revolute", None, g[0], anchors=(0.0, 0.0)))
    with pytest.raises(pc.InvalidInputError, match="axis"):
        s.add(pc.Joints("revolute", None, g[0], anchors=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 0.0)))
    with pytest.raises(pc.InvalidInputError, match="particles"):
        s.add(pc.Pins([0], g[0]))  # the scene has no particles
    with pytest.raises(pc.InvalidInputError, match="particles"):
        pc.Pins([0, 0], g[0])
    with pytest.raises(pc.InvalidInputError, match="body"):
        pc.Pins([0, 1, 2], g[[0, 1]])
    s2 = pc.Scene(dim=2)
    with pytest.raises(pc.InvalidInputError, match="3D"):
        s2.add(pc.Bodies("box", size=(0.1, 0.1, 0.1)))
    assert len(s.bodies) == 1 and not s2.bodies
    x0 = g.positions
    s.step(10)
    assert g.positions[0, 2] < x0[0, 2]  # still steps: the refusals left it whole


def test_a_grain_hitting_a_free_box_in_3d_keeps_momentum_and_a_grain_rests_on_a_box():
    s = _scene(gravity=False)
    box = s.add(pc.Bodies("box", size=(0.2, 0.2, 0.2), positions=[(0.0, 0.0, 0.0)], density=100.0))
    s.add_particles([[-1.0, 0.05, 0.08]], velocities=[[2.0, 0.0, 0.0]], masses=[0.5])
    s.set_attribute("radius", [0.02])
    p0 = 0.5 * np.array([2.0, 0.0, 0.0])
    s.step(240)
    p1 = 0.5 * s.velocities[0] + box.masses[0] * box.velocities[0]
    assert np.allclose(p1, p0, rtol=0, atol=1e-12)
    assert box.velocities[0, 0] > 0.03
    assert abs(box.angular_velocities[0, 1]) > 0 and abs(box.angular_velocities[0, 2]) > 0  # hit off-centre
    g = _scene()
    g.add(pc.Bodies("box", size=[(1.0, 1.0, 0.1)], positions=[(0.0, 0.0, -0.1)], kind="fixed"))
    g.add_particles([[0.1, 0.2, 0.5]], masses=[1.0])
    g.set_attribute("radius", [0.05])
    g.step(480)
    assert g.positions[0] == pytest.approx([0.1, 0.2, 0.05], abs=2e-3)


@pytest.mark.parametrize(("shape", "kwargs"), [("box", {"size": (0.1, 0.2, 0.3)}), ("ball", {"size": 0.1}),
                                                ("capsule", {"size": (0.2, 0.05)}),
                                                ("hull", {"vertices": [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]})])
def test_each_3d_shape_is_drawn_as_a_closed_surface_around_its_body(shape, kwargs):
    """What the renderer draws: each body's triangles close a surface (Euler: V − E + F = 2,
    every edge in two triangles) and reach as far as the shape does."""
    s = _scene(gravity=False)
    g = s.add(pc.Bodies(shape, positions=[(0.0, 0.0, 0.0)], **kwargs))
    (v, t), = g.meshes()
    assert v.shape[1] == 3 and t.shape[1] == 3 and t.max() < len(v)
    # Welded: the same corner may be listed twice by a shape's own mesh (a ball's seam).
    key = np.round(v, 9)
    _, weld = np.unique(key, axis=0, return_inverse=True)
    tri = weld.reshape(-1)[t]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    e, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()
    assert len(np.unique(tri)) - len(e) + len(t) == 2
    reach = {"box": np.linalg.norm([0.1, 0.2, 0.3]), "ball": 0.1, "capsule": 0.25, "hull": np.sqrt(3.0)}[shape]
    assert np.linalg.norm(v, axis=1).max() == pytest.approx(reach, rel=1e-9)
