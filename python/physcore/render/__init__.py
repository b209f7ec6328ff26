"""Animated GIF rendering of physcore scenes, with numpy rasterisation and Pillow output.

The whole animation is simulated first and kept in memory (positions as float32), then a single
camera is fitted to every frame, and each frame is rasterised into a uint8 palette-index image:
static boundary (wall) particles in grey, springs as 1-pixel lines coloured by strain, particles
as filled discs coloured by speed or pressure, and a colour bar with the scale's range and unit.
The frames are written as a palette GIF with one fixed palette, atomically.

Public functions
----------------
============================== ======================================================================
record(scene, ...)             step a scene and return every frame's state (a Recording).
gif(recording, path, ...)      draw a Recording as an animated GIF (or a scene: record, then draw).
save(recording, path, ...)     the same in the format of path's extension: .gif, .mp4, .webm, .png
                               (or .glb, .gltf, .html: gltf() and html()).
gltf(recording, path, ...)     the motion in 3D as glTF 2.0 (.glb or .gltf): bodies, meshes, points.
html(recording, path, ...)     one self-contained page playing it in WebGL (three.js), orbit camera.
frames(recording, ...)         the same frames as an iterator of RGB arrays.
render_frame(positions, ...)   rasterise one state to an RGB array (for notebooks and tests).
contact_sheet(scenes, path)    several scenes animated side by side in one GIF.
============================== ======================================================================

Layout
------
A package of private modules, one idea each; a module imports only from those listed above it.
The public names are defined there and re-exported here (with ``__module__`` set to this
package, so that they read, pickle and document as ``physcore.render.NAME``).

=============== ====================================================================================
_rows           row-wise numpy helpers on (N, d) point arrays: finite rows, norms, finite mean.
_palette        the one fixed palette, and the colour maps onto it (speed, pressure, strain).
_camera         orthographic camera (projection, fit to every frame), ``DEFAULT_VIEW``.
_checks         argument checks of the public functions, ``COLOR_BY``.
_scene_state    reading a scene's optional parts: springs and strain, planes, pressures, walls.
_recording      ``Recording`` and ``record()``: stepping a scene into frames of data, ``MAX_STEPS``.
_colorbar       the colour bar: labels, layout and drawing into the background.
_mesh           ``Mesh`` (triangles over the particles) and its shading; the core rasterises it.
_look           ``Look`` (fading trails, line widths, lit spheres, a backdrop and props, swept
                areas): its checks and drawing helpers; ``swept_polygons``.
_raster         disc size, background, lines and discs; ``_Rasteriser`` (Recording -> index images,
                or RGB with a shaded mesh).
_gltf           ``gltf()``: a Recording as glTF 2.0 through pygltflib (bodies animated, meshes and
                points by morph targets), ``glb_bytes()``.
_html           ``html()``: the player page, three.js r111 vendored in ``_vendor/`` and ``_player.js``.
_gif            ``gif()``, ``save()``, ``frames()``: record a scene if given one, rasterise, write a
                palette GIF, an MP4/WebM video (PyAV) or PNGs atomically, or yield RGB frames;
                the notebook display (``Recording._repr_html_``: its GIF as a data URL).
_frame          ``render_frame()``: one state to an RGB array.
_sheet          ``contact_sheet()``: several scenes' GIFs tiled on one clock (sweep variants).
=============== ====================================================================================

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

# Names outside __all__ are re-exported with a redundant alias: DEFAULT_VIEW and MAX_STEPS are
# documented constants; the private ones, none of them API, are reached through this package by
# the CLI (_check_path, _check_writable), the tests (palette indices, _colorbar_labels) and
# benches/render/bench_render.py (_Rasteriser, _row_norms, _strain).
from ._camera import DEFAULT_VIEW as DEFAULT_VIEW
from ._checks import COLOR_BY
from ._checks import _check_path as _check_path
from ._checks import _check_writable as _check_writable
from ._colorbar import _colorbar_labels as _colorbar_labels
from ._frame import render_frame
from ._gif import FORMATS, frames, gif, recording_html, save
from ._gltf import gltf
from ._html import html
from ._look import Look, swept_polygons
from ._mesh import Mesh
from ._palette import _N_PRESSURE as _N_PRESSURE
from ._palette import _N_SPEED as _N_SPEED
from ._palette import _PALETTE as _PALETTE
from ._palette import _PRESSURE0 as _PRESSURE0
from ._palette import _SPEED0 as _SPEED0
from ._palette import _TEXT as _TEXT
from ._palette import _WALL as _WALL
from ._palette import CMAPS, GROUP_COLORS, STRAIN_SATURATION
from ._raster import _Rasteriser as _Rasteriser
from ._recording import MAX_STEPS as MAX_STEPS
from ._recording import Recording, record
from ._rows import _row_norms as _row_norms
from ._scene_state import _strain as _strain
from ._sheet import contact_sheet

# The notebook display lives with the GIF writer: _recording sits below _gif and cannot import it.
Recording._repr_html_ = recording_html  # type: ignore[attr-defined]

__all__ = ["record", "Recording", "Mesh", "Look", "gif", "save", "frames", "render_frame", "contact_sheet", "swept_polygons", "gltf", "html",
           "FORMATS", "COLOR_BY", "STRAIN_SATURATION", "CMAPS", "GROUP_COLORS"]

for _public in (Recording, Mesh, Look, record, gif, save, frames, render_frame, contact_sheet, swept_polygons, gltf, html):
    _public.__module__ = __name__
del _public
del annotations  # bound by `from __future__ import annotations`: not part of the API
