"""Argument checks of the public functions: each returns the checked value or raises
InvalidTypeError / InvalidInputError naming the argument, before anything is stepped or written."""
from __future__ import annotations

import math
import operator
import os
from pathlib import Path
from typing import Any

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ._camera import CAMERAS, DEFAULT_VIEW
from ._palette import CMAPS, GROUP_COLORS

#: Valid values of the ``color_by`` argument.
COLOR_BY = ("speed", "pressure", "strain", "density", "none")

# Most automatic substeps Scene.advance takes in one call (it refuses more, naming duration).
_MAX_AUTO_SUBSTEPS = 1e12


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
    try:
        w0, h0 = size[0], size[1]
    except (TypeError, KeyError, IndexError):  # a set or a dict: two things, but no pair
        raise InvalidTypeError(f"size must be a pair of ints (width, height), got {_short(size)}") from None
    w = _check_int("size[0] (width)", w0, 16)
    h = _check_int("size[1] (height)", h0, 16)
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
        raise InvalidInputError(f"color_by: must be one of {valid}; got {_short(color_by)}")
    return str(color_by)


def _check_cmap(cmap: Any) -> str | None:
    """None, or the name of one of :data:`CMAPS` (InvalidInputError / InvalidTypeError naming cmap)."""
    if cmap is None:
        return None
    if not isinstance(cmap, str):
        raise InvalidTypeError(f"cmap must be a str naming a colour map, got {type(cmap).__name__}")
    if cmap not in CMAPS:
        raise InvalidInputError(f"cmap: must be one of {', '.join(CMAPS)}; got {_short(cmap)}")
    return cmap


def _rgb_rows(value: Any, arg: str, count: int | None) -> np.ndarray:
    """(K, 3) uint8 from RGB rows (uint8 or ints 0–255, or floats in [0, 1]) or "#rrggbb"
    strings; `count`: K required (None: any)."""
    arr = _check.array(arg, value)
    if arr.dtype.kind in "US":
        flat = arr.reshape(-1)
        rows = []
        for text in flat:
            t = str(text)
            if len(t) != 7 or t[0] != "#" or any(ch not in "0123456789abcdefABCDEF" for ch in t[1:]):
                raise InvalidInputError(f"{arg}: colours as text must be '#rrggbb', got {_short(t)}")
            rows.append([int(t[1:3], 16), int(t[3:5], 16), int(t[5:7], 16)])
        arr = np.array(rows, dtype=np.int64).reshape(-1, 3)
    elif arr.dtype == bool or arr.dtype.kind not in "uif":
        raise InvalidTypeError(f"{arg} must hold numbers (RGB) or '#rrggbb' strings, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3 or (count is not None and arr.shape[0] != count):
        want = f"({count}, 3)" if count is not None else "(K, 3)"
        raise InvalidInputError(f"{arg} must have shape {want} (RGB per particle), got {arr.shape}")
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or arr.min(initial=0.0) < 0 or arr.max(initial=0.0) > 1:
            raise InvalidInputError(f"{arg}: float colours must be finite and in [0, 1] (or give uint8 0–255)")
        return np.rint(arr * 255).astype(np.uint8)
    if arr.size and (arr.min() < 0 or arr.max() > 255):
        raise InvalidInputError(f"{arg}: integer colours must be 0–255, got {int(arr.min())} to {int(arr.max())}")
    return arr.astype(np.uint8)


def _check_colors(colors: Any, n: int) -> np.ndarray | None:
    """None, or (n, 3) uint8 RGB from `colors` as ``gif(colors=...)`` takes it: RGB rows,
    "#rrggbb" strings, or (n,) integer group labels (≥ 0) in :data:`GROUP_COLORS`."""
    if colors is None:
        return None
    arr = _check.array("colors", colors) if not isinstance(colors, (str, bytes)) else None
    if arr is None or arr.dtype == object:
        raise InvalidTypeError(f"colors must be an array of RGB rows, '#rrggbb' strings or group labels, got {type(colors).__name__}")
    if arr.ndim == 1 and arr.dtype.kind in "US":
        arr = arr.reshape(-1, 1)
        if arr.shape[0] != n:
            raise InvalidInputError(f"colors must give one colour per particle ({n}), got {arr.shape[0]}")
        return _rgb_rows(arr.reshape(-1), "colors", None)
    if arr.ndim == 1:
        if arr.dtype.kind not in "iu" or arr.dtype == bool:
            raise InvalidTypeError(f"colors as group labels must be integers, got dtype {arr.dtype}")
        if arr.shape[0] != n:
            raise InvalidInputError(f"colors must give one group label per particle ({n}), got {arr.shape[0]}")
        if arr.size and arr.min() < 0:
            raise InvalidInputError(f"colors: group labels must be >= 0, got {int(arr.min())}")
        return GROUP_COLORS[arr.astype(np.int64) % len(GROUP_COLORS)]
    return _rgb_rows(arr, "colors", n)


def _check_background(background: Any) -> tuple[int, int, int] | None:
    """None, or an RGB triple of ints 0–255 (a "#rrggbb" string, or floats in [0, 1], too)."""
    if background is None:
        return None
    if isinstance(background, (str, bytes)):
        background = [background]
    a = _check.array("background", background)
    row = _rgb_rows([background] if a.ndim == 1 and a.dtype.kind not in "US" else background, "background", 1)
    return (int(row[0, 0]), int(row[0, 1]), int(row[0, 2]))


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


#: Valid values of the ``arrows`` argument.
ARROWS = ("none", "velocity", "acceleration")

_CAMERA_FORMS = "'fit', 'follow', 'zoom', 'orbit', ('follow', particle_index), ('zoom', particle_index) or ('orbit', degrees_per_second)"


def _check_camera(camera: Any, dim: int, n: int) -> tuple[str, Any]:
    """(mode, parameter): ("fit", None), ("follow" or "zoom", None or a particle index in
    [0, n)), ("orbit", None or finite degrees per second of playback); orbit needs a 3D scene
    (`dim`)."""
    if isinstance(camera, str):
        mode, param = camera, None
    elif isinstance(camera, (tuple, list)) and len(camera) == 2 and isinstance(camera[0], str):
        mode, param = camera
    elif isinstance(camera, (tuple, list)):
        raise InvalidInputError(f"camera must be {_CAMERA_FORMS}; got {_short(camera)}")
    else:
        raise InvalidTypeError(f"camera must be a str or a (str, number) pair, got {type(camera).__name__} {_short(camera)}")
    if mode not in CAMERAS or (mode == "fit" and not isinstance(camera, str)):
        raise InvalidInputError(f"camera must be {_CAMERA_FORMS}; got {_short(camera)}")
    if mode == "orbit" and dim != 3:
        raise InvalidInputError(f"camera='orbit' turns a 3D view; this scene is {dim}D (use 'fit', 'follow' or 'zoom')")
    if param is None:
        return mode, None
    if mode in ("follow", "zoom"):
        index = _check_int("camera's particle index", param, 0)
        if index >= n:
            raise InvalidInputError(f"camera: particle index {index} is out of range for {n} particles")
        return mode, index
    if isinstance(param, (bool, np.bool_)) or not isinstance(param, (int, float, np.integer, np.floating)):
        raise InvalidTypeError(f"camera: ('orbit', degrees_per_second) needs a number, got {_short(param)}")
    rate = _check.real("camera", param)
    if not math.isfinite(rate):
        raise InvalidInputError(f"camera: the orbit's degrees per second must be finite, got {_short(param)}")
    return mode, rate


def _check_arrows(arrows: Any) -> str | None:
    """None (no arrows) or "velocity" / "acceleration"."""
    if arrows is None:
        return None
    if not isinstance(arrows, str):
        raise InvalidTypeError(f"arrows must be a str or None, got {type(arrows).__name__} {_short(arrows)}")
    if arrows not in ARROWS:
        raise InvalidInputError(f"arrows: must be one of {', '.join(repr(a) for a in ARROWS)} or None; got {_short(arrows)}")
    return None if arrows == "none" else arrows


def _check_path(path: Any, fmt: str = "gif") -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    _check_no_nul(path)
    p = Path(path)
    if p.suffix.lower() != f".{fmt}":
        other = fmt == "gif" and p.suffix.lower() in (".mp4", ".webm", ".png", ".glb", ".gltf", ".html", ".htm")
        hint = f"; pc.render.save(scene, {p.name!r}) writes {p.suffix.lower()}" if other else ""
        raise InvalidInputError(f"path must end in .{fmt}, got {str(p)!r}{hint}")
    if not p.parent.is_dir():
        raise InvalidInputError(f"path: directory {str(p.parent)!r} does not exist")
    if p.is_dir():
        raise InvalidInputError(f"path {str(p)!r} is a directory")
    if p.exists() and not p.is_file():  # a FIFO, socket or device: refused before the simulation, not after
        raise InvalidInputError(f"path {str(p)!r} is not a regular file (a pipe, socket or device)")
    return p


def _check_png_targets(path: Path, count: int) -> None:
    """Refuse, before anything is simulated, a PNG sequence (``stem_0000.png``, …) whose
    frame files include one that is not a regular file: found only while the frames were put
    in place, it left an older sequence of the same name half replaced."""
    digits = max(4, len(str(count - 1)))
    for k in range(count):
        target = path.with_name(f"{path.stem}_{k:0{digits}d}.png")
        if target.exists() and not target.is_file():
            raise InvalidInputError(f"path: frame file {str(target)!r} is a directory or not a regular file")


def _check_no_nul(path: Any) -> None:
    """Refuse a path holding a NUL character (the OS cannot open it; tempfile raised a bare
    ValueError "embedded null byte"), as Scene.save does."""
    p = os.fspath(path)
    if ("\0" if isinstance(p, str) else b"\0") in p:
        raise InvalidInputError("path: contains a NUL character")


def _check_writable(path: Path) -> None:
    """Create and remove a file beside ``path``, as the final atomic write will: an unwritable
    directory then fails in milliseconds, not after the whole simulation. Raises OSError."""
    import tempfile

    _check_no_nul(path)
    try:
        fd, probe = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".probe")
    except OSError as e:
        raise type(e)(e.errno, f"path: cannot create files in {str(path.parent)!r} ({e.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def _check_auto_substeps(scene: Any, frame_time: float, name: str = "frame_time") -> None:
    """Refuse, naming `name` (frame_time, or the lead-in before the first frame), a span of
    simulated time that would need more automatic substeps than ``Scene.advance`` takes in one
    call (1e12) at the scene's current substep."""
    auto_dt = getattr(scene, "auto_dt", None)
    if not callable(auto_dt):
        return
    step = float(auto_dt())
    if step > 0 and not frame_time / step <= _MAX_AUTO_SUBSTEPS:
        raise InvalidInputError(
            f"{name}: {frame_time:.3g} s{' per frame' if name == 'frame_time' else ''} would take {frame_time / step:.3g} automatic substeps of "
            f"{step:.3g} s, more than {_MAX_AUTO_SUBSTEPS:.0e}; give a shorter {name}"
        )


def _check_memory(scene: Any, frames: int, size: tuple[int, int], springs: bool, velocities: bool = False) -> None:
    """Refuse, before simulating, an animation whose recording and frames would not fit in
    memory (:func:`physcore._check.memory_limit`). InvalidInputError naming frames and size.
    `velocities`: the recording holds them too (arrows)."""
    n = int(getattr(scene, "n_particles", 0))
    m = 0
    if springs and callable(getattr(scene, "spring_pairs", None)):
        m = int(np.asarray(scene.spring_pairs()[0]).size)
    dim = int(getattr(scene, "dim", 3))
    # float32 positions, speed, pressure per particle and strain per spring; the palette-index
    # buffer and its Pillow image per frame.
    per_frame = 4 * n * (dim + 2) + 4 * m + 2 * size[0] * size[1] + (4 * n * dim if velocities else 0)
    # A grid's recorded field (float32, one 2D slice) and a fluid's tracers.
    grids = getattr(scene, "grids", ())
    cells = 0
    if grids:
        g = grids[0]
        cells = int(g.shape[0]) * int(g.shape[1])
        per_frame += 4 * cells + 8 * int(getattr(g, "n_tracers", 0))
    _check.memory(
        "frames, size",
        frames * per_frame,
        f"{_short(frames)} frames of {size[0]}x{size[1]} pixels, {n} particles" + (f" and {cells} grid cells" if cells else ""),
    )


def _check_advance(scene: Any) -> None:
    if not callable(getattr(scene, "advance", None)):
        raise InvalidInputError(
            "frame_time needs a scene with an advance(duration) method (automatic substeps); "
            "this one has none: use steps_per_frame instead"
        )


def _extent_box(extent: Any, dim: int) -> np.ndarray | None:
    """The 2**dim corners (float64) of the box `extent` = (lower, upper), or None."""
    if extent is None:
        return None
    lo_hi = _check.real_array("extent", extent).astype(np.float64)
    if lo_hi.shape != (2, dim) or not np.all(np.isfinite(lo_hi)):
        raise InvalidInputError(
            f"extent: expected (lower, upper), two finite points of {dim} coordinates, got shape {lo_hi.shape}"
            + ("" if lo_hi.shape != (2, dim) else f": {lo_hi.tolist()}")
        )
    if not np.all(lo_hi[1] >= lo_hi[0]):
        raise InvalidInputError(f"extent: lower must be <= upper on every axis, got lower {lo_hi[0].tolist()}, upper {lo_hi[1].tolist()}")
    if np.abs(lo_hi).max() > 1e38:  # the drawing's coordinates are float32 (3.4e38 at most)
        raise InvalidInputError(f"extent: coordinates must be within ±1e38 m (the drawing is float32), got {lo_hi.tolist()}")
    return np.array([[lo_hi[(k >> a) & 1, a] for a in range(dim)] for k in range(2**dim)])
