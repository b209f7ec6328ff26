"""Forces on charged particles: uniform fields (:class:`ElectricField`, :class:`MagneticField`),
:class:`Coulomb` between charges, and field maps on a grid (:class:`GridElectricField`,
:class:`GridMagneticField`)."""
from __future__ import annotations

import dataclasses
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, ClassVar

import numpy as np

from .. import _check, _deprecate
from .._errors import InvalidInputError
from .._parts import AttachContext, LoadContext
from ._base import ArrayLike, Term, _finite_float, _same_dim, _vector


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
