"""The scene file: the layout :meth:`Scene.save` writes and the hostile-file reader behind
:meth:`Scene.load`.

A scene file is a zip archive of uncompressed ``.npy`` members, as ``numpy.savez`` writes it:
``meta`` (a JSON string: parameters, terms, colliders, counters), ``time_hex`` (the time as
``float.hex``), ``positions``, ``velocities``, ``masses``, ``pinned``, the per-term arrays
``term{k}_*``, ``ledger`` (energy dissipated per term, J) and, for the integrators that keep one,
``cache_forces`` and ``cache_power`` (the forces carried to the next step and the term powers
there, then any controller memory; for ``wisdom_holman`` with a corrector, the corrected state
the next call goes on from: 2N rows, positions then velocities, and its dt last). A scene saved on a GPU names its device in ``meta``
(``device``; absent means the CPU) and holds the device's rows, read back as float64:
``device_pos``, ``device_vel``, ``device_acc``, ``device_aux`` (N × 4) and ``device_hits`` (N);
its ledger is read from the device's books, and it has no integrator cache (``Scene.load``).

The reader treats every file as hostile:

* nothing in it is executed: object arrays are refused from their header, before any data;
* nothing is allocated from a size the file claims before the claim is checked against the bytes
  the file holds: members must be stored (not compressed, so no zip bombs), each ``.npy``
  header's shape times item size must equal its member's size, the members must fit in the
  archive, and the zip central directory and ``meta`` have fixed caps. Array data read is
  therefore at most the file's size;
* every field is checked for type and range (numbers finite, counters integers in range, no bool
  for an int, no unknown keys or members), and what reaches the Scene API is validated there
  again.

Every failure is one :class:`~physcore.SceneFileError` naming the file and the field.
"""
from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import struct
import warnings
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from . import _check, _core
from ._errors import InvalidInputError, InvalidTypeError, SceneFileError
from ._parts import PART_ALIASES, section_kinds

__all__ = ["FORMAT_VERSION", "check_path", "read", "SceneFile"]

FORMAT_VERSION = 1
#: Bytes of zip central directory accepted (room for ~50 000 members; zipfile keeps a Python
#: object of a few hundred bytes per 46-byte entry, so this caps that cost too).
MAX_CENTRAL_DIRECTORY = 4 << 20
#: Characters of ``meta`` JSON accepted (4 bytes each in the file; ~10 000 terms or colliders).
MAX_META_CHARS = 1 << 22
MAX_TIME_HEX_CHARS = 64
#: numpy's own default cap on a ``.npy`` header, bytes.
MAX_NPY_HEADER = 10_000
#: ``step`` is a u64 in the core; files keep it below 2**63 so it survives any int64 consumer.
STEP_LIMIT = 2**63
_CHUNK = 1 << 20

def _term_types() -> dict[str, Any]:
    """Every registered term type by its key (the parts of the ``"terms"`` section in
    :data:`physcore._parts.PARTS`): each describes its own record (``record_fields``,
    ``record_arrays``; see :class:`physcore.terms.Term`). The part modules register themselves
    when imported, which ``physcore.scene`` (this module's only user) does."""
    return section_kinds("terms")


def _flow_kinds() -> dict[str, dict[str, Any]]:
    """Every flow kind and its spec (dimension, parameters): the flow part's catalog."""
    (flow,) = section_kinds("flows").values()
    return flow.catalog  # type: ignore[attr-defined,no-any-return]


# Fields of each collider, by kind of value (see _Reader.value).
COLLIDER_FIELDS: dict[str, dict[str, str]] = {
    "planes": {"point": "vector", "normal": "vector", "restitution": "number", "friction": "number"},
    "boxes": {"lower": "vector", "upper": "vector", "restitution": "number", "friction": "number"},
    "spheres": {"center": "vector", "radius": "number", "restitution": "number", "friction": "number", "inside": "bool"},
}
_META_FIELDS: dict[str, str] = {
    "format": "int",
    "dim": "int",
    "integrator": "str",
    "dt": "number",
    "threads": "threads",
    "time": "time",
    "step": "step",
    "collisions": "number",
    "e0": "optional_number",
    "e0_scale": "nonnegative",
    "terms": "list",
    "planes": "list",
}
# Absent from files of earlier versions; these are the values those versions used.
_META_DEFAULTS: dict[str, Any] = {
    "rtol": 1e-6, "atol": 1e-9, "cg_tol": 1e-8, "cg_max_iter": 200, "precision": "f64", "boxes": [], "grids": [], "flows": [],
    "spheres": [],
}
_META_OPTIONAL: dict[str, str] = {
    "rtol": "number", "atol": "number", "cg_tol": "number", "cg_max_iter": "int", "precision": "str", "boxes": "list",
    "grids": "list", "flows": "list", "spheres": "list",
}
# The "xpbd" integrator's options (absent from files written before it).
_META_DEFAULTS.update({"xpbd_substeps": 10, "xpbd_iterations": 1})
# The keyed colliders' section (physcore._parts.OPTIONAL_SECTIONS): written only when it holds one.
_META_DEFAULTS["colliders"] = []
_META_OPTIONAL["colliders"] = "list"
# The rigid bodies' section (physcore.bodies): groups and joints, written only when it holds one.
_META_DEFAULTS["bodies"] = []
_META_OPTIONAL["bodies"] = "list"
_META_OPTIONAL.update({"xpbd_substeps": "int", "xpbd_iterations": "int"})
# Where a scene stepped (absent: the CPU), and for a scene saved on a GPU whether the device's
# accelerations were current; its raw rows are the members device_* (_expected_members).
_META_DEFAULTS.update({"device": "cpu", "device_acc_valid": False})
_META_OPTIONAL.update({"device": "str", "device_acc_valid": "bool"})
# The "wisdom_holman" coordinates, written where they matter (a wisdom_holman scene, or one set
# off the default; `Scene.save`), so that other scenes' files keep their bytes. Without the
# key a wisdom_holman file was written before the option and stepped the democratic
# heliocentric split, and goes on with it; any other file takes the default, Jacobi (`read`).
_META_OPTIONAL["wh_coordinates"] = "str"
WH_DEFAULT = "jacobi"
# The order of the "wisdom_holman" corrector, written only when one is set (other files keep
# their bytes); absent, none (0).
_META_OPTIONAL["wh_corrector"] = "int"
_META_DEFAULTS["wh_corrector"] = 0
#: A grid's state members by kind (the record fixes their sizes): name -> (dtype, size axis), the
#: axis "G" being the grid's cell count.
_GRID_STATE: dict[str, dict[str, tuple[str, Any]]] = {
    "wave": {"u": ("f8", "G"), "u_prev": ("f8", "G"), "clock": ("f8", 5)},
    "gray_scott": {"u": ("f8", "G"), "v": ("f8", "G"), "made": ("f8", 2)},
    # The fluid's arrays carry ghost faces; their sizes follow from the record (_fluid_sizes).
    "stable_fluid": {k: ("f8", None) for k in ("u", "v", "density", "temperature", "pressure", "tracers", "steps", "books")},
}
#: State members absent from files written before them (the core takes their earlier value):
#: the wave's book of its changes of dt.
_GRID_STATE_OPTIONAL: dict[str, dict[str, tuple[str, Any]]] = {"wave": {"dt_changes": ("f8", 1)}}
#: Each grid kind's record (what ``Grid._record`` writes): key -> kind of value. The kinds beyond
#: :meth:`_Reader.value`'s are checked by :func:`_grid_record`. ``_GRID_RECORD_OPTIONAL`` keys may
#: be absent (files written before them).
_GRID_RECORD: dict[str, dict[str, str]] = {
    "wave": {
        "shape": "cells", "dx": "number", "edges": "strs", "c": "number", "gamma": "number", "absorbing": "strs",
        "layer": "int", "layer_strength": "number", "cfl": "number", "mask": "bool", "drops": "drops",
        "oscillators": "oscillators",
    },
    "gray_scott": {
        "shape": "cells", "dx": "number", "edges": "strs", "du": "number", "dv": "number", "feed": "number",
        "kill": "number", "cfl": "number",
    },
    "stable_fluid": {
        "shape": "cells", "dx": "number", "viscosity": "number", "buoyancy": "pair", "ambient_temperature": "number",
        "vorticity": "number", "advection": "str", "tolerance": "number", "max_iterations": "int", "walls": "str",
        "lid": "optional_number", "mask": "bool", "tracers": "int", "cfl": "number", "sources": "sources",
    },
}
_GRID_RECORD_OPTIONAL: dict[str, dict[str, str]] = {"stable_fluid": {"inflow": "optional_number", "projection": "str"}}
#: Entries of a grid's lists of sources, by position: kind of value (see _grid_record).
_GRID_ENTRIES: dict[str, tuple[tuple[str, str], ...]] = {
    "drops": (("t", "number"), ("center", "vector"), ("radius", "number"), ("amplitude", "number")),
    "oscillators": (("amplitude", "number"), ("frequency", "number"), ("center", "optional_vector"), ("radius", "number"), ("phase", "number")),
    "sources": (("density", "number"), ("temperature", "number"), ("velocity", "vector"), ("center", "optional_vector"), ("radius", "number")),
}
#: Bytes the core holds per cell of each grid kind (its fields and scratch, float64): a generous
#: estimate (not a measurement) for the memory check before a file's grid is built.
_GRID_BYTES_PER_CELL = {"wave": 8 * 8, "gray_scott": 8 * 8, "stable_fluid": 8 * 32}


def check_path(path: object, arg: str = "path") -> Path:
    """``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    TypeError
        ``path`` is not a str or an ``os.PathLike`` giving a str.
    ValueError
        It contains a NUL character.
    """
    p = os.fspath(path) if isinstance(path, os.PathLike) else path
    if not isinstance(p, str):
        raise InvalidTypeError(f"{arg}: expected a file name (str or os.PathLike), got {type(path).__name__}")
    if "\0" in p:
        raise InvalidInputError(f"{arg}: contains a NUL character")
    return Path(p)


def _show(value: object) -> str:
    """A short repr for messages (a hostile file may hold megabyte strings)."""
    r = repr(value) if not isinstance(value, int) or abs(value) < 10**40 else f"an integer of {len(str(abs(value)))} digits"
    return r if len(r) <= 80 else r[:77] + "..."


def _kind(value: object) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a bool", type(None): "null"}.get(type(value), type(value).__name__)


class _DuplicateKey(ValueError):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


class _Reader:
    """Error construction and typed field checks for one file."""

    def __init__(self, name: str) -> None:
        self.name = name

    def error(self, field: str, problem: str) -> SceneFileError:
        return SceneFileError(self.name, field, problem)

    @contextmanager
    def api(self, context: str, members: Mapping[str, str] | None = None) -> Iterator[None]:
        """Turns the Scene API's TypeError/ValueError (whose message starts with the argument's
        name) into a SceneFileError naming the field: ``members`` maps argument names to the file
        members they came from; others become ``context.argument``."""
        try:
            yield
        except SceneFileError:
            raise
        except (TypeError, ValueError, OverflowError) as exc:
            msg = str(exc)
            m = re.match(r"([A-Za-z_][\w/]*): (.*)", msg, re.S)
            if m:
                arg, problem = m.groups()
                field = (members or {}).get(arg) or (f"{context}.{arg}" if context else arg)
            else:
                field, problem = context, msg
            raise self.error(field, problem) from exc

    # ------------------------------------------------------------ JSON values
    def number(self, field: str, v: object) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(field, f"must be a finite number, got {_kind(v)} {_show(v)}")
        try:
            x = float(v)
        except OverflowError:
            raise self.error(field, f"must be a finite number, got {_show(v)}") from None
        if not math.isfinite(x):
            raise self.error(field, f"must be a finite number, got {x}")
        return x

    def integer(self, field: str, v: object, lo: int, hi: int, hi_text: str = "") -> int:
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v < hi:
            raise self.error(field, f"must be an integer in [{lo}, {hi_text or hi}), got {_kind(v)} {_show(v)}")
        return v

    def value(self, field: str, kind: str, v: object, dim: int = 0) -> Any:
        if kind == "number":
            return self.number(field, v)
        if kind == "nonnegative":
            x = self.number(field, v)
            if x < 0:
                raise self.error(field, f"must be >= 0, got {x}")
            return x
        if kind == "optional_number":
            return None if v is None else self.number(field, v)
        if kind == "time":
            x = self.number(field, v)
            if x < 0:
                raise self.error(field, f"must be >= 0 (s), got {x}")
            return x
        if kind == "step":
            return self.integer(field, v, 0, STEP_LIMIT, "2**63")
        if kind == "count":
            return self.integer(field, v, 0, STEP_LIMIT, "2**63")
        if kind == "int":
            if isinstance(v, bool) or not isinstance(v, int):
                raise self.error(field, f"must be an integer, got {_kind(v)} {_show(v)}")
            return v
        if kind == "threads":
            if v is None:
                return None
            return self.integer(field, v, 1, STEP_LIMIT, "2**63")
        if kind == "str":
            if not isinstance(v, str):
                raise self.error(field, f"must be a string, got {_kind(v)} {_show(v)}")
            return v
        if kind == "bool":
            if not isinstance(v, bool):
                raise self.error(field, f"must be true or false, got {_kind(v)} {_show(v)}")
            return v
        if kind == "list":
            if not isinstance(v, list):
                raise self.error(field, f"must be a list, got {_kind(v)}")
            return v
        if kind == "object":
            if not isinstance(v, dict):
                raise self.error(field, f"must be an object, got {_kind(v)}")
            return v
        if kind == "vector":
            if not isinstance(v, list) or len(v) != dim:
                raise self.error(field, f"must be a list of {dim} numbers (the scene is {dim}D), got {_kind(v)} {_show(v)}")
            return [self.number(f"{field}[{i}]", x) for i, x in enumerate(v)]
        if kind == "axial":  # a pseudo-vector (magnetic field): B_z in 2D, 3 components in 3D
            n = 1 if dim == 2 else 3
            if not isinstance(v, list) or len(v) != n:
                raise self.error(field, f"must be a list of {n} numbers (the scene is {dim}D), got {_kind(v)} {_show(v)}")
            return [self.number(f"{field}[{i}]", x) for i, x in enumerate(v)]
        raise AssertionError(kind)  # pragma: no cover - a kind name missing above

    def record(self, field: str, v: object, fields: Mapping[str, str], dim: int, required: tuple[str, ...] = ()) -> dict[str, Any]:
        """A JSON object with exactly the keys ``fields`` (plus ``required``, checked by the
        caller), each converted by its kind."""
        if not isinstance(v, dict):
            raise self.error(field, f"must be an object, got {_kind(v)}")
        allowed = set(fields) | set(required)
        for k in v:
            if k not in allowed:
                raise self.error(field, f"unknown key {_show(k)} (expected {', '.join(sorted(allowed))})")
        for k in (*required, *fields):
            if k not in v:
                raise self.error(f"{field}.{k}", "missing")
        out = {k: v[k] for k in required}
        out.update({k: self.value(f"{field}.{k}", kind, v[k], dim) for k, kind in fields.items()})
        return out


# ---------------------------------------------------------------------------------- the meta
def _parse_meta(r: _Reader, text: str) -> dict[str, Any]:
    try:
        raw = json.loads(text, object_pairs_hook=_no_duplicates)
    except _DuplicateKey as exc:
        raise r.error("meta", f"duplicate key {_show(str(exc))}") from None
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, int digit limit, deep nesting
        raise r.error("meta", f"not valid JSON ({type(exc).__name__}: {_show(str(exc))})") from None
    if not isinstance(raw, dict):
        raise r.error("meta", f"must be a JSON object, got {_kind(raw)}")
    # The version first, so a newer file says so instead of listing unknown keys.
    if "format" not in raw:
        raise r.error("meta.format", "missing")
    fmt = raw["format"]
    if isinstance(fmt, bool) or not isinstance(fmt, int) or fmt != FORMAT_VERSION:
        raise r.error("meta.format", f"unsupported scene format {_show(fmt)} (this physcore reads format {FORMAT_VERSION})")
    dim = raw.get("dim")
    if isinstance(dim, bool) or not isinstance(dim, int) or dim not in (2, 3):
        raise r.error("meta.dim", f"must be 2 or 3, got {_kind(dim)} {_show(dim)}")
    fields = {**_META_FIELDS, **{k: kind for k, kind in _META_OPTIONAL.items() if k in raw}}
    meta = r.record("meta", raw, fields, dim)
    for k, default in _META_DEFAULTS.items():
        meta.setdefault(k, default)
    meta.setdefault("wh_coordinates", "democratic_heliocentric" if meta.get("integrator") == "wisdom_holman" else WH_DEFAULT)

    terms = []
    names = {"collisions"}  # reserved: the colliders' entry in the energy books
    for k, t in enumerate(meta["terms"]):
        field = f"meta.terms[{k}]"
        if not isinstance(t, dict):
            raise r.error(field, f"must be an object, got {_kind(t)}")
        kind = t.get("type")
        types = _term_types()
        if not isinstance(kind, str) or kind not in types:
            raise r.error(f"{field}.type", f"unknown term type {_show(kind)} (expected one of {', '.join(types)})")
        cls = types[kind]
        fields = {**cls.record_fields, **{f: fk for f, fk in cls.record_fields_optional.items() if f in t}}
        rec = r.record(field, t, fields, dim, required=("type", "name"))
        name = rec.get("name")
        if not isinstance(name, str) or not name:
            raise r.error(f"{field}.name", f"must be a non-empty string, got {_kind(name)} {_show(name)}")
        if name in names:
            raise r.error(f"{field}.name", f"{_show(name)} is taken (by an earlier term, or reserved)")
        names.add(name)
        terms.append(rec)
    meta["terms"] = terms
    for group, spec in COLLIDER_FIELDS.items():
        meta[group] = [r.record(f"meta.{group}[{i}]", c, spec, dim) for i, c in enumerate(meta[group])]
    keyed = section_kinds("colliders")
    colliders = []
    for k, c in enumerate(meta["colliders"]):
        field = f"meta.colliders[{k}]"
        if not isinstance(c, dict):
            raise r.error(field, f"must be an object, got {_kind(c)}")
        kind = c.get("type")
        if not isinstance(kind, str) or kind not in keyed:
            raise r.error(f"{field}.type", f"unknown collider type {_show(kind)} (expected one of {', '.join(keyed)})")
        colliders.append(r.record(field, c, {"type": "str", **keyed[kind].record_fields}, dim))
    meta["colliders"] = colliders
    bodies = []
    for k, b in enumerate(meta["bodies"]):
        field = f"meta.bodies[{k}]"
        if not isinstance(b, dict):
            raise r.error(field, f"must be an object, got {_kind(b)}")
        if b.get("part") not in ("group", "joints", "pins"):
            raise r.error(f"{field}.part", f"must be \"group\", \"joints\" or \"pins\", got {_show(b.get('part'))}")
        fields = {"part": "str", "record": "object", **({"name": "str"} if b["part"] == "group" else {})}
        rec = r.record(field, b, fields, dim)
        count = "n" if b["part"] == "group" else "m"
        v = rec["record"].get(count)
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 1 << 24:
            raise r.error(f"{field}.record.{count}", f"must be a count in 1..{1 << 24}, got {_show(v)}")
        shapes = ("ball", "box", "capsule", "polygon", "polyline") if dim == 2 else ("ball", "box", "capsule", "hull", "mesh")
        if b["part"] == "group" and rec["record"].get("shape") not in shapes:
            raise r.error(f"{field}.record.shape", f"must be one of {', '.join(shapes)} in {dim}D, got {_show(rec['record'].get('shape'))}")
        bodies.append(rec)
    meta["bodies"] = bodies
    grids = []
    for k, g in enumerate(meta["grids"]):
        field = f"meta.grids[{k}]"
        rec = r.record(field, g, {"kind": "str", "name": "str", "record": "object"}, dim)
        rec["kind"] = PART_ALIASES.get(f"grids/{rec['kind']}", f"grids/{rec['kind']}")[len("grids/"):]  # "fluid": the old name
        if rec["kind"] not in _GRID_STATE:
            raise r.error(f"{field}.kind", f"unknown grid kind {_show(rec['kind'])} (expected one of {', '.join(_GRID_STATE)})")
        if not rec["name"] or rec["name"] in names:
            raise r.error(f"{field}.name", f"{_show(rec['name'])} is empty or taken")
        names.add(rec["name"])
        rec["record"] = _grid_record(r, f"{field}.record", rec["kind"], rec["record"], dim)
        grids.append(rec)
    meta["grids"] = grids
    FLOWS = _flow_kinds()
    flows = []
    for k, f in enumerate(meta["flows"]):
        field = f"meta.flows[{k}]"
        rec = r.record(field, f, {"name": "str", "record": "object"}, dim)
        if not rec["name"] or rec["name"] in names:
            raise r.error(f"{field}.name", f"{_show(rec['name'])} is empty or taken")
        names.add(rec["name"])
        fr = r.record(f"{field}.record", rec["record"], {"kind": "str", "params": "object", "method": "str", "max_dt": "number", "n": "int"}, dim)
        kind, n = fr["kind"], fr["n"]
        if kind not in FLOWS or FLOWS[kind]["dim"] != dim:
            flows_here = ", ".join(name for name, spec in FLOWS.items() if spec["dim"] == dim)
            raise r.error(f"{field}.record.kind", f"must name a {dim}D flow ({flows_here}), got {_show(kind)}")
        if not 1 <= n <= 1 << 27:
            raise r.error(f"{field}.record.n", f"must be a point count in 1..{1 << 27}, got {_show(n)}")
        for p, v in fr["params"].items():
            r.number(f"{field}.record.params.{p}", v)
        rec["record"] = fr
        flows.append(rec)
    meta["flows"] = flows
    return meta


def _grid_record(r: _Reader, field: str, kind: str, v: object, dim: int) -> dict[str, Any]:
    """A grid's record, every key present and of its type (lists of sources entry by entry), its
    shape in range and within the memory limit; the values are checked again by the grid's
    constructor."""
    optional = _GRID_RECORD_OPTIONAL.get(kind, {})
    fields = {**_GRID_RECORD[kind], **({k: t for k, t in optional.items() if k in v} if isinstance(v, dict) else {})}
    plain = {k: t for k, t in fields.items() if t in ("number", "int", "str", "bool", "optional_number")}
    rec = r.record(field, v, plain, dim, required=tuple(k for k in fields if k not in plain))
    shape = rec["shape"]
    if not (isinstance(shape, list) and len(shape) == dim and all(isinstance(n, int) and not isinstance(n, bool) and 3 <= n <= 1 << 20 for n in shape)):
        raise r.error(f"{field}.shape", f"must be {dim} cell counts in 3..{1 << 20}, got {_show(shape)}")
    cells = math.prod(shape)
    if cells > 1 << 31:
        raise r.error(f"{field}.shape", f"{_show(shape)} has more than 2**31 cells")
    try:
        _check.memory("shape", cells * _GRID_BYTES_PER_CELL[kind], f"a {kind} grid of {_show(shape)} cells")
    except InvalidInputError as exc:
        raise r.error(f"{field}.shape", str(exc)[len("shape: "):]) from None
    if kind == "stable_fluid":
        if dim != 2:
            raise r.error(f"{field}.shape", f"the grid fluid is 2D, got {_show(shape)}")
        r.integer(f"{field}.tracers", rec["tracers"], 0, (1 << 24) + 1, "2**24 + 1")  # it sizes the tracers member
    for k, t in fields.items():
        if k in plain or k == "shape":
            continue
        x, at = rec[k], f"{field}.{k}"
        if t == "strs":
            if not isinstance(x, list) or not all(isinstance(e, str) for e in x):
                raise r.error(at, f"must be a list of strings, got {_kind(x)} {_show(x)}")
        elif t == "pair":
            if not isinstance(x, list) or len(x) != 2:
                raise r.error(at, f"must be a list of 2 numbers, got {_kind(x)} {_show(x)}")
            rec[k] = [r.number(f"{at}[{i}]", e) for i, e in enumerate(x)]
        else:  # a list of sources: each a list of values by position (_GRID_ENTRIES)
            entries = _GRID_ENTRIES[t]
            if not isinstance(x, list):
                raise r.error(at, f"must be a list, got {_kind(x)} {_show(x)}")
            for j, e in enumerate(x):
                if not isinstance(e, list) or len(e) != len(entries):
                    names = ", ".join(n for n, _ in entries)
                    raise r.error(f"{at}[{j}]", f"must be a list of {len(entries)} values ({names}), got {_kind(e)} {_show(e)}")
                for i, (name, ek) in enumerate(entries):
                    n_vec = 2 if t == "sources" else dim  # a fluid's vectors are 2D
                    if ek == "optional_vector":
                        if e[i] is not None:
                            r.value(f"{at}[{j}].{name}", "vector", e[i], n_vec)
                    else:
                        r.value(f"{at}[{j}].{name}", ek, e[i], n_vec)
    return rec


# ---------------------------------------------------------------------------------- the archive
def _open_regular(path: Path, name: str) -> tuple[IO[bytes], int]:
    """Opens ``path`` for reading without blocking (a FIFO would wait for a writer forever) and
    refuses anything but a regular file (a device could be endless)."""
    flags = os.O_RDONLY | getattr(os, "O_BINARY", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise SceneFileError(name, "", "not a regular file (a directory, pipe or device); give a .npz written by Scene.save")
        return os.fdopen(fd, "rb"), st.st_size
    except BaseException:
        os.close(fd)
        raise


def _central_directory_size(fh: IO[bytes], size: int) -> int | None:
    """The central directory size the zip's end records declare, located as zipfile locates
    them (end record last, or in the last 64 KiB; a Zip64 record just before it overrides);
    None if there is no end record (zipfile then reports the file is not a zip)."""
    start = max(size - (1 << 16) - 22, 0)
    fh.seek(start)
    tail = fh.read()
    if tail[-22:-18] == b"PK\x05\x06" and tail[-2:] == b"\0\0":
        pos = len(tail) - 22
    else:
        pos = tail.rfind(b"PK\x05\x06")
        if pos < 0 or len(tail) - pos < 22:
            return None
    cd_size = struct.unpack_from("<L", tail, pos + 12)[0]
    locator = start + pos - 20
    if locator >= 56:
        fh.seek(locator)
        if fh.read(4) == b"PK\x06\x07":
            fh.seek(locator - 56)
            rec = fh.read(56)
            if rec[:4] == b"PK\x06\x06":
                cd_size = struct.unpack_from("<Q", rec, 40)[0]
    return cd_size


@dataclass
class _Spec:
    """An expected member: dtype (kind + item size, or "U" for a string) and shape, one name per
    axis; a name bound to a size (by the meta, or by the first member read with it) must match."""

    dtype: str
    shape: tuple[str, ...]
    max_chars: int = 0


def _read_member(
    r: _Reader, zf: zipfile.ZipFile, info: zipfile.ZipInfo, field: str, spec: _Spec, sizes: dict[str, tuple[int, str]]
) -> np.ndarray:
    try:
        fh = zf.open(info)
    except Exception as exc:  # noqa: BLE001 - damaged local header: zipfile raises several kinds
        raise r.error(field, f"unreadable zip member ({type(exc).__name__}: {_show(str(exc))})") from None
    with fh:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # numpy warns (and goes on) on Python-2 headers
                version = np.lib.format.read_magic(fh)
                if version == (1, 0):
                    shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=MAX_NPY_HEADER)
                elif version == (2, 0):
                    shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=MAX_NPY_HEADER)
                else:
                    raise ValueError(f"unsupported .npy version {version}")
            header = fh.tell()
        except Exception as exc:  # noqa: BLE001 - numpy's header parser raises several kinds
            raise r.error(field, f"not a valid .npy header ({type(exc).__name__}: {_show(str(exc))})") from None
        if dtype.hasobject or dtype.names is not None or dtype.subdtype is not None:
            raise r.error(field, f"dtype {dtype.descr if dtype.names else dtype.str} is refused (object or structured arrays are never read)")
        code = "U" if dtype.kind == "U" else f"{dtype.kind}{dtype.itemsize}"
        if code != spec.dtype:
            want = {"U": "a string", "b1": "bool"}.get(spec.dtype, f"{np.dtype(spec.dtype).name}")
            raise r.error(field, f"expected {want}, got dtype {dtype.str}")
        if spec.max_chars and dtype.itemsize > 4 * spec.max_chars:
            raise r.error(field, f"{dtype.itemsize // 4} characters is over the limit of {spec.max_chars}")
        if fortran:
            raise r.error(field, "Fortran-ordered arrays are not written by Scene.save")
        if len(shape) != len(spec.shape) or not all(type(n) is int and n >= 0 for n in shape):
            want = "(" + ", ".join(str(p) for p in spec.shape) + ("," if len(spec.shape) == 1 else "") + ")"
            raise r.error(field, f"expected shape {want}, got {_show(shape)}")
        for axis, (n, p) in enumerate(zip(shape, spec.shape, strict=False)):
            if p in sizes and n != sizes[p][0]:
                what = ("rows", "columns")[axis] if len(shape) == 2 else "entries"
                want, origin = sizes[p]
                raise r.error(field, f"has {n} {what} where {origin} {'is' if origin.startswith('meta') else 'has'} {want}")
        count = math.prod(shape)
        nbytes = count * dtype.itemsize
        # The claim is checked against the member's real size before anything is allocated.
        if header + nbytes != info.file_size:
            raise r.error(field, f"the header claims shape {_show(shape)} ({nbytes} bytes) but the member holds {info.file_size - header}")
        for n, p in zip(shape, spec.shape, strict=False):
            sizes.setdefault(p, (n, field))
        out = np.empty(count, dtype=dtype)
        raw = out.view(np.uint8)
        try:
            done = 0
            while done < nbytes:
                chunk = fh.read(min(_CHUNK, nbytes - done))
                if not chunk:
                    raise EOFError("the data ends early")
                raw[done : done + len(chunk)] = np.frombuffer(chunk, np.uint8)
                done += len(chunk)
            if fh.read(1):  # also makes zipfile check the CRC
                raise ValueError("data past the array's end")
        except MemoryError:
            raise  # the process's memory, not the file's damage: OutOfMemoryError from the caller
        except Exception as exc:  # noqa: BLE001 - BadZipFile (CRC), OSError, EOFError
            raise r.error(field, f"damaged data ({type(exc).__name__}: {_show(str(exc))})") from None
    out = out.reshape(shape)
    if not out.dtype.isnative:
        out = out.astype(out.dtype.newbyteorder("="))
    if dtype.kind == "b" and raw.size and raw.max() > 1:
        raise r.error(field, f"entry {int(np.argmax(raw > 1))} is not a bool (byte {int(raw.max())})")  # Rust reads bool bytes
    if dtype.kind == "f":
        bad = ~np.isfinite(out)
        if bad.any():
            at = np.unravel_index(int(np.argmax(bad)), out.shape)
            at_s = str(int(at[0])) if len(at) == 1 else str(tuple(int(i) for i in at))
            raise r.error(field, f"entry {at_s} is {out[at]} (must be finite)")
    return out


def _read_text(r: _Reader, zf: zipfile.ZipFile, infos: dict[str, zipfile.ZipInfo], field: str, max_chars: int) -> str:
    if field not in infos:
        raise r.error(field, "missing member (not a scene file written by Scene.save?)")
    a = _read_member(r, zf, infos[field], field, _Spec("U", (), max_chars), {})
    codes = a.reshape(-1).view(np.uint32)
    if codes.size and (codes.max() > 0x10FFFF or np.any((codes >= 0xD800) & (codes < 0xE000))):
        raise r.error(field, "holds invalid Unicode code points")
    return str(a[()])


def _expected_members(meta: dict[str, Any]) -> tuple[dict[str, _Spec], dict[str, _Spec], dict[str, tuple[int, str]]]:
    """(required, optional) members of a file with this meta, in reading order, and the sizes
    the meta fixes (axis name -> (size, field))."""
    d = "D"
    sizes = {"D": (meta["dim"], "meta.dim"), "T": (len(meta["terms"]), "the number of meta.terms"),
             "Q4": (4, "a quaternion"), "A3": (3, "a 3D angular velocity (or a triangle)"), "L2": (2, "a range (lower, upper)")}
    fx = "f4" if meta["precision"] == "f32" else "f8"  # positions/velocities as the scene holds them
    req = {
        "positions": _Spec(fx, ("N", d)),
        "velocities": _Spec(fx, ("N", d)),
        "masses": _Spec("f8", ("N",)),
        "pinned": _Spec("b1", ("N",)),
        "ledger": _Spec("f8", ("T",)),
    }
    opt: dict[str, _Spec] = {}
    types = _term_types()
    for k, t in enumerate(meta["terms"]):
        cls = types[t["type"]]
        for optional, arrays in ((False, cls.record_arrays), (True, cls.record_optional)):
            for f, (dtype, axes) in arrays.items():
                named = []
                for a in axes:
                    if a == "D":
                        named.append(d)
                        continue
                    if a in cls.record_fields:  # sized by the record: e.g. a fluid's count
                        sizes[f"{a}{k}"] = (t[a], f"meta.terms[{k}].{a}")
                    named.append(f"{a}{k}")
                (opt if optional else req)[f"term{k}_{f}"] = _Spec(dtype, tuple(named))
    for k, g in enumerate(meta["grids"]):
        cells = f"G{k}"
        sizes[cells] = (math.prod(g["record"]["shape"]), f"meta.grids[{k}].record.shape")
        if g["kind"] == "stable_fluid":
            rec = g["record"]
            for name, n in _fluid_sizes(rec).items():
                origin = (f"meta.grids[{k}].record.tracers (x and y of {rec['tracers']} tracers)" if name == "tracers"
                          else f"meta.grids[{k}].record.shape ({name} of a {rec['shape'][0]} x {rec['shape'][1]} fluid)")
                sizes[f"{name}{k}"] = (n, origin)
        for name, (dtype, axis) in _GRID_STATE[g["kind"]].items():
            if axis not in ("G", None):
                sizes[f"{name}{k}"] = (axis, f"a {g['kind']} grid's {name}")
            req[f"grid{k}_{name}"] = _Spec(dtype, (cells if axis == "G" else f"{name}{k}",))
        for name, (dtype, n) in _GRID_STATE_OPTIONAL.get(g["kind"], {}).items():
            sizes[f"{name}{k}"] = (n, f"a {g['kind']} grid's {name}")
            opt[f"grid{k}_{name}"] = _Spec(dtype, (f"{name}{k}",))
        if g["record"].get("mask"):
            req[f"grid{k}_mask"] = _Spec("b1", (cells,))
        for j, o in enumerate(g["record"].get("oscillators", [])):
            if isinstance(o, list) and len(o) > 2 and o[2] is None:
                req[f"grid{k}_region{j}"] = _Spec("b1", (cells,))
        for j, src in enumerate(g["record"].get("sources", [])):
            if isinstance(src, list) and len(src) > 3 and src[3] is None:
                req[f"grid{k}_region{j}"] = _Spec("b1", (cells,))
    for k, f in enumerate(meta["flows"]):
        sizes[f"F{k}"] = (f["record"]["n"] * meta["dim"], f"meta.flows[{k}].record.n")
        req[f"flow{k}_y"] = _Spec("f8", (f"F{k}",))
    for k, b in enumerate(meta.get("bodies", ())):
        rec, field = b["record"], f"meta.bodies[{k}].record"
        if b["part"] == "group":
            n, w = rec["n"], {"ball": 1, "box": meta["dim"], "capsule": 2, "polygon": 0, "polyline": 0, "hull": 0, "mesh": 0}[rec["shape"]]
            sizes[f"B{k}"] = (n, f"{field}.n")
            sizes[f"BS{k}"] = (n * w, f"{field}.n (and its shape)")
            turn = (("angles", (f"B{k}",)), ("angular_velocities", (f"B{k}",))) if meta["dim"] == 2 else (
                ("orientations", (f"B{k}", "Q4")), ("angular_velocities", (f"B{k}", "A3")))
            for name, axes in (("positions", (f"B{k}", d)), ("velocities", (f"B{k}", d)), ("size", (f"BS{k}",)), *turn):
                req[f"body{k}_{name}"] = _Spec("f8", axes)
            opt[f"body{k}_vertices"] = _Spec("f8", (f"BV{k}", d))
            opt[f"body{k}_triangles"] = _Spec("f8", (f"BT{k}", "A3"))
            opt[f"body{k}_state"] = _Spec("f8", (f"BX{k}",))
            opt[f"body{k}_state_bytes"] = _Spec("f8", (f"BY{k}",))
        elif b["part"] == "pins":
            sizes[f"P{k}"] = (rec["m"], f"{field}.m")
            for name, axes in (("particles", (f"P{k}",)), ("body", (f"P{k}",)), ("points", (f"P{k}", d))):
                req[f"body{k}_{name}"] = _Spec("f8", axes)
        else:
            sizes[f"J{k}"] = (rec["m"], f"{field}.m")
            for name, axes in (("a", (f"J{k}",)), ("b", (f"J{k}",)), ("anchor", (f"J{k}", d))):
                req[f"body{k}_{name}"] = _Spec("f8", axes)
            for name, axes in (("anchor_b", (f"J{k}", d)), ("axis", (f"J{k}", d)), ("limits", (f"J{k}", "L2")), ("length", (f"J{k}",))):
                opt[f"body{k}_{name}"] = _Spec("f8", axes)
    opt.update({"cache_forces": _Spec("f8", ("C", d)), "cache_power": _Spec("f8", ("K",))})
    # Optional per-particle attributes (charge, radius): one value per particle when set.
    opt.update({f"attr_{a}": _Spec("f8", ("N",)) for a, _ in _core.particle_attributes()})
    if meta["device"] != "cpu":
        # A scene saved on a GPU: the device's raw rows (position and mass, velocity and
        # 1/mass, acceleration, drag books; "collisions" per particle), read back as float64.
        sizes["R4"] = (4, "a device row")
        opt.update({f"device_{k}": _Spec("f8", ("N", "R4")) for k in ("pos", "vel", "acc", "aux")})
        opt["device_hits"] = _Spec("f8", ("N",))
    return req, opt, sizes


def _fluid_sizes(record: dict[str, Any]) -> dict[str, int]:
    """Entries of a grid fluid's state members, fixed by its record: the MAC grid's face
    velocities and pressure carry a ring of ghost cells (``StableFluid`` in the core)."""
    nx, ny = record["shape"]
    return {
        "u": (nx + 1) * (ny + 2), "v": (nx + 2) * (ny + 1), "density": nx * ny, "temperature": nx * ny,
        "pressure": (nx + 2) * (ny + 2), "tracers": 2 * record["tracers"],
    }


@dataclass
class SceneFile:
    """What :func:`read` returns: the checked meta and arrays, and the reader (for errors)."""

    meta: dict[str, Any]
    arrays: dict[str, np.ndarray]
    time: float
    reader: _Reader


def read(path: Path) -> SceneFile:
    """Reads and checks a scene file (see the module docstring).

    Raises
    ------
    OSError
        The file cannot be opened (missing, no permission).
    SceneFileError
        Anything wrong with what is in it.
    """
    r = _Reader(str(path))
    fh, size = _open_regular(path, r.name)
    return _read_archive(r, fh, size)


def read_bytes(data: bytes, name: str = "<pickled Scene>") -> SceneFile:
    """:func:`read` of a scene file held in memory (a pickled :class:`~physcore.Scene`): the
    same checks, since pickles cross machines too."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise SceneFileError(name, "", f"expected the bytes of a scene file, got {type(data).__name__}")
    data = bytes(data)
    return _read_archive(_Reader(name), io.BytesIO(data), len(data))


def _read_archive(r: _Reader, fh: IO[bytes], size: int) -> SceneFile:
    with fh:
        cd = _central_directory_size(fh, size)
        if cd is not None and cd > MAX_CENTRAL_DIRECTORY:
            raise r.error("", f"zip central directory of {cd} bytes is over the limit of {MAX_CENTRAL_DIRECTORY} (a scene file has a few dozen members)")
        fh.seek(0)
        try:
            zf = zipfile.ZipFile(fh)
        except Exception as exc:  # noqa: BLE001 - zipfile raises many kinds on damaged archives
            raise r.error("", f"not a readable zip archive ({type(exc).__name__}: {_show(str(exc))}); give a .npz written by Scene.save") from None
        with zf:
            infos: dict[str, zipfile.ZipInfo] = {}
            total = 0
            for info in zf.infolist():
                stem = info.filename[:-4] if info.filename.endswith(".npy") else None
                if stem is None or not re.fullmatch(r"[a-z0-9_]+", stem):
                    raise r.error("", f"unexpected member {_show(info.filename)} (not a scene file written by Scene.save?)")
                if stem in infos:
                    raise r.error(stem, "appears twice in the archive")
                if info.flag_bits & 0x1:
                    raise r.error(stem, "is encrypted")
                if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size:
                    raise r.error(stem, "is compressed; Scene.save stores members uncompressed, and the loader reads no more than the file holds")
                total += info.compress_size
                infos[stem] = info
            if total > size:
                raise r.error("", f"members claim {total} bytes, more than the file's {size}")

            meta = _parse_meta(r, _read_text(r, zf, infos, "meta", MAX_META_CHARS))
            req, opt, sizes = _expected_members(meta)
            expected = {**req, "meta": None, "time_hex": None}
            for stem in infos:
                if stem not in expected and stem not in opt:
                    raise r.error(stem, "unexpected member for this meta (not written by Scene.save)")
            for stem in req:
                if stem not in infos:
                    raise r.error(stem, "missing member")
            rows = [f"device_{k}" for k in ("pos", "vel", "acc", "aux", "hits")]
            if any(k in infos for k in rows) and not all(k in infos for k in rows):
                raise r.error(next(k for k in rows if k not in infos), "missing member (the device's rows come as five)")
            if ("cache_forces" in infos) != ("cache_power" in infos):
                raise r.error("cache_forces" if "cache_forces" not in infos else "cache_power", "missing member (the integrator cache has two)")
            arrays = {}
            for stem, spec in {**req, **opt}.items():
                if stem in infos:
                    arrays[stem] = _read_member(r, zf, infos[stem], stem, spec, sizes)

            text = _read_text(r, zf, infos, "time_hex", MAX_TIME_HEX_CHARS)
            try:
                time = float.fromhex(text)
            except (ValueError, OverflowError):
                raise r.error("time_hex", f"not a hexadecimal float: {_show(text)}") from None
            if time != meta["time"]:  # both are written from the same float; NaN fails here too
                raise r.error("time_hex", f"{_show(text)} does not match meta.time = {meta['time']!r}")

    n = sizes["N"][0]
    # N rows (forces), or 2N (wisdom_holman's corrected state: positions, then velocities).
    if sizes.get("C", (0,))[0] not in (0, n, 2 * n):
        raise r.error("cache_forces", f"has {sizes['C'][0]} rows where positions has {n} (N or 2N expected)")
    if sizes.get("K", (0,))[0] > len(meta["terms"]) + 2:
        raise r.error("cache_power", f"has {sizes['K'][0]} entries, more than the integrators keep for {len(meta['terms'])} terms")
    taken: list[tuple[int, int, int]] = []
    types = _term_types()
    for k, t in enumerate(meta["terms"]):
        if types[t["type"]].owns_particles:
            if t["first"] + t["count"] > n:
                raise r.error(f"meta.terms[{k}].first", f"particles {t['first']}..{t['first'] + t['count']} are not all in the scene ({n})")
            taken.append((t["first"], t["first"] + t["count"], k))
    taken.sort()
    for (_, a1, ka), (b0, _, kb) in zip(taken, taken[1:], strict=False):
        if b0 < a1:
            raise r.error(f"meta.terms[{kb}].first", f"its particles overlap those of meta.terms[{ka}] (each fluid owns its own)")
    return SceneFile(meta, arrays, time, r)
