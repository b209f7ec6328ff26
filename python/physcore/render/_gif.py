"""Animated GIF output: :func:`gif` draws a Recording (or records a scene first) and writes every
frame with the one fixed palette, atomically."""
from __future__ import annotations

import os
import tempfile
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from .. import _check
from .._atomic import TEMP_PREFIX, TEMP_SUFFIX, atomic_write, ctrl_c_held
from .._errors import InvalidInputError, InvalidTypeError, refusing_memory
from . import _recording, _threads
from ._checks import (
    _check_arrows,
    _check_background,
    _check_camera,
    _check_cmap,
    _check_color_by,
    _check_colors,
    _check_fps,
    _check_int,
    _check_memory,
    _check_path,
    _check_png_targets,
    _check_radius,
    _check_size,
    _check_view,
    _check_writable,
    _extent_box,
    _short,
)
from ._look import check_look, check_look_particles
from ._mesh import check_mesh, check_texture
from ._palette import _PALETTE, THEMES
from ._raster import _Rasteriser

#: The core's calls a render makes (stepping the scene, reading it, drawing its frames), whose
#: memory refusals are named as the call the user made (``gif``, ``save``).
_DRAWING = ("step", "advance", "positions", "velocities", "splat", "blur", "sphere_depths", "rasterise")


@refusing_memory("gif", "the frames", rename=_DRAWING)
def gif(
    scene: Any,
    path: str | os.PathLike,
    *,
    frames: int | None = None,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int | None = None,
    fps: float | None = None,
    size: tuple[int, int] | None = None,
    color_by: str | None = None,
    colorbar: bool = True,
    radius: int | None = None,
    springs: bool = True,
    view: tuple[float, float] | None = None,
    progress: bool = False,
    trail: int | None = None,
    size_by: str | None = None,
    theme: str | None = None,
    title: str | None = None,
    camera: str | tuple | None = None,
    arrows: str | None = None,
    mesh: Any = None,
    texture: Any = None,
    antialias: bool | None = None,
    colors: Any = None,
    cmap: str | None = None,
    background: Any = None,
    surface: bool | None = None,
    extent: Any = None,
    halo: Any = None,
    loop: bool | None = None,
    look: Any = None,
    dither: bool | None = None,
) -> Path:
    """Draw a :class:`Recording` as an animated GIF, or simulate `scene` forward and draw it:
    ``gif(scene, path, ...)`` is ``gif(record(scene, ...), path, ...)``.

    Frame 0 shows the current state; between consecutive frames the scene advances either
    ``steps_per_frame`` steps of ``scene.dt``, so the animation covers
    ``(frames - 1) * steps_per_frame * scene.dt`` seconds of simulated time, or, with
    `frame_time`, ``frame_time`` seconds with substeps the scene picks itself, covering
    ``(frames - 1) * frame_time`` seconds. Given neither, it advances as ``physcore render``
    does (see :func:`record`): a ready-made scene by its ``render_defaults``, any other scene by
    1/30 s of simulated time per frame, so it plays in real time. `frames`, `fps`, `size` and
    `color_by` default to the scene's ``render_defaults`` too (else 90, 30, (480, 360), "speed"). The scene is left at the last frame's state. The whole
    run is simulated before anything is drawn, and a single camera is fitted to all frames (and to
    the scene's boundary particles), so the view does not move (``camera="fit"``; ``"follow"``
    and ``"orbit"`` move it, see `camera`).

    Parameters
    ----------
    scene : physcore.Scene or Recording
        A recording from :func:`record` (then `frames`, `steps_per_frame`, `frame_time` and
        `substeps` must be left out: it is already simulated, and `color_by` needs what it
        recorded), or a 2D or 3D scene, stepped in place (to the end of the recording; Ctrl-C
        leaves it at the last step completed, its time and step count consistent, and writes
        no file). Optional methods, used when present:
        ``pressure()`` -> (N,) float64 Pa (needed for ``color_by="pressure"``),
        ``boundary_points()`` -> (B, dim) float64 m, static wall particles (B may be 0), and
        ``advance(duration)`` -> int substeps taken (needed for `frame_time`).
    path : str or os.PathLike
        Output file; must end in ``.gif`` and its directory must exist and be writable (checked
        by creating and removing a file there before simulating). Written atomically: a
        temporary file in the same directory is renamed onto `path` only once complete.
    frames : int, optional
        Number of frames, >= 1 (scenes only). Together with `size` and the scene's particles it must fit in
        memory: the estimate ``frames · (4 N (dim + 2) + 4 M + 2 W H)`` bytes (N particles,
        M springs, W × H pixels) is refused above :func:`physcore._check.memory_limit` (half
        the physical memory) before anything is simulated.
    steps_per_frame : int, optional
        Simulation steps of ``scene.dt`` between frames, 1 to :data:`MAX_STEPS` (2**53); giving
        it and `frame_time` is an error. Given neither, see above.
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
    fps : float, optional
        Playback rate, > 0 (a GIF's at least 100/65535 ≈ 0.0015: a frame lasts at most
        655.35 s; a video's 1/1001 to 2**31 − 1). GIF stores delays in whole centiseconds, so the delays alternate
        (30 fps: 30, 30, 40 ms, …) to keep the playing time exact: frame k starts at
        ``round(k · 100 / fps)`` cs. Most viewers play delays below 20 ms at 100 ms, so each is
        at least 20 ms (fps above 50 play at 50).
    size : (int, int), optional
        Image width and height in pixels, each >= 16.
    color_by : {"speed", "pressure", "strain", "density", "none"}, optional
        Particle colouring. ``"strain"``: plain discs under the springs, which are drawn on top
        in a blue (compressed), grey, red (stretched) map whose ends are ± the run's 99th
        percentile of ``|strain|`` (the colour bar gives it in %), so small strains show; the scene
        needs springs. Otherwise springs are drawn under the discs and saturate at
        ``STRAIN_SATURATION``. ``"speed"``: a viridis-like map of ``|v|`` (m/s). ``"pressure"``: a
        plasma-like map of ``scene.pressure()`` (Pa; 0 for particles that are not fluid,
        negative values get the bottom colour). Both scales run from 0 at the bottom to a top
        fixed over the whole animation at the 99th percentile of all frames' values.
        ``"density"``: glow, for large clouds (galaxies, attractors, fluids as a continuous
        surface): each free particle is splatted bilinearly into a per-pixel density (so edges
        are antialiased and sub-pixel motion shows), blurred twice (a tight core of σ ≈ radius/2
        and a 4× wider bloom at half weight, each three box blurs) and tone-mapped as
        1 − exp(−2.5 (d / d99.5)^0.75) onto a 32-level ramp from the background to white (dark theme) or near
        black (light), with d99.5 the 99.5th percentile of three frames' density, fixed over
        the animation; additive, so 3D needs no depth order. Pinned particles stay discs.
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
    trail : int, optional
        Draw each moving particle's path over the previous `trail` frames behind it, fading with
        age (orbits, parabolas, figure-eights). 0: none. Default: the scene's ``render_defaults``
        (Kepler: one orbit; projectiles: the whole flight), else 0.
    size_by : {"none", "mass", "radius"}, optional
        ``"mass"``: each disc's radius grows as ∛(m / m_min), up to 3× the default radius (a
        star beside its planet). ``"radius"``: each disc at the true size of the scene's
        ``"radius"`` attribute (grains under :class:`~physcore.Contacts`). Default: the scene's
        ``render_defaults`` (Kepler: "mass", the grain scenes: "radius"), else ``"none"`` (one
        size).

    theme : {"light", "dark"}, optional
        Colours of particle animations: ``"light"`` (white background) or ``"dark"`` (night
        blue, light text, trails like long exposures). Field animations keep their own maps.
        Default: the scene's ``render_defaults`` (galaxies, attractors: "dark"), else "light".
    title : str, optional
        A caption in the top-left corner of particle animations (one line, up to 200
        characters; cut with "..." where it would run into the colour bar; Latin-1 only, other
        characters show as "?", and the font of images 235 pixels and more on their shorter side
        shows accented letters without their accents). Default: the scene's
        ``render_defaults``, else none.
    camera : str or tuple, optional
        How the view moves. ``"fit"``: one camera fitted to every frame, still. ``"follow"``:
        the view's centre tracks the centre of mass of the moving (non-pinned) particles, or
        with ``("follow", i)`` particle ``i``, along that target's projected path smoothed by
        a Gaussian of σ = ``FOLLOW_SMOOTHING`` (0.1) s of playback: centred, so there is no lag
        on straight or steady motion, and each frame's step is a weighted mean of the target's
        steps, so the view never jumps further in a frame than the target does (a jump of the
        target is spread over about half a second). The scale is fixed, zoomed in on the
        fitted view (up to ``FOLLOW_MAX_ZOOM``, 4×) until the moving particles' spread around
        the target fits (95 % of them above 20 particles); colliders and boundary particles
        pass by behind, the labels stay put over everything. ``"zoom"`` (or ``("zoom", i)``)
        follows as ``"follow"`` does at a scale of each frame's own: the largest at which that
        frame's spread fits (within ``FOLLOW_MAX_ZOOM`` of the fitted view), never larger than
        an earlier frame's, eased by a Gaussian of ``ZOOM_EASE`` (0.5) s of playback and taken
        that far ahead that the view widens before the motion needs it; the last frame is
        ``"follow"``'s. The scale bar is drawn at each frame's scale, and a glow
        (``color_by="density"``) keeps its brightness per area. ``"orbit"`` (3D only): the
        azimuth turns by 360°/`frames` a frame from ``view``'s (one full turn over the
        animation, looping), or with ``("orbit", degrees_per_second)`` at that rate of
        playback, about the vertical axis through the middle of the scene, at one scale that
        holds every point at every azimuth. Default: the scene's ``render_defaults``, else
        ``"fit"``.
    arrows : {"none", "velocity", "acceleration"}, optional
        Draw arrows on the moving particles (every one up to 64; else a fixed subset of at
        most ``MAX_ARROWS``, 300, one per square of an arrow's length of the image, so they
        seldom overlap): their velocity, or their acceleration (the net force per unit mass), which is the central difference of the recorded velocities,
        (v[k+1] − v[k−1]) / (t[k+1] − t[k−1]), one-sided at the first and last frame. Arrows
        show the projection onto the image, in one colour, with lengths proportional to the
        magnitude, fixed over the animation: the run's 95th percentile is 1/12 of the image's
        shorter side (longer ones stop at three times that; under 2 pixels none is drawn).
        The recording needs velocities (``record(..., velocities=True)``); a scene records
        them. Default: the scene's ``render_defaults``, else none.
    mesh : physcore.render.Mesh, (T, 3) int array, or False, optional
        Draw these triangles over the particles as a shaded surface: per-vertex normals,
        Lambert diffuse plus a Blinn–Phong highlight from a light at the viewer's upper left,
        interpolated over each triangle (Gouraud shading), the back side in a second colour,
        nearer surfaces in front (a depth buffer), edges antialiased with 2×2 samples per
        pixel. Springs between mesh particles are not drawn; pinned particles stay discs on
        top. ``color_by`` "speed", "pressure" or "strain" (each vertex the mean strain of its
        springs) colours the surface; "none" gives a plain fabric colour. Default: the scene's
        ``render_defaults`` (``scenes.cloth`` has its grid, :meth:`Mesh.grid`); False: none.
        Not with ``color_by="density"``. Frames with a mesh are drawn in full colour; a GIF then
        gets one adaptive 256-colour palette for the whole animation.
    texture : str, os.PathLike or (H, W, 3) uint8 array, optional
        An image mapped onto the mesh by its texture coordinates (``Mesh.uv``; a grid mesh has
        them), shaded like the plain surface. Needs a mesh with uv. Default: the scene's
        ``render_defaults`` (the cloths' gingham), unless `mesh` is given or `color_by` (other
        than "none") or `colors` colours the surface. False: none (the plain fabric).
    antialias : bool, optional
        Draw the discs with soft edges: each pixel blended by the fraction of it the disc
        covers (the discs in full colour; a GIF then gets one adaptive 256-colour palette).
        Default: the scene's ``render_defaults`` (the ready-made particle scenes have it on),
        else False: hard-edged discs in the fixed palette, the smallest GIFs. Glow and shaded
        surfaces are antialiased whatever this says.
    colors : array_like, optional
        Each particle's own colour, for bodies meant to read as objects (billiard balls, two
        galaxies, a star and its planet): an (N, 3) array of RGB, uint8 0–255 or floats in
        [0, 1], or "#rrggbb" strings (N,), or (N,) integer group labels, drawn in matplotlib's
        "tab10" colours (:data:`physcore.render.GROUP_COLORS`, cycling). Used with
        ``color_by="none"`` (discs in these colours, soft-edged, pinned ones too) and
        ``"density"`` (each particle glows in its colour; where colours mix, the glow takes their
        density-weighted mean, whitening towards the densest cores); the other colourings show
        their quantity and ignore it. Default: the scene's ``render_defaults``, else none.
    cmap : str, optional
        The colour map of ``color_by`` "speed" and "pressure": one of
        :data:`physcore.render.CMAPS` ("viridis", "plasma", "magma", "inferno", "cividis",
        "turbo", and "ice", water from deep navy to a light cyan). Default: the scene's ``render_defaults``, else viridis for speed and plasma
        for pressure.
    background : (int, int, int), optional
        The background's RGB colour, 0–255 each (a billiard table's felt); trails fade into it,
        and labels turn light on a dark one. Default: the scene's ``render_defaults``, else the
        theme's.
    surface : bool, optional
        Draw the moving particles as one continuous surface, for liquids: each particle's count
        and value (``color_by`` "speed" or "pressure", else one colour) splatted per pixel and
        blurred with σ ≈ 0.7 particle spacings (the spacing read off the first frame), inside
        where the density passes 45 % of a filled interior's, with a soft edge and a light on
        the surface's upper-left rim; each pixel takes the density-weighted mean value. Spray
        (particles with fewer than three others within two spacings) is drawn under it as a
        soft mist, blurred three times wider, where two or more overlap (a lone particle is
        left out), so a splash reads as a plume rather than specks. Walls
        and colliders are drawn as usual. In 3D the surface is lit instead (screen-space
        fluid rendering, van der Laan, Green & Sainz, I3D 2009): each particle a sphere of 0.9
        spacings (the spacing in space, read off the first frame) in a depth buffer, the nearest
        depth smoothed over 0.7 spacings and shaded by its normal (a key light from the upper
        left front, a highlight, a rim), coloured by the nearest particles' values; boundary
        particles (a tank) are drawn as glass, a faint tint darker along the edges, instead of
        discs. Not with a mesh or ``color_by`` "density"/"strain"
        (then ignored). Default: the scene's ``render_defaults`` (the fluid scenes have it on),
        else False.
    extent : (array_like (dim,), array_like (dim,)), optional
        (lower, upper) corners of the box, m, the still camera is fitted to instead of every
        frame's particles: what lies outside is not drawn (a queue of balls above a Galton
        board enters the picture one by one). Default: the scene's ``render_defaults``, else
        the fit to everything.
    halo : array_like of bool (N,) or of int, optional
        Particles drawn with a soft halo of their own colour around the disc (a star): a mask,
        or particle indices (``[]``: none). Drawn with soft discs only (``antialias=False``
        leaves it out); in a glow in own colours (``color_by="density"`` with ``colors``) as
        a bright core, 2.5 % of the first frame's side across (σ), whitened (the galaxies'
        central masses). Default: the scene's ``render_defaults`` (Kepler's star, the
        galaxies' centres), else none.
    loop : bool, optional
        The animation is periodic (the frame after the last would be the first: an orbit, a
        choreography), so each trail at the start runs on from the end and the GIF loops
        without a seam (with the still camera). Default: the scene's ``render_defaults``
        (Kepler, the figure-eight) where the frames close the period (the step from the last
        frame back to the first at most 1.5 times the largest between frames: other frames or
        frame times than the scene's own turn it off), else False.
    look : physcore.render.Look or dict, optional
        How the particles' frames look beyond their colouring (:class:`Look`): trails that
        fade with age (``trail_fade``) and their width, springs drawn as strokes of a width,
        discs lit as spheres, a gradient backdrop and static props, and the areas a radius
        vector sweeps in equal times (Kepler's second law). A dict changes only the fields it
        names over the scene's ``render_defaults["look"]``; each field's default leaves the
        picture as it was. Any of them but the trail's draws the frames in full colour with
        soft discs (unless ``antialias=False`` is given, which leaves them out). With a mesh or
        a liquid surface only the backdrop and props are drawn (behind it); with glow, none.
    dither : bool, optional
        Field animations: round each pixel to the map's shades with Bayer's 8 × 8 ordered dither
        instead of to the nearest shade, so a slow gradient (a dye's soft edge) reads as a smooth
        mix of neighbouring shades instead of flat bands. The thresholds are fixed to the pixels'
        places, so the frames are the same for the same recording and still regions stay still
        (the GIF stores only what changes). Full-colour particle frames (a ``look``'s, soft
        discs) are put on the GIF's 255 colours by the same thresholds, each pixel one of the
        two colours its own lies between (:func:`_ordered_indices`), their flat colours exact:
        a glow reads smooth, not as rings (Kepler's GIF: 284 → 362 kB, its render about 1.7×
        as long). Other particle frames ignore it. Default: the scene's ``render_defaults``
        (``scenes.cavity`` and ``scenes.kepler`` have it on), else False.

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
        whose ``pressure()`` raises AttributeError), `frame_time` on a scene without
        ``advance``, ``camera="orbit"`` on a 2D scene, a followed particle index out of range,
        `arrows` on a recording without velocities and ``arrows="acceleration"`` with one frame.
    physcore.SimulationDiverged
        If the simulation diverges; no file is written (the scene is rolled back to the last
        good state of the failing ``step``/``advance`` call by the scene itself).
    OSError
        If the file cannot be written: an unwritable directory is found before simulating; a
        failure while writing leaves no partial file behind.
    physcore.OutOfMemoryError
        (a ``MemoryError``) Memory refused while simulating or drawing, naming ``gif``; no file
        is written and a scene is put back as it was before the call (its state is kept for
        that, so one that cannot be had is refused before anything is simulated).

    Notes
    -----
    Collider planes are drawn in 2D (shaded solid side and an edge line), not in 3D. Boundary
    particles are drawn once, in grey, under everything that moves; in 3D they are projected the
    same way but not depth-sorted against the moving particles (always underneath). Pillow
    merges consecutive identical frames into one longer frame, so a GIF of a scene at rest can
    report fewer frames than `frames` while playing for the same time.
    """
    return _render(scene, path, "gif", frames=frames, steps_per_frame=steps_per_frame, frame_time=frame_time,
                   substeps=substeps, fps=fps, size=size, color_by=color_by, colorbar=colorbar, radius=radius,
                   springs=springs, view=view, progress=progress, trail=trail, size_by=size_by, theme=theme,
                   title=title, camera=camera, arrows=arrows, mesh=mesh, texture=texture, antialias=antialias,
                   colors=colors, cmap=cmap, background=background, surface=surface, extent=extent,
                   halo=halo, loop=loop, look=look, dither=dither)


#: gif()'s keyword options, in its signature's order (what save(), frames() and _render take).
_OPTIONS = ("frames", "steps_per_frame", "frame_time", "substeps", "fps", "size", "color_by", "colorbar", "radius",
            "springs", "view", "progress", "trail", "size_by", "theme", "title", "camera", "arrows", "mesh", "texture",
            "antialias", "colors", "cmap", "background", "surface", "extent", "halo", "loop", "look", "dither")


def _render(scene: Any, path: Path | str | os.PathLike | None, fmt: str, **options: Any) -> Any:
    """gif()'s body for every output format (see _emit). `options`: gif()'s keyword arguments,
    checked against its signature (an unknown one is a TypeError naming it), defaults applied."""
    import inspect

    bound = inspect.signature(gif).bind(scene, path, **options)
    bound.apply_defaults()
    (frames, steps_per_frame, frame_time, substeps, fps, size, color_by, colorbar, radius, springs, view, progress,
     trail, size_by, theme, title, camera, arrows, mesh, texture, antialias, colors, cmap, background, surface, extent, halo, loop,
     look, dither) = (
        bound.arguments[k] for k in _OPTIONS)
    # Defaults: the scene's render_defaults (the ready-made scenes', as `physcore render` uses
    # them), else 30 fps, 480x360, speed.
    if isinstance(scene, _recording.Recording):
        # A recording draws as its scene would: the scene's defaults and the colouring recorded.
        d = dict(scene.defaults or {})
        if scene.color_by is not None:
            d["color_by"] = scene.color_by
    else:
        d = _recording.scene_defaults(scene)
    fps = _check_fps(d.get("fps", 30.0) if fps is None else fps)
    if fmt in ("mp4", "webm"):
        _check_video_rate(fps)
    elif fmt == "gif" and fps < 100 / 65535:
        # A GIF frame lasts at most 65535 cs: a slower rate cannot be written (it was clamped).
        raise InvalidInputError(f"fps must be at least 100/65535 = 0.00153 for a GIF (a frame lasts at most 655.35 s), got {fps:g}")
    size = _check_size(tuple(d.get("size", (480, 360))) if size is None else size)
    color_by = _check_color_by(d.get("color_by", "speed") if color_by is None else color_by)
    trail = _check_int("trail", d.get("trail", 0) if trail is None else trail, 0, 2**31)
    size_by = d.get("size_by", "none") if size_by is None else size_by
    size_by = _check.choice("size_by", size_by, ("none", "mass", "radius"))
    title = d.get("title") if title is None else title
    if title is not None and not isinstance(title, str):
        raise InvalidTypeError(f"title must be a str, got {type(title).__name__}")
    if title is not None and ("\n" in title or len(title) > 200):
        raise InvalidInputError(f"title must be one line of at most 200 characters, got {_short(title)}")
    if title is not None:
        _check.text("title", title)
    theme = d.get("theme", "light") if theme is None else theme
    theme = _check.choice("theme", theme, THEMES)
    radius = _check_radius(d.get("radius") if radius is None else radius)
    view_given = view is not None
    view = _check_view(d.get("view") if view is None else view)
    colorbar = _check.flag("colorbar", colorbar)
    springs = _check.flag("springs", springs)
    progress = _check.flag("progress", progress)
    arrows_given = arrows is not None
    arrows = _check_arrows(d.get("arrows") if arrows is None else arrows)
    camera = d.get("camera", "fit") if camera is None else camera
    mesh_given = mesh is not None
    mesh = d.get("mesh") if mesh is None else mesh
    if color_by == "density" and mesh is not None and mesh is not False:
        if mesh_given:
            raise InvalidInputError("mesh: color_by='density' (glow) draws no surface; give another color_by or mesh=False")
        mesh = None  # the scene's default surface gives way to a requested glow
    n_points = (scene.positions.shape[1] if isinstance(scene, _recording.Recording)
                else int(getattr(_recording.points_view(scene), "n_particles", 0)))
    mesh = check_mesh(mesh, n_points)
    if texture is None and not mesh_given and mesh is not None and mesh.uv is not None and color_by == "none" and colors is None:
        texture = d.get("texture")  # a scene's default fabric gives way to a mesh or colouring asked for
    if texture is False:
        texture = None  # the plain fabric
    texture = check_texture(texture, mesh)
    antialias = _check.flag("antialias", bool(d.get("antialias", False)) if antialias is None else antialias)
    cmap = _check_cmap(d.get("cmap") if cmap is None else cmap)
    surface = _check.flag("surface", bool(d.get("surface", False)) if surface is None else surface)
    dither = _check.flag("dither", d.get("dither", False) if dither is None else dither)
    background = _check_background(d.get("background") if background is None else background)
    # One colour per drawn point: a recording's, or the scene's particles (a flow's points).
    n_colors = (scene.positions.shape[1] if isinstance(scene, _recording.Recording)
                else int(getattr(_recording.points_view(scene), "n_particles", 0)))
    colors = _check_colors(d.get("colors") if colors is None else colors, n_colors)
    dim = scene.positions.shape[2] if isinstance(scene, _recording.Recording) else int(getattr(_recording.points_view(scene), "dim", 0))
    if view_given and dim == 2:
        raise InvalidInputError("view: a 2D scene is drawn in its plane; view=(azimuth, elevation) turns 3D scenes only")
    box = _extent_box(d.get("extent") if extent is None else extent, dim)
    halo = _check_halo(d.get("halo") if halo is None else halo, n_colors)
    loop_default = loop is None
    loop = _check.flag("loop", bool(d.get("loop", False)) if loop is None else loop)
    look = check_look(look, d.get("look"))
    check_look_particles(look, n_colors, dim)
    if look.full_colour and not antialias and bound.arguments["antialias"] is None:
        antialias = True  # the look's strokes, shading, backdrop and wedges are drawn in full colour
    # Arrows, and the swept areas and look.trail_samples' curves, which follow the bodies' paths
    # between frames by their recorded velocities.
    velocities = _recording.wants_velocities(arrows, look, trail)
    path = None if fmt == "frames" else _check_path(path, fmt)
    if isinstance(scene, _recording.Recording):
        rec = scene
        camera = _check_camera(camera, rec.positions.shape[2], rec.positions.shape[1])
        if arrows is not None and rec.velocities is None:
            if arrows_given:
                raise InvalidInputError(f"arrows={arrows!r}: the recording holds no velocities; record(..., velocities=True)")
            arrows = None  # the scene's default, which this recording was made without
        if arrows == "acceleration" and rec.frames < 2:
            raise InvalidInputError("arrows='acceleration' differences the velocities of two frames or more; this recording has 1")
        given = [a for a, v in (("frames", frames), ("steps_per_frame", steps_per_frame), ("frame_time", frame_time), ("substeps", substeps)) if v is not None]
        if given:
            raise InvalidInputError(f"{given[0]}: a Recording is already simulated; give it to record() instead")
        if color_by == "speed" and rec.speeds is None or color_by == "pressure" and rec.pressures is None:
            raise InvalidInputError(f"color_by: the recording holds no {color_by}s; record(..., color_by={color_by!r})")
        if color_by == "strain" and (rec.strain is None or not springs):
            raise InvalidInputError("color_by='strain': the recording holds no springs (or springs=False)")
        if not springs:
            rec = rec._replace(pairs=None, strain=None)
        _check.memory("frames, size", rec.frames * 2 * size[0] * size[1], f"{rec.frames} frames of {size[0]}x{size[1]} pixels")
        if path is not None:
            _check_writable(path)
            if fmt == "png":
                _check_png_targets(path, rec.frames)
    else:
        own = scene  # what the state is kept of (the view below may be a flows' points view)
        scene = _recording.points_view(scene)
        camera = _check_camera(camera, int(getattr(scene, "dim", 0)), int(getattr(scene, "n_particles", 0)))
        plan = _recording._plan(scene, frames, steps_per_frame, frame_time, substeps, color_by, springs, velocities)
        if arrows == "acceleration" and plan["frames"] < 2:
            raise InvalidInputError("arrows='acceleration' differences the velocities of two frames or more; give frames >= 2")
        _check_memory(scene, plan["frames"], size, springs, velocities)
        if path is not None:
            _check_writable(path)
            if fmt == "png":
                _check_png_targets(path, plan["frames"])
        # What the scene was, put back if the simulation or the drawing runs out of memory (a
        # refusal leaves the scene as it was); None where the scene has no state (a batch's
        # view): then it is left at the last step, as after Ctrl-C.
        before = _state_before(own)
        rec = None
        try:
            # Looked up at call time, as record() does, so that patching _recording._simulate covers both.
            rec = _recording._simulate(scene, progress=progress, **plan)
            if fmt != "frames":
                return _draw(rec, fmt, path, size, fps, color_by, radius, view, colorbar, trail, size_by, title, camera,
                             arrows, mesh, texture, theme, antialias, colors, cmap, background, surface, box, halo, loop,
                             loop_default, look, dither)
        except MemoryError as e:
            if before is not None:
                # The drawing's buffers (held by the traceback's frames) and the recording
                # freed first: the restore needs room under the same limit.
                traceback.clear_frames(e.__traceback__)
                rec = None
                # Not a step taken (refused at the first, which the scene itself undoes whole):
                # nothing to put back, and the restore, refused under the same limit, named
                # itself (set_state) in place of the call.
                if own.step_count != before["step"] or own.time != before["time"]:
                    own.set_state(before)
            raise
    return _draw(rec, fmt, path, size, fps, color_by, radius, view, colorbar, trail, size_by, title, camera, arrows, mesh,
                 texture, theme, antialias, colors, cmap, background, surface, box, halo, loop, loop_default, look, dither)


def _state_before(scene: Any) -> dict[str, Any] | None:
    """``scene.state()`` where the scene has one, else None. OutOfMemoryError where it cannot be
    had now (before anything is simulated: a render that cannot keep it would not draw)."""
    from ..scene import Scene

    if not isinstance(scene, Scene):
        return None
    return scene.state()


def _draw(rec: Any, fmt: str, path: Any, size: Any, fps: Any, color_by: Any, radius: Any, view: Any, colorbar: Any, trail: Any,
          size_by: Any, title: Any, camera: Any, arrows: Any, mesh: Any, texture: Any, theme: Any, antialias: Any, colors: Any,
          cmap: Any, background: Any, surface: Any, box: Any, halo: Any, loop: Any, loop_default: Any, look: Any,
          dither: Any) -> Any:
    """The frames of the recording `rec`, drawn and written as `fmt` (:func:`_render`'s options,
    checked there)."""
    if rec.fields is not None and rec.positions.shape[1] == 0:
        from ._fields import FieldRasteriser, fit_size, palette

        fsize = fit_size(rec.field_extent, size)
        fr = FieldRasteriser(
            rec.fields, rec.field_style, fsize, rec.field_mask, rec.field_extent, rec.field_points, rec.times, rec.field_label, colorbar,
            dither=dither,
        )
        return _emit(fmt, path, (fr.frame(k) for k in range(rec.frames)), palette(rec.field_style), fps, rec.frames)
    if loop and loop_default and not _closes(rec):
        loop = False  # other frames or frame times than the scene's cut its period: a seam, not a loop
    trail = min(trail, rec.frames)
    ras = _Rasteriser(rec, size, color_by, radius, view, colorbar=colorbar, trail=trail, size_by=size_by, annotate=True,
                      title=title or None, camera=camera, arrows=arrows, fps=fps, mesh=mesh, texture=texture, theme=theme,
                      antialias=antialias, colors=colors, cmap=cmap, background=background,
                      surface=surface, fit=None if box is None else box - rec.origin, halo=halo, loop=loop, look=look)
    if ras.full_colour:
        if fmt == "gif":  # full-colour frames are kept until the palette is made: 3 bytes a pixel
            _check.memory("frames, size", rec.frames * 4 * size[0] * size[1], f"{rec.frames} colour frames of {size[0]}x{size[1]} pixels")
        # Frames that depend on their index alone are drawn side by side on threads (the same
        # bytes: _threads).
        return _emit(fmt, path, _threads.in_order(ras.frame_rgb, rec.frames, ras.frames_independent), None, fps, rec.frames, dither)
    return _emit(fmt, path, _threads.in_order(ras.frame, rec.frames, ras.frames_independent), ras.palette, fps, rec.frames)


def _check_halo(halo: Any, n: int) -> np.ndarray | None:
    """None, or an (n,) bool mask from a mask or particle indices (errors name `halo`)."""
    if halo is None:
        return None
    arr = _check.array("halo", halo)
    if arr.size == 0 and arr.ndim == 1:
        return None
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise InvalidInputError(f"halo: a mask must have shape ({n},), got {arr.shape}")
        return arr
    if arr.dtype.kind not in "iu" or arr.ndim != 1:
        raise InvalidTypeError(f"halo must be a bool mask or a 1-D array of particle indices, got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise InvalidInputError(f"halo: particle indices must be in [0, {n}), got {int(arr.min())} to {int(arr.max())}")
    mask = np.zeros(n, dtype=bool)
    mask[arr] = True
    return mask


#: Output formats by file extension: what :func:`save` and ``physcore render -o`` write (the
#: last three: glTF 2.0 and the HTML player, :func:`gltf` and :func:`html`).
FORMATS = {".gif": "gif", ".mp4": "mp4", ".webm": "webm", ".png": "png", ".glb": "glb", ".gltf": "gltf", ".html": "html"}
#: The formats of the motion in 3D rather than pixels, and the options they take.
_WEB = ("glb", "gltf", "html")
_WEB_OPTIONS = ("frames", "steps_per_frame", "frame_time", "substeps", "fps", "mesh", "theme", "view", "progress", "title")
_VIDEO_INSTALL = 'pip install "physcore[video]"'


def _closes(rec: _recording.Recording) -> bool:
    """Whether a recording's last frame runs on into its first as each frame into the next: the
    step from the last frame back to the first at most 1.5 times the largest step between
    frames. A scene's ``loop`` default holds for the span it renders by default; fewer frames,
    another frame time or another step cut the period, and its trails would draw the seam as
    chords across the picture."""
    x = np.asarray(rec.positions)
    if x.shape[0] < 3 or x.shape[1] == 0:
        return False
    step = float(np.abs(np.diff(x, axis=0)).max())
    return bool(np.isfinite(step) and float(np.abs(x[-1] - x[0]).max()) <= 1.5 * step)


def _emit(fmt: str, path: Path | None, index_frames: Any, colours: np.ndarray | None, fps: float, count: int,
          dither: bool = False) -> Any:
    """Writes (or yields) the palette-index frames in `fmt`: "gif", "mp4", "webm", "png" (one
    file per frame) or "frames" (an iterator of RGB arrays). `colours` None: the frames are
    (H, W, 3) uint8 RGB already (shaded meshes)."""
    if fmt == "gif":
        if colours is None:
            _write_gif_rgb(path, list(index_frames), _gif_delays_ms(fps, count), dither)
        else:
            _write_gif(path, index_frames, _gif_delays_ms(fps, count), colours)
        return path
    # (H, W) uint8 indices -> (H, W, 3) uint8
    rgb = index_frames if colours is None else (colours[idx] for idx in index_frames)
    if fmt == "frames":
        return rgb
    if fmt == "png":
        return _write_pngs(path, rgb, count)
    _write_video(path, rgb, fps, fmt)
    return path


def _write_pngs(path: Path, rgb: Any, count: int) -> list[Path]:
    """One PNG per frame beside `path`: ``stem_0000.png``, ``stem_0001.png``, … (as many digits as
    the count needs, at least 4), written as a whole: every frame goes to a temporary file in the
    same directory first, and only when all are written are they renamed into place. On any
    failure (a full disk, Ctrl-C) the temporaries are removed and no frame file is touched, so an
    older sequence of the same name stays whole."""
    from PIL import Image

    digits = max(4, len(str(count - 1)))
    directory = path.parent if str(path.parent) else Path(".")
    done: list[tuple[str, Path]] = []  # (temporary, target) not renamed yet
    targets: list[Path] = []
    try:
        for k, frame in enumerate(rgb):
            target = path.with_name(f"{path.stem}_{k:0{digits}d}.png")
            with ctrl_c_held():  # made and kept for the clean-up together (see atomic_write)
                fd, tmp = tempfile.mkstemp(dir=directory, prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX)
                done.append((tmp, target))
                fh = os.fdopen(fd, "wb")
            targets.append(target)
            with fh:
                Image.fromarray(frame).save(fh, format="PNG", optimize=False)
        umask = os.umask(0)
        os.umask(umask)
        for tmp, _ in done:
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; an ordinary new file's mode
        # The renames take milliseconds; a Ctrl-C among them would leave new frames beside old
        # ones, so it is held until they are all in place (and raised then).
        with ctrl_c_held():
            while done:
                tmp, target = done[0]
                os.replace(tmp, target)
                done.pop(0)
    except BaseException:
        for tmp, _ in done:
            Path(tmp).unlink(missing_ok=True)
        raise
    return targets


def _write_video(path: Path, rgb: Any, fps: float, fmt: str) -> None:
    """H.264 in MP4 (yuv420p, CRF 26: plays everywhere; the default 4 s cloth is ~0.4 MB) or VP9 in WebM (CRF 32), through PyAV
    (FFmpeg's libraries in its wheel), written atomically. Odd sizes are padded by one pixel
    (4:2:0 chroma needs even ones)."""
    from fractions import Fraction

    av = _video_module()
    codec, options = ("libx264", {"crf": "26", "preset": "medium"}) if fmt == "mp4" else ("libvpx-vp9", {"crf": "32", "b": "0"})

    def write(fh: Any) -> None:
        try:
            encode(fh)
        except Exception as e:
            # PyAV wraps an error of the file's own writes (a full disk under WebM's muxer) in
            # its callback error, a RuntimeError: raise the OSError itself, as the other formats do.
            inner = e.__cause__ or e.__context__
            while inner is not None and not isinstance(inner, OSError):
                inner = inner.__cause__ or inner.__context__
            if isinstance(e, OSError) or inner is None:
                raise
            raise inner from e

    def encode(fh: Any) -> None:
        with av.open(fh, mode="w", format=fmt) as container:
            stream = None
            for frame in rgb:
                h, w = frame.shape[:2]
                if h % 2 or w % 2:
                    frame = np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
                if stream is None:
                    stream = container.add_stream(codec, rate=Fraction(fps).limit_denominator(1001))
                    stream.width, stream.height = frame.shape[1], frame.shape[0]
                    stream.pix_fmt = "yuv420p"
                    stream.options = options
                for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                    container.mux(packet)
            if stream is not None:
                for packet in stream.encode(None):
                    container.mux(packet)

    atomic_write(path, write)


def _check_video_rate(fps: float) -> None:
    """Refuse, naming fps, a rate a video stream cannot carry: ``_write_video`` writes it as a
    fraction of denominator at most 1001 whose numerator is a C int (fps = 1e-300 rounded to 0,
    and FFmpeg then wrote 24 fps; fps = 1e308 overflowed after the whole simulation)."""
    from fractions import Fraction

    rate = Fraction(fps).limit_denominator(1001)
    if not (0 < rate and rate.numerator < 2**31):
        raise InvalidInputError(f"fps must be between 1/1001 and 2**31 - 1 frames per second for a video, got {fps:g}")


def _video_module() -> Any:
    try:
        import av
    except ImportError:
        raise ImportError(f"MP4 and WebM output need PyAV: {_VIDEO_INSTALL}") from None
    return av


@refusing_memory("save", "the frames", rename=_DRAWING)
def save(scene: Any, path: str | os.PathLike, **options: Any) -> Any:
    """Draw a scene or :class:`Recording` like :func:`gif`, in the format `path`'s extension names.

    ``.gif``: :func:`gif`. ``.mp4``: H.264 video (CRF 26, yuv420p; plays in browsers, phones and
    slides). ``.webm``: VP9 video. Both through PyAV, an optional extra (``pip install
    "physcore[video]"``; its wheel brings FFmpeg's libraries). ``.png``: one PNG per frame,
    ``stem_0000.png``, ``stem_0001.png``, … beside `path`, renamed into place only once all are
    written. ``.glb``/``.gltf``: :func:`gltf`; ``.html``: :func:`html` (they take only
    frames, steps_per_frame, frame_time, substeps, fps, mesh, theme, view, progress and, for
    ``.html``, title). Every file is written atomically.

    Parameters
    ----------
    scene : physcore.Scene or Recording
        As for :func:`gif`.
    path : str or os.PathLike
        Ends in ``.gif``, ``.mp4``, ``.webm``, ``.png``, ``.glb``, ``.gltf`` or ``.html``; its
        directory must exist and be writable (checked before simulating).
    **options
        The keyword arguments of :func:`gif` (frames, frame_time, fps, size, color_by, theme, …).

    Returns
    -------
    pathlib.Path, or a list of them for ``.png``

    Raises
    ------
    TypeError, ValueError
        As :func:`gif`; also an extension that is none of the above, naming `path`.
    ImportError
        ``.mp4``/``.webm`` without PyAV, ``.glb``/``.gltf``/``.html`` without pygltflib, naming
        the extra to install (before simulating).
    physcore.SimulationDiverged, OSError
        As :func:`gif`: no file is written.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidTypeError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise InvalidInputError(f"path must end in one of {', '.join(FORMATS)}; got {str(path)!r}")
    if fmt in ("mp4", "webm"):
        _video_module()  # fail before simulating
    if fmt in _WEB:
        other = [k for k in options if k not in _WEB_OPTIONS or (k == "title" and fmt != "html")]
        if other:
            if other[0] in _OPTIONS or other[0] == "title":
                raise InvalidInputError(f"{other[0]}: a .{fmt} file is not drawn in pixels and takes no {other[0]}; "
                                        f"its options are {', '.join(o for o in _WEB_OPTIONS if o != 'title' or fmt == 'html')}")
            raise InvalidTypeError(f"save() got an unexpected keyword argument {other[0]!r}")
        from ._gltf import gltf
        from ._html import html

        return html(scene, path, **options) if fmt == "html" else gltf(scene, path, **options)
    return _render(scene, path, fmt, **options)


def frames(scene: Any, **options: Any) -> Any:
    """The frames :func:`gif` would draw, as an iterator of (H, W, 3) uint8 RGB arrays, for
    composing your own figures or writing another format. A scene is simulated when this is
    called (as :func:`record`); the frames are drawn one at a time as the iterator is read.
    `options` are :func:`gif`'s keyword arguments; raises what it raises."""
    return _render(scene, None, "frames", **options)


def _gif_delays_ms(fps: float, frames: int) -> list[int]:
    """Per-frame delays (ms, multiples of 10) for `frames` frames at `fps`: GIF delays are whole
    centiseconds, so frame k starts at round(k · 100/fps) cs and the total is exact to 1 cs;
    each delay is at least 2 cs (most viewers play shorter ones at 100 ms) and at most 65535."""
    step = min(max(100.0 / fps, 2.0), 65535.0)  # before rounding: 100/fps is inf for a subnormal fps
    starts = [round(k * step) for k in range(frames + 1)]
    return [10 * (b - a) for a, b in zip(starts[:-1], starts[1:], strict=True)]


#: Full-colour dither (:func:`_ordered_indices`): a pair of palette colours p, q mixed at a
#: ratio r scores its miss of the colour drawn plus DITHER_NOISE times the pattern's own noise,
#: r (1 − r) |q − p|²: without it a colour just off the line of its nearest shades mixed in a
#: far one at a small ratio, lone bright specks on a dark glow's edge (kepler's). Pixels that
#: differ from a 4-neighbour by over DITHER_EDGE levels in a channel (a stroke's or a disc's
#: antialiased edge, not a glow) take their nearest colour: dithered, a thin line reads dotted.
DITHER_NOISE = 0.2
DITHER_EDGE = 24


def _ordered_indices(frame: np.ndarray, palette: np.ndarray, candidates: int = 8) -> np.ndarray:
    """(H, W) uint8 palette indices of an (H, W, 3) uint8 frame by Bayer's 8 × 8 ordered dither
    between two colours (after Yliluoma's "arbitrary-palette positional dithering"): each colour
    c is drawn as a mix of its nearest palette colour p and one q of its `candidates` nearest,
    at c ≈ p + r (q − p), 0 ≤ r ≤ 1, the pair that misses c least counting the mix's noise
    (DITHER_NOISE), and a pixel takes q where its threshold (fixed to its place:
    :func:`._fields._threshold`) is below r, else p. So each 8 × 8 tile has on average the
    colour drawn, to within the palette's reach, however far apart its colours are (an offset
    of fixed size mixed colours only near the boundaries between them), and a still region
    stays still from frame to frame. Edges (DITHER_EDGE) take the nearest colour. Computed once
    per distinct colour of the frame."""
    from ._fields import _threshold

    flat = frame.reshape(-1, 3)
    keys = flat.astype(np.int64) @ np.array([65536, 256, 1], dtype=np.int64)
    unique, inverse = np.unique(keys, return_inverse=True)
    u = np.stack([unique >> 16, (unique >> 8) & 255, unique & 255], axis=1).astype(np.float64)
    pal = palette.astype(np.float64)
    if len(pal) < 2:  # nothing to mix: every pixel the one colour (or none)
        return np.zeros(frame.shape[:2], dtype=np.uint8)
    k = min(max(candidates, 2), len(pal))
    near = np.empty((len(u), k), dtype=np.int64)
    for lo in range(0, len(u), 4096):  # in blocks: (block, palette) distances
        d2 = ((u[lo:lo + 4096, None, :] - pal[None]) ** 2).sum(axis=2)
        part = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < len(pal) else np.tile(np.arange(k), (len(d2), 1))
        order = np.argsort(np.take_along_axis(d2, part, axis=1), axis=1, kind="stable")
        near[lo:lo + 4096] = np.take_along_axis(part, order, axis=1)
    p = pal[near[:, 0]]
    q = pal[near[:, 1:]]  # (U, k - 1, 3)
    span = q - p[:, None]
    length2 = np.maximum((span * span).sum(axis=2), 1e-12)
    r = np.clip(((u - p)[:, None] * span).sum(axis=2) / length2, 0.0, 1.0)
    miss = (((p[:, None] + r[..., None] * span) - u[:, None]) ** 2).sum(axis=2) + DITHER_NOISE * r * (1 - r) * length2
    best = np.argmin(miss, axis=1)
    rows = np.arange(len(u))
    second, ratio = near[rows, 1 + best], r[rows, best]
    t = _threshold(frame.shape[:2]).ravel()
    pick = np.where(t < ratio[inverse], second[inverse], near[inverse, 0])
    edge = _edges(frame, DITHER_EDGE).ravel()
    pick[edge] = near[inverse[edge], 0]
    return pick.reshape(frame.shape[:2]).astype(np.uint8)


def _edges(frame: np.ndarray, levels: int) -> np.ndarray:
    """(H, W) bool: the pixels of an (H, W, 3) uint8 frame that differ from a 4-neighbour by
    more than `levels` in some channel."""
    f = frame.astype(np.int16)
    out = np.zeros(frame.shape[:2], dtype=bool)
    for axis in (0, 1):
        step = np.abs(np.diff(f, axis=axis)).max(axis=2) > levels
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        out[tuple(lo)] |= step
        out[tuple(hi)] |= step
    return out


def _palette_frames(rgb: list[np.ndarray], n_colours: int = 256, dither: bool = False) -> tuple[list[Any], bytes]:
    """Full-colour (H, W, 3) uint8 frames as 'P' images on one palette of `n_colours` (at most
    256) for the whole animation (so that colours do not flicker from frame to frame), made from
    up to 8 frames spread through it: their 16 most frequent colours exactly (the background,
    text and other flat colours stay exact) and the rest (240 of 256) by median cut. Each frame
    is mapped to its nearest colours without error diffusion (its noise would spread from what
    moves into still regions, changing every frame and costing bytes); with `dither`, by
    Bayer's 8 × 8 ordered dither between two colours instead (:func:`_ordered_indices`), so a
    smooth gradient (a glow under a translucent wedge) reads as a mix of neighbouring colours,
    not as rings. Returns the images and the palette's 768 bytes (entries from `n_colours` on
    are black and unused: the GIF writer keeps one for its transparent pixels)."""
    from PIL import Image

    weights = np.array([65536, 256, 1], dtype=np.int64)
    picks = np.unique(np.linspace(0, len(rgb) - 1, min(8, len(rgb))).round().astype(int))
    sample = np.concatenate([rgb[k] for k in picks], axis=0)
    values, counts = np.unique(sample.reshape(-1, 3).astype(np.int64) @ weights, return_counts=True)
    top = values[np.argsort(counts, kind="stable")[::-1][:16]]
    exact = np.stack([top >> 16, (top >> 8) & 255, top & 255], axis=1).astype(np.uint8)
    adaptive = Image.fromarray(sample).quantize(n_colours - len(exact), method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    colours = exact.tobytes() + bytes(adaptive.getpalette()[: 3 * (n_colours - len(exact))])
    colours += bytes(768 - len(colours))
    palette_image = Image.new("P", (1, 1))
    # Only the palette's first n_colours entries: Pillow must map no pixel to the unused rest.
    palette_image.putpalette(colours[: 3 * n_colours])
    # Pillow maps to a palette through a coarse colour cache (a near-white background can come
    # out as a neighbouring entry), so the exact colours are put back by their packed value.
    order = np.argsort(top)
    top_sorted = top[order]

    def mapped(frame: np.ndarray) -> Any:
        if dither:
            q = _ordered_indices(frame, np.frombuffer(colours, np.uint8).reshape(-1, 3)[:n_colours])
        else:
            q = np.array(Image.fromarray(frame).quantize(palette=palette_image, dither=Image.Dither.NONE))
        key = frame.astype(np.int64) @ weights
        pos = np.minimum(np.searchsorted(top_sorted, key), len(top_sorted) - 1)
        hit = top_sorted[pos] == key
        q[hit] = order[pos[hit]]
        im = Image.fromarray(q)  # 'L' from the uint8 indices; putpalette makes it 'P'
        im.putpalette(colours)
        return im

    # Each frame's mapping is its own (Pillow and numpy release the GIL): side by side on threads.
    return _threads.map_frames(lambda k: mapped(rgb[k]), len(rgb)), colours


#: The GIF writer stores a pixel of a frame only where its colour differs from the one the
#: viewer already shows there by more than this, in any of R, G and B (0-255); the other pixels
#: are transparent and the previous frame shows through (frame-difference transparency). 0:
#: every change is stored, so the decoded GIF shows exactly the frames drawn (particle scenes:
#: their flat colours and hard edges would show any error).
GIF_TOLERANCE = 0
#: The same for fields (palettes of smooth colour maps, :mod:`._fields`). It was 8 (a pixel
#: could lag its frame by one shade of the map), which cut a Turing GIF from 6.3 to 4.2 MB when
#: the maps had more shades; at the maps' present few dozen shades it saves 0–8 % (ripple
#: 2.62 → 2.55 MB, smoke 2.40 → 2.23, vortex_street 2.67 → 2.46, the others nothing) and the
#: lagging pixels drew a visible texture of fine rings and streaks over the ripple's smooth
#: water (a fifth of its pixels off by one shade at t = 2.76 s). 0: the frames exactly.
FIELD_GIF_TOLERANCE = 0


def _write_gif_rgb(path: Path, rgb: list[np.ndarray], duration_ms: list[int], dither: bool = False) -> None:
    """A GIF of full-colour frames (shaded surfaces, soft discs) on one palette of 255 colours
    (see :func:`_palette_frames`, `dither` its; the 256th is the transparent one of
    :func:`_write_indexed`), written atomically."""
    images, colours = _palette_frames(rgb, n_colours=255, dither=dither)
    _write_indexed(path, [np.asarray(im) for im in images], duration_ms, np.frombuffer(colours, np.uint8).reshape(-1, 3))


def _write_gif(path: Path, index_frames, duration_ms: list[int], colours: Any = None, tolerance: int | None = None) -> None:
    """A GIF of (H, W) uint8 palette-index frames on `colours` ((K <= 256, 3) uint8; the fixed
    particle palette when None), written atomically (see :func:`_write_indexed`) with
    `tolerance`, by default :data:`FIELD_GIF_TOLERANCE` on the fields' colour maps
    (:func:`._fields.palette`) and :data:`GIF_TOLERANCE` on any other."""
    frames = [np.asarray(buf, dtype=np.uint8) for buf in index_frames]
    if tolerance is None:
        from ._fields import STYLES, palette

        field = colours is not None and any(np.array_equal(colours, palette(s)) for s in STYLES)
        tolerance = FIELD_GIF_TOLERANCE if field else GIF_TOLERANCE
    _write_indexed(path, frames, duration_ms, np.asarray(_PALETTE if colours is None else colours, dtype=np.uint8), tolerance)


def _transparent_slot(frames: list[np.ndarray], colours: np.ndarray) -> int | None:
    """A palette index no frame uses (the last such), for the transparent pixels; None if the
    frames use all 256."""
    used = np.zeros(256, dtype=bool)
    for f in frames:
        used |= np.bincount(f.ravel(), minlength=256)[:256] > 0
    free = np.flatnonzero(~used)
    return int(free[-1]) if free.size else None


#: The shortest run of unchanged pixels (in the order GIF stores them, row after row) made
#: transparent; shorter ones keep their colour, so that a run of a smoothly varying field is not
#: broken into pieces that each cost LZW codes.
_MIN_RUN = 16


def _short_runs_filled(changed: np.ndarray, min_run: int) -> np.ndarray:
    """`changed` (H, W) bool with every run of False shorter than `min_run` (in row-major order)
    set True: the pixels a frame stores."""
    flat = changed.ravel()
    edges = np.flatnonzero(np.diff(np.concatenate(([True], flat, [True])).astype(np.int8)))
    starts, ends = edges[0::2], edges[1::2]  # runs of False: [start, end)
    short = (ends - starts) < min_run
    if not short.any():
        return changed
    delta = np.zeros(flat.size + 1, dtype=np.int32)
    np.add.at(delta, starts[short], 1)
    np.add.at(delta, ends[short], -1)
    return (flat | (np.cumsum(delta[:-1]) > 0)).reshape(changed.shape)


def _box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """(top, bottom, left, right), the ends exclusive, of the True pixels of `mask`; None if none."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not rows.size:
        return None
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _lzw(pixels: np.ndarray) -> bytes:
    """GIF's LZW code of (h, w) uint8 indices (8-bit codes, not interlaced) in its data
    sub-blocks, as Pillow's GIF encoder writes them, without the terminating empty block."""
    from PIL import Image

    return Image.fromarray(np.ascontiguousarray(pixels)).tobytes("gif", "L", 8, 0)


def _write_indexed(path: Path, frames: list[np.ndarray], duration_ms: list[int], colours: np.ndarray, tolerance: int = 0) -> None:
    """Write palette-index frames as an animated GIF with one global colour table (looping),
    storing each frame after the first as its difference from what is on screen: pixels whose
    colour is within `tolerance` (any channel, 0-255) of the colour shown there become the
    transparent index (an index no frame uses), the frame is cropped to the box of what it
    stores and kept on screen under the next (disposal 1, "do not dispose"); a frame with no
    change lengthens the previous one. Per frame, whichever LZW-codes shortest is stored: the
    changed pixels only, those and the short unchanged runs between them (see
    :data:`_MIN_RUN`), or the whole box of the changes (a field on the move compresses best
    whole). What is shown is tracked exactly, so no pixel ever strays from its frame's colour by
    more than `tolerance` (0: the frames exactly). Where the frames use all 256 indices, each is
    stored whole, cropped to the box of its changes."""
    import struct

    pal = np.zeros((256, 3), dtype=np.uint8)
    pal[: min(256, len(colours))] = colours[:256]
    slot = _transparent_slot(frames, pal)
    h, w = frames[0].shape
    # What is on screen is always some palette entry's colour, so it is tracked as an index
    # image, and "changed" is a lookup in the 256 × 256 table of index pairs whose colours differ
    # by more than `tolerance`: keyed by (new << 8) | shown, 0.14 against 8.6 ms a 480×360 frame
    # for the colours' channel-wise difference.
    rgb = pal.astype(np.int16)
    differs = (np.abs(rgb[:, None, :] - rgb[None, :, :]).max(axis=2) > tolerance).ravel()
    shown = frames[0].astype(np.uint16)
    stored: list[list[Any]] = [[frames[0], 0, 0, int(duration_ms[0]), None]]  # pixels, x, y, ms, LZW code
    for f, ms in zip(frames[1:], duration_ms[1:], strict=True):
        key = f.astype(np.uint16)
        key <<= 8
        key |= shown
        changed = np.take(differs, key)
        box = _box(changed)
        if box is None:
            stored[-1][3] += int(ms)
            continue
        top, bottom, left, right = box
        whole = np.zeros_like(changed)
        whole[top:bottom, left:right] = True
        masks = [whole] if slot is None else [changed, _short_runs_filled(changed, _MIN_RUN), whole]
        best = None
        for mask in masks:
            top, bottom, left, right = _box(mask)
            cand = np.where(mask, f, np.uint8(0 if slot is None else slot))[top:bottom, left:right]
            code = _lzw(cand)
            if best is None or len(code) < len(best[0]):
                best = (code, mask, cand, left, top)
        code, mask, cand, x, y = best
        np.copyto(shown, f, where=mask)
        stored.append([cand, x, y, int(ms), code])  # the code chosen by, kept: not encoded twice
    head = b"GIF89a" + struct.pack("<HHBBB", w, h, 0xF7, 0, 0) + pal.tobytes()
    head += b"!\xff\x0bNETSCAPE2.0\x03\x01" + struct.pack("<H", 0) + b"\x00"  # loop for ever
    flags = (1 << 2) | (0 if slot is None else 1)  # do not dispose; transparent index given

    def write(fh: Any) -> None:
        fh.write(head)
        for pixels, x, y, ms, code in stored:
            ph, pw = pixels.shape
            fh.write(b"!\xf9\x04" + struct.pack("<BHBB", flags, min(65535, round(ms / 10)), slot or 0, 0))
            fh.write(b"," + struct.pack("<HHHHB", x, y, pw, ph, 0) + b"\x08" + (_lzw(pixels) if code is None else code) + b"\x00")
        fh.write(b";")

    atomic_write(path, write)


def recording_html(rec: _recording.Recording) -> str:
    """Jupyter and IPython show a Recording inline: its GIF as :func:`gif` draws it with the
    defaults, embedded as a data URL (``IPython.display.display(rec)``; it is also what a
    notebook cell ending in a recording shows). It is ``Recording._repr_html_``, set by the
    package (``render/__init__.py``): the display lives with the GIF writer, since the
    recording's module sits below the writer and cannot import it."""
    import base64

    with tempfile.TemporaryDirectory(prefix="physcore-") as tmp:
        data = gif(rec, os.path.join(tmp, "recording.gif")).read_bytes()
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img src="data:image/gif;base64,{b64}" alt="physcore recording: {rec.frames} frames"/>'
