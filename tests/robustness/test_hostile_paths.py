"""Hostile paths and batch/results files: ``Batch.load``/``Batch.save`` check their path as
``Scene.load``/``Scene.save`` do, a batch file does not decide how many threads start, no writer
replaces a pipe, directory or socket by a plain file, and ``sweep(out=...)`` neither hangs on a
pipe nor resumes a results file whose header was edited.

Special files are made in ``tmp_path`` (a FIFO, a socket), never /dev's.
"""
from __future__ import annotations

import json
import os
import socket
import stat
import threading
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import physcore as pc
from physcore import batch as batch_mod
from physcore._atomic import atomic_write
from physcore._system import usable_cpus

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")


def _in_thread(f: Callable[[], Any], timeout: float = 10.0) -> BaseException | None:
    """What `f` raised (None if it returned), failing the test if it is still blocked after
    `timeout` s (the thread is a daemon: a blocked open of a FIFO cannot be interrupted)."""
    got: list[BaseException | None] = []

    def run() -> None:
        try:
            f()
            got.append(None)
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            got.append(exc)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(timeout)
    assert not t.is_alive(), "blocked on a named pipe"
    return got[0]


def _batch_file(tmp_path: Path, name: str = "b.batch", **meta_update: Any) -> Path:
    """A batch file of two Kepler members, its batch.json updated with `meta_update`."""
    good = pc.Batch.from_scene(pc.scenes.kepler(), 2).save(tmp_path / "good.batch")
    with zipfile.ZipFile(good) as z:
        items = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(items["batch.json"])
    meta.update(meta_update)
    items["batch.json"] = json.dumps(meta).encode()
    with zipfile.ZipFile(tmp_path / name, "w") as z:
        for n, d in items.items():
            z.writestr(n, d)
    return tmp_path / name


# ------------------------------------------------------------------------------ Batch.load
def test_batch_load_caps_the_files_thread_count_at_the_usable_cpus(tmp_path, monkeypatch):
    path = _batch_file(tmp_path, threads=2000)
    real, seen = batch_mod._core.step_batch, []

    def spy(sims, n, threads):
        seen.append(threads)
        if threads is None or threads > usable_cpus():  # do not start the file's 2000 threads
            raise AssertionError(f"the core was asked for {threads} threads")
        return real(sims, n, threads)

    monkeypatch.setattr(batch_mod._core, "step_batch", spy)
    b = pc.Batch.load(path)
    b.step(3)
    assert seen == [min(2000, usable_cpus())]
    assert (b.time > 0).all()


@pytest.mark.parametrize("key", ["\u00b2", "\u0661", "1" * 5000], ids=["superscript", "arabic-one", "huge"])
def test_batch_load_refuses_a_diverged_key_naming_no_member(tmp_path, key):
    # "²" and "1"*5000 pass str.isdigit() but int() refuses them (a bare ValueError); "١" (an
    # Arabic-Indic one) was taken as member 1.
    path = _batch_file(tmp_path, diverged={key: "x"})
    with pytest.raises(pc.SceneFileError, match=r"b\.batch: batch\.json\.diverged: names no member") as e:
        pc.Batch.load(path)
    assert e.value.field == "batch.json.diverged"


@pytest.mark.parametrize("bad", [None, 123, 1.5, b"b.batch"])
def test_batch_load_and_save_refuse_a_path_that_is_no_file_name(tmp_path, bad):
    b = pc.Batch.from_scene(pc.scenes.kepler(), 2)
    with pytest.raises(pc.InvalidTypeError, match="^path: expected a file name"):
        pc.Batch.load(bad)
    with pytest.raises(pc.InvalidTypeError, match="^path: expected a file name"):
        b.save(bad)
    with pytest.raises(pc.InvalidInputError, match="^path: contains a NUL"):
        b.save(str(tmp_path / "a\0b.batch"))
    assert list(tmp_path.iterdir()) == []


@needs_fifo
def test_batch_load_refuses_a_fifo_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.batch"
    os.mkfifo(fifo)
    exc = _in_thread(lambda: pc.Batch.load(fifo))
    assert type(exc) is pc.SceneFileError and "not a regular file" in str(exc) and str(fifo) in str(exc), exc


def test_batch_load_refuses_a_directory_and_names_a_missing_file(tmp_path):
    with pytest.raises(pc.SceneFileError, match="not a regular file"):
        pc.Batch.load(tmp_path)
    # A missing file raises FileNotFoundError naming it, as Scene.load does (it was a
    # SceneFileError wrapping one: a caller had to catch two kinds for one mistake).
    with pytest.raises(FileNotFoundError, match=r"nope\.batch"):
        pc.Batch.load(tmp_path / "nope.batch")
    with pytest.raises(FileNotFoundError, match=r"nope\.npz"):
        pc.Scene.load(tmp_path / "nope.npz")


# ------------------------------------------------------------------------------ atomic writes
@needs_fifo
@pytest.mark.parametrize("writer", ["scene", "batch", "atomic_write"])
def test_a_fifo_target_is_refused_before_anything_is_written(tmp_path, writer):
    fifo = tmp_path / "pipe.npz"
    os.mkfifo(fifo)
    calls: list[int] = []
    save = {
        "scene": lambda: pc.scenes.kepler().save(fifo),
        "batch": lambda: pc.Batch.from_scene(pc.scenes.kepler(), 2).save(fifo),
        "atomic_write": lambda: atomic_write(fifo, lambda fh: calls.append(1)),
    }[writer]
    with pytest.raises(pc.InvalidInputError, match=r"^path: '.*pipe\.npz' is a named pipe, not a regular file"):
        save()
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still the pipe, not a zip in its place
    assert calls == [] and sorted(p.name for p in tmp_path.iterdir()) == ["pipe.npz"]  # no temporary file


def test_a_directory_or_a_link_to_one_is_refused_a_link_to_a_file_is_written_through(tmp_path):
    (tmp_path / "d.npz").mkdir()
    (tmp_path / "link.npz").symlink_to(tmp_path / "d.npz")
    for target in ("d.npz", "link.npz"):
        with pytest.raises(pc.InvalidInputError, match=rf"^path: '.*{target}' is a directory, not a regular file"):
            pc.scenes.kepler().save(tmp_path / target)
    assert (tmp_path / "link.npz").is_symlink() and list((tmp_path / "d.npz").iterdir()) == []
    # A link to a regular file: replaced by the new file, as before (the file it named is kept).
    (tmp_path / "old.npz").write_bytes(b"old")
    (tmp_path / "to_file.npz").symlink_to(tmp_path / "old.npz")
    pc.scenes.kepler().save(tmp_path / "to_file.npz")
    assert not (tmp_path / "to_file.npz").is_symlink() and (tmp_path / "old.npz").read_bytes() == b"old"
    assert pc.Scene.load(tmp_path / "to_file.npz").n_particles == pc.scenes.kepler().n_particles


@pytest.mark.skipif(not hasattr(socket, "AF_UNIX"), reason="needs Unix sockets")
def test_a_socket_target_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a short name: a socket's path is limited to ~100 bytes
    with socket.socket(socket.AF_UNIX) as s:
        s.bind("s.npz")
        with pytest.raises(pc.InvalidInputError, match=r"^path: 's\.npz' is a socket, not a regular file"):
            pc.scenes.kepler().save("s.npz")
        assert stat.S_ISSOCK(os.lstat("s.npz").st_mode)


# ------------------------------------------------------------------------------ sweep(out=...)
def _build(dt: float, n: int = 1) -> pc.Scene:
    s = pc.Scene(2, dt=dt)
    s.add_particles([[0.0, float(n)]])
    s.add(pc.Gravity([0.0, -9.81]))
    return s


CALLS: list[float] = []


def _measure(s: pc.Scene) -> dict:
    CALLS.append(s.dt)
    s.step(5)
    return {"y": float(s.positions[0, 1])}


@needs_fifo
def test_sweep_refuses_a_fifo_out_without_blocking(tmp_path):
    pytest.importorskip("pandas")
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    CALLS.clear()
    exc = _in_thread(lambda: pc.sweep(_build, {"dt": [0.1]}, measure=_measure, client="serial", progress=False, out=fifo))
    assert isinstance(exc, pc.InvalidInputError) and str(exc).startswith("out: ") and "not a regular file" in str(exc), exc
    assert CALLS == [] and stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_sweep_refuses_a_directory_out(tmp_path):
    pytest.importorskip("pandas")
    (tmp_path / "d.csv").mkdir()
    with pytest.raises(pc.InvalidInputError, match=r"^out: '.*d\.csv' is not a regular file"):
        pc.sweep(_build, {"dt": [0.1]}, measure=_measure, client="serial", progress=False, out=tmp_path / "d.csv")


def test_sweep_refuses_to_resume_a_file_whose_parameter_column_was_renamed(tmp_path):
    pd = pytest.importorskip("pandas")
    out = tmp_path / "runs.csv"
    grid = {"dt": [0.1, 0.2], "n": [1, 2]}
    pc.sweep(_build, grid, measure=_measure, client="serial", progress=False, out=out)
    header, rest = out.read_text().split("\n", 1)
    assert header.split(",")[1:3] == ["dt", "n"]
    out.write_text(header.replace(",n,", ",height,", 1) + "\n" + rest)  # the run_keys still match
    before = out.read_text()
    CALLS.clear()
    with pytest.raises(pc.InvalidInputError, match=r"^out: '.*runs\.csv': its columns differ from the sweep's parameters: no column 'n'"):
        pc.sweep(_build, grid, measure=_measure, client="serial", progress=False, out=out)
    assert CALLS == [] and out.read_text() == before
    # The file as the sweep wrote it still resumes, running nothing.
    out.write_text(before.replace(",height,", ",n,", 1))
    df = pc.sweep(_build, grid, measure=_measure, client="serial", progress=False, out=out)
    assert CALLS == [] and len(df) == 4 and list(pd.read_csv(out).columns[1:3]) == ["dt", "n"]


def test_saving_into_a_missing_directory_names_the_target_not_a_temporary_file(tmp_path):
    """Scene.save into a missing directory: a FileNotFoundError naming the file asked for (it
    named the temporary file the atomic write tried to create there)."""
    target = tmp_path / "nope" / "x.npz"
    with pytest.raises(FileNotFoundError, match=r"path: cannot write .*nope/x\.npz") as e:
        pc.scenes.kepler().save(target)
    assert ".tmp" not in str(e.value) and not target.parent.exists()
