"""SPH fluids, weakly compressible (WCSPH) or divergence-free (DFSPH): the :class:`Fluid` term,
lattice and tank helpers, and :func:`neighbors`, the spatial hash on its own.

Physics (all in the Rust core, f32 or f64):

* density by summation, ``ρ_i = Σ_j m_j W_ij + Σ_b Ψ_b W_ib`` (self included; ``b``: static wall
  particles with ``Ψ_b = ρ0 V_b``, Akinci et al., ACM TOG 31(4) 62, 2012, eq. 4–5);
* Tait equation of state ``p = B[(ρ/ρ0)^γ − 1]``, ``B = ρ0 c0²/γ`` (Monaghan, J. Comput. Phys.
  110, 1994; Becker & Teschner 2007, eq. 6), by default clamped to ``p ≥ 0``;
* the symmetric pressure force with Monaghan (1992) artificial viscosity,
  ``dv_i/dt = −Σ_j m_j (p_i/ρ_i² + p_j/ρ_j² + Π_ij) ∇_i W_ij − Σ_b Ψ_b (p_i/ρ_i²) ∇_i W_ib``,
  ``Π_ij = −α c0 μ_ij / ρ̄_ij``, ``μ_ij = h v_ij·r_ij/(r_ij² + 0.01h²)`` for approaching pairs
  (Monaghan, Annu. Rev. Astron. Astrophys. 30, 1992, eq. 4.1–4.2); walls are free-slip
  (Akinci et al. 2012, eq. 10, without wall viscosity), so fluid neither leaks nor sticks;
* kernels: cubic spline (Monaghan & Lattanzio 1985) and Wendland C2 (Dehnen & Aly 2012), support
  ``2h``, normalised in 2D and 3D;
* energy books: the pressure force is the gradient of the internal energy ``Σ m_i u(ρ_i)``,
  ``u' = p/ρ²`` (Price, J. Comput. Phys. 231, 2012, §3.2), booked as the fluid's potential; the
  viscosity's dissipation ``½ Σ_ij m_i m_j Π_ij v_ij·∇_i W_ij`` is accumulated; gravity is a
  separate :class:`~physcore.Gravity` term.
* time step: CFL ``0.25 h/(c0 (1 + 0.6α) + |v|max)`` and force ``0.25 √(h/|a|max)`` criteria
  (Monaghan 1992, §5) through :meth:`Scene.suggest_dt` and :meth:`Scene.advance`.

``Fluid(method="dfsph")`` replaces the equation of state by DFSPH (Bender & Koschier, "Divergence-free
SPH for incompressible and viscous fluids", IEEE TVCG 23, 2017, Algorithms 1–3): each step solves
for the pressure twice, a divergence solve that makes the velocities divergence free and a
density solve that keeps the mean compression below ``density_error`` (0.1 % by default), both
warm-started from the previous step. The same density summation, walls, kernels and viscosity
(with the same ``α c0``) as WCSPH; ``c0`` enters only the viscosity; the walls push with the
particle's pressure mirrored (``p_b = p_i``), without which the hydrostatic push drives corner
particles through the walls. Its step follows the flow: CFL ``cfl · h/|v|max`` (``cfl = 0.4``),
the viscous limit ``0.125 h²/ν`` (``ν = α c0 h/(2(d+2))``) and ``0.25 √(h/|g|)``, not the speed of
sound, so a dam break takes ten to twenty times fewer steps. The projections are inelastic: the
kinetic energy each removes is booked as the fluid's dissipation (with the viscosity's), and
:meth:`Scene.solver_stats` reports each solver's share, iterations and residuals. DFSPH steps with
``integrator="semi_implicit_euler"`` only, in float64. Several DFSPH fluids with the same ``h``,
kernel, rest density and solver settings are solved as one (a drop falling into a pool): one
neighbour search and one pair of projections over all their particles, each particle seeing the
walls of all of them; the solve's first fluid keeps the solve's books.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import Any, ClassVar

import numpy as np

from . import _check, _core, _deprecate
from ._check import finite_float as _finite_float
from ._errors import InvalidInputError, InvalidTypeError, SeparateFluidsWarning, allocating
from ._parts import AttachContext, LoadContext
from .shapes import lattice, tank_walls  # the lattice and tank builders, still importable from here
from .shapes import lattice_counts as lattice_counts
from .terms import Gravity, Term

__all__ = ["Fluid", "WCSPH", "DFSPH", "neighbors", "lattice", "tank_walls", "kernel_w", "KERNELS", "default_smoothing"]

#: Kernel names accepted by :class:`Fluid`.
KERNELS = ("cubic_spline", "wendland_c2")

#: Pressure methods accepted by :class:`Fluid`.
METHODS = ("wcsph", "dfsph")

def default_smoothing(dim: int, method: str, surface: bool = False) -> float:
    """The default ``h/Δx`` of a :class:`Fluid`: 1.0 for a 3D DFSPH fluid without surface
    tension or adhesion, 1.3 otherwise.

    Such a fluid takes the DFSPH paper's reach (Bender & Koschier 2017; SPlisHSPlasH's default: a
    support of 2 Δx, about 33 neighbours). At 1.3 a pass visits 2.2 times the pairs and the
    solves' Jacobi iterations need relaxing (ω = 0.585; at 1.0 ω = 1,
    docs/guide/fluids_dfsph.md, "Relaxation"): a 3D dam break costs about twice as much for
    fronts within 2 % of each other and of SPlisHSPlasH's (the guide's "Choosing h in 3D").
    Where the fluid has surface tension or adhesion it keeps 1.3: at 1.0 a 12³ cube of water
    freezes into a lumpy drop (the outermost particles' spread over 26 directions 4.9 % against
    2.1 %, averaged over 0.5–1.0 s). In 2D a narrower h gains nothing (the CFL step shrinks with
    h and the pairs are few), and WCSPH keeps 1.3, the value its tests and tables were measured at.

    Parameters
    ----------
    dim : int
        2 or 3.
    method : str
        ``"wcsph"`` or ``"dfsph"``.
    surface : bool
        The fluid has surface tension or adhesion.

    Returns
    -------
    float
    """
    return 1.0 if dim == 3 and method == "dfsph" and not surface else 1.3


#: Range of ``Fluid(spacing=...)``, m: keeps ``h^dim``, its reciprocal (the kernel's
#: normalisation) and squared kernel distances inside float64.
SPACING_RANGE = (1e-100, 1e100)


def _array2(value: object, arg: str, dims: tuple[int, ...] = (2, 3)) -> np.ndarray:
    try:
        a = np.asarray(value)
    except ValueError as exc:  # ragged nested sequences
        raise InvalidInputError(f"{arg}: not a rectangular array ({exc})") from None
    if a.dtype.kind not in "iuf" or a.dtype == bool:
        raise InvalidTypeError(f"{arg}: expected real numbers, got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] not in dims:
        want = " or ".join(f"(N, {d})" for d in dims)
        raise InvalidInputError(f"{arg}: expected shape {want}, got {a.shape}")
    # A copy of its own, read-only: the record was the caller's array (a later write to it, or
    # to `fluid.positions`, went into what save writes, not into the particles the core holds).
    a = np.array(a, dtype=np.float64, order="C")
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise InvalidInputError(f"{arg}: row {int(np.flatnonzero(bad)[0])} is not finite")
    a.setflags(write=False)
    return a


def _scaled(a: np.ndarray, factor: float) -> np.ndarray:
    """``factor * a`` with overflow giving inf quietly (the caller refuses it by name)."""
    with np.errstate(over="ignore"):
        return factor * a


def neighbors(points: np.typing.ArrayLike, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """All pairs of points closer than ``radius``, found with physcore's parallel spatial hash.

    A pair ``(i, j)`` with ``i < j`` is returned when ``Σ_k (p_i,k − p_j,k)² < radius²``, evaluated
    in float64 in that order (points exactly ``radius`` apart are not neighbours). The domain is
    unbounded (cells are hashed when the points are spread out), so huge and negative coordinates
    work.

    Parameters
    ----------
    points : array_like, shape (N, d), d in {1, 2, 3}
        Coordinates (float64 after conversion). N may be 0.
    radius : float
        Search radius > 0, finite, in the points' units.

    Returns
    -------
    i, j : numpy.ndarray, shape (M,), int64
        Indices with ``i < j``, sorted by ``i`` then ``j``.

    Raises
    ------
    TypeError
        Non-numeric points or radius.
    ValueError
        Wrong shape, NaN/inf coordinates, radius not finite and > 0.

    Examples
    --------
    >>> import physcore as pc
    >>> i, j = pc.neighbors([[0.0, 0.0], [0.5, 0.0], [2.0, 0.0]], radius=1.0)
    >>> i.tolist(), j.tolist()
    ([0], [1])
    """
    pts = _array2(points, "points", (1, 2, 3))
    r = _finite_float(radius, "radius", minimum=0.0, strict=True)
    if pts.shape[1] == 1:
        pts = np.ascontiguousarray(np.hstack([pts, np.zeros_like(pts)]))
    if pts.shape[0] < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return _core.neighbors(pts, r)


def kernel_w(q: np.ndarray, h: float, dim: int, kernel: str = "cubic_spline") -> np.ndarray:
    """The smoothing kernel ``W(r) = σ_d w(q)``, ``q = r/h``, support ``2h`` (1/m^dim): an array
    of q's shape, float64. The core's formula (``sph::resolve``), which also gives the fluid's
    particle mass and wall volumes.

    Cubic spline (Monaghan & Lattanzio 1985, eq. 21): ``w = ¼(2−q)₊³ − (1−q)₊³``,
    ``σ₂ = 10/(7πh²)``, ``σ₃ = 1/(πh³)``.
    Wendland C2 (Wendland 1995): ``w = (1 − q/2)₊⁴ (2q + 1)``, ``σ₂ = 7/(4πh²)``, ``σ₃ = 21/(16πh³)``.

    Raises InvalidInputError naming ``q`` (negative or not finite), ``h`` (not finite and > 0,
    or without ``h^dim`` in float64), ``dim`` or ``kernel``.
    """
    q = _check.real_array("q", q).astype(np.float64)
    h = _finite_float(h, "h", minimum=0.0, strict=True)
    dim = _check.int_in_range("dim", dim, 2, 3)
    kernel = _check.choice("kernel", kernel, KERNELS)
    flat = np.ascontiguousarray(q.reshape(-1))
    return _core.sph_kernel(flat, h, dim, kernel).reshape(q.shape)


def lattice_density_sum(spacing: float, h: float, dim: int, kernel: str) -> float:
    """``Σ_j W(x_i − x_j)`` over an infinite cubic lattice of the given spacing (1/m^dim): a fluid
    particle's mass ``ρ0 / sum`` makes a lattice at rest have exactly the rest density (the
    core's formula, ``sph::resolve``)."""
    return float(_core.sph_lattice_sum(float(spacing), float(h), int(dim), str(kernel)))


# ----------------------------------------------------------------------------- the solver records
def _check_wcsph(rec: Any) -> None:
    """Check (TypeError / InvalidInputError naming the field) a record's WCSPH options: ``gamma``,
    ``clamp_pressure``, ``pass_precision`` (a :class:`WCSPH` or a :class:`Fluid`)."""
    if isinstance(rec.gamma, bool) or not isinstance(rec.gamma, (int, np.integer)):
        raise InvalidTypeError(f"gamma: expected an int, got {type(rec.gamma).__name__}")
    if not 1 <= rec.gamma <= 15:
        raise InvalidInputError(f"gamma: must be in 1..15, got {rec.gamma}")
    if not isinstance(rec.clamp_pressure, (bool, np.bool_)):
        raise InvalidTypeError(f"clamp_pressure: expected a bool, got {type(rec.clamp_pressure).__name__}")
    if not isinstance(rec.pass_precision, str) or rec.pass_precision not in ("f32", "f64"):
        raise InvalidInputError(f"pass_precision: expected 'f32' or 'f64', got {rec.pass_precision!r}")


def _check_dfsph(rec: Any) -> None:
    """Check and normalise (floats, ints) a record's DFSPH options, naming the field: the
    tolerances, ``max_iterations``, ``cfl``, ``surface_tension``, ``adhesion`` (a :class:`DFSPH`
    or a :class:`Fluid`)."""
    for arg in ("density_error", "divergence_error"):
        v = _finite_float(getattr(rec, arg), arg, minimum=0.0, strict=True)
        if not v < 1.0:
            raise InvalidInputError(f"{arg}: a relative error in (0, 1) (0.001 = 0.1 %), got {v}")
        object.__setattr__(rec, arg, v)
    object.__setattr__(rec, "max_iterations", _check.int_in_range("max_iterations", rec.max_iterations, 1, 100_000))
    cfl = _finite_float(rec.cfl, "cfl", minimum=0.0, strict=True)
    if not cfl <= 1.0:
        raise InvalidInputError(f"cfl: must be in (0, 1], got {cfl}")
    object.__setattr__(rec, "cfl", cfl)
    for arg in ("surface_tension", "adhesion"):
        object.__setattr__(rec, arg, _finite_float(getattr(rec, arg), arg, minimum=0.0))


@dataclass(frozen=True)
class SPHSolver:
    """Base of the particle-fluid solver records, :class:`WCSPH` and :class:`DFSPH`: the pressure
    solver of a :class:`Fluid` with its own options (``Fluid(..., solver=pc.DFSPH(cfl=0.3))``).
    Records compare by value, hash, and are immutable; their fields are keyword-only and checked
    when the record is made."""

    #: The solver's name, ``Fluid.method`` (``"wcsph"``, ``"dfsph"``), as scene files keep it.
    name: ClassVar[str] = ""

    def options(self) -> dict[str, Any]:
        """The :class:`Fluid` keywords this record sets (its fields), with its values: a new dict."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


@dataclass(frozen=True, kw_only=True)
class WCSPH(SPHSolver):
    """Weakly compressible SPH (Becker & Teschner 2007; Monaghan 1994): the pressure from the Tait
    equation of state ``p = B[(ρ/ρ0)^γ − 1]``, ``B = ρ0 c0²/γ`` (module docstring).
    ``Fluid(..., solver=pc.WCSPH(...))`` is ``Fluid(..., method="wcsph", ...)`` with the same
    options; the default solver.

    Parameters
    ----------
    gamma : int
        Tait exponent γ (dimensionless), 1..15. Default 7 (water).
    clamp_pressure : bool
        Clamp ``p ≥ 0`` (no tension at the free surface). Default True.
    pass_precision : {"f64", "f32"}
        Arithmetic of the density and force passes (positions and velocities stay float64).
        ``"f32"`` is about twice as fast. Default ``"f64"``.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) ``gamma`` not an int, ``clamp_pressure`` not a bool; names it.
    InvalidInputError
        (a ``ValueError``) A field out of range, naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> from physcore.shapes import lattice
    >>> fluid = pc.Fluid(lattice([0, 0], [0.1, 0.1], 0.01), 0.01, solver=pc.WCSPH(gamma=3))
    >>> fluid.method, fluid.gamma
    ('wcsph', 3)
    """

    name: ClassVar[str] = "wcsph"

    gamma: int = 7
    clamp_pressure: bool = True
    pass_precision: str = "f64"

    def __post_init__(self) -> None:
        _check_wcsph(self)


@dataclass(frozen=True, kw_only=True)
class DFSPH(SPHSolver):
    """Divergence-free SPH (Bender & Koschier, "Divergence-free SPH for incompressible and viscous
    fluids", IEEE TVCG 23, 2017, Algorithms 1–3): a divergence solve and a density solve each
    step, warm-started (module docstring). ``Fluid(..., solver=pc.DFSPH(...))`` is
    ``Fluid(..., method="dfsph", ...)`` with the same options. Steps inside
    ``integrator="semi_implicit_euler"`` only. The solves' Jacobi iterations are relaxed by an ω
    that follows from the dimension, the kernel and ``smoothing`` (1 at the defaults, h = 1.3 Δx
    in 2D and 1.0 Δx in 3D; 0.585 in 3D at 1.3 Δx; Ihmsen et al. 2014, eq. 14), so wider
    neighbourhoods stay stable
    (docs/guide/fluids_dfsph.md, "Relaxation").

    Parameters
    ----------
    density_error : float
        The density solve iterates until the predicted mean compression ``mean((ρ − ρ0)₊)/ρ0``
        is at most this (dimensionless), in (0, 1). Default 1e-3 (0.1 %); 1e-4 is the paper's
        strict setting.
    divergence_error : float
        The divergence solve's tolerance, ``mean((Dρ/Dt)₊) dt/ρ0`` (dimensionless), in (0, 1).
        Default 1e-3.
    max_iterations : int
        Most iterations of each solve, 1..100000. Default 100.
    cfl : float
        The CFL number λ of the step limit ``λ h/|v|max`` (dimensionless), in (0, 1]. Default 0.4.
    surface_tension : float
        Surface tension σ ≥ 0, N/m (N in 2D; water: 0.072 N/m), Akinci, Akinci & Teschner, ACM
        TOG 32(6) 182, 2013, eq. 1–6 (see :class:`Fluid`). Default 0: none.
    adhesion : float
        Attraction to the walls ≥ 0 (Akinci et al. 2013, eq. 7), in σ's units. Default 0.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) A field of the wrong type (``bool`` and ``str`` are not numbers); names it.
    InvalidInputError
        (a ``ValueError``) A field out of range, naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> from physcore.shapes import lattice
    >>> fluid = pc.Fluid(lattice([0, 0], [0.1, 0.1], 0.01), 0.01, solver=pc.DFSPH(cfl=0.3))
    >>> fluid.method, fluid.cfl, fluid == pc.Fluid(fluid.positions, 0.01, method="dfsph", cfl=0.3)
    ('dfsph', 0.3, True)
    """

    name: ClassVar[str] = "dfsph"

    density_error: float = 1e-3
    divergence_error: float = 1e-3
    max_iterations: int = 100
    cfl: float = 0.4
    surface_tension: float = 0.0
    adhesion: float = 0.0

    def __post_init__(self) -> None:
        _check_dfsph(self)


#: The solver record of each ``Fluid(method=...)`` name.
SOLVERS: dict[str, type[SPHSolver]] = {cls.name: cls for cls in (WCSPH, DFSPH)}


#: Fluid's fields in their positional order before issue 45 (new names), and its renames.
_FLUID_ORDER = (
    "positions", "spacing", "velocities", "density", "sound_speed", "alpha", "smoothing", "kernel", "gamma",
    "clamp_pressure", "mass", "boundary", "boundary_volume", "pass_precision", "method", "density_error",
    "divergence_error", "max_iterations", "cfl", "surface_tension", "adhesion",
)
_FLUID_RENAMES = {"viscosity": "alpha", "walls": "boundary", "wall_volume": "boundary_volume", "precision": "pass_precision"}


@_deprecate.record(_FLUID_ORDER, keep=2, renames=_FLUID_RENAMES)
@dataclass(frozen=True, eq=False)
class Fluid(Term, kind="fluid"):
    """A WCSPH fluid: its particles and parameters, SI units. Add it with :meth:`Scene.add`
    (or :meth:`Scene.add_fluid`), which appends the particles and the force term.

    Several fluids in one scene push on each other when they have the same ``h``
    (``smoothing · spacing``), ``kernel`` and ``pass_precision`` (up to 8 such fluids): they share one
    neighbour search and one pair of SPH passes, in which each particle keeps its own fluid's
    equation of state, artificial viscosity and boundary (a pair's viscosity uses the mean of the
    two fluids' ``α c0``), and each fluid keeps its own energy books. Fluids that differ in one of the three
    pass through each other, and adding such a fluid warns
    (:class:`~physcore.SeparateFluidsWarning`). Density is by summation over both fluids, so
    across a large density jump it is smeared over the kernel support (a light layer on water at
    ρ0 700 vs 1000: the rows at the interface are 5–15 % off their hydrostatic pressure, the
    bulk within 1 %); keep density ratios moderate. Boundary particles act on the fluid that has
    them: give every fluid the tank's walls (``boundary=tank_walls(...)``).

    ``positions`` and ``spacing`` may be given by position, the rest by keyword (positionally,
    in the old order, they still work this release with a DeprecationWarning). Renamed in issue 45
    (docs/naming.md; the old keywords and attributes still work this release, deprecated):
    ``viscosity`` → ``alpha``, ``walls`` → ``boundary``, ``wall_volume`` → ``boundary_volume``,
    ``precision`` → ``pass_precision``. Scene files keep the old keys.

    Parameters
    ----------
    positions : array_like, shape (N, dim)
        Initial particle positions, m, e.g. from :func:`lattice` (spacing apart).
    spacing : float
        Initial particle spacing ``Δx``, m, in :data:`SPACING_RANGE` (1e-100 to 1e100, so that
        ``h^dim`` and its reciprocal fit float64). Sets ``h = smoothing · Δx`` and the masses.
    velocities : array_like, shape (N, dim), optional
        Initial velocities, m/s. Default zero.
    density : float
        Rest density ``ρ0``, kg/m³ (kg/m² in 2D). Default 1000 (water).
    sound_speed : float, optional
        Numerical speed of sound ``c0``, m/s. Default ``10 × v_max`` with
        ``v_max = max(√(2|g|H), max |v0|)``, ``H`` the fluid's extent along the scene's gravity when
        it is added: density then varies by about 1 % (Monaghan 1994); with surface tension also
        at least the capillary speed ``√(σ/(ρ0 h))``. (DFSPH: c0 only scales the viscosity.)
    alpha : float
        Artificial viscosity ``α`` ≥ 0, dimensionless (Monaghan 1992, eq. 4.1–4.2). Default 0.05.
        (Not a kinematic viscosity ν: the one of :class:`~physcore.StableFluid` is ``nu``.)
    smoothing : float, optional
        ``h / Δx``, in [0.5, 4]. Default :func:`default_smoothing`: 1.0 for a 3D DFSPH fluid
        without surface tension or adhesion (the DFSPH paper's reach: its step costs half of
        1.3's), 1.3 otherwise; set when the fluid is made (``dataclasses.replace`` keeps it).
    kernel : {"cubic_spline", "wendland_c2"}
        Default ``"cubic_spline"``.
    gamma : int
        Tait exponent γ (1..15). Default 7 (water).
    clamp_pressure : bool
        Clamp ``p ≥ 0`` (no tension at the free surface). Default True.
    mass : float, optional
        Particle mass, kg (at least 2.2e-308, so that 1/m is finite). Default ``ρ0 / Σ_j W_ij`` over the initial lattice, so a fluid at rest
        starts exactly at the rest density (``≈ ρ0 Δx^dim``).
    boundary : array_like, shape (M, dim), optional
        Static boundary (wall) particle positions, m (Akinci et al. 2012), e.g. from
        :func:`tank_walls`.
    boundary_volume : "lattice", "akinci", float or array_like shape (M,)
        Volume ``V_b`` of each boundary particle, m³ (m² in 2D) (``Ψ_b = ρ0 V_b``).
        ``"lattice"`` (default): walls sampled on the fluid's lattice with full kernel support,
        ``Ψ_b = mass``. ``"akinci"``: ``V_b = 1/Σ_k W_bk`` over the boundary (Akinci et al.
        2012, eq. 4), for thin or irregular walls.
    pass_precision : {"f64", "f32"}
        Arithmetic of the density and force passes (positions and velocities stay float64:
        not the scene's ``Scene(precision=)``, which is how the state is stored). ``"f32"`` is
        about twice as fast. Default ``"f64"``. WCSPH only: DFSPH computes in float64 whatever
        this says.
    method : {"wcsph", "dfsph"}
        ``"wcsph"`` (default, unless ``solver`` says otherwise): Tait equation of state.
        ``"dfsph"``: divergence-free SPH (module docstring); ``gamma``, ``clamp_pressure`` and
        ``pass_precision`` then do not apply. A DFSPH fluid at rest settles at the defaults (a
        layer 24 particles deep: rms speed 0.013 m/s at t = 1–4 s); keep the default ``alpha``
        where a pressure or a float is measured (a large one holds the water up:
        docs/guide/fluids_dfsph.md, Limits).
    density_error : float
        DFSPH: the density solver iterates until the mean compression ``mean((ρ − ρ0)₊)/ρ0`` of
        the predicted state is at most this, in (0, 1). Default 1e-3 (0.1 %); 1e-4 is the
        paper's strict setting. It bounds the mean over the particles of the predicted state
        only: the compression a state actually reaches can exceed it a little (at rest
        measured up to 0.1016 % at the default) and single particles by far more (up to 0.83 %
        at rest); the tolerance is on the average, as in Bender & Koschier (2015, Alg. 3).
    divergence_error : float
        DFSPH: the divergence solver's tolerance, ``mean((Dρ/Dt)₊) dt/ρ0``, in (0, 1). Default 1e-3.
    max_iterations : int
        DFSPH: most iterations of each solve (1..100000). Default 100.
    cfl : float
        DFSPH: the CFL number λ of the step limit ``λ h/|v|max``, in (0, 1]. Default 0.4.
    surface_tension : float
        DFSPH: surface tension σ ≥ 0, N/m (N in 2D; water: 0.072 N/m). Default 0: none. The
        cohesion and curvature forces of Akinci, Akinci & Teschner, "Versatile surface tension
        and adhesion for SPH fluids", ACM TOG 32(6) 182, 2013, eq. 1–6, with the paper's γ set
        from σ by the Kirkwood–Buff integral of the cohesion force (module docstring). Adds
        the capillary step limit ``0.25 √(ρ0 h³/(2π σ))`` (Brackbill et al. 1992).
        Limit of the model, measured (``benches/fluids/droplet_oscillation.py``,
        ``docs/surface_tension.md``; water, drops released as ellipses of axes R(1 ± 0.1)): drops
        ring near Rayleigh's frequency but damp several times faster than their viscosity
        explains. 2D, ν = 1.6e-5 m²/s (``ν = α c0 h/8``), medians (ranges) over four drops:
        ω/ω_Rayleigh 0.96 (0.82–1.07) at 24 particles across (R = 9.2 h) and 1.02 (0.70–1.20)
        at 40 (R = 15.4 h); the mode-2 decay rate over the viscous ``4ν/R²`` (Lamb's
        calculation, §355, for a cylinder) 5.8 (4.8–6.4) at 24 across, 12 (9.9–13.3) at 40 and
        31 at 64, where the drop keeps up to a third of its deformation: refining makes it
        worse, so it is the model's, not a resolution error. At α = 0 the mode still decays
        (1.2–1.7 s⁻¹ at 24 across, 3–4 times the viscous rate of ν = 1.6e-5) and rings 8–31 %
        slow (24 and 40 across). 3D, 12 and 16 across (R = 4.6 h, 6.1 h): ω/ω_Rayleigh 1.09,
        decay 2.6–2.9 times ``5ν/R²`` (Lamb 1932, §355). Cause, as far as measured: the
        viscosity's own work on the drop's mode-2 flow is about half the continuum's
        ``2ρ0ν∫e:e`` (0.39–0.45 at 24 across; the Monaghan term acts on approaching pairs
        only), under a tenth of the 2D decay at ν = 1.6e-5 (a fifth in 3D). The rest leaves
        through the fluid's only other forces, the surface forces and the pressure projections:
        the drop carries a particle-scale jitter of 4–15 times the mode's kinetic energy (2D,
        24 and 40 across), which the surface forces drive and the projections remove (22–57
        times the mode's peak kinetic energy over two periods). Use the model for the shapes
        and the Laplace pressure of drops, not for their damping (measured 2026-11-30).
    adhesion : float
        DFSPH: attraction of the fluid to the walls (Akinci et al. 2013, eq. 7), in σ's units:
        half the work of adhesion, so ``adhesion = surface_tension`` makes a wall attract like
        fluid (continuum contact angle ``cos θ = 2·adhesion/σ − 1``, Young–Dupré). Default 0.
    name : str
        Key of the fluid in the energy books.
    solver : WCSPH or DFSPH, optional
        The solver as a record holding its own options, checked when it is made:
        ``solver=pc.DFSPH(cfl=0.3)`` makes the same fluid as ``method="dfsph", cfl=0.3`` (same
        core term, same saved file). It sets ``method`` and the record's fields; the fluid keeps
        them as fields (``fluid.method``, ``fluid.cfl``) and not the record. A ``method`` naming
        the other solver, or one of the record's options also given here with another value than
        the record's, raises InvalidInputError naming it (an option left at its default defers
        to the record).

    Raises
    ------
    TypeError
        An argument of the wrong type, naming it.
    InvalidInputError
        (a ``ValueError``) A value out of range, naming it, including a density and spacing
        whose particle mass ``≈ ρ0 Δx^dim`` or Tait stiffness ``ρ0 c0²`` float64 cannot hold.
    """

    #: Not replaceable by :meth:`Scene.replace`: it owns particles and a neighbour search.
    replaceable: ClassVar[bool] = False

    positions: np.ndarray
    spacing: float
    _: KW_ONLY
    velocities: np.ndarray | None = None
    density: float = 1000.0
    sound_speed: float | None = None
    alpha: float = 0.05
    #: None while being made: then :func:`default_smoothing` of the dimension and the solver.
    smoothing: float = None  # type: ignore[assignment]
    kernel: str = "cubic_spline"
    # The solver options' defaults are their records' (WCSPH, DFSPH).
    gamma: int = WCSPH.gamma
    clamp_pressure: bool = WCSPH.clamp_pressure
    mass: float | None = None
    boundary: np.ndarray | None = None
    boundary_volume: str | float | np.ndarray = "lattice"
    pass_precision: str = WCSPH.pass_precision
    #: None while being made: the solver record's name, else "wcsph" (always a str once made).
    method: str = None  # type: ignore[assignment]
    density_error: float = DFSPH.density_error
    divergence_error: float = DFSPH.divergence_error
    max_iterations: int = DFSPH.max_iterations
    cfl: float = DFSPH.cfl
    surface_tension: float = DFSPH.surface_tension
    adhesion: float = DFSPH.adhesion
    name: str = "fluid"
    #: Index of the first particle once added to a scene (set by :meth:`Scene.add`).
    first: int | None = field(default=None, compare=False)
    #: The solver as a record: not kept (it sets ``method`` and its options, which the fluid
    #: keeps as fields; ``dataclasses.replace`` leaves them as they are).
    solver: InitVar[SPHSolver | None] = None

    @allocating("Fluid", "its arrays")
    def __post_init__(self, solver: SPHSolver | None = None) -> None:
        x = _array2(self.positions, "positions")
        dim = x.shape[1]
        object.__setattr__(self, "positions", x)
        if self.velocities is not None:
            v = _array2(self.velocities, "velocities")
            if v.shape != x.shape:
                raise InvalidInputError(f"velocities: expected shape {x.shape}, got {v.shape}")
            object.__setattr__(self, "velocities", v)
        object.__setattr__(self, "spacing", _finite_float(self.spacing, "spacing", minimum=0.0, strict=True))
        object.__setattr__(self, "density", _finite_float(self.density, "density", minimum=0.0, strict=True))
        if self.sound_speed is not None:
            object.__setattr__(self, "sound_speed", _finite_float(self.sound_speed, "sound_speed", minimum=0.0, strict=True))
        object.__setattr__(self, "alpha", _finite_float(self.alpha, "alpha", minimum=0.0))
        if self.smoothing is None:
            # The default follows the solver and the dimension (DEFAULT_SMOOTHING's note); the
            # solver is read here because the masses below depend on h.
            method = getattr(solver, "name", None) or (self.method if isinstance(self.method, str) else None) or "wcsph"
            surface = any(
                isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                for v in (getattr(solver, arg, getattr(self, arg)) for arg in ("surface_tension", "adhesion"))
            )
            object.__setattr__(self, "smoothing", default_smoothing(dim, method, surface))
        object.__setattr__(self, "smoothing", _finite_float(self.smoothing, "smoothing", minimum=0.0, strict=True))
        if not 0.5 <= self.smoothing <= 4.0:
            raise InvalidInputError(f"smoothing: h/spacing must be in [0.5, 4] (typical 1.2-2), got {self.smoothing}")
        lo, hi = SPACING_RANGE
        if not lo <= self.spacing <= hi:
            raise InvalidInputError(
                f"spacing: must be in [{lo:g}, {hi:g}] m (so that h^dim, 1/h^dim and kernel distances fit float64), got {self.spacing}"
            )
        if not isinstance(self.kernel, str) or self.kernel not in KERNELS:
            raise InvalidInputError(f"kernel: unknown kernel {self.kernel!r}; valid: {', '.join(KERNELS)}")
        if self.mass is not None:
            object.__setattr__(self, "mass", _check.mass("mass", _finite_float(self.mass, "mass", minimum=0.0, strict=True)))
        if self.boundary is not None:
            w = _array2(self.boundary, "boundary")
            if w.shape[1] != dim:
                raise InvalidInputError(f"boundary: expected shape (M, {dim}) (the positions are {dim}D), got {w.shape}")
            object.__setattr__(self, "boundary", w)
        wv = self.boundary_volume
        if isinstance(wv, str):
            if wv not in ("lattice", "akinci"):
                raise InvalidInputError(f"boundary_volume: expected 'lattice', 'akinci', a float or an array, got {wv!r}")
        else:
            a = _check.array("boundary_volume", wv)
            if a.dtype.kind not in "iuf" or a.dtype == bool:
                raise InvalidTypeError(f"boundary_volume: expected 'lattice', 'akinci' or real numbers, got dtype {a.dtype}")
            m = 0 if self.boundary is None else self.boundary.shape[0]
            a = np.full(m, float(a)) if a.ndim == 0 else a.astype(np.float64)
            if a.shape != (m,) or not np.all(np.isfinite(a) & (a > 0)):
                raise InvalidInputError(f"boundary_volume: expected finite values > 0, scalar or shape ({m},)")
            with np.errstate(over="ignore", under="ignore"):
                psi = a * self.density
            if not np.all(np.isfinite(psi) & (psi > 0)):
                raise InvalidInputError("boundary_volume: the boundary masses density·boundary_volume are outside float64 range")
            a.setflags(write=False)
            object.__setattr__(self, "boundary_volume", a)
        if self.sound_speed is not None and not math.isfinite(self.density * self.sound_speed * self.sound_speed):
            raise InvalidInputError("sound_speed: the Tait stiffness density·sound_speed² overflows float64")
        if self.mass is not None:
            # The core takes the particles' spacing from m/ρ0 where it samples a body's surface;
            # a mass far from ρ0·spacing^dim made it sample at a billionth of the spacing (an
            # abort on a 22 GB allocation, found by a file with an edited density).
            log_ratio = math.log(self.mass) - math.log(self.density) - dim * math.log(self.spacing)
            if not abs(log_ratio) <= math.log(1e3):
                raise InvalidInputError(
                    f"mass: {self.mass:.4g} kg is {math.exp(min(log_ratio, 700.0)):.3g} times density · spacing^{dim}; a "
                    "particle's mass must lie within a factor 1000 of it (about ρ0 Δx^dim), or leave mass out"
                )
        if self.mass is None:
            # ρ0 Δx^dim, computed here so that a density or spacing giving an unusable particle
            # mass is refused by name (not later as "masses" of Scene.add_particles).
            m = self.particle_mass()
            if not (math.isfinite(m) and m >= _check.MIN_MASS):
                raise InvalidInputError(
                    f"density: {self.density} kg/m^{dim} with spacing {self.spacing} m gives a particle mass of {m:.3g} kg, "
                    f"outside float64's usable range [{_check.MIN_MASS:.3g}, max]"
                )
        if isinstance(self.boundary_volume, np.ndarray) and not np.all(np.isfinite(_scaled(self.boundary_volume, self.density))):
            raise InvalidInputError("boundary_volume: density · boundary volume overflows float64")
        _check_wcsph(self)
        if self.method is not None and (not isinstance(self.method, str) or self.method not in METHODS):
            raise InvalidInputError(f"method: expected one of {', '.join(map(repr, METHODS))}, got {self.method!r}")
        _check_dfsph(self)
        if solver is not None:
            self._take_solver(solver)
        elif self.method is None:
            object.__setattr__(self, "method", "wcsph")
        for arg in ("surface_tension", "adhesion"):
            v = getattr(self, arg)
            if v > 0 and self.method != "dfsph":
                raise InvalidInputError(f"{arg}: needs method='dfsph' (WCSPH has no surface tension), got {v} with method={self.method!r}")
        if not isinstance(self.name, str) or not self.name:
            raise InvalidTypeError("name: expected a non-empty str")
        _check.text("name", self.name)

    def _take_solver(self, solver: object) -> None:
        """Set ``method`` and the options from a solver record. An option also given as a keyword
        (checked already) with another value than the record's, and not at its default, is given
        twice: InvalidInputError naming it; so is a ``method`` naming another solver."""
        if not isinstance(solver, SPHSolver):
            raise InvalidTypeError(f"solver: expected a solver record (pc.WCSPH(...), pc.DFSPH(...)), got {type(solver).__name__}")
        if self.method is not None and self.method != solver.name:
            raise InvalidInputError(f"method: {self.method!r} conflicts with solver={solver!r}; give one of them")
        for f in dataclasses.fields(solver):
            given, value = getattr(self, f.name), getattr(solver, f.name)
            if given != f.default and given != value:
                raise InvalidInputError(
                    f"{f.name}: {given!r} conflicts with solver={solver!r}, which sets it to {value!r}; give it once"
                )
        for f, value in solver.options().items():
            object.__setattr__(self, f, value)
        object.__setattr__(self, "method", solver.name)

    # ------------------------------------------------------------ the term protocol (see Term)
    #: Scene files keep the keys they had before issue 45 (``viscosity``, ``precision``,
    #: ``walls``, ``wall_volume``: the record's own names, like the core's keys; docs/naming.md).
    record_fields: ClassVar[dict[str, str]] = {
        "count": "count",
        "first": "count",
        "spacing": "number",
        "density": "number",
        "sound_speed": "number",
        "viscosity": "number",
        "smoothing": "number",
        "kernel": "str",
        "gamma": "int",
        "clamp_pressure": "bool",
        "precision": "str",
        "mass": "number",
    }
    #: DFSPH's fields: files written before it have none (their fluids are WCSPH).
    record_fields_optional: ClassVar[dict[str, str]] = {
        "method": "str",
        "density_error": "number",
        "divergence_error": "number",
        "max_iterations": "int",
        "cfl": "number",
        "surface_tension": "number",
        "adhesion": "number",
        # How the boundary's Ψ_b came about ("lattice", "akinci" or "given"): a load recomputes
        # them by the same rule, bit for bit (ρ0·(Ψ/ρ0) is not always Ψ: a dam break loaded
        # from its file stepped 3e-14 m/s away from the run it was saved from).
        "wall_rule": "str",
    }
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "positions": ("f8", ("count", "D")),
        "walls": ("f8", ("W", "D")),
        "wall_volume": ("f8", ("W",)),
    }
    #: DFSPH: the solvers' warm starts (2 per particle; the scene adds them from the core).
    record_optional: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {"history": ("f8", ("H",))}
    owns_particles: ClassVar[bool] = True

    def _attach(self, ctx: AttachContext, name: str) -> Fluid:
        return _add_fluid(ctx, self, name, ctx.restoring.get("first"))

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        meta: dict[str, Any] = {"count": len(self), "first": self.first}
        stored = {"viscosity": "alpha", "precision": "pass_precision"}  # file key -> attribute
        for f in ("spacing", "density", "sound_speed", "viscosity", "smoothing", "kernel", "precision", "method",
                  "density_error", "divergence_error", "cfl", "surface_tension", "adhesion"):
            meta[f] = getattr(self, stored.get(f, f))
        meta["max_iterations"] = int(self.max_iterations)
        meta["gamma"] = int(self.gamma)
        meta["clamp_pressure"] = bool(self.clamp_pressure)
        meta["mass"] = self.particle_mass()
        walls = self.boundary if self.boundary is not None else np.zeros((0, self.dim))
        wv = self.boundary_volume
        meta["wall_rule"] = wv if isinstance(wv, str) else "given"
        # Given volumes as given (Ψ = ρ0·V again on load); a rule's Ψ/ρ0 for readers of the volumes.
        volume = wv if isinstance(wv, np.ndarray) and len(wv) == len(walls) else self.boundary_psi() / self.density
        return meta, {"positions": self.positions, "walls": walls, "wall_volume": volume}

    @classmethod
    def record_api_names(cls, k: int, ctx: str) -> dict[str, str]:
        # The arguments renamed in issue 45 stand for the file's old keys.
        return {"n": f"{ctx}.first", "alpha": f"{ctx}.viscosity", "pass_precision": f"{ctx}.precision",
                "boundary": f"term{k}_walls", "boundary_volume": f"term{k}_wall_volume"}

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        walls = arrays["walls"]
        # Files written before "wall_rule" hold the volumes alone.
        rule = meta.get("wall_rule", "given")
        if rule not in ("lattice", "akinci", "given"):
            raise InvalidInputError(f"wall_rule: expected 'lattice', 'akinci' or 'given', got {rule!r}")
        volume = (arrays["wall_volume"] if rule == "given" else rule) if len(walls) else "lattice"
        fluid = cls(
            arrays["positions"],
            meta["spacing"],
            density=meta["density"],
            sound_speed=meta["sound_speed"],
            alpha=meta["viscosity"],
            smoothing=meta["smoothing"],
            kernel=meta["kernel"],
            gamma=meta["gamma"],
            clamp_pressure=meta["clamp_pressure"],
            mass=meta["mass"],
            boundary=walls if len(walls) else None,
            boundary_volume=volume,
            pass_precision=meta["precision"],
            # Files written before DFSPH have no method: they are WCSPH.
            method=meta.get("method", "wcsph"),
            density_error=meta.get("density_error", 1e-3),
            divergence_error=meta.get("divergence_error", 1e-3),
            max_iterations=meta.get("max_iterations", 100),
            cfl=meta.get("cfl", 0.4),
            surface_tension=meta.get("surface_tension", 0.0),
            adhesion=meta.get("adhesion", 0.0),
            name=meta["name"],
        )
        dt_saved = ctx.sim.dt  # the file's dt, which adding lowers to the fluid's CFL limit
        # Its particles are in the scene already (the file's positions): the fluid is added over them.
        added = ctx.add(fluid, first=meta["first"])
        if "history" in arrays:
            ctx.sim.set_term_history(added.name, np.ascontiguousarray(arrays["history"], dtype=np.float64))
        ctx.sim.dt = dt_saved

    @property
    def dim(self) -> int:
        return int(self.positions.shape[1])

    @property
    def h(self) -> float:
        """Smoothing length ``h = smoothing · spacing``, m (kernel support ``2h``)."""
        return self.smoothing * self.spacing

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    def particle_mass(self) -> float:
        """Mass of each particle, kg (see ``mass``)."""
        if self.mass is not None:
            return self.mass
        return float(_core.sph_particle_mass(self.density, self.spacing, self.h, self.dim, self.kernel))

    def boundary_psi(self) -> np.ndarray:
        """``Ψ_b = ρ0 V_b`` of each boundary particle, kg: (M,) float64 (the core's formula,
        ``sph::resolve``; Akinci et al. 2012, eq. 4–5). Raises InvalidInputError naming
        ``wall_volume, density`` where one is not a finite number > 0 (the core's names)."""
        if self.boundary is None or len(self.boundary) == 0:
            return np.zeros(0)
        wv = self.boundary_volume
        walls = np.ascontiguousarray(self.boundary, dtype=np.float64)
        if isinstance(wv, np.ndarray):
            given = np.ascontiguousarray(wv, dtype=np.float64).reshape(-1)
            return _core.sph_wall_psi(walls, self.density, self.h, self.kernel, "given", 0.0, given)
        mass = self.particle_mass() if wv == "lattice" else 0.0
        return _core.sph_wall_psi(walls, self.density, self.h, self.kernel, wv, mass)

    def wall_psi(self) -> np.ndarray:
        """Deprecated alias of :meth:`boundary_psi`."""
        _deprecate.warn("Fluid.wall_psi() is now .boundary_psi()")
        return self.boundary_psi()

    def max_dt(self) -> float:
        """The step limit at rest, s (needs ``sound_speed``; the core's formula, ``sph::resolve``):
        WCSPH ``0.25 h / (c0 (1 + 0.6 α))`` (Monaghan 1992, §5); DFSPH: the viscous limit
        ``0.125 h²/ν = (d + 2) h/(4 α c0)`` (Monaghan 2005, §4.3) and, with surface tension, the
        capillary limit ``0.25 √(ρ0 h³/(2π max(σ, adhesion)))`` (Brackbill et al. 1992, eq. 61)
        (infinite without either: the flow's speed sets it)."""
        if self.sound_speed is None:
            raise InvalidInputError("sound_speed: not set yet (it is estimated when the fluid is added to a scene)")
        return float(_core.sph_max_dt(self.method, self.dim, self.h, self.sound_speed, self.alpha,
                                      self.density, self.surface_tension, self.adhesion))


# ----------------------------------------------------------------------------- joining a scene
#: Most fluids that share one neighbour search (the core's MAX_FLUIDS).
_FLUIDS_PER_SEARCH = 8


def _check_fluid_method(ctx: AttachContext, fluid: Fluid) -> None:
    """Refuse, before anything is added, a DFSPH fluid this scene cannot step: the core's
    part–integrator rule (DFSPH runs inside "semi_implicit_euler" steps)."""
    if fluid.method == "dfsph":
        _core.check_integrator("dfsph", ctx.integrator)


def _search_key(fluid: Fluid) -> tuple[Any, ...]:
    """What two fluids must share to push on each other (the core's rule): WCSPH fluids share a
    neighbour search when ``h``, kernel and pass precision agree (up to 8 a search); DFSPH fluids
    share one solve when ``h``, kernel, rest density and the solver's settings (tolerances,
    iterations, surface tension, adhesion) agree. A WCSPH and a DFSPH fluid never do."""
    if fluid.method == "dfsph":
        return ("dfsph", fluid.h, fluid.kernel, fluid.density, fluid.density_error, fluid.divergence_error,
                int(fluid.max_iterations), fluid.surface_tension, fluid.adhesion)
    return ("wcsph", fluid.h, fluid.kernel, fluid.pass_precision)


def _warn_separate_fluids(ctx: AttachContext, fluid: Fluid, name: str) -> None:
    """Warn (:class:`SeparateFluidsWarning`) if ``fluid`` will not interact with some fluid
    already in the scene (see :func:`_search_key`; a 9th WCSPH fluid starts a new search, which
    the next ones join)."""
    fluids = [t for t in ctx.parts if isinstance(t, Fluid)]
    key = _search_key(fluid)
    alike = [f for f in fluids if _search_key(f) == key]
    per = _FLUIDS_PER_SEARCH if fluid.method == "wcsph" else len(alike) + 1
    together = alike[len(alike) - len(alike) % per :]
    apart = [f.name for f in fluids if all(f is not g for g in together)]
    if apart:
        if len(together) < len(alike):
            why = f"{_FLUIDS_PER_SEARCH} fluids already share its neighbour search"
        elif fluid.method == "dfsph":
            why = ("a DFSPH fluid pushes only on DFSPH fluids with the same h (smoothing · spacing), kernel, density, "
                   "density_error, divergence_error, max_iterations, surface_tension and adhesion")
        else:
            why = ("a WCSPH fluid pushes only on WCSPH fluids with the same h (smoothing · spacing), kernel and "
                   "pass_precision")
        shown = ", ".join(repr(a) for a in apart[:5]) + (", ..." if len(apart) > 5 else "")
        warnings.warn(
            f"{name!r} does not interact with the scene's fluid(s) {shown} and will pass through them: {why}",
            SeparateFluidsWarning,
            # The frame it named before the part protocol (Scene.add's decorator): one more
            # frame (Scene._add) lies between now.
            stacklevel=6,
        )


def _add_fluid(ctx: AttachContext, fluid: Fluid, name: str, first: int | None = None) -> Fluid:
    """Append the fluid's particles (unless ``first`` says they exist: a fluid loaded from a
    file) and its SPH term; returns the fluid as stored."""
    dim = ctx.dim
    if fluid.dim != dim:
        raise InvalidInputError(f"positions: the fluid is {fluid.dim}D, the scene is {dim}D")
    c0 = fluid.sound_speed
    if c0 is None:
        # The core estimates it (``sph::resolve::sound_speed``) from the scene's gravity.
        g = sum((t.g for t in ctx.parts if isinstance(t, Gravity)), np.zeros(dim))
        pos = np.ascontiguousarray(fluid.positions, dtype=np.float64)
        vel = None if fluid.velocities is None else np.ascontiguousarray(fluid.velocities, dtype=np.float64)
        c0 = float(_core.sph_sound_speed(pos, vel, np.ascontiguousarray(g, dtype=np.float64), fluid.spacing,
                                         fluid.density, fluid.h, max(fluid.surface_tension, fluid.adhesion)))
    fluid = dataclasses.replace(fluid, sound_speed=c0, name=name)
    walls = fluid.boundary if fluid.boundary is not None else np.zeros((0, dim))
    psi = fluid.boundary_psi()
    max_dt = fluid.max_dt()
    # The scene's dt is lowered to this; a subnormal or zero step would never advance.
    if not max_dt >= _check.MIN_NORMAL:
        what = (
            "step limit (viscous (d + 2) h/(4 α c0), capillary 0.25 √(ρ0 h³/(2π max(σ, adhesion))))"
            if fluid.method == "dfsph"
            else "CFL step 0.25 h / (c0 (1 + 0.6 α))"
        )
        args = "sound_speed, alpha, spacing" + (", surface_tension, adhesion" if fluid.method == "dfsph" else "")
        raise InvalidInputError(f"{args}: the fluid's {what} = {max_dt:.3g} s is below float64's normal range")
    m = fluid.particle_mass()
    # Also for a fluid loaded from a file (`first` given): a file may pair DFSPH with another fluid.
    _check_fluid_method(ctx, fluid)
    if first is None:
        _warn_separate_fluids(ctx, fluid, name)
        n = len(fluid)
        first = int(ctx.add_particles(fluid.positions, fluid.velocities, np.full(n, m))[0]) if n else ctx.n_particles
    common = {
        "first": first,
        "n": len(fluid),
        "h": fluid.h,
        "density": fluid.density,
        "sound_speed": c0,
        "viscosity": fluid.alpha,  # the core's key for α
        "kernel": fluid.kernel,
        "walls": np.ascontiguousarray(walls, dtype=np.float64),
        "wall_psi": np.ascontiguousarray(psi, dtype=np.float64),
    }
    if fluid.method == "dfsph":
        ctx.sim.add_term(
            "dfsph",
            name,
            common
            | {
                "density_error": fluid.density_error,
                "divergence_error": fluid.divergence_error,
                "max_iterations": int(fluid.max_iterations),
                "cfl": fluid.cfl,
                "surface_tension": fluid.surface_tension,
                "adhesion": fluid.adhesion,
                # h/Δx: the solves' Jacobi relaxation follows from it (rust_core/src/sph/dfsph/relax.rs).
                "smoothing": fluid.smoothing,
            },
        )
    else:
        ctx.sim.add_term(
            "sph",
            name,
            common | {"gamma": int(fluid.gamma), "clamp_pressure": bool(fluid.clamp_pressure), "precision": fluid.pass_precision},
        )
    fluid = dataclasses.replace(fluid, first=first)
    # A step above the fluid's CFL limit would blow up on the first step.
    ctx.lower_dt(max_dt)
    return fluid
