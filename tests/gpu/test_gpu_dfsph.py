"""A DFSPH fluid on the GPU path (``Scene(device=...)`` with ``Fluid(method="dfsph")``, a
:class:`~physcore.Gravity` and a :class:`~physcore.Box`): against the CPU path, the reference;
its warm starts travelling as the fluid's history (save and load bit for bit, the CPU
continuing a GPU file and the other way round, ``state``/``set_state``, rollback); the
solver's statistics and step limit; what it refuses, by name, before anything changes.

Like ``test_gpu_scenes.py`` they run on a real GPU where one is present, else on lavapipe (CI).
The expected values are the CPU path's, never numbers copied from an earlier GPU run. Past some
30 steps the two stop a solve at different iterations now and then (each solve's mean error
against its tolerance, summed in another order: ``rust_core/src/sph/dfsph_device_tests.rs``),
so the comparisons to round-off run 10 steps; longer runs compare the flow.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from test_gpu_scenes import DEVICE, F64
from test_interrupt import _interrupt

import physcore as pc
from physcore.shapes import lattice, tank_walls

pytestmark = pytest.mark.skipif(DEVICE is None, reason="no GPU adapter and no lavapipe")
DX = 0.01
PRECISIONS = ["f32", "f64"] if F64 else ["f32"]
DT = 1e-3


def _tank(dim: int, device: str = "cpu", precision: str | None = None, **fluid) -> pc.Scene:
    """A block of water (0.12 wide, 0.2 tall; 0.06 deep in 3D) in the corner of a tank 0.4 ×
    0.3 (× 0.2) lined with 3 layers of boundary particles, inside a Box collider, under gravity,
    stepped at 1 ms."""
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", device=device, precision=precision)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    if dim == 2:
        lo, hi, tlo, thi = [0.0, 0.0], [0.12, 0.2], [0.0, 0.0], [0.4, 0.3]
    else:
        lo, hi, tlo, thi = [0.0, 0.0, 0.0], [0.06, 0.06, 0.1], [0.0, 0.0, 0.0], [0.2, 0.06, 0.15]
    s.add(pc.Fluid(lattice(lo, hi, DX), DX, name="water", method="dfsph", boundary=tank_walls(tlo, thi, DX, layers=3), **fluid))
    s.add(pc.Box([c - 0.05 for c in tlo], [c + 0.05 for c in thi]))
    s.dt = DT
    return s


def _books(s: pc.Scene) -> dict[str, float]:
    e = s.energy()
    return {"kinetic": e.kinetic, **{f"U {k}": v for k, v in e.potential.items()},
            **{f"D {k}": v for k, v in e.dissipated.items()}}


def _edge(x: np.ndarray) -> float:
    """The leading edge: the mean x of the 10 particles farthest along +x, m."""
    return float(np.sort(x[:, 0])[-10:].mean())


@pytest.mark.parametrize("dim", [2, 3])
def test_a_dfsph_tank_on_the_gpu_steps_books_and_counts_as_on_the_cpu(dim: int) -> None:
    cpu = _tank(dim)
    b0 = _books(cpu)
    cpu.step(10)
    b1 = _books(cpu)
    assert b1["kinetic"] > 0 and b1["D water"] != 0  # it moved, and the solves did work
    scale = sum(abs(v) for v in b1.values())
    width = 0.4 if dim == 2 else 0.2
    vmax = np.abs(cpu.velocities).max()
    for precision in PRECISIONS:
        gpu = _tank(dim, DEVICE, precision)
        assert _books(gpu).keys() == b0.keys()
        gpu.step(10)
        assert gpu.device == DEVICE and gpu.precision == precision
        dx = np.abs(gpu.positions - cpu.positions).max() / width
        dv = np.abs(gpu.velocities - cpu.velocities).max() / vmax
        drho = np.abs(gpu.density() - cpu.density()).max() / 1000.0
        g1 = _books(gpu)
        assert g1.keys() == b1.keys()
        db = max(abs(g1[k] - b1[k]) for k in b1) / scale
        print(f"\nDFSPH {dim}D {precision}, 10 steps: x {dx:.1e} of the tank, v {dv:.1e} of the fastest, "
              f"density {drho:.1e} of rho0, books {db:.1e} of their scale")
        # f64: round-off, grown by the solves' iterations (measured 1.1e-12 of the tank and
        # 2e-9 of the fastest speed in 3D, 5e-14 and 1.2e-10 in 2D). f32: a solve stops at another iteration from the first steps on, so
        # the velocities part at the solver's tolerance (measured 10 % of the fastest in 3D, 5 %
        # in 2D) and the positions by that times the 10 ms run (1.1e-4 of the tank in 3D).
        tol = {"f32": (3e-4, 0.2, 2e-3, 0.05), "f64": (1e-11, 2e-8, 1e-10, 1e-9)}[precision]
        assert dx < tol[0] and dv < tol[1] and drho < tol[2] and db < tol[3], (precision, dx, dv, drho, db)
        stats_cpu, stats_gpu = cpu.solver_stats("water"), gpu.solver_stats("water")
        assert stats_gpu["steps"] == stats_cpu["steps"] == 10
        if precision == "f64":
            for k in ("density_iterations", "divergence_iterations", "unconverged"):
                assert stats_gpu[k] == stats_cpu[k], k
            for k in ("density_error", "divergence_error", "density_error_max", "divergence_error_max"):
                assert stats_gpu[k] == pytest.approx(stats_cpu[k], rel=1e-6, abs=1e-12), k


def test_the_warm_starts_are_the_cpus_and_travel_as_the_fluids_history() -> None:
    """The device's warm starts and pressure, read as the fluid term's history (the scene
    file's ``term{k}_history``), are the CPU term's after the same steps; put into a CPU scene
    (``set_state``) they continue as the device does."""
    precision = "f64" if F64 else "f32"
    cpu, gpu = _tank(2), _tank(2, DEVICE, precision)
    for s in (cpu, gpu):
        s.step(8)
    hc, hg = cpu.state(), gpu.state()
    key = next(k for k in hc if k.endswith("_history"))
    n = cpu.n_particles
    assert hg[key].shape == hc[key].shape == (3 * n,)
    scale = np.abs(hc[key]).reshape(3, n).max(axis=1)
    assert (scale > 0).all()  # both warm starts and the pressure are live
    err = (np.abs(hg[key] - hc[key]).reshape(3, n).max(axis=1) / scale).max()
    assert err < (1e-9 if precision == "f64" else 0.05), err
    # The CPU continues from the device's state, warm starts included.
    twin = _tank(2)
    twin.set_state({k: v for k, v in hg.items() if not k.startswith("device_")} | {"cache_forces": None, "cache_power": None})
    for s in (twin, gpu):
        s.step(2)
    assert np.abs(twin.positions - gpu.positions).max() < (1e-12 if precision == "f64" else 1e-4)


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_a_gpu_dfsph_scene_saved_and_loaded_continues_bit_for_bit_and_on_the_cpu(tmp_path, precision: str) -> None:
    if precision == "f64" and not F64:
        pytest.skip("the adapter has no f64")
    a = _tank(2, DEVICE, precision)
    a.step(10)
    path = a.save(tmp_path / "tank.npz")
    b = pc.Scene.load(path)
    c = pickle.loads(pickle.dumps(a))
    on_cpu = pc.Scene.load(path, device="cpu")
    state = a.state()
    for s in (a, b, c, on_cpu):
        s.step(5)
    d = _tank(2, DEVICE, precision)
    d.step(3)
    d.set_state(state)  # the device's rows and the warm starts put back
    d.step(5)
    assert b.device == DEVICE and c.device == DEVICE and on_cpu.device == "cpu"
    for s in (b, c, d):
        np.testing.assert_array_equal(s.positions, a.positions)
        np.testing.assert_array_equal(s.velocities, a.velocities)
        assert s.energy().total == pytest.approx(a.energy().total, rel=1e-12 if precision == "f64" else 1e-6)
        assert s.solver_stats("water")["steps"] == a.solver_stats("water")["steps"] == 15
    tol = 1e-12 if precision == "f64" else 1e-4
    assert np.abs(on_cpu.positions - a.positions).max() < tol
    # A CPU file continues on the device likewise (its warm starts uploaded with the state).
    cpu = _tank(2)
    cpu.step(10)
    cpu_path = cpu.save(tmp_path / "cpu.npz")
    moved = pc.Scene.load(cpu_path, device=DEVICE)
    moved_precision = moved.precision
    for s in (cpu, moved):
        s.step(5)
    assert moved.device == DEVICE
    assert np.abs(moved.positions - cpu.positions).max() < (1e-12 if moved_precision == "f64" else 1e-4)


def test_a_gpu_dfsph_fluid_that_diverges_is_rolled_back() -> None:
    """A step of 1e100 s sends the f32 state past float32's range: the call raises naming the
    particle and the scene, warm starts included, is as it was before it."""
    s = _tank(2, DEVICE, "f32")
    s.step(5)
    before = s.state()
    s.dt = 1e100
    with pytest.raises(pc.SimulationDiverged, match="particle"), pytest.warns(pc.StabilityWarning, match="CFL"):
        s.step(20)
    after = s.state()
    for k, v in before.items():
        if k == "device_aux":
            # Row 0: the books; rows 1 and 2, the solver's counts and largest errors, keep the
            # steps rolled back (as the CPU's `solver_stats` does).
            np.testing.assert_array_equal(after[k][0], v[0])
        elif isinstance(v, np.ndarray):
            np.testing.assert_array_equal(after[k], v, err_msg=k)
    s.dt = DT
    s.step(5)  # and it steps on
    assert np.isfinite(s.positions).all()


@pytest.mark.parametrize("dim", [2, 3])
def test_the_dfsph_step_limit_on_the_device_is_the_cpus(dim: int) -> None:
    """``auto_dt``: the flow's CFL condition at the largest speed, the viscosity's limit and
    gravity's force criterion, as the CPU's DFSPH takes them; ``advance`` takes it before every
    substep (the limit follows the flow), so it takes the CPU's substeps. The water is thrown
    at 2 m/s so that the CFL condition binds (at rest, the force criterion does)."""
    def thrown(device: str = "cpu", precision: str | None = None) -> pc.Scene:
        s = _tank(dim, device, precision)
        v = np.zeros((s.n_particles, dim))
        v[:, 0] = 2.0
        s.velocities = v
        return s

    rest = _tank(dim).auto_dt()
    cpu = thrown()
    limit0 = cpu.auto_dt()
    assert limit0 < rest  # the flow's CFL condition binds
    cpu.step(5)
    limit = cpu.auto_dt()
    assert limit != limit0
    for precision in PRECISIONS:
        assert _tank(dim, DEVICE, precision).auto_dt() == pytest.approx(rest, rel=1e-12)
        gpu = thrown(DEVICE, precision)
        assert gpu.auto_dt() == pytest.approx(limit0, rel=1e-12 if precision == "f64" else 1e-6)
        gpu.step(5)
        assert gpu.auto_dt() == pytest.approx(limit, rel=1e-9 if precision == "f64" else 1e-2)
        twin = thrown()
        twin.step(5)
        assert gpu.advance(0.005) == twin.advance(0.005)


def test_the_gpu_dfsph_collapse_follows_the_cpus() -> None:
    """0.15 s of the column's collapse (150 steps): past the first 30 steps the solves stop at
    other iterations now and then, so the flow is compared: the leading edge within 1 % of the
    column's width, the kinetic energy within 5 %."""
    cpu = _tank(2)
    cpu.step(150)
    e0, k0 = _edge(cpu.positions), cpu.energy().kinetic
    assert e0 > 0.14  # the column (0.12 wide) spread
    for precision in PRECISIONS:
        gpu = _tank(2, DEVICE, precision)
        gpu.step(150)
        e, k = _edge(gpu.positions), gpu.energy().kinetic
        print(f"\nDFSPH collapse {precision}: leading edge {abs(e - e0) / 0.12:.1e} of the width, kinetic {k / k0 - 1:+.1e}")
        assert abs(e - e0) < 0.01 * 0.12 and abs(k / k0 - 1) < 0.05, (precision, e, e0, k, k0)


@pytest.mark.parametrize("change", ["two_fluids", "springs"])
def test_what_the_gpu_dfsph_fluid_cannot_hold_is_refused_by_name_and_nothing_changes(change: str) -> None:
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", device=DEVICE)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Fluid(lattice([0.0, 0.0], [0.1, 0.1], DX), DX, name="water", method="dfsph"))
    if change == "two_fluids":
        s.add(pc.Fluid(lattice([0.2, 0.0], [0.3, 0.1], DX), DX, name="oil", method="dfsph"))
    if change == "springs":
        s.add(pc.Springs([0], [1], stiffness=10.0, rest_length=DX, name="tie"))
    s.add(pc.Box([-0.1, -0.1], [0.5, 0.5]))
    want = {"two_fluids": "oil|particles", "springs": "tie"}[change]
    x0 = s.positions
    with pytest.raises(pc.InvalidInputError, match=want):
        s.step(1)
    np.testing.assert_array_equal(s.positions, x0)
    assert s.time == 0.0


def test_the_dam_break_scene_runs_dfsph_on_the_gpu_as_on_the_cpu() -> None:
    """``dam_break(device=...)``: DFSPH (the scene's default) on the device in float32, the
    surge after 0.3 s as the CPU's (the leading edge within 2 % of the column's width)."""
    cpu = pc.scenes.dam_break(n=12)
    gpu = pc.scenes.dam_break(n=12, device=DEVICE)
    for s in (cpu, gpu):
        s.advance(0.3)
    assert gpu.precision == "f32"
    e0, e = _edge(cpu.positions), _edge(gpu.positions)
    assert e0 > 1.5  # it surged (the column is 1 m wide)
    assert abs(e - e0) < 0.02, (e, e0)


def test_a_bad_history_is_refused_by_name_on_the_device_and_nothing_changes(tmp_path) -> None:
    """A snapshot or a file whose warm starts are not finite, or of another length, is refused
    naming the history; the scene on the device is as it was and steps on as before."""
    s = _tank(2, DEVICE, "f32")
    s.step(3)
    good = s.state()
    key = next(k for k in good if k.endswith("_history"))
    twin = _tank(2, DEVICE, "f32")
    twin.step(3)
    for bad in (np.where(np.arange(len(good[key])) == 7, np.nan, good[key]), good[key][:-1]):
        with pytest.raises(pc.InvalidInputError, match="history"):
            s.set_state({**good, key: bad})
        now = s.state()
        for k, v in good.items():
            if isinstance(v, np.ndarray):
                np.testing.assert_array_equal(now[k], v, err_msg=k)
    for t in (s, twin):
        t.step(3)
    np.testing.assert_array_equal(s.positions, twin.positions)
    # A file with a bad history is refused by the loader, naming it.
    path = s.save(tmp_path / "tank.npz")
    with np.load(path) as z:
        arrays = dict(z)
    arrays[key] = arrays[key][:-1]
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(pc.InvalidInputError, match="history"):
        pc.Scene.load(tmp_path / "bad.npz")


def test_ctrl_c_during_a_gpu_dfsph_call_rolls_it_back() -> None:
    """Ctrl-C 0.3 s into a call of 100,000 steps (the device's submissions each take about
    0.1 s; the stop flag is read between them): KeyboardInterrupt, and the scene, warm starts
    included, is as before the call; it steps on."""
    s = _tank(2, DEVICE, "f32")
    s.step(2)
    before = s.state()
    assert _interrupt(lambda: s.step(100_000), 0.3) < 9.7  # it stopped soon after the signal
    after = s.state()
    for k, v in before.items():
        if k == "device_aux":
            np.testing.assert_array_equal(after[k][0], v[0])  # the books; rows 1, 2: the solver's, every step run
        elif isinstance(v, np.ndarray):
            np.testing.assert_array_equal(after[k], v, err_msg=k)
    s.step(2)
    assert s.step_count == 4


@pytest.mark.parametrize("dim", [2, 3])
def test_surface_tension_and_adhesion_on_the_gpu_act_as_on_the_cpu(dim: int) -> None:
    """Akinci et al. (2013) cohesion, curvature and adhesion to the walls on the device: the
    tank's water with a surface tension of 0.0728 N/m (water's) and adhesion 0.05, 10 steps
    against the CPU; its step limit (with the capillary one) is the CPU's."""
    cpu = _tank(dim, surface_tension=0.0728, adhesion=0.05)
    plain = _tank(dim)
    for s in (cpu, plain):
        s.step(10)
    width = 0.4 if dim == 2 else 0.2
    effect = np.abs(cpu.positions - plain.positions).max() / width
    assert effect > 1e-9  # the surface forces moved the water
    for precision in PRECISIONS:
        gpu = _tank(dim, DEVICE, precision, surface_tension=0.0728, adhesion=0.05)
        assert gpu.auto_dt() == pytest.approx(_tank(dim, surface_tension=0.0728, adhesion=0.05).auto_dt(), rel=1e-12)
        gpu.step(10)
        dx = np.abs(gpu.positions - cpu.positions).max() / width
        b1, g1 = _books(cpu), _books(gpu)
        assert g1.keys() == b1.keys()
        db = max(abs(g1[k] - b1[k]) for k in b1) / sum(abs(v) for v in b1.values())
        print(f"\nDFSPH {dim}D surface tension {precision}: x {dx:.1e} of the tank (the forces' effect {effect:.1e}), books {db:.1e}")
        tol = {"f64": (1e-11, 1e-9), "f32": (3e-4, 0.05)}[precision]
        assert dx < tol[0] and db < tol[1], (precision, dx, db)
