"""Geometry builders for your own scenes: point lattices, tank walls, blobs, Plummer spheres and
the index arrays of meshes. Plain numpy in, plain numpy out (positions in m, float64; indices
int64); nothing here builds a :class:`~physcore.Scene`. The ready-made scenes
(:mod:`physcore.scenes`) are built from these.

lattice, lattice_counts   particle centres filling a box on a cubic lattice, and their count per axis
tank_walls                static wall particles lining a box (the boundary of an SPH tank)
sample_boundary           static SPH boundary particles on any collider's surface (plane, box, sphere, capsule, oriented box)
blob                      the lattice points within a radius of a centre: a disc (2D) or ball (3D)
plummer_sphere            positions and velocities of a Plummer star cluster in equilibrium
cloth_springs             structural, shear and bend springs of an n×n grid
mesh_edges_and_hinges     edges and bending hinges of a triangle mesh (for XpbdConstraints)

Every function raises, naming the argument, ``TypeError`` (:class:`~physcore.InvalidTypeError`)
for an argument of the wrong type and :class:`~physcore.InvalidInputError` (a ``ValueError``)
for a value out of range; both are :class:`~physcore.PhyscoreError`.

>>> import physcore as pc
>>> water = pc.shapes.lattice([0.0, 0.0], [0.4, 0.2], 0.1)  # 4 × 2 cells
>>> water.shape
(8, 2)
>>> water[:3].tolist()
[[0.05, 0.05], [0.15000000000000002, 0.05], [0.25, 0.05]]
>>> drop = pc.shapes.blob([0.0, 0.0], 0.25, 0.1)  # a disc 5 points across
>>> drop.shape, drop.mean(axis=0).round(12).tolist()
((21, 2), [0.0, 0.0])
>>> i, j = pc.shapes.cloth_springs(3)  # 12 structural, 8 shear, 6 bend
>>> len(i)
26
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from . import _check
from ._check import finite_float as _finite_float
from ._errors import InvalidInputError, InvalidTypeError

__all__ = ["lattice", "lattice_counts", "tank_walls", "sample_boundary", "blob", "plummer_sphere", "cloth_springs", "mesh_edges_and_hinges"]


# --------------------------------------------------------------------------- lattices and tanks
def _corner(value: object, arg: str) -> np.ndarray:
    a = _check.real_array(arg, value)
    return a.astype(np.float64)


def lattice_counts(lower: np.typing.ArrayLike, upper: np.typing.ArrayLike, spacing: float) -> list[int]:
    """Cells along each axis of :func:`lattice` (Python ints, never overflowing; the box sides
    are rounded to whole cells, at least one; -1 for an axis whose count overflows float64).

    Raises TypeError / InvalidInputError naming ``lower``, ``upper`` (two vectors of 2 or 3
    finite numbers, ``upper > lower``) or ``spacing`` (finite, > 0)."""
    lo, hi = _corner(lower, "lower"), _corner(upper, "upper")
    s = _finite_float(spacing, "spacing", minimum=0.0, strict=True)
    if lo.shape != hi.shape or lo.ndim != 1 or lo.shape[0] not in (2, 3):
        raise InvalidInputError(f"lower/upper: expected two vectors of length 2 or 3, got {lo.shape} and {hi.shape}")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise InvalidInputError("upper: must be finite and > lower on every axis")
    counts = []
    for d in range(lo.shape[0]):
        cells = (float(hi[d]) - float(lo[d])) / s  # Python floats: overflow gives inf, no warning
        counts.append(max(round(cells), 1) if math.isfinite(cells) else -1)
    return counts


def lattice(lower: np.typing.ArrayLike, upper: np.typing.ArrayLike, spacing: float) -> np.ndarray:
    """Particle centres filling the box ``[lower, upper]`` on a cubic lattice: positions
    ``lower + (i + ½) spacing`` for every cell of the box (the box sides are rounded to whole
    cells). Returns ``(N, dim)`` float64, m. Ordered with the first axis fastest.

    Raises TypeError / InvalidInputError naming the argument, and InvalidInputError naming
    ``spacing`` when the lattice would not fit in memory (:func:`physcore._check.memory_limit`)."""
    counts = lattice_counts(lower, upper, spacing)
    lo = _corner(lower, "lower")  # upper was checked by lattice_counts
    s = float(spacing)
    total = math.prod(counts) if min(counts) > 0 else math.inf
    # meshgrid, stack and the result: about three copies of (N, dim) float64.
    _check.memory("spacing", 3 * 8 * len(counts) * total, f"a lattice of {total} points")
    n = np.array(counts, dtype=np.int64)
    axes = [lo[d] + (np.arange(n[d]) + 0.5) * s for d in range(lo.shape[0])]
    grids = np.meshgrid(*axes[::-1], indexing="ij")[::-1]
    return np.ascontiguousarray(np.stack([g.ravel() for g in grids], axis=1))


def tank_walls(
    lower: np.typing.ArrayLike,
    upper: np.typing.ArrayLike,
    spacing: float,
    layers: int = 3,
    *,
    top: bool = False,
) -> np.ndarray:
    """Static wall particles lining the inside box ``[lower, upper]`` (an open tank unless
    ``top``): ``layers`` lattice layers outside each face, on the same lattice as
    :func:`lattice` (so a fluid filled with :func:`lattice` continues into the wall). Use at
    least ``⌈2h/spacing⌉`` layers for full kernel support (3 for h = 1.3 spacing).

    Returns ``(M, dim)`` float64, m.

    Raises TypeError / InvalidInputError naming the argument as :func:`lattice` does, ``layers``
    (an int in 1..1000), ``top`` (True or False), or ``spacing`` when the layers reach beyond
    float64's range."""
    lattice_counts(lower, upper, spacing)  # checks lower, upper and spacing, naming them
    lo, hi = _corner(lower, "lower"), _corner(upper, "upper")
    s = _finite_float(spacing, "spacing", minimum=0.0, strict=True)
    layers = _check.int_in_range("layers", layers, 1, 1000)
    top = _check.flag("top", top)
    pad = layers * s
    if not (math.isfinite(pad) and np.isfinite(lo - pad).all() and np.isfinite(hi + pad).all()):
        raise InvalidInputError(f"spacing: {layers} layers of {s} m reach beyond float64's range")
    outer_hi = hi.copy() + pad
    if not top:
        outer_hi[-1] = hi[-1]  # open top: walls only up to the rim
    pts = lattice(lo - pad, outer_hi, s)
    inside = np.all((pts > lo) & (pts < hi), axis=1)
    return np.ascontiguousarray(pts[~inside])


def blob(centre: np.typing.ArrayLike, radius: float, spacing: float) -> np.ndarray:
    """The points of a cubic lattice of ``spacing`` (m) within ``radius`` (m) of ``centre``: a
    disc in 2D, a ball in 3D (the dimension is ``len(centre)``).

    The lattice is :func:`lattice` over the box ``centre ± radius``: points at
    ``centre − radius + (i + ½) spacing``, so a ``centre`` on a tank's lattice (at
    ``(k + ½) spacing``, as :func:`tank_walls` and :func:`lattice` place theirs) with ``radius``
    a whole number of spacings gives a blob on that same lattice. Returns ``(N, dim)`` float64,
    m, first axis fastest, symmetric about ``centre`` (up to rounding); empty (``(0, dim)``)
    when ``radius`` is below half a spacing.

    Raises :class:`~physcore.InvalidTypeError` (non-numbers) or
    :class:`~physcore.InvalidInputError` naming ``centre`` (not 2 or 3 finite numbers),
    ``radius`` (not finite and > 0, or reaching beyond float64 from ``centre``) or ``spacing``
    (not finite and > 0, or a lattice too large for memory).
    """
    c = np.asarray(_check.real_array("centre", centre), dtype=np.float64)
    if c.ndim != 1 or c.shape[0] not in (2, 3):
        raise InvalidInputError(f"centre: expected 2 or 3 numbers, got shape {c.shape}")
    if not np.isfinite(c).all():
        raise InvalidInputError(f"centre: must be finite, got {c.tolist()}")
    r = _finite_float(radius, "radius", minimum=0.0, strict=True)
    with np.errstate(over="ignore"):
        reach = np.isfinite(c - r).all() and np.isfinite(c + r).all()
    if not reach:
        raise InvalidInputError(f"radius: {r:.3g} m about {c.tolist()} reaches beyond float64's range")
    pts = lattice(c - radius, c + radius, spacing)
    return pts[np.linalg.norm(pts - c, axis=1) <= radius]


# --------------------------------------------------------------------------- Plummer spheres
def plummer_sphere(
    n: int, *, mass: float = 1.0, a: float = 1.0, G: float = 1.0, cutoff: float = 0.999, seed: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities, (n, 3) float64 each, of a Plummer sphere in equilibrium: density
    ρ ∝ (1 + r²/a²)^(−5/2), total mass `mass`, scale radius `a`, in its centre-of-mass frame.
    Sampled as Aarseth, Hénon & Wielen, Astron. Astrophys. 37 (1974) 183, Appendix: radii by
    inverting the cumulative mass M(r)/M = r³/(r² + a²)^{3/2}, speeds q·v_esc with
    g(q) ∝ q²(1 − q²)^{7/2} by rejection, v_esc = √(2GM/√(r² + a²)); isotropic directions.
    The half-mass radius is ≈ 1.305 a; the virial ratio ``2K/|W|`` is 1 up to sampling noise.
    `cutoff` (in (0, 1)) is the mass fraction sampled: the sphere ends at the radius holding it
    (0.999: about 30 a), so no body starts absurdly far out. Units are any consistent set (G = 1
    by default: N-body units); `seed` (an int or None) makes the draw repeatable.

    Raises :class:`~physcore.InvalidTypeError` / :class:`~physcore.InvalidInputError` naming the
    argument: `n` not an int ≥ 1, `cutoff` outside (0, 1), `a` not finite and > 0, `mass` or `G`
    not finite and ≥ 0.
    """
    n = _check.int_in_range("n", n, 1)
    a, mass, G = _check.positive_float("a", a), _check.nonneg_float("mass", mass), _check.nonneg_float("G", G)
    cutoff = _check.float_in_range("cutoff", cutoff, 0.0, 1.0, lo_open=True, hi_open=True)
    rng = np.random.default_rng(seed)

    def directions(k: int) -> np.ndarray:
        d = rng.normal(size=(k, 3))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    m = rng.uniform(1e-9 * cutoff, cutoff, n)  # mass fractions below 1 keep r finite
    r = a / np.sqrt(m ** (-2.0 / 3.0) - 1.0)
    q = np.empty(n)
    filled = 0
    while filled < n:
        x = rng.uniform(0.0, 1.0, 2 * (n - filled))
        y = rng.uniform(0.0, 0.1, x.size)  # max of q²(1 − q²)^{7/2} is 0.0921
        keep = x[y < x * x * (1 - x * x) ** 3.5][: n - filled]
        q[filled : filled + keep.size] = keep
        filled += keep.size
    v = q * np.sqrt(2.0 * G * mass) * (r * r + a * a) ** -0.25
    x = r[:, None] * directions(n)
    u = v[:, None] * directions(n)
    return x - x.mean(axis=0), u - u.mean(axis=0)


# --------------------------------------------------------------------------- meshes
def cloth_springs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Structural, shear and bend spring index pairs of an n×n grid (index = row·n + col).

    Returns ``(i, j)`` int64 arrays, each spring once: structural (±1 along a row or column),
    shear (both diagonals), bend (±2 along a row or column); 6n² − 10n + 2 springs for n ≥ 2
    (none for n < 2). The grid of :meth:`physcore.render.Mesh.grid` (rows of n): pass them to
    :class:`~physcore.Springs`.

    Raises :class:`~physcore.InvalidTypeError` / :class:`~physcore.InvalidInputError` naming
    ``n`` when it is not an int ≥ 0 or its springs would not fit in memory.
    """
    n = _check.int_in_range("n", n, 0)
    # the index grid, the pairs' views concatenated twice and cast: about 4 copies of 6n² int64
    _check.memory("n", 4 * 8 * 6 * n * n, f"the springs of a {n}×{n} grid")
    idx = np.arange(n * n).reshape(n, n)  # [row j, col i]
    pairs = [
        (idx[:, :-1], idx[:, 1:]),  # structural, along x
        (idx[:-1, :], idx[1:, :]),  # structural, along y
        (idx[:-1, :-1], idx[1:, 1:]),  # shear
        (idx[:-1, 1:], idx[1:, :-1]),  # shear, other diagonal
        (idx[:, :-2], idx[:, 2:]),  # bend, along x
        (idx[:-2, :], idx[2:, :]),  # bend, along y
    ]
    i = np.concatenate([a.ravel() for a, _ in pairs])
    j = np.concatenate([b.ravel() for _, b in pairs])
    return i.astype(np.int64), j.astype(np.int64)


def mesh_edges_and_hinges(faces: np.typing.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Edges and bending hinges of a triangle mesh, for :class:`XpbdConstraints`.

    Returns ``(edges, hinges)``: ``edges`` (E, 2) int64, every edge once; ``hinges`` (H, 4)
    int64, one row ``(a, b, c, d)`` per edge shared by two triangles ``(a, b, c)`` and
    ``(b, a, d)`` (the ``bending`` rows of a 3D scene). Edges of more than two triangles get no
    hinge.

    ``faces`` is (F, 3) integer vertex indices ≥ 0 (one triangle a row; real numbers are cut to
    integers, as ``np.asarray(faces, dtype=np.int64)`` does). Raises
    :class:`~physcore.InvalidTypeError` / :class:`~physcore.InvalidInputError` naming ``faces``
    for anything else.
    """
    f = _check.real_array("faces", faces)
    if f.size == 0:
        f = f.reshape(0, 3)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InvalidInputError(f"faces: expected shape (F, 3), got {f.shape}")
    if not np.isfinite(f).all() or (f < 0).any() or (f >= 2**63).any():
        raise InvalidInputError("faces: expected finite vertex indices >= 0")
    f = np.asarray(f, dtype=np.int64)
    owner: dict[tuple[int, int], list[int]] = {}
    for a, b, c in f.tolist():
        for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
            owner.setdefault((min(u, v), max(u, v)), []).append(w)
    edges = np.array(sorted(owner), dtype=np.int64).reshape(-1, 2)
    hinges = [(a, b, w[0], w[1]) for (a, b), w in sorted(owner.items()) if len(w) == 2]
    return edges, np.array(hinges, dtype=np.int64).reshape(-1, 4)


# --------------------------------------------------------------------------- SPH boundaries on colliders
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def sample_boundary(shape: object, spacing: float, *, layers: int = 1, extent: tuple | None = None) -> np.ndarray:
    """Static SPH boundary particles on the surface of a collider record, for
    :class:`~physcore.Fluid`'s ``boundary``: the same wall for the fluid as the collider is for
    other particles.

    The particles sit on the forbidden side of the surface, as :func:`tank_walls` places
    its: the first layer half a spacing beyond the surface, each further one a spacing beyond
    the last (``layers`` of them; use ``⌈2h/spacing⌉`` for full kernel support, 3 for
    h = 1.3 spacing). Along the surface they are about ``spacing`` apart:

    ==========================  ================================================================
    :class:`~physcore.Plane`    a grid on the plane clipped to ``extent`` (``(lower, upper)``, a
                                box that must cut the plane), layers below it (against the normal)
    :class:`~physcore.Box`      a tank: the lattice around ``[lower, upper]`` outside it, closed
                                on every side; a box whose sides are whole spacings gives exactly
                                ``tank_walls(lower, upper, spacing, layers, top=True)``
    :class:`~physcore.Sphere`   circles (2D) or Fibonacci spheres (3D: ``round(4πR²/spacing²)``
                                points on a golden-angle spiral; González, Math. Geosci. 42
                                (2010) 49) at radius ``R = radius ± (k − ½) spacing``: outward for
                                a bowl (``inside=True``), inward for a ball
    :class:`~physcore.Capsule`  the stadium (2D) or capsule (3D: rings on the cylinder, Fibonacci
                                half-spheres at the ends) at ``R = radius − (k − ½) spacing``
    ``OrientedBox``             the box's own lattice (its sides rounded to whole cells) within
                                ``layers`` cells of its faces
    ==========================  ================================================================

    Inward layers stop at the middle: a box less than ``2 layers`` cells thick is filled, and a
    ball's or capsule's layers end with its centre (its axis, points a spacing apart) where the
    next one would pass it.

    Off a lattice (curved surfaces, rounded ends, turned boxes) the particles are only about
    ``spacing`` apart: give the fluid ``boundary_volume="akinci"``, which weighs each by
    its neighbours (tested: water held in a 2D bowl, and kept out of a turned box in a dam break,
    ``tests/fluids/test_boundary_shapes.py``).

    Parameters
    ----------
    shape : Plane, Box, Sphere, Capsule or OrientedBox
        The collider record, 2D or 3D (the result's dim).
    spacing : float
        Particle spacing, m; finite and > 0 (the fluid's ``spacing``).
    layers : int
        Layers of particles, 1..1000. Default 1.
    extent : (array_like, array_like), optional
        ``(lower, upper)`` corners, m, of the box that clips a :class:`Plane` (required for one,
        refused for any other shape).

    Returns
    -------
    numpy.ndarray
        ``(M, dim)`` float64, m, a new array; the same for the same arguments.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) ``shape`` not one of the records above, ``spacing`` or ``layers`` not
        a number (an int), ``extent`` not a pair of vectors.
    InvalidInputError
        (a ``ValueError``) naming the argument: ``spacing`` not finite and > 0, or the particles
        too many for memory (:func:`physcore._check.memory_limit`) or reaching beyond float64;
        ``layers`` outside 1..1000; ``extent`` missing for a plane, given for another shape, of
        another dimension, not finite with ``upper > lower``, or not crossing the plane.

    Examples
    --------
    >>> import physcore as pc
    >>> bowl = pc.shapes.sample_boundary(pc.Sphere([0.0, 0.0], 1.0, inside=True), 0.1, layers=3)
    >>> bowl.shape  # rings of 66, 72 and 79 particles at radii 1.05, 1.15 and 1.25 m
    (217, 2)
    >>> floor = pc.shapes.sample_boundary(pc.Plane([0.0, 0.0], [0.0, 1.0]), 0.25, extent=([0, 0], [1, 1]))
    >>> floor.tolist()
    [[0.125, -0.125], [0.375, -0.125], [0.625, -0.125], [0.875, -0.125]]
    """
    from .terms import Box, Capsule, OrientedBox, Plane, Sphere

    samplers = {Plane: _plane_boundary, Box: _box_boundary, Sphere: _sphere_boundary,
                Capsule: _capsule_boundary, OrientedBox: _oriented_box_boundary}
    sampler = samplers.get(type(shape))
    if sampler is None:
        raise InvalidTypeError(
            f"shape: expected a collider record (Plane, Box, Sphere, Capsule or OrientedBox), got {type(shape).__name__}"
        )
    s = _finite_float(spacing, "spacing", minimum=0.0, strict=True)
    layers = _check.int_in_range("layers", layers, 1, 1000)
    if type(shape) is Plane:
        if extent is None:
            raise InvalidInputError("extent: a Plane is infinite; give extent=(lower, upper), the box to clip it to")
        return sampler(shape, s, layers, _extent(extent, shape.point.shape[0]))
    if extent is not None:
        raise InvalidInputError(f"extent: only a Plane is clipped to an extent; a {type(shape).__name__} has its own bounds")
    return sampler(shape, s, layers)


def _extent(value: object, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """``extent`` as two (dim,) float64 corners, finite, upper > lower."""
    try:
        lo, hi = value  # type: ignore[misc]
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"extent: expected a pair (lower, upper) of corners, got {type(value).__name__}") from exc
    lo = _check.real_array("extent", lo).astype(np.float64)
    hi = _check.real_array("extent", hi).astype(np.float64)
    if lo.shape != (dim,) or hi.shape != (dim,):
        raise InvalidInputError(f"extent: expected two corners of shape ({dim},) (the plane is {dim}D), got {lo.shape} and {hi.shape}")
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and np.all(hi > lo)):
        raise InvalidInputError(f"extent: the corners must be finite with upper > lower on every axis, got {lo.tolist()} and {hi.tolist()}")
    return lo, hi


def _refuse_beyond(dim: int, count: float, what: str) -> None:
    """The memory check, naming ``spacing``: the points, their layers and a few working copies."""
    _check.memory("spacing", 4 * 8 * dim * count, what)


def _cells(length: float, s: float) -> float:
    """Cells of about ``s`` along ``length`` (a float: inf where it overflows)."""
    with np.errstate(over="ignore"):
        c = float(length) / s
    return max(c, 1.0) if math.isfinite(c) else math.inf


def _tangents(normal: np.ndarray) -> np.ndarray:
    """(dim − 1, dim) orthonormal tangents of a unit normal: the coordinate axes other than the
    one most along it, Gram–Schmidt'ed (so an axis-aligned normal gets coordinate axes)."""
    dim = normal.shape[0]
    drop = int(np.argmax(np.abs(normal)))
    basis = [normal]
    for d in range(dim):
        if d == drop:
            continue
        e = np.zeros(dim)
        e[d] = 1.0
        for b in basis:
            e = e - (e @ b) * b
        basis.append(e / np.linalg.norm(e))
    return np.array(basis[1:])


def _shell(counts: list[int], band: list[np.ndarray]) -> np.ndarray:
    """(M, dim) int64 cell indices of the grid ``counts`` with at least one index in its axis'
    ``band`` (a boolean mask per axis), in the grid's order (first axis fastest), built without
    the whole grid: each cell once, from the first axis on which it is in the band."""
    dim = len(counts)
    parts = []
    for d in range(dim):
        axes = [np.flatnonzero(~band[e]) if e < d else np.flatnonzero(band[e]) if e == d else np.arange(counts[e])
                for e in range(dim)]
        if min(a.size for a in axes) == 0:
            continue
        grids = np.meshgrid(*axes, indexing="ij")
        parts.append(np.stack([g.ravel() for g in grids], axis=1))
    idx = np.concatenate(parts) if parts else np.zeros((0, dim), dtype=np.int64)
    order = np.lexsort(idx.T)  # the last axis the primary key: the first axis fastest
    return np.ascontiguousarray(idx[order].astype(np.int64))


def _box_boundary(box: Any, s: float, layers: int) -> np.ndarray:
    """A tank: the lattice cells around [lower, upper], ``layers`` deep, outside it."""
    lo, hi = box.lower, box.upper
    dim = lo.shape[0]
    cells = [_cells(float(hi[d]) - float(lo[d]), s) for d in range(dim)]
    outer = math.prod(c + 2 * layers for c in cells)
    _refuse_beyond(dim, outer - math.prod(cells) if math.isfinite(outer) else math.inf, f"a tank's {layers} layers of boundary particles")
    n = [max(round(c), 1) for c in cells]
    # A side of whole spacings keeps the spacing itself: the fluid's lattice, as tank_walls.
    step = [s if math.isclose(n[d] * s, hi[d] - lo[d], rel_tol=1e-9) else (hi[d] - lo[d]) / n[d] for d in range(dim)]
    base = np.array([lo[d] - layers * step[d] for d in range(dim)])
    top = np.array([hi[d] + layers * step[d] for d in range(dim)])
    if not (np.isfinite(base).all() and np.isfinite(top).all()):
        raise InvalidInputError(f"spacing: {layers} layers of {s} m reach beyond float64's range")
    counts = [n[d] + 2 * layers for d in range(dim)]
    band = [(np.arange(m) < layers) | (np.arange(m) >= m - layers) for m in counts]
    idx = _shell(counts, band)
    return np.ascontiguousarray(base + (idx + 0.5) * np.array(step))


def _oriented_box_boundary(box: Any, s: float, layers: int) -> np.ndarray:
    """The box's own lattice (cells of about s) within ``layers`` cells of its faces."""
    h = box.half_extents
    dim = h.shape[0]
    cells = [_cells(2.0 * float(h[d]), s) for d in range(dim)]
    whole = math.prod(cells)
    inner = math.prod(max(c - 2 * layers, 0.0) for c in cells) if math.isfinite(whole) else 0.0
    _refuse_beyond(dim, whole - inner if math.isfinite(whole) else math.inf, f"an oriented box's {layers} layers of boundary particles")
    n = [max(round(c), 1) for c in cells]
    step = np.array([2.0 * float(h[d]) / n[d] for d in range(dim)])
    band = [(np.arange(m) < layers) | (np.arange(m) >= m - layers) for m in n]
    local = -h + (_shell(n, band) + 0.5) * step
    return np.ascontiguousarray(box.center + local @ box.axes())


def _plane_boundary(plane: Any, s: float, layers: int, extent: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """A grid on the plane within ``extent``, ``layers`` deep below it."""
    lo, hi = extent
    dim = lo.shape[0]
    n_hat = plane.normal
    t = _tangents(n_hat)
    corners = np.array([[(hi if (i >> d) & 1 else lo)[d] for d in range(dim)] for i in range(2**dim)])
    with np.errstate(over="ignore", invalid="ignore"):
        side = (corners - plane.point) @ n_hat
        u = corners @ t.T  # (2**dim, dim − 1) tangent coordinates of the corners
    if not (np.isfinite(side).all() and np.isfinite(u).all()):
        raise InvalidInputError("extent: its corners' distances from the plane overflow float64")
    if side.min() > 0.0 or side.max() < 0.0:
        raise InvalidInputError(f"extent: the plane through {plane.point.tolist()} does not cross the box {lo.tolist()}..{hi.tolist()}")
    ulo, uhi = u.min(axis=0), u.max(axis=0)
    cells = [_cells(float(uhi[d]) - float(ulo[d]), s) for d in range(dim - 1)]
    _refuse_beyond(dim, 2 * layers * math.prod(cells), f"{layers} layers of boundary particles on the plane")
    n = [max(round(c), 1) for c in cells]
    step = [s if math.isclose(n[d] * s, uhi[d] - ulo[d], rel_tol=1e-9) else (uhi[d] - ulo[d]) / n[d] for d in range(dim - 1)]
    axes = [ulo[d] + (np.arange(n[d]) + 0.5) * step[d] for d in range(dim - 1)]
    grids = np.meshgrid(*axes[::-1], indexing="ij")[::-1]
    uv = np.stack([g.ravel() for g in grids], axis=1)
    on = (plane.point @ n_hat) * n_hat + uv @ t  # the grid's points on the plane
    tol = 1e-9 * max(float(np.abs(lo).max()), float(np.abs(hi).max()), float(np.max(hi - lo)))
    on = on[np.all((on >= lo - tol) & (on <= hi + tol), axis=1)]
    depth = (np.arange(layers) + 0.5) * s
    if not np.isfinite(on - depth[-1] * n_hat).all():
        raise InvalidInputError(f"spacing: {layers} layers of {s} m reach beyond float64's range")
    return np.ascontiguousarray(np.concatenate([on - d * n_hat for d in depth]))


def _sphere_boundary(sphere: Any, s: float, layers: int) -> np.ndarray:
    sign = 1.0 if sphere.inside else -1.0
    return _rounded(sphere.center, sphere.center, sphere.radius, sign, s, layers, "a sphere's")


def _capsule_boundary(capsule: Any, s: float, layers: int) -> np.ndarray:
    return _rounded(capsule.a, capsule.b, capsule.radius, -1.0, s, layers, "a capsule's")


def _rounded(a: np.ndarray, b: np.ndarray, radius: float, sign: float, s: float, layers: int, whose: str) -> np.ndarray:
    """The layers of the points within R of the segment a–b (a sphere where a == b) at radii
    ``R = radius + sign (k − ½) s``; inward (sign −1) they end at the axis."""
    dim = a.shape[0]
    length = float(np.linalg.norm(b - a))
    reach = radius + sign * (layers - 0.5) * s
    if not math.isfinite(reach) or not np.isfinite(a + reach).all() or not np.isfinite(b + reach).all():
        raise InvalidInputError(f"spacing: {layers} layers of {s} m reach beyond float64's range")
    big = max(radius, reach)
    with np.errstate(over="ignore"):
        area = 2 * math.pi * big + 2 * length if dim == 2 else 4 * math.pi * big * big + 2 * math.pi * big * length
        count = layers * (area / s ** (dim - 1) + length / s + 2)
    _refuse_beyond(dim, count, f"{whose} {layers} layers of boundary particles")
    u, frame = _segment_frame(a, b, length)
    out = []
    for k in range(layers):
        r = radius + sign * (k + 0.5) * s
        if r <= 0.0:
            if k == 0 or r + s > 0.5 * s:  # the last layer is over half a spacing from the axis
                n = max(round(length / s), 0)
                t = np.arange(n + 1) / n if n else np.zeros(1)
                out.append(a + t[:, None] * (b - a))
            break
        out.append(_stadium(a, b, u, frame, length, r, s) if dim == 2 else _capsule_surface(a, u, frame, length, r, s))
    return np.ascontiguousarray(np.concatenate(out))


def _segment_frame(a: np.ndarray, b: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """The unit axis u of a–b (the last coordinate axis where a == b) and unit vectors across it
    (rows)."""
    dim = a.shape[0]
    if length > 0.0:
        u = (b - a) / length
    else:
        u = np.zeros(dim)
        u[-1] = 1.0
    return u, _tangents(u)


def _stadium(a, b, u, frame, length, r, s) -> np.ndarray:
    """2D: points about s apart along the outline of the stadium of radius r about a–b: the side
    at +w from a to b, the half circle about b, the side at −w back, the half circle about a."""
    w = frame[0]
    perimeter = 2.0 * length + 2.0 * math.pi * r
    n = max(round(perimeter / s), 1)
    arc = (np.arange(n) + 0.5) * (perimeter / n)
    half = math.pi * r
    pts = np.empty((n, 2))
    for lo, hi, f in (
        (0.0, length, lambda x: a + r * w + x[:, None] * u),
        (length, length + half, lambda x: b + r * (np.cos(x / r)[:, None] * w + np.sin(x / r)[:, None] * u)),
        (length + half, 2 * length + half, lambda x: b - r * w - x[:, None] * u),
        (2 * length + half, perimeter + 1.0, lambda x: a - r * (np.cos(x / r)[:, None] * w + np.sin(x / r)[:, None] * u)),
    ):
        m = (arc >= lo) & (arc < hi)
        pts[m] = f(arc[m] - lo)
    return pts


def _capsule_surface(a, u, frame, length, r, s) -> np.ndarray:
    """3D: a Fibonacci sphere of radius r split into the half about a (behind it) and the half
    about b, and between them rings about s apart, each of about 2πr/s points."""
    n = max(round(4.0 * math.pi * r * r / (s * s)), 1)
    i = np.arange(n)
    z = 1.0 - (2.0 * i + 1.0) / n
    rho = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = i * _GOLDEN_ANGLE
    d = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1) @ np.vstack([frame, u])
    back = z <= 0.0
    caps = [a + r * d[back]]
    if length > 0.0:
        around = max(round(2.0 * math.pi * r / s), 1)
        rows = max(round(length / s), 1)
        ang = np.arange(around) * (2.0 * math.pi / around)
        ring = np.cos(ang)[:, None] * frame[0] + np.sin(ang)[:, None] * frame[1]
        along = (np.arange(rows) + 0.5) * (length / rows)
        caps.append((a + along[:, None, None] * u + r * ring[None]).reshape(-1, 3))
    caps.append(a + length * u + r * d[~back])
    return np.concatenate(caps)
