"""DEM grains on the GPU path (``Scene(device=...)`` with :class:`~physcore.Contacts` between
grains of the scene's ``"radius"`` attribute, pinned grains as pegs, walls of every shape, a
:class:`~physcore.Gravity` and a :class:`~physcore.Drag`):
against the CPU path, the reference; the contact history (spins, angles, tangential and rolling
springs) travelling as the term's history (save and load bit for bit, the CPU continuing a
GPU file and the other way round, ``state``/``set_state``, rollback); the contact count and
per-grain fields; the Galton board (pegs and dividers pinned, balls sinking under drag); what it
refuses, by name, before anything changes.

Like ``test_gpu_scenes.py`` they run on a real GPU where one is present, else on lavapipe (CI).
The expected values are the CPU path's, never numbers copied from an earlier GPU run.
"""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest
from test_gpu_scenes import DEVICE, F64
from test_interrupt import _interrupt

import physcore as pc

pytestmark = pytest.mark.skipif(DEVICE is None, reason="no GPU adapter and no lavapipe")
PRECISIONS = ["f32", "f64"] if F64 else ["f32"]
R = 0.01


def _pile(dim: int, device: str = "cpu", precision: str | None = None, rolling: float = 0.0,
          law: str = "linear") -> pc.Scene:
    """24 grains (radii 0.8–1.2 R, a deterministic jitter) thrown down in a loose block onto a
    floor between two side walls, friction 0.4, restitution 0.6, steps of 20 µs."""
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", device=device, precision=precision)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    k = np.arange(24)
    cols = 4 if dim == 2 else 2
    if dim == 2:
        x = np.stack([(k % cols) * 2.3 * R + 0.0003 * np.sin(7 * k), (k // cols) * 2.3 * R + 1.5 * R], axis=1)
    else:
        x = np.stack([(k % cols) * 2.3 * R + 0.0003 * np.sin(7 * k), ((k // cols) % cols) * 2.3 * R + 0.0002 * np.cos(5 * k),
                      (k // (cols * cols)) * 2.3 * R + 1.5 * R], axis=1)
    v = np.zeros_like(x)
    v[:, 0] = 0.05 * np.cos(3 * k)
    v[:, -1] = -0.3  # thrown down: the pile forms within the test's few thousand steps
    s.add_particles(x, v, masses=2e-3 * (1.0 + 0.1 * np.sin(k)))
    s.set_attribute("radius", R * (1.0 + 0.2 * np.sin(11 * k)))
    up = [0.0] * (dim - 1) + [1.0]
    side = [1.0] + [0.0] * (dim - 1)
    walls = [pc.Plane([0.0] * dim, up, restitution=0.6, friction=0.4),
             pc.Plane([-1.5 * R] + [0.0] * (dim - 1), side, restitution=0.6, friction=0.4),
             pc.Plane([cols * 2.3 * R + 0.5 * R] + [0.0] * (dim - 1), [-c for c in side], restitution=0.6, friction=0.4)]
    s.add(pc.Contacts(stiffness=2e3, restitution=0.6, friction=0.4, walls=walls, rolling_friction=rolling, law=law))
    s.dt = 2e-5
    return s


def _books(s: pc.Scene) -> dict[str, float]:
    e = s.energy()
    return {"kinetic": e.kinetic, **{f"U {k}": v for k, v in e.potential.items()},
            **{f"D {k}": v for k, v in e.dissipated.items()}}


#: The device against the CPU: positions (R), the state's books and the dissipated ones (of the
#: books' scale), by precision.
AGREE = {"f32": (1e-2, 1e-4, 3e-4), "f64": (1e-10, 1e-12, 1e-4)}


def _apart(gpu: pc.Scene, cpu: pc.Scene, b1: dict[str, float]) -> tuple[float, float, float]:
    """How far `gpu` is from `cpu` (whose books are `b1`): positions over R, the largest state
    book's and dissipated book's difference over the sum of |books|."""
    g1 = _books(gpu)
    assert g1.keys() == b1.keys()
    scale = sum(abs(v) for v in b1.values())
    dx = np.abs(gpu.positions - cpu.positions).max() / R
    ds = max(abs(g1[k] - b1[k]) for k in b1 if not k.startswith("D ")) / scale
    db = max(abs(g1[k] - b1[k]) for k in b1 if k.startswith("D ")) / scale
    return dx, ds, db


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("rolling", [0.0, 0.1])
def test_grains_on_the_gpu_fall_collide_and_book_as_on_the_cpu(dim: int, rolling: float) -> None:
    cpu = _pile(dim, rolling=rolling)
    b0 = _books(cpu)
    cpu.step(1500)
    b1 = _books(cpu)
    assert cpu.contact_count() > 3  # they landed and touch
    assert b1["D contacts (normal damping)"] > 0 and b1["D contacts (friction)"] > 0
    for precision in PRECISIONS:
        gpu = _pile(dim, DEVICE, precision, rolling=rolling)
        assert _books(gpu).keys() == b0.keys()
        gpu.step(1500)
        assert gpu.device == DEVICE and gpu.precision == precision
        # The state's books (kinetic, potentials) to the precision's round-off; the dissipated
        # ones differ by design: the device does not book the energy a contact's normal spring
        # holds at its first evaluation (formed within a step, no force did work on it; the CPU
        # books it and its totals keep that jump, O((ω dt)²) of the impact's: physcore_gpu::dem's
        # module doc), measured 1.3e-6 J of 0.041 J here.
        dx, ds, db = _apart(gpu, cpu, b1)
        spin = "angular_velocity" if dim == 2 else "angular_velocity_z"
        dw = np.abs(gpu.particle_field(spin) - cpu.particle_field(spin)).max()
        print(f"\nDEM {dim}D rolling={rolling} {precision}, 1500 steps: x {dx:.1e} R, state books {ds:.1e}, dissipated {db:.1e} of their scale, "
              f"spins {dw:.1e} rad/s, contacts {gpu.contact_count()} vs {cpu.contact_count()}")
        tol = AGREE[precision]
        assert dx < tol[0] and ds < tol[1] and db < tol[2], (precision, dx, ds, db)
        if precision == "f64":
            assert gpu.contact_count() == cpu.contact_count()
            assert dw < 1e-8


def _bowl(dim: int, device: str = "cpu", precision: str | None = None) -> pc.Scene:
    """Three grains thrown down at 0.3 m/s inside a bowl (a :class:`~physcore.Sphere` wall
    with ``inside=True``, radius 5 cm), each onto a wall of its own, apart from each other: a
    rod (a :class:`~physcore.Capsule` wall; in 3D the grain rolls off its side), a ramp tilted
    down towards +x (an :class:`~physcore.OrientedBox` wall; the grain rolls off round its lower
    edge) and the bowl's sloping side; Hertz contacts (k_n = 1e5 N/m^1.5: overlaps of some
    0.4 mm, which f32's positions resolve to about 1e-5), friction 0.4, restitution 0.3, steps
    of 20 µs; the up axis last, the 3D scene the 2D one with a little depth."""
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", device=device, precision=precision)

    def at(x: float, up: float, depth: float = 0.0) -> list[float]:
        return [x, up] if dim == 2 else [x, depth, up]

    s.add(pc.Gravity(at(0.0, -9.81)))
    x = [at(-0.001, 0.058, 0.006), at(0.016, 0.05, -0.002), at(-0.028, 0.025, 0.002)]
    s.add_particles(x, [at(0.0, -0.3)] * 3, masses=4e-3)
    s.set_attribute("radius", [R, 0.9 * R, 1.1 * R])
    turn = -0.4 if dim == 2 else [0.0, 0.4, 0.0]  # the ramp's +x end down
    walls = [pc.Sphere(at(0.0, 0.05), 0.05, inside=True, restitution=0.3, friction=0.4),
             pc.Capsule(at(-0.018, 0.04), at(-0.004, 0.04), 0.004, restitution=0.3, friction=0.4),
             pc.OrientedBox(at(0.018, 0.03), at(0.01, 0.003, 0.01), turn, restitution=0.3, friction=0.4)]
    s.add(pc.Contacts(stiffness=1e5, restitution=0.3, friction=0.4, walls=walls, law="hertz"))
    s.dt = 2e-5
    return s


@pytest.mark.parametrize("dim", [2, 3])
def test_grains_against_a_bowl_a_rod_and_a_ramp_on_the_gpu_as_on_the_cpu(dim: int) -> None:
    """Walls other than planes on the device (the CPU's shapes, read by its own parser): the
    grains where the CPU has them and the books equal to its, after every grain met its wall."""
    cpu = _bowl(dim)
    x0 = cpu.positions
    steps = 1500
    cpu.step(steps)
    b1 = _books(cpu)
    # Each grain held up by its wall, none by another: less far down than a free fall, apart.
    t = steps * cpu.dt
    drop = x0[:, -1] - cpu.positions[:, -1]
    assert (drop < 0.3 * t + 0.5 * 9.81 * t**2 - 0.3 * R).all(), drop / R
    r = cpu.attributes["radius"]
    gap = np.linalg.norm(cpu.positions[:, None] - cpu.positions[None], axis=2) - (r[:, None] + r[None])
    assert gap[np.triu_indices(3, 1)].min() > 0.1 * R
    assert b1["D contacts (normal damping)"] > 0 and b1["D contacts (friction)"] != 0
    for precision in PRECISIONS:
        gpu = _bowl(dim, DEVICE, precision)
        gpu.step(steps)
        assert gpu.device == DEVICE and gpu.precision == precision
        dx, ds, db = _apart(gpu, cpu, b1)
        print(f"\nDEM {dim}D bowl, rod and ramp {precision}, {steps} steps: x {dx:.1e} R, state books {ds:.1e}, "
              f"dissipated {db:.1e} of their scale, contacts {gpu.contact_count()} vs {cpu.contact_count()}")
        tol = AGREE[precision]
        assert dx < tol[0] and ds < tol[1] and db < tol[2], (precision, dx, ds, db)
        if precision == "f64":
            assert gpu.contact_count() == cpu.contact_count()


def test_gpu_grains_in_a_bowl_save_and_load_bit_for_bit(tmp_path) -> None:
    """Shaped walls in the file (their records): a load continues bit for bit on the device,
    and on the CPU as the device does."""
    precision = "f64" if F64 else "f32"
    a = _bowl(2, DEVICE, precision)
    a.step(1500)
    assert a.contact_count() > 0
    path = a.save(tmp_path / "bowl.npz")
    b = pc.Scene.load(path)
    on_cpu = pc.Scene.load(path, device="cpu")
    for s in (a, b, on_cpu):
        s.step(500)
    assert b.device == DEVICE
    np.testing.assert_array_equal(b.positions, a.positions)
    np.testing.assert_array_equal(b.velocities, a.velocities)
    assert _books(b) == _books(a)
    assert np.abs(on_cpu.positions - a.positions).max() / R < (1e-10 if precision == "f64" else 1e-2)


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_gpu_grains_saved_and_loaded_continue_bit_for_bit_and_on_the_cpu(tmp_path, precision: str) -> None:
    if precision == "f64" and not F64:
        pytest.skip("the adapter has no f64")
    a = _pile(2, DEVICE, precision, rolling=0.1)
    a.step(800)
    assert a.contact_count() > 0  # springs are live: the history matters
    path = a.save(tmp_path / "pile.npz")
    b = pc.Scene.load(path)
    c = pickle.loads(pickle.dumps(a))
    on_cpu = pc.Scene.load(path, device="cpu")
    state = a.state()
    for s in (a, b, c, on_cpu):
        s.step(300)
    d = _pile(2, DEVICE, precision, rolling=0.1)
    d.step(5)
    d.set_state(state)
    d.step(300)
    for s in (b, c, d):
        assert s.device == DEVICE
        np.testing.assert_array_equal(s.positions, a.positions)
        np.testing.assert_array_equal(s.velocities, a.velocities)
        assert s.energy().total == pytest.approx(a.energy().total, rel=1e-12 if precision == "f64" else 1e-6)
    tol = 1e-10 if precision == "f64" else 1e-2
    assert np.abs(on_cpu.positions - a.positions).max() / R < tol
    # A CPU file continues on the device likewise (its springs uploaded with the state).
    cpu = _pile(2, rolling=0.1)
    cpu.step(800)
    moved = pc.Scene.load(cpu.save(tmp_path / "cpu.npz"), device=DEVICE)
    for s in (cpu, moved):
        s.step(300)
    assert moved.device == DEVICE
    assert np.abs(moved.positions - cpu.positions).max() / R < (1e-10 if moved.precision == "f64" else 1e-2)


def test_gpu_grains_that_diverge_are_rolled_back() -> None:
    s = _pile(2, DEVICE, "f32")
    s.step(400)
    before = s.state()
    s.dt = 1e100
    with pytest.raises(pc.SimulationDiverged), pytest.warns(pc.ContactStepWarning):
        s.step(20)
    after = s.state()
    for k, v in before.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(after[k], v, err_msg=k)
    s.dt = 2e-5
    s.step(10)
    assert np.isfinite(s.positions).all()


@pytest.mark.parametrize("change", ["pinned_point", "springs", "collider"])
def test_what_gpu_grains_cannot_hold_is_refused_by_name_and_nothing_changes(change: str) -> None:
    """Pinned grains are held (see the Galton board's tests); a pinned particle of radius 0 (a
    point, not a grain) is not: on the device every particle is a grain."""
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", device=DEVICE)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Drag(0.01))
    s.add_particles([[0.0, 0.02], [0.03, 0.02]], masses=1e-3, pinned=[True, False])
    s.set_attribute("radius", [0.0 if change == "pinned_point" else R, R])
    s.add(pc.Contacts(stiffness=2e3, walls=[pc.Plane([0.0, 0.0], [0.0, 1.0])]))
    if change == "springs":
        s.add(pc.Springs([0], [1], stiffness=10.0, rest_length=0.03, name="tie"))
    if change == "collider":
        s.add(pc.Box([-1.0, -1.0], [1.0, 1.0]))
    want = {"pinned_point": "radius", "springs": "tie", "collider": "collider"}[change]
    x0 = s.positions
    with pytest.raises(pc.InvalidInputError, match=want):
        s.step(1)
    np.testing.assert_array_equal(s.positions, x0)
    assert s.time == 0.0


RB = 0.002  # the Galton board's balls' radius


def _galton(device: str = "cpu", precision: str | None = None) -> pc.Scene:
    """``galton_board(balls=6, rows=3)`` (pegs and dividers pinned, drag, gravity, plane walls;
    its automatic step), built on the CPU and, for a device, built again there from its
    particles, attributes and (copies of its) terms: no stepped state crosses over. The queue
    starts 1 mm above the top peg at its terminal speed, a quarter radius off the axis, so
    ball 0 strikes the peg at once and rolls off it within 700 steps (from the scene's own start
    it takes some 3,700 steps, each about 10 ms on lavapipe)."""
    cpu = pc.scenes.galton_board(balls=6, rows=3)
    x, v = cpu.positions, cpu.velocities
    x[:6, 0] += 0.25 * RB
    x[:6, 1] -= 2.75 * (2 * RB)
    v[:6, 1] = -2.6e-4 * 9.81 / 4e-3  # m g / b, the scene's terminal speed
    cpu.positions, cpu.velocities = x, v
    if device == "cpu":
        return cpu
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", device=device, precision=precision)
    s.add_particles(cpu.positions, cpu.velocities, masses=cpu.masses, pinned=cpu.pinned)
    for k, v in cpu.attributes.items():
        s.set_attribute(k, v)
    for t in cpu.terms:
        s.add(copy.deepcopy(t))
    s.dt = cpu.dt
    return s


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_a_galton_board_runs_on_the_gpu_as_on_the_cpu(precision: str) -> None:
    """The board of 6 balls and 3 rows for 2,000 steps (45 ms: the first ball strikes the top
    peg, rolls off it and slides down its side, the next sinks towards it): the balls where the
    CPU has them, the pegs and dividers not moved by a bit, the books under the CPU's names in
    its order (drag first of the dissipated) and equal to its, their total drifting as the
    CPU's does (the left-point drag book and gravity's ½dt Σ m g·(v₀ − v), the scheme's own)."""
    if precision == "f64" and not F64:
        pytest.skip("the adapter has no f64")
    cpu, gpu = _galton(), _galton(DEVICE, precision)
    assert gpu.dt == cpu.dt and gpu.pinned.sum() > 100
    b0, g0 = _books(cpu), _books(gpu)
    assert list(g0) == list(b0) and list(b0)[-3:] == ["D drag", "D contacts (normal damping)", "D contacts (friction)"]
    pins = cpu.pinned
    x0 = cpu.positions
    steps, seen = 2000, 0
    for _ in range(20):  # calls of 100 steps: the first ends during ball 0's first contact
        cpu.step(steps // 20)
        gpu.step(steps // 20)
        seen += cpu.contact_count()
        assert gpu.contact_count() == cpu.contact_count() or precision == "f32"
    assert gpu.device == DEVICE and gpu.precision == precision
    b1, g1 = _books(cpu), _books(gpu)
    assert list(g1) == list(b1)
    # Ball 0 met the top peg and left its column (off it by more than a radius).
    assert seen > 0 and abs(cpu.positions[0, 0]) > RB and b1["D contacts (normal damping)"] > 0
    # Where they were put (f32: as the device rounded them), to the bit.
    np.testing.assert_array_equal(gpu.positions[pins], x0[pins].astype(np.float32) if precision == "f32" else x0[pins])
    np.testing.assert_array_equal(gpu.velocities[pins], 0.0)
    dx = np.abs(gpu.positions[~pins] - cpu.positions[~pins]).max() / RB
    scale = sum(abs(v) for v in b1.values())
    ds = max(abs(g1[k] - b1[k]) for k in b1 if not k.startswith("D ")) / scale
    db = max(abs(g1[k] - b1[k]) for k in b1 if k.startswith("D ")) / scale
    dd = abs(g1["D drag"] - b1["D drag"]) / b1["D drag"]
    drift = {k: sum(b[1].values()) - sum(b[0].values()) for k, b in (("cpu", (b0, b1)), ("gpu", (g0, g1)))}
    print(f"\nGalton board 6 balls, 3 rows, {precision}, {steps} steps: balls {dx:.1e} RB apart, state books {ds:.1e}, "
          f"dissipated {db:.1e} of their scale, drag {dd:.1e}; total drift CPU {drift['cpu']:.2e} J, GPU {drift['gpu']:.2e} J "
          f"of {scale:.2e} J; {seen} contacts seen")
    # f32: the queue sinks at 0.64 m/s up to y = 0.26 m, where each step's displacement rounds
    # by up to half an ulp of y: a drift of at most steps · ulp/2 (1.5e-2 RB; measured 6.0e-3 RB
    # on lavapipe, growing linearly with the steps and the same for any offset of ball 0).
    ulp = float(np.spacing(np.float32(np.abs(cpu.positions).max())))
    tol = {"f32": (steps * ulp / 2 / RB, 1e-4, 3e-4), "f64": (1e-10, 1e-12, 1e-4)}[precision]
    assert dx < tol[0] and ds < tol[1] and db < tol[2], (precision, dx, ds, db)
    assert dd < tol[2] and abs(drift["gpu"] - drift["cpu"]) < tol[2] * scale
    # The books balance to the scheme's first-order error (both paths alike).
    assert abs(drift["gpu"]) < 1e-2 * (g1["D drag"] + g1["D contacts (normal damping)"])


def test_a_galton_board_on_the_gpu_saves_and_loads_bit_for_bit(tmp_path) -> None:
    """Pegs and drag in the file: a load and a pickle continue bit for bit, the CPU from the
    GPU's file as the GPU does."""
    precision = "f64" if F64 else "f32"
    a = _galton(DEVICE, precision)
    a.step(400)
    assert _books(a)["D contacts (normal damping)"] > 0  # ball 0 has met the top peg
    path = a.save(tmp_path / "galton.npz")
    b = pc.Scene.load(path)
    c = pickle.loads(pickle.dumps(a))
    on_cpu = pc.Scene.load(path, device="cpu")
    for s in (a, b, c, on_cpu):
        s.step(300)
    for s in (b, c):
        assert s.device == DEVICE
        np.testing.assert_array_equal(s.positions, a.positions)
        np.testing.assert_array_equal(s.velocities, a.velocities)
        assert _books(s) == _books(a)
    tol = 1e-10 if precision == "f64" else 1e-2
    assert np.abs(on_cpu.positions - a.positions).max() / RB < tol
    np.testing.assert_array_equal(a.positions[a.pinned], _galton().positions[a.pinned])


def test_device_auto_keeps_grains_on_the_cpu_and_says_why() -> None:
    s = _pile(2, "auto")
    s.step(1)
    assert s.device == "cpu" and "grains' (DEM) GPU path has not been timed" in s.device_reason


def test_ctrl_c_during_a_gpu_dem_call_rolls_it_back() -> None:
    """Ctrl-C 0.3 s into a call of 10^6 steps (submissions of about 0.1 s, the stop flag read
    between them): KeyboardInterrupt, and the grains, their spins and springs are as before."""
    s = _pile(2, DEVICE, "f32", rolling=0.1)
    s.step(600)
    before = s.state()
    assert _interrupt(lambda: s.step(1_000_000), 0.3) < 9.7  # 10 s from the call's start
    after = s.state()
    for k, v in before.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(after[k], v, err_msg=k)
    s.step(10)
    assert s.step_count == 610


@pytest.mark.parametrize("law", ["linear", "hertz"])
def test_the_dem_step_limit_on_the_device_is_the_cpus(law: str) -> None:
    """``auto_dt``: a 50th of the lightest pair's contact duration (Hertz: at the fastest speed
    and the last evaluation's deepest overlap, read back from the device), as the CPU's."""
    cpu = _pile(2, law=law, rolling=0.1)
    gpu = _pile(2, DEVICE, "f64" if F64 else "f32", law=law, rolling=0.1)
    assert gpu.auto_dt() == pytest.approx(cpu.auto_dt(), rel=1e-12)
    for s in (cpu, gpu):
        s.step(900)
    assert cpu.contact_count() > 0
    assert gpu.auto_dt() == pytest.approx(cpu.auto_dt(), rel=1e-12 if F64 else 1e-5)
