"""Output formats beside the GIF: MP4 and WebM video (PyAV), PNG frame sequences, frames as numpy
arrays, the CLI's format by extension, and a Recording shown inline in a notebook."""
from __future__ import annotations

import base64
import errno
import io
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image, ImageSequence

import physcore as pc

av = pytest.importorskip("av")


def _gif_frames(data: bytes) -> list[np.ndarray]:
    with Image.open(io.BytesIO(data)) as im:
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]


@pytest.fixture(scope="module")
def rec():
    """A moving scene's recording (every frame differs, so the GIF keeps all of them)."""
    return pc.render.record(pc.scenes.kepler(e=0.6), frames=12, frame_time=0.5)  # a twelfth of an orbit a frame


def test_frames_are_the_gifs_frames(rec, tmp_path):
    # Hard-edged discs: the fixed palette, so the GIF holds the frames exactly.
    # radius=3: the scene's default discs (12 px, for its 380 × 320) would fill a 96 × 72 image.
    frames = list(pc.render.frames(rec, size=(96, 72), antialias=False, radius=3))
    assert len(frames) == 12 and frames[0].shape == (72, 96, 3) and frames[0].dtype == np.uint8
    gif = pc.render.gif(rec, tmp_path / "a.gif", size=(96, 72), antialias=False, radius=3)
    decoded = _gif_frames(gif.read_bytes())
    assert len(decoded) == 12
    for a, b in zip(frames, decoded, strict=True):
        assert np.array_equal(a, b)


def test_soft_disc_frames_are_the_gifs_up_to_its_palette(rec, tmp_path):
    # Soft discs (Kepler's default): full colour, one 256-colour palette for the GIF; the
    # frequent flat colours (background, text, trail) exact, the rest within a few levels.
    # halo=[]: without the star's glow, most of the small image is the flat background.
    frames = list(pc.render.frames(rec, size=(96, 72), radius=3, halo=[]))
    decoded = _gif_frames(pc.render.gif(rec, tmp_path / "a.gif", size=(96, 72), radius=3, halo=[]).read_bytes())
    assert len(decoded) == 12
    for a, b in zip(frames, decoded, strict=True):
        a, b = a.astype(int), b.astype(int)
        assert np.abs(a - b).mean() < 1.0
        background = np.all(a == a[0, 0], axis=2)
        assert background.mean() > 0.5 and np.all(b[background] == a[0, 0])


def test_png_sequence_holds_every_frame_exactly(rec, tmp_path):
    paths = pc.render.save(rec, tmp_path / "orbit.png", size=(64, 48))
    assert [p.name for p in paths] == [f"orbit_{k:04d}.png" for k in range(12)]
    frames = list(pc.render.frames(rec, size=(64, 48)))
    for p, f in zip(paths, frames, strict=True):
        assert np.array_equal(np.asarray(Image.open(p).convert("RGB")), f)


def test_png_sequence_on_a_full_disk_leaves_the_old_sequence_whole(rec, tmp_path, monkeypatch):
    # Issue 44, item 12: the disk fills while frame 5 is written, over an older sequence of 20
    # frames of the same name. Every old frame stays as it was (none of the new render's), and
    # no temporary file is left.
    old = {}
    for k in range(20):
        p = tmp_path / f"orbit_{k:04d}.png"
        Image.fromarray(np.full((8, 8, 3), k, dtype=np.uint8)).save(p)
        old[p.name] = p.read_bytes()
    real_save = Image.Image.save
    calls = []

    def save(self, fp, *args, **kwargs):
        calls.append(1)
        if len(calls) == 6:  # frames 0..4 written, frame 5 fails
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_save(self, fp, *args, **kwargs)

    monkeypatch.setattr(Image.Image, "save", save)
    with pytest.raises(OSError, match="No space left"):
        pc.render.save(rec, tmp_path / "orbit.png", size=(64, 48))
    assert len(calls) == 6
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(old)
    assert all((tmp_path / name).read_bytes() == data for name, data in old.items())


@pytest.mark.parametrize("ext", ["mp4", "webm"])
def test_a_video_on_a_full_disk_raises_the_oserror_and_keeps_the_old_file(rec, tmp_path, monkeypatch, ext):
    # A fault-injection review: under WebM's muxer PyAV wrapped the full disk's OSError in its
    # own callback error (a RuntimeError, "Error in PyAV callback: '3'"); MP4's came through.
    from physcore import _atomic

    target = tmp_path / f"orbit.{ext}"
    target.write_bytes(b"OLD")

    class Full(io.FileIO):
        def write(self, b):  # the disk fills after the first 4 KiB
            if self.tell() + len(b) > 4096:
                raise OSError(errno.ENOSPC, "No space left on device")
            return super().write(b)

    real_fdopen = _atomic.os.fdopen
    monkeypatch.setattr(_atomic.os, "fdopen", lambda fd, mode="r", **kw: Full(fd, "w") if "b" in mode else real_fdopen(fd, mode, **kw))
    with pytest.raises(OSError, match="No space left") as info:
        pc.render.save(rec, target, size=(320, 240))
    assert info.value.errno == errno.ENOSPC
    assert target.read_bytes() == b"OLD" and sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_a_render_path_with_a_nul_is_refused_by_name_before_anything_is_simulated(tmp_path):
    s = pc.scenes.kepler()
    for render, ext in ((pc.render.gif, "gif"), (pc.render.save, "mp4"), (pc.render.html, "html"), (pc.render.gltf, "glb")):
        with pytest.raises(pc.InvalidInputError, match="^path: contains a NUL character"):
            render(s, str(tmp_path / f"a\0b.{ext}"), frames=2, steps_per_frame=1)
    assert s.step_count == 0


def test_a_png_sequence_over_a_directory_is_refused_before_anything_is_simulated(tmp_path):
    # A fault audit: frame 1's name was a directory; found only as the frames were put in
    # place, after the simulation, it left frame 0 new and frames 2-3 old (a bare
    # IsADirectoryError). Now refused by name before the scene steps, every old frame kept.
    for k in (0, 2, 3):
        Image.fromarray(np.full((8, 8, 3), k, dtype=np.uint8)).save(tmp_path / f"seq_{k:04d}.png")
    (tmp_path / "seq_0001.png").mkdir()
    old = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    s = pc.scenes.projectile()
    with pytest.raises(pc.InvalidInputError, match=r"^path: frame file .*seq_0001\.png' is a directory"):
        pc.render.save(s, tmp_path / "seq.png", frames=4, size=(32, 24))
    assert s.step_count == 0
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == old


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes")
@pytest.mark.parametrize("ext", ["gif", "mp4", "png"])
def test_a_pipe_as_the_target_is_refused_before_anything_is_simulated(tmp_path, ext):
    # The same audit: a FIFO target was refused only by the final write, after the whole
    # simulation (the CLI simulated 120 frames first).
    import os

    name = "f_0000.png" if ext == "png" else f"f.{ext}"
    os.mkfifo(tmp_path / name)
    s = pc.scenes.projectile()
    with pytest.raises(pc.InvalidInputError, match="not a regular file"):
        pc.render.save(s, tmp_path / f"f.{ext}", frames=3, size=(32, 24))
    assert s.step_count == 0


@pytest.mark.parametrize(("ext", "codec"), [("mp4", "h264"), ("webm", "vp9")])
def test_video_has_the_frames_size_and_duration(rec, tmp_path, ext, codec):
    out = pc.render.save(rec, tmp_path / f"orbit.{ext}", size=(97, 71), fps=24)  # odd: padded to even
    with av.open(str(out)) as c:
        st = c.streams.video[0]
        assert st.codec_context.name == codec
        decoded = [f.to_ndarray(format="rgb24") for f in c.decode(st)]
    assert len(decoded) == 12
    assert decoded[0].shape == (72, 98, 3)
    want = list(pc.render.frames(rec, size=(97, 71), fps=24))
    # Lossy, but the same picture: mean error of a few levels out of 255.
    for got, ref in zip(decoded, want, strict=True):
        assert np.abs(got[:71, :97].astype(int) - ref.astype(int)).mean() < 6.0
    assert np.abs(decoded[0].astype(int) - decoded[-1].astype(int)).mean() > 0.1  # it moves


def test_save_refuses_unknown_extensions_and_missing_pyav(tmp_path, monkeypatch):
    scene = pc.scenes.kepler()
    with pytest.raises(ValueError, match=r"path must end in one of \.gif, \.mp4, \.webm, \.png"):
        pc.render.save(scene, tmp_path / "a.bmp", frames=2)
    monkeypatch.setitem(sys.modules, "av", None)
    with pytest.raises(ImportError, match=r'pip install "physcore\[video\]"'):
        pc.render.save(scene, tmp_path / "a.mp4", frames=2)
    assert scene.time == 0.0  # refused before simulating
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fps", [1e-300, 1e308])
def test_a_video_refuses_a_rate_it_cannot_carry_before_simulating(tmp_path, fps):
    # The stream's rate is a fraction of C ints: fps = 1e-300 rounded to 0 and FFmpeg wrote a
    # 24 fps video without a word; fps = 1e308 raised PyAV's bare OverflowError after simulating.
    scene = pc.scenes.kepler()
    for ext in ("mp4", "webm"):
        with pytest.raises(pc.InvalidInputError, match="fps"):
            pc.render.save(scene, tmp_path / f"a.{ext}", frames=2, fps=fps)
    assert scene.time == 0.0 and list(tmp_path.iterdir()) == []


def test_a_gif_refuses_a_rate_slower_than_its_longest_frame_before_simulating(tmp_path):
    # A GIF frame lasts at most 65535 cs: fps = 1e-308 was clamped to that without a word.
    scene = pc.scenes.kepler()
    for fps in (1e-308, 5e-324, 0.0015):
        with pytest.raises(pc.InvalidInputError, match=r"^fps must be at least 100/65535"):
            pc.render.gif(scene, tmp_path / "a.gif", frames=2, fps=fps)
    assert scene.time == 0.0 and list(tmp_path.iterdir()) == []
    pc.render.gif(scene, tmp_path / "a.gif", frames=2, fps=100 / 65535)  # the slowest a GIF plays
    assert (tmp_path / "a.gif").stat().st_size > 0


def test_diverging_video_render_leaves_no_file(tmp_path):
    scene = pc.Scene(dim=2, dt=0.05)
    scene.add_particles([[0.0, 0.0], [0.1, 0.0]], [[0.0, 0.0], [1.0, 0.0]], pinned=[True, False])
    scene.add(pc.Springs([0], [1], stiffness=1e9))
    with pytest.raises(pc.SimulationDiverged), pytest.warns(pc.StabilityWarning, match="stiffest spring"):
        pc.render.save(scene, tmp_path / "boom.mp4", frames=20, steps_per_frame=50)
    assert list(tmp_path.iterdir()) == []


def test_recording_shows_itself_in_a_notebook(rec):
    html = rec._repr_html_()
    assert html.startswith('<img src="data:image/gif;base64,') and "12 frames" in html
    data = base64.b64decode(html.split("base64,", 1)[1].split('"', 1)[0])
    assert len(_gif_frames(data)) == 12


def test_cli_picks_the_format_from_the_extension(tmp_path):
    run = [sys.executable, "-m", "physcore", "render", "kepler", "--frames", "6", "--size", "64x48"]
    r = subprocess.run([*run, "-o", str(tmp_path / "k.mp4")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    with av.open(str(tmp_path / "k.mp4")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 6
    r = subprocess.run([*run, "-o", str(tmp_path / "k.png")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(list(tmp_path.glob("k_*.png"))) == 6 and "wrote 6 frames" in r.stdout
    r = subprocess.run([*run, "-o", str(tmp_path / "k.bmp")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "extension picks the format" in r.stderr


def test_save_and_frames_take_gifs_options_only(tmp_path):
    scene = pc.scenes.kepler()
    with pytest.raises(TypeError, match="colour"):
        pc.render.save(scene, tmp_path / "a.png", colour="speed")
    with pytest.raises(TypeError, match="colour"):
        pc.render.frames(scene, colour="speed")
    with pytest.raises(TypeError, match="path"):
        pc.render.save(scene, None)
    assert scene.time == 0.0 and list(tmp_path.iterdir()) == []
