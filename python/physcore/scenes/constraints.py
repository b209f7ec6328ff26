"""Constrained bodies: rigid boxes held by XPBD shape matching (shape_matched_boxes) and double
pendulums on stiff rods (double_pendulum)."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ..contacts import Contacts
from ..scene import Scene, _quiet_options
from ..terms import Gravity, Plane, Springs, XpbdConstraints
from ._common import SKY_2D, _count, _finite_books, _nonneg, _optional, _particle_mass, _particles, _positive, _stamped


def shape_matched_boxes(
    n_boxes: int = 6,
    *,
    particles_per_side: int = 4,
    size: float = 0.4,
    mass: float = 1.0,
    restitution: float = 0.3,
    friction: float = 0.8,
    substeps: int = 300,
    integrator: str = "xpbd",
    dt: float = 1 / 120,
    threads: int | None = None,
) -> Scene:
    """A leaning tower of rigid 2D boxes of particles, dropped spinning: it lands, topples and
    scatters across the floor.

    (Until issue 46 this was ``tumbling_boxes``, which is now made of rapier's rigid bodies:
    :func:`tumbling_boxes`.)

    Each of the ``n_boxes`` boxes is a square of ``particles_per_side``² particles, ``size`` m across and ``mass`` kg,
    held rigid by shape matching (:class:`XpbdConstraints` ``shapes``, stiffness 1); they start
    one above another (box b's centre 1 + 1.6 b sizes up, a little left or right of the
    column, at its own angle), spinning at 3 rad/s, alternately either way, and fall under
    gravity (0, -9.81) m/s² onto the floor y = 0 and onto each other. Their particles are grains
    (:class:`Contacts`, radius 0.45 of their spacing, so that the grains of one box never touch
    each other and those of two boxes cannot pass between them) with the floor as a contact
    wall, ``restitution`` and ``friction`` for every contact. The contacts' stiffness is set
    so that a contact lasts 60 substeps; the grains do not spin on their own (their moment of
    inertia is made huge: a grain glued into a rigid box turns with it, not about itself, and a
    free spin would let a box roll on its grains as on ball bearings). Integrator ``"xpbd"``
    with ``substeps`` per step of ``dt`` s: contacts and gravity act in every substep, then the
    shapes are projected (another ``integrator`` leaves the shapes inert: the particles fall
    apart; then the floor is a :class:`Plane` collider and the boxes pass through each other).
    The contacts close their books at each substep's predicted state, before the projections,
    whose work the shapes book: the books balance to 7.9e-5 of the energy over 2 s at the
    defaults (3.5e-5 for the five boxes of the defaults before issue 65; closing them after the
    projections mixed the two: 2.6e-2).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n_boxes = _count(n_boxes, "n_boxes", 1)
    k = _count(particles_per_side, "particles_per_side", 2)
    _particles("n_boxes, particles_per_side", n_boxes * k * k, 1)
    size, mass = _positive(size, "size"), _positive(mass, "mass")
    restitution = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    if restitution == 0.0:
        raise InvalidInputError("restitution: must be > 0 (a dashpot cannot stop a box dead)")
    friction = _nonneg(friction, "friction")
    substeps = _check.int_in_range("substeps", substeps, 1, 100_000)
    dt = _positive(dt, "dt")
    if not math.isfinite(4.0 * size * n_boxes):
        raise InvalidInputError(f"size: {n_boxes} boxes of {size:g} m do not fit float64")
    if size / (k - 1) < 1e-100:  # the particles' spacing must survive squaring (shape matching)
        raise InvalidInputError(f"size: {size:.3g} m over {k} particles a side is below float64's usable range")
    m = _particle_mass(mass / (k * k), "mass, particles_per_side")
    spacing = size / (k - 1)
    g = (np.arange(k) / (k - 1) - 0.5) * size
    gx, gy = np.meshgrid(g, g)
    local = np.stack([gx.ravel(), gy.ravel()], axis=1)
    xs, vs, shapes = [], [], []
    for b in range(n_boxes):
        # A wobbly column (1.6 sizes apart: clear of each other at any angle, corners included).
        th = 0.2 + 0.7 * b
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        centre = np.array([0.4 * size * math.sin(2.4 * b), size + 1.6 * size * b])
        omega = 3.0 * (-1) ** b
        r = local @ rot.T
        xs.append(centre + r)
        vs.append(omega * np.stack([-r[:, 1], r[:, 0]], axis=1))
        shapes.append(np.arange(b * k * k, (b + 1) * k * k))
    with _quiet_options():  # the scene's option is kept whatever the integrator
        scene = Scene(2, integrator=integrator, dt=dt, threads=threads, xpbd_substeps=substeps)
    scene.add_particles(np.concatenate(xs), np.concatenate(vs), masses=m)
    scene.set_attribute("radius", np.full(n_boxes * k * k, 0.45 * spacing))
    scene.add(Gravity([0.0, -9.81]))
    scene.add(XpbdConstraints(shapes=shapes, name="boxes"))
    # A contact of two grains (m* = m/2) lasts π√(m*/k) = 60 substeps.
    h = dt / substeps if integrator == "xpbd" else dt
    w = math.pi / (60.0 * h) if h > 0.0 else math.inf
    stiffness = 0.5 * m * w * w if w < 1e150 else math.inf  # (** would raise OverflowError)
    if not (math.isfinite(stiffness) and stiffness > 0.0):
        raise InvalidInputError(f"mass, dt, substeps: give a contact stiffness (m·w²/2) out of float64's range ({stiffness})")
    # Each box its own colour (tab10's), drawn whole (the hull of its grains, not k² dots), so
    # the boxes read as objects, before a sky-grey backdrop over the floor.
    scene.render_defaults = {  # plain lists: render_defaults compare with ==
        "colors": np.repeat(np.arange(n_boxes), k * k).tolist(),
        "look": {"hulls": [list(range(b * k * k, (b + 1) * k * k)) for b in range(n_boxes)],
                 "backdrop": SKY_2D},
    }
    if integrator in ("xpbd", "semi_implicit_euler"):
        # tangential_ratio 2/7 (the default before it became 1/3 for discs): the grains of a box do
        # not turn (inertia_factor 1e6), so no ratio equalises their periods, and the boxes'
        # landings were tuned at 2/7 (at 1/3, a box dropped on another in tests/constraints/test_xpbd.py
        # slides off it).
        scene.add(Contacts(stiffness=stiffness, restitution=restitution, friction=friction, inertia_factor=1e6,
                           tangential_ratio=2.0 / 7.0,
                           walls=[Plane([0.0, 0.0], [0.0, 1.0], restitution=restitution, friction=friction)]))
    else:
        scene.add(Plane([0.0, 0.0], [0.0, 1.0], restitution=restitution, friction=friction))
    return _finite_books(scene, "size, mass")


# From 0.6 s (lead_in: the tower already falling, its lowest box landing, so the first frame
# shows the collapse under way rather than a still column) to 3.47 s: the boxes topple and
# scatter into a heap; the last one stops sliding at about 3.2 s, and the GIF ends a moment
# after it comes to rest. The camera fits what moves from then on, a landscape frame over the
# heap, so the boxes fill a good part of it.
shape_matched_boxes.render_defaults = {"frames": 87, "fps": 30, "frame_time": 1 / 30, "lead_in": 0.6, "size": (400, 360),
                                 "size_by": "radius", "color_by": "none", "antialias": True}
shape_matched_boxes = _stamped(shape_matched_boxes)


def double_pendulum(
    *,
    n: int = 100,
    angles: tuple[float, float] = (2.2, 2.2),
    spread: float = 1e-6,
    length: float = 1.0,
    mass: float = 1.0,
    stiffness: float | None = None,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """A fan of double pendulums started almost alike: chaos pulls them apart.

    2D, gravity (0, −9.81) m/s². `n` double pendulums hang from one pivot at the origin (a
    pinned particle), each of two bobs of `mass` (kg) on two rods of `length` (m), released at
    rest at angles ``angles = (θ1, θ2)`` (rad, from the downward vertical: the upper rod's and
    the lower rod's), pendulum k with θ2 + k·`spread`. Until the spread has grown by about
    e^(λt) to a visible angle they move as one; then they fan out into a rainbow (the largest
    Lyapunov exponent of this start is of order 1/s, so 1e-6 rad becomes a radian in ~15 s).

    The rods are stiff springs: `stiffness` (N/m) defaults to 2·10⁵ m g / length, so the
    largest tension of a swing (about 15 m g) stretches a rod by under 0.1 %, and the motion
    is the rigid double pendulum's to that order. For small angles its normal modes are
    ω² = (g/l)(2 ∓ √2) with θ2/θ1 = ±√2 (equal masses and lengths; e.g. Goldstein, Classical
    Mechanics, 3rd ed., §6.4; Landau & Lifshitz, Mechanics, §23, problem 1), which the tests
    check. Velocity Verlet; ``dt=None`` takes 0.2/ω_rod, ω_rod = √(2 stiffness/mass), so the
    energy error is bounded and second order.

    Returns
    -------
    Scene
        Particle 0 is the pivot; pendulum k's upper and lower bobs are 1 + 2k and 2 + 2k.

    Raises
    ------
    TypeError, InvalidInputError
        As every scene function (module docstring), naming the argument.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.double_pendulum(n=3)
    >>> scene.n_particles
    7
    """
    n = _check.int_in_range("n", n, 1, 100_000)
    _particles("n", 2 * n + 1, 2 * n)
    a1, a2 = _pair_any(angles, "angles")
    spread = _nonneg(spread, "spread")
    if not spread * n < 1e6:  # angles far beyond a turn only lose precision in sin and cos
        raise InvalidInputError(f"spread: the fan spans spread · n = {spread * n:.3g} rad; give at most 1e6 rad in all")
    length, mass = _positive(length, "length"), _positive(mass, "mass")
    if not (length >= 1e-100 and length <= 1e100 and mass >= 1e-100 and mass <= 1e100):
        raise InvalidInputError("length, mass: must lie in [1e-100, 1e100] (m, kg)")
    k = 2e5 * mass * 9.81 / length if stiffness is None else _positive(stiffness, "stiffness")
    dt = _optional(dt, "dt")
    with np.errstate(over="ignore", divide="ignore"):
        step = 0.2 / math.sqrt(2 * k / mass) if math.isfinite(2 * k / mass) else 0.0
    if dt is None and not _check.MIN_NORMAL <= step < math.inf:
        raise InvalidInputError(f"stiffness, mass: the step 0.2/√(2 k/m) = {step:.3g} s is outside float64's normal range; give a dt")
    th1 = np.full(n, a1)
    th2 = a2 + spread * np.arange(n)
    p1 = length * np.stack([np.sin(th1), -np.cos(th1)], axis=1)
    p2 = p1 + length * np.stack([np.sin(th2), -np.cos(th2)], axis=1)
    x = np.concatenate([np.zeros((1, 2)), np.stack([p1, p2], axis=1).reshape(-1, 2)])
    pinned = np.zeros(2 * n + 1, dtype=bool)
    pinned[0] = True
    upper = 1 + 2 * np.arange(n)
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=mass, pinned=pinned)
    scene.add(Springs(np.concatenate([np.zeros(n, dtype=np.int64), upper]), np.concatenate([upper, upper + 1]),
                      stiffness=k, rest_length=length))
    scene.add(Gravity([0.0, -9.81]))
    # Each pendulum its own hue (rods and bobs), around the colour wheel; the pivot a grey mark.
    hue = np.arange(n) / max(n, 1)
    rgb = np.clip(np.stack([np.abs(hue * 6 - 3) - 1, 2 - np.abs(hue * 6 - 2), 2 - np.abs(hue * 6 - 4)], axis=1), 0, 1)
    rgb = 0.25 + 0.75 * rgb  # pastel enough to glow on the night background
    colors = np.concatenate([[[0.6, 0.6, 0.65]], np.repeat(rgb, 2, axis=0)])
    scene.render_defaults = {"colors": np.rint(colors * 255).astype(np.uint8).tolist()}  # plain lists: compared with ==
    return _finite_books(scene, "length, mass")


def _pair_any(value: object, arg: str) -> tuple[float, float]:
    """A pair of finite floats (any sign), naming `arg`."""
    # (A 0-d array has no len(): it is refused here too, by name.)
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list, np.ndarray)) or np.ndim(value) != 1 or len(value) != 2:
        raise InvalidTypeError(f"{arg}: expected a pair of numbers, got {type(value).__name__} of shape {np.shape(value)}")
    out = tuple(_check.finite(arg, v) for v in value)
    return out[0], out[1]


# 7.5 s at 30 fps, one simulated second a second, from t = 3 s: together for 2.5 s, then the
# fan (from t = 0 the GIF showed one pendulum for 55 % of its 10 s, a panel's "don't post").
double_pendulum.render_defaults = {"antialias": True, "frames": 225, "fps": 30, "frame_time": 1 / 30, "lead_in": 3.0,
                                   "size": (400, 400), "color_by": "none", "theme": "dark", "radius": 3}
double_pendulum = _stamped(double_pendulum)
