"""physcore.Batch: many scenes stepped in one call (issue "Many small worlds at once").

What a member does alone it does in the batch, bit for bit, for any thread count; a diverging
member is rolled back alone and retired while the others go on; Ctrl-C rolls every member back;
a saved batch continues bit for bit; bad input is refused by name before anything steps."""
from __future__ import annotations

import json
import pickle
import sys
import time

import numpy as np
import pytest
from conftest import batch_uses_say_busy
from test_interrupt import _interrupt

import physcore as pc


def _fan(m: int, scene=None) -> list[pc.Scene]:
    """``m`` figure-eight three-body problems, member k's positions scaled by 1 + 1e-3 k."""
    base = scene if scene is not None else pc.scenes.figure_eight(integrator="yoshida4")
    return list(pc.Batch.from_scene(base, m, positions=lambda k, x: x * (1 + 1e-3 * k)).members)


def _alone(scenes: list[pc.Scene], n: int) -> list[pc.Scene]:
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
    # The books' reference each member took at its first step (in one call for all members).
    assert all(b.energy_drift() == a.energy_drift() for b, a in zip(batch.members, alone, strict=True))
    assert batch.positions.shape == (24, 3, 2) and batch.time.shape == (24,) and (batch.step_count == 700).all()
    # The members differ (a fan, not copies).
    assert not np.array_equal(batch.positions[0], batch.positions[1])


def _small_nbody(dim: int) -> pc.Scene:
    """Five bodies, one pinned, under pairwise and uniform gravity: what the fused kernel of
    small N-body members steps (rust_core/src/batch.rs)."""
    rng = np.random.default_rng(7)
    scene = pc.Scene(dim, integrator="yoshida4", dt=2e-3)
    scene.add_particles(rng.normal(size=(5, dim)), 0.3 * rng.normal(size=(5, dim)), masses=rng.uniform(0.5, 2.0, 5),
                        pinned=[False, False, True, False, False])
    scene.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    scene.add(pc.Gravity(g=[0.0, -0.5, 0.1][:dim]))
    return scene


@pytest.mark.parametrize("dim", [2, 3])
def test_small_nbody_members_of_mixed_integrators_and_steps_keep_their_bits_at_every_simd_level(dim):
    """Small N-body members go through the fused kernel (one member per SIMD lane), the others
    (rk4 here) through the general step, in one batch: every member has its bits alone, at
    every SIMD level this CPU has, with 1 and 2 threads, across two calls (the force cache the
    kernel leaves behind), its force evaluations counted as alone."""
    try:
        for level in pc.simd_levels():
            pc.set_simd_level(level)
            members = _fan(11, _small_nbody(dim))
            for k, m in enumerate(members):
                m.integrator = ("verlet", "yoshida4", "rk4")[k % 3]
                m.dt = 2e-3 * (1 + 0.1 * k)
            alone = _alone(members, 130)
            for threads in (1, 2):
                batch = pc.Batch([pickle.loads(pickle.dumps(m)) for m in members], threads=threads)
                batch.step(90)
                batch.step(40)
                assert not batch.diverged
                for b, a in zip(batch.members, alone, strict=True):
                    assert _same(b, a), (level, threads, b.integrator)
                    assert b.force_evaluations == a.force_evaluations and b.energy_drift() == a.energy_drift()
    finally:
        pc.set_simd_level(None)


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
    members[2].dt = 1.0  # far past the chain's stability limit: it blows up within a few dozen steps
    before, file = members[2].positions, members[2].to_bytes()
    alone = _alone([members[k] for k in (0, 1, 3)], 200)
    with pytest.raises(pc.SimulationDiverged) as lone, pytest.warns(pc.StabilityWarning):  # the same member stepped alone
        pickle.loads(pickle.dumps(members[2])).step(200)
    batch = pc.Batch(members)
    batch.step(200)
    assert list(batch.diverged) == [2]
    e = batch.diverged[2]
    assert isinstance(e, pc.SimulationDiverged) and e.rolled_back_to == 0 and 0 < e.step == lone.value.step < 200
    assert np.array_equal(members[2].positions, before) and members[2].step_count == 0
    # Byte for byte as before, the books' reference too (the batch took it for the first step).
    assert members[2].to_bytes() == file
    assert all(_same(members[k], a) for k, a in zip((0, 1, 3), alone, strict=True))
    batch.step(10)  # the retired member is not stepped again
    assert members[2].step_count == 0 and members[0].step_count == 210


def test_a_small_nbody_member_that_diverges_in_the_fused_kernel_fails_alone():
    """A fused member flying past the largest float is stepped again alone, which reports its
    divergence and rolls it back; the other members of its SIMD chunk are written back."""
    members = _fan(6)
    members[3].positions = members[3].positions * 1.79e308  # past the largest float in ~20 steps
    members[3].velocities = members[3].velocities * 1e308
    alone = _alone([m for k, m in enumerate(members) if k != 3], 200)
    twin = pickle.loads(pickle.dumps(members[3]))
    with pytest.raises(pc.SimulationDiverged) as alone_error:
        twin.step(200)
    before, file = members[3].positions, members[3].to_bytes()
    batch = pc.Batch(members)
    batch.step(200)
    assert list(batch.diverged) == [3]
    assert batch.diverged[3].step == alone_error.value.step and batch.diverged[3].rolled_back_to == 0
    assert np.array_equal(members[3].positions, before) and members[3].to_bytes() == file
    assert all(_same(b, a) for b, a in zip([m for k, m in enumerate(members) if k != 3], alone, strict=True))


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("integrator", ["dopri5", "yoshida4"])  # the general step, the fused kernel
def test_ctrl_c_rolls_every_member_back(integrator):
    members = _fan(64, pc.scenes.figure_eight(integrator=integrator))
    before = [(m.positions, m.velocities, m.step_count, m.time) for m in members]
    files = [m.to_bytes() for m in members]
    batch = pc.Batch(members, threads=2)
    assert _interrupt(lambda: batch.step(10**9), 0.3) < 9.7  # 10 s from the call's start
    for m, (x, v, n, t) in zip(members, before, strict=True):
        assert np.array_equal(m.positions, x) and np.array_equal(m.velocities, v)
        assert m.step_count == n and m.time == t
    assert [m.to_bytes() for m in members] == files  # the first call's books' reference undone too
    assert not batch.diverged


def _blow_up_chain(s: pc.Scene) -> None:
    s.dt = 1.0  # far past the chain's stability limit


def _blow_up_orbit(s: pc.Scene) -> None:
    s.positions, s.velocities = s.positions * 1.79e308, s.velocities * 1e308  # past the largest float in ~20 steps


@pytest.mark.parametrize("make, blow_up", [(pc.scenes.spring_chain, _blow_up_chain), (pc.scenes.figure_eight, _blow_up_orbit)],
                         ids=["general", "fused"])
def test_save_and_load_continue_bit_for_bit(tmp_path, make, blow_up):
    members = _fan(5, make())
    blow_up(members[4])
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


def test_hostile_batch_files_raise_scene_file_error(tmp_path):
    """What the hostile run found (issue "Physics you can trust, round 2", item 9): a compressed
    member (inflated whole before: a 1 MB file peaked at 2 GB), JSON nested past the recursion
    limit (a bare RecursionError), members of two different scenes (InvalidInputError): each a
    SceneFileError naming the field."""
    import zipfile

    path = pc.Batch(_fan(2)).save(tmp_path / "ok.batch")
    with zipfile.ZipFile(path) as z:
        parts = {n: z.read(n) for n in z.namelist()}

    def write(name, entries, deflated=()):
        with zipfile.ZipFile(tmp_path / name, "w") as out:
            for n, b in entries.items():
                out.writestr(n, b, zipfile.ZIP_DEFLATED if n in deflated else zipfile.ZIP_STORED)
        return tmp_path / name

    with pytest.raises(pc.SceneFileError, match="member0.npz: compressed"):
        pc.Batch.load(write("zipped.batch", parts, deflated={"member0.npz"}))
    with pytest.raises(pc.SceneFileError, match="batch.json: not JSON"):
        pc.Batch.load(write("deep.batch", {**parts, "batch.json": b"[" * 100_000 + b"]" * 100_000}))
    other = pc.scenes.kepler().__reduce__()[1][0]
    with pytest.raises(pc.SceneFileError, match="batch.json.members: .*differs"):
        pc.Batch.load(write("mixed.batch", {**parts, "member1.npz": other}))


def test_overlapping_extra_and_loosely_typed_batch_members_are_refused_before_any_is_read(tmp_path):
    """A fault audit: members whose data overlap (each begins with the next's header) let a
    1.5 MB file claim 5 GB, all read before any was checked (a bare MemoryError under a 3 GB
    cap); a member save never writes, a format of ``true`` and a retired member's message that
    is not a string were accepted; a missing file was a SceneFileError where Scene.load raises
    FileNotFoundError."""
    import struct
    import zipfile
    import zlib

    path = pc.Batch(_fan(2)).save(tmp_path / "ok.batch")
    with zipfile.ZipFile(path) as z:
        parts = {n: z.read(n) for n in z.namelist()}

    def write(name, entries):
        with zipfile.ZipFile(tmp_path / name, "w") as out:
            for n, b in entries.items():
                out.writestr(n, b, zipfile.ZIP_STORED)
        return tmp_path / name

    def header(name, data):
        n = name.encode()
        return struct.pack("<4sHHHHHIIIHH", b"PK\x03\x04", 20, 0, 0, 0, 0x21, zlib.crc32(data), len(data), len(data), len(n), 0) + n

    # member0's data is member1's header and data: 2 members in the bytes of one.
    meta = json.dumps({**json.loads(parts["batch.json"]), "members": 2}).encode()
    inner = header("member1.npz", parts["member1.npz"]) + parts["member1.npz"]
    out = bytearray(header("batch.json", meta) + meta)
    entries = [("batch.json", meta, 0), ("member0.npz", inner, len(out))]
    out += header("member0.npz", inner) + inner
    entries.append(("member1.npz", parts["member1.npz"], entries[1][2] + len(header("member0.npz", inner))))
    cd = b"".join(struct.pack("<4sHHHHHHIIIHHHHHII", b"PK\x01\x02", 20, 20, 0, 0, 0, 0x21, zlib.crc32(d), len(d), len(d),
                              len(n.encode()), 0, 0, 0, 0, 0, at) + n.encode() for n, d, at in entries)
    start = len(out)
    out += cd + struct.pack("<4sHHHHIIH", b"PK\x05\x06", 0, 0, 3, 3, len(cd), start, 0)
    (tmp_path / "overlap.batch").write_bytes(bytes(out))
    with pytest.raises(pc.SceneFileError, match="members claim .* more than the file's"):
        pc.Batch.load(tmp_path / "overlap.batch")
    with pytest.raises(pc.SceneFileError, match="unexpected member"):
        pc.Batch.load(write("extra.batch", {**parts, "evil.py": b"print('hi')"}))
    for fmt in (True, 1.0, "1"):
        bad = json.dumps({**json.loads(parts["batch.json"]), "format": fmt}).encode()
        with pytest.raises(pc.SceneFileError, match="batch.json.format"):
            pc.Batch.load(write("fmt.batch", {**parts, "batch.json": bad}))
    bad = json.dumps({**json.loads(parts["batch.json"]), "diverged": {"1": {"x": 1}}}).encode()
    with pytest.raises(pc.SceneFileError, match=r"batch.json.diverged.1: must be a message"):
        pc.Batch.load(write("msg.batch", {**parts, "batch.json": bad}))
    with pytest.raises(FileNotFoundError):
        pc.Batch.load(tmp_path / "missing.batch")
    assert len(pc.Batch.load(path)) == 2


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


def test_n_past_a_members_largest_step_count_is_refused_before_any_member_steps(tmp_path):
    """The core checks ``n`` against every member's step count before stepping any: a member
    whose count is near 2**63 - 1 (a scene file may hold one) stops the whole call."""
    a, b = _fan(2)
    path = a.save(tmp_path / "a.npz")
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    meta["step"] = 2**63 - 10
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "late.npz", **arrays)
    late = pc.Scene.load(tmp_path / "late.npz")
    batch = pc.Batch([b, late])
    before = batch.positions
    with pytest.raises(pc.InvalidInputError, match=r"^n: 20 more steps .* 2\*\*63 - 1"):
        batch.step(20)
    assert np.array_equal(batch.positions, before) and list(batch.step_count) == [0, 2**63 - 10]
    batch.step(9)  # up to the largest count: allowed
    assert list(batch.step_count) == [9, 2**63 - 1]


def test_a_member_used_by_another_thread_while_its_batch_steps_says_so():
    """While a batch steps (GIL released), another thread's use of a member raises
    SceneBusyError (a PhyscoreError) naming the other thread, as a scene stepped alone does, never
    pyo3's bare "Already mutably borrowed"; the batch's call is unharmed."""
    batch = pc.Batch(_fan(2, pc.scenes.cloth(n=32, threads=1)), threads=1)
    if not batch_uses_say_busy(batch, lambda: batch.step(3000)):  # it lost the race: again
        return test_a_member_used_by_another_thread_while_its_batch_steps_says_so()
    assert all(c in (3000, 3001, 3002, 3003) for c in batch.step_count)


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


def test_from_scene_refuses_copies_that_would_not_fit_before_making_any():
    """m copies are estimated (twice the pickled size plus 4 kB each) before the first is made:
    2^24 figure-eights (about 200 GB) are refused at once, naming m (the hostile run waited
    644 s for a bare MemoryError)."""
    t0 = time.perf_counter()
    with pytest.raises(pc.OutOfMemoryError, match="^m: ") as err:
        pc.Batch.from_scene(pc.scenes.figure_eight(), 1 << 24)
    assert time.perf_counter() - t0 < 5.0
    assert err.value.bytes > 1e11


@pytest.mark.parametrize("make", [pc.scenes.tablecloth, pc.scenes.dominoes])
def test_from_scene_copies_are_the_scenes_file_each_with_its_own_arrays(make):
    """from_scene reads the scene file once and builds every copy from it (the parse was 85 %
    of a copy's time): each copy's file is the scene's, byte for byte, as a pickled copy's is,
    and no two copies share an array of their parts or their render_defaults, so changing or
    stepping one leaves the others as they were."""
    scene = make()
    b = pc.Batch.from_scene(scene, 3)
    data = scene.to_bytes()
    assert data == pickle.loads(pickle.dumps(scene)).to_bytes()
    assert all(m.to_bytes() == data for m in b.members)

    def arrays(s: pc.Scene) -> list[np.ndarray]:
        return [v for part in s.parts for v in vars(part).values() if isinstance(v, np.ndarray)]

    a0, a1 = arrays(b[0]), arrays(b[1])
    assert a0 and len(a0) == len(a1)
    assert not any(np.shares_memory(x, y) for x in a0 for y in a1)
    assert b[0].render_defaults == scene.render_defaults
    assert b[0].render_defaults is not b[1].render_defaults
    b[0].step(3)
    assert b[1].to_bytes() == data and b[0].to_bytes() != data


@pytest.mark.parametrize("make", [lambda: pc.scenes.figure_eight(integrator="yoshida4"), pc.scenes.tablecloth,
                                  lambda: pc.scenes.spring_chain(6000, damping=0.5)])
def test_the_books_of_every_member_are_each_members_own_bit_for_bit(make):
    """energy_total and energy_drift read small members' books in one call into the core and
    larger ones (a 6000-particle chain) alone: each value is the member's own Scene.energy()
    total and Scene.energy_drift(), bit for bit, before the first step (drift 0) and after."""
    b = pc.Batch.from_scene(make(), 3, velocities=lambda k, v: v + 0.01 * k)
    assert np.array_equal(b.energy_drift(), np.zeros(3))
    b.step(20)
    total, drift = b.energy_total(), b.energy_drift()
    assert total.tolist() == [m.energy().total for m in b.members]
    assert drift.tolist() == [m.energy_drift() for m in b.members]
    assert np.all(drift != 0) and len(set(total.tolist())) == 3  # the members differ, and drift


def test_the_books_add_left_to_right_under_every_python():
    """The books' parts are summed from 0.0 left to right, as the core adds them (Python 3.12's
    sum() compensates its rounding and would give 1.0 here): a total is the same bits in Python
    and in the core, whichever Python runs."""
    from physcore.session import books, left_sum

    assert left_sum([1e16, 1.0, -1e16]) == 0.0 and left_sum([]) == 0.0
    d = {"kinetic": 1.0, "potential": [("a", 1e16), ("b", 1.0), ("c", -1e16)], "dissipated": [("d", 2.0)]}
    assert books(d) == ((1.0 + ((1e16 + 1.0) - 1e16)) + 2.0, (1.0 + ((1e16 + 1.0) + 1e16)) + 2.0) == (3.0, 2e16)


def test_positions_and_velocities_are_the_members_own_in_one_array():
    """batch.positions and velocities are each member's own, stacked: one copy in the core for
    float64 members on the CPU, each member's own array (float32) for f32 members."""
    b = pc.Batch(_fan(5))
    b.step(40)
    for name in ("positions", "velocities"):
        a = getattr(b, name)
        assert a.dtype == np.float64 and a.shape == (5, 3, 2)
        assert np.array_equal(a, np.stack([getattr(m, name) for m in b.members]))
        a[:] = 0.0  # a copy: writing to it changes no member
        assert np.abs(getattr(b, name)).max() > 0.1
    s = pc.Scene(3, integrator="verlet", dt=1e-3, precision="f32")
    s.add_particles(np.eye(3), np.ones((3, 3)), np.ones(3))
    b32 = pc.Batch.from_scene(s, 4, velocities=lambda k, v: v * k)
    b32.step(5)
    assert b32.positions.dtype == np.float32 and b32.velocities.dtype == np.float32
    assert np.array_equal(b32.velocities, np.stack([m.velocities for m in b32.members]))


def test_from_scene_under_a_memory_cap_is_refused_by_name():
    """Under RLIMIT_AS (what the process maps now + 300 MB), 10^5 copies (about 1.2 GB) are
    refused naming m, in a fresh interpreter so the cap stays there."""
    import subprocess

    code = (
        "import os, resource, physcore as pc\n"
        "s = pc.scenes.figure_eight()\n"
        "mapped = int(open('/proc/self/statm').read().split()[0]) * os.sysconf('SC_PAGE_SIZE')\n"
        "resource.setrlimit(resource.RLIMIT_AS, (mapped + 300_000_000, resource.RLIM_INFINITY))\n"
        "try:\n"
        "    pc.Batch.from_scene(s, 100_000)\n"
        "except pc.OutOfMemoryError as e:\n"
        "    print('refused', str(e).split(':')[0])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "refused m", out.stderr[-2000:]


def test_a_member_changed_after_the_batch_was_made_is_refused_by_save(tmp_path):
    """A part added to one member after Batch(): save refuses by name before writing (the file
    could not be loaded as a batch: its members differ), and a file already there stays."""
    b = pc.Batch.from_scene(pc.scenes.figure_eight(), 3)
    path = tmp_path / "b.npz"
    b.save(path)
    before = path.read_bytes()
    b[1].add(pc.Drag(0.1))
    with pytest.raises(pc.InvalidInputError, match="member 1 differs from entry 0 in its parts"):
        b.step(5)  # refused too, before a step (tests/robustness/test_batch_members.py)
    with pytest.raises(pc.InvalidInputError, match="member 1 differs from entry 0 in its parts since the batch was made"):
        b.save(path)
    assert path.read_bytes() == before
    assert len(pc.Batch.load(path)) == 3


def test_a_batch_of_body_scenes_renders_every_members_bodies_and_surface():
    """A batch of dominoes (bodies, no particles) renders, every member's bodies in the
    recording with each member's own poses; a batch of tablecloths draws its tables and dishes
    and one cloth surface a member (the hostile run: the first raised on the empty colour list,
    the second drew the cloth's particles alone)."""
    from physcore import render

    b = pc.Batch.from_scene(pc.scenes.dominoes(), 2)
    b[1].bodies[1].velocities = b[1].bodies[1].velocities + [0.5, 0.0]  # member 1 moves differently
    alone = render.record(pc.scenes.dominoes(), frames=3).bodies.poses
    rec = render.record(b, frames=3)
    poses = rec.bodies.poses
    assert poses.shape == (3, 2 * alone.shape[1], 3)
    assert np.array_equal(poses[0, : alone.shape[1]], alone[0])
    assert not np.array_equal(poses[-1, : alone.shape[1]], poses[-1, alone.shape[1]:])
    assert len(list(render.frames(b, frames=2))) == 2

    cloth = pc.Batch.from_scene(pc.scenes.tablecloth(), 2)
    one = pc.scenes.tablecloth()
    n, faces = one.n_particles, one.render_defaults["mesh"].faces
    view = cloth._render_view()
    assert np.array_equal(view.render_defaults["mesh"].faces, np.concatenate([faces, faces + n]))
    assert len(view.bodies) == 2 * len(one.bodies)
