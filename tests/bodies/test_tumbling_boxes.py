"""The ready-made scene tumbling_boxes (rapier bodies down a zig-zag of ramps): what it is made of,
that it keeps tumbling to the end of its default GIF, that its energy books close with the
contacts taking energy out, and that bad arguments are refused by name."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc

G = 9.81


def _moving(scene: pc.Scene) -> list[pc.Bodies]:
    return [g for g in scene.bodies if g.kind == "dynamic"]


def test_the_scene_is_boxes_on_fixed_ramps():
    s = pc.scenes.tumbling_boxes()
    ramps, *bodies = s.bodies
    assert ramps.kind == "fixed" and ramps.shape == "box"
    boxes = s.bodies[1]
    assert boxes.name == "boxes" and boxes.shape == "box"
    assert sum(len(g) for g in bodies) == 16
    assert len(boxes) > sum(len(g) for g in bodies) / 2  # mostly boxes, a few capsules and hexagons
    assert not s.n_particles


def test_it_keeps_tumbling_to_the_end_of_its_gif_and_stays_finite():
    s = pc.scenes.tumbling_boxes()
    d = pc.scenes.tumbling_boxes.render_defaults
    end = d["frames"] * d["frame_time"]
    x0 = np.concatenate([g.positions for g in _moving(s)])
    s.step(round(0.9 * end / s.dt))
    late = np.concatenate([g.positions for g in _moving(s)])
    s.step(round(0.1 * end / s.dt))
    x1 = np.concatenate([g.positions for g in _moving(s)])
    v = np.concatenate([np.linalg.norm(g.velocities, axis=1) for g in _moving(s)])
    assert np.isfinite(x1).all() and np.isfinite(v).all()
    # In the GIF's last tenth some bodies still travel a good part of a metre...
    assert np.linalg.norm(x1 - late, axis=1).max() > 0.2
    assert (v > 0.2).sum() >= 2
    # ...and the cascade came down: every body fell, none left the walls.
    assert (x1[:, 1] < x0[:, 1]).all()
    ramps = s.bodies[0].positions
    assert (x1[:, 0] > ramps[:, 0].min()).all() and (x1[:, 0] < ramps[:, 0].max()).all()


def test_energy_books_close_and_the_contacts_take_energy_out():
    s = pc.scenes.tumbling_boxes()
    e0 = s.energy()
    m = np.concatenate([g.masses for g in _moving(s)])
    y0 = np.concatenate([g.positions[:, 1] for g in _moving(s)])
    taken = [0.0]
    for _ in range(8):
        s.step(120)  # 0.5 s
        e = s.energy()
        assert e.total == pytest.approx(e0.total, rel=1e-9)
        taken.append(e.dissipated["bodies: contacts and joints"])
    assert taken[-1] > 0 and min(np.diff(taken)) > -1e-6 * taken[-1]  # passive contacts only take energy out
    # The gravity book is m g y of the bodies (fixed ramps have no mass).
    y = np.concatenate([g.positions[:, 1] for g in _moving(s)])
    drop = float(m @ (y0 - y)) * G
    assert e0.potential["bodies: gravity"] - e.potential["bodies: gravity"] == pytest.approx(drop, rel=1e-9)
    # What the contacts took is the fall's m g Δy plus the kinetic energy lost (they start spinning).
    assert taken[-1] == pytest.approx(drop + e0.kinetic - e.kinetic, rel=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"n": 0}, "n"),
        ({"n": 2**40}, "n"),
        ({"ramps": 0}, "ramps"),
        ({"slope": 0.0}, "slope"),
        ({"slope": 1.5}, "slope"),
        ({"box": -0.1}, "box"),
        ({"box": 1.0}, "box"),
        ({"friction": -1.0}, "friction"),
        ({"restitution": 1.5}, "restitution"),
        ({"density": 0.0}, "density"),
        ({"box": 0.0}, "box"),
        ({"dt": 0.0}, "dt"),
        ({"seed": -1}, "seed"),
    ],
)
def test_bad_arguments_are_refused_by_name(kwargs, arg):
    with pytest.raises(pc.InvalidInputError, match=arg):
        pc.scenes.tumbling_boxes(**kwargs)


@pytest.mark.parametrize(("kwargs", "arg"), [({"n": 2.5}, "n"), ({"slope": "steep"}, "slope"), ({"seed": None}, "seed")])
def test_wrong_types_are_refused_by_name(kwargs, arg):
    with pytest.raises(TypeError, match=arg):
        pc.scenes.tumbling_boxes(**kwargs)


def test_the_shape_matched_version_is_kept_under_its_own_name():
    s = pc.scenes.shape_matched_boxes(n_boxes=2)
    assert s.n_particles == 2 * 16 and not s.bodies
    assert pc.scenes.REGISTRY["shape_matched_boxes"] is pc.scenes.shape_matched_boxes
