"""gif(look=...): render.Look's checks and what each field draws; Kepler's swept areas are
equal (measured from the recorded motion)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore.render import Look, swept_polygons
from physcore.render._look import polygon_area, swept_path, width_offsets


def _ball(n: int = 1) -> pc.Scene:
    s = pc.Scene(2, dt=1e-3)
    s.add_particles([[float(i), 0.0] for i in range(n)], masses=1.0)
    return s


def test_kepler_wedges_sweep_equal_areas_in_equal_times():
    # The default Kepler render shades the areas swept in each sixth of a period (10 frames):
    # measured from the recorded positions and velocities (the path between frames as their
    # cubic Hermite curve), each is the same area, (Δt/P) π a b of the relative orbit, to 1e-4.
    scene = pc.scenes.kepler()
    sw = scene.render_defaults["look"]["swept_areas"]
    assert (sw["centre"], sw["body"], sw["frames"]) == (0, 1, 10)
    rec = pc.render.record(scene)
    assert rec.velocities is not None  # recorded for the swept areas
    polys = swept_polygons(rec, 0, 1, 10)
    assert len(polys) == (rec.frames - 1) // 10 == 11
    areas = np.array([polygon_area(p) for p in polys])
    e, a = 0.5, 1.0
    dt = float(rec.times[10] - rec.times[0])
    exact = dt / (2 * math.pi * math.sqrt(a**3)) * math.pi * a * a * math.sqrt(1 - e * e)
    assert np.abs(areas / exact - 1).max() < 3e-4, areas / exact  # measured 1.2e-4
    assert np.ptp(areas) / exact < 3e-4
    # Fat near perihelion, thin near aphelion: the shapes differ, the areas do not.
    turn = [abs(math.remainder(math.atan2(p[-1, 1], p[-1, 0]) - math.atan2(p[1, 1], p[1, 0]), 2 * math.pi)) for p in polys]
    assert max(turn) > 3 * min(turn), turn
    # The polygons run through the recorded relative positions at the wedges' boundaries.
    rel = (rec.positions[:, 1] - rec.positions[:, 0]).astype(np.float64)
    for j, p in enumerate(polys):
        np.testing.assert_allclose(p[1], rel[10 * j], atol=1e-6)
        np.testing.assert_allclose(p[-1], rel[10 * (j + 1)], atol=1e-6)
    # Straight chords between frames would be 0.8 % short: the curve is what makes them equal.
    chords = np.array([polygon_area(p) for p in swept_polygons(rec, 0, 1, 10, samples=1)])
    assert np.abs(chords / exact - 1).max() > 3e-3


def test_swept_path_without_velocities_follows_catmull_rom_tangents():
    rec = pc.render.record(pc.scenes.kepler(), velocities=False)
    assert rec.velocities is None
    areas = np.array([polygon_area(p) for p in swept_polygons(rec, 0, 1, 10)])
    assert np.ptp(areas) / areas.mean() < 2e-3  # measured 8e-4
    loop = swept_path(rec.positions, None, rec.times, 1, -3, 2, loop=True, samples=4)
    assert loop.shape == (5 * 4 + 1, 2)
    np.testing.assert_allclose(loop[0], rec.positions[-3, 1])


def test_kepler_frame_shows_the_wedges():
    rec = pc.render.record(pc.scenes.kepler())  # two whole orbits: it loops
    on = list(pc.render.frames(rec, size=(190, 160), radius=3))
    off = list(pc.render.frames(rec, size=(190, 160), radius=3, look={"swept_areas": None}))
    for k in (0, 25):  # frame 0 of the looping recording already shows the last orbit's wedges
        changed = np.abs(on[k].astype(int) - off[k].astype(int)).sum(axis=2) > 12
        assert changed.mean() > 0.2, (k, changed.mean())


def test_a_default_look_leaves_the_picture_as_it_was():
    rec = pc.render.record(pc.scenes.projectile(n=3), frames=6)
    base = list(pc.render.frames(rec, size=(96, 64)))
    for look in ({}, Look(), {"trail_fade": None}):
        again = list(pc.render.frames(rec, size=(96, 64), look=look))
        assert all(np.array_equal(a, b) for a, b in zip(base, again, strict=True))


def test_look_is_checked_naming_the_field(tmp_path):
    s = _ball(2)
    path = tmp_path / "x.gif"
    cases = [
        ({"trail_fad": 0.5}, ValueError, "trail_fad"),
        ("sphere", TypeError, "look"),
        ({"trail_fade": 1.5}, ValueError, "trail_fade"),
        ({"trail_width": 0}, ValueError, "trail_width"),
        ({"shading": "metal"}, ValueError, "shading"),
        ({"backdrop": [(0, 0, 0)]}, ValueError, "backdrop"),
        ({"decor": [{"polygon": [[0, 0], [1, 0]], "color": (1, 2, 3)}]}, ValueError, "decor"),
        ({"decor": [{"polygon": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "color": (1, 2, 3)}]}, ValueError, "decor"),
        ({"decor": [{"line": [[0, 0], [1, 0]]}]}, ValueError, "color"),
        ({"swept_areas": {"centre": 0, "body": 5, "frames": 2}}, ValueError, "swept_areas"),
        ({"swept_areas": {"centre": 0, "body": 0, "frames": 2}}, ValueError, "swept_areas"),
        ({"swept_areas": {"centre": 0, "frames": 2}}, ValueError, "body"),
    ]
    for look, err, word in cases:
        with pytest.raises(err, match=word):
            pc.render.gif(s, path, frames=2, size=(64, 48), look=look)
    assert not path.exists() and s.time == 0.0


def test_a_dict_changes_only_the_fields_it_names():
    kepler = pc.scenes.kepler()
    from physcore.render._look import check_look

    merged = check_look({"trail_width": 1}, kepler.render_defaults["look"])
    assert merged.trail_width == 1 and merged.trail_fade == 0.0 and merged.swept_areas["frames"] == 10
    assert check_look({"swept_areas": None}, kepler.render_defaults["look"]).swept_areas is None


def test_trail_fade_fades_the_oldest_end_to_nothing():
    s = pc.Scene(2, dt=1e-3)
    s.add_particles([[0.0, 0.0]], [[1.0, 0.0]], masses=1.0)
    rec = pc.render.record(s, frames=30, frame_time=0.02)
    opts = dict(size=(200, 60), trail=29, color_by="none", colors=["#ff3000"], colorbar=False, theme="dark", radius=3,
                antialias=True)
    classic = list(pc.render.frames(rec, **opts))[-1].astype(int)
    faded = list(pc.render.frames(rec, look={"trail_fade": 0.0, "trail_width": 3}, **opts))[-1].astype(int)
    bg = faded[2, 2]
    row = np.argmax((np.abs(faded - bg).sum(axis=2) > 3).sum(axis=1))  # the trail's middle row
    red = faded[row, :, 0] - bg[0]
    lit = np.flatnonzero(red > 3)
    # From nothing at the oldest end to nearly the full colour at the ball, rising all the way.
    tail, head = red[lit[:10]].mean(), red[lit[-20:-10]].mean()
    assert tail < 0.15 * (255 - bg[0]) and head > 0.6 * (255 - bg[0]), (tail, head)
    assert not np.array_equal(classic, faded)
    assert width_offsets(1) == ((0, 0),) and width_offsets(2) == ((0, 0), (1, 0), (0, 1)) and len(width_offsets(3)) == 5


def test_sphere_shading_lights_the_upper_left():
    s = _ball()
    opts = dict(frames=1, size=(80, 80), radius=24, color_by="none", colors=["#b0b0b0"], colorbar=False)
    flat = next(pc.render.frames(s, **opts)).astype(int)
    lit = next(pc.render.frames(s, look={"shading": "sphere"}, **opts)).astype(int)
    centre = np.argwhere((flat == [176, 176, 176]).all(axis=2)).mean(axis=0).round().astype(int)
    r, c = centre
    upper_left, lower_right = lit[r - 9, c - 7].sum(), lit[r + 12, c + 12].sum()
    assert upper_left > 3 * 250 and lower_right < 3 * 150, (upper_left, lower_right)  # a highlight; a shaded side


def test_backdrop_and_decor_are_drawn_behind_and_framed(tmp_path):
    s = _ball()
    decor = [{"polygon": [[-3.0, -1.0], [3.0, -1.0], [3.0, -0.8], [-3.0, -0.8]], "color": (200, 40, 40)}]
    opts = dict(frames=1, size=(160, 120), radius=4, color_by="none", colors=["#ffffff"], colorbar=False)
    img = next(pc.render.frames(s, look={"backdrop": ((0, 0, 100), (0, 100, 0)), "decor": decor}, **opts)).astype(int)
    top, bottom = img[1, 80], img[-1, 80]
    assert top[2] > 90 and top[1] < 10 and bottom[1] > 90 and bottom[2] < 10  # the gradient, top to bottom
    red = (img[..., 0] > 150) & (img[..., 1] < 80)
    cols = np.flatnonzero(red.any(axis=0))
    assert cols.size and cols.min() < 20 and cols.max() > 140  # the 6 m prop, framed whole
    rows = np.flatnonzero(red.any(axis=1))
    ball_row = np.argwhere((img == 255).all(axis=2))[:, 0].mean()
    assert rows.min() > ball_row  # below the ball, as placed


def test_thick_springs_are_coloured_by_strain_under_the_beads():
    s = pc.scenes.spring_chain(n=6)
    rec = pc.render.record(s, frames=12, color_by="strain")
    opts = dict(size=(240, 160), radius=0, colorbar=False)
    img = list(pc.render.frames(rec, look={"spring_width": 9}, **opts))[-1].astype(int)
    reddish = (img[..., 0] - img[..., 2] > 40)
    assert reddish.sum() > 200  # a stretched rope, 9 px wide
    thin = list(pc.render.frames(rec, look={"spring_width": None}, **opts))[-1].astype(int)
    assert (thin[..., 0] - thin[..., 2] > 40).sum() < 0.5 * reddish.sum()


def test_hulls_draw_a_body_of_grains_whole():
    # A 3 × 3 box of grains (radius 0.3 of their spacing, so gaps show between the discs): as a
    # hull it is one solid square out to the grains' outer edges, in its colour, and no wider.
    x = np.array([[i, j] for j in range(3) for i in range(3)], dtype=float)
    s = pc.Scene(2, dt=1e-3)
    s.add_particles(x, masses=1.0)
    s.set_attribute("radius", np.full(9, 0.3))
    opts = dict(frames=1, size=(200, 200), size_by="radius", color_by="none", colors=["#2060c0"] * 9, colorbar=False,
                antialias=True)
    discs = next(pc.render.frames(s, **opts)).astype(int)
    hull = next(pc.render.frames(s, look={"hulls": [list(range(9))]}, **opts)).astype(int)
    blue = lambda img: (img[..., 2] > 150) & (img[..., 0] < 100)  # noqa: E731
    r, c = np.argwhere(blue(hull)).T
    # Between two neighbouring grains' centres (gaps there among the discs, filled in the hull).
    mid_r, mid_c = int(round(r.mean())), int(round(c.mean()))
    span = c.max() - c.min()
    gap = (mid_r, mid_c - int(round(0.25 * span)))  # halfway from the middle grain to its left one
    assert blue(hull)[gap] and not blue(discs)[gap]
    # The hull reaches the grains' outer edges: 2 spacings + 2 radii across, as the discs do.
    rd, cd = np.argwhere(blue(discs)).T
    assert abs(span - (cd.max() - cd.min())) <= 2 and abs((r.max() - r.min()) - (rd.max() - rd.min())) <= 2
    assert blue(hull).sum() > 1.15 * blue(discs).sum()


def test_look_containers_of_the_wrong_kind_are_refused_naming_the_field(tmp_path):
    # A number for decor or hulls, an array for decor and dict keys that are not all strings
    # raised Python's own TypeError ("'int' object is not iterable", "'<' not supported")
    # or numpy's "truth value of an array is ambiguous", naming nothing.
    s = _ball(2)
    path = tmp_path / "x.gif"
    cases = [
        ({"decor": 5}, pc.InvalidTypeError, "look.decor"),
        ({"decor": 2.5}, pc.InvalidTypeError, "look.decor"),
        ({"decor": {"polygon": [[0, 0], [1, 0], [0, 1]], "color": (1, 2, 3)}}, pc.InvalidTypeError, "look.decor"),
        ({"decor": np.zeros((3, 2))}, pc.InvalidTypeError, r"look.decor\[0\]"),
        ({"hulls": 5}, pc.InvalidTypeError, "look.hulls"),
        ({"hulls": True}, pc.InvalidTypeError, "look.hulls"),
        ({1: 2, "trail_fad": 3}, pc.InvalidInputError, "unknown field"),
        ({"decor": [{1: 2, "polygon": [[0, 0], [1, 0], [0, 1]], "color": (1, 2, 3)}]}, pc.InvalidInputError, r"look.decor\[0\]"),
        ({"swept_areas": {1: 0, "body": 1, "frames": 1}}, pc.InvalidInputError, "swept_areas"),
        ({"decor": [{"line": ["a", "b"], "color": (1, 2, 3)}]}, pc.InvalidTypeError, r"look.decor\[0\].line"),
    ]
    for look, err, word in cases:
        with pytest.raises(err, match=word):
            pc.render.gif(s, path, frames=2, size=(64, 48), look=look)
    assert not path.exists() and s.time == 0.0
    pc.render.gif(s, path, frames=2, size=(64, 48), look={"hulls": np.array([[0, 1]]), "decor": []})
    assert path.exists()


def test_hulls_are_checked_naming_the_field(tmp_path):
    s = _ball(2)
    for look, err in (({"hulls": [[0, 5]]}, ValueError), ({"hulls": [[]]}, ValueError), ({"hulls": [[0.5]]}, ValueError)):
        with pytest.raises(err, match="hulls"):
            pc.render.gif(s, tmp_path / "x.gif", frames=2, size=(64, 48), look=look)
    s3 = pc.Scene(3, dt=1e-3)
    s3.add_particles([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], masses=1.0)
    with pytest.raises(ValueError, match="hulls"):
        pc.render.gif(s3, tmp_path / "y.gif", frames=2, size=(64, 48), look={"hulls": [[0, 1]]})


def test_a_backdrop_shows_behind_a_mesh_and_a_liquid_surface():
    # Issue 65: the backdrop (and props) were left out with a mesh or a liquid surface.
    back = {"backdrop": ((0, 0, 120), (0, 120, 0))}
    cloth = pc.scenes.cloth(n=6)
    drop = pc.scenes.drop(n=20)
    for img in (next(pc.render.frames(cloth, frames=1, size=(120, 90), look=back)),
                next(pc.render.frames(drop, frames=1, size=(120, 90), surface=True, colorbar=False, look=back))):
        img = img.astype(int)
        top, bottom = img[1, 60], img[-2, 60]  # the gradient's top and bottom rows, not white
        assert top[2] > 100 and top[0] < 30 and top[1] < 30, top
        assert bottom[1] > 100 and bottom[0] < 30 and bottom[2] < 30, bottom


def _sheet_over_a_floor(height: float) -> np.ndarray:
    """A 1 m sheet (a 6 × 6 mesh) lying flat `height` m over a floor prop at z = 0, seen by a
    camera fixed on the floor: the frame's image."""
    g = np.linspace(-0.5, 0.5, 6)
    x = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    s = pc.Scene(3)
    s.add_particles(np.concatenate([x, np.full((36, 1), height)], axis=1), masses=1.0)
    floor = {"polygon": [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], "color": (200, 200, 200)}
    return next(pc.render.frames(s, frames=1, size=(160, 120), mesh=pc.render.Mesh.grid(6, 6), colorbar=False,
                                 extent=((-2, -2, 0), (2, 2, 1)), look={"decor": [floor]})).astype(int)


def test_a_mesh_casts_a_soft_shadow_on_a_floor_prop():
    # Issue 65: a sheet over a floor drawn as a prop darkens the floor under it, less the higher
    # it hangs; a sheet far above casts nothing to speak of.
    near, high, far = (_sheet_over_a_floor(h) for h in (0.1, 0.6, 50.0))
    floor = (np.abs(far - 200).max(axis=2) <= 1)  # the floor's pixels with no shadow on them
    assert floor.mean() > 0.1
    def shaded(img: np.ndarray) -> np.ndarray:  # floor pixels darkened to a grey: the shadow, not the sheet
        grey = (np.abs(img[..., 0] - img[..., 1]) <= 2) & (np.abs(img[..., 1] - img[..., 2]) <= 2)
        return floor & grey & (img[..., 0] < far[..., 0])

    for img in (near, high):
        assert shaded(img).any()
        assert (img[shaded(img)] <= far[shaded(img)]).all()  # a shadow only darkens
    depth = lambda img: int((200 - img[shaded(img)][:, 0]).max())  # noqa: E731 - the darkest shade
    assert depth(near) > depth(high) > 5


def _sheet_over_a_ground(height: float, ground: str, shadow: bool = True, cube: bool = False) -> np.ndarray:
    """A 1 m sheet (a 6 × 6 mesh) lying flat `height` m over a ground at z = 0 drawn in the
    mesh's depth buffer: a plane collider (``"plane"``) or a fixed box's top (``"box"``), with
    a 10 cm cube standing on the box's corner (``cube``); the frame's image, with the shadows
    or (``shadow=False``) without."""
    from physcore.render import _raster

    g = np.linspace(-0.5, 0.5, 6)
    x = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    s = pc.Scene(3)
    s.add_particles(np.concatenate([x, np.full((36, 1), height)], axis=1), masses=1.0)
    if ground == "plane":
        s.add(pc.Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]))
    else:
        s.add(pc.Bodies("box", size=[(1.5, 1.5, 0.05)], positions=[(0.0, 0.0, -0.05)], kind="fixed"))
        if cube:
            s.add(pc.Bodies("box", size=[(0.05, 0.05, 0.05)], positions=[(0.9, -0.9, 0.05)], color=(200, 40, 40)))
    dark = _raster.SHADOW_DARK
    _raster.SHADOW_DARK = dark if shadow else 0.0
    try:
        return next(pc.render.frames(s, frames=1, size=(160, 120), mesh=pc.render.Mesh.grid(6, 6), colorbar=False,
                                     extent=((-1, -1, 0), (1, 1, 1)), view=(-60.0, 25.0))).astype(int)
    finally:
        _raster.SHADOW_DARK = dark


@pytest.mark.parametrize("ground", ["plane", "box"])
def test_a_mesh_casts_a_soft_shadow_on_a_floor_collider_and_a_fixed_bodys_top(ground):
    # Issue 65: cloth_on_ball's floor (a plane collider) and tablecloth's table (a fixed box) are
    # drawn in the mesh's depth buffer, not as a floor prop, and had no shadow under the sheet.
    # Now the ground darkens under it (only darkens), less the higher the sheet hangs.
    shade = {}  # by height: how much darker each pixel is with the shadow than without
    for h in (0.1, 0.6):
        img, plain = _sheet_over_a_ground(h, ground), _sheet_over_a_ground(h, ground, shadow=False)
        assert (img <= plain + 1).all()  # a shadow only darkens (±1 for rounding)
        shade[h] = (plain - img).sum(axis=2)
    assert shade[0.1].max() > shade[0.6].max() > 30
    # The shadow falls on the ground straight under the sheet, centred on the screen as it is.
    _, cols = np.nonzero(shade[0.1] > 30)
    assert abs(cols.mean() - 80) < 10


def test_a_body_standing_on_a_fixed_body_casts_a_contact_shadow():
    # The dishes on tablecloth's table looked placed, not settled: a body resting on a fixed
    # body's top darkens it around its foot.
    with_, without = _sheet_over_a_ground(0.3, "box", cube=True), _sheet_over_a_ground(0.3, "box", shadow=False, cube=True)
    red = (without[..., 0] > 120) & (without[..., 1] < 60)  # the cube's faces
    assert red.any()
    rows, cols = np.nonzero(red)
    near = np.zeros_like(red)
    near[max(rows.min() - 6, 0) : rows.max() + 7, max(cols.min() - 6, 0) : cols.max() + 7] = True
    darker = (without - with_).sum(axis=2) > 15
    assert (darker & near & ~red).any()


def test_trail_of_draws_only_the_named_particles_paths():
    # Issue 65: spring_chain's frame was empty while its rope lay level, and every link's trail
    # was clutter; look.trail_of draws one path (the free end's). Two balls fly side by side,
    # 1 m apart: with trail_of=(1,) only ball 1's band holds trail pixels, with none both do.
    from physcore.render import _palette

    s = pc.Scene(2, dt=1e-2)
    s.add_particles([[0.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [1.0, 0.0]], masses=1.0)
    rec = pc.render.record(s, frames=20, frame_time=0.05)

    def trail_rows(look):
        ras = pc.render._Rasteriser(rec, (200, 150), "none", 2, pc.render.DEFAULT_VIEW, trail=10, look=look)
        img = ras.frame(rec.frames - 1)
        rows = np.nonzero(((img >= _palette._TRAIL0) & (img < _palette._TRAIL0 + _palette._N_TRAIL)).any(axis=1))[0]
        ball = [ras.cam.pixels(ras.cam.project(rec.positions[-1][[i]])[0])[1][0] for i in (0, 1)]
        return rows, ball

    rows, (y0, y1) = trail_rows(Look(trail_of=(1,)))
    assert rows.size and np.all(np.abs(rows - y1) <= 3)
    rows, (y0, y1) = trail_rows(None)
    assert (np.abs(rows - y0) <= 3).any() and (np.abs(rows - y1) <= 3).any()


def test_trail_of_is_checked(tmp_path):
    with pytest.raises(ValueError, match="trail_of"):
        pc.render.gif(_ball(2), tmp_path / "x.gif", frames=2, trail=2, look={"trail_of": [-1]})
    with pytest.raises(ValueError, match="trail_of"):
        pc.render.gif(_ball(2), tmp_path / "x.gif", frames=2, trail=2, look={"trail_of": [5]})
    assert pc.scenes.spring_chain(n=6).render_defaults["look"]["trail_of"] == (5,)
