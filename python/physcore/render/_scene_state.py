"""Reading a scene's state into checked float64 arrays: springs and their strain, collider planes
and spheres, pressures and static boundary points (the optional parts a scene may or may not have)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ._rows import _row_norms, _rows_finite


def _strain(x: np.ndarray, i: np.ndarray, j: np.ndarray, rest: np.ndarray) -> np.ndarray:
    length = _row_norms(x[j] - x[i])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(rest > 0, (length - rest) / rest, np.nan)


def _planes(planes: Any, dim: int) -> list:
    """Plane objects (.point, .normal) -> [(point, unit normal)]; degenerate ones are skipped."""
    out = []
    for pl in planes or []:
        p = np.asarray(pl.point, dtype=np.float64).reshape(-1)
        n = np.asarray(pl.normal, dtype=np.float64).reshape(-1)
        nn = float(np.sqrt(n @ n)) if n.shape == (dim,) else 0.0
        if p.shape == (dim,) and nn > 0 and np.isfinite(p).all() and math.isfinite(nn):
            out.append((p, n / nn))
    return out


def _spheres(spheres: Any, dim: int) -> list:
    """Sphere colliders (.center, .radius, .inside) -> [(centre (dim,), radius, inside)] in m;
    degenerate ones are skipped."""
    out = []
    for sp in spheres or []:
        c = np.asarray(sp.center, dtype=np.float64).reshape(-1)
        r = float(sp.radius)
        if c.shape == (dim,) and np.isfinite(c).all() and math.isfinite(r) and r > 0:
            out.append((c, r, bool(getattr(sp, "inside", False))))
    return out


def _scene_springs(scene: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(i, j, rest length) of every line the scene draws: its springs (``spring_pairs()``) and,
    on a physcore Scene, the rods of its XPBD distance constraints (a pendulum's rods, a rope),
    drawn alike."""
    from ..terms import XpbdConstraints  # here: the terms module imports the renderer's package lazily too

    i, j, rest = scene.spring_pairs()
    parts = [(np.asarray(i, dtype=np.intp), np.asarray(j, dtype=np.intp), np.asarray(rest, dtype=np.float64))]
    for t in getattr(scene, "terms", ()):
        if isinstance(t, XpbdConstraints) and np.asarray(t.distance).size:
            d = np.asarray(t.distance, dtype=np.intp).reshape(-1, 2)
            r = np.full(len(d), np.nan) if t.rest_length is None else np.asarray(t.rest_length, dtype=np.float64).reshape(-1)
            parts.append((d[:, 0], d[:, 1], r))
    i = np.concatenate([p[0] for p in parts])
    if i.size == 0:
        return None
    return i, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts])


def _pressure_array(p: Any, n: int) -> np.ndarray:
    """Check what ``scene.pressure()`` returned: (N,) float64 Pa."""
    p = np.asarray(p, dtype=np.float64)
    if p.shape != (n,):
        raise InvalidInputError(f"scene.pressure() must return an array of shape ({n},) in Pa, got shape {p.shape}")
    return p


def _scene_pressure(scene: Any, n: int) -> np.ndarray:
    """``scene.pressure()`` as (N,) float64 Pa; ValueError naming color_by if the scene has none
    (no ``pressure()`` method, or a physcore Scene without a fluid, whose pressure is 0 everywhere
    and would draw one flat colour)."""
    from ..scene import Scene  # here: the scene module imports the renderer's package lazily too

    if isinstance(scene, Scene) and scene.fluids == ():
        raise InvalidInputError(
            "color_by='pressure': the scene has no fluid (its pressure is 0 everywhere); add a Fluid or use color_by='speed'"
        )
    try:
        p = scene.pressure()
    except AttributeError as e:
        raise InvalidInputError(
            f"color_by='pressure' needs a scene with a pressure() method (an SPH fluid); "
            f"this one has none ({e})"
        ) from None
    return _pressure_array(p, n)


def _boundary_array(b: Any, dim: int) -> np.ndarray:
    """Static boundary points (B, dim) float64, non-finite rows dropped."""
    b = np.asarray(b, dtype=np.float64)
    if b.size == 0:
        return np.zeros((0, dim))
    if b.ndim != 2 or b.shape[1] != dim:
        raise InvalidInputError(f"boundary points must have shape (B, {dim}), got {b.shape}")
    return b if np.isfinite(b).all() else b[_rows_finite(b)]


def _scene_boundary(scene: Any, dim: int) -> np.ndarray | None:
    """``scene.boundary_points()`` as (B, dim) float64, or None where the scene has no such method."""
    method = getattr(scene, "boundary_points", None)
    if not callable(method):
        return None
    try:
        b = method()
    except AttributeError:
        return None
    return _boundary_array(b, dim)
