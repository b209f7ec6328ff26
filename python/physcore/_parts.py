"""The part protocol: everything a :class:`~physcore.Scene` holds is a *part*.

Force terms (:class:`~physcore.terms.Term`, fluids included), colliders (:class:`Plane`,
:class:`Box`, :class:`Sphere`), grid systems (:class:`~physcore.grids.Grid`) and flows
(:class:`~physcore.flows.Flow`) all subclass :class:`Part` and register themselves in
:data:`PARTS` by a key. A part describes itself completely:

* :attr:`Part.section` — the list of the scene file it is written in (``"terms"``, ``"planes"``,
  ``"boxes"``, ``"spheres"``, ``"grids"``, ``"flows"``: the sections files have always had, in
  the order they are written and read, so files stay byte-identical; then ``"colliders"``, for
  colliders registered by key, written only when it holds one) and :attr:`Part.part_kind`,
  its key within the section (a term's type key, a grid's kind; one-class sections use the
  singular, ``"plane"``, ``"flow"``). The registry key is ``"{section}/{part_kind}"``: a section
  qualifies the kind because the kinds of different sections were chosen independently. Since
  issue 45 no kind means two things: the SPH term is ``"terms/fluid"``, the grid fluid
  ``"grids/stable_fluid"``; :data:`PART_ALIASES` maps the old key ``"grids/fluid"`` (scene files
  written before) onto it.
* :meth:`Part._claim_name` and :meth:`Part._attach` — how it joins a scene, given an
  :class:`AttachContext`: the scene's dimension, the names taken, its integrator, attribute names
  and particle count, and the few operations a part may perform (register with the core
  Simulation ``sim``; fluids: append particles, lower dt; live handles: a :class:`Host` to read
  their state later). It returns the part as stored.
* :meth:`Part._entry` — what the scene file holds of it: its JSON entry in its section and its
  array members (named ``{prefix}{k}_{member}`` by the writer, the prefix being the section's
  :data:`MEMBER_PREFIX`).
* :meth:`Part._load` (a classmethod) — how the reader rebuilds it from its checked entry and
  members, given a :class:`LoadContext`.

Why this shape:

* The scene never needs to know what a part is: :meth:`Scene.add` looks the class up in
  :data:`PARTS`, builds one context, calls ``_attach``, and keeps the result in one list; the
  scene file writer and reader loop over parts and sections without a branch per kind. A new
  kind of part touches only its own module.
* Parts never see the :class:`Scene`: the context holds exactly what they may read and do. So no
  part module imports ``scene.py`` (the old import circle scene -> terms/contacts/flows/fluids
  -> scene is gone), and a part cannot reach into the scene's private members.
* ``_attach(ctx, name)`` keeps the ``name`` argument of the old term protocol
  (``_attach(scene, name)``): the name a part joins under is resolved by the part class's own
  rule (:meth:`Part._claim_name`: terms are renamed ``_2``, ``_3``, ...; grids and flows must
  have a free name; colliders have none) before it attaches. Terms written against the old
  protocol, outside physcore, keep working: the context offers what they used of the scene
  (``dim``, ``n_particles``, ``positions``, ``integrator``, ``attributes``, and ``_sim`` as an
  alias of ``sim``).
* Live handles (grids, flows) get a :class:`Host`, not the scene: ``exclusive(call)`` runs a
  core call as the scene's only user (so another thread's use raises ``SceneBusyError``), and
  ``energy_changed()`` says that the energy books' reference must be taken anew.

This module imports nothing from the part modules or from ``scene.py``.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import numpy as np

from ._errors import InvalidInputError, InvalidTypeError

__all__ = ["Part", "PARTS", "PART_ALIASES", "SECTIONS", "OPTIONAL_SECTIONS", "COLLIDER_SECTIONS", "MEMBER_PREFIX", "AttachContext", "LoadContext", "Host", "part_class", "unique_name"]

#: The sections of a scene file's ``meta``, in the order they are written and read.
SECTIONS: tuple[str, ...] = ("terms", "planes", "boxes", "spheres", "grids", "flows", "colliders", "bodies")
#: The prefix of each section's array members: ``term{k}_positions``, ``grid{k}_u``, ...
MEMBER_PREFIX: dict[str, str] = {
    "terms": "term", "planes": "plane", "boxes": "box", "spheres": "sphere", "grids": "grid", "flows": "flow",
    "colliders": "collider", "bodies": "body",
}
#: The field of a section's entries that names the part's kind (sections of one class have none).
SECTION_KEY: dict[str, str] = {"terms": "type", "grids": "kind", "colliders": "type", "bodies": "part"}
#: Sections written only when they hold a part: those added after files of this format were
#: first written, so a scene without one saves the same bytes as before. ``"colliders"`` holds
#: the colliders registered by key (:class:`physcore.terms.Collider`: the capsule, and the next
#: ones); the plane, box and sphere keep their own sections.
OPTIONAL_SECTIONS: frozenset[str] = frozenset({"colliders", "bodies"})
#: The sections that hold colliders, in the order :attr:`physcore.Scene.colliders` lists them
#: (the order they are written and read, so a scene and its loaded copy list them alike).
COLLIDER_SECTIONS: tuple[str, ...] = ("planes", "boxes", "spheres", "colliders")
#: Names no part may take: the energy books' entry of the colliders, and of the particles.
RESERVED_NAMES: frozenset[str] = frozenset({"collisions"})
RESERVED_SYSTEM_NAMES: frozenset[str] = frozenset({"particles", "collisions"})

#: Every part class by its key ``"{section}/{part_kind}"``, filled as the classes are defined.
PARTS: dict[str, type[Part]] = {}
#: Old keys that scene files may hold -> the key now (docs/naming.md).
PART_ALIASES: dict[str, str] = {"grids/fluid": "grids/stable_fluid"}


class Host(Protocol):
    """What a live handle (a grid, a flow) may do with the scene it joined."""

    def exclusive(self, call: Callable[[Any], Any]) -> Any:
        """Runs ``call(sim)`` as the scene's only user (see ``Scene._exclusive``)."""

    def energy_changed(self) -> None:
        """The scene's energy-drift reference is to be taken anew (a field was set)."""


@dataclass(frozen=True)
class AttachContext:
    """What a part sees of the scene it joins (see the module docstring)."""

    #: Spatial dimension, 2 or 3.
    dim: int
    #: Names taken, by section (``"terms"``, ``"grids"``, ``"flows"``).
    names: Mapping[str, frozenset[str]]
    #: The scene's integrator name.
    integrator: str
    #: Particles in the scene now.
    n_particles: int
    #: The core ``Simulation``: a part registers itself with it (``add_term``, ``add_grid``, ...).
    sim: Any
    #: The parts already in the scene, as stored, in the order added.
    parts: tuple[Part, ...]
    #: ``read_positions()``: the particles' positions now, (N, dim) (a copy; only some parts need it).
    read_positions: Callable[[], np.ndarray]
    #: ``read_attributes()``: the names of the per-particle attributes set so far.
    read_attributes: Callable[[], frozenset[str]]
    #: ``add_particles(positions, velocities, masses)``: appends particles (checked as
    #: :meth:`Scene.add_particles` checks them); returns their indices.
    add_particles: Callable[..., np.ndarray]
    #: ``lower_dt(limit)``: the scene's dt becomes ``min(dt, limit)``.
    lower_dt: Callable[[float], None]
    #: The scene as a live handle may use it later.
    host: Host
    #: What a scene file says the part already holds in the scene (a loaded fluid's ``first``
    #: particle); empty when a user adds the part.
    restoring: Mapping[str, Any] = field(default_factory=dict)

    @property
    def positions(self) -> np.ndarray:
        """The particles' positions now (as ``Scene.positions``)."""
        return self.read_positions()

    @property
    def attributes(self) -> frozenset[str]:
        """The names of the per-particle attributes set so far (``"charge"``, ``"radius"``)."""
        return self.read_attributes()

    @property
    def _sim(self) -> Any:
        """``sim``, under the name terms written against the old ``_attach(scene, name)``
        protocol use."""
        return self.sim


@dataclass(frozen=True)
class LoadContext:
    """What the scene file reader gives a part class's :meth:`Part._load`."""

    dim: int
    #: The core ``Simulation`` (restoring a part's state: ``set_term_history``, ``system_load``).
    sim: Any
    #: The part's index in its section, and its field in the file (``"meta.terms[3]"``).
    index: int
    field: str
    #: ``add(part, **restoring)``: adds the rebuilt part to the scene (as :meth:`Scene.add`,
    #: with what the file says it holds already) and returns it as stored.
    add: Callable[..., Any]
    #: ``api(context, members)``: turns the API's errors inside into a SceneFileError naming the
    #: file's field (see ``_scenefile._Reader.api``).
    api: Callable[..., AbstractContextManager[None]]

    @property
    def _sim(self) -> Any:
        return self.sim


class Part:
    """Base of everything a scene holds (see the module docstring)."""

    #: The scene file section the part is written in (one of :data:`SECTIONS`).
    section: ClassVar[str] = ""
    #: The part's key within its section; a class that sets it is registered in :data:`PARTS`.
    part_kind: ClassVar[str] = ""
    #: Whether adding the part changes the energy books (the scene then takes a new reference
    #: energy at its next step). Flows are not in the books.
    changes_energy: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("part_kind"):
            register(cls)

    # ------------------------------------------------------------ the protocol
    def _claim_name(self, ctx: AttachContext) -> str | None:
        """The name the part joins under (``None``: it has none). Raises if it cannot have one."""
        return None

    def _attach(self, ctx: AttachContext, name: Any) -> Part:
        """Checks the part against the scene, registers it with ``ctx.sim`` and returns the part
        as stored. Raises before changing anything."""
        raise NotImplementedError

    def _taken_despite(self, ctx: AttachContext, name: Any) -> Part | None:
        """After ``_attach`` raised: the part completed as stored if the core took it all the
        same (Ctrl-C raised as the core's call returned), so that the scene records what the core
        holds; ``None`` (the default) if the core did not take it."""
        return None

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Its entry in its section of the scene file (JSON values) and its array members (by
        member name, without the ``{prefix}{k}_`` the writer adds). ``sim`` is the core, read
        for state only the core holds (a grid's fields, a contact term's springs)."""
        raise NotImplementedError

    def _state(self, sim: Any) -> dict[str, np.ndarray]:
        """What changes of the part while the scene runs, for :meth:`Scene.state`: float64 arrays
        by member name, as its scene file members are named (``history``, a grid's fields); a
        part with no state of its own (a record the core only reads) returns ``{}``."""
        return {}

    def _set_state(self, sim: Any, arrays: Mapping[str, np.ndarray]) -> None:
        """Puts back what :meth:`_state` returned (for :meth:`Scene.set_state`, which has checked
        the names, dtypes and finiteness); the core checks the contents."""

    @classmethod
    def _load_names(cls, ctx: LoadContext, arrays: Mapping[str, np.ndarray]) -> tuple[str, dict[str, str]]:
        """``(context, members)`` for the reader's error messages while :meth:`_load` runs (see
        :attr:`LoadContext.api`)."""
        return ctx.field, {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        """Rebuilds the part from its checked entry and members and adds it (``ctx.add``)."""
        raise NotImplementedError


def part_key(section: str, kind: str) -> str:
    return f"{section}/{kind}"


def register(cls: type[Part]) -> type[Part]:
    """Registers ``cls`` under its section and kind; a key is taken once."""
    if cls.section not in SECTIONS:
        raise InvalidTypeError(f"section: {cls.__name__} names section {cls.section!r}; valid: {', '.join(SECTIONS)}")
    key = part_key(cls.section, cls.part_kind)
    if key in PARTS and PARTS[key] is not cls:
        raise InvalidTypeError(f"kind: {cls.part_kind!r} is already the key of {PARTS[key].__name__} in {cls.section}")
    PARTS[key] = cls
    return cls


def section_kinds(section: str) -> dict[str, type[Part]]:
    """The registered classes of one section, by kind."""
    prefix = f"{section}/"
    return {k[len(prefix):]: c for k, c in PARTS.items() if k.startswith(prefix)}


def part_class(item: object) -> type[Part] | None:
    """The registered class of ``item``, or None: it is not a part, or its class is not the one
    registered under its key (an unregistered subclass, which files could not name)."""
    if not isinstance(item, Part):
        return None
    cls = type(item)
    if not (cls.section and cls.part_kind):
        return None
    return cls if PARTS.get(part_key(cls.section, cls.part_kind)) is cls else None


def entry_class(section: str, entry: Mapping[str, Any]) -> type[Part]:
    """The class that reads ``entry`` of ``section`` (the reader has checked that it names one)."""
    key = SECTION_KEY.get(section)
    if key is None:
        (cls,) = section_kinds(section).values()
        return cls
    k = part_key(section, entry[key])
    return PARTS[PART_ALIASES.get(k, k)]


def unique_name(base: object, taken: frozenset[str] | set[str]) -> str:
    """``base``, or ``base_2``, ``base_3``, ... : the first not in ``taken``."""
    if not isinstance(base, str) or not base:
        raise InvalidTypeError("name: expected a non-empty str")
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name


def check_system(ctx: AttachContext, item: Any, what: str) -> None:
    """The rule of the systems of the world (grids, flows): the scene's dimension, one scene
    each, and a name no term, grid or flow has (nor a reserved one)."""
    if item.dim != ctx.dim:
        raise InvalidInputError(f"item: a {item.dim}D {what} ({item.kind}) cannot join a {ctx.dim}D scene")
    if item._host is not None:
        raise InvalidInputError(f"item: {what} {item.name!r} is already in a scene (a {what} joins one scene)")
    taken = ctx.names["grids"] | ctx.names["flows"] | ctx.names["terms"] | RESERVED_SYSTEM_NAMES
    if item.name in taken:
        raise InvalidInputError(f"name: {item.name!r} is taken in this scene; give the {what} another name")
