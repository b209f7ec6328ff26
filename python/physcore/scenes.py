"""Ready-made scenes: functions returning a :class:`~physcore.Scene`. Each is also a CLI name
(``physcore render NAME``); keyword arguments are CLI ``--param key=value`` options.

Every function accepts ``integrator=`` and ``dt=`` (``None``: the scene's own choice) and
``threads=``. ``render_defaults`` on each function gives the CLI's animation defaults
(``frame_time`` is simulated seconds per frame).
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Optional

import numpy as np

from ._errors import InvalidInputError
from .scene import Scene, _check_int as _count
from .terms import Drag, Gravity, PairwiseGravity, Plane, Springs

__all__ = ["cloth", "projectile", "kepler", "spring_chain", "REGISTRY"]


def _positive(value: float, arg: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise InvalidInputError(f"{arg}: must be finite and > 0, got {value}")
    return value


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
    size: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.1,
    air_drag: float = 0.5,
    pin: str = "edge",
    ground: bool = False,
    integrator: str = "verlet",
    dt: Optional[float] = None,
    threads: Optional[int] = None,
) -> Scene:
    """Hanging cloth: an n×n mass-spring sheet, one edge pinned, falling and swinging under gravity.

    The sheet starts flat in the z = 0 plane (x, y in [0, size]); the row y = 0 is pinned
    (``pin="edge"``) or only its two corners (``pin="corners"``). Structural, shear and bend
    springs (stiffness N/m, dashpot damping N·s/m) join neighbours; gravity is (0, 0, -9.81) m/s²;
    linear air drag b = air_drag · m per particle (air_drag in 1/s; 0 turns it off).
    ``ground=True`` adds a floor at z = -0.8·size (restitution 0.1, friction 0.5). ``dt=None``
    uses twice :meth:`Scene.suggest_dt` (1/ω_max here), half of velocity Verlet's stability limit.
    """
    n = _count(n, "n", 2)
    size, mass, stiffness = _positive(size, "size"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    if pin not in ("edge", "corners"):
        raise InvalidInputError(f"pin: must be 'edge' or 'corners', got {pin!r}")
    s = size / (n - 1)
    gx, gy = np.meshgrid(np.arange(n) * s, np.arange(n) * s)
    x = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], axis=1)
    pinned = np.zeros(n * n, dtype=bool)
    if pin == "edge":
        pinned[:n] = True
    else:
        pinned[[0, n - 1]] = True
    scene = Scene(3, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=mass / (n * n), pinned=pinned)
    i, j = cloth_springs(n)
    scene.add(Springs(i, j, stiffness=stiffness, damping=damping))
    scene.add(Gravity([0.0, 0.0, -9.81]))
    if air_drag:
        scene.add(Drag(_positive(air_drag, "air_drag") * mass / (n * n)))
    if ground:
        scene.add(Plane([0.0, 0.0, -0.8 * size], [0.0, 0.0, 1.0], restitution=0.1, friction=0.5))
    if dt is None:
        # suggest_dt() is half the fastest time scale (1/ω_max or the dashpot's 1/λ_max); twice
        # that is still well inside velocity Verlet's limits (2/ω_max; 2/λ_max with dashpots).
        scene.dt = 2 * scene.suggest_dt()
    return scene


cloth.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 360)}


def projectile(
    n: int = 5,
    speed: float = 20.0,
    drag: float = 0.0,
    restitution: float = 0.6,
    ground: bool = True,
    integrator: str = "verlet",
    dt: Optional[float] = 1e-3,
    threads: Optional[int] = None,
) -> Scene:
    """Projectiles: n balls (1 kg) launched from the origin at angles from 20° to 70°, bouncing.

    2D, gravity (0, -9.81) m/s², optional linear drag (kg/s), a ground plane y = 0 with the given
    restitution and friction 0.2. Without drag and ground the closed form is
    x = v0 cos θ t, y = v0 sin θ t - g t²/2.
    """
    n = _count(n, "n", 1)
    speed = _positive(speed, "speed")
    angles = np.radians(np.linspace(20.0, 70.0, n)) if n > 1 else np.radians([45.0])
    v = speed * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    scene = Scene(2, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(np.zeros((n, 2)), v, masses=1.0)
    scene.add(Gravity([0.0, -9.81]))
    if drag:
        scene.add(Drag(drag))
    if ground:
        scene.add(Plane([0.0, 0.0], [0.0, 1.0], restitution=restitution, friction=0.2))
    return scene


projectile.render_defaults = {"frames": 120, "fps": 30, "frame_time": 1 / 30, "size": (480, 320)}


def kepler(
    e: float = 0.5,
    a: float = 1.0,
    mass_ratio: float = 1e-3,
    steps_per_orbit: int = 1000,
    integrator: str = "verlet",
    dt: Optional[float] = None,
    threads: Optional[int] = None,
) -> Scene:
    """Kepler orbit: two bodies under Newtonian gravity (G = 1, total mass 1), eccentricity e.

    The relative orbit has semi-major axis a and starts at pericentre r = a(1 - e) with speed
    sqrt(G M (1 + e) / (a (1 - e))); bodies are placed in the centre-of-mass frame. Period
    P = 2π sqrt(a³ / (G M)); total energy -G m1 m2 / (2a). ``mass_ratio = 0`` pins a unit-mass
    star at the origin and makes the planet (mass 1) a test particle: then E = -1/(2a) exactly.
    ``dt=None`` uses P / steps_per_orbit.
    """
    e = float(e)
    if not (0.0 <= e < 1.0):
        raise InvalidInputError(f"e: eccentricity must be in [0, 1), got {e}")
    a = _positive(a, "a")
    q = float(mass_ratio)
    if not (math.isfinite(q) and q >= 0):
        raise InvalidInputError(f"mass_ratio: must be finite and >= 0, got {q}")
    steps_per_orbit = _count(steps_per_orbit, "steps_per_orbit", 1)
    period = 2 * math.pi * math.sqrt(a**3)
    rp = a * (1 - e)
    vp = math.sqrt((1 + e) / (a * (1 - e)))
    scene = Scene(2, integrator=integrator, dt=period / steps_per_orbit if dt is None else dt, threads=threads)
    if q == 0:
        scene.add_particles([[0.0, 0.0], [rp, 0.0]], [[0.0, 0.0], [0.0, vp]], masses=[1.0, 1.0], pinned=[True, False])
    else:
        m1, m2 = 1 / (1 + q), q / (1 + q)
        x = np.array([[-m2 * rp, 0.0], [m1 * rp, 0.0]])
        v = np.array([[0.0, -m2 * vp], [0.0, m1 * vp]])
        scene.add_particles(x, v, masses=[m1, m2])
    scene.add(PairwiseGravity(G=1.0))
    return scene


kepler.render_defaults = {"frames": 120, "fps": 30, "frame_time": 4 * math.pi / 120, "size": (400, 400)}


def spring_chain(
    n: int = 24,
    length: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 2000.0,
    damping: float = 0.0,
    dim: int = 2,
    integrator: str = "verlet",
    dt: Optional[float] = None,
    threads: Optional[int] = None,
) -> Scene:
    """Spring chain: n particles joined by springs, first one pinned, released horizontally.

    It swings down under gravity like a heavy rope. Total mass (kg) shared equally, spring
    stiffness (N/m) and dashpot damping (N·s/m) per link. ``dt=None`` uses the suggested step.
    """
    n = _count(n, "n", 2)
    length, mass, stiffness = _positive(length, "length"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    if dim not in (2, 3):
        raise InvalidInputError(f"dim: must be 2 or 3, got {dim}")
    x = np.zeros((n, dim))
    x[:, 0] = np.linspace(0.0, length, n)
    pinned = np.zeros(n, dtype=bool)
    pinned[0] = True
    scene = Scene(dim, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=mass / n, pinned=pinned)
    scene.add(Springs(np.arange(n - 1), np.arange(1, n), stiffness=stiffness, damping=damping))
    g = [0.0] * dim
    g[1 if dim == 2 else 2] = -9.81
    scene.add(Gravity(g))
    if dt is None:
        scene.dt = scene.suggest_dt()
    return scene


spring_chain.render_defaults = {"frames": 100, "fps": 30, "frame_time": 1 / 30, "size": (400, 400)}

#: Scene name → function, in the order ``physcore scenes`` lists them.
REGISTRY: Dict[str, Callable[..., Scene]] = {
    "cloth": cloth,
    "projectile": projectile,
    "kepler": kepler,
    "spring_chain": spring_chain,
}
DEFAULT_SCENE = "cloth"
