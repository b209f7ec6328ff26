"""The bodies' solver state in a scene file (issue 64 item 9): rapier's whole state (islands,
broad and narrow phase, bodies, colliders, joints) travels as bincode bytes in `body{k}_state`,
sealed with a digest. A hostile run found that one flipped bit in it loaded, then aborted the
process on the next step (a 103 GB allocation) or made every call panic (159 of 5,999 single
flips), and that another scene's state with as many bodies loaded silently, the groups then
reading the other scene's bodies. Each is now refused by `Scene.load`, before anything steps.
"""
from __future__ import annotations

import io

import numpy as np
import pytest

import physcore as pc


def _scene(size: float = 0.1) -> pc.Scene:
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-3)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Bodies("box", size=[(1.0, 0.1)], positions=[(0.0, -0.1)], kind="fixed"))
    s.add(pc.Bodies("ball", size=[size] * 3, positions=[(-0.3, 0.2), (0.0, 0.3), (0.3, 0.4)], restitution=0.5))
    s.step(200)  # the balls land: contacts in the narrow phase
    return s


def _arrays(path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def _write(path, arrays: dict[str, np.ndarray]) -> None:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())


def _state_bytes(a: dict[str, np.ndarray]) -> bytearray:
    """The bytes packed six to a float in body0_state (the core's `pack`)."""
    out = bytearray()
    for w in a["body0_state"].ravel():
        out += int(w).to_bytes(8, "little")[:6]
    return out[: int(a["body0_state_bytes"].ravel()[0])]


def _with_state(a: dict[str, np.ndarray], b: bytes) -> dict[str, np.ndarray]:
    a = dict(a)
    packed = [float(int.from_bytes(b[i:i + 6] + b"\0\0", "little")) for i in range(0, len(b), 6)]
    a["body0_state"] = np.array(packed, dtype=a["body0_state"].dtype).reshape(-1)
    return a


def test_a_saved_body_scene_loads_and_steps_on_the_same_bits(tmp_path):
    s = _scene()
    s.save(tmp_path / "s.npz")
    r = pc.Scene.load(tmp_path / "s.npz")
    s.step(100)
    r.step(100)
    assert np.array_equal(s.bodies[1].positions, r.bodies[1].positions)
    assert s.energy().total == r.energy().total


def test_every_flipped_bit_of_the_tag_and_digest_and_a_sample_of_the_state_is_refused(tmp_path):
    s = _scene()
    s.save(tmp_path / "s.npz")
    a = _arrays(tmp_path / "s.npz")
    b = _state_bytes(a)
    assert b[:8] == b"pcbody01"
    rng = np.random.default_rng(7)
    bits = list(range(128)) + sorted(rng.choice(np.arange(128, 8 * len(b)), 64, replace=False).tolist())
    for bit in bits:
        flipped = bytearray(b)
        flipped[bit // 8] ^= 1 << (bit % 8)
        _write(tmp_path / "f.npz", _with_state(a, bytes(flipped)))
        with pytest.raises(pc.SceneFileError, match="state"):
            pc.Scene.load(tmp_path / "f.npz")
    # Unchanged, the repacked bytes load (the test's packing is the core's).
    _write(tmp_path / "f.npz", _with_state(a, bytes(b)))
    pc.Scene.load(tmp_path / "f.npz").step(10)


def test_another_scenes_state_with_as_many_bodies_is_refused(tmp_path):
    _scene(0.1).save(tmp_path / "a.npz")
    _scene(0.05).save(tmp_path / "b.npz")  # the same bodies and handles, smaller balls
    a, b = _arrays(tmp_path / "a.npz"), _arrays(tmp_path / "b.npz")
    a["body0_state"], a["body0_state_bytes"] = b["body0_state"], b["body0_state_bytes"]
    _write(tmp_path / "mixed.npz", a)
    with pytest.raises(pc.SceneFileError, match="other bodies than the scene's"):
        pc.Scene.load(tmp_path / "mixed.npz")


def _fnv1a(b: bytes) -> int:
    """The seal's digest (the core's `fnv1a`): FNV-1a, 64 bit."""
    h = 0xCBF29CE484222325
    for x in b:
        h = ((h ^ x) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def test_a_crafted_state_that_passes_the_digest_is_refused_or_fails_cleanly(tmp_path):
    """A file crafted to pass the seal (a bit of rapier's state flipped and the digest computed
    again) is checked before anything steps: the load's checks refuse most, a trial step on a copy
    refuses those rapier's step trips over, and one that trips it later raises
    SimulationDiverged(quantity="solver") with the scene rolled back, never a PanicException
    (before: 11 of these 300 loaded and then made every step raise one)."""
    import random

    s = _scene()
    s.save(tmp_path / "s.npz")
    a = _arrays(tmp_path / "s.npz")
    b = _state_bytes(a)
    body = b[16:]
    rng = random.Random(7)
    outcomes = {"refused": 0, "trial": 0, "solver": 0, "fine": 0}
    for _ in range(300):
        bit = rng.randrange(8 * len(body))
        crafted = bytearray(body)
        crafted[bit // 8] ^= 1 << (bit % 8)
        sealed = bytes(b[:8]) + _fnv1a(crafted).to_bytes(8, "little") + bytes(crafted)
        _write(tmp_path / "c.npz", _with_state(a, sealed))
        try:
            r = pc.Scene.load(tmp_path / "c.npz")
        except pc.SceneFileError as e:
            outcomes["trial" if "inconsistent" in str(e) else "refused"] += 1
            continue
        failure = None
        for _ in range(20):
            before, count = r.bodies[1].positions.copy(), r.step_count
            try:
                r.step(1)
            except pc.SimulationDiverged as e:
                failure = e
                break
        if failure is None:
            outcomes["fine"] += 1
            continue
        assert failure.quantity == "solver", str(failure)
        assert r.step_count == count and np.array_equal(r.bodies[1].positions, before)  # rolled back
        outcomes["solver"] += 1
    # Every path taken (when written: 112 refused by the checks, 12 by the trial steps, 3 caught
    # at a later step, 173 stepping on).
    assert min(outcomes.values()) > 0, outcomes
