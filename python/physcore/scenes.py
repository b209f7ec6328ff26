"""Ready-made scenes: functions returning a :class:`~physcore.Scene`. Each is also a CLI name
(``physcore render NAME``); keyword arguments are CLI ``--param key=value`` options.

Every function accepts ``integrator=`` and ``dt=`` (``None``: the scene's own choice) and
``threads=``. ``render_defaults`` on each function gives the CLI's animation defaults
(``frame_time`` is simulated seconds per frame).

Every function raises, before building anything, ``TypeError`` for an argument of the wrong type
(``str``, ``bool`` or ``None`` where a number is meant, anything but True/False for a flag) and
:class:`~physcore.InvalidInputError` (a ``ValueError``) for a value out of range or one whose
consequences float64 cannot hold: a particle mass whose reciprocal overflows, a spacing or
stable time step below the normal range, energy books beyond float64, or more particles than
fit in memory (about 512 B each and 256 B per spring, against half the physical memory). The
message names the arguments involved.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from . import _check, _deprecate
from ._errors import InvalidInputError, InvalidTypeError
from .contacts import Contacts
from .fluids import SPACING_RANGE, lattice, lattice_counts, tank_walls
from .render._mesh import Mesh
from .scene import Scene
from .terms import (
    Box,
    Drag,
    ElectricField,
    Gravity,
    MagneticField,
    PairwiseGravity,
    Plane,
    Sphere,
    Springs,
    TreeGravity,
    XpbdConstraints,
)

__all__ = ["cloth", "projectile", "kepler", "spring_chain", "dam_break", "drop", "droplets", "crown", "figure_eight", "pythagorean", "galaxies", "cyclotron", "lorenz", "plummer_sphere", "galton_board", "galton_bins", "billiards", "newtons_cradle", "jelly", "xpbd_cloth", "tumbling_boxes", "cloth_on_ball", "REGISTRY"]


# Argument checks: the shared ones of physcore._check (TypeError for bool/str/None, names the
# argument), plus checks of what the scene derives from them, naming the arguments involved.
def _positive(value: object, arg: str) -> float:
    return _check.positive_float(arg, value)


def _nonneg(value: object, arg: str) -> float:
    return _check.nonneg_float(arg, value)


def _count(value: object, arg: str, minimum: int) -> int:
    return _check.int_in_range(arg, value, minimum)


def _flag(value: object, arg: str) -> bool:
    return _check.flag(arg, value)


def _dim(dim: object) -> int:
    if isinstance(dim, (bool, np.bool_)) or not isinstance(dim, (int, np.integer)):
        raise InvalidTypeError(f"dim: expected 2 or 3, got {type(dim).__name__}")
    if dim not in (2, 3):
        raise InvalidInputError(f"dim: must be 2 or 3, got {dim}")
    return int(dim)


def _optional(value: object, arg: str) -> float | None:
    """None, or a finite number > 0."""
    return None if value is None else _check.positive_float(arg, value)


def _particle_mass(value: float, args: str) -> float:
    """A per-particle mass derived from ``args``; refused by their names if 1/m would overflow."""
    if not (math.isfinite(value) and value >= _check.MIN_MASS):
        raise InvalidInputError(
            f"{args}: give each particle a mass of {value:.3g} kg, outside float64's usable range "
            f"[{_check.MIN_MASS:.3g} kg, max] (its reciprocal must be finite)"
        )
    return value


def _particles(args: str, n_particles: float, n_springs: float = 0) -> None:
    """Refuse, naming ``args``, a scene too large for memory (estimated before allocating)."""
    _check.memory(
        args,
        n_particles * _check.PARTICLE_BYTES + n_springs * _check.SPRING_BYTES,
        f"{_big(n_particles)} particles" + (f" and {_big(n_springs)} springs" if n_springs else ""),
    )


def _cfl_step(wave: Any, arg: str) -> float:
    """The wave's automatic step, or an error naming `arg` if it is not a usable float step."""
    dt = wave.cfl * wave.cfl_limit
    if not (math.isfinite(dt) and dt >= 1e-300):
        raise InvalidInputError(f"{arg}: the CFL step dx/(c√2) = {dt:.3g} s is beyond float64's usable range")
    return dt


def _cells(args: str, cells: float, arrays: int = 6) -> None:
    """Refuse, naming ``args``, a grid too large for memory (`arrays` float64 values per cell:
    state, scratch and a rollback copy)."""
    _check.memory(args, cells * 8 * arrays, f"{_big(cells)} grid cells")


def _big(count: float) -> str:
    if count < 1e15:
        return str(count)
    if isinstance(count, int):  # may be beyond float64: give its order of magnitude
        return f"about 1e{int(count.bit_length() * math.log10(2))}"
    return f"{count:.3g}"


def _per(total: float, count: int) -> float:
    """``total / count`` for a count that may be beyond float64 (then 0.0)."""
    try:
        return total / count
    except OverflowError:
        return 0.0


def _set_stable_dt(scene: Scene, factor: float, args: str) -> None:
    """``scene.dt = factor · scene.suggest_dt()``, refused by ``args`` outside float64's normal range."""
    dt = factor * scene.suggest_dt()
    if not (math.isfinite(dt) and dt >= _check.MIN_NORMAL):
        raise InvalidInputError(
            f"{args}: the stable time step for these values, {dt:.3g} s, is outside float64's normal range; "
            "change them or give dt="
        )
    scene.dt = dt


def _finite_books(scene: Scene, args: str) -> Scene:
    """The scene, once its energy books are finite; else refused naming ``args``."""
    e = scene.energy()
    if not math.isfinite(e.total) or not math.isfinite(e.kinetic):
        raise InvalidInputError(
            f"{args}: the scene's energy (kinetic {e.kinetic:.3g} J, total {e.total:.3g} J) is beyond float64"
        )
    return scene


def cloth_springs(n: int):
    """Structural, shear and bend spring index pairs of an n×n grid (index = row·n + col).

    Returns ``(i, j)`` int64 arrays, each spring once: structural (±1 along a row or column),
    shear (both diagonals), bend (±2 along a row or column).
    """
    idx = np.arange(n * n).reshape(n, n)  # [row j, col i]
    pairs = [
        (idx[:, :-1], idx[:, 1:]),  # structural, along x
        (idx[:-1, :], idx[1:, :]),  # structural, along y
        (idx[:-1, :-1], idx[1:, 1:]),  # shear
        (idx[:-1, 1:], idx[1:, :-1]),  # shear, other diagonal
        (idx[:, :-2], idx[:, 2:]),  # bend, along x
        (idx[:-2, :], idx[2:, :]),  # bend, along y
    ]
    i = np.concatenate([a.ravel() for a, _ in pairs])
    j = np.concatenate([b.ravel() for _, b in pairs])
    return i.astype(np.int64), j.astype(np.int64)


def cloth(
    n: int = 40,
    *,
    size: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.1,
    air_drag: float = 0.5,
    pin: str = "edge",
    ground: bool = False,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Hanging cloth: an n×n mass-spring sheet, one edge pinned, falling and swinging under gravity.

    The sheet starts flat in the z = 0 plane (x, y in [0, size]); the row y = 0 is pinned
    (``pin="edge"``) or only its two corners (``pin="corners"``). Structural, shear and bend
    springs (stiffness N/m, dashpot damping N·s/m) join neighbours; gravity is (0, 0, -9.81) m/s²;
    linear air drag b = air_drag · m per particle (air_drag in 1/s; 0 turns it off).
    ``ground=True`` adds a floor at z = -0.8·size (restitution 0.1, friction 0.5). ``dt=None``
    uses twice :meth:`Scene.suggest_dt` (1/ω_max here), half of velocity Verlet's stability limit.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    _particles("n", n * n, 6 * n * n)
    size, mass, stiffness = _positive(size, "size"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    damping, air_drag = _nonneg(damping, "damping"), _nonneg(air_drag, "air_drag")
    pin = _check.choice("pin", pin, ("edge", "corners"))
    ground = _flag(ground, "ground")
    dt = _optional(dt, "dt")
    s = size / (n - 1)
    # Bend springs span 2 s and their lengths come from squared lengths: (2 s)², with a margin.
    if not (s >= _check.MIN_NORMAL and math.isfinite(8 * s * s)):
        raise InvalidInputError(f"size: a grid spacing of size/(n - 1) = {s:.3g} m is outside float64's usable range")
    m = _particle_mass(mass / (n * n), "mass, n")
    b = air_drag * mass / (n * n)
    if not math.isfinite(b):
        raise InvalidInputError(f"air_drag: the drag coefficient air_drag · m = {b} kg/s overflows float64")
    gx, gy = np.meshgrid(np.arange(n) * s, np.arange(n) * s)
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], axis=1)
    pinned = np.zeros(n * n, dtype=bool)
    if pin == "edge":
        pinned[:n] = True
    else:
        pinned[[0, n - 1]] = True
    scene = Scene(3, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=m, pinned=pinned)
    i, j = cloth_springs(n)
    scene.add(Springs(i, j, stiffness=stiffness, damping=damping))
    scene.add(Gravity([0.0, 0.0, -9.81]))
    if air_drag:
        scene.add(Drag(b))
    if ground:
        scene.add(Plane([0.0, 0.0, -0.8 * size], [0.0, 0.0, 1.0], restitution=0.1, friction=0.5))
    if dt is None:
        # suggest_dt() is half the fastest time scale (1/ω_max or the dashpot's 1/λ_max); twice
        # that is still well inside velocity Verlet's limits (2/ω_max; 2/λ_max with dashpots).
        _set_stable_dt(scene, 2.0, "stiffness, damping, air_drag, mass")
    # Drawn as a shaded sheet over its grid (render.Mesh.grid: rows of n, index row·n + col).
    scene.render_defaults = {"mesh": Mesh.grid(n, n)}
    return _finite_books(scene, "size, mass")


# A plain fabric colour: the shading is the picture (--color-by speed or strain colours the sheet).
cloth.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none"}


def cloth_on_ball(
    n: int = 36,
    *,
    size: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.1,
    air_drag: float = 0.3,
    radius: float = 0.3,
    offset: float = 0.12,
    height: float = 0.25,
    friction: float = 0.3,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Cloth on a ball: an n×n mass-spring sheet dropped flat onto a ball, draping over it and
    sliding off onto the floor.

    The sheet (the springs, masses and air drag of :func:`cloth`, nothing pinned) starts at rest
    and flat, centred over the origin at z = 2·radius + height (m). The ball, a :class:`Sphere`
    collider of `radius` m (restitution 0.1, Coulomb `friction`), rests on the floor z = 0
    (restitution 0.1, friction 0.5) with its centre `offset` m along x: off-centre, the heavier
    side of the sheet pulls it off. Gravity is (0, 0, -9.81) m/s²; ``dt=None`` uses twice
    :meth:`Scene.suggest_dt`, as :func:`cloth` does.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    _particles("n", n * n, 6 * n * n)
    size, mass, stiffness = _positive(size, "size"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    damping, air_drag = _nonneg(damping, "damping"), _nonneg(air_drag, "air_drag")
    radius, height, friction = _positive(radius, "radius"), _nonneg(height, "height"), _nonneg(friction, "friction")
    offset = _check.real("offset", offset)
    if not math.isfinite(offset):
        raise InvalidInputError(f"offset: must be finite, got {offset}")
    dt = _optional(dt, "dt")
    s = size / (n - 1)
    if not (s >= _check.MIN_NORMAL and math.isfinite(8 * s * s)):
        raise InvalidInputError(f"size: a grid spacing of size/(n - 1) = {s:.3g} m is outside float64's usable range")
    top = 2.0 * radius + height
    if not math.isfinite(top * top + size * size + offset * offset):
        raise InvalidInputError(f"radius, height, size, offset: a scene {top:.3g} m high does not fit float64")
    m = _particle_mass(mass / (n * n), "mass, n")
    b = air_drag * mass / (n * n)
    if not math.isfinite(b):
        raise InvalidInputError(f"air_drag: the drag coefficient air_drag · m = {b} kg/s overflows float64")
    gx, gy = np.meshgrid(np.arange(n) * s - 0.5 * size, np.arange(n) * s - 0.5 * size)
    x = np.stack([gx.ravel(), gy.ravel(), np.full(n * n, top)], axis=1)
    scene = Scene(3, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=m)
    i, j = cloth_springs(n)
    scene.add(Springs(i, j, stiffness=stiffness, damping=damping))
    scene.add(Gravity([0.0, 0.0, -9.81]))
    if air_drag:
        scene.add(Drag(b))
    # The floor before the ball: a saved scene reloads planes before spheres, in this order.
    scene.add(Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], restitution=0.1, friction=0.5))
    scene.add(Sphere([offset, 0.0, radius], radius, restitution=0.1, friction=friction))
    if dt is None:
        _set_stable_dt(scene, 2.0, "stiffness, damping, air_drag, mass")
    scene.render_defaults = {"mesh": Mesh.grid(n, n)}
    return _finite_books(scene, "size, mass")


cloth_on_ball.render_defaults = {"frames": 69, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none",
                                 "view": (-60.0, 25.0)}


def mesh_edges_and_hinges(faces: np.typing.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Edges and bending hinges of a triangle mesh, for :class:`XpbdConstraints`.

    Returns ``(edges, hinges)``: ``edges`` (E, 2) int64, every edge once; ``hinges`` (H, 4)
    int64, one row ``(a, b, c, d)`` per edge shared by two triangles ``(a, b, c)`` and
    ``(b, a, d)`` (the ``bending`` rows of a 3D scene). Edges of more than two triangles get no
    hinge.
    """
    f = np.asarray(faces, dtype=np.int64)
    owner: dict[tuple[int, int], list[int]] = {}
    for a, b, c in f.tolist():
        for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
            owner.setdefault((min(u, v), max(u, v)), []).append(w)
    edges = np.array(sorted(owner), dtype=np.int64).reshape(-1, 2)
    hinges = [(a, b, w[0], w[1]) for (a, b), w in sorted(owner.items()) if len(w) == 2]
    return edges, np.array(hinges, dtype=np.int64).reshape(-1, 4)


def xpbd_cloth(
    n: int = 32,
    *,
    size: float = 1.0,
    mass: float = 1.0,
    compliance: float = 5e-4,
    bending_compliance: float = 5.0,
    air_drag: float = 0.2,
    pin: str = "corners",
    substeps: int = 20,
    integrator: str = "xpbd",
    dt: float = 1 / 60,
    threads: int | None = None,
) -> Scene:
    """Hanging cloth by XPBD: an n×n sheet of distance and bending constraints, pinned, falling.

    The sheet starts flat in the z = 0 plane (x, y in [0, size]), pinned at the two corners of the
    row y = 0 (``pin="corners"``) or along that row (``"edge"``), like :func:`cloth`. Its grid is
    cut into triangles (:meth:`render.Mesh.grid`); every triangle edge is a distance constraint of
    ``compliance`` (m/N; 5e-4 is :func:`cloth`'s 2000 N/m) and every interior edge a dihedral bending constraint of
    ``bending_compliance`` (rad²/J), both at the flat sheet's rest values. Gravity (0, 0, -9.81)
    m/s², linear air drag ``air_drag · m`` per particle (1/s). Integrator ``"xpbd"`` with
    ``substeps`` substeps of one iteration per step of ``dt`` (s): unconditionally stable, so one
    step per 60 Hz frame. Another ``integrator`` leaves the constraints inert (the sheet falls
    freely).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    _particles("n", n * n, 6 * n * n)
    size, mass = _positive(size, "size"), _positive(mass, "mass")
    compliance, bending_compliance = _nonneg(compliance, "compliance"), _nonneg(bending_compliance, "bending_compliance")
    air_drag = _nonneg(air_drag, "air_drag")
    pin = _check.choice("pin", pin, ("edge", "corners"))
    substeps = _check.int_in_range("substeps", substeps, 1, 100_000)
    dt = _positive(dt, "dt")
    if not math.isfinite(air_drag * mass):
        raise InvalidInputError(f"air_drag: the drag coefficient air_drag · m = {air_drag * mass} kg/s overflows float64")
    s = size / (n - 1)
    # The dihedral bending angles take products of five spacings ((n1 × n2)·e): they must stay
    # normal floats (size = 1e-300 made every rest angle NaN, refused under the wrong name).
    if not 1e-60 <= s <= 1e60:
        raise InvalidInputError(f"size: a grid spacing of size/(n - 1) = {s:.3g} m is outside 1e-60 to 1e60 m (bending angles take its fifth power)")
    m = _particle_mass(mass / (n * n), "mass, n")
    gx, gy = np.meshgrid(np.arange(n) * s, np.arange(n) * s)
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], axis=1)
    pinned = np.zeros(n * n, dtype=bool)
    if pin == "edge":
        pinned[:n] = True
    else:
        pinned[[0, n - 1]] = True
    scene = Scene(3, integrator=integrator, dt=dt, threads=threads, xpbd_substeps=substeps)
    scene.add_particles(x, masses=m, pinned=pinned)
    mesh = Mesh.grid(n, n)
    edges, hinges = mesh_edges_and_hinges(mesh.faces)
    scene.add(Gravity([0.0, 0.0, -9.81]))
    if air_drag:
        scene.add(Drag(air_drag * mass / (n * n)))
    scene.add(
        XpbdConstraints(
            distance=edges, distance_compliance=compliance, bending=hinges, bending_compliance=bending_compliance, name="cloth"
        )
    )
    scene.render_defaults = {"mesh": mesh}
    return _finite_books(scene, "size, mass")


xpbd_cloth.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none"}


def tumbling_boxes(
    n_boxes: int = 5,
    *,
    particles_per_side: int = 4,
    size: float = 0.4,
    mass: float = 1.0,
    restitution: float = 0.3,
    friction: float = 0.5,
    substeps: int = 300,
    integrator: str = "xpbd",
    dt: float = 1 / 120,
    threads: int | None = None,
) -> Scene:
    """Rigid 2D boxes of particles dropped, spinning, onto a floor and onto each other.

    Each of the ``n_boxes`` boxes is a square of ``particles_per_side``² particles, ``size`` m across and ``mass`` kg,
    held rigid by shape matching (:class:`XpbdConstraints` ``shapes``, stiffness 1); they start
    side by side at different heights and angles, spinning, and fall under gravity (0, -9.81)
    m/s² onto the floor y = 0 and onto each other. Their particles are grains
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
    whose work the shapes book: the books balance to 3.5e-5 of the energy over 2 s at the
    defaults (closing them after the projections mixed the two: 2.6e-2).

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
        th = 0.35 + 0.6 * b
        rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        centre = np.array([1.2 * size * b, 1.5 * size + 1.3 * size * b])
        omega = 4.0 * (-1) ** b
        r = local @ rot.T
        xs.append(centre + r)
        vs.append(omega * np.stack([-r[:, 1], r[:, 0]], axis=1) + np.array([0.3 * (1 - b), 0.0]))
        shapes.append(np.arange(b * k * k, (b + 1) * k * k))
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
    # Each box its own colour (tab10's), so the boxes read as objects.
    scene.render_defaults = {"colors": np.repeat(np.arange(n_boxes), k * k).tolist()}  # plain lists: render_defaults compare with ==
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


# 3 s: five boxes fall, tumble over each other and come to rest at about 2.7 s.
tumbling_boxes.render_defaults = {"frames": 90, "fps": 30, "frame_time": 1 / 30, "size": (480, 360),
                                 "size_by": "radius", "color_by": "none", "antialias": True}


def projectile(
    n: int = 7,
    *,
    speed: float = 20.0,
    drag: float = 0.0,
    restitution: float = 0.6,
    ground: bool = True,
    integrator: str = "verlet",
    dt: float | None = 1e-3,
    threads: int | None = None,
) -> Scene:
    """Projectiles: n balls (1 kg) launched from the origin at angles from 20° to 70°, bouncing.

    2D, gravity (0, -9.81) m/s², optional linear drag (kg/s), a ground plane y = 0 with the given
    restitution and friction 0.2. Without drag and ground the closed form is
    x = v0 cos θ t, y = v0 sin θ t - g t²/2. The render gives each ball its own colour (the
    "tab10" group colours, by launch angle from the lowest).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring), e.g.
    for a speed whose kinetic energy overflows float64.
    """
    n = _count(n, "n", 1)
    _particles("n", n)
    speed = _positive(speed, "speed")
    drag = _nonneg(drag, "drag")
    restitution = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    ground = _flag(ground, "ground")
    if not math.isfinite(0.5 * speed * speed * n):
        raise InvalidInputError(f"speed: the kinetic energy n · ½ (1 kg) speed² of {speed:.3g} m/s overflows float64")
    angles = np.radians(np.linspace(20.0, 70.0, n)) if n > 1 else np.radians([45.0])
    v = speed * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    scene = Scene(2, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(np.zeros((n, 2)), v, masses=1.0)
    scene.add(Gravity([0.0, -9.81]))
    if drag:
        scene.add(Drag(drag))
    if ground:
        scene.add(Plane([0.0, 0.0], [0.0, 1.0], restitution=restitution, friction=0.2))
    scene.render_defaults = {"colors": list(range(n))}  # one colour per ball: the angles read apart
    return _finite_books(scene, "speed")


# 4 s: the flights (up to 3.9 s at 70°) and the first bounces; the whole paths stay drawn. Wide:
# the 45° range (40.8 m) is 2.2 times the 70° apex (18.0 m).
projectile.render_defaults = {"antialias": True, "frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (560, 300), "trail": 120,
                              "radius": 8, "color_by": "none"}


#: Range of a Kepler orbit's separations a(1 ∓ e), m: keeps r², 1/r³ and v² = GM/r inside float64.
KEPLER_RANGE = (1e-100, 1e100)

#: ``kepler``: colours of the star (warm yellow-white) and the planet (blue), RGB.
KEPLER_COLORS = ((255, 214, 120), (100, 175, 255))


def kepler(
    e: float = 0.5,
    *,
    a: float = 1.0,
    mass_ratio: float = 1e-3,
    steps_per_orbit: int = 1000,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Kepler orbit: two bodies under Newtonian gravity (G = 1, total mass 1), eccentricity e.

    The relative orbit has semi-major axis a and starts at pericentre r = a(1 - e) with speed
    sqrt(G M (1 + e) / (a (1 - e))); bodies are placed in the centre-of-mass frame. Period
    P = 2π sqrt(a³ / (G M)); total energy -G m1 m2 / (2a). ``mass_ratio = 0`` pins a unit-mass
    star at the origin and makes the planet (mass 1) a test particle: then E = -1/(2a) exactly.
    ``dt=None`` uses P / steps_per_orbit. Particle 0 is the star, 1 the planet; the render
    draws them in their own colours (:data:`KEPLER_COLORS`: warm yellow, blue).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring); the
    separations a(1 - e) and a(1 + e) must lie in :data:`KEPLER_RANGE` (1e-100 to 1e100 m) so
    that r², 1/r³ and v² stay inside float64, and both masses must be usable (mass_ratio 0 or
    in about [2.2e-308, 4.5e307]).
    """
    e = _check.float_in_range("e", e, 0.0, 1.0, hi_open=True)
    a = _positive(a, "a")
    lo, hi = KEPLER_RANGE
    if not (a * (1 - e) >= lo and a * (1 + e) <= hi):
        raise InvalidInputError(
            f"a: the separations a(1 - e) = {a * (1 - e):.3g} m to a(1 + e) = {a * (1 + e):.3g} m must lie in "
            f"[{lo:g}, {hi:g}] m (so that r², 1/r³ and v² stay inside float64); check a and e"
        )
    q = _nonneg(mass_ratio, "mass_ratio")
    if q > 0:
        _particle_mass(min(1 / (1 + q), q / (1 + q)), "mass_ratio")
    steps_per_orbit = _count(steps_per_orbit, "steps_per_orbit", 1)
    period = 2 * math.pi * math.sqrt(a**3)
    # Ints beyond 2**1000 would overflow the conversion to float; any such step is 0 anyway.
    step = period / steps_per_orbit if steps_per_orbit <= 2**1000 else 0.0
    if dt is None and not step >= _check.MIN_NORMAL:
        raise InvalidInputError(
            f"steps_per_orbit: the step P / steps_per_orbit = {step:.3g} s is below float64's normal range (P = {period:.3g} s)"
        )
    rp = a * (1 - e)
    vp = math.sqrt((1 + e) / (a * (1 - e)))
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    if q == 0:
        scene.add_particles([[0.0, 0.0], [rp, 0.0]], [[0.0, 0.0], [0.0, vp]], masses=[1.0, 1.0], pinned=[True, False])
    else:
        m1, m2 = 1 / (1 + q), q / (1 + q)
        x = np.array([[-m2 * rp, 0.0], [m1 * rp, 0.0]])
        v = np.array([[0.0, -m2 * vp], [0.0, m1 * vp]])
        scene.add_particles(x, v, masses=[m1, m2])
    scene.add(PairwiseGravity(G=1.0))
    # Plain lists: render_defaults compare with ==. The star (particle 0) glows.
    scene.render_defaults = {"colors": list(KEPLER_COLORS), "halo": [0]}
    return scene


kepler.render_defaults = {"antialias": True,
    "frames": 120,
    "fps": 30,
    "frame_time": 4 * math.pi / 120,
    "size": (380, 320),  # the e = 0.5 ellipse is 2a wide and 1.73a high
    "speed_unit": "(G=1)",  # G = 1, total mass 1, a = 1: no SI unit applies
    "trail": 90,  # three quarters of an orbit (the 120 frames cover two): the ellipse stays drawn
    "size_by": "mass",  # the star (3× the planet's 12 px) larger than the planet
    "radius": 12,
    # Bodies as objects (a sun, a planet: KEPLER_COLORS), not a speed map that turns the star at
    # rest into the map's darkest end; the night sky.
    "color_by": "none", "theme": "dark", "loop": True,  # two whole orbits: the GIF loops seamlessly
}


#: Figure-eight choreography of three equal masses (G = m = 1): Chenciner & Montgomery, Ann.
#: Math. 152 (2000) 881; initial conditions and period from Simó (2002), as tabulated by
#: Chenciner & Montgomery's Fig. 1 caption: x₁ = −x₂, x₃ = 0, v₁ = v₂ = −v₃/2.
FIGURE_EIGHT_X1 = (0.97000436, -0.24308753)
FIGURE_EIGHT_V3 = (-0.93240737, -0.86473146)
FIGURE_EIGHT_PERIOD = 6.32591398


def figure_eight(
    *,
    steps_per_period: int = 2000,
    integrator: str = "yoshida4",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Three equal masses chasing each other around one figure-eight curve.

    G = m = 1: the choreography found by Moore (1993) and proved by Chenciner & Montgomery (2000), with
    Simó's initial conditions (:data:`FIGURE_EIGHT_X1`, :data:`FIGURE_EIGHT_V3`). Period
    T = 6.32591398; each body follows the one ahead by T/3. Total momentum 0, energy −1.287.
    ``dt=None`` uses T / steps_per_period, with Yoshida's fourth-order integrator.
    """
    steps_per_period = _count(steps_per_period, "steps_per_period", 1)
    step = FIGURE_EIGHT_PERIOD / steps_per_period if steps_per_period <= 2**1000 else 0.0
    if dt is None and not step >= _check.MIN_NORMAL:
        raise InvalidInputError(f"steps_per_period: the step T / steps_per_period = {step:.3g} is below float64's normal range")
    x1, v3 = np.array(FIGURE_EIGHT_X1), np.array(FIGURE_EIGHT_V3)
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    scene.add_particles(np.stack([x1, -x1, np.zeros(2)]), np.stack([-v3 / 2, -v3 / 2, v3]), masses=1.0)
    scene.add(PairwiseGravity(G=1.0))
    scene.render_defaults = {"colors": [0, 1, 3]}  # tab10 blue, orange, red: three bodies, three hues
    return scene


# One period; the curve is 2.2 wide and 0.7 high, hence the wide frame.
figure_eight.render_defaults = {"antialias": True,
    "frames": 150, "fps": 30, "frame_time": FIGURE_EIGHT_PERIOD / 150, "size": (560, 300), "radius": 10,
    "speed_unit": "(G=1)", "trail": 50, "theme": "dark",  # each trail a third of the curve: the three close it
    "color_by": "none",  # equal speeds at equal phases: the bodies as objects, each its own colour
    "loop": True,  # one whole period: the trails run on across the GIF's loop
}


def pythagorean(
    *,
    rtol: float = 1e-10,
    integrator: str = "dopri5",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Burrau's three-body problem: masses 3, 4 and 5 released at rest, until one is thrown out.

    The masses start at the corners of a 3-4-5 right triangle (Burrau 1913), each opposite the side of its length (G = 1), at (1, 3), (−2, −1) and (1, −1).
    After a long dance of close encounters the lightest body is thrown out near t = 60 and the
    other two leave as a binary (Szebehely & Peters, Astron. J. 72 (1967) 876). The encounters
    are far closer than the start, so the adaptive ``"dopri5"`` (tolerance `rtol`) is the
    default; ``dt`` (default 0.1) is then the output interval.
    """
    rtol = _check.float_in_range("rtol", rtol, 1e-14, 1.0, hi_open=True)
    scene = Scene(2, integrator=integrator, dt=0.1 if dt is None else dt, threads=threads, rtol=rtol, atol=rtol * 1e-3)
    x = np.array([[1.0, 3.0], [-2.0, -1.0], [1.0, -1.0]])
    scene.add_particles(x, np.zeros((3, 2)), masses=[3.0, 4.0, 5.0])
    scene.add(PairwiseGravity(G=1.0))
    scene.render_defaults = {"colors": [3, 0, 1]}  # masses 3, 4, 5: tab10 red, blue, orange
    return scene


pythagorean.render_defaults = {"antialias": True,
    # To t = 60.2: the last close encounter (t ≈ 59) has flung the lightest body out and it is
    # 5–6 from the centre, no farther than its excursion at t ≈ 53, so the camera still fits
    # the dance (|x| ≤ 3.2, |y| ≤ 4.5 before); a second later it is 8.4 out and the dance would
    # shrink. Frames 0.2 apart (two output intervals of dopri5's default dt) keep the trails of the
    # close encounters smooth; trails of 20 time units; the masses as objects, each its own colour.
    "frames": 302, "fps": 50, "frame_time": 0.2, "size": (400, 440), "speed_unit": "(G=1)", "trail": 100, "size_by": "mass",
    "radius": 6, "theme": "dark", "color_by": "none",
}


def plummer_sphere(
    n: int, *, mass: float = 1.0, a: float = 1.0, G: float = 1.0, cutoff: float = 0.999, seed: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities, (n, 3) float64 each, of a Plummer sphere in equilibrium: density
    ρ ∝ (1 + r²/a²)^(−5/2), total mass `mass`, scale radius `a`, in its centre-of-mass frame.
    Sampled as Aarseth, Hénon & Wielen, Astron. Astrophys. 37 (1974) 183, Appendix: radii by
    inverting the cumulative mass M(r)/M = r³/(r² + a²)^{3/2}, speeds q·v_esc with
    g(q) ∝ q²(1 − q²)^{7/2} by rejection, v_esc = √(2GM/√(r² + a²)); isotropic directions.
    The half-mass radius is ≈ 1.305 a; the virial ratio 2K/|W| is 1 up to sampling noise.
    `cutoff` (in (0, 1)) is the mass fraction sampled: the sphere ends at the radius holding it
    (0.999: about 30 a), so no body starts absurdly far out.
    """
    n = _count(n, "n", 1)
    cutoff = _check.float_in_range("cutoff", cutoff, 0.0, 1.0, lo_open=True, hi_open=True)
    rng = np.random.default_rng(seed)

    def directions(k: int) -> np.ndarray:
        d = rng.normal(size=(k, 3))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    m = rng.uniform(1e-9 * cutoff, cutoff, n)  # mass fractions below 1 keep r finite
    r = a / np.sqrt(m ** (-2.0 / 3.0) - 1.0)
    q = np.empty(n)
    filled = 0
    while filled < n:
        x = rng.uniform(0.0, 1.0, 2 * (n - filled))
        y = rng.uniform(0.0, 0.1, x.size)  # max of q²(1 − q²)^{7/2} is 0.0921
        keep = x[y < x * x * (1 - x * x) ** 3.5][: n - filled]
        q[filled : filled + keep.size] = keep
        filled += keep.size
    v = q * np.sqrt(2.0 * G * mass) * (r * r + a * a) ** -0.25
    x = r[:, None] * directions(n)
    u = v[:, None] * directions(n)
    return x - x.mean(axis=0), u - u.mean(axis=0)


#: ``galaxies``: colours of the two galaxies' stars (pale blue, warm gold), RGB.
GALAXY_COLORS = ((150, 190, 255), (255, 196, 110))


def galaxies(
    n: int = 10000,
    *,
    pericentre: float = 1.6,
    prograde: bool = True,
    theta: float = 0.6,
    softening: float = 0.05,
    seed: int = 3,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Two disk galaxies pass on a parabolic orbit and throw out tidal tails and a bridge.

    The set-up of Toomre & Toomre, Astrophys. J. 178 (1972) 623: each galaxy is a central mass
    with a cold disk of stars on circular orbits around it, and the two centres fall towards
    each other on a parabola. G = 1. Each galaxy: a central body of mass 1 (one particle, the
    bulge and halo in one) and a disk of (n − 2)/2 stars of total mass 0.05 (near test
    particles, as Toomre's), spread with uniform surface density between radii 0.15 and 1
    (r = √U(0.15², 1)) at random azimuths, each on the circular orbit of the softened central
    mass plus the disk mass inside its radius taken as spherical,
    v_c² = G M_c r² / (r² + ε²)^{3/2} + G M_d(< r) / r (→ G M(< r)/r for r ≫ ε; the thin
    disk's own field departs from the spherical one by about M_d/M_c).

    The orbit of the centres is the Kepler parabola (eccentricity 1) r = 2q / (1 + cos f) of
    pericentre q = `pericentre` in the xy-plane about the total mass μ = 2 × 1.05 (radial and
    tangential speeds √(μ/2q) sin f and √(μ/2q)(1 + cos f), so the relative speed is the escape
    speed √(2μ/r) and the orbital energy 0), started at separation 4.5 (f ≈ −107° for q = 1.6);
    by Barker's equation (Kepler's equation for e = 1) the pericentre comes at
    t = √(2q³/μ)(τ + τ³/3), τ = tan(|f|/2): 4.27 for q = 1.6. The disks are tilted 15° and 45°
    about the x-axis from the orbital plane; with `prograde` both spin the way the orbit turns,
    which, Toomre & Toomre found, makes the long tails; ``prograde=False`` (both retrograde)
    leaves the disks nearly undisturbed. Everything is placed in the centre-of-mass frame.

    Forces by Barnes–Hut (:class:`~physcore.TreeGravity`, opening angle `theta`, Plummer
    `softening` ε). ``dt=None`` takes 0.0125: 32 steps per orbit at the inner edge of the disks
    (angular speed √(G M_c / (r² + ε²)^{3/2}) there), and the few stars that plunge through the
    other galaxy's centre (accelerations up to 0.385 G M_c/ε² ≈ 150) keep the energy to 1e-5 of
    the initial kinetic energy over the render (measured at n = 10 000; 0.025 gives 2.5e-2, from
    those plunges). The render colours each galaxy's stars by origin (:data:`GALAXY_COLORS`:
    first blue, then gold). Particle order: centre A, its stars, centre B, its stars.
    :func:`plummer_sphere` samples a spherical cluster instead.
    """
    n = _count(n, "n", 4)
    q = _positive(pericentre, "pericentre")
    prograde = _flag(prograde, "prograde")
    theta = _nonneg(theta, "theta")
    # Beyond the disks' size (1) a softening only blurs the galaxies into each other; the bound
    # also keeps (r² + ε²)^{3/2} inside float64.
    softening = _check.float_in_range("softening", softening, 0.0, 10.0, lo_open=True)
    seed = _count(seed, "seed", 0)
    _particles("n", n)
    if not 1e-3 <= q < 2.25:  # the start at separation 4.5 must come before the pericentre
        raise InvalidInputError(f"pericentre: must be in [0.001, 2.25) (half the starting separation 4.5), got {q:.3g}")
    rng = np.random.default_rng(seed)
    m_centre, m_disk, r_in, r_out, sep = 1.0, 0.05, 0.15, 1.0, 4.5
    mu = 2.0 * (m_centre + m_disk)
    f = -math.acos(2.0 * q / sep - 1.0)  # true anomaly at the start: r = 2q / (1 + cos f)
    k = math.sqrt(mu / (2.0 * q))
    rhat = np.array([math.cos(f), math.sin(f), 0.0])
    rel = sep * rhat
    vrel = k * math.sin(f) * rhat + k * (1.0 + math.cos(f)) * np.array([-rhat[1], rhat[0], 0.0])
    spin = 1.0 if prograde else -1.0  # the orbit turns counter-clockwise (about +z)
    half = (n - 2) // 2
    xs, vs, ms = [], [], []
    for stars, side, tilt in ((half, -0.5, 15.0), (n - 2 - half, 0.5, 45.0)):
        r = np.sqrt(rng.uniform(r_in**2, r_out**2, stars))
        phi = rng.uniform(0.0, 2.0 * np.pi, stars)
        inside = m_disk * (np.argsort(np.argsort(r)) + 1) / stars  # M_d(≤ r)
        vc = spin * np.sqrt(m_centre * r * r / (r * r + softening**2) ** 1.5 + inside / r)
        c, s = math.cos(math.radians(tilt)), math.sin(math.radians(tilt))
        tilt_x = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
        p = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros(stars)], axis=1) @ tilt_x.T
        u = np.stack([-vc * np.sin(phi), vc * np.cos(phi), np.zeros(stars)], axis=1) @ tilt_x.T
        xs += [np.zeros((1, 3)), p]
        vs += [np.zeros((1, 3)), u]
        ms += [[m_centre], np.full(stars, m_disk / stars)]
        xs[-2:] = [a + side * rel for a in xs[-2:]]
        vs[-2:] = [a + side * vrel for a in vs[-2:]]
    x, v, m = np.concatenate(xs), np.concatenate(vs), np.concatenate(ms)
    x -= m @ x / m.sum()  # the random disks' own small centre-of-mass offsets and momenta
    v -= m @ v / m.sum()
    scene = Scene(3, integrator=integrator, dt=0.0125 if dt is None else dt, threads=threads)
    scene.add_particles(x, v, masses=m)
    scene.add(TreeGravity(G=1.0, softening=softening, theta=theta))
    scene.render_defaults = {"colors": [GALAXY_COLORS[0]] * (half + 1) + [GALAXY_COLORS[1]] * (n - 1 - half)}
    return scene


# 120 frames of 8 steps (t = 0 to 11.9) played in 5 s: the approach, the pericentre at t ≈ 4.3,
# and the tails and bridge growing for about one orbit of the disks' edges (2π) after it. The view looks down
# on the orbital plane at 70°, with the separating pair across the frame; "follow" frames 95 % of
# the stars (the centre of mass stays put), so a few stars flung far do not shrink the picture.
galaxies.render_defaults = {
    "frames": 120, "fps": 24, "frame_time": 0.1, "size": (480, 400), "view": (30.0, 70.0), "radius": 0,
    "speed_unit": "(G=1)", "theme": "dark", "color_by": "density",  # glow: stars accumulate like an exposure
    "camera": "follow",
}


def cyclotron(
    n: int = 6,
    *,
    B: float = 1.0,
    E: float = 0.3,
    seed: int = 5,
    integrator: str = "boris",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Charges gyrating in a magnetic field and drifting together across an electric one.

    2D, B_z = `B` out of the plane and a uniform E = (0, `E`): `n` particles of charge ±1
    (alternating, first +1) and mass 1, 2 or 4 (cycling; units where these are 1). Each turns
    at its cyclotron frequency ω_c = |q|B/m on a circle of radius m w/(|q|B) (w its speed in the
    frame drifting at E×B/B² = (E/B, 0)), positive and negative charges in opposite senses, and
    every one drifts at E/B along x whatever its charge and mass: trochoids (Jackson,
    *Classical Electrodynamics*, 3rd ed., §12.3). Each starts at x = 0 moving along x at
    E/B − w, w drawn uniformly in [0.15, 0.6] (`seed`): w < E/B gives a wave, w = E/B a
    cycloid with cusps, w > E/B loops. Each is at the edge of its gyration circle, so it
    sweeps a band 2 m w/(|q|B) high (above its start if positive, below if negative); the
    bands are stacked 0.6/B apart, in index order from the bottom, centred on y = 0. Boris push;
    ``dt=None`` takes 0.02/B (ω_c dt ≤ 0.02). The render colours positive charges red and
    negative blue (:data:`CHARGE_COLORS`).
    """
    n = _count(n, "n", 1)
    B = _positive(B, "B")
    E = _nonneg(E, "E")
    seed = _count(seed, "seed", 0)
    _particles("n", n)
    step = 0.02 / B if B < math.inf else 0.0
    if dt is None and not _check.MIN_NORMAL <= step < math.inf:
        raise InvalidInputError(f"B: the step 0.02/B = {step:.3g} s is outside float64's normal range; give another B or a dt")
    rng = np.random.default_rng(seed)
    q = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    m = np.array([1.0, 2.0, 4.0])[np.arange(n) % 3]
    w = rng.uniform(0.15, 0.6, n)
    with np.errstate(over="ignore"):  # E/B beyond float64 is refused by _finite_books below
        height = 2.0 * m * w / B  # each band: the gyration circle's diameter
        top = np.cumsum(height + 0.6 / B)
    if not (np.isfinite(top[-1]) and top[-1] < 1e300):
        raise InvalidInputError(f"B: the gyration bands, 2 m w/(|q| B) each, span {top[-1]:.3g} m at B = {B:.3g}: beyond float64")
    with np.errstate(over="ignore"):
        y = np.where(q > 0, top - height, top)  # a positive charge turns up first (q v×B)
        y -= 0.5 * (top[0] - height[0] + top[-1])  # the stack's bottom and top about y = 0
        x = np.stack([np.zeros(n), y], axis=1)
        v = np.stack([E / B - w, np.zeros(n)], axis=1)
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    scene.add_particles(x, v, masses=m)
    scene.set_attribute("charge", q)
    scene.add(MagneticField(B))
    if E:
        scene.add(ElectricField([0.0, E]))
    scene.render_defaults = {"colors": [CHARGE_COLORS[0] if c > 0 else CHARGE_COLORS[1] for c in q]}
    return _finite_books(scene, "E, B")  # the drift E/B: a huge E or a tiny B


#: ``cyclotron``: colours of positive (red) and negative (blue) charges, RGB.
CHARGE_COLORS = ((235, 85, 70), (80, 150, 255))

# 45 (q=m=B=1) time units: about seven turns of the lightest charges, two of the heaviest, and a
# drift of 13.5 (E = 0.3); the trails draw the whole trochoids, band by band.
cyclotron.render_defaults = {"antialias": True,
    "frames": 150, "fps": 30, "frame_time": 0.3, "size": (480, 400), "speed_unit": "(q=m=B=1)", "trail": 150,
    "size_by": "mass", "radius": 4, "theme": "dark", "color_by": "none",
}


def spring_chain(
    n: int = 24,
    *,
    length: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.0,
    dim: int = 2,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Spring chain: n particles joined by springs, first one pinned, released horizontally.

    It swings down under gravity like a heavy rope. Total mass (kg) shared equally, spring
    stiffness (N/m) and dashpot damping (N·s/m) per link. ``dt=None`` uses half the suggested
    step: the whip at the end of the swing reaches energy errors of 2e-3 at the suggested step
    (stable, but visible in the books) and 3e-4 at half of it.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    _particles("n", n, n)
    length, mass, stiffness = _positive(length, "length"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    damping = _nonneg(damping, "damping")
    dim = _dim(dim)
    dt = _optional(dt, "dt")
    link = length / (n - 1)
    # Spring lengths come from squared lengths: link², with a margin for rounding.
    if not (link >= _check.MIN_NORMAL and math.isfinite(2 * link * link)):
        raise InvalidInputError(f"length: a link of length/(n - 1) = {link:.3g} m is outside float64's usable range")
    m = _particle_mass(mass / n, "mass, n")
    x = np.zeros((n, dim))
    x[:, 0] = np.linspace(0.0, length, n)
    pinned = np.zeros(n, dtype=bool)
    pinned[0] = True
    scene = Scene(dim, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=m, pinned=pinned)
    scene.add(Springs(np.arange(n - 1), np.arange(1, n), stiffness=stiffness, damping=damping))
    g = [0.0] * dim
    g[1 if dim == 2 else 2] = -9.81
    scene.add(Gravity(g))
    if dt is None:
        _set_stable_dt(scene, 0.5, "stiffness, damping, mass")
    return _finite_books(scene, "length, mass")


# The swing spans the chain's length either side of the pivot and one below it: a wide frame.
# Beads 7 px wide (the links hidden under them) and short trails for the whip of the free end.
spring_chain.render_defaults = {"antialias": True, "frames": 100, "fps": 30, "frame_time": 1 / 30, "size": (480, 320),
                                "radius": 7, "trail": 4}

# --------------------------------------------------------------------------- SPH fluid scenes
_G = 9.81  # m/s², gravity of the fluid scenes


def _pair(value: object, arg: str) -> tuple[float, float]:
    """A (length, height) pair of finite numbers > 0, m."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list, np.ndarray)):
        raise InvalidTypeError(f"{arg}: expected (length, height) in m, got {type(value).__name__}")
    items = list(value) if not (isinstance(value, np.ndarray) and value.ndim == 0) else []
    if len(items) != 2:
        raise InvalidInputError(f"{arg}: expected (length, height) in m, got {len(items)} numbers")
    a, b = (_check.positive_float(arg, v) for v in items)
    return a, b


def _spacing(dx: float, args: str) -> float:
    """The fluid's lattice spacing derived from ``args``, inside :data:`SPACING_RANGE`."""
    lo, hi = SPACING_RANGE
    if not lo <= dx <= hi:
        raise InvalidInputError(f"{args}: give a particle spacing of {dx:.3g} m, outside [{lo:g}, {hi:g}] m")
    return dx


def _lattice_size(lo, hi, dx) -> float:
    """Particles of ``lattice(lo, hi, dx)`` (inf beyond float64), counted without allocating."""
    counts = lattice_counts(lo, hi, dx)
    return math.prod(counts) if min(counts) > 0 else math.inf


def _walls_size(lo, hi, dx) -> float:
    """At most the particles of ``tank_walls(lo, hi, dx, layers=3)``: its whole outer lattice."""
    pad = 3 * dx
    return _lattice_size([v - pad for v in lo], [v + pad for v in hi], dx)


def _fluid_scene(dim: int, integrator: str, dt: float | None, threads: int | None) -> Scene:
    """A scene with gravity along −y (2D) or −z (3D), added before the fluid so that the fluid's
    default sound speed is estimated from it."""
    scene = Scene(dim, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    g = [0.0] * dim
    g[-1] = -_G
    scene.add(Gravity(g))
    return scene


def _box(dim: int, x: tuple[float, float], height: tuple[float, float], depth: tuple[float, float]):
    """Lower and upper corners of a box spanning ``x`` along x, ``height`` along the vertical
    axis (y in 2D, z in 3D) and, in 3D, ``depth`` along y."""
    if dim == 2:
        return [x[0], height[0]], [x[1], height[1]]
    return [x[0], depth[0], height[0]], [x[1], depth[1], height[1]]


def _water_in_tank(
    positions, dx, tlo, thi, *, dim, lid, pass_precision, kernel, alpha, sound_speed, integrator, dt, threads, method="wcsph",
    velocities=None, **surface: float,
) -> Scene:
    """A fluid scene: water particles at ``positions`` in a tank lined with 3 wall layers
    (``surface``: DFSPH's ``surface_tension`` and ``adhesion``)."""
    scene = _fluid_scene(dim, integrator, dt, threads)
    scene.add_fluid(
        positions,
        velocities=velocities,
        **surface,
        spacing=dx,
        boundary=tank_walls(tlo, thi, dx, layers=3, top=lid),
        pass_precision=pass_precision,
        kernel=kernel,
        alpha=alpha,
        sound_speed=sound_speed,
        method=method,
        name="water",
    )
    if dt is not None:
        scene.dt = dt
    return _finite_books(scene, "n, tank")


def dam_break(
    *,
    dim: int = 2,
    n: int | None = None,
    width: float = 1.0,
    height: float = 2.0,
    tank: tuple[float, float] = (4.0, 3.0),
    depth: float = 1.0,
    lid: bool = True,
    pass_precision: str = "f32",
    kernel: str = "cubic_spline",
    alpha: float = 0.05,
    sound_speed: float | None = None,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
    method: str | None = None,
) -> Scene:
    """Dam break: a water column collapses in a tank, surges along the floor and splashes back.

    A column ``width × height`` (m) of water (ρ0 = 1000 kg/m³) at rest in the lower-left corner
    of a tank ``tank = (length, height)``, under gravity 9.81 m/s² (−y in 2D, −z in 3D),
    simulated with DFSPH by default (:class:`~physcore.fluids.Fluid`: divergence-free SPH, or
    WCSPH's Tait equation of state with ``method="wcsph"``; Monaghan artificial viscosity,
    free-slip boundary-particle walls, 3 layers). For ``height = 2 width``
    this is the experiment of Martin & Moyce (1952): in T = t·√(2g/width) the front reaches the
    far wall (x = 4 width) at T ≈ 3.3, a jet runs up the wall to the lid (T ≈ 5) and the water
    falls back as a plunging wave (T ≈ 6–8).

    Parameters
    ----------
    dim : {2, 3}
        In 3D the tank has a ``depth`` (along y) and the column spans it.
    n : int, optional
        Particles across the column width (spacing ``width / n``). Default 72 in 2D
        (N = 2n² = 10 368 particles; the default render to T = 8 then takes seconds, and the
        surface drawing shows no grain at 480 × 360) and 24 in 3D (N = 2n³·depth/width ≈
        27 600). The README's speed and Martin & Moyce tables use n = 144 (41 472).
    width, height : float
        The water column, m (> 0).
    tank : (float, float)
        Tank length (along x) and height, m; the column must fit inside.
    depth : float
        3D only: tank (and column) depth, m (> 0).
    lid : bool
        Close the tank with a lid of wall particles (default), so the jet and the spray thrown up
        by the impact on the far wall stay in the tank; ``False``: an open tank.
    pass_precision : {"f32", "f64"}
        Arithmetic of the SPH passes; f32 is about twice as fast. Default "f32". (Old name
        ``precision``, deprecated.)
    kernel : {"cubic_spline", "wendland_c2"}
    alpha : float
        Monaghan artificial viscosity α (≥ 0, dimensionless). Default 0.05. (Old name
        ``viscosity``, deprecated.)
    sound_speed : float, optional
        Numerical speed of sound, m/s. Default: 10·√(2 g height) (about 1 % density variation).
    integrator : str
        Default "semi_implicit_euler" (the usual WCSPH choice: symplectic, one evaluation).
    dt : float, optional
        Fixed time step, s. Default: the fluid's CFL limit (renders use automatic substeps).
    threads : int, optional
    method : {"dfsph", "wcsph"}, optional
        The fluid's pressure (:class:`~physcore.fluids.Fluid`). Default ``"dfsph"`` with the
        default integrator, ``"wcsph"`` with any other (DFSPH steps with
        ``"semi_implicit_euler"`` only). ``"dfsph"`` solves for an incompressible pressure (0.1 % mean compression) and steps at the flow's CFL limit
        instead of the speed of sound's: a render at n = 144 to T = 4 takes about 1,800 steps instead
        of 29,000, three times faster (README, "Fluids (DFSPH)"), with the Martin & Moyce
        front as close; ``sound_speed`` then only scales the viscosity and ``pass_precision`` does
        not apply (DFSPH computes in float64). ``"wcsph"``: the Tait equation of state.

    Returns
    -------
    Scene
        Particles ``0 .. N`` are the water (one fluid, ``"water"``); ``scene.boundary_points()``
        are the tank's walls.

    Raises
    ------
    TypeError, InvalidInputError
        As every scene function (module docstring), naming the argument; also a spacing
        ``width / n`` outside :data:`~physcore.fluids.SPACING_RANGE`.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.dam_break(n=10)
    >>> scene.n_particles
    200
    >>> substeps = scene.advance(0.05)
    """
    dim = _dim(dim)
    lid = _flag(lid, "lid")
    n = _count(24 if dim == 3 and n is None else 72 if n is None else n, "n", 2)
    width, height, depth = _positive(width, "width"), _positive(height, "height"), _positive(depth, "depth")
    length, top = _pair(tank, "tank")
    if not width < length:
        raise InvalidInputError(f"tank, width: the tank's length {length} must exceed the column width {width}")
    if not height <= top:
        raise InvalidInputError(f"tank, height: the tank's height {top} must be at least the column height {height}")
    dx = _spacing(_per(width, n), "n, width")
    if method is None:
        # (Any other integrator, a bad one included, goes to Scene, which names it.)
        method = "dfsph" if isinstance(integrator, str) and integrator == "semi_implicit_euler" else "wcsph"
    lo, hi = _box(dim, (0.0, width), (0.0, height), (0.0, depth))
    tlo, thi = _box(dim, (0.0, length), (0.0, top), (0.0, depth))
    _particles("n, width, height, depth, tank", _lattice_size(lo, hi, dx) + _walls_size(tlo, thi, dx))
    return _water_in_tank(
        lattice(lo, hi, dx), dx, tlo, thi, dim=dim, lid=lid, pass_precision=pass_precision, kernel=kernel,
        alpha=alpha, sound_speed=sound_speed, integrator=integrator, dt=dt, threads=threads, method=method,
    )


# 120 frames (4 s at 30 fps) over T = t·√(2g/width) = 0..8 for the default width (1 m): the
# collapse, the surge along the floor, its impact on the far wall (T ≈ 3.3), the jet up to the
# lid (T ≈ 5) and the plunging wave falling back (T ≈ 6–8), played 2.2× slower than real time.
# The water is drawn as one surface (render.gif(surface=...)), by speed from deep navy to foam.
dam_break.render_defaults = {
    "frames": 120,
    "fps": 30,
    "frame_time": 8.0 / math.sqrt(2.0 * _G / 1.0) / 120,
    "substeps": "auto",
    "color_by": "speed",
    "size": (480, 360),
    "surface": True,
    "cmap": "ice",
}


def drop(
    *,
    dim: int = 2,
    n: int | None = None,
    tank: tuple[float, float] = (2.0, 2.0),
    depth: float = 1.0,
    lid: bool = True,
    pool: float = 0.6,
    block: float = 0.4,
    fall: float = 0.6,
    pass_precision: str = "f32",
    kernel: str = "cubic_spline",
    alpha: float = 0.05,
    sound_speed: float | None = None,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
    method: str | None = None,
) -> Scene:
    """Drop: a block of water falls into a pool at rest in a tank and splashes.

    The pool fills the tank ``tank = (length, height)`` (m) to depth ``pool``; a square (3D: cubic)
    block of side ``block`` hangs centred above it, its bottom ``fall`` above the pool surface, all
    at rest, under gravity 9.81 m/s² (−y in 2D, −z in 3D). WCSPH water (ρ0 = 1000 kg/m³) as in
    :func:`dam_break`. With the defaults the block hits the pool at √(2 g fall) ≈ 3.4 m/s after
    0.35 s, opens a crater, throws up a crown and spray, and the crater's collapse sends a jet up
    the middle and waves to the walls.

    Parameters
    ----------
    dim : {2, 3}
        In 3D the tank has a ``depth`` (along y) and the block is centred in it.
    n : int, optional
        Particles across the tank length (spacing ``tank[0] / n``). Default 160 in 2D
        (8 704 particles) and 40 in 3D (10 112).
    tank : (float, float)
        Tank length (along x) and height, m.
    depth : float
        3D only: tank depth, m (> 0).
    lid : bool
        Close the tank with a lid (default), so the spray stays in; ``False``: an open tank.
    pool : float
        Pool depth, m (≥ 0; 0: the block falls on the bare floor).
    block : float
        Side of the falling block, m (> 0, narrower than the tank, at least 2 spacings).
    fall : float
        Gap between the pool surface and the block's bottom, m (≥ 0).
    pass_precision, kernel, alpha, integrator, dt, threads
        As for :func:`dam_break`.
    sound_speed : float, optional
        m/s. Default: 10·√(2 g (pool + fall + block)), ten times the fastest fall.
    method : {"dfsph", "wcsph"}, optional
        The fluid's pressure (:class:`~physcore.fluids.Fluid`), as for :func:`dam_break`:
        default ``"dfsph"`` with the default integrator (the default render then takes seconds:
        WCSPH's sound-speed step made it 44 s), ``"wcsph"`` with any other. ``"dfsph"`` steps
        with ``"semi_implicit_euler"`` only and computes in float64 (``pass_precision`` does not
        apply).

    Returns
    -------
    Scene
        The pool's particles first, then the block's; one fluid, ``"water"``.

    Raises
    ------
    TypeError, InvalidInputError
        As every scene function (module docstring), naming the argument; also a spacing
        ``tank[0] / n`` outside :data:`~physcore.fluids.SPACING_RANGE`.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.drop(n=40)   # 480 in the pool, 8 × 8 in the block
    >>> scene.n_particles
    544
    """
    dim = _dim(dim)
    lid = _flag(lid, "lid")
    n = _count(40 if dim == 3 and n is None else 160 if n is None else n, "n", 2)
    length, top = _pair(tank, "tank")
    depth = _positive(depth, "depth")
    pool, fall, block = _nonneg(pool, "pool"), _nonneg(fall, "fall"), _positive(block, "block")
    if not block < min(length, depth if dim == 3 else length):
        raise InvalidInputError(
            f"block, tank{', depth' if dim == 3 else ''}: the block's side {block} must be smaller than the tank's "
            f"length{' and depth' if dim == 3 else ''}"
        )
    if not pool + fall + block <= top:
        raise InvalidInputError(
            f"tank, pool, fall, block: the tank's height {top} must be at least pool + fall + block = {pool + fall + block}"
        )
    dx = _spacing(_per(length, n), "n, tank")
    if method is None:
        method = "dfsph" if isinstance(integrator, str) and integrator == "semi_implicit_euler" else "wcsph"
    if not block >= 2 * dx:
        raise InvalidInputError(f"n, block, tank: n = {n} gives spacing {dx:.3g} m, too coarse for a block of {block} m")
    tlo, thi = _box(dim, (0.0, length), (0.0, top), (0.0, depth))
    _particles("n, tank, depth, pool, block", _lattice_size(tlo, thi, dx) + _walls_size(tlo, thi, dx))
    def snap(v):  # keep the block on the pool's (and walls') lattice
        return round(v / dx) * dx

    x0 = snap(0.5 * (length - block))
    z0 = snap(pool + fall)
    y0 = snap(0.5 * (depth - block)) if dim == 3 else 0.0  # 2D: no depth (which may be huge)
    parts = []
    if pool > 0:
        lo, hi = _box(dim, (0.0, length), (0.0, pool), (0.0, depth))
        parts.append(lattice(lo, hi, dx))
    lo, hi = _box(dim, (x0, x0 + block), (z0, z0 + block), (y0, y0 + block))
    parts.append(lattice(lo, hi, dx))
    if sound_speed is None:
        # 10× the impact speed bound √(2 g H), H from the floor to the block's top (the fluid's
        # own estimate would miss the fall of a block into an empty tank).
        sound_speed = 10.0 * math.sqrt(2.0 * _G * (pool + fall + block))
    return _water_in_tank(
        np.concatenate(parts), dx, tlo, thi, dim=dim, lid=lid, pass_precision=pass_precision, kernel=kernel,
        alpha=alpha, sound_speed=sound_speed, integrator=integrator, dt=dt, threads=threads, method=method,
    )


# 120 frames, 2 s: the fall (0.35 s), the splash and the waves' first return from the walls;
# the water as one surface, by speed.
drop.render_defaults = {
    "frames": 120,
    "fps": 30,
    "frame_time": 2.0 / 120,
    "substeps": "auto",
    "color_by": "speed",
    "size": (480, 480),
    "surface": True,
    "cmap": "ice",
}

def _surface_scene_args(dim, n, n2, n3, integrator, surface_tension, adhesion, alpha):
    """The checks the two surface-tension scenes share: (dim, n, σ, adhesion, α)."""
    dim = _dim(dim)
    n = _count(n3 if dim == 3 and n is None else n2 if n is None else n, "n", 8)
    if not (isinstance(integrator, str) and integrator == "semi_implicit_euler"):
        raise InvalidInputError(
            f"integrator: surface tension is DFSPH's (Fluid(method='dfsph')), which steps with 'semi_implicit_euler' only, got {integrator!r:.80}"
        )
    return dim, n, _nonneg(surface_tension, "surface_tension"), _nonneg(adhesion, "adhesion"), _nonneg(alpha, "alpha")


def _speed(value: object) -> float:
    """A drop's initial speed, m/s: ≥ 0 and at most 1e150 (the fluid's estimated sound speed,
    10 × it, must keep ρ0 c0² finite)."""
    speed = _nonneg(value, "speed")
    if not speed <= 1e150:
        raise InvalidInputError(f"speed: at most 1e150 m/s (the fluid's sound speed is estimated as 10 × it), got {speed}")
    return speed


def _on_lattice(v: float, dx: float) -> float:
    """``v`` moved to the nearest particle centre of the walls' lattice (centres at (i + ½) dx)."""
    return (math.floor(v / dx) + 0.5) * dx


def _surface_water(pos, vel, dx, tlo, thi, dim, lid, alpha, sigma, adh, integrator, dt, threads) -> Scene:
    """The surface-tension scenes' water: DFSPH (float64, cubic spline) with σ and adhesion, at
    ``pos`` moving at ``vel``, in a tank lined with 3 wall layers, sound speed estimated."""
    return _water_in_tank(
        pos, dx, tlo, thi, dim=dim, lid=lid, pass_precision="f64", kernel="cubic_spline", alpha=alpha,
        sound_speed=None, integrator=integrator, dt=dt, threads=threads, method="dfsph", velocities=vel,
        surface_tension=sigma, adhesion=adh,
    )


def _ball(centre, radius, dx, dim):
    """Lattice points (spacing ``dx``, on the tank's lattice) within ``radius`` of ``centre``."""
    c = np.asarray(centre, dtype=np.float64)
    pts = lattice(c - radius, c + radius, dx)
    return pts[np.linalg.norm(pts - c, axis=1) <= radius]


def droplets(
    *,
    dim: int = 2,
    n: int | None = None,
    drops: int = 3,
    radius: float = 0.003,
    speed: float = 1.5,
    tank: tuple[float, float] = (0.06, 0.03),
    depth: float = 0.02,
    surface_tension: float = 0.072,
    adhesion: float = 0.0,
    alpha: float = 0.02,
    lid: bool = True,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Droplets: water drops hit a floor, spread into sheets, and surface tension pulls the
    sheets' rims back into round drops (a splash with surface tension).

    ``drops`` drops of ``radius`` (m) start in a row across the tank at staggered heights, moving
    down at ``speed`` (m/s), under gravity 9.81 m/s². Water at millimetre scale: DFSPH
    (ρ0 = 1000 kg/m³) with Akinci et al. (2013) surface tension σ = 0.072 N/m (N in 2D) and no
    adhesion to the walls by default (:class:`~physcore.fluids.Fluid`; with the 0.02 N/m of earlier
    versions the spray thrown up hung from the lid for the rest of the animation); the capillary length
    √(σ/(ρ0 g)) = 2.7 mm is the drops' size, so both gravity and surface tension shape them. The
    default impact (Weber number ρ0 v² 2R/σ ≈ 190) spreads each drop into a thin sheet whose rim
    gathers and breaks into droplets.

    Parameters
    ----------
    dim : {2, 3}
        In 3D the tank has a ``depth`` (along y) and the drops are centred in it.
    n : int, optional
        Particles across the tank length (spacing ``tank[0] / n``). Default 240 in 2D (about
        1 400 water particles, 12 across a drop's radius) and 120 in 3D (about 2 700, 6 across).
    drops : int
        Number of drops (1..20).
    radius : float
        Drop radius, m (> 0, at least 2 spacings).
    speed : float
        Initial downward speed, m/s (≥ 0).
    tank : (float, float)
        Tank length (along x) and height, m.
    depth : float
        3D only: tank depth, m.
    surface_tension, adhesion : float
        σ and the walls' adhesion, N/m (N in 2D), ≥ 0 (:class:`~physcore.fluids.Fluid`).
    alpha : float
        Monaghan artificial viscosity α (≥ 0, dimensionless). (Old name ``viscosity``, deprecated.)
    lid : bool
        Close the tank with a lid (default).
    integrator : str
        ``"semi_implicit_euler"`` only (DFSPH); others are refused, naming ``integrator``.
    dt : float, optional
        Fixed time step, s. Default: the fluid's limit (renders use automatic substeps).
    threads : int, optional

    Returns
    -------
    Scene
        One fluid, ``"water"``, the drops' particles in order.

    Raises
    ------
    TypeError, InvalidInputError
        As every scene function (module docstring), naming the argument.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.droplets(n=80, drops=2)
    >>> scene.n_particles
    104
    """
    dim, n, sigma, adh, alpha = _surface_scene_args(dim, n, 240, 120, integrator, surface_tension, adhesion, alpha)
    drops = _check.int_in_range("drops", drops, 1, 20)
    radius, speed = _positive(radius, "radius"), _speed(speed)
    length, top = _pair(tank, "tank")
    depth = _positive(depth, "depth")
    lid = _flag(lid, "lid")
    dx = _spacing(_per(length, n), "n, tank")
    if not radius >= 2 * dx:
        raise InvalidInputError(f"n, tank, radius: n = {n} across the tank gives spacing {dx:.3g} m, too coarse for drops of radius {radius} m")
    # Drops side by side (centres length/(drops + 1) apart) must not touch, whatever their heights.
    if not (2 * radius + 2 * dx <= length / (drops + 1) and 4 * radius < top and (dim == 2 or 2 * radius < depth)):
        raise InvalidInputError(
            f"radius, drops, tank: {drops} drops of radius {radius} m do not fit side by side in the tank {length} × {top} m"
        )
    tlo, thi = _box(dim, (0.0, length), (0.0, top), (0.0, depth))
    _particles("dim, n, tank, depth, drops", _walls_size(tlo, thi, dx) + drops * _lattice_size([0.0] * dim, [2 * radius] * dim, dx))

    snap = functools.partial(_on_lattice, dx=dx)

    parts = []
    for k in range(drops):
        x = snap(length * (k + 1) / (drops + 1))
        z = snap(top - radius - 2 * dx - (k % 2) * (top - 4 * radius - 4 * dx) * 0.5)
        centre = [x, z] if dim == 2 else [x, snap(0.5 * depth), z]
        parts.append(_ball(centre, radius, dx, dim))
    pos = np.concatenate(parts)
    vel = np.zeros_like(pos)
    vel[:, -1] = -speed
    return _surface_water(pos, vel, dx, tlo, thi, dim, lid, alpha, sigma, adh, integrator, dt, threads)


# 120 frames over 0.15 s: the fall, the impacts (the first at ≈ 6 ms), the sheets and the rims
# pulling back into drops, and the spray raining back from the lid (after 0.15 s the puddles
# only wobble).
droplets.render_defaults = {
    "frames": 120,
    "fps": 30,
    "frame_time": 0.15 / 120,
    "substeps": "auto",
    "color_by": "speed",
    "size": (480, 240),
    "surface": True,
    "cmap": "ice",
}


def crown(
    *,
    dim: int = 2,
    n: int | None = None,
    tank: tuple[float, float] = (0.07, 0.03),
    depth: float = 0.04,
    pool: float = 0.002,
    radius: float = 0.002,
    speed: float = 2.5,
    surface_tension: float = 0.072,
    adhesion: float = 0.05,
    alpha: float = 0.02,
    lid: bool = True,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Crown: a water drop hits a shallow pool and throws up a crown-shaped sheet (in 2D, two
    sheets) whose rim breaks into droplets (Worthington's splash; Yarin, Annu. Rev. Fluid Mech.
    38, 2006).

    A drop of ``radius`` (m) just above a pool of depth ``pool`` (m), moving down at ``speed``
    (m/s), under gravity. DFSPH water with Akinci et al. (2013) surface tension, as
    :func:`droplets`. The default impact: Weber number ρ0 v² 2R/σ ≈ 350, pool depth half the
    drop's diameter, the regime of crown splashes.

    Parameters
    ----------
    dim : {2, 3}
        In 3D the tank has a ``depth`` (along y).
    n : int, optional
        Particles across the tank length (spacing ``tank[0] / n``). Default 525 in 2D (8 591
        particles, 15 across the drop's radius) and 140 in 3D (45 080, 4 across).
    tank : (float, float)
        Tank length (along x) and height, m.
    depth : float
        3D only: tank depth, m.
    pool : float
        Pool depth, m (> 0, at least 2 spacings).
    radius : float
        Drop radius, m (at least 2 spacings).
    speed : float
        The drop's initial downward speed, m/s (≥ 0).
    surface_tension, adhesion, alpha, lid, integrator, dt, threads
        As for :func:`droplets`.

    Returns
    -------
    Scene
        One fluid, ``"water"``: the pool's particles, then the drop's.

    Raises
    ------
    TypeError, InvalidInputError
        As every scene function (module docstring), naming the argument.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.scenes.crown(n=80)   # 160 in the pool, 17 in the drop
    >>> scene.n_particles
    177
    """
    dim, n, sigma, adh, alpha = _surface_scene_args(dim, n, 525, 140, integrator, surface_tension, adhesion, alpha)
    length, top = _pair(tank, "tank")
    depth = _positive(depth, "depth")
    pool, radius, speed = _positive(pool, "pool"), _positive(radius, "radius"), _speed(speed)
    lid = _flag(lid, "lid")
    dx = _spacing(_per(length, n), "n, tank")
    if not (pool >= 2 * dx and radius >= 2 * dx):
        raise InvalidInputError(f"n, tank, pool, radius: n = {n} across the tank gives spacing {dx:.3g} m, too coarse for the pool or the drop")
    if not (2 * radius < length and pool + 2 * radius + 2 * dx < top and (dim == 2 or 2 * radius < depth)):
        raise InvalidInputError(f"pool, radius, tank: the pool and a drop of radius {radius} m do not fit in the tank")
    tlo, thi = _box(dim, (0.0, length), (0.0, top), (0.0, depth))
    _particles("dim, n, tank, depth, pool", _walls_size(tlo, thi, dx) + _lattice_size(tlo, _box(dim, (0.0, length), (0.0, pool), (0.0, depth))[1], dx)
               + _lattice_size([0.0] * dim, [2 * radius] * dim, dx))

    snap = functools.partial(_on_lattice, dx=dx)

    lo, hi = _box(dim, (0.0, length), (0.0, pool), (0.0, depth))
    water = lattice(lo, hi, dx)
    z = snap(water[:, -1].max() + radius + 1.5 * dx)
    centre = [snap(0.5 * length), z] if dim == 2 else [snap(0.5 * length), snap(0.5 * depth), z]
    ball = _ball(centre, radius, dx, dim)
    pos = np.concatenate([water, ball])
    vel = np.zeros_like(pos)
    vel[len(water):, -1] = -speed
    return _surface_water(pos, vel, dx, tlo, thi, dim, lid, alpha, sigma, adh, integrator, dt, threads)


# 120 frames over 25 ms: the impact, the crown rising and its rim breaking up; the tank (7 cm)
# is wide enough that the sheets never reach its walls in that time.
crown.render_defaults = {
    "frames": 120,
    "fps": 30,
    "frame_time": 0.025 / 120,
    "substeps": "auto",
    "color_by": "speed",
    "size": (480, 240),
    "surface": True,
    "cmap": "ice",
}


def ripple(
    n: int = 256,
    *,
    drops: int = 6,
    speed: float = 0.25,
    damping: float = 0.15,
    seed: int = 3,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Ripples on a pond: stones dropped one after another into a 1 m square pond.

    The banks reflect (free faces); an n × n wave grid (:class:`~physcore.grids.Wave`).

    `drops` Gaussian dents (radius 1.2 cm, depth 4 mm) fall at random places (seeded) every 0.6 s
    from t = 0; the waves travel at `speed` (m/s) and fade at `damping` (1/s).
    """
    from .grids import Drop, Wave

    n = _count(n, "n", 16)
    _cells("n", n * n)
    drops = _check.int_in_range("drops", drops, 0, 1000)
    speed = _positive(speed, "speed")
    damping = _nonneg(damping, "damping")
    rng = np.random.default_rng(_check.int_in_range("seed", seed, 0, 2**63 - 1))
    stones = [Drop(0.6 * k, tuple(rng.uniform(0.2, 0.8, 2)), radius=0.012, amplitude=0.004) for k in range(drops)]
    scene = Scene(2, dt=1e-3 if dt is None else dt, threads=threads)
    pond = scene.add(Wave((n, n), 1.0 / n, c=speed, damping=damping, edges="free", drops=stones, name="pond"))
    if dt is None:
        scene.dt = _cfl_step(pond, "speed")
    return scene


# 25 fps: waves move everywhere, so each frame costs its whole picture; 4 s in 100 frames.
ripple.render_defaults = {"frames": 100, "fps": 25, "frame_time": 1 / 25, "substeps": "auto", "size": (400, 400)}


def double_slit(
    n: int = 256,
    *,
    wavelength: float = 0.05,
    separation: float = 0.2,
    width: float = 0.03,
    speed: float = 0.3,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Interference behind two slits: a plane wave passes a wall with two openings.

    The wave comes from an oscillating line on the left of a 1.5 m × 1 m tank and meets a wall
    with two slits (`width` m wide, centres `separation` m apart);
    the other faces absorb (damping layers), so the fringes are those of an open field. The
    grid is (1.5 n) × n; the source's frequency is speed / wavelength.
    """
    from .grids import Oscillator, Wave

    n = _count(n, "n", 32)
    _cells("n", (3 * n * n) // 2)
    wavelength, separation, width = _positive(wavelength, "wavelength"), _positive(separation, "separation"), _positive(width, "width")
    speed = _positive(speed, "speed")
    if separation + width > 0.8:
        raise InvalidInputError(f"separation: {separation} m apart, {width} m wide: the slits must fit in the 1 m tank (separation + width <= 0.8)")
    if width > separation:
        raise InvalidInputError(f"width: {width} m is wider than the separation {separation} m: the slits would merge")
    nx, dx = (3 * n) // 2, 1.0 / n
    x = (np.arange(nx) + 0.5) * dx
    y = (np.arange(n) + 0.5) * dx
    wall = np.zeros((nx, n), dtype=bool)
    col = int(0.35 / dx)
    wall[col:col + 2, :] = True
    for yc in (0.5 - separation / 2, 0.5 + separation / 2):
        wall[col:col + 2, np.abs(y - yc) < width / 2] = False
    if wall[col].all():
        raise InvalidInputError(f"width, n: the slits ({width} m) are narrower than a cell (1/n = {dx:.3g} m); raise n or the width")
    line = np.zeros((nx, n), dtype=bool)
    line[np.argmin(np.abs(x - 0.12)), :] = True
    if not math.isfinite(40.0 * speed / wavelength):
        raise InvalidInputError(f"wavelength, speed: the source's frequency speed/wavelength = {speed / wavelength:g} Hz is beyond float64")
    source = Oscillator(amplitude=40.0 * speed / wavelength, frequency=speed / wavelength, region=line)
    scene = Scene(2, dt=1e-3 if dt is None else dt, threads=threads)
    layer = max(4, n // 10)
    tank = scene.add(Wave((nx, n), dx, c=speed, edges="fixed", absorbing=True, layer=layer, mask=wall, oscillators=[source], name="tank"))
    if dt is None:
        scene.dt = _cfl_step(tank, "speed")
    return scene


double_slit.render_defaults = {"frames": 100, "fps": 25, "frame_time": 1 / 25, "substeps": "auto", "size": (480, 320), "style": "signed"}


def turing(
    preset: str = "maze",
    *,
    n: int = 256,
    duration: float = 4500.0,
    seeds: int = 2,
    seed: int = 1,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Turing patterns: Gray–Scott reaction–diffusion grows spots, stripes or mazes.

    :class:`~physcore.grids.GrayScott` from Pearson's start on his 2.5 × 2.5 periodic domain (n × n cells,
    D_u = 2e-5, D_v = 1e-5), with `seeds` perturbed squares (seeded) and the (F, k) of `preset`
    (:data:`physcore.grids.PRESETS`: spots, mitosis, stripes, maze, coral, holes, chaos).
    The animation spans `duration` time units: by default the maze grows from two seeds until
    it fills the domain, at about 4500. Steps are at most 1 time unit (the reaction's accuracy;
    Pearson's step) and within the diffusion limit, so coarse grids stay stable.
    """
    from .grids import PRESETS, GrayScott

    if not isinstance(preset, str):
        raise InvalidTypeError(f"preset: expected a name ({', '.join(PRESETS)}), got {type(preset).__name__}")
    if preset not in PRESETS:
        raise InvalidInputError(f"preset: unknown {preset!r}; valid: {', '.join(PRESETS)}")
    n = _count(n, "n", 16)
    _cells("n", n * n)
    duration = _positive(duration, "duration")
    scene = Scene(2, dt=1.0 if dt is None else dt, threads=threads)
    dx = 2.5 / n
    # The automatic step keeps a fraction of the diffusion limit dx²/(4 D_u), which grows as dx²:
    # on coarse grids (n <= 64: 76 time units at n = 32) it would step straight over the
    # reactions (rates ~1) and diverge; cap the step at 1, the reaction's accuracy.
    cfl = min(0.8, 1.0 / (dx * dx / (4 * 2e-5)))
    gs = scene.add(GrayScott((n, n), dx, preset=preset, cfl=cfl, name="turing"))
    if dt is None:
        scene.dt = gs.cfl * gs.diffusion_limit
    gs.seed(_check.int_in_range("seed", seed, 0, 2**63 - 1), squares=_check.int_in_range("seeds", seeds, 1, 1000), size=0.06)
    scene.render_defaults = {"frame_time": duration / 119}
    return scene


# The default duration (4500) over 119 frame steps: the maze grows until the last frame.
turing.render_defaults = {"frames": 120, "fps": 30, "frame_time": 4500.0 / 119, "substeps": "auto", "size": (400, 400)}


def smoke(
    n: int = 128,
    *,
    buoyancy: float = 4.0,
    vorticity: float = 0.3,
    obstacle: bool = True,
    tracers: int = 0,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Smoke: a hot plume rises from a vent and curls around a disc.

    The box is 1 m × 1.5 m (n × 1.5n cells, free-slip walls); the smoke is lifted by `buoyancy` (β, m/s² per unit
    temperature) and curled by vorticity confinement (ε = `vorticity`), around a disc
    (`obstacle`), with `tracers` passive particles (:class:`~physcore.grids.StableFluid`; none by
    default: drawn as single pixels over the smoke they read as noise).
    """
    from .grids import Source, StableFluid

    n = _count(n, "n", 16)
    _cells("n", (3 * n * n) // 2, arrays=40)
    buoyancy = _nonneg(buoyancy, "buoyancy")
    vorticity = _nonneg(vorticity, "vorticity")
    obstacle = _flag(obstacle, "obstacle")
    tracers = _check.int_in_range("tracers", tracers, 0, 1 << 20)
    ny, dx = (3 * n) // 2, 1.0 / n
    mask = None
    if obstacle:
        x = (np.arange(n) + 0.5) * dx
        y = (np.arange(ny) + 0.5) * dx
        mask = (x[:, None] - 0.45) ** 2 + (y[None, :] - 0.55) ** 2 < 0.09**2
    vent = Source(density=1.0, temperature=1.0, velocity=(0.0, 0.3), center=(0.5, 0.08), radius=0.06)
    scene = Scene(2, dt=1e-2 if dt is None else dt, threads=threads)
    scene.add(
        StableFluid(
            (n, ny), dx, buoyancy=(0.0, buoyancy), vorticity=vorticity, obstacles=mask, sources=[vent], tracers=tracers,
            tolerance=1e-6, name="smoke",
        )
    )
    return scene


smoke.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "substeps": "auto", "size": (320, 480)}


def cavity(
    n: int = 64,
    *,
    reynolds: float = 100.0,
    tracers: int = 0,
    dye: int = 6,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """The lid-driven cavity: a box of fluid stirred by its sliding top wall.

    A unit square whose top wall slides at 1 m/s (no-slip walls), at Reynolds number
    `reynolds` = U L / ν (:class:`~physcore.grids.StableFluid`). At
    Re = 100 the steady centreline profile is Ghia, Ghia & Shin (1982), Table I. The fluid starts
    at rest with `dye` horizontal bands of dye (its ``density``, 0 or 1; 0: none), which the
    vortex winds into a spiral as it spins up; drawn as that dye. `tracers` passive particles
    (spread over the box) can show the circulation too.
    """
    from .grids import StableFluid

    n = _count(n, "n", 8)
    _cells("n", n * n, arrays=40)
    reynolds = _positive(reynolds, "reynolds")
    if not math.isfinite(1.0 / reynolds):
        raise InvalidInputError(f"reynolds: {reynolds:g} makes the viscosity 1/Re overflow float64")
    tracers = _check.int_in_range("tracers", tracers, 0, 1 << 20)
    dye = _check.int_in_range("dye", dye, 0, n)
    scene = Scene(2, dt=1e-2 if dt is None else dt, threads=threads)
    box = scene.add(
        StableFluid(
            (n, n), 1.0 / n, nu=1.0 / reynolds, walls="no_slip", lid=1.0, advection="maccormack",
            tracers=tracers, tolerance=1e-8, name="cavity",
        )
    )
    if dye:
        y = (np.arange(n) + 0.5) / n
        band = np.floor(y * (2 * dye)) % 2 == 1  # 2·dye equal layers, every other one dyed
        box.density = np.broadcast_to(band.astype(np.float64)[None, :], (n, n)).copy()
    return scene


# 12 s of the spin-up from rest in 3.6 s: the dye winds into the vortex to the last frame.
cavity.render_defaults = {
    "frames": 90, "fps": 25, "frame_time": 0.135, "substeps": "auto", "size": (400, 400), "field": "density", "style": "turing",
}


def lorenz(
    n: int = 600,
    *,
    kind: str = "lorenz",
    spread: float = 0.5,
    seed: int = 7,
    integrator: str = "rk4",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """A strange attractor painted by a cloud of points (Lorenz's by default).

    `n` points start in a ball of radius `spread` near the attractor and chaos stretches them
    over it, each drawn as a glowing streak that fades (the render's ``trail``: 600 streaks draw
    the butterfly's sheets and holes, where 40 000 dots blurred into one fuzzy blob)
    (:class:`~physcore.flows.Flow`; the
    Lorenz system by default, ``kind="rossler"``, ``"thomas"``, ``"aizawa"`` or ``"halvorsen"``
    for the others). `integrator` is the flow's Runge–Kutta method (``"rk4"``, ``"euler"``,
    ``"heun"`` or ``"dopri5"``); ``dt=None`` takes the flow's default step.
    """
    from .flows import _METHODS, FLOWS, Flow

    n = _count(n, "n", 1)
    if not isinstance(kind, str) or kind not in FLOWS or FLOWS[kind]["dim"] != 3:
        raise InvalidInputError(f"kind: expected one of {', '.join(k for k, v in FLOWS.items() if v['dim'] == 3)}, got {kind!r}")
    if not isinstance(integrator, str) or integrator not in _METHODS:
        raise InvalidInputError(f"integrator: the flow's method must be one of {', '.join(_METHODS)}, got {integrator!r}")
    spread = _nonneg(spread, "spread")
    seed = _count(seed, "seed", 0)
    step = FLOWS[kind]["max_dt"] if dt is None else _positive(dt, "dt")
    # Last, once every other argument is checked: a point is 3 float64 coordinates, a snapshot
    # of them and the rate field read for colouring (about 72 B), not a particle's 512 B.
    _check.memory("n", 72 * n, f"{_big(n)} flow points")
    scene = Scene(3, integrator="rk4" if integrator == "rk4" else "verlet", dt=step, threads=threads)
    scene.add(Flow(kind, n, spread=spread, seed=seed, method=integrator))
    # Frames every 6 steps of the default dt (0.03 time units for Lorenz): the streaks stay smooth
    # and the 150 frames reach t = 4.5, when the cloud has spread over the whole attractor.
    scene.render_defaults = {"steps_per_frame": max(1, round(6 * FLOWS[kind]["max_dt"] / step))}
    return scene


lorenz.render_defaults = {
    "frames": 150, "fps": 30, "steps_per_frame": 6, "size": (480, 400), "view": (-80.0, 8.0), "radius": 1,
    "speed_unit": "(flow units)", "theme": "dark", "color_by": "density",  # glow: the cloud paints the attractor
    "trail": 30,  # a second of fading streaks behind each point (a still camera: a turning one would smear them)
}


# --------------------------------------------------------------------------- grains (DEM)
def _grain_scene(dt: float | None, integrator: str | None, threads: int | None) -> Scene:
    if integrator is not None and not isinstance(integrator, str):
        raise InvalidTypeError(f"integrator: expected a string or None, got {type(integrator).__name__}")
    if integrator not in (None, "semi_implicit_euler"):
        raise InvalidInputError(f"integrator: the grain scenes step with 'semi_implicit_euler' (the DEM scheme), got {integrator!r}")
    return Scene(2, integrator="semi_implicit_euler", dt=1e-4 if dt is None else dt, threads=threads)


def _auto_grain_dt(scene: Scene, dt: float | None, factor: float = 1.0) -> Scene:
    """The scene with dt = `factor` × its contacts' automatic step (a 50th of the contact
    duration) unless `dt` was given."""
    if dt is None:
        scene.dt = factor * scene.suggest_dt()
    return scene


def galton_board(
    balls: int = 120,
    *,
    rows: int = 8,
    restitution: float = 0.69,
    friction: float = 0.0,
    seed: int = 0,
    spacing: float = 12.0,
    width: float = 0.1,
    drag: float = 4e-3,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Galton board in a viscous liquid: a queue of balls sinks at terminal speed onto `rows`
    staggered rows of pegs and piles up in bins.

    2D; balls of radius 2 mm and 0.26 g, pegs of radius 2.3 mm spaced 9 mm (rows 7.8 mm apart,
    gaps of 1.1 ball diameters), linear contacts (:class:`~physcore.Contacts`, k = 10³ N/m)
    with the given restitution and friction; the pegs and the bins' dividers (columns of
    grains of radius 0.8 mm, 2.4 mm apart) are pinned grains, the floor and sides are walls.
    The board is `width` metres wide (at least rows + 1 pitches); the bins are deep enough for
    the binomial's fullest bin plus three of its standard deviations.

    The balls start at rest in one vertical column above the top peg, `spacing` ball diameters
    apart (a hair off the axis, by up to 0.02 radii, from `seed`). The board stands in a liquid,
    modelled as linear `drag` b (kg/s; a sphere's Stokes drag 6πηr at η ≈ 0.1 Pa·s, a
    water–glycerol mix; buoyancy left out): every ball sinks at the same terminal speed
    v = m g / b (0.64 m/s by default), so none catches up with the one below and they reach
    the pegs one by one, every spacing·2r / v (75 ms by default), all at that speed. Glycerine
    Galton boards are classroom demonstrations.

    An ideal board sends each ball left or right at every row, so its bin is
    Binomial(rows, ½) (Galton, *Natural Inheritance*, 1889), of variance rows/4 bins². This one
    comes close only by calibration: the spread depends steeply on restitution and drag
    (isolated balls, 8 rows, v = 0.64 m/s: variance 0.55 / 2.5 / 2.6 bins² at restitution
    0.6 / 0.75 / 0.9; at v = 1 m/s balls hop across columns, 4–6 bins²). The default stream (8 rows, 120 balls,
    seeds 0–3) gives variance 1.52–1.97 bins² (mean 1.72) at restitution 0.69, 1.75–2.65
    (mean 2.23, seeds 0–5) at 0.70 and 1.59–2.06 at 0.68, against the binomial's 2.0; the
    test suite's variance and Pearson χ² tests (160 balls, significance 0.001) pass at the
    default. A ball takes about 0.9 s through the pegs, so several are on the board at once.
    Other restitutions, drags and spacings give other spreads. With friction balls can rest
    on the pegs. Particles: the balls first (indices
    0..balls-1), then the fixed ones; :func:`galton_bins` counts the balls per bin.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    balls = _check.int_in_range("balls", balls, 1, 1 << 40)  # the particle count is then checked in float
    rows = _count(rows, "rows", 1)
    if rows > 40:
        raise InvalidInputError(f"rows: at most 40, got {rows}")
    restitution = _check.float_in_range("restitution", restitution, 0.0, 1.0)
    if restitution == 0.0:
        raise InvalidInputError("restitution: must be > 0 (a dashpot cannot stop a ball dead)")
    friction = _nonneg(friction, "friction")
    seed = _count(seed, "seed", 0)
    spacing = _check.float_in_range("spacing", spacing, 1.5, 50.0)
    width = _check.float_in_range("width", width, 0.02, 10.0)
    # Up to 1 kg/s: the balls' speed then relaxes in m/b = 0.26 ms, still 50 steps; beyond, the
    # automatic step would follow the drag down (1e303 kg/s made it subnormal).
    # > 0: the queue sinks at the terminal speed m g / drag.
    drag = _check.float_in_range("drag", drag, 0.0, 1.0, lo_open=True)
    dt = _optional(dt, "dt")
    # A tight lattice: gaps of 1.1 ball diameters, so a ball leaving a peg drops into the gap
    # beside it onto the peg below (with wider gaps, 1.9 d, balls skipped columns).
    rb, s, mass = 0.002, 0.009, 2.6e-4
    d = 2 * rb
    rp = 0.5 * (s - 1.1 * d)
    h = s * math.sqrt(3.0) / 2.0
    half = max(0.5 * (rows + 1) * s, 0.5 * width)  # the board spans x in [-half, half]
    r_g, p = 0.0008, 0.0024  # the dividers' grains, 0.8 mm gaps (a ball cannot pass)
    # The fullest bin of Binomial(rows, ½) plus 3 standard deviations, about 1.5 mm a ball (two
    # abreast in the 7.4 mm between dividers; measured), and a margin.
    full = balls * math.comb(rows, rows // 2) / 2.0**rows
    bin_depth = max(0.03, 0.0018 * (full + 3 * math.sqrt(full) + 3))
    _particles("balls, rows, width", balls + (2 * half / s + 1) * rows + (2 * half / s + 1) * bin_depth / p)
    fixed: list[tuple[float, float, float]] = []
    # Staggered rows across the whole width: row k has pegs at x = (j − k/2)·s, so a ball above
    # peg 0 of row 0 is shifted by ±s/2 a row.
    n_across = int(half / s) + rows + 2
    for k in range(rows):
        for j in range(-n_across, n_across + 1):
            x = (j - 0.5 * k) * s
            if abs(x) <= half + 1e-9:
                fixed.append((x, -k * h, rp))
    # Bins: dividers between the landing places (m − rows/2)s, from just under the last row.
    y_top_bins = -rows * h + 0.5 * h
    y_floor = y_top_bins - bin_depth
    for m in range(-n_across, n_across + 1):
        x = (m - 0.5 * rows - 0.5) * s
        if abs(x) < half - r_g:
            fixed.extend((x, float(y), r_g) for y in np.arange(y_top_bins - r_g, y_floor, -p))
    # The queue: ball i at rest 3 d above the top peg plus i spacings.
    rng = np.random.default_rng(seed)
    b = np.zeros((balls, 2))
    b[:, 0] = rng.uniform(-0.02, 0.02, balls) * rb
    b[:, 1] = rp + rb + 3 * d + spacing * d * np.arange(balls)
    f = np.array(fixed)
    x = np.concatenate([b, f[:, :2]])
    radius = np.concatenate([np.full(balls, rb), f[:, 2]])
    pinned = np.arange(len(x)) >= balls
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, masses=mass, pinned=pinned)
    scene.set_attribute("radius", radius)
    scene.add(Gravity([0.0, -9.81]))
    scene.add(Drag(drag))
    scene.add(Contacts(stiffness=1e3, restitution=restitution, friction=friction,
                       walls=[Plane([0.0, y_floor], [0.0, 1.0], restitution=restitution, friction=friction),
                              Plane([-half, 0.0], [1.0, 0.0], restitution=restitution, friction=friction),
                              Plane([half, 0.0], [-1.0, 0.0], restitution=restitution, friction=friction)]))
    # Drawn as a diagram: grey pegs and dividers, balls in four warm hues, a pale liquid; the
    # camera holds the board (from the floor to 3 pitches above the top peg), so the queue
    # enters the picture ball by ball.
    hues = np.array(GALTON_COLORS, dtype=np.uint8)
    colors = np.concatenate([hues[np.arange(balls) % len(hues)], np.full((len(f), 3), 125, np.uint8)])
    scene.render_defaults = {"galton": {"balls": balls, "rows": rows, "pitch": s},
                             "colors": colors.tolist(),  # plain lists: render_defaults compare with ==
                             "extent": ((-half, y_floor), (half, rp + 3 * s))}
    return _auto_grain_dt(scene, dt)


GALTON_COLORS = ((230, 120, 30), (214, 62, 48), (240, 175, 40), (190, 80, 120))  # RGB: amber, red, gold, plum

# 10.2 s of simulated time at 1.6× speed: the default queue's last ball lands at about 10 s.
galton_board.render_defaults = {"antialias": True, "frames": 154, "fps": 25, "frame_time": 1 / 15, "size": (300, 560),
                                "size_by": "radius", "color_by": "none", "background": (226, 236, 244)}


def galton_bins(scene: Scene) -> np.ndarray:
    """Balls per bin of a :func:`galton_board` scene now: (rows + 1,) int64, bin m holding the
    balls that turned right m times (below the last row of pegs); balls still above are not
    counted."""
    g = (getattr(scene, "render_defaults", None) or {}).get("galton")
    if not g:
        raise InvalidInputError("scene: not a galton_board scene")
    x = scene.positions[: g["balls"]]
    rows, s = g["rows"], g["pitch"]
    below = x[:, 1] < -rows * s * math.sqrt(3.0) / 2.0 + 0.25 * s
    m = np.clip(np.rint(x[below, 0] / s + 0.5 * rows), 0, rows).astype(np.int64)
    return np.bincount(m, minlength=rows + 1)


def billiards(
    *,
    speed: float = 6.0,
    restitution: float = 0.93,
    cushion: float = 0.75,
    seed: int = 0,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Billiards break: a cue ball at `speed` (m/s) into a rack of 15 balls, seen from above.

    Pool balls (radius 28.6 mm, 170 g) on a 2.54 × 1.27 m table, Hertz contacts
    (:class:`~physcore.Contacts`, so the touching rack passes the impulse through like a real
    one) with ball–ball `restitution` and friction 0.05, cushions of restitution `cushion`;
    the cloth's rolling resistance as linear drag 0.05 kg/s (speeds decay over m/b = 3.4 s,
    so the balls still roll at the end of the 5 s animation). No pockets. Drawn on felt, each
    ball in its colour (stripes in a lighter shade of their solid). `seed`
    offsets the cue by a fraction of a millimetre, so each seed breaks differently.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    speed = _positive(speed, "speed")
    if speed > 50:
        raise InvalidInputError(f"speed: at most 50 m/s (a cue ball's record is about 15), got {speed}")
    restitution = _check.float_in_range("restitution", restitution, 1e-3, 1.0)
    cushion = _check.float_in_range("cushion", cushion, 1e-3, 1.0)
    seed = _count(seed, "seed", 0)
    dt = _optional(dt, "dt")
    r, m, L, W = 0.028575, 0.17, 2.54, 1.27
    rack = []
    apex = np.array([0.75 * L, 0.5 * W])
    for row in range(5):
        for k in range(row + 1):
            rack.append(apex + [row * 2 * r * math.sqrt(3) / 2 * 1.0005, (k - row / 2) * 2 * r * 1.0005])
    rng = np.random.default_rng(seed)
    cue = np.array([0.25 * L, 0.5 * W + rng.uniform(-5e-4, 5e-4)])
    x = np.array([cue, *rack])
    v = np.zeros_like(x)
    v[0, 0] = speed
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, v, masses=m)
    scene.set_attribute("radius", np.full(len(x), r))
    scene.add(Drag(0.05))
    scene.add(Contacts(stiffness=5e9, restitution=restitution, friction=0.05, law="hertz",
                       walls=Box([0.0, 0.0], [L, W], restitution=cushion, friction=0.2)))
    # Drawn as the table is: each ball its own colour (the cue white; the 1 ball at the apex,
    # the 8 in the middle of the third row), on felt.
    scene.render_defaults = {"colors": [_POOL_COLORS[k] for k in (0, 1, 9, 2, 10, 8, 3, 11, 4, 12, 5, 6, 13, 14, 7, 15)],
                             "background": (28, 110, 60)}
    return _auto_grain_dt(scene, dt)


#: Pool balls' colours (RGB) by number, 0 the cue ball: the solids 1–7, the 8 and the stripes
#: 9–15 drawn in their solid's colour, lightened (a disc has no stripe).
_POOL_COLORS = {0: (246, 244, 236), 1: (250, 200, 30), 2: (30, 70, 190), 3: (215, 35, 35), 4: (120, 50, 160),
                5: (245, 125, 25), 6: (20, 150, 80), 7: (140, 35, 30), 8: (18, 18, 18)}
_POOL_COLORS.update({k + 8: tuple(int(c + 0.35 * (255 - c)) for c in _POOL_COLORS[k]) for k in range(1, 8)})


billiards.render_defaults = {"antialias": True, "frames": 150, "fps": 30, "frame_time": 1 / 30, "size": (480, 260),
                             "size_by": "radius", "trail": 12, "color_by": "none"}


def newtons_cradle(
    balls: int = 5,
    *,
    lift: int = 1,
    angle: float = 30.0,
    law: str = "hertz",
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Newton's cradle: `balls` steel balls (radius 2 cm, 0.26 kg) hanging touching on 40 cm
    strings, the first `lift` pulled out by `angle` degrees and let go.

    The strings are stiff springs (stretch 0.01 % under a ball's weight) from pinned anchors
    (radius 2.5 mm, 40 cm above the balls: they touch nothing); the balls touch through :class:`~physcore.Contacts`
    with the `law` given and restitution 0.999. With ``law="hertz"`` the impulse runs through
    the row as a solitary wave and as many balls leave the far end as were let go; the linear
    law spreads it (try ``--param law=linear``).

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    balls = _count(balls, "balls", 2)
    if balls > 50:
        raise InvalidInputError(f"balls: at most 50, got {balls}")
    lift = _count(lift, "lift", 1)
    if lift >= balls:
        raise InvalidInputError(f"lift: must be less than balls ({balls}), got {lift}")
    angle = _check.float_in_range("angle", angle, 0.0, 80.0)
    law = _check.choice("law", law, ("hertz", "linear"))
    dt = _optional(dt, "dt")
    r, m, L = 0.02, 0.26, 0.4
    k_string = m * 9.81 / (1e-4 * L)
    th = math.radians(angle)
    anchors = np.array([[2 * r * i, 0.0] for i in range(balls)])
    hang = anchors + [0.0, -L]
    for i in range(lift):  # the lifted ones swing out together, still touching
        hang[i] = anchors[i] + L * np.array([-math.sin(th), -math.cos(th)])
    x = np.concatenate([hang, anchors])
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(x, masses=m, pinned=np.arange(2 * balls) >= balls)
    # The anchors are small pivots (2.5 mm, drawn as marks): 4 cm apart and 40 cm above the
    # balls, they touch nothing.
    scene.set_attribute("radius", np.concatenate([np.full(balls, r), np.full(balls, 0.125 * r)]))
    scene.add(Gravity([0.0, -9.81]))
    scene.add(Springs(np.arange(balls), np.arange(balls, 2 * balls), stiffness=k_string, damping=0.0, rest_length=L))
    stiffness = 5e9 if law == "hertz" else 1e6
    scene.add(Contacts(stiffness=stiffness, restitution=0.999, friction=0.0, law=law))
    # Steel balls on dark pivots (the impulse shows in the balls' motion, not in a colour map).
    scene.render_defaults = {"colors": [(140, 148, 162)] * balls + [(60, 60, 66)] * balls}
    return _auto_grain_dt(scene, dt)


newtons_cradle.render_defaults = {"antialias": True, "frames": 150, "fps": 30, "frame_time": 1 / 30, "size": (400, 360),
                                  "size_by": "radius", "color_by": "none"}


def jelly(
    n: int = 12,
    *,
    size: float = 0.3,
    mass: float = 1.0,
    stiffness: float = 60.0,
    damping: float = 0.02,
    height: float = 0.6,
    spin: float = 3.0,
    integrator: str | None = None,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Jelly: a soft square (n×n particles on springs) dropped, turning, on a floor in a box.

    2D. The body is the cloth's spring network (structural, shear and bend springs of
    `stiffness` N/m and `damping` N·s/m, rest lengths as built) over `mass` kg; its particles
    are grains of radius half their spacing under :class:`~physcore.Contacts` (k = 4·10⁴ N/m,
    restitution 0.3, friction 0.6), so it lands, squashes, rolls and wobbles on the floor and
    walls, and cannot fold through itself. It falls from `height` m with angular velocity
    `spin` rad/s. Drawn as a shaded surface (:class:`~physcore.render.Mesh`) coloured by its
    springs' strain.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    if n > 100:
        raise InvalidInputError(f"n: at most 100, got {n}")
    size = _check.float_in_range("size", size, 0.01, 10.0)
    mass = _check.float_in_range("mass", mass, 1e-6, 1e6)
    stiffness = _check.float_in_range("stiffness", stiffness, 1e-3, 1e7)
    # Bounded like the stiffness: the automatic step falls as 1/damping (3e303 gave dt = 2e-308).
    damping = _check.float_in_range("damping", damping, 0.0, 1e6)
    height = _check.float_in_range("height", height, 0.0, 100.0)
    spin = _check.float_in_range("spin", spin, -100.0, 100.0)
    s = size / (n - 1)
    m = mass / (n * n)
    g = (np.arange(n) - 0.5 * (n - 1)) * s
    gx, gy = np.meshgrid(g, g)
    local = np.stack([gx.ravel(), gy.ravel()], axis=1)
    th = 0.5
    rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    r = local @ rot.T
    centre = np.array([0.0, height + 0.75 * size])
    v = spin * np.stack([-r[:, 1], r[:, 0]], axis=1) + np.array([0.4, 0.0])
    scene = _grain_scene(dt, integrator, threads)
    scene.add_particles(centre + r, v, masses=m)
    scene.set_attribute("radius", np.full(n * n, 0.5 * s))
    i, j = cloth_springs(n)
    scene.add(Springs(i, j, stiffness=stiffness, damping=damping))
    scene.add(Gravity([0.0, -9.81]))
    # tangential_ratio 2/7 (the disc default is 1/3): its grains are nodes of one soft body, not
    # rolling discs, and at 1/3 its wobble faded to 0.20 of the motion by the end (gallery budget
    # 0.3); 2/7 keeps the look the gallery was measured with.
    scene.add(Contacts(stiffness=4e4, restitution=0.3, friction=0.6, tangential_ratio=2.0 / 7.0,
                       walls=Box([-2.0 * size, 0.0], [2.0 * size, height + 3.0 * size], restitution=0.3, friction=0.6)))
    # A raspberry jelly: its own colour on the shaded sheet (--color-by strain shows the strain).
    scene.render_defaults = {"mesh": Mesh.grid(n, n), "colors": [(214, 40, 90)] * (n * n)}
    # A 100th of a contact: the dashpots' rectangle-rule books then stay within 1e-3 of the
    # energy over the fall and the bounces (1.2e-3 at a 50th).
    return _auto_grain_dt(scene, dt, 0.5)


# 1.9 s: the fall, the landing and the roll to the wall, cut while it still rocks (it is at rest
# by about 3 s; the strain colours flicker on, so a GIF to rest would end on a long fade).
jelly.render_defaults = {"antialias": True, "frames": 57, "fps": 30, "frame_time": 1 / 30, "size": (400, 320),
                         "color_by": "none"}


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
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise InvalidTypeError(f"{arg}: expected a pair of numbers, got {type(value).__name__}")
    out = tuple(_check.finite(arg, v) for v in value)
    return out[0], out[1]


# 10 s at 30 fps, one simulated second a second: together for 3–4 s, then the fan.
double_pendulum.render_defaults = {"antialias": True, "frames": 300, "fps": 30, "frame_time": 1 / 30,
                                   "size": (400, 400), "color_by": "none", "theme": "dark", "radius": 3}


def vortex_street(
    n: int = 10,
    *,
    reynolds: float = 120.0,
    length: float = 22.0,
    height: float = 10.0,
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """A von Kármán vortex street: water flowing past a cylinder sheds vortices, drawn by dye.

    A channel `length` × `height` cylinder diameters (D = 1 cm) with a uniform inflow U = 1 cm/s
    on the left and an open outflow on the right (``StableFluid(inflow=U)``: pressure 0, zero
    normal gradient), free-slip top and bottom walls, and a no-slip cylinder (a disc of solid
    cells, `n` cells across) 5 D downstream of the inlet on the centre line. The viscosity is
    ν = U D / `reynolds` (m²/s; Re = 100 is water's 1e-6 m²/s), so times are in units of
    D/U = 1 s. Streaks of dye (the fluid's ``density``, 0 or 1, in bands D/4 wide)
    enter through the inlet within 2.5 D of the centre line and start laid through the whole
    channel; a small asymmetric puff of transverse velocity behind the cylinder at t = 0
    (v ≤ U/2, a Gaussian of width D/2, 1.5 D downstream) starts the shedding within a few
    periods instead of waiting for round-off.

    Above Re ≈ 47 the wake sheds vortices alternately from either side at the Strouhal number
    St = f D / U, which Roshko (1954, NACA Report 1191) measured as
    St = 0.212 (1 − 21.2 / Re) for 50 < Re < 150 (reviewed by Williamson 1996, Annu. Rev.
    Fluid Mech. 28, 477). The walls confine the flow: the blockage D/H = 1 / `height`
    (0.1 by default) raises St slightly above the unbounded value; tests/grids/test_vortex_street.py
    measures St against Roshko's curve at the default blockage and at 1/16.

    Parameters
    ----------
    n : int
        Cells per cylinder diameter (≥ 4; the channel is round(length·n) × round(height·n)).
    reynolds : float
        Re = U D / ν (> 0; the street forms for 47 ≲ Re ≲ 190, where the 2D flow is laminar).
    length, height : float
        The channel in diameters (length ≥ 8, height ≥ 3).

    Raises
    ------
    TypeError, InvalidInputError
        Naming the argument (a non-integer `n`, a non-positive `reynolds`, a channel too short
        or too low for the cylinder, or a grid too large for memory).
    """
    from .grids import Source, StableFluid

    # A grid has at most 2**20 cells a side: a larger n is refused here, by name, before
    # length · n overflows float64 (n = 10**400 raised OverflowError).
    n = _check.int_in_range("n", n, 4, 1 << 20)
    reynolds = _positive(reynolds, "reynolds")
    length, height = _positive(length, "length"), _positive(height, "height")
    if length < 8.0:
        raise InvalidInputError(f"length: the channel must be at least 8 diameters long (5 D of inlet), got {length:g}")
    if height < 3.0:
        raise InvalidInputError(f"height: the channel must be at least 3 diameters high, got {height:g}")
    # Checked in float before any int(): length · n beyond float64 is refused by name (found by
    # the scene fuzz: 1.8e307 diameters overflowed the conversion).
    _cells("n, length, height", length * n * height * n, arrays=40)
    nx, ny = int(round(length * n)), int(round(height * n))
    D, U = 0.01, 0.01
    dx = D / n
    nu = U * D / reynolds
    if not (math.isfinite(nu) and nu > 0):
        raise InvalidInputError(f"reynolds: {reynolds:g} gives no finite viscosity U·D/Re > 0")
    xc, yc = 5.0 * D, 0.5 * ny * dx
    x = (np.arange(nx) + 0.5) * dx
    y = (np.arange(ny) + 0.5) * dx
    cylinder = (x[:, None] - xc) ** 2 + (y[None, :] - yc) ** 2 < (0.5 * D) ** 2
    # Streaks: bands D/4 wide, every other one dyed, within 2.5 D of the centre line.
    yy = y - yc
    streak = (np.abs(yy) < 2.5 * D) & (np.floor(yy / (0.25 * D)) % 2 == 0)
    inlet = np.zeros((nx, ny), bool)
    inlet[0] = True
    dyed, clear = inlet & streak[None, :], inlet & ~streak[None, :]
    sources = [Source(density=1.0, velocity=(U, 0.0), region=dyed), Source(density=0.0, velocity=(U, 0.0), region=clear)]
    scene = Scene(2, dt=0.5 * dx / U if dt is None else dt, threads=threads)
    fluid = scene.add(
        StableFluid(
            (nx, ny), dx, nu=nu, advection="maccormack", inflow=U, obstacles=cylinder, sources=sources,
            tolerance=1e-6, name="channel",
        )
    )
    X, Y = np.meshgrid(x, np.arange(ny + 1) * dx, indexing="ij")
    kick = 0.5 * U * np.exp(-((X - xc - 1.5 * D) ** 2 + (Y - yc) ** 2) / (2 * (0.5 * D) ** 2))
    fluid.set_velocity(np.full((nx + 1, ny), U), kick)
    fluid.density = np.broadcast_to(streak[None, :].astype(np.float64), (nx, ny)) * ~cylinder
    return scene


vortex_street.render_defaults = {
    "frames": 100, "fps": 25, "frame_time": 0.6, "substeps": "auto", "size": (528, 240), "field": "density", "style": "smoke",
}


def _stamped(fn: Callable[..., Scene], **deprecated: Any) -> Callable[..., Scene]:
    """`fn` returning scenes that carry its ``render_defaults`` (so ``render.gif(scene)`` shows
    the motion ``physcore render NAME`` shows); same name, docs, signature and attributes.
    ``deprecated``: the old spellings it still takes this release (see :func:`_deprecate.args`)."""
    if deprecated:
        fn = _deprecate.args(name=fn.__name__, **deprecated)(fn)

    @functools.wraps(fn)
    def scene_function(*args: Any, **kwargs: Any) -> Scene:
        scene = fn(*args, **kwargs)
        own = scene.render_defaults or {}  # what the function set from its arguments
        scene.render_defaults = {**fn.render_defaults, **own}  # type: ignore[attr-defined]
        return scene

    # Old keyword names the CLI's --param still takes this release (old -> new; new None: ignored).
    scene_function.deprecated_params = {  # type: ignore[attr-defined]
        **deprecated.get("renames", {}), **dict.fromkeys(deprecated.get("ignored", ()))
    }
    return scene_function


cloth = _stamped(cloth, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'air_drag', 'pin', 'ground', 'integrator', 'dt', 'threads'), keep=1)
projectile = _stamped(projectile, old_order=('n', 'speed', 'drag', 'restitution', 'ground', 'integrator', 'dt', 'threads'), keep=1)
kepler = _stamped(kepler, old_order=('e', 'a', 'mass_ratio', 'steps_per_orbit', 'integrator', 'dt', 'threads'), keep=1)
figure_eight = _stamped(figure_eight, old_order=('steps_per_period', 'integrator', 'dt', 'threads'), keep=0)
pythagorean = _stamped(pythagorean, old_order=('rtol', 'integrator', 'dt', 'threads'), keep=0)
galaxies = _stamped(galaxies, old_order=('n', 'pericentre', 'prograde', 'theta', 'softening', 'seed', 'integrator', 'dt', 'threads'), keep=1)
cyclotron = _stamped(cyclotron, old_order=('n', 'B', 'E', 'seed', 'integrator', 'dt', 'threads'), keep=1)
spring_chain = _stamped(spring_chain, old_order=('n', 'length', 'mass', 'stiffness', 'damping', 'dim', 'integrator', 'dt', 'threads'), keep=1)
_SPH_RENAMES = {"viscosity": "alpha", "precision": "pass_precision"}
dam_break = _stamped(dam_break, renames=_SPH_RENAMES)
drop = _stamped(drop, renames=_SPH_RENAMES)
droplets = _stamped(droplets, renames={"viscosity": "alpha"})
crown = _stamped(crown, renames={"viscosity": "alpha"})
ripple = _stamped(ripple, old_order=('n', 'drops', 'speed', 'damping', 'seed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
double_slit = _stamped(double_slit, old_order=('n', 'wavelength', 'separation', 'width', 'speed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
turing = _stamped(turing, old_order=('preset', 'n', 'duration', 'seeds', 'seed', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
smoke = _stamped(smoke, old_order=('n', 'buoyancy', 'vorticity', 'obstacle', 'tracers', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
cavity = _stamped(cavity, old_order=('n', 'reynolds', 'tracers', 'dye', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))
lorenz = _stamped(lorenz, old_order=('n', 'kind', 'spread', 'seed', 'integrator', 'dt', 'threads'), keep=1)
galton_board = _stamped(galton_board, old_order=('balls', 'rows', 'restitution', 'friction', 'seed', 'spacing', 'width', 'drag', 'integrator', 'dt', 'threads'), keep=1)
billiards = _stamped(billiards, old_order=('speed', 'restitution', 'cushion', 'seed', 'integrator', 'dt', 'threads'), keep=0)
newtons_cradle = _stamped(newtons_cradle, old_order=('balls', 'lift', 'angle', 'law', 'integrator', 'dt', 'threads'), keep=1)
jelly = _stamped(jelly, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'height', 'spin', 'integrator', 'dt', 'threads'), keep=1)
xpbd_cloth = _stamped(xpbd_cloth, old_order=('n', 'size', 'mass', 'compliance', 'bending_compliance', 'air_drag', 'pin', 'substeps', 'integrator', 'dt', 'threads'), keep=1)
tumbling_boxes = _stamped(tumbling_boxes, old_order=('n_boxes', 'particles_per_side', 'size', 'mass', 'restitution', 'friction', 'substeps', 'integrator', 'dt', 'threads'), keep=1)
cloth_on_ball = _stamped(cloth_on_ball, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'air_drag', 'radius', 'offset', 'height', 'friction', 'integrator', 'dt', 'threads'), keep=1)
double_pendulum = _stamped(double_pendulum)
vortex_street = _stamped(vortex_street, old_order=('n', 'reynolds', 'length', 'height', 'integrator', 'dt', 'threads'), keep=1, ignored=("integrator",))

#: Scene name → function, in the order ``physcore scenes`` lists them.
REGISTRY: dict[str, Callable[..., Scene]] = {
    "cloth": cloth,
    "projectile": projectile,
    "kepler": kepler,
    "figure_eight": figure_eight,
    "pythagorean": pythagorean,
    "galaxies": galaxies,
    "cyclotron": cyclotron,
    "spring_chain": spring_chain,
    "dam_break": dam_break,
    "drop": drop,
    "droplets": droplets,
    "crown": crown,
    "ripple": ripple,
    "double_slit": double_slit,
    "turing": turing,
    "smoke": smoke,
    "cavity": cavity,
    "lorenz": lorenz,
    "galton_board": galton_board,
    "billiards": billiards,
    "newtons_cradle": newtons_cradle,
    "jelly": jelly,
    "xpbd_cloth": xpbd_cloth,
    "tumbling_boxes": tumbling_boxes,
    "cloth_on_ball": cloth_on_ball,
    "double_pendulum": double_pendulum,
    "vortex_street": vortex_street,
}
DEFAULT_SCENE = "cloth"
