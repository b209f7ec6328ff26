"""Automatic step choice: ``advance(duration, substeps="auto")`` per integrator, and the
adaptive ``"dopri5"`` integrator's tolerances, failure report and determinism."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import oscillator

import physcore as pc


def _stiff_chain(integrator: str, k: float = 1e4) -> pc.Scene:
    return pc.scenes.spring_chain(n=8, stiffness=k, damping=0.0, integrator=integrator, threads=1)


def test_auto_substeps_follow_each_integrators_stability_interval():
    # ω_max·dt = 0.5 with ω_max from a safe (Gershgorin) bound, inside the stability interval of
    # every fixed-step method (2 for semi-implicit Euler and Verlet, 2√2 for RK4); dopri5 takes one
    # substep per call and controls its own internal steps.
    dts = {name: _stiff_chain(name).auto_dt() for name in ("semi_implicit_euler", "verlet", "rk4", "euler")}
    assert dts["verlet"] == dts["semi_implicit_euler"] == dts["euler"] == dts["rk4"]
    # Gershgorin on M⁻¹K: a link mass m between two springs k has ω² ≤ 2k/m + 2·k/m.
    omega_max = 2 * math.sqrt(1e4 / (1.0 / 8))
    assert dts["verlet"] * omega_max == pytest.approx(0.5, rel=1e-12)
    s = _stiff_chain("verlet")
    assert dts["verlet"] == pytest.approx(s.suggest_dt(), rel=1e-12)
    assert _stiff_chain("dopri5").auto_dt() == math.inf
    frame = 1 / 30
    counts = {}
    for name in ("verlet", "rk4", "dopri5"):
        s = _stiff_chain(name)
        counts[name] = s.advance(frame)
        assert s.time == pytest.approx(frame, rel=1e-14)
        assert s.dt == pytest.approx(frame / counts[name], rel=1e-14)
    assert counts["verlet"] == math.ceil(frame / dts["verlet"])
    assert counts["rk4"] == counts["verlet"]
    assert counts["dopri5"] == 1


@pytest.mark.parametrize("integrator", ["semi_implicit_euler", "verlet", "rk4", "dopri5"])
@pytest.mark.parametrize("k", [1e2, 1e6, 1e10])
def test_auto_substeps_stay_stable_over_stiffness(integrator, k):
    # Over 8 orders of magnitude of stiffness the automatic substeps keep the undamped chain
    # stable for 10 frames of up to 20 stiff periods each (at most 2 s: the soft chain's swing
    # is chaotic later, and its links then fold through zero length, where the force direction
    # jumps). Bounds from each method's linear theory at ω·dt ≤ 0.5: semi-implicit Euler's
    # modified energy differs from H by up to ω·dt/2 = 0.25, Verlet's by (ω·dt)²/8 ≈ 0.03; RK4
    # loses at most (ω·dt)⁶/72 ≈ 2e-4 of a mode's energy per step, dopri5 is held to its rtol.
    s = _stiff_chain(integrator, k)
    if integrator == "dopri5":
        s.rtol, s.atol = 1e-5, 1e-9
    period = 2 * math.pi * math.sqrt(s.masses[1] / k)
    frame = min(20 * period, 0.2)
    taken = [s.advance(frame) for _ in range(10)]
    assert all(t >= 1 for t in taken)
    bound = {"semi_implicit_euler": 0.25, "verlet": 0.03}.get(integrator, 1e-3)
    assert abs(s.energy_drift()) < bound, (taken, s.energy_drift())


def test_fixed_substeps():
    s = oscillator("verlet", 0.1)
    assert s.advance(1.0, substeps=40) == 40
    assert s.dt == 1.0 / 40 and s.step_count == 40
    for bad, exc in [(0, ValueError), ("fast", ValueError), (2.5, TypeError), (True, TypeError)]:
        with pytest.raises(exc, match="substeps"):
            s.advance(1.0, substeps=bad)
    assert s.step_count == 40 and s.dt == 1.0 / 40


def test_dopri5_tolerance_validation():
    s = pc.Scene(2, integrator="dopri5", rtol=1e-8, atol=1e-12)
    assert (s.rtol, s.atol) == (1e-8, 1e-12)
    for kw, exc in [({"rtol": 0.0}, ValueError), ({"rtol": 1.0}, ValueError), ({"rtol": 1e-16}, ValueError),
                    ({"atol": -1.0}, ValueError), ({"atol": math.nan}, ValueError), ({"rtol": "1e-6"}, TypeError)]:
        with pytest.raises(exc, match=next(iter(kw))):
            pc.Scene(2, integrator="dopri5", **kw)
    with pytest.raises(ValueError, match="rtol"):
        s.rtol = -1e-3
    assert s.rtol == 1e-8
    # Tolerances survive a change of integrator.
    s.integrator = "verlet"
    s.integrator = "dopri5"
    assert (s.rtol, s.atol) == (1e-8, 1e-12)


def test_dopri5_gives_up_with_a_named_particle_and_rolls_back():
    # Unsoftened gravity between coincident-ish particles: infinite forces that no step size
    # can control. The scene must say so, name a particle, and roll back.
    s = pc.Scene(2, integrator="dopri5", dt=0.1)
    s.add_particles([[0.0, 0.0], [1e-160, 0.0], [5.0, 0.0]], masses=[1.0, 1.0, 1.0])
    s.add(pc.PairwiseGravity(G=1.0, softening=0.0))
    x0 = s.positions
    with pytest.raises(pc.SimulationDiverged, match="rtol/atol") as info:
        s.step(3)
    assert info.value.particle in (0, 1)
    assert info.value.quantity == "error"
    assert s.step_count == 0 and np.array_equal(s.positions, x0)
    # The rollback covers the controller's books too: the failed attempts are not counted and
    # the never-stepped scene has no next step yet.
    assert s.integrator_stats == {"accepted": 0, "rejected": 0, "next_step": 0.0}


def test_dopri5_rollback_keeps_the_counts_of_earlier_calls():
    s = pc.Scene(2, integrator="dopri5", dt=0.1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]], masses=[1.0, 1.0, 1.0])
    s.add(pc.PairwiseGravity(G=1.0, softening=0.0))
    s.step(2)
    before = s.integrator_stats
    assert before["accepted"] >= 2
    s.positions = [[0.0, 0.0], [1e-160, 0.0], [5.0, 0.0]]
    with pytest.raises(pc.SimulationDiverged):
        s.step(3)
    assert s.integrator_stats["accepted"] == before["accepted"]
    assert s.integrator_stats["rejected"] == before["rejected"]


@pytest.mark.parametrize("when", ["fresh", "step0", "switched"])
def test_dopri5_scene_saved_before_its_first_step_loads(tmp_path, when):
    # Saved before dopri5 has taken a step (no derivative cached yet), the file must load and the
    # loaded scene continue exactly as the original.
    if when == "switched":
        s = pc.scenes.kepler()
        s.step(10)
        s.integrator = "dopri5"
    else:
        s = pc.scenes.kepler(integrator="dopri5")
        if when == "step0":
            s.step(0)
    path = s.save(tmp_path / "k.npz")
    t = pc.Scene.load(path)
    s.step(5)
    t.step(5)
    assert np.array_equal(s.positions, t.positions)
    assert s.integrator_stats == t.integrator_stats


def test_dopri5_is_thread_count_independent():
    runs = []
    for threads in (1, 2):
        s = pc.scenes.cloth(n=64, threads=threads, integrator="dopri5", dt=1 / 60)
        s.rtol, s.atol = 1e-5, 1e-8
        s.step(3)
        runs.append(s)
    assert runs[0].integrator_stats == runs[1].integrator_stats
    assert runs[0].integrator_stats["accepted"] > 3
    assert np.array_equal(runs[0].positions, runs[1].positions)
    assert runs[0].energy() == runs[1].energy()


def test_dopri5_books_dissipation():
    # A damped chain: kinetic + potential + dissipated stays at its start value to about rtol.
    s = pc.scenes.spring_chain(n=10, damping=0.5, integrator="dopri5", dt=0.02, threads=1)
    s.rtol, s.atol = 1e-9, 1e-12
    s.step(100)
    assert s.energy().dissipated["springs"] > 0
    assert s.energy_drift() < 1e-6


def test_repr_names_tolerances_and_precision():
    r = repr(pc.Scene(2, integrator="dopri5", rtol=1e-8, precision="f32"))
    assert "rtol=1e-08" in r and "precision='f32'" in r
    r = repr(pc.Scene(2))
    assert "rtol" not in r and "precision" not in r


def test_dopri5_pure_relative_tolerance_with_pinned_particles():
    # atol = 0: components that stay exactly 0 (a pinned anchor, the unused axis) have a zero
    # error, which must pass a zero tolerance rather than divide 0 by 0.
    s = oscillator("dopri5", 0.5)
    s.rtol, s.atol = 1e-8, 0.0
    s.step(20)
    assert s.integrator_stats["accepted"] >= 20
    assert np.array_equal(s.positions[0], [0.0, 0.0])
    assert abs(s.energy_drift()) < 1e-6
