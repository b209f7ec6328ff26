"""The colour bar: a horizontal gradient strip with its range and unit, in the top-right corner.
The camera keeps a band at the top free of particles for it, so it never hides any, and since the
scale is fixed over the animation it is drawn once, into the background."""
from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

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
    px: int | None = None  # the labels' font size (None: the bitmap font), see _text_mask


def _font():
    from PIL import ImageFont

    # The classic bitmap font (about 6x11 pixels a character): crisp in a palette image.
    load = getattr(ImageFont, "load_default_imagefont", None)  # Pillow >= 10.1
    return load() if load is not None else ImageFont.load_default()


#: Label font size (px) at 480x360 (:func:`_label_px`); smaller ones than _MIN_LABEL_PX use the
#: bitmap font, whose digits are about as tall.
_LABEL_PX = 13
_MIN_LABEL_PX = 11


@functools.cache
def _freetype(px: int) -> Any:
    """Pillow's default FreeType font at `px` pixels, or None without FreeType (Pillow built
    without it, or older than 10.1: ``load_default`` takes no size)."""
    from PIL import ImageFont, features

    try:
        if not features.check_module("freetype2"):
            return None
        font = ImageFont.load_default(size=px)
    except (TypeError, OSError, ImportError, ValueError):
        return None
    return font if isinstance(font, ImageFont.FreeTypeFont) else None


def _label_px(size: tuple[int, int]) -> int | None:
    """Font size of the labels (colour bar, clock, title, scale bar) in an image of `size`
    (width, height): 13 px at 480x360, growing as the square root of the shorter side (15 at
    640x480, 23 at 1920x1080); None, the bitmap font, where that is below 11 px (a shorter side
    under about 235 px) or FreeType is missing."""
    px = int(round(_LABEL_PX * math.sqrt(min(size) / 360.0)))
    return px if px >= _MIN_LABEL_PX and _freetype(px) is not None else None


@functools.lru_cache(maxsize=1024)
def _text_mask(text: str, px: int | None = None) -> np.ndarray:
    """(rows, width) bool pixels of `text`, read-only (cached per string and size): the bitmap
    font's 11-row cell (`px` None), or Pillow's default FreeType font at `px` pixels rendered
    without antialiasing (hinted monochrome glyphs: crisp in a palette image) on a line cell
    cut like the bitmap one, digits starting on row 2 (see :func:`_digit_rows`). Every string
    of one font has the same number of rows. The FreeType font has ASCII and a few more (°,
    ±): other letters lose their accents (É as E), and what is left shows as "?"; nothing
    raises."""
    from PIL import Image, ImageDraw

    font = _font() if px is None else _freetype(px)
    if font is None:
        return _text_mask(text, None)
    if px is None:
        x0, y0, x1, y1 = font.getbbox(text)
        im = Image.new("L", (max(int(x1), 1), max(int(y1), 1)), 0)
        ImageDraw.Draw(im).text((0, 0), text, fill=255, font=font)
        mask = np.asarray(im) > 127
    else:
        text = _folded(text, px)
        x0, y0, x1, y1 = font.getbbox(text)
        ascent, descent = font.getmetrics()
        top = max(int(font.getbbox("0")[1]) - 2, 0)  # two blank rows above the digits
        left = max(-int(x0), 0)  # a glyph hanging left of the origin (a "t" at some sizes)
        # Hinted monochrome glyphs can be wider than the bounding box Pillow reports: drawn on
        # a wider canvas, then cut after the last inked column.
        im = Image.new("L", (int(x1) + left + 2 * px + 2 * len(text), ascent + descent - top), 0)
        draw = ImageDraw.Draw(im)
        draw.fontmode = "1"  # no antialiasing
        draw.text((left, -top), text, fill=255, font=font)
        mask = np.asarray(im) > 127
        cols = np.nonzero(mask.any(axis=0))[0]
        mask = mask[:, : cols[-1] + 1 if cols.size else 1]
    mask.flags.writeable = False
    return mask


@functools.cache
def _glyphs(px: int) -> frozenset:
    """The characters up to U+00FF that the FreeType font of `px` pixels draws (not as its box
    glyph, the one of U+FFFF)."""
    from PIL import Image, ImageDraw

    font = _freetype(px)

    def ink(c: str) -> bytes:
        im = Image.new("1", (3 * px, 2 * px), 0)
        ImageDraw.Draw(im).text((px // 2, 0), c, fill=1, font=font)
        return im.tobytes()

    box = ink("\uffff")
    return frozenset(c for c in map(chr, range(32, 256)) if c.isprintable() and (c == " " or ink(c) != box))


_FOLD = {"ß": "ss", "æ": "ae", "Æ": "AE", "ø": "o", "Ø": "O", "œ": "oe", "Œ": "OE", "ð": "d", "Ð": "D", "þ": "th", "Þ": "Th"}


def _folded(text: str, px: int) -> str:
    """`text` in the characters the FreeType font of `px` pixels has: accents dropped
    (Unicode's compatibility decomposition), a few letters spelt out (ß as ss), anything else
    as "?"."""
    import unicodedata

    have = _glyphs(px)
    if all(c in have for c in text):
        return text
    out = []
    for c in text:
        if c in have:
            out.append(c)
            continue
        base = _FOLD.get(c) or "".join(b for b in unicodedata.normalize("NFKD", c) if not unicodedata.combining(b))
        out.append(base if base and all(b in have for b in base) else "?")
    return "".join(out)


@functools.cache
def _digit_rows(px: int | None = None) -> tuple[int, int]:
    """First and last row of a digit's ink in :func:`_text_mask` cells of font `px` (the
    bitmap font: rows 2 to 8)."""
    rows = np.nonzero(_text_mask("0", px).any(axis=1))[0]
    return int(rows[0]), int(rows[-1])


def _draw_text(buf: np.ndarray, text: str, x: int, y: int, ink: int, box: int, below: int = 0,
               px: int | None = None) -> None:
    """`text` (font `px`, see :func:`_text_mask`) with its top-left corner at (x, y) in palette
    index `ink`, on a box of index `box` two pixels wider each side and one above (`below` rows
    more underneath): the clock, the title and the field labels all read on any background
    this way."""
    m = _text_mask(text, px)
    buf[max(y - 1, 0) : y + m.shape[0] + below, max(x - 2, 0) : x + m.shape[1] + 2] = box
    region = buf[y : y + m.shape[0], x : x + m.shape[1]]
    region[m[: region.shape[0], : region.shape[1]]] = ink


def _format_value(v: float) -> str:
    """Three significant digits; plain digits (no exponent) from 1000 up to 10^6 (also for a value
    that rounds to 1000, such as a clock at 999.9999 after automatic substeps)."""
    return f"{v:.0f}" if 1000 <= float(f"{v:.3g}") < 1e6 else f"{v:.3g}"


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
    px = _label_px(size)
    lo_mask, hi_mask = _text_mask(lo, px), _text_mask(hi, px)
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
    return _ColorBarLayout(lo, hi, lo_x, strip_x, length, hi_x, text_y, band, px)


def _draw_colorbar(buf: np.ndarray, bar: _ColorBarLayout, base: int, levels: int) -> None:
    """Draw the colour bar of the `levels`-entry map at palette index `base` into buf (H, W)."""
    # Clear its box (a collider's shading may reach the top of the image).
    buf[: bar.band, max(bar.lo_x - 2, 0) :] = _BACKGROUND
    for text, x in ((bar.lo, bar.lo_x), (bar.hi, bar.hi_x)):
        mask = _text_mask(text, bar.px)
        region = buf[bar.text_y : bar.text_y + mask.shape[0], x : x + mask.shape[1]]
        region[mask[: region.shape[0], : region.shape[1]]] = _TEXT
    # Strip over the digits' rows (2..8 of the bitmap font's cell), outlined.
    d0, d1 = _digit_rows(bar.px)
    top, bottom = bar.text_y + d0 - 1, bar.text_y + d1 + 1  # outline rows
    x0, x1 = bar.strip_x - 1, bar.strip_x + bar.length  # outline columns
    buf[top : bottom + 1, x0 : x1 + 1] = _TEXT
    c = np.arange(bar.length)
    ramp = (base + np.minimum((c + 0.5) * levels / bar.length, levels - 1).astype(np.int64)).astype(np.uint8)
    buf[top + 1 : bottom, bar.strip_x : bar.strip_x + bar.length] = ramp[None, :]
