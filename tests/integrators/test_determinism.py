"""Bit-identical results: for any thread count, and across save/load restarts."""
from __future__ import annotations

import os

import numpy as np
import pytest
from conftest import INTEGRATOR_NAMES, random_cloud

import physcore as pc


def _assert_same_run(a: pc.Scene, b: pc.Scene) -> None:
    assert a.step_count == b.step_count
    assert a.time == b.time
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.velocities, b.velocities)
    ea, eb = a.energy(), b.energy()
    assert ea == eb  # every book entry equal, bit for bit
    assert np.array_equal(a.momentum(), b.momentum())
    assert np.array_equal(np.atleast_1d(a.angular_momentum()), np.atleast_1d(b.angular_momentum()))


# ----------------------------------------------------------------------------- thread count
@pytest.mark.parametrize("name", ["verlet", "rk4"])
def test_cloth_is_thread_count_independent(name):
    # 64×64 = 4096 particles and ~24k springs: large enough for the parallel code paths.
    runs = []
    for threads in (1, 2, 3):
        s = pc.scenes.cloth(n=64, threads=threads, integrator=name)
        assert s.threads == threads
        s.step(40)
        runs.append(s)
    assert runs[0].n_particles == 4096
    # The run did something: the free part of the cloth moved.
    assert np.abs(runs[0].velocities).max() > 0
    for other in runs[1:]:
        _assert_same_run(runs[0], other)


def _nbody(threads: int) -> pc.Scene:
    x, v, m = random_cloud(11, 150, dim=3, speed=0.1, box=2.0)
    s = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads)
    s.add_particles(x, v, masses=m / m.sum())
    s.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    return s


def test_nbody_cloud_is_thread_count_independent():
    a, b = _nbody(1), _nbody(2)
    x0 = a.positions
    a.step(60)
    b.step(60)
    assert not np.array_equal(a.positions, x0)
    _assert_same_run(a, b)


def test_collisions_are_thread_count_independent():
    # 6000 particles raining onto a tilted, rough floor: the collider's parallel path and its
    # dissipation sum must not depend on the thread count.
    rng = np.random.default_rng(5)
    n = 6000
    x = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(0.0, 0.05, n)])
    v = np.column_stack([rng.normal(size=n), rng.normal(size=n), rng.uniform(-3, -1, n)])
    m = rng.uniform(0.5, 1.5, n)
    runs = []
    for threads in (1, 2):
        s = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads)
        s.add_particles(x, v, masses=m)
        s.add(pc.Gravity([0.0, 0.0, -9.81]))
        s.add(pc.Drag(0.05))
        s.add(pc.Plane([0.0, 0.0, 0.0], [0.1, 0.0, 1.0], restitution=0.7, friction=0.3))
        s.step(30)
        runs.append(s)
    assert runs[0].energy().dissipated["collisions"] > 0
    _assert_same_run(runs[0], runs[1])


def test_default_thread_pool_matches_single_thread():
    a = pc.scenes.cloth(n=64, threads=1)
    b = pc.scenes.cloth(n=64, threads=None)
    a.step(10)
    b.step(10)
    _assert_same_run(a, b)


# ----------------------------------------------------------------------------- save / load
def _damped_chain(name: str) -> pc.Scene:
    # Velocity-dependent forces (dashpots, drag) make Verlet's cached force depend on the
    # half-step velocity: a restart that recomputed it would not be bit-identical.
    s = pc.scenes.spring_chain(n=12, damping=0.5, dim=3, integrator=name)
    s.add(pc.Drag(0.01))
    return s


@pytest.mark.parametrize("name", INTEGRATOR_NAMES)
def test_save_load_restart_is_bit_identical(tmp_path, name):
    k = 300
    a = _damped_chain(name)
    a.step(2 * k)

    b = _damped_chain(name)
    b.step(k)
    drift_b = b.energy_drift()
    path = b.save(tmp_path / "s.npz")
    assert path == tmp_path / "s.npz"
    c = pc.Scene.load(path)
    # The loaded scene is the saved one...
    assert c.integrator == name
    assert c.dt == b.dt
    assert c.energy_drift() == drift_b
    assert [t.name for t in c.terms] == [t.name for t in b.terms]
    _assert_same_run(b, c)
    # ...and continuing it reproduces the uninterrupted run bit for bit.
    c.step(k)
    _assert_same_run(a, c)
    assert c.energy_drift() == a.energy_drift()
    assert c.energy().dissipated["springs"] > 0


@pytest.mark.parametrize("name", INTEGRATOR_NAMES)
def test_save_load_restart_with_collider(tmp_path, name):
    # A cloth falling onto a floor: damping, friction and restitution, contacts before and after
    # the restart.
    def make():
        s = pc.scenes.cloth(n=10, ground=True, pin="corners", integrator=name)
        if name == "euler":
            s.dt = s.dt / 2  # explicit Euler is unstable at the scene's default step
        return s

    k = round(0.6 / make().dt)  # 0.6 s: the sheet reaches the floor (0.8 below) before the restart
    a = make()
    a.step(2 * k)
    b = make()
    b.step(k)
    assert b.energy().dissipated["collisions"] > 0, "the cloth should have reached the floor"
    b.save(tmp_path / "cloth.npz")
    c = pc.Scene.load(tmp_path / "cloth.npz", threads=2)
    assert c.threads == 2
    assert len(c.planes) == 1
    assert c.planes[0].restitution == b.planes[0].restitution
    c.step(k)
    _assert_same_run(a, c)
    assert c.energy().dissipated["collisions"] > b.energy().dissipated["collisions"]


def test_load_preserves_energy_drift_baseline(tmp_path):
    s = pc.scenes.kepler(e=0.7, integrator="semi_implicit_euler")
    s.step(700)  # past pericentre: a visible first-order energy error
    d = s.energy_drift()
    assert d != 0.0
    s.save(tmp_path / "k.npz")
    t = pc.Scene.load(tmp_path / "k.npz")
    assert t.energy_drift() == d
    assert t.step_count == s.step_count == 700
    assert t.time == s.time


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path, monkeypatch):
    s = pc.scenes.spring_chain(n=5)
    s.step(10)
    target = tmp_path / "s.npz"
    s.save(target)
    assert sorted(os.listdir(tmp_path)) == ["s.npz"]
    before = target.read_bytes()

    # A failure in the middle of writing must leave the previous file intact and no debris.
    s.step(10)

    def broken_savez(fh, **arrays):
        fh.write(b"partial garbage")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        s.save(target)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == ["s.npz"]
    assert target.read_bytes() == before
    assert pc.Scene.load(target).step_count == 10

    # A second successful save replaces it.
    s.save(target)
    assert sorted(os.listdir(tmp_path)) == ["s.npz"]
    assert pc.Scene.load(target).step_count == 20


def test_save_rejects_wrong_suffix(tmp_path):
    s = pc.scenes.spring_chain(n=3)
    with pytest.raises(ValueError, match="path"):
        s.save(tmp_path / "s.txt")
    assert os.listdir(tmp_path) == []
