"""Bad selections of bodies, joints and pins: refused by name before anything changes, and
what is accepted saves and loads again (the scene file's rules are the constructors')."""
from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

import physcore as pc


def _scene() -> tuple[pc.Scene, pc.Bodies]:
    s = pc.Scene(dim=2, dt=1 / 240, threads=1)
    g = s.add(pc.Bodies("box", size=[0.1, 0.1], positions=[[0, 0], [1, 0], [2, 0]]))
    s.add_particles([[0, 0.5], [1, 0.5], [2, 0.5]])
    return s, g


@pytest.mark.parametrize("key", [None, True, (Ellipsis, None), [[0, 1], [1, 2]], 2**63, np.uint64(2**64 - 1)])
def test_a_body_selection_is_one_body_or_a_list_of_them(key):
    """Keys that add an axis (None, a bool, a nested list) or overflow int64 are refused naming
    `key`: they made tables of bodies that Pins and Joints then failed on with numpy's errors."""
    _, g = _scene()
    with pytest.raises(pc.InvalidInputError, match="key: "):
        g[key]
    assert g[1].index.tolist() == [1] and g[[0, 2]].index.tolist() == [0, 2] and len(g[:]) == 3


def test_joints_of_no_bodies_are_refused_as_the_file_would_refuse_them():
    s, g = _scene()
    with pytest.raises(pc.InvalidInputError, match="^a: selects no bodies"):
        pc.Joints("revolute", g[5:], g[5:], np.zeros((0, 2)))
    parts = len(s.parts)
    s.add(pc.Joints("revolute", g[:1], g[1:2], np.zeros((1, 2))))
    assert len(pc.Scene.from_bytes(s.to_bytes()).parts) == parts + 1


def test_a_particle_is_pinned_by_one_pins_part_only():
    s, g = _scene()
    s.add(pc.Pins([0], g[0]))
    before = (len(s.parts), s.positions.copy())
    with pytest.raises(pc.InvalidInputError, match="particles: particle 0 is pinned already"):
        s.add(pc.Pins([2, 0], g[1]))
    assert len(s.parts) == before[0] and np.array_equal(s.positions, before[1])
    s.add(pc.Pins([2], g[1]))
    assert len(pc.Scene.from_bytes(s.to_bytes()).parts) == before[0] + 1


@pytest.mark.parametrize("particles, problem", [([99.0], "beyond the scene's 3 particles"), ([1.0, 1.0], "pinned once")])
def test_pins_read_from_a_file_are_checked_against_the_scene(particles, problem):
    """A file's pins pass the constructor's checks too: an index beyond the particles, or one
    pinned twice, is a SceneFileError naming the record (it was loaded and saved again)."""
    s, g = _scene()
    s.add(pc.Pins([0, 1][: len(particles)], g[0]))
    src = zipfile.ZipFile(io.BytesIO(s.to_bytes()))
    name = next(n for n in src.namelist() if n.endswith("_particles.npy"))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for n in src.namelist():
            data = src.read(n)
            if n == name:
                buf = io.BytesIO()
                np.save(buf, np.array(particles))
                data = buf.getvalue()
            z.writestr(n, data)
    with pytest.raises(pc.SceneFileError, match=f"record.particles: .*{problem}"):
        pc.Scene.from_bytes(out.getvalue())
