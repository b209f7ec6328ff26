"""The base of the force-term records, :class:`Term`, its registry by type key, and the
argument checks the term families share."""
from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, NamedTuple, Union

import numpy as np

from .. import _check
from .._errors import InvalidInputError, InvalidTypeError
from .._parts import RESERVED_NAMES, AttachContext, LoadContext, Part, unique_name

#: Every force term by its type key (``Term.kind``), filled as the term classes are defined.
REGISTRY: dict[str, type[Term]] = {}

ArrayLike = Union[float, int, "np.typing.ArrayLike"]


_finite_float = _check.finite_float


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


class LiveParam(NamedTuple):
    """A parameter of a term that the live viewer and the notebook widget offer as a key pair and
    a slider. A term class lists its own in ``live_params`` (a class attribute), so a new term
    gets its sliders without any table elsewhere naming its class.

    Attributes
    ----------
    name : str
        The parameter's name in the viewer (``"stiffness"``): unique across term classes.
    attribute : str
        The term record's field it scales (``"stiffness"``, ``"g"``, ``"coefficient"``).
    reduce : {"mean", "norm", "value"}
        How the shown value is read: the mean over every term's array field (springs), the
        vector's length in the first term (gravity, m/s²), the first term's scalar (drag).
    keys : tuple of (str, str)
        The viewer's keys that lower and raise it.
    label, unit : str
        Its symbol and SI unit on the heads-up line (``"k"``, ``"N/m"``).
    at_zero : {"critical", "mass", None}
        A parameter that starts at 0 gets a slider up to ``PARAM_RANGE`` times: 1 % of the
        critical damping of the mean spring (``"critical"``), the mean particle mass in kg/s
        (``"mass"``); None: no slider from 0.
    rank : int
        Its place on the heads-up line and among the sliders (lower first).
    """

    name: str
    attribute: str
    reduce: str
    keys: tuple[str, str]
    label: str
    unit: str
    at_zero: str | None = None
    rank: int = 100


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
    #: The parameters the live viewer and the notebook widget offer for this term
    #: (:class:`LiveParam`); none by default.
    live_params: ClassVar[tuple[LiveParam, ...]] = ()

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
        if isinstance(self.name, str):  # text the core can take (unique_name checks the type)
            _check.text("name", self.name)
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

    def _state(self, sim: Any) -> dict[str, np.ndarray]:
        """``{"history": ...}`` where the core keeps the term's own state (contacts: spins and
        springs; DFSPH: the solvers' warm starts), else ``{}``."""
        history = sim.term_history(self.name)
        return {} if history is None else {"history": history}

    def _set_state(self, sim: Any, arrays: Any) -> None:
        if "history" in arrays:
            sim.set_term_history(self.name, np.ascontiguousarray(arrays["history"], dtype=np.float64))

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
