"""physcore.Batch: many scenes stepped in one call (issue "Many small worlds at once").

What a member does alone it does in the batch, bit for bit, for any thread count; a diverging
member is rolled back alone and retired while the others go on; Ctrl-C rolls every member back;
a saved batch continues bit for bit; bad input is refused by name before anything steps."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

import physcore as pc


def _fan(m: int, scene=None) -> list[pc.Scene]:
    """``m`` figure-eight three-body problems, member k's positions scaled by 1 + 1e-3 k."""
    base = scene if scene is not None else pc.scenes.figure_eight(integrator="yoshida4")
    return list(pc.Batch.from_scene(base, m, positions=lambda k, x: x * (1 + 1e-3 * k)).members)


def _alone(scenes: list[pc.Scene], n: int) -> list[pc.Scene]:
    import pickle

    copies = [pickle.loads(pickle.dumps(s)) for s in scenes]
    for c in copies:
        c.step(n)
    return copies


def _same(a: pc.Scene, b: pc.Scene) -> bool:
    return (
        np.array_equal(a.positions, b.positions)
        and np.array_equal(a.velocities, b.velocities)
        and a.time == b.time
        and a.step_count == b.step_count
        and a.energy().total == b.energy().total
    )


@pytest.mark.parametrize("threads", [1, 2])
def test_members_step_bit_for_bit_as_they_would_alone(threads):
    members = _fan(24)
    alone = _alone(members, 700)
    batch = pc.Batch(members, threads=threads)
    batch.step(300)
    batch.step(400)
    assert not batch.diverged
    assert all(_same(b, a) for b, a in zip(batch.members, alone, strict=True))
    assert batch.positions.shape == (24, 3, 2) and batch.time.shape == (24,) and (batch.step_count == 700).all()
    # The members differ (a fan, not copies).
    assert not np.array_equal(batch.positions[0], batch.positions[1])


def test_large_members_that_fork_inside_agree_too():
    """Members above the parallel threshold (5 041-particle cloths, whose own loops fork onto
    their own pools) are bit-identical to stepping alone, with 1 and 2 batch threads."""
    base = pc.scenes.cloth(n=71)
    runs = []
    for threads in (1, 2):
        members = list(pc.Batch.from_scene(base, 3, velocities=lambda k, v: v + [0.0, 0.01 * k, 0.0]).members)
        alone = _alone(members, 40)
        pc.Batch(members, threads=threads).step(40)
        assert all(_same(b, a) for b, a in zip(members, alone, strict=True))
        runs.append(np.stack([m.positions for m in members]))
    assert np.array_equal(runs[0], runs[1])


def test_a_diverging_member_is_rolled_back_and_retired_alone():
    members = _fan(4, pc.scenes.spring_chain())
    members[2].dt = 1.0  # far past the chain's stability limit: it blows up at step 31
    before = members[2].positions
    alone = _alone([members[k] for k in (0, 1, 3)], 200)
    batch = pc.Batch(members)
    batch.step(200)
    assert list(batch.diverged) == [2]
    e = batch.diverged[2]
    assert isinstance(e, pc.SimulationDiverged) and e.rolled_back_to == 0 and e.step == 31
    assert np.array_equal(members[2].positions, before) and members[2].step_count == 0
    assert all(_same(members[k], a) for k, a in zip((0, 1, 3), alone, strict=True))
    batch.step(10)  # the retired member is not stepped again
    assert members[2].step_count == 0 and members[0].step_count == 210


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_rolls_every_member_back():
    members = _fan(64, pc.scenes.figure_eight(integrator="dopri5"))
    before = [(m.positions, m.velocities, m.step_count, m.time) for m in members]
    batch = pc.Batch(members, threads=2)
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            batch.step(10**9)
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 10.0
    for m, (x, v, n, t) in zip(members, before, strict=True):
        assert np.array_equal(m.positions, x) and np.array_equal(m.velocities, v)
        assert m.step_count == n and m.time == t
    assert not batch.diverged


def test_save_and_load_continue_bit_for_bit(tmp_path):
    members = _fan(5, pc.scenes.spring_chain())
    members[4].dt = 1.0
    batch = pc.Batch(members, threads=2)
    batch.step(100)
    path = batch.save(tmp_path / "fan.batch")
    copy = pc.Batch.load(path)
    assert len(copy) == 5 and list(copy.diverged) == [4] and "diverged" in repr(copy)
    batch.step(150)
    copy.step(150)
    assert all(_same(a, b) for a, b in zip(batch.members, copy.members, strict=True))


def test_a_broken_batch_file_is_refused_naming_what(tmp_path):
    import zipfile

    path = pc.Batch(_fan(2)).save(tmp_path / "ok.batch")
    (tmp_path / "junk.batch").write_bytes(b"not a zip")
    with pytest.raises(pc.SceneFileError, match="not a batch file"):
        pc.Batch.load(tmp_path / "junk.batch")
    with zipfile.ZipFile(path) as z, zipfile.ZipFile(tmp_path / "bad.batch", "w") as out:
        out.writestr("batch.json", z.read("batch.json"))
        out.writestr("member0.npz", z.read("member0.npz"))
        out.writestr("member1.npz", b"PK junk")
    with pytest.raises(pc.SceneFileError, match="member1"):
        pc.Batch.load(tmp_path / "bad.batch")


def test_bad_input_is_refused_by_name_before_anything_steps():
    a, b = _fan(2)
    with pytest.raises(pc.InvalidInputError, match="at least one"):
        pc.Batch([])
    with pytest.raises(TypeError, match="scenes"):
        pc.Batch(a)
    with pytest.raises(TypeError, match="entry 1"):
        pc.Batch([a, "b"])
    with pytest.raises(pc.InvalidInputError, match="entry 1 is entry 0"):
        pc.Batch([a, a])
    with pytest.raises(pc.InvalidInputError, match="entry 1 differs .* particle count"):
        pc.Batch([a, pc.scenes.kepler()])
    with pytest.raises(pc.InvalidInputError, match="entry 1 differs .* parts"):
        c = pc.Scene(2)
        c.add_particles(a.positions, a.velocities, a.masses)
        pc.Batch([a, c])
    with pytest.raises(pc.InvalidInputError, match="n"):
        pc.Batch([a, b]).step(-1)
    with pytest.raises(TypeError, match="threads"):
        pc.Batch([a, b], threads="2")
    assert a.step_count == 0 and b.step_count == 0


def test_a_batch_renders_as_one_animation_of_its_members_overlaid(tmp_path):
    """``render.record``/``render.gif`` take a batch: every frame holds every member's particles
    (member k's particle i at k·N + i, equal to the member's own positions), each member its own
    hue; stepping the recording stepped the batch."""
    fan = pc.Batch.from_scene(pc.scenes.figure_eight(), 6, positions=lambda k, x: x * (1 + 2e-3 * k))
    rec = pc.render.record(fan, frames=5, steps_per_frame=40)
    assert rec.positions.shape == (5, 18, 2) and (fan.step_count == 160).all()
    last = rec.positions[-1].astype(np.float64) + rec.origin
    assert np.allclose(last, fan.positions.reshape(18, 2), atol=1e-6)
    colors = np.array(fan.render_defaults["colors"])
    assert colors.shape == (18, 3) and len({tuple(c) for c in colors}) == 6
    assert fan.render_defaults["color_by"] == "none"
    path = pc.render.gif(fan, tmp_path / "fan.gif", frames=8, steps_per_frame=20, size=(160, 120))
    assert path.read_bytes()[:6] == b"GIF89a"
