"""Position-based constraints with compliance: :class:`XpbdConstraints`."""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, ClassVar

import numpy as np

from .. import _check, _deprecate
from .._errors import InvalidInputError, InvalidTypeError, allocating
from .._parts import AttachContext, LoadContext
from ._base import ArrayLike, Term, _int_array, _per_spring


def _index_rows(value: object, arg: str, width: int | tuple[int, ...]) -> np.ndarray:
    """Rows of distinct particle indices, shape (M, width), int64, read-only."""
    widths = (width,) if isinstance(width, int) else width
    a = _check.array(arg, value)
    if a.dtype.kind not in "iu" and not (a.size == 0 and a.dtype.kind == "f"):
        raise InvalidTypeError(f"{arg}: expected integer particle indices, got dtype {a.dtype}")
    if a.size == 0:
        a = a.reshape(0, widths[0])
    if a.ndim != 2 or a.shape[1] not in widths:
        want = " or ".join(f"(M, {w})" for w in widths)
        raise InvalidInputError(f"{arg}: expected shape {want}, got {a.shape}")
    a = a.astype(np.int64)
    if a.size and a.min() < 0:
        raise InvalidInputError(f"{arg}: indices must be >= 0, got {int(a.min())}")
    srt = np.sort(a, axis=1)
    dup = np.flatnonzero((srt[:, 1:] == srt[:, :-1]).any(axis=1)) if a.shape[1] > 1 else np.zeros(0, int)
    if dup.size:
        raise InvalidInputError(f"{arg}: row {int(dup[0])} names a particle twice: {a[dup[0]].tolist()}")
    a.setflags(write=False)
    return a


def _per_row(value: object, m: int, arg: str, *, signed: bool = False) -> np.ndarray:
    """A scalar or one value per constraint, float64, read-only; >= 0 unless ``signed``."""
    if signed:
        a = _check.real_array(arg, value).astype(np.float64)
        if a.ndim == 0:
            a = np.full(m, float(a))
        if a.shape != (m,):
            raise InvalidInputError(f"{arg}: expected a scalar or shape ({m},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InvalidInputError(f"{arg}: entry {int(np.flatnonzero(~np.isfinite(a))[0])} is not finite")
        a.setflags(write=False)
        return a
    return _per_spring(value, m, arg)


@_deprecate.record(('distance', 'distance_compliance', 'rest_length', 'bending', 'bending_compliance', 'rest_angle', 'pins', 'pin_targets', 'pin_compliance', 'area', 'area_compliance', 'rest_area', 'volume', 'volume_compliance', 'rest_volume', 'shapes', 'shape_sizes', 'shape_rest', 'shape_stiffness'), keep=0)
@dataclass(frozen=True, eq=False)
class XpbdConstraints(Term, kind="xpbd_constraints"):
    """Position-based constraints with compliance (XPBD), projected by ``Scene(integrator="xpbd")``.

    Each substep of length ``h`` predicts ``v += h (f/m + g)``, ``x += h v`` from the scene's
    force terms, then projects every constraint ``C(x) = 0`` with compliance ``α`` (inverse
    stiffness) by ``Δλ = (−C − α̃λ) / (Σ w_k |∇_k C|² + α̃)``, ``x_k += w_k ∇_k C Δλ``,
    ``α̃ = α/h²`` (Macklin, Müller & Chentanez, "XPBD", MIG 2016, eqs. 17–18; ``w = 1/m``, 0 for
    pinned particles), λ accumulated over the iterations of one substep, and sets
    ``v = (x − x_prev)/h``. A compliance is a material constant: the static stretch of one
    distance constraint under a force F is ``F α`` for any step, substep count or iteration
    count. A chain of many is stiffer than that only where the iterations converge: one
    Gauss–Seidel sweep a substep leaves a residual stretch that grows with the substep h, as
    h² (a hanging chain of 40 links of 2.5 cm and 0.01 kg a node, at rest (``Drag(0.5)``, 20 s;
    undamped, the compliant chain still swings after 10 s), at dt = 1/60 and 10 substeps of 1
    iteration: 21.8 mm with ``α = 0``, and 102 mm where ``F α`` gives 80.4 mm at ``α = 1e-3``
    m/N; 20 substeps 5.4 and 85.9 mm, 10 iterations 2.2 and 80.44 mm). More
    substeps (or iterations) where a long chain's stretch matters. ``α = 0`` is infinitely
    stiff in the limit. Kinds are projected in the order of the parameters below, each by
    Gauss–Seidel over a greedy graph colouring (bit-identical results for any thread count).

    Parameters
    ----------
    distance : array_like of int, shape (M, 2), optional
        Particle pairs kept at ``rest_length``: ``C = |x_i − x_j| − L0``.
    distance_compliance : float or array_like, shape (M,)
        ``α`` ≥ 0, m/N (``1/k`` of the equivalent spring). Default 0.
    rest_length : None or array_like, shape (M,)
        ``L0`` ≥ 0, m. ``None``: the lengths when the term is added.
    bending : array_like of int, optional
        2D: shape (B, 3), rows ``(i, j, k)``: the signed angle at ``j`` from ``x_i − x_j`` to
        ``x_k − x_j``. 3D: shape (B, 4), rows ``(a, b, c, d)``: the dihedral angle between
        triangles ``(a, b, c)`` and ``(b, a, d)`` across their shared edge ``a–b``, 0 when flat
        (dihedral bending: Müller et al., "Position based dynamics", JVCIR 2007, §4.2; gradient
        of Bridson, Marino & Fedkiw, SCA 2003). ``C = θ − θ0``.
    bending_compliance : float or array_like, shape (B,)
        ``α`` ≥ 0, rad²/J (``1/k`` for a bending stiffness ``k`` in J/rad²). Default 0.
    rest_angle : None or array_like, shape (B,)
        ``θ0`` in [−π, π], rad. ``None``: the angles when the term is added.
    pins : array_like of int, shape (P,), optional
        Particles held at ``pin_targets``: ``C = |x_i − p_i|``.
    pin_targets : None or array_like, shape (P, dim)
        Fixed points, m. ``None``: the positions when the term is added.
    pin_compliance : float or array_like, shape (P,)
        ``α`` ≥ 0, m/N (a zero-length spring of stiffness ``1/α``; 0: held exactly). Default 0.
    area : array_like of int, shape (A, 3), optional (2D only)
        Triangles whose signed area ``½ (x_j − x_i) × (x_k − x_i)`` is kept at ``rest_area``.
    area_compliance : float or array_like, shape (A,)
        ``α`` ≥ 0, m⁴/J. Default 0.
    rest_area : None or array_like, shape (A,)
        Signed rest areas, m², non-zero. ``None``: the areas when the term is added.
    volume : array_like of int, shape (T, 4), optional (3D only)
        Tetrahedra whose signed volume ``⅙ (x_j − x_i)·((x_k − x_i) × (x_l − x_i))`` is kept.
    volume_compliance : float or array_like, shape (T,)
        ``α`` ≥ 0, m⁶/J. Default 0.
    rest_volume : None or array_like, shape (T,)
        Signed rest volumes, m³, non-zero. ``None``: the volumes when the term is added.
    shapes : sequence of array_like of int, optional
        Particle clusters kept at their rest shape by shape matching (Müller, Heidelberger,
        Teschner & Gross, "Meshless deformations based on shape matching", SIGGRAPH 2005, eqs.
        5–7: goals ``g_i = R (x⁰_i − x⁰_cm) + x_cm`` with ``R`` the rotation of
        ``A_pq = Σ m_i p_i q_iᵀ``; each particle moves ``shape_stiffness`` of the way to its
        goal per iteration). At least 2 particles each. A cluster with pinned particles turns
        about them as far as they let it: one pin is a pivot, two pins in 2D or three not on a
        line in 3D hold it still, and pins on a line in 3D are a hinge (the rotation is fitted
        to the pins where they fix it, to the free particles where they do not: the limit of
        pins of infinite mass). (Or a flat index array with ``shape_sizes``.)
    shape_sizes : None or array_like of int, shape (S,)
        With a flat ``shapes``: the particle count of each cluster, in order.
    shape_rest : None or array_like, shape (Σ sizes, dim)
        Rest positions of the clusters' particles, m. ``None``: the positions when added.
    shape_stiffness : float or array_like, shape (S,)
        In (0, 1]; 1 (default) is rigid. Not a material constant (it acts per iteration).
    name : str
        Key of this term in the energy books.

    Energy books: potential ``Σ C²/(2α)`` over the compliant constraints (J; α = 0 and shapes
    store none); the energy each projection removes is measured and booked as this term's
    dissipated energy (see docs/guide/constraints.md).

    Numerical damping: a compliant constraint oscillates as implicit Euler would step it. A
    mode of angular frequency ``ω = 1/√(α m)`` loses amplitude at ``γ = ln(1 + ω²h²)/(2h) ≈
    ω²h/2`` per second for a substep ``h = dt/xpbd_substeps`` (measured for a mass on a
    distance constraint, ω = 10 rad/s: γ = 0.4975, 0.0500, 0.00500 1/s at h = 1e-2, 1e-3, 1e-4,
    the formula's values to 4 digits). A constraint with ``ω h ≫ 1`` (stiff, or α = 0) loses
    its oscillation within a substep; for an oscillation that lasts ``N`` periods, take
    ``h ≲ 1/(π N ω)``.

    Raises
    ------
    TypeError
        Non-integer indices or non-numeric parameters.
    ValueError
        (:class:`InvalidInputError`) Wrong shapes, negative indices, a particle named twice in
        one constraint, negative or non-finite compliances, a shape stiffness outside (0, 1], a
        shape of fewer than 2 particles; on :meth:`Scene.add`: an index out of range, area in 3D
        or volume in 2D, a degenerate rest triangle, tetrahedron or shape. Named by argument;
        nothing changes.

    Notes
    -----
    Only ``Scene(integrator="xpbd")`` projects the constraints. Any other integrator would step
    the particles as if they were not there (the term adds no force), so it is refused by name:
    adding the term to such a scene, or changing an xpbd scene's integrator, raises
    :class:`~physcore.InvalidInputError` naming ``integrator``, before anything changes.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=2, integrator="xpbd", dt=1e-2, xpbd_substeps=20)
    >>> _ = s.add_particles([[0.0, 0.0], [0.0, -1.0]], masses=[1.0, 0.5], pinned=[True, False])
    >>> _ = s.add(pc.Gravity([0.0, -9.81]))
    >>> _ = s.add(pc.Drag(0.5))
    >>> _ = s.add(pc.XpbdConstraints(distance=[[0, 1]], distance_compliance=1e-3))
    >>> s.step(2000)
    >>> stretch = -s.positions[1, 1] - 1.0
    >>> float(round(stretch / (0.5 * 9.81 * 1e-3), 6))      # m g α
    1.0
    """

    _: KW_ONLY
    distance: Any = None
    distance_compliance: ArrayLike = 0.0
    rest_length: ArrayLike | None = None
    bending: Any = None
    bending_compliance: ArrayLike = 0.0
    rest_angle: ArrayLike | None = None
    pins: Any = None
    pin_targets: ArrayLike | None = None
    pin_compliance: ArrayLike = 0.0
    area: Any = None
    area_compliance: ArrayLike = 0.0
    rest_area: ArrayLike | None = None
    volume: Any = None
    volume_compliance: ArrayLike = 0.0
    rest_volume: ArrayLike | None = None
    shapes: Any = None
    shape_sizes: Any = None
    shape_rest: ArrayLike | None = None
    shape_stiffness: ArrayLike = 1.0
    name: str = field(default="xpbd", kw_only=True)

    #: (indices, compliance, rest, row widths) of the scalar kinds, in projection order.
    _KINDS: ClassVar[tuple[tuple[str, str, str, tuple[int, ...]], ...]] = (
        ("distance", "distance_compliance", "rest_length", (2,)),
        ("bending", "bending_compliance", "rest_angle", (3, 4)),
        ("area", "area_compliance", "rest_area", (3,)),
        ("volume", "volume_compliance", "rest_volume", (4,)),
    )

    @allocating("XpbdConstraints", "its arrays")
    def __post_init__(self) -> None:
        put = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        for idx, comp, rest, widths in self._KINDS:
            rows = _index_rows([] if getattr(self, idx) is None else getattr(self, idx), idx, widths)
            put(idx, rows)
            m = rows.shape[0]
            put(comp, _per_row(getattr(self, comp), m, comp))
            if getattr(self, rest) is not None:
                put(rest, _per_row(getattr(self, rest), m, rest, signed=rest != "rest_length"))
        pins = _check.array("pins", [] if self.pins is None else self.pins)
        if pins.size == 0:
            pins = pins.reshape(0)
        if pins.dtype.kind not in "iu" and not (pins.size == 0 and pins.dtype.kind == "f"):
            raise InvalidTypeError(f"pins: expected integer particle indices, got dtype {pins.dtype}")
        if pins.ndim != 1:
            raise InvalidInputError(f"pins: expected shape (P,), got {pins.shape}")
        pins = pins.astype(np.int64)
        if pins.size and pins.min() < 0:
            raise InvalidInputError(f"pins: indices must be >= 0, got {int(pins.min())}")
        pins.setflags(write=False)
        put("pins", pins)
        put("pin_compliance", _per_row(self.pin_compliance, pins.size, "pin_compliance"))
        if self.pin_targets is not None:
            t = _check.real_array("pin_targets", self.pin_targets).astype(np.float64)
            if t.ndim != 2 or t.shape[0] != pins.size or t.shape[1] not in (2, 3) or not np.all(np.isfinite(t)):
                raise InvalidInputError(f"pin_targets: expected finite values of shape ({pins.size}, dim), got {t.shape}")
            t.setflags(write=False)
            put("pin_targets", t)
        # Shapes: a list of index arrays, or a flat array with shape_sizes.
        if self.shape_sizes is None:
            groups = [] if self.shapes is None else self.shapes
            if isinstance(groups, (str, bytes)) or not isinstance(groups, (Sequence, np.ndarray)) or (isinstance(groups, np.ndarray) and groups.ndim == 0):
                raise InvalidTypeError(f"shapes: expected a list of index arrays (or a flat one with shape_sizes), got {type(groups).__name__}")
            arrays = [_check.array("shapes", g) for g in groups]
            for k, g in enumerate(arrays):
                if g.dtype.kind not in "iu" or g.ndim != 1:
                    raise InvalidInputError(f"shapes: cluster {k} must be a 1-D array of particle indices, got dtype {g.dtype}, shape {g.shape}")
            sizes = np.array([g.size for g in arrays], dtype=np.int64)
            members = np.concatenate(arrays).astype(np.int64) if arrays else np.zeros(0, np.int64)
        else:
            members, sizes = (_int_array(a, getattr(self, a)) for a in ("shapes", "shape_sizes"))
            if sizes.sum() != members.size:
                raise InvalidInputError(f"shape_sizes: sums to {int(sizes.sum())}, shapes has {members.size} indices")
        if sizes.size and sizes.min() < 2:
            k = int(np.flatnonzero(sizes < 2)[0])
            who = "shapes" if self.shape_sizes is None else "shape_sizes"
            raise InvalidInputError(f"{who}: cluster {k} has {int(sizes[k])} particles (a shape needs at least 2)")
        if members.size and members.min() < 0:
            raise InvalidInputError(f"shapes: indices must be >= 0, got {int(members.min())}")
        for k, (a, b) in enumerate(zip(np.cumsum(sizes) - sizes, np.cumsum(sizes), strict=True)):
            if np.unique(members[a:b]).size != b - a:
                raise InvalidInputError(f"shapes: cluster {k} names a particle twice")
        members.setflags(write=False)
        sizes.setflags(write=False)
        put("shapes", members)
        put("shape_sizes", sizes)
        put("shape_stiffness", _per_row(self.shape_stiffness, sizes.size, "shape_stiffness"))
        st = self.shape_stiffness
        if st.size and not np.all((st > 0) & (st <= 1)):
            k = int(np.flatnonzero(~((st > 0) & (st <= 1)))[0])
            raise InvalidInputError(f"shape_stiffness: entry {k} is {st[k]} (must be in (0, 1])")
        if self.shape_rest is not None:
            r = _check.real_array("shape_rest", self.shape_rest).astype(np.float64)
            if r.ndim != 2 or r.shape[0] != members.size or r.shape[1] not in (2, 3) or not np.all(np.isfinite(r)):
                raise InvalidInputError(f"shape_rest: expected finite values of shape ({members.size}, dim), got {r.shape}")
            r.setflags(write=False)
            put("shape_rest", r)

    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "distance": ("i8", ("DI",)),
        "distance_compliance": ("f8", ("DC",)),
        "rest_length": ("f8", ("DC",)),
        "bending": ("i8", ("BI",)),
        "bending_compliance": ("f8", ("BC",)),
        "rest_angle": ("f8", ("BC",)),
        "pins": ("i8", ("P",)),
        "pin_targets": ("f8", ("P", "D")),
        "pin_compliance": ("f8", ("P",)),
        "area": ("i8", ("AI",)),
        "area_compliance": ("f8", ("AC",)),
        "rest_area": ("f8", ("AC",)),
        "volume": ("i8", ("VI",)),
        "volume_compliance": ("f8", ("VC",)),
        "rest_volume": ("f8", ("VC",)),
        "shapes": ("i8", ("SM",)),
        "shape_sizes": ("i8", ("S",)),
        "shape_rest": ("f8", ("SM", "D")),
        "shape_stiffness": ("f8", ("S",)),
    }

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        # Index rows are stored flat (a bending row is 3 wide in 2D, 4 in 3D).
        return {}, {a: np.asarray(getattr(self, a)).reshape(-1) if a in ("distance", "bending", "area", "volume") else np.asarray(getattr(self, a)) for a in self.record_arrays}

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        a = dict(arrays)
        widths = {"distance": 2, "bending": 3 if ctx.dim == 2 else 4, "area": 3, "volume": 4}
        for k, w in widths.items():
            if a[k].size % w:
                raise InvalidInputError(f"{k}: {a[k].size} indices are not rows of {w}")
            a[k] = a[k].reshape(-1, w)
        ctx.add(cls(**a, name=meta["name"]))

    def _attach(self, ctx: AttachContext, name: str) -> XpbdConstraints:
        dim, n = ctx.dim, ctx.n_particles
        for arg in ("distance", "bending", "pins", "area", "volume", "shapes"):
            a = getattr(self, arg)
            if a.size and a.max() >= n:
                raise InvalidInputError(f"{arg}: index {int(a.max())} is out of range for {n} particles")
        if self.bending.size == 0:
            object.__setattr__(self, "bending", np.zeros((0, 3 if dim == 2 else 4), np.int64))
        if self.bending.size and self.bending.shape[1] != (3 if dim == 2 else 4):
            raise InvalidInputError(f"bending: rows of {3 if dim == 2 else 4} indices in {dim}D, got {self.bending.shape[1]}")
        if dim == 3 and self.area.size:
            raise InvalidInputError("area: area constraints are for 2D scenes (use volume in 3D)")
        if dim == 2 and self.volume.size:
            raise InvalidInputError("volume: volume constraints are for 3D scenes (use area in 2D)")
        for arg in ("pin_targets", "shape_rest"):
            v = getattr(self, arg)
            if v is not None and v.shape[1] != dim:
                raise InvalidInputError(f"{arg}: has {v.shape[1]} components, the scene is {dim}D")
        x = ctx.positions.astype(np.float64)
        rest = {}
        with np.errstate(all="ignore"):
            d, b, ar, vo = self.distance, self.bending, self.area, self.volume
            rest["rest_length"] = np.linalg.norm(x[d[:, 0]] - x[d[:, 1]], axis=1) if d.size else np.zeros(0)
            rest["rest_angle"] = _angles(x, b) if b.size else np.zeros(0)
            rest["rest_area"] = (0.5 * _cross2(x[ar[:, 1]] - x[ar[:, 0]], x[ar[:, 2]] - x[ar[:, 0]])) if ar.size else np.zeros(0)
            rest["rest_volume"] = (
                np.einsum("ij,ij->i", x[vo[:, 1]] - x[vo[:, 0]], np.cross(x[vo[:, 2]] - x[vo[:, 0]], x[vo[:, 3]] - x[vo[:, 0]])) / 6.0
                if vo.size
                else np.zeros(0)
            )
        resolved = {}
        for arg, value in rest.items():
            if getattr(self, arg) is None:
                if not np.all(np.isfinite(value)):
                    raise InvalidInputError(f"{arg}: the current geometry of row {int(np.flatnonzero(~np.isfinite(value))[0])} is beyond float64; give {arg}=")
                resolved[arg] = value
        for arg, idx in (("rest_area", "area"), ("rest_volume", "volume")):
            v = resolved.get(arg, getattr(self, arg))
            if v.size and np.any(v == 0):
                k = int(np.flatnonzero(v == 0)[0])
                raise InvalidInputError(f"{idx}: row {k} is degenerate at rest ({arg} 0); it has no {idx} to keep")
        ra = resolved.get("rest_angle", self.rest_angle)
        if ra.size and np.any(np.abs(ra) > math.pi):
            raise InvalidInputError(f"rest_angle: entry {int(np.flatnonzero(np.abs(ra) > math.pi)[0])} is outside [-pi, pi]")
        if dim == 3 and b.size:
            area1 = np.linalg.norm(np.cross(x[b[:, 2]] - x[b[:, 0]], x[b[:, 2]] - x[b[:, 1]]), axis=1)
            area2 = np.linalg.norm(np.cross(x[b[:, 3]] - x[b[:, 1]], x[b[:, 3]] - x[b[:, 0]]), axis=1)
            bad = np.flatnonzero(~((area1 > 0) & (area2 > 0)))
            if bad.size:
                raise InvalidInputError(f"bending: row {int(bad[0])} has a degenerate triangle (no dihedral angle)")
        if self.pin_targets is None:
            resolved["pin_targets"] = x[self.pins].reshape(-1, dim)
        srest = self.shape_rest if self.shape_rest is not None else x[self.shapes].reshape(-1, dim)
        for k, (a0, b0) in enumerate(zip(np.cumsum(self.shape_sizes) - self.shape_sizes, np.cumsum(self.shape_sizes), strict=True)):
            if np.all(srest[a0:b0] == srest[a0]):
                raise InvalidInputError(f"shapes: cluster {k}'s rest positions all coincide (a degenerate rest shape)")
        resolved["shape_rest"] = srest
        for v in resolved.values():
            v.setflags(write=False)
        stored = dataclasses.replace(self, **resolved, shape_sizes=self.shape_sizes, name=name)
        u32 = lambda a: np.ascontiguousarray(a.reshape(-1), dtype=np.uint32)  # noqa: E731
        f64 = lambda a: np.ascontiguousarray(a.reshape(-1), dtype=np.float64)  # noqa: E731
        params: dict[str, Any] = {}
        for idx, comp, rest_arg, _ in self._KINDS:
            rows = getattr(stored, idx)
            if rows.size:
                params[idx] = u32(rows)
                params[f"{idx}_compliance"] = f64(getattr(stored, comp))
                params[f"{idx}_rest"] = f64(getattr(stored, rest_arg))
        if stored.pins.size:
            params["pins"] = u32(stored.pins)
            params["pins_compliance"] = f64(stored.pin_compliance)
            params["pins_target"] = f64(stored.pin_targets)
        if stored.shape_sizes.size:
            params["shapes"] = u32(stored.shapes)
            params["shapes_size"] = u32(stored.shape_sizes)
            params["shapes_rest"] = f64(stored.shape_rest)
            params["shapes_stiffness"] = f64(stored.shape_stiffness)
        ctx.sim.add_term(self.kind, name, params)
        return stored


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def _angles(x: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Bending angles (rad) of ``rows``: 2D the signed angle at the middle particle, 3D the
    dihedral angle across the edge of the first two (as the core measures them)."""
    if rows.shape[1] == 3:
        u, w = x[rows[:, 0]] - x[rows[:, 1]], x[rows[:, 2]] - x[rows[:, 1]]
        return np.arctan2(_cross2(u, w), np.einsum("ij,ij->i", u, w))
    p0, p1, p2, p3 = (x[rows[:, k]] for k in range(4))
    e = p1 - p0
    n1 = np.cross(p2 - p0, p2 - p1)
    n2 = np.cross(p3 - p1, p3 - p0)
    s = np.einsum("ij,ij->i", np.cross(n1, n2), e) / np.linalg.norm(e, axis=1)
    return np.arctan2(s, np.einsum("ij,ij->i", n1, n2))
