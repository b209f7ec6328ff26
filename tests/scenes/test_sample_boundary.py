"""physcore.shapes.sample_boundary: SPH boundary particles on every collider record, 2D and 3D.

Where they sit (the forbidden side, layer k at (k − ½) spacing from the surface, as tank_walls
places its), how far apart (about a spacing), the box as tank_walls' closed tank bit for bit,
the plane clipped to its extent, determinism, and bad input refused naming the argument."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore.shapes import sample_boundary, tank_walls
from physcore.terms.oriented_box import _axes


def _nearest(x: np.ndarray) -> np.ndarray:
    """(M,) distance from each point to its nearest other point, m (brute force)."""
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def _beyond(shape, x: np.ndarray) -> np.ndarray:
    """(M,) signed distance, m, of each point past the surface into the forbidden side."""
    if isinstance(shape, pc.Plane):
        return -(x - shape.point) @ shape.normal
    if isinstance(shape, pc.Sphere):
        r = np.linalg.norm(x - shape.center, axis=1) - shape.radius
        return r if shape.inside else -r
    if isinstance(shape, pc.Capsule):
        ab = shape.b - shape.a
        t = np.clip((x - shape.a) @ ab / (ab @ ab), 0.0, 1.0) if ab @ ab > 0 else np.zeros(len(x))
        return shape.radius - np.linalg.norm(x - shape.a - t[:, None] * ab, axis=1)
    if isinstance(shape, pc.OrientedBox):
        q = (x - shape.center) @ _axes(shape.rotation).T
        return (shape.half_extents - np.abs(q)).min(axis=1)
    raise AssertionError(type(shape))


SHAPES = {
    "plane2": (pc.Plane([0.0, 0.1], [0.3, 1.0]), {"extent": ([-1.0, -1.0], [1.0, 1.0])}),
    "plane3": (pc.Plane([0.0, 0.0, 0.1], [0.2, -0.1, 1.0]), {"extent": ([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])}),
    "ball2": (pc.Sphere([0.1, 0.2], 0.5), {}),
    "bowl2": (pc.Sphere([0.1, 0.2], 0.5, inside=True), {}),
    "ball3": (pc.Sphere([0.1, 0.2, 0.3], 0.4), {}),
    "bowl3": (pc.Sphere([0.1, 0.2, 0.3], 0.4, inside=True), {}),
    "capsule2": (pc.Capsule([-0.3, 0.0], [0.4, 0.2], 0.3), {}),
    "capsule3": (pc.Capsule([-0.3, 0.0, 0.1], [0.4, 0.2, -0.1], 0.3), {}),
    "obox2": (pc.OrientedBox([0.2, -0.1], [0.5, 0.3], 0.4), {}),
    "obox3": (pc.OrientedBox([0.2, -0.1, 0.0], [0.5, 0.3, 0.4], [0.1, -0.3, 0.2]), {}),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_layers_sit_beyond_the_surface_about_a_spacing_apart(name):
    shape, kw = SHAPES[name]
    s, layers = 0.1, 3
    x = sample_boundary(shape, s, layers=layers, **kw)
    dim = len(np.atleast_1d(getattr(shape, "point", getattr(shape, "center", getattr(shape, "a", None)))))
    assert x.dtype == np.float64 and x.ndim == 2 and x.shape[1] == dim and x.flags.c_contiguous and len(x) > 10
    assert np.array_equal(x, sample_boundary(shape, s, layers=layers, **kw))  # deterministic
    depth = _beyond(shape, x)
    if isinstance(shape, pc.OrientedBox):
        # The box's own lattice, its cells 0.1 m ± rounding: within the layers, inside.
        assert depth.min() > 0.0 and depth.max() < layers * 0.11
    else:
        # Exactly (k − ½) s beyond the surface, every layer k = 1..3 present.
        k = depth / s + 0.5
        np.testing.assert_allclose(k, np.rint(k), atol=1e-9)
        assert set(np.rint(k).astype(int).tolist()) == {1, 2, 3}
    # About a spacing apart: none farther than 1.5 of it from its nearest (in its own layer or
    # the next), no two closer than 0.4 of it (where a capsule's rings meet its half-spheres,
    # and on an inner layer of 3 + 3 points: 0.50 s, the closest measured).
    d = _nearest(x)
    assert d.min() > 0.4 * s and d.max() < 1.5 * s, (d.min(), d.max())


@pytest.mark.parametrize(("lower", "upper", "layers"), [
    ([0.0, 0.0], [1.0, 0.6], 3),
    ([-0.2, 0.0, 0.1], [0.3, 0.4, 0.5], 2),
])
def test_a_box_is_tank_walls_closed_tank_bit_for_bit(lower, upper, layers):
    x = sample_boundary(pc.Box(lower, upper), 0.1, layers=layers)
    assert np.array_equal(x, tank_walls(lower, upper, 0.1, layers, top=True))


def test_a_box_of_fractional_sides_keeps_whole_cells_outside_it():
    lo, hi = np.array([0.0, 0.0]), np.array([1.03, 0.47])
    x = sample_boundary(pc.Box(lo, hi), 0.1, layers=2)
    assert not np.all((x > lo) & (x < hi), axis=1).any()
    # 10 × 5 cells of 0.103 × 0.094 m: the 14 × 9 outer lattice less the inside.
    assert len(x) == 14 * 9 - 10 * 5
    assert x[:, 0].min() == pytest.approx(-1.5 * 0.103) and x[:, 1].max() == pytest.approx(0.47 + 1.5 * 0.094)


def test_a_floor_plane_continues_the_tank_lattice():
    """A floor clipped to the tank's width gives the tank's floor rows (without the corners)."""
    floor = sample_boundary(pc.Plane([0.0, 0.0], [0.0, 1.0]), 0.1, layers=3, extent=([0.0, 0.0], [1.0, 0.6]))
    walls = tank_walls([0.0, 0.0], [1.0, 0.6], 0.1, 3)
    under = walls[(walls[:, 1] < 0) & (walls[:, 0] > 0) & (walls[:, 0] < 1.0)]
    assert sorted(map(tuple, floor.round(12).tolist())) == sorted(map(tuple, under.round(12).tolist()))


def test_a_tilted_plane_is_clipped_to_its_extent():
    lo, hi = np.array([-0.5, -0.5, -0.5]), np.array([0.5, 0.5, 0.5])
    plane = pc.Plane([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    x = sample_boundary(plane, 0.05, layers=2, extent=(lo, hi))
    on = x + ((x - plane.point) @ plane.normal)[:, None] * -plane.normal  # back onto the plane
    assert np.all((on >= lo - 1e-12) & (on <= hi + 1e-12))
    # The plane cuts the cube in a regular hexagon of side √2/2 m, area (3√3/2)(√2/2)² m²: one
    # point per spacing² of it in each layer.
    area = 1.5 * math.sqrt(3) * 0.5
    assert len(x) / 2 == pytest.approx(area / 0.05**2, rel=0.1)


def test_sphere_and_circle_counts_follow_the_surface():
    s = 0.05
    for k, r in enumerate((0.5 + 0.025, 0.5 + 0.075)):
        x = sample_boundary(pc.Sphere([0.0, 0.0, 0.0], 0.5, inside=True), s, layers=2)
        on = np.isclose(np.linalg.norm(x, axis=1), r)
        assert on.sum() == round(4 * math.pi * r * r / (s * s)), k
    ring = sample_boundary(pc.Sphere([0.0, 0.0], 0.5, inside=True), s)
    assert len(ring) == round(2 * math.pi * 0.525 / s)


def test_inward_layers_end_at_the_centre():
    """A ball 1.2 spacings across gets one ring and then its centre; a thin capsule its axis."""
    ball = sample_boundary(pc.Sphere([1.0, 2.0], 0.12), 0.1, layers=3)
    assert len(ball) == 5 and ball[-1].tolist() == [1.0, 2.0]
    rod = sample_boundary(pc.Capsule([0.0, 0.0, 0.0], [0.3, 0.0, 0.0], 0.04), 0.1, layers=3)
    np.testing.assert_allclose(rod, [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0], [0.3, 0.0, 0.0]], atol=1e-15)


def test_a_thin_oriented_box_is_filled():
    box = pc.OrientedBox([0.0, 0.0], [0.5, 0.1], math.pi / 6)
    x = sample_boundary(box, 0.1, layers=3)
    assert len(x) == 10 * 2  # every cell of the 10 × 2 lattice is within 3 of a face


@pytest.mark.parametrize(("shape", "kwargs", "exc", "arg"), [
    ("not a shape", {}, pc.InvalidTypeError, "shape"),
    (pc.Gravity([0.0, -9.81]), {}, pc.InvalidTypeError, "shape"),
    (pc.Sphere([0.0, 0.0], 1.0), {"spacing": 0.0}, pc.InvalidInputError, "spacing"),
    (pc.Sphere([0.0, 0.0], 1.0), {"spacing": float("nan")}, pc.InvalidInputError, "spacing"),
    (pc.Sphere([0.0, 0.0], 1.0), {"spacing": "fine"}, pc.InvalidTypeError, "spacing"),
    (pc.Sphere([0.0, 0.0], 1.0), {"layers": 0}, pc.InvalidInputError, "layers"),
    (pc.Sphere([0.0, 0.0], 1.0), {"layers": 2.0}, pc.InvalidTypeError, "layers"),
    (pc.Sphere([0.0, 0.0], 1.0), {"extent": ([0, 0], [1, 1])}, pc.InvalidInputError, "extent"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {}, pc.InvalidInputError, "extent"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": 3.0}, pc.InvalidTypeError, "extent"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": ([0, 0, 0], [1, 1, 1])}, pc.InvalidInputError, "extent"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": ([0, 0], [1, -1])}, pc.InvalidInputError, "extent"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": ([0, 1], [1, 2])}, pc.InvalidInputError, "extent"),
    # Too many for memory: refused naming spacing, before anything is allocated.
    (pc.Box([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), {"spacing": 1e-6}, pc.InvalidInputError, "spacing"),
    (pc.Sphere([0.0, 0.0, 0.0], 1e150), {}, pc.InvalidInputError, "spacing"),
    (pc.OrientedBox([0.0, 0.0], [1e300, 1.0]), {}, pc.InvalidInputError, "spacing"),
    (pc.Plane([0.0, 0.0], [0.0, 1.0]), {"extent": ([0, -1], [1e300, 1])}, pc.InvalidInputError, "spacing"),
    (pc.Box([0.0, 0.0], [1e308, 1.0]), {"spacing": 1e307, "layers": 1000}, pc.InvalidInputError, "spacing"),
])
def test_bad_input_is_refused_naming_the_argument(shape, kwargs, exc, arg):
    args = {"spacing": 0.1} | kwargs
    with pytest.raises(exc, match=rf"^{arg}:"):
        sample_boundary(shape, args.pop("spacing"), **args)
