"""Producing frames of data: :class:`Recording` (a scene's state at every frame, no pixels) and
:func:`record`, which steps a scene and fills one."""
from __future__ import annotations

import math
import operator
import sys
import warnings
from typing import Any, NamedTuple

import numpy as np

from .. import _check
from .._deprecate import user_stacklevel
from .._errors import EnergyBooksWarning, InvalidInputError, InvalidTypeError, refusing_memory
from ._checks import (
    _check_advance,
    _check_auto_substeps,
    _check_color_by,
    _check_frame_time,
    _check_int,
    _check_memory,
    _short,
)
from ._rows import _finite_mean, _row_norms
from ._scene_state import _planes, _pressure_array, _scene_boundary, _scene_pressure, _scene_springs, _spheres, _strain

#: Largest ``steps_per_frame`` and ``substeps``: 2**53, beyond which step counts and the time
#: ``n · dt`` are no longer exact in float64 (and no run would finish anyway).
MAX_STEPS = 2**53


class Recording(NamedTuple):
    """What :func:`record` produced: the scene's state at every frame, as data (no pixels).

    Attributes
    ----------
    positions : (F, N, dim) float32
        Positions relative to `origin`, m (float32 keeps its precision near the scene's centre).
    origin : (dim,) float64
        Centroid of the first frame, m; absolute positions are ``positions + origin``.
    speeds : (F, N) float32 or None
        ``|v|``, m/s (recorded when asked for).
    pairs : ((M,), (M,)) intp or None
        Spring endpoints, when springs were recorded.
    strain : (F, M) float32 or None
        Spring strain (L - L0)/L0, NaN where the rest length is 0.
    pinned : (N,) bool
    planes : list of (point (dim,), normal (dim,)) float64
        The scene's collider planes (unit normals).
    pressures : (F, N) float32 or None
        Pa (recorded when asked for).
    walls : (B, dim) float64 or None
        Static boundary points, relative to `origin`.
    times : (F,) float64 or None
        The scene's time at each frame, s.
    masses : (N,) float64 or None
        The particles' masses (kg) at frame 0, when the scene has them (for ``size_by="mass"``).
    speed_unit : str
        The unit the colour bar gives speeds in: "m/s", or the scene's ``render_defaults``
        ``speed_unit`` (Kepler: "(G=1)", a scene in units where G = 1).
    velocities : (F, N, dim) float32 or None
        Velocities, m/s (recorded when asked for: ``record(..., velocities=True)``, which
        arrows need).
    """

    positions: np.ndarray
    origin: np.ndarray
    speeds: np.ndarray | None
    pairs: tuple[np.ndarray, np.ndarray] | None
    strain: np.ndarray | None
    pinned: np.ndarray
    planes: list
    pressures: np.ndarray | None = None
    walls: np.ndarray | None = None
    times: np.ndarray | None = None
    speed_unit: str = "m/s"
    masses: np.ndarray | None = None
    #: (N,) float64: the scene's "radius" attribute (m) when it has one (``size_by="radius"``).
    radii: np.ndarray | None = None
    #: (F, nx, ny) float32: a grid field at every frame (the scene's first grid, or the one its
    #: ``render_defaults`` name; a 3D grid's middle z slice), with the style to draw it in, the
    #: grid's obstacle mask (nx, ny) and its extent (m).
    fields: np.ndarray | None = None
    field_style: str = ""
    field_mask: np.ndarray | None = None
    field_extent: tuple[float, float] | None = None
    #: (F, T, 2) float32: tracer positions (m) of a grid fluid at every frame, drawn as streaks.
    field_points: np.ndarray | None = None
    #: The recorded field's name and unit, for the colour bar ("v", "density", "speed m/s").
    field_label: str = ""
    #: The colouring :func:`record` was asked for (what :func:`gif` then draws by default), and
    #: the scene's ``render_defaults`` at the time (fps, size, theme, trail, ...), so that a
    #: recording draws as its scene would.
    color_by: str | None = None
    defaults: dict | None = None
    velocities: np.ndarray | None = None
    #: The scene's sphere colliders as (centre (dim,) float64 m, radius m, inside) tuples (a
    #: sphere is drawn shaded in 3D, a disc in 2D).
    spheres: tuple = ()
    #: Rods ``(a, b, radius)`` (m) drawing the keyed colliders (a capsule), as the balls draw.
    rods: tuple = ()
    #: Filled convex polygons, ``(k, 2)`` float64 vertices in order around (m), drawing the keyed
    #: colliders of a 2D scene (an oriented box), as the discs draw.
    polygons: tuple = ()
    #: The scene's rigid bodies (``render._bodies.BodyTrack``: outlines, colours, poses per
    #: frame), or None.
    bodies: Any = None

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])


class _FlowPoints:
    """A scene without particles whose flows' points (:class:`physcore.Flow`) are drawn as its
    particles: positions are the points, velocities the flow's u there; every other attribute
    is the scene's, so stepping goes to it."""

    def __init__(self, scene: Any) -> None:
        self._scene = scene
        self._flows = tuple(scene.flows)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._scene, name)

    @property
    def n_particles(self) -> int:
        return sum(f.n for f in self._flows)

    @property
    def positions(self) -> np.ndarray:
        return np.concatenate([f.points for f in self._flows])

    @property
    def velocities(self) -> np.ndarray:
        return np.concatenate([f.velocity for f in self._flows])

    @property
    def pinned(self) -> np.ndarray:
        return np.zeros(self.n_particles, dtype=bool)

    masses = None


def points_view(scene: Any) -> Any:
    """`scene`, or for a scene with flows and no particles, a view drawing the flows' points, or
    for what offers one (a :class:`~physcore.Batch`: its members overlaid) its ``_render_view()``."""
    view = getattr(scene, "_render_view", None)
    if callable(view):
        return view()
    if not (hasattr(scene, "positions") and hasattr(scene, "dim") and callable(getattr(scene, "step", None))):
        # Anything else failed deep inside (`None`: "'NoneType' object has no attribute 'dim'").
        raise InvalidTypeError(
            f"scene: expected a physcore Scene, Batch or Recording, got {type(scene).__name__}"
        )
    if getattr(scene, "flows", ()) and int(getattr(scene, "n_particles", 0)) == 0:
        return _FlowPoints(scene)
    return scene


def _simulate(
    scene: Any,
    frames: int,
    steps_per_frame: int,
    need_speed: bool,
    springs: bool,
    progress: bool,
    need_pressure: bool = False,
    frame_time: float | None = None,
    substeps: str | int = "auto",
    on_frame: Any = None,
    need_velocity: bool = False,
    lead_in: float = 0.0,
) -> Recording:
    """Step `scene` and record every frame; frame 0 is the current state, or the state `lead_in`
    simulated seconds later (the scene's ``render_defaults["lead_in"]``: a first frame where
    something is already visible, e.g. a Turing pattern grown from its seeds).

    Between frames: ``scene.step(steps_per_frame)``, or ``scene.advance(frame_time)`` when
    `frame_time` is given. Everything read from the scene is checked at frame 0, so a bad scene
    raises before it is stepped.
    """
    dim = int(scene.dim)
    if dim not in (2, 3):
        raise InvalidInputError(f"scene.dim must be 2 or 3, got {dim}")
    n = int(scene.n_particles)
    sp = _scene_springs(scene) if springs else None
    x = np.asarray(scene.positions, dtype=np.float64).reshape(n, dim)
    p0 = _scene_pressure(scene, n) if need_pressure else None
    walls = _scene_boundary(scene, dim)
    from ._bodies import body_track

    track, grab_bodies = body_track(scene, frames)
    b0 = grab_bodies() if track is not None else None
    # Store positions relative to the start centroid so float32 keeps its precision far from 0.
    if n:
        origin = _finite_mean(x)
    elif walls is not None and len(walls):
        origin = _finite_mean(walls)
    elif b0 is not None:
        origin = _finite_mean(b0[:, :dim])
    else:
        origin = np.zeros(dim)
    pos = np.empty((frames, n, dim), dtype=np.float32)
    speeds = np.empty((frames, n), dtype=np.float32) if need_speed else None
    vels = np.empty((frames, n, dim), dtype=np.float32) if need_velocity else None
    pressures = np.empty((frames, n), dtype=np.float32) if need_pressure else None
    strain = np.empty((frames, sp[0].size), dtype=np.float32) if sp is not None else None
    from ._fields import grid_plan

    gp = grid_plan(scene)
    fields = None
    if gp is not None:
        g = gp["grid"]

        def grab() -> np.ndarray:
            f = g.field(gp["field"])
            return f[:, :, f.shape[2] // 2] if f.ndim == 3 else f

        fields = np.empty((frames, *g.shape[:2]), dtype=np.float32)
    n_tracers = int(getattr(gp["grid"], "n_tracers", 0)) if gp is not None else 0
    points = np.empty((frames, n_tracers, 2), dtype=np.float32) if n_tracers else None
    has_time = hasattr(scene, "time")
    times = np.empty(frames) if has_time else None
    if lead_in > 0:  # after every read above has been checked: a bad scene still raises unstepped
        _lead_in(scene, lead_in, fixed=frame_time is None)
        x = np.asarray(scene.positions, dtype=np.float64).reshape(n, dim)
        if p0 is not None:
            p0 = _scene_pressure(scene, n)
        if b0 is not None:
            b0 = grab_bodies()
    bar = None
    if progress:
        from tqdm import tqdm  # plain text bar: works in terminals and notebooks alike

        bar = tqdm(total=frames, desc="simulating", unit="frame", file=sys.stderr)
    try:
        for k in range(frames):
            taken = None
            if k:
                if frame_time is None:
                    scene.step(steps_per_frame)
                else:
                    # Only a fixed count is passed on, so any advance(duration) scene works.
                    taken = scene.advance(frame_time) if substeps == "auto" else scene.advance(frame_time, substeps=substeps)
                    if bar is not None:
                        try:
                            bar.set_postfix(substeps=operator.index(taken), refresh=False)
                        except TypeError:
                            bar.set_postfix(substeps="?", refresh=False)
                x = np.asarray(scene.positions, dtype=np.float64).reshape(n, dim)
            # A value beyond float32 (or a difference beyond float64) is stored as inf, and its
            # particle is then left out of the drawing like any non-finite one.
            with np.errstate(over="ignore", invalid="ignore"):
                pos[k] = x - origin
                if speeds is not None or vels is not None:
                    v = np.asarray(scene.velocities, dtype=np.float64).reshape(n, dim)
                    if speeds is not None:
                        speeds[k] = _row_norms(v)
                    if vels is not None:
                        vels[k] = v
                if pressures is not None:
                    pressures[k] = p0 if k == 0 else _pressure_array(scene.pressure(), n)
                if strain is not None:
                    strain[k] = _strain(x, *sp)
            if fields is not None:
                with np.errstate(over="ignore"):
                    fields[k] = grab()
                    if points is not None:
                        points[k] = gp["grid"].tracers
            if times is not None:
                times[k] = float(scene.time)
            if track is not None:
                b = b0 if k == 0 else grab_bodies()
                with np.errstate(over="ignore", invalid="ignore"):
                    track.poses[k, :, :dim] = b[:, :dim] - origin[:dim]
                    track.poses[k, :, dim:] = b[:, dim:]
            if on_frame is not None:
                on_frame(k, scene, taken)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    pinned = np.asarray(scene.pinned, dtype=bool).reshape(n)
    pairs = (sp[0], sp[1]) if sp is not None else None
    _warn_books(scene)
    return Recording(
        pos,
        origin,
        speeds,
        pairs,
        strain,
        pinned,
        _planes(_drawn_planes(scene), dim),
        pressures=pressures,
        walls=None if walls is None else walls - origin,
        times=times,
        speed_unit=str(scene_defaults(scene).get("speed_unit", "m/s")),
        masses=_masses(scene, n),
        radii=_radii(scene, n),
        fields=fields,
        field_style=gp["style"] if gp else "",
        field_mask=_grid_mask(gp),
        field_extent=tuple(gp["grid"].extent[:2]) if gp else None,
        field_points=points,
        field_label=_field_label(gp),
        velocities=vels,
        spheres=tuple(_spheres([*(getattr(scene, "spheres", None) or ()), *_contact_walls(scene, "sphere")], dim)),
        rods=tuple(_drawn_rods(scene, dim)),
        polygons=tuple(_drawn_polygons(scene, dim)),
        bodies=track,
    )


def _drawn_rods(scene: Any, dim: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The rods ``(a, b, radius)`` (m) that draw the scene's keyed colliders (their
    ``drawn_rods()``: a capsule is one); degenerate ones are skipped. The scene's planes, boxes
    and spheres, in ``scene.colliders`` too, are drawn from ``scene.planes`` and ``scene.spheres``."""
    from ..terms import Collider

    out = []
    keyed = [c for c in getattr(scene, "colliders", ()) if isinstance(c, Collider)]
    for c in [*keyed, *_contact_walls(scene, "capsule", "oriented_box")]:
        for a, b, r in c.drawn_rods():
            a, b, r = np.asarray(a, np.float64).reshape(-1), np.asarray(b, np.float64).reshape(-1), float(r)
            if a.shape == b.shape == (dim,) and np.isfinite(a).all() and np.isfinite(b).all() and math.isfinite(r) and r > 0:
                out.append((a, b, r))
    return out


def _drawn_polygons(scene: Any, dim: int) -> list[np.ndarray]:
    """The filled polygons ``(k, 2)`` (m) that draw a 2D scene's keyed colliders (their
    ``drawn_polygons()``: an oriented box is one); none in 3D; degenerate ones are skipped."""
    from ..terms import Collider

    if dim != 2:
        return []
    out = []
    keyed = [c for c in getattr(scene, "colliders", ()) if isinstance(c, Collider)]
    for c in [*keyed, *_contact_walls(scene, "oriented_box")]:
        for v in c.drawn_polygons():
            v = np.asarray(v, np.float64)
            if v.ndim == 2 and v.shape[0] >= 3 and v.shape[1] == 2 and np.isfinite(v).all():
                out.append(v)
    return out


def _field_label(gp: dict[str, Any] | None) -> str:
    if gp is None:
        return ""
    units = {"u": "m", "velocity": "m/s", "speed": "m/s", "vorticity": "1/s", "temperature": "K"}
    name, grid = gp["field"], gp["grid"]
    if name == "density" and grid.kind == "stable_fluid":
        # A passive scalar of 0..1, not a mass density: smoke where buoyancy lifts it, else
        # dye (the cavity's bands, the vortex street's streaks).
        return "smoke" if any(grid.buoyancy) else "dye"
    # "u (m)", not "u m", which read as a garbled unit beside the bar's top value.
    return f"{name} ({units[name]})" if name in units and grid.kind != "gray_scott" else name


def _grid_mask(gp: dict[str, Any] | None) -> np.ndarray | None:
    m = None if gp is None else getattr(gp["grid"], "mask", None)
    if m is None:
        return None
    return m[:, :, m.shape[2] // 2] if m.ndim == 3 else m


def _masses(scene: Any, n: int) -> np.ndarray | None:
    """The scene's (N,) masses if it has finite, positive ones (for ``size_by="mass"``)."""
    m = getattr(scene, "masses", None)
    if m is None:
        return None
    m = np.asarray(m, dtype=np.float64).reshape(-1)
    return m.copy() if m.shape == (n,) and np.all(np.isfinite(m) & (m > 0)) else None


def _contact_walls(scene: Any, *kinds: str) -> list:
    """The walls of the scene's contact terms (``Contacts.walls``: collider records) whose key
    is one of ``kinds``, drawn as the colliders of that kind are."""
    from ..fluids import Fluid

    # A fluid's boundary particles are not walls of this kind (and Fluid.walls is a deprecated alias).
    own = [getattr(t, "walls", None) for t in getattr(scene, "terms", ()) if not isinstance(t, Fluid)]
    return [w for ws in own if isinstance(ws, tuple) for w in ws if getattr(w, "part_kind", None) in kinds]


def _drawn_planes(scene: Any) -> list | None:
    """The scene's plane colliders plus the plane walls of its contact terms (drawn alike)."""
    planes = getattr(scene, "planes", None)
    walls = _contact_walls(scene, "plane")
    return planes if not walls else [*(planes or []), *walls]


def _radii(scene: Any, n: int) -> np.ndarray | None:
    """The scene's (N,) "radius" attribute (m) if it has finite, non-negative ones."""
    a = getattr(scene, "attributes", None)
    r = a.get("radius") if isinstance(a, dict) else None
    if r is None:
        return None
    r = np.asarray(r, dtype=np.float64).reshape(-1)
    return r.copy() if r.shape == (n,) and np.all(np.isfinite(r) & (r >= 0)) else None


_LEAD_IN = "render_defaults['lead_in']"


def _lead_in(scene: Any, seconds: float, fixed: bool) -> None:
    """Advance `scene` by `seconds` before the first frame, as its frames step: in automatic
    substeps where they do (and it has ``advance``), else as the nearest number of steps of its
    dt. (``advance`` on a scene of fixed steps sets its dt to one of its own: the double
    pendulum's frames, counted in steps of the dt before, then ran 1.77 times too long.)"""
    if hasattr(scene, "advance") and not fixed:
        scene.advance(seconds)
    else:
        scene.step(steps_for(seconds, scene.dt, _LEAD_IN))


def _check_lead_in(scene: Any, d: dict[str, Any], fixed: bool = False) -> float:
    """``render_defaults["lead_in"]`` (simulated seconds before the first frame, default 0)
    checked, and refused where it would take more steps than a frame may (InvalidInputError):
    the checks of a frame's stepping, under the lead-in's name."""
    v = d.get("lead_in", 0.0)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
        raise InvalidInputError(f"{_LEAD_IN}: expected simulated seconds >= 0 (finite), got {_short(v)}")
    v = float(v)
    if v > 0:
        if hasattr(scene, "advance") and fixed is False:
            _check_auto_substeps(scene, v, _LEAD_IN)
        else:
            steps_for(v, scene.dt, _LEAD_IN)
    return v


def wants_velocities(arrows: Any, look: Any, trail: Any) -> bool:
    """Whether a drawing with these options needs the recorded velocities: `arrows` (other than
    None or "none"), a `look`'s swept areas (their path between frames follows the velocities)
    or a `trail` drawn as ``look.trail_samples`` > 1 pieces a frame step (the Hermite curve of
    the positions and velocities; with Catmull–Rom tangents instead, pythagorean's 8 pieces a
    step stray 1.2 px from the true paths at the 90th percentile, against 0.2 px). `look` a
    :class:`Look`, a mapping of its fields or None."""
    if look is None:
        look = {}
    field = look.get if isinstance(look, dict) else (lambda name: getattr(look, name, None))
    samples = field("trail_samples")
    return (arrows not in (None, "none") or bool(field("swept_areas"))
            or bool(trail) and isinstance(samples, int) and samples > 1)


def scene_defaults(scene: Any) -> dict[str, Any]:
    """The scene's animation defaults (``scene.render_defaults``, set by :mod:`physcore.scenes`),
    or {} for a scene without them."""
    d = getattr(scene, "render_defaults", None)
    return dict(d) if isinstance(d, dict) else {}


def steps_for(frame_time: float, dt: float, name: str = "frame_time") -> int:
    """Steps of `dt` closest to `frame_time` simulated seconds (at least 1); InvalidInputError
    naming `name` above MAX_STEPS. The one conversion the CLI and the library share."""
    ratio = float(frame_time) / float(dt)
    if not ratio <= MAX_STEPS:
        raise InvalidInputError(
            f"{name}: {float(frame_time):.3g} s{' per frame' if name == 'frame_time' else ''} is {ratio:.3g} steps of "
            f"dt = {float(dt):.3g} s, above {MAX_STEPS:.3g}; give a shorter {name} or a larger dt"
        )
    return max(1, int(round(ratio)))


def default_stepping(d: dict[str, Any], dt: Any) -> tuple[int, float | None]:
    """(steps_per_frame, frame_time) when the caller gives neither, the same as ``physcore
    render``: the scene's ``render_defaults`` (a fixed step count, or a frame time: in automatic
    substeps if it says ``"substeps": "auto"``, else as the nearest number of steps of dt), and
    for a scene without them one frame per 1/fps of simulated time (real-time playback at the
    default 30 fps). A scene without a usable `dt` takes 10 steps per frame. The CLI calls this
    too, so both pick the same stepping."""
    if "steps_per_frame" in d:
        return _check_int("steps_per_frame", d["steps_per_frame"], 1, MAX_STEPS), None
    frame_time = float(d.get("frame_time", 1.0 / float(d.get("fps", 30.0))))
    if str(d.get("substeps", "")).lower() == "auto":
        return 1, frame_time
    if not isinstance(dt, (int, float)) or not (dt > 0 and math.isfinite(dt)):
        return 10, None
    return steps_for(frame_time, dt), None


def _plan(
    scene: Any,
    frames: int | None,
    steps_per_frame: int | None,
    frame_time: float | None,
    substeps: str | int | None,
    color_by: str,
    springs: bool,
    velocities: bool = False,
) -> dict[str, Any]:
    """The checked simulation arguments of :func:`record` (and :func:`gif` of a scene), as
    keyword arguments of ``_simulate``; `velocities`: record them too (arrows). Raises before
    anything is stepped."""
    d = scene_defaults(scene)
    frames = _check_int("frames", d.get("frames", 90) if frames is None else frames, 1)
    frame_time = _check_frame_time(frame_time)
    if substeps is None:
        substeps = "auto"
    elif isinstance(substeps, str):
        if substeps != "auto":
            raise InvalidInputError(f"substeps must be 'auto' or an int >= 1, got {_short(substeps)}")
    else:
        substeps = _check_int("substeps", substeps, 1, MAX_STEPS)
        if frame_time is None:
            raise InvalidInputError("substeps needs frame_time (seconds between frames)")
    if steps_per_frame is None and frame_time is None:
        steps_per_frame, frame_time = default_stepping(d, getattr(scene, "dt", None))
    elif steps_per_frame is None:
        steps_per_frame = 1  # unused: frame_time steps the scene
    elif frame_time is not None:
        raise InvalidInputError("give steps_per_frame or frame_time, not both")
    else:
        steps_per_frame = _check_int("steps_per_frame", steps_per_frame, 1, MAX_STEPS)
    if frame_time is not None:
        _check_advance(scene)
        if substeps == "auto":
            _check_auto_substeps(scene, frame_time)
    if color_by == "strain":
        if not springs:
            raise InvalidInputError("color_by='strain' colours the springs: it needs springs=True")
        if not hasattr(scene, "spring_pairs") or _scene_springs(scene) is None:
            raise InvalidInputError("color_by='strain': the scene has no springs; use color_by='speed'")
    return {
        "frames": frames,
        "steps_per_frame": steps_per_frame,
        "need_speed": color_by == "speed",
        "springs": springs,
        "need_pressure": color_by == "pressure",
        "frame_time": frame_time,
        "substeps": substeps,
        "need_velocity": bool(velocities),
        "lead_in": _check_lead_in(scene, d, fixed=frame_time is None),
    }


@refusing_memory("record", "the frames")
def record(
    scene: Any,
    *,
    frames: int | None = None,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int = "auto",
    color_by: str | None = None,
    springs: bool = True,
    progress: bool = False,
    on_frame: Any = None,
    velocities: bool | None = None,
) -> Recording:
    """Step `scene` and return every frame's state as data: the producing half of :func:`gif`.

    Frame 0 is the current state; between frames the scene advances ``steps_per_frame`` steps
    or, with `frame_time`, ``frame_time`` seconds in automatic (or `substeps` fixed) substeps,
    exactly as :func:`gif` does with the same arguments. Given neither, it advances as
    ``physcore render`` does: by the scene's ``render_defaults`` (the ready-made scenes have
    them), else 1/30 s of simulated time per frame in steps of ``scene.dt`` (real time at 30
    fps). `frames` defaults to the scene's, else 90. The scene is left at the last frame.

    Parameters
    ----------
    scene, frames, steps_per_frame, frame_time, substeps, springs, progress
        As for :func:`gif`.
    color_by : {"speed", "pressure", "strain", "density", "none"}, optional
        Default: the scene's ``render_defaults``, else ``"speed"``. Which per-particle scalar to record (``|v|`` or ``scene.pressure()``) for colouring later.
    on_frame : callable, optional
        ``on_frame(k, scene, substeps)`` after frame ``k`` is recorded; ``substeps`` is what
        ``scene.advance`` returned for that frame (None for frame 0 and for fixed steps). For
        progress reports and probes (energy books, counters); it must not change the scene.
    velocities : bool, optional
        Also record every frame's (N, dim) velocities (``Recording.velocities``, float32), which
        :func:`gif`'s `arrows` draw (and its ``look`` swept areas follow between frames); 4·N·dim
        bytes a frame more. Default: only when the scene's ``render_defaults`` ask for arrows,
        swept areas or a trail with ``look.trail_samples`` above 1.

    Returns
    -------
    Recording
        Give it to :func:`gif` to draw (``gif(recording, path, size=..., ...)``).

    Raises
    ------
    As :func:`gif` (bad arguments before stepping; :class:`physcore.SimulationDiverged`).

    Examples
    --------
    >>> import physcore as pc
    >>> rec = pc.render.record(pc.scenes.projectile(n=2), frames=5, steps_per_frame=20)
    >>> rec.frames, rec.positions.shape, rec.positions.dtype
    (5, (5, 2, 2), dtype('float32'))
    >>> rec.times.round(6).tolist()
    [0.0, 0.02, 0.04, 0.06, 0.08]
    """
    scene = points_view(scene)
    color_by = _check_color_by(scene_defaults(scene).get("color_by", "speed") if color_by is None else color_by)
    springs = _check.flag("springs", springs)
    progress = _check.flag("progress", progress)
    if on_frame is not None and not callable(on_frame):
        raise InvalidTypeError(f"on_frame: expected a callable or None, got {type(on_frame).__name__}")
    if velocities is None:
        d = scene_defaults(scene)
        velocities = wants_velocities(d.get("arrows"), d.get("look"), d.get("trail"))
    velocities = _check.flag("velocities", velocities)
    plan = _plan(scene, frames, steps_per_frame, frame_time, substeps, color_by, springs, velocities)
    _check_memory(scene, plan["frames"], (0, 0), springs, velocities)
    defaults = dict(scene_defaults(scene))
    rec = _simulate(scene, progress=progress, on_frame=on_frame, **plan)
    return rec._replace(color_by=color_by, defaults=defaults)


def _warn_books(scene: Any) -> None:
    """An :class:`~physcore.EnergyBooksWarning` where the recorded scene's books are off by
    half the energy in play or more: a run that blew up without yet overflowing (the books of
    every ready-made scene close within 0.5 % at its defaults)."""
    drift = getattr(scene, "energy_drift", None)
    if not callable(drift):
        return
    try:
        d = float(drift())
    except (AttributeError, TypeError, ValueError, RuntimeError):  # a view without books of its own: nothing to say
        return
    if abs(d) < 0.5:
        return
    try:
        hint = f" (scene.suggest_dt() = {float(scene.suggest_dt()):.3g} s; dt now {float(scene.dt):.3g} s)"
    except (AttributeError, TypeError, ValueError, RuntimeError):
        hint = ""
    warnings.warn(
        f"the energy books are off by {d:+.2g} of the energy in play at the recording's end: unless "
        f"something the books do not count drives the scene, the run blew up; try a smaller dt or "
        f"more substeps{hint}",
        EnergyBooksWarning,
        stacklevel=user_stacklevel(),
    )
