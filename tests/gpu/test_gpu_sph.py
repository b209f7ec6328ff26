"""A WCSPH fluid on the GPU path (``Scene(device=...)`` with a :class:`~physcore.Fluid`, a
:class:`~physcore.Gravity` and a :class:`~physcore.Box`): against the CPU path, the reference;
its promises (save and load bit for bit, pickling, the CPU continuing a GPU file, rollback);
and what it refuses, by name, before anything changes.

Like ``test_gpu_scenes.py`` they run on a real GPU where one is present, else on lavapipe (CI).
The expected values are the CPU path's, never numbers copied from an earlier GPU run.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from test_gpu_scenes import DEVICE, F64, F64_EXACT

import physcore as pc
from physcore.shapes import lattice, tank_walls

pytestmark = pytest.mark.skipif(DEVICE is None, reason="no GPU adapter and no lavapipe")
DX = 0.01
PRECISIONS = ["f32", "f64"] if F64 else ["f32"]


def _tank(dim: int, device: str = "cpu", precision: str | None = None, walls: bool = True,
          integrator: str = "semi_implicit_euler") -> pc.Scene:
    """A block of water (0.2 wide, 0.3 tall; 0.1 deep in 3D) in the corner of a tank 0.6 × 0.5
    (× 0.2) lined with 3 layers of boundary particles, inside a Box collider, under gravity."""
    s = pc.Scene(dim=dim, integrator=integrator, device=device, precision=precision)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    if dim == 2:
        lo, hi, tlo, thi = [0.0, 0.0], [0.2, 0.3], [0.0, 0.0], [0.6, 0.5]
    else:
        lo, hi, tlo, thi = [0.0, 0.0, 0.0], [0.1, 0.06, 0.15], [0.0, 0.0, 0.0], [0.3, 0.06, 0.25]
    kw = {"boundary": tank_walls(tlo, thi, DX, layers=3)} if walls else {}
    s.add(pc.Fluid(lattice(lo, hi, DX), DX, name="water", **kw))
    s.add(pc.Box([c - 0.05 for c in tlo], [c + 0.05 for c in thi]))
    return s


def _books(s: pc.Scene) -> dict[str, float]:
    e = s.energy()
    return {"kinetic": e.kinetic, **{f"U {k}": v for k, v in e.potential.items()},
            **{f"D {k}": v for k, v in e.dissipated.items()}}


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("walls", [True, False])
def test_a_wcsph_tank_on_the_gpu_steps_and_books_as_on_the_cpu(dim: int, walls: bool) -> None:
    cpu = _tank(dim, walls=walls)
    b0 = _books(cpu)
    cpu.step(200)
    b1 = _books(cpu)
    assert b1["D water"] > 0 and b1["kinetic"] > 0  # it moved, and the viscosity took energy
    scale = sum(abs(v) for v in b1.values())
    for precision in ["f32", "f64"] if F64 else ["f32"]:
        gpu = _tank(dim, DEVICE, precision, walls=walls)
        assert _books(gpu).keys() == b0.keys()
        gpu.step(200)
        assert gpu.device == DEVICE and gpu.precision == precision
        width = 0.6 if dim == 2 else 0.3
        dx = np.abs(gpu.positions - cpu.positions).max() / width
        dv = np.abs(gpu.velocities - cpu.velocities).max() / np.abs(cpu.velocities).max()
        drho = np.abs(gpu.density() - cpu.density()).max() / 1000.0
        # The pressure over the Tait stiffness B = ρ0 c0²/γ (a free surface's pressure is near 0).
        fluid = next(t for t in cpu.terms if isinstance(t, pc.Fluid))
        dp = np.abs(gpu.pressure() - cpu.pressure()).max() / (1000.0 * fluid.sound_speed**2 / fluid.gamma)
        g1 = _books(gpu)
        assert g1.keys() == b1.keys()
        db = max(abs(g1[k] - b1[k]) for k in b1) / scale
        # f64: round-off (lavapipe, or a GPU that fuses a·b + c); f32: 24-bit mantissas over 200 steps.
        tol = {"f32": (1e-4, 1e-2, 1e-4, 1e-3, 1e-4), "f64": (1e-12, 1e-9, 1e-12, 1e-11, 1e-12)}[precision]
        assert dx < tol[0] and dv < tol[1] and drho < tol[2] and dp < tol[3] and db < tol[4], (precision, dx, dv, drho, dp, db)
        np.testing.assert_array_equal(gpu.masses, cpu.masses)


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_a_gpu_fluid_saved_and_loaded_continues_bit_for_bit_and_on_the_cpu(tmp_path, precision: str) -> None:
    if precision == "f64" and not F64:
        pytest.skip("the adapter has no f64")
    a = _tank(2, DEVICE, precision)
    a.step(50)
    path = a.save(tmp_path / "tank.npz")
    b = pc.Scene.load(path)
    c = pickle.loads(pickle.dumps(a))
    on_cpu = pc.Scene.load(path, device="cpu")
    state = a.state()
    for s in (a, b, c, on_cpu):
        s.step(50)
    d = _tank(2, DEVICE, precision)
    d.step(1)
    d.set_state(state)  # the state snapshot puts the device's rows back
    d.step(50)
    assert b.device == DEVICE and c.device == DEVICE and on_cpu.device == "cpu"
    for s in (b, c, d):
        np.testing.assert_array_equal(s.positions, a.positions)
        np.testing.assert_array_equal(s.velocities, a.velocities)
        # The dissipated books carried over and added to: round-off of the device's precision,
        # since the per-particle sums restart from zero on the host's total.
        assert s.energy().total == pytest.approx(a.energy().total, rel=1e-12 if precision == "f64" else 1e-6)
    # The CPU continues the GPU's file: the same motion to the device's precision.
    tol = 1e-12 if precision == "f64" else 1e-4
    assert np.abs(on_cpu.positions - a.positions).max() < tol
    assert on_cpu.energy().total == pytest.approx(a.energy().total, rel=tol)


def test_a_gpu_fluid_that_diverges_is_rolled_back() -> None:
    """A step of 1e100 s sends the f32 state past float32's range: the call raises naming the
    particle and the scene is as it was before it (the checkpoint read back and sent again)."""
    s = _tank(2, DEVICE, "f32", walls=False)
    s.step(5)
    x0, v0, e0 = s.positions, s.velocities, s.energy().total
    s.dt = 1e100
    with pytest.raises(pc.SimulationDiverged, match="particle"), pytest.warns(pc.StabilityWarning, match="CFL"):
        s.step(20)
    np.testing.assert_array_equal(s.positions, x0)
    np.testing.assert_array_equal(s.velocities, v0)
    assert s.energy().total == e0
    s.dt = 1e-4
    s.step(5)  # and it steps on
    assert np.isfinite(s.positions).all()


@pytest.mark.parametrize("change", ["springs", "no_box", "verlet", "pinned"])
def test_what_the_gpu_fluid_cannot_hold_is_refused_by_name_and_nothing_changes(change: str) -> None:
    integrator = "verlet" if change == "verlet" else "semi_implicit_euler"
    s = pc.Scene(dim=2, integrator=integrator, device=DEVICE)
    s.add(pc.Gravity([0.0, -9.81]))
    pos = lattice([0.0, 0.0], [0.1, 0.1], DX)
    s.add(pc.Fluid(pos, DX, name="water", method="wcsph"))
    if change != "no_box":
        s.add(pc.Box([-0.1, -0.1], [0.5, 0.5]))
    if change == "springs":
        s.add(pc.Springs([0], [1], stiffness=10.0, rest_length=DX, name="tie"))
    if change == "pinned":
        s.add_particles([[0.3, 0.3]], masses=[1.0], pinned=[True])
    want = {"springs": "tie", "no_box": "colliders", "verlet": "integrator", "pinned": "particles|pinned"}[change]
    x0 = s.positions
    with pytest.raises(pc.InvalidInputError, match=want):
        s.step(1)
    np.testing.assert_array_equal(s.positions, x0)
    assert s.time == 0.0


def test_device_auto_keeps_a_fluid_on_the_cpu_and_says_why() -> None:
    s = _tank(2, "auto")
    s.step(1)
    assert s.device == "cpu" and "fluids' GPU path has not been timed" in s.device_reason


@pytest.mark.skipif(not F64_EXACT, reason="bit-identity with the CPU holds on lavapipe only (a GPU fuses a·b + c)")
def test_on_lavapipe_the_f64_fluid_runs_to_round_off_of_the_cpu() -> None:
    cpu, gpu = _tank(2), _tank(2, DEVICE, "f64")
    for s in (cpu, gpu):
        s.step(100)
    assert np.abs(gpu.positions - cpu.positions).max() < 1e-14


def test_the_dam_break_scene_runs_on_the_gpu_as_on_the_cpu() -> None:
    """``dam_break(method="wcsph", device=...)``: the same surge as the CPU's (its front after
    0.3 s, the water's books), the tank in a Box one the CPU does not need (DFSPH, the scene's
    default: ``test_gpu_dfsph.py``)."""
    cpu = pc.scenes.dam_break(n=12, method="wcsph")
    gpu = pc.scenes.dam_break(n=12, method="wcsph", device=DEVICE)  # float32 on the device
    for s in (cpu, gpu):
        s.advance(0.3)
    assert gpu.step_count == cpu.step_count and gpu.precision == "f32"
    front_cpu, front_gpu = cpu.positions[:, 0].max(), gpu.positions[:, 0].max()
    assert front_cpu > 1.5  # it surged (the column is 1 m wide)
    assert front_gpu == pytest.approx(front_cpu, abs=1e-3)
    assert gpu.energy().total == pytest.approx(cpu.energy().total, rel=1e-4)


def test_the_gpu_dam_break_front_matches_martin_and_moyce() -> None:
    """The CPU's Martin & Moyce test (tests/fluids/test_sph.py: column a × 2a, 20 particles
    across, the surge front over T = 0..3 within 15 % of every measured point with the gate's
    time shift) run on the device in float32, inside a Box around the open tank; and the front
    CPU's at every sample: its leading edge (the mean x of the 20 particles farthest along, a
    continuous measure) to 0.2 % of a. (The front itself, the farthest particle still within
    1.3 spacings of the body of water, jumps when a particle at the tip crosses that distance:
    one sample of 61 differed by 6.8 % of a once both runs took the same substeps, the others
    by at most 0.14 %.)"""
    import math
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fluids"))
    from test_sph import MARTIN_MOYCE_1952, MM_TIME_SHIFT, front

    a, n, g = 0.25, 20, 9.81
    dx, up = a / n, [5.0 * a, 2.5 * a]
    runs = []
    for device in ("cpu", DEVICE):
        s = pc.Scene(dim=2, integrator="semi_implicit_euler", device=device)
        s.add(pc.Gravity([0.0, -g]))
        s.add(pc.Fluid(lattice([0, 0], [a, 2 * a], dx), dx, boundary=tank_walls([0.0, 0.0], up, dx, layers=3, top=False),
                       pass_precision="f32", name="water"))
        s.add(pc.Box([-4 * dx, -4 * dx], [up[0] + 4 * dx, 4 * up[1]]))
        tscale = math.sqrt(2 * g / a)
        ts, zs, edge = [0.0], [1.0], []
        while ts[-1] < MARTIN_MOYCE_1952[-1][0] + 0.05:
            s.advance(0.05 / tscale)
            ts.append(s.time * tscale)
            zs.append(front(s.positions, 1.3 * dx) / a)
            edge.append(np.sort(s.positions[:, 0])[-20:].mean() / a)
        runs.append((np.array(ts), np.array(zs), np.array(edge)))
    (tc, zc, ec), (tg, zg, eg) = runs
    np.testing.assert_allclose(tg, tc, rtol=1e-12)  # the same samples (the clocks add in another order)
    assert np.abs(eg - ec).max() < 2e-3
    t_exp = np.array([t for t, _ in MARTIN_MOYCE_1952])
    z_exp = np.array([z for _, z in MARTIN_MOYCE_1952])
    err = np.interp(t_exp - MM_TIME_SHIFT, tg, zg) / z_exp - 1.0
    print(f"\nMartin & Moyce on {DEVICE} (f32): worst {np.abs(err).max():.1%}; front vs the CPU's: {np.abs(zg - zc).max():.2e} a")
    assert np.abs(err).max() < 0.15, err


@pytest.mark.parametrize("dim", [2, 3])
def test_the_step_limit_on_the_device_is_the_cpus(dim: int) -> None:
    """``auto_dt`` (what ``advance`` substeps by): the CFL condition at the largest speed and the
    force criterion at the last step's largest pressure and viscous acceleration, read back from
    the device, as the CPU's WCSPH takes them; so ``advance`` takes the CPU's substeps."""
    cpu = _tank(dim)
    limit0 = cpu.auto_dt()
    cpu.step(150)
    limit = cpu.auto_dt()
    assert limit < limit0  # the flow moved and pushed: the limit now follows it
    for precision in PRECISIONS:
        gpu = _tank(dim, DEVICE, precision)
        assert gpu.auto_dt() == pytest.approx(limit0, rel=1e-12)  # at rest: the sound speed's CFL
        gpu.step(150)
        assert gpu.auto_dt() == pytest.approx(limit, rel=1e-12 if precision == "f64" else 1e-4)
        twin = _tank(dim)
        twin.step(150)
        assert gpu.advance(0.02) == twin.advance(0.02)
