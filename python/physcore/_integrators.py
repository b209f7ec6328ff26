"""The integrator records: one small immutable record per integrator of
:data:`physcore.INTEGRATORS`, holding that integrator's own options (issue 62, "Seams before
the second backend").

``Scene(integrator=pc.Dopri5(rtol=1e-8))`` is the same scene as
``Scene(integrator="dopri5", rtol=1e-8)``: the record gives its name and sets the Scene keywords
it owns (:attr:`Integrator.scene_options`); the core, the scene file and ``Scene.integrator`` (the
name) see no difference. Each record checks its fields when it is made, with the checks Scene's
keywords use (the ranges of ``rtol``, ``atol`` and ``cg_tol`` are the core's, asked of it).

This module imports nothing of :mod:`physcore.scene`.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

from . import _check, _core
from ._errors import InvalidInputError, InvalidTypeError

__all__ = [
    "Integrator",
    "Euler",
    "SemiImplicitEuler",
    "Verlet",
    "Yoshida4",
    "RK4",
    "Dopri5",
    "WisdomHolman",
    "Boris",
    "XPBD",
    "ImplicitEuler",
    "REGISTRY",
]

#: Every integrator record by its integrator name (``Integrator.name``), filled as the record
#: classes are defined. A test checks it covers :data:`physcore.INTEGRATORS`.
REGISTRY: dict[str, type[Integrator]] = {}

#: Ranges of the integer options, as Scene checks them (``Scene(cg_max_iter=...)``,
#: ``xpbd_substeps``, ``xpbd_iterations``): (lowest, highest).
CG_MAX_ITER_RANGE = (1, 1_000_000)
XPBD_SUBSTEPS_RANGE = (1, 100_000)
XPBD_ITERATIONS_RANGE = (1, 10_000)


def check_cg_max_iter(value: object, arg: str = "cg_max_iter") -> int:
    """``value`` as an int in :data:`CG_MAX_ITER_RANGE` (TypeError / InvalidInputError naming ``arg``)."""
    return _check.int_in_range(arg, value, *CG_MAX_ITER_RANGE)


def check_xpbd_substeps(value: object, arg: str = "xpbd_substeps") -> int:
    """``value`` as an int in :data:`XPBD_SUBSTEPS_RANGE` (naming ``arg``)."""
    return _check.int_in_range(arg, value, *XPBD_SUBSTEPS_RANGE)


def check_xpbd_iterations(value: object, arg: str = "xpbd_iterations") -> int:
    """``value`` as an int in :data:`XPBD_ITERATIONS_RANGE` (naming ``arg``)."""
    return _check.int_in_range(arg, value, *XPBD_ITERATIONS_RANGE)


#: The coordinates of ``"wisdom_holman"`` (``WisdomHolman(coordinates=...)``, Scene's
#: ``wh_coordinates``), the default first.
WH_COORDINATES = ("jacobi", "democratic_heliocentric")


def check_wh_coordinates(value: object, arg: str = "wh_coordinates") -> str:
    """``value`` as one of :data:`WH_COORDINATES` (TypeError / InvalidInputError naming ``arg``)."""
    return _check.choice(arg, value, WH_COORDINATES)


#: The orders of ``"wisdom_holman"``'s symplectic corrector (``WisdomHolman(corrector=...)``,
#: Scene's ``wh_corrector``); 0 is none (the default).
WH_CORRECTORS = (0, 3, 5, 7, 11, 17)


def check_wh_corrector(value: object, arg: str = "wh_corrector") -> int:
    """``value`` as one of :data:`WH_CORRECTORS` (TypeError / InvalidInputError naming ``arg``)."""
    order = _check.int_in_range(arg, value, 0, 17)
    if order not in WH_CORRECTORS:
        raise InvalidInputError(f"{arg}: {order} is no corrector's order: 0 (none) or one of {WH_CORRECTORS[1:]}")
    return order


def _core_rules() -> Any:
    """A bare core simulation, asked only to check options: the ranges of ``rtol``, ``atol`` and
    ``cg_tol`` are the core's (``set_tolerances``, ``set_solver_options``), stated there once.
    About 30 µs; it never steps, and runs on the core's shared thread pool."""
    return _core.Simulation(2, "verlet", 1e-3, None)


@dataclass(frozen=True)
class Integrator:
    """Base of the integrator records. A subclass registers itself by its integrator name
    (``class RK4(Integrator, name="rk4")``) and lists in :attr:`scene_options` the
    :class:`~physcore.Scene` keywords its fields stand for. Records compare by value, hash, and
    are immutable; their fields are keyword-only."""

    #: The integrator's name in :data:`physcore.INTEGRATORS`, ``Scene.integrator`` and scene files.
    name: ClassVar[str] = ""
    #: Scene keyword -> this record's field, for each option the integrator owns.
    scene_options: ClassVar[dict[str, str]] = {}

    def __init_subclass__(cls, name: str = "", **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if name:
            if name in REGISTRY:
                raise InvalidTypeError(f"name: {name!r} is already the name of {REGISTRY[name].__name__}")
            cls.name = name
            REGISTRY[name] = cls

    def options(self) -> dict[str, Any]:
        """The Scene keywords this record sets, with its values (``{"rtol": 1e-8, "atol": 1e-9}``
        for ``Dopri5(rtol=1e-8)``; ``{}`` for an integrator without options): a new dict."""
        return {kw: getattr(self, f) for kw, f in self.scene_options.items()}

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """The Scene keywords of :meth:`options` at the record's defaults (Scene's defaults)."""
        by_field = {f.name: f.default for f in fields(cls)}
        return {kw: by_field[f] for kw, f in cls.scene_options.items()}


@dataclass(frozen=True, kw_only=True)
class Euler(Integrator, name="euler"):
    """Explicit (forward) Euler: first order, not symplectic, gains energy on every oscillator;
    there for contrast. No options.

    >>> import physcore as pc
    >>> pc.Scene(integrator=pc.Euler()).integrator
    'euler'
    """


@dataclass(frozen=True, kw_only=True)
class SemiImplicitEuler(Integrator, name="semi_implicit_euler"):
    """Semi-implicit (symplectic) Euler, kick then drift: first order, symplectic; the one a DFSPH
    fluid steps with. No options."""


@dataclass(frozen=True, kw_only=True)
class Verlet(Integrator, name="verlet"):
    """Velocity Verlet (kick–drift–kick): second order, symplectic, one force evaluation a step;
    Scene's default. No options."""


@dataclass(frozen=True, kw_only=True)
class Yoshida4(Integrator, name="yoshida4"):
    """Yoshida's fourth-order composition of three velocity-Verlet substeps (Yoshida, Phys. Lett.
    A 150 (1990) 262, eq. 4.14): symplectic, 3 force evaluations a step. No options."""


@dataclass(frozen=True, kw_only=True)
class RK4(Integrator, name="rk4"):
    """The classic fourth-order Runge–Kutta method: 4 force evaluations a step, not symplectic.
    No options."""


@dataclass(frozen=True, kw_only=True)
class Dopri5(Integrator, name="dopri5"):
    """Adaptive Dormand–Prince 5(4) (Dormand & Prince, J. Comput. Appl. Math. 6, 1980): each step
    of ``dt`` is integrated in as many error-controlled internal steps (6 force evaluations each)
    as the tolerances need, and lands exactly on its end.

    Parameters
    ----------
    rtol : float
        Relative tolerance, in [1e-14, 1) (dimensionless). Default 1e-6. An internal step is
        accepted when every position and velocity component i has a local error estimate below
        ``atol + rtol · |y_i|`` (max norm over all particles).
    atol : float
        Absolute tolerance, finite and >= 0: m for positions, m/s for velocities. Default 1e-9.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) A field not a real number (``bool`` and ``str`` are not), naming it.
    InvalidInputError
        (a ``ValueError``) A field out of range (the core's rule, as ``Scene(rtol=...)``), naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.Scene(integrator=pc.Dopri5(rtol=1e-8))
    >>> scene.integrator, scene.rtol, scene.atol
    ('dopri5', 1e-08, 1e-09)
    """

    scene_options: ClassVar[dict[str, str]] = {"rtol": "rtol", "atol": "atol"}

    rtol: float = 1e-6
    atol: float = 1e-9

    def __post_init__(self) -> None:
        rtol, atol = _check.real("rtol", self.rtol), _check.real("atol", self.atol)
        _core_rules().set_tolerances(rtol, atol)  # InvalidInputError naming rtol or atol
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)


@dataclass(frozen=True, kw_only=True)
class WisdomHolman(Integrator, name="wisdom_holman"):
    """The Wisdom–Holman map for planetary systems (Wisdom & Holman, AJ 102 (1991) 1528): each
    body follows a Kepler orbit exactly (a universal-variable Kepler solver, Danby 1992 §6.9), and
    the rest of the forces kick it. Second order, symplectic, one force evaluation a step, with
    an error of order (m_planet / m_central) dt²: on the outer Solar System it reaches Verlet's
    energy error at a step 43 times longer (P_Jupiter/20 against P_Jupiter/860, in Jacobi
    coordinates).

    Parameters
    ----------
    coordinates : {"jacobi", "democratic_heliocentric"}
        The split. ``"jacobi"`` (default; Wisdom & Holman 1991, as REBOUND's WHFast, Rein &
        Tamayo, MNRAS 452 (2015) 376): body k's orbit is about the centre of mass of the
        heaviest particle and the bodies listed before it, with their mass (list the planets from
        the inside out). ``"democratic_heliocentric"`` (Duncan, Levison & Lee, AJ 116 (1998)
        2067): each orbit is about the heaviest particle, with heliocentric positions and
        barycentric velocities, and the Sun's reflex is a separate drift (the order of the bodies
        does not matter). Jacobi is the default because it is the more accurate on a hierarchical
        system for the same force evaluations: on the outer Solar System over 10⁴ years at
        P_Jupiter/20 its energy error is half the heliocentric one (REBOUND's WHFast's, to three
        digits), on a star with planets at a = 1 and 4 a fifteenth of it, and two bodies are
        exact. Its step costs two Kepler solves a body to the heliocentric one's one, so on the
        outer Solar System the two reach a given error in about the same time; a body that
        passes inside the orbit of one listed before it (a comet) is better served by the
        heliocentric split (docs/guide/integrators.md). Scene's keyword ``wh_coordinates``.
        About a pinned (fixed) centre the two are the same map.
    corrector : {0, 3, 5, 7, 11, 17}
        The order of the symplectic corrector (Wisdom, Holman & Touma, Fields Inst. Commun. 10
        (1996) 217; as REBOUND's WHFast, Rein & Tamayo 2015, §4); 0 (default) for none. The map
        is, to first order in the planets' masses, a change of coordinates C away from the exact
        flow: stepping C(x) and handing back C⁻¹ of the result removes that part of its error
        through dt^(order+1). C is applied at the first step; each ``step``/``advance`` call
        hands back C⁻¹ of the corrected state, at 2(order − 1) force evaluations a call (32 for
        order 17), and keeps that state, from which the next call goes on (as WHFast with
        ``keep_unsynchronized``): outputs do not perturb the run, and ``step(n)`` and ``n``
        calls of ``step(1)`` give the same bits (as do one and many threads, and a saved and
        loaded scene: :meth:`Scene.state` and the file hold the corrected state). Changing the
        scene between calls (positions, velocities, terms, ``dt``, the order) makes the next
        call apply C afresh to the state it then has. Between the steps of one call the state is
        a private one (the corrected coordinates, and each step's second half drift joined with
        the next step's first, as WHFast does). On the outer Solar System at
        P_Jupiter/20, order 17 keeps the energy to 1.96e-9 against 2.31e-6 without, WHFast's
        errors to three digits (docs/guide/integrators.md). Jacobi coordinates about a free
        centre, and a scene without colliders, only (refused otherwise, naming
        ``wh_corrector``, when the scene steps). Scene's keyword ``wh_corrector``.

    The scene needs exactly one :class:`~physcore.PairwiseGravity` with ``softening=0`` (the
    Kepler part is split off it) and no velocity-dependent force; other conservative terms
    (uniform fields, springs, Coulomb forces) join the kick. Only the heaviest particle may be
    pinned, which makes it a fixed centre. A scene that does not fit is refused when it steps,
    before anything changes (:class:`~physcore.InvalidInputError` naming ``integrator``). Close
    encounters between the other bodies are not treated specially: the step must resolve them,
    as with Verlet.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) ``coordinates`` not a str, or ``corrector`` not an int, naming it.
    InvalidInputError
        (a ``ValueError``) ``coordinates`` not one of the names, or ``corrector`` not one of the
        orders, naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.Scene(dim=2, dt=0.05, integrator=pc.WisdomHolman())
    >>> scene.wh_coordinates
    'jacobi'
    >>> _ = scene.add_particles([[0, 0], [1, 0], [2, 0]], [[0, 0], [0, 1], [0, 0.7071]],
    ...                         masses=[1.0, 1e-3, 1e-3])
    >>> _ = scene.add(pc.PairwiseGravity(G=1.0))
    >>> e0 = scene.energy().total
    >>> scene.step(1000)
    >>> abs(scene.energy().total / e0 - 1) < 1e-5
    True
    >>> scene.wh_corrector = 17  # the symplectic corrector, at both ends of each call
    >>> scene.step(1000)
    >>> abs(scene.energy().total / e0 - 1) < 1e-5
    True
    """

    scene_options: ClassVar[dict[str, str]] = {"wh_coordinates": "coordinates", "wh_corrector": "corrector"}

    coordinates: str = WH_COORDINATES[0]
    corrector: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "coordinates", check_wh_coordinates(self.coordinates, "coordinates"))
        object.__setattr__(self, "corrector", check_wh_corrector(self.corrector, "corrector"))


@dataclass(frozen=True, kw_only=True)
class Boris(Integrator, name="boris"):
    """The Boris push for charges in magnetic fields (Boris 1970; Birdsall & Langdon, *Plasma
    Physics via Computer Simulation*, §4-3): second order, volume-preserving, turns each velocity
    through B exactly; velocity Verlet when the scene has no magnetic term. No options."""


@dataclass(frozen=True, kw_only=True)
class XPBD(Integrator, name="xpbd"):
    """Extended position-based dynamics with substeps (Macklin, Müller & Chentanez, MIG 2016;
    Macklin et al., "Small steps in physics simulation", SCA 2019): each step is ``substeps``
    substeps of semi-implicit Euler under the force terms, each followed by ``iterations``
    projections of the :class:`~physcore.XpbdConstraints`. First order, damped by the projection.

    Parameters
    ----------
    substeps : int
        Substeps per step, 1 to 100000. Default 10. Scene's keyword ``xpbd_substeps``.
    iterations : int
        Constraint iterations per substep, 1 to 10000. Default 1. Scene's keyword
        ``xpbd_iterations``. Many substeps of one iteration each converge faster than few
        substeps of many iterations (Macklin et al. 2019).

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) A field not an int (``bool`` is not), naming it.
    InvalidInputError
        (a ``ValueError``) A field out of range, naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.Scene(dim=3, integrator=pc.XPBD(substeps=20))
    >>> scene.integrator, scene.xpbd_substeps, scene.xpbd_iterations
    ('xpbd', 20, 1)
    """

    scene_options: ClassVar[dict[str, str]] = {"xpbd_substeps": "substeps", "xpbd_iterations": "iterations"}

    substeps: int = 10
    iterations: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "substeps", check_xpbd_substeps(self.substeps, "substeps"))
        object.__setattr__(self, "iterations", check_xpbd_iterations(self.iterations, "iterations"))


@dataclass(frozen=True, kw_only=True)
class ImplicitEuler(Integrator, name="implicit_euler"):
    """Linearised backward Euler (Baraff & Witkin, SIGGRAPH 1998): springs and drag implicit,
    solved by conjugate gradients each step. First order, unconditionally stable on springs, at
    the price of numerical damping (the energy books show it as a residual).

    Parameters
    ----------
    cg_tol : float
        Conjugate gradients stop once the residual is below ``cg_tol`` times the right-hand
        side's norm (dimensionless), in [1e-14, 1). Default 1e-8.
    cg_max_iter : int
        ... or after this many iterations, 1 to 1000000. Default 200. A solve stopped by the
        limit keeps its last iterate and is counted in ``Scene.integrator_stats``.

    Raises
    ------
    InvalidTypeError
        (a ``TypeError``) A field of the wrong type, naming it.
    InvalidInputError
        (a ``ValueError``) A field out of range (``cg_tol``'s is the core's rule), naming it.

    Examples
    --------
    >>> import physcore as pc
    >>> scene = pc.Scene(dim=3, integrator=pc.ImplicitEuler(cg_tol=1e-10))
    >>> scene.integrator, scene.cg_tol, scene.cg_max_iter
    ('implicit_euler', 1e-10, 200)
    """

    scene_options: ClassVar[dict[str, str]] = {"cg_tol": "cg_tol", "cg_max_iter": "cg_max_iter"}

    cg_tol: float = 1e-8
    cg_max_iter: int = 200

    def __post_init__(self) -> None:
        cg_tol = _check.real("cg_tol", self.cg_tol)
        cg_max_iter = check_cg_max_iter(self.cg_max_iter)
        _core_rules().set_solver_options(cg_tol, cg_max_iter)  # InvalidInputError naming cg_tol
        object.__setattr__(self, "cg_tol", cg_tol)
        object.__setattr__(self, "cg_max_iter", cg_max_iter)
