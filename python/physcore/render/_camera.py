"""The camera: orthographic projection of 2D or 3D world points onto the image. ``"fit"`` fits one
camera to every frame, so the view does not move; ``"follow"`` and ``"orbit"`` give each frame
its own centre (a smoothed target) or azimuth (a turn about the vertical axis) at one fixed
scale (:func:`_follow_centres`, :func:`_orbit_bounds`); ``"zoom"`` follows with a scale of
each frame's own, widening as the motion spreads (:func:`_zoom_scales`)."""
from __future__ import annotations

import copy
import math

import numpy as np

from ._rows import _rows_finite

#: Default oblique view of 3D scenes, (azimuth, elevation) in degrees.
DEFAULT_VIEW = (-60.0, 25.0)

#: Camera modes (``gif(camera=...)``).
CAMERAS = ("fit", "follow", "zoom", "orbit")

#: ``camera="follow"``: σ of the Gaussian that smooths the target's path, in seconds of playback.
FOLLOW_SMOOTHING = 0.1

#: ``camera="follow"``: the most the view zooms in on the fitted one (a lone target has no spread
#: to fit, so it is shown at this zoom).
FOLLOW_MAX_ZOOM = 4.0

#: ``camera="zoom"``: σ of the Gaussian that eases the zoom, in seconds of playback; the view
#: starts to widen three σ before the motion needs it.
ZOOM_EASE = 0.5


def _view_basis(az_deg: float, el_deg: float) -> np.ndarray:
    """(3, 3) float64 columns right, up, toward of the camera at azimuth `az_deg` (from +x
    towards +y) and elevation `el_deg` above the xy-plane, looking at the origin, +z up."""
    az, el = math.radians(az_deg), math.radians(el_deg)
    right = [-math.sin(az), math.cos(az), 0.0]
    up = [-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)]
    toward = [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
    return np.array([right, up, toward], dtype=np.float64).T


class _Camera:
    """Orthographic camera: world -> screen plane (right, up) -> pixel (col, row).

    3D uses an oblique view: the camera sits at azimuth `az` (from +x towards +y) and elevation
    `el` above the xy-plane, looking at the origin, with +z up on screen.
    """

    def __init__(self, dim: int, view: tuple[float, float], size: tuple[int, int]):
        self.dim = dim
        self.width, self.height = size
        if dim == 3:
            self.basis = _view_basis(view[0], view[1])  # (3, 3)
        else:
            self.basis = np.eye(2)
        self.centre = np.zeros(2)
        self.scale = 1.0
        self.row0 = 0.5 * self.height  # pixel row of the screen-plane centre

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(N, dim) world -> (N, 2) screen-plane coordinates and (N,) depth (3D; larger = nearer)."""
        # inf coordinates (beyond float32, see _simulate) give NaN rows, which are not drawn.
        # einsum, not `@`: numpy's matmul takes a slow path for an inner dimension of 2 or 3
        # (97 ms against 6 ms for 432,000 float32 points, measured), and a 10⁶-particle frame
        # projects several times.
        with np.errstate(over="ignore", invalid="ignore"):
            s = np.einsum("ij,jk->ik", x, self.basis.astype(x.dtype, copy=False))
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

    def moved(self, centre: np.ndarray, basis: np.ndarray | None = None, scale: float | None = None) -> _Camera:
        """A copy looking at screen-plane point `centre` (2,), optionally along another `basis`
        (3, 3) or at another `scale` (pixels per unit); the same image (a per-frame camera
        costs no fitting)."""
        cam = copy.copy(self)
        cam.centre = centre
        if basis is not None:
            cam.basis = basis
        if scale is not None:
            cam.scale = scale
        return cam

    def pixels(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) screen-plane coordinates -> float pixel column and row (pixel k spans [k, k+1))."""
        col = (s[:, 0] - self.centre[0]) * self.scale + 0.5 * self.width
        row = self.row0 - (s[:, 1] - self.centre[1]) * self.scale
        return col, row


def _screen_bounds(cam: _Camera, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Screen-plane bounding box (lo, hi) of all finite (F, N, dim) positions, and max |x|.
    Frames side by side on threads (:func:`._threads.map_frames`; min and max do not depend on
    the order): 3.3 s on one core for 120 frames of 10⁶ particles."""
    from ._threads import map_frames

    def one(k: int) -> tuple[np.ndarray, np.ndarray, float] | None:
        x = positions[k]  # per frame: the (F, N, 2) projection of a big run need not fit in memory
        with np.errstate(invalid="ignore"):
            amax = float(np.abs(x).max()) if x.size else 0.0
        if not math.isfinite(amax):  # a NaN or inf coordinate: that frame's finite rows only
            x = x[_rows_finite(x)]
            amax = float(np.abs(x).max()) if x.size else 0.0
        if x.size == 0:
            return None
        s, _ = cam.project(x)
        return np.array([s[:, 0].min(), s[:, 1].min()]), np.array([s[:, 0].max(), s[:, 1].max()]), amax

    lo, hi, amax = np.full(2, np.inf), np.full(2, -np.inf), 0.0
    # Threads for big frames only: a few particles' frame takes microseconds, a thread's turn more.
    for b in map_frames(one, len(positions), parallel=positions.shape[1] >= 10_000):
        if b is not None:
            lo, hi, amax = np.minimum(lo, b[0]), np.maximum(hi, b[1]), max(amax, b[2])
    return lo, hi, amax


def _fill_gaps(path: np.ndarray) -> np.ndarray:
    """(F, D) path with non-finite rows filled by linear interpolation between finite ones (held
    constant beyond the first and last; zeros if none is finite)."""
    ok = np.isfinite(path).all(axis=1)
    if ok.all():
        return path
    if not ok.any():
        return np.zeros_like(path)
    t = np.arange(len(path))
    return np.stack([np.interp(t, t[ok], path[ok, d]) for d in range(path.shape[1])], axis=1)


def _gaussian_smooth(path: np.ndarray, sigma: float) -> np.ndarray:
    """(F, D) path smoothed along frames by a Gaussian of `sigma` frames, zero-phase (centred:
    no lag, straight-line motion is kept exactly). The ends are padded by odd reflection about
    the end points, so the path's first and last points are kept and a padded step is a copy of
    a real one: each smoothed step is a weighted mean of the path's steps, never larger than
    the largest of them."""
    f = len(path)
    half = int(math.ceil(3.0 * sigma))
    if half < 1 or f < 3:
        return path.copy()
    w = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    w /= w.sum()
    padded = np.pad(path, ((half, half), (0, 0)), mode="reflect", reflect_type="odd")
    out = np.zeros_like(path, dtype=np.float64)
    for j, wj in enumerate(w):  # 2·half + 1 shifted copies: O(F·half), no per-frame loop
        out += wj * padded[j : j + f]
    return out


def _finite(x: np.ndarray) -> np.ndarray:
    """The finite rows of (N, dim) `x` (`x` itself when all are)."""
    ok = _rows_finite(x)
    return x if ok.all() else x[ok]


def _follow_target(positions: np.ndarray, pinned: np.ndarray, masses: np.ndarray | None,
                   index: int | None) -> np.ndarray:
    """(F, dim) float64 path the follow camera tracks: particle `index`, or the centre of mass of
    the moving (non-pinned; all, if every one is pinned) particles with finite positions (mass
    weighted where the masses are known). Frames without a finite target are interpolated."""
    f, n, dim = positions.shape
    if index is not None:
        return _fill_gaps(positions[:, index].astype(np.float64))
    sel = None if pinned.all() or not pinned.any() else ~pinned
    w_all = None if masses is None else np.asarray(masses, dtype=np.float64)
    out = np.full((f, dim), np.nan)
    for k in range(f):  # per frame, vectorised over particles
        x = positions[k] if sel is None else positions[k][sel]
        w = None if w_all is None else (w_all if sel is None else w_all[sel])
        ok = _rows_finite(x)
        if not ok.all():
            x, w = x[ok], None if w is None else w[ok]
        if len(x):
            out[k] = x.mean(axis=0, dtype=np.float64) if w is None else (w @ x.astype(np.float64)) / w.sum()
    return _fill_gaps(out)


#: Particles the follow camera's spread is measured on, at most (an even stride through them).
_SPREAD_SAMPLE = 20000


def _follow_centres(cam: _Camera, positions: np.ndarray, pinned: np.ndarray, masses: np.ndarray | None,
                    index: int | None, sigma_frames: float) -> tuple[np.ndarray, np.ndarray]:
    """The follow camera's (F, 2) screen-plane centres (the target's projected path smoothed by
    :func:`_gaussian_smooth`) and the (2,) half-extents of the moving particles around them: per
    frame the largest offset along each screen axis (the 95th percentile of them above 20
    particles, measured on at most _SPREAD_SAMPLE, so that a few strays do not zoom the view
    out), then the largest over frames (64 frames at most, spread through the run)."""
    f, n, _ = positions.shape
    target, _ = cam.project(_follow_target(positions, pinned, masses, index))
    centres = _gaussian_smooth(target, sigma_frames)
    moving = np.flatnonzero(~pinned) if (~pinned).any() else np.arange(n)
    q = 1.0 if moving.size <= 20 else 0.95
    moving = moving[:: max(1, -(-moving.size // _SPREAD_SAMPLE))]
    spread = np.zeros(2)
    for k in np.unique(np.linspace(0, f - 1, min(f, 64)).round().astype(np.int64)):
        x = _finite(positions[k][moving])
        if len(x):
            s, _ = cam.project(x)
            spread = np.maximum(spread, np.quantile(np.abs(s - centres[k].astype(s.dtype)), q, axis=0))
    return centres, spread


def _zoom_scales(cam: _Camera, positions: np.ndarray, pinned: np.ndarray, centres: np.ndarray, avail: np.ndarray,
                 lo: float, hi: float, sigma_frames: float) -> np.ndarray:
    """The zoom camera's (F,) scales (pixels per unit): each frame's the largest at which the
    moving particles' spread around its centre fits `avail` (2,) pixels (measured as
    :func:`_follow_centres` does but on 99 % of them, so that the subject of a close view is
    whole; on at most 256 frames spread through the run, interpolated between them), within
    [`lo`, `hi`]; then never larger than an earlier frame's (the view only widens), taken 3σ
    frames ahead and eased by a Gaussian of σ = `sigma_frames`, so it widens smoothly and before
    the motion needs it (an average of later, smaller scales: every frame still fits)."""
    f, n, _ = positions.shape
    moving = np.flatnonzero(~pinned) if (~pinned).any() else np.arange(n)
    q = 1.0 if moving.size <= 20 else 0.99
    moving = moving[:: max(1, -(-moving.size // _SPREAD_SAMPLE))]
    picks = np.unique(np.linspace(0, f - 1, min(f, 256)).round().astype(np.int64))
    fit = np.full(len(picks), hi)
    for j, k in enumerate(picks):
        x = _finite(positions[k][moving])
        if len(x):
            s, _ = cam.project(x)
            spread = np.quantile(np.abs(s - centres[k].astype(s.dtype)), q, axis=0)
            wide = spread > 0
            if wide.any():
                fit[j] = float(np.min(avail[wide] / (2.0 * spread[wide])))
    fit = np.minimum.accumulate(np.clip(np.interp(np.arange(f), picks, fit), lo, hi))
    ahead = int(math.ceil(3.0 * sigma_frames))
    lead = fit[np.minimum(np.arange(f) + ahead, f - 1)]
    if ahead < 1 or f < 3:
        return lead
    w = np.exp(-0.5 * (np.arange(-ahead, ahead + 1) / sigma_frames) ** 2)
    eased = np.convolve(np.pad(lead, ahead, mode="edge"), w / w.sum(), mode="valid")
    return np.minimum(eased, fit)


def _orbit_bounds(positions: np.ndarray, walls: np.ndarray | None, el_deg: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """For a camera turning about the vertical axis through the centre of the scene's xy
    bounding box (over all frames and walls): the axis point (3,) (z = 0), and the screen-plane
    box (lo, hi) that holds every point at every azimuth (a point at distance ρ from the axis
    and height z projects within ±ρ across and cos(el)·z ± sin(el)·ρ up), with max |x|."""
    frames = [*positions, *([] if walls is None or not len(walls) else [walls])]
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for x in frames:  # per frame, column by column
        x = _finite(x)
        if len(x):
            lo = np.minimum(lo, [x[:, 0].min(), x[:, 1].min()])
            hi = np.maximum(hi, [x[:, 0].max(), x[:, 1].max()])
    axis = np.zeros(3)
    if np.isfinite(lo).all():
        axis[:2] = 0.5 * (lo + hi)
    el = math.radians(el_deg)
    ce, se = math.cos(el), abs(math.sin(el))
    rho_max, up_lo, up_hi, amax = 0.0, math.inf, -math.inf, 0.0
    for x in frames:
        x = _finite(x)
        if not len(x):
            continue
        dt = x.dtype
        rho = np.hypot(x[:, 0] - dt.type(axis[0]), x[:, 1] - dt.type(axis[1]))
        rho_max = max(rho_max, float(rho.max()))
        z = x[:, 2] * dt.type(ce)
        rho *= dt.type(se)
        up_lo, up_hi = min(up_lo, float((z - rho).min())), max(up_hi, float((z + rho).max()))
        amax = max(amax, float(max(-x.min(), x.max())))
    return axis, np.array([-rho_max, up_lo]), np.array([rho_max, up_hi]), amax
