"""The ``physcore`` command line (physcore.cli): scenes listing, render, errors and exit codes."""
from __future__ import annotations

import shutil
import subprocess
import sys

import pytest
from PIL import Image

from physcore.cli import main

SMALL = ["--frames", "5", "--size", "64x48", "--steps-per-frame", "2"]


def test_render_spring_chain(tmp_path, capsys):
    out = tmp_path / "x.gif"
    assert main(["render", "spring_chain", "-o", str(out)] + SMALL) == 0
    with Image.open(out) as im:
        assert im.n_frames == 5
        assert im.size == (64, 48)
    stdout = capsys.readouterr().out
    assert str(out) in stdout
    assert "energy drift:" in stdout and "(relative)" in stdout
    assert "simulated time:" in stdout and "wall time:" in stdout
    assert list(tmp_path.iterdir()) == [out]


def test_render_default_output_path_and_params(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["render", "spring_chain", "--param", "dim=3", "--param", "n=6", "--integrator", "rk4", "--dt", "5e-4", "-q"]
    assert main(args + SMALL) == 0
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


def test_unknown_scene(tmp_path, capsys):
    assert main(["render", "nosuchscene", "-o", str(tmp_path / "x.gif")]) == 2
    err = capsys.readouterr().err
    assert "nosuchscene" in err and "spring_chain" in err
    assert list(tmp_path.iterdir()) == []


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
        ["--param", "n=0"],  # rejected by the scene itself
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, extra):
    assert main(["render", "spring_chain", "-o", str(tmp_path / "x.gif"), "-q"] + extra) == 2
    assert "error" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_bad_output_path_exit_2(tmp_path, capsys):
    assert main(["render", "spring_chain", "-o", str(tmp_path / "x.png"), "-q"] + SMALL) == 2
    assert ".gif" in capsys.readouterr().err
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
