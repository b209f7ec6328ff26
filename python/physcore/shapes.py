"""Geometry builders for your own scenes: point lattices, tank walls, blobs, Plummer spheres and
the index arrays of meshes. Plain numpy in, plain numpy out (positions in m, float64; indices
int64); nothing here builds a :class:`~physcore.Scene`. The ready-made scenes
(:mod:`physcore.scenes`) are built from these.

lattice, lattice_counts   particle centres filling a box on a cubic lattice, and their count per axis
tank_walls                static wall particles lining a box (the boundary of an SPH tank)
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

import numpy as np

from . import _check
from ._check import finite_float as _finite_float
from ._errors import InvalidInputError

__all__ = ["lattice", "lattice_counts", "tank_walls", "blob", "plummer_sphere", "cloth_springs", "mesh_edges_and_hinges"]


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
