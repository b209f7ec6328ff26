"""Grains that collide: the discrete element method (DEM) for discs (2D) and spheres (3D).

A :class:`Contacts` term makes the scene's particles solid grains of the radii in the scene's
``"radius"`` attribute (:meth:`~physcore.Scene.set_attribute`): overlapping grains push apart
through a spring–dashpot whose damping gives the chosen coefficient of restitution, rub through
Coulomb friction with a tangential spring (Cundall & Strack 1979), and roll, each grain carrying
an angular velocity. Pinned particles are fixed obstacles (pegs); walls are the colliders'
shapes (planes, boxes, balls and bowls, capsules, oriented boxes).

Examples
--------
Two discs collide head-on with e = 0.5: they separate at half their approach speed.

>>> import numpy as np, physcore as pc
>>> s = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=1)
>>> _ = s.add_particles([[0.0, 0.0], [0.03, 0.0]], [[1.0, 0.0], [-1.0, 0.0]], masses=0.01)
>>> s.set_attribute("radius", [0.01, 0.01])
>>> _ = s.add(pc.Contacts(stiffness=1e4, restitution=0.5))
>>> _ = s.advance(0.05)
>>> round(float(s.velocities[1, 0] - s.velocities[0, 0]) / 2.0, 2)   # separation / approach speed
0.5
>>> s.contact_count()
0
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, ClassVar

import numpy as np

from . import _core, _deprecate
from ._check import finite_float as _finite_float
from ._errors import InvalidInputError, InvalidTypeError, PhyscoreError
from ._parts import AttachContext, LoadContext
from .terms import Box, Capsule, OrientedBox, Plane, Sphere, Term

__all__ = ["Contacts"]

_LAWS = ("linear", "hertz")

#: The collider records a wall may be, by their key (the core's ``wall_kinds``), each with the
#: fields that give its geometry, in the order the core reads them (``terms::contacts::walls``);
#: every wall also has its ``restitution`` and ``friction``. A :class:`Box` is its faces.
_WALL_SHAPES: dict[str, tuple[type, tuple[str, ...]]] = {
    "plane": (Plane, ("point", "normal")),
    "sphere": (Sphere, ("center", "radius", "inside")),
    "capsule": (Capsule, ("a", "b", "radius")),
    "oriented_box": (OrientedBox, ("center", "half_extents", "rotation")),
}
_WALL_TYPES = tuple(cls for cls, _ in _WALL_SHAPES.values())
_EXPECTED = "a Plane, Box, Sphere, Capsule or OrientedBox"

_Wall = Plane | Sphere | Capsule | OrientedBox


def _walls(walls: Any) -> tuple[_Wall, ...]:
    if walls is None:
        return ()
    if isinstance(walls, (Box, *_WALL_TYPES)):
        walls = [walls]
    if isinstance(walls, (str, bytes)) or not isinstance(walls, Sequence):
        raise InvalidTypeError(f"walls: expected {_EXPECTED}, or a list of them, got {type(walls).__name__}")
    out: list[_Wall] = []
    for k, w in enumerate(walls):
        if isinstance(w, Box):
            out.extend(w.faces())
        elif isinstance(w, _WALL_TYPES):
            out.append(w)
        else:
            raise InvalidTypeError(f"walls: entry {k} is a {type(w).__name__}, expected {_EXPECTED}")
    return tuple(out)


def _wall_dim(w: _Wall) -> int:
    """The dimension of a wall: the length of its first vector (point, center or a)."""
    return int(getattr(w, _WALL_SHAPES[w.part_kind][1][0]).shape[0])


def _wall_numbers(w: _Wall) -> np.ndarray:
    """A wall's geometry as the core reads it: its fields in order, flat (``inside`` as 0 or 1)."""
    return np.concatenate([np.asarray(getattr(w, f), dtype=np.float64).reshape(-1) for f in _WALL_SHAPES[w.part_kind][1]])


def _wall_entry(w: _Wall) -> dict[str, Any]:
    """A wall's record in a scene file (``meta.terms[k].walls[j]``): its key, its geometry and
    its coefficients, as JSON values (floats round-trip exactly)."""
    fields = (*_WALL_SHAPES[w.part_kind][1], "restitution", "friction")
    out: dict[str, Any] = {"type": w.part_kind}
    for f in fields:
        v = getattr(w, f)
        out[f] = v.tolist() if isinstance(v, np.ndarray) else v
    return out


def _wall_from_entry(k: int, entry: Any) -> _Wall:
    """The wall a file's record describes; a TypeError or ValueError naming ``walls`` and the wall
    if it is not one (an unknown type, a missing or extra key, a value the record refuses)."""
    if not isinstance(entry, dict):
        raise InvalidTypeError(f"walls: wall {k} must be an object, got {type(entry).__name__}")
    kind = entry.get("type")
    if not isinstance(kind, str) or kind not in _WALL_SHAPES:
        raise InvalidInputError(f"walls: wall {k} has type {kind!r}, expected one of {', '.join(_WALL_SHAPES)}")
    cls, geometry = _WALL_SHAPES[kind]
    fields = ("type", *geometry, "restitution", "friction")
    if set(entry) != set(fields):
        raise InvalidInputError(f"walls: wall {k} ({kind}) has keys {sorted(entry)}, expected {sorted(fields)}")
    try:
        return cls(**{f: entry[f] for f in fields[1:]})
    except (TypeError, ValueError) as exc:
        wrap = type(exc) if isinstance(exc, PhyscoreError) else (InvalidTypeError if isinstance(exc, TypeError) else InvalidInputError)
        raise wrap(f"walls: wall {k} ({kind}): {exc}") from exc


def _restitution(arg: str, e: Any) -> float:
    x = _finite_float(e, arg)
    if not 0.0 < x <= 1.0:
        raise InvalidInputError(
            f"{arg}: must be in (0, 1], got {x} (a dashpot that never pulls cannot stop a grain dead; use e.g. 0.05)"
        )
    return x


def _equal_periods(dim: int) -> float:
    """The default ``tangential_ratio``: β/(1 + β) for the dimension's solid grain (β = ½, a disc,
    in 2D; ⅖, a sphere, in 3D), which equalises the normal and tangential periods (see
    :class:`Contacts`)."""
    return 1.0 / 3.0 if dim == 2 else 2.0 / 7.0


@_deprecate.record(('stiffness', 'restitution', 'friction', 'walls', 'tangential_ratio', 'law', 'inertia_factor', 'rolling_friction', 'rolling_damping'), keep=1)
@dataclass(frozen=True, eq=False)
class Contacts(Term, kind="contacts"):
    """Contacts between grains (DEM): spring–dashpot normal force, Coulomb friction with a
    tangential spring, rolling.

    For grains i, j of radii r (the scene's ``"radius"`` attribute, m) at distance
    ``d < r_i + r_j``: overlap ``δ = r_i + r_j − d``, normal ``n`` from i to j, effective mass
    ``m* = 1/(1/m_i + 1/m_j)``, contact-point relative velocity ``v_c`` (including each grain's
    spin times its lever ``r − δ/2``), ``v_n = v_c·n``.

    * normal force, never attractive: ``f_n = max(0, k δ + γ v_n)`` (``law="linear"``) or
      ``max(0, k δ^{3/2} + γ v_n)`` with ``γ ∝ δ^{1/4}`` (``law="hertz"``, Tsuji, Tanaka &
      Ishida, Powder Technol. 71 (1992) 239, eq. 9; Hertz's ``k = (4/3) E* √R*``, E* the
      effective Young's modulus and R* the effective radius, r/2 for two grains of radius r, r
      against a wall: one k is one material at one R*); ``γ = 2ζ√(k m*)`` with the damping ratio ζ
      solved so that a head-on collision of this clamped model returns exactly ``restitution``
      (Schwager & Pöschel, Phys. Rev. E 78 (2008) 051304, for the linear law; integrated
      numerically for Hertz);
    * tangential force ``f_t = −k_t ξ − γ_t v_t`` with ``|f_t| ≤ μ f_n`` (Cundall & Strack,
      Géotechnique 29 (1979) 47–65): ξ is a spring stretched by the sliding of the contact point,
      which slips when the cap is reached, so a grain can rest on a slope and roll without
      slipping; ``k_t = tangential_ratio · k``;
    * torque ``τ = (r − δ/2) n × f_t`` on an angular velocity per grain, moment of inertia
      ``I = inertia_factor · m r²``;
    * rolling resistance (``rolling_friction`` μ_r > 0): the elastic–plastic spring–dashpot,
      model C of Ai, Chen, Rotter & Ooi (Powder Technol. 206 (2011) 269–282; chosen over
      their constant-torque model A, which chatters about ω_r = 0 and cannot hold a grain at
      rest). Relative rolling velocity ``ω_r = ω_i − ω_j`` less its twist about n (3D; for a
      wall ``ω_j = 0``), rolling radius ``R* = r_i r_j/(r_i + r_j)`` (a wall: ``r_i``). A rolling
      spring ``θ_r`` follows ``ω_r`` (``θ_r ← θ_r + ω_r dt``, turned with the contact like ξ)
      with stiffness ``k_r = 2.25 k_c μ_r² R*²`` (their ``k_r`` after Iwashita & Oda 1998;
      ``k_c`` = k, or ``(3/2)k√δ`` for Hertz); its torque ``−k_r θ_r`` is capped at the limiting
      torque ``μ_r R* f_n`` (full mobilisation: the spring slips and the dashpot is off, their
      ``f = 0``); below the cap a dashpot ``−η_r 2√(I_r k_r) ω_r`` acts, ``η_r`` =
      ``rolling_damping``, ``I_r = 1/(1/(I_i + m_i r_i²) + 1/(I_j + m_j r_j²))``, and the sum is
      again capped at ``μ_r R* f_n``. The torque acts on grain i and its opposite on j: momentum
      and angular momentum are conserved. A grain rolling on a floor at v₀ then stops after
      ``s = (1 + β) v₀² / (2 μ_r g)`` (its kinetic energy ``½(1 + β) m v²`` spent at the rate
      ``μ_r r m g · v/r``), plus the spring's give, about ``m g /(2.25 k μ_r)``.

    The scene must use ``integrator="semi_implicit_euler"`` (the usual DEM scheme: forces at
    the step's start, then v, ω, x, then each spring with the new velocities) or ``"xpbd"``
    (the same in each substep, whose projections then hold shape-matched bodies and other
    constraints: the contacts are its external forces; see ``shape_matched_boxes``). The automatic
    step (:meth:`~physcore.Scene.advance`) is a 50th of the contact duration ``π√(m*/k)``, at
    which the measured restitution is within 1 % of ``restitution``. Pinned particles with a
    radius are fixed obstacles; particles of radius 0 do not collide.

    Energy books (:meth:`~physcore.Scene.energy`): the kinetic energy includes rotation; the
    term's potential is the springs' energy (``½kδ²`` or ``⅖kδ^{5/2}``, plus ``½k_t|ξ|²`` and
    ``½k_r|θ_r|²``); ``"<name> (normal damping)"`` and ``"<name> (friction)"`` are the energy the
    dashpots and slipping (sliding and rolling) have dissipated.
    :meth:`~physcore.Scene.angular_momentum` includes the spins
    ``Σ I ω``. :meth:`~physcore.Scene.particle_field` gives ``"angular_velocity"`` (2D, rad/s;
    ``"angular_velocity_x|y|z"`` in 3D), ``"angle"`` (2D, rad) and ``"coordination"`` (contacts
    per grain); :meth:`~physcore.Scene.contact_count` the contacts now.

    Parameters
    ----------
    stiffness : float
        Normal stiffness ``k`` > 0: N/m (linear) or N/m^{3/2} (Hertz). Pick it so that the
        largest overlap, about ``v √(m*/k)`` at impact speed v, is a few percent of a radius.
    restitution : float
        Coefficient of restitution ``e`` in (0, 1] of grain–grain collisions. Default 0.9.
    friction : float
        Coulomb friction coefficient ``μ`` ≥ 0. Default 0.5.
    walls : Plane, Box, Sphere, Capsule, OrientedBox or sequence of them, optional
        Walls, each with its own restitution (in (0, 1]) and friction: the colliders' records
        (the same objects :meth:`~physcore.Scene.add` takes for particles) as fixed obstacles
        for the grains. A :class:`Plane` is a floor or a ramp; a :class:`Box`, its faces (one
        plane each, so a grain in a corner touches two); a :class:`Sphere` a ball to land on, or
        with ``inside=True`` a bowl; a :class:`Capsule` a rod or rail; an :class:`OrientedBox`
        a block, a tilted ramp, rounded at its edges and corners as seen by a grain. Grain i
        touches a wall when the signed distance ``s`` of its centre from the wall's surface
        (positive on the allowed side; the geometry layer's ``Shape::closest``) is below
        ``r_i``: overlap ``δ = r_i − s``, normal along the surface's at the nearest point. The
        contact is the grains' (same law, friction, spin, rolling resistance) with ``m* = m_i``,
        ``R* = r_i``, and a wall that neither moves nor turns. Plane walls give the same bits
        as before the other shapes.
    tangential_ratio : float, optional
        ``k_t / k`` > 0 (Hertz: over the normal contact stiffness ``(3/2)k√δ``). Default (None):
        the ratio that gives the scene's solid grains equal normal and tangential periods, 1/3
        for discs (2D) and 2/7 for spheres (3D; Silbert et al., Phys. Rev. E 64 (2001) 051302).
        Derivation: a grain of mass m on a wall; the normal mode has ``ω_n² = k/m``; the
        tangential spring stretches with the contact point, which moves by ``dx + a dθ``, and
        ``m ẍ = f``, ``I θ̈ = a f`` give an effective mass ``1/m_t = 1/m + a²/I = (1 + 1/β)/m``
        (a ≈ r, ``I = β m r²``), so ``ω_t² = k_t (1 + 1/β)/m``: equal when
        ``k_t/k = β/(1 + β)``, 2/7 for β = 2/5 (sphere), 1/3 for β = 1/2 (disc). (The same holds
        for a pair, both masses halved.) For another ``inertia_factor`` pass β/(1 + β) yourself.
        0 is refused: to turn friction off, set ``friction=0``.
    law : {"linear", "hertz"}
        Normal force law. Default ``"linear"``. Hertz passes impulses through chains of touching
        balls (Newton's cradle) far better.
    inertia_factor : float, optional
        β in ``I = β m r²``: default ½ (a disc) in 2D, ⅖ (a solid sphere) in 3D.
    rolling_friction : float
        Coefficient of rolling friction μ_r ≥ 0 (dimensionless: the limiting rolling torque over
        ``R* f_n``). Default 0: no rolling resistance, the contacts of physcore before it bit
        for bit (at the same ``tangential_ratio``). Round grains have none; μ_r stands for their
        shape and roughness and is calibrated per material: see ``docs/granular.md``, where
        0.2–0.3 brings a 2D column's collapse into the experiments' band.
    rolling_damping : float
        η_r ≥ 0: the rolling dashpot over its critical value ``2√(I_r k_r)`` (Ai et al. 2011).
        Default 0.3: under-damped, so a grain at rest stops rocking within a few periods of its
        rolling spring. Used only when ``rolling_friction`` > 0.
    name : str
        Key of this term in the energy books. Default ``"contacts"``.

    Raises
    ------
    TypeError
        A wall that is not a Plane, Box, Sphere, Capsule or OrientedBox; non-numeric parameters.
    ValueError
        Parameters out of range (named; a wall's restitution not in (0, 1]: ``walls``); at
        :meth:`~physcore.Scene.add`, before the scene changes: a scene whose integrator is
        neither ``"semi_implicit_euler"`` nor ``"xpbd"``, walls of the wrong dimension
        (``walls``), or no ``"radius"`` attribute.
    """

    stiffness: float
    _: KW_ONLY
    restitution: float = 0.9
    friction: float = 0.5
    walls: Any = ()
    tangential_ratio: float | None = None
    law: str = "linear"
    inertia_factor: float | None = None
    rolling_friction: float = 0.0
    rolling_damping: float = 0.3
    name: str = field(default="contacts", kw_only=True)
    _dim: int = field(default=0, init=False, repr=False, compare=False)

    record_fields: ClassVar[dict[str, str]] = {
        "stiffness": "number",
        "restitution": "number",
        "friction": "number",
        "tangential_ratio": "number",
        "law": "str",
        "inertia_factor": "optional_number",
    }
    record_fields_optional: ClassVar[dict[str, str]] = {
        "rolling_friction": "number",
        "rolling_damping": "number",
        # Every wall's record ({"type": "sphere", "center": ..., ...}), written only when a wall
        # is not a plane (the ``wall_*`` arrays then hold none): plane walls are written as
        # files always held them.
        "walls": "list",
    }
    record_arrays: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "wall_points": ("f8", ("W", "D")),
        "wall_normals": ("f8", ("W", "D")),
        "wall_restitution": ("f8", ("W",)),
        "wall_friction": ("f8", ("W",)),
        "history": ("f8", ("H",)),
    }

    def __post_init__(self) -> None:
        k = _finite_float(self.stiffness, "stiffness")
        if not k > 0:
            raise InvalidInputError(f"stiffness: must be > 0 (N/m, or N/m^1.5 for Hertz), got {k}")
        object.__setattr__(self, "stiffness", k)
        object.__setattr__(self, "restitution", _restitution("restitution", self.restitution))
        object.__setattr__(self, "friction", _finite_float(self.friction, "friction", minimum=0.0))
        if self.tangential_ratio is not None:
            ratio = _finite_float(self.tangential_ratio, "tangential_ratio")
            if not ratio > 0:
                raise InvalidInputError(
                    f"tangential_ratio: must be > 0, got {ratio} (a tangential spring of stiffness 0 holds nothing; "
                    "to turn friction off, set friction=0)"
                )
            object.__setattr__(self, "tangential_ratio", ratio)
        object.__setattr__(self, "rolling_friction", _finite_float(self.rolling_friction, "rolling_friction", minimum=0.0))
        object.__setattr__(self, "rolling_damping", _finite_float(self.rolling_damping, "rolling_damping", minimum=0.0))
        if not isinstance(self.law, str):
            raise InvalidTypeError(f"law: expected one of {', '.join(_LAWS)}, got {type(self.law).__name__}")
        if self.law not in _LAWS:
            raise InvalidInputError(f"law: unknown law {self.law!r}; valid: {', '.join(_LAWS)}")
        if self.inertia_factor is not None:
            b = _finite_float(self.inertia_factor, "inertia_factor")
            if not b > 0:
                raise InvalidInputError(f"inertia_factor: must be > 0 (I = β m r²), got {b}")
            object.__setattr__(self, "inertia_factor", b)
        walls = _walls(self.walls)
        for k, w in enumerate(walls):
            if not 0.0 < w.restitution <= 1.0:
                raise InvalidInputError(
                    f"walls: wall {k} ({w.part_kind}) has restitution {w.restitution}, which must be in (0, 1] here "
                    "(a dashpot that never pulls cannot stop a grain dead; use e.g. 0.05)"
                )
        object.__setattr__(self, "walls", walls)

    def _check_dim(self, dim: int) -> None:
        for k, w in enumerate(self.walls):
            n = _wall_dim(w)
            if n != dim:
                raise InvalidInputError(f"walls: wall {k} ({w.part_kind}) has {n} components, the scene is {dim}D")

    def _core_walls(self, dim: int) -> dict[str, Any]:
        """The walls as the core's parameters: their keys, their numbers (``_wall_numbers``) and
        their coefficients."""
        self._check_dim(dim)
        numbers = [_wall_numbers(w) for w in self.walls]
        return {
            "wall_kinds": ",".join(w.part_kind for w in self.walls),
            "wall_params": np.concatenate(numbers) if numbers else np.zeros(0),
            "wall_restitution": np.array([w.restitution for w in self.walls], dtype=np.float64),
            "wall_friction": np.array([w.friction for w in self.walls], dtype=np.float64),
        }

    def _wall_arrays(self, dim: int) -> dict[str, np.ndarray]:
        """The plane walls as a scene file's arrays (none if a wall is not a plane: see
        ``record_fields_optional``)."""
        self._check_dim(dim)
        planes = [w for w in self.walls if isinstance(w, Plane)] if self._planes_only() else []
        return {
            "wall_points": np.array([w.point for w in planes], dtype=np.float64).reshape(-1, dim),
            "wall_normals": np.array([w.normal for w in planes], dtype=np.float64).reshape(-1, dim),
            "wall_restitution": np.array([w.restitution for w in planes], dtype=np.float64),
            "wall_friction": np.array([w.friction for w in planes], dtype=np.float64),
        }

    def _planes_only(self) -> bool:
        return all(isinstance(w, Plane) for w in self.walls)

    def _attach(self, ctx: AttachContext, name: str) -> Contacts:
        _core.check_integrator("contacts", ctx.integrator)  # the core's part–integrator rule
        if "radius" not in ctx.attributes:
            raise InvalidInputError('radius: Contacts need the scene\'s "radius" attribute: scene.set_attribute("radius", r) first')
        ratio = self.tangential_ratio if self.tangential_ratio is not None else _equal_periods(ctx.dim)
        params: dict[str, Any] = {
            "stiffness": self.stiffness,
            "restitution": self.restitution,
            "friction": self.friction,
            "tangential_ratio": ratio,
            "rolling_friction": self.rolling_friction,
            "rolling_damping": self.rolling_damping,
            "law": self.law,
            **self._core_walls(ctx.dim),
        }
        if self.inertia_factor is not None:
            params["inertia_factor"] = self.inertia_factor
        ctx.sim.add_term("contacts", name, params)
        stored = dataclasses.replace(self, name=name, tangential_ratio=ratio)
        object.__setattr__(stored, "_dim", ctx.dim)
        return stored

    def particle_fields(self, dim: int) -> tuple[str, ...]:
        """The names :meth:`~physcore.Scene.particle_field` accepts for this term."""
        spin = ("angular_velocity", "angle") if dim == 2 else tuple(f"angular_velocity_{c}" for c in "xyz")
        return (*spin, "coordination")

    def _record(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        meta = {f: getattr(self, f) for f in (*self.record_fields, "rolling_friction", "rolling_damping")}
        if not self._planes_only():
            meta["walls"] = [_wall_entry(w) for w in self.walls]
        dim = _wall_dim(self.walls[0]) if self.walls else self._dim
        return meta, self._wall_arrays(dim)  # the scene adds "history" (the spins and springs) from the core

    @classmethod
    def _load(cls, ctx: LoadContext, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        planes = [
            Plane(p, n, restitution=float(e), friction=float(mu))
            for p, n, e, mu in zip(arrays["wall_points"], arrays["wall_normals"], arrays["wall_restitution"], arrays["wall_friction"], strict=True)
        ]
        walls: list[_Wall] = list(planes)
        if "walls" in meta:
            if planes:
                raise InvalidInputError("walls: a file holds the walls either as records (walls) or as planes (wall_points, ...), not both")
            walls = [_wall_from_entry(k, e) for k, e in enumerate(meta["walls"])]
        fields = {f: meta[f] for f in cls.record_fields}
        # Files from before rolling resistance hold none: the old contacts, bit for bit.
        fields.update({f: meta[f] for f in ("rolling_friction", "rolling_damping") if f in meta})
        term = ctx.add(cls(**fields, walls=walls, name=meta["name"]))
        ctx.sim.set_term_history(term.name, np.ascontiguousarray(arrays["history"], dtype=np.float64))
