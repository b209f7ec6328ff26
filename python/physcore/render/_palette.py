"""The one fixed palette of every image and GIF, and the colour maps from values to its indices:
speed (viridis-like), pressure (plasma-like) and spring strain (blue, grey, red)."""
from __future__ import annotations

import math

import numpy as np

#: Spring strain ``|(L - L0) / L0|`` at which the strain colours saturate (fully red or blue).
STRAIN_SATURATION = 0.1


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
_N_TRAIL = 8  # trail shades, oldest (palest) first
_TRAIL0 = _PRESSURE0 + _N_PRESSURE
_N_GLOW = 32  # color_by="density": brightness of the accumulated particle density, 0 = background (32: half the GIF bytes of 64, no visible banding under the blur)
_GLOW0 = _TRAIL0 + _N_TRAIL
_ARROW = _GLOW0 + _N_GLOW  # gif(arrows=...): velocity or acceleration arrows
_PALETTE_SIZE = _ARROW + 1

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
    pal[_PRESSURE0:_TRAIL0] = _sample_map(_PLASMA, 0.88, _N_PRESSURE)
    # Trails fade into the white background: from 10 % to 55 % of the way to a slate grey.
    slate = np.array([70.0, 80.0, 100.0])
    for k, a in enumerate(np.linspace(0.1, 0.55, _N_TRAIL)):
        pal[_TRAIL0 + k] = (1 - a) * np.array([255.0, 255.0, 255.0]) + a * slate
    # Density glow on paper: white through sky and ink blue to near black.
    pal[_GLOW0 : _GLOW0 + _N_GLOW] = _sample_map(np.array([[255.0, 255, 255], [150, 185, 235], [45, 80, 170], [20, 30, 80], [5, 8, 25]]), 1.0, _N_GLOW)
    pal[_ARROW] = (200, 0, 110)  # a deep magenta: apart from the speed, pressure and strain maps
    assert _WALL == _STRAIN0 + 2 * half + 1 and pal.shape[0] <= 256
    return np.round(pal).astype(np.uint8)


_PALETTE = _build_palette()

#: Themes: the same indices drawn in other colours (a palette swap, so the raster is the same).
THEMES = ("light", "dark")


def _build_dark_palette() -> np.ndarray:
    """The palette of ``theme="dark"``: a night-blue background, light text, the full viridis
    and plasma (their bright ends show on dark), trails fading from the background to pale
    blue, so orbits and attractors read like long exposures."""
    pal = _PALETTE.astype(np.float64)
    night = np.array([12.0, 14.0, 26.0])
    pal[_BACKGROUND] = night
    pal[_PLANE_FILL] = (40, 40, 52)
    pal[_PLANE_LINE] = (150, 150, 170)
    pal[_PLAIN] = (120, 190, 255)
    pal[_SPEED0:_STRAIN0] = _sample_map(_VIRIDIS, 1.0, _N_SPEED)
    pal[_PRESSURE0:_TRAIL0] = _sample_map(_PLASMA, 1.0, _N_PRESSURE)
    pal[_WALL] = (90, 90, 100)
    pal[_TEXT] = (225, 225, 235)
    pale = np.array([150.0, 185.0, 255.0])
    for k, a in enumerate(np.linspace(0.12, 0.6, _N_TRAIL)):
        pal[_TRAIL0 + k] = (1 - a) * night + a * pale
    # Density glow at night: from the sky through deep blue and cyan to white, like starlight.
    pal[_GLOW0 : _GLOW0 + _N_GLOW] = _sample_map(np.array([night, [40, 55, 140], [80, 140, 240], [170, 215, 255], [255, 255, 255]]), 1.0, _N_GLOW)
    pal[_ARROW] = (255, 110, 200)
    return np.round(pal).astype(np.uint8)


_DARK_PALETTE = _build_dark_palette()


def theme_palette(theme: str) -> np.ndarray:
    """(256 or fewer, 3) uint8 palette of `theme` (one of :data:`THEMES`)."""
    return _DARK_PALETTE if theme == "dark" else _PALETTE


# Perceptual colour maps (Smith & van der Walt's matplotlib maps, 2015; cividis: Nuñez, Anderton
# & Renslow 2018; turbo: Mikhailov 2019), sampled at 9 points in [0, 1] and interpolated linearly.
_CMAPS = {
    "viridis": _VIRIDIS,
    "plasma": _PLASMA,
    "magma": np.array([[0, 0, 4], [29, 17, 71], [81, 18, 124], [131, 38, 129], [183, 55, 121], [231, 82, 99],
                       [252, 137, 97], [254, 196, 136], [252, 253, 191]], dtype=np.float64),
    "inferno": np.array([[0, 0, 4], [33, 12, 74], [87, 16, 110], [138, 34, 106], [188, 55, 84], [228, 90, 49],
                         [249, 142, 9], [249, 203, 53], [252, 255, 164]], dtype=np.float64),
    "cividis": np.array([[0, 34, 78], [26, 56, 111], [67, 78, 108], [97, 101, 111], [125, 124, 120], [155, 148, 118],
                         [188, 174, 108], [222, 201, 88], [254, 232, 56]], dtype=np.float64),
    "turbo": np.array([[48, 18, 59], [70, 107, 227], [40, 188, 235], [50, 242, 152], [164, 252, 60], [238, 207, 58],
                       [251, 126, 33], [208, 47, 5], [122, 4, 3]], dtype=np.float64),
    # "ice": water from deep navy through blue to a light cyan (physcore's own ramp, monotone in
    # lightness), the fluid scenes' speed map. It ended in foam white, which vanished on a white
    # background: the fastest water, a dam break's spray, was the part not seen. It started at
    # near-black navy (CIELAB L* 8.6), which drew still water as ink; it now starts at L* 21, a
    # deep sea blue, and rises in even steps of L* (8 to 10) to the same light cyan.
    "ice": np.array([[18, 48, 108], [22, 66, 138], [26, 86, 166], [34, 108, 194], [50, 135, 210], [75, 165, 228],
                     [105, 192, 240], [140, 214, 247], [175, 232, 252]], dtype=np.float64),
}
#: Names of the colour maps ``gif(cmap=...)`` takes for speed and pressure.
CMAPS = tuple(_CMAPS)

#: Colours of ``gif(colors=...)`` given as group labels: matplotlib's "tab10", in its order.
GROUP_COLORS = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                         [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207]], dtype=np.uint8)


def styled_palette(theme: str, cmap: str | None = None, background: tuple[int, int, int] | None = None) -> np.ndarray:
    """The palette of `theme` with the speed and pressure maps replaced by `cmap` (one of
    :data:`CMAPS`; its bright end cut at 0.9 on the light theme, where near-white hardly shows)
    and the background by the RGB triple `background` (trails then fade into it)."""
    pal = theme_palette(theme).astype(np.float64)
    if cmap is not None:
        top = 1.0 if theme == "dark" else 0.9
        ramp = _sample_map(_CMAPS[cmap], top, _N_SPEED)
        pal[_SPEED0:_STRAIN0] = ramp
        pal[_PRESSURE0:_TRAIL0] = _sample_map(_CMAPS[cmap], top, _N_PRESSURE)
    if background is not None:
        bg = np.asarray(background, dtype=np.float64)
        old = pal[_BACKGROUND].copy()
        pal[_BACKGROUND] = bg
        # Trails keep their contrast: each shade is re-blended from the new background.
        ink = np.array([70.0, 80.0, 100.0]) if theme != "dark" else np.array([150.0, 185.0, 255.0])
        if bg.mean() < 128 and theme != "dark":
            ink = np.array([235.0, 240.0, 225.0])  # a dark background of a light theme (felt): pale trails
        for k, a in enumerate(np.linspace(0.12, 0.6, _N_TRAIL)):
            pal[_TRAIL0 + k] = (1 - a) * bg + a * ink
        if np.abs(old - bg).sum() > 0 and bg.mean() < 128 and theme != "dark":
            pal[_TEXT] = (235, 235, 235)  # labels stay legible on a dark background
    return np.round(pal).astype(np.uint8)


def _scalar_levels(values: np.ndarray, vmax: float, base: int, levels: int) -> np.ndarray:
    """(N,) values -> (N,) uint8 indices into the sequential map of `levels` entries at `base`.

    0 (and anything below, and NaN) maps to the bottom, `vmax` and above to the top.
    """
    if not (vmax > 0 and math.isfinite(vmax)):
        return np.full(values.shape, base, dtype=np.uint8)
    with np.errstate(over="ignore", invalid="ignore"):  # a subnormal vmax: overflow to inf, the top
        lv = np.nan_to_num(values * (levels / vmax), nan=0.0, posinf=levels, neginf=0.0)
    return (base + np.clip(lv, 0, levels - 1).astype(np.uint8)).astype(np.uint8)


def _strain_levels(strain: np.ndarray, saturation: float = STRAIN_SATURATION) -> np.ndarray:
    """(M,) strains -> (M,) uint8 palette indices, fully blue or red at ±`saturation`; NaN (zero
    rest length) -> at-rest grey."""
    half = _N_STRAIN // 2
    # Clipped before dividing, so that a strain near the float32 limit cannot overflow.
    s = np.clip(np.nan_to_num(strain, nan=0.0), -saturation, saturation) / saturation
    return (_STRAIN0 + half + np.rint(s * half)).astype(np.uint8)
