"""Colour that serves the picture: per-particle colours (``colors=``), named colour maps
(``cmap=``) and a background of one's own (``background=``), in discs and in the glow."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc
from physcore.render import _palette


def _two_balls(separation: float = 4.0) -> pc.Scene:
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.0], [separation, 0.0]], masses=1.0)
    return s


def _pixel_at(img: np.ndarray, scene_x: float, xs: tuple[float, float]) -> np.ndarray:
    """The RGB at the image row through the particles' centre, at the column of `scene_x`
    between the two particles' columns (found as the extreme non-background columns)."""
    bg = img[0, 0]
    mask = (img != bg).any(axis=2)
    rows, cols = np.nonzero(mask[: int(img.shape[0] * 0.8)])  # above the clock and scale bar
    r = int(np.median(rows))
    c0, c1 = cols.min(), cols.max()
    frac = (scene_x - xs[0]) / (xs[1] - xs[0])
    return img[r, int(round(c0 + 4 + frac * (c1 - c0 - 8)))]


def test_each_particle_is_drawn_in_its_own_colour():
    s = _two_balls()
    img = next(pc.render.frames(s, frames=1, size=(200, 120), radius=6, color_by="none", colors=["#d62728", "#1f77b4"]))
    np.testing.assert_array_equal(_pixel_at(img, 0.0, (0.0, 4.0)), [0xD6, 0x27, 0x28])
    np.testing.assert_array_equal(_pixel_at(img, 4.0, (0.0, 4.0)), [0x1F, 0x77, 0xB4])


def test_colors_forms_agree():
    s = _two_balls()
    opts = dict(frames=1, size=(200, 120), radius=6, color_by="none")
    as_text = next(pc.render.frames(s, colors=["#ff7f0e", "#2ca02c"], **opts))
    as_ints = next(pc.render.frames(s, colors=np.array([[255, 127, 14], [44, 160, 44]], np.uint8), **opts))
    as_floats = next(pc.render.frames(s, colors=np.array([[255, 127, 14], [44, 160, 44]]) / 255.0, **opts))
    as_groups = next(pc.render.frames(s, colors=[1, 2], **opts))  # tab10's orange and green
    np.testing.assert_array_equal(as_text, as_ints)
    np.testing.assert_array_equal(as_text, as_floats)
    np.testing.assert_array_equal(as_text, as_groups)


def test_colors_give_way_to_a_coloured_quantity():
    # color_by="speed" shows the speed: own colours are for bodies read as objects.
    s = _two_balls()
    s.velocities = [[1.0, 0.0], [0.0, 0.0]]
    opts = dict(frames=1, size=(200, 120), radius=6, color_by="speed", antialias=True)
    with_colors = next(pc.render.frames(s, colors=["#ff0000", "#00ff00"], **opts))
    without = next(pc.render.frames(s, **opts))
    np.testing.assert_array_equal(with_colors, without)


def test_glow_takes_each_particles_colour():
    # Two clouds glowing: the blue cloud's pixels are blue-dominant, the gold one's red-dominant.
    rng = np.random.default_rng(0)
    a = rng.normal(size=(400, 2)) * 0.3
    b = rng.normal(size=(400, 2)) * 0.3 + [4.0, 0.0]
    s = pc.Scene(2)
    s.add_particles(np.concatenate([a, b]), masses=1.0)
    colors = np.repeat(np.array([[90, 150, 255], [255, 180, 60]], np.uint8), 400, axis=0)
    img = next(pc.render.frames(s, frames=1, size=(240, 120), color_by="density", theme="dark", colors=colors)).astype(int)
    top = img[: int(0.75 * img.shape[0])]  # above the clock and scale bar
    lit = top.sum(axis=2) > top[0, 0].sum() + 150
    half = np.arange(top.shape[1]) < top.shape[1] // 2
    blue, gold = top[lit & half].mean(axis=0), top[lit & ~half].mean(axis=0)
    assert blue[2] > blue[0] and gold[0] > gold[2]


def test_cmap_replaces_the_speed_map():
    pal = _palette.styled_palette("dark", "magma")
    np.testing.assert_array_equal(pal[_palette._SPEED0], [0, 0, 4])  # magma's first stop
    np.testing.assert_array_equal(pal[_palette._SPEED0 + _palette._N_SPEED - 1], [252, 253, 191])  # its last
    assert set(pc.render.CMAPS) >= {"viridis", "magma", "inferno", "plasma", "cividis", "turbo", "ice"}
    s = _two_balls()
    s.velocities = [[1.0, 0.0], [0.0, 0.0]]
    opts = dict(frames=1, size=(200, 120), radius=6, color_by="speed")
    assert not np.array_equal(next(pc.render.frames(s, cmap="magma", **opts)), next(pc.render.frames(s, **opts)))


def test_background_colours_the_image():
    img = next(pc.render.frames(_two_balls(), frames=1, size=(200, 120), color_by="none", background=(28, 110, 60)))
    np.testing.assert_array_equal(img[2, 100], [28, 110, 60])


@pytest.mark.parametrize(
    "options, error, name",
    [
        ({"colors": [[255, 0, 0]]}, ValueError, "colors"),  # one colour for two particles
        ({"colors": [[300, 0, 0], [0, 0, 0]]}, ValueError, "colors"),
        ({"colors": [[0.5, np.nan, 0], [0, 0, 0]]}, ValueError, "colors"),
        ({"colors": ["red", "blue"]}, ValueError, "colors"),
        ({"colors": [True, False]}, TypeError, "colors"),
        ({"colors": [-1, 0]}, ValueError, "colors"),
        ({"colors": "red"}, TypeError, "colors"),
        ({"cmap": "jet"}, ValueError, "cmap"),
        ({"cmap": 3}, TypeError, "cmap"),
        ({"background": (0, 0, 256)}, ValueError, "background"),
        ({"background": (0, 0)}, ValueError, "background"),
    ],
)
def test_bad_colours_are_refused_before_stepping(tmp_path, options, error, name):
    s = _two_balls()
    s.velocities = [[1.0, 0.0], [0.0, 0.0]]
    with pytest.raises(error, match=name):
        pc.render.gif(s, tmp_path / "x.gif", frames=3, **options)
    assert s.time == 0.0 and not (tmp_path / "x.gif").exists()


def _block(n: int = 40, spacing: float = 0.05) -> pc.Scene:
    g = np.arange(n) * spacing
    x = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    s = pc.Scene(2)
    s.add_particles(x, masses=1.0)
    return s


def test_surface_closes_the_gaps_between_particles():
    # A 40 × 40 lattice drawn 4 pixels apart: as discs of radius 1 the background shows between
    # them; as a surface the interior is filled, with no background pixel inside the block.
    s = _block()
    opts = dict(frames=1, size=(240, 240), color_by="none", colorbar=False)
    discs = next(pc.render.frames(s, radius=1, **opts))
    surf = next(pc.render.frames(s, surface=True, **opts))
    bg = surf[0, 0]
    mask = (surf != bg).any(axis=2)
    rows, cols = np.nonzero(mask[: int(0.8 * mask.shape[0])])
    r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
    inner = (slice(r0 + 4, r1 - 3), slice(c0 + 4, c1 - 3))
    assert mask[inner].all()
    assert not (discs[inner] != discs[0, 0]).any(axis=2).all()


def test_surface_draws_spray_as_a_mist_and_leaves_out_a_lone_particle():
    # Issue 65: spray read as specks. A jet of particles two spacings apart (two others each
    # within two spacings) is drawn as one soft streak; a particle alone is not drawn; the
    # block's interior stays filled.
    block = _block()
    jet = np.stack([np.full(17, 2.4), np.linspace(0.2, 1.8, 17)], axis=1)
    lone = np.array([[2.9, 1.0]])
    s = pc.Scene(2)
    s.add_particles(np.concatenate([block.positions, jet, lone]), masses=1.0)
    img = next(pc.render.frames(s, surface=True, frames=1, size=(300, 200), color_by="none", colorbar=False))
    bg = img[0, 0]
    mask = (img != bg).any(axis=2)
    mask[-20:] = False  # the clock and the scale bar
    rows, cols = np.nonzero(mask)
    r0, r1, c0 = rows.min(), rows.max(), cols.min()  # the block's top, bottom and left
    px = (r1 - r0) / 1.95  # pixels a metre
    c1 = int(round(c0 + 1.95 * px))
    assert mask[r0 + 4 : r1 - 3, c0 + 4 : c1 - 3].all()

    def col(x: float) -> int:
        return int(round(c0 + x * px))

    def row(y: float) -> int:
        return int(round(r1 - y * px))

    streak = mask[row(1.6) : row(0.4), col(2.4) - 2 : col(2.4) + 3].any(axis=1)
    assert streak.mean() > 0.9  # drawn along the jet, without gaps
    assert not mask[row(1.0) - 5 : row(1.0) + 6, col(2.9) - 5 : col(2.9) + 6].any()  # the lone one: nothing
    # A mist, fainter than the surface: no streak pixel is as far from the background as the block.
    far = np.abs(img.astype(int) - bg.astype(int)).sum(axis=2)
    assert far[row(1.6) : row(0.4), col(2.4) - 2 : col(2.4) + 3].max() < far[(r0 + r1) // 2, (c0 + c1) // 2]


def test_surface_colours_by_the_local_mean_speed():
    # Left half at rest, right half moving: the surface's colour follows the speed map.
    s = _block()
    v = np.zeros((s.n_particles, 2))
    v[s.positions[:, 0] > 1.0, 0] = 1.0
    s.velocities = v
    img = next(pc.render.frames(s, surface=True, frames=1, size=(240, 240), color_by="speed", colorbar=False))
    pal = _palette.styled_palette("light")
    row = img[img.shape[0] // 2]
    slow, fast = pal[_palette._SPEED0], pal[_palette._SPEED0 + _palette._N_SPEED - 1]
    left, right = row[img.shape[1] // 3].astype(int), row[2 * img.shape[1] // 3].astype(int)
    assert np.abs(left - slow).sum() < np.abs(left - fast).sum()
    assert np.abs(right - fast).sum() < np.abs(right - slow).sum()


def test_a_shaded_surface_takes_the_particles_colours():
    # The cloth's sheet in its particles' own colour: blue-dominant pixels where the plain
    # fabric (a warm red) shows none.
    s = pc.scenes.cloth(n=8)
    # The plain fabric on white, fitted to the sheet, from the default view (the scene's own
    # is a blue gingham in a room, seen from low down).
    s.render_defaults = {k: v for k, v in s.render_defaults.items() if k not in ("look", "texture", "view", "extent")}
    blue = np.tile(np.array([[30, 60, 220]], np.uint8), (s.n_particles, 1))

    def bluish(img: np.ndarray) -> float:
        img = img.astype(int)
        return float(((img != img[0, 0]).any(axis=2) & (img[..., 2] > img[..., 0] + 60)).mean())

    opts = dict(frames=1, size=(160, 120), color_by="none")
    assert bluish(next(pc.render.frames(s, colors=blue, **opts))) > 0.05
    assert bluish(next(pc.render.frames(s, **opts))) == 0.0


def test_the_back_of_a_white_texture_stays_neutral():
    # A white texture seen from behind (from below the flat sheet) is a darker grey, not tinted
    # towards the fabric's back: it read salmon pink (R − B = 23 on every pixel), now R = G = B.
    white = np.full((2, 2, 3), 255, np.uint8)
    s = pc.scenes.cloth(n=12)
    img = next(pc.render.frames(s, frames=1, size=(160, 120), texture=white, view=(-60, -25), look=pc.render.Look())).astype(int)
    sheet = (img != img[0, 0]).any(axis=2)
    pinned = np.abs(img - [255, 127, 14]).sum(axis=2) < 200  # the orange discs of the pinned edge
    tint = np.abs(img[..., 0] - img[..., 2])[sheet & ~pinned]
    assert tint.size > 1000 and np.percentile(tint, 90) <= 2


def test_glow_trails_are_continuous_streaks():
    # One particle crossing the image at ~10 pixels a frame, drawn as glow with a trail: the
    # history is a continuous streak along its path, not one dot a frame.
    s = pc.Scene(2, dt=0.01)
    s.add_particles([[0.0, 0.0], [20.0, 0.0]], masses=1.0)  # the second, at rest, widens the view
    s.velocities = [[10.0, 0.0], [0.0, 0.0]]
    frames = list(pc.render.frames(s, frames=10, steps_per_frame=10, size=(240, 80), color_by="density",
                                   trail=10, theme="dark", colorbar=False))
    last = frames[-1].astype(int).sum(axis=2)
    row = last[np.argmax(last.max(axis=1))]
    path = row[: int(0.4 * row.size)]  # x from 0 to 8 m of the 0–20 m view: the path so far
    lit = np.flatnonzero(path > last[0, 0] + 30)
    assert lit.size > 60  # the streak spans the path
    assert np.diff(lit).max() == 1  # without a gap (one dot a frame left gaps of ~10 px)


def test_extent_fixes_the_view_and_is_checked_before_stepping(tmp_path):
    # A box around the first particle only: the second, 20 m away, is out of the picture.
    s = pc.Scene(2, dt=0.01)
    s.add_particles([[0.0, 0.0], [20.0, 0.0]], masses=1.0)
    opts = dict(frames=1, size=(200, 100), colorbar=False, color_by="none", radius=4)
    fitted = next(pc.render.frames(s, extent=([-1, -1], [1, 1]), **opts))
    assert (fitted != fitted[0, 0]).any(axis=2)[:60, 150:].sum() == 0  # nothing right of the first one's box (above the scale bar)
    whole = next(pc.render.frames(s, **opts))
    assert (whole != whole[0, 0]).any(axis=2)[:60, 150:].sum() > 0  # the second particle, fitted in
    for bad in ([1.0, 2.0], ([0, 0], [-1, 1]), ([0, np.nan], [1, 1])):
        with pytest.raises(ValueError, match="extent"):
            pc.render.gif(s, tmp_path / "x.gif", frames=3, extent=bad)
    assert s.time == 0.0


def test_halo_in_an_own_colour_glow_is_a_bright_core_at_its_particle():
    """color_by="density" with colours: a halo particle (a galaxy's central mass inside the
    stars' ring) shines as a whitened core where the glow alone left the ring's dark hole."""
    rng = np.random.default_rng(1)
    r = np.sqrt(rng.uniform(0.3**2, 1.0, 3000))  # a ring of stars round an empty centre
    phi = rng.uniform(0, 2 * np.pi, 3000)
    x = np.concatenate([[[0.0, 0.0]], np.stack([r * np.cos(phi), r * np.sin(phi)], 1)])
    s = pc.Scene(2)
    s.add_particles(x)
    opts = dict(frames=1, size=(200, 200), radius=0, color_by="density", colors=["#6080ff"] * len(x), theme="dark",
                colorbar=False)
    plain = next(pc.render.frames(s, **opts)).astype(int)
    core = next(pc.render.frames(s, halo=[0], **opts)).astype(int)
    ring_r, ring_c = np.nonzero(plain.sum(axis=2) > plain[0, 0].sum() + 60)  # the ring's pixels
    r0, c0 = int(round(ring_r.mean())), int(round(ring_c.mean()))  # its centre
    rows, cols = np.nonzero(np.abs(core - plain).sum(axis=2) > 10)
    assert rows.size and abs(rows.mean() - r0) < 2 and abs(cols.mean() - c0) < 2  # at the centre only
    assert np.ptp(rows) < 0.5 * np.ptp(ring_r)  # inside the ring
    assert core[r0, c0].min() > 170 and (core[r0, c0] - plain[r0, c0]).min() > 60  # whitened, where it was dim


def test_halo_glows_around_its_particle_only(tmp_path):
    s = _two_balls()
    opts = dict(frames=1, size=(200, 120), radius=6, color_by="none", colors=["#ffd000", "#0060ff"], theme="dark",
                colorbar=False, antialias=True)
    plain = next(pc.render.frames(s, **opts)).astype(int)
    glow = next(pc.render.frames(s, halo=[0], **opts)).astype(int)
    diff = np.abs(glow - plain).sum(axis=2)
    lit = np.nonzero(diff > 10)
    # Around the first (yellow) ball only: the halo's pixels are left of the image's middle,
    # reach beyond its disc (6 px), and are tinted yellow (red and green over blue).
    assert lit[1].size and lit[1].max() < 100 and np.ptp(lit[1]) > 2 * 6 + 4
    tint = (glow - plain)[lit]
    assert (tint[:, 0] > tint[:, 2]).mean() > 0.9
    with pytest.raises(ValueError, match="halo"):
        pc.render.gif(s, tmp_path / "x.gif", frames=2, halo=[5])
    with pytest.raises(TypeError, match="halo"):
        pc.render.gif(s, tmp_path / "x.gif", frames=2, halo=[0.5])
    assert s.time == 0.0


def test_loop_runs_the_trail_on_from_the_end():
    # A bob on a circle (a zero-length spring to a pinned centre: an isotropic oscillator, one
    # period over the recording): with loop the first frame already shows the trail that the
    # last frames drew; without it the first frame has none.
    s = pc.Scene(2, dt=1e-3)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 1.0]], masses=1.0, pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=1.0, rest_length=0.0))  # ω = 1: the period is 2π
    rec = pc.render.record(s, frames=60, frame_time=2 * np.pi / 60)
    opts = dict(size=(320, 320), trail=20, color_by="none", colors=["#808080", "#ff4000"], springs=False, colorbar=False)
    first = next(iter(pc.render.frames(rec, loop=True, **opts))).astype(int)
    plain = next(iter(pc.render.frames(rec, **opts))).astype(int)
    trail_px = lambda img: int(((img - img[0, 0]) != 0).any(axis=2)[:260].sum())  # noqa: E731 - above the labels
    assert trail_px(first) > trail_px(plain) + 200  # a third of the circle, 2 px wide
    with pytest.raises(TypeError, match="loop"):
        pc.render.gif(rec, "x.gif", loop="yes")


def test_a_scenes_loop_default_holds_only_where_its_frames_close_the_period():
    # The figure-eight loops by default (one period in 150 frames of 14 steps). In 60 frames the
    # recording ends 40 % round: a loop would join its last positions to its first with chords
    # across the picture, so the default gives way; loop=True given still loops.
    opts = dict(size=(280, 150), trail=50, antialias=False, colorbar=False)
    trail_px = lambda img: int(((img - img[0, 0]) != 0).any(axis=2)[:125].sum())  # noqa: E731 - above the labels
    dot = trail_px(next(iter(pc.render.frames(pc.scenes.figure_eight(), frames=1, **opts))).astype(int))
    whole = trail_px(next(iter(pc.render.frames(pc.scenes.figure_eight(), **opts))).astype(int))
    cut = trail_px(next(iter(pc.render.frames(pc.scenes.figure_eight(), frames=60, **opts))).astype(int))
    forced = trail_px(next(iter(pc.render.frames(pc.scenes.figure_eight(), frames=60, loop=True, **opts))).astype(int))
    assert whole > dot + 200  # the default: frame 0 shows the trails run on from the end
    assert cut == dot  # 60 frames: no loop, frame 0 shows the bodies alone
    assert forced > dot + 200


def test_the_colour_bar_stays_over_a_particle_that_passes_under_it():
    # A scene's extent can let spray fly up into the colour bar's band (the crown's droplet
    # hid "2 m/s"): the labels are pasted over every frame, the still camera's too.
    def top_right(corner: list[float]) -> np.ndarray:
        s = pc.Scene(2)
        s.add_particles([[0.0, 0.0], corner], [[1.0, 0.0], [0.0, 0.0]])
        f = next(iter(pc.render.frames(s, frames=1, steps_per_frame=1, size=(240, 160), radius=12, color_by="speed",
                                       extent=((0.0, 0.0), (1.0, 1.0)), antialias=False)))
        return f[:24, 120:].astype(int)

    under, away = top_right([0.97, 1.08]), top_right([0.5, 0.5])  # past the extent, as spray flies
    ink = (away != 255).any(axis=2)  # the bar and its labels
    assert ink.sum() > 200 and (under != away).any()  # the disc is there, beside them
    assert np.array_equal(under[ink], away[ink])


def test_a_decompression_bomb_texture_is_refused_by_name(tmp_path, monkeypatch):
    # A PNG whose header claims more pixels than Pillow's bomb limit: one clear error naming
    # texture, at the CLI one line with exit code 2 (issue 44 item 9: a 20-line traceback).
    import subprocess
    import sys

    from PIL import Image

    bomb = tmp_path / "bomb.png"
    Image.new("RGB", (4000, 4000)).save(bomb)  # 16 Mpx: over a limit of 1 Mpx set below
    code = (
        "import sys; from PIL import Image; Image.MAX_IMAGE_PIXELS = 500_000;"
        "from physcore.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    out = subprocess.run([sys.executable, "-c", code, "render", "cloth", "--param", "n=6", "--frames", "2",
                          "--texture", str(bomb), "-o", str(tmp_path / "x.gif")], capture_output=True, text=True)
    assert out.returncode == 2 and "texture" in out.stderr and "Traceback" not in out.stderr, out.stderr
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 500_000)
    with pytest.raises(ValueError, match="texture"):
        pc.render.gif(pc.scenes.cloth(n=6), tmp_path / "y.gif", frames=2, texture=bomb)


def _ball3(radius: float = 1.0, spacing: float = 0.1) -> pc.Scene:
    g = np.arange(-radius, radius + 1e-9, spacing)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    s = pc.Scene(3)
    s.add_particles(x[np.linalg.norm(x, axis=1) <= radius], masses=1.0)
    return s


def test_a_3d_liquid_surface_is_lit_from_the_upper_left():
    # Issue 66: the 3D surface was the projected density in one flat colour. Lit as the nearest
    # spheres' smoothed depth (screen-space fluid rendering), a ball of particles is a closed
    # disc, brighter towards the key light (upper left, front) than away from it, with its
    # highlight in the upper-left quadrant.
    img = next(pc.render.frames(_ball3(), surface=True, frames=1, size=(240, 240), color_by="none", colorbar=False))
    bg = img[0, 0]
    mask = (img != bg).any(axis=2)
    mask[-24:] = False  # the clock and the scale bar
    rows, cols = np.nonzero(mask)
    rc, cc = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
    rad = (rows.max() - rows.min()) / 2
    assert abs((cols.max() - cols.min()) / 2 - rad) < 0.1 * rad  # a disc
    yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
    inner = (yy - rc) ** 2 + (xx - cc) ** 2 < (0.85 * rad) ** 2
    assert mask[inner].all()  # closed: no background inside
    light = img.astype(float).sum(axis=2)
    upper_left = inner & (yy < rc) & (xx < cc)
    lower_right = inner & (yy > rc) & (xx > cc)
    assert light[upper_left].mean() > light[lower_right].mean() + 60  # of 765
    top = np.unravel_index(np.argmax(np.where(inner, light, -1)), light.shape)
    assert top[0] < rc and top[1] < cc


def test_a_3d_tank_is_drawn_as_glass_without_a_stipple():
    # The 3D dam break's walls as discs beat with the pixel grid (a moiré stipple); as glass a
    # wall seen face on is an even tint. The patch is above the water, inside the tank.
    s = pc.scenes.dam_break(dim=3, n=8)
    opts = dict(frames=1, size=(320, 240), colorbar=False)
    glass = next(pc.render.frames(s, **opts)).astype(float).sum(axis=2)
    discs = next(pc.render.frames(s, surface=False, **opts)).astype(float).sum(axis=2)
    mask = (np.abs(glass - glass[0, 0]) > 0)[: int(0.8 * glass.shape[0])]
    rows, cols = np.nonzero(mask)
    r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
    top, mid = r0 + int(0.3 * (r1 - r0)), (c0 + c1) // 2  # the back wall, right of the column
    patch = (slice(top, top + 20), slice(mid, mid + 30))

    def grain(img: np.ndarray) -> float:  # the mean step between neighbouring pixels, of 765
        p = img[patch]
        return float(np.abs(np.diff(p, axis=0)).mean() + np.abs(np.diff(p, axis=1)).mean())

    assert grain(glass) < 2.0  # smooth (a gradient at most)
    assert glass[0, 0] - glass[patch].mean() > 10.0  # tinted
    assert grain(discs) > 10 * grain(glass)  # what it replaces


def _circling_scene(dt: float = 1e-3) -> pc.Scene:
    """A bob on a circle of radius 1 about a pinned centre (a zero-length spring, ω = 1:
    uniform circular motion)."""
    s = pc.Scene(2, dt=dt)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 1.0]], masses=1.0, pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=1.0, rest_length=0.0))
    return s


def _circling(frames_per_turn: int, turns: float = 1.0, velocities: bool = True) -> pc.render.Recording:
    """:func:`_circling_scene` recorded `frames_per_turn` frames a period, its positions (and
    with `velocities` its velocities) those of the exact circle."""
    rec = pc.render.record(_circling_scene(), frames=int(frames_per_turn * turns) + 1, frame_time=2 * np.pi / frames_per_turn)
    # The integrator's orbit is a near circle (0.9 % eccentric at dt = 1e-3): the exact one.
    th = 2 * np.pi * np.arange(rec.frames) / frames_per_turn
    centre = rec.positions[0, 0].astype(np.float64)
    x = np.zeros((rec.frames, 2, 2))
    x[:, 0] = centre
    x[:, 1] = centre + np.stack([np.cos(th), np.sin(th)], axis=1)
    v = np.zeros_like(x)
    v[:, 1] = np.stack([-np.sin(th), np.cos(th)], axis=1)
    return rec._replace(positions=x.astype(np.float32), velocities=v.astype(np.float32) if velocities else None)


def _rasteriser(rec: pc.render.Recording, **kw):
    from physcore.render._look import check_look
    from physcore.render._raster import _Rasteriser

    look = check_look(kw.pop("look", None))
    return _Rasteriser(rec, (320, 320), kw.pop("color_by", "none"), 2, (0.0, 0.0), look=look, **kw)


def _off_circle(rec: pc.render.Recording, ras, cs: np.ndarray, rs: np.ndarray) -> tuple[np.ndarray, float]:
    """|distance from the circle's centre (particle 0) / radius − 1| of pixel points, and the
    radius in pixels (the bob's distance in frame 0)."""
    (cc, cb), (rc, rb) = ras.cam.pixels(ras.cam.project(rec.positions[0])[0])
    radius = float(np.hypot(cb - cc, rb - rc))
    return np.abs(np.hypot(cs - cc, rs - rc) / radius - 1.0), radius


def test_trail_samples_follow_the_hermite_curve_not_the_chord():
    # Eight frames a turn: a chord strays 7.6 % of the radius inside the circle at its middle
    # (1 − cos 22.5°); the Hermite curve of the positions and velocities at its ends stays
    # within 0.1 %, and that of Catmull–Rom tangents (a recording without velocities) within 1.5 %.
    for velocities, tol in ((True, 1e-3), (False, 1.5e-2)):
        rec = _circling(8, velocities=velocities)
        ras = _rasteriser(rec, trail=8, look={"trail_samples": 8})
        cs, rs = ras._sub_pixels(2, ras.cam)
        assert cs.shape == (9, 2)
        off, radius = _off_circle(rec, ras, cs[:, 1], rs[:, 1])
        mid, _ = _off_circle(rec, ras, 0.5 * (cs[[0, -1], 1]), 0.5 * (rs[[0, -1], 1]))
        assert mid[0] > 0.07 and radius > 80
        assert off.max() < tol, (velocities, off.max())
    # Drawn: 8 pieces a step put the trail's pixels on the circle, 1 a step on the chords.
    rec = _circling(8)
    ras = _rasteriser(rec, trail=8)
    opts = dict(size=(320, 320), trail=8, color_by="none", colors=["#808080", "#ff4000"], springs=False, colorbar=False,
                antialias=False, radius=2)

    def sag(samples: int) -> float:
        img = list(pc.render.frames(rec, look={"trail_samples": samples}, **opts))[-1].astype(int)
        drawn = np.abs(img - img[0, 0]).sum(axis=2) > 30
        drawn[-40:] = False  # the clock and the scale bar
        rows, cols = np.nonzero(drawn)
        dot_r, dot_c = np.nonzero(np.abs(img - 128).sum(axis=2) < 10)  # the centre, a grey disc
        d = np.hypot(rows - dot_r.mean(), cols - dot_c.mean())
        d = d[d > 20]
        return float(np.ptp(np.percentile(d, [3, 97])) / np.median(d))  # the spread of the radius

    assert sag(8) < 0.03 < 0.5 * sag(1)


def test_trail_samples_default_leaves_the_trail_as_it_was():
    from physcore.render import Look

    assert Look().trail_samples == 1
    rec = _circling(12, 0.75)
    opts = dict(size=(160, 160), trail=6, color_by="none", colors=["#808080", "#ff4000"], colorbar=False)
    for extra in ({"antialias": False}, {"look": {"trail_fade": 0.0, "trail_width": 3}}):
        look = extra.get("look", {})
        rest = {k: v for k, v in extra.items() if k != "look"}
        base = list(pc.render.frames(rec, look=look, **rest, **opts))
        same = list(pc.render.frames(rec, look={**look, "trail_samples": 1}, **rest, **opts))
        curved = list(pc.render.frames(rec, look={**look, "trail_samples": 8}, **rest, **opts))
        assert all(np.array_equal(a, b) for a, b in zip(base, same, strict=True))
        assert not np.array_equal(base[-1], curved[-1])


def test_trail_samples_have_the_velocities_recorded_for_them():
    # Simulating a scene to draw it, gif() records the velocities when the trail is drawn as
    # look.trail_samples pieces a frame step, so they follow the true tangents, not Catmull–Rom's
    # from the neighbouring frames: at 45° a frame the drawn ring of the bob's path is as thin
    # as a recording with velocities draws it, well under what one without them draws.
    turn = 2 * np.pi
    dt = turn / 8 / 400  # whole steps a frame
    opts = dict(size=(320, 320), trail=8, color_by="none", colors=["#808080", "#ff4000"], springs=False, colorbar=False,
                antialias=False, radius=2, look={"trail_samples": 8})
    drawn = list(pc.render.frames(_circling_scene(dt), frames=9, frame_time=turn / 8, **opts))[-1]

    def recorded(velocities: bool) -> np.ndarray:
        rec = pc.render.record(_circling_scene(dt), frames=9, frame_time=turn / 8, velocities=velocities)
        assert (rec.velocities is not None) == velocities
        return list(pc.render.frames(rec, **opts))[-1]

    def ring(img: np.ndarray) -> float:  # the 90th percentile of the trail pixels' distances off the ring
        drawn = np.abs(img.astype(int) - img[0, 0]).sum(axis=2) > 30
        drawn[-40:] = False  # the clock and the scale bar
        rows, cols = np.nonzero(drawn)
        dot_r, dot_c = np.nonzero(np.abs(img.astype(int) - 128).sum(axis=2) < 10)  # the centre, a grey disc
        d = np.hypot(rows - dot_r.mean(), cols - dot_c.mean())
        d = d[d > 20]
        return float(np.percentile(np.abs(d - np.median(d)), 90))

    with_v, without = recorded(True), recorded(False)
    assert np.array_equal(drawn, with_v)
    assert not np.array_equal(drawn, without)
    assert ring(drawn) < 2.0 and ring(drawn) < 0.6 * ring(without)
    # record() asks for them as gif() does: a trail of trail_samples pieces (none without a trail).
    for defaults, wanted in (({"trail": 8, "look": {"trail_samples": 8}}, True), ({"trail": 8, "look": {"trail_samples": 1}}, False),
                             ({"trail": 0, "look": {"trail_samples": 8}}, False), ({"trail": 8}, False)):
        s = _circling_scene()
        s.render_defaults = defaults
        assert (pc.render.record(s, frames=2, frame_time=0.01).velocities is not None) == wanted, defaults


@pytest.mark.parametrize("bad, err", [(0, ValueError), (65, ValueError), (2.5, TypeError), (True, TypeError), ("8", TypeError)])
def test_trail_samples_is_checked_naming_it(tmp_path, bad, err):
    s = _two_balls()
    path = tmp_path / "x.gif"
    with pytest.raises(err, match="trail_samples") as info:
        pc.render.gif(s, path, frames=2, size=(64, 48), trail=2, look={"trail_samples": bad})
    assert isinstance(info.value, pc.PhyscoreError)
    assert not path.exists() and s.time == 0.0


def test_glow_trails_follow_curves_and_fade_without_seams():
    # A glowing point going round a circle at 45° a frame (about 90 px a step, a recording
    # without velocities): its glow's path is sampled on the curve through the frames (a
    # chord's middle sags 7.6 % of the radius inside the circle), densely (no gap), and its
    # weight falls off with age continuously, across each frame's end too (no seam).
    rec = _circling(8, velocities=False)
    ras = _rasteriser(rec, trail=4, color_by="density")
    decay = 0.05 ** (1 / 4)
    c2, r2, w2, o2 = ras._streak(2)
    c3, r3, w3, o3 = ras._streak(3)
    for c, r in ((c2, r2), (c3, r3)):
        off, radius = _off_circle(rec, ras, c, r)
        assert off.max() < 0.015 and radius > 80
        assert np.hypot(np.diff(c), np.diff(r)).max() < 1.0  # every 0.6 px along the path
    assert (o2 == 0).all() and np.all(np.diff(w2) > 0)  # brighter towards the bob, one particle
    # The start of frame 3's path is as bright as the end of frame 2's, one frame older.
    assert w3[0] == pytest.approx(decay * w2[-1], rel=0.02)
    # The first frame, with no history, shows the path on to the next frame, not a dot alone.
    c0, r0, w0, _ = ras._streak(0, True)
    assert c0.size > 100 and np.all(np.diff(w0) < 0)
    frames = list(pc.render.frames(rec, size=(320, 320), trail=4, color_by="density", theme="dark", colorbar=False))
    lit = lambda img: int((img.astype(int).sum(axis=2) > img[5, 5].astype(int).sum() + 60).sum())  # noqa: E731
    assert lit(frames[0]) > 0.5 * lit(frames[1])


def test_a_path_looping_once_a_frame_is_drawn_smooth_not_as_a_saw_tooth():
    # A bob circling (radius 1) at 0.97 turns a frame while drifting 3 a frame: at every frame it
    # is at about the same phase, so its velocities are near the same, off the chord by the
    # circling speed. A cubic through them zig-zags 0.6 off the drift line each frame
    # (pythagorean's escaping binary); those steps take Catmull-Rom's tangents, and the pieces
    # keep close to the drift line, while a resolved path (45° a frame) keeps its velocities.
    from physcore.render._raster import _hermite

    frames, w, drift = 12, 2 * np.pi * 0.97, 3.0
    k = np.arange(frames, dtype=np.float64)
    x = np.zeros((frames, 2, 2))
    x[:, 1] = np.stack([drift * k + np.cos(w * k), np.sin(w * k)], axis=1)
    v = np.zeros_like(x)
    v[:, 1] = np.stack([drift - w * np.sin(w * k), w * np.cos(w * k)], axis=1)  # per frame (times 1 s apart)
    rec = _circling(8, turns=(frames - 1) / 8)._replace(positions=x.astype(np.float32), velocities=v.astype(np.float32),
                                                        times=k)
    ras = _rasteriser(rec, trail=8, look={"trail_samples": 8})

    def at(g: int) -> np.ndarray:
        return rec.positions[g].astype(np.float64)

    def off_line(t0: np.ndarray, t1: np.ndarray, a: int) -> float:  # the pieces' largest distance off the chord
        s = np.linspace(0.0, 1.0, 9)[:, None, None]
        pts = _hermite(at(a), t0, at(a + 1), t1, s)[:, 1]
        p0, p1 = at(a)[1], at(a + 1)[1]
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        rel = pts - p0
        return float(np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]).max())

    for a in range(2, 8):
        t0, t1 = ras._tangents(a, a + 1, at, lambda g, h: rec.velocities[g].astype(np.float64) * h)
        raw = (v[a], v[a + 1])
        assert off_line(*raw, a) > 0.2  # the velocities' cubic strays off the line
        assert off_line(t0, t1, a) < 0.05  # Catmull-Rom's keeps to it
    resolved = _circling(8)
    ras = _rasteriser(resolved, trail=8, look={"trail_samples": 8})
    t0, t1 = ras._tangents(2, 3, lambda g: resolved.positions[g].astype(np.float64),
                           lambda g, h: resolved.velocities[g].astype(np.float64) * h)
    h = float(resolved.times[3] - resolved.times[2])
    np.testing.assert_allclose(t0[1], resolved.velocities[2, 1] * h, rtol=1e-6)
