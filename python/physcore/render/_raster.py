"""Rasterisation of a :class:`Recording` into (H, W) uint8 palette-index images, numpy only (no
per-particle Python loops): collider background, boundary particles, spring lines and particle
discs, drawn by a :class:`_Rasteriser` that fixes camera, disc size and colour scale over an
animation."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _core
from ._camera import (
    FOLLOW_MAX_ZOOM,
    FOLLOW_SMOOTHING,
    ZOOM_EASE,
    _Camera,
    _follow_centres,
    _orbit_bounds,
    _screen_bounds,
    _view_basis,
    _zoom_scales,
)
from ._colorbar import (
    _CB_MARGIN,
    _colorbar_labels,
    _colorbar_layout,
    _draw_colorbar,
    _draw_text,
    _format_value,
    _label_px,
    _text_mask,
)
from ._lines import _draw_lines
from ._look import (
    Look,
    blend,
    disc_hull,
    draw_spheres,
    polygon_coverage,
    polyline_coverage,
    stroke_points,
    swept_path,
    width_offsets,
)
from ._mesh import Mesh, _MeshShader
from ._palette import (
    _ARROW,
    _BACKGROUND,
    _GLOW0,
    _N_GLOW,
    _N_PRESSURE,
    _N_SPEED,
    _N_STRAIN,
    _N_TRAIL,
    _PINNED,
    _PLAIN,
    _PLANE_FILL,
    _PLANE_LINE,
    _PRESSURE0,
    _SPEED0,
    _STRAIN0,
    _TEXT,
    _TRAIL0,
    _WALL,
    STRAIN_SATURATION,
    _scalar_levels,
    _strain_levels,
    styled_palette,
)
from ._recording import Recording
from ._rows import _row_norms


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


def _disc_stencil(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column offsets (S,) intp of a filled disc of `radius` pixels."""
    d = np.arange(-radius, radius + 1)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    # r^2 + r/2 rounds the disc: radius 1 is a plus, radius 2 a 5x5 square without corners.
    keep = dx * dx + dy * dy <= radius * radius + 0.5 * radius
    return dy[keep].astype(np.intp), dx[keep].astype(np.intp)


def _background(cam: _Camera, planes: list, origin: np.ndarray, spheres: Any = (), rods: Any = (), polygons: Any = ()) -> np.ndarray:
    """(H, W) uint8 index image with the colliders of a 2D scene: solid side shaded, edge a line
    (a sphere collider is a disc: filled, or with ``inside`` its outside filled, a bowl; a rod
    ``(a, b, radius)`` a stadium; a convex polygon, ``(k, 2)`` vertices in order around, filled)."""
    w, h = cam.width, cam.height
    img = np.full((h, w), _BACKGROUND, dtype=np.uint8)
    if cam.dim != 2 or not (planes or spheres or rods or len(polygons)):
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
    for c, r, inside in spheres:
        c = c - origin
        # Distance from the circle in pixels; > 0 on the allowed side.
        d = (np.hypot(xs[None, :] - c[0], ys[:, None] - c[1]) - r) * cam.scale
        d = -d if inside else d
        img[d < 0] = _PLANE_FILL
        img[np.abs(d) <= 0.75] = _PLANE_LINE
    for a, b, r in rods:
        a, ab = a - origin, b - a
        # Distance from the segment's nearest point, less r, in pixels.
        px, py = xs[None, :] - a[0], ys[:, None] - a[1]
        l2 = float(ab @ ab)
        t = np.clip((px * ab[0] + py * ab[1]) / l2, 0.0, 1.0) if l2 > 0 else 0.0
        d = (np.hypot(px - t * ab[0], py - t * ab[1]) - r) * cam.scale
        img[d < 0] = _PLANE_FILL
        img[np.abs(d) <= 0.75] = _PLANE_LINE
    for v in polygons:
        v = np.asarray(v, np.float64) - origin
        e = np.roll(v, -1, axis=0) - v
        # Outward edge normals whichever way round the vertices go (the sign of the area).
        turn = 1.0 if float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])) >= 0 else -1.0
        nx, ny = turn * e[:, 1], -turn * e[:, 0]
        ln = np.hypot(nx, ny)
        keep = ln > 0
        if not keep.any():
            continue
        d = np.full((h, w), -np.inf)
        # The largest distance beyond an edge's line, in pixels: < 0 inside the polygon.
        for (x0, y0), ux, uy in zip(v[keep], nx[keep] / ln[keep], ny[keep] / ln[keep], strict=True):
            d = np.maximum(d, ((xs[None, :] - x0) * ux + (ys[:, None] - y0) * uy) * cam.scale)
        img[d < 0] = _PLANE_FILL
        img[np.abs(d) <= 0.75] = _PLANE_LINE
    return img


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


#: ``gif(arrows=...)``: at most this many arrows a frame, on a fixed, evenly spread subset of the
#: moving particles (all of them up to _ALL_ARROWS).
MAX_ARROWS = 300
_ALL_ARROWS = 64


def _acceleration(v: np.ndarray, times: np.ndarray | None) -> np.ndarray:
    """(F, K, dim) accelerations from (F, K, dim) velocities recorded at (F,) `times`: central
    differences (v[k+1] − v[k−1]) / (t[k+1] − t[k−1]) (the scenes have no force read-out),
    one-sided at the first and last frame. Frame numbers stand in for missing or non-increasing
    times (arrows need only directions and ratios). Zeros for a single frame."""
    f = len(v)
    if f < 2:
        return np.zeros_like(v)
    t = np.arange(f, dtype=np.float64)
    if times is not None and np.isfinite(times).all() and np.all(np.diff(times) > 0):
        t = np.asarray(times, dtype=np.float64)
    a = np.empty_like(v)
    with np.errstate(over="ignore", invalid="ignore"):
        a[1:-1] = (v[2:] - v[:-2]) / (t[2:] - t[:-2])[:, None, None]
        a[0] = (v[1] - v[0]) / (t[1] - t[0])
        a[-1] = (v[-1] - v[-2]) / (t[-1] - t[-2])
    return a


def _arrow_subset(rec: Recording, cams: Any, cell: float) -> np.ndarray:
    """(K,) sorted indices of the particles that carry arrows, the same in every frame: every
    moving one up to _ALL_ARROWS; else one per `cell`-pixel square of the image (the nearest its
    middle), at whichever of the first, middle and last frame (seen through ``cams(k)``) that
    covers the most squares, so that arrows about `cell` long seldom overlap; at most
    MAX_ARROWS, thinned evenly."""
    moving = np.flatnonzero(~rec.pinned)
    if moving.size <= _ALL_ARROWS:
        return moving
    best = moving[:0]
    for k in sorted({0, rec.frames // 2, rec.frames - 1}):
        cam = cams(k)
        col, row = cam.pixels(cam.project(rec.positions[k][moving])[0])
        ok = (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)  # False for NaN
        cx, cy = np.floor(col[ok] / cell), np.floor(row[ok] / cell)
        square = cy * (cam.width // cell + 1) + cx
        off = (col[ok] / cell - cx - 0.5) ** 2 + (row[ok] / cell - cy - 0.5) ** 2
        order = np.lexsort((off, square))  # by square, nearest its middle first
        first = order[np.r_[True, square[order][1:] != square[order][:-1]]] if order.size else order
        if first.size > best.size:
            best = moving[ok][first]
    if best.size > MAX_ARROWS:
        best = best[np.unique(np.linspace(0, best.size - 1, MAX_ARROWS).round().astype(np.int64))]
    return np.sort(best)


def _arrow_vectors(rec: Recording, arrows: str, ref_px: float, pick: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """What ``arrows`` draws, fixed over the animation: the (K,) particles `pick` carrying them,
    their (F, K, dim) float32 velocities or accelerations in pixels (the run's 95th-percentile
    magnitude is `ref_px` long), and the longest arrow drawn (3 `ref_px`). None when nothing
    moves or no velocities were recorded."""
    if rec.velocities is None or pick.size == 0:
        return None
    vec = rec.velocities[:, pick].astype(np.float64)
    if arrows == "acceleration":
        vec = _acceleration(vec, rec.times)
    with np.errstate(over="ignore", invalid="ignore"):
        mag = _row_norms(vec.reshape(-1, vec.shape[-1]))
    mag = mag[np.isfinite(mag)]
    ref = float(np.percentile(mag, 95)) if mag.size else 0.0
    if not (ref > 0 and math.isfinite(ref)):
        return None
    with np.errstate(over="ignore", invalid="ignore"):
        return pick, (vec * (ref_px / ref)).astype(np.float32), 3.0 * ref_px


_HEAD_COS, _HEAD_SIN = math.cos(math.radians(25.0)), math.sin(math.radians(25.0))


def _draw_arrows(buf: np.ndarray, cam: _Camera, x: np.ndarray, vec: np.ndarray, cap: float) -> None:
    """Arrows from the (K, dim) points `x` along their (K, dim) vectors `vec` (in pixels) as
    `cam` projects them: a shaft from the point and a head of two strokes at ±25°, in the arrow
    colour. Longer than `cap` pixels: drawn `cap` long; shorter than 2 pixels: left out."""
    s, _ = cam.project(x)
    c0, r0 = cam.pixels(s)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        d = vec.astype(np.float64) @ cam.basis[:, :2]
        dc, dr = d[:, 0], -d[:, 1]  # rows grow downwards
        length = np.hypot(dc, dr)
        shrink = np.minimum(1.0, cap / length)
    ok = np.isfinite(c0) & np.isfinite(r0) & np.isfinite(length) & (length >= 2.0)
    if not ok.any():
        return
    c0, r0, length, shrink = c0[ok], r0[ok], length[ok], shrink[ok]
    dc, dr = dc[ok] * shrink, dr[ok] * shrink
    length = length * shrink
    c1, r1 = c0 + dc, r0 + dr
    head = np.minimum(np.clip(0.3 * length, 3.0, 8.0), length)
    bx, by = -dc / length * head, -dr / length * head  # back along the shaft, head long
    hc = np.concatenate([c1 + bx * _HEAD_COS - by * _HEAD_SIN, c1 + bx * _HEAD_COS + by * _HEAD_SIN])
    hr = np.concatenate([r1 + bx * _HEAD_SIN + by * _HEAD_COS, r1 - bx * _HEAD_SIN + by * _HEAD_COS])
    starts_c, starts_r = np.concatenate([c0, c1, c1]), np.concatenate([r0, r1, r1])
    ends_c, ends_r = np.concatenate([c1, hc]), np.concatenate([r1, hr])
    _draw_lines(buf, starts_c, starts_r, ends_c, ends_r, np.full(starts_c.shape, _ARROW, dtype=np.uint8))


def _draw_title(buf: np.ndarray, title: str, right: int, font_px: int | None = None) -> None:
    """`title` at the top left, in the text colour on a box of background, cut with "..." to end
    before column `right` (the colour bar's left edge); font `font_px` (see :func:`_text_mask`).
    Latin-1 only: other characters are drawn as "?"."""
    text = shown = title.encode("latin-1", "replace").decode("latin-1")
    while _text_mask(shown, font_px).shape[1] > right - _CB_MARGIN and len(text) > 1:
        text = text[: max(1, len(text) - max(1, len(text) // 8))]
        shown = text.rstrip() + "..."
    _draw_text(buf, shown, _CB_MARGIN, _CB_MARGIN - 1, _TEXT, _BACKGROUND, below=1, px=font_px)


def _scale_bar_length(px_per_unit: float, target_px: float) -> float:
    """The 1, 2 or 5 × 10^k length (in scene units) whose bar is nearest `target_px` pixels."""
    raw = target_px / px_per_unit
    k = math.floor(math.log10(raw))
    return min((m * 10.0**k for m in (1, 2, 5, 10)), key=lambda L: abs(math.log(L / raw)))


def _draw_scale_bar(buf: np.ndarray, px_per_unit: float, unit: str, font_px: int | None = None) -> tuple[float, int] | None:
    """A scale bar in the bottom-right corner: a round length (1, 2 or 5 × 10^k, about a sixth of
    the width) as a line with end ticks, labelled ("50 cm", "2 m"; a bare number in a scene's own
    units; font `font_px`), on a box of background. The camera is orthographic, so in 3D it
    holds at every depth. Returns (length, pixels), or None where it is left out (small images,
    no scale)."""
    h, w = buf.shape
    if w < 100 or h < 80 or not (math.isfinite(px_per_unit) and px_per_unit > 0):
        return None
    length = _scale_bar_length(px_per_unit, w / 6.0)
    px = int(round(length * px_per_unit))
    if not 8 <= px <= w // 2:
        return None
    if unit == "m" and length < 1.0 and length >= 1e-2:
        label = f"{_format_value(length * 100.0)} cm"
    elif unit == "m" and length < 1e-2 and length >= 1e-3:
        label = f"{_format_value(length * 1e3)} mm"
    else:
        label = f"{_format_value(length)} {unit}".rstrip()
    mask = _text_mask(label, font_px)
    x1 = w - 6
    x0 = x1 - px
    y = h - 6  # the line's row
    top = y - 4 - mask.shape[0]
    # The ink (line, ticks, label) on a halo of background two pixels wide, not on a solid box:
    # a box cut a notch out of whatever ran under the corner (a tank's floor, in every fluid
    # scene), where a halo only parts it around the strokes.
    left = min(x0, x1 - mask.shape[1]) - 2
    ink = np.zeros((y + 3 - (top - 1), x1 + 2 - left), dtype=bool)
    oy, ox = top - 1, left
    ink[y - 1 - oy : y + 1 - oy, x0 - ox : x1 + 1 - ox] = True
    ink[y - 4 - oy : y + 2 - oy, x0 - ox] = True
    ink[y - 4 - oy : y + 2 - oy, x1 - ox] = True
    tx = x1 - mask.shape[1] + (mask.shape[1] - px) // 2 if mask.shape[1] < px else x1 - mask.shape[1]
    text = ink[top - oy : top - oy + mask.shape[0], tx - ox : tx - ox + mask.shape[1]]
    text |= mask[: text.shape[0], : text.shape[1]]
    halo = ink.copy()
    for _ in range(2):
        grown = halo.copy()
        grown[1:] |= halo[:-1]
        grown[:-1] |= halo[1:]
        grown[:, 1:] |= halo[:, :-1]
        grown[:, :-1] |= halo[:, 1:]
        halo = grown
    region = buf[oy : oy + ink.shape[0], ox : ox + ink.shape[1]]
    region[halo[: region.shape[0], : region.shape[1]]] = _BACKGROUND
    region[ink[: region.shape[0], : region.shape[1]]] = _TEXT
    return length, px


def _box_blur(a: np.ndarray, r: int, axis: int) -> np.ndarray:
    """Mean over a window of 2r + 1 along `axis` (zeros beyond the edges). Small windows as sums
    of shifted slices; wide ones by one cumulative sum and a difference of two slices (O(1) a
    pixel whatever r is)."""
    pad = [(0, 0)] * a.ndim
    n = a.shape[axis]

    def cut(arr: np.ndarray, start: int, stop: int) -> np.ndarray:
        sl = [slice(None)] * arr.ndim
        sl[axis] = slice(start, stop)
        return arr[tuple(sl)]

    if r <= 2:
        pad[axis] = (r, r)
        p = np.pad(a, pad)
        out = cut(p, 0, n).copy()
        for k in range(1, 2 * r + 1):
            out += cut(p, k, k + n)
        return out * np.float32(1.0 / (2 * r + 1))
    pad[axis] = (r + 1, r)
    c = np.cumsum(np.pad(a, pad), axis=axis, dtype=np.float32)
    m = c.shape[axis]
    return (cut(c, 2 * r + 1, m) - cut(c, 0, m - 2 * r - 1)) * np.float32(1.0 / (2 * r + 1))


#: A 3D mesh's shadow on a floor prop: blurred with σ about this fraction of the image's width,
#: darkening the floor by up to this much.
SHADOW_BLUR, SHADOW_DARK = 0.012, 0.45
#: At most this many heights of fixed bodies' upward faces receive it (the largest by area).
SHADOW_RECEIVERS = 4

#: A liquid's spray (``surface``): particles with fewer than SPRAY_NEIGHBOURS others within two
#: spacings are drawn apart from the surface as a mist, blurred SPRAY_BLUR times wider than the
#: surface and at most SPRAY_OPACITY opaque (see _Rasteriser._spray_of and _mist).
SPRAY_NEIGHBOURS = 3
SPRAY_BLUR = 3
SPRAY_OPACITY = 0.7

#: A 3D liquid's lit surface (``surface`` in 3D, see _Rasteriser._lit_surface): each particle a
#: sphere of SURFACE_SPHERE particle spacings in the depth buffer, the buffer smoothed over
#: SURFACE_SMOOTH spacings (σ), so the spheres' bumps merge into one surface (two particles one
#: spacing apart leave a dip of 3 % of a spacing under spheres of 0.9); lit by a key light from
#: the upper left front (SURFACE_LIGHT, camera coordinates: right, up, towards the viewer), with a
#: Blinn–Phong highlight of exponent SURFACE_SHINE and a Fresnel-like rim towards white.
SURFACE_SPHERE = 0.9
SURFACE_SMOOTH = 0.7
SURFACE_LIGHT = (-0.45, 0.65, 0.62)
SURFACE_SHINE = 40.0
#: A 3D liquid's tank walls as glass (_Rasteriser._glass): the opacity of a wall seen face on
#: (the median over the walls' pixels) and the most any pixel takes (edges seen edge on).
GLASS_FACE = 0.10
GLASS_EDGE = 0.45
#: The largest sphere radius `_core.sphere_depths` takes, pixels (raster::MAX_SPHERE_RADIUS).
_MAX_SPHERE_PX = 64.0
#: The widest box `_core.blur` takes, pixels (raster::MAX_BLUR_RADIUS).
_MAX_BLUR_PX = 4096


def _blur(a: np.ndarray, r: int) -> np.ndarray:
    """Three box blurs each way: close to a Gaussian of σ ≈ r (the central limit), O(1) a pixel.
    A float32 image goes to the core (`_core.blur`: `_box_blur`'s f32 operations in its order,
    bit for bit, rows in parallel; 6 numpy passes took about 12 ms a 480 × 360 frame, and a
    liquid's frame blurs several times); others stay in numpy."""
    if a.dtype == np.float32 and a.ndim == 2 and 0 <= r <= _MAX_BLUR_PX:
        return _core.blur(np.ascontiguousarray(a), int(r))
    for _ in range(3):
        a = _box_blur(_box_blur(a, r, 0), r, 1)
    return a


def _bloom(a: np.ndarray, r: int) -> np.ndarray:
    """A wide blur (σ ≈ r) computed at half resolution (a quarter of the work) and brought back
    by repeating pixels; the result is smooth at that width, so the blocks do not show."""
    h, w = a.shape
    he, we = h + h % 2, w + w % 2
    half = np.pad(a, ((0, he - h), (0, we - w))).reshape(he // 2, 2, we // 2, 2).mean(axis=(1, 3))
    return np.repeat(np.repeat(_blur(half, max(1, r // 2)), 2, axis=0), 2, axis=1)[:h, :w]


def _occupied(col: np.ndarray, row: np.ndarray, c: float) -> int:
    """How many square cells of side `c` (pixels) the points (`col`, `row`, finite) fall in:
    an occupancy grid over their bounding box (O(N); np.unique over the pairs sorted them:
    1.6 s for 432,000 points), or the distinct cells counted by a sort of one integer key
    where the box holds more cells than points."""
    ix = np.floor(col / c)
    iy = np.floor(row / c)
    ix -= ix.min()
    iy -= iy.min()
    nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
    key = ix.astype(np.int64) * ny + iy.astype(np.int64)
    if nx * ny <= 4 * col.size + 1024:
        grid = np.zeros(nx * ny, dtype=bool)
        grid[key] = True
        return int(np.count_nonzero(grid))
    return int(np.unique(key).size)


def _spacing(x: np.ndarray) -> float | None:
    """The mean particle spacing (world units) of the (N, d) points `x` (d = 2 or 3): the area or
    volume of the cells of twice the spacing they occupy, over their count, refined three times
    from their bounding box's (the form of _Rasteriser._surface_setup's estimate in space);
    None for fewer than 2 points."""
    x = x[np.isfinite(x).all(axis=1)].astype(np.float64)
    n, d = x.shape
    if n < 2:
        return None
    lo = x.min(axis=0)
    ext = np.maximum(np.ptp(x, axis=0), 1e-12)
    s = float((np.prod(ext) / n) ** (1.0 / d))
    for _ in range(3):
        c = 2.0 * s
        k = np.floor((x - lo) / c).astype(np.int64)
        dims = k.max(axis=0) + 1
        key = k[:, 0] * dims[1] + k[:, 1]
        if d == 3:
            key = key * dims[2] + k[:, 2]
        total = int(np.prod(dims))
        if total <= 4 * n + 1024:  # an occupancy grid, O(N), as _occupied counts (np.unique sorted
            grid = np.zeros(total, dtype=bool)  # the keys: 0.3 s of a 10⁶-particle GIF's setup)
            grid[key] = True
            cells = int(np.count_nonzero(grid))
        else:
            cells = np.unique(key).size
        s = float((cells * c**d / n) ** (1.0 / d))
    return s


def _splat(col: np.ndarray, row: np.ndarray, shape: tuple[int, int], weights: np.ndarray | None = None) -> np.ndarray:
    """Particle count per pixel, each particle shared bilinearly among the four pixels around its
    position (sub-pixel motion shows, edges are antialiased): an (H, W) float32 grid. `weights`:
    (N,) per-particle weights instead of counts (the glow's colour channels). In the core
    (`_core.splat`: the same arithmetic as numpy's bincount over the four corners, bit for bit,
    without its 4N-entry temporaries: 110 ms for 10⁶ particles in numpy)."""
    h, w = shape
    return _core.splat(np.ascontiguousarray(col, dtype=np.float64), np.ascontiguousarray(row, dtype=np.float64), h, w,
                       None if weights is None else np.ascontiguousarray(weights, dtype=np.float32))


#: A glow trail's path between two frames is sampled every GLOW_STEP pixels of its length (the
#: splat shares each sample among four pixels and the blur closes what is left: no seam), at
#: most GLOW_MAX_SAMPLES a particle a frame and GLOW_BUDGET samples a frame in all.
GLOW_STEP = 0.6
GLOW_MAX_SAMPLES = 256
GLOW_BUDGET = 2_000_000


def _hermite(p0: np.ndarray, t0: np.ndarray, p1: np.ndarray, t1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Cubic Hermite points between points p0 and p1 with tangents t0, t1 (per frame step), at
    fractions `t` of the step, all broadcast together: `t` shaped (M, 1) for one fraction a row
    of (M, D) points, (S, 1, 1) for S fractions along every one."""
    t2, t3 = t * t, t * t * t
    return (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * t0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * t1


def _path_samples(p0: np.ndarray, t0: np.ndarray, p1: np.ndarray, t1: np.ndarray, step: float = GLOW_STEP,
                  cap: int = GLOW_MAX_SAMPLES, budget: int = GLOW_BUDGET
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points along each of N paths from its (N, 2) pixel point p0 to p1, the cubic Hermite
    curve of the tangents t0, t1 (pixels per frame step): (col, row, frac, owner), each (S,),
    the samples of path i at fractions j / m_i, j = 1 … m_i (its start is the previous path's
    end), m_i = ⌈L_i / step⌉ for the length bound L_i of the curve's Bézier control polygon,
    1 ≤ m_i ≤ `cap`, scaled down to `budget` samples in all. A path with a non-finite end is
    its end point alone (NaN: not drawn)."""
    ctrl = np.stack([p0, p0 + t0 / 3.0, p1 - t1 / 3.0, p1])  # the Bézier form of the curve
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.hypot(*np.moveaxis(np.diff(ctrl, axis=0), -1, 0)).sum(axis=0)
    length = np.where(np.isfinite(length), length, 0.0)
    m = np.clip(np.ceil(length / step), 1, cap).astype(np.int64)
    total = int(m.sum())
    if total > budget:
        m = np.maximum(1, (m * (budget / total)).astype(np.int64))
    owner = np.repeat(np.arange(m.size), m)
    first = np.cumsum(m) - m
    frac = (np.arange(owner.size) - first[owner] + 1) / m[owner]
    tan0, tan1 = np.nan_to_num(t0[owner]), np.nan_to_num(t1[owner])
    with np.errstate(invalid="ignore", over="ignore"):
        pts = _hermite(p0[owner], tan0, p1[owner], tan1, frac[:, None])
    return pts[:, 0], pts[:, 1], frac, owner


def _with_offsets(c0: np.ndarray, r0: np.ndarray, c1: np.ndarray, r1: np.ndarray, vals: np.ndarray,
                  offsets: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Segments (P, M) `c0` … `r1` with values `vals` ((P, M) or (P, M, C)) drawn once at each
    pixel offset (dc, dr) of `offsets` (a width's passes), flattened piece by piece, pass by
    pass (the order the trails were drawn in one frame step at a time)."""
    d = np.asarray(offsets, np.float64).reshape(-1, 2)
    p, m = c0.shape
    cols = [(a[:, None, :] + d[None, :, i, None]).reshape(-1) for a, i in ((c0, 0), (r0, 1), (c1, 0), (r1, 1))]
    v = np.broadcast_to(vals[:, None], (p, d.shape[0]) + vals.shape[1:]).reshape((p * d.shape[0] * m,) + vals.shape[2:])
    return cols[0], cols[1], cols[2], cols[3], v


def _overlay(shape: tuple[int, int]) -> np.ndarray:
    """An (H, W) int16 layer of palette indices to draw over a full-colour image: −1 (nothing)
    until drawn on (the drawing functions take it as they take an index image)."""
    return np.full(shape, -1, dtype=np.int16)


def _paste(out: np.ndarray, over: np.ndarray, palette: np.ndarray) -> None:
    """The drawn pixels of the `over` layer (see _overlay) onto the (H, W, 3) image `out`."""
    drawn = over >= 0
    out[drawn] = palette[over[drawn]]


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
        fit: np.ndarray | None = None,
        trail: int = 0,
        size_by: str = "none",
        annotate: bool = False,
        title: str | None = None,
        camera: tuple[str, Any] = ("fit", None),
        arrows: str | None = None,
        fps: float = 30.0,
        mesh: Mesh | None = None,
        texture: np.ndarray | None = None,
        theme: str = "light",
        antialias: bool = False,
        colors: np.ndarray | None = None,
        cmap: str | None = None,
        background: tuple[int, int, int] | None = None,
        surface: bool = False,
        halo: np.ndarray | None = None,
        loop: bool = False,
        look: Look | None = None,
    ):
        """`fit`: (K, dim) points (relative to ``rec.origin``) the camera is fitted to instead
        of the recorded positions and walls (``render_frame(extent=...)``). `trail`: frames of
        each moving particle's path drawn behind it, fading (``gif(trail=...)``). `annotate`:
        the clock and the scale bar along the bottom, with a band kept free for them (animations).
        `camera`: (mode, parameter) as ``_check_camera`` returns it; `arrows`: None, "velocity"
        or "acceleration" (needs ``rec.velocities``); `fps`: playback rate, which the follow
        camera's smoothing and the orbit's turn rate are timed in (``gif(camera=..., arrows=...)``).
        `mesh`, `texture`: a checked :class:`Mesh` drawn as a shaded surface by
        :meth:`frame_rgb` (:meth:`frame` draws its particles as discs and springs), and its
        (H', W', 3) float32 texture; `theme`: the palette (and surface colours) of frame_rgb;
        `antialias`: frame_rgb draws the discs with soft edges (coverage-blended, in the core).
        `colors`: (N, 3) uint8 RGB per particle, used by ``color_by`` "none" (discs, drawn in
        full colour by frame_rgb) and "density" (each particle's glow in its colour); `cmap`:
        the speed and pressure maps' name; `background`: an RGB triple for the background.
        `halo`: (N,) bool, particles frame_rgb draws with a soft halo of their colour (a star).
        `loop`: the recording is periodic (its last frame runs on into its first), so trails
        at the start continue from the end and the GIF loops without a seam.
        `surface`: frame_rgb draws the free particles as one continuous surface (a liquid),
        coloured by `color_by` (see :meth:`_frame_rgb_surface`). `look`: a checked
        :class:`~physcore.render.Look` (fading trails, line widths, lit spheres, a backdrop and
        props, swept areas), drawn by the soft discs' frames (:meth:`_frame_rgb_discs`)."""
        n, dim = rec.positions.shape[1:]
        self.look = Look() if look is None else look
        mode, cam_param = camera
        walls = rec.walls if rec.walls is not None and len(rec.walls) else None
        self.rec = rec
        self.radius = _auto_radius(n + (0 if walls is None else len(walls)), size) if radius is None else radius
        self.color_by = color_by
        self.trail = int(trail)
        self.loop = bool(loop)
        self._glow_px: dict[int, np.ndarray] = {}  # a few frames' pixel positions (the glow's paths)
        self._glow_history: tuple[int, np.ndarray] | None = None  # (frame, glow with trail)
        self._sub_pix: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # trail_samples' paths, by frame
        # The colour scale: 0 at the bottom, the top fixed over the animation.
        self.vmax = 0.0
        values, scale, base, levels = {
            "speed": (rec.speeds, speed_scale, _SPEED0, _N_SPEED),
            "pressure": (rec.pressures, pressure_scale, _PRESSURE0, _N_PRESSURE),
            # Strain: the run's own scale (|strain|, saturating at its 99th percentile), so a
            # cloth straining 0.3 % shows its pattern rather than grey under a fixed 10 %.
            "strain": (None if rec.strain is None else np.abs(rec.strain), None, _STRAIN0, _N_STRAIN),
        }.get(color_by, (None, None, 0, 0))
        if values is not None and values.size:
            if scale is None:
                # All finite (the usual case): no masked copy of the (F, N) values.
                finite = values.reshape(-1) if np.isfinite(values).all() else values[np.isfinite(values)]
                # 99th percentile: a few outliers should not wash out the whole map.
                scale = float(np.percentile(finite, 99)) if finite.size else 0.0
            self.vmax = float(scale)
        # Springs saturate at the strain scale when colouring by strain, else at the fixed 10 %.
        self.strain_scale = self.vmax if color_by == "strain" and self.vmax > 0 else STRAIN_SATURATION
        self.colorbar = None
        if colorbar and values is not None and self.vmax > 0 and math.isfinite(self.vmax):
            lo, hi = _colorbar_labels(color_by, self.vmax, rec.speed_unit)
            # The quantity named before the scale ("speed 0 [strip] 4.42 m/s"), where it fits.
            self.colorbar = _colorbar_layout(size, f"{color_by} {lo}", hi) or _colorbar_layout(size, lo, hi)
        self.cam = _Camera(dim, view, size)
        # Room for the largest disc (size_by="mass" draws up to 3× the radius).
        grow = 1.0
        if size_by == "mass" and rec.masses is not None and len(rec.masses):
            grow = float(min(3.0, np.cbrt(rec.masses.max() / rec.masses.min())))
        pad = max(int(math.ceil(self.radius * grow)) + 2, int(round(0.05 * min(size))))
        if mode == "orbit":
            # One scale for every azimuth: the box that holds the scene however it turns.
            axis, lo, hi, amax = _orbit_bounds(rec.positions, walls, view[1])
        elif fit is not None:
            lo, hi, amax = _screen_bounds(self.cam, np.asarray(fit, dtype=np.float32)[None])
        else:
            lo, hi, amax = _screen_bounds(self.cam, rec.positions)
            if size_by == "radius" and rec.radii is not None and rec.radii.size:
                lo, hi = lo - rec.radii.max(), hi + rec.radii.max()  # whole grains in view
            if walls is not None:
                wlo, whi, wmax = _screen_bounds(self.cam, walls[None])
                lo, hi, amax = np.minimum(lo, wlo), np.maximum(hi, whi), max(amax, wmax)
            balls = [(c - rec.origin, r) for c, r, inside in rec.spheres if not inside]
            balls += [(e - rec.origin, r) for a, b, r in rec.rods for e in (a, b)]  # a rod: its two end balls
            balls += [(e - rec.origin, 0.0) for v in rec.polygons for e in v]  # a polygon: its corners
            if balls:  # sphere colliders (balls) whole in view: a sphere's outline is ±r about its centre
                c = np.array([b[0] for b in balls])
                r = np.array([b[1] for b in balls])[:, None]
                s, _ = self.cam.project(c)
                lo, hi = np.minimum(lo, (s - r).min(axis=0)), np.maximum(hi, (s + r).max(axis=0))
                amax = max(amax, float(np.abs(c).max() + r.max()))
        if self.look.decor and fit is None and mode != "orbit":
            # Props are framed as the colliders are: whole in view.
            pts = np.concatenate([item["points"] for item in self.look.decor]) - rec.origin
            s, _ = self.cam.project(pts)
            lo, hi = np.minimum(lo, s.min(axis=0)), np.maximum(hi, s.max(axis=0))
            amax = max(amax, float(np.abs(pts).max()))
        if rec.bodies is not None and fit is None and mode != "orbit":
            from ._bodies import body_bounds, body_bounds3

            blo, bhi = body_bounds3(rec.bodies, self.cam) if rec.bodies.dim == 3 else body_bounds(rec.bodies)
            if np.isfinite(blo).all() and np.isfinite(bhi).all():
                if rec.positions.shape[1] == 0:
                    lo, hi = blo, bhi
                else:
                    lo, hi = np.minimum(lo, blo), np.maximum(hi, bhi)
                amax = max(amax, float(np.abs(np.concatenate([blo, bhi])).max()))
        # Keep the colour bar's band free: no disc reaches into it (nor into the title's).
        top_pad = None if self.colorbar is None else max(pad, self.colorbar.band + self.radius + 1)
        w, h = size
        self.font_px = _label_px(size)  # the labels' font (None: the small bitmap one)
        line = _text_mask("0", self.font_px).shape[0]  # rows of a line of text (11: bitmap)
        self.title = title if title and w >= 100 and h >= 80 else None
        if self.title is not None:
            top_pad = max(top_pad or pad, _CB_MARGIN + line + 1 + int(math.ceil(self.radius * grow)) + 1)
        # Positions are float32 relative to the origin: extents below their rounding are zero.
        self.annotate = annotate and w >= 100 and h >= 80
        bottom_pad = max(pad, line + 9 + int(math.ceil(self.radius * grow))) if self.annotate else None
        self.cam.fit(lo, hi, pad, tol=1e-6 * amax, top_pad=top_pad, bottom_pad=bottom_pad)
        # Per-frame cameras (follow, orbit): (F, 2) screen-plane centres and, orbiting, (F, 3, 3)
        # bases; None for the one fitted camera. The scale stays fixed, so the scale bar holds.
        self._centres: np.ndarray | None = None
        self._bases: np.ndarray | None = None
        #: camera="zoom": (F,) per-frame scales (pixels per unit), self.cam's the last and smallest.
        self._scales: np.ndarray | None = None
        if mode in ("follow", "zoom"):
            centres, spread = _follow_centres(self.cam, rec.positions, rec.pinned, rec.masses, cam_param,
                                              FOLLOW_SMOOTHING * fps)
            avail = np.array([max(w - 2 * pad, 1), max(h - (bottom_pad or pad) - (top_pad or pad), 1)], dtype=float)
            wide = spread > 1e-6 * amax
            # Zoom in (never out: the fitted view holds everything) until the spread fits.
            zoom = float(np.min(avail[wide] / (2.0 * spread[wide]))) / self.cam.scale if wide.any() else math.inf
            fitted = self.cam.scale
            self.cam.scale *= min(max(zoom, 1.0), FOLLOW_MAX_ZOOM)
            self._centres = centres
            if mode == "zoom":
                self._scales = _zoom_scales(self.cam, rec.positions, rec.pinned, centres, avail, self.cam.scale,
                                            FOLLOW_MAX_ZOOM * fitted, ZOOM_EASE * fps)
                self.cam.scale = float(self._scales[-1])
        elif mode == "orbit":
            turn = np.arange(rec.frames) * (360.0 / rec.frames if cam_param is None else cam_param / fps)
            self._bases = np.stack([_view_basis(view[0] + a, view[1]) for a in turn])
            self._centres = (axis @ self._bases)[:, :2] + self.cam.centre
        if radius is None:
            r_springs = _spring_radius(rec, self.cam.scale)
            if r_springs is not None:
                self.radius = min(self.radius, r_springs)
        self.stencil = _disc_stencil(self.radius)
        # Per-particle disc radii (size_by="mass"): None when every disc has self.radius.
        self.radii = None
        if size_by == "mass" and rec.masses is not None and len(rec.masses):
            rel = np.cbrt(rec.masses / rec.masses.min())
            radii = np.rint(np.minimum(rel, 3.0) * max(self.radius, 1)).astype(np.int64)
            if np.any(radii != self.radius):
                self.radii = radii
        elif size_by == "radius" and rec.radii is not None and len(rec.radii):
            # Grains at their true size (m → pixels), at least one pixel; no radius: the default.
            px = np.where(rec.radii > 0, rec.radii * self.cam.scale, self.radius)
            self.radii = np.maximum(np.rint(px), 1).astype(np.int64)
        self.walls = walls
        self._wall_spacing: float | None = None  # world units, found once (_scene_background)
        # A 3D liquid's tank walls are drawn as glass (_glass), not as a stipple of discs.
        self._glass_walls = (walls is not None and len(walls) > 0 and dim == 3 and bool(surface) and mesh is None
                             and color_by in ("speed", "pressure", "none"))
        self._glass_cache: np.ndarray | None = None
        self._surf_backdrop: np.ndarray | None = None  # a liquid's backdrop (float RGB), fixed camera
        self.background = self._scene_background(self.cam)
        # The fitted camera draws the labels once, into the background. Every frame pastes them
        # over everything too: a followed scene may pass under them, and spray thrown past a
        # scene's extent did (the crown's over its colour bar). The pixels they set are those
        # drawn alike over 0s and over 1s; where nothing passes under them, no pixel changes.
        labels = [np.zeros((h, w), np.uint8), np.ones((h, w), np.uint8)]
        if self._centres is None:
            labels.insert(0, self.background)
        self.scale_bar = None
        for img in labels:
            if self.colorbar is not None:
                _draw_colorbar(img, self.colorbar, base, levels)
            if self.title is not None:
                _draw_title(img, self.title, w - 8 if self.colorbar is None else self.colorbar.lo_x - 8, self.font_px)
            if self.annotate and self._scales is None:  # a zooming view draws its own each frame
                self.scale_bar = _draw_scale_bar(img, self.cam.scale, "m" if rec.speed_unit == "m/s" else "", self.font_px)
        idx = np.flatnonzero(labels[-2] == labels[-1])
        self._labels: tuple[np.ndarray, np.ndarray] | None = (idx, labels[-2].reshape(-1)[idx]) if idx.size else None
        self._arrows = None
        if arrows is not None and rec.velocities is not None:
            pick = _arrow_subset(rec, self.cam_at, min(size) / 12.0)
            self._arrows = _arrow_vectors(rec, arrows, min(size) / 12.0, pick)
        self.glow_scale = 0.0
        if color_by == "density":
            # One brightness scale for the whole animation, from three frames' density (the
            # middle and last ones' with their trails, which add up where paths cross, with a
            # still camera).
            trails = self.trail and self._centres is None
            glows = [self._glow_density(k) if k and trails else self._density(k) for k in sorted({0, rec.frames // 2, rec.frames - 1})]
            sample = np.concatenate([d[d > 0] for d in glows] or [np.zeros(1)])
            self.glow_scale = float(np.percentile(sample, 99.5)) if sample.size else 1.0
        self.trail = int(trail)
        #: (N,) bool: the particles whose paths the trails draw (the moving ones, or look.trail_of's).
        self._trailed = ~rec.pinned
        if self.look.trail_of:
            self._trailed = self._trailed & np.isin(np.arange(len(rec.pinned)), self.look.trail_of)
        self._pix: list | None = None  # per-frame pixel positions, projected once (trails)
        # 2D draw order: pinned particles last, so they stay visible (3D sorts by depth per frame).
        self.pin_order = np.argsort(rec.pinned, kind="stable") if dim == 2 and rec.pinned.any() else None
        if self.look.backdrop is not None and background is None:
            # Text boxes and the classic trails fade into the backdrop's mean colour.
            background = tuple(int(round(c)) for c in np.mean(np.array(self.look.backdrop, dtype=np.float64), axis=0))
        self.palette = styled_palette(theme, cmap, background)
        self._static: np.ndarray | None = None  # the backdrop and props, fitted camera
        # Own colours apply where no quantity is coloured: plain discs and the glow.
        self.colors = colors if colors is not None and color_by in ("none", "density") else None
        # Own colours: hard-edged discs take palette entries of their own while they fit beside
        # the fixed palette (one entry kept free for the GIF writer's transparency); more hues,
        # or soft edges, are drawn in full colour.
        self._color_idx: np.ndarray | None = None
        own = self.colors is not None and color_by == "none" and mesh is None
        if own and not antialias:
            hues, which = np.unique(self.colors, axis=0, return_inverse=True)
            if len(self.palette) + len(hues) <= 255:
                self._color_idx = (len(self.palette) + which.reshape(-1)).astype(np.uint8)
                self.palette = np.concatenate([self.palette, hues.astype(np.uint8)])
        self.antialias = (bool(antialias) or (self.colors is not None and self._color_idx is None)) and color_by != "density"
        # A halo needs full colour: hard-edged discs (antialias=False) go without; a glow in its
        # own colours draws it as a bright core (a galaxy's bulge, `_frame_rgb_glow`).
        glow_rgb = color_by == "density" and self.colors is not None
        full = (color_by != "density" and antialias) or glow_rgb
        self.halo = halo if halo is not None and halo.any() and mesh is None and full else None
        self.surface = bool(surface) and mesh is None and color_by in ("speed", "pressure", "none")
        if self.surface:
            self._surface_setup()
        #: frame_rgb is the frame (full colour): shaded meshes, soft discs, glow in own colours,
        #: rigid bodies (filled and shaded: a palette frame had none of them, so a scene of
        #: bodies rendered without antialias= showed its particles only).
        self.full_colour = (mesh is not None or self.antialias or self.surface
                            or (self.colors is not None and color_by == "density") or rec.bodies is not None)
        # Trails 2 px wide from 300 px on: a 1-px path vanishes at a shared GIF's size.
        self._line_px = 2 if min(size) >= 300 else 1
        self.trail_px = self.look.trail_width or self._line_px
        self._swept_cache: dict[int, np.ndarray] = {}  # complete swept areas by interval
        self.mesh = mesh
        self._shader = None
        if mesh is not None:
            bounds = None
            if dim == 3 and rec.planes:
                pts = rec.positions.reshape(-1, 3)
                pts = pts[np.isfinite(pts).all(axis=1)]
                if len(pts):
                    bounds = (pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64))
            planes = [(np.asarray(p, np.float64) - rec.origin, np.asarray(nrm, np.float64)) for p, nrm in rec.planes]
            edge = 0.0
            if rec.rods and len(mesh.faces) and rec.positions.shape[-1] == 3:
                x0 = rec.positions[0]
                edge = float(np.median(np.linalg.norm(x0[mesh.faces[:, 0]] - x0[mesh.faces[:, 1]], axis=1)))
            self._shader = _MeshShader(mesh, theme, texture, rec.spheres, rec.origin, planes, bounds, rec.rods, edge)
        if mesh is not None:
            on_mesh = np.zeros(n, dtype=bool)
            on_mesh[mesh.faces.ravel()] = True
            self._off_mesh = ~on_mesh & ~rec.pinned  # drawn as discs under the surface
            self._pinned_idx = np.flatnonzero(rec.pinned)  # drawn as discs over it
        # A 3D mesh over a floor drawn as a prop (a horizontal decor polygon, the lowest): the
        # mesh casts a soft shadow on it (light from overhead), (z, (K, 3) points) relative to
        # the recording's origin.
        self._ground: tuple[float, np.ndarray] | None = None
        if mesh is not None and dim == 3:
            flat = [item["points"] - rec.origin for item in self.look.decor
                    if item["kind"] == "polygon" and np.ptp(item["points"][:, 2]) <= 1e-9 * max(1.0, float(np.abs(item["points"]).max()))]
            if flat:
                low = min(flat, key=lambda q: float(q[0, 2]))
                self._ground = (float(low[0, 2]), low)
        self._ground_cover: np.ndarray | None = None  # the floor's coverage, for the fitted camera
        # What else the mesh casts its shadow on, drawn in its depth buffer: the plane colliders
        # that face up (a floor) and the upward faces of fixed bodies (a table's top, a floor
        # slab), each a plane (point, unit normal) relative to the origin, and a label for each
        # vertex the shader draws (the sheet's, the static geometry's, the bodies') naming the
        # plane it lies on (−1: none).
        self._receivers: list[tuple[np.ndarray, np.ndarray]] = []
        self._receiver_labels: np.ndarray | None = None
        if mesh is not None and dim == 3:
            self._receivers_setup(planes, n)


    def forget_projection(self) -> None:
        """Drop the per-frame pixel positions projected so far (the trails'): the recording's
        history moved, so they are projected again at the next frame."""
        self._pix = None
        self._glow_px = {}
        self._sub_pix = {}

    def cam_at(self, k: int) -> _Camera:
        """The camera of frame k: the fitted one, or that frame's follow or orbit camera (the
        same scale and image, its own centre and, orbiting, its own basis)."""
        if self._centres is None:
            return self.cam
        return self.cam.moved(self._centres[k], None if self._bases is None else self._bases[k],
                              None if self._scales is None else float(self._scales[k]))

    def _under(self, cam: _Camera) -> np.ndarray:
        """A fresh copy of what frame drawing starts from, seen through `cam`: the background."""
        return self.background.copy() if self._centres is None else self._scene_background(cam)

    def _scene_background(self, cam: _Camera) -> np.ndarray:
        """(H, W) uint8 index image with what does not move through `cam`: the colliders (2D)
        and the boundary particles, under everything that moves."""
        img = _background(cam, self.rec.planes, self.rec.origin, self.rec.spheres, self.rec.rods, self.rec.polygons)
        if self.walls is not None and not self._glass_walls:
            s, _ = cam.project(self.walls)
            col, row = cam.pixels(s)
            stencil = self.stencil
            if self.walls.shape[1] == 2:
                # Discs that close the lattice's gaps (radius 0.7 spacings: the half diagonal):
                # the particle-sized ones drew the walls as perforated bands.
                if self._wall_spacing is None:
                    self._wall_spacing = _spacing(self.walls) or 0.0
                r = min(int(math.ceil(0.7 * self._wall_spacing * cam.scale)), 12)
                if r > int(self.radius):
                    stencil = _disc_stencil(r)
            _draw_discs(img, col, row, np.full(col.shape, _WALL, dtype=np.uint8), stencil)
        return img

    def _glass(self, cam: _Camera) -> np.ndarray:
        """(H, W) float32 opacity of a 3D liquid's tank walls drawn as glass: the boundary
        particles splatted and blurred over about 0.7 wall spacing (σ), so a wall seen face on is a
        faint, even tint (GLASS_FACE opaque) and one seen edge on (many particles over a pixel) a
        darker line, at most GLASS_EDGE: the tank's edges outline it, where discs drew a stipple
        that beat with the pixel grid (moiré). Kept for the fitted camera."""
        if self._centres is None and self._glass_cache is not None:
            return self._glass_cache
        s, _ = cam.project(self.walls)
        col, row = cam.pixels(s)
        d = _spacing(self.walls)
        r = max(1, int(round(0.6 * (d if d is not None else 0.0) * cam.scale)))  # σ ≈ 0.7 spacing
        dens = _blur(_splat(col, row, (cam.height, cam.width)), r)
        lit = dens[dens > 1e-6]
        face = float(np.median(lit)) if lit.size else 1.0
        glass = np.clip(GLASS_FACE * dens / max(face, 1e-12), 0.0, GLASS_EDGE).astype(np.float32)
        if self._centres is None:
            self._glass_cache = glass
        return glass

    def _density(self, k: int, ahead: bool = False) -> np.ndarray:
        """Frame k's glow: the free particles' density (per pixel), a tight blur plus a wide
        bloom. Additive, so it needs no depth order in 3D. `ahead`: their paths to frame k + 1
        instead (:meth:`_streak`)."""
        col, row, w, _ = self._streak(k, ahead)
        d = _splat(col, row, self.background.shape, w)
        r = max(1, self.radius // 2)
        return _blur(d, r) + 0.5 * _bloom(d, 4 * r)

    def _streak(self, k: int, ahead: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Pixel positions, weights and owners (the index among the free particles of each
        sample; None: one sample each, in order) to splat for frame k's glow: the free particles
        where they are or, with a `trail` and a still camera, their paths from frame k − 1
        sampled every GLOW_STEP pixels (:func:`_path_samples`: the cubic Hermite curve of the
        recorded velocities, or of Catmull–Rom tangents from the neighbouring frames, see
        :meth:`_tangents`, so a point that moves 80 pixels a frame round a bend draws the bend,
        not its chord). Each sample weighs its share of the path's length (a pixel's worth at
        most) times the trail's decay over its age within the frame, so the glow's history is
        one continuous fading line: neither dots nor a seam at each frame. `ahead`: the paths
        on to frame k + 1 instead, fading away from frame k (what the first frame, with no
        history, shows of the motion: :meth:`_glow_density`)."""
        rec = self.rec
        cam = self.cam_at(k)
        free = ~rec.pinned
        x = rec.positions[k][free] if rec.pinned.any() else rec.positions[k]
        col, row = cam.pixels(cam.project(x)[0])
        if self._scales is not None:
            # Zoomed in z times, the particles spread over z² times the pixels: each weighs z²,
            # so that a region's glow (its surface brightness) does not change with the zoom.
            gain = (float(self._scales[k]) / self.cam.scale) ** 2
            return col, row, np.full(col.shape, gain, dtype=np.float32), None
        if not self.trail or (k == 0 and not ahead) or self._centres is not None:
            return col, row, None, None
        sel = free if rec.pinned.any() else slice(None)
        cache = self._glow_px
        if len(cache) > 8:
            cache.clear()

        def px(f: int) -> np.ndarray:
            if f not in cache:
                y = rec.positions[f][sel]
                cache[f] = np.stack(self.cam.pixels(self.cam.project(y)[0]), axis=1)
            return cache[f]

        cache[k] = np.stack([col, row], axis=1)
        a, b = (k, k + 1) if ahead else (k - 1, k)
        p0, p1 = px(a), px(b)

        def velocity_px(g: int, h: float) -> np.ndarray:  # pixels per frame step
            s = self.cam.project(rec.velocities[g % rec.frames][sel].astype(np.float64) * h)[0]
            return np.stack([s[:, 0] * self.cam.scale, -s[:, 1] * self.cam.scale], axis=1)

        t0, t1 = self._tangents(a, b, px, velocity_px)
        cs, rs, frac, owner = _path_samples(p0, t0, p1, t1)
        with np.errstate(invalid="ignore"):
            length = np.hypot(p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1])
        m = np.bincount(owner, minlength=p0.shape[0])
        share = np.maximum(np.nan_to_num(length), 1.0) / np.maximum(m, 1)  # ~1 a pixel along the path
        decay = 0.05 ** (1.0 / self.trail)
        w = (share[owner] * decay ** (frac if ahead else 1.0 - frac)).astype(np.float32)
        return cs, rs, w, owner

    def _tangents(self, a: int, b: int, at: Any, velocity: Any) -> tuple[np.ndarray, np.ndarray]:
        """The tangents (per frame step) at both ends of the path from frame a to b = a + 1
        (taken modulo the frame count with `loop`): `velocity(g, h)`, frame g's recorded
        velocities times the frame interval h (:meth:`_frame_interval`) in the units of
        `at`, where there are velocities and times, else Catmull–Rom's of the positions
        `at(frame)` (:meth:`_catmull_rom`). A resolved path's mean end tangent is near its
        chord (Simpson's rule; within 0.4 of it up to a 120° turn a step); one off by over half
        the chord turned by more than about 135° within the step (a tight binary looping once a
        frame, a close pass), which no cubic follows: the velocities' curve draws a saw-tooth or
        overshoots there (pythagorean's escaping binary; 23 px off at its closest passes, against
        14 px), so such paths take Catmull–Rom's tangents, the smoother guess."""
        h = None if self.rec.velocities is None else self._frame_interval(a, b)
        if h is None:
            return self._catmull_rom(a, at), self._catmull_rom(b, at)
        t0, t1 = velocity(a, h), velocity(b, h)
        with np.errstate(invalid="ignore", over="ignore"):
            chord = at(b) - at(a)
            loops = np.linalg.norm(0.5 * (t0 + t1) - chord, axis=-1) > 0.5 * np.linalg.norm(chord, axis=-1)
        if loops.any():
            loops = loops[:, None]
            t0 = np.where(loops, self._catmull_rom(a, at), t0)
            t1 = np.where(loops, self._catmull_rom(b, at), t1)
        return t0, t1

    def _frame_interval(self, a: int, b: int) -> float | None:
        """The time from frame a to frame b = a + 1 that turns recorded velocities into tangents
        per frame step: the difference of their times, or where that is not a positive number
        (a step across a periodic recording's end, or past it) the median positive interval;
        None where there is none (no times, one frame)."""
        t = self.rec.times
        if t is None:
            return None
        h = float(t[b] - t[a]) if 0 <= a and b == a + 1 and b < self.rec.frames else float("nan")
        if not (math.isfinite(h) and h > 0):
            d = np.diff(np.asarray(t, np.float64))
            d = d[np.isfinite(d) & (d > 0)]
            h = float(np.median(d)) if d.size else float("nan")
        return h if math.isfinite(h) and h > 0 else None

    def _catmull_rom(self, g: int, at: Any) -> np.ndarray:
        """Catmull–Rom's tangent (per frame step) at frame g of the positions `at(frame)`:
        (at(g + 1) − at(g − 1)) / 2, frames taken modulo the frame count with `loop`, else
        one-sided at the recording's ends (zero for a recording of one frame)."""
        n = self.rec.frames
        lo, hi = ((g - 1) % n, (g + 1) % n) if self.loop else (max(0, g - 1), min(n - 1, g + 1))
        if lo == hi:
            return np.zeros_like(at(g % n))
        return (at(hi) - at(lo)) / (2.0 if self.loop else float(hi - lo))

    def _glow_density(self, k: int, density: Any = None) -> np.ndarray:
        """Frame k's density, or with a `trail` its fading history: d_k + decay · h_{k−1},
        decay = 0.05^(1/trail), a phosphor's persistence: the paths fade to 5 % over `trail`
        frames, continuously (each frame's path fades along its length, see :meth:`_streak`),
        and add up where they cross, as in a long exposure (a maximum of the two drew a seam
        at every frame's end and bands where paths overlap). The history is carried
        from frame to frame when they are drawn in order, else rebuilt from `trail` frames.
        With a following or orbiting camera the history would smear across the image: the glow
        then has no trail."""
        density = self._density if density is None else density  # or _density_rgb: own colours
        if not self.trail or self._centres is not None:
            # A moving camera would smear a history kept in pixels: no glow trail there.
            return density(k)
        decay = 0.05 ** (1.0 / self.trail)
        if k == 0 and not self.loop and self.rec.frames > 1:
            # No history yet: the first frame (a GIF's thumbnail) shows the particles' paths on
            # to the next frame, fading away from them, where it would show only dots; the
            # history it passes on is the dots', so nothing is drawn twice.
            h = density(0)
            self._glow_history = (0, h)
            return h + density(0, True)
        if self._glow_history is not None and self._glow_history[0] == k - 1:
            h = density(k) + decay * self._glow_history[1]
        else:
            h = density(max(0, k - self.trail))
            for f in range(max(0, k - self.trail) + 1, k + 1):
                h = density(f) + decay * h
        self._glow_history = (k, h)
        return h

    def _density_rgb(self, k: int, ahead: bool = False) -> np.ndarray:
        """(4, H, W): frame k's glow density (as _density) and its sums of the particles' own
        colours (red, green, blue in [0, 1], each weighted by the particle's density)."""
        rec = self.rec
        free = ~rec.pinned
        col, row, wt, owner = self._streak(k, ahead)
        c = (self.colors[free] if rec.pinned.any() else self.colors).astype(np.float32) / 255.0
        if owner is not None:
            c = c[owner]
        r = max(1, self.radius // 2)
        out = []
        for w in (wt, c[:, 0], c[:, 1], c[:, 2]):
            if w is not None and wt is not None and w is not wt:
                w = w * wt
            d = _splat(col, row, self.background.shape, w)
            out.append(_blur(d, r) + 0.5 * _bloom(d, 4 * r))
        return np.stack(out)

    def _frame_rgb_glow(self, k: int) -> np.ndarray:
        """Frame k of ``color_by="density"`` with own colours: each pixel's glow is tone-mapped as
        :meth:`_glow` does, in the density-weighted mean of the colours there, whitening towards
        the densest cores (as an exposure saturates); trails persist as :meth:`_glow_density`."""
        h = self._glow_density(k, self._density_rgb)
        cam = self.cam_at(k)
        under = self._under(cam)
        out = np.take(self.palette, under, axis=0).astype(np.float32)
        d = h[0]
        if self.glow_scale > 0:
            t = (1.0 - np.exp(-2.5 * (np.maximum(d, 0) / self.glow_scale) ** 0.75))[..., None]
            hue = np.moveaxis(h[1:], 0, -1) / np.maximum(d, 1e-30)[..., None]
            hue = np.clip(hue, 0.0, 1.0) * 255.0
            white = np.float32(0.6) * t * t
            lit = hue * (1 - white) + 255.0 * white
            out = out * (1 - t) + lit * t
        out = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        if self.halo is not None:
            # The halo particles (e.g. a galaxy's central mass, one particle among thousands of
            # stars, which the glow alone leaves as a dark hole) shine as a core: the halo's
            # Gaussian in their colour, whitened by 80 %, σ 2.5 % of the first frame's shorter
            # side, a size in the scene that follows a zooming camera.
            col, row = cam.pixels(cam.project(self.rec.positions[k])[0])
            sigma = 0.025 * min(out.shape[:2]) / self.cam_at(0).scale * cam.scale
            self._draw_halos(out, col, row, np.full(col.size, max(sigma, 1.5) / 1.3), None, white=0.8)
        over = _overlay(under.shape)
        if self.rec.pinned.any():  # pinned particles stay discs on top
            s, _ = cam.project(self.rec.positions[k][self.rec.pinned])
            col, row = cam.pixels(s)
            _draw_discs(over, col, row, np.full(col.shape, _PINNED, dtype=np.uint8), self.stencil)
        return self._finish_rgb(out, over, k, cam)

    def _surface_setup(self) -> None:
        """The surface's fixed scales: the particle spacing in pixels, from frame 0's projected
        free particles (the area of the cells they occupy, over their count, refined twice
        with cells of twice the spacing), the blur that closes the gaps between neighbours
        (σ ≈ 0.7 spacing) and the density of a filled interior (one particle per spacing²)."""
        rec = self.rec
        free = ~rec.pinned
        s, _ = self.cam.project(rec.positions[0][free])
        col, row = self.cam.pixels(s)
        ok = np.isfinite(col) & np.isfinite(row)
        col, row = col[ok], row[ok]
        n = max(int(col.size), 1)
        span = max(float(np.ptp(col)) if col.size else 1.0, 1.0) * max(float(np.ptp(row)) if row.size else 1.0, 1.0)
        spacing = math.sqrt(span / n)
        for _ in range(3):
            c = max(2.0 * spacing, 1e-3)
            cells = _occupied(col, row, c) if col.size else 1
            spacing = math.sqrt(cells * c * c / n)
        self._surf_spacing = max(spacing, 0.5)
        target = 0.7 * self._surf_spacing  # σ of three box blurs of radius r is √(r(r+1))
        self._surf_r = max(1, int(round(math.sqrt(target * target + 0.25) - 0.5)))
        self._surf_ref = 1.0 / (self._surf_spacing**2)
        # 3D: the spheres of the lit surface (_lit_surface), sized by the true spacing in space
        # (the projected one above shrinks with the liquid's thickness).
        self._surf_sphere = None
        if self.cam.dim == 3:
            d = _spacing(rec.positions[0][free])
            if d is not None:
                px = d * self.cam.scale
                self._surf_sphere = min(max(SURFACE_SPHERE * px, 1.0), _MAX_SPHERE_PX)
                self._surf_smooth = max(1, int(round(math.sqrt((SURFACE_SMOOTH * px) ** 2 + 0.25) - 0.5)))

    def _frame_rgb_surface(self, k: int) -> np.ndarray:
        """Frame k with the free particles as a continuous liquid: their count and their values
        (speed or pressure) splatted per pixel and blurred (σ ≈ 0.7 spacing), so gaps between
        neighbours close; a pixel is inside where the density passes 45 % of a filled
        interior's, with a soft edge over 30–60 %, coloured by the density-weighted mean value
        on the colour map, lit along the surface's edge (the density's gradient as a normal,
        light from the upper left) so a wave's crest reads as a surface. Spray (particles with
        fewer than SPRAY_NEIGHBOURS others within two spacings) is left out of the surface and
        drawn under it as a soft mist (:meth:`_mist`), a lone particle not at all, so a splash
        reads as a plume, not as specks. Walls and colliders stay as drawn underneath."""
        rec = self.rec
        cam = self.cam_at(k)
        under = self._under(cam)
        if self.trail and (k > 0 or self.loop):
            self._draw_trail(under, k, cam)
        still = self._centres is None and not self.trail  # the same backdrop every frame: kept
        if still and self._surf_backdrop is not None:
            out = self._surf_backdrop.copy()
        else:
            out = self._rgb(under, cam).astype(np.float32)  # with the look's backdrop and props
            if self._glass_walls:
                g = self._glass(cam)[..., None]
                out = out * (1.0 - g) + self.palette[_WALL].astype(np.float32) * (0.55 * g)
            if still:
                self._surf_backdrop = out.copy()
        free = ~rec.pinned
        s, depth = cam.project(rec.positions[k][free] if rec.pinned.any() else rec.positions[k])
        col, row = cam.pixels(s)
        # Spray (particles with few neighbours) is drawn apart, as a mist under the surface.
        spray = self._spray_of(col, row, under.shape)
        body = ~spray
        values = None
        if self.color_by == "speed" and rec.speeds is not None:
            values = rec.speeds[k]
        elif self.color_by == "pressure" and rec.pressures is not None:
            values = rec.pressures[k]
        v = None
        if values is not None:
            v = np.nan_to_num(values[free] if rec.pinned.any() else values, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)
        if self._surf_sphere is not None and cam.dim == 3:
            # 3D: the lit surface of the nearest spheres (it needs none of the projected density).
            lit = None
            if body.any():
                lit = self._lit_surface(col[body], row[body], depth[body] * cam.scale,
                                        None if v is None else v[body], under.shape)
            if spray.any():
                out = self._mist(out, col[spray], row[spray], None if v is None else v[spray])
            if lit is not None:
                box, colour, a = lit
                out[box] = out[box] * (1 - a[..., None]) + colour * a[..., None]
        else:
            r = self._surf_r
            dens = _blur(_splat(col[body], row[body], under.shape), r) / self._surf_ref
            if v is not None:
                wsum = _blur(_splat(col[body], row[body], under.shape, v[body]), r) / self._surf_ref
                mean = wsum / np.maximum(dens, 1e-12)
                idx = self._value_levels_of(mean.reshape(-1)).reshape(mean.shape)
                colour = np.take(self.palette, idx, axis=0).astype(np.float32)
            else:
                colour = np.broadcast_to(self.palette[_PLAIN].astype(np.float32), out.shape)
            alpha = np.clip((dens - 0.3) / 0.3, 0.0, 1.0)
            alpha = alpha * alpha * (3 - 2 * alpha)  # smoothstep: a soft, antialiased edge
            # Edge light: the density's gradient is the surface normal in the image plane.
            gy, gx = np.gradient(np.minimum(dens, 1.0))
            lit2 = np.clip(-(gx + gy) * (0.7 * self._surf_spacing), -1.0, 1.0)  # light from the upper left
            shade = (1.0 + 0.35 * lit2)[..., None]
            colour = np.clip(colour * shade + 60.0 * np.maximum(lit2, 0)[..., None], 0, 255)
            if spray.any():
                out = self._mist(out, col[spray], row[spray], None if v is None else v[spray])
            a = alpha[..., None]
            out = out * (1 - a) + colour * a
        out = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        over = _overlay(under.shape)
        if rec.pinned.any():
            s, _ = cam.project(rec.positions[k][rec.pinned])
            col, row = cam.pixels(s)
            _draw_discs(over, col, row, np.full(col.shape, _PINNED, dtype=np.uint8), self.stencil)
        return self._finish_rgb(out, over, k, cam)

    def _lit_surface(self, col: np.ndarray, row: np.ndarray, depth: np.ndarray, values: np.ndarray | None,
                     shape: tuple[int, int]) -> tuple[tuple[slice, slice], np.ndarray, np.ndarray] | None:
        """A 3D liquid's surface lit (screen-space fluid rendering: van der Laan, Green & Sainz,
        I3D 2009), on the covered pixels' bounding box `box` (a pair of slices of the (H, W)
        `shape`): (box, colours (h, w, 3) float32, opacity (h, w)); None if no pixel is covered.
        The nearest sphere of SURFACE_SPHERE spacings over each pixel (`_core.sphere_depths`;
        `depth` in pixels, larger = nearer), that depth smoothed over SURFACE_SMOOTH spacings
        within the covered pixels, its gradient the normal; the colour that of the nearest
        particles' `values` (their mean over the same window; the plain colour where `values`
        is None) times an ambient and a diffuse term, plus a Blinn–Phong highlight and a rim
        towards white where the surface turns away; the opacity the smoothed coverage (a soft
        edge along the spheres' union)."""
        h, w = shape
        z, ids = _core.sphere_depths(np.ascontiguousarray(col, np.float64), np.ascontiguousarray(row, np.float64),
                                     np.ascontiguousarray(depth, np.float64), self._surf_sphere, h, w)
        covered = ids >= 0
        rows, cols = np.flatnonzero(covered.any(axis=1)), np.flatnonzero(covered.any(axis=0))
        if rows.size == 0:
            return None
        r = self._surf_smooth
        pad = 3 * r + 2  # three box blurs of radius r reach 3r
        y0, y1 = max(int(rows[0]) - pad, 0), min(int(rows[-1]) + pad + 1, h)
        x0, x1 = max(int(cols[0]) - pad, 0), min(int(cols[-1]) + pad + 1, w)
        box = (slice(y0, y1), slice(x0, x1))
        covered, z, ids = covered[box], z[box], ids[box]
        m = covered.astype(np.float32)
        wsum = _blur(m, r)
        inside = wsum > 1e-3
        zs = _blur(np.where(covered, z, np.float32(0.0)), r)
        zs = np.where(inside, zs / np.maximum(wsum, 1e-6), np.float32(0.0))
        gy, gx = np.gradient(zs)
        gx, gy = np.where(inside, gx, 0.0), np.where(inside, gy, 0.0)
        norm = np.sqrt(gx * gx + gy * gy + 1.0)
        nx, ny, nz = -gx / norm, gy / norm, 1.0 / norm  # rows run down, so +y on screen is −row
        lx, ly, lz = (np.asarray(SURFACE_LIGHT) / np.linalg.norm(SURFACE_LIGHT)).tolist()
        hx, hy, hz = lx, ly, lz + 1.0  # the half vector of the light and the view (0, 0, 1)
        hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        diffuse = np.clip(nx * lx + ny * ly + nz * lz, 0.0, 1.0)
        spec = np.clip((nx * hx + ny * hy + nz * hz) / hn, 0.0, 1.0) ** SURFACE_SHINE
        rim = (1.0 - nz) ** 2
        if values is not None:
            front = np.where(covered, values.astype(np.float32)[np.maximum(ids, 0)], np.float32(0.0))
            mean = _blur(front, r) / np.maximum(wsum, 1e-6)
            base = self.palette[self._value_levels_of(mean.reshape(-1)).reshape(mean.shape)].astype(np.float32)
        else:
            base = self.palette[_PLAIN].astype(np.float32)
        lit = base * (0.55 + 0.6 * diffuse)[..., None] + 255.0 * (0.5 * spec + 0.25 * rim)[..., None]
        a = np.clip((wsum - 0.25) / 0.5, 0.0, 1.0)
        a = a * a * (3 - 2 * a)  # smoothstep: half covered is the edge
        return box, np.clip(lit, 0.0, 255.0).astype(np.float32), a.astype(np.float32)

    def _spray_of(self, col: np.ndarray, row: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """(N,) bool: the particles of the liquid's spray, those with fewer than SPRAY_NEIGHBOURS
        others within about two particle spacings (a square window of half-width 2 spacings,
        which holds some 20 in a filled interior); the surface leaves them to the mist."""
        h, w = shape
        ok = np.isfinite(col) & np.isfinite(row) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        spray = np.zeros(col.shape, bool)
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            return spray
        half = max(2, int(round(2.0 * self._surf_spacing)))
        counts = _splat(col, row, shape)
        near = _box_blur(_box_blur(counts, half, 0), half, 1) * float((2 * half + 1) ** 2)
        others = near[row[idx].astype(np.int64), col[idx].astype(np.int64)] - 1.0
        spray[idx] = others < SPRAY_NEIGHBOURS
        return spray

    def _mist(self, out: np.ndarray, col: np.ndarray, row: np.ndarray, values: np.ndarray | None) -> np.ndarray:
        """`out` (H, W, 3 float32) with the liquid's spray (the particles at `col`, `row`, see
        :meth:`_spray_of`) drawn as a mist: splatted and blurred SPRAY_BLUR times wider than the
        surface, shown where about two of them overlap or more (full at about four), at most
        SPRAY_OPACITY opaque, coloured like the surface by their `values`. A jet or a cloud of
        spray reads as one soft plume, not as specks a pixel or two wide; a particle alone, far
        from any other, is left out (too small to see at the image's scale)."""
        h, w = out.shape[:2]
        rw = SPRAY_BLUR * self._surf_r
        # Only the spray's bounding box (with the blur's reach, 3·rw) can change.
        ok = np.isfinite(col) & np.isfinite(row)
        if not ok.any():
            return out
        pad = 3 * rw + 2
        x0, x1 = max(int(np.floor(col[ok].min())) - pad, 0), min(int(np.ceil(col[ok].max())) + pad + 1, w)
        y0, y1 = max(int(np.floor(row[ok].min())) - pad, 0), min(int(np.ceil(row[ok].max())) + pad + 1, h)
        if x0 >= x1 or y0 >= y1:
            return out
        box = (slice(y0, y1), slice(x0, x1))
        col, row = col - x0, row - y0
        h, w = y1 - y0, x1 - x0
        dw = _blur(_splat(col, row, (h, w)), rw)
        one = 1.0 / (2.0 * math.pi * rw * (rw + 1))  # a lone particle's peak: σ² = r(r + 1)
        mist = np.clip((dw - 1.5 * one) / (3.0 * one), 0.0, 1.0)
        mist = SPRAY_OPACITY * mist * mist * (3 - 2 * mist)
        if not mist.any():
            return out
        if values is not None:
            mean = _blur(_splat(col, row, (h, w), values), rw) / np.maximum(dw, 1e-12)
            colour = self.palette[self._value_levels_of(mean.reshape(-1)).reshape(mean.shape)].astype(np.float32)
        else:
            colour = np.broadcast_to(self.palette[_PLAIN].astype(np.float32), (h, w, 3))
        m = mist[..., None]
        out = np.array(out, dtype=np.float32, copy=True)
        out[box] = out[box] * (1 - m) + colour * m
        return out

    def _value_levels_of(self, values: np.ndarray) -> np.ndarray:
        """Palette indices of `values` on the map of `color_by` (speed or pressure)."""
        if self.color_by == "pressure":
            return _scalar_levels(values, self.vmax, _PRESSURE0, _N_PRESSURE)
        return _scalar_levels(values, self.vmax, _SPEED0, _N_SPEED)

    def _glow(self, buf: np.ndarray, k: int) -> None:
        """Tone-maps frame k's density into the glow levels: 1 − exp(−2.5 (d / scale)^0.75), so
        the densest 0.5 % saturate towards white while a filament a hundred times fainter still
        shows at a seventh of the range (a long exposure's compressive curve; the square root
        washed a whole attractor out to white, a linear curve lost its filaments). With a
        `trail`, the glow persists and fades (see _glow_density)."""
        d = self._glow_density(k)
        if self.glow_scale <= 0:
            return
        level = np.rint((1.0 - np.exp(-2.5 * (d / self.glow_scale) ** 0.75)) * (_N_GLOW - 1)).astype(np.int64)
        lit = level >= 1
        buf[lit] = (_GLOW0 + level[lit]).astype(np.uint8)

    def frame(self, k: int) -> np.ndarray:
        """(H, W) uint8 palette-index image of frame k."""
        rec = self.rec
        cam = self.cam_at(k)
        buf = self._under(cam)
        if self.color_by == "density":
            self._glow(buf, k)
            if rec.pinned.any():  # pinned particles stay discs on top
                s, _ = cam.project(rec.positions[k][rec.pinned])
                col, row = cam.pixels(s)
                _draw_discs(buf, col, row, np.full(col.shape, _PINNED, dtype=np.uint8), self.stencil)
            self._draw_overlays(buf, k, cam)
            self._draw_clock(buf, k)
            return buf
        s, depth = cam.project(rec.positions[k])
        col, row = cam.pixels(s)
        on_top = self._draw_behind(buf, k, cam, col, row)
        if col.size == 0:
            self._draw_overlays(buf, k, cam)
            return buf
        colors = self._disc_colors(k, col.size)
        if depth is not None:
            order = np.argsort(depth, kind="stable")  # painter's algorithm: far ones first
        else:
            order = self.pin_order
        c, r, cs = (col, row, colors) if order is None else (col[order], row[order], colors[order])
        if self.radii is None:
            _draw_discs(buf, c, r, cs, self.stencil)
        else:
            # Largest first, so that a small body next to a big one stays visible (within one
            # size the painter's order holds).
            radii = self.radii if order is None else self.radii[order]
            for rad in np.unique(radii)[::-1]:
                m = radii == rad
                _draw_discs(buf, c[m], r[m], cs[m], _disc_stencil(int(rad)))
        if on_top:
            i, j = rec.pairs
            _draw_lines(buf, col[i], row[i], col[j], row[j], _strain_levels(rec.strain[k], self.strain_scale))
        self._draw_overlays(buf, k, cam)
        self._draw_clock(buf, k)
        return buf

    @property
    def frames_independent(self) -> bool:
        """Whether frame(k) and frame_rgb(k) depend on k alone, so that frames may be drawn
        side by side (:mod:`._threads`): discs, trails, springs, bodies, a liquid's surface
        (what they cache on the way, such as the projected trails or the backdrop, is the same
        whichever frame fills it). Not a glow (``color_by="density"``: with trails each frame
        decays the last one's), nor a mesh (its shader keeps the geometry it drew for the
        shadows drawn after it). Every ready-made scene's first frames are tested to be the
        same drawn one by one and side by side."""
        return self.mesh is None and self.color_by != "density"

    def frame_rgb(self, k: int) -> np.ndarray:
        """(H, W, 3) uint8 RGB image of frame k: :meth:`frame` in the theme's colours or, with a
        mesh, the shaded surface (antialiased) over the background, trails and the particles
        that are not part of it, under the pinned particles, arrows and labels."""
        if self.mesh is None:
            if self.surface:
                return self._frame_rgb_surface(k)
            if self.color_by == "density" and self.colors is not None:
                return self._frame_rgb_glow(k)
            if self.antialias:
                return self._frame_rgb_discs(k)
            out = self.palette[self.frame(k)]
            self._draw_bodies(out, k, self.cam_at(k))
            return out
        rec = self.rec
        cam = self.cam_at(k)
        under = self._under(cam)
        if self.trail and (k > 0 or self.loop):
            self._draw_trail(under, k, cam)
        free = np.flatnonzero(self._off_mesh)
        if free.size:
            s, depth = cam.project(rec.positions[k][free])
            col, row = cam.pixels(s)
            order = slice(None) if depth is None else np.argsort(depth, kind="stable")
            colors = self._disc_colors(k, rec.positions.shape[1])[free]
            _draw_discs(under, col[order], row[order], colors[order], self.stencil)
        out = self._rgb(under, cam)  # a new C-contiguous (H, W, 3) uint8 array, with the look's backdrop
        solids = self._solids(k)
        if self._ground is not None:
            self._cast_shadow(out, under, k, cam, solids)
        self._shader.draw(out, rec.positions[k], cam, self._mesh_colors(k), solids=solids)
        if self._receivers:
            self._shadow_on_receivers(out, k, cam, solids)
        # Over the surface: pinned particles, arrows and labels, drawn as palette indices.
        over = _overlay(under.shape)
        if self._pinned_idx.size:
            col, row = cam.pixels(cam.project(rec.positions[k][self._pinned_idx])[0])
            _draw_discs(over, col, row, np.full(col.size, _PINNED, dtype=np.uint8), self.stencil)
        return self._finish_rgb(out, over, k, cam)

    def _receivers_setup(self, planes: list[tuple[np.ndarray, np.ndarray]], n: int) -> None:
        """Finds the surfaces, other than a floor prop, that the mesh casts its shadow on (see
        ``self._receivers``): each plane collider whose normal points up (at most 60° from +z)
        and, grouped by height, the upward faces of fixed 3D bodies (the SHADOW_RECEIVERS
        largest heights by area)."""
        shader = self._shader
        static = 0 if shader.ball is None else len(shader.ball[0])
        labels = [np.full(n, -1, dtype=np.int64), np.full(static, -1, dtype=np.int64)]
        for j, (p, nrm) in enumerate(planes):
            unit = nrm / max(float(np.linalg.norm(nrm)), 1e-300)
            if unit[2] >= 0.5 and shader.floor_verts:
                labels[1][j * shader.floor_verts:(j + 1) * shader.floor_verts] = len(self._receivers)
                self._receivers.append((np.asarray(p, np.float64), unit))
        bodies = self.rec.bodies
        if bodies is not None and bodies.dim == 3:
            from ._bodies import body_geometry

            verts, normals, faces, _ = body_geometry(bodies, 0)
            up = (normals[:, 2] > 0.99) & bodies.flat & bodies.fixed[bodies.owner] & np.isfinite(verts).all(axis=1)
            own = np.full(len(verts), -1, dtype=np.int64)
            tri = faces[up[faces].all(axis=1)]
            if len(tri):
                scale = max(1.0, float(np.abs(verts[up]).max()))
                level = np.round(verts[:, 2] / (1e-6 * scale))
                heights, which = np.unique(level[tri[:, 0]], return_inverse=True)
                e1, e2 = verts[tri[:, 1]] - verts[tri[:, 0]], verts[tri[:, 2]] - verts[tri[:, 0]]
                area = np.bincount(which, weights=0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]),
                                   minlength=len(heights))
                for g in np.argsort(-area)[:SHADOW_RECEIVERS]:
                    own[tri[which == g].ravel()] = len(self._receivers)
                    z = float(verts[tri[which == g][0, 0], 2])
                    self._receivers.append((np.array([0.0, 0.0, z]), np.array([0.0, 0.0, 1.0])))
            labels.append(own)
        self._receiver_labels = np.concatenate(labels) if self._receivers else None

    def _shadow(self, k: int, cam: _Camera, point: np.ndarray, normal: np.ndarray, shape: tuple[int, int],
                solids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
        """(H, W) float32 in [0, 1], the soft shadow frame k's mesh (and its rigid bodies,
        `solids` as :meth:`_solids` gives them) casts on the plane through `point` with unit
        `normal` (relative to the origin, facing up), light from straight overhead (an overcast
        sky): their triangles dropped straight down onto the plane, rasterised (where two
        overlap, the lower one's), each vertex weighing exp(−h / the mesh's width) at a height
        h above the plane (fainter the higher), and blurred (σ ≈ SHADOW_BLUR of the image's
        width). A triangle with no corner above the plane (a body's face lying on it, one below
        it) casts nothing. None if nothing lies above the plane."""
        from .. import _core

        x = np.nan_to_num(np.asarray(self.rec.positions[k], dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        size = max(float(np.ptp(x[:, :2], axis=0).max()), 1e-12)
        faces = self._shader.faces_u32
        if solids is not None and len(solids[2]):
            faces = np.concatenate([faces, (solids[2] + len(x)).astype(np.uint32)])
            x = np.concatenate([x, np.nan_to_num(solids[0], nan=0.0, posinf=0.0, neginf=0.0)])
        height = ((x - point) @ normal) / normal[2]  # straight up from the plane to the vertex
        # Above by more than rounding: a body's face lying on the plane casts nothing on it.
        above = height > 1e-6 * max(1.0, float(np.abs(point).max()), size)
        if not above.any():
            return None
        x[:, 2] -= height
        col, row = cam.pixels(cam.project(x)[0])
        # Drawn and blurred at half the resolution (a quarter of the work; what comes back is
        # smooth at the blur's width, so its 2 × 2 blocks do not show).
        h, w = shape
        verts = np.zeros((len(x), 3), dtype=np.float32)
        with np.errstate(over="ignore"):  # a blown-up scene's far points: inf, off the picture
            verts[:, 0], verts[:, 1], verts[:, 2] = 0.5 * col, 0.5 * row, -height  # the lowest nearest: its shadow shows
        faces = faces[above[faces].any(axis=1)]  # a triangle below the plane casts nothing on it
        img = np.full(((h + 1) // 2, (w + 1) // 2, 3), 255, dtype=np.uint8)
        ink = np.zeros((len(x), 4), dtype=np.float32)
        ink[:, :3] = (1.0 - np.exp(-np.maximum(height, 0.0) / size))[:, None]
        _core.rasterise_mesh(verts, np.ascontiguousarray(faces), ink, ink, img, 1)
        half = _blur(1.0 - img[..., 0].astype(np.float32) / 255.0, max(1, int(round(0.5 * SHADOW_BLUR * w))))
        return np.repeat(np.repeat(half, 2, axis=0), 2, axis=1)[:h, :w]

    def _shadow_on_receivers(self, out: np.ndarray, k: int, cam: _Camera,
                             solids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        """Frame k's mesh casts its soft shadow (:meth:`_shadow`) on the surfaces drawn with it
        that face up (``self._receivers``), in `out`, in place, after the shader drew them:
        darkening each by up to SHADOW_DARK where it shows (nothing in front of it)."""
        labels = self._receiver_labels
        if labels is None or len(labels) != len(self._shader.drawn[0]):
            return
        shape = out.shape[:2]
        cover = self._shader.coverage(labels, len(self._receivers), shape)
        dark = np.zeros(shape, dtype=np.float32)
        for (point, normal), part in zip(self._receivers, cover, strict=True):
            if part.max() <= 0.0:
                continue
            shade = self._shadow(k, cam, point, normal, shape, solids)
            if shade is not None:
                dark += SHADOW_DARK * shade * part
        if dark.any():
            out[...] = np.rint(out * (1.0 - np.minimum(dark, 1.0))[..., None]).astype(np.uint8)

    def _cast_shadow(self, out: np.ndarray, under: np.ndarray, k: int, cam: _Camera,
                     solids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        """Frame k's mesh casts a soft shadow (:meth:`_shadow`) on the floor prop
        (``self._ground``) in `out`, in place, darkening the floor by up to SHADOW_DARK where it
        shows (nothing that moves, no label is drawn there)."""
        z, poly = self._ground
        h, w = under.shape
        shade = self._shadow(k, cam, np.array([0.0, 0.0, z]), np.array([0.0, 0.0, 1.0]), (h, w), solids)
        if shade is None:
            return
        if self._ground_cover is None or self._centres is not None:
            pc, pr = cam.pixels(cam.project(poly)[0])
            cover = np.zeros((h, w), np.float32)
            part = polygon_coverage(np.stack([pc, pr], axis=1), (h, w))
            if part is not None:
                top, left, c = part
                cover[top : top + c.shape[0], left : left + c.shape[1]] = c
            if self._centres is None:
                self._ground_cover = cover
        else:
            cover = self._ground_cover
        dark = SHADOW_DARK * shade * cover * (under == _BACKGROUND)
        out[...] = np.rint(out * (1.0 - dark)[..., None]).astype(np.uint8)

    def _frame_rgb_discs(self, k: int) -> np.ndarray:
        """:meth:`frame` with antialiased discs: the background, trails and springs as palette
        indices, the discs blended by coverage over them in the core (the painter's order of
        frame()), then the overlays (strain springs, arrows, labels) on top."""
        from .. import _core

        rec = self.rec
        cam = self.cam_at(k)
        under = self._under(cam)
        s, depth = cam.project(rec.positions[k])
        col, row = cam.pixels(s)
        # Look: springs as soft strokes of a width, under the discs.
        thick = self.look.spring_width is not None and rec.pairs is not None and rec.strain is not None
        if self.colors is None:
            on_top = self._draw_behind(under, k, cam, col, row, springs=not thick)
            out = self._rgb(under, cam)
            self._draw_swept(out, k, cam)
        else:  # own colours: trails and springs in the particles' colours, in full colour
            on_top = False
            out = self._rgb(under, cam)
            self._draw_swept(out, k, cam)
            self._draw_behind_rgb(out, k, cam, col, row, springs=not thick)
        if thick:
            self._draw_thick_springs(out, k, col, row)
        if col.size:
            colors = self._disc_colors(k, col.size)
            order = np.argsort(depth, kind="stable") if depth is not None else self.pin_order
            if order is None:
                order = np.arange(col.size)
            if self.look.hulls:  # bodies of grains, drawn whole in place of their discs
                self._draw_hulls(out, cam, col, row, colors)
                order = order[~self._in_hull[order]]
            # The stencil's reach, sqrt(r² + r/2) (see _disc_stencil), as the soft disc's radius.
            r = np.full(col.size, float(self.radius)) if self.radii is None else self.radii.astype(np.float64)
            rad = np.maximum(np.sqrt(r * r + 0.5 * r), 0.6)
            if self.radii is not None:  # largest first, the painter's order within one size
                order = order[np.argsort(-rad[order], kind="stable")]
            if self.halo is not None:
                self._draw_halos(out, col, row, rad, colors)
            rgb = self.palette[colors[order]] if self.colors is None else self.colors[order]
            if self.look.shading == "sphere":
                draw_spheres(out, col[order], row[order], rad[order], rgb)
            else:
                _core.draw_discs(out, col[order].astype(np.float32), row[order].astype(np.float32),
                                 rad[order].astype(np.float32), np.ascontiguousarray(rgb))
        over = _overlay(under.shape)
        if on_top:
            i, j = rec.pairs
            _draw_lines(over, col[i], row[i], col[j], row[j], _strain_levels(rec.strain[k], self.strain_scale))
        return self._finish_rgb(out, over, k, cam)

    def _draw_hulls(self, out: np.ndarray, cam: _Camera, col: np.ndarray, row: np.ndarray, colors: np.ndarray) -> None:
        """``look.hulls`` on the full-colour image `out`: each group of particles (at pixel
        centres `col`, `row`; `colors` their palette indices) as the filled convex hull of its
        discs (true radii where the recording has them, else the drawn ones), in its first
        particle's colour, with a rim of 0.6 of it 1.5 pixels wide."""
        rec = self.rec
        if rec.radii is not None and len(rec.radii) == col.size and (rec.radii > 0).all():
            rad = rec.radii.astype(np.float64) * cam.scale
        else:
            rad = np.full(col.size, float(self.radius)) if self.radii is None else self.radii.astype(np.float64)
        shape = out.shape[:2]
        # Centres to a quarter pixel (the coverage's own resolution): a body at rest that creeps by
        # a thousandth of a pixel a frame then draws the same frame after frame, not flickering edges.
        col, row = np.round(col * 4) / 4, np.round(row * 4) / 4
        for group in self.look.hulls:
            g = np.asarray(group)
            pts = disc_hull(col[g], row[g], rad[g])
            if len(pts) < 3:
                continue
            rgb = (self.palette[colors[g[0]]] if self.colors is None else self.colors[g[0]]).astype(np.float32)
            blend(out, polygon_coverage(pts, shape), rgb)
            blend(out, polyline_coverage(np.concatenate([pts, pts[:1]]), 1.5, shape), 0.6 * rgb)

    @property
    def _in_hull(self) -> np.ndarray:
        """(N,) bool: the particles drawn as part of a ``look.hulls`` body."""
        mask = np.zeros(self.rec.positions.shape[1], dtype=bool)
        for group in self.look.hulls:
            mask[list(group)] = True
        return mask

    def _finish_rgb(self, out: np.ndarray, over: np.ndarray, k: int, cam: _Camera) -> np.ndarray:
        """A full-colour frame's last layer: the arrows and labels drawn on the `over` layer
        (which may hold more already), pasted onto `out`, which is returned."""
        self._draw_bodies(out, k, cam)
        self._draw_overlays(over, k, cam)
        self._draw_clock(over, k)
        if self.look.backdrop is not None or self.look.decor:
            # The labels' boxes show the backdrop (and props) there, as the still labels do.
            box = over == _BACKGROUND
            out[box] = self._static_image(cam)[box]
            over[box] = -1
        _paste(out, over, self.palette)
        return out

    def _solids(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Frame k's 3D rigid bodies as geometry for the mesh shader (None if there are none)."""
        if self.rec.bodies is None or self.rec.bodies.dim != 3:
            return None
        from ._bodies import body_geometry

        return body_geometry(self.rec.bodies, k)

    def _draw_bodies(self, out: np.ndarray, k: int, cam: _Camera) -> None:
        """Frame k's rigid bodies, filled and shaded, on the RGB image `out` (in 3D, lit solids
        over the particles; with a mesh they were drawn in its depth buffer)."""
        if self.rec.bodies is None:
            return
        if cam.dim == 2:
            from ._bodies import draw_bodies

            draw_bodies(out, cam, self.rec.bodies, k)
        elif self.mesh is None:
            from ._mesh import shade_solids

            shade_solids(out, cam, self._solids(k))  # type: ignore[arg-type]

    def _draw_behind(self, buf: np.ndarray, k: int, cam: _Camera, col: np.ndarray, row: np.ndarray,
                     springs: bool = True) -> bool:
        """What frame k draws under its discs: the trails, and the springs unless colouring by
        strain, which draws them over the discs (the picture is the springs). `col`, `row`:
        the particles' pixel positions; `springs` False: none (they are drawn elsewhere).
        Returns whether the springs still go on top."""
        rec = self.rec
        if self.trail and (k > 0 or self.loop):
            self._draw_trail(buf, k, cam)
        springs = springs and rec.pairs is not None and rec.strain is not None
        if springs and self.color_by != "strain":
            i, j = rec.pairs
            _draw_lines(buf, col[i], row[i], col[j], row[j], _strain_levels(rec.strain[k], self.strain_scale))
        return springs and self.color_by == "strain"

    def _draw_halos(self, out: np.ndarray, col: np.ndarray, row: np.ndarray, rad: np.ndarray, colors: np.ndarray | None,
                    white: float = 0.0) -> None:
        """A soft halo around each `halo` particle, onto the RGB image `out`: its colour (moved a
        share `white` towards white) blended in with weight 0.85 exp(−d²/2σ²), σ = 1.3 disc
        radii, out to 4σ (a star's glow). `colors`: palette indices, unused with own colours."""
        h, w = out.shape[:2]
        for i in np.flatnonzero(self.halo):
            c, r = col[i], row[i]
            if not (np.isfinite(c) and np.isfinite(r)):
                continue
            sigma = 1.3 * float(rad[i])
            reach = int(math.ceil(4 * sigma))
            c0, c1 = max(0, int(c) - reach), min(w, int(c) + reach + 1)
            r0, r1 = max(0, int(r) - reach), min(h, int(r) + reach + 1)
            if c0 >= c1 or r0 >= r1:
                continue
            yy, xx = np.mgrid[r0:r1, c0:c1]
            a = (0.85 * np.exp(-((xx + 0.5 - c) ** 2 + (yy + 0.5 - r) ** 2) / (2 * sigma * sigma)))[..., None]
            tint = (self.palette[colors[i]] if self.colors is None else self.colors[i]).astype(np.float32)
            tint = tint * (1 - white) + 255.0 * white
            patch = out[r0:r1, c0:c1].astype(np.float32)
            out[r0:r1, c0:c1] = np.rint(patch * (1 - a) + tint * a).astype(np.uint8)

    def _draw_behind_rgb(self, out: np.ndarray, k: int, cam: _Camera, col: np.ndarray, row: np.ndarray,
                         springs: bool = True) -> None:
        """What frame k draws under its discs in their own colours (``colors``), onto the RGB
        image `out`: each moving particle's trail in its colour, fading into the background
        with age (from 15 % to 75 % of the colour; with ``look.trail_fade``, blended as
        :meth:`_draw_faded_trail` does), then the springs (rods, strings; unless `springs` is
        False) in the colour of their moving end (the pinned end is a pivot), 2 px wide from
        300 px on."""
        rec = self.rec
        bg = self.palette[_BACKGROUND].astype(np.float32)
        rgb = self.colors.astype(np.float32)
        passes = width_offsets(self.trail_px)
        if self.trail and (k > 0 or self.loop) and self.look.trail_fade is not None:
            self._draw_faded_trail(out, k, cam, rgb)
        elif self.trail and (k > 0 or self.loop):
            moving = self._trailed
            # Every segment in one call, in the order they used to be drawn one frame at a time
            # (oldest first, pass by pass): the same pixels, a fraction of the time.
            first, c0, r0, c1, r1, _, hi = self._trail_pieces(k, cam, moving)
            if c0.size:
                a = 0.15 + 0.6 * (hi - first) / max(1, k - first)
                w0, w1 = (1 - a).astype(np.float32)[:, None, None], a.astype(np.float32)[:, None, None]
                shade = np.rint(bg * w0 + rgb[moving][None] * w1).astype(np.uint8)
                _draw_lines(out, *_with_offsets(c0, r0, c1, r1, shade, passes))
        if springs and rec.pairs is not None and rec.strain is not None:
            passes = width_offsets(self._line_px)
            i, j = rec.pairs
            end = np.where(rec.pinned[j], i, j)
            shade = np.rint(0.2 * bg + 0.8 * rgb[end]).astype(np.uint8)
            for dc, dr in passes:
                _draw_lines(out, col[i] + dc, row[i] + dr, col[j] + dc, row[j] + dr, shade)

    def _value_levels(self, k: int) -> np.ndarray | None:
        """(N,) uint8 palette indices of frame k's speeds or pressures on their colour map, or
        None when `color_by` is neither (or they were not recorded)."""
        rec = self.rec
        if self.color_by == "speed" and rec.speeds is not None:
            return _scalar_levels(rec.speeds[k], self.vmax, _SPEED0, _N_SPEED)
        if self.color_by == "pressure" and rec.pressures is not None:
            return _scalar_levels(rec.pressures[k], self.vmax, _PRESSURE0, _N_PRESSURE)
        return None

    def _disc_colors(self, k: int, n: int) -> np.ndarray:
        """(n,) uint8 palette indices of frame k's discs by `color_by` (pinned: their own
        colour; strain: grey discs, so that blue reads as compressed springs only)."""
        if self._color_idx is not None:  # own colours, pinned ones too
            return self._color_idx.copy()
        colors = self._value_levels(k)
        if colors is None:
            colors = np.full(n, _WALL if self.color_by == "strain" else _PLAIN, dtype=np.uint8)
        colors[self.rec.pinned] = _PINNED
        return colors

    def _mesh_colors(self, k: int) -> np.ndarray | None:
        """(N, 3) float32 per-vertex surface colours in [0, 1] from `color_by` (speed, pressure,
        or strain: each vertex the mean strain of its springs), the particles' own colours
        (``colors`` with color_by "none": a jelly's, a flag's stripes), or None for the plain
        surface."""
        rec = self.rec
        if self.colors is not None:
            return self.colors.astype(np.float32) * np.float32(1 / 255)
        if self.color_by == "strain" and rec.strain is not None and rec.pairs is not None:
            i, j = rec.pairs
            n = rec.positions.shape[1]
            strain = np.nan_to_num(rec.strain[k].astype(np.float64), nan=0.0)
            total = np.bincount(i, weights=strain, minlength=n) + np.bincount(j, weights=strain, minlength=n)
            count = np.bincount(i, minlength=n) + np.bincount(j, minlength=n)
            idx = _strain_levels(total / np.maximum(count, 1), self.strain_scale)
        else:
            idx = self._value_levels(k)
            if idx is None:
                return None
        return self.palette[idx].astype(np.float32) * np.float32(1 / 255)

    def _draw_overlays(self, buf: np.ndarray, k: int, cam: _Camera) -> None:
        """Over everything that moves, under the clock: frame k's arrows, then the colour bar,
        title and scale bar."""
        if self._arrows is not None:
            _draw_arrows(buf, cam, self.rec.positions[k][self._arrows[0]], self._arrows[1][k], self._arrows[2])
        if self._labels is not None:
            buf.reshape(-1)[self._labels[0]] = self._labels[1]
        if self._scales is not None and self.annotate:  # a zooming view: the scale bar of this frame's scale
            self.scale_bar = _draw_scale_bar(buf, cam.scale, "m" if self.rec.speed_unit == "m/s" else "", self.font_px)

    def _draw_clock(self, buf: np.ndarray, k: int) -> None:
        """The simulated time in the bottom-left corner ("t = 1.23 s"; no unit in a scene's own
        units, such as G = 1), on a box of background, over everything. Left out on images too
        small to read it and for recordings without times."""
        times = self.rec.times
        h, w = buf.shape
        if not self.annotate or times is None or not np.isfinite(times[k]):
            return
        unit = " s" if self.rec.speed_unit == "m/s" else ""
        text = f"t = {_format_value(float(times[k]))}{unit}"
        _draw_text(buf, text, 4, h - 4 - _text_mask(text, self.font_px).shape[0], _TEXT, _BACKGROUND, px=self.font_px)

    def _draw_trail(self, buf: np.ndarray, k: int, cam: _Camera) -> None:
        """The paths of the moving particles over the `trail` frames before k, oldest (palest)
        first: one segment per particle per frame step, under everything that moves; seen
        through frame k's camera `cam`."""
        moving = self._trailed
        # Every segment in one call, in the order they used to be drawn one frame at a time
        # (oldest first, pass by pass): the same pixels, a fraction of the time.
        if self.look.trail_fade is None:
            first, c0, r0, c1, r1, lo, _ = self._trail_pieces(k, cam, moving)
            shade = _TRAIL0 + np.minimum(_N_TRAIL - 1, ((lo - first) * _N_TRAIL // max(1, k - first)).astype(np.int64))
        else:  # look.trail_fade: the shade of the opacity at this age (see _trail_alpha)
            c0, r0, c1, r1, a = self._faded_pieces(k, cam, moving, lambda a: a >= 0.5 / _N_TRAIL)
            shade = _TRAIL0 + np.minimum(_N_TRAIL - 1, (a * _N_TRAIL).astype(np.int64))
        if c0.size:
            colors = np.broadcast_to(shade.astype(np.uint8)[:, None], c0.shape)
            _draw_lines(buf, *_with_offsets(c0, r0, c1, r1, colors, width_offsets(self.trail_px)))

    # ------------------------------------------------------------------ look (see _look.Look)

    def _trail_pieces(self, k: int, cam: _Camera, sel: Any
                      ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The pieces of frame k's trails seen through `cam`, oldest first: the first frame they
        start from (:meth:`_trail_pixels`), (c0, r0, c1, r1), each (P, M), the pixel ends of
        the selected (`sel`) particles' P pieces, and (P,) lo, hi, the fractional frames each
        spans. One straight piece a frame step, pix(f) to pix(f + 1), or with
        ``look.trail_samples`` = S > 1 the S pieces of the path's cubic Hermite curve
        (:meth:`_sub_pixels`)."""
        first, pix = self._trail_pixels(k, cam)
        S = self.look.trail_samples
        blocks = []
        for f in range(first, k):
            if S <= 1:
                (c0, r0), (c1, r1) = pix(f), pix(f + 1)
                blocks.append((c0[sel][None], r0[sel][None], c1[sel][None], r1[sel][None]))
            else:
                cs, rs = self._sub_pixels(f, cam)
                cs, rs = cs[:, sel], rs[:, sel]
                blocks.append((cs[:-1], rs[:-1], cs[1:], rs[1:]))
        if not blocks:
            none = np.zeros((0, 0))
            return first, none, none, none, none, np.zeros(0), np.zeros(0)
        c0, r0, c1, r1 = (np.concatenate([b[i] for b in blocks]) for i in range(4))
        f = np.repeat(np.arange(first, k, dtype=np.float64), max(S, 1))
        j = np.tile(np.arange(max(S, 1), dtype=np.float64), k - first)
        return first, c0, r0, c1, r1, f + j / max(S, 1), f + (j + 1) / max(S, 1)

    def _faded_pieces(self, k: int, cam: _Camera, sel: Any, keep: Any
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Frame k's trail pieces (:meth:`_trail_pieces`: c0, r0, c1, r1) and (P,) opacities
        under ``look.trail_fade`` (:meth:`_trail_alpha`), only those whose opacity passes
        `keep` (a mask of the opacities)."""
        _, c0, r0, c1, r1, _, hi = self._trail_pieces(k, cam, sel)
        a = self._trail_alpha(k, hi - 1)
        kept = keep(a)
        return c0[kept], r0[kept], c1[kept], r1[kept], a[kept]

    def _sub_pixels(self, f: int, cam: _Camera) -> tuple[np.ndarray, np.ndarray]:
        """(S + 1, N) pixel columns and rows along every particle's path from frame f to f + 1
        (modulo the frame count with `loop`), seen through `cam`: the cubic Hermite curve of the
        positions and the recorded velocities times the frame interval (without velocities or
        times, Catmull–Rom tangents from the neighbouring frames: :meth:`_tangents`), at
        S = ``look.trail_samples`` + 1 evenly spaced fractions of the step. The fitted
        camera's are kept."""
        rec = self.rec
        n = rec.frames
        a, b = (f % n, (f + 1) % n) if self.loop else (f, min(f + 1, n - 1))
        still = self._centres is None
        if still and a in self._sub_pix:
            return self._sub_pix[a]

        def at(g: int) -> np.ndarray:
            return rec.positions[g].astype(np.float64)

        p0, p1 = at(a), at(b)
        t0, t1 = self._tangents(a, b, at, lambda g, h: rec.velocities[g].astype(np.float64) * h)
        S = self.look.trail_samples
        with np.errstate(invalid="ignore", over="ignore"):
            pts = _hermite(p0, t0, p1, t1, (np.arange(S + 1) / S)[:, None, None])
        pts[0], pts[-1] = p0, p1  # the frames' own points, exactly
        c, r = cam.pixels(cam.project(pts.reshape(-1, pts.shape[-1]))[0])
        out = (c.reshape(S + 1, -1), r.reshape(S + 1, -1))
        if still:
            self._sub_pix[a] = out
        return out

    def _trail_alpha(self, k: int, f: Any) -> Any:
        """The opacity of frame k's trail segment from frame f to f + 1 under
        ``look.trail_fade`` = φ: φ + (1 − φ)(1 − age)², age = (k − 1 − f) / trail (f
        fractional for the pieces of ``look.trail_samples``: a piece ending at frame g is as old
        as a whole step ending there)."""
        fade = float(self.look.trail_fade or 0.0)
        age = (k - 1 - f) / max(1, self.trail)
        return fade + (1.0 - fade) * (1.0 - age) ** 2

    def _trail_pixels(self, k: int, cam: _Camera) -> tuple[int, Any]:
        """(first frame, f -> (col, row) of every particle at frame f through `cam`) of frame k's
        trails: with the fitted camera projected once for all frames (a periodic recording's
        trail runs on from its end: pix[-1] ...), following the screen-plane points projected
        once (only the centre moves), orbiting projected again (the paths turn with the view)."""
        rec = self.rec
        first = max(0, k - self.trail)
        if self._centres is None:
            if self._pix is None:
                self._pix = [self.cam.pixels(self.cam.project(rec.positions[f])[0]) for f in range(rec.frames)]
            if self.loop:
                first = k - self.trail
            return first, self._pix.__getitem__
        if self._bases is None:
            if self._pix is None:
                self._pix = [self.cam.project(rec.positions[f])[0] for f in range(rec.frames)]
            pix = self._pix
            return first, lambda f: cam.pixels(pix[f])
        return first, lambda f: cam.pixels(cam.project(rec.positions[f])[0])

    def _draw_faded_trail(self, out: np.ndarray, k: int, cam: _Camera, rgb: np.ndarray) -> None:
        """The moving particles' trails in their (N, 3) float colours `rgb`, blended over the
        full-colour image `out` with the opacity of their age (:meth:`_trail_alpha`): drawn
        into one layer of colour and opacity, oldest first (a newer segment covers an older
        one where they cross), then laid over `out` once, so nothing is blended twice."""
        moving = np.flatnonzero(self._trailed)
        h, w = out.shape[:2]
        c0, r0, c1, r1, a = self._faded_pieces(k, cam, moving, lambda a: a > 0.0)
        if not c0.size:
            return
        vals = np.concatenate([np.broadcast_to(rgb[moving].astype(np.float32), c0.shape + (3,)),
                               np.broadcast_to(a.astype(np.float32)[:, None, None], c0.shape + (1,))], axis=2)
        c0, r0, c1, r1, vals = _with_offsets(c0, r0, c1, r1, vals, width_offsets(self.trail_px))
        # The layer covers the trails' box only (clipped to the image).
        with np.errstate(invalid="ignore"):
            cols, rows = np.concatenate([c0, c1]), np.concatenate([r0, r1])
            fin = np.isfinite(cols) & np.isfinite(rows)
        if not fin.any():
            return
        left = max(0, int(math.floor(cols[fin].min())) - 1)
        top = max(0, int(math.floor(rows[fin].min())) - 1)
        right = min(w, int(math.ceil(cols[fin].max())) + 2)
        bottom = min(h, int(math.ceil(rows[fin].max())) + 2)
        if left >= right or top >= bottom:
            return
        layer = np.zeros((bottom - top, right - left, 4), np.float32)
        _draw_lines(layer, c0 - left, r0 - top, c1 - left, r1 - top, vals)
        a = layer[..., 3:4]
        drawn = a[..., 0] > 0
        view = out[top:bottom, left:right]
        mixed = view[drawn].astype(np.float32) * (1 - a[drawn]) + layer[drawn][:, :3] * a[drawn]
        view[drawn] = np.clip(np.rint(mixed), 0, 255).astype(np.uint8)

    def _rgb(self, under: np.ndarray, cam: _Camera) -> np.ndarray:
        """The full-colour image of the index image `under`, with the look's backdrop and props
        where `under` shows the background (labels, colliders and walls stay on top)."""
        # `take` and a masked copy, not fancy and boolean indexing: 2.5 against 7.5 ms a
        # 480×360 frame.
        out = np.take(self.palette, under, axis=0)
        if self.look.backdrop is None and not self.look.decor:
            return out
        np.copyto(out, self._static_image(cam), where=(under == _BACKGROUND)[..., None])
        return out

    def _static_image(self, cam: _Camera) -> np.ndarray:
        """(H, W, 3) uint8: the look's backdrop (a vertical gradient, else the background
        colour) with its props drawn over it (antialiased), through `cam`; kept for the fitted
        camera."""
        if self._centres is None and self._static is not None:
            return self._static
        h, w = cam.height, cam.width
        if self.look.backdrop is not None:
            top, bottom = (np.array(c, np.float32) for c in self.look.backdrop)
            t = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None, None]
            img = np.broadcast_to(top * (1 - t) + bottom * t, (h, w, 3)).copy()
        else:
            img = np.broadcast_to(self.palette[_BACKGROUND].astype(np.float32), (h, w, 3)).copy()
        for item in self.look.decor:
            col, row = cam.pixels(cam.project(item["points"] - self.rec.origin)[0])
            pts = np.stack([col, row], axis=1)
            cover = (polygon_coverage(pts, (h, w)) if item["kind"] == "polygon"
                     else polyline_coverage(pts, float(item["width"]), (h, w)))
            blend(img, cover, item["color"])
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if self._centres is None:
            self._static = img
        return img

    def _draw_thick_springs(self, out: np.ndarray, k: int, col: np.ndarray, row: np.ndarray) -> None:
        """Frame k's springs as soft round strokes ``look.spring_width`` pixels wide on the
        full-colour image `out`: coloured by strain (the strain map and scale of the thin
        ones), or, with own colours and no strain colouring, in their moving end's colour."""
        from .. import _core

        rec = self.rec
        i, j = rec.pairs
        if self.colors is not None and self.color_by != "strain":
            end = np.where(rec.pinned[j], i, j)
            bg = self.palette[_BACKGROUND].astype(np.float32)
            rgb = np.rint(0.2 * bg + 0.8 * self.colors[end].astype(np.float32)).astype(np.uint8)
        else:
            rgb = self.palette[_strain_levels(rec.strain[k], self.strain_scale)]
        cc, rr, seg = stroke_points(col[i], row[i], col[j], row[j])
        if cc.size:
            rad = np.full(cc.size, 0.5 * float(self.look.spring_width), np.float32)
            _core.draw_discs(out, cc, rr, rad, np.ascontiguousarray(rgb[seg]))

    def _swept_colors(self) -> np.ndarray:
        """(2, 3) float32: the alternating colours of the swept areas."""
        sw = self.look.swept_areas
        if sw["colors"] is not None:
            return sw["colors"].astype(np.float32)
        if self.colors is not None:
            return self.colors[[sw["body"], sw["centre"]]].astype(np.float32)
        return self.palette[[_PLAIN, _PINNED]].astype(np.float32)

    def _draw_swept(self, out: np.ndarray, k: int, cam: _Camera) -> None:
        """``look.swept_areas`` at frame k on the full-colour image `out`: the area being swept
        (from the start of its interval to now) and the `count` − 1 intervals before it, each the
        polygon of the centre and the body's path (:func:`~._look.swept_path`, relative to the
        centre, placed at its position now), filled in two alternating colours, the older ones
        fainter; then the radius vector. Intervals before frame 0 come from the end of a
        periodic (`loop`) recording and are left out otherwise."""
        sw = self.look.swept_areas
        if sw is None:
            return
        rec = self.rec
        n_f, centre, body = sw["frames"], sw["centre"], sw["body"]
        colours = self._swept_colors()
        here = rec.positions[k, centre].astype(np.float64)
        shape = out.shape[:2]
        now = k // n_f
        for age in range(sw["count"] - 1, -1, -1):  # oldest first
            j = now - age
            f0, f1 = j * n_f, min((j + 1) * n_f, k)
            if f1 <= f0 or (f0 < 0 and not self.loop):
                continue
            rel = self._swept_cache.get(j) if f1 == (j + 1) * n_f else None
            if rel is None:
                # A motion beyond float64 (a hostile dt) leaves no area to draw, not a warning.
                with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                    b = swept_path(rec.positions, rec.velocities, rec.times, body, f0, f1, loop=self.loop)
                    c = swept_path(rec.positions, rec.velocities, rec.times, centre, f0, f1, loop=self.loop)
                    rel = b - c
                if f1 == (j + 1) * n_f:
                    self._swept_cache[j] = rel
            with np.errstate(invalid="ignore", over="ignore"):
                poly = np.concatenate([here[None], here + rel])
            if not np.isfinite(poly).all():
                continue
            col, row = cam.pixels(cam.project(poly)[0])
            opacity = 0.5 if age == 0 else 0.3  # the one being swept brighter; the rest alike
            blend(out, polygon_coverage(np.stack([col, row], axis=1), shape, 3), colours[j % 2], opacity)
        # The radius vector that sweeps them.
        seg = rec.positions[k, [centre, body]].astype(np.float64)
        if not np.isfinite(seg).all():
            return
        col, row = cam.pixels(cam.project(seg)[0])
        ink = 0.5 * (colours[0] + colours[1]) * 0.4 + 255.0 * 0.6
        blend(out, polyline_coverage(np.stack([col, row], axis=1), 1.5, shape), ink, 0.8)
