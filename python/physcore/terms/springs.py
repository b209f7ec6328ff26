"""Hookean springs with dashpot damping: :class:`Springs`."""
from __future__ import annotations

import dataclasses
from dataclasses import KW_ONLY, dataclass, field
from typing import ClassVar

import numpy as np

from .. import _check, _deprecate
from .._errors import InvalidInputError, InvalidTypeError, allocating
from .._parts import AttachContext
from ._base import ArrayLike, LiveParam, Term, _per_spring


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
    OutOfMemoryError
        (a ``MemoryError``) The arrays would not fit (broadcast indices of a billion springs).
    """

    i: np.ndarray
    j: np.ndarray
    _: KW_ONLY
    stiffness: ArrayLike = field(default=1.0)
    damping: ArrayLike = 0.0
    rest_length: ArrayLike | None = None
    name: str = field(default="springs", kw_only=True)

    def __post_init__(self) -> None:
        views = []
        for arg, val in (("i", self.i), ("j", self.j)):
            a = _check.array(arg, val, sized=False)  # the springs' need is asked for below
            if a.dtype.kind not in "iu" and not (a.size == 0 and a.dtype.kind == "f"):
                raise InvalidTypeError(f"{arg}: expected integer particle indices, got dtype {a.dtype}")
            if a.ndim != 1:
                raise InvalidInputError(f"{arg}: expected shape (M,), got {a.shape}")
            views.append(a)
        if views[0].shape != views[1].shape:
            raise InvalidInputError(f"j: has {views[1].shape[0]} entries but i has {views[0].shape[0]}")
        m = views[0].shape[0]
        # Broadcast indices can stand for more springs than memory holds: the record's five
        # (M,) arrays of 8 bytes are asked for before any copy.
        _check.room("i/j", 40 * m, f"{m:,} springs")
        idx = []
        for arg, a in zip(("i", "j"), views, strict=True):
            if a.dtype.kind == "u" and a.size and int(a.max()) > np.iinfo(np.int64).max:  # before the cast wraps it negative
                raise InvalidInputError(f"{arg}: index {int(a.max())} is beyond any particle count")
            with allocating(arg, f"a copy of {arg} as int64"):
                a = a.astype(np.int64)
            if a.size and a.min() < 0:
                raise InvalidInputError(f"{arg}: indices must be >= 0, got {int(a.min())}")
            a.setflags(write=False)
            idx.append(a)
        i, j = idx
        same = np.flatnonzero(i == j)
        if same.size:
            raise InvalidInputError(f"i/j: spring {int(same[0])} joins particle {int(i[same[0]])} to itself")
        object.__setattr__(self, "i", i)
        object.__setattr__(self, "j", j)
        for arg in ("stiffness", "damping", "rest_length"):
            if getattr(self, arg) is not None:  # rest_length=None: measured when added
                with allocating(arg, f"a float64 copy of {arg}"):
                    object.__setattr__(self, arg, _per_spring(getattr(self, arg), m, arg))

    live_params: ClassVar[tuple[LiveParam, ...]] = (
        LiveParam("stiffness", "stiffness", "mean", ("[", "]"), "k", "N/m", rank=0),
        LiveParam("damping", "damping", "mean", ("-", "="), "c", "N·s/m", at_zero="critical", rank=1),
    )
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
