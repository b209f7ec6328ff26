"""Cloth scenes: mass-spring sheets (:func:`cloth`, :func:`cloth_on_ball`) and XPBD cloth
(:func:`xpbd_cloth`)."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from ..render import Mesh
from ..scene import Scene, _quiet_options
from ..shapes import cloth_springs, mesh_edges_and_hinges
from ..terms import Drag, Gravity, Plane, Sphere, Springs, XpbdConstraints
from ._common import (
    _count,
    _finite_books,
    _flag,
    _nonneg,
    _optional,
    _particle_mass,
    _particles,
    _positive,
    _set_stable_dt,
    _stamped,
)


def cloth(
    n: int = 40,
    *,
    size: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.1,
    air_drag: float = 0.5,
    pin: str = "corners",
    ground: bool = False,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Hanging cloth: an n×n mass-spring sheet pinned by two corners, falling and swinging
    under gravity.

    The sheet starts flat in the z = 0 plane (x, y in [0, size]); the two corners of the row
    y = 0 are pinned (``pin="corners"``) or that whole row (``pin="edge"``). Structural, shear and bend
    springs (stiffness N/m, dashpot damping N·s/m) join neighbours; gravity is (0, 0, -9.81) m/s²;
    linear air drag b = air_drag · m per particle (air_drag in 1/s; 0 turns it off).
    ``ground=True`` adds a floor at z = -0.8·size (restitution 0.1, friction 0.5), which the
    hanging sheet's lower fifth folds onto (the default render draws a floor well below the
    sheet's reach, a prop that takes no part). ``dt=None``
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
    # Drawn as a shaded sheet over its grid (render.Mesh.grid: rows of n, index row·n + col),
    # in a room of its size.
    scene.render_defaults = {"mesh": Mesh.grid(n, n), **_room(size, floor=not ground)}
    return _finite_books(scene, "size, mass")


def _gingham(light: tuple, dark: tuple, cells: int = 8, px: int = 8) -> list:
    """A gingham texture, (cells·px)² RGB as nested lists (render_defaults compare with ==):
    checks of `light`, half-tone bands of `dark` one way and the other, full `dark` where they
    cross (folds read in its lines)."""
    u = (np.arange(cells * px) // px) % 2
    w = 0.5 * (u[:, None] + u[None, :])
    a, b = np.array(light, np.float64), np.array(dark, np.float64)
    return np.rint(a * (1 - w)[..., None] + b * w[..., None]).astype(np.uint8).tolist()


def _room(size: float, floor: bool = True) -> dict:
    """Render defaults for a sheet of `size` m hanging from z = 0: a pale wall (a gradient
    backdrop) over a tiled floor 1.25·size below its pins, drawn as props (the floor takes no
    part in the physics: the sheet reaches 1.0·size below its pins, 1.1·size by XPBD), one
    polygon and its joints' lines (a few dozen props, drawn once); and the camera fitted to
    the sheet's swing (to 0.9·size and 1.0·size through) and the floor. ``floor=False``: the
    wall only (a scene with a ground collider, which the renderer draws itself)."""
    z, cell = -1.25 * size, 0.25 * size
    (x0, y0), (x1, y1) = (-1.5 * size, -2.0 * size), (2.5 * size, 4.0 * size)
    decor = [{"polygon": [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], "color": (212, 207, 197)}]
    decor += [{"line": [[x, y0, z], [x, y1, z]], "color": (184, 178, 168), "width": 1} for x in np.arange(x0, x1 + 0.5 * cell, cell)]
    decor += [{"line": [[x0, y, z], [x1, y, z]], "color": (184, 178, 168), "width": 1} for y in np.arange(y0, y1 + 0.5 * cell, cell)]
    return {"look": {"backdrop": ((226, 232, 240), (196, 204, 216)), "decor": decor if floor else []},
            "extent": ((-0.05 * size, -1.0 * size, z), (1.05 * size, 1.0 * size, 0.05 * size))}


#: The sheets' fabrics (blue and red gingham), seen in their room (:func:`_room`) from low
#: down, so that the wall shows above the floor.
_BLUE_GINGHAM = _gingham((250, 246, 238), (62, 104, 168))
_RED_GINGHAM = _gingham((250, 246, 238), (186, 58, 52))

# A gingham fabric (its lines show the folds and the swing) before a wall, over the floor.
cloth.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none",
                         "texture": _BLUE_GINGHAM, "view": (-60.0, 8.0)}
cloth = _stamped(cloth, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'air_drag', 'pin', 'ground', 'integrator', 'dt', 'threads'), keep=1)


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


# The floor's far edge shows over the ball: the cloth scenes' pale wall behind it (a gradient
# backdrop), not a white void.
cloth_on_ball.render_defaults = {"frames": 69, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none",
                                 "view": (-60.0, 25.0), "look": {"backdrop": ((226, 232, 240), (196, 204, 216))}}
cloth_on_ball = _stamped(cloth_on_ball, old_order=('n', 'size', 'mass', 'stiffness', 'damping', 'air_drag', 'radius', 'offset', 'height', 'friction', 'integrator', 'dt', 'threads'), keep=1)


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
    with _quiet_options():  # the scene's option is kept whatever the integrator
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
    scene.render_defaults = {"mesh": mesh, **_room(size)}
    return _finite_books(scene, "size, mass")


xpbd_cloth.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 360), "color_by": "none",
                              "texture": _RED_GINGHAM, "view": (-60.0, 8.0)}
xpbd_cloth = _stamped(xpbd_cloth, old_order=('n', 'size', 'mass', 'compliance', 'bending_compliance', 'air_drag', 'pin', 'substeps', 'integrator', 'dt', 'threads'), keep=1)
