"""The camera: orthographic projection of 2D or 3D world points onto the image, fitted once to
every frame so that the view does not move."""
from __future__ import annotations

import math

import numpy as np

from ._rows import _rows_finite

#: Default oblique view of 3D scenes, (azimuth, elevation) in degrees.
DEFAULT_VIEW = (-60.0, 25.0)


class _Camera:
    """Orthographic camera: world -> screen plane (right, up) -> pixel (col, row).

    3D uses an oblique view: the camera sits at azimuth `az` (from +x towards +y) and elevation
    `el` above the xy-plane, looking at the origin, with +z up on screen.
    """

    def __init__(self, dim: int, view: tuple[float, float], size: tuple[int, int]):
        self.dim = dim
        self.width, self.height = size
        if dim == 3:
            az, el = math.radians(view[0]), math.radians(view[1])
            right = [-math.sin(az), math.cos(az), 0.0]
            up = [-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)]
            toward = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
            self.basis = np.array([right, up, toward], dtype=np.float64).T  # (3, 3)
        else:
            self.basis = np.eye(2)
        self.centre = np.zeros(2)
        self.scale = 1.0
        self.row0 = 0.5 * self.height  # pixel row of the screen-plane centre

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(N, dim) world -> (N, 2) screen-plane coordinates and (N,) depth (3D; larger = nearer)."""
        # inf coordinates (beyond float32, see _simulate) give NaN rows, which are not drawn.
        with np.errstate(over="ignore", invalid="ignore"):
            s = x @ self.basis.astype(x.dtype, copy=False)
        if self.dim == 3:
            return s[:, :2], s[:, 2]
        return s, None

    def fit(self, lo: np.ndarray, hi: np.ndarray, pad: int, tol: float = 0.0, top_pad: int | None = None,
            bottom_pad: int | None = None) -> None:
        """Fit the screen-plane box [lo, hi] into the image with `pad` pixels spare each side.

        `top_pad` / `bottom_pad` (default `pad`) keep that many pixels spare at the top (room for
        the colour bar) / bottom (the clock and the scale bar) instead. A box no wider than `tol`
        (world units) counts as a point and gets a unit box around it.
        """
        top = pad if top_pad is None else top_pad
        bottom = pad if bottom_pad is None else bottom_pad
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or np.any(hi < lo):
            lo, hi = np.full(2, -0.5), np.full(2, 0.5)
        ext = hi - lo
        avail = np.array([max(self.width - 2 * pad, 1), max(self.height - bottom - top, 1)], dtype=float)
        self.row0 = 0.5 * self.height + 0.5 * (top - bottom)
        if ext.max() <= tol:
            # A single point (one particle, all at one place, or all on one line of sight).
            self.scale = float(avail.min())
        else:
            # A flat box (particles on a line) is fitted along its long side only.
            self.scale = float(min(a / e for a, e in zip(avail, ext, strict=False) if e > tol))
        self.centre = 0.5 * (lo + hi)

    def pixels(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) screen-plane coordinates -> float pixel column and row (pixel k spans [k, k+1))."""
        col = (s[:, 0] - self.centre[0]) * self.scale + 0.5 * self.width
        row = self.row0 - (s[:, 1] - self.centre[1]) * self.scale
        return col, row


def _screen_bounds(cam: _Camera, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Screen-plane bounding box (lo, hi) of all finite (F, N, dim) positions, and max |x|."""
    lo, hi, amax = np.full(2, np.inf), np.full(2, -np.inf), 0.0
    for x in positions:  # per frame: the (F, N, 2) projection of a big run need not fit in memory
        if not np.isfinite(x).all():
            x = x[_rows_finite(x)]
        if x.size == 0:
            continue
        s, _ = cam.project(x)
        lo = np.minimum(lo, [s[:, 0].min(), s[:, 1].min()])
        hi = np.maximum(hi, [s[:, 0].max(), s[:, 1].max()])
        amax = max(amax, float(np.abs(x).max()))
    return lo, hi, amax
