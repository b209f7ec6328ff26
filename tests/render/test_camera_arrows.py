"""Camera modes (fit, follow, zoom, orbit), velocity and acceleration arrows, and the labels' font:
measured on the drawn pixels (disc and arrow centroids, text masks) against the geometry each
promises."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore import render
from physcore.render import _colorbar, _palette
from physcore.render._camera import FOLLOW_SMOOTHING

PLAIN = render._PALETTE[_palette._PLAIN]
PINNED = render._PALETTE[_palette._PINNED]
ARROW = render._PALETTE[_palette._ARROW]
TEXT = render._PALETTE[render._TEXT]


def mask_of(img: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    return np.all(img == rgb, axis=-1)


def centroid(mask: np.ndarray) -> np.ndarray:
    """(col, row) of the pixel centres of `mask` (pixel k spans [k, k + 1))."""
    r, c = np.nonzero(mask)
    assert r.size, "nothing drawn"
    return np.array([c.mean() + 0.5, r.mean() + 0.5])


def still_scene(x, v=None, dim: int = 2, pinned=None) -> pc.Scene:
    """Particles moving freely (no forces) from `x` at velocities `v`."""
    s = pc.Scene(dim=dim, integrator="verlet", dt=1e-3)
    x = np.asarray(x, dtype=float)
    s.add_particles(x, np.zeros_like(x) if v is None else np.asarray(v, dtype=float),
                    pinned=None if pinned is None else np.asarray(pinned))
    return s


# --------------------------------------------------------------------------------- follow
def test_follow_keeps_a_projectile_at_the_centre_while_fit_lets_it_cross():
    """A lone ball in free flight: the fitted view watches it cross the image; the follow view
    holds it within 3 pixels of where frame 0 put it, the image's centre column (the smoothing
    only lags on the parabola's curvature: g σ² / 2, about 1.5 pixels here)."""
    rec = render.record(pc.scenes.projectile(n=1, ground=False), frames=45)
    size = (240, 180)
    fit = [centroid(mask_of(f, PLAIN)) for f in render.frames(rec, size=size, color_by="none", trail=0)]
    follow = [centroid(mask_of(f, PLAIN)) for f in render.frames(rec, size=size, color_by="none", trail=0, camera="follow")]
    assert np.ptp([c[0] for c in fit]) > 100  # fitted: the ball crosses most of the width
    assert abs(follow[0][0] - size[0] / 2) <= 1.0
    drift = np.abs(np.array(follow) - follow[0]).max(axis=0)
    assert drift.max() <= 3.0, drift


def test_follow_eases_a_jump_over_several_frames():
    """Two particles 1 m apart jump 0.4 m sideways at frame 20. The view follows their centre
    of mass, but no frame moves it more than the largest weight of the smoothing Gaussian
    (σ = FOLLOW_SMOOTHING s at 30 fps: 1/(σ√(2π)) ≈ 0.133) times the jump, and it ends on it."""
    f = 41
    x = np.zeros((f, 2, 2), dtype=np.float32)
    x[:, 1, 0] = 1.0
    x[20:, :, 0] += 0.4
    rec = render.Recording(positions=x, origin=np.zeros(2), speeds=None, pairs=None, strain=None,
                           pinned=np.zeros(2, dtype=bool), planes=[], times=np.arange(f) / 30.0)
    w = 320
    imgs = list(render.frames(rec, size=(w, 240), color_by="none", fps=30, radius=3, camera="follow"))
    left = []
    for img in imgs:
        disc = mask_of(img, PLAIN)
        left.append(centroid(disc & (np.arange(w) < w / 2)[None, :])[0])
    # Pixels per metre, from the pair's spacing before the jump (both discs in view).
    cols = np.nonzero(mask_of(imgs[0], PLAIN).any(axis=0))[0]
    scale = (cols[cols >= w / 2].mean() - cols[cols < w / 2].mean()) / 1.0
    # The view's centre, in pixels: the left disc's world position less where it is drawn.
    world = np.where(np.arange(f) >= 20, 0.4, 0.0) * scale
    cam = world - np.array(left)
    steps = np.abs(np.diff(cam))
    sigma = FOLLOW_SMOOTHING * 30
    bound = 0.4 * scale / (sigma * math.sqrt(2 * math.pi))
    assert steps.max() <= bound + 1.0, (steps.max(), bound)
    assert steps.max() >= 0.5 * bound  # it does move, smoothly, not by a delay
    assert abs((cam[-1] - cam[0]) - 0.4 * scale) <= 1.0  # and ends centred on the new place
    assert (steps[:10] <= 0.5).all() and (steps[-10:] <= 0.5).all()  # still away from the jump


def test_follow_steps_never_exceed_the_targets():
    """Following Kepler's planet: the view's step each frame is a weighted mean of the planet's
    projected steps, so no larger than the largest of them; a fixed scale (zoomed in no less
    than the fitted view)."""
    rec = render.record(pc.scenes.kepler(), frames=60)
    fit = render._Rasteriser(rec, (240, 240), "none", None, render.DEFAULT_VIEW)
    ras = render._Rasteriser(rec, (240, 240), "none", None, render.DEFAULT_VIEW, camera=("follow", 1))
    centres = np.array([ras.cam_at(k).centre for k in range(rec.frames)])
    target = rec.positions[:, 1].astype(np.float64)
    assert np.all(np.abs(np.diff(centres, axis=0)).max(axis=0) <= np.abs(np.diff(target, axis=0)).max(axis=0) + 1e-9)
    assert ras.cam.scale >= fit.cam.scale
    assert {ras.cam_at(k).scale for k in range(rec.frames)} == {ras.cam.scale}


# ----------------------------------------------------------------------------------- zoom
def _spreading_ring(frames: int = 120) -> render.Recording:
    """300 particles: 200 at rest in a disc 0.5 m across, 100 on a ring of radius 1 m moving
    out at 1 m/s, recorded over 4 s (the ring ends at 5 m)."""
    rng = np.random.default_rng(1)
    core = rng.uniform(-0.25, 0.25, (200, 2))
    a = np.linspace(0.0, 2.0 * np.pi, 100, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    scene = still_scene(np.concatenate([core, ring]), np.concatenate([np.zeros_like(core), ring]))
    return render.record(scene, frames=frames, frame_time=4.0 / (frames - 1))


def test_zoom_starts_close_and_widens_to_follows_scale_keeping_every_frame_whole():
    """Issue 65 (galaxies small and blurred in the first frame, the one scale set by the tails
    at the end): the zoom's scale never grows, ends at follow's, starts at least twice as close
    on a ring that spreads fivefold, and every frame holds 99 % of the particles in the image,
    around follow's centres."""
    rec = _spreading_ring()
    size = (240, 200)
    follow = render._Rasteriser(rec, size, "none", 2, render.DEFAULT_VIEW, camera=("follow", None), fps=24)
    zoom = render._Rasteriser(rec, size, "none", 2, render.DEFAULT_VIEW, camera=("zoom", None), fps=24)
    scales = np.array([zoom.cam_at(k).scale for k in range(rec.frames)])
    assert np.all(np.diff(scales) <= 1e-12 * scales[0])
    assert scales[-1] == pytest.approx(follow.cam.scale)
    assert scales[0] >= 2.0 * follow.cam.scale
    for k in range(rec.frames):
        cam = zoom.cam_at(k)
        assert np.array_equal(cam.centre, follow.cam_at(k).centre)
        col, row = cam.pixels(cam.project(rec.positions[k])[0])
        inside = (col >= 0) & (col <= size[0]) & (row >= 0) & (row <= size[1])
        assert inside.mean() >= 0.99, k


def test_zoom_draws_the_scale_bar_of_each_frame():
    """The scale bar holds in every frame of a zoom: drawn at that frame's scale (its pixels
    over the scale are the round length it is labelled with), the first frame's bar standing
    for a shorter length than the last's."""
    from physcore.render._raster import _scale_bar_length

    rec = _spreading_ring()
    ras = render._Rasteriser(rec, (240, 200), "none", 2, render.DEFAULT_VIEW, camera=("zoom", None), fps=24,
                             annotate=True)
    lengths = []
    for k in (0, rec.frames - 1):
        ras.frame(k)
        length, px = ras.scale_bar
        assert length == _scale_bar_length(ras.cam_at(k).scale, 240 / 6.0)
        assert px == round(length * ras.cam_at(k).scale)
        lengths.append(length)
    assert lengths[0] < lengths[1]


def test_galaxies_zoom_in_on_the_disks_at_the_start():
    # The default galaxies start closer than one scale for the whole run would (n = 2000: the
    # zoom stops at FOLLOW_MAX_ZOOM times the fitted view; 2.4 times follow's at n = 10 000).
    assert pc.scenes.galaxies.render_defaults["camera"] == "zoom"
    rec = render.record(pc.scenes.galaxies(n=2000), frames=120, frame_time=0.1)
    follow = render._Rasteriser(rec, (240, 200), "density", 0, (30.0, 70.0), camera=("follow", None), fps=24)
    zoom = render._Rasteriser(rec, (240, 200), "density", 0, (30.0, 70.0), camera=("zoom", None), fps=24)
    assert zoom.cam_at(0).scale > 1.3 * follow.cam.scale


# ---------------------------------------------------------------------------------- orbit
def marker_azimuth(img: np.ndarray, el: float) -> float:
    """Azimuth (degrees) of the camera seeing the pinned marker at (+0.5, 0, 0) and the free
    particle at (-0.5, 0, 0): their pixel offset is (-sin az, +sin(el) cos az) times the scale."""
    a, b = centroid(mask_of(img, PINNED)), centroid(mask_of(img, PLAIN))
    dcol, drow = a - b
    return math.degrees(math.atan2(-dcol, drow / math.sin(math.radians(el))))


def angle_diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.mark.parametrize("camera, turn", [("orbit", lambda k, f: 360.0 * k / f), (("orbit", 90.0), lambda k, f: 90.0 * k / 30)])
def test_orbit_turns_the_view_as_stated(camera, turn):
    """One full turn over the animation by default (360°/frames a frame, so the loop closes),
    or the given degrees per second of playback; measured from two markers' drawn positions in
    every frame, the last included."""
    scene = still_scene([[0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]], dim=3, pinned=[True, False])
    f, view = 12, (-60.0, 25.0)
    imgs = list(render.frames(scene, frames=f, steps_per_frame=1, size=(240, 180), color_by="none", view=view,
                              fps=30, camera=camera))
    for k, img in enumerate(imgs):
        assert angle_diff(marker_azimuth(img, view[1]), view[0] + turn(k, f)) <= 1.0, k


def test_orbit_keeps_everything_in_the_image_at_one_scale():
    """A 3D cluster turned about the vertical: every frame's particles lie inside the image
    (none touches its edge), at one scale fitted to the box that holds every point at every
    azimuth, tight enough that some frame reaches near its side."""
    rec = render.record(pc.scenes.galaxies(n=300), frames=12, color_by="speed")
    size = (240, 200)
    ras = render._Rasteriser(rec, size, "speed", 1, (-60.0, 55.0), camera=("orbit", None))
    reach = 0.0
    for k in range(rec.frames):
        cam = ras.cam_at(k)
        assert cam.scale == ras.cam.scale
        col, row = cam.pixels(cam.project(rec.positions[k])[0])
        assert col.min() >= 1 and col.max() <= size[0] - 1 and row.min() >= 1 and row.max() <= size[1] - 1
        reach = max(reach, np.abs(col - size[0] / 2).max() / (size[0] / 2))
        img = ras.frame(k)
        drawn = (img != _palette._BACKGROUND) & (img != render._TEXT)
        assert not (drawn[0].any() or drawn[-1].any() or drawn[:, 0].any() or drawn[:, -1].any())
    assert reach > 0.75


def test_orbit_is_refused_for_2d_scenes_before_stepping(tmp_path):
    scene = pc.scenes.projectile(n=2)
    with pytest.raises(ValueError, match="camera.*3D"):
        render.gif(scene, tmp_path / "o.gif", frames=2, camera="orbit")
    assert scene.time == 0.0
    assert not (tmp_path / "o.gif").exists()


@pytest.mark.parametrize("camera, error", [
    ("pan", ValueError), (3, TypeError), (("follow", 1.5), TypeError), (("follow", 5), ValueError), (("zoom", 5), ValueError),
    (("follow", -1), ValueError), (("follow", True), TypeError), (("fit", 1), ValueError), (("orbit",), ValueError),
    (("orbit", math.inf), ValueError), (("orbit", "fast"), TypeError),
])
def test_bad_camera_values_are_refused_naming_camera(tmp_path, camera, error):
    scene = still_scene([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], dim=3)
    with pytest.raises(error, match="camera"):
        render.gif(scene, tmp_path / "c.gif", frames=2, camera=camera)
    assert scene.time == 0.0


def test_fit_is_the_default_camera():
    scene = still_scene([[0.0, 0.0], [1.0, 0.5]], v=[[1.0, 0.0], [0.0, 1.0]])
    rec = render.record(scene, frames=3)
    a = list(render.frames(rec, size=(120, 90)))
    b = list(render.frames(rec, size=(120, 90), camera="fit"))
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


# --------------------------------------------------------------------------------- arrows
def test_velocity_arrows_point_along_the_velocity():
    """A projectile's arrow (its pixels' centroid seen from the disc's) points along its
    velocity in every frame, up on the way up and down on the way down."""
    rec = render.record(pc.scenes.projectile(n=1, ground=False), frames=60, velocities=True)
    assert rec.velocities.shape == (60, 1, 2) and rec.velocities.dtype == np.float32
    imgs = render.frames(rec, size=(480, 360), color_by="none", trail=0, arrows="velocity")
    signs = set()
    for k, img in enumerate(imgs):
        d = centroid(mask_of(img, ARROW)) - centroid(mask_of(img, PLAIN))
        vx, vy = rec.velocities[k, 0]
        assert angle_diff(math.degrees(math.atan2(-d[1], d[0])), math.degrees(math.atan2(vy, vx))) <= 4.0, k
        signs.add(bool(vy > 0))
    assert signs == {True, False}


def test_arrow_length_is_proportional_to_speed_and_absent_at_rest():
    """Three particles at 1, 2 and 0 m/s: the 95th percentile of the run's speeds (2 m/s) is
    drawn 1/12 of the image's shorter side long, 1 m/s half that, and the resting one has none."""
    scene = still_scene([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]], v=[[1.0, 0.0], [2.0, 0.0], [0.0, 0.0]])
    size = (480, 360)
    img = next(iter(render.frames(scene, frames=2, steps_per_frame=1, size=size, color_by="none", radius=4,
                                  arrows="velocity")))
    discs, arrows = mask_of(img, PLAIN), mask_of(img, ARROW)
    rows = np.nonzero(discs.any(axis=1))[0]
    bands = np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1)  # one band of rows per particle, top first
    assert len(bands) == 3
    lengths = []
    for band in bands:
        sl = slice(band[0] - 6, band[-1] + 7)
        disc = np.nonzero(discs[sl].any(axis=0))[0]
        centre = 0.5 * (disc.min() + disc.max() + 1)  # the disc's middle (the shaft covers some of it)
        cols = np.nonzero(arrows[sl].any(axis=0))[0]
        lengths.append(cols.max() + 1 - centre if cols.size else 0.0)
    at_0, at_2, at_1 = lengths  # top first: y = 2 (at rest), y = 1 (2 m/s), y = 0 (1 m/s)
    assert at_0 == 0.0
    assert abs(at_2 - min(size) / 12) <= 1.5
    assert 1.85 <= at_2 / at_1 <= 2.15


def test_arrows_on_many_particles_are_an_even_spread_of_few():
    """On a 60 x 60 sheet of moving particles the arrows go on a subset, at most MAX_ARROWS,
    one per square of an arrow's length: no two closer than half of it, and no particle further
    than one and a half from an arrow (small scenes keep every particle's)."""
    from physcore.render._raster import MAX_ARROWS

    g = np.arange(60) * 0.05
    x = np.column_stack([a.ravel() for a in np.meshgrid(g, g)])
    scene = still_scene(x, v=np.tile([[0.3, 0.1]], (len(x), 1)))
    rec = render.record(scene, frames=3, velocities=True)
    size = (480, 360)
    ras = render._Rasteriser(rec, size, "speed", None, render.DEFAULT_VIEW, arrows="velocity")
    pick = ras._arrows[0]
    assert 50 <= pick.size <= MAX_ARROWS
    cam = ras.cam_at(0)
    col, row = cam.pixels(cam.project(rec.positions[0])[0])
    p, allp = np.column_stack([col[pick], row[pick]]), np.column_stack([col, row])
    d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    cell = min(size) / 12
    assert d.min() >= 0.5 * cell
    nearest = np.hypot(*(allp[:, None, :] - p[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert nearest.max() <= 1.5 * cell


def test_acceleration_arrows_are_central_differences_of_the_velocities():
    """Under gravity alone every acceleration arrow points straight down, with the central
    difference of the recorded velocities equal to g."""
    from physcore.render._raster import _acceleration

    rec = render.record(pc.scenes.projectile(n=1, ground=False), frames=20, velocities=True)
    a = _acceleration(rec.velocities.astype(np.float64), rec.times)
    assert np.allclose(a[..., 0], 0.0, atol=1e-3) and np.allclose(a[..., 1], -9.81, atol=1e-3)
    for img in render.frames(rec, size=(320, 240), color_by="none", trail=0, arrows="acceleration"):
        d = centroid(mask_of(img, ARROW)) - centroid(mask_of(img, PLAIN))
        assert d[1] > 5 and abs(d[0]) <= 0.5


def test_bad_arrows_are_refused_naming_arrows(tmp_path):
    scene = still_scene([[0.0, 0.0], [1.0, 0.0]], v=[[1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="arrows"):
        render.gif(scene, tmp_path / "a.gif", frames=2, arrows="force")
    with pytest.raises(TypeError, match="arrows"):
        render.gif(scene, tmp_path / "a.gif", frames=2, arrows=1)
    with pytest.raises(ValueError, match="arrows.*frames"):
        render.gif(scene, tmp_path / "a.gif", frames=1, arrows="acceleration")
    assert scene.time == 0.0
    rec = render.record(scene, frames=2)
    assert rec.velocities is None  # recorded only when asked for
    with pytest.raises(ValueError, match="velocities"):
        render.gif(rec, tmp_path / "a.gif", arrows="velocity")
    assert not (tmp_path / "a.gif").exists()


def test_arrows_count_their_velocities_in_the_memory_check(tmp_path, monkeypatch):
    """The recording's (F, N, dim) float32 velocities are in the estimate checked before
    simulating: a limit between the two estimates lets the plain run through and refuses the
    one with arrows."""
    from physcore import _check

    n, f = 1000, 10
    scene = still_scene(np.column_stack([np.arange(n), np.zeros(n)]))
    plain = f * (4 * n * (2 + 2) + 2 * 16 * 16)
    monkeypatch.setattr(_check, "memory_limit", lambda: plain + f * 4 * n * 2 // 2)
    render.gif(scene, tmp_path / "p.gif", frames=f, steps_per_frame=1, size=(16, 16))
    with pytest.raises(ValueError, match="frames, size"):
        render.gif(scene, tmp_path / "v.gif", frames=f, steps_per_frame=1, size=(16, 16), arrows="velocity")


# ---------------------------------------------------------------------------------- fonts
def test_label_font_grows_with_the_image_and_never_below_the_bitmap_one():
    sizes = [(160, 120), (240, 180), (320, 240), (480, 320), (480, 360), (640, 480), (1280, 720), (1920, 1080)]
    px = [_colorbar._label_px(s) for s in sizes]
    assert _colorbar._label_px((480, 360)) == 13 and _colorbar._label_px((240, 180)) is None
    heights = [np.ptp(_colorbar._digit_rows(p)) + 1 for p in px]  # a digit's height, pixels
    assert heights == sorted(heights)
    assert min(heights) == np.ptp(_colorbar._digit_rows(None)) + 1 == 7  # the bitmap font
    assert heights[sizes.index((480, 360))] >= 9


@pytest.mark.parametrize("size", [(480, 360), (640, 480)])
def test_clock_and_title_are_drawn_in_the_larger_font(size):
    """At 480x360 and up the clock (bottom left) and the title (top left) read as their text
    in the FreeType font of that size, taller than the bitmap font's 11-pixel cell."""
    scene = still_scene([[0.0, 0.0], [1.0, 1.0]], v=[[1.0, 0.0], [0.0, 1.0]])
    frames = list(render.frames(scene, frames=3, frame_time=0.05, size=size, title="Two balls"))
    px = _colorbar._label_px(size)
    clock = _colorbar._text_mask("t = 0.1", px)
    assert clock.shape[0] > 11
    h = size[1]
    ink = mask_of(frames[2][h - 4 - clock.shape[0] : h - 4, 4 : 4 + clock.shape[1]], TEXT)
    assert np.array_equal(ink, clock)
    title = _colorbar._text_mask("Two balls", px)
    assert np.array_equal(mask_of(frames[0][3 : 3 + title.shape[0], 4 : 4 + title.shape[1]], TEXT), title)


def test_colour_bar_strip_spans_the_digits_of_its_labels():
    """The strip's gradient covers the rows of the labels' digits in the larger font (its
    outline one row above and below), as it did with the bitmap font."""
    x, v = np.array([[0.0, 0.0], [1.0, 0.5]]), np.array([[0.0, 0.0], [3.2, 0.0]])
    img = render.render_frame(x, velocities=v, radius=3)
    speed = np.isin(img.reshape(-1, 3) @ [65536, 256, 1],
                    render._PALETTE[render._SPEED0 : render._SPEED0 + render._N_SPEED] @ [65536, 256, 1]).reshape(img.shape[:2])
    strip_rows = np.nonzero(speed[:30].any(axis=1))[0]
    strip_x = np.nonzero(speed[:30].any(axis=0))[0].min()
    # The label "speed 0" ends 4 columns before the strip's outline: its "0" is the 8 before.
    zero = mask_of(img[:30, strip_x - 1 - 4 - 8 : strip_x - 1 - 4], TEXT)
    digit_rows = np.nonzero(zero.any(axis=1))[0]
    assert np.ptp(digit_rows) + 1 == np.ptp(_colorbar._digit_rows(13)) + 1 > 7  # the 13-pixel font's digit
    assert (strip_rows.min(), strip_rows.max()) == (digit_rows.min(), digit_rows.max())


def test_text_without_freetype_falls_back_to_the_bitmap_font(monkeypatch):
    monkeypatch.setattr(_colorbar, "_freetype", lambda px: None)
    assert _colorbar._label_px((480, 360)) is None
    scene = still_scene([[0.0, 0.0], [1.0, 1.0]], v=[[1.0, 0.0], [0.0, 1.0]])
    img = next(iter(render.frames(scene, frames=1, size=(480, 360), title="Two balls")))
    bitmap = _colorbar._text_mask("Two balls")
    assert bitmap.shape[0] == 11
    assert np.array_equal(mask_of(img[3:14, 4 : 4 + bitmap.shape[1]], TEXT), bitmap)


def test_accents_and_other_scripts_do_not_raise():
    """The FreeType font has ASCII and a few more: accents are dropped (É draws as E), other
    characters as "?"; nothing raises, in a mask or a whole title."""
    assert np.array_equal(_colorbar._text_mask("Émile", 13), _colorbar._text_mask("Emile", 13))
    assert np.array_equal(_colorbar._text_mask("σ = 10", 13), _colorbar._text_mask("? = 10", 13))
    assert _colorbar._text_mask("Straße ±1 °C", 13).shape[0] == _colorbar._text_mask("0", 13).shape[0]
    scene = still_scene([[0.0, 0.0], [1.0, 1.0]])
    img = next(iter(render.frames(scene, frames=1, size=(480, 360), title="σ = 10, ρ = 28 — Émile")))
    assert mask_of(img[:20, :200], TEXT).sum() > 50


# ------------------------------------------------------------------------------------ CLI
def test_cli_camera_and_arrows(tmp_path, capsys):
    """--camera follow:0 --arrows velocity draws the arrows (the recording keeps velocities
    for them); --camera orbit on a 2D scene, or a bad mode, is one line on stderr and exit 2,
    before anything is written."""
    from physcore.cli import main

    out = tmp_path / "p.gif"
    args = ["render", "projectile", "-o", str(out), "--param", "n=1", "--frames", "3", "--size", "160x120", "-q"]
    assert main(args + ["--camera", "follow:0", "--arrows", "velocity"]) == 0
    from PIL import Image

    with Image.open(out) as im:
        assert mask_of(np.asarray(im.convert("RGB")), ARROW).sum() > 5
    capsys.readouterr()
    for bad in (["--camera", "orbit"], ["--camera", "follow:3"], ["--camera", "pan"], ["--arrows", "force"]):
        out.unlink(missing_ok=True)
        assert main(args + bad) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) >= 1 and ("camera" in err[-1] or "arrows" in err[-1]) and "Traceback" not in err[-1]
        assert not out.exists()
