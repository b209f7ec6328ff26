"""The ``physcore`` command line (physcore.cli): scenes listing, render, errors and exit codes."""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import physcore as pc
from physcore import cli, render
from physcore.cli import main

SMALL = ["--frames", "5", "--size", "64x48", "--steps-per-frame", "2"]
# The chain falls visibly from frame to frame (a frame the same as the one before is merged
# into it by the GIF writer, and the chain, with no trail, barely moves in 2 steps).
CHAIN = ["--frames", "5", "--size", "64x48", "--steps-per-frame", "300"]


def test_render_spring_chain(tmp_path, capsys):
    out = tmp_path / "x.gif"
    assert main(["render", "spring_chain", "-o", str(out)] + CHAIN) == 0
    with Image.open(out) as im:
        assert im.n_frames == 5
        assert im.size == (64, 48)
    stdout = capsys.readouterr().out
    assert str(out) in stdout
    assert "energy drift:" in stdout and "(relative)" in stdout
    assert "simulated time:" in stdout and "wall time:" in stdout
    assert list(tmp_path.iterdir()) == [out]


def test_an_old_integrator_name_renders_with_a_note(tmp_path, capsys):
    # The old name is said on stderr, not raised as a DeprecationWarning from inside the scene
    # (an exception under -W error, as the fuzzed CLI found).
    out = tmp_path / "x.gif"
    assert main(["render", "kepler", "-o", str(out), "--integrator", "rk45", "-q"] + SMALL) == 0
    captured = capsys.readouterr()
    assert "--integrator rk45 is now dopri5" in captured.err
    assert out.exists()


def test_render_default_output_path_and_params(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["render", "spring_chain", "--param", "dim=3", "--param", "n=6", "--integrator", "rk4", "--dt", "5e-4", "-q"]
    assert main(args + CHAIN) == 0
    with Image.open(tmp_path / "spring_chain.gif") as im:
        assert im.n_frames == 5
    stdout = capsys.readouterr().out
    assert "rk4" in stdout
    assert "dt = 0.0005 s" in stdout


def test_render_bool_param(tmp_path):
    for value in ("yes", "false", "1", "OFF"):
        out = tmp_path / f"p_{value}.gif"
        assert main(["render", "projectile", "-o", str(out), "--param", f"ground={value}", "-q"] + SMALL) == 0
        assert out.exists()


def test_scenes_lists_all(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("cloth", "projectile", "kepler", "spring_chain"):
        assert name in out
    assert "n=40" in out  # parameters with their defaults


def test_scenes_says_each_scene_in_a_whole_sentence_of_plain_text(capsys):
    # Each summary is the docstring's first sentence, however it wraps there (it was cut at the
    # docstring's first line: "…coalesce; surface"), without reST markup; an abbreviation
    # ("Annu. Rev.") does not end it.
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    width = max(len(n) for n in pc.scenes.REGISTRY) + 2
    summaries, current = {}, None
    for line in out.splitlines():
        head = line[:width].strip()
        if head in pc.scenes.REGISTRY:
            current = head
            summaries[current] = line[width:].strip()
        elif current and line.startswith(" " * width) and not line.startswith(" " * (width + 2)):
            summaries[current] += " " + line.strip()
    assert summaries.keys() == pc.scenes.REGISTRY.keys()
    for name, text in summaries.items():
        assert text.endswith("."), (name, text)
        assert "``" not in text and ":func:" not in text and ":class:" not in text, (name, text)
    assert summaries["droplets"].endswith("pulls the merged puddle back in from the walls.")
    assert summaries["crown"].endswith("(Worthington's splash; Yarin, Annu. Rev. Fluid Mech. 38, 2006).")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Wayland's runtime directory is a Linux matter")
def test_info_on_a_machine_without_a_login_session_prints_no_wayland_error():
    # Mesa's Vulkan drivers probe Wayland at each adapter enumeration; without XDG_RUNTIME_DIR
    # (a container, a CI job) libwayland printed "error: XDG_RUNTIME_DIR is invalid or not set
    # in the environment." 2-4 times, which a new user reads as a failure.
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "WAYLAND_DISPLAY")}
    proc = subprocess.run([sys.executable, "-m", "physcore", "info"], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "XDG_RUNTIME_DIR" not in proc.stderr and "error" not in proc.stderr.lower(), proc.stderr
    assert proc.stdout.startswith("physcore ")


def test_a_view_angle_for_a_2d_scene_is_refused_before_simulating(tmp_path, capsys):
    # It was ignored: --camera orbit on a 2D scene was refused, --view AZ,EL silently dropped.
    out = tmp_path / "k.gif"
    assert main(["render", "kepler", "-o", str(out), "--view", "30,20"]) == 2
    err = capsys.readouterr().err
    assert "--view: a 2D scene is drawn in its plane" in err and "simulating" not in err
    assert not out.exists()
    with pytest.raises(pc.InvalidInputError, match="^view: a 2D scene"):
        render.gif(pc.scenes.kepler(), tmp_path / "k.gif", view=(30, 20), frames=2)


def test_unknown_scene(tmp_path, capsys):
    assert main(["render", "nosuchscene", "-o", str(tmp_path / "x.gif")]) == 2
    err = capsys.readouterr().err
    assert "nosuchscene" in err and "spring_chain" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("typed", "meant"), [("clth", "cloth"), ("Cloth", "cloth"), ("dambreak", "dam_break")])
def test_a_misspelt_scene_gets_the_closest_name(tmp_path, capsys, typed, meant):
    assert main(["render", typed, "-o", str(tmp_path / "x.gif")]) == 2
    assert f"did you mean {meant!r}?" in capsys.readouterr().err


def test_an_integrator_for_a_grid_scene_is_refused_not_ignored(tmp_path, capsys):
    """The grid scenes step their fields by their own schemes: ``--integrator`` was accepted,
    ignored, and the summary named verlet."""
    assert main(["render", "turing", "-o", str(tmp_path / "x.gif"), "--integrator", "rk4"]) == 2
    assert "--integrator: turing steps its fields by its own scheme" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_run_that_blew_up_without_overflowing_is_written_with_a_warning(tmp_path, capsys):
    """Three substeps a frame are far past the cloth's stable step: in ten frames its energy
    reaches some 1e45 J, every value still finite, so nothing raises; the command says so."""
    out = tmp_path / "b.gif"
    assert main(["render", "cloth", "-o", str(out), "--frames", "10", "--substeps", "3", "--size", "64x48", "-q"]) == 0
    err = capsys.readouterr().err
    assert "physcore render: warning: the energy books are off by +1 of the energy in play" in err, err
    assert "RuntimeWarning" not in err and out.exists()


def test_a_divergence_at_fixed_substeps_asks_for_more_of_them(tmp_path, capsys):
    """With ``--substeps N`` the hint is a larger N, not "the automatic substeps were too long",
    and the core's message asks for a smaller step (the run blew up from a normal start), not
    for "values of a physical size"."""
    assert main(["render", "cloth", "-o", str(tmp_path / "b.gif"), "--substeps", "3", "--size", "64x48", "-q"]) == 1
    err = capsys.readouterr().err
    assert "3 substeps of 0.0111 s a frame are too long; try --substeps 585" in err, err
    assert "automatic substeps" not in err and "physical size;" not in err
    assert "try a smaller dt" in err


@pytest.mark.parametrize(
    "param, message",
    [
        ("nosuch=1", "valid parameters"),
        ("n=many", "--param n"),
        ("ground=maybe", "--param ground"),
        ("novalue", "key=value"),
        ("dt=0.1", "--dt"),
    ],
)
def test_bad_param(tmp_path, capsys, param, message):
    code = main(["render", "projectile", "-o", str(tmp_path / "x.gif"), "--param", param] + SMALL)
    assert code == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "extra",
    [
        ["--frames", "0"],
        ["--size", "10x10"],
        ["--size", "big"],
        ["--fps", "-1"],
        ["--integrator", "leapfrog"],
        ["--color-by", "mass"],
        ["--frame-time", "0"],
        ["--frame-time", "1", "--steps-per-frame", "1"],
        ["--param", "n=0"],  # rejected by the scene itself
        ["--trail", "-5"],  # these two were refused only after the simulation had run
        ["--radius", "-2"],
        ["--radius", "201"],
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, extra):
    assert main(["render", "spring_chain", "-o", str(tmp_path / "x.gif"), "-q"] + extra) == 2
    assert "error" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_bad_output_path_exit_2(tmp_path, capsys):
    assert main(["render", "spring_chain", "-o", str(tmp_path / "x.bmp"), "-q"] + SMALL) == 2
    assert ".gif, .mp4, .webm, .png" in capsys.readouterr().err
    assert main(["render", "spring_chain", "-o", str(tmp_path / "no" / "x.gif"), "-q"] + SMALL) == 2
    assert list(tmp_path.iterdir()) == []


def test_divergence_exit_1_and_no_file(tmp_path, capsys):
    # Verlet with dt = 1 s on 2000 N/m springs of 40 g masses blows up within a few steps.
    out = tmp_path / "boom.gif"
    code = main(["render", "spring_chain", "-o", str(out), "--dt", "1", "--frames", "5", "--steps-per-frame", "200", "-q"])
    assert code == 1
    assert "diverged" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_help_and_missing_command(capsys):
    assert main(["--help"]) == 0
    assert "render" in capsys.readouterr().out
    assert main([]) == 2


def test_console_script(tmp_path):
    exe = shutil.which("physcore")
    cmd = [exe, "scenes"] if exe else [sys.executable, "-m", "physcore", "scenes"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "spring_chain" in res.stdout


def test_python_dash_m(tmp_path):
    out = tmp_path / "m.gif"
    res = subprocess.run(
        [sys.executable, "-m", "physcore", "render", "kepler", "-o", str(out)] + SMALL,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    assert "energy drift" in res.stdout
    assert "5/5" in res.stderr  # the progress bar
    with Image.open(out) as im:
        assert im.n_frames == 5


# --------------------------------------------------------------------------- fluid-style scenes
# Stand-ins for the SPH scenes: a real Scene behind a wrapper with a fluid scene's optional methods
# (pressure, boundary_points, advance), registered under a test name for the CLI to find.
class Tank:
    def __init__(self, scene, hide=()):
        self.scene = scene
        self.hide = set(hide)
        self.advanced = []

    def __getattribute__(self, name):
        if name in object.__getattribute__(self, "hide"):
            raise AttributeError(name)
        return object.__getattribute__(self, name)

    def __getattr__(self, name):
        if name in object.__getattribute__(self, "hide"):
            raise AttributeError(name)
        return getattr(self.scene, name)

    def pressure(self):
        return np.maximum(1000.0 * 9.81 * (1.0 - self.scene.positions[:, 1]), 0.0)

    def boundary_points(self):
        ys = np.arange(-0.1, 1.2, 0.05)
        xs = np.arange(-0.1, 1.05, 0.05)
        return np.concatenate([np.column_stack([np.full_like(ys, -0.1), ys]),
                               np.column_stack([np.full_like(ys, 1.0), ys]),
                               np.column_stack([xs, np.full_like(xs, -0.1)])])

    def advance(self, duration):
        k = max(1, math.ceil(duration / self.scene.dt - 1e-9))
        self.scene.step(k)
        self.advanced.append(duration)
        return k


@pytest.fixture
def tanks(monkeypatch):
    """Registers 'tank' (automatic substeps, pressure colouring by default) and 'tank_plain'
    (neither pressure() nor advance()); returns the list of scenes made."""
    made = []

    def make(hide, n: int = 4, integrator: str = "verlet", dt: float | None = None):
        g = np.linspace(0.2, 0.6, n)
        gx, gy = (a.ravel() for a in np.meshgrid(g, g + 0.3))
        s = pc.Scene(dim=2, integrator=integrator, dt=1e-3 if dt is None else dt)
        s.add_particles(np.column_stack([gx, gy]))
        s.add(pc.Gravity([0.0, -9.81]))
        made.append(Tank(s, hide))
        return made[-1]

    def tank(n: int = 4, integrator: str = "verlet", dt: float | None = None):
        """A falling block in a tank (test stand-in for a fluid scene)."""
        return make((), n, integrator, dt)

    def tank_plain(n: int = 4, integrator: str = "verlet", dt: float | None = None):
        """The same without pressure() and advance()."""
        return make(("pressure", "advance"), n, integrator, dt)

    def tank_boom(n: int = 1, integrator: str = "verlet", dt: float | None = None):
        """A particle at 1e308 m/s: diverges on the first substep."""
        s = pc.Scene(dim=2, integrator=integrator, dt=10.0 if dt is None else dt)
        s.add_particles(np.zeros((1, 2)), np.array([[1e308, 0.0]]))
        made.append(Tank(s))
        return made[-1]

    tank_boom.render_defaults = {"frames": 3, "frame_time": 10.0, "substeps": "auto", "size": (64, 48)}
    tank.render_defaults = {"frames": 5, "fps": 30, "frame_time": 0.05, "substeps": "auto",
                            "size": (200, 150), "color_by": "pressure"}
    tank_plain.render_defaults = {"frames": 5, "fps": 30, "frame_time": 0.01, "size": (200, 150)}
    registry = dict(cli._registry())
    registry.update(tank=tank, tank_plain=tank_plain, tank_boom=tank_boom)
    monkeypatch.setattr(cli, "_registry", lambda: registry)
    return made


PRESSURE_RGB = {tuple(int(v) for v in c) for c in render._PALETTE[render._PRESSURE0:render._PRESSURE0 + render._N_PRESSURE]}
TEXT_RGB = tuple(int(v) for v in render._PALETTE[render._TEXT])


def gif_colours(path, clock: bool = True) -> set:
    """The colours of a GIF's first frame; ``clock=False`` leaves out the bottom rows, where the
    simulated time is written."""
    with Image.open(path) as im:
        rgb = np.asarray(im.convert("RGB"))
    if not clock:
        rgb = rgb[:-20]
    return {tuple(int(v) for v in c) for c in np.unique(rgb.reshape(-1, 3), axis=0)}


def test_auto_substeps_from_render_defaults(tmp_path, capsys, tanks):
    out = tmp_path / "t.gif"
    assert main(["render", "tank", "-o", str(out)]) == 0
    (scene,) = tanks
    assert scene.advanced == [0.05] * 4  # frame_time from render_defaults, once per frame after the first
    assert math.isclose(scene.time, 0.2, rel_tol=1e-9)
    with Image.open(out) as im:
        assert im.n_frames == 5 and im.size == (200, 150)
    colours = gif_colours(out)
    assert len(colours & PRESSURE_RGB) > 10  # render_defaults' color_by="pressure" (particles and bar)
    assert TEXT_RGB in colours  # the colour bar's labels
    captured = capsys.readouterr()
    assert "substeps:" in captured.out and "200 in all" in captured.out and "50.0 per frame" in captured.out
    assert "4 intervals of 0.05 s" in captured.out
    assert "energy drift:" in captured.out
    assert "substeps=50" in captured.err  # the progress bar


def test_steps_per_frame_turns_auto_substeps_off(tmp_path, capsys, tanks):
    out = tmp_path / "t.gif"
    assert main(["render", "tank", "-o", str(out), "--steps-per-frame", "3", "-q"]) == 0
    (scene,) = tanks
    assert scene.advanced == []
    assert scene.step_count == 12
    stdout = capsys.readouterr().out
    assert "12 steps of dt = 0.001 s, 3 per frame" in stdout
    assert "substeps:" not in stdout


def test_frame_time_option(tmp_path, capsys, tanks):
    out = tmp_path / "t.gif"
    assert main(["render", "tank", "-o", str(out), "--frame-time", "0.02", "--frames", "3", "-q"]) == 0
    assert tanks[0].advanced == [0.02, 0.02]
    assert "40 in all" in capsys.readouterr().out
    # A scene without automatic substeps takes round(frame_time / dt) fixed steps instead.
    out2 = tmp_path / "c.gif"
    assert main(["render", "spring_chain", "-o", str(out2), "--frame-time", "0.005", "--dt", "1e-3",
                 "--frames", "5", "--size", "64x48", "-q"]) == 0
    assert "20 steps of dt = 0.001 s, 5 per frame" in capsys.readouterr().out


def test_a_frame_time_the_scene_sets_from_its_arguments_wins_over_the_functions(tmp_path, capsys, tanks, monkeypatch):
    # double_slit sets frame_time = wavelength / speed / 8 on the scene it builds: the CLI's
    # --param speed=... must change the frame spacing, as render.gif(scene) does.
    registry = dict(cli._registry())
    tank = registry["tank"]

    def tank_timed(n: int = 4, frame_time: float = 0.05):
        made = tank(n)
        made.scene.render_defaults = {"frame_time": frame_time}
        return made

    tank_timed.render_defaults = dict(tank.render_defaults)  # frame_time 0.05
    registry["tank_timed"] = tank_timed
    monkeypatch.setattr(cli, "_registry", lambda: registry)
    out = tmp_path / "t.gif"
    assert main(["render", "tank_timed", "-o", str(out), "--param", "frame_time=0.03", "--frames", "3", "-q"]) == 0
    assert tanks[-1].advanced == [0.03, 0.03]
    # The command line's own --frame-time still wins over both.
    assert main(["render", "tank_timed", "-o", str(out), "--param", "frame_time=0.03", "--frame-time", "0.02",
                 "--frames", "3", "-q"]) == 0
    assert tanks[-1].advanced == [0.02, 0.02]


@pytest.mark.parametrize(
    "extra",
    [
        ["--frame-time", "0"],
        ["--frame-time", "-0.1"],
        ["--frame-time", "nan"],
        ["--frame-time", "soon"],
        ["--frame-time", "0.01", "--steps-per-frame", "2"],
    ],
)
def test_bad_frame_time_exit_2(tmp_path, capsys, tanks, extra):
    assert main(["render", "tank", "-o", str(tmp_path / "x.gif"), "-q"] + extra) == 2
    assert "error" in capsys.readouterr().err
    assert all(s.time == 0.0 for s in tanks)
    assert list(tmp_path.iterdir()) == []


def test_color_by_and_colorbar_options(tmp_path, capsys, tanks):
    speed = tmp_path / "s.gif"
    assert main(["render", "tank", "-o", str(speed), "--color-by", "speed", "-q"]) == 0
    assert not gif_colours(speed) & PRESSURE_RGB  # the option beats render_defaults
    bare = tmp_path / "b.gif"
    assert main(["render", "tank", "-o", str(bare), "--no-colorbar", "-q"]) == 0
    colours = gif_colours(bare, clock=False)
    assert colours & PRESSURE_RGB and TEXT_RGB not in colours  # no colour bar (its labels are text)
    # Pressure colouring of a scene without pressure(): a usage error, before any stepping.
    out = tmp_path / "p.gif"
    assert main(["render", "tank_plain", "-o", str(out), "--color-by", "pressure", "-q"]) == 2
    assert "color_by" in capsys.readouterr().err
    assert tanks[-1].time == 0.0
    assert not out.exists()


def test_divergence_with_auto_substeps_exit_1_and_no_file(tmp_path, capsys, tanks):
    out = tmp_path / "boom.gif"
    assert main(["render", "tank_boom", "-o", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert "diverged" in err and "no file written" in err
    assert tanks[0].advanced == []  # advance() raised: nothing was recorded as taken
    assert list(tmp_path.iterdir()) == []


def test_render_dopri5_with_tolerances(tmp_path, capsys):
    out = tmp_path / "k.gif"
    args = ["render", "kepler", "-o", str(out), "--integrator", "dopri5", "--rtol", "1e-9", "--atol", "1e-12", "-q"]
    assert main(args + SMALL) == 0
    stdout = capsys.readouterr().out
    assert "dopri5:" in stdout and "internal steps accepted" in stdout and "rtol 1e-09" in stdout


@pytest.mark.parametrize("extra, message", [
    (["--rtol", "1e-6"], "--integrator dopri5"),
    (["--integrator", "dopri5", "--rtol", "2"], "rtol"),
    (["--integrator", "dopri5", "--atol", "-1"], "atol"),
])
def test_render_tolerance_errors(tmp_path, capsys, extra, message):
    out = tmp_path / "k.gif"
    assert main(["render", "kepler", "-o", str(out), "-q"] + SMALL + extra) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_render_substeps_option(tmp_path, capsys):
    out = tmp_path / "c.gif"
    base = ["render", "spring_chain", "-o", str(out), "-q", "--frames", "4", "--size", "64x48", "--frame-time", "0.01"]
    assert main(base + ["--substeps", "7"]) == 0
    stdout = capsys.readouterr().out
    assert "7 per frame (fixed" in stdout and "21 steps" not in stdout
    assert main(base + ["--substeps", "auto"]) == 0
    stdout = capsys.readouterr().out
    assert "automatic:" in stdout
    for bad in (["--substeps", "0"], ["--substeps", "many"]):
        assert main(base + bad) == 2
        assert "--substeps" in capsys.readouterr().err
    assert main(["render", "spring_chain", "-o", str(out), "-q", "--steps-per-frame", "3", "--substeps", "4"]) == 2
    assert "--substeps goes with --frame-time" in capsys.readouterr().err


def test_out_of_memory_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    # A MemoryError from anywhere in the run (here: the renderer) is reported in one line, with
    # exit code 2 and no traceback, and no file is left behind.
    def save(*args, **kwargs):
        raise MemoryError("frames: needs 12.0 GB for 400 frames")

    monkeypatch.setattr(render, "save", save)
    out = tmp_path / "x.gif"
    assert main(["render", "spring_chain", "-o", str(out), "--frames", "2", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "out of memory" in err and "12.0 GB" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_closed_pipe_is_not_a_traceback():
    # `physcore scenes | head -1`: the reader leaves early; the command ends quietly.
    with subprocess.Popen(
        [sys.executable, "-m", "physcore", "scenes"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0
    ) as proc:
        proc.stdout.read(1)
        proc.stdout.close()
        err = proc.stderr.read().decode()
        proc.wait(timeout=60)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert proc.returncode in (0, 1)  # 0 if it finished writing before the reader left


def test_scenes_describes_one_scene_in_full(capsys):
    assert cli.main(["scenes", "cloth"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("cloth\n\nHanging cloth") and "parameters (--param key=value)" in out
    assert "Render it with: physcore render cloth" in out
    assert cli.main(["scenes", "clth"]) == 2
    assert "did you mean 'cloth'?" in capsys.readouterr().err


@pytest.mark.parametrize(("option", "message"), [
    (["-o", "nodir/x.gif"], "-o: directory 'nodir' does not exist"),
    (["--cmap", "nope", "-o", "x.gif"], "--cmap: must be one of"),
    (["--trail", "-3", "-o", "x.gif"], "--trail: must be >= 0, got -3"),
    (["--background", "zz", "-o", "x.gif"], "--background: colours as text"),
])
def test_a_bad_option_is_named_as_typed(tmp_path, monkeypatch, capsys, option, message):
    monkeypatch.chdir(tmp_path)
    assert main(["render", "projectile", *option] + SMALL) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_the_cli_draws_curved_trail_pieces_from_the_velocities_as_the_library_does(tmp_path):
    # pythagorean draws each trail step as 8 Hermite pieces (look.trail_samples), which need the
    # recorded velocities; the CLI once recorded them only for arrows and drew Catmull-Rom curves.
    cli_out, lib_out = tmp_path / "cli.gif", tmp_path / "lib.gif"
    assert main(["render", "pythagorean", "-o", str(cli_out), "--frames", "12", "-q"]) == 0
    render.gif(pc.scenes.pythagorean(), lib_out, frames=12)
    no_velocities = tmp_path / "nov.gif"
    render.gif(render.record(pc.scenes.pythagorean(), frames=12, velocities=False), no_velocities)
    assert cli_out.read_bytes() == lib_out.read_bytes()
    assert cli_out.read_bytes() != no_velocities.read_bytes()  # the velocities do change the trails


def test_frames_a_built_scene_sets_are_checked_against_memory_before_simulating(tmp_path, monkeypatch, capsys):
    """A scene function may set frames or size on the scene it builds (double_slit sets its
    frame_time so): the frames buffer is checked again by the built scene's render_defaults,
    a usage error (exit 2) before any step, with no file written."""
    base = pc.scenes.spring_chain
    stepped = []

    def big(**kwargs):
        scene = base(**kwargs)
        scene.render_defaults = {**scene.render_defaults, "frames": 10**9, "size": (640, 480)}
        stepped.append(scene)
        return scene

    big.render_defaults = base.render_defaults
    monkeypatch.setattr(cli, "_registry", lambda: {"big": big})
    out = tmp_path / "b.gif"
    assert main(["render", "big", "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "--frames, --size" in err and "1000000000 frames of 640x480 pixels" in err, err
    assert not out.exists() and stepped and stepped[0].step_count == 0


def test_a_param_given_twice_is_a_usage_error(tmp_path, capsys):
    """The last of two would win unseen (kepler e=0.8 then e=0.5 drew e=0.5)."""
    out = tmp_path / "k.gif"
    assert main(["render", "kepler", "-o", str(out), "-q", "--param", "e=0.8", "--param", "e=0.5"] + SMALL) == 2
    assert "--param e given twice (0.8, 0.5)" in capsys.readouterr().err and not out.exists()
