"""Rigid bodies in 2D and 3D: balls, boxes, capsules, convex polygons (2D) and hulls (3D), and
fixed triangle meshes (3D), that fall, stack, topple and roll, joined by revolute, fixed,
prismatic, spherical (3D) and rope joints, and coupled both ways with the scene's particles
(grains, cloth, fluids), which can also be pinned to them (:class:`Pins`).

Contacts and joints are solved by rapier (dimforge's ``rapier2d-f64`` and ``rapier3d-f64``, double precision, its
deterministic build): the field's well-kept library, a sequential-impulse (soft PGS) solver with
warm starting (Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005). physcore adds the
coupling with its particles, the energy books, rollback on divergence and on Ctrl-C, and
restarts that continue bit for bit (the solver's whole state, contacts and warm-start impulses
included, is saved in the scene file).

A :class:`Bodies` part is a group of bodies of one shape; every body of the scene gets a
number in the order added, and a :class:`Joints` part joins bodies by reference
(``bodies[i]``, ``bodies[a:b]``). Bodies fall under the scene's :class:`~physcore.Gravity`
terms (their sum), like the particles.

The particles (with their ``radius`` attribute, else as points) are kept out of every body: a
particle found inside or touching a body after a step is put back on its surface, and the
impulse that stops its approach (the body's restitution, Coulomb friction with the body's
coefficient) is applied to both, equal and opposite, at the contact point. So grains push
boxes, a box ploughs through grains, and cloth drapes on a table. A grain that turns (a
radius and a spin under :class:`~physcore.Contacts`) is pushed at its surface point: the
friction sees that point's velocity (v + ω × r), its effective mass counts the grain's moment
of inertia (I = β m r², the term's ``inertia_factor``), and its moment r × J turns the grain,
so a grain meeting a body with friction leaves rolling as rigid impact theory says (a disc at
⅔ of its tangential speed when it sticks: Stronge, *Impact Mechanics*, 2000, §4.2) and the
angular momentum of grains and bodies is kept. Particles without spin (plain particles, SPH
fluids, cloth) are pushed at their centres, as before.

A DFSPH fluid (``Fluid(method="dfsph")``) meets the dynamic and kinematic bodies through boundary
particles (Akinci et al., "Versatile rigid-fluid coupling for incompressible SPH", ACM TOG 31
(2012) 62): each body's surface is sampled at the fluid's spacing, half a spacing inside it,
each sample weighed by Ψ_b = ρ0/Σ_k W_bk (paper eq. 4–5, scaled so that a flat layer stands for
the lattice rows a wall would have); the fluid counts them in its density and divergence like
moving walls, and its pressure solve pushes each body as it pushes its particles, iteration by
iteration (the body's response enters the next iteration, as in the strong coupling of Gissler
et al., ACM TOG 38 (2019) 5: a floating body's added mass exceeds its own); a sample mirrors
its particle's pressure plus the hydrostatic rise between them (Adami et al., J. Comput. Phys.
231 (2012) 7057, eq. 27), and a box floats at its Archimedes draft to a fifth or a third of a
spacing (3.7 % shallow at 6 spacings of draft, 80 across, at the fluid's defaults; the guide's
table and its limits). A WCSPH fluid meets them through the same samples, counted in its density
and pushing with −m_i Ψ_b (p_i/ρ_i²) ∇W_ib (paper eq. 10), the reaction applied to the body
(eq. 11). Fixed bodies are the fluid's walls to give (``boundary=``).

Energy books (:meth:`Scene.energy`): the bodies' kinetic energy (translation and rotation) is
in ``kinetic``, the potential of gravity under ``"bodies: gravity"``; rapier does not report
what contacts, friction, restitution and joints take out, so their sum (with the solver's
error, and what rolling resistance takes) is booked as the residual ``"bodies: contacts and joints"``, and what the particle
coupling removes (kinetic energy, less the potential its moves raise: of gravity, springs and
the other terms whose potential is a cheap pass; an SPH fluid's, DEM contacts' or N-body
gravity's share is left to the drift) as ``"bodies ⇄ particles"``.

Examples
--------
>>> import physcore as pc
>>> scene = pc.Scene(dim=2, dt=1 / 240)
>>> _ = scene.add(pc.Gravity([0.0, -9.81]))
>>> ground = scene.add(pc.Bodies("box", size=[(5.0, 0.1)], positions=[(0.0, -0.1)], kind="fixed"))
>>> crate = scene.add(pc.Bodies("box", size=[(0.2, 0.2)], positions=[(0.0, 1.0)]))
>>> scene.step(480)
>>> round(float(crate.positions[0, 1]), 2)  # resting on the ground: its half-height up
0.2
"""
from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from . import _check
from ._errors import InvalidInputError, InvalidTypeError, allocating
from ._parts import AttachContext, Host, LoadContext, Part

__all__ = ["Bodies", "Joints", "Pins", "BodyRef", "SHAPES", "JOINTS"]

#: The shapes of a :class:`Bodies` group and what ``size`` gives per body.
SHAPES: dict[str, str] = {
    "ball": "radius r (m)",
    "box": "half extents (hx, hy) in 2D, (hx, hy, hz) in 3D (m)",
    "capsule": "half length of the axis and radius (l, r) (m), axis along the body's x",
    "polygon": "2D; none: the group's ``vertices`` (m, in the body's frame; their convex hull)",
    "polyline": "2D, fixed bodies only; none: the group's ``vertices``, a chain of segments (ground, ramps)",
    "hull": "3D; none: the group's ``vertices`` (m, in the body's frame; their convex hull)",
    "mesh": "3D, fixed bodies only; none: the group's ``vertices`` and ``triangles``",
}
_SHAPES_2D = ("ball", "box", "capsule", "polygon", "polyline")
_SHAPES_2D_ONLY = ("polygon", "polyline")
_SHAPES_3D = ("hull", "mesh")
#: The joints of :class:`Joints`.
JOINTS: tuple[str, ...] = ("revolute", "fixed", "prismatic", "spherical", "rope")
_KINDS = ("dynamic", "fixed", "kinematic")
#: The name of the core's system that holds every body.
SYSTEM = "bodies"
#: Bytes one body costs, about (rapier's body, collider, broad-phase and island entries, and
#: physcore's arrays of it): what a group is refused by before anything is allocated.
BODY_BYTES = 2048


def _rows(arg: str, value: Any, n: int | None, width: int) -> np.ndarray:
    a = _check.real_array(arg, value).astype(np.float64)
    if width == 1:
        if a.ndim == 0 or a.shape == (1,):
            a = np.full(n if n is not None else 1, float(a.reshape(-1)[0]))
        if a.ndim != 1 or (n is not None and a.shape[0] != n):
            raise InvalidInputError(f"{arg}: expected shape ({n if n is not None else 'N'},), got {a.shape}")
    else:
        if a.shape in ((width,), (1, width)):
            a = np.tile(a.reshape(1, width), (n if n is not None else 1, 1))
        if a.ndim != 2 or a.shape[1] != width or (n is not None and a.shape[0] != n):
            raise InvalidInputError(f"{arg}: expected shape ({n if n is not None else 'N'}, {width}), got {a.shape}")
    if not np.isfinite(a).all():
        raise InvalidInputError(f"{arg}: every value must be finite")
    return np.ascontiguousarray(a)


def _number(arg: str, value: Any, lo: float, hi: float = math.inf, *, open_lo: bool = False) -> float:
    x = _check.real(arg, value)
    if not math.isfinite(x) or x < lo or x > hi or (open_lo and x == lo):
        lo_s = f"> {lo:g}" if open_lo else f">= {lo:g}"
        raise InvalidInputError(f"{arg}: must be {lo_s}" + (f" and <= {hi:g}" if math.isfinite(hi) else "") + f", got {value!r}")
    return x


def _unit_quaternions(q: np.ndarray) -> np.ndarray:
    """The rows of q (N, 4) normalised (scaled by their largest entry first, so that no norm
    overflows); InvalidInputError naming orientations for a zero row."""
    big = np.abs(q).max(axis=1, keepdims=True)
    if not (big > 0).all():
        raise InvalidInputError("orientations: a zero quaternion is no rotation")
    u = q / big
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _width(value: Any) -> int | None:
    """The last axis of an array argument, if it says a dimension (2 or 3)."""
    try:
        a = np.asarray(value)
    except Exception:  # noqa: BLE001 - checked by name later
        return None
    return int(a.shape[-1]) if a.ndim >= 1 and a.shape[-1] in (2, 3) and a.dtype != object else None


def _spin_width(value: Any, n: int) -> int | None:
    """3 if angular velocities can only be 3D ones: rows of 3, or one vector of 3 for a group
    of other than 3 bodies (in 2D they are one value a body); None otherwise."""
    try:
        a = np.asarray(value)
    except Exception:  # noqa: BLE001 - checked by name later
        return None
    if a.dtype == object:
        return None
    if a.ndim == 2 and a.shape[-1] == 3:
        return 3
    return 3 if a.ndim == 1 and a.shape[0] == 3 and n != 3 else None


def _dim_of(shape: str, positions: Any, size: Any, orientations: Any, angles: Any, vertices: Any,
            velocities: Any = None, angular_velocities: Any = None) -> int | None:
    """The dimension the arguments give (None: they do not say; the scene's then). Without
    positions, the widths of the velocities and angular velocities count too; arguments that
    give different dimensions are refused, naming both."""
    if positions is not None:
        w = _width(positions)
        if w is None:
            raise InvalidInputError(f"positions: expected shape (N, 2) or (N, 3), got {_check.array('positions', positions).shape}")
        return w
    if shape in _SHAPES_3D or orientations is not None:
        dim, first = 3, "orientations" if orientations is not None else f"shape {shape!r}"
    elif shape in _SHAPES_2D_ONLY or angles is not None:
        dim, first = 2, "angles" if angles is not None else f"shape {shape!r}"
    elif vertices is not None:
        dim, first = _width(vertices), "vertices"
    elif shape == "box" and size is not None:
        dim, first = _width(size), "size"
    else:
        dim, first = None, ""
    said: list[tuple[str, int]] = [(first, dim)] if dim is not None else []
    if velocities is not None and (w := _width(velocities)):
        said.append(("velocities", w))
    if angular_velocities is not None:
        # Bodies in the group as the sizes count them (one without sizes).
        try:
            sized = np.asarray(size) if size is not None and vertices is None else None
        except Exception:  # noqa: BLE001 - checked by name later
            sized = None
        n = 1 if sized is None or sized.dtype == object or sized.ndim == 0 else (
            sized.shape[0] if sized.ndim == 2 or shape == "ball" else 1)
        if w := _spin_width(angular_velocities, n):
            said.append(("angular_velocities", w))
    if not said:
        return None
    first, dim = said[0]
    for other, d in said[1:]:
        if d != dim:
            raise InvalidInputError(f"{other}: {d} components say a {d}D group, but {first} says {dim}D; "
                                    "make them agree (or give positions, (N, 2) or (N, 3))")
    return dim


class _BodiesPart(Part):
    """What the parts of the "bodies" section share: where a file names their entries, and
    their JSON record, checked."""

    section: ClassVar[str] = "bodies"

    @classmethod
    def _load_names(cls, ctx: LoadContext, arrays: Any) -> tuple[str, dict[str, str]]:
        return f"{ctx.field}.record", {}

    @staticmethod
    def _checked_record(entry: dict[str, Any]) -> dict[str, Any]:
        rec = entry["record"]
        if not isinstance(rec, dict):
            raise InvalidInputError(f"record: expected an object, got {type(rec).__name__}")
        return rec


class BodyRef:
    """Some bodies of a :class:`Bodies` group, by index within it: ``bodies[3]``,
    ``bodies[:-1]``, ``bodies[[0, 2]]`` (what :class:`Joints` joins)."""

    def __init__(self, group: Bodies, index: np.ndarray) -> None:
        self.group = group
        self.index = index

    def __len__(self) -> int:
        return int(self.index.size)

    def __repr__(self) -> str:
        return f"BodyRef({self.group.name!r}, {self.index.tolist()})"


class Bodies(_BodiesPart):
    """A group of rigid bodies of one shape, in 2D or 3D (the dimension of the positions).

    Parameters
    ----------
    shape : str
        2D: ``"ball"``, ``"box"``, ``"capsule"``, ``"polygon"`` or ``"polyline"``; 3D: ``"ball"``,
        ``"box"``, ``"capsule"``, ``"hull"`` or ``"mesh"`` (:data:`SHAPES`).
    size : array_like of float
        Per body (or one value for all): a ball's radius, shape (N,); a box's half extents
        ``(hx, hy)`` in 2D or ``(hx, hy, hz)`` in 3D, (N, dim); a capsule's ``(half_length,
        radius)``, (N, 2), its axis along the body's x; m, > 0. Not used by polygons, hulls and
        meshes. Its length sets N when ``positions`` is not given.
    positions : (N, 2) or (N, 3) array_like of float, default one body at the origin
        Centres, m. Their width sets the dimension (else the shape's, the orientations' or
        angles', the vertices', a box's size's, the velocities' or angular velocities' (rows of
        3: 3D), which must agree; else the scene's when the group is added).
    angles : (N,) array_like of float or float, default 0, 2D only
        Orientations, rad (counter-clockwise).
    orientations : (N, 4) or (4,) array_like of float, default identity, 3D only
        Unit quaternions ``(x, y, z, w)``, scalar last as ``scipy.spatial.transform.Rotation``
        reads them (normalised here; a zero one is refused).
    velocities : (N, dim) array_like of float, default 0
        Linear velocities, m/s.
    angular_velocities : default 0
        rad/s: (N,) in 2D (counter-clockwise), (N, 3) in 3D (the rotation vector's rate, world
        frame).
    vertices : (K, dim) array_like of float, polygon, polyline, hull and mesh only
        In the body's frame, m: a polygon's or hull's points (their convex hull is the shape),
        a polyline's chain (fixed bodies only), or a mesh's vertices.
    triangles : (T, 3) array_like of int, mesh only
        The mesh's triangles, as vertex indices. A mesh has no volume: fixed bodies only.
    density : float, default 1000
        kg/m² in 2D, kg/m³ in 3D: the mass and moment of inertia follow from it and the shape.
    friction : float, default 0.5
        Coulomb friction coefficient μ ≥ 0 (a contact uses the mean of its two bodies').
    restitution : float, default 0.1
        Coefficient of restitution e in [0, 1] (a contact uses the larger of its two bodies'). A
        body leaves an impact with e times its normal arrival speed at any step (to 0.3 % at
        dt = 1/240), a box landing flat at both corners at once; a fast body meets the surface
        where it is (it looks ahead for contacts), so a dropped ball's apexes are e² of each
        other within 0.1 % at dt = 1/60 as at 1/240. A contact that goes on touching does not
        bounce unless e = 1.
    rolling_friction : float, default 0
        Coefficient of rolling friction μ_r ≥ 0 (dimensionless; a contact uses the larger of its
        two bodies', so a default ground leaves a ball's own): a contact resists the relative
        rolling of its bodies (their relative angular velocity less its twist about the
        normal) with a torque of at most μ_r R f_n, f_n the normal force and R the rolling
        radius: the distance along the normal from the body's centre of mass to the contact
        point (a ball's radius, a capsule's on its side), R₁R₂/(R₁ + R₂) between two dynamic
        bodies, a fixed or kinematic body counting as a wall. The grains' model at full
        mobilisation (Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269, model A: a
        constant torque against the rolling), applied after each rapier step from its normal
        impulses and never reversing the rolling; a contact that sticks keeps sticking (the
        resistance slows spin and speed together). A ball rolling at v₀ on a flat floor stops
        after ``s = (1 + I/(m R²)) v₀² / (2 μ_r g)`` (a = μ_r g/(1 + I/(m R²)); measured within
        0.01 % at dt = 1/240), and rests on a slope of tan θ ≤ μ_r. 0: none, the bits of physcore
        before it. Grains meeting bodies do not see it (their own ``rolling_friction`` is in
        :class:`~physcore.Contacts`).
    kind : str, default "dynamic"
        ``"dynamic"`` (moves under forces and contacts), ``"fixed"`` (never moves: the ground,
        walls, a table), ``"kinematic"`` (moves at its set velocity, unmoved by contacts).
    color : str, (3,) or (N, 3) int, optional
        The drawing colour (a matplotlib name, or RGB 0–255 for all or per body); default by shape.
    name : str, optional
        Unique among the scene's bodies; default ``"bodies"``, ``"bodies_2"``, ...

    Attributes
    ----------
    positions, velocities : (N, dim) float64
        Once in a scene: the state now (copies; settable), m and m/s.
    angles : (N,) float64, 2D
        rad (settable).
    orientations : (N, 4) float64, 3D
        Unit quaternions (x, y, z, w) (settable).
    angular_velocities : float64
        (N,) in 2D, (N, 3) in 3D, rad/s (settable).
    masses : (N,) float64
        kg.
    rolling_friction : float
        μ_r as given (dimensionless).
    inertia : float64
        kg·m²: (N,) in 2D; (N, 3) in 3D, the inertia tensor's diagonal in the body's axes
        (a box's and a capsule's principal moments; see the property).

    Raises
    ------
    InvalidInputError
        (a ``ValueError``) naming the argument: an unknown shape or kind, a shape of the other
        dimension, wrong shapes, non-finite values, sizes ≤ 0, density ≤ 0, friction < 0,
        restitution outside [0, 1], rolling_friction < 0, a zero quaternion, too few vertices or
        all on a line (a plane in 3D), vertices whose extent float64 cannot resolve (under
        1e-150 m, or under 1e-12 of their distance from the origin), a mass or moment of inertia
        beyond float64 or below 1e-280 (SI), a mesh that is not fixed or indexes no vertex; a
        group whose dimension is not the scene's.
    InvalidTypeError
        (a ``TypeError``) a non-numeric argument.
    OutOfMemoryError
        (a ``MemoryError``, from ``Scene.add``) rapier's sets cannot grow by the group now (about
        2.5 kB a body is asked for first: rapier's own growth cannot be refused, it aborted the
        process); nothing is added. Under a memory cap, the first step (its checkpoint copies
        rapier's state), ``Scene.save`` and pickling, and loading are refused the same way,
        named ``step``, ``save`` and ``load``.
    KeyboardInterrupt
        Ctrl-C while ``Scene.add`` builds the group's shape (parry's convex hull of 200,000
        vertices on a sphere takes 3–13 s) is answered within about 30 ms, and nothing is
        added; the abandoned build finishes on its own thread and is dropped. A Ctrl-C while
        the built bodies go into rapier's sets (0.4 s for 100,000 balls) is raised as that ends,
        and the group is added whole: the scene records what the core holds.

    Notes
    -----
    Bodies are stepped by rapier's own scheme (semi-implicit Euler with sequential-impulse
    contacts and joints, Catto 2005), whatever the scene's ``integrator``: that names the
    particles' integrator only, and gives the bodies the same bits under every name. rapier's
    tolerances are in units of the smallest dynamic body's size L and its contact rates in
    units of √(L / 1 m) s, so a scene scaled in size behaves the same (docs/guide/bodies.md,
    "Units"); bodies are never held to a top speed.
    """

    part_kind: ClassVar[str] = "group"

    @classmethod
    def from_shape(
        cls,
        shape: Any,
        *,
        extent: float | None = None,
        kind: str = "fixed",
        density: float = 1000.0,
        rolling_friction: float = 0.0,
        color: Any = None,
        name: str | None = None,
    ) -> Bodies:
        """The rigid bodies (rapier, parry's shapes) that fill a collider record, so that one
        shape serves particles (as a collider), grains (as a :class:`~physcore.Contacts` wall),
        fluids (:func:`physcore.shapes.sample_boundary`) and bodies alike. Restitution and
        friction are the record's.

        ===================================== =============================================
        record                                bodies
        ===================================== =============================================
        :class:`~physcore.OrientedBox`        one box: its centre, half extents, rotation
        :class:`~physcore.Sphere`             one ball (``inside=True``, a bowl, is refused)
        :class:`~physcore.Capsule`            one capsule along ``b − a`` (a ball if a = b)
        :class:`~physcore.Plane`              one slab under the plane: ``extent`` m either
                                              side of ``point`` along the plane, ``extent``/4
                                              thick below it (``extent`` required)
        :class:`~physcore.Box` (a tank)       its walls: one slab a face, ¼ of the box's
                                              largest side thick, outside the box
        ===================================== =============================================

        ``kind`` is ``"fixed"`` (default), ``"kinematic"`` or ``"dynamic"`` (then ``density``,
        kg/m³ or kg/m² in 2D, gives the mass). Rotations follow the records: a 2D angle
        counter-clockwise, a 3D rotation vector (axis × angle, rad) turned into the unit
        quaternion (x, y, z, w) = (k sin(θ/2), cos(θ/2)).

        Raises TypeError / InvalidInputError naming ``shape`` (not a collider record, or a
        bowl) or ``extent`` (missing or not finite and > 0 for a Plane); the rest as
        :class:`Bodies` raises."""
        from .terms import Box as _Box
        from .terms import Capsule as _Capsule
        from .terms import OrientedBox as _OrientedBox
        from .terms import Plane as _Plane
        from .terms import Sphere as _Sphere

        common = {"kind": kind, "density": density, "rolling_friction": rolling_friction, "color": color, "name": name}
        if isinstance(shape, _OrientedBox):
            c, h, rot = (np.asarray(a, dtype=np.float64) for a in (shape.center, shape.half_extents, shape.rotation))
            turn = {"angles": [float(rot[0])]} if c.shape[0] == 2 else {"orientations": [_quaternion(rot)]}
            return cls("box", size=[h], positions=[c], friction=shape.friction, restitution=shape.restitution,
                       **turn, **common)
        if isinstance(shape, _Sphere):
            if shape.inside:
                raise InvalidInputError("shape: a Sphere with inside=True (a bowl) has no solid body; build it from "
                                        "boxes or a mesh")
            return cls("ball", size=[float(shape.radius)], positions=[np.asarray(shape.center, dtype=np.float64)],
                       friction=shape.friction, restitution=shape.restitution, **common)
        if isinstance(shape, _Capsule):
            a, b = np.asarray(shape.a, dtype=np.float64), np.asarray(shape.b, dtype=np.float64)
            axis = b - a
            length = float(np.linalg.norm(axis))
            rec = {"friction": shape.friction, "restitution": shape.restitution}
            if length == 0.0:
                return cls("ball", size=[float(shape.radius)], positions=[a], **rec, **common)
            turn = _turn_x_onto(axis / length)
            return cls("capsule", size=[(0.5 * length, float(shape.radius))], positions=[0.5 * (a + b)], **turn, **rec,
                       **common)
        if isinstance(shape, _Plane):
            if extent is None:
                raise InvalidInputError("extent: a Plane is unbounded; give extent (m), the slab's half width along it")
            half = _check.finite_float(extent, "extent", minimum=0.0, strict=True)
            p, n = np.asarray(shape.point, dtype=np.float64), np.asarray(shape.normal, dtype=np.float64)
            n = n / np.linalg.norm(n)
            return cls._slabs([(p, n)], half, 0.25 * half, shape, common)
        if isinstance(shape, _Box):
            lo, hi = np.asarray(shape.lower, dtype=np.float64), np.asarray(shape.upper, dtype=np.float64)
            dim, side = lo.shape[0], float(np.max(hi - lo))
            faces = []
            for k in range(dim):
                for corner, sign in ((lo, 1.0), (hi, -1.0)):
                    n = np.zeros(dim)
                    n[k] = sign
                    p = 0.5 * (lo + hi)
                    p[k] = corner[k]
                    faces.append((p, n))
            return cls._slabs(faces, 0.5 * side + 0.25 * side, 0.125 * side, shape, common)
        raise InvalidTypeError(f"shape: expected a collider record (OrientedBox, Sphere, Capsule, Plane, Box), got "
                               f"{type(shape).__name__}")

    @classmethod
    def _slabs(cls, faces: list[tuple[np.ndarray, np.ndarray]], half: float, thick: float, shape: Any,
               common: dict[str, Any]) -> Bodies:
        """Boxes under the planes ``(point, unit normal)``: ``half`` m either side of the point
        along the plane, ``2 thick`` m thick, their top face on the plane."""
        dim = faces[0][0].shape[0]
        size = [(half, thick) if dim == 2 else (half, half, thick) for _ in faces]
        positions = [p - thick * n for p, n in faces]
        # The box's local y (2D) or z (3D) turned onto the normal.
        if dim == 2:
            turn: dict[str, Any] = {"angles": [math.atan2(-n[0], n[1]) for _, n in faces]}
        else:
            turn = {"orientations": [_quaternion_between(np.array([0.0, 0.0, 1.0]), n) for _, n in faces]}
        return cls("box", size=size, positions=positions, friction=shape.friction, restitution=shape.restitution,
                   **turn, **common)

    @allocating("Bodies", "its arrays")
    def __init__(
        self,
        shape: str = "box",
        size: Any = None,
        positions: Any = None,
        *,
        angles: Any = None,
        orientations: Any = None,
        velocities: Any = 0.0,
        angular_velocities: Any = 0.0,
        vertices: Any = None,
        triangles: Any = None,
        density: float = 1000.0,
        friction: float = 0.5,
        restitution: float = 0.1,
        rolling_friction: float = 0.0,
        kind: str = "dynamic",
        color: Any = None,
        name: str | None = None,
    ) -> None:
        self.shape = _check.choice("shape", shape, tuple(SHAPES))
        self.kind = _check.choice("kind", kind, _KINDS)
        self._args = {"size": size, "positions": positions, "angles": angles, "orientations": orientations,
                      "velocities": velocities, "angular_velocities": angular_velocities, "vertices": vertices,
                      "triangles": triangles}
        self.density = _number("density", density, 0.0, open_lo=True)
        self.friction = _number("friction", friction, 0.0)
        self.restitution = _number("restitution", restitution, 0.0, 1.0)
        self.rolling_friction = _number("rolling_friction", rolling_friction, 0.0)
        if name is not None and (not isinstance(name, str) or not name):
            raise InvalidInputError(f"name: expected a non-empty str, got {name!r}")
        if name is not None:
            _check.text("name", name)
        self.name = name
        self._color_arg = color
        self.dim = _dim_of(self.shape, positions, size, orientations, angles, vertices, velocities, angular_velocities)
        # Checked now in the dimension the arguments give (2 if they do not say; checked again
        # in the scene's when added).
        self._resolve(self.dim or 2)
        self.first: int | None = None
        self._host: Host | None = None

    @allocating("Bodies", "its arrays")
    def _resolve(self, dim: int) -> None:
        """Checks the arguments as a `dim`-D group and sets the starting state from them."""
        a = self._args
        shape = self.shape
        if shape in _SHAPES_3D and dim == 2:
            raise InvalidInputError(f"shape: {shape!r} is a 3D shape; in 2D use one of {', '.join(_SHAPES_2D)}")
        if shape in _SHAPES_2D_ONLY and dim == 3:
            raise InvalidInputError(f"shape: {shape!r} is a 2D shape; in 3D use 'hull' or 'mesh' (vertices (K, 3))")
        width = 1 if shape == "ball" else (dim if shape == "box" else 2)
        listed = shape in ("polygon", "polyline", "hull", "mesh")
        if a["positions"] is not None:
            x = _rows("positions", a["positions"], None, dim)
            n = x.shape[0]
        elif a["size"] is not None and not listed:
            n = _rows("size", a["size"], None, width).shape[0]
            x = np.zeros((n, dim))
        else:
            n, x = 1, np.zeros((1, dim))
        if n < 1:
            raise InvalidInputError("positions: a group needs at least one body")
        _check.memory("positions", n * BODY_BYTES, f"{n} rigid bodies")
        self.n = n
        self.start = x
        self.triangles = None
        if listed:
            if a["vertices"] is None:
                raise InvalidInputError(f"vertices: a {shape} group needs its vertices, shape (K, {dim})")
            if a["size"] is not None:
                raise InvalidInputError(f"size: a {shape} takes its shape from its vertices, not a size")
            v = _rows("vertices", a["vertices"], None, dim)
            need = {"mesh": 3, "polyline": 2}.get(shape, dim + 1)
            if v.shape[0] < need:
                raise InvalidInputError(f"vertices: a {shape} needs at least {need}, got {v.shape[0]}")
            with np.errstate(all="ignore"):
                e = v - v.mean(axis=0)
            if not np.isfinite(e).all():
                raise InvalidInputError("vertices: beyond float64 (their centre overflows); give them in m, near the body's origin")
            rank = np.linalg.matrix_rank(e, tol=1e-12 * max(1e-300, float(np.abs(e).max())))
            if shape in ("polygon", "hull") and rank < dim:
                raise InvalidInputError("vertices: " + ("all on one line (the polygon has no area)" if dim == 2
                                                        else "all on one plane (the hull has no volume)"))
            if shape == "polyline":
                if self.kind != "fixed":
                    raise InvalidInputError("kind: a polyline has no area and so no mass: make it kind='fixed'")
                if (np.abs(np.diff(v, axis=0)).max(axis=1) == 0).any():
                    raise InvalidInputError("vertices: two consecutive vertices coincide (a segment of no length)")
            if shape == "mesh":
                if self.kind != "fixed":
                    raise InvalidInputError("kind: a triangle mesh has no volume and so no mass: make it kind='fixed'")
                if a["triangles"] is None:
                    raise InvalidInputError("triangles: a mesh needs its triangles, shape (T, 3) vertex indices")
                t = _check.real_array("triangles", a["triangles"])
                if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
                    raise InvalidInputError(f"triangles: expected shape (T, 3) with T >= 1, got {t.shape}")
                if not (np.isfinite(t).all() and (t == np.round(t)).all() and (t >= 0).all() and (t < v.shape[0]).all()):
                    raise InvalidInputError(f"triangles: every entry must be a vertex index in 0..{v.shape[0] - 1}")
                self.triangles = t.astype(np.int64)
            elif a["triangles"] is not None:
                raise InvalidInputError(f"triangles: only meshes have triangles, not a {shape}")
            self.vertices = v
            self.size = np.zeros((n, 0))
        else:
            for key in ("vertices", "triangles"):
                if a[key] is not None:
                    raise InvalidInputError(f"{key}: only polygons, hulls and meshes have {key}, not a {shape}")
            size = a["size"]
            if size is None:
                size = {"ball": 0.1, "box": (0.1,) * dim, "capsule": (0.1, 0.05)}[shape]
            try:
                s = _rows("size", size, n, width)
            except InvalidInputError as e:
                if shape == "box" and a["positions"] is not None and _width(size) not in (None, dim):
                    # The positions set the dimension: say so, where they may be the mistake.
                    raise InvalidInputError(f"{e} (a {dim}D box: the positions give {dim} coordinates)") from None
                raise
            if not (s > 0).all():
                raise InvalidInputError("size: every size must be > 0 (m)")
            self.size = s if width > 1 else s.reshape(n)
            self.vertices = None
        if dim == 2:
            if a["orientations"] is not None:
                raise InvalidInputError("orientations: quaternions orient 3D bodies; in 2D give angles (rad)")
            self.start_turns = _rows("angles", 0.0 if a["angles"] is None else a["angles"], n, 1)
            ang_width = 1
        else:
            if a["angles"] is not None:
                raise InvalidInputError("angles: a 3D body's orientation is a unit quaternion: give orientations (x, y, z, w)")
            q = _rows("orientations", (0.0, 0.0, 0.0, 1.0) if a["orientations"] is None else a["orientations"], n, 4)
            self.start_turns = _unit_quaternions(q)  # (N, 4) in 3D, angles (N,) in 2D
            ang_width = 3
        vel = a["velocities"]
        vel_rank = _check.array("velocities", vel).ndim  # a ragged list refused by name
        self.start_velocities = _rows("velocities", vel if vel_rank else np.full((n, dim), float(_check.real("velocities", vel))), n, dim)
        om = a["angular_velocities"]
        if ang_width == 3 and not _check.array("angular_velocities", om).ndim:
            om = np.full((n, 3), float(_check.real("angular_velocities", om)))
        self.start_angular = _rows("angular_velocities", om, n, ang_width)
        with np.errstate(all="ignore"):
            reach = float(np.abs(self.size).max()) if self.vertices is None else float(np.abs(self.vertices).max())
            mass = self.density * float(np.power(2.0 * reach, dim))  # inf, not OverflowError, past float64
            if not (np.isfinite(mass * reach * reach) and np.isfinite(np.abs(x).max() + 2 * reach)):
                raise InvalidInputError(f"size, density: a body of {reach:g} m at {self.density:g} kg/m^{dim} has a mass "
                                        "or moment of inertia beyond float64")
            # The other end: a mass or inertia that underflows (to 0, it hangs in the air and
            # others pass through it), or whose inverse, which the contact solver multiplies,
            # is near overflow: both below 1e-280 (a lower bound from the smallest size; a
            # polygon's or mesh's vertices are checked for their resolution instead).
            lo = float(np.abs(self.size).min()) if self.vertices is None else 1.0
            mass_lo = self.density * float(np.power(2.0 * lo, dim))
            if self.vertices is None and not (mass_lo >= 1e-280 and mass_lo * lo * lo >= 1e-280):
                raise InvalidInputError(f"size, density: a body of {lo:g} m at {self.density:g} kg/m^{dim} has a mass "
                                        "or moment of inertia below 1e-280 (SI): it underflows, or its inverse "
                                        "overflows in the contact solver")
        self.color = _color(self._color_arg, shape)
        if self.color.ndim == 2 and self.color.shape[0] != n:
            raise InvalidInputError(f"color: {self.color.shape[0]} colours for {n} bodies")
        # The records are copies of the arguments, read-only: a write into `size` went into what
        # save writes (a negative size: a file that failed to load), not into the core's bodies.
        for rec in (self.start, self.size, self.vertices, self.triangles, self.start_turns, self.start_velocities,
                    self.start_angular, self.color):
            if rec is not None:
                rec.setflags(write=False)

    # -- referring to bodies
    def __len__(self) -> int:
        return self.n

    def __getitem__(self, key: Any) -> BodyRef:
        idx = np.arange(self.n)
        try:
            sel = np.atleast_1d(idx[key])
        except (IndexError, TypeError, OverflowError) as e:  # OverflowError: an index beyond int64
            raise InvalidInputError(f"key: {key!r:.80} does not select bodies of this group of {self.n} ({e})") from None
        if sel.ndim != 1:  # None, True or a nested list add axes: the bodies are a list, not a table
            raise InvalidInputError(f"key: {key!r:.80} selects a {sel.ndim}-D table of bodies, shape {sel.shape}; expected one body or a 1-D selection")
        return BodyRef(self, sel.astype(np.int64))

    # -- state
    def _bound(self) -> Host:
        if self._host is None:
            raise InvalidInputError(f"Bodies {self.name!r} are not in a scene yet: scene.add(them) first")
        return self._host

    def _fields(self, names: list[str]) -> list[np.ndarray]:
        host = self._bound()
        out = host.exclusive(lambda sim: sim.system_fields(SYSTEM, names))
        a, b = self.first, self.first + self.n  # type: ignore[operator]
        return [np.asarray(f)[a:b].copy() for f in out]

    def _set(self, names: list[str], values: list[np.ndarray]) -> None:
        host = self._bound()

        def write(sim: Any) -> None:
            full = sim.system_fields(SYSTEM, names)
            for name, f, v in zip(names, full, values, strict=True):
                f = np.array(f)
                f[self.first:self.first + self.n] = v  # type: ignore[operator]
                sim.set_system_field(SYSTEM, name, f)

        host.exclusive(write)
        host.energy_changed()

    def _axes(self, prefix: str = "") -> list[str]:
        return [prefix + c for c in "xyz"[: self.dim]]

    @property
    def positions(self) -> np.ndarray:
        """Centres now, (N, dim) float64, m (a copy). Settable."""
        return np.stack(self._fields(self._axes()), axis=1)

    @positions.setter
    def positions(self, value: Any) -> None:
        a = _rows("positions", value, self.n, self.dim)
        self._set(self._axes(), list(a.T))

    @property
    def angles(self) -> np.ndarray:
        """Orientations now, (N,) float64, rad in (−π, π] (2D). Settable."""
        self._need(2, "angles", "orientations")
        return self._fields(["angle"])[0]

    @angles.setter
    def angles(self, value: Any) -> None:
        self._need(2, "angles", "orientations")
        self._set(["angle"], [_rows("angles", value, self.n, 1)])

    @property
    def orientations(self) -> np.ndarray:
        """Orientations now, (N, 4) float64 unit quaternions (x, y, z, w) (3D). Settable
        (normalised; a zero quaternion is refused)."""
        self._need(3, "orientations", "angles")
        return np.stack(self._fields(["qx", "qy", "qz", "qw"]), axis=1)

    @orientations.setter
    def orientations(self, value: Any) -> None:
        self._need(3, "orientations", "angles")
        q = _unit_quaternions(_rows("orientations", value, self.n, 4))
        host = self._bound()

        def write(sim: Any) -> None:
            full = np.stack([np.asarray(f) for f in sim.system_fields(SYSTEM, ["qx", "qy", "qz", "qw"])], axis=1)
            full[self.first:self.first + self.n] = q  # type: ignore[operator]
            sim.set_system_field(SYSTEM, "q", np.ascontiguousarray(full).reshape(-1))

        host.exclusive(write)
        host.energy_changed()

    @property
    def velocities(self) -> np.ndarray:
        """Linear velocities now, (N, dim) float64, m/s. Settable."""
        return np.stack(self._fields(self._axes("v")), axis=1)

    @velocities.setter
    def velocities(self, value: Any) -> None:
        a = _rows("velocities", value, self.n, self.dim)
        self._set(self._axes("v"), list(a.T))

    @property
    def angular_velocities(self) -> np.ndarray:
        """Angular velocities now, rad/s: (N,) float64 in 2D (counter-clockwise), (N, 3) in 3D
        (world frame). Settable."""
        if self.dim == 2:
            return self._fields(["omega"])[0]
        return np.stack(self._fields(["wx", "wy", "wz"]), axis=1)

    @angular_velocities.setter
    def angular_velocities(self, value: Any) -> None:
        if self.dim == 2:
            self._set(["omega"], [_rows("angular_velocities", value, self.n, 1)])
        else:
            a = _rows("angular_velocities", value, self.n, 3)
            self._set(["wx", "wy", "wz"], list(a.T))

    @property
    def masses(self) -> np.ndarray:
        """(N,) float64, kg (0 for fixed and kinematic bodies)."""
        return self._fields(["mass"])[0]

    @property
    def inertia(self) -> np.ndarray:
        """Moments of inertia about the centres of mass, kg·m²: (N,) float64 in 2D; (N, 3) in
        3D, the diagonal of the inertia tensor in each body's own axes (x, y, z): a box's and a
        capsule's principal moments (a capsule's axis is its x); a hull's principal axes are
        where its shape puts them, and its products of inertia are not given."""
        if self.dim == 2:
            return self._fields(["inertia"])[0]
        return np.stack(self._fields(["ix", "iy", "iz"]), axis=1)

    def _need(self, dim: int, what: str, other: str) -> None:
        if self.dim != dim:
            raise InvalidInputError(f"{what}: these bodies are {self.dim}D; read their {other}")

    def outline(self) -> list[np.ndarray]:
        """The shape of each body as a polygon in its own frame, (V, 2) float64 m (a ball and a
        capsule's caps as 32-gons): what the renderer fills (2D)."""
        self._need(2, "outline", "meshes")
        return _outline(self.shape, self.size, self.vertices)

    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each body's shape as triangles in its own frame (3D): vertices (V, 3) float64 m and
        faces (T, 3) int64 (a ball and a capsule as 16 × 32 facets): what the renderer draws."""
        self._need(3, "meshes", "outline")
        host = self._bound()
        first = self.first

        def read(sim: Any) -> list[tuple[np.ndarray, np.ndarray]]:
            out = []
            for i in range(self.n):
                v, t = sim.body_mesh(first + i)  # type: ignore[operator]
                out.append((np.asarray(v, np.float64), np.asarray(t, np.int64)))
            return out

        return host.exclusive(read)

    # -- the part protocol
    def _params(self) -> dict[str, Any]:
        """The core's parameters of the group, at its starting state."""
        p: dict[str, Any] = {
            "shape": self.shape, "kind": self.kind, "n": self.n,
            "positions": np.ascontiguousarray(self.start).reshape(-1),
            ("angles" if self.dim == 2 else "orientations"): np.ascontiguousarray(self.start_turns).reshape(-1),
            "velocities": np.ascontiguousarray(self.start_velocities).reshape(-1),
            "angular_velocities": np.ascontiguousarray(self.start_angular).reshape(-1),
            "size": np.ascontiguousarray(self.size, dtype=np.float64).reshape(-1),
            "density": self.density, "friction": self.friction, "restitution": self.restitution,
            "rolling_friction": self.rolling_friction,
        }
        if self.vertices is not None:
            p["vertices"] = np.ascontiguousarray(self.vertices).reshape(-1)
            p["n_vertices"] = int(self.vertices.shape[0])
        if self.triangles is not None:
            p["triangles"] = np.ascontiguousarray(self.triangles, np.float64).reshape(-1)
            p["n_triangles"] = int(self.triangles.shape[0])
        return p

    def _claim_name(self, ctx: AttachContext) -> str:
        taken = {p.name for p in ctx.parts if isinstance(p, Bodies)}
        if self.name is not None:
            if self.name in taken:
                raise InvalidInputError(f"name: {self.name!r} is taken by other bodies of this scene")
            return self.name
        name, k = "bodies", 2
        while name in taken:
            name, k = f"bodies_{k}", k + 1
        return name

    def _attach(self, ctx: AttachContext, name: str) -> Bodies:
        if self.dim is not None and self.dim != ctx.dim:
            raise InvalidInputError(f"item: these bodies are {self.dim}D (their arguments' width) and the scene is {ctx.dim}D")
        if self._host is not None:
            raise InvalidInputError(f"item: bodies {self.name!r} are already in a scene (a group joins one scene)")
        if self.dim is None:
            self._resolve(ctx.dim)
            self.dim = ctx.dim
        self.first = int(ctx.sim.add_bodies(self._params()))
        self.name = name
        self._host = ctx.host
        return self

    def _taken_despite(self, ctx: AttachContext, name: str) -> Bodies | None:
        # The core numbers bodies across groups in the order added: it took this group if it
        # holds this many more than the scene's groups.
        known = sum(p.n for p in ctx.parts if isinstance(p, Bodies))
        try:
            held = len(ctx.sim.system_fields(SYSTEM, ["x"])[0])
        except Exception:  # noqa: BLE001 - no system "bodies" yet: nothing taken
            return None
        if (self._host is not None and self._host is not ctx.host) or held != known + self.n:
            return None
        self.first, self.name, self._host = known, name, ctx.host
        return self

    def _record(self) -> dict[str, Any]:
        rec = {"shape": self.shape, "kind": self.kind, "n": self.n, "density": self.density, "friction": self.friction,
               "restitution": self.restitution, "color": np.asarray(self.color).astype(int).tolist()}
        if self.rolling_friction:
            # Only when set: files of groups without it stay as they were (absent: 0).
            rec["rolling_friction"] = self.rolling_friction
        return rec

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        a, b = self.first, self.first + self.n  # type: ignore[operator]
        if self.dim == 2:
            f = [np.asarray(v)[a:b] for v in sim.system_fields(SYSTEM, ["x", "y", "angle", "vx", "vy", "omega"])]
            arrays = {"positions": np.stack(f[:2], 1), "angles": f[2], "velocities": np.stack(f[3:5], 1),
                      "angular_velocities": f[5]}
        else:
            names = ["x", "y", "z", "qx", "qy", "qz", "qw", "vx", "vy", "vz", "wx", "wy", "wz"]
            f = [np.asarray(v)[a:b] for v in sim.system_fields(SYSTEM, names)]
            arrays = {"positions": np.stack(f[:3], 1), "orientations": np.stack(f[3:7], 1),
                      "velocities": np.stack(f[7:10], 1), "angular_velocities": np.stack(f[10:13], 1)}
        arrays["size"] = np.asarray(self.size, np.float64).reshape(-1)
        if self.vertices is not None:
            arrays["vertices"] = self.vertices
        if self.triangles is not None:
            arrays["triangles"] = self.triangles.astype(np.float64)
        if self.first == 0:
            # The solver's whole state (contacts, warm starts), once, with the first group.
            state = dict(sim.system_save(SYSTEM))
            arrays["state"], arrays["state_bytes"] = state["state"], state["bytes"]
        return {"name": self.name, "part": "group", "record": self._record()}, arrays

    def _state(self, sim: Any) -> dict[str, np.ndarray]:
        """The rigid-body solver's whole state (every group's poses and velocities, contacts,
        warm starts: ``state`` and ``state_bytes``, as the scene file), held by the first group;
        ``{}`` for the others."""
        if self.first != 0:
            return {}
        state = dict(sim.system_save(SYSTEM))
        return {"state": state["state"], "state_bytes": state["bytes"]}

    def _set_state(self, sim: Any, arrays: Any) -> None:
        if "state" in arrays:
            sim.system_load(SYSTEM, [("state", np.asarray(arrays["state"], np.float64)),
                                     ("bytes", np.asarray(arrays["state_bytes"], np.float64).reshape(-1))])

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        rec = cls._checked_record(entry)
        need = ["positions", "angles" if "orientations" not in arrays else "orientations", "velocities",
                "angular_velocities", "size"]
        missing = [k for k in need if k not in arrays]
        if missing:
            raise InvalidInputError(f"arrays: missing {', '.join(missing)}")
        shape = rec.get("shape")
        x = np.asarray(arrays["positions"])
        dim = x.shape[1] if x.ndim == 2 and x.shape[1] in (2, 3) else 2
        width = dim if shape == "box" else 2
        size = arrays["size"].reshape(-1, width) if shape in ("box", "capsule") else arrays["size"]
        listed = shape in ("polygon", "polyline", "hull", "mesh")
        part = cls(shape, size=size if not listed else None, positions=arrays["positions"], angles=arrays.get("angles"),
                   orientations=arrays.get("orientations"),
                   velocities=arrays["velocities"], angular_velocities=arrays["angular_velocities"],
                   vertices=arrays.get("vertices"), triangles=arrays.get("triangles"),
                   density=rec.get("density"), friction=rec.get("friction"),
                   restitution=rec.get("restitution"), rolling_friction=rec.get("rolling_friction", 0.0),
                   kind=rec.get("kind"), color=rec.get("color"), name=entry.get("name"))
        if ("state" in arrays) != ("state_bytes" in arrays):
            raise InvalidInputError("state, state_bytes: the bodies' solver state needs both (its packed bytes and their count)")
        ctx.add(part)
        if "state" in arrays:
            ctx.sim.system_load(SYSTEM, [("state", np.asarray(arrays["state"], np.float64)),
                                         ("bytes", np.asarray(arrays["state_bytes"], np.float64).reshape(-1))])

    def __repr__(self) -> str:
        return f"Bodies({self.shape!r}, n={self.n}, kind={self.kind!r}, name={self.name!r})"


class Joints(_BodiesPart):
    """Joints between rigid bodies, one per pair ``(a[k], b[k])``; 2D or 3D (the width of
    ``anchors``).

    Parameters
    ----------
    kind : str
        ``"revolute"`` (a hinge: the bodies share the anchor point and turn freely about it;
        in 3D about ``axis``), ``"fixed"`` (welded as they are now), ``"prismatic"`` (a slider
        along ``axis``, no turning), ``"spherical"`` (3D: a ball-and-socket, turning freely
        about every axis; a body held only by one to the world is a heavy top, stepped about
        its pivot by a second-order symplectic splitting while it touches nothing: Dullweber,
        Leimkuhler and McLachlan, J. Chem. Phys. 107 (1997) 5840; see the bodies guide),
        ``"rope"`` (the anchors at most ``length`` apart; slack below it).
    a, b : BodyRef or None
        The bodies joined, as ``group[i]`` or ``group[i:j]`` (equal counts M); ``None`` for one
        of them: the fixed world (a pendulum's pivot).
    anchors : (M, dim) or (dim,) array_like of float
        The joints' points in the world now, m (on body ``a``; for a rope, its end on ``a``).
    anchors_b : (M, dim) or (dim,) array_like of float, optional
        A rope's end on body ``b`` (default: ``anchors``).
    axis : (dim,) or (M, dim) array_like, prismatic (and revolute in 3D) only
        The sliding direction, or the hinge's axis, in the world now (default x for a slider in
        2D, z otherwise).
    limits : (2,) or (M, 2) array_like, optional
        Revolute: the relative angle's range, rad; prismatic: the travel along the axis, m.
    length : float or (M,) array_like, rope only
        The rope's longest length, m (default: the anchors' distance now).

    Raises
    ------
    InvalidInputError
        Unknown kind, or a spherical joint in 2D; `a` and `b` of different lengths, both None,
        or joining a body to itself; bodies of another scene or dimension, or not yet added;
        wrong shapes; a zero axis; lower > upper limit.
    """

    part_kind: ClassVar[str] = "joints"

    @allocating("Joints", "its arrays")
    def __init__(self, kind: str, a: BodyRef | Bodies | None, b: BodyRef | Bodies | None, anchors: Any, *,
                 anchors_b: Any = None, axis: Any = None, limits: Any = None, length: Any = None) -> None:
        self.kind = _check.choice("kind", kind, JOINTS)
        ra, rb = _ref("a", a), _ref("b", b)
        if ra is None and rb is None:
            raise InvalidInputError("a: a joint needs at least one body (a and b are both None)")
        m = len(ra) if ra is not None else len(rb)  # type: ignore[arg-type]
        if ra is not None and rb is not None and len(ra) != len(rb):
            raise InvalidInputError(f"b: joins {len(rb)} bodies to {len(ra)} (a and b must have equal counts)")
        if m == 0:  # as the scene file's rule (m >= 1): what is added must save and load again
            raise InvalidInputError(f"{'a' if ra is not None else 'b'}: selects no bodies; a Joints part joins at least one pair")
        self.m = m
        self.a, self.b = ra, rb
        dim = _width(anchors)
        if dim is None:
            raise InvalidInputError(f"anchors: expected shape (M, 2) or (M, 3), got {np.shape(anchors)}")
        self.dim = dim
        if self.kind == "spherical" and dim != 3:
            raise InvalidInputError("kind: a spherical joint is 3D (in 2D a revolute joint turns freely)")
        self.anchors = _rows("anchors", anchors, m, dim)
        self.anchors_b = None if anchors_b is None else _rows("anchors_b", anchors_b, m, dim)
        if axis is not None and not (self.kind == "prismatic" or (self.kind == "revolute" and dim == 3)):
            raise InvalidInputError(f"axis: only prismatic joints (and revolute ones in 3D) have one, not {self.kind}"
                                    + (" in 2D" if self.kind == "revolute" else ""))
        self.axis = None if axis is None else _rows("axis", axis, m, dim)
        if self.axis is not None and (np.linalg.norm(self.axis, axis=1) == 0).any():
            raise InvalidInputError("axis: must not be zero")
        if limits is not None and self.kind not in ("revolute", "prismatic"):
            raise InvalidInputError(f"limits: only revolute and prismatic joints have them, not {self.kind}")
        self.limits = None if limits is None else _rows("limits", limits, m, 2)
        if self.limits is not None and (self.limits[:, 0] > self.limits[:, 1]).any():
            raise InvalidInputError("limits: lower > upper")
        if length is not None and self.kind != "rope":
            raise InvalidInputError(f"length: only ropes have one, not {self.kind}")
        self.length = None if length is None else _rows("length", length, m, 1)
        if self.length is not None and (self.length < 0).any():
            raise InvalidInputError("length: must be >= 0 (m)")
        for rec in (self.anchors, self.anchors_b, self.axis, self.limits, self.length):  # copies: read-only (see Bodies)
            if rec is not None:
                rec.setflags(write=False)
        self._host: Host | None = None
        self._loaded: tuple[np.ndarray, np.ndarray] | None = None

    def _numbers(self, ref: BodyRef | None, ctx_parts: tuple[Part, ...] | None, arg: str) -> np.ndarray:
        """The core's numbers of the bodies `ref` (−1: the world)."""
        if self._loaded is not None:  # read from a scene file: the numbers it holds
            return self._loaded[0 if arg == "a" else 1]
        if ref is None:
            return np.full(self.m, -1.0)
        g = ref.group
        if g.first is None or (ctx_parts is not None and not any(p is g for p in ctx_parts)):
            raise InvalidInputError(f"{arg}: bodies {g.name!r} are not in this scene (add them before their joints)")
        return (g.first + ref.index).astype(np.float64)

    def _params(self, parts: tuple[Part, ...] | None) -> dict[str, Any]:
        p: dict[str, Any] = {"kind": self.kind, "m": self.m, "a": self._numbers(self.a, parts, "a"),
                             "b": self._numbers(self.b, parts, "b"), "anchor": self.anchors.reshape(-1)}
        for key, v in (("anchor_b", self.anchors_b), ("axis", self.axis), ("limits", self.limits), ("length", self.length)):
            if v is not None:
                p[key] = np.ascontiguousarray(v).reshape(-1)
        return p

    def _attach(self, ctx: AttachContext, name: Any) -> Joints:
        if self.dim != ctx.dim:
            raise InvalidInputError(f"anchors: these joints are {self.dim}D (the anchors' width) and the scene is {ctx.dim}D")
        if self._host is not None:
            raise InvalidInputError("item: these joints are already in a scene")
        ctx.sim.add_joints(self._params(ctx.parts))
        self._host = ctx.host
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        p = self._params(None)
        arrays = {k: np.asarray(p[k], np.float64) for k in ("a", "b", "length") if k in p}
        for key, v in (("anchor", self.anchors), ("anchor_b", self.anchors_b), ("axis", self.axis), ("limits", self.limits)):
            if v is not None:
                arrays[key] = np.asarray(v, np.float64)
        return {"part": "joints", "record": {"kind": self.kind, "m": self.m}}, arrays

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        rec = cls._checked_record(entry)
        j = cls.__new__(cls)
        j.kind = _check.choice("kind", rec.get("kind"), JOINTS)
        j.m = _check.int_in_range("m", rec.get("m"), 1, 1 << 24)
        j.a = j.b = None
        j.dim = _width(arrays.get("anchor")) or 2
        j.anchors = _rows("anchor", arrays.get("anchor"), j.m, j.dim)
        j.anchors_b = None if "anchor_b" not in arrays else _rows("anchor_b", arrays["anchor_b"], j.m, j.dim)
        j.axis = None if "axis" not in arrays else _rows("axis", arrays["axis"], j.m, j.dim)
        j.limits = None if "limits" not in arrays else _rows("limits", arrays["limits"], j.m, 2)
        j.length = None if "length" not in arrays else _rows("length", arrays["length"], j.m, 1)
        j._host = None
        j._loaded = (_rows("a", arrays.get("a"), j.m, 1), _rows("b", arrays.get("b"), j.m, 1))
        ctx.add(j)

    def __repr__(self) -> str:
        return f"Joints({self.kind!r}, m={self.m})"


class Pins(_BodiesPart):
    """Particles pinned to rigid bodies: each particle moves with the point of its body where it
    is when added, both ways (cloth hung from a bar, a rope tied to a box). Each step the
    particle is put on that point and its velocity made the point's by an impulse along the
    difference, applied to the body the other way (the particle's forces, springs and all,
    reach the body through it); a fixed or kinematic body is not pushed. What this exchanges is
    booked with the particle coupling (``"bodies ⇄ particles"``). Particles pinned in the scene
    (``pinned=True``) stay where they are.

    Parameters
    ----------
    particles : (M,) array_like of int
        Particle indices (distinct).
    body : BodyRef
        One body for all (``bars[0]``) or one per particle (``boxes[[0, 0, 1]]``).

    Raises
    ------
    InvalidInputError
        Indices not distinct, negative or beyond the scene's particles; a body count that is
        neither 1 nor M; bodies of another scene or dimension, or not yet added.
    InvalidTypeError
        `body` not a BodyRef or Bodies group.

    Examples
    --------
    >>> import numpy as np, physcore as pc
    >>> scene = pc.Scene(dim=2, dt=1 / 240)
    >>> _ = scene.add(pc.Gravity([0.0, -9.81]))
    >>> _ = scene.add_particles(np.array([[0.3, 0.0]]))
    >>> bar = scene.add(pc.Bodies("box", size=(0.3, 0.05), positions=[(0.0, 0.0)], kind="kinematic",
    ...                           velocities=[(1.0, 0.0)]))
    >>> _ = scene.add(pc.Pins([0], bar[0]))
    >>> scene.step(240)
    >>> np.round(scene.positions[0], 3)  # carried along with the bar's end, 1 m in 1 s
    array([1.3, 0. ])
    """

    part_kind: ClassVar[str] = "pins"

    @allocating("Pins", "its arrays")
    def __init__(self, particles: Any, body: BodyRef | Bodies) -> None:
        self.particles = _indices(particles)
        self.particles.setflags(write=False)  # a copy: read-only (see Bodies)
        if np.unique(self.particles).size != self.particles.size:
            raise InvalidInputError("particles: each particle can be pinned once")
        ref = _ref("body", body)
        if ref is None:
            raise InvalidInputError("body: pins need a body (a particle pinned to the world: scene.add_particles(pinned=True))")
        if len(ref) not in (1, self.particles.size):
            raise InvalidInputError(f"body: {len(ref)} bodies for {self.particles.size} particles (give 1, or one per particle)")
        self.body = ref
        self._host: Host | None = None
        self._loaded: dict[str, np.ndarray] | None = None

    def _attach(self, ctx: AttachContext, name: Any) -> Pins:
        if self._host is not None:
            raise InvalidInputError("item: these pins are already in a scene")
        m = self.particles.size
        # Checked here, for a file's pins as for new ones: distinct, in the scene, and pinned
        # by no other Pins part (one point each particle is put on).
        if np.unique(self.particles).size != m:
            raise InvalidInputError("particles: each particle can be pinned once")
        if int(self.particles.max()) >= ctx.n_particles:
            raise InvalidInputError(f"particles: index {int(self.particles.max())} is beyond the scene's "
                                    f"{ctx.n_particles} particles (add the particles first)")
        for other in ctx.parts:
            if isinstance(other, Pins) and other is not self:
                twice = np.intersect1d(self.particles, other.particles)
                if twice.size:
                    raise InvalidInputError(f"particles: particle {int(twice[0])} is pinned already (each particle can be pinned once)")
        if self._loaded is not None:
            numbers, points = self._loaded["body"], self._loaded["points"]
        else:
            g = self.body.group
            if g.first is None or not any(p is g for p in ctx.parts):
                raise InvalidInputError(f"body: bodies {g.name!r} are not in this scene (add them before the pins)")
            if g.dim != ctx.dim:
                raise InvalidInputError(f"body: these bodies are {g.dim}D and the scene is {ctx.dim}D")
            numbers = np.broadcast_to(g.first + self.body.index, (m,)).astype(np.float64)
            points = np.asarray(ctx.read_positions(), np.float64)[self.particles]
        ctx.sim.add_pins({"m": m, "particles": self.particles.astype(np.float64), "body": np.ascontiguousarray(numbers),
                          "points": np.ascontiguousarray(points).reshape(-1)})
        self._numbers, self._points = np.array(numbers), np.array(points)
        self._numbers.setflags(write=False)
        self._points.setflags(write=False)
        self._host = ctx.host
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return ({"part": "pins", "record": {"m": int(self.particles.size)}},
                {"particles": self.particles.astype(np.float64), "body": self._numbers, "points": self._points})

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        rec = cls._checked_record(entry)
        m = _check.int_in_range("m", rec.get("m"), 1, 1 << 24)
        missing = [k for k in ("particles", "body", "points") if k not in arrays]
        if missing:
            raise InvalidInputError(f"arrays: missing {', '.join(missing)}")
        p = cls.__new__(cls)
        p.particles = _indices(arrays["particles"])
        if p.particles.size != m:
            raise InvalidInputError(f"particles: {p.particles.size} entries where record.m is {m}")
        body = _rows("body", arrays["body"], m, 1)
        pts = np.asarray(arrays["points"], np.float64)
        dim = _width(pts) or 2
        p._loaded = {"body": body, "points": _rows("points", pts, m, dim)}
        p.body = None  # type: ignore[assignment]
        p._host = None
        ctx.add(p)

    def __repr__(self) -> str:
        return f"Pins(m={self.particles.size})"


def _indices(value: Any) -> np.ndarray:
    """Particle indices (M,) int64 from `value`, checked: integers in 0..2⁴⁰, M ≥ 1."""
    idx = _check.real_array("particles", value)
    if idx.ndim != 1 or idx.size < 1:
        raise InvalidInputError(f"particles: expected shape (M,) with M >= 1, got {idx.shape}")
    if not (np.isfinite(idx).all() and (idx == np.round(idx)).all() and (idx >= 0).all() and (idx < 2.0**40).all()):
        raise InvalidInputError("particles: every entry must be a particle index (an integer >= 0)")
    return idx.astype(np.int64)


def _ref(arg: str, value: Any) -> BodyRef | None:
    if value is None:
        return None
    if isinstance(value, Bodies):
        return value[:]
    if isinstance(value, BodyRef):
        return value
    raise InvalidTypeError(f"{arg}: expected bodies[i] (a BodyRef), a Bodies group or None, got {type(value).__name__}")


_DEFAULT_COLORS = {"ball": (214, 96, 77), "box": (222, 160, 87), "capsule": (95, 158, 160), "polygon": (130, 120, 190),
                   "polyline": (110, 116, 128),
                   "hull": (130, 120, 190), "mesh": (150, 156, 166)}


def _color(value: Any, shape: str) -> np.ndarray:
    if value is None:
        return np.array(_DEFAULT_COLORS[shape], dtype=np.uint8)
    if isinstance(value, str):
        try:
            from matplotlib.colors import to_rgb
        except ImportError:  # pragma: no cover - matplotlib is optional
            raise InvalidInputError("color: a colour name needs matplotlib; give RGB 0-255 instead") from None
        try:
            return np.array([round(255 * c) for c in to_rgb(value)], dtype=np.uint8)
        except ValueError:
            raise InvalidInputError(f"color: unknown colour {value!r}") from None
    a = _check.real_array("color", value)
    if a.ndim == 2 and a.shape[1] == 3 and np.isfinite(a).all() and (a >= 0).all() and (a <= 255).all():
        return a.astype(np.uint8)
    if a.shape != (3,) or not np.isfinite(a).all() or (a < 0).any() or (a > 255).any():
        raise InvalidInputError(f"color: expected a name or 3 values in 0..255, got {value!r}")
    return a.astype(np.uint8)


def _outline(shape: str, size: np.ndarray, vertices: np.ndarray | None) -> list[np.ndarray]:
    """Each body's polygon in its own frame (see :meth:`Bodies.outline`)."""
    t = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    out = []
    for i in range(size.shape[0]):
        if shape == "ball":
            out.append(circle * float(size[i]))
        elif shape == "box":
            hx, hy = (float(s) for s in size[i])
            out.append(np.array([(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]))
        elif shape == "capsule":
            half, r = (float(s) for s in size[i])
            h = np.linspace(-np.pi / 2, np.pi / 2, 17)
            right = np.stack([half + r * np.cos(h), r * np.sin(h)], 1)
            left = np.stack([-half - r * np.cos(h), -r * np.sin(h)], 1)
            out.append(np.concatenate([right, left]))
        elif shape == "polyline":
            out.append(np.asarray(vertices, np.float64))  # an open chain: drawn segment by segment
        else:
            out.append(_hull(vertices))  # type: ignore[arg-type]
    return out


def _hull(v: np.ndarray) -> np.ndarray:
    """The convex hull of 2D points, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.asarray(v, np.float64)))

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=np.float64)


def _quaternion(rotvec: np.ndarray) -> list[float]:
    """The unit quaternion (x, y, z, w) of a rotation vector (axis × angle, rad)."""
    theta = float(np.linalg.norm(rotvec))
    if theta == 0.0:
        return [0.0, 0.0, 0.0, 1.0]
    k = rotvec / theta
    return [*(math.sin(0.5 * theta) * k).tolist(), math.cos(0.5 * theta)]


def _quaternion_between(u: np.ndarray, v: np.ndarray) -> list[float]:
    """The unit quaternion (x, y, z, w) of the shortest turn taking unit u onto unit v."""
    c = float(np.dot(u, v))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis normal to u
        axis = np.cross(u, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(u, [0.0, 1.0, 0.0])
        return _quaternion(math.pi * axis / np.linalg.norm(axis))
    w = np.cross(u, v)
    q = np.array([*w, 1.0 + c])
    return (q / np.linalg.norm(q)).tolist()


def _turn_x_onto(d: np.ndarray) -> dict[str, Any]:
    """``angles`` (2D) or ``orientations`` (3D) turning a body's local x onto the unit d."""
    if d.shape[0] == 2:
        return {"angles": [math.atan2(d[1], d[0])]}
    return {"orientations": [_quaternion_between(np.array([1.0, 0.0, 0.0]), d)]}
