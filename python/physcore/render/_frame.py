"""One image: :func:`render_frame` rasterises a single state (a scene, or arrays) to RGB, with the
camera fitted to that state."""
from __future__ import annotations

from typing import Any

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError, allocating
from ._checks import _check_color_by, _check_radius, _check_size, _check_view, _extent_box
from ._palette import _PALETTE
from ._raster import _Rasteriser
from ._recording import Recording, _drawn_polygons, _drawn_rods
from ._rows import _finite_mean, _row_norms
from ._scene_state import _boundary_array, _planes, _scene_boundary, _scene_pressure, _scene_springs, _spheres, _strain


@allocating("render_frame", "its arrays")
def render_frame(
    positions: Any,
    *,
    size: tuple[int, int] = (480, 360),
    velocities: np.ndarray | None = None,
    pinned: np.ndarray | None = None,
    springs: Any = None,
    planes: list | None = None,
    pressures: np.ndarray | None = None,
    boundary: np.ndarray | None = None,
    color_by: str = "speed",
    speed_scale: float | None = None,
    pressure_scale: float | None = None,
    colorbar: bool = True,
    radius: int | None = None,
    view: tuple[float, float] | None = None,
    extent: Any = None,
) -> np.ndarray:
    """Rasterise one state to an RGB image, with the camera fitted to that state (or to
    `extent`).

    Frames made in a loop keep one view and one colour scale when they are given: pass the same
    `extent`, `speed_scale` (or `pressure_scale`) and `radius` to every call (by default each
    call fits its own state, so a moving scene's frames would jump).

    Parameters
    ----------
    positions : array_like (N, dim) float, or physcore.Scene
        Particle positions in m, dim 2 or 3. A Scene supplies its positions, and also its
        velocities, pinned flags, springs, planes, pressures (``pressure()``, only for
        ``color_by="pressure"``) and boundary points (``boundary_points()``, where it has those
        methods) unless those are given explicitly; in 2D its other colliders are drawn too, as
        :func:`gif` draws them (spheres, capsules, oriented boxes).
    size : (int, int), default (480, 360)
        Width and height in pixels, each >= 16.
    velocities : array_like (N, dim) float, optional
        m/s; needed for ``color_by="speed"`` (without them all particles get the lowest colour).
    pinned : array_like (N,) bool, optional
        Pinned particles are drawn orange.
    springs : (i, j, rest) or bool, optional
        Spring endpoints, int arrays (M,), and rest lengths, float (M,) m, as returned by
        ``Scene.spring_pairs()``; drawn as strain-coloured lines. For a Scene, None or True takes
        its springs and False draws none.
    planes : list of objects with ``.point`` and ``.normal`` (dim,) arrays, optional
        Collider planes, drawn in 2D only.
    pressures : array_like (N,) float, optional
        Pa; needed for ``color_by="pressure"`` (from the Scene's ``pressure()`` otherwise).
    boundary : array_like (B, dim) float, optional
        Static boundary (wall) particles in m, drawn in grey under the particles and included
        in the camera fit.
    color_by : {"speed", "pressure", "strain", "density", "none"}, default "speed"
    speed_scale : float, optional
        Speed (m/s) at the top of the colour map; default the 99th percentile of the speeds.
    pressure_scale : float, optional
        Pressure (Pa) at the top of the colour map; default the 99th percentile of the pressures.
    colorbar : bool, default True
        Draw the colour bar (see `gif`) when colouring by speed or pressure.
    radius : int, optional
        Disc radius in pixels; default chosen from N + B and `size`.
    view : (float, float), optional
        3D camera (azimuth, elevation) in degrees, default ``(-60, 25)``.
    extent : (array_like (dim,), array_like (dim,)), optional
        A box ``(lower, upper)`` in m that the camera is fitted to instead of the state (and its
        boundary points): the same box gives the same view in every frame.

    Returns
    -------
    numpy.ndarray (H, W, 3) uint8
        The RGB image (row 0 at the top).

    Raises
    ------
    TypeError, ValueError
        On an invalid argument or inconsistent array shapes; ``color_by="pressure"`` without
        pressures (neither given nor from a Scene with ``pressure()``) names `color_by`.
    """
    size = _check_size(size)
    color_by = _check_color_by(color_by)
    radius = _check_radius(radius)
    view = _check_view(view)
    if springs is False:
        sp = None
    elif hasattr(positions, "positions") and hasattr(positions, "spring_pairs") and (springs is None or springs is True):
        sp = _scene_springs(positions)
    elif springs is None or springs is True:
        sp = None
    else:
        sp = _springs(springs)
    solids: dict[str, tuple] = {}
    if hasattr(positions, "positions"):
        scene = positions
        positions = scene.positions
        velocities = scene.velocities if velocities is None else velocities
        pinned = scene.pinned if pinned is None else pinned
        planes = getattr(scene, "planes", None) if planes is None else planes
        dim = np.asarray(positions).shape[-1]
        if pressures is None and color_by == "pressure":
            pressures = _scene_pressure(scene, len(np.asarray(positions)))
        if boundary is None:
            boundary = _scene_boundary(scene, dim)
        if dim == 2:  # the other colliders, as a recording holds them (3D draws them on a mesh only)
            solids = {"spheres": tuple(_spheres(getattr(scene, "spheres", None), dim)),
                      "rods": tuple(_drawn_rods(scene, dim)), "polygons": tuple(_drawn_polygons(scene, dim))}

    x = _check.real_array("positions", positions).astype(np.float64)
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise InvalidInputError(f"positions must have shape (N, 2) or (N, 3), got {x.shape}")
    n, dim = x.shape
    if sp is not None and sp[0].size and (
        min(sp[0].min(), sp[1].min()) < 0 or max(sp[0].max(), sp[1].max()) >= n
    ):
        raise InvalidInputError(f"springs: particle index out of range for {n} particles")
    pin = np.zeros(n, dtype=bool) if pinned is None else _pinned(pinned)
    if pin.shape != (n,):
        raise InvalidInputError(f"pinned must have shape ({n},), got {pin.shape}")
    speeds = None
    if color_by == "speed" and velocities is not None:
        v = _check.real_array("velocities", velocities).astype(np.float64)
        if v.shape != x.shape:
            raise InvalidInputError(f"velocities must have shape {x.shape}, got {v.shape}")
        speeds = _row_norms(v).astype(np.float32)[None]
    pres = None
    if color_by == "pressure":
        if pressures is None:
            raise InvalidInputError("color_by='pressure' needs pressures= (or a scene with a pressure() method)")
        p = _check.real_array("pressures", pressures).astype(np.float64)
        if p.shape != (n,):
            raise InvalidInputError(f"pressures must have shape ({n},), got {p.shape}")
        pres = p.astype(np.float32)[None]
    walls = None
    if boundary is not None:
        try:
            walls = _boundary_array(_check.real_array("boundary", boundary), dim)
        except InvalidInputError as e:
            raise InvalidInputError(f"boundary: {e}") from None
    speed_scale = None if speed_scale is None else _check.positive_float("speed_scale", speed_scale, unit="m/s")
    pressure_scale = None if pressure_scale is None else _check.positive_float("pressure_scale", pressure_scale, unit="Pa")
    colorbar = _check.flag("colorbar", colorbar)

    box = _extent_box(extent, dim)  # the box's corners: every combination of lower/upper per axis
    if box is not None:
        origin = box.mean(axis=0)
    elif n:
        origin = _finite_mean(x)
    else:
        origin = _finite_mean(walls) if walls is not None and len(walls) else np.zeros(dim)
    rec = Recording(
        positions=(x - origin).astype(np.float32)[None],
        origin=origin,
        speeds=speeds,
        pairs=(sp[0], sp[1]) if sp is not None else None,
        strain=_strain(x, *sp).astype(np.float32)[None] if sp is not None else None,
        pinned=pin,
        planes=_planes(_check_planes(planes), dim),
        pressures=pres,
        walls=None if walls is None else walls - origin,
        **solids,
    )
    ras = _Rasteriser(
        rec, size, color_by, radius, view, speed_scale=speed_scale, pressure_scale=pressure_scale,
        colorbar=colorbar, fit=None if box is None else box - origin,
    )
    return _PALETTE[ras.frame(0)]


def _springs(springs: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``springs=(i, j, rest)``: two int index arrays and the rest lengths (m), 1-D, one length."""
    try:
        count = -1 if isinstance(springs, (str, bytes)) else len(springs)
    except TypeError:  # no len(), or a 0-d array
        count = -1
    if count != 3:
        raise InvalidTypeError(f"springs: expected None, a bool or (i, j, rest), got {type(springs).__name__} {springs!r:.40}")
    i, j, rest = (_check.real_array("springs", a) for a in springs)
    for a in (i, j):
        # An index must be a whole number well inside intp (a float index is allowed if whole).
        f = a.astype(np.float64)
        if f.size and not (np.all(np.isfinite(f)) and np.all(f == np.floor(f)) and np.all(np.abs(f) < 2.0**62)):
            raise InvalidInputError("springs: i and j must be whole particle indices")
    sp = (i.astype(np.intp), j.astype(np.intp), rest.astype(np.float64))
    if not (sp[0].shape == sp[1].shape == sp[2].shape and sp[0].ndim == 1):
        raise InvalidInputError("springs: i, j and rest must be 1-D arrays of equal length")
    return sp


def _check_planes(planes: Any) -> list:
    """``planes``: a list of objects with ``.point`` and ``.normal`` of real numbers."""
    if planes is None:
        return []
    try:
        out = None if isinstance(planes, (str, bytes)) else list(planes)
    except TypeError:  # not iterable, or a 0-d array
        out = None
    if out is None:
        raise InvalidTypeError(f"planes: expected a list of planes (.point, .normal), got {type(planes).__name__}")
    for k, pl in enumerate(out):
        if not (hasattr(pl, "point") and hasattr(pl, "normal")):
            raise InvalidTypeError(f"planes[{k}]: expected a plane (.point, .normal), got {type(pl).__name__}")
        _check.real_array(f"planes[{k}].point", pl.point)
        _check.real_array(f"planes[{k}].normal", pl.normal)
    return out


def _pinned(pinned: Any) -> np.ndarray:
    """``pinned``: bools (or 0/1 numbers) as a bool array."""
    a = _check.array("pinned", pinned)
    if a.dtype.kind not in "biuf":
        raise InvalidTypeError(f"pinned: expected bools, got dtype {a.dtype}")
    return a.astype(bool)
