"""Colliders: :class:`Plane`, :class:`Box` and :class:`Sphere`, and :class:`Collider`, the base of
the colliders registered by key (:class:`~physcore.Capsule`)."""
from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass
from typing import Any, ClassVar

import numpy as np

from .. import _deprecate
from .._errors import InvalidInputError, InvalidTypeError
from .._parts import AttachContext, LoadContext, Part
from ._base import _finite_float, _hashable, _same, _same_dim, _vector


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
        ctx.sim.add_collider("plane", {"point": self.point, "normal": self.normal, "restitution": self.restitution, "friction": self.friction})
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
        ctx.sim.add_collider("box", {"lower": self.lower, "upper": self.upper, "restitution": self.restitution, "friction": self.friction})
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
        ctx.sim.add_collider("sphere", {"center": self.center, "radius": self.radius, "inside": self.inside, "restitution": self.restitution, "friction": self.friction})
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        record = {"center": self.center.tolist(), "radius": self.radius, "restitution": self.restitution, "friction": self.friction, "inside": self.inside}
        return record, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ctx.add(cls(entry["center"], entry["radius"], restitution=entry["restitution"], friction=entry["friction"], inside=entry["inside"]))


class Collider(Part):
    """Base of the colliders registered by key, in the core (``constraints::registry``, one Rust
    file each with ``register_collider!``) and here: a subclass is a frozen dataclass that sets
    ``part_kind`` (the core's key) and ``record_fields`` (its fields by kind of value:
    ``"vector"``, ``"axial"``, ``"number"``, ``"bool"``), checks them in ``__post_init__``, and may draw itself
    (:meth:`drawn_rods`, :meth:`drawn_polygons`). Adding, saving, loading, the hostile-file checks and the energy books
    ("collisions") then need nothing else: a new collider touches its own files only
    (:class:`~physcore.Capsule` is one)."""

    section: ClassVar[str] = "colliders"
    #: Its fields, in order, by kind of value (``_scenefile._Reader.value``).
    record_fields: ClassVar[dict[str, str]] = {}

    # By value, as terms compare (subclasses are dataclasses with ``eq=False``, which keep these).
    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(_same(getattr(self, f), getattr(other, f)) for f in self.record_fields)

    def __hash__(self) -> int:
        return hash((type(self), *(_hashable(getattr(self, f)) for f in self.record_fields)))

    def _attach(self, ctx: AttachContext, name: None) -> Collider:
        for f, kind in self.record_fields.items():
            if kind == "vector":
                _same_dim(ctx, f, getattr(self, f))
        ctx.sim.add_collider(self.part_kind, {f: getattr(self, f) for f in self.record_fields})
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        record: dict[str, Any] = {"type": self.part_kind}
        for f, kind in self.record_fields.items():
            v = getattr(self, f)
            record[f] = v.tolist() if kind in ("vector", "axial") else v
        return record, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        ctx.add(cls(**{f: entry[f] for f in cls.record_fields}))

    def drawn_rods(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """What draws the collider in a render: rods ``(a, b, radius)``, the points within
        ``radius`` of the segment a–b, m (a ball where a == b); none by default."""
        return []

    def drawn_polygons(self) -> list[np.ndarray]:
        """What draws the collider in a 2D render as filled solids: convex polygons, each
        ``(k, 2)`` float64 vertices in order around it, m (drawn as the sphere's disc is: filled,
        with an edge line); none by default."""
        return []

