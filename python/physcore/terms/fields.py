"""Uniform fields on every free particle: :class:`Gravity` and :class:`Drag`."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ._base import LiveParam, Term, _finite_float, _vector


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
    live_params: ClassVar[tuple[LiveParam, ...]] = (LiveParam("gravity", "g", "norm", ("g", "G"), "g", "m/s²", rank=2),)

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
    live_params: ClassVar[tuple[LiveParam, ...]] = (
        LiveParam("drag", "coefficient", "value", ("d", "D"), "b", "kg/s", at_zero="mass", rank=3),
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "coefficient", _finite_float(self.coefficient, "coefficient", minimum=0.0))
