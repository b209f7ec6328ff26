"""Drawing fields on grids (ripples, Turing patterns, smoke) into palette images.

A field frame is upsampled to the image size with Pillow's bicubic resampling (smooth edges, no
blocky cells), then mapped through one of the styles below onto a 256-entry palette of its own:
255 shades of the style's colour map and one colour for obstacle cells. A frame uses a few
dozen of the shades (see ``_LEVELS``); with ``dither=True`` each pixel is rounded up or down to
one of them by Bayer's 8 × 8 ordered dither (a threshold fixed to the pixel's place, so still
regions stay still and the output is deterministic), which turns the steps of a slow gradient
(a dye's soft edges) into a fine even mix of the two shades either side.

Styles
------
water    a shaded height field: surface normals from the gradient of u, lit by a low light from
         the upper left (Lambert diffuse plus a Blinn–Phong highlight) over deep-to-shallow blues,
         so ripples read as water.
turing   a perceptually uniform dark-to-light map (magma-like) of the concentration, scaled to the
         run's 1st–99.5th percentiles.
smoke    density over a dark background (inferno-like), scaled to the run's 99.5th percentile.
signed   a diverging blue–white–red map, symmetric about 0 at the run's 99th percentile of |u|,
         through a square-root tone curve so that weak waves far from a source show.
"""
from __future__ import annotations

from typing import Any

import numpy as np

STYLES = ("water", "turing", "smoke", "signed")
_OBSTACLE = 255
_N = 255
#: Shades a frame uses of its map's 255, by style: GIF's LZW codes runs of equal pixels, so fewer
#: shades make much smaller files (Turing 400², 60 frames: 9.4 MB with 255 shades, 4.1 MB with
#: 48). Each count is the fewest that showed no banding by eye at the default sizes: the shaded
#: water and the diverging waves (an odd count, so 0 is the white middle) vary smoothly and
#: take few; the smoke's thin wisps over black need the most. (Double slit, 100 frames of
#: 480 × 320: 64 shades 4.6 MB, 17 shades 1.8 MB; Turing, 120 frames of 400²: 48 shades 3.7 MB,
#: 24 shades 2.5 MB.)
_LEVELS = {"water": 32, "signed": 17, "turing": 24, "smoke": 64}
#: Shades with ``dither=True``: the dither mixes neighbouring shades, so fewer show no bands
#: and keep the file near its undithered size (cavity, 90 frames of 400²: 24 shades 2.70 MB
#: banded; dithered, 24 shades 3.45 MB, 16 shades 2.75 MB, both smooth at 1:1). The other
#: styles take the same two thirds of their counts (signed an odd one, 0 the white middle),
#: untuned: no ready-made scene dithers them.
_DITHERED_LEVELS = {"water": 24, "signed": 13, "turing": 16, "smoke": 48}


def _ramp(stops: list[tuple[float, tuple[int, int, int]]]) -> np.ndarray:
    """(255, 3) uint8: the colours interpolated linearly between (position, RGB) stops."""
    x = np.linspace(0.0, 1.0, _N)
    pos = np.array([p for p, _ in stops])
    rgb = np.array([c for _, c in stops], dtype=np.float64)
    return np.stack([np.interp(x, pos, rgb[:, k]) for k in range(3)], axis=1).round().astype(np.uint8)


# magma and inferno sampled at a few points (their published definitions, van der Walt & Smith
# for matplotlib, 2015); linear interpolation between them keeps the lightness monotonic.
_MAGMA = [(0.0, (0, 0, 4)), (0.25, (81, 18, 124)), (0.5, (183, 55, 121)), (0.75, (252, 137, 97)), (1.0, (252, 253, 191))]
_INFERNO = [(0.0, (0, 0, 4)), (0.25, (87, 16, 110)), (0.5, (188, 55, 84)), (0.75, (249, 142, 9)), (1.0, (252, 255, 164))]
_WATER = [(0.0, (4, 30, 66)), (0.35, (16, 78, 139)), (0.65, (64, 156, 208)), (0.85, (170, 222, 242)), (1.0, (255, 255, 255))]
_SIGNED = [(0.0, (33, 102, 172)), (0.5, (247, 247, 247)), (1.0, (178, 24, 43))]
_MAPS = {"water": _WATER, "turing": _MAGMA, "smoke": _INFERNO, "signed": _SIGNED}
_OBSTACLE_RGB = {"water": (92, 84, 74), "turing": (128, 128, 128), "smoke": (110, 110, 120), "signed": (60, 60, 60)}


def _bayer(n: int) -> np.ndarray:
    """(n, n) thresholds in (0, 1) of Bayer's ordered dither (n a power of 2)."""
    m = np.zeros((1, 1), dtype=np.int64)
    while m.shape[0] < n:
        m = np.block([[4 * m, 4 * m + 2], [4 * m + 3, 4 * m + 1]])
    return (m + 0.5) / m.size


_BAYER8 = _bayer(8)


def _threshold(shape: tuple[int, int]) -> np.ndarray:
    """(H, W) thresholds of Bayer's 8 × 8 ordered dither tiled over an image: each pixel's
    threshold is fixed to its place, so a still region stays still from frame to frame (the
    GIF's frame differences store only what moves) and the same frames give the same bytes."""
    h, w = shape
    return np.tile(_BAYER8, (-(-h // 8), -(-w // 8)))[:h, :w]


def palette(style: str) -> np.ndarray:
    """(256, 3) uint8: the style's 255 shades, then the obstacle colour."""
    return np.vstack([_ramp(_MAPS[style]), np.array([_OBSTACLE_RGB[style]], dtype=np.uint8)])


def _image(field: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(nx, ny) field → (H, W) float32 image, y up, bicubic upsampling."""
    from PIL import Image

    w, h = size
    img = Image.fromarray(np.ascontiguousarray(field.T[::-1], dtype=np.float32), mode="F")
    return np.asarray(img.resize((w, h), Image.Resampling.BICUBIC), dtype=np.float32)


def _mask_image(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(nx, ny) bool cells → (H, W) bool pixels: the cells drawn as squares, blurred by a
    Gaussian of 0.6 cells' width and cut at one half, so that a disc of cells is drawn round,
    not as a staircase of squares. (The cells upsampled bicubically and cut at one half, as
    before issue 65, kept most of the staircase: smoke's obstacle read as blocky.) 0.6 cells is
    the widest blur that keeps a wall one cell thick: its middle stays at erf(0.59) ≈ 0.6 > ½."""
    from PIL import Image, ImageFilter

    w, h = size
    cell = min(w / max(mask.shape[0], 1), h / max(mask.shape[1], 1))
    img = Image.fromarray(np.ascontiguousarray(mask.T[::-1], dtype=np.uint8) * np.uint8(255), mode="L")
    img = img.resize((w, h), Image.Resampling.NEAREST).filter(ImageFilter.GaussianBlur(0.6 * cell))
    return np.asarray(img) >= 128


def _round_top(top: float) -> float:
    """`top`, the colour scale's end (a percentile of the run's field, so arbitrary in its last
    digits), raised to the round number just above it where one lies within 2 %: a scale to
    "1" reads, one to "0.999" looks like an error, and 2 % less contrast does not show. Round:
    1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 8 times a power of ten."""
    if not (np.isfinite(top) and top > 0):
        return top
    scale = 10.0 ** np.floor(np.log10(top))
    for m in (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0):
        if m * scale >= top * (1 - 1e-12):
            return float(m * scale) if m * scale <= 1.02 * top else top
    return top


def fit_size(extent: tuple[float, ...], size: tuple[int, int]) -> tuple[int, int]:
    """The largest image within `size` with the domain's aspect ratio (pixels square)."""
    w, h = size
    aspect = extent[0] / extent[1]
    if w / h > aspect:
        w = max(2, int(round(h * aspect)))
    else:
        h = max(2, int(round(w / aspect)))
    return w, h


class FieldRasteriser:
    """Index images of a recording's field frames in one style, on scales fixed over the run."""

    def __init__(
        self,
        fields: np.ndarray,
        style: str,
        size: tuple[int, int],
        mask: np.ndarray | None,
        extent: tuple[float, float],
        points: np.ndarray | None = None,
        times: np.ndarray | None = None,
        label: str = "",
        colorbar: bool = True,
        time_unit: str | None = None,
        dither: bool = False,
    ) -> None:
        self.fields, self.style, self.size, self.extent, self.points = fields, style, size, extent, points
        self.times, self.label, self.colorbar = times, label, colorbar
        self.dither = dither
        # The clock's unit: seconds, but none for a dimensionless model (Gray–Scott's time is in
        # the units of its rates F and k; its fields u and v are labelled without a unit).
        self.time_unit = ("" if label in _DIMENSIONLESS else "s") if time_unit is None else time_unit
        self.mask = None if mask is None else _mask_image(mask, size)
        finite = fields[np.isfinite(fields)]
        if style == "water":
            gx, gy = np.gradient(fields.astype(np.float64), axis=(1, 2))
            slope = np.hypot(gx, gy)
            top = float(np.percentile(slope, 99.5)) if slope.size else 0.0
            # Slopes scaled so the run's steepest ripples tilt the surface by ~35°.
            self.gain = 0.7 / top if top > 0 else 0.0
        elif style == "signed":
            top = _round_top(float(np.percentile(np.abs(finite), 99))) if finite.size else 0.0
            self.lo, self.hi = -top, top
        elif style == "turing":
            self.lo = float(np.percentile(finite, 1)) if finite.size else 0.0
            self.hi = float(np.percentile(finite, 99.5)) if finite.size else 1.0
            # A quantity that is never negative (a speed, a concentration) whose low end is near
            # 0 starts its scale at 0: "0" reads, "0.000115" does not.
            if finite.size and float(finite.min()) >= 0.0 and self.lo < 0.05 * self.hi:
                self.lo = 0.0
            self.hi = _round_top(self.hi)
        else:
            self.lo, self.hi = 0.0, _round_top(float(np.percentile(finite, 99.5))) if finite.size else 1.0
        if style != "water" and not self.hi > self.lo:
            self.hi = self.lo + 1.0

    def frame(self, k: int) -> np.ndarray:
        f = self.fields[k]
        if self.style == "water":
            # Gradients on the grid (per cell), then upsampled: the shading of a smooth surface.
            gx, gy = np.gradient(f.astype(np.float64))
            nx, ny = _image(-self.gain * gx, self.size), _image(-self.gain * gy, self.size)
            # Image rows run down: flip the y slope to screen coordinates.
            ny = -ny
            inv = 1.0 / np.sqrt(nx * nx + ny * ny + 1.0)
            light = np.array([-0.45, -0.55, 0.70])
            light /= np.linalg.norm(light)
            half = light + np.array([0.0, 0.0, 1.0])
            half /= np.linalg.norm(half)
            diffuse = (nx * light[0] + ny * light[1] + light[2]) * inv
            spec = np.clip((nx * half[0] + ny * half[1] + half[2]) * inv, 0.0, 1.0) ** 60
            t = np.clip(0.55 + 1.6 * (diffuse - light[2]) + 0.9 * spec, 0.0, 1.0)
        elif self.style == "signed":
            # A square-root tone curve: the weak waves far from a source still show.
            z = np.clip(_image(f, self.size) / self.hi, -1.0, 1.0)
            t = 0.5 + 0.5 * np.sign(z) * np.sqrt(np.abs(z))
        else:
            t = np.clip((_image(f, self.size) - self.lo) / (self.hi - self.lo), 0.0, 1.0)
        t = np.nan_to_num(t, nan=0.0)
        levels = (_DITHERED_LEVELS if self.dither else _LEVELS)[self.style]
        x = t * (levels - 1)
        # Dithered: each pixel's shade rounded up or down by a threshold fixed to its place on
        # the screen (floor(x + θ), θ uniform over each 8 × 8 tile, is x on average), so a
        # smooth ramp between two shades reads as their mix, not as a step.
        x = np.floor(x + _threshold(x.shape)) if self.dither else np.round(x)
        out = (np.clip(x, 0, levels - 1) * ((_N - 1) / (levels - 1))).round().astype(np.uint8)
        if self.points is not None:
            # Tracers: one bright pixel each over the field (a cloud of them reads as streaks).
            p = self.points[k]
            w, h = self.size
            px = np.floor(p[:, 0] / self.extent[0] * w)
            py = np.floor((1.0 - p[:, 1] / self.extent[1]) * h)
            ok = np.isfinite(px) & np.isfinite(py) & (px >= 0) & (px < w) & (py >= 0) & (py < h)
            out[py[ok].astype(np.intp), px[ok].astype(np.intp)] = _N - 1
        if self.mask is not None:
            out[self.mask] = _OBSTACLE
        self._annotate(out, k)
        return out

    def _annotate(self, out: np.ndarray, k: int) -> None:
        """The time (bottom left) and, for the colour maps, a colour bar with the scale's ends and
        the quantity's name (top right); drawn in the map's own end colours, whichever contrasts
        with the background. Left out where the image is too small to read them."""
        from ._colorbar import _digit_rows, _draw_text, _format_value, _label_px, _text_mask

        h, w = out.shape
        if w < 100 or h < 80:
            return
        # Ink and a box behind it from the map's own colours: light on dark maps, dark on light.
        ink, box = {"water": (0, _N - 1), "signed": (0, _N // 2)}.get(self.style, (_N - 1, 0))
        # The particle animations' label font: larger on larger images (the bitmap one below).
        px = _label_px((w, h))
        cell = _text_mask("0", px).shape[0]

        def text(s: str, x: int, y: int) -> None:
            _draw_text(out, s, x, y, ink, box, px=px)

        if self.times is not None and np.isfinite(self.times[k]):
            text(f"t = {_format_value(float(self.times[k]))} {self.time_unit}".rstrip(), 4, h - 3 - cell)
        if self.colorbar and self.style != "water":
            # A bottom at round-off from 0 (a percentile of a field at rest) reads as 0.
            low = 0.0 if abs(self.lo) < 1e-9 * abs(self.hi) else self.lo
            lo, hi = (_format_value(low), _format_value(self.hi)) if self.style != "signed" else (f"-{_format_value(self.hi)}", _format_value(self.hi))
            hi = f"{hi} {self.label}".rstrip()
            length = max(24, w // 6)
            hi_w, lo_w = _text_mask(hi, px).shape[1], _text_mask(lo, px).shape[1]
            x_hi = w - 4 - hi_w
            x_strip = x_hi - 4 - length
            x_lo = x_strip - 4 - lo_w
            if x_lo < w // 3:
                return
            y = 2
            out[0 : y + cell, x_lo - 2 : x_hi + hi_w + 2] = box
            text(lo, x_lo, y)
            text(hi, x_hi, y)
            # The strip spans the digits' height: outline a row above and below them.
            d0, d1 = _digit_rows(px)
            top, bottom = y + d0 - 2, y + d1 + 1
            ramp = (np.arange(length) * (_N - 1) / (length - 1)).round().astype(np.uint8)
            out[top + 1 : bottom, x_strip : x_strip + length] = ramp[None, :]
            out[top, x_strip - 1 : x_strip + length + 1] = ink
            out[bottom, x_strip - 1 : x_strip + length + 1] = ink
            out[top : bottom + 1, x_strip - 1] = ink
            out[top : bottom + 1, x_strip + length] = ink


#: Field labels of dimensionless models (Gray–Scott's concentrations): the clock shows no unit.
_DIMENSIONLESS = ("u", "v")


def default_style(kind: str) -> str:
    return {"wave": "water", "gray_scott": "turing", "stable_fluid": "smoke"}.get(kind, "signed")


def default_field(kind: str) -> str:
    return {"wave": "u", "gray_scott": "v", "stable_fluid": "density"}.get(kind, "u")


def grid_plan(scene: Any) -> dict[str, Any] | None:
    """What to record of the scene's first grid (or the one its ``render_defaults`` names):
    {"grid", "field", "style"}; None for a scene without grids."""
    grids = getattr(scene, "grids", ())
    if not grids:
        return None
    d = getattr(scene, "render_defaults", None) or {}
    grid = next((g for g in grids if g.name == d.get("grid")), grids[0])
    style = d.get("style", default_style(grid.kind))
    if style not in STYLES:
        style = default_style(grid.kind)
    return {"grid": grid, "field": d.get("field", default_field(grid.kind)), "style": style}
