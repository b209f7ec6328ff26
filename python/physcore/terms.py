"""Force terms and colliders: plain, immutable descriptions that a :class:`~physcore.Scene` adds.

A scene computes only the terms it holds. Every term validates its own arguments when it is
constructed; what depends on the scene (dimension, particle indices) is checked by
:meth:`Scene.add`, before anything changes.

Examples
--------
>>> import physcore as pc
>>> scene = pc.Scene(dim=2, dt=1e-3, threads=1)
>>> scene.add_particles([[0.0, 1.0]], [[1.0, 0.0]], masses=[2.0])
array([0])
>>> scene.add(pc.Gravity([0.0, -9.81]))
Gravity(g=array([ 0.  , -9.81]), name='gravity')
>>> _ = scene.add(pc.Plane(point=[0.0, 0.0], normal=[0.0, 1.0], restitution=0.5))
>>> scene.step(100)
>>> round(scene.time, 6), bool(scene.positions[0, 1] < 1.0)
(0.1, True)
>>> pc.Gravity([0.0, float("nan")])
Traceback (most recent call last):
...
physcore._errors.InvalidInputError: g: must be finite, got [0.0, nan]
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, ClassVar, Union

import numpy as np

from . import _check, _deprecate
from ._errors import InvalidInputError, InvalidTypeError
from ._parts import RESERVED_NAMES, AttachContext, LoadContext, Part, unique_name

__all__ = [
    "Term",
    "Gravity",
    "Drag",
    "Springs",
    "PairwiseGravity",
    "TreeGravity",
    "ElectricField",
    "Coulomb",
    "MagneticField",
    "GridElectricField",
    "GridMagneticField",
    "XpbdConstraints",
    "Plane",
    "Box",
    "Sphere",
]

#: Every force term by its type key (``Term.kind``), filled as the term classes are defined.
REGISTRY: dict[str, type[Term]] = {}

ArrayLike = Union[float, int, "np.typing.ArrayLike"]


def _finite_float(value: object, arg: str, *, minimum: float | None = None, strict: bool = False) -> float:
    v = _check.real(arg, value)  # TypeError for bool/str/None; an int beyond float64 is refused
    if not np.isfinite(v):
        raise InvalidInputError(f"{arg}: must be finite, got {v}")
    if minimum is not None and (v < minimum or (strict and v == minimum)):
        op = ">" if strict else ">="
        raise InvalidInputError(f"{arg}: must be {op} {minimum}, got {v}")
    return v


def _int_array(arg: str, value: object) -> np.ndarray:
    """A flat int64 array of integers (an empty array of any dtype too), refused by name."""
    a = _check.array(arg, value).reshape(-1)
    if a.size == 0:
        return np.zeros(0, np.int64)
    if a.dtype.kind not in "iu":
        raise InvalidTypeError(f"{arg}: expected integers, got dtype {a.dtype}")
    if a.dtype.kind == "u" and a.max() > np.iinfo(np.int64).max:
        raise InvalidInputError(f"{arg}: {int(a.max())} is beyond int64")
    return a.astype(np.int64)


def _vector(value: object, arg: str) -> np.ndarray:
    try:
        a = np.asarray(value)
    except Exception as exc:  # pragma: no cover - numpy raises many kinds
        raise InvalidTypeError(f"{arg}: expected a sequence of 2 or 3 numbers") from exc
    if a.dtype.kind not in "iuf" or a.dtype == bool:
        raise InvalidTypeError(f"{arg}: expected real numbers, got dtype {a.dtype}")
    if a.ndim != 1 or a.shape[0] not in (2, 3):
        raise InvalidInputError(f"{arg}: expected shape (2,) or (3,), got {a.shape}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{arg}: must be finite, got {a.tolist()}")
    a.setflags(write=False)
    return a


def _per_spring(value: object, m: int, arg: str) -> np.ndarray:
    a = _check.real_array(arg, value)
    a = a.astype(np.float64)
    if a.ndim == 0:
        a = np.full(m, float(a))
    if a.shape != (m,):
        raise InvalidInputError(f"{arg}: expected a scalar or shape ({m},), got {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        bad = int(np.flatnonzero(~np.isfinite(a) | (a < 0))[0])
        raise InvalidInputError(f"{arg}: entry {bad} is {a[bad]} (must be finite and >= 0)")
    a.setflags(write=False)
    return a


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)
    return bool(a == b)


def _hashable(v: object) -> object:
    return (v.dtype.str, v.shape, v.tobytes()) if isinstance(v, np.ndarray) else v


class Term(Part):
    """Base of the force-term records: the parts of the ``"terms"`` section of a scene file (see
    :mod:`physcore._parts`). A subclass registers itself by its type key
    (``class Gravity(Term, kind="gravity")``) and describes itself completely, so that adding a
    term to physcore touches only its own files: how it attaches to a scene (:meth:`_attach`,
    given an :class:`~physcore._parts.AttachContext` and the name it joins under), what a scene
    file holds of it (:attr:`record_fields`, :attr:`record_arrays`, :meth:`_record`) and how it
    is rebuilt from a file (:meth:`_load`, given a :class:`~physcore._parts.LoadContext`).
    Records compare by value (arrays element-wise) and are immutable.
    """

    section: ClassVar[str] = "terms"

    #: The term's type key in scene files, unique across terms.
    kind: ClassVar[str] = ""
    #: Scalar fields a scene file holds in ``meta.terms[k]`` (besides ``type`` and ``name``), by
    #: the kind of value the loader checks (``"number"``, ``"vector"``, ``"int"``, ...).
    record_fields: ClassVar[dict[str, str]] = {}
    #: Record fields a file may lack (written by an older physcore): name -> kind, as
    #: ``record_fields``; the term's ``_load`` supplies the default.
    record_fields_optional: ClassVar[dict[str, str]] = {}
    #: Array members ``term{k}_{field}`` of a scene file: field -> (dtype, axes). An axis named
    #: after a record field takes its size from it, ``"D"`` is the dimension, and any other name
    #: is a size the term's arrays share.
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {}
    #: Array members a file may hold or not, as ``record_arrays`` (a DFSPH fluid's warm starts,
    #: which files from before DFSPH and WCSPH fluids do not have).
    record_optional: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {}
    #: True when the term owns a run of the scene's particles (``first``, ``count`` in its record).
    owns_particles: ClassVar[bool] = False

    name: str

    def __init_subclass__(cls, kind: str = "", **kwargs: Any) -> None:
        if kind:
            if kind in REGISTRY:
                raise InvalidTypeError(f"kind: {kind!r} is already the key of {REGISTRY[kind].__name__}")
            cls.kind = kind
            cls.part_kind = kind  # Part.__init_subclass__ registers it in physcore._parts.PARTS
            REGISTRY[kind] = cls
        super().__init_subclass__(**kwargs)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(
            _same(getattr(self, f.name), getattr(other, f.name)) for f in dataclasses.fields(self) if f.compare
        )

    def __hash__(self) -> int:
        return hash((type(self), *(_hashable(getattr(self, f.name)) for f in dataclasses.fields(self) if f.compare)))

    # ------------------------------------------------------------ the protocol of a term type
    def _claim_name(self, ctx: AttachContext) -> str:
        """A term whose name is taken (by another term, or reserved) gets ``_2``, ``_3``, ..."""
        return unique_name(self.name, ctx.names["terms"] | RESERVED_NAMES)

    def _attach(self, ctx: AttachContext, name: str) -> Term:
        """Check the term against the scene (``ctx``), add it to the core under ``name`` and
        return the record as stored. Raises before changing anything. By default the core term
        of the same ``kind`` gets the ``record_fields`` as its parameters, each ``"vector"`` one
        checked against the scene's dimension; terms with more to check (indices, particles)
        override it."""
        params = {}
        for f, kind in self.record_fields.items():
            value = getattr(self, f)
            if kind == "vector":
                _same_dim(ctx, f, value)
            params[f] = value
        ctx.sim.add_term(self.kind, name, params)
        return dataclasses.replace(self, name=name)

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """``{"type", "name", **record_fields}`` and the record's arrays, plus ``history``: the
        term's own state in the core, where it keeps one (contacts: spins and springs; DFSPH:
        the solvers' warm starts)."""
        record, members = self._record()
        history = sim.term_history(self.name)
        if history is not None:
            members = {**members, "history": history}
        return {"type": self.kind, "name": self.name, **record}, members

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """What a scene file holds of this term: the ``record_fields`` (JSON values) and the
        ``record_arrays``."""
        meta = {}
        for f in self.record_fields:
            v = getattr(self, f)
            meta[f] = v.tolist() if isinstance(v, np.ndarray) else v
        return meta, {a: np.asarray(getattr(self, a)) for a in self.record_arrays}

    @classmethod
    def record_api_names(cls, k: int, ctx: str) -> dict[str, str]:
        """Error-message names: the file fields that argument names of :meth:`_load` stand for,
        beyond ``record_fields`` (as ``{ctx}.{field}``) and ``record_arrays`` (``term{k}_{field}``)."""
        return {}

    @classmethod
    def _load_names(cls, ctx: LoadContext, arrays: Any) -> tuple[str, dict[str, str]]:
        members = {a: f"term{ctx.index}_{a}" for a in arrays}
        return ctx.field, {**members, **cls.record_api_names(ctx.index, ctx.field)}

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        """Rebuild the term from its checked record and add it to the scene (``ctx.add``)."""
        fields = {f: meta[f] for f in cls.record_fields}
        ctx.add(cls(**fields, **arrays, name=meta["name"]))


def _same_dim(ctx: AttachContext, arg: str, v: np.ndarray) -> None:
    if v.shape[0] != ctx.dim:
        raise InvalidInputError(f"{arg}: has {v.shape[0]} components, the scene is {ctx.dim}D")


@dataclass(frozen=True, eq=False)
class Gravity(Term, kind="gravity"):
    """Uniform gravity: force ``m g`` on every free particle; potential ``-m g·x``.

    Parameters
    ----------
    g : array_like, shape (dim,)
        Gravitational acceleration, m/s². Earth: ``[0, -9.81]`` (2D) or ``[0, 0, -9.81]`` (3D).
    name : str
        Key of this term in the energy books.
    """

    g: np.ndarray
    name: str = field(default="gravity", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"g": "vector"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "g", _vector(self.g, "g"))


@dataclass(frozen=True, eq=False)
class Drag(Term, kind="drag"):
    """Linear (Stokes) drag ``F = -b v`` on every free particle; dissipates ``b |v|²``.

    Parameters
    ----------
    coefficient : float
        Drag coefficient ``b`` ≥ 0, kg/s.
    name : str
        Key of this term in the energy books.
    """

    coefficient: float
    name: str = field(default="drag", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"coefficient": "number"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "coefficient", _finite_float(self.coefficient, "coefficient", minimum=0.0))


@_deprecate.record(('i', 'j', 'stiffness', 'damping', 'rest_length'), keep=2)
@dataclass(frozen=True, eq=False)
class Springs(Term, kind="springs"):
    """Hookean springs with dashpot damping along the spring axis.

    Force on ``i`` from spring ``(i, j)``: ``f = [k (L - L0) + c (v_j - v_i)·n] n`` with
    ``n = (x_j - x_i)/L`` (and ``-f`` on ``j``); potential ``½ k (L - L0)²``; the dashpot
    dissipates ``c ((v_j - v_i)·n)²``. Coincident endpoints exert no force (the axis is undefined).

    Parameters
    ----------
    i, j : array_like of int, shape (M,)
        Particle indices of the two ends of each spring (``i != j``, both < ``n_particles``).
    stiffness : float or array_like, shape (M,)
        ``k`` ≥ 0, N/m.
    damping : float or array_like, shape (M,)
        Dashpot coefficient ``c`` ≥ 0, N·s/m. Default 0.
    rest_length : None, float or array_like, shape (M,)
        ``L0`` ≥ 0, m. ``None`` (default) takes each spring's length at the moment it is added.
    name : str
        Key of this term in the energy books.

    Raises
    ------
    TypeError
        Non-integer indices or non-numeric parameters.
    ValueError
        Mismatched lengths, negative indices, ``i == j``, negative or non-finite parameters.
    """

    i: np.ndarray
    j: np.ndarray
    _: KW_ONLY
    stiffness: ArrayLike = field(default=1.0)
    damping: ArrayLike = 0.0
    rest_length: ArrayLike | None = None
    name: str = field(default="springs", kw_only=True)

    def __post_init__(self) -> None:
        idx = []
        for arg, val in (("i", self.i), ("j", self.j)):
            a = _check.array(arg, val)
            if a.dtype.kind not in "iu" and not (a.size == 0 and a.dtype.kind == "f"):
                raise InvalidTypeError(f"{arg}: expected integer particle indices, got dtype {a.dtype}")
            if a.ndim != 1:
                raise InvalidInputError(f"{arg}: expected shape (M,), got {a.shape}")
            a = a.astype(np.int64)
            if a.size and a.min() < 0:
                raise InvalidInputError(f"{arg}: indices must be >= 0, got {int(a.min())}")
            a.setflags(write=False)
            idx.append(a)
        i, j = idx
        if i.shape != j.shape:
            raise InvalidInputError(f"j: has {j.shape[0]} entries but i has {i.shape[0]}")
        same = np.flatnonzero(i == j)
        if same.size:
            raise InvalidInputError(f"i/j: spring {int(same[0])} joins particle {int(i[same[0]])} to itself")
        m = i.shape[0]
        object.__setattr__(self, "i", i)
        object.__setattr__(self, "j", j)
        object.__setattr__(self, "stiffness", _per_spring(self.stiffness, m, "stiffness"))
        object.__setattr__(self, "damping", _per_spring(self.damping, m, "damping"))
        if self.rest_length is not None:
            object.__setattr__(self, "rest_length", _per_spring(self.rest_length, m, "rest_length"))

    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "i": ("i8", ("M",)),
        "j": ("i8", ("M",)),
        "stiffness": ("f8", ("M",)),
        "damping": ("f8", ("M",)),
        "rest_length": ("f8", ("M",)),
    }

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def record_api_names(cls, k: int, ctx: str) -> dict[str, str]:
        return {"i/j": f"term{k}_i"}

    def _attach(self, ctx: AttachContext, name: str) -> Springs:
        n = ctx.n_particles
        for arg in ("i", "j"):
            a = getattr(self, arg)
            if a.size and a.max() >= n:
                raise InvalidInputError(f"{arg}: index {int(a.max())} is out of range for {n} particles")
        rest = self.rest_length
        if rest is None:
            x = ctx.positions
            with np.errstate(over="ignore", invalid="ignore"):  # refused by name just below
                rest = np.linalg.norm(x[self.j] - x[self.i], axis=1) if len(self) else np.zeros(0)
            if not np.all(np.isfinite(rest)):
                k = int(np.flatnonzero(~np.isfinite(rest))[0])
                raise InvalidInputError(
                    f"rest_length: spring {k}'s current length is beyond float64; give rest_length= (m)"
                )
        stored = dataclasses.replace(self, rest_length=rest, name=name)
        ctx.sim.add_term(
            "springs",
            name,
            {
                "i": stored.i.astype(np.uint32),
                "j": stored.j.astype(np.uint32),
                "stiffness": np.ascontiguousarray(stored.stiffness),
                "damping": np.ascontiguousarray(stored.damping),
                "rest_length": np.ascontiguousarray(stored.rest_length),
            },
        )
        return stored


@_deprecate.record(('G', 'softening'), keep=1)
@dataclass(frozen=True, eq=False)
class PairwiseGravity(Term, kind="pairwise_gravity"):
    """Newtonian gravity between every pair of particles, with Plummer softening.

    ``a_i = G Σ_j m_j (x_j - x_i) / (|x_j - x_i|² + ε²)^{3/2}`` and
    ``U = -G Σ_{i<j} m_i m_j / (|x_j - x_i|² + ε²)^{1/2}`` (Plummer 1911; Aarseth, *Gravitational
    N-body simulations*, 2003, eq. 2.4). Direct summation, O(N²), parallel over particles.
    Pinned particles attract but do not move.

    Parameters
    ----------
    G : float
        Gravitational constant > 0, m³/(kg·s²). Default 1 (N-body units).
    softening : float
        Plummer softening length ε ≥ 0, m. Default 0.
    name : str
        Key of this term in the energy books.
    """

    G: float = 1.0
    _: KW_ONLY
    softening: float = 0.0
    name: str = field(default="pairwise_gravity", kw_only=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, "G", _finite_float(self.G, "G", minimum=0.0, strict=True))
        object.__setattr__(self, "softening", _finite_float(self.softening, "softening", minimum=0.0))

    record_fields: ClassVar[dict[str, str]] = {"G": "number", "softening": "number"}


@_deprecate.record(('G', 'softening', 'theta'), keep=1)
@dataclass(frozen=True, eq=False)
class TreeGravity(Term, kind="tree_gravity"):
    """Newtonian gravity with Plummer softening by a Barnes–Hut tree (an octree in 3D, a quadtree
    in 2D; Barnes & Hut, *Nature* 324 (1986) 446–449): O(N log N) instead of
    :class:`PairwiseGravity`'s O(N²), to the accuracy set by the opening angle ``theta``.

    The force law is :class:`PairwiseGravity`'s,
    ``a_i = G Σ_j m_j (x_j - x_i) / (|x_j - x_i|² + ε²)^{3/2}``, with the particles of each
    distant tree node replaced by one point of their total mass at their centre of mass
    (monopoles). A node of side ``l`` (its tight bounding box's longest side) whose centre of mass
    lies ``δ`` from the box's centre is used whole when it is farther than
    ``max(l/θ, l·√dim/2) + δ`` from the receiver (the ``l/θ + δ`` criterion of Barnes' treecode,
    which guards against the failure of the plain ``l/d < θ`` test found by Salmon & Warren,
    *J. Comput. Phys.* 111 (1994) 136; a node containing the receiver is always opened).
    ``theta=0`` opens every node: the direct sum, to round-off. Receivers share one tree walk per
    group of up to 128 neighbours (Barnes, *J. Comput. Phys.* 87 (1990) 161), so the error is at
    most that of the per-particle walk. The tree is rebuilt in parallel every evaluation and the
    results are bit-identical for any thread count. Pinned particles attract but do not move.

    The potential in the energy books is the tree's approximation of
    ``U = -G Σ_{i<j} m_i m_j / (|x_j - x_i|² + ε²)^{1/2}``, as accurate as the forces (exact at
    ``theta=0``). Tree forces are not exactly equal and opposite, so momentum and energy are
    conserved only to the force error (see "Tree gravity" in the README for measured errors per
    ``theta``: on a 3D Plummer sphere of 10⁴ bodies the median relative force error is about 6e-4
    at ``theta=0.5``; in 2D about ten times more at the same ``theta``). Computes in float64
    whatever the scene's precision.

    Parameters
    ----------
    G : float
        Gravitational constant > 0, m³/(kg·s²). Default 1 (N-body units).
    softening : float
        Plummer softening length ε ≥ 0, m. Default 0.
    theta : float
        Opening angle θ ≥ 0 (dimensionless). Smaller is more accurate and slower; 0 is the
        direct sum. Default 0.5.
    name : str
        Key of this term in the energy books.

    Raises
    ------
    InvalidInputError
        ``G`` not finite or ≤ 0, ``softening`` or ``theta`` not finite or < 0, or ``softening²``
        beyond float64, naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=3, dt=1e-3, threads=1)
    >>> _ = s.add_particles([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], masses=[1.0, 1.0])
    >>> s.add(pc.TreeGravity(G=1.0, theta=0.5))
    TreeGravity(G=1.0, softening=0.0, theta=0.5, name='tree_gravity')
    >>> pc.TreeGravity(theta=-0.1)
    Traceback (most recent call last):
    ...
    physcore._errors.InvalidInputError: theta: must be >= 0.0, got -0.1
    """

    G: float = 1.0
    _: KW_ONLY
    softening: float = 0.0
    theta: float = 0.5
    name: str = field(default="tree_gravity", kw_only=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, "G", _finite_float(self.G, "G", minimum=0.0, strict=True))
        object.__setattr__(self, "softening", _finite_float(self.softening, "softening", minimum=0.0))
        if not math.isfinite(self.softening * self.softening):
            raise InvalidInputError(f"softening: {self.softening} is too large: its square overflows float64")
        object.__setattr__(self, "theta", _finite_float(self.theta, "theta", minimum=0.0))

    record_fields: ClassVar[dict[str, str]] = {"G": "number", "softening": "number", "theta": "number"}


@dataclass(frozen=True, eq=False)
class ElectricField(Term, kind="uniform_electric_field"):
    """A uniform electric field acting on charged particles: force ``q E`` on every free
    particle, potential ``-q E·x`` (Griffiths, *Introduction to Electrodynamics*, 4th ed., eqs.
    2.21 and 4.14). The charges are the scene's ``"charge"`` attribute
    (:meth:`Scene.set_attribute`); particles without one feel nothing.

    Parameters
    ----------
    E : array_like, shape (dim,)
        Field strength, V/m (= N/C).
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=2, dt=1e-3, threads=1)
    >>> _ = s.add_particles([[0.0, 0.0], [0.0, 1.0]], masses=[1.0, 1.0])
    >>> s.set_attribute("charge", [1e-3, -1e-3])          # C
    >>> _ = s.add(pc.ElectricField([100.0, 0.0]))          # V/m: a = qE/m = ±0.1 m/s²
    >>> s.step(1000)
    >>> s.positions[:, 0].round(6)                          # x = a t²/2 after 1 s
    array([ 0.05, -0.05])
    """

    E: np.ndarray
    name: str = field(default="electric_field", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"E": "vector"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "E", _vector(self.E, "E"))


#: Coulomb's constant 1/(4π ε0), N·m²/C² (CODATA 2018).
COULOMB_K = 8.9875517923e9


@_deprecate.record(('k', 'softening'), keep=1)
@dataclass(frozen=True, eq=False)
class Coulomb(Term, kind="coulomb"):
    """The Coulomb force between every pair of charged particles, with Plummer softening.

    ``F_i = k q_i Σ_j q_j (x_i - x_j) / (|x_i - x_j|² + ε²)^{3/2}`` and
    ``U = k Σ_{i<j} q_i q_j / (|x_i - x_j|² + ε²)^{1/2}`` (Griffiths, *Introduction to
    Electrodynamics*, 4th ed., eqs. 2.1 and 2.42, softened as Plummer 1911): like charges repel,
    unlike attract. Direct summation, O(N²), on the same SIMD kernel as
    :class:`PairwiseGravity` (the charges are its source weights). The charges are the scene's
    ``"charge"`` attribute (:meth:`Scene.set_attribute`): a scene without it feels no force and
    holds no potential, and a particle of charge 0 neither pushes nor is pushed. Pinned
    particles push the others but do not move.

    Parameters
    ----------
    k : float
        Coulomb's constant > 0, N·m²/C². Default ``8.9875517923e9`` (SI); pass ``k=1`` in
        scaled (Gaussian-like) units.
    softening : float
        Plummer softening length ε ≥ 0, m. Default 0 (two charges at one point then exert no
        force on each other).
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=2, dt=1e-3, threads=1)
    >>> _ = s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, 1.0])
    >>> s.set_attribute("charge", [1.0, 1.0])
    >>> _ = s.add(pc.Coulomb(k=1.0))
    >>> round(s.energy().potential["coulomb"], 12)           # k q q / r
    1.0
    """

    k: float = COULOMB_K
    _: KW_ONLY
    softening: float = 0.0
    name: str = field(default="coulomb", kw_only=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, "k", _finite_float(self.k, "k", minimum=0.0, strict=True))
        object.__setattr__(self, "softening", _finite_float(self.softening, "softening", minimum=0.0))

    record_fields: ClassVar[dict[str, str]] = {"k": "number", "softening": "number"}


def _axial(value: object, arg: str) -> np.ndarray:
    """A magnetic field as given: a number (B_z, 2D) or 1 or 3 components, finite."""
    a = _check.real_array(arg, value).astype(np.float64)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1 or a.shape[0] not in (1, 3):
        raise InvalidInputError(f"{arg}: expected a number (B_z, 2D) or shape (3,) (3D), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{arg}: must be finite, got {a.tolist()}")
    a.setflags(write=False)
    return a


def _axial_for(ctx: AttachContext, arg: str, b: np.ndarray) -> np.ndarray:
    """``b`` as the scene's dimension takes it: shape (1,) (B_z) in 2D, (3,) in 3D."""
    if ctx.dim == 3:
        if b.shape != (3,):
            raise InvalidInputError(f"{arg}: has {b.shape[0]} component, the scene is 3D (give [Bx, By, Bz])")
        return b
    if b.shape == (3,):
        if b[0] != 0.0 or b[1] != 0.0:
            raise InvalidInputError(
                f"{arg}: in 2D only B_z (out of the plane) acts on motion in the plane; got in-plane components {b[:2].tolist()}"
            )
        b = b[2:].copy()
        b.setflags(write=False)
    return b


@dataclass(frozen=True, eq=False)
class MagneticField(Term, kind="uniform_magnetic_field"):
    """A uniform magnetic field acting on charged particles: the Lorentz force ``q v × B`` on
    every free particle (Griffiths, *Introduction to Electrodynamics*, 4th ed., eq. 5.1). The
    charges are the scene's ``"charge"`` attribute; particles without one feel nothing.

    The force does no work: the term has no potential and dissipates nothing. Use the
    ``"boris"`` integrator, which turns every velocity through B exactly (the speed keeps to
    round-off for any ``dt``); the other integrators take ``q v × B`` as a velocity-dependent
    force (Verlet with a predicted velocity, second order, a slow drift in the speed).

    Parameters
    ----------
    B : float or array_like, shape (3,)
        Field, T. In 2D the out-of-plane component B_z (a number; ``[0, 0, Bz]`` is accepted
        too); in 3D the vector. A charge q > 0 turns clockwise about B at the cyclotron
        frequency ``ω_c = |q| B / m``.
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import math, physcore as pc
    >>> s = pc.Scene(dim=2, integrator="boris", dt=math.pi / 2000, threads=1)
    >>> _ = s.add_particles([[0.0, 0.0]], [[1.0, 0.0]], masses=[1.0])
    >>> s.set_attribute("charge", [1.0])
    >>> _ = s.add(pc.MagneticField(2.0))                  # ω_c = qB/m = 2 rad/s
    >>> s.step(1000)                                        # t = π/2: half a turn
    >>> s.velocities.round(4) + 0.0                         # v reversed
    array([[-1.,  0.]])
    >>> s.positions.round(4) + 0.0                          # clockwise: 2 r_L = 1 m below
    array([[ 0., -1.]])
    """

    B: ArrayLike
    name: str = field(default="magnetic_field", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"B": "axial"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "B", _axial(self.B, "B"))

    def _attach(self, ctx: AttachContext, name: str) -> MagneticField:
        b = _axial_for(ctx, "B", self.B)  # type: ignore[arg-type]
        ctx.sim.add_term(self.kind, name, {"B": b})
        return dataclasses.replace(self, B=b, name=name)


def _grid_frame(origin: object, spacing: object) -> tuple[np.ndarray, np.ndarray]:
    o = _vector(origin, "origin")
    sp = _check.real_array("spacing", spacing).astype(np.float64)
    if sp.ndim == 0:
        sp = np.full(o.shape[0], float(sp))
    if sp.shape != o.shape:
        raise InvalidInputError(f"spacing: expected a number or shape {o.shape} (one per axis of origin), got shape {sp.shape}")
    if not np.all(np.isfinite(sp) & (sp > 0)):
        raise InvalidInputError(f"spacing: must be finite and > 0 on every axis, got {sp.tolist()}")
    sp.setflags(write=False)
    return o, sp


def _grid_values(arg: str, value: object, dim: int, comps: int, alone: bool) -> np.ndarray:
    """Node values of shape (nx, ny[, nz], comps), each axis >= 2 nodes, finite. ``alone``: in 2D
    one component may be given without its axis, (nx, ny)."""
    a = _check.real_array(arg, value).astype(np.float64)
    if alone and a.ndim == dim:
        a = a[..., None]
    want = "(nx, ny" + (", nz" if dim == 3 else "") + f", {comps})"
    if a.ndim != dim + 1 or a.shape[-1] != comps:
        raise InvalidInputError(f"{arg}: expected shape {want} for a {dim}D grid (dim from origin), got {a.shape}")
    if any(n < 2 for n in a.shape[:-1]):
        raise InvalidInputError(f"{arg}: a grid needs at least 2 nodes per axis, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise InvalidInputError(f"{arg}: entry {tuple(int(i) for i in bad)} is {a[tuple(bad)]} (must be finite)")
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


class _GridField(Term):
    """The protocol of the field-map terms: a field on a regular grid (shape (nx, ny[, nz], C)),
    saved as the member ``term{k}_values`` with 4 axes (nz = 1 in 2D), so one record describes
    both dimensions."""

    _field: ClassVar[str]
    origin: np.ndarray
    spacing: np.ndarray

    record_fields: ClassVar[dict[str, str]] = {"origin": "vector", "spacing": "vector"}

    @property
    def dim(self) -> int:
        return int(self.origin.shape[0])

    def _attach(self, ctx: AttachContext, name: str) -> Term:
        _same_dim(ctx, "origin", self.origin)
        v = getattr(self, self._field)
        params = {
            "origin": self.origin,
            "spacing": self.spacing,
            "shape": np.asarray(v.shape[:-1], dtype=np.float64),
            "values": v.reshape(-1),
        }
        ctx.sim.add_term(self.kind, name, params)
        return dataclasses.replace(self, name=name)  # type: ignore[type-var]

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        v = getattr(self, self._field)
        meta = {"origin": self.origin.tolist(), "spacing": self.spacing.tolist()}
        return meta, {"values": v[:, :, None, :] if self.dim == 2 else v}

    @classmethod
    def record_api_names(cls, k: int, ctx: str) -> dict[str, str]:
        return {cls._field: f"term{k}_values"}

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        v = arrays["values"]
        if ctx.dim == 2:
            if v.shape[2] != 1:
                raise InvalidInputError(f"{cls._field}: a 2D grid is saved with one node along z, got shape {v.shape}")
            v = v[:, :, 0, :]
        ctx.add(cls(v, meta["origin"], spacing=meta["spacing"], name=meta["name"]))  # type: ignore[call-arg]


@_deprecate.record(('E', 'origin', 'spacing'), keep=2)
@dataclass(frozen=True, eq=False)
class GridElectricField(_GridField, kind="grid_electric_field"):
    """An electric field given on a regular grid (a field map): force ``q E(x)`` on every free
    charged particle, E interpolated bilinearly (2D) or trilinearly (3D) from the nodes, and
    zero outside the grid's box ``[origin, origin + (n - 1) spacing]``. A uniform field is
    reproduced exactly, a linear one to round-off.

    The field is taken as given, not as the gradient of a potential (it need not be
    curl-free), so the term holds no potential energy and its work is in no energy book: the
    books' total changes by it. A conservative field is better given by its potential.

    Parameters
    ----------
    E : array_like, shape (nx, ny, 2) or (nx, ny, nz, 3)
        The field at the nodes, V/m: ``E[i, j(, k)]`` is at ``origin + (i, j(, k)) * spacing``.
        At least 2 nodes per axis.
    origin : array_like, shape (dim,)
        Position of node (0, 0(, 0)), m. Its length is the grid's dimension.
    spacing : float or array_like, shape (dim,)
        Node spacing > 0 per axis, m.
    name : str
        Key of this term in the energy books.
    """

    E: np.ndarray
    origin: np.ndarray
    _: KW_ONLY
    spacing: ArrayLike
    name: str = field(default="grid_electric_field", kw_only=True)

    _field: ClassVar[str] = "E"
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {"values": ("f8", ("X", "Y", "Z", "D"))}

    def __post_init__(self) -> None:
        o, sp = _grid_frame(self.origin, self.spacing)
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "spacing", sp)
        object.__setattr__(self, "E", _grid_values("E", self.E, o.shape[0], o.shape[0], alone=False))


@_deprecate.record(('B', 'origin', 'spacing'), keep=2)
@dataclass(frozen=True, eq=False)
class GridMagneticField(_GridField, kind="grid_magnetic_field"):
    """A magnetic field given on a regular grid (a field map): the Lorentz force
    ``q v × B(x)`` on every free charged particle, B interpolated bilinearly (2D) or
    trilinearly (3D) from the nodes, and zero outside the grid's box. Like
    :class:`MagneticField` it does no work, has no potential, and the ``"boris"`` integrator
    turns the velocities through it exactly (B taken at each particle's position).

    Parameters
    ----------
    B : array_like, shape (nx, ny) or (nx, ny, 1) in 2D (B_z), (nx, ny, nz, 3) in 3D
        The field at the nodes, T. At least 2 nodes per axis.
    origin : array_like, shape (dim,)
        Position of node (0, 0(, 0)), m. Its length is the grid's dimension.
    spacing : float or array_like, shape (dim,)
        Node spacing > 0 per axis, m.
    name : str
        Key of this term in the energy books.
    """

    B: np.ndarray
    origin: np.ndarray
    _: KW_ONLY
    spacing: ArrayLike
    name: str = field(default="grid_magnetic_field", kw_only=True)

    _field: ClassVar[str] = "B"
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {"values": ("f8", ("X", "Y", "Z", "C"))}

    def __post_init__(self) -> None:
        o, sp = _grid_frame(self.origin, self.spacing)
        dim = o.shape[0]
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "spacing", sp)
        object.__setattr__(self, "B", _grid_values("B", self.B, dim, 1 if dim == 2 else 3, alone=dim == 2))


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
    ``v = (x − x_prev)/h``. A compliance is a material constant: the static stretch of a distance
    constraint under a force F is ``F α`` for any step, substep count or iteration count. ``α =
    0`` is infinitely stiff. Kinds are projected in the order of the parameters below, each by
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
        about them. (Or a flat index array with ``shape_sizes``.)
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
    dissipated energy (see the README's XPBD section).

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
    Only ``Scene(integrator="xpbd")`` projects the constraints; under any other integrator the
    term is inert (no force, no projection) and only reports its potential.

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


@_deprecate.record(('point', 'normal', 'restitution', 'friction'), keep=2)
@dataclass(frozen=True)
class Plane(Part):
    """Half-space collider ``{x : (x - point)·normal ≥ 0}`` with restitution and friction.

    After each step a particle below the plane is projected onto it; if moving into the plane its
    normal velocity becomes ``-e v_n`` and its tangential speed drops by ``μ (1 + e) |v_n|``
    (Coulomb friction on the collision impulse, never reversing it). The energy removed is booked
    under ``"collisions"`` in :meth:`Scene.energy`.

    Parameters
    ----------
    point : array_like, shape (dim,)
        A point on the plane, m.
    normal : array_like, shape (dim,)
        Normal pointing into the allowed side (normalised for you; must be non-zero).
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]. Default 0.5.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.
    """

    point: np.ndarray
    normal: np.ndarray
    _: KW_ONLY
    restitution: float = 0.5
    friction: float = 0.0

    def __post_init__(self) -> None:
        point = _vector(self.point, "point")
        normal = _vector(self.normal, "normal")
        if point.shape != normal.shape:
            raise InvalidInputError(f"normal: has {normal.shape[0]} components, point has {point.shape[0]}")
        if not np.any(normal):
            raise InvalidInputError("normal: must be non-zero")
        with np.errstate(over="ignore", under="ignore"):
            norm = float(np.linalg.norm(normal))
        if not 1e-150 < norm < 1e150:
            # |normal|² would overflow or underflow (a zero or infinite "unit" normal): scale first.
            normal = normal / np.abs(normal).max()
            norm = float(np.linalg.norm(normal))
        unit = normal / norm
        unit.setflags(write=False)
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", unit)
        e = _finite_float(self.restitution, "restitution", minimum=0.0)
        if e > 1.0:
            raise InvalidInputError(f"restitution: must be in [0, 1], got {e}")
        object.__setattr__(self, "restitution", e)
        object.__setattr__(self, "friction", _finite_float(self.friction, "friction", minimum=0.0))

    # ------------------------------------------------------------ the part protocol
    section: ClassVar[str] = "planes"
    part_kind: ClassVar[str] = "plane"

    def _attach(self, ctx: AttachContext, name: None) -> Plane:
        for arg in ("point", "normal"):
            _same_dim(ctx, arg, getattr(self, arg))
        ctx.sim.add_plane(self.point.tolist(), self.normal.tolist(), self.restitution, self.friction)
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {"point": self.point.tolist(), "normal": self.normal.tolist(), "restitution": self.restitution, "friction": self.friction}, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ctx.add(cls(entry["point"], entry["normal"], restitution=entry["restitution"], friction=entry["friction"]))


@_deprecate.record(('lower', 'upper', 'restitution', 'friction'), keep=2)
@dataclass(frozen=True)
class Box(Part):
    """Axis-aligned box collider that keeps particles inside ``[lower, upper]`` (a tank or room).

    One pass over the particles handles all faces; each face acts like a :class:`Plane` with
    the same restitution and friction (a particle found outside is projected onto the face; if
    it moves outward its normal velocity becomes ``-e v_n`` and its tangential speed drops by
    ``μ (1 + e) |v_n|``). The energy removed is booked under ``"collisions"``.

    Parameters
    ----------
    lower, upper : array_like, shape (dim,)
        Corners, m; ``upper > lower`` on every axis.
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]. Default 0.5.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.
    """

    lower: np.ndarray
    upper: np.ndarray
    _: KW_ONLY
    restitution: float = 0.5
    friction: float = 0.0

    def __post_init__(self) -> None:
        lo = _vector(self.lower, "lower")
        hi = _vector(self.upper, "upper")
        if lo.shape != hi.shape:
            raise InvalidInputError(f"upper: has {hi.shape[0]} components, lower has {lo.shape[0]}")
        if not np.all(hi > lo):
            raise InvalidInputError(f"upper: must be > lower on every axis, got {hi.tolist()} and {lo.tolist()}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        e = _finite_float(self.restitution, "restitution", minimum=0.0)
        if e > 1.0:
            raise InvalidInputError(f"restitution: must be in [0, 1], got {e}")
        object.__setattr__(self, "restitution", e)
        object.__setattr__(self, "friction", _finite_float(self.friction, "friction", minimum=0.0))

    def faces(self) -> list[Plane]:
        """The box's faces as inward-facing :class:`Plane` objects (for drawing)."""
        out = []
        for k in range(self.lower.shape[0]):
            n = np.zeros(self.lower.shape[0])
            n[k] = 1.0
            out.append(Plane(self.lower, n, restitution=self.restitution, friction=self.friction))
            out.append(Plane(self.upper, -n, restitution=self.restitution, friction=self.friction))
        return out

    # ------------------------------------------------------------ the part protocol
    section: ClassVar[str] = "boxes"
    part_kind: ClassVar[str] = "box"

    def _attach(self, ctx: AttachContext, name: None) -> Box:
        for arg in ("lower", "upper"):
            _same_dim(ctx, arg, getattr(self, arg))
        ctx.sim.add_box(self.lower.tolist(), self.upper.tolist(), self.restitution, self.friction)
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {"lower": self.lower.tolist(), "upper": self.upper.tolist(), "restitution": self.restitution, "friction": self.friction}, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ctx.add(cls(entry["lower"], entry["upper"], restitution=entry["restitution"], friction=entry["friction"]))


@_deprecate.record(('center', 'radius', 'restitution', 'friction', 'inside'), keep=2)
@dataclass(frozen=True)
class Sphere(Part):
    """Sphere collider (a disc in a 2D scene) that keeps particles outside it, a ball they land on
    and slide off, or with ``inside=True`` inside it, a bowl.

    After each step a particle found on the wrong side of the surface (``|x - center| <
    radius``; inside: ``>``) is projected onto it along the radius; if it is moving into the
    sphere (out of the bowl) its normal velocity becomes ``-e v_n`` and its tangential speed
    drops by ``μ (1 + e) |v_n|`` (Coulomb friction on the collision impulse, never reversing it),
    as at a :class:`Plane` tangent there. The energy removed is booked under ``"collisions"`` in
    :meth:`Scene.energy`.

    Parameters
    ----------
    center : array_like, shape (dim,)
        Centre, m.
    radius : float
        Radius, m; > 0, with a square that fits float64.
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]. Default 0.5.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.
    inside : bool
        Keep particles inside the sphere instead of outside. Default False.

    Raises
    ------
    TypeError
        A non-numeric ``center``, ``radius``, ``restitution`` or ``friction`` (bool, str, None);
        ``inside`` not a bool.
    InvalidInputError
        (a ``ValueError``) naming the argument: ``center`` not 2 or 3 finite numbers, ``radius``
        not finite and > 0 (or its square beyond float64), ``restitution`` outside [0, 1],
        ``friction`` < 0 or not finite.

    Examples
    --------
    >>> import physcore as pc
    >>> pc.Sphere([0.0, 0.0, 0.3], 0.3, friction=0.4).radius
    0.3
    """

    center: np.ndarray
    radius: float
    _: KW_ONLY
    restitution: float = 0.5
    friction: float = 0.0
    inside: bool = False

    def __post_init__(self) -> None:
        center = _vector(self.center, "center")
        r = _finite_float(self.radius, "radius", minimum=0.0, strict=True)
        if not math.isfinite(r * r):
            raise InvalidInputError(f"radius: {r} m has a square beyond float64")
        if not isinstance(self.inside, (bool, np.bool_)):
            raise InvalidTypeError(f"inside: expected True or False, got {type(self.inside).__name__}")
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "radius", r)
        e = _finite_float(self.restitution, "restitution", minimum=0.0)
        if e > 1.0:
            raise InvalidInputError(f"restitution: must be in [0, 1], got {e}")
        object.__setattr__(self, "restitution", e)
        object.__setattr__(self, "friction", _finite_float(self.friction, "friction", minimum=0.0))
        object.__setattr__(self, "inside", bool(self.inside))

    # ------------------------------------------------------------ the part protocol
    section: ClassVar[str] = "spheres"
    part_kind: ClassVar[str] = "sphere"

    def _attach(self, ctx: AttachContext, name: None) -> Sphere:
        _same_dim(ctx, "center", self.center)
        ctx.sim.add_sphere(self.center.tolist(), self.radius, self.inside, self.restitution, self.friction)
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        record = {"center": self.center.tolist(), "radius": self.radius, "restitution": self.restitution, "friction": self.friction, "inside": self.inside}
        return record, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ctx.add(cls(entry["center"], entry["radius"], restitution=entry["restitution"], friction=entry["friction"], inside=entry["inside"]))
