"""The oriented box collider: a rotated block, a tilted ramp."""
from __future__ import annotations

import itertools
import math
from dataclasses import KW_ONLY, dataclass
from typing import ClassVar

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from ._base import ArrayLike, _finite_float, _vector
from .colliders import Collider


def _rotation(value: object, dim: int) -> np.ndarray:
    """The rotation as the core takes it: shape (1,) (the angle) in 2D, (3,) in 3D; finite."""
    if value is None:
        a = np.zeros(1 if dim == 2 else 3)
    else:
        a = _check.real_array("rotation", value).astype(np.float64).reshape(-1) if np.ndim(value) <= 1 else None
        if a is None or a.shape[0] != (1 if dim == 2 else 3):
            want = "a number (the angle, rad)" if dim == 2 else "a rotation vector of shape (3,) (axis × angle, rad)"
            raise InvalidInputError(f"rotation: the box is {dim}D, so expected {want}, got shape {np.shape(value)}")
        if not np.all(np.isfinite(a)):
            raise InvalidInputError(f"rotation: must be finite, got {a.tolist()}")
    a.setflags(write=False)
    return a


def _axes(rotation: np.ndarray) -> np.ndarray:
    """The box's local axes as rows, (dim, dim): R's columns (the core's ``geometry::oriented_box``)."""
    if rotation.shape[0] == 1:
        c, s = math.cos(rotation[0]), math.sin(rotation[0])
        return np.array([[c, s], [-s, c]])
    theta = float(np.linalg.norm(rotation))
    if theta == 0.0:
        return np.eye(3)
    k = rotation / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return (np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * kx @ kx).T


@dataclass(frozen=True, eq=False)
class OrientedBox(Collider):
    """Oriented box collider: a block of half extents ``half_extents`` about ``center``, turned by
    ``rotation``, which particles are kept out of: a tilted ramp, a wedge, a beam at an angle.

    After each step a particle found inside (``|q_j| < h_j`` on every local axis, with ``q_j =
    (x − center)·u_j`` its local coordinates; Ericson, *Real-Time Collision Detection*, 2005,
    §4.4 and §5.1.4) leaves through the nearest face, the axis of least depth ``h_j − |q_j|``,
    along that face's outward normal ``±u_j``; if it is moving in, its normal velocity becomes
    ``-e v_n`` and its tangential speed drops by ``μ (1 + e) |v_n|``, as at a :class:`Plane`
    there. The energy removed is booked under ``"collisions"`` in :meth:`Scene.energy`. A
    particle that crosses more than half the box in one step leaves through the far face: keep
    ``|v| dt`` below the smallest half extent.

    Parameters
    ----------
    center : array_like, shape (dim,)
        Centre, m (finite).
    half_extents : array_like, shape (dim,)
        Half the side along each local axis, m; finite and > 0.
    rotation : float or array_like, shape (3,)
        In 2D the angle θ, rad, counterclockwise: the local x axis is ``(cos θ, sin θ)``. In 3D
        the rotation vector ``θ k`` (unit axis k, angle θ, rad; Rodrigues' formula, Murray, Li &
        Sastry, *A Mathematical Introduction to Robotic Manipulation*, 1994, §2.2). Default: no
        rotation.
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]. Default 0.5.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.

    Raises
    ------
    TypeError
        A non-numeric ``center``, ``half_extents``, ``rotation``, ``restitution`` or ``friction``.
    InvalidInputError
        (a ``ValueError``) naming the argument: ``center`` not 2 or 3 finite numbers,
        ``half_extents`` of another length or not finite and > 0, ``rotation`` not one number
        (2D) or three (3D) or not finite, ``restitution`` outside [0, 1], ``friction`` < 0.

    Examples
    --------
    >>> import math, physcore as pc
    >>> ramp = pc.OrientedBox([0.0, -1.0], [2.0, 1.0], math.radians(20), restitution=0.0)
    >>> s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-3)
    >>> _ = s.add_particles([[0.0, 0.5]])
    >>> _ = s.add(pc.Gravity([0.0, -9.81]))
    >>> _ = s.add(ramp)
    >>> s.step(1000)
    >>> bool(s.velocities[0, 0] < 0.0)  # landed, and sliding down the slope (to −x)
    True
    """

    center: np.ndarray
    half_extents: np.ndarray
    rotation: ArrayLike | None = None
    _: KW_ONLY
    restitution: float = 0.5
    friction: float = 0.0

    part_kind: ClassVar[str] = "oriented_box"
    record_fields: ClassVar[dict[str, str]] = {
        "center": "vector", "half_extents": "vector", "rotation": "axial", "restitution": "number", "friction": "number",
    }

    def __post_init__(self) -> None:
        center, half = _vector(self.center, "center"), _vector(self.half_extents, "half_extents")
        if half.shape != center.shape:
            raise InvalidInputError(f"half_extents: has {half.shape[0]} components, center has {center.shape[0]}")
        if not np.all(half > 0.0):
            raise InvalidInputError(f"half_extents: must be > 0 on every axis, got {half.tolist()}")
        rotation = _rotation(self.rotation, center.shape[0])
        e = _finite_float(self.restitution, "restitution", minimum=0.0)
        if e > 1.0:
            raise InvalidInputError(f"restitution: must be in [0, 1], got {e}")
        mu = _finite_float(self.friction, "friction", minimum=0.0)
        for name, value in (("center", center), ("half_extents", half), ("rotation", rotation), ("restitution", e), ("friction", mu)):
            object.__setattr__(self, name, value)

    def axes(self) -> np.ndarray:
        """The box's local unit axes u_j as rows, (dim, dim) float64: the columns of its rotation
        (the angle in 2D, counter-clockwise; the rotation vector by Rodrigues' formula in 3D)."""
        return _axes(self.rotation)

    def corners(self) -> np.ndarray:
        """The box's corners, m, (2**dim, dim): ``center + Σ_j ±h_j u_j``, in binary order of
        the signs (the last axis fastest)."""
        axes = _axes(self.rotation) * self.half_extents[:, None]
        signs = np.array(list(itertools.product((-1.0, 1.0), repeat=self.center.shape[0])))
        return self.center + signs @ axes

    def drawn_rods(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """In 3D drawn as its 12 edges: thin rods (radius 2% of the smallest half extent) between
        the corners that differ in one sign. In 2D none: it is drawn filled
        (:meth:`drawn_polygons`)."""
        c, dim = self.corners(), self.center.shape[0]
        if dim == 2:
            return []
        r = 0.02 * float(self.half_extents.min())
        return [(c[i], c[i | 1 << b], r) for i in range(2**dim) for b in range(dim) if not i & 1 << b]

    def drawn_polygons(self) -> list[np.ndarray]:
        """In 2D drawn as a filled rectangle: its 4 corners in order around it, m. In 3D none."""
        if self.center.shape[0] != 2:
            return []
        return [self.corners()[[0, 1, 3, 2]]]
