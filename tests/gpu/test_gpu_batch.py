"""A batch on the GPU path (``Batch(..., device=...)``): every member in one dispatch per stage,
against the CPU batch, the reference; its promises (a member's bits do not depend on the other
members, a diverging member is retired alone, Ctrl-C changes nothing, save and load continue
bit for bit) and what it refuses, by name, before anything changes.

Like ``test_gpu_scenes.py`` they run on a real GPU where one is present, else on lavapipe (CI).
The expected values are the CPU path's, never numbers copied from an earlier GPU run.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import batch_uses_say_busy
from test_gpu_scenes import DEVICE, F64
from test_interrupt import _interrupt

import physcore as pc

pytestmark = pytest.mark.skipif(DEVICE is None, reason="no GPU adapter and no lavapipe")
PRECISIONS = ["f32", "f64"] if F64 else ["f32"]


def _fan(m: int, scene: pc.Scene | None = None, device: str = "cpu", precision: str | None = None) -> pc.Batch:
    """``m`` figure-eight three-body problems, member k's positions scaled by 1 + 1e-3 k."""
    base = scene if scene is not None else pc.scenes.figure_eight()
    return pc.Batch.from_scene(base, m, positions=lambda k, x: x * (1 + 1e-3 * k), device=device, precision=precision)


def _books(s: pc.Scene) -> dict[str, float]:
    e = s.energy()
    return {"kinetic": e.kinetic, **{f"U {k}": v for k, v in e.potential.items()},
            **{f"D {k}": v for k, v in e.dissipated.items()}}


@pytest.mark.parametrize("precision", PRECISIONS)
def test_a_gpu_batch_of_three_body_problems_agrees_with_the_cpu_batch(precision: str) -> None:
    """Figure-eight orbits (Yoshida 4, about a sixth of a period): positions to the device's
    rounding, the clock and step count exactly, the energy books to the same drift."""
    cpu, gpu = _fan(32), _fan(32, device=DEVICE, precision=precision)
    assert gpu.device.endswith(f", {precision})") and cpu.device == "cpu"
    cpu.step(1000)
    gpu.step(1000)
    moved = np.abs(cpu.positions - _fan(32).positions).max()
    assert moved > 0.1  # the orbits went somewhere
    err = np.abs(gpu.positions - cpu.positions).max()
    # f64: the same method in another summation order (measured 2.5e-14); f32: its rounding,
    # 6e-8 a step carried over 1000 steps of a chaotic orbit (measured 3.3e-5).
    assert err < (1e-11 if precision == "f64" else 3e-4), err
    assert np.array_equal(gpu.time, cpu.time) and np.array_equal(gpu.step_count, cpu.step_count)
    drift = np.abs(gpu.energy_drift())
    assert drift.max() < (1e-10 if precision == "f64" else 1e-5), drift.max()
    gpu.step(500)  # a second call continues from what the first wrote back
    cpu.step(500)
    assert np.abs(gpu.positions - cpu.positions).max() < (1e-11 if precision == "f64" else 1e-3)


def _chain(k: int, dim: int = 2) -> pc.Scene:
    """A damped spring chain under gravity and drag, its stiffness and masses member k's own."""
    s = pc.scenes.spring_chain(12, stiffness=2000.0 * (1 + 0.25 * k), mass=1.0 + 0.1 * k, damping=0.5, dim=dim, dt=2e-4)
    s.add(pc.Drag(0.05))
    return s


@pytest.mark.parametrize("dim", [2, 3])
def test_members_with_their_own_springs_and_masses_keep_their_own_books(dim: int) -> None:
    """Springs and masses differ between members (one dispatch still): each member's state and
    books (springs' potential, the dashpots' and the drag's dissipation) as its CPU run's."""
    members = [_chain(k, dim) for k in range(4)]
    cpus = [_chain(k, dim) for k in range(4)]
    precision = "f64" if F64 else "f32"
    batch = pc.Batch(members, device=DEVICE, precision=precision)
    batch.step(2000)
    for c in cpus:
        c.step(2000)
    tol = 1e-9 if F64 else 2e-3
    for g, c in zip(members, cpus, strict=True):
        scale = np.abs(c.positions).max()
        assert np.abs(g.positions - c.positions).max() < tol * scale
        bg, bc = _books(g), _books(c)
        assert bg.keys() == bc.keys() and bc["D drag"] > 0 and bc["D springs"] > 0
        total = sum(abs(v) for v in bc.values())
        for key in bc:
            assert abs(bg[key] - bc[key]) < tol * total, key
        assert g.time == c.time and g.step_count == c.step_count
        assert abs(g.energy_drift()) < 10 * tol + abs(c.energy_drift())


def _drops(k: int) -> pc.Scene:
    """Ten balls dropped onto a plane of restitution 0.6, from heights member k's own."""
    s = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    x = np.column_stack([np.linspace(0, 1, 10), 0.5 + 0.05 * k + 0.03 * np.arange(10)])
    s.add_particles(x)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.6))
    return s


def test_colliders_book_each_members_losses() -> None:
    members, cpus = [_drops(k) for k in range(3)], [_drops(k) for k in range(3)]
    batch = pc.Batch(members, device=DEVICE, precision="f64" if F64 else "f32")
    batch.step(1500)
    for g, c in zip(members, cpus, strict=True):
        c.step(1500)
        lost = _books(c)["D collisions"]
        assert lost > 1.0  # the balls bounced and lost energy
        assert abs(_books(g)["D collisions"] - lost) < (1e-6 if F64 else 1e-3) * lost
        assert np.all(g.positions[:, 1] >= -1e-9)


def test_a_members_bits_do_not_depend_on_the_other_members() -> None:
    """Each world pulls only on its own particles, in one order: member k of a batch of 32 is
    bit for bit member k alone in a batch of one, and two runs repeat."""
    big = _fan(32, device=DEVICE)
    big.step(300)
    again = _fan(32, device=DEVICE)
    again.step(300)
    assert np.array_equal(big.positions, again.positions)
    for k in (0, 17, 31):
        one = pc.Batch([_fan(32).members[k]], device=DEVICE)
        one.step(300)
        assert np.array_equal(one.positions[0], big.positions[k]) and np.array_equal(one.velocities[0], big.velocities[k])


def test_terms_added_to_the_members_between_calls_are_stepped_too() -> None:
    """The device batch is built from its members' terms; a term added to every member after a
    call (each member's records then get a new stamp) is on the device at the next call, which
    builds the batch again: the members step with their drag as the CPU batch's do, and a
    member's term replaced (a drag of another coefficient) is taken up the same way."""
    cpu, gpu = _fan(4), _fan(4, device=DEVICE, precision="f64" if F64 else "f32")
    cpu.step(100)
    gpu.step(100)
    for b in (cpu, gpu):
        for m in b.members:
            m.add(pc.Drag(0.3))
    cpu.step(200)
    gpu.step(200)
    tol = 1e-11 if F64 else 3e-4
    assert np.abs(gpu.positions - cpu.positions).max() < tol
    drag = np.array([m.energy().dissipated["drag"] for m in gpu.members])
    assert np.all(drag > 1e-3) and np.allclose(drag, [m.energy().dissipated["drag"] for m in cpu.members], rtol=1e-6)
    for b in (cpu, gpu):
        for m in b.members:
            m.replace("drag", pc.Drag(3.0))
    cpu.step(200)
    gpu.step(200)
    assert np.abs(gpu.positions - cpu.positions).max() < tol
    assert np.abs(gpu.velocities - cpu.velocities).max() < (1e-9 if F64 else 1e-3)


def test_a_diverging_member_is_retired_and_the_others_do_not_notice() -> None:
    members = list(_fan(6).members)
    v = members[3].velocities
    members[3].velocities = v / np.abs(v).max() * 3e38  # in f32's range, its positions past it in ~350 steps
    before = members[3].positions
    batch = pc.Batch(members, device=DEVICE)
    batch.step(600)
    assert list(batch.diverged) == [3]
    e = batch.diverged[3]
    assert isinstance(e, pc.SimulationDiverged) and e.rolled_back_to == 0 and 0 < e.step <= 600
    assert np.array_equal(members[3].positions, before) and members[3].step_count == 0
    others = pc.Batch([_fan(6).members[k] for k in (0, 1, 2, 4, 5)], device=DEVICE)
    others.step(600)
    assert np.array_equal(others.positions, np.stack([members[k].positions for k in (0, 1, 2, 4, 5)]))
    batch.step(10)  # the retired member is not stepped again; the batch on the device is rebuilt
    assert members[3].step_count == 0 and members[0].step_count == 610


def test_members_stay_on_the_device_between_calls_and_are_written_back_when_used() -> None:
    """The members' state stays on the device between calls: calls of 100, 100 and 100 steps
    give the bits of one call of 300 (state, clock) with no member used between them; a member
    used between calls (read, pickled, its velocities set) is written back first, so it reads
    as the batch does, and the next call steps it from what it was set to, bit for bit as a
    batch of it alone; the members left alone go on from the device, unaffected."""
    precision = "f64" if F64 else "f32"
    one, three = _fan(8, device=DEVICE, precision=precision), _fan(8, device=DEVICE, precision=precision)
    one.step(300)
    for _ in range(3):
        three.step(100)
    assert np.array_equal(one.positions, three.positions) and np.array_equal(one.velocities, three.velocities)
    assert np.array_equal(one.time, three.time) and np.array_equal(one.step_count, three.step_count)
    batch = _fan(8, device=DEVICE, precision=precision)
    batch.step(100)
    m = batch.members[5]
    x = m.positions  # written back from the device
    assert np.array_equal(x, batch.positions[5]) and m.step_count == 100 and m.time == batch.time[5]
    copy = pc.Scene.from_bytes(m.to_bytes())
    assert np.array_equal(copy.positions, x) and copy.step_count == 100
    m.velocities = m.velocities * 0.5
    alone = pc.Batch([pc.Scene.from_bytes(m.to_bytes())], device=DEVICE, precision=precision)
    batch.step(200)
    alone.step(200)
    assert np.array_equal(batch.positions[5], alone.positions[0]) and batch.step_count[5] == 300
    assert np.array_equal(m.positions, alone.positions[0])
    keep = [k for k in range(8) if k != 5]
    assert np.array_equal(batch.positions[keep], one.positions[keep])  # bit for bit: 300 steps untouched
    assert np.array_equal(batch.velocities[keep], one.velocities[keep])
    assert np.array_equal(batch.energy_drift()[keep], one.energy_drift()[keep])


def test_calls_reads_and_a_changed_member_leave_the_other_members_bits_alone() -> None:
    """Damped spring chains with drag (forces of the velocities: velocity Verlet carries each
    step's accelerations, taken at predicted velocities, into the next). A run in calls of 250
    steps is one call of 1000 bit for bit, state and books (drag and dashpot losses go on
    adding up on the device from call to call), also when every member is read between the
    calls; a member whose velocities are set between calls starts from them with its forces
    evaluated anew, as a batch of it alone does, and changes no other member's bits."""
    precision = "f64" if F64 else "f32"
    one = pc.Batch([_chain(k) for k in range(4)], device=DEVICE, precision=precision)
    four = pc.Batch([_chain(k) for k in range(4)], device=DEVICE, precision=precision)
    one.step(1000)
    for _ in range(4):
        four.step(250)
        four.energy_drift(), [m.positions for m in four.members]  # every member written back
    assert np.array_equal(one.positions, four.positions) and np.array_equal(one.velocities, four.velocities)
    for a, b in zip(one.members, four.members, strict=True):
        ba, bb = _books(a), _books(b)
        assert ba["D drag"] > 0 and ba["D springs"] > 0
        assert ba == bb
    changed = pc.Batch([_chain(k) for k in range(4)], device=DEVICE, precision=precision)
    changed.step(500)
    m = changed.members[2]
    m.velocities = m.velocities + 0.01
    alone = pc.Batch([pc.Scene.from_bytes(m.to_bytes())], device=DEVICE, precision=precision)
    changed.step(500)
    alone.step(500)
    assert np.array_equal(changed.positions[2], alone.positions[0])
    assert _books(changed.members[2]) == _books(alone.members[0])
    assert not np.array_equal(changed.positions[2], one.positions[2])
    others = [0, 1, 3]
    assert np.array_equal(changed.positions[others], one.positions[others])
    assert np.array_equal(changed.velocities[others], one.velocities[others])
    assert all(_books(changed.members[k]) == _books(one.members[k]) for k in others)


def test_a_member_of_two_gpu_batches_is_stepped_by_each_from_the_other_s_result() -> None:
    """A scene in two GPU batches stepped in turn: each call starts from what the other batch
    left (written back from its device first), as two CPU batches of the same scenes do."""
    precision = "f64" if F64 else "f32"
    cpu, gpu = _fan(4), _fan(4, device=DEVICE, precision=precision)
    cpu_pair = pc.Batch(list(cpu.members[:2]))
    gpu_pair = pc.Batch(list(gpu.members[:2]), device=DEVICE, precision=precision)
    for b in (cpu, cpu_pair, cpu, gpu, gpu_pair, gpu):
        b.step(150)
    assert np.array_equal(gpu.step_count, [450, 450, 300, 300])
    assert np.abs(gpu.positions - cpu.positions).max() < (1e-11 if F64 else 1e-3)


def test_a_gpu_batch_renders_from_its_mirror_as_a_cpu_batch_does(tmp_path) -> None:
    """``render.record`` of a GPU batch reads every member's particles from the device's mirror
    each frame (no member written back), frame for frame the batch's own positions, and the
    members then read as the batch does."""
    fan = _fan(6, device=DEVICE, precision="f64" if F64 else "f32")
    rec = pc.render.record(fan, frames=4, steps_per_frame=30)
    assert rec.positions.shape == (4, 18, 2) and (fan.step_count == 90).all()  # frame 0 at the start
    last = rec.positions[-1].astype(np.float64) + rec.origin
    assert np.allclose(last, fan.positions.reshape(18, 2), atol=1e-6)
    assert np.array_equal(np.stack([m.positions for m in fan.members]), fan.positions)
    path = pc.render.gif(fan, tmp_path / "fan.gif", frames=6, steps_per_frame=20, size=(160, 120))
    assert path.read_bytes()[:6] == b"GIF89a"


def test_a_gpu_batch_dropped_with_its_members_is_freed_at_once() -> None:
    """A member's state on the device keeps the batch's device buffers alive while the member
    lives (it is written back from them when used), and no longer: a batch dropped with its
    members is freed at once, by reference counting, not left to the cycle collector."""
    import gc
    import weakref

    gc.collect()
    gc.disable()
    try:
        batch = _fan(16, device=DEVICE)
        batch.step(10)
        kept = batch.members[3]
        res = weakref.ref(batch._res)
        del batch
        assert res() is not None and kept.step_count == 10  # the member kept it, and read it
        del kept
        batch = _fan(16, device=DEVICE)
        batch.step(10)
        res = weakref.ref(batch._res)
        del batch
        assert res() is None
    finally:
        gc.enable()


def test_a_member_used_by_another_thread_while_its_gpu_batch_steps_says_so() -> None:
    """While a GPU batch steps, another thread's use of a member (its state kept on the
    device) or of the batch raises SceneBusyError, as for a CPU batch; the call is unharmed."""
    batch = _fan(64, device=DEVICE)
    batch.step(1)  # the members' state is on the device from here on
    if not batch_uses_say_busy(batch, lambda: batch.step(200_000)):  # it lost the race: again
        return test_a_member_used_by_another_thread_while_its_gpu_batch_steps_says_so()
    assert np.array_equal(batch.step_count, np.full(64, 200_001))


def test_a_member_diverging_beside_forces_of_the_velocities_leaves_the_others_bits() -> None:
    """Damped chains with drag (velocity Verlet carries accelerations taken at predicted
    velocities): a member made to diverge in a later call is retired, and the call's run again
    starts the others from the device's copy of the call's start, so they go on bit for bit as
    a batch without that member does (forces evaluated anew would differ in the last bits)."""
    batch = pc.Batch([_chain(k) for k in range(4)], device=DEVICE, precision="f32")
    without = pc.Batch([_chain(k) for k in (0, 2, 3)], device=DEVICE, precision="f32")
    batch.step(300)
    without.step(300)
    m = batch.members[1]
    m.velocities = np.where(np.arange(m.n_particles)[:, None] % 2 == 0, 3e37, -3e37) * np.ones(m.dim)
    before = m.positions
    batch.step(300)
    without.step(300)
    assert list(batch.diverged) == [1] and batch.diverged[1].rolled_back_to == 300
    assert np.array_equal(m.positions, before) and m.step_count == 300
    assert np.array_equal(batch.positions[[0, 2, 3]], without.positions)
    assert np.array_equal(batch.velocities[[0, 2, 3]], without.velocities)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_changes_no_member() -> None:
    batch = _fan(64, device=DEVICE)
    before = [(m.positions, m.velocities, m.step_count, m.time) for m in batch.members]
    assert _interrupt(lambda: batch.step(10**9), 0.3) < 9.7  # 10 s from the call's start
    for m, (x, v, n, t) in zip(batch.members, before, strict=True):
        assert np.array_equal(m.positions, x) and np.array_equal(m.velocities, v)
        assert m.step_count == n and m.time == t
    batch.step(5)  # and it steps on afterwards
    assert batch.members[0].step_count == 5


def test_save_and_load_continue_bit_for_bit_on_the_device(tmp_path) -> None:
    batch = _fan(5, device=DEVICE)
    batch.step(100)
    copy = pc.Batch.load(batch.save(tmp_path / "fan.batch"))
    assert copy.device == batch.device
    batch.step(150)
    copy.step(150)
    assert np.array_equal(batch.positions, copy.positions) and np.array_equal(batch.time, copy.time)
    # The same file continues on the CPU, as the CPU batch of the same start does (to f32's
    # rounding of the device's 100 steps before the save).
    path = tmp_path / "fan.batch"
    on_cpu = pc.Batch.load(path, device="cpu")
    assert on_cpu.device == "cpu" and np.array_equal(on_cpu.step_count, np.full(5, 100))
    on_cpu.step(150)
    cpu = _fan(5)
    cpu.step(250)
    assert np.abs(on_cpu.positions - cpu.positions).max() < 1e-3


def test_what_a_gpu_batch_cannot_hold_is_refused_by_name_before_anything_changes() -> None:
    def refused(members: list[pc.Scene], match: str, **kw) -> None:
        before = [(m.positions, m.step_count) for m in members]
        with pytest.raises(pc.InvalidInputError, match=match):
            pc.Batch(members, device=kw.pop("device", DEVICE), **kw)
        assert all(np.array_equal(m.positions, x) and m.step_count == n for m, (x, n) in zip(members, before, strict=True))

    members = list(_fan(3).members)
    members[1].dt = members[1].dt * 2
    refused(members, "^dt: member 1's dt differs")
    chains = [pc.scenes.spring_chain(12, dt=2e-4) for _ in range(2)]
    for k, c in enumerate(chains):
        c.add(pc.Drag(0.05 * (1 + k)))  # one drag coefficient a dispatch
    refused(chains, "^terms: member 1's field parameters")
    refused([pc.scenes.dam_break(n=8), pc.scenes.dam_break(n=8)], '^water: the GPU path has no kernel for "dfsph"')
    refused([pc.scenes.turing(n=16), pc.scenes.turing(n=16)], "^sims: entry 0 has the grid")
    far = list(_fan(2).members)
    far[1].positions = far[1].positions * 1e39  # past f32's range: refused, not inf on the device
    refused(far, "^positions: value .* past f32's range", precision="f32")
    refused(list(_fan(2).members), "^device: must be", device="tpu")
    refused(list(_fan(2).members), "^precision: must be", precision="f16")
    with pytest.raises(pc.InvalidInputError, match="^device"):
        pc.Batch(list(_fan(2).members), device="gpu:no-such-adapter")
    with pytest.raises(TypeError, match="^device"):
        pc.Batch(list(_fan(2).members), device=3)
