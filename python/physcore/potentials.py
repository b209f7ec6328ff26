"""Potential fields fixed in space: point masses and point charges, a harmonic trap, and a
potential sampled on a grid. Each is a conservative force term whose potential energy is in
:meth:`Scene.energy`'s books under the term's name; pinned particles feel nothing and hold no
potential energy, as with :class:`~physcore.Gravity`.

Examples
--------
A particle in a harmonic trap oscillates at ω = √(k/m):

>>> import numpy as np
>>> import physcore as pc
>>> s = pc.Scene(dim=2, dt=1e-3, threads=1)
>>> _ = s.add_particles([[1.0, 0.0]], masses=[2.0])
>>> _ = s.add(pc.HarmonicTrap(8.0))              # ω = √(8/2) = 2 rad/s: period π s
>>> s.step(round(np.pi / 1e-3))
>>> s.positions.round(4)                         # back near where it started
array([[1., 0.]])

A potential sampled on a grid: ``φ = ½ ω² |x|²`` (J/kg) on nodes 0.05 m apart, trilinear in between:

>>> ax = np.linspace(-1.0, 1.0, 41)
>>> X, Y, Z = np.meshgrid(ax, ax, ax, indexing="ij")
>>> grid = pc.PotentialGrid(0.5 * 4.0 * (X**2 + Y**2 + Z**2), spacing=0.05, origin=-1.0)
>>> grid.shape, grid.spacing.tolist(), grid.origin.tolist()
((41, 41, 41), [0.05, 0.05, 0.05], [-1.0, -1.0, -1.0])
"""
from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, ClassVar, Union

import numpy as np

from . import _check, _deprecate
from ._check import finite_float as _finite_float
from ._errors import InvalidInputError, InvalidTypeError, allocating
from ._parts import AttachContext, LoadContext
from .terms import Term

__all__ = ["PointMasses", "PointCharges", "HarmonicTrap", "PotentialGrid"]

ArrayLike = Union[float, int, "np.typing.ArrayLike"]

#: Coulomb's constant 1/(4π ε0), N·m²/C² (CODATA 2018).
COULOMB_K = 8.9875517923e9


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _scalar_or_axes(value: object, arg: str, *, nonnegative: bool = False) -> float | np.ndarray:
    """A finite real number, or one per axis (shape (2,) or (3,)); ``nonnegative`` refuses < 0."""
    a = _check.real_array(arg, value)
    if a.ndim == 0:
        return _finite_float(value, arg, minimum=0.0 if nonnegative else None)
    if a.ndim != 1 or a.shape[0] not in (2, 3):
        raise InvalidInputError(f"{arg}: expected a number or shape (2,) or (3,), got {a.shape}")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a) | ((a < 0) if nonnegative else False)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InvalidInputError(f"{arg}: component {k} is {a[k]} (must be finite{' and >= 0' if nonnegative else ''})")
    return _frozen(a)


def _per_axis(value: float | np.ndarray, dim: int, arg: str) -> np.ndarray:
    """``value`` as one number per axis of a ``dim``-D scene."""
    if isinstance(value, np.ndarray):
        if value.shape[0] != dim:
            raise InvalidInputError(f"{arg}: has {value.shape[0]} components, the scene is {dim}D")
        return value
    return _frozen(np.full(dim, float(value)))


def _sources(positions: object, strengths: object, pos_arg: str, str_arg: str, *, nonnegative: bool) -> tuple[np.ndarray, np.ndarray]:
    """Source positions (S, dim) and strengths (S,): one source may be given as a single point and
    a single number."""
    x = _check.real_array(pos_arg, positions)
    if x.ndim == 1 and x.shape[0] in (2, 3):
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise InvalidInputError(f"{pos_arg}: expected shape (S, 2) or (S, 3) (or one point), got {x.shape}")
    x = np.array(x, dtype=np.float64, order="C")
    if not np.all(np.isfinite(x)):
        s = int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])
        raise InvalidInputError(f"{pos_arg}: source {s} is {x[s].tolist()} (must be finite)")
    q = _check.real_array(str_arg, strengths).astype(np.float64)
    if q.ndim == 0:
        q = q.reshape(1)
    if q.shape != (x.shape[0],):
        raise InvalidInputError(f"{str_arg}: expected shape ({x.shape[0]},), one per source (row of {pos_arg}), got {q.shape}")
    bad = ~np.isfinite(q) | ((q < 0) if nonnegative else False)
    if bad.any():
        s = int(np.flatnonzero(bad)[0])
        raise InvalidInputError(f"{str_arg}: source {s} is {q[s]} (must be finite{' and >= 0' if nonnegative else ''})")
    return _frozen(x), _frozen(np.array(q, order="C"))


def _named(record: Term, name: str) -> Term:
    """``record`` under ``name``, sharing its (read-only) arrays: no second copy of a grid."""
    out = copy.copy(record)
    object.__setattr__(out, "name", name)
    return out


def _check_product(constant: float, strengths: np.ndarray, const_arg: str, str_arg: str) -> None:
    with np.errstate(over="ignore"):
        k = constant * strengths
    if not np.all(np.isfinite(k)):
        s = int(np.flatnonzero(~np.isfinite(k))[0])
        raise InvalidInputError(f"{str_arg}: source {s}: {strengths[s]} times {const_arg} = {constant} overflows float64")


def _add_sources(ctx: AttachContext, name: str, record: Term, strengths: np.ndarray, constant: float, coupling: str) -> Term:
    x = record.positions  # type: ignore[attr-defined]
    if x.shape[1] != ctx.dim:
        raise InvalidInputError(f"positions: has {x.shape[1]} columns, the scene is {ctx.dim}D")
    params = {"positions": x, "strengths": strengths, "constant": constant, "softening": record.softening, "coupling": coupling}  # type: ignore[attr-defined]
    ctx.sim.add_term("point_sources", name, params)
    return _named(record, name)


@_deprecate.record(('positions', 'masses', 'G', 'softening'), keep=2)
@dataclass(frozen=True, eq=False)
class PointMasses(Term, kind="point_masses"):
    """Point masses fixed in space that attract every free particle by Newton's law, with
    Plummer softening:

    ``F_i = -G m_i Σ_s M_s (x_i - x_s) / (|x_i - x_s|² + ε²)^{3/2}``,
    ``U = -G Σ_i m_i Σ_s M_s / (|x_i - x_s|² + ε²)^{1/2}``

    (Plummer 1911; Aarseth, *Gravitational N-body simulations*, 2003, eq. 2.4). The sources do
    not move and feel no reaction: momentum is not conserved, angular momentum about a single
    source is. A particle exactly on an unsoftened source gets nothing from it (the direction is
    undefined). Cost O(N·S), parallel over particles.

    Parameters
    ----------
    positions : array_like, shape (S, dim) or (dim,)
        Source positions, m (one point for a single source).
    masses : float or array_like, shape (S,)
        Source masses ``M_s`` ≥ 0, kg.
    G : float
        Gravitational constant > 0, m³/(kg·s²). Default 1 (N-body units, as
        :class:`~physcore.PairwiseGravity`); SI: ``6.674e-11``.
    softening : float
        Plummer softening length ε ≥ 0, m. Default 0.
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=2, integrator="verlet", dt=1e-3, threads=1)
    >>> _ = s.add_particles([[1.0, 0.0]], [[0.0, 1.0]], masses=[1e-3])  # circular: v² = GM/r
    >>> _ = s.add(pc.PointMasses([0.0, 0.0], 1.0))
    >>> s.step(round(2 * 3.141592653589793 / 1e-3))                    # one period, 2π s
    >>> s.positions.round(3)
    array([[ 1., -0.]])
    """

    positions: np.ndarray
    masses: ArrayLike
    _: KW_ONLY
    G: float = 1.0
    softening: float = 0.0
    name: str = field(default="point_masses", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"G": "number", "softening": "number"}
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "positions": ("f8", ("S", "D")),
        "masses": ("f8", ("S",)),
    }

    @allocating("PointMasses", "its arrays")
    def __post_init__(self) -> None:
        x, m = _sources(self.positions, self.masses, "positions", "masses", nonnegative=True)
        object.__setattr__(self, "positions", x)
        object.__setattr__(self, "masses", m)
        object.__setattr__(self, "G", _finite_float(self.G, "G", minimum=0.0, strict=True))
        object.__setattr__(self, "softening", _finite_float(self.softening, "softening", minimum=0.0))
        _check_product(self.G, m, "G", "masses")

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def _attach(self, ctx: AttachContext, name: str) -> PointMasses:
        return _add_sources(ctx, name, self, self.masses, self.G, "mass")  # type: ignore[return-value,arg-type]


@_deprecate.record(('positions', 'charges', 'k', 'softening'), keep=2)
@dataclass(frozen=True, eq=False)
class PointCharges(Term, kind="point_charges"):
    """Point charges fixed in space acting on the particles' ``"charge"`` attribute by Coulomb's
    law, with Plummer softening:

    ``F_i = k q_i Σ_s Q_s (x_i - x_s) / (|x_i - x_s|² + ε²)^{3/2}``,
    ``U = k Σ_i q_i Σ_s Q_s / (|x_i - x_s|² + ε²)^{1/2}``

    (Griffiths, *Introduction to Electrodynamics*, 4th ed., eqs. 2.1 and 2.26): like charges
    repel. Particles without a charge (a scene that never called
    :meth:`Scene.set_attribute` ``("charge", ...)``, or particles added later) feel nothing,
    as with :class:`~physcore.ElectricField`. A particle exactly on an unsoftened source gets
    nothing from it. Cost O(N·S), parallel over particles.

    A separate class from :class:`PointMasses` (one kernel underneath) because the two differ
    in what they act on, in the sign of the force, in whether a source may be negative and in
    the constant's default, and a record should read as the physics it is.

    Parameters
    ----------
    positions : array_like, shape (S, dim) or (dim,)
        Source positions, m (one point for a single source).
    charges : float or array_like, shape (S,)
        Source charges ``Q_s``, C, of either sign.
    k : float
        Coulomb's constant > 0, N·m²/C². Default ``8.9875517923e9`` (SI).
    softening : float
        Plummer softening length ε ≥ 0, m. Default 0.
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=2, integrator="euler", dt=1e-3, threads=1)
    >>> _ = s.add_particles([[1.0, 0.0], [-1.0, 0.0]], masses=[1.0, 1.0])
    >>> s.set_attribute("charge", [1.0, -1.0])
    >>> _ = s.add(pc.PointCharges([0.0, 0.0], 2.0, k=1.0))
    >>> s.step(1)                                      # one Euler step: v = (F/m) dt
    >>> s.velocities[:, 0] / 1e-3                      # like repels (+x), unlike attracts (+x)
    array([2., 2.])
    """

    positions: np.ndarray
    charges: ArrayLike
    _: KW_ONLY
    k: float = COULOMB_K
    softening: float = 0.0
    name: str = field(default="point_charges", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"k": "number", "softening": "number"}
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "positions": ("f8", ("S", "D")),
        "charges": ("f8", ("S",)),
    }

    @allocating("PointCharges", "its arrays")
    def __post_init__(self) -> None:
        x, q = _sources(self.positions, self.charges, "positions", "charges", nonnegative=False)
        object.__setattr__(self, "positions", x)
        object.__setattr__(self, "charges", q)
        object.__setattr__(self, "k", _finite_float(self.k, "k", minimum=0.0, strict=True))
        object.__setattr__(self, "softening", _finite_float(self.softening, "softening", minimum=0.0))
        _check_product(self.k, q, "k", "charges")

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def _attach(self, ctx: AttachContext, name: str) -> PointCharges:
        return _add_sources(ctx, name, self, self.charges, self.k, "charge")  # type: ignore[return-value,arg-type]


@_deprecate.record(('k', 'center'), keep=1)
@dataclass(frozen=True, eq=False)
class HarmonicTrap(Term, kind="harmonic_trap"):
    """A harmonic trap: every free particle is pulled towards ``center`` by a spring of
    stiffness ``k``, ``F = -k (x - center)``, ``U = ½ Σ_i k |x_i - center|²``. With a
    stiffness per axis the trap is anisotropic: ``F_a = -k_a (x_a - c_a)``,
    ``U = ½ Σ_i Σ_a k_a (x_ia - c_a)²``. A particle of mass ``m`` oscillates at ``ω = √(k/m)``
    (the trap acts on position, not on mass: heavier particles oscillate more slowly).

    Parameters
    ----------
    k : float or array_like, shape (dim,)
        Stiffness ≥ 0, N/m, one for every axis or one per axis (0: free along that axis).
    center : float or array_like, shape (dim,)
        The trap's centre, m. Default the origin (a number stands for every coordinate).
    name : str
        Key of this term in the energy books.

    The record a scene stores (what :meth:`Scene.add` returns) holds ``k`` and ``center`` as
    one number per axis of the scene.

    Examples
    --------
    >>> import physcore as pc
    >>> s = pc.Scene(dim=3, threads=1)
    >>> s.add(pc.HarmonicTrap(2.0, center=[0.0, 0.0, 1.0]))
    HarmonicTrap(k=array([2., 2., 2.]), center=array([0., 0., 1.]), name='harmonic_trap')
    """

    k: ArrayLike
    _: KW_ONLY
    center: ArrayLike = 0.0
    name: str = field(default="harmonic_trap", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"k": "vector", "center": "vector"}

    @allocating("HarmonicTrap", "its arrays")
    def __post_init__(self) -> None:
        k = _scalar_or_axes(self.k, "k", nonnegative=True)
        c = _scalar_or_axes(self.center, "center")
        if isinstance(k, np.ndarray) and isinstance(c, np.ndarray) and k.shape != c.shape:
            raise InvalidInputError(f"center: has {c.shape[0]} components, k has {k.shape[0]}")
        object.__setattr__(self, "k", k)
        object.__setattr__(self, "center", c)

    def _attach(self, ctx: AttachContext, name: str) -> HarmonicTrap:
        k = _per_axis(self.k, ctx.dim, "k")  # type: ignore[arg-type]
        c = _per_axis(self.center, ctx.dim, "center")  # type: ignore[arg-type]
        ctx.sim.add_term("harmonic_trap", name, {"k": k, "center": c})
        return dataclasses.replace(self, k=k, center=c, name=name)


COUPLINGS = ("mass", "charge")


@_deprecate.record(('phi', 'spacing', 'origin', 'coupling'), keep=2)
@dataclass(frozen=True, eq=False)
class PotentialGrid(Term, kind="potential_grid"):
    """A potential sampled on a regular grid, interpolated bilinearly (2D) or trilinearly (3D),
    acting on the particles' mass or charge:

    ``U = Σ_i c_i φ̃(x_i)``, ``F_i = -c_i ∇φ̃(x_i)``

    with ``c_i`` the mass (``coupling="mass"``, φ in J/kg = m²/s²) or the ``"charge"``
    attribute (``coupling="charge"``, φ in V; particles without a charge feel nothing, as with
    :class:`~physcore.ElectricField`) and ``φ̃`` the interpolant of the samples.

    **Layout.** The grid is node-centred: ``phi[i, j]`` (``phi[i, j, k]``) is φ at
    ``origin + (i, j[, k]) * spacing``, so the grid covers the box
    ``[origin, origin + (shape - 1) * spacing]``. Sample a function ``f`` with
    ``np.meshgrid(*axes, indexing="ij")``.

    **Force.** The force is minus the exact gradient of the same interpolant the energy books
    use, so the field is conservative with respect to the booked potential. A linear φ is
    reproduced exactly (a uniform force). The interpolant is continuous but its gradient jumps
    across cell faces (by ``O(h |∂²φ|)`` for a smooth φ): each cell crossing costs a symplectic
    integrator an energy error of order ``|jump| |v| dt`` of either sign, so Verlet's energy
    error over many crossings is small but not bounded as for a smooth force (see
    ``docs/potentials.md`` for the measured orders).

    **Outside the grid** φ̃ is continued by its value at the nearest point of the box (each
    coordinate clamped): a particle outside feels no force along the axes on which it is out
    of the box, and the interpolant's gradient at the nearest face along the others. The
    continuation is continuous and the force is its exact gradient, so the energy books stay
    balanced for particles that leave (and come back). Make the grid cover where particles go.

    **Steps.** :meth:`Scene.advance` with automatic substeps moves no particle more than one
    cell per substep (``|v| dt + ½ a dt² ≤ min(spacing)``, ``a`` bounded by the samples'
    steepest slope); :meth:`Scene.suggest_dt` also keeps to that.

    Parameters
    ----------
    phi : array_like, shape (nx, ny) or (nx, ny, nz)
        Node values, J/kg or V; at least 2 nodes per axis, all finite. Copied.
    spacing : float or array_like, shape (dim,)
        Node spacing per axis, m, > 0.
    origin : float or array_like, shape (dim,)
        Position of node ``(0, 0[, 0])``, m. Default 0 (a number stands for every coordinate).
    coupling : {"mass", "charge"}
        What the field acts on. Default ``"mass"``.
    name : str
        Key of this term in the energy books.

    Examples
    --------
    >>> import numpy as np
    >>> import physcore as pc
    >>> x = np.linspace(0.0, 1.0, 11)
    >>> X, Y = np.meshgrid(x, x, indexing="ij")
    >>> s = pc.Scene(dim=2, dt=1e-3, threads=1)
    >>> _ = s.add_particles([[0.33, 0.71]], masses=[2.0])
    >>> _ = s.add(pc.PotentialGrid(3.0 * X - 2.0 * Y, spacing=0.1))   # φ = 3x - 2y, J/kg
    >>> s.step(1)
    >>> (s.velocities / 1e-3).round(12)                                 # a = -∇φ exactly
    array([[-3.,  2.]])
    """

    phi: np.ndarray
    spacing: ArrayLike
    _: KW_ONLY
    origin: ArrayLike = 0.0
    coupling: str = "mass"
    name: str = field(default="potential_grid", kw_only=True)

    record_fields: ClassVar[dict[str, str]] = {"shape": "vector", "spacing": "vector", "origin": "vector", "coupling": "str"}
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {"phi": ("f8", ("P",))}

    @allocating("PotentialGrid", "its arrays")
    def __post_init__(self) -> None:
        a = _check.real_array("phi", self.phi)
        if a.ndim not in (2, 3):
            raise InvalidInputError(f"phi: expected shape (nx, ny) or (nx, ny, nz), got {a.shape}")
        if min(a.shape) < 2:
            raise InvalidInputError(f"phi: needs at least 2 nodes per axis, got shape {a.shape}")
        phi = np.array(a, dtype=np.float64, order="C")
        bad = ~np.isfinite(phi)
        if bad.any():
            at = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), phi.shape))
            raise InvalidInputError(f"phi: entry {at} is {phi[at]} (must be finite)")
        d = phi.ndim
        h = self._axes(self.spacing, "spacing", d)
        with np.errstate(over="ignore"):
            ok = (h > 0) & np.isfinite(1.0 / np.where(h > 0, h, 1.0))
        if not ok.all():
            k = int(np.flatnonzero(~ok)[0])
            raise InvalidInputError(f"spacing: component {k} is {h[k]} (must be > 0 and its reciprocal finite)")
        o = self._axes(self.origin, "origin", d)
        with np.errstate(over="ignore"):
            end = o + (np.array(phi.shape) - 1) * h
        if not np.all(np.isfinite(end)):
            k = int(np.flatnonzero(~np.isfinite(end))[0])
            raise InvalidInputError(f"spacing: axis {k}'s far end origin + (n - 1) * spacing is beyond float64")
        object.__setattr__(self, "phi", _frozen(phi))
        object.__setattr__(self, "spacing", h)
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "coupling", _check.choice("coupling", self.coupling, COUPLINGS))

    @staticmethod
    def _axes(value: object, arg: str, dim: int) -> np.ndarray:
        v = _scalar_or_axes(value, arg)
        if isinstance(v, np.ndarray):
            if v.shape[0] != dim:
                raise InvalidInputError(f"{arg}: has {v.shape[0]} components, phi has {dim} axes")
            return v
        return _frozen(np.full(dim, v))

    @property
    def shape(self) -> tuple[int, ...]:
        """Nodes per axis."""
        return tuple(self.phi.shape)

    @property
    def upper(self) -> np.ndarray:
        """The far corner of the grid's box, ``origin + (shape - 1) * spacing``, m."""
        return self.origin + (np.array(self.shape) - 1) * self.spacing  # type: ignore[operator]

    def _attach(self, ctx: AttachContext, name: str) -> PotentialGrid:
        if self.phi.ndim != ctx.dim:
            raise InvalidInputError(f"phi: a {self.phi.ndim}D grid (shape {self.shape}) cannot act in a {ctx.dim}D scene")
        params = {
            "phi": self.phi,
            "shape": np.array(self.shape, dtype=np.float64),
            "spacing": self.spacing,
            "origin": self.origin,
            "coupling": self.coupling,
        }
        ctx.sim.add_term("grid_potential", name, params)
        return _named(self, name)  # type: ignore[return-value]

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        meta = {"shape": list(self.shape), "spacing": self.spacing.tolist(), "origin": self.origin.tolist(), "coupling": self.coupling}  # type: ignore[union-attr]
        return meta, {"phi": self.phi.reshape(-1)}

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        shape = meta["shape"]
        if not all(float(n).is_integer() and 2 <= n <= 2**40 for n in shape):
            raise InvalidInputError(f"shape: must be whole numbers of nodes >= 2, got {shape}")
        shape = tuple(int(n) for n in shape)
        phi = arrays["phi"]
        if math.prod(shape) != phi.size:
            raise InvalidInputError(f"phi: holds {phi.size} values, the shape {shape} needs {math.prod(shape)}")
        if not isinstance(meta["coupling"], str):  # pragma: no cover - the reader checked it
            raise InvalidTypeError("coupling: expected a string")
        ctx.add(cls(phi.reshape(shape), meta["spacing"], origin=meta["origin"], coupling=meta["coupling"], name=meta["name"]))
