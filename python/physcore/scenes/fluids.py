"""SPH fluid scenes: the dam break, the drop, and the surface-tension scenes droplets and crown."""
from __future__ import annotations

import functools
import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ..bodies import Bodies
from ..fluids import SPACING_RANGE
from ..scene import Scene
from ..shapes import blob, lattice, lattice_counts, tank_walls
from ..terms import Gravity
from ..terms.colliders import Box
from ._common import _count, _dim, _finite_books, _flag, _nonneg, _particles, _per, _positive, _stamped

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


def _fluid_scene(dim: int, integrator: str, dt: float | None, threads: int | None, device: str = "cpu") -> Scene:
    """A scene with gravity along −y (2D) or −z (3D), added before the fluid so that the fluid's
    default sound speed is estimated from it."""
    scene = Scene(dim, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads, device=device)
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
    velocities=None, device="cpu", smoothing=None, **surface: float,
) -> Scene:
    """A fluid scene: water particles at ``positions`` in a tank lined with 3 wall layers
    (``surface``: DFSPH's ``surface_tension`` and ``adhesion``). On a GPU ``device`` the tank
    also stands in a Box collider 4 spacings outside its outer wall layer: the extent of the
    device's cell list (a particle that leaks through the walls is held there; on the CPU it
    would fall away)."""
    scene = _fluid_scene(dim, integrator, dt, threads, device)
    scene.add_fluid(
        positions,
        velocities=velocities,
        **surface,
        spacing=dx,
        smoothing=smoothing,
        boundary=tank_walls(tlo, thi, dx, layers=3, top=lid),
        pass_precision=pass_precision,
        kernel=kernel,
        alpha=alpha,
        sound_speed=sound_speed,
        method=method,
        name="water",
    )
    if device != "cpu":
        margin = 4.0 * dx  # the 3 wall layers lie within 3 dx of the tank's faces
        scene.add(Box([c - margin for c in tlo], [c + margin for c in thi]))
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
    smoothing: float | None = None,
    alpha: float = 0.05,
    sound_speed: float | None = None,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
    method: str | None = None,
    device: str = "cpu",
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
        surface drawing shows no grain at 480 × 360) and 16 in 3D (N = 2n³·depth/width = 8 192:
        the default render takes 8 s on 2 cores of an AMD EPYC at AVX2, drawn as a lit
        surface in a glass tank; 21 s at h = 1.3 Δx, 3D's default before 2026-12-01, when
        ``n=24``, 27 648 particles, took 83 s). The guide's speed and
        Martin & Moyce tables (docs/guide/fluids_dfsph.md) use n = 144 (41 472).
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
    smoothing : float
        Smoothing length over the spacing, h = smoothing·Δx (0.5 to 4; :class:`~physcore.fluids.Fluid`).
        Default the fluid's (:func:`~physcore.fluids.default_smoothing`): 1.0 for 3D DFSPH
        without surface tension (SPlisHSPlasH's reach, a support of 2Δx: 2.2× fewer pairs a pass
        than 1.3; from rest to T = 4 at ``n=24``, 27 648 particles, 10.3 s against 18.1 s on 2
        cores, the fronts within 2 %: docs/guide/fluids_dfsph.md, "Choosing h in 3D"), 1.3
        otherwise (in 2D a smaller h gains nothing: the steps follow h).
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
        of 29,000, three times faster (docs/guide/fluids_dfsph.md), with the Martin & Moyce
        front as close; ``sound_speed`` then only scales the viscosity and ``pass_precision`` does
        not apply (DFSPH computes in float64). ``"wcsph"``: the Tait equation of state.
    device : {"cpu", "gpu", "gpu:NAME", "auto"}
        ``"gpu"`` steps the water on a GPU in float32 (:class:`~physcore.Scene`; DFSPH or
        WCSPH). The tank then also stands in a :class:`~physcore.Box`
        4 spacings outside its walls, the extent of the device's cell list. On an NVIDIA H200,
        ``dim=3, n=80`` (10⁶ particles) took 132 s to simulate the default render's 120 frames
        (docs/guide/gpu.md, measured before the device's neighbour lists, at h = 1.3 Δx, 3D's
        default then).

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
    n = _count(16 if dim == 3 and n is None else 72 if n is None else n, "n", 2)
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
        device=device, smoothing=smoothing,
    )


# 120 frames (4 s at 30 fps) over T = t·√(2g/width) = 0..8 for the default width (1 m): the
# collapse, the surge along the floor, its impact on the far wall (T ≈ 3.3), the jet up to the
# lid (T ≈ 5) and the plunging wave falling back (T ≈ 6–8), played 2.2× slower than real time.
# The water is drawn as one surface (render.gif(surface=...)), by speed from deep navy to light cyan;
# in 3D a lit one (the nearest particles' smoothed depth, shaded) in a glass tank.
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
_SPH_RENAMES = {"viscosity": "alpha", "precision": "pass_precision"}
dam_break = _stamped(dam_break, renames=_SPH_RENAMES)


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
drop = _stamped(drop, renames=_SPH_RENAMES)

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


def droplets(
    *,
    dim: int = 2,
    n: int | None = None,
    drops: int = 3,
    radius: float = 0.003,
    speed: float = 0.3,
    tank: tuple[float, float] = (0.04, 0.02),
    depth: float = 0.02,
    surface_tension: float = 0.072,
    adhesion: float = 0.0,
    alpha: float = 0.02,
    lid: bool = True,
    integrator: str = "semi_implicit_euler",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Droplets: water drops fall onto a floor, splash into one another and coalesce; surface
    tension rounds the splash's jets and pulls the merged puddle back in from the walls.

    ``drops`` drops of ``radius`` (m) start in a row across the tank at staggered heights, moving
    down at ``speed`` (m/s), under gravity 9.81 m/s². Water at millimetre scale: DFSPH
    (ρ0 = 1000 kg/m³) with Akinci et al. (2013) surface tension σ = 0.072 N/m (N in 2D) and no
    adhesion to the walls by default (:class:`~physcore.fluids.Fluid`; with the 0.02 N/m of earlier
    versions the spray thrown up hung from the lid for the rest of the animation); the capillary length
    √(σ/(ρ0 g)) = 2.7 mm is the drops' size, so both gravity and surface tension shape them. The
    default impact (about 0.6 m/s after the fall: Weber number ρ0 v² 2R/σ ≈ 30) spreads each drop
    into a sheet that runs into its neighbours' and throws up a jet, without breaking into spray
    (at the 1.5 m/s of earlier versions, Weber ≈ 190, the rims broke into droplets of a few
    particles each, which filled the tank as specks).

    Parameters
    ----------
    dim : {2, 3}
        In 3D the tank has a ``depth`` (along y) and the drops are centred in it.
    n : int, optional
        Particles across the tank length (spacing ``tank[0] / n``). Default 160 in 2D (about
        1 400 water particles, 12 across a drop's radius) and 80 in 3D (about 2 700, 6 across).
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
    224
    """
    dim, n, sigma, adh, alpha = _surface_scene_args(dim, n, 160, 80, integrator, surface_tension, adhesion, alpha)
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
        parts.append(blob(centre, radius, dx))
    pos = np.concatenate(parts)
    vel = np.zeros_like(pos)
    vel[:, -1] = -speed
    return _surface_water(pos, vel, dx, tlo, thi, dim, lid, alpha, sigma, adh, integrator, dt, threads)


# 72 frames over 0.118 s, played at 24 fps (3 s): the fall, the impacts (the first at ≈ 25 ms),
# the sheets running into each other and the jet they throw up, and the merged film running up
# the walls and drawing back, which it still does at the end (later the puddle only creeps in:
# over 0.165 s the last quarter's motion was 0.21 of the rest's). Plain water before a pale
# backdrop: coloured by speed, the drops' small velocity jitter mottled them (the first frame,
# the thumbnail, most of all), and the story here is the shape, not the speed (--color-by speed
# shows it, in the "ice" map).
droplets.render_defaults = {
    "frames": 72,
    "fps": 24,
    "frame_time": 1 / 600,
    "substeps": "auto",
    "color_by": "none",
    "size": (480, 240),
    "surface": True,
    "cmap": "ice",
    "look": {"backdrop": ((240, 245, 250), (210, 220, 232))},
}
droplets = _stamped(droplets, renames={"viscosity": "alpha"})


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
    ball = blob(centre, radius, dx)
    pos = np.concatenate([water, ball])
    vel = np.zeros_like(pos)
    vel[len(water):, -1] = -speed
    return _surface_water(pos, vel, dx, tlo, thi, dim, lid, alpha, sigma, adh, integrator, dt, threads)


# 120 frames over 25 ms: the impact, the crown rising and its rim breaking up; the tank (7 cm)
# is wide enough that the sheets never reach its walls in that time. The camera holds the
# middle 5.4 cm and the lowest 2.7 cm, where the sheets rise (a droplet thrown higher leaves
# the picture), before a pale backdrop.
crown.render_defaults = {
    "frames": 120,
    "fps": 30,
    "frame_time": 0.025 / 120,
    "substeps": "auto",
    "color_by": "speed",
    "size": (480, 240),
    "surface": True,
    "cmap": "ice",
    "extent": ((0.008, -0.0005), (0.062, 0.0265)),
    "look": {"backdrop": ((240, 245, 250), (210, 220, 232))},
}
crown = _stamped(crown, renames={"viscosity": "alpha"})


def floating(
    n: int = 56,
    *,
    density: float = 500.0,
    method: str | None = None,
    integrator: str = "semi_implicit_euler",
    threads: int | None = None,
) -> Scene:
    """Crates and a ball afloat on a pool, struck by a dam break: a water column
    (:func:`dam_break`'s, DFSPH, ``n`` particles across its width, 1 m wide and 2 m high in a
    4 × 3 m tank) collapses onto a still layer 0.3 m deep on which two crates and a ball
    (``density`` kg/m², lighter than the water's 1000) float at rest; the bore lifts them,
    carries them to the far wall and back. The tank is both the fluid's walls and fixed bodies;
    the crates and the ball meet the fluid through boundary particles on their surfaces
    (Akinci et al. 2012, :mod:`physcore.bodies`), so they float at their Archimedes draft
    (measured in still water at this resolution: 10.01 cm for a ball of radius 10 cm at 500
    kg/m², 5.08 at 200) and the surge pushes them by its pressure. ``method`` and
    ``integrator`` step the fluid (see :func:`dam_break`).

    Until 2026-12-02 the column fell onto a dry floor with the bodies on its top: the surge
    left 0.2–0.3 m of water beside them, the run-up and backwash then buried them from 2.0 to
    about 4.2 s (floating correctly on the water that was there), and the 3.2 s render ended
    with them under it. The layer keeps water under them throughout.

    Raises TypeError / InvalidInputError naming the argument (a ``density`` below 100 kg/m², a
    tenth of the water's, which the coupling refuses: such a body is flung out by the
    pressure it takes).
    """
    rho = _positive(density, "density")
    if rho < 100.0:  # the core's LIGHTEST (0.1) times the water's 1000: refused here, not at the first step
        raise InvalidInputError(f"density: the bodies must be at least 100 kg/m² (a tenth of the water's), got {rho:g}")
    n = _count(n, "n", 2)
    dx = _spacing(_per(1.0, n), "n")
    wall, w, h, bed = 0.1, 4.0, 3.0, 0.3
    _particles("n", _lattice_size([0.0, 0.0], [1.0, 2.0], dx) + _lattice_size([1.0, 0.0], [w, bed], dx)
               + _walls_size([0.0, 0.0], [w, h], dx))
    if method is None:
        method = "dfsph" if isinstance(integrator, str) and integrator == "semi_implicit_euler" else "wcsph"
    # The bodies float at rest on the layer, their centres near its surface (the draft of a
    # half-density body); the layer's water is cut away within half a spacing of each.
    crates = [(1.6, bed + 0.02, 0.15, 0.1), (3.2, bed + 0.04, 0.12, 0.12)]
    ball = (2.4, bed + 0.02, 0.1)
    pool = lattice([1.0, 0.0], [w, bed], dx)
    keep = np.hypot(pool[:, 0] - ball[0], pool[:, 1] - ball[1]) > ball[2] + 0.5 * dx
    for cx, cy, hx, hy in crates:
        keep &= ~((np.abs(pool[:, 0] - cx) < hx + 0.5 * dx) & (np.abs(pool[:, 1] - cy) < hy + 0.5 * dx))
    water = np.vstack([lattice([0.0, 0.0], [1.0, 2.0], dx), pool[keep]])
    scene = _water_in_tank(
        water, dx, [0.0, 0.0], [w, h], dim=2, lid=True, pass_precision="f32", kernel="cubic_spline", alpha=0.05,
        sound_speed=None, integrator=integrator, dt=None, threads=threads, method=method,
    )
    scene.add(Bodies("box", size=[(w / 2 + 2 * wall, wall), (wall, h / 2 + wall), (wall, h / 2 + wall)],
                     positions=[(w / 2, -wall), (-wall, h / 2), (w + wall, h / 2)], kind="fixed", color=(84, 92, 104), name="tank"))
    scene.add(Bodies("box", size=[c[2:] for c in crates], positions=[c[:2] for c in crates],
                     density=rho, friction=0.4, restitution=0.1, color=[(214, 156, 96), (226, 172, 110)], name="crates"))
    scene.add(Bodies("ball", size=[ball[2]], positions=[ball[:2]], density=rho, friction=0.4, restitution=0.1,
                     color=(214, 96, 77), name="ball"))
    scene.render_defaults = None
    return _finite_books(scene, "density")


# 3.2 s: the collapse, the bore striking the floating bodies and carrying them to the far wall,
# and the ride back.
floating.render_defaults = {"frames": 160, "fps": 30, "frame_time": 1 / 50, "substeps": "auto", "color_by": "speed",
                            "size": (480, 360), "surface": True, "cmap": "ice"}
floating = _stamped(floating)
