"""The single-precision state (``precision="f32"``): what it stores, what it costs in accuracy,
and that it keeps the library's guarantees (determinism, save/load, validation)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import random_cloud

import physcore as pc


def _kepler(precision: str, steps_per_orbit: int, integrator: str = "verlet") -> pc.Scene:
    s = pc.Scene(2, integrator=integrator, dt=2 * math.pi / steps_per_orbit, precision=precision, threads=1)
    e = 0.5
    s.add_particles([[0.0, 0.0], [1 - e, 0.0]], [[0.0, 0.0], [0.0, math.sqrt((1 + e) / (1 - e))]], masses=[1.0, 1.0], pinned=[True, False])
    s.add(pc.PairwiseGravity(G=1.0, softening=0.0))
    return s


def test_state_is_float32_and_representable():
    s = _kepler("f32", 1000)
    assert s.precision == "f32"
    assert s.positions.dtype == np.float32 and s.velocities.dtype == np.float32
    s.step(37)
    x64 = s._sim.positions  # the core's float64 copy holds exactly the float32 values
    assert np.array_equal(x64, x64.astype(np.float32).astype(np.float64))
    assert pc.Scene(2).positions.dtype == np.float64


def test_explicit_euler_step_is_the_rounded_double_step():
    # Explicit Euler reads only the start state, so one single-precision step must equal the
    # double-precision step from the same (float32) start, rounded to float32.
    x, v, m = random_cloud(3, 40, dim=3, speed=0.3, box=1.0)
    x, v = x.astype(np.float32).astype(np.float64), v.astype(np.float32).astype(np.float64)
    runs = {}
    for prec in ("f64", "f32"):
        s = pc.Scene(3, integrator="euler", dt=1e-3, precision=prec, threads=1)
        s.add_particles(x, v, masses=m)
        # Springs compute in float64 at either precision (pairwise gravity would not).
        s.add(pc.Springs(np.arange(39), np.arange(1, 40), stiffness=50.0, rest_length=0.1))
        s.step(1)
        runs[prec] = s
    assert np.array_equal(runs["f32"].positions, runs["f64"].positions.astype(np.float32))
    assert np.array_equal(runs["f32"].velocities, runs["f64"].velocities.astype(np.float32))
    assert not np.array_equal(runs["f64"].positions, runs["f64"].positions.astype(np.float32).astype(np.float64))


@pytest.mark.parametrize("integrator", ["verlet", "rk4"])
def test_f32_error_floor(integrator):
    # Coarse steps: truncation error dominates and both precisions agree. Fine steps: the f64
    # error keeps falling while f32 stops near its rounding floor (unit roundoff 6e-8 per step,
    # accumulating as a random walk over the steps).
    def drift(prec, spo):
        s = _kepler(prec, spo, integrator)
        s.step(10 * spo)
        return abs(s.energy_drift())

    coarse = 200 if integrator == "verlet" else 60
    d64, d32 = drift("f64", coarse), drift("f32", coarse)
    assert 0.5 < d32 / d64 < 2, (d64, d32)
    fine = 20000 if integrator == "verlet" else 2000
    f64, f32 = drift("f64", fine), drift("f32", fine)
    assert f64 < 1e-9, f64
    assert 1e-8 < f32 < 1e-4, f32


def test_f32_is_thread_count_independent_and_saves(tmp_path):
    runs = []
    for threads in (1, 2):
        s = pc.scenes.cloth(n=64, threads=threads)
        s2 = pc.Scene(3, integrator="verlet", dt=s.dt, precision="f32", threads=threads)
        s2.add_particles(s.positions, s.velocities, masses=s.masses, pinned=s.pinned)
        for t in s.terms:
            s2.add(t)
        s2.step(20)
        runs.append(s2)
    assert np.array_equal(runs[0].positions, runs[1].positions)
    assert np.array_equal(runs[0].velocities, runs[1].velocities)
    path = runs[0].save(tmp_path / "c.npz")
    c = pc.Scene.load(path)
    assert c.precision == "f32"
    runs[0].step(10)
    c.step(10)
    assert np.array_equal(runs[0].positions, c.positions)
    assert runs[0].energy() == c.energy()


def test_f32_rounds_assigned_state():
    s = pc.Scene(2, precision="f32")
    s.add_particles([[0.1, 1 / 3]], [[math.pi, 0.0]])
    assert s.positions[0, 1] == np.float32(1 / 3)
    s.velocities = [[1 / 7, 0.0]]
    assert s._sim.velocities[0, 0] == float(np.float32(1 / 7))


# None is the default: "f64" on the CPU, "f32" on a GPU device (tests/gpu).
@pytest.mark.parametrize("bad, exc", [("f16", ValueError), ("double", ValueError), (32, TypeError), (b"f32", TypeError)])
def test_bad_precision(bad, exc):
    with pytest.raises(exc, match="precision"):
        pc.Scene(2, precision=bad)


def test_f32_pairwise_gravity_runs_in_single_precision():
    # The float32 N-body kernel: forces agree with float64 ones to single precision, not better.
    x, v, m = random_cloud(4, 300, dim=3, speed=0.1, box=1.0)
    x = x.astype(np.float32).astype(np.float64)
    acc = {}
    for prec in ("f64", "f32"):
        s = pc.Scene(3, integrator="euler", dt=1e-6, precision=prec, threads=1)
        s.add_particles(x, np.zeros_like(x), masses=m)
        s.add(pc.PairwiseGravity(G=1.0, softening=0.01))
        s.step(1)
        acc[prec] = s._sim.velocities / 1e-6
    err = np.abs(acc["f32"] - acc["f64"]).max() / np.abs(acc["f64"]).max()
    assert 1e-9 < err < 1e-5, err


def test_dopri5_f32_does_not_chase_rounding():
    # The error estimate must come from the smooth stage 7, not the float32-rounded state: on a
    # stiff chain rounding noise times ω² once made the controller take ~75× the f64 steps.
    evals, err = {}, {}
    for prec in ("f64", "f32"):
        s0 = pc.scenes.spring_chain(n=16, stiffness=1e4, integrator="dopri5", dt=0.01, threads=1)
        s = pc.Scene(2, integrator="dopri5", dt=0.01, rtol=1e-7, atol=1e-10, precision=prec, threads=1)
        s.add_particles(s0.positions, masses=s0.masses, pinned=s0.pinned)
        for t in s0.terms:
            s.add(t)
        s.step(20)
        evals[prec], err[prec] = s.force_evaluations, abs(s.energy_drift())
    # One extra evaluation per step in f32 (the derivative at the rounded state): 7/6.
    assert evals["f32"] < 1.5 * evals["f64"], evals
    assert err["f32"] < 1e-4, err


def test_f32_rejects_values_beyond_float32():
    s = pc.Scene(2, precision="f32")
    with pytest.raises(ValueError, match="positions.*float32"):
        s.add_particles([[1e39, 0.0]])
    assert s.n_particles == 0
    s.add_particles([[1.0, 0.0]])
    with pytest.raises(ValueError, match="velocities.*float32"):
        s.velocities = [[0.0, -1e40]]
    assert s.velocities[0, 1] == 0.0
    pc.Scene(2).add_particles([[1e39, 0.0]])  # fine in float64
