"""How a particle animation looks beyond its colouring: :class:`Look`, the one parameter object
of ``gif(look=...)`` (trails that fade, line widths, lit spheres, a backdrop and static props,
the areas a radius vector sweeps), its checks, and the drawing helpers it needs (numpy and
Pillow, on full-colour frames)."""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from ._checks import _check_int, _rgb_rows

#: ``Look.shading`` values: flat discs, or discs lit as spheres.
SHADINGS = ("flat", "sphere")


@dataclasses.dataclass(frozen=True)
class Look:
    """How ``gif()`` draws a particle animation beyond its colouring; every field's default
    leaves the picture as it was. Give a Look or a dict of some of its fields
    (``gif(scene, look={"trail_fade": 0.0})``); a scene's ``render_defaults["look"]`` is the
    default, and a dict given to ``gif`` changes only the fields it names (None: the default).

    Attributes
    ----------
    trail_fade : float in [0, 1], optional
        Trails fade with age to this opacity at their oldest end, from full opacity at the
        particle: opacity ``f + (1 − f)(1 − age)²``, age from 0 (now) to 1 (`trail` frames
        ago), so the last moments read and older loops fade out (0: to nothing). Each trail is
        blended over what is drawn under it (a backdrop, swept areas). Default None: the fixed
        ramp (15 % to 75 % of the particle's colour, or the palette's trail shades).
    trail_width : int, optional
        Trail width in pixels, 1 to 16. Default: 1, and 2 on images of 300 pixels and more.
    trail_samples : int, optional
        Points per frame step along each trail, 1 to 64: with more than 1, the path between
        two frames is the cubic Hermite curve of the recorded positions and velocities at both
        ends (:func:`gif` records the velocities for it; a recording without them takes
        Catmull–Rom tangents from the neighbouring frames), drawn as that many segments, so a
        close pass that turns sharply between two frames reads as a curve, not a corner.
        Default 1: one straight segment a frame step.
    trail_of : sequence of int, optional
        The particles whose paths the trail draws (a chain's free end, a pendulum's bob: one
        path that reads where every particle's would clutter). Default: every moving one.
    spring_width : int, optional
        Springs (rods, strings, a chain's links) drawn this many pixels wide, 1 to 32, as soft
        round-capped strokes in full-colour frames, under the discs, coloured as before (by
        strain, or the particle's own colour). Default: 1 pixel (2 for own-colour springs on
        images of 300 pixels and more), strain-coloured springs over the discs.
    shading : {"flat", "sphere"}
        ``"sphere"``: each disc lit as a ball (Lambert diffuse plus a Blinn–Phong highlight
        from a light at the upper left, a darker rim), a steel ball's look. Default "flat".
    backdrop : ((r, g, b), (r, g, b)), optional
        A vertical gradient from the first colour at the top to the second at the bottom,
        behind everything (the background colour of the palette becomes their mean, which text
        boxes and the classic trails fade into).
    decor : sequence of dict
        Static props drawn over the backdrop and under everything that moves, in world
        coordinates (m), antialiased, and included in the camera's fit: ``{"polygon":
        [[x, y], ...], "color": (r, g, b)}`` (filled, three points or more) or ``{"line":
        [[x, y], ...], "color": (r, g, b), "width": px}`` (a polyline, default 2 px). A
        cradle's frame, a ceiling bracket: what explains the scene but does not move. In 3D
        the lowest horizontal polygon is a floor: a mesh drawn over it casts a soft shadow on
        it (light from overhead; fainter the higher the mesh hangs), as it does on an upward
        plane collider and on the upward faces of fixed bodies.
    swept_areas : dict, optional
        Kepler's second law drawn: the areas the line from particle ``"centre"`` to particle
        ``"body"`` sweeps in equal times, as wedges of ``"frames"`` frames each (the first from
        frame 0), filled in two alternating colours (``"colors"``: default the body's and the
        centre's own colours), the one being swept brighter than the ``"count"`` − 1 before it
        (default 5), with the radius vector drawn. The body's path between
        frames is the cubic Hermite curve of the recorded positions and velocities, so the
        wedges' areas are those of the motion (:func:`swept_polygons`). With ``loop`` the
        wedges run on across the GIF's end (`frames` should divide the frame count).
    hulls : sequence of sequences of int, optional
        2D: groups of particles drawn as one solid body each (a rigid box of grains), in
        place of their discs: the convex hull of the group's discs (each of its drawn radius,
        the true radius with ``size_by="radius"``), filled in the group's first particle's
        colour with a darker rim. For a convex rigid body of grains the hull is its outline
        but for the notches between neighbouring grains (a grain of another body can sit a
        little way into one). Drawn under the other discs.
    """

    trail_fade: float | None = None
    trail_width: int | None = None
    trail_samples: int = 1
    trail_of: tuple = ()
    spring_width: int | None = None
    shading: str = "flat"
    backdrop: tuple | None = None
    decor: tuple = ()
    swept_areas: dict | None = None
    hulls: tuple = ()

    @property
    def full_colour(self) -> bool:
        """Whether this look needs frames drawn in full colour (soft discs)."""
        return (self.shading != "flat" or self.backdrop is not None or bool(self.decor)
                or self.swept_areas is not None or self.spring_width is not None or bool(self.hulls))


_FIELDS = tuple(f.name for f in dataclasses.fields(Look))


def check_look(value: Any, base: Any = None) -> Look:
    """The checked :class:`Look` of `value` (a Look, a dict of some of its fields, or None)
    over `base` (the scene's default, likewise): the fields `value` names replace `base`'s."""
    fields: dict[str, Any] = {}
    for v in (base, value):
        if v is None:
            continue
        if isinstance(v, Look):
            v = dataclasses.asdict(v)
        if not isinstance(v, dict):
            raise InvalidTypeError(f"look must be a physcore.render.Look or a dict of its fields, got {type(v).__name__}")
        unknown = _keys(k for k in v if k not in _FIELDS)
        if unknown:
            raise InvalidInputError(f"look: unknown field(s) {unknown}; valid: {', '.join(_FIELDS)}")
        fields.update(v)
    out: dict[str, Any] = {}
    fade = fields.get("trail_fade")
    if fade is not None:
        out["trail_fade"] = _check.float_in_range("look.trail_fade", fade, 0.0, 1.0)
    for name, top in (("trail_width", 16), ("spring_width", 32), ("trail_samples", 64)):
        if fields.get(name) is not None:
            out[name] = _check_int(f"look.{name}", fields[name], 1, top)
    if fields.get("shading") is not None:
        out["shading"] = _check.choice("look.shading", fields["shading"], SHADINGS)
    if fields.get("backdrop") is not None:
        rows = _rgb_rows(fields["backdrop"], "look.backdrop", 2)
        out["backdrop"] = tuple(tuple(int(c) for c in row) for row in rows)
    if fields.get("decor") is not None:
        out["decor"] = tuple(_check_decor_item(k, item) for k, item in enumerate(_items("look.decor", fields["decor"])))
    if fields.get("swept_areas") is not None:
        out["swept_areas"] = _check_swept(fields["swept_areas"])
    if fields.get("trail_of") is not None and (trail_of := _items("look.trail_of", fields["trail_of"])):
        out["trail_of"] = _check_hull("trail_of", trail_of, "look.trail_of")
    if fields.get("hulls") is not None:
        out["hulls"] = tuple(_check_hull(k, group) for k, group in enumerate(_items("look.hulls", fields["hulls"])))
    return Look(**out)


def _items(arg: str, value: Any) -> list:
    """The entries of `value`, a list, tuple or array (InvalidTypeError naming `arg` otherwise:
    a number, a string, a dict or a set is not a sequence of entries)."""
    if isinstance(value, np.ndarray) and value.ndim >= 1:
        return list(value)
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
        raise InvalidTypeError(f"{arg} must be a list of entries, got {type(value).__name__}")
    return list(value)


def _keys(keys: Any) -> str:
    """Dict keys for a message, in a stable order whatever their types."""
    return ", ".join(sorted(repr(k) if not isinstance(k, str) else k for k in keys))


def _check_hull(k: Any, group: Any, where: str | None = None) -> tuple[int, ...]:
    where = f"look.hulls[{k}]" if where is None else where
    idx = _check.array(where, group)
    if idx.ndim != 1 or idx.size == 0 or idx.dtype.kind not in "iu" or (idx < 0).any():
        raise InvalidInputError(f"{where} must be a non-empty sequence of particle indices (ints >= 0), got {group!r}")
    return tuple(int(i) for i in idx)


def _check_decor_item(k: int, item: Any) -> dict:
    where = f"look.decor[{k}]"
    if not isinstance(item, dict):
        raise InvalidTypeError(f"{where} must be a dict with 'polygon' or 'line', and 'color'; got {type(item).__name__}")
    kinds = [key for key in ("polygon", "line") if key in item]
    unknown = [key for key in item if key not in ("polygon", "line", "color", "width")]
    if len(kinds) != 1 or unknown:
        raise InvalidInputError(f"{where} needs exactly one of 'polygon' and 'line' (and 'color', 'width'), got keys {_keys(item)}")
    kind = kinds[0]
    pts = _check.real_array(f"{where}.{kind}", item[kind]).astype(np.float64)
    least = 3 if kind == "polygon" else 2
    if pts.ndim != 2 or pts.shape[0] < least or pts.shape[1] not in (2, 3) or not np.isfinite(pts).all():
        raise InvalidInputError(f"{where}.{kind} must be {least} or more finite points (K, 2) or (K, 3), got shape {pts.shape}")
    if "color" not in item:
        raise InvalidInputError(f"{where} needs a 'color'")
    color = tuple(int(c) for c in _rgb_rows([item["color"]] if not isinstance(item["color"], str) else item["color"], f"{where}.color", 1)[0])
    width = _check_int(f"{where}.width", item.get("width", 2), 1, 64) if kind == "line" else None
    return {"kind": kind, "points": pts, "color": color, "width": width}


def _check_swept(value: Any) -> dict:
    if not isinstance(value, dict):
        raise InvalidTypeError(f"look.swept_areas must be a dict with 'centre', 'body' and 'frames', got {type(value).__name__}")
    unknown = _keys(k for k in value if k not in ("centre", "body", "frames", "count", "colors"))
    missing = ", ".join(k for k in ("centre", "body", "frames") if k not in value)
    if unknown or missing:
        raise InvalidInputError(f"look.swept_areas: keys 'centre', 'body', 'frames' (and 'count', 'colors'); "
                                f"{'unknown ' + unknown if unknown else 'missing ' + missing}")
    out = {
        "centre": _check_int("look.swept_areas['centre']", value["centre"], 0),
        "body": _check_int("look.swept_areas['body']", value["body"], 0),
        "frames": _check_int("look.swept_areas['frames']", value["frames"], 1),
        "count": _check_int("look.swept_areas['count']", value.get("count", 6), 1, 1000),
        "colors": None,
    }
    if out["centre"] == out["body"]:
        raise InvalidInputError(f"look.swept_areas: 'centre' and 'body' must be two particles, got {out['centre']} twice")
    if value.get("colors") is not None:
        out["colors"] = _rgb_rows(value["colors"], "look.swept_areas['colors']", 2).astype(np.uint8)
    return out


def check_look_particles(look: Look, n: int, dim: int) -> None:
    """Refuse particle indices and decor points that do not fit a recording of `n` particles
    in `dim` dimensions."""
    sw = look.swept_areas
    if sw is not None and max(sw["centre"], sw["body"]) >= n:
        raise InvalidInputError(f"look.swept_areas: particle indices must be in [0, {n}), got centre {sw['centre']}, body {sw['body']}")
    if look.trail_of and max(look.trail_of) >= n:
        raise InvalidInputError(f"look.trail_of: particle indices must be in [0, {n}), got {max(look.trail_of)}")
    for k, group in enumerate(look.hulls):
        if dim != 2:
            raise InvalidInputError(f"look.hulls: drawn in 2D scenes only, got a {dim}D one")
        if max(group) >= n:
            raise InvalidInputError(f"look.hulls[{k}]: particle indices must be in [0, {n}), got {max(group)}")
    for k, item in enumerate(look.decor):
        if item["points"].shape[1] != dim:
            raise InvalidInputError(f"look.decor[{k}]: points of {item['points'].shape[1]} coordinates in a {dim}D scene")


# --------------------------------------------------------------------------- lines and widths


def width_offsets(width: int) -> tuple[tuple[int, int], ...]:
    """Pixel offsets (dc, dr) that draw a 1-pixel line `width` pixels wide: (0, 0) for 1, the
    classic three of a 2-pixel trail, then a rounded square of side `width`."""
    if width <= 1:
        return ((0, 0),)
    if width == 2:
        return ((0, 0), (1, 0), (0, 1))
    r = 0.5 * (width - 1)
    reach = int(math.ceil(r))
    return tuple((dc, dr) for dr in range(-reach, reach + 1) for dc in range(-reach, reach + 1)
                 if dc * dc + dr * dr <= r * r + 0.5 * r)


def stroke_points(c0: np.ndarray, r0: np.ndarray, c1: np.ndarray, r1: np.ndarray, step: float = 0.75
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points every `step` pixels along each segment (both ends included), in segment order,
    and the (P,) index of the segment each belongs to: soft round strokes drawn as a row of
    antialiased discs (``_core.draw_discs``)."""
    ok = np.isfinite(c0) & np.isfinite(r0) & np.isfinite(c1) & np.isfinite(r1)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return np.zeros(0, np.float32), np.zeros(0, np.float32), np.zeros(0, np.int64)
    c0, r0, c1, r1 = (np.asarray(a, np.float64)[idx] for a in (c0, r0, c1, r1))
    n = np.minimum(np.ceil(np.hypot(c1 - c0, r1 - r0) / step), 4096).astype(np.int64) + 1
    first = np.cumsum(n) - n
    k = np.arange(int(n.sum()), dtype=np.int64) - np.repeat(first, n)
    t = k / np.repeat(np.maximum(n - 1, 1), n)
    seg = np.repeat(np.arange(idx.size), n)
    cc = c0[seg] + t * (c1 - c0)[seg]
    rr = r0[seg] + t * (r1 - r0)[seg]
    return cc.astype(np.float32), rr.astype(np.float32), idx[seg]


# --------------------------------------------------------------------------- lit spheres


#: The light of ``shading="sphere"`` (towards the viewer's upper left; x right, y down, z out of
#: the image), and the half vector towards the viewer.
_LIGHT = np.array([-0.45, -0.6, 0.66]) / np.linalg.norm([-0.45, -0.6, 0.66])
_HALF = (_LIGHT + np.array([0.0, 0.0, 1.0])) / np.linalg.norm(_LIGHT + np.array([0.0, 0.0, 1.0]))


def draw_spheres(out: np.ndarray, col: np.ndarray, row: np.ndarray, rad: np.ndarray, rgb: np.ndarray) -> None:
    """Discs lit as balls onto the (H, W, 3) uint8 image `out`, in the order given (later ones
    in front): at (N,) pixel centres `col`, `row` with (N,) radii `rad` (px) and (N, 3) uint8
    colours, each pixel blended by the disc's coverage of it (an antialiased edge). Shading:
    ambient 0.3 plus Lambert 0.75 of the colour, a darker rim, and a Blinn–Phong highlight
    (exponent 60) of white light, the look of polished steel."""
    h, w = out.shape[:2]
    for i in range(len(col)):
        c, r, R = float(col[i]), float(row[i]), float(rad[i])
        if not (math.isfinite(c) and math.isfinite(r)) or R <= 0:
            continue
        c0, c1 = max(0, int(math.floor(c - R - 1))), min(w, int(math.ceil(c + R + 1)))
        r0, r1 = max(0, int(math.floor(r - R - 1))), min(h, int(math.ceil(r + R + 1)))
        if c0 >= c1 or r0 >= r1:
            continue
        yy, xx = np.mgrid[r0:r1, c0:c1].astype(np.float32)
        dx, dy = (xx + 0.5 - c) / R, (yy + 0.5 - r) / R
        d2 = dx * dx + dy * dy
        d = np.sqrt(d2)
        cover = np.clip(R * (1.0 - d) + 0.5, 0.0, 1.0)[..., None]
        nz = np.sqrt(np.clip(1.0 - d2, 0.0, 1.0))
        lambert = np.clip(dx * _LIGHT[0] + dy * _LIGHT[1] + nz * _LIGHT[2], 0.0, 1.0)
        spec = np.clip(dx * _HALF[0] + dy * _HALF[1] + nz * _HALF[2], 0.0, 1.0) ** 60
        rim = 1.0 - 0.35 * np.clip(d2, 0.0, 1.0) ** 2
        base = rgb[i].astype(np.float32)
        lit = base * ((0.3 + 0.75 * lambert) * rim)[..., None] + (255.0 * 0.85 * spec)[..., None]
        patch = out[r0:r1, c0:c1].astype(np.float32)
        out[r0:r1, c0:c1] = np.clip(np.rint(patch * (1 - cover) + lit * cover), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- filled shapes


def polygon_coverage(pts: np.ndarray, shape: tuple[int, int], supersample: int = 4) -> tuple[int, int, np.ndarray] | None:
    """The antialiased coverage of the polygon with (K, 2) pixel vertices (column, row) in an
    image of `shape`: (top, left, (h, w) float32 coverage in [0, 1]) over its bounding box, by
    Pillow's scan conversion at `supersample` × the resolution; None if it misses the image."""
    from PIL import Image, ImageDraw

    pts = np.asarray(pts, np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) < 2:
        return None
    h, w = shape
    left, top = max(0, int(math.floor(pts[:, 0].min())) - 1), max(0, int(math.floor(pts[:, 1].min())) - 1)
    right, bottom = min(w, int(math.ceil(pts[:, 0].max())) + 1), min(h, int(math.ceil(pts[:, 1].max())) + 1)
    if left >= right or top >= bottom:
        return None
    s = supersample
    img = Image.new("L", ((right - left) * s, (bottom - top) * s), 0)
    local = (pts - [left, top]) * s
    ImageDraw.Draw(img).polygon([tuple(p) for p in local], fill=255)
    a = np.asarray(img, np.float32).reshape(bottom - top, s, right - left, s).mean(axis=(1, 3)) / 255.0
    return top, left, a


def polyline_coverage(pts: np.ndarray, width: float, shape: tuple[int, int], supersample: int = 4
                      ) -> tuple[int, int, np.ndarray] | None:
    """As :func:`polygon_coverage`, for a polyline `width` pixels wide with round joints."""
    from PIL import Image, ImageDraw

    pts = np.asarray(pts, np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) < 2:
        return None
    h, w = shape
    m = 0.5 * width + 1
    left, top = max(0, int(math.floor(pts[:, 0].min() - m))), max(0, int(math.floor(pts[:, 1].min() - m)))
    right, bottom = min(w, int(math.ceil(pts[:, 0].max() + m))), min(h, int(math.ceil(pts[:, 1].max() + m)))
    if left >= right or top >= bottom:
        return None
    s = supersample
    img = Image.new("L", ((right - left) * s, (bottom - top) * s), 0)
    local = [tuple(p) for p in (pts - [left, top]) * s]
    ImageDraw.Draw(img).line(local, fill=255, width=max(1, int(round(width * s))), joint="curve")
    a = np.asarray(img, np.float32).reshape(bottom - top, s, right - left, s).mean(axis=(1, 3)) / 255.0
    return top, left, a


def blend(out: np.ndarray, cover: tuple[int, int, np.ndarray] | None, rgb: Any, opacity: float = 1.0) -> None:
    """Blend colour `rgb` into the (H, W, 3) image `out` (uint8 or float) by `cover` (from
    :func:`polygon_coverage`) times `opacity`."""
    if cover is None:
        return
    top, left, a = cover
    hh, ww = a.shape
    a = (a * np.float32(opacity))[..., None]
    patch = out[top : top + hh, left : left + ww].astype(np.float32)
    mixed = patch * (1 - a) + np.asarray(rgb, np.float32) * a
    out[top : top + hh, left : left + ww] = np.rint(mixed) if out.dtype == np.uint8 else mixed


def disc_hull(col: np.ndarray, row: np.ndarray, rad: np.ndarray, sides: int = 32) -> np.ndarray:
    """(M, 2) pixel vertices (column, row), in order, of the convex hull of the discs at
    (K,) centres `col`, `row` with (K,) radii `rad`: each disc as a regular `sides`-gon round
    its circle (whose edges touch it), hulled by Andrew's monotone chain. Non-finite discs are
    left out; empty if none is left."""
    ok = np.isfinite(col) & np.isfinite(row) & np.isfinite(rad)
    if not ok.any():
        return np.zeros((0, 2))
    a = np.arange(sides) * (2 * math.pi / sides)
    reach = np.asarray(rad, np.float64)[ok, None] / math.cos(math.pi / sides)
    pts = np.stack([(np.asarray(col, np.float64)[ok, None] + reach * np.cos(a)).ravel(),
                    (np.asarray(row, np.float64)[ok, None] + reach * np.sin(a)).ravel()], axis=1)
    pts = np.unique(pts, axis=0)  # sorted by column, then row
    if len(pts) < 3:
        return pts

    def chain(points: np.ndarray) -> list:
        out: list = []
        for p in points:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


# --------------------------------------------------------------------------- swept areas


def _hermite(p0, v0, p1, v1, h: float, t: np.ndarray) -> np.ndarray:
    """Cubic Hermite points between (dim,) p0 and p1 with velocities v0, v1 over time `h`, at
    (S,) fractions `t` in [0, 1]."""
    t = t[:, None]
    t2, t3 = t * t, t * t * t
    return ((2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * h * v0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * h * v1)


def swept_path(positions: np.ndarray, velocities: np.ndarray | None, times: np.ndarray | None, particle: int,
               f0: int, f1: int, loop: bool = False, samples: int = 8) -> np.ndarray:
    """(S, dim) float64 points along `particle`'s path from frame `f0` to `f1` (f0 <= f1), with
    `samples` points per frame step: the cubic Hermite curve of the recorded positions and
    velocities (without velocities, Catmull–Rom tangents from the neighbouring frames). With
    `loop` the frames are periodic (index −1 is the last frame, and the one after the last is
    the first); else they are clipped to the recording."""
    n = positions.shape[0]
    if not loop:
        f0, f1 = max(0, min(f0, n - 1)), max(0, min(f1, n - 1))

    def at(f: int) -> int:
        return f % n if loop else max(0, min(f, n - 1))

    step = 1.0
    if times is not None and n > 1 and np.all(np.isfinite(times)):
        d = np.diff(np.asarray(times, np.float64))
        if d.size and np.all(d > 0):
            step = float(np.median(d))

    def h_of(f: int) -> float:
        a, b = at(f), at(f + 1)
        if times is not None and b == a + 1 and np.isfinite(times[b] - times[a]) and times[b] > times[a]:
            return float(times[b] - times[a])
        return step

    def vel(f: int) -> np.ndarray:
        if velocities is not None:
            return velocities[at(f), particle].astype(np.float64)
        a, b = at(f - 1), at(f + 1)
        span = h_of(f - 1) + h_of(f)
        return (positions[b, particle].astype(np.float64) - positions[a, particle].astype(np.float64)) / span

    pts = [positions[at(f0), particle].astype(np.float64)[None]]
    t = np.arange(1, samples + 1) / samples
    for f in range(f0, f1):
        p0, p1 = positions[at(f), particle].astype(np.float64), positions[at(f + 1), particle].astype(np.float64)
        pts.append(_hermite(p0, vel(f), p1, vel(f + 1), h_of(f), t))
    return np.concatenate(pts)


def swept_polygons(recording: Any, centre: int, body: int, frames: int, *, samples: int = 8) -> list[np.ndarray]:
    """The areas the line from particle `centre` to particle `body` sweeps in each whole
    interval of `frames` frames of `recording` (from frame 0), as (S + 1, dim) polygons of
    the body's position relative to the centre: the origin, then the body's path
    (:func:`swept_path`, `samples` points a frame). By Kepler's second law they are all of one
    area (half the angular momentum per unit reduced mass, times the interval). ``look=
    {"swept_areas": ...}`` draws them, placed at the centre's position."""
    out = []
    rec = recording
    for j in range((rec.frames - 1) // frames):
        f0, f1 = j * frames, (j + 1) * frames
        b = swept_path(rec.positions, rec.velocities, rec.times, body, f0, f1, samples=samples)
        c = swept_path(rec.positions, rec.velocities, rec.times, centre, f0, f1, samples=samples)
        out.append(np.concatenate([np.zeros((1, b.shape[1])), b - c]))
    return out


def polygon_area(pts: np.ndarray) -> float:
    """Area of a simple polygon with (K, 2) vertices (shoelace formula), positive whichever
    way round."""
    x, y = np.asarray(pts, np.float64)[:, 0], np.asarray(pts, np.float64)[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
