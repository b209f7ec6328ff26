"""The colour bar: a horizontal gradient strip with its range and unit, in the top-right corner.
The camera keeps a band at the top free of particles for it, so it never hides any, and since the
scale is fixed over the animation it is drawn once, into the background."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._palette import _BACKGROUND, _TEXT

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


def _draw_text(buf: np.ndarray, text: str, x: int, y: int, ink: int, box: int, below: int = 0) -> None:
    """`text` with its top-left corner at (x, y) in palette index `ink`, on a box of index `box`
    two pixels wider each side and one above (`below` rows more underneath): the clock, the
    title and the field labels all read on any background this way."""
    m = _text_mask(text)
    buf[max(y - 1, 0) : y + m.shape[0] + below, max(x - 2, 0) : x + m.shape[1] + 2] = box
    region = buf[y : y + m.shape[0], x : x + m.shape[1]]
    region[m[: region.shape[0], : region.shape[1]]] = ink


def _format_value(v: float) -> str:
    """Three significant digits; plain digits (no exponent) from 1000 up to 10^6."""
    return f"{v:.0f}" if 1000 <= v < 1e6 else f"{v:.3g}"


def _colorbar_labels(color_by: str, vmax: float, speed_unit: str = "m/s") -> tuple[str, str]:
    """Bottom and top labels of the colour bar; pressure in Pa, kPa, MPa or GPa, whichever reads
    as a number below 1000; speed in `speed_unit`."""
    if color_by == "strain":
        pct = _format_value(100.0 * vmax)
        return f"-{pct}%", f"+{pct}%"
    if color_by == "pressure":
        for factor, unit in ((1.0, "Pa"), (1e3, "kPa"), (1e6, "MPa"), (1e9, "GPa")):  # noqa: B007 - used after the loop
            if float(f"{vmax / factor:.3g}") < 1000:
                break
        return "0", f"{_format_value(vmax / factor)} {unit}"
    return "0", f"{_format_value(vmax)} {speed_unit}".rstrip()


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
