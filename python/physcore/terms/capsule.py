"""The capsule collider: a rod, a rail, a rounded beam."""
from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass
from typing import ClassVar

import numpy as np

from .._errors import InvalidInputError
from ._base import _finite_float, _vector
from .colliders import Collider


@dataclass(frozen=True, eq=False)
class Capsule(Collider):
    """Capsule collider: the points within ``radius`` of the segment from ``a`` to ``b`` (a
    stadium in a 2D scene), which particles are kept out of: a rod a cloth drapes over, a rail
    grains pile against.

    After each step a particle found inside is projected onto the surface along the normal at
    the nearest point of the axis, ``p = a + t (b − a)``, ``t = clamp((x − a)·(b − a)/|b − a|², 0,
    1)`` (Ericson, *Real-Time Collision Detection*, 2005, §5.1.2); if it is moving in, its normal
    velocity becomes ``-e v_n`` and its tangential speed drops by ``μ (1 + e) |v_n|``, as at a
    :class:`Sphere` (which it is with ``a == b``). The energy removed is booked under
    ``"collisions"`` in :meth:`Scene.energy`.

    Parameters
    ----------
    a, b : array_like, shape (dim,)
        The ends of the axis, m (finite; they may coincide).
    radius : float
        Radius, m; > 0, with a square that fits float64.
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]. Default 0.5.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.

    Raises
    ------
    TypeError
        A non-numeric ``a``, ``b``, ``radius``, ``restitution`` or ``friction``.
    InvalidInputError
        (a ``ValueError``) naming the argument: ``a`` or ``b`` not 2 or 3 finite numbers, of
        different lengths or with an axis whose squared length overflows, ``radius`` not finite
        and > 0 (or its square beyond float64), ``restitution`` outside [0, 1], ``friction`` < 0.

    Examples
    --------
    >>> import physcore as pc
    >>> rod = pc.Capsule([-0.5, 0.0, 0.4], [0.5, 0.0, 0.4], 0.05, restitution=0.0, friction=0.3)
    >>> s = pc.Scene(3, integrator="semi_implicit_euler", dt=1e-3)
    >>> _ = s.add_particles([[0.0, 0.0, 0.6]])
    >>> _ = s.add(pc.Gravity([0.0, 0.0, -9.81]))
    >>> _ = s.add(rod)
    >>> s.step(1000)
    >>> round(float(s.positions[0, 2]), 3)  # resting on top of the rod: 0.4 + 0.05
    0.45
    """

    a: np.ndarray
    b: np.ndarray
    radius: float
    _: KW_ONLY
    restitution: float = 0.5
    friction: float = 0.0

    part_kind: ClassVar[str] = "capsule"
    record_fields: ClassVar[dict[str, str]] = {
        "a": "vector", "b": "vector", "radius": "number", "restitution": "number", "friction": "number",
    }

    def __post_init__(self) -> None:
        a, b = _vector(self.a, "a"), _vector(self.b, "b")
        if a.shape != b.shape:
            raise InvalidInputError(f"b: has {b.shape[0]} components, a has {a.shape[0]}")
        with np.errstate(over="ignore", invalid="ignore"):
            axis2 = float(np.sum((b - a) ** 2))
        if not math.isfinite(axis2):
            raise InvalidInputError("b: the axis' squared length overflows float64")
        r = _finite_float(self.radius, "radius", minimum=0.0, strict=True)
        if not math.isfinite(r * r):
            raise InvalidInputError(f"radius: {r} m has a square beyond float64")
        e = _finite_float(self.restitution, "restitution", minimum=0.0)
        if e > 1.0:
            raise InvalidInputError(f"restitution: must be in [0, 1], got {e}")
        for name, value in (("a", a), ("b", b), ("radius", r), ("restitution", e)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "friction", _finite_float(self.friction, "friction", minimum=0.0))

    def drawn_rods(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Drawn as itself: one rod ``(a, b, radius)``."""
        return [(self.a, self.b, self.radius)]
