"""Scene.state() / Scene.set_state(): the state protocol (issue 62).

A snapshot put back replays the run after it bit for bit, for every kind of state the scenes
hold: particles, cloth springs, a grid, rigid bodies, a DFSPH fluid (warm starts), contacts with
spins, an adaptive integrator's controller, a flow."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc
from physcore import scenes

# (scene, its arguments, steps before the snapshot, steps after): small and quick.
CASES = {
    "kepler": ({}, 5, 40),
    "cloth": ({}, 3, 30),
    "turing": ({"start": 0.0}, 2, 10),  # from the seeds (the default returns it stepped to t = 1000)
    "tumbling_boxes": ({}, 30, 30),
    "dam_break": ({"n": 12}, 3, 8),
    "galton_board": ({}, 20, 40),
    "lorenz": ({}, 3, 20),
}


def _observed(scene: pc.Scene) -> list[np.ndarray]:
    """What the run shows: positions, velocities, every grid field, every body's pose."""
    out = [scene.positions, scene.velocities, np.array([scene.time, scene.dt])]
    for g in scene.grids:
        out += [np.asarray(getattr(g, f)) for f in ("u", "v") if hasattr(g, f)]
    for b in scene.bodies:
        out += [np.asarray(b.positions), np.asarray(b.velocities)]
    for f in scene.flows:
        out.append(np.asarray(f.points))
    return out


@pytest.mark.parametrize("name", sorted(CASES))
def test_state_round_trip_is_bit_identical(name: str) -> None:
    kwargs, before, after = CASES[name]
    scene = scenes.REGISTRY[name](**kwargs)
    scene.step(before)
    snap = scene.state()
    scene.step(after)
    first = _observed(scene)
    e_first = scene.energy_drift()
    scene.step(7)  # somewhere else, so that set_state has something to undo
    scene.set_state(snap)
    assert scene.step_count == before and scene.time == snap["time"]
    scene.step(after)
    second = _observed(scene)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        assert a.tobytes() == b.tobytes()
    assert scene.energy_drift() == e_first or (np.isnan(e_first) and np.isnan(scene.energy_drift()))
    # The run moved: the check above compares two different states, not one state twice.
    fresh = _observed(scenes.REGISTRY[name](**kwargs))
    assert any(a.tobytes() != b.tobytes() for a, b in zip(first, fresh, strict=True))


def test_state_before_the_first_step_drops_the_integrator_cache() -> None:
    scene = scenes.REGISTRY["kepler"]()
    snap = scene.state()
    assert snap["cache_forces"] is None and snap["reference_energy"] is None
    scene.step(50)
    x50 = scene.positions
    scene.step(5)
    scene.set_state(snap)
    assert scene.state()["reference_energy"] is None
    scene.step(50)
    assert scene.positions.tobytes() == x50.tobytes()


def test_state_holds_copies_and_documented_keys() -> None:
    scene = scenes.REGISTRY["galton_board"]()
    scene.step(10)
    snap = scene.state()
    for key in ("time", "step", "dt", "positions", "velocities", "ledger", "collisions", "cache_forces",
                "cache_power", "reference_energy"):
        assert key in snap
    assert snap["positions"].dtype == np.float64 and snap["positions"].shape == (scene.n_particles, scene.dim)
    assert any(k.startswith("term") and k.endswith("_history") for k in snap)  # contacts: spins, springs
    x = snap["positions"].copy()
    scene.step(5)
    assert np.array_equal(snap["positions"], x)


def _bad(scene: pc.Scene, snap: dict, key: str, value: object, exc: type[Exception]) -> None:
    before = scene.state()
    bad = {**snap, key: value}
    with pytest.raises(exc, match=rf"state\[{key!r}\]"):
        scene.set_state(bad)
    after = scene.state()
    for k in before:
        if isinstance(before[k], np.ndarray):
            assert np.array_equal(before[k], after[k]), k
        else:
            assert before[k] == after[k], k


def test_set_state_refuses_bad_input_naming_the_key_before_changing_anything() -> None:
    scene = scenes.REGISTRY["cloth"]()
    scene.step(2)
    snap = scene.state()
    scene.step(3)
    x = snap["positions"]
    _bad(scene, snap, "positions", x[:-1], pc.InvalidInputError)
    _bad(scene, snap, "positions", x.astype(np.float32), TypeError)
    nan = x.copy()
    nan[3, 0] = np.nan
    _bad(scene, snap, "positions", nan, ValueError)
    _bad(scene, snap, "step", -1, ValueError)
    _bad(scene, snap, "step", 1.5, TypeError)
    _bad(scene, snap, "time", float("inf"), ValueError)
    # What Scene.load would refuse is refused here too: a state set must save and load again.
    _bad(scene, snap, "time", -1.0, pc.InvalidInputError)
    _bad(scene, snap, "reference_energy", np.array([1.0, -2.0]), pc.InvalidInputError)
    _bad(scene, snap, "dt", 0.0, ValueError)
    _bad(scene, snap, "ledger", np.zeros(len(snap["ledger"]) + 1), pc.PhyscoreError)
    _bad(scene, snap, "not_a_key", 1.0, pc.InvalidInputError)
    with pytest.raises(pc.InvalidInputError, match="missing key 'velocities'"):
        scene.set_state({k: v for k, v in snap.items() if k != "velocities"})
    with pytest.raises(TypeError, match="state: expected a dict"):
        scene.set_state([1, 2])  # type: ignore[arg-type]


def test_set_state_puts_the_scene_back_when_the_core_refuses_a_part() -> None:
    scene = scenes.REGISTRY["turing"]()
    scene.step(1)
    snap = scene.state()
    key = next(k for k in snap if k.startswith("grid0_"))
    scene.step(2)
    before = scene.state()
    with pytest.raises(pc.PhyscoreError):
        scene.set_state({**snap, key: snap[key][:-1]})
    after = scene.state()
    for k in before:
        if isinstance(before[k], np.ndarray):
            assert before[k].tobytes() == after[k].tobytes(), k
