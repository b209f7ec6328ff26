"""physcore.diagnostics: the energy recorder and its plot; `physcore render --energy-plot`."""
import numpy as np
import pytest
from PIL import Image

import physcore as pc
from physcore.cli import main
from physcore.diagnostics import EnergyRecorder


def test_recorder_matches_the_scene_books_and_drift():
    scene = pc.scenes.spring_chain(n=8, damping=0.05)
    rec = EnergyRecorder()
    rec.record(scene)
    for _ in range(10):
        scene.step(200)
        rec.record(scene)
    e = scene.energy()
    assert len(rec) == 11
    assert rec.time[-1] == scene.time and rec.total[-1] == e.total and rec.kinetic[-1] == e.kinetic
    assert set(rec.potential) == set(e.potential) and set(rec.dissipated) == set(e.dissipated)
    assert rec.dissipated["springs"][-1] > rec.dissipated["springs"][0] == 0.0  # dashpots dissipate
    # The recorder's drift uses the scene's definition (first sample = the reference state).
    assert rec.drift[0] == 0.0
    assert rec.drift[-1] == pytest.approx(scene.energy_drift(), rel=1e-12, abs=1e-15)
    total = rec.kinetic + sum(rec.potential.values()) + sum(rec.dissipated.values())
    assert np.allclose(total, rec.total, rtol=1e-12, atol=1e-12)


def test_plot_writes_a_png_atomically(tmp_path):
    scene = pc.scenes.projectile()
    rec = EnergyRecorder()
    for _ in range(5):
        rec.record(scene)
        scene.step(10)
    out = rec.plot(tmp_path / "e.png")
    with Image.open(out) as im:
        assert im.format == "PNG" and im.size[0] > 300
    assert [p.name for p in tmp_path.iterdir()] == ["e.png"]  # no temporary left behind


def test_plot_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="recorder"):
        EnergyRecorder().plot(tmp_path / "e.png")
    rec = EnergyRecorder()
    rec.record(pc.scenes.projectile())
    with pytest.raises(ValueError, match="path"):
        rec.plot(tmp_path / "e.jpg")


def test_cli_energy_plot(tmp_path, capsys):
    gif, png = tmp_path / "c.gif", tmp_path / "e.png"
    rc = main(["render", "spring_chain", "-o", str(gif), "--frames", "12", "--energy-plot", str(png), "--quiet"])
    assert rc == 0 and gif.exists()
    with Image.open(png) as im:
        assert im.format == "PNG"
    assert "energy books at 12 frames" in capsys.readouterr().out


def test_cli_energy_plot_needs_png(tmp_path):
    rc = main(["render", "spring_chain", "-o", str(tmp_path / "c.gif"), "--energy-plot", str(tmp_path / "e.pdf")])
    assert rc == 2 and not (tmp_path / "c.gif").exists()


def test_cli_energy_plot_into_a_missing_directory_is_a_usage_error(tmp_path, capsys):
    """Exit 2 (a usage error, as -o into a missing directory), before the scene is built; it
    was 1."""
    rc = main(["render", "spring_chain", "-o", str(tmp_path / "c.gif"), "--energy-plot", str(tmp_path / "nope" / "e.png")])
    assert rc == 2 and not (tmp_path / "c.gif").exists()
    assert "--energy-plot" in capsys.readouterr().err


def test_cli_says_what_fps_a_gif_plays_at_when_it_cannot_store_the_one_asked(tmp_path, capsys):
    """GIF delays are whole centiseconds from 2 to 65535: --fps 1e9 plays at 50 fps, and the
    summary says so (it said 1e+09 fps and 0.00 s)."""
    assert main(["render", "kepler", "-o", str(tmp_path / "k.gif"), "--frames", "3", "--fps", "1e9"]) == 0
    assert "so it plays at 50 fps" in capsys.readouterr().out
    assert main(["render", "kepler", "-o", str(tmp_path / "k.gif"), "--frames", "3", "--fps", "25"]) == 0
    assert "plays at" not in capsys.readouterr().out


def test_record_refuses_what_is_not_a_scene_and_a_second_scene():
    rec = EnergyRecorder()
    with pytest.raises(pc.InvalidTypeError, match="^scene: expected a physcore Scene"):
        rec.record(None)
    a, b = pc.scenes.projectile(), pc.scenes.spring_chain(n=4)
    rec.record(a)
    with pytest.raises(pc.InvalidInputError, match="^scene: this recorder follows another scene"):
        rec.record(b)  # its books mixed with a's made a drift of neither
    a.step(5)
    rec.record(a)
    assert len(rec) == 2
