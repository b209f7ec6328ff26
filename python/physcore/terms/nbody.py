"""Gravity between every pair of particles: :class:`PairwiseGravity` (direct sum) and
:class:`TreeGravity` (Barnes–Hut)."""
from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field
from typing import ClassVar

from .. import _deprecate
from .._errors import InvalidInputError
from ._base import Term, _finite_float


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
    conserved only to the force error (see docs/guide/tree_gravity.md for measured errors per
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
