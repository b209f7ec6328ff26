"""Optional per-particle attributes (charge, radius): set, read, kept across add_particles, saved."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc


def _scene(n=4):
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles(np.arange(2 * n, dtype=float).reshape(n, 2), masses=np.ones(n))
    return s


def test_known_attributes_and_units():
    assert dict(pc._core.particle_attributes()) == {"charge": "C", "radius": "m"}


def test_a_scene_has_no_attribute_until_one_is_set():
    s = _scene()
    assert s.attributes == {}
    s.set_attribute("radius", [0.1, 0.2, 0.3, 0.4])
    assert list(s.attributes) == ["radius"]
    got = s.attributes["radius"]
    got[0] = 99.0  # a copy: the scene keeps its own
    assert np.array_equal(s.attributes["radius"], [0.1, 0.2, 0.3, 0.4])


def test_particles_added_later_hold_zero():
    s = _scene(2)
    s.set_attribute("charge", [1.0, -2.0])
    s.add_particles([[9.0, 9.0]], masses=[1.0])
    assert np.array_equal(s.attributes["charge"], [1.0, -2.0, 0.0])


@pytest.mark.parametrize(
    "name, values, exc, starts",
    [
        ("mass", [1.0] * 4, pc.InvalidInputError, "name: unknown attribute"),
        ("charge", [1.0] * 3, pc.InvalidInputError, "charge: has 3 entries, the scene has 4 particles"),
        ("charge", [1.0, np.inf, 0.0, 0.0], pc.InvalidInputError, "charge: entry 1 is inf"),
        ("radius", [1.0, 0.0, -0.5, 0.0], pc.InvalidInputError, "radius: entry 2 is -0.5 (must be finite and >= 0)"),
        ("radius", [[1.0] * 4], pc.InvalidInputError, "radius: expected shape (4,)"),
        ("charge", [True] * 4, TypeError, "charge: expected real numbers"),
        (None, [1.0] * 4, TypeError, "name: expected a str"),
    ],
)
def test_bad_attributes_are_refused_by_name_before_anything_changes(name, values, exc, starts):
    s = _scene()
    s.set_attribute("charge", [0.5] * 4)
    with pytest.raises(exc) as info:
        s.set_attribute(name, values)
    assert str(info.value).startswith(starts), str(info.value)
    assert list(s.attributes) == ["charge"] and np.array_equal(s.attributes["charge"], [0.5] * 4)


def test_attributes_survive_save_and_load(tmp_path):
    s = _scene()
    s.set_attribute("charge", [1e-3, -1e-3, 0.0, 2e-3])
    s.set_attribute("radius", [0.1, 0.1, 0.2, 0.2])
    back = pc.Scene.load(s.save(tmp_path / "a.npz"))
    assert back.attributes.keys() == s.attributes.keys()
    for k in s.attributes:
        assert np.array_equal(back.attributes[k], s.attributes[k])
    assert pc.Scene.load(_scene().save(tmp_path / "none.npz")).attributes == {}
