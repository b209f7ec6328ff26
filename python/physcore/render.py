"""Animated GIF rendering of physcore scenes, with numpy rasterisation and Pillow output.

The whole animation is simulated first and kept in memory (positions as float32), then a single
camera is fitted to every frame, and each frame is rasterised into a uint8 palette-index image:
static boundary (wall) particles in grey, springs as 1-pixel lines coloured by strain, particles
as filled discs coloured by speed or pressure, and a colour bar with the scale's range and unit.
The frames are written as a palette GIF with one fixed palette, atomically.

Public functions
----------------
record(scene, ...)             step a scene and return every frame's state (a Recording).
gif(recording, path, ...)      draw a Recording as an animated GIF (or a scene: record, then draw).
render_frame(positions, ...)   rasterise one state to an RGB array (for notebooks and tests).

Examples
--------
>>> import os, tempfile
>>> import physcore as pc
>>> scene = pc.scenes.projectile(n=3)
>>> image = pc.render.render_frame(scene.positions, velocities=scene.velocities, size=(64, 48))
>>> image.shape, image.dtype
((48, 64, 3), dtype('uint8'))
>>> with tempfile.TemporaryDirectory() as tmp:
...     out = pc.render.gif(scene, os.path.join(tmp, "balls.gif"), frames=4, size=(64, 48))
...     out.name, out.stat().st_size > 0
('balls.gif', True)
"""
from __future__ import annotations

import math
import operator
import os
import sys
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from . import _check
from ._atomic import atomic_write
from ._errors import InvalidInputError, InvalidTypeError

__all__ = ["record", "Recording", "gif", "render_frame", "COLOR_BY", "STRAIN_SATURATION"]

#: Valid values of the ``color_by`` argument.
COLOR_BY = ("speed", "pressure", "none")

#: Spring strain |(L - L0) / L0| at which the strain colours saturate (fully red or blue).
STRAIN_SATURATION = 0.1

#: Default oblique view of 3D scenes, (azimuth, elevation) in degrees.
DEFAULT_VIEW = (-60.0, 25.0)

#: Largest ``steps_per_frame`` and ``substeps``: 2**53, beyond which step counts and the time
#: ``n · dt`` are no longer exact in float64 (and no run would finish anyway).
MAX_STEPS = 2**53

# Most automatic substeps Scene.advance takes in one call (it refuses more, naming duration).
_MAX_AUTO_SUBSTEPS = 1e12

# ---------------------------------------------------------------------------------------------
# The one fixed palette. Index layout (at most 256 entries, the GIF limit; Pillow always encodes
# with 8-bit LZW codes, so the size of the table costs only its 768 bytes, once per file).
# ---------------------------------------------------------------------------------------------
_BACKGROUND = 0
_PLANE_FILL = 1
_PLANE_LINE = 2
_PINNED = 3
_PLAIN = 4
_N_SPEED = 64
_SPEED0 = 5
_N_STRAIN = 31
_STRAIN0 = _SPEED0 + _N_SPEED
_WALL = _STRAIN0 + _N_STRAIN  # static boundary particles: neutral grey
_TEXT = _WALL + 1  # colour-bar labels and outline
_N_PRESSURE = 64
_PRESSURE0 = _TEXT + 1
_PALETTE_SIZE = _PRESSURE0 + _N_PRESSURE

# viridis sampled at 9 points in [0, 1]; interpolated linearly and cut at 0.9 because its
# brightest yellow hardly shows on the white background.
_VIRIDIS = np.array(
    [
        [0x44, 0x01, 0x54], [0x47, 0x2D, 0x7B], [0x3B, 0x52, 0x8B],
        [0x2C, 0x72, 0x8E], [0x21, 0x91, 0x8C], [0x28, 0xAE, 0x80],
        [0x5E, 0xC9, 0x62], [0xAD, 0xDC, 0x30], [0xFD, 0xE7, 0x25],
    ],
    dtype=np.float64,
)
# plasma sampled at 9 points in [0, 1] (deep blue, purple, pink, orange, yellow); a sequential
# map distinct from the speed one, cut at 0.88 for the same reason.
_PLASMA = np.array(
    [
        [0x0D, 0x08, 0x87], [0x4C, 0x02, 0xA1], [0x7E, 0x03, 0xA8],
        [0xA9, 0x23, 0x95], [0xCC, 0x47, 0x78], [0xE5, 0x6B, 0x5D],
        [0xF8, 0x94, 0x41], [0xFD, 0xC3, 0x28], [0xF0, 0xF9, 0x21],
    ],
    dtype=np.float64,
)
_STRAIN_BLUE = np.array([33.0, 102.0, 172.0])  # compressed
_STRAIN_GREY = np.array([165.0, 165.0, 165.0])  # at rest
_STRAIN_RED = np.array([200.0, 30.0, 40.0])  # stretched


def _sample_map(anchors: np.ndarray, top: float, n: int) -> np.ndarray:
    """(n, 3) colours interpolated linearly along `anchors` (K, 3) from 0 to `top` in [0, 1]."""
    t = np.linspace(0.0, top, n) * (len(anchors) - 1)
    k = np.minimum(t.astype(int), len(anchors) - 2)
    f = (t - k)[:, None]
    return anchors[k] * (1 - f) + anchors[k + 1] * f


def _build_palette() -> np.ndarray:
    pal = np.zeros((_PALETTE_SIZE, 3), dtype=np.float64)
    pal[_BACKGROUND] = (255, 255, 255)
    pal[_PLANE_FILL] = (228, 222, 212)
    pal[_PLANE_LINE] = (110, 95, 80)
    pal[_PINNED] = (255, 127, 14)
    pal[_PLAIN] = (31, 119, 180)
    pal[_SPEED0:_STRAIN0] = _sample_map(_VIRIDIS, 0.9, _N_SPEED)
    half = _N_STRAIN // 2
    s = np.linspace(-1.0, 1.0, _N_STRAIN)[:, None]
    pal[_STRAIN0:_WALL] = np.where(
        s < 0, _STRAIN_GREY + (_STRAIN_GREY - _STRAIN_BLUE) * s, _STRAIN_GREY + (_STRAIN_RED - _STRAIN_GREY) * s
    )
    pal[_WALL] = (178, 178, 178)
    pal[_TEXT] = (30, 30, 30)
    pal[_PRESSURE0:] = _sample_map(_PLASMA, 0.88, _N_PRESSURE)
    assert _WALL == _STRAIN0 + 2 * half + 1 and pal.shape[0] <= 256
    return np.round(pal).astype(np.uint8)


_PALETTE = _build_palette()


# ---------------------------------------------------------------------------------------------
# Argument checks
# ---------------------------------------------------------------------------------------------
def _check_int(name: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, (bool, np.bool_)):
        raise InvalidTypeError(f"{name} must be an int, got {value!r}")
    try:
        n = operator.index(value)
    except TypeError:
        raise InvalidTypeError(f"{name} must be an int, got {type(value).__name__} {_short(value)}") from None
    if n < minimum:
        raise InvalidInputError(f"{name} must be >= {minimum}, got {n}")
    if maximum is not None and n > maximum:
        raise InvalidInputError(f"{name} must be <= {maximum}, got {_short(n)}")
    return n


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _check_size(size: Any) -> tuple[int, int]:
    try:
        count = len(size)
    except TypeError:  # no len(), or a 0-d array
        count = -1
    if isinstance(size, (str, bytes)) or count < 0:
        raise InvalidTypeError(f"size must be a pair of ints (width, height), got {_short(size)}")
    if count != 2:
        raise InvalidInputError(f"size must be a pair of ints (width, height), got {_short(size)}")
    w = _check_int("size[0] (width)", size[0], 16)
    h = _check_int("size[1] (height)", size[1], 16)
    if w > 65535 or h > 65535:
        raise InvalidInputError(f"size must be at most 65535 x 65535 (the GIF limit), got {_short(w)}x{_short(h)}")
    return w, h


def _check_fps(fps: Any) -> float:
    if isinstance(fps, (bool, np.bool_)) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise InvalidTypeError(f"fps must be a number, got {_short(fps)}")
    f = _check.real("fps", fps)
    if not (math.isfinite(f) and f > 0):
        raise InvalidInputError(f"fps must be a finite number > 0, got {_short(fps)}")
    return f


def _check_frame_time(frame_time: Any) -> float | None:
    if frame_time is None:
        return None
    if isinstance(frame_time, (bool, np.bool_)) or not isinstance(
        frame_time, (int, float, np.integer, np.floating)
    ):
        raise InvalidTypeError(f"frame_time must be a number of seconds or None, got {_short(frame_time)}")
    t = _check.real("frame_time", frame_time)
    # As Scene.advance: a subnormal duration has no finite reciprocal.
    if not (math.isfinite(t) and t >= _check.MIN_NORMAL):
        raise InvalidInputError(f"frame_time must be a finite number of seconds >= {_check.MIN_NORMAL:.3g}, got {_short(frame_time)}")
    return t


def _check_color_by(color_by: Any) -> str:
    if not isinstance(color_by, str) or color_by not in COLOR_BY:
        valid = ", ".join(repr(c) for c in COLOR_BY)
        raise InvalidInputError(f"color_by must be one of {valid}; got {_short(color_by)}")
    return str(color_by)


def _check_radius(radius: Any) -> int | None:
    if radius is None:
        return None
    r = _check_int("radius", radius, 0)
    if r > 200:
        raise InvalidInputError(f"radius must be <= 200 pixels, got {_short(r)}")
    return r


def _check_view(view: Any) -> tuple[float, float]:
    if view is None:
        return DEFAULT_VIEW
    try:
        count = len(view)
    except TypeError:  # no len(), or a 0-d array
        count = -1
    if isinstance(view, (str, bytes)) or count != 2:
        raise InvalidInputError(f"view must be (azimuth_deg, elevation_deg), got {_short(view)}")
    az, el = (_check.real("view", a) for a in view)
    if not (math.isfinite(az) and math.isfinite(el)):
        raise InvalidInputError(f"view must be finite angles in degrees, got {_short(view)}")
    return az, el


def _check_path(path: Any) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    p = Path(path)
    if p.suffix.lower() != ".gif":
        raise InvalidInputError(f"path must end in .gif, got {str(p)!r}")
    if not p.parent.is_dir():
        raise InvalidInputError(f"path: directory {str(p.parent)!r} does not exist")
    if p.is_dir():
        raise InvalidInputError(f"path {str(p)!r} is a directory")
    return p


def _check_writable(path: Path) -> None:
    """Create and remove a file beside ``path``, as the final atomic write will: an unwritable
    directory then fails in milliseconds, not after the whole simulation. Raises OSError."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".probe")
    except OSError as e:
        raise type(e)(e.errno, f"path: cannot create files in {str(path.parent)!r} ({e.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def _check_auto_substeps(scene: Any, frame_time: float) -> None:
    """Refuse, naming frame_time, a frame that would need more automatic substeps than
    ``Scene.advance`` takes in one call (1e12) at the scene's current substep."""
    auto_dt = getattr(scene, "auto_dt", None)
    if not callable(auto_dt):
        return
    step = float(auto_dt())
    if step > 0 and not frame_time / step <= _MAX_AUTO_SUBSTEPS:
        raise InvalidInputError(
            f"frame_time: {frame_time:.3g} s per frame would take {frame_time / step:.3g} automatic substeps of "
            f"{step:.3g} s, more than {_MAX_AUTO_SUBSTEPS:.0e}; give a shorter frame_time"
        )


def _check_memory(scene: Any, frames: int, size: tuple[int, int], springs: bool) -> None:
    """Refuse, before simulating, an animation whose recording and frames would not fit in
    memory (:func:`physcore._check.memory_limit`). InvalidInputError naming frames and size."""
    n = int(getattr(scene, "n_particles", 0))
    m = 0
    if springs and callable(getattr(scene, "spring_pairs", None)):
        m = int(np.asarray(scene.spring_pairs()[0]).size)
    dim = int(getattr(scene, "dim", 3))
    # float32 positions, speed, pressure per particle and strain per spring; the palette-index
    # buffer and its Pillow image per frame.
    per_frame = 4 * n * (dim + 2) + 4 * m + 2 * size[0] * size[1]
    _check.memory(
        "frames, size",
        frames * per_frame,
        f"{_short(frames)} frames of {size[0]}x{size[1]} pixels and {n} particles",
    )


def _gif_duration_ms(fps: float) -> int:
    # GIF delays are whole centiseconds; most viewers play delays under 20 ms at 100 ms, so clamp
    # (before rounding: 100 / fps is inf for a subnormal fps).
    cs = round(min(max(100.0 / fps, 2.0), 65535.0))
    return int(cs * 10)


# ---------------------------------------------------------------------------------------------
# Recording: what the simulation produced, per frame
# ---------------------------------------------------------------------------------------------
class Recording(NamedTuple):
    """What :func:`record` produced: the scene's state at every frame, as data (no pixels).

    Attributes
    ----------
    positions : (F, N, dim) float32
        Positions relative to `origin`, m (float32 keeps its precision near the scene's centre).
    origin : (dim,) float64
        Centroid of the first frame, m; absolute positions are ``positions + origin``.
    speeds : (F, N) float32 or None
        |v|, m/s (recorded when asked for).
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

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])



# Row-wise helpers written column by column: numpy reductions along a short last axis (N, 2)
# are several times slower than whole-column operations.
def _rows_finite(x: np.ndarray) -> np.ndarray:
    """(N, d) -> (N,) bool, True where the whole row is finite."""
    ok = np.isfinite(x[:, 0])
    for c in range(1, x.shape[1]):
        ok &= np.isfinite(x[:, c])
    return ok


def _row_norms(v: np.ndarray) -> np.ndarray:
    """(N, d) -> (N,) Euclidean norms."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _finite_mean(x: np.ndarray) -> np.ndarray:
    """(N, d) -> (d,) mean of the finite rows; zeros if there are none."""
    if np.isfinite(x).all():
        return np.array([x[:, c].mean() for c in range(x.shape[1])]) if len(x) else np.zeros(x.shape[1])
    ok = _rows_finite(x)
    return np.array([x[ok, c].mean() for c in range(x.shape[1])]) if ok.any() else np.zeros(x.shape[1])


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


def _scene_springs(scene: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    i, j, rest = scene.spring_pairs()
    i = np.asarray(i, dtype=np.intp)
    if i.size == 0:
        return None
    return i, np.asarray(j, dtype=np.intp), np.asarray(rest, dtype=np.float64)


def _pressure_array(p: Any, n: int) -> np.ndarray:
    """Check what ``scene.pressure()`` returned: (N,) float64 Pa."""
    p = np.asarray(p, dtype=np.float64)
    if p.shape != (n,):
        raise InvalidInputError(f"scene.pressure() must return an array of shape ({n},) in Pa, got shape {p.shape}")
    return p


def _scene_pressure(scene: Any, n: int) -> np.ndarray:
    """``scene.pressure()`` as (N,) float64 Pa; ValueError naming color_by if the scene has none."""
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


def _check_advance(scene: Any) -> None:
    if not callable(getattr(scene, "advance", None)):
        raise InvalidInputError(
            "frame_time needs a scene with an advance(duration) method (automatic substeps); "
            "this one has none: use steps_per_frame instead"
        )


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
) -> Recording:
    """Step `scene` and record every frame; frame 0 (read before any stepping) is the current state.

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
    # Store positions relative to the start centroid so float32 keeps its precision far from 0.
    origin = _finite_mean(x) if n else (_finite_mean(walls) if walls is not None and len(walls) else np.zeros(dim))
    pos = np.empty((frames, n, dim), dtype=np.float32)
    speeds = np.empty((frames, n), dtype=np.float32) if need_speed else None
    pressures = np.empty((frames, n), dtype=np.float32) if need_pressure else None
    strain = np.empty((frames, sp[0].size), dtype=np.float32) if sp is not None else None
    has_time = hasattr(scene, "time")
    times = np.empty(frames) if has_time else None
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
                if speeds is not None:
                    v = np.asarray(scene.velocities, dtype=np.float64).reshape(n, dim)
                    speeds[k] = _row_norms(v)
                if pressures is not None:
                    pressures[k] = p0 if k == 0 else _pressure_array(scene.pressure(), n)
                if strain is not None:
                    strain[k] = _strain(x, *sp)
            if times is not None:
                times[k] = float(scene.time)
            if on_frame is not None:
                on_frame(k, scene, taken)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    pinned = np.asarray(scene.pinned, dtype=bool).reshape(n)
    pairs = (sp[0], sp[1]) if sp is not None else None
    return Recording(
        pos,
        origin,
        speeds,
        pairs,
        strain,
        pinned,
        _planes(getattr(scene, "planes", None), dim),
        pressures=pressures,
        walls=None if walls is None else walls - origin,
        times=times,
    )


# ---------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------
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

    def fit(self, lo: np.ndarray, hi: np.ndarray, pad: int, tol: float = 0.0, top_pad: int | None = None) -> None:
        """Fit the screen-plane box [lo, hi] into the image with `pad` pixels spare each side.

        `top_pad` (default `pad`) keeps that many pixels spare at the top instead (room for the
        colour bar). A box no wider than `tol` (world units) counts as a point and gets a unit box
        around it.
        """
        top = pad if top_pad is None else top_pad
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or np.any(hi < lo):
            lo, hi = np.full(2, -0.5), np.full(2, 0.5)
        ext = hi - lo
        avail = np.array([max(self.width - 2 * pad, 1), max(self.height - pad - top, 1)], dtype=float)
        self.row0 = 0.5 * self.height + 0.5 * (top - pad)
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


def _auto_radius(n: int, size: tuple[int, int]) -> int:
    """Disc radius in pixels from the particle count alone (an upper bound for the final one)."""
    # About a third of the mean spacing were the particles spread over the image; capped so a few
    # bodies (Kepler) are dots rather than blobs.
    w, h = size
    r = int(0.3 * math.sqrt(w * h / max(n, 1)))
    return max(0, min(r, max(1, min(w, h) // 40)))


def _spring_radius(rec: Recording, scale: float) -> int | None:
    """Disc radius in pixels from the median spring length at frame 0, or None without springs.

    Keeps discs to about a third of the neighbour spacing so that the springs stay visible.
    """
    if rec.pairs is None or rec.pairs[0].size == 0:
        return None
    i, j = rec.pairs
    x = rec.positions[0]
    length = float(np.median(_row_norms(x[j] - x[i])))
    if not (length > 0 and math.isfinite(length)):
        return None
    return int(0.3 * length * scale)


# ---------------------------------------------------------------------------------------------
# Rasterisation (numpy only; no per-particle Python loops)
# ---------------------------------------------------------------------------------------------
def _disc_stencil(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets (S,) intp of a filled disc of `radius` pixels."""
    d = np.arange(-radius, radius + 1)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    # r^2 + r/2 rounds the disc: radius 1 is a plus, radius 2 a 5x5 square without corners.
    keep = dx * dx + dy * dy <= radius * radius + 0.5 * radius
    return dy[keep].astype(np.intp), dx[keep].astype(np.intp)


def _background(cam: _Camera, planes: list, origin: np.ndarray) -> np.ndarray:
    """(H, W) uint8 index image with the colliders of a 2D scene: solid side shaded, edge a line."""
    w, h = cam.width, cam.height
    img = np.full((h, w), _BACKGROUND, dtype=np.uint8)
    if cam.dim != 2 or not planes:
        return img
    # World coordinates (relative to origin) of the pixel centres.
    xs = (np.arange(w) + 0.5 - 0.5 * w) / cam.scale + cam.centre[0]
    ys = (cam.row0 - (np.arange(h) + 0.5)) / cam.scale + cam.centre[1]
    for p, n in planes:
        p = p - origin
        # Signed distance in pixels; > 0 on the allowed side.
        d = ((xs[None, :] - p[0]) * n[0] + (ys[:, None] - p[1]) * n[1]) * cam.scale
        img[d < 0] = _PLANE_FILL
        img[np.abs(d) <= 0.75] = _PLANE_LINE
    return img


def _draw_lines(buf: np.ndarray, c0, r0, c1, r1, colors: np.ndarray) -> None:
    """Draw segments between (M,) float pixel endpoints, sampling about one point per pixel.

    colors is (M,) uint8. Samples falling outside buf are dropped.
    """
    h, w = buf.shape
    ok = np.isfinite(c0) & np.isfinite(r0) & np.isfinite(c1) & np.isfinite(r1)
    # Segments wholly outside the image cost nothing.
    ok &= (np.maximum(c0, c1) >= 0) & (np.minimum(c0, c1) < w)
    ok &= (np.maximum(r0, r1) >= 0) & (np.minimum(r0, r1) < h)
    if not ok.all():
        c0, r0, c1, r1, colors = c0[ok], r0[ok], c1[ok], r1[ok], colors[ok]
    if c0.size == 0:
        return
    c0, r0 = c0.astype(np.float32), r0.astype(np.float32)
    dc, dr = c1.astype(np.float32) - c0, r1.astype(np.float32) - r0
    # One sample per pixel along the longer axis, capped (a segment crossing the image from far
    # outside would otherwise cost memory for nothing).
    n = np.minimum(np.ceil(np.maximum(np.abs(dc), np.abs(dr))), 2 * (w + h)).astype(np.int64) + 1
    first = np.cumsum(n) - n
    # Sample k of segment m sits at t = k / (n_m - 1); np.repeat spreads per-segment values.
    k = np.arange(int(first[-1] + n[-1]), dtype=np.int64) - np.repeat(first, n)
    t = k.astype(np.float32) * np.repeat((1.0 / np.maximum(n - 1, 1)).astype(np.float32), n)
    cc = np.floor(np.repeat(c0, n) + t * np.repeat(dc, n)).astype(np.int64)
    rr = np.floor(np.repeat(r0, n) + t * np.repeat(dr, n)).astype(np.int64)
    vals = np.repeat(colors, n)
    inside = (cc >= 0) & (cc < w) & (rr >= 0) & (rr < h)
    if not inside.all():
        cc, rr, vals = cc[inside], rr[inside], vals[inside]
    buf.reshape(-1)[rr * w + cc] = vals


def _draw_discs(buf: np.ndarray, col, row, colors: np.ndarray, stencil) -> None:
    """Draw filled discs at (N,) float pixel centres with (N,) uint8 colours.

    Particles later in the arrays overwrite earlier ones (1-D fancy assignment writes in index
    order), which gives the painter's order.
    """
    h, w = buf.shape
    dy, dx = stencil
    r = int(np.abs(dx).max())
    ok = (col > -r - 1) & (col < w + r) & (row > -r - 1) & (row < h + r)  # also drops NaN
    if not ok.all():
        col, row, colors = col[ok], row[ok], colors[ok]
    ci = np.floor(col).astype(np.int64)
    ri = np.floor(row).astype(np.int64)
    flat = buf.reshape(-1)
    # Discs wholly inside need no per-pixel bounds test. A fitted camera keeps every particle at
    # least r + 2 pixels from the edges, so the clipped path below is the rare one and drawing it
    # second cannot upset the painter's order in practice.
    inner = (ci >= r) & (ci < w - r) & (ri >= r) & (ri < h - r)
    all_inner = bool(inner.all())
    centre = ri * w + ci if all_inner else ri[inner] * w + ci[inner]
    offsets = dy.astype(np.int64) * w + dx
    if offsets.size == 1:
        flat[centre] = colors if all_inner else colors[inner]
    else:
        flat[(centre[:, None] + offsets).reshape(-1)] = np.repeat(colors if all_inner else colors[inner], offsets.size)
    if not all_inner:
        edge = ~inner
        rr = ri[edge][:, None] + dy
        cc = ci[edge][:, None] + dx
        inside = (cc >= 0) & (cc < w) & (rr >= 0) & (rr < h)
        flat[(rr * w + cc)[inside]] = np.broadcast_to(colors[edge][:, None], rr.shape)[inside]


def _scalar_levels(values: np.ndarray, vmax: float, base: int, levels: int) -> np.ndarray:
    """(N,) values -> (N,) uint8 indices into the sequential map of `levels` entries at `base`.

    0 (and anything below, and NaN) maps to the bottom, `vmax` and above to the top.
    """
    if not (vmax > 0 and math.isfinite(vmax)):
        return np.full(values.shape, base, dtype=np.uint8)
    with np.errstate(over="ignore", invalid="ignore"):  # a subnormal vmax: overflow to inf, the top
        lv = np.nan_to_num(values * (levels / vmax), nan=0.0, posinf=levels, neginf=0.0)
    return (base + np.clip(lv, 0, levels - 1).astype(np.uint8)).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Colour bar: a horizontal gradient strip with its range and unit, in the top-right corner. The
# camera keeps a band at the top free of particles for it, so it never hides any, and since the
# scale is fixed over the animation it is drawn once, into the background.
# ---------------------------------------------------------------------------------------------
_CB_MARGIN = 4  # pixels between the colour bar and the image's top and right edges
_CB_GAP = 4  # pixels between a label and the strip
_CB_MIN_LENGTH = 32  # shortest strip worth drawing, pixels
_CB_MAX_LENGTH = 120


class _ColorBarLayout(NamedTuple):
    lo: str  # label at the bottom of the scale (left of the strip)
    hi: str  # label at the top (right of the strip), with the unit
    lo_x: int  # left pixel column of `lo`
    strip_x: int  # first gradient column
    length: int  # gradient columns
    hi_x: int  # left pixel column of `hi`
    text_y: int  # top row of the labels' text cell
    band: int  # rows [0, band) hold the colour bar


def _font():
    from PIL import ImageFont

    # The classic bitmap font (about 6x11 pixels a character): crisp in a palette image.
    load = getattr(ImageFont, "load_default_imagefont", None)  # Pillow >= 10.1
    return load() if load is not None else ImageFont.load_default()


def _text_mask(text: str) -> np.ndarray:
    """(11, width) bool pixels of `text` in the default bitmap font."""
    from PIL import Image, ImageDraw

    font = _font()
    x0, y0, x1, y1 = font.getbbox(text)
    im = Image.new("L", (max(int(x1), 1), max(int(y1), 1)), 0)
    ImageDraw.Draw(im).text((0, 0), text, fill=255, font=font)
    return np.asarray(im) > 127


def _format_value(v: float) -> str:
    """Three significant digits; plain digits (no exponent) from 1000 up to 10^6."""
    return f"{v:.0f}" if 1000 <= v < 1e6 else f"{v:.3g}"


def _colorbar_labels(color_by: str, vmax: float) -> tuple[str, str]:
    """Bottom and top labels of the colour bar; pressure in Pa, kPa, MPa or GPa, whichever reads
    as a number below 1000."""
    if color_by == "pressure":
        for factor, unit in ((1.0, "Pa"), (1e3, "kPa"), (1e6, "MPa"), (1e9, "GPa")):  # noqa: B007 - used after the loop
            if float(f"{vmax / factor:.3g}") < 1000:
                break
        return "0", f"{_format_value(vmax / factor)} {unit}"
    return "0", f"{_format_value(vmax)} m/s"


def _colorbar_layout(size: tuple[int, int], lo: str, hi: str) -> _ColorBarLayout | None:
    """Where the colour bar goes in an image of `size`, or None if it would not fit legibly."""
    w, h = size
    lo_mask, hi_mask = _text_mask(lo), _text_mask(hi)
    lo_w, hi_w = lo_mask.shape[1], hi_mask.shape[1]
    text_y = _CB_MARGIN - 1  # the font's cell has 2 blank rows above the digits
    band = text_y + max(lo_mask.shape[0], hi_mask.shape[0]) + 2
    if 5 * band > h:  # the band would take more than a fifth of the height
        return None
    # Right to left: margin, top label, gap, strip (with a 1-pixel outline), gap, bottom label.
    spare = w - 2 * _CB_MARGIN - hi_w - lo_w - 2 * _CB_GAP - 2
    length = min(max(int(round(0.2 * w)), _CB_MIN_LENGTH), _CB_MAX_LENGTH, spare)
    if length < _CB_MIN_LENGTH:
        return None
    hi_x = w - _CB_MARGIN - hi_w
    strip_x = hi_x - _CB_GAP - 1 - length
    lo_x = strip_x - 1 - _CB_GAP - lo_w
    return _ColorBarLayout(lo, hi, lo_x, strip_x, length, hi_x, text_y, band)


def _draw_colorbar(buf: np.ndarray, bar: _ColorBarLayout, base: int, levels: int) -> None:
    """Draw the colour bar of the `levels`-entry map at palette index `base` into buf (H, W)."""
    # Clear its box (a collider's shading may reach the top of the image).
    buf[: bar.band, max(bar.lo_x - 2, 0) :] = _BACKGROUND
    for text, x in ((bar.lo, bar.lo_x), (bar.hi, bar.hi_x)):
        mask = _text_mask(text)
        region = buf[bar.text_y : bar.text_y + mask.shape[0], x : x + mask.shape[1]]
        region[mask[: region.shape[0], : region.shape[1]]] = _TEXT
    # Strip over the digits' rows (2..8 of the font cell), outlined.
    top, bottom = bar.text_y + 1, bar.text_y + 9  # outline rows
    x0, x1 = bar.strip_x - 1, bar.strip_x + bar.length  # outline columns
    buf[top : bottom + 1, x0 : x1 + 1] = _TEXT
    c = np.arange(bar.length)
    ramp = (base + np.minimum((c + 0.5) * levels / bar.length, levels - 1).astype(np.int64)).astype(np.uint8)
    buf[top + 1 : bottom, bar.strip_x : bar.strip_x + bar.length] = ramp[None, :]


def _strain_levels(strain: np.ndarray) -> np.ndarray:
    """(M,) strains -> (M,) uint8 palette indices; NaN (zero rest length) -> at-rest grey."""
    half = _N_STRAIN // 2
    # Clipped before dividing, so that a strain near the float32 limit cannot overflow.
    s = np.clip(np.nan_to_num(strain, nan=0.0), -STRAIN_SATURATION, STRAIN_SATURATION) / STRAIN_SATURATION
    return (_STRAIN0 + half + np.rint(s * half)).astype(np.uint8)


class _Rasteriser:
    """Everything fixed over an animation: camera, background, stencil, colour scale."""

    def __init__(
        self,
        rec: Recording,
        size: tuple[int, int],
        color_by: str,
        radius: int | None,
        view: tuple[float, float],
        speed_scale: float | None = None,
        *,
        pressure_scale: float | None = None,
        colorbar: bool = False,
    ):
        n, dim = rec.positions.shape[1:]
        walls = rec.walls if rec.walls is not None and len(rec.walls) else None
        self.rec = rec
        self.radius = _auto_radius(n + (0 if walls is None else len(walls)), size) if radius is None else radius
        self.color_by = color_by
        # The colour scale: 0 at the bottom, the top fixed over the animation.
        self.vmax = 0.0
        values, scale, base, levels = {
            "speed": (rec.speeds, speed_scale, _SPEED0, _N_SPEED),
            "pressure": (rec.pressures, pressure_scale, _PRESSURE0, _N_PRESSURE),
        }.get(color_by, (None, None, 0, 0))
        if values is not None and values.size:
            if scale is None:
                finite = values[np.isfinite(values)]
                # 99th percentile: a few outliers should not wash out the whole map.
                scale = float(np.percentile(finite, 99)) if finite.size else 0.0
            self.vmax = float(scale)
        self.colorbar = None
        if colorbar and values is not None and self.vmax > 0 and math.isfinite(self.vmax):
            self.colorbar = _colorbar_layout(size, *_colorbar_labels(color_by, self.vmax))
        self.cam = _Camera(dim, view, size)
        pad = max(self.radius + 2, int(round(0.05 * min(size))))
        lo, hi, amax = _screen_bounds(self.cam, rec.positions)
        if walls is not None:
            wlo, whi, wmax = _screen_bounds(self.cam, walls[None])
            lo, hi, amax = np.minimum(lo, wlo), np.maximum(hi, whi), max(amax, wmax)
        # Keep the colour bar's band free: no disc reaches into it.
        top_pad = None if self.colorbar is None else max(pad, self.colorbar.band + self.radius + 1)
        # Positions are float32 relative to the origin: extents below their rounding are zero.
        self.cam.fit(lo, hi, pad, tol=1e-6 * amax, top_pad=top_pad)
        if radius is None:
            r_springs = _spring_radius(rec, self.cam.scale)
            if r_springs is not None:
                self.radius = min(self.radius, r_springs)
        self.stencil = _disc_stencil(self.radius)
        self.background = _background(self.cam, rec.planes, rec.origin)
        if walls is not None:
            # Static: drawn once, under everything that moves.
            s, _ = self.cam.project(walls)
            col, row = self.cam.pixels(s)
            _draw_discs(self.background, col, row, np.full(col.shape, _WALL, dtype=np.uint8), self.stencil)
        if self.colorbar is not None:
            _draw_colorbar(self.background, self.colorbar, base, levels)
        # 2D draw order: pinned particles last, so they stay visible (3D sorts by depth per frame).
        self.pin_order = np.argsort(rec.pinned, kind="stable") if dim == 2 and rec.pinned.any() else None

    def frame(self, k: int) -> np.ndarray:
        """(H, W) uint8 palette-index image of frame k."""
        rec = self.rec
        buf = self.background.copy()
        s, depth = self.cam.project(rec.positions[k])
        col, row = self.cam.pixels(s)
        if rec.pairs is not None and rec.strain is not None:
            i, j = rec.pairs
            _draw_lines(buf, col[i], row[i], col[j], row[j], _strain_levels(rec.strain[k]))
        if col.size == 0:
            return buf
        if self.color_by == "speed" and rec.speeds is not None:
            colors = _scalar_levels(rec.speeds[k], self.vmax, _SPEED0, _N_SPEED)
        elif self.color_by == "pressure" and rec.pressures is not None:
            colors = _scalar_levels(rec.pressures[k], self.vmax, _PRESSURE0, _N_PRESSURE)
        else:
            colors = np.full(col.shape, _PLAIN, dtype=np.uint8)
        colors[rec.pinned] = _PINNED
        if depth is not None:
            order = np.argsort(depth, kind="stable")  # painter's algorithm: far ones first
        else:
            order = self.pin_order
        if order is not None:
            col, row, colors = col[order], row[order], colors[order]
        _draw_discs(buf, col, row, colors, self.stencil)
        return buf


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
def gif(
    scene: Any,
    path: str | os.PathLike,
    *,
    frames: int | None = None,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int | None = None,
    fps: float = 30,
    size: tuple[int, int] = (480, 360),
    color_by: str = "speed",
    colorbar: bool = True,
    radius: int | None = None,
    springs: bool = True,
    view: tuple[float, float] | None = None,
    progress: bool = False,
) -> Path:
    """Draw a :class:`Recording` as an animated GIF, or simulate `scene` forward and draw it:
    ``gif(scene, path, ...)`` is ``gif(record(scene, ...), path, ...)``.

    Frame 0 shows the current state; between consecutive frames the scene advances either
    ``steps_per_frame`` steps of ``scene.dt`` (default), so the animation covers
    ``(frames - 1) * steps_per_frame * scene.dt`` seconds of simulated time, or, with
    `frame_time`, ``frame_time`` seconds with substeps the scene picks itself, covering
    ``(frames - 1) * frame_time`` seconds. The scene is left at the last frame's state. The whole
    run is simulated before anything is drawn, and a single camera is fitted to all frames (and to
    the scene's boundary particles), so the view does not move.

    Parameters
    ----------
    scene : physcore.Scene or Recording
        A recording from :func:`record` (then `frames`, `steps_per_frame`, `frame_time` and
        `substeps` must be left out: it is already simulated, and `color_by` needs what it
        recorded), or a 2D or 3D scene, stepped in place. Optional methods, used when present:
        ``pressure()`` -> (N,) float64 Pa (needed for ``color_by="pressure"``),
        ``boundary_points()`` -> (B, dim) float64 m, static wall particles (B may be 0), and
        ``advance(duration)`` -> int substeps taken (needed for `frame_time`).
    path : str or os.PathLike
        Output file; must end in ``.gif`` and its directory must exist and be writable (checked
        by creating and removing a file there before simulating). Written atomically: a
        temporary file in the same directory is renamed onto `path` only once complete.
    frames : int, default 90
        Number of frames, >= 1 (scenes only). Together with `size` and the scene's particles it must fit in
        memory: the estimate ``frames · (4 N (dim + 2) + 4 M + 2 W H)`` bytes (N particles,
        M springs, W × H pixels) is refused above :func:`physcore._check.memory_limit` (half
        the physical memory) before anything is simulated.
    steps_per_frame : int, optional
        Simulation steps of ``scene.dt`` between frames, 1 to :data:`MAX_STEPS` (2**53). Default
        10 when `frame_time` is not given; giving both is an error.
    frame_time : float, optional
        Simulated seconds between frames, finite and at least 2.2e-308 (a normal float64). Each
        frame then calls ``scene.advance(frame_time)``, which picks its own substeps (from the
        scene's CFL and stability limits) and returns how many it took; with `progress` the bar
        shows the last frame's count. The scene must have an ``advance`` method, and a frame
        that would need more than 1e12 automatic substeps is refused before simulating.
    substeps : "auto" or int, default "auto"
        With `frame_time`: ``"auto"`` lets ``scene.advance`` choose the substeps of every frame
        inside the integrator's stability region (see :meth:`physcore.Scene.advance`); an int
        (1 to 2**53) fixes that many per frame. Needs `frame_time`.
    fps : float, default 30
        Playback rate, > 0. GIF stores delays in whole centiseconds and most viewers play delays
        below 20 ms at 100 ms, so the delay is rounded to 10 ms and clamped to at least 20 ms
        (fps above 50 play at 50).
    size : (int, int), default (480, 360)
        Image width and height in pixels, each >= 16.
    color_by : {"speed", "pressure", "none"}, default "speed"
        Particle colouring. ``"speed"``: a viridis-like map of |v| (m/s). ``"pressure"``: a
        plasma-like map of ``scene.pressure()`` (Pa; 0 for particles that are not fluid,
        negative values get the bottom colour). Both scales run from 0 at the bottom to a top
        fixed over the whole animation at the 99th percentile of all frames' values.
        ``"none"``: one colour. Pinned particles are always orange.
    colorbar : bool, default True
        With ``color_by`` "speed" or "pressure", draw a colour bar in the top-right corner: a
        gradient strip labelled "0" and the top of the scale with its unit (m/s; Pa, kPa, MPa or
        GPa, whichever reads below 1000), e.g. ``0 [strip] 19.6 kPa``. The camera keeps a band at
        the top free for it, so no particle is hidden. It is left out where it would not be
        legible (images narrower than about 100 pixels or shorter than 80) and when the top of
        the scale is 0 (nothing moves, no pressure).
    radius : int, optional
        Particle disc radius in pixels (0 draws single pixels). Default: chosen from the number
        of particles and boundary particles and the image size.
    springs : bool, default True
        Draw the springs of all ``Springs`` terms as lines under the particles, coloured by strain
        (L - L0)/L0: grey at rest, red stretched, blue compressed, saturating at
        ``STRAIN_SATURATION`` (10 %).
    view : (float, float), optional
        3D only: (azimuth, elevation) of the orthographic camera in degrees; screen up is +z.
        Default ``(-60, 25)``. Ignored for 2D scenes (x right, y up).
    progress : bool, default False
        Show a tqdm progress bar on stderr while simulating.

    Returns
    -------
    pathlib.Path
        `path`.

    Raises
    ------
    TypeError
        An argument of the wrong type (``bool`` is not an int, ``str`` not a number, and
        `colorbar`, `springs`, `progress` must be bools), naming it.
    physcore.InvalidInputError
        (a ``ValueError``) An invalid value, naming it, including an animation too large for
        memory (naming frames and size). Raised before the scene is stepped or a file is made.
        ValueError also covers ``color_by="pressure"`` on a scene without ``pressure()`` (or
        whose ``pressure()`` raises AttributeError), and `frame_time` on a scene without
        ``advance``.
    physcore.SimulationDiverged
        If the simulation diverges; no file is written (the scene is rolled back to the last
        good state of the failing ``step``/``advance`` call by the scene itself).
    OSError
        If the file cannot be written: an unwritable directory is found before simulating; a
        failure while writing leaves no partial file behind.

    Notes
    -----
    Collider planes are drawn in 2D (shaded solid side and an edge line), not in 3D. Boundary
    particles are drawn once, in grey, under everything that moves; in 3D they are projected the
    same way but not depth-sorted against the moving particles (always underneath). Pillow
    merges consecutive identical frames into one longer frame, so a GIF of a scene at rest can
    report fewer frames than `frames` while playing for the same time.
    """
    duration = _gif_duration_ms(_check_fps(fps))
    size = _check_size(size)
    color_by = _check_color_by(color_by)
    radius = _check_radius(radius)
    view = _check_view(view)
    colorbar = _check.flag("colorbar", colorbar)
    springs = _check.flag("springs", springs)
    progress = _check.flag("progress", progress)
    path = _check_path(path)
    if isinstance(scene, Recording):
        rec = scene
        given = [a for a, v in (("frames", frames), ("steps_per_frame", steps_per_frame), ("frame_time", frame_time), ("substeps", substeps)) if v is not None]
        if given:
            raise InvalidInputError(f"{given[0]}: a Recording is already simulated; give it to record() instead")
        if color_by == "speed" and rec.speeds is None or color_by == "pressure" and rec.pressures is None:
            raise InvalidInputError(f"color_by: the recording holds no {color_by}s; record(..., color_by={color_by!r})")
        if not springs:
            rec = rec._replace(pairs=None, strain=None)
        _check.memory("frames, size", rec.frames * 2 * size[0] * size[1], f"{rec.frames} frames of {size[0]}x{size[1]} pixels")
        _check_writable(path)
    else:
        plan = _plan(scene, frames, steps_per_frame, frame_time, substeps, color_by, springs)
        _check_memory(scene, plan["frames"], size, springs)
        _check_writable(path)
        rec = _simulate(scene, progress=progress, **plan)
    ras = _Rasteriser(rec, size, color_by, radius, view, colorbar=colorbar)
    _write_gif(path, (ras.frame(k) for k in range(rec.frames)), duration)
    return path


def _plan(
    scene: Any,
    frames: int | None,
    steps_per_frame: int | None,
    frame_time: float | None,
    substeps: str | int | None,
    color_by: str,
    springs: bool,
) -> dict[str, Any]:
    """The checked simulation arguments of :func:`record` (and :func:`gif` of a scene), as
    keyword arguments of ``_simulate``. Raises before anything is stepped."""
    frames = _check_int("frames", 90 if frames is None else frames, 1)
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
    if steps_per_frame is None:
        steps_per_frame = 10
    elif frame_time is not None:
        raise InvalidInputError("give steps_per_frame or frame_time, not both")
    else:
        steps_per_frame = _check_int("steps_per_frame", steps_per_frame, 1, MAX_STEPS)
    if frame_time is not None:
        _check_advance(scene)
        if substeps == "auto":
            _check_auto_substeps(scene, frame_time)
    return {
        "frames": frames,
        "steps_per_frame": steps_per_frame,
        "need_speed": color_by == "speed",
        "springs": springs,
        "need_pressure": color_by == "pressure",
        "frame_time": frame_time,
        "substeps": substeps,
    }


def record(
    scene: Any,
    *,
    frames: int = 90,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int = "auto",
    color_by: str = "speed",
    springs: bool = True,
    progress: bool = False,
    on_frame: Any = None,
) -> Recording:
    """Step `scene` and return every frame's state as data: the producing half of :func:`gif`.

    Frame 0 is the current state; between frames the scene advances ``steps_per_frame`` steps
    (default 10) or, with `frame_time`, ``frame_time`` seconds in automatic (or `substeps`
    fixed) substeps, exactly as :func:`gif` does with the same arguments. The scene is left at
    the last frame.

    Parameters
    ----------
    scene, frames, steps_per_frame, frame_time, substeps, springs, progress
        As for :func:`gif`.
    color_by : {"speed", "pressure", "none"}, default "speed"
        Which per-particle scalar to record (|v| or ``scene.pressure()``) for colouring later.
    on_frame : callable, optional
        ``on_frame(k, scene, substeps)`` after frame ``k`` is recorded; ``substeps`` is what
        ``scene.advance`` returned for that frame (None for frame 0 and for fixed steps). For
        progress reports and probes (energy books, counters); it must not change the scene.

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
    color_by = _check_color_by(color_by)
    springs = _check.flag("springs", springs)
    progress = _check.flag("progress", progress)
    if on_frame is not None and not callable(on_frame):
        raise InvalidTypeError(f"on_frame: expected a callable or None, got {type(on_frame).__name__}")
    plan = _plan(scene, frames, steps_per_frame, frame_time, substeps, color_by, springs)
    _check_memory(scene, plan["frames"], (0, 0), springs)
    return _simulate(scene, progress=progress, on_frame=on_frame, **plan)


def _write_gif(path: Path, index_frames, duration_ms: int) -> None:
    from PIL import Image

    palette = _PALETTE.tobytes()
    images = []
    for buf in index_frames:
        im = Image.fromarray(buf)  # 'L' from the (H, W) uint8 buffer; putpalette makes it 'P'
        im.putpalette(palette)
        images.append(im)
    # Passing the palette writes it once as the global colour table and keeps Pillow from
    # re-optimising it per frame (smaller files, and faster).
    atomic_write(
        path,
        lambda fh: images[0].save(
            fh, format="GIF", save_all=True, append_images=images[1:], duration=duration_ms, loop=0, palette=palette
        ),
    )


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
) -> np.ndarray:
    """Rasterise one state to an RGB image, with the camera fitted to that state.

    Parameters
    ----------
    positions : array_like (N, dim) float, or physcore.Scene
        Particle positions in m, dim 2 or 3. A Scene supplies its positions, and also its
        velocities, pinned flags, springs, planes, pressures (``pressure()``, only for
        ``color_by="pressure"``) and boundary points (``boundary_points()``, where it has those
        methods) unless those are given explicitly.
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
    color_by : {"speed", "pressure", "none"}, default "speed"
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
        i, j, rest = springs
        sp = (np.asarray(i, dtype=np.intp), np.asarray(j, dtype=np.intp), np.asarray(rest, dtype=np.float64))
        if not (sp[0].shape == sp[1].shape == sp[2].shape and sp[0].ndim == 1):
            raise InvalidInputError("springs: i, j and rest must be 1-D arrays of equal length")
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

    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise InvalidInputError(f"positions must have shape (N, 2) or (N, 3), got {x.shape}")
    n, dim = x.shape
    if sp is not None and sp[0].size and (
        min(sp[0].min(), sp[1].min()) < 0 or max(sp[0].max(), sp[1].max()) >= n
    ):
        raise InvalidInputError(f"springs: particle index out of range for {n} particles")
    pin = np.zeros(n, dtype=bool) if pinned is None else np.asarray(pinned, dtype=bool)
    if pin.shape != (n,):
        raise InvalidInputError(f"pinned must have shape ({n},), got {pin.shape}")
    speeds = None
    if color_by == "speed" and velocities is not None:
        v = np.asarray(velocities, dtype=np.float64)
        if v.shape != x.shape:
            raise InvalidInputError(f"velocities must have shape {x.shape}, got {v.shape}")
        speeds = _row_norms(v).astype(np.float32)[None]
    pres = None
    if color_by == "pressure":
        if pressures is None:
            raise InvalidInputError("color_by='pressure' needs pressures= (or a scene with a pressure() method)")
        p = np.asarray(pressures, dtype=np.float64)
        if p.shape != (n,):
            raise InvalidInputError(f"pressures must have shape ({n},), got {p.shape}")
        pres = p.astype(np.float32)[None]
    walls = None
    if boundary is not None:
        try:
            walls = _boundary_array(boundary, dim)
        except ValueError as e:
            raise InvalidInputError(f"boundary: {e}") from None
    for name, value in (("speed_scale", speed_scale), ("pressure_scale", pressure_scale)):
        if value is not None:
            v = float(value)
            if not (v > 0 and math.isfinite(v)):
                raise InvalidInputError(f"{name} must be a finite number > 0, got {value!r}")
    speed_scale = None if speed_scale is None else float(speed_scale)
    pressure_scale = None if pressure_scale is None else float(pressure_scale)

    if n:
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
        planes=_planes(planes, dim),
        pressures=pres,
        walls=None if walls is None else walls - origin,
    )
    ras = _Rasteriser(
        rec, size, color_by, radius, view, speed_scale=speed_scale, pressure_scale=pressure_scale, colorbar=bool(colorbar)
    )
    return _PALETTE[ras.frame(0)]
