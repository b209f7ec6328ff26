"""What a new user tripped over on a first run (issue 16, "What a new user tripped over"): each
check runs what they ran.

* ``render.gif(scenes.cloth(), path)`` with no options shows the motion ``physcore render cloth``
  shows (the scene's frame time, not 10 steps), and any other scene plays in real time;
* a "4 s" GIF plays for 4 s: GIF delays are whole centiseconds, so they alternate;
* ``color_by="pressure"`` on a scene without a fluid is an error, not a flat blue picture;
* ``physcore scenes`` lists as parameters only what ``--param`` accepts;
* ``dir(physcore)`` shows ``render`` and ``scenes``;
* a diverging explicit-Euler render says once that the simulation diverged, and advises another
  integrator rather than a smaller dt (which explicit Euler never becomes stable with).
"""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image, ImageSequence

import physcore as pc
from physcore import render


def test_library_defaults_are_the_clis_for_a_ready_made_scene():
    scene = pc.scenes.cloth(n=8)
    # The function's defaults, plus what this sheet's size decides: its grid mesh, and its room
    # (the floor's props and the camera's box scale with the sheet).
    fn_defaults = pc.scenes.cloth.render_defaults
    assert {k: scene.render_defaults[k] for k in fn_defaults} == fn_defaults
    assert set(scene.render_defaults) - set(fn_defaults) == {"mesh", "look", "extent"}
    assert np.array_equal(scene.render_defaults["mesh"].faces, render.Mesh.grid(8, 8).faces)
    rec = render.record(scene, frames=3)
    frame_time = pc.scenes.cloth.render_defaults["frame_time"]
    step = np.diff(rec.times)
    # round(frame_time / dt) steps of dt: within half a step of the scene's frame time (1/30 s).
    assert np.all(np.abs(step - frame_time) <= 0.5 * scene.dt + 1e-12), (step, frame_time, scene.dt)
    assert render.record(pc.scenes.cloth(n=8)).frames == pc.scenes.cloth.render_defaults["frames"]


def test_a_scene_without_defaults_plays_in_real_time(tmp_path):
    scene = pc.Scene(2, dt=1e-3)
    scene.add_particles([[0.0, 0.0]], velocities=[[1.0, 0.0]])
    assert scene.render_defaults is None
    rec = render.record(scene, frames=4)
    assert np.allclose(np.diff(rec.times), 0.033, atol=1e-12)  # round((1/30) / 1e-3) = 33 steps
    path = render.gif(pc.Scene(2, dt=1e-3), tmp_path / "x.gif", frames=2)
    with Image.open(path) as im:
        assert im.size == (480, 360)


def test_the_ready_made_scenes_carry_their_defaults_and_the_functions_keep_their_signatures():
    import inspect

    for name, fn in pc.scenes.REGISTRY.items():
        assert fn.__name__ == name and "render_defaults" in vars(fn)
        # Every scene with particles or flows takes an integrator; the grid scenes do not (their
        # grids step with their own schemes: issue 45 dropped the integrator= that did nothing),
        # nor do the scenes of rigid bodies only (rapier's scheme).
        grid = name in ("ripple", "double_slit", "turing", "smoke", "cavity", "vortex_street", "dominoes", "pyramid",
                        "tumbling_boxes")
        assert ("integrator" in inspect.signature(fn).parameters) != grid, name


@pytest.mark.parametrize("fps, frames", [(30, 90), (30, 121), (24, 48), (25, 10), (7, 9), (60, 30)])
def test_gif_plays_for_frames_over_fps_seconds(tmp_path, fps, frames):
    """The delays sum to frames/fps within 10 ms (one centisecond), each a multiple of 10 ms and
    at least 20 ms (60 fps plays at 50). Pillow merges identical consecutive frames and adds their
    delays, which keeps the sum: the total is what is checked."""
    scene = pc.Scene(2, dt=1e-3)
    scene.add_particles(np.zeros((2, 2)), velocities=[[1.0, 0.3], [-1.0, 0.5]])
    path = render.gif(scene, tmp_path / "t.gif", frames=frames, fps=fps, size=(64, 64), steps_per_frame=100)
    with Image.open(path) as im:
        delays = [f.info["duration"] for f in ImageSequence.Iterator(im)]
    assert 0 < len(delays) <= frames
    assert all(d % 10 == 0 and d >= 20 for d in delays), delays
    want = frames * 1000 / min(fps, 50)
    assert abs(sum(delays) - want) <= 10, (sum(delays), want)
    if fps == 30:
        assert {30, 40} <= set(delays), set(delays)  # alternating, not a flat 30 (3.6 s for "4 s")


def test_pressure_colouring_needs_a_fluid(tmp_path):
    scene = pc.scenes.projectile(n=2)
    with pytest.raises(pc.InvalidInputError, match="color_by='pressure': the scene has no fluid"):
        render.gif(scene, tmp_path / "p.gif", frames=2, color_by="pressure")
    assert not (tmp_path / "p.gif").exists()
    assert scene.step_count == 0  # refused before stepping


def test_cli_pressure_on_a_scene_without_fluid_is_a_usage_error(tmp_path):
    out = tmp_path / "p.gif"
    r = subprocess.run([sys.executable, "-m", "physcore", "render", "projectile", "--color-by", "pressure",
                        "--frames", "2", "-o", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "no fluid" in r.stderr and not out.exists()


def test_scenes_listing_offers_only_what_param_accepts():
    r = subprocess.run([sys.executable, "-m", "physcore", "scenes"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    for block in text.split("parameters (--param key=value): ")[1:]:
        params = block.split(";")[0]
        assert "integrator=" not in params and "dt=" not in params, params
    assert "options: --integrator (default 'verlet'), --dt" in text
    # What the listing offers, --param takes.
    r = subprocess.run([sys.executable, "-m", "physcore", "render", "spring_chain", "--param", "n=3",
                        "--integrator", "rk4", "--frames", "2", "--size", "32x32", "-o", "/dev/null", "--quiet"],
                       capture_output=True, text=True)
    assert "--param" not in r.stderr, r.stderr


def test_dir_shows_the_lazy_submodules():
    names = dir(pc)
    assert "render" in names and "scenes" in names and "Scene" in names
    assert pc.render.gif is render.gif


def test_a_diverging_explicit_euler_render_advises_another_integrator(tmp_path):
    out = tmp_path / "e.gif"
    r = subprocess.run([sys.executable, "-m", "physcore", "render", "cloth",
                        "--integrator", "euler", "--param", "n=12", "--size", "32x32", "-o", str(out), "--quiet"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, (r.returncode, r.stderr)
    err = r.stderr
    assert err.count("diverged") == 1, err
    assert "at any dt" in err and "--integrator verlet" in err, err
    assert "e.g." not in err and "try a smaller time step" not in err, err
    assert "Warning" not in err and not out.exists()


def test_the_python_error_says_so_too():
    scene = pc.scenes.cloth(n=12, integrator="euler")
    with pytest.raises(pc.SimulationDiverged) as info:
        scene.step(20000)
    assert "Explicit Euler amplifies every undamped oscillation" in str(info.value)
    assert "Try a smaller dt" not in str(info.value)
    assert math.isfinite(scene.time) and scene.step_count == 0


def _ink_centre(img: np.ndarray, colour) -> tuple[float, float]:
    rows, cols = np.nonzero(np.all(img == np.asarray(colour), axis=2))
    return float(rows.mean()), float(cols.mean())


def test_render_frame_in_a_loop_keeps_one_view_with_an_extent():
    """Frames made in a loop: a pinned particle at the origin and one moving away. With the same
    `extent` in every call the pinned one stays on its pixels; without it each call refits the
    camera to its own state and the pinned one jumps."""
    from physcore.render._palette import _PALETTE, _PINNED

    pinned_rgb = _PALETTE[_PINNED]
    centres = {"fitted": [], "extent": []}
    for t in (0.0, 0.5, 1.0):
        x = np.array([[0.0, 0.0], [1.0 + 2.0 * t, 0.5]])
        for kind, extra in (("fitted", {}), ("extent", {"extent": ([-0.5, -0.5], [3.5, 1.0])})):
            img = render.render_frame(x, pinned=[True, False], size=(96, 64), radius=2, colorbar=False, **extra)
            centres[kind].append(_ink_centre(img, pinned_rgb))
    assert len(set(centres["extent"])) == 1, centres["extent"]
    assert len(set(centres["fitted"])) > 1, centres["fitted"]


@pytest.mark.parametrize(
    ("bad", "error"),
    [
        ([0.0, 1.0], pc.InvalidInputError),
        (([0, 0], [1]), pc.InvalidInputError),
        (([0, 0], [-1, 1]), pc.InvalidInputError),
        (([0, np.nan], [1, 1]), pc.InvalidInputError),
        ("box", pc.InvalidTypeError),  # not numbers at all: a TypeError, as everywhere else
    ],
)
def test_render_frame_refuses_a_bad_extent(bad, error):
    with pytest.raises(error, match="extent"):
        render.render_frame(np.zeros((2, 2)), extent=bad, size=(32, 32))


def test_kepler_speeds_are_not_labelled_m_per_s():
    """The Kepler scene is in G = 1 units: its colour bar says so, not m/s; SI scenes keep m/s."""
    from physcore.render._colorbar import _colorbar_labels

    assert render.record(pc.scenes.kepler(), frames=2).speed_unit == "(G=1)"
    assert render.record(pc.scenes.cloth(n=6), frames=2).speed_unit == "m/s"
    assert _colorbar_labels("speed", 1.25, "(G=1)") == ("0", "1.25 (G=1)")
    assert _colorbar_labels("speed", 1.25) == ("0", "1.25 m/s")


def test_strain_is_a_colour_choice_on_the_runs_own_scale(tmp_path):
    """A hanging cloth strains well under 1 %: coloured by strain, its springs (drawn over grey
    discs) use both ends of the map, whose ends are ± the run's 99th percentile of |strain| (the
    colour bar says it in %), not a fixed 10 % under which everything is grey."""
    from physcore.render._palette import _N_STRAIN, _PALETTE, _STRAIN0

    rec = render.record(pc.scenes.cloth(n=12), frames=20, color_by="strain")
    p99 = float(np.percentile(np.abs(rec.strain[np.isfinite(rec.strain)]), 99))
    assert 0 < p99 < 0.02  # the strains this test is about: far below STRAIN_SATURATION
    path = render.gif(rec, tmp_path / "s.gif", color_by="strain", size=(240, 180), look=render.Look(), view=render.DEFAULT_VIEW)
    with Image.open(path) as im:
        im.seek(im.n_frames - 1)
        img = np.asarray(im.convert("RGB"))
    used = {tuple(c) for c in img.reshape(-1, 3)}
    ends = 4  # the 4 most saturated colours at each end of the diverging map
    blues = {tuple(int(v) for v in _PALETTE[_STRAIN0 + k]) for k in range(ends)}
    reds = {tuple(int(v) for v in _PALETTE[_STRAIN0 + _N_STRAIN - 1 - k]) for k in range(ends)}
    assert used & blues and used & reds, "both compressed and stretched springs show"
    from physcore.render._colorbar import _colorbar_labels

    lo, hi = _colorbar_labels("strain", p99)
    assert lo.startswith("-") and hi.startswith("+") and hi.endswith("%")


def test_strain_colouring_needs_springs(tmp_path):
    with pytest.raises(pc.InvalidInputError, match="no springs"):
        render.record(pc.scenes.projectile(n=2), frames=2, color_by="strain")
    with pytest.raises(pc.InvalidInputError, match="springs=True"):
        render.record(pc.scenes.cloth(n=6), frames=2, color_by="strain", springs=False)
    rec = render.record(pc.scenes.cloth(n=6), frames=2)
    with pytest.raises(pc.InvalidInputError, match="strain"):
        render.gif(rec, tmp_path / "x.gif", color_by="strain", springs=False)
    assert not (tmp_path / "x.gif").exists()


def _last_frame(path) -> np.ndarray:
    with Image.open(path) as im:
        im.seek(im.n_frames - 1)
        return np.asarray(im.convert("RGB"))


def test_trails_show_the_paths(tmp_path):
    """Projectiles with a trail: the last frame has trail-shaded pixels along the arcs, and their
    number grows with the trail's length; without a trail there are none. The ready-made Kepler
    and projectile scenes have one by default (one orbit; the whole flight)."""
    from physcore.render._palette import _N_TRAIL, _PALETTE, _TRAIL0

    shades = {tuple(int(v) for v in _PALETTE[_TRAIL0 + k]) for k in range(_N_TRAIL)}

    def trail_pixels(path) -> int:
        img = _last_frame(path)
        return sum(int(np.all(img == np.asarray(c), axis=2).sum()) for c in shades)

    # color_by="speed": the fixed palette's trail shades (own colours draw trails in each
    # particle's colour instead, tests/render/test_colors.py).
    counts = {}
    for t in (0, 10, 40):
        s = pc.scenes.projectile(n=3)
        counts[t] = trail_pixels(render.gif(s, tmp_path / f"t{t}.gif", frames=41, size=(160, 120), trail=t, color_by="speed"))
    assert counts[0] == 0 and 0 < counts[10] < counts[40], counts
    assert pc.scenes.kepler().render_defaults["trail"] > 0
    k = render.gif(pc.scenes.kepler(), tmp_path / "k.gif", frames=40, size=(120, 120), color_by="speed", halo=[], theme="light", radius=3)
    assert trail_pixels(k) > 0


@pytest.mark.parametrize("bad, exc", [(-1, ValueError), (1.5, TypeError), ("3", TypeError)])
def test_a_bad_trail_is_refused_by_name(tmp_path, bad, exc):
    scene = pc.scenes.projectile(n=2)
    with pytest.raises(exc, match="trail"):
        render.gif(scene, tmp_path / "x.gif", frames=2, trail=bad)
    assert not (tmp_path / "x.gif").exists() and scene.step_count == 0  # before stepping


def test_size_by_mass_draws_a_star_larger_than_its_planet(tmp_path):
    """Two bodies at rest, 1 kg and 27 kg: with size_by="mass" the heavy one's disc has 3× the
    radius (∛27), so about 9× the pixels; with the default one size, the same. Kepler draws its
    star that way by default."""
    scene = pc.Scene(2, dt=1e-3)
    scene.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, 27.0])
    areas = {}
    for size_by in ("none", "mass"):
        path = render.gif(scene, tmp_path / f"{size_by}.gif", frames=1, size=(200, 100), color_by="none",
                          radius=4, size_by=size_by)
        ink = np.any(_last_frame(path) != 255, axis=2)[:-20]  # above the clock
        areas[size_by] = (int(ink[:, :100].sum()), int(ink[:, 100:].sum()))
    light, heavy = areas["mass"]
    assert areas["none"][0] == areas["none"][1] == light > 0
    assert 6 < heavy / light < 12, areas
    assert pc.scenes.kepler().render_defaults["size_by"] == "mass"
    with pytest.raises(pc.InvalidInputError, match="size_by"):
        render.gif(scene, tmp_path / "x.gif", frames=1, size_by="volume")
