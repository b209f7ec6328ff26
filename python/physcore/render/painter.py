"""The painter's seam: the pieces of :mod:`physcore.render` that draw frames one at a time, under
public names, for what paints outside :func:`~physcore.render.gif` (the live viewer and the
notebook widget share them through ``physcore._live``; the CLI checks its options with them).

These are the very objects :func:`~physcore.render.gif` draws with, so a frame painted here is
the GIF's frame, bit for bit. They take and return what the renderer does internally: images are
``(H, W)`` uint8 palette indices (see :data:`~physcore.render.GROUP_COLORS` and the themes),
positions and pixel coordinates float64, and every ``check_*`` raises a
:class:`~physcore.PhyscoreError` (also ``ValueError`` or ``TypeError``) naming the argument.

Camera, scale and discs
    :class:`Rasteriser` (camera, disc size and colour scale fixed over an animation),
    :func:`extent_box`, :func:`points_view` (the camera that frames a set of points).
Overlays
    :func:`draw_title`, :func:`overlay`, :func:`paste`, :func:`draw_text`, :func:`text_mask`,
    :data:`CB_MARGIN` (the colour bar's margin, px).
Palette
    :data:`BACKGROUND`, :data:`TEXT` (palette indices), :data:`THEMES`.
Scene state as the renderer reads it
    :func:`scene_springs`, :func:`strain`, :func:`row_norms`, :func:`body_track`.
Stepping as the renderer steps
    :func:`simulate`, :func:`default_stepping`, :func:`scene_defaults`, :func:`steps_for`,
    :func:`wants_velocities`.
Option checks
    :func:`check_background`, :func:`check_camera`, :func:`check_cmap`, :func:`check_color_by`,
    :func:`check_colors`, :func:`check_fps`, :func:`check_halo`, :func:`check_look`, :func:`check_mesh`,
    :func:`check_path`, :func:`check_radius`, :func:`check_size`, :func:`check_texture`,
    :func:`check_view`, :func:`check_writable`.
"""
from __future__ import annotations

from ._bodies import body_track
from ._checks import _check_background as check_background
from ._checks import _check_camera as check_camera
from ._checks import _check_cmap as check_cmap
from ._checks import _check_color_by as check_color_by
from ._checks import _check_colors as check_colors
from ._checks import _check_fps as check_fps
from ._checks import _check_path as check_path
from ._checks import _check_radius as check_radius
from ._checks import _check_size as check_size
from ._checks import _check_view as check_view
from ._checks import _check_writable as check_writable
from ._checks import _extent_box as extent_box
from ._colorbar import _CB_MARGIN as CB_MARGIN
from ._colorbar import _draw_text as draw_text
from ._colorbar import _text_mask as text_mask
from ._gif import _check_halo as check_halo
from ._look import check_look
from ._mesh import check_mesh, check_texture
from ._palette import _BACKGROUND as BACKGROUND
from ._palette import _TEXT as TEXT
from ._palette import THEMES
from ._raster import _draw_title as draw_title
from ._raster import _overlay as overlay
from ._raster import _paste as paste
from ._raster import _Rasteriser as Rasteriser
from ._recording import _simulate as simulate
from ._recording import default_stepping, points_view, scene_defaults, steps_for, wants_velocities
from ._rows import _row_norms as row_norms
from ._scene_state import _scene_springs as scene_springs
from ._scene_state import _strain as strain

__all__ = [
    "BACKGROUND", "CB_MARGIN", "TEXT", "THEMES", "Rasteriser", "body_track", "check_background", "check_camera",
    "check_cmap", "check_color_by", "check_colors", "check_fps", "check_halo", "check_look", "check_mesh", "check_path",
    "check_radius", "check_size", "check_texture", "check_view", "check_writable", "default_stepping", "draw_text",
    "draw_title", "extent_box", "overlay", "paste", "points_view", "row_norms", "scene_defaults", "scene_springs", "simulate",
    "steps_for", "strain", "text_mask", "wants_velocities",
]
