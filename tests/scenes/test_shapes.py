"""physcore.shapes, the geometry builders for one's own scenes: lattices and their counts, tank
walls, blobs, Plummer spheres, cloth springs and mesh hinges. Counts and spacings against their
formulas, the blob's symmetry, bad input refused naming the argument (a PhyscoreError), and the
old import paths (physcore.fluids, physcore.scenes) giving the same objects. Also the layout of
the scenes package built on them: a family module imports only _common and physcore's modules."""
from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

import physcore as pc
from physcore import shapes
from physcore.render import Mesh


# --------------------------------------------------------------------------- lattice, tank_walls
@pytest.mark.parametrize("lower, upper, spacing, counts", [
    ([0.0, 0.0], [1.0, 0.5], 0.1, [10, 5]),
    ([-1.0, 2.0, 0.0], [1.0, 3.0, 0.25], 0.25, [8, 4, 1]),
    ([0.0, 0.0], [0.3, 0.04], 0.1, [3, 1]),  # a side shorter than a cell still gets one
])
def test_lattice_counts_and_spacing(lower, upper, spacing, counts):
    assert shapes.lattice_counts(lower, upper, spacing) == counts
    pts = shapes.lattice(lower, upper, spacing)
    assert pts.shape == (math.prod(counts), len(lower)) and pts.dtype == np.float64 and pts.flags.c_contiguous
    lo = np.asarray(lower)
    # Cell centres lower + (i + ½) spacing, the first axis fastest.
    idx = np.rint((pts - lo) / spacing - 0.5).astype(int)
    np.testing.assert_allclose(pts, lo + (idx + 0.5) * spacing, rtol=0, atol=1e-12)
    assert idx[:, 0].tolist()[: counts[0]] == list(range(counts[0]))
    assert {tuple(r) for r in idx.tolist()} == set(np.ndindex(*counts))
    # Nearest neighbours are one spacing apart.
    if len(pts) > 1:
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        np.fill_diagonal(d, np.inf)
        np.testing.assert_allclose(d.min(axis=1), spacing, rtol=1e-12)


@pytest.mark.parametrize("top", [False, True])
def test_tank_walls_line_the_box_on_the_same_lattice(top):
    lo, hi, s, layers = np.array([0.0, 0.0]), np.array([1.0, 0.6]), 0.1, 3
    walls = shapes.tank_walls(lo, hi, s, layers, top=top)
    assert walls.dtype == np.float64 and walls.shape[1] == 2
    # None inside; all within `layers` cells of the box (none above the rim of an open tank).
    assert not np.all((walls > lo) & (walls < hi), axis=1).any()
    assert (walls >= lo - layers * s).all() and (walls[:, 0] <= hi[0] + layers * s).all()
    assert walls[:, 1].max() == pytest.approx(hi[1] + (layers - 0.5) * s if top else hi[1] - 0.5 * s)
    # The outer lattice (16 × 9 cells open, 16 × 12 closed) less the 10 × 6 inside.
    assert len(walls) == (16 * 12 if top else 16 * 9) - 10 * 6
    # The fluid's lattice continues into the walls: every coordinate is (k + ½) s.
    k = walls / s - 0.5
    np.testing.assert_allclose(k, np.rint(k), atol=1e-9)


# --------------------------------------------------------------------------- blob
def test_blob_is_the_old_scene_helper_bit_for_bit():
    # What the droplets and crown scenes computed before the blob was public (_ball).
    for centre, radius, dx in (([0.0125, 0.0205], 0.003, 0.00025), ([0.5, 0.25, 0.75], 0.2, 0.05)):
        c = np.asarray(centre, dtype=np.float64)
        pts = shapes.lattice(c - radius, c + radius, dx)
        old = pts[np.linalg.norm(pts - c, axis=1) <= radius]
        new = shapes.blob(centre, radius, dx)
        assert new.dtype == old.dtype and new.shape == old.shape and new.tobytes() == old.tobytes()


@pytest.mark.parametrize("centre", [[0.0, 0.0], [0.35, -0.15], [0.05, 0.05, 0.05]])
def test_blob_is_round_and_symmetric(centre):
    radius, s = 0.3, 0.1
    pts = shapes.blob(centre, radius, s)
    c = np.asarray(centre)
    dim = len(centre)
    assert pts.shape[1] == dim and pts.dtype == np.float64
    r = np.linalg.norm(pts - c, axis=1)
    assert (r <= radius).all()
    # Every lattice point of the box that is within the radius is there: none left out.
    box = shapes.lattice(c - radius, c + radius, s)
    assert len(pts) == int((np.linalg.norm(box - c, axis=1) <= radius).sum())
    # Symmetric about the centre (reflected through it, the set is itself) and about each axis.
    rel = np.round((pts - c) / s, 9)
    as_set = {tuple(p) for p in rel.tolist()}
    assert {tuple(p) for p in (-rel).tolist()} == as_set
    for axis in range(dim):
        flipped = rel.copy()
        flipped[:, axis] *= -1
        assert {tuple(p) for p in flipped.tolist()} == as_set
    np.testing.assert_allclose(pts.mean(axis=0), c, atol=1e-12)
    # About the area or volume of the disc or ball, in lattice cells.
    cells = math.pi * radius**2 / s**2 if dim == 2 else 4 / 3 * math.pi * radius**3 / s**3
    assert abs(len(pts) - cells) < 0.3 * cells


def test_blob_smaller_than_half_a_spacing_is_empty():
    pts = shapes.blob([0.0, 0.0, 0.0], 0.01, 0.1)
    assert pts.shape == (0, 3)


# --------------------------------------------------------------------------- Plummer spheres
def test_plummer_sphere_shapes_frame_and_seed():
    x, v = shapes.plummer_sphere(500, seed=3)
    assert x.shape == v.shape == (500, 3) and x.dtype == v.dtype == np.float64
    np.testing.assert_allclose(x.mean(axis=0), 0.0, atol=1e-12)  # centre-of-mass frame
    np.testing.assert_allclose(v.mean(axis=0), 0.0, atol=1e-12)
    x2, v2 = shapes.plummer_sphere(500, seed=3)
    assert x.tobytes() == x2.tobytes() and v.tobytes() == v2.tobytes()
    # The half-mass radius is about 1.305 a (a = 2 here); velocities scale as √(G M / a).
    xa, va = shapes.plummer_sphere(4000, a=2.0, mass=4.0, seed=1)
    assert np.median(np.linalg.norm(xa, axis=1)) == pytest.approx(1.305 * 2.0, rel=0.1)
    x1, v1 = shapes.plummer_sphere(4000, a=2.0, mass=1.0, seed=1)
    np.testing.assert_allclose(va, 2.0 * v1, rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- meshes
@pytest.mark.parametrize("n", [2, 3, 7])
def test_cloth_springs_counts_and_lengths(n):
    i, j = shapes.cloth_springs(n)
    assert i.dtype == j.dtype == np.int64 and i.shape == j.shape == (6 * n * n - 10 * n + 2,)
    pairs = {(min(a, b), max(a, b)) for a, b in zip(i.tolist(), j.tolist(), strict=True)}
    assert len(pairs) == len(i)  # each spring once
    # On the grid (index row·n + col): structural 1, shear √2, bend 2 cells long.
    ri, ci, rj, cj = i // n, i % n, j // n, j % n
    length = np.hypot(ri - rj, ci - cj)
    counts = {round(float(L), 6): int((length == L).sum()) for L in np.unique(length)}
    expected = {1.0: 2 * n * (n - 1), round(math.sqrt(2), 6): 2 * (n - 1) ** 2}
    if n > 2:
        expected[2.0] = 2 * n * (n - 2)
    assert counts == expected


def test_cloth_springs_of_tiny_grids_are_empty():
    for n in (0, 1):
        i, j = shapes.cloth_springs(n)
        assert i.shape == j.shape == (0,) and i.dtype == np.int64


@pytest.mark.parametrize("m", [2, 3, 5])
def test_mesh_edges_and_hinges_of_a_grid(m):
    faces = Mesh.grid(m, m).faces
    edges, hinges = shapes.mesh_edges_and_hinges(faces)
    assert edges.dtype == hinges.dtype == np.int64 and edges.shape[1] == 2 and hinges.shape[1] == 4
    # Rows and columns of the grid plus one diagonal a cell, each once, sorted.
    assert len(edges) == 2 * m * (m - 1) + (m - 1) ** 2
    assert (edges[:, 0] < edges[:, 1]).all() and len({tuple(e) for e in edges.tolist()}) == len(edges)
    assert edges.tolist() == sorted(edges.tolist())
    # A hinge for every edge but the 4(m − 1) on the border; its wings are the triangles' third corners.
    assert len(hinges) == len(edges) - 4 * (m - 1)
    tris = {frozenset(f) for f in faces.tolist()}
    for a, b, c, d in hinges.tolist():
        assert frozenset((a, b, c)) in tris and frozenset((a, b, d)) in tris and c != d


def test_mesh_edges_and_hinges_of_two_triangles():
    edges, hinges = shapes.mesh_edges_and_hinges([[0, 1, 2], [1, 0, 3]])
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3]]
    assert hinges.tolist() == [[0, 1, 2, 3]]
    e0, h0 = shapes.mesh_edges_and_hinges(np.zeros((0, 3), dtype=np.int64))
    assert e0.shape == (0, 2) and h0.shape == (0, 4)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, arg", [
    (lambda: shapes.lattice([0.0, 0.0], [1.0, 1.0], 0.0), "spacing"),
    (lambda: shapes.lattice([0.0, 0.0], [1.0, 1.0], "0.1"), "spacing"),
    (lambda: shapes.lattice([0.0, 0.0], [1.0, 1.0], 1e-200), "spacing"),  # far beyond memory
    (lambda: shapes.lattice([0.0, 0.0], [-1.0, 1.0], 0.1), "upper"),
    (lambda: shapes.lattice(["a", "b"], [1.0, 1.0], 0.1), "lower"),
    (lambda: shapes.lattice_counts([0.0], [1.0], 0.1), "lower/upper"),
    (lambda: shapes.tank_walls([0.0, 0.0], [1.0, 1.0], 0.1, 0), "layers"),
    (lambda: shapes.tank_walls([0.0, 0.0], [1.0, 1.0], 0.1, top=1), "top"),
    (lambda: shapes.blob([0.0], 0.3, 0.1), "centre"),
    (lambda: shapes.blob([[0.0, 0.0]], 0.3, 0.1), "centre"),
    (lambda: shapes.blob([0.0, np.nan], 0.3, 0.1), "centre"),
    (lambda: shapes.blob(["x", "y"], 0.3, 0.1), "centre"),
    (lambda: shapes.blob([0.0, 0.0], 0.0, 0.1), "radius"),
    (lambda: shapes.blob([0.0, 0.0], -1.0, 0.1), "radius"),
    (lambda: shapes.blob([0.0, 0.0], math.inf, 0.1), "radius"),
    (lambda: shapes.blob([0.0, 0.0], None, 0.1), "radius"),
    (lambda: shapes.blob([1e308, 0.0], 1e308, 0.1), "radius"),
    (lambda: shapes.blob([0.0, 0.0], 0.3, 0.0), "spacing"),
    (lambda: shapes.blob([0.0, 0.0], 0.3, True), "spacing"),
    (lambda: shapes.plummer_sphere(0), "n"),
    (lambda: shapes.plummer_sphere(2.5), "n"),
    (lambda: shapes.plummer_sphere(10, cutoff=1.0), "cutoff"),
    (lambda: shapes.plummer_sphere(10, a=0.0), "a"),
    (lambda: shapes.plummer_sphere(10, mass=-1.0), "mass"),
    (lambda: shapes.plummer_sphere(10, G="1"), "G"),
    (lambda: shapes.cloth_springs(-1), "n"),
    (lambda: shapes.cloth_springs(3.0), "n"),
    (lambda: shapes.cloth_springs(10**9), "n"),  # beyond memory
    (lambda: shapes.mesh_edges_and_hinges([[0, 1]]), "faces"),
    (lambda: shapes.mesh_edges_and_hinges([[0, 1, -2]]), "faces"),
    (lambda: shapes.mesh_edges_and_hinges([["a", "b", "c"]]), "faces"),
    (lambda: shapes.mesh_edges_and_hinges([[0, 1, 2], [3, 4]]), "faces"),
])
def test_bad_input_is_refused_naming_the_argument(call, arg):
    with pytest.raises(pc.PhyscoreError) as info:
        call()
    assert isinstance(info.value, (ValueError, TypeError))
    assert str(info.value).startswith(f"{arg}:"), str(info.value)


# --------------------------------------------------------------------------- where they live
def test_old_import_paths_give_the_same_objects():
    from physcore.fluids import lattice, lattice_counts, tank_walls
    from physcore.scenes import cloth_springs, mesh_edges_and_hinges, plummer_sphere

    assert lattice is shapes.lattice and lattice_counts is shapes.lattice_counts and tank_walls is shapes.tank_walls
    assert cloth_springs is shapes.cloth_springs and mesh_edges_and_hinges is shapes.mesh_edges_and_hinges
    assert plummer_sphere is shapes.plummer_sphere
    assert pc.shapes is shapes and "shapes" in pc.__all__
    assert set(shapes.__all__) == {"lattice", "lattice_counts", "tank_walls", "sample_boundary", "blob", "plummer_sphere",
                                   "cloth_springs", "mesh_edges_and_hinges"}
    for name in shapes.__all__:
        fn = getattr(shapes, name)
        assert fn.__module__ == "physcore.shapes" and fn.__doc__ and "Raises" in fn.__doc__, name


def test_scene_functions_read_as_physcore_scenes():
    for name, fn in pc.scenes.REGISTRY.items():
        assert fn is getattr(pc.scenes, name) and fn.__module__ == "physcore.scenes" and fn.__name__ == name
    assert pc.scenes.galton_bins.__module__ == "physcore.scenes"


def test_scene_family_modules_import_only_common_and_physcore():
    """No import circle: a module of the scenes package imports its sibling _common and
    physcore's modules (``..name``), never the package itself or another family."""
    pkg = Path(pc.scenes.__file__).parent
    modules = sorted(p for p in pkg.glob("*.py") if p.name != "__init__.py")
    assert {p.stem for p in modules} >= {"_common", "cloth", "orbits", "fluids", "grids", "grains"}
    for path in modules:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level:
                where = "." * node.level + (node.module or "")
                assert node.level == 2 or where == "._common", f"{path.name}: from {where} import ..."
