"""The :class:`Scene` builder: the one object a user scripts.

A scene validates every input once, in Python, before any state changes; the Rust core then owns
all state and steps ``n`` steps per call with the GIL released. Arrays cross in bulk.
"""
from __future__ import annotations

import contextlib
import contextvars
import copy
import dataclasses
import io
import json
import math
import os
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import _check, _core, _deprecate, _scenefile
from . import terms as _terms_pkg
from ._atomic import atomic_write, ctrl_c_held
from ._errors import (
    ContactStepWarning,
    InvalidInputError,
    InvalidTypeError,
    SceneBusyError,
    StabilityWarning,
    ThreadPoolWarning,
    UnchargedWarning,
    UnusedOptionWarning,
    allocating,
)
from ._integrators import (
    REGISTRY,
    XPBD,
    Dopri5,
    ImplicitEuler,
    Integrator,
    WisdomHolman,
    check_cg_max_iter,
    check_wh_coordinates,
    check_wh_corrector,
    check_xpbd_iterations,
    check_xpbd_substeps,
)
from ._parts import (
    COLLIDER_SECTIONS,
    MEMBER_PREFIX,
    OPTIONAL_SECTIONS,
    PARTS,
    SECTIONS,
    AttachContext,
    LoadContext,
    Part,
    entry_class,
    part_class,
)
from ._system import gpu_adapters, quiet_wayland_probe, usable_cpus

# The part modules register their classes in physcore._parts.PARTS when imported: the scene
# file reader finds every part kind there. (They import nothing from this module.)
from .contacts import Contacts
from .flows import Flow
from .fluids import Fluid
from .grids import Grid
from .potentials import PointMasses  # noqa: F401 - registers the potential terms
from .session import Session, books, drift, left_sum
from .terms import Box, Plane, Sphere, Springs, Term

__all__ = ["Scene", "EnergyReport", "INTEGRATORS"]

#: Old integrator names (still accepted this release, with a DeprecationWarning; scene files that
#: hold them load silently) -> the name now. ``"rk45"`` could be Fehlberg's pair; physcore's is
#: Dormand–Prince 5(4), and the flows call the same tableau ``"dopri5"`` (docs/naming.md).
INTEGRATOR_ALIASES: dict[str, str] = {"rk45": "dopri5"}

#: Integrator names accepted by ``Scene(integrator=...)``, with order, symplecticity and force
#: evaluations per step, as reported by the core (whose names are these: one vocabulary).
INTEGRATORS: tuple[dict[str, Any], ...] = tuple(_core.integrator_table())
_INTEGRATOR_NAMES = tuple(d["name"] for d in INTEGRATORS)
#: Largest ``threads`` accepted: rayon's own limit (it silently uses no more than this).
MAX_THREADS = 65535

#: The thread count of a Scene made with ``threads=None`` in the current context, where a caller
#: has set one (:func:`physcore.sweep` sets 1 inside each run so that parallel runs do not
#: oversubscribe the cores); unset: all cores (rayon's global pool, or ``RAYON_NUM_THREADS``).
#: ``Scene.threads`` still reports what the scene was given (None), and files save None.
DEFAULT_THREADS: contextvars.ContextVar[int | None] = contextvars.ContextVar("physcore_default_threads", default=None)
_MIN_DT = _check.MIN_NORMAL
#: The shortest step of a scene with a DFSPH fluid, s: its density solve divides by dt²
#: (Bender & Koschier 2017, Alg. 3: the pressure's ρ_err/dt²), which overflows below 7.5e-155 s
#: (a step of 1e-160 s "diverged" at step 1, advising a smaller dt).
_DFSPH_MIN_DT = 1e-150
_MAX_SUBSTEPS = 2**53  # as render.MAX_STEPS: beyond it n·dt is no longer exact



@dataclass(frozen=True)
class EnergyReport:
    """The energy books at one instant, in joules.

    ``total = kinetic + Σ potential + Σ dissipated`` is conserved by the exact dynamics, so its
    change over a run is the integrator's error (plus the first-order error of collision
    projections). ``mechanical = kinetic + Σ potential``.

    Attributes
    ----------
    kinetic : float
        ``Σ ½ m |v|²`` over free particles.
    potential : dict[str, float]
        Potential energy of each conservative term, by term name.
    dissipated : dict[str, float]
        Energy removed so far by each dissipative term (drag, dashpots) and by colliders
        (``"collisions"``), accumulated while stepping with the integrator's own quadrature.
    total : float
    mechanical : float
    """

    kinetic: float
    potential: dict[str, float]
    dissipated: dict[str, float]
    total: float
    mechanical: float


#: The largest step count (files store it as an int64; it never wraps).
_MAX_STEPS = 2**63 - 1


def _check_int(value: object, arg: str, minimum: int, maximum: int | None = None) -> int:
    return _check.int_in_range(arg, value, minimum, maximum)


def _check_dt(dt: object) -> float:
    """``dt`` as a float; its range (finite, >= the smallest normal float64) is the core's rule
    (``world::check_dt``), checked when the core takes it."""
    return _check.real("dt", dt)


class _Rejoining:
    """The core simulation as a part sees it while its interrupted join is run again
    (:meth:`Scene._rejoin`): a call that registers a term, grid, flow or collider is passed
    over where the core took it already (it holds more of that kind than ``before``, the
    structure before the join), and made where it did not; everything else is the core's."""

    def __init__(self, sim: Any, before: tuple[Any, ...], done: tuple[Any, ...]) -> None:
        self._sim = sim
        # How many of each kind the interrupted join registered, still to be passed over.
        self._taken = {"terms": done[1] - before[1], "colliders": done[2] - before[2]}
        self._systems = set(done[3]) - set(before[3])

    def _skip(self, kind: str) -> bool:
        if self._taken[kind] > 0:
            self._taken[kind] -= 1
            return True
        return False

    def add_term(self, kind: str, name: str, params: dict[str, Any]) -> None:
        if not self._skip("terms"):
            self._sim.add_term(kind, name, params)

    def add_collider(self, kind: str, params: dict[str, Any]) -> None:
        if not self._skip("colliders"):
            self._sim.add_collider(kind, params)

    def add_grid(self, kind: str, name: str, params: dict[str, Any]) -> None:
        if name not in self._systems:
            self._sim.add_grid(kind, name, params)

    def add_flow(self, kind: str, name: str, params: dict[str, Any]) -> None:
        if name not in self._systems:
            self._sim.add_flow(kind, name, params)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._sim, attr)


class _Replacing:
    """The core simulation as a part sees it while it replaces a term (:meth:`Scene.replace`):
    its ``add_term`` becomes the core's ``replace_term``."""

    def __init__(self, sim: Any) -> None:
        self._sim = sim

    def add_term(self, kind: str, name: str, params: dict[str, Any]) -> None:
        self._sim.replace_term(kind, name, params)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._sim, attr)


def _no_particles(*_args: Any, **_kw: Any) -> Any:
    raise InvalidInputError("item: a part that brings particles (a fluid) cannot replace a term")


def _check_integrator(name: object, warn: bool = True) -> str:
    """The integrator's Python name, of a name or of an integrator record (its ``name``); an old
    name (:data:`INTEGRATOR_ALIASES`) warns unless ``warn`` is False (a scene file's)."""
    if isinstance(name, Integrator):
        name = name.name
    if not isinstance(name, str):
        raise InvalidTypeError(
            f"integrator: expected a name (str) or an integrator record (pc.Verlet(), pc.Dopri5(rtol=...), ...), "
            f"got {type(name).__name__}"
        )
    if name in INTEGRATOR_ALIASES:
        if warn:
            _deprecate.warn(f"integrator: {name!r} is now {INTEGRATOR_ALIASES[name]!r}", stacklevel=4)
        name = INTEGRATOR_ALIASES[name]
    if name not in _INTEGRATOR_NAMES:
        raise InvalidInputError(f"integrator: unknown integrator {name!r}; valid names: {', '.join(_INTEGRATOR_NAMES)}")
    return name


def _record_options(integrator: object, options: dict[str, Any]) -> dict[str, Any]:
    """Scene's integrator keywords ``options`` (checked) with an integrator record's own in place
    (``Dopri5(rtol=1e-8)`` sets ``rtol`` and ``atol``). A keyword the record owns that was set
    away from its default, to another value than the record's, raises naming the keyword: the
    option is given twice. (A keyword left at its default defers to the record.)"""
    if not isinstance(integrator, Integrator):
        return options
    own, defaults = integrator.options(), integrator.defaults()
    for kw, value in own.items():
        given = options[kw]
        if given != defaults[kw] and given != value:
            raise InvalidInputError(
                f"{kw}: {given!r} conflicts with integrator={integrator!r}, which sets it to {value!r}; "
                f"give it once (in the record, or integrator={integrator.name!r} with {kw}=)"
            )
    return {**options, **own}


#: Each integrator option of Scene's keywords -> the integrator that uses it (of the records'
#: ``scene_options``: rtol -> "dopri5", cg_tol -> "implicit_euler", ...).
_OPTION_OWNER = {kw: name for name, rec in REGISTRY.items() for kw in rec.scene_options}
_OPTION_DEFAULTS = {kw: v for rec in REGISTRY.values() for kw, v in rec.defaults().items()}

#: Set while a scene is rebuilt from its own file or by a ready-made scene, whose options are
#: kept whatever the integrator (a scene that switched integrators saves them all).
_QUIET_OPTIONS: contextvars.ContextVar[bool] = contextvars.ContextVar("physcore_quiet_options", default=False)


@contextlib.contextmanager
def _quiet_options() -> Iterator[None]:
    """Within: a Scene made keeps every option given without :class:`UnusedOptionWarning`."""
    token = _QUIET_OPTIONS.set(True)
    try:
        yield
    finally:
        _QUIET_OPTIONS.reset(token)


def _warn_unused_options(integrator: str, given: dict[str, Any]) -> None:
    """UnusedOptionWarning naming each option in ``given`` away from its default that
    ``integrator`` does not use (it is kept for a later switch of integrator)."""
    if _QUIET_OPTIONS.get():
        return
    unused = [kw for kw, v in given.items() if _OPTION_OWNER[kw] != integrator and v != _OPTION_DEFAULTS[kw]]
    if unused:
        owners = ", ".join(f"{kw} ({_OPTION_OWNER[kw]!r})" for kw in unused)
        warnings.warn(
            f"integrator={integrator!r} does not use {owners}; kept for a later switch of "
            f"integrator, {'it changes' if len(unused) == 1 else 'they change'} nothing until then",
            UnusedOptionWarning,
            stacklevel=3,
        )


def _check_tol(value: object, arg: str) -> float:
    return _check.real(arg, value)


_PRECISIONS = ("f64", "f32")


def _check_device(value: object) -> str:
    if not isinstance(value, str):
        raise InvalidTypeError(f"device: expected 'cpu', 'gpu', 'gpu:NAME' or 'auto', got {type(value).__name__}")
    if value not in ("cpu", "gpu", "auto") and not (value.startswith("gpu:") and len(value) > 4):
        raise InvalidInputError(f"device: must be 'cpu', 'gpu', 'gpu:NAME' (an adapter; physcore info lists them) or 'auto', got {value!r}")
    return value


#: ``device="auto"``'s cost model (docs/guide/gpu.md, "Choosing a device"), fitted to
#: benches/gpu on an NVIDIA H100 SXM beside its host's 16-thread Xeon (AVX-512; f32 on the
#: device, f64 on the CPU, medians of 3 calls), the CPU's rates checked on the project's
#: 2-core Xeon. A CPU step: a floor plus each kind's work at its rate per thread, on as many
#: threads as the work has chunks (a direct sum splits by particle, 256 a chunk; the rest 4096
#: units a chunk). A GPU step: a floor per system (its dispatches) plus each kind's work at the
#: GPU's rate, where a direct sum runs one thread per particle, looping over all N at a fixed
#: rate until the GPU is full (N² / (rate · min(N, lanes))). The scene goes to the GPU when that
#: is at most half the CPU's time. Fitted: N-body 1024 / 4096 / 65536 on 16 threads 0.28 / 1.1 /
#: 268 ms a step (measured 0.30 / 1.4–1.7 / 273), on the GPU 4096 / 65536 / 262144 0.23 / 3.3 /
#: 49 ms (0.18 / 3.4 / 51); cloth 16² / 64² 45 / 138 µs on the CPU (16–18 / 126–149), 30 / 31
#: µs on the GPU (33 / 33–40), 1024² 0.27 ms (0.26); Gray–Scott 128² / 4096² 30 µs / 3.9 ms (27–46 µs / 3.9 ms) on the
#: CPU. The grids' GPU rate and floor were refitted on the H200 (2026-11-28) after their
#: workgroups took more rows on large grids: the wave (f32) 128² / 1024² / 4096² 10 / 17 / 122
#: µs (measured 10.9 / 20 / 112), Gray–Scott 4096² 122 µs (100); the CPU (16 threads) 30 / 0.26
#: ms / 3.9 ms for the wave (12 µs / 0.24 / 3.7 ms: at 128² the two are within 10 %, and the
#: model's choice of the GPU there costs nothing noticeable).
#: A smaller GPU has about the same floors and fewer lanes: near the threshold the floors
#: decide, far above it any GPU wins.
_AUTO_CPU_FLOOR_S = 15e-6
_AUTO_FLOOR_S = {"particles": 30e-6, "grid": 10e-6}  # a GPU step, per system
_AUTO_LANES = 7e4
#: kind: (CPU rate per thread, CPU chunk, GPU rate), in units of work per second (pairs: the
#: GPU's rate is per thread, see _AUTO_LANES; the CPU's chunks are of particles).
_AUTO_RATES = {
    "pairs": (1.0e9, 256, 2.0e7),
    "springs": (5.0e7, 4096, 2.7e10),
    "cells": (2.7e8, 4096, 1.5e11),
    "particles": (1.0e8, 4096, 1.0e10),
}


def _auto_work(parts: list[Part], n: int) -> dict[str, float]:
    """One step's work for ``device="auto"``'s cost model, by kind (see :data:`_AUTO_RATES`)."""
    work = {"pairs": 0.0, "springs": 0.0, "cells": 0.0, "particles": float(n), "grids": 0.0, "unmeasured": 0.0}
    for part in parts:
        if part.section == "grids" and part.part_kind in _GPU_UNMEASURED:
            work["unmeasured"] += 1.0
        if part.section == "terms" and part.part_kind in ("pairwise_gravity", "coulomb"):
            work["pairs"] += float(n) * float(n)
        elif part.section == "terms" and part.part_kind == "springs":
            work["springs"] += float(len(part))  # type: ignore[arg-type]
        elif part.section == "grids":
            work["cells"] += float(math.prod(part.shape))  # type: ignore[attr-defined]
            work["grids"] += 1.0
    return work


def _auto_times(work: dict[str, float], threads: int) -> tuple[float, float]:
    """A step's estimated seconds on the CPU (``threads`` threads) and on a GPU."""
    n = work["particles"]
    cpu, gpu = _AUTO_CPU_FLOOR_S, 0.0
    if n > 0:
        gpu += _AUTO_FLOOR_S["particles"]
    gpu += _AUTO_FLOOR_S["grid"] * work["grids"]
    for kind, (rate, chunk, gpu_rate) in _AUTO_RATES.items():
        w = work[kind]
        if w <= 0:
            continue
        chunks = (n if kind == "pairs" else w) / chunk
        cpu += w / (rate * min(max(threads, 1), max(chunks, 1.0)))
        gpu += w / (gpu_rate * (min(max(n, 1.0), _AUTO_LANES) if kind == "pairs" else 1.0))
    return cpu, gpu


def _best_gpu(adapters: Iterable[dict[str, Any]]) -> dict[str, Any] | None:
    """The adapter ``device="gpu"`` takes of ``adapters``: discrete, then integrated, then
    virtual, never a CPU one (the core's ``Gpu::open``); None where there is none."""
    order = {"discrete": 0, "integrated": 1, "virtual": 2}
    return min((a for a in adapters if a["kind"] != "cpu"), key=lambda a: order.get(a["kind"], 3), default=None)


def _auto_choice(work: dict[str, float], threads: int, adapters: list[dict[str, Any]], precision: str | None) -> tuple[str, str]:
    """``device="auto"``: the device a scene of this work per step runs on, and why. Only a
    real GPU is taken (never a CPU adapter such as lavapipe), one with f64 where ``precision``
    asks for it; the GPU when the cost model says a step there takes at most half the CPU's time."""
    best = _best_gpu(a for a in adapters if precision != "f64" or a["f64"])
    if best is None:
        what = "no GPU adapter" + (" with f64" if precision == "f64" and any(a["kind"] != "cpu" for a in adapters) else "")
        return "cpu", f"{what} (device='auto')"
    if work.get("unmeasured", 0.0) > 0:
        return "cpu", ("the stable fluid's GPU path has not been timed on a GPU yet, so device='auto' keeps it on "
                       "the CPU (device='gpu' runs it there)")
    cpu, gpu = _auto_times(work, threads)
    estimate = f"a step estimated at {cpu * 1e3:.3g} ms on {threads} CPU thread(s), {gpu * 1e3:.3g} ms on {best['name']}"
    if gpu <= 0.5 * cpu:
        return f"gpu:{best['name']}", estimate
    return "cpu", estimate + " (too small a scene to gain on a GPU)"


#: Term kinds the GPU path has kernels for (rust_core/src/systems/device.rs).
_GPU_TERMS = ("gravity", "drag", "pairwise_gravity", "coulomb", "springs")
#: The core's name of the particles' system on a device (`systems::device::DeviceParticles`).
_DEVICE_PARTICLES = "device particles"
#: Grid kinds the GPU path has kernels for (the same file).
_GPU_GRIDS = ("gray_scott", "wave", "stable_fluid")
#: Grid kinds the GPU path runs but device="auto" does not choose the GPU for: no GPU timing
#: to fit its cost model to yet (the stable fluid's was written and checked on lavapipe only).
_GPU_UNMEASURED = ("stable_fluid",)
#: Collider sections the GPU path has kernels for (planes, boxes and spheres; capsules and oriented boxes below).
_GPU_COLLIDERS = ("planes", "boxes", "spheres")
#: Kinds of the generic "colliders" section the GPU path has kernels for.
_GPU_SHAPES = ("capsule", "oriented_box")


def _check_precision(value: object) -> str:
    if not isinstance(value, str):
        raise InvalidTypeError(f"precision: expected 'f64' or 'f32', got {type(value).__name__}")
    if value not in _PRECISIONS:
        raise InvalidInputError(f"precision: must be 'f64' or 'f32', got {value!r}")
    return value


def _not_a_part(item: object, terms_only: bool = False) -> str:
    """What :meth:`Scene.add` (``terms_only``: :meth:`Scene.replace`) says of an ``item`` it
    cannot take: the kinds it takes, by name, and for a class given where an instance was meant
    (``scene.add(pc.Gravity)``) the call that makes one."""
    kinds = sorted({c.__name__ for c in PARTS.values() if not terms_only or issubclass(c, Term)})
    what = "a term" if terms_only else "a part"
    if isinstance(item, type) and item in set(PARTS.values()):
        return f"got the class {item.__name__}, not {what}: did you mean {item.__name__}(...)?"
    return f"expected {what} of physcore ({', '.join(kinds)}), got {type(item).__name__}"


def _points(value: object, arg: str, dim: int, n: int | None = None, *, precision: str = "f64",
            row_bytes: int = 0, call: str | None = None) -> np.ndarray:
    """(N, dim) float64 C-contiguous copy of ``value``; TypeError/ValueError naming ``arg``;
    OutOfMemoryError, naming ``call`` (default ``arg``: a refused allocation names the call),
    where the call's need (``row_bytes`` a row, default the copy's) is beyond memory or the copy
    cannot be had; rows refused that ``precision`` cannot hold."""
    a = _check.real_array(arg, value, sized=False)  # its own need is asked for below, by particles
    if a.ndim == 1 and a.shape[0] == dim and n in (None, 1):
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != dim:
        raise InvalidInputError(f"{arg}: expected shape (N, {dim}), got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise InvalidInputError(f"{arg}: expected {n} rows (one per particle), got {a.shape[0]}")
    # A zero-stride (broadcast) input can stand for more rows than memory holds: asked for
    # before copying, and a copy refused all the same is named as the argument's.
    _check.room(call or arg, a.shape[0] * (row_bytes or 8 * dim), f"{a.shape[0]:,} particles")
    with allocating(call or arg, f"a float64 copy of {arg}"):
        a = np.ascontiguousarray(a, dtype=np.float64)
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise InvalidInputError(f"{arg}: row {int(np.flatnonzero(bad)[0])} is not finite")
        return _fit_precision(a, arg, precision)


def _fit_precision(a: np.ndarray, arg: str, precision: str) -> np.ndarray:
    """``a``, rows (N, dim) of float64, with the first row that a float32 state would hold as
    infinity refused by name. Both paths check here: the core checks only in the CPU's f32
    mode, and a GPU scene's state stays float64 on the host until its first step, so it took
    such rows and ``save`` wrote them as inf."""
    if precision == "f32":
        with np.errstate(over="ignore"):
            bad = ~np.isfinite(a.astype(np.float32)).all(axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InvalidInputError(f'{arg}: row {k} does not fit float32 (precision="f32"): {a[k].tolist()}')
    return a


#: The core's reads a save or a snapshot makes, whose memory refusals are named as the call the
#: user made (``save``, ``state``, ``to_bytes``), not as the read inside it.
_READS = ("positions", "velocities", "masses", "pinned", "integrator_cache", "field", "attributes")


def _check_state_value(key: str, value: Any, now: Any, scene: Scene) -> Any:
    """``value`` of ``state[key]`` checked against the scene's own ``now`` (see Scene.set_state)."""
    arg = f"state[{key!r}]"
    if key in ("time", "collisions"):
        v = _check.real(arg, value)
        if not math.isfinite(v):
            raise InvalidInputError(f"{arg}: must be finite, got {v}")
        if key == "time" and v < 0:  # as Scene.load's rule: a state saved must load again
            raise InvalidInputError(f"{arg}: must be >= 0 (s), got {v}")
        return v
    if key == "dt":
        v = _check.real(arg, value)
        if not (math.isfinite(v) and v >= _MIN_DT):
            raise InvalidInputError(f"{arg}: must be > 0 and finite (at least {_MIN_DT:.3g} s, the smallest normal float64), got {v}")
        return v
    if key == "step":
        return _check_int(value, arg, 0, _MAX_STEPS)
    if value is None:
        if key in ("cache_forces", "cache_power", "reference_energy"):
            return None
        raise InvalidTypeError(f"{arg}: expected an array, got None")
    a = _check.array(arg, value)
    if a.dtype != np.float64:
        raise InvalidTypeError(f"{arg}: expected dtype float64, got {a.dtype}")
    if key in ("positions", "velocities") or key.startswith(("attr_", "device_")) or key in ("ledger", "reference_energy"):
        want = now.shape if now is not None else (2,)
        if a.shape != want:
            raise InvalidInputError(f"{arg}: expected shape {want}, got {a.shape}")
    elif key == "cache_forces":
        if a.ndim != 2 or a.shape[1] != scene.dim:
            raise InvalidInputError(f"{arg}: expected shape (M, {scene.dim}), got {a.shape}")
    elif a.ndim != 1 if now is None else a.ndim != now.ndim:
        raise InvalidInputError(f"{arg}: expected {1 if now is None else now.ndim} dimension(s), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise InvalidInputError(f"{arg}: must be finite")
    if key == "reference_energy" and a[1] < 0:  # (E0, its scale): a scale is >= 0, as load's rule
        raise InvalidInputError(f"{arg}: its scale (entry 1) must be >= 0, got {a[1]}")
    if key in ("positions", "velocities"):
        _fit_precision(a, arg, scene.precision)
    return np.ascontiguousarray(a)


class Scene:
    """A particle system: particles, the force terms and colliders it names, an integrator.

    Parameters
    ----------
    dim : {2, 3}
        Spatial dimension.
    integrator : str or integrator record
        A name or, equally, its record (below): ``"euler"`` (explicit, 1st order, for contrast), ``"semi_implicit_euler"`` (symplectic,
        1st order), ``"verlet"`` (velocity Verlet, symplectic, 2nd order; default), ``"yoshida4"``
        (Yoshida 1990's fourth-order composition of three Verlet substeps, symplectic, 3 force
        evaluations per step), ``"rk4"``
        (classic Runge–Kutta, 4th order, 4 force evaluations per step), ``"dopri5"`` (adaptive
        Dormand–Prince 5(4), Dormand & Prince 1980: error-controlled internal steps, 6 force
        evaluations each; see `rtol`; old name ``"rk45"``, deprecated), ``"wisdom_holman"`` (the
        Wisdom–Holman map for planetary systems, Wisdom & Holman 1991: Kepler orbits about the
        heaviest body followed exactly, 2nd order, symplectic; needs one unsoftened
        :class:`PairwiseGravity`, see :class:`WisdomHolman`) or ``"boris"`` (the Boris push for charges in magnetic
        fields, 2nd order, volume-preserving: turns each velocity through B exactly, so the
        speed keeps to round-off in a pure magnetic field for any dt; velocity Verlet when the
        scene has no magnetic term), ``"xpbd"`` (position-based dynamics with substeps,
        Macklin et al. 2016/2019: each step is ``xpbd_substeps`` substeps of semi-implicit Euler
        under the force terms, each followed by ``xpbd_iterations`` projections of the
        :class:`XpbdConstraints`; 1st order, damped by the projection) or
        ``"implicit_euler"`` (linearised backward Euler, Baraff &
        Witkin 1998: springs and drag implicit, solved by conjugate gradients each step; 1st
        order, unconditionally stable on springs, so stiff cloth may take steps 10–100× the
        explicit limit, at the price of numerical damping that the energy books show as a
        residual; see `cg_tol`).

        Each name has an immutable record holding that integrator's own options, checked when
        the record is made: :class:`~physcore.Euler`, :class:`~physcore.SemiImplicitEuler`,
        :class:`~physcore.Verlet`, :class:`~physcore.Yoshida4`, :class:`~physcore.RK4`,
        :class:`~physcore.Dopri5` (``rtol``, ``atol``), :class:`~physcore.WisdomHolman`
        (``coordinates``: ``wh_coordinates`` here), :class:`~physcore.Boris`,
        :class:`~physcore.XPBD` (``substeps``, ``iterations``: ``xpbd_substeps``,
        ``xpbd_iterations`` here) and :class:`~physcore.ImplicitEuler` (``cg_tol``,
        ``cg_max_iter``). ``integrator=pc.Dopri5(rtol=1e-8)`` makes the same scene as
        ``integrator="dopri5", rtol=1e-8`` (same core calls, same saved file). A keyword that the
        record owns, also given here with another value than the record's, raises
        InvalidInputError naming the keyword (left at its default, it defers to the record).
        An option of another integrator given away from its default is kept (it takes effect
        when the scene switches to that integrator) with an :class:`UnusedOptionWarning`.
    dt : float
        Time step, s: finite and at least the smallest normal float64 (2.2e-308; a subnormal
        step has no finite reciprocal). Default 1e-3. For ``"dopri5"`` it is the output interval: each step
        of ``dt`` is integrated in as many internal steps as the tolerances need and lands
        exactly on its end.
    rtol, atol : float
        Tolerances of ``"dopri5"`` (kept, and ignored, by the other integrators, with an
        :class:`UnusedOptionWarning`). A step is
        accepted when every position and velocity component i has a local error estimate below
        ``atol + rtol · |y_i|`` (atol in m for positions and m/s for velocities; max norm over
        all particles). ``rtol`` in [1e-14, 1), default 1e-6; ``atol`` >= 0, default 1e-9.
    cg_tol, cg_max_iter : float, int
        The linear solve of ``"implicit_euler"`` (kept, and ignored, by the other integrators,
        with an :class:`UnusedOptionWarning`):
        conjugate gradients stop once the residual is below ``cg_tol`` times the right-hand
        side's norm, or after ``cg_max_iter`` iterations. ``cg_tol`` in [1e-14, 1), default
        1e-8; ``cg_max_iter`` in 1..1000000, default 200. A solve stopped by the limit keeps its
        last iterate and is counted in :attr:`integrator_stats` (``"cg_unconverged"``).
    precision : {"f64", "f32"} or None
        ``"f64"`` (the default on the CPU: ``None``) keeps positions and velocities in double
        precision. ``"f32"`` keeps them in single precision: every stored value is rounded to the nearest float32 after
        each step (the arithmetic within a step stays float64), as a float32 state array would
        hold them; ``positions``/``velocities`` are then returned as float32. It shows what
        single precision costs in accuracy (see the work-precision table in docs/guide/integrators.md).
        With a GPU ``device``: the precision of the device's state and arithmetic, ``"f32"`` by
        default (``None``); ``"f64"`` where the adapter has it (refused, naming the adapter, where not).
    device : {"cpu", "gpu", "gpu:NAME", "auto"}
        Where the particles are stepped. ``"cpu"`` (default): the reference path, with every part.
        ``"auto"``: chosen at the first step, a real GPU (never a CPU adapter such as lavapipe)
        when every part has a GPU kernel and a cost model fitted to measurements (an NVIDIA H100
        beside a 16-thread Xeon; docs/guide/gpu.md) expects a step there in at most half the
        CPU's time (at default threads: a direct N-body sum from ~500 particles, a cloth from
        ~32², a Gray–Scott or wave grid of any size), else the CPU; :attr:`device` then says which and
        :attr:`device_reason` why. The precision follows the choice (f32 on a GPU, f64 on the
        CPU) unless ``precision`` is given.
        ``"gpu"``: the best GPU adapter (discrete, then integrated; ``physcore info`` lists them);
        ``"gpu:NAME"``: the first adapter whose name, backend or kind contains NAME
        (``"gpu:lavapipe"`` takes Mesa's CPU Vulkan, which is never taken silently). The GPU path
        (wgpu: Vulkan, Metal, DX12) holds particles under :class:`Gravity`, :class:`Drag`,
        :class:`PairwiseGravity`, :class:`Coulomb` (the ``"charge"`` attribute) and one :class:`Springs`, stepped by ``"semi_implicit_euler"``, ``"verlet"`` or ``"yoshida4"``,
        with every collider (:class:`Plane`, :class:`Box`, :class:`Sphere`, :class:`Capsule`,
        :class:`OrientedBox`), and :class:`~physcore.grids.GrayScott` and
        :class:`~physcore.grids.Wave` grids (their fields read and set as on the CPU); the parts
        move to the device at the first step, and a part it has no kernel for is refused then,
        by name (never run silently on the CPU; a :class:`~physcore.Batch` moves its GPU members
        likewise). After that step the scene steps, reads positions, velocities and the energy
        books, renders, saves and pickles (:meth:`save`), and :meth:`state` / :meth:`set_state`
        work; adding parts, another integrator and :meth:`set_attribute` are refused (not yet on
        the GPU path).
        docs/guide/gpu.md gives each kernel's measured agreement with the CPU path.
    threads : int or None
        Worker threads for this scene, 1 to :data:`MAX_THREADS` (65535, rayon's own limit);
        ``None`` (default) uses all cores (or ``RAYON_NUM_THREADS``). Results are bit-identical
        for any thread count. If no thread can be started (a limit on threads), ``None`` runs on
        the calling thread with a :class:`ThreadPoolWarning`.

    xpbd_substeps, xpbd_iterations : int
        Substeps per step (1 to 100000, default 10) and constraint iterations per substep (1 to
        10000, default 1) of ``"xpbd"``; kept, and ignored, by the other integrators (with an
        :class:`UnusedOptionWarning`). Many
        substeps of one iteration each converge faster than few substeps of many iterations
        ("Small steps in physics simulation", Macklin et al., SCA 2019).
    wh_coordinates : {"jacobi", "democratic_heliocentric"}
        The coordinates of ``"wisdom_holman"``'s split (default ``"jacobi"``; see
        :class:`WisdomHolman`); kept, and ignored, by the other integrators.
    wh_corrector : {0, 3, 5, 7, 11, 17}
        The order of ``"wisdom_holman"``'s symplectic corrector (default 0: none; see
        :class:`WisdomHolman`): applied at the first step, undone for each call's output;
        kept, and ignored, by the other integrators (with an :class:`UnusedOptionWarning`).

    Raises
    ------
    TypeError
        An argument of the wrong type (``bool`` and ``str`` are not numbers); names it.
    InvalidInputError
        (a ``ValueError``) An argument out of range, or not representable (e.g. an int beyond
        float64, ``threads=2**64``); names it.
    ThreadPoolError
        ``threads=n`` threads could not be started.

    Warns
    -----
    UnusedOptionWarning
        An option of another integrator than ``integrator`` (``rtol`` with ``"verlet"``) was
        given away from its default; names it and the integrator that uses it.
    ThreadPoolWarning
        ``threads=None`` could not start a thread pool; the scene runs on the calling thread.

    Examples
    --------
    >>> import numpy as np, physcore as pc
    >>> scene = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    >>> ids = scene.add_particles(np.array([[0.0, 0.0], [1.0, 0.0]]), pinned=[True, False])
    >>> _ = scene.add(pc.Gravity([0.0, -9.81]))
    >>> _ = scene.add(pc.Springs([0], [1], stiffness=100.0))
    >>> scene.step(1000)
    >>> round(scene.time, 6)
    1.0
    """

    def __init__(
        self,
        dim: int = 2,
        *,
        integrator: str | Integrator = "verlet",
        dt: float = 1e-3,
        # The options' defaults are their integrator records' (physcore/_integrators.py).
        rtol: float = Dopri5.rtol,
        atol: float = Dopri5.atol,
        cg_tol: float = ImplicitEuler.cg_tol,
        cg_max_iter: int = ImplicitEuler.cg_max_iter,
        precision: str | None = None,
        threads: int | None = None,
        xpbd_substeps: int = XPBD.substeps,
        xpbd_iterations: int = XPBD.iterations,
        wh_coordinates: str = WisdomHolman.coordinates,
        wh_corrector: int = WisdomHolman.corrector,
        device: str = "cpu",
    ) -> None:
        device = _check_device(device)
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)):
            raise InvalidTypeError(f"dim: expected 2 or 3, got {type(dim).__name__}")
        if dim not in (2, 3):
            raise InvalidInputError(f"dim: must be 2 or 3, got {dim}")
        name = _check_integrator(integrator)
        dt = _check_dt(dt)
        rtol, atol = _check_tol(rtol, "rtol"), _check_tol(atol, "atol")
        cg_tol, cg_max_iter = _check_tol(cg_tol, "cg_tol"), check_cg_max_iter(cg_max_iter)
        xpbd_substeps, xpbd_iterations = check_xpbd_substeps(xpbd_substeps), check_xpbd_iterations(xpbd_iterations)
        wh_coordinates, wh_corrector = check_wh_coordinates(wh_coordinates), check_wh_corrector(wh_corrector)
        options = _record_options(
            integrator,
            {"rtol": rtol, "atol": atol, "cg_tol": cg_tol, "cg_max_iter": cg_max_iter,
             "xpbd_substeps": xpbd_substeps, "xpbd_iterations": xpbd_iterations,
             "wh_coordinates": wh_coordinates, "wh_corrector": wh_corrector},
        )
        rtol, atol, cg_tol, cg_max_iter = options["rtol"], options["atol"], options["cg_tol"], options["cg_max_iter"]
        xpbd_substeps, xpbd_iterations = options["xpbd_substeps"], options["xpbd_iterations"]
        wh_coordinates, wh_corrector = options["wh_coordinates"], options["wh_corrector"]
        integrator = name
        # device="auto": the precision follows the choice made at the first step (f64 on the CPU,
        # f32 on a GPU) unless it was given.
        auto_precision = None if precision is None or device != "auto" else _check_precision(precision)
        precision = _check_precision(("f64" if device in ("cpu", "auto") else "f32") if precision is None else precision)
        if threads is not None:
            threads = _check_int(threads, "threads", 1, MAX_THREADS)
        sim = _core.Simulation(int(dim), integrator, dt, DEFAULT_THREADS.get() if threads is None else threads)
        if sim.sequential is not None:
            warnings.warn(
                f"threads=None: could not start a thread pool ({sim.sequential}); this scene runs on "
                "the calling thread alone (same results, slower; Ctrl-C takes effect when a call "
                "ends, and the call is still undone). The process has probably hit its limit on "
                "threads (ulimit -u, RLIMIT_NPROC).",
                ThreadPoolWarning,
                stacklevel=2,
            )
        sim.set_tolerances(rtol, atol)  # validates (ValueError naming rtol/atol)
        sim.set_substeps(xpbd_substeps, xpbd_iterations)
        sim.set_wh_coordinates(wh_coordinates)
        sim.set_wh_corrector(wh_corrector)
        sim.set_solver_options(cg_tol, cg_max_iter)  # validates (ValueError naming cg_tol)
        _warn_unused_options(name, options)  # once every option is known valid
        # The CPU's f32 mode rounds the stored state; a device computes in its own precision.
        sim.single = precision == "f32" and device in ("cpu", "auto")
        self._device = device
        self._device_precision = precision
        self._auto_precision = auto_precision
        self._device_reason: str | None = None
        # The particle attributes as they were moved to the device (None before): the core's
        # host side hands them over with the particles, and they cannot change there.
        self._device_attrs: dict[str, np.ndarray] | None = None
        # One thread at a time, and the books' reference (physcore.session).
        #: Everything the scene holds, as stored, in the order added (see physcore._parts); the
        #: session shares the list (never rebound), which a Batch counts.
        self._parts: list[Part] = []
        self._session = Session(sim, self._parts)
        self._threads = threads
        self._step_checked: float | None = None  # the dt last checked against the contacts' step
        self._grid_step_checked: float | None = None  # ... and against the grids' limits
        self._stable_step_checked: float | None = None  # ... and against the terms' stability
        self._charge_checked = False  # terms on charges checked against the charges (_warn_uncharged)
        #: Animation defaults of :mod:`physcore.render` for this scene (``frames``, ``fps``,
        #: ``frame_time``, ``size``, ...), set by the ready-made scenes of :mod:`physcore.scenes`;
        #: ``None``: the renderer's own (real-time playback). Not saved with the scene.
        self.render_defaults: dict[str, Any] | None = None

    # ---------------------------------------------------------------- threads
    @property
    def session(self) -> Session:
        """The scene's :class:`~physcore.session.Session`: its core simulation, the lock that
        lets one thread at a time use it, and the energy books' reference. The same object for
        the scene's life; its parts hold it too. What drives scenes from outside
        (:class:`~physcore.Batch`, :func:`~physcore.sweep`, the live viewer) uses this."""
        return self._session

    @property
    def parts(self) -> tuple[Part, ...]:
        """Everything the scene holds (terms, colliders, grids, flows, bodies), as stored, in the
        order added: a new tuple. Each part has a ``section`` and a ``part_kind``
        (``physcore/_parts.py``)."""
        return tuple(self._parts)

    @property
    def _sim(self) -> _core.Simulation:
        # A Scene is not shared between threads while one of them steps it (`Session`).
        return self._session.checked()

    @property
    def _e0(self) -> float | None:
        ref = self._session.reference_energy
        return None if ref is None else ref[0]

    @_e0.setter
    def _e0(self, value: None) -> None:
        assert value is None  # a reference is taken whole (Session.take_reference_energy)
        self._session.reference_energy = None

    @property
    def _e0_scale(self) -> float:
        ref = self._session.reference_energy
        return 0.0 if ref is None else ref[1]

    def _exclusive(self, call: Callable[[_core.Simulation], Any]) -> Any:
        """Runs ``call(sim)`` (a call that releases the GIL: stepping, energies, fields) as the
        only user of the scene; another thread's use meanwhile raises :class:`SceneBusyError`
        (so does this call, if another thread is inside one)."""
        return self._session.exclusive(call)

    # ---------------------------------------------------------------- building
    def add_particles(
        self,
        positions: np.typing.ArrayLike,
        velocities: np.typing.ArrayLike | None = None,
        masses: float | np.typing.ArrayLike = 1.0,
        pinned: np.typing.ArrayLike | None = None,
    ) -> np.ndarray:
        """Append particles.

        Parameters
        ----------
        positions : array_like, shape (N, dim)
            Positions, m.
        velocities : array_like, shape (N, dim), optional
            Velocities, m/s. Default zero. Ignored (set to zero) for pinned particles.
        masses : float or array_like, shape (N,)
            Masses, kg: finite and at least the smallest normal float64 (2.2e-308), so that the
            inverse mass is finite. Default 1.
        pinned : array_like of bool, shape (N,), optional
            ``True`` fixes a particle in place (infinite inertia); it still attracts under
            :class:`PairwiseGravity` and anchors springs. Default none pinned.

        Returns
        -------
        numpy.ndarray, shape (N,), int64
            Indices of the new particles.

        Raises
        ------
        TypeError
            Non-numeric arrays.
        InvalidInputError
            (a ``ValueError``) Wrong shapes, NaN/inf, masses not in [2.2e-308, finite], a row
            past float32's range in an f32 scene (CPU or GPU); nothing is added.
        OutOfMemoryError
            (a ``MemoryError``) The particles would not fit (a broadcast array of a billion
            rows), naming the argument; nothing is added.
        """
        dim, precision = self.dim, self.precision
        # Positions, velocities, masses and pinned flags, each held twice during the call (the
        # checked copies and the core's): asked for before the first copy.
        x = _points(positions, "positions", dim, precision=precision, row_bytes=2 * (2 * 8 * dim + 9), call="add_particles")
        n = x.shape[0]
        with allocating("add_particles", "zero velocities"):
            v = np.zeros_like(x) if velocities is None else _points(velocities, "velocities", dim, n, precision=precision,
                                                                     call="add_particles")
        m = _check.real_array("masses", masses, sized=False)
        if m.ndim != 0 and m.shape != (n,):  # before copying: a broadcast array can be huge
            raise InvalidInputError(f"masses: expected a scalar or shape ({n},), got {m.shape}")
        with allocating("add_particles", "a float64 copy of masses"):
            m = np.ascontiguousarray(np.broadcast_to(m.astype(np.float64), (n,)) if m.ndim == 0 else m, dtype=np.float64)
        # The integrators divide by the mass: below the smallest normal float64 1/m overflows.
        bad = ~(np.isfinite(m) & (m >= _check.MIN_MASS))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InvalidInputError(
                f"masses: entry {k} is {m[k]} (must be finite and >= {_check.MIN_MASS:.3g} kg, so that 1/m is finite)"
            )
        if pinned is None:
            p = np.zeros(n, dtype=bool)
        else:
            p = _check.array("pinned", pinned)
            if p.dtype != bool:
                raise InvalidTypeError(f"pinned: expected booleans, got dtype {p.dtype}")
            if p.shape != (n,):
                raise InvalidInputError(f"pinned: expected shape ({n},), got {p.shape}")
            with allocating("add_particles", "a copy of pinned"):
                p = np.ascontiguousarray(p)
        first = self._sim.add_particles(x, v, m, p)
        self._e0 = None
        return np.arange(first, first + n, dtype=np.int64)

    @allocating("add", "a copy of the item's arrays for the core")
    def add(self, item: Any) -> Any:
        """Add a force term (:class:`Gravity`, :class:`Drag`, :class:`Springs`,
        :class:`PairwiseGravity`, :class:`~physcore.fluids.Fluid`), a collider (:class:`Plane`,
        :class:`Box`, :class:`Sphere`) or a grid system (:class:`~physcore.grids.Wave`,
        :class:`~physcore.grids.GrayScott`), stepped with the particles on the scene's clock.

        A grid joins one scene only; its name must be free. It is returned bound to the scene:
        its fields (``wave.u``) read the scene's state.

        A :class:`~physcore.fluids.Fluid` brings its own particles: they are appended, the stored
        fluid records the first index and the resolved ``sound_speed``, and the scene's ``dt`` is
        lowered to the fluid's CFL limit if it is above it.

        A term whose name is already taken gets ``_2``, ``_3``, ... appended. Returns the term as
        stored (for :class:`Springs` with ``rest_length=None``, with the rest lengths resolved).

        Whatever is added is a *part* (``physcore/_parts.py``): its class is registered by its
        kind and attaches itself through a small context, so this method has no case per kind,
        and a new kind of part needs no change here.

        Raises
        ------
        TypeError
            ``item`` is not a term or collider.
        InvalidInputError
            (a ``ValueError``) Vector length differs from ``dim``; spring index out of range; a
            spring's current length (for ``rest_length=None``) beyond float64. Nothing is added.
        """
        return self._add(item)

    def _add(self, item: Any, **restoring: Any) -> Any:
        """:meth:`add`; ``restoring``: what a scene file says the part holds in the scene already
        (a loaded fluid's ``first`` particle)."""
        cls = part_class(item)
        if cls is None:
            raise InvalidTypeError(f"item: {_not_a_part(item)}")
        ctx = self._context(restoring)
        name = item._claim_name(ctx)
        before = self._sim.structure()
        host = getattr(item, "_host", None)
        try:
            stored = item._attach(ctx, name)
        except BaseException:
            # Ctrl-C raised as the core's call returned, the part taken (the bodies' insertion
            # into rapier cannot be stopped): recorded, so that the scene and the core agree.
            stored = item._taken_despite(ctx, name)
            # Rigid bodies, joints and pins answer for themselves (`_taken_despite`): a join run
            # again would insert a group the core refused, and that insertion cannot be stopped.
            if stored is None and item.section != "bodies" and self._sim.structure() != before:
                stored = self._rejoin(item, ctx, name, before, host)
            if stored is not None:
                self._parts.append(stored)
            raise
        self._parts.append(stored)
        self._charge_checked = False
        if cls.changes_energy:
            self._e0 = None
        return stored

    def _rejoin(self, item: Any, ctx: AttachContext, name: Any, before: tuple[Any, ...], host: Any) -> Any:
        """After ``item._attach`` raised (a Ctrl-C as one of its calls into the core returned)
        with the core changed since ``before`` (:meth:`Simulation.structure`): the part as
        stored, its join run again, with Ctrl-C held, against the core as it is, each call that
        took effect already passed over and any it had not reached made (a fluid's particles in,
        its term not yet), so that the scene records all the core holds. A fault audit found the
        scene without the part and the core with it: the part acted unseen, and the next save
        wrote a file that failed to load. None, the scene left as it was, if the join fails."""
        with ctrl_c_held():
            if host is None and getattr(item, "_host", None) is not None:
                item._host = None  # bound by the interrupted join: the join binds it again
            done = self._sim.structure()
            sim = _Rejoining(self._sim, before, done)
            grown = done[0] - before[0]
            added: list[np.ndarray] = []

            def add_particles(*args: Any, **kw: Any) -> np.ndarray:
                if grown and not added:  # they are in already: their indices
                    added.append(np.arange(before[0], done[0], dtype=np.int64))
                    return added[0]
                return ctx.add_particles(*args, **kw)

            again = dataclasses.replace(ctx, sim=sim, add_particles=add_particles)
            try:
                with warnings.catch_warnings():  # said by the interrupted join already
                    warnings.simplefilter("ignore")
                    return item._attach(again, name)
            except Exception:  # noqa: BLE001 - the interrupt is what the caller raises
                return None

    def _unrecorded(self) -> str | None:
        """What the core holds that the scene has not recorded (a join interrupted where
        :meth:`_rejoin` could not finish it), or None: the scene and the core agree."""
        n, terms, colliders, systems = self._sim.structure()
        mine = len(self._section("terms"))
        walls = sum(len(self._section(k)) for k in ("planes", "boxes", "spheres", "colliders"))
        named = {p.name for p in self._parts if p.section in ("grids", "flows")} | ({"bodies"} if self._section("bodies") else set())
        extra = [x for x in systems if x not in named and x != "device particles"]
        if terms != mine:
            return f"{terms} force terms where the scene records {mine}"
        if colliders != walls:
            return f"{colliders} colliders where the scene records {walls}"
        if extra:
            return f"a system {extra[0]!r} the scene does not record"
        return None

    def replace(self, name: str, item: Any) -> Any:
        """Put force term ``item`` in place of the term called ``name``, keeping the scene's state,
        time, books and the term's place in the evaluation order (the core's ``replace_term``):
        what the viewer's parameter keys do. ``item`` must be of the same class as the term it
        replaces; it takes that term's name. The integrator's cached forces are dropped and the
        energy-drift reference restarts (the energy's definition may have changed).

        Returns the term as stored. Raises InvalidInputError naming ``name`` (no such term),
        ``item`` (another class, or a fluid, whose particles and neighbour search it owns) or
        the record's field, and InvalidTypeError for an ``item`` that is not a term; nothing
        changes then.
        """
        if not isinstance(name, str):
            raise InvalidTypeError(f"name: expected a term name (str), got {type(name).__name__}")
        terms = [k for k, p in enumerate(self._parts) if p.section == "terms" and p.name == name]
        if not terms:
            raise InvalidInputError(f"name: the scene has no term named {name!r}")
        at = terms[0]
        old = self._parts[at]
        if part_class(item) is None or not isinstance(item, Term):
            raise InvalidTypeError(f"item: {_not_a_part(item, terms_only=True)}")
        if not getattr(type(old), "replaceable", True):
            raise InvalidInputError(f"item: {name!r} is a {type(old).__name__}, which owns particles and cannot be replaced")
        if type(item) is not type(old):
            raise InvalidInputError(f"item: {name!r} is a {type(old).__name__}; a {type(item).__name__} cannot replace it")
        ctx = self._context({})
        sim = _Replacing(self._sim)
        ctx = dataclasses.replace(ctx, sim=sim, parts=tuple(p for p in self._parts if p is not old),
                                  names={**ctx.names, "terms": ctx.names["terms"] - {name}}, add_particles=_no_particles)
        stored = item._attach(ctx, name)
        self._parts[at] = stored
        self._e0 = None
        return stored

    def _context(self, restoring: dict[str, Any]) -> AttachContext:
        """What a part sees of this scene as it joins (see :class:`physcore._parts.AttachContext`)."""
        sim = self._sim
        names = {s: frozenset(getattr(p, "name", "") for p in self._parts if p.section == s) for s in ("terms", "grids", "flows")}
        return AttachContext(
            dim=sim.dim,
            names=names,
            integrator=sim.integrator,  # parts pass it to the core's rules (the same names)
            n_particles=sim.n_particles,
            sim=sim,
            parts=tuple(self._parts),
            read_positions=lambda: self.positions,
            read_attributes=lambda: frozenset(self.attributes),
            add_particles=self.add_particles,
            lower_dt=self._lower_dt,
            host=self._session,
            restoring=restoring,
        )

    def _lower_dt(self, limit: float) -> None:
        self._sim.dt = min(self.dt, limit)

    @allocating("add_fluid", "a copy of the fluid's arrays")
    def add_fluid(self, positions: np.typing.ArrayLike, **params: Any) -> np.ndarray:
        """Add a WCSPH fluid block: ``scene.add(Fluid(positions, **params))``.

        Takes the parameters of :class:`~physcore.fluids.Fluid` (``spacing`` is required) and
        returns the new particles' indices, ``(N,)`` int64.

        Raises TypeError / InvalidInputError naming the argument, before anything is added, for
        the fluid's own parameters (see :class:`~physcore.fluids.Fluid`) and for what the scene
        derives from them: an estimated ``sound_speed`` whose Tait stiffness overflows, a CFL
        step below float64's normal range, wall masses that are not finite and > 0.

        Examples
        --------
        >>> import physcore as pc
        >>> from physcore.fluids import lattice, tank_walls
        >>> scene = pc.Scene(dim=2, integrator="semi_implicit_euler")
        >>> _ = scene.add(pc.Gravity([0.0, -9.81]))
        >>> ids = scene.add_fluid(lattice([0, 0], [0.2, 0.1], 0.01), spacing=0.01,
        ...                       boundary=tank_walls([0, 0], [0.4, 0.3], 0.01))
        >>> len(ids), scene.dt < 1e-3
        (200, True)
        >>> substeps = scene.advance(0.01)   # CFL-limited substeps
        """
        fluid = self.add(Fluid(positions, **params))
        assert fluid.first is not None
        return np.arange(fluid.first, fluid.first + len(fluid), dtype=np.int64)

    # ---------------------------------------------------------------- stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps of ``dt`` in Rust (GIL released).

        Raises
        ------
        SimulationDiverged
            NaN/inf appeared; the scene is rolled back to where this call started, and the
            exception names the step, the particle and a suggested dt.
        KeyboardInterrupt
            Ctrl-C (or any exception raised by a Python signal handler), noticed within about
            20 ms plus one force evaluation: between steps and between dopri5's internal steps;
            the scene is rolled back likewise. A call of at most 4096 particle-steps with a
            fixed-step integrator runs unwatched, and Ctrl-C lands just after it. Rigid bodies:
            inside a long rapier step too (seconds for 1,000 balls in one place): such a step
            runs on a thread of its own, left to finish unseen (docs/guide/bodies.md, "Limits").
        OutOfMemoryError
            (a ``MemoryError``) The call's checkpoint or scratch cannot be had now (for rigid
            bodies, a copy of rapier's state and an allowance for what its step allocates:
            docs/guide/bodies.md, "Limits"); nothing was stepped.

        Warns
        -----
        ContactStepWarning
            The scene has :class:`~physcore.Contacts` and ``dt`` is more than twice
            :meth:`auto_dt` (checked once per ``dt`` value): the collisions would be wrong.
        StabilityWarning
            ``dt`` is above a grid's stability limit (:attr:`Wave.cfl_limit`,
            :attr:`GrayScott.diffusion_limit`): the grid's field will grow without bound; or,
            with an explicit fixed-step integrator (``"euler"``, ``"semi_implicit_euler"``,
            ``"verlet"``: stable while ω·dt < h = 2; ``"rk4"``: 2√2; ``"yoshida4"``: 1.5734),
            ``dt`` is over 4h × :meth:`auto_dt`: past the stability interval of the stiffest
            spring or drag for certain (auto_dt's ω is a Gershgorin bound, at most twice the
            true one, so a dt just past the interval may go unwarned), over 8× a fluid's CFL
            step (Verlet), or over 4 closest free-fall times. The motion is then wrong or grows
            without bound. Scenes with contacts or grids are checked by their own rules above.
            Checked once per ``dt`` value.
        UnchargedWarning
            A term acts on charges (:class:`Coulomb`, :class:`ElectricField`, ...) and no
            particle has one, so it does nothing (checked once after each change of the terms
            or attributes).
        """
        n = _check_int(n, "n", 0)
        if n > _MAX_STEPS - self.step_count:
            raise InvalidInputError(f"n: {n} more steps would take the step count past 2**63 - 1 (it is {self.step_count})")
        self._check_dfsph_step(self.dt, "dt")
        self._to_device()
        with self._books_reference("step"):
            self.warn_contact_step()
            self._warn_grid_step()
            self._warn_unstable_step()
            self._warn_uncharged()
            self._exclusive(lambda sim: sim.step(n))

    @property
    def device(self) -> str:
        """Where the particles are stepped: ``"cpu"``, ``"gpu"`` or ``"gpu:NAME"`` (see the
        constructor). A scene made with ``device="auto"`` says ``"auto"`` until its first step
        and then what was chosen (``"cpu"`` or ``"gpu:NAME"``; :attr:`device_reason` says why)."""
        return self._device

    @property
    def device_reason(self) -> str | None:
        """Why ``device="auto"`` chose :attr:`device` (the cost model's estimate of a step on
        each, or what kept the scene on the CPU); None for any other device and before the
        first step."""
        return self._device_reason

    def _to_device(self) -> None:
        """Moves the particles and terms to the GPU before the first step of a GPU scene,
        refusing by name any part the GPU path has no kernel for (nothing changes then).
        ``device="auto"`` makes its choice here (:func:`_auto_choice`)."""
        if self._device == "auto":
            self._choose_device()
            return
        if self._device == "cpu" or self._sim.on_device:
            return
        self._check_device_parts()
        self._move_to_device(self._device, self._device_precision)

    def _move_to_device(self, device: str, precision: str) -> None:
        """The core's move, keeping a copy of the particle attributes it takes with it (read by
        :attr:`attributes`, so that a save, a pickle and :meth:`state` keep the charges)."""
        attrs = {k: np.array(v, dtype=np.float64) for k, v in self._sim.attributes().items()}
        quiet_wayland_probe()
        self._exclusive(lambda sim: sim.move_to_device(device, precision))
        self._device_attrs = attrs

    def _choose_device(self) -> None:
        """``device="auto"``: a GPU when every part has a kernel there, a real GPU is present and
        the cost model expects a step there in at most half the CPU's time; else the CPU. A
        failed move (the device's memory, a value f32 cannot hold) raises and leaves the
        scene as it was (still ``"auto"``)."""
        part = self._unsupported_part()
        fluid = next((p for p in self._parts if p.section == "terms" and p.part_kind == "fluid"), None)
        grains = next((p for p in self._parts if p.section == "terms" and p.part_kind == "contacts"), None)
        if part is not None:
            device = "cpu"
            why = f"{type(part).__name__} {getattr(part, 'name', None) or type(part).__name__!r} has no GPU kernel yet (device='auto')"
        elif fluid is not None:
            device = "cpu"
            why = ("the fluids' GPU path has not been timed on a GPU yet, so device='auto' keeps the fluid on the CPU "
                   "(device='gpu' runs it there)")
        elif grains is not None:
            device = "cpu"
            why = ("the grains' (DEM) GPU path has not been timed on a GPU yet, so device='auto' keeps them on the CPU "
                   "(device='gpu' runs them there)")
        else:
            threads = self._threads if self._threads is not None else _core.default_threads()
            device, why = _auto_choice(_auto_work(self._parts, self.n_particles), threads,
                                       gpu_adapters(), self._auto_precision)
        if device == "cpu":
            self._device, self._device_reason = "cpu", why
            return
        precision = self._auto_precision or "f32"
        self._sim.single = False
        try:
            self._move_to_device(device, precision)
        except BaseException:
            self._sim.single = self._auto_precision == "f32"
            raise
        self._device, self._device_precision, self._device_reason = device, precision, why

    def _unsupported_part(self) -> Part | None:
        """The first part the GPU path has no kernel for, or None."""
        for part in self._parts:
            ok = ((part.section == "terms" and part.part_kind in _GPU_TERMS)
                  or (part.section == "terms" and part.part_kind == "fluid" and getattr(part, "method", None) in ("wcsph", "dfsph"))
                  or (part.section == "terms" and part.part_kind == "contacts")
                  or (part.section == "grids" and part.part_kind in _GPU_GRIDS)
                  or part.section in _GPU_COLLIDERS
                  or (part.section == "colliders" and part.part_kind in _GPU_SHAPES))
            if not ok:
                return part
        return None

    def _check_device_parts(self) -> None:
        """Refuses by name a part the GPU path has no kernel for (a GPU scene not yet moved)."""
        if self._device in ("cpu", "auto") or self._sim.on_device:
            return
        part = self._unsupported_part()
        if part is not None:
            what = getattr(part, "name", None) or type(part).__name__
            raise InvalidInputError(
                f"device={self._device!r}: the GPU path has no kernel for {type(part).__name__} {what!r} yet "
                f"(it has the terms {', '.join(_GPU_TERMS)}, a WCSPH or DFSPH Fluid in a Box, Contacts between grains with walls of any shape, Plane, Box, Sphere, Capsule and OrientedBox colliders and the grids {', '.join(_GPU_GRIDS)}); "
                "run this scene with device='cpu' (or 'auto', which chooses the CPU for it)"
            )

    def to_device(self, *, check_only: bool = False) -> None:
        """Moves a GPU scene's parts to its device now, as its first :meth:`step` does; nothing
        for a CPU scene or one already there. What steps the scene's :attr:`session` itself
        (a :class:`~physcore.Batch`) calls it first. ``check_only=True`` only checks that the
        device has a kernel for every part (a batch checks all its members before any moves).

        Raises
        ------
        InvalidInputError
            (a ``ValueError``) A part the GPU path has no kernel for, named; no such device, or
            f64 on an adapter without it (naming ``device``); a value the device's precision
            cannot hold. Nothing changes.
        """
        if check_only:
            self._check_device_parts()
        else:
            self._to_device()  # checks the parts first

    def warn_contact_step(self) -> None:
        """Warn (once per dt value) when a scene with contacts steps at more than twice its
        automatic step: ``Scene``'s default dt is far too long for stiff contacts. :meth:`step`
        calls it; so does whatever steps the scene's :attr:`session` itself (a Batch).

        Warns
        -----
        ContactStepWarning
            As :meth:`step` describes.
        """
        if self._step_checked == self.dt or not any(isinstance(t, Contacts) for t in self.terms):
            return
        self._step_checked = self.dt
        limit = self._exclusive(lambda sim: sim.auto_dt())
        if limit is not None and self.dt > 2.0 * limit:
            warnings.warn(
                f"dt: {self.dt:.3g} s is {self.dt / limit:.0f}x the step this scene's contacts need "
                f"({limit:.3g} s, a 50th of a contact): collisions will be wrong; use scene.advance(), "
                "or scene.dt = scene.suggest_dt()",
                ContactStepWarning,
                stacklevel=3,
            )

    def _check_dfsph_step(self, h: float, arg: str) -> None:
        """InvalidInputError naming `arg` where a step of `h` s is too short for a DFSPH fluid of
        the scene (:data:`_DFSPH_MIN_DT`); nothing has changed."""
        if h < _DFSPH_MIN_DT and any(f.method == "dfsph" for f in self.fluids):
            raise InvalidInputError(
                f"{arg}: a step of {h:.3e} s is too short for a DFSPH fluid: its density solve divides by "
                f"dt² (Bender & Koschier 2017), which float64 holds for steps of {_DFSPH_MIN_DT:g} s or more"
            )

    def _warn_grid_step(self) -> None:
        """Warn (StabilityWarning, once per dt value) when dt is above a grid's stability limit."""
        if self._grid_step_checked == self.dt:
            return
        self._grid_step_checked = self.dt
        for g in self.grids:
            for attr, what in (("cfl_limit", "CFL limit spacing/(c*sqrt(dim))"),
                               ("diffusion_limit", "explicit diffusion limit dx^2/(2*dim*max(D))")):
                limit = getattr(g, attr, None)
                if limit is not None and self.dt > limit:
                    ratio = self.dt / limit if limit > 0 else math.inf  # a limit may underflow to 0
                    warnings.warn(
                        f"dt: {self.dt:.3g} s is {ratio:.3g}x the {what} = {limit:.3g} s of grid {g.name!r}: "
                        "the scheme is unstable there and the field will grow without bound; "
                        "use scene.advance(), or scene.dt = scene.suggest_dt()",
                        StabilityWarning,
                        stacklevel=3,
                    )

    #: ω dt at which each fixed-step explicit integrator loses stability on an undamped
    #: oscillation (tests/integrators/test_stability_limits.py derives each): Verlet and
    #: semi-implicit Euler 2, RK4 2√2, Yoshida's composition 1.5734 (Yoshida 1990, its middle
    #: substep runs backwards). Explicit Euler grows at every dt; it is warned where the
    #: symplectic ones fail. Not warned: implicit Euler and XPBD (stable at any dt on what they
    #: take implicitly), dopri5 (picks its own steps), Wisdom–Holman (takes the central body's
    #: pull exactly, so a free fall is no limit on it) and Boris (its gyration is a rotation,
    #: stable at any ω_c dt, so a magnetic field's time scale is no limit on it).
    _STABILITY_INTERVAL = {
        "euler": 2.0, "semi_implicit_euler": 2.0, "verlet": 2.0, "rk4": 2.0 * math.sqrt(2.0), "yoshida4": 1.5734019474,
    }

    def _warn_unstable_step(self) -> None:
        """Warn (StabilityWarning, once per dt value) when a fixed-step explicit integrator's dt
        is over 4h x :meth:`auto_dt` (h in :attr:`_STABILITY_INTERVAL`): ω·dt > 2h for the
        Gershgorin bound ω = 1/(2 auto_dt) of the stiffest spring or drag, which is at most twice
        the true ω_max, so such a dt is past the stability interval for certain (a dt between h
        and 2h of it may be too, unwarned); or 8x a fluid's CFL step (Verlet); or 4 closest
        free-fall times, where an orbit is not resolved. Scenes with contacts or grids have
        their own warnings."""
        if self._stable_step_checked == self.dt:
            return
        self._stable_step_checked = self.dt
        h = self._STABILITY_INTERVAL.get(self.integrator)
        if h is None or self.grids or self.n_particles == 0 or any(isinstance(t, Contacts) for t in self.terms):
            return
        limit = self._exclusive(lambda sim: sim.auto_dt())
        if limit is not None and self.dt > 4.0 * h * limit:
            warnings.warn(
                f"dt: {self.dt:.3g} s is {self.dt / limit:.3g}x auto_dt() = {limit:.3g} s: with {self.integrator!r} that is past "
                "the stability limit of this scene's stiffest spring or drag, several times a fluid's CFL step, or too "
                "long for its closest free fall: the motion will be wrong or grow without bound; use scene.advance(), or "
                "scene.dt = scene.auto_dt()",
                StabilityWarning,
                stacklevel=3,
            )

    def _warn_uncharged(self) -> None:
        """Warn (UnchargedWarning) when a term acts on charges and no particle has one: such a
        term then does nothing, silently. Once after each change of the terms or attributes."""
        if self._charge_checked:
            return
        self._charge_checked = True
        from .potentials import PointCharges
        from .terms.charges import Coulomb, ElectricField, GridElectricField, GridMagneticField, MagneticField

        on_charge = (Coulomb, ElectricField, MagneticField, GridElectricField, GridMagneticField, PointCharges)
        users = [t for t in self.terms if isinstance(t, on_charge) or getattr(t, "coupling", None) == "charge"]
        if not users:
            return
        try:
            q = self.attributes.get("charge")
        except MemoryError:  # no room for a copy of the charges now: the step goes on unwarned
            return
        if q is None or not np.any(q):
            names = ", ".join(dict.fromkeys(type(t).__name__ for t in users))
            warnings.warn(
                f"{names}: no particle has a charge ({'no charge attribute' if q is None else 'every charge is 0'}), "
                "so it exerts no force; set them with scene.set_attribute('charge', q) (C)",
                UnchargedWarning,
                stacklevel=3,
            )

    def advance(self, duration: float, *, substeps: str | int = "auto") -> int:
        """Advance ``duration`` seconds in ``n`` substeps and return ``n``; sets :attr:`dt` to
        ``duration / n`` (equal substeps; with a DFSPH fluid, see below, the last substep).

        With ``substeps="auto"`` (default) ``n = ⌈duration / auto_dt⌉``, where ``auto_dt``
        (:meth:`auto_dt`) keeps every substep inside the stability region of the scene's
        integrator at the start of the call: a quarter of its stability interval on the
        imaginary axis over the fastest angular frequency ω_max in the scene (ω·dt = 0.5 for
        semi-implicit Euler and Verlet, stable to 2; 0.71 for RK4, stable to 2√2), and never
        above a term's own limit (the fluid CFL condition). ``"implicit_euler"`` is stable at any
        step on the terms it takes implicitly (springs, drag): on those it gets 20× that step,
        ω_max·dt = 10, a choice of accuracy (see docs/guide/integrators.md), and 0.5 on the others;
        ``"xpbd"`` takes its compliant distance and pin constraints alike, ω_max·h = 10 per
        substep ``h = dt/xpbd_substeps`` (XPBD damps them as implicit Euler would: see
        :class:`XpbdConstraints`). ``"dopri5"`` controls its own internal
        steps, so it takes one substep per call unless a CFL limit asks for more. With a DFSPH
        fluid (``Fluid(method="dfsph")``) the limit follows the flow's speed, not a sound speed,
        so it is taken anew before every substep: the substeps are then unequal (the last ends
        the duration exactly) and ``dt`` is left at the last one. An int gives that many
        substeps. The count chosen is returned (the CLI and ``render.gif`` show it).

        Raises
        ------
        TypeError
            ``duration`` not a number, ``substeps`` not "auto" or an int (bools are neither).
        InvalidInputError
            (a ``ValueError``) ``duration`` not finite or below 2.2e-308 s (the smallest normal
            float64); ``substeps`` not in 1..2**53 or giving substeps below 2.2e-308 s; automatic
            substeps above 1e12 per call.
        SimulationDiverged, KeyboardInterrupt
            As for :meth:`step`; ``dt`` is rolled back too.

        Warns
        -----
        UnchargedWarning
            As for :meth:`step`.
        """
        if isinstance(duration, bool) or not isinstance(duration, (int, float, np.integer, np.floating)):
            raise InvalidTypeError(f"duration: expected a number of seconds, got {type(duration).__name__}")
        duration = _check.real("duration", duration)
        # As for dt: a subnormal duration would become a step with no finite reciprocal.
        if not (math.isfinite(duration) and duration >= _MIN_DT):
            raise InvalidInputError(f"duration: must be > 0 and finite (at least {_MIN_DT:.3g} s, the smallest normal float64), got {duration}")
        if isinstance(substeps, str):
            if substeps != "auto":
                raise InvalidInputError(f"substeps: must be 'auto' or an int >= 1, got {substeps!r}")
            fixed = None
        else:
            fixed = _check_int(substeps, "substeps", 1, _MAX_SUBSTEPS)
            if not duration / fixed >= _MIN_DT:
                raise InvalidInputError(
                    f"substeps: {fixed} substeps of {duration:.3e} s would each last {duration / fixed:.3e} s, below float64's normal range"
                )
            if fixed > _MAX_STEPS - self.step_count:
                raise InvalidInputError(f"substeps: {fixed} more steps would take the step count past 2**63 - 1 (it is {self.step_count})")
        # A substep is at most the duration, a fixed one exactly duration / substeps.
        self._check_dfsph_step(duration if fixed is None else duration / fixed, "duration" if fixed is None else "substeps")
        self._to_device()
        with self._books_reference("advance"):
            self._warn_uncharged()
            return int(self._exclusive(lambda sim: sim.advance(duration, fixed)))

    def auto_dt(self) -> float:
        """The substep (s) ``advance(duration)`` would take now with ``substeps="auto"`` (before
        rounding to a whole number of substeps per call): see :meth:`advance`. ``inf`` for
        ``"dopri5"`` without a CFL limit; the current :attr:`dt` for a scene with no time scale
        (free flight, uniform gravity only)."""
        d = self._exclusive(lambda sim: sim.auto_dt())
        if d is not None:
            return float(d)
        return math.inf if self.integrator == "dopri5" else self.dt

    def _set_reference_energy(self) -> None:
        self._session.take_reference_energy()

    @contextlib.contextmanager
    def _books_reference(self, call: str) -> Iterator[None]:
        """Within: the stepping of `call` ("step", "advance"). The books' reference is taken
        first if there is none (a refusal of its memory is `call`'s), and dropped again if the
        block fails: a failed first call is undone whole (the scene's file as before)."""
        fresh = self._e0 is None
        if fresh:
            with allocating(call, "the energy books' reference", rename=("energy",)):
                self._set_reference_energy()
        try:
            yield
        except SceneBusyError:
            raise  # another thread's call, whose reference this is
        except BaseException:
            if fresh:
                self._e0 = None
            raise

    # ---------------------------------------------------------------- state
    @property
    def dim(self) -> int:
        """Spatial dimension, 2 or 3."""
        return self._sim.dim

    @property
    def n_particles(self) -> int:
        return self._sim.n_particles

    @property
    def time(self) -> float:
        """Simulated time, s."""
        return self._sim.time

    @property
    def step_count(self) -> int:
        """Steps taken since the scene was built."""
        return self._sim.step_count

    @property
    def dt(self) -> float:
        """Time step, s. Settable."""
        return self._sim.dt

    @dt.setter
    def dt(self, value: float) -> None:
        self._sim.dt = _check_dt(value)

    @property
    def integrator(self) -> str:
        """Integrator name (a str, also where the scene was made with a record). Settable to a
        name (see :data:`INTEGRATORS`; an old name, ``"rk45"``, is taken with a
        DeprecationWarning and reads back as the new one, ``"dopri5"``) or to an integrator record,
        which also sets its options (``scene.integrator = pc.Dopri5(rtol=1e-8)`` is
        ``scene.integrator = "dopri5"; scene.rtol = 1e-8; scene.atol = 1e-9``)."""
        return self._sim.integrator

    @integrator.setter
    def integrator(self, value: str | Integrator) -> None:
        name = _check_integrator(value)
        # The device keeps the integrator it was given at the first step: another one set
        # afterwards would be read back but never run.
        if name != self.integrator and self._device != "cpu" and self._sim.on_device:
            raise InvalidInputError(f"integrator: the particles are on the GPU, stepped by {self.integrator!r} since the "
                                    f"first step; set the integrator before it (got {name!r})")
        self._sim.integrator = name
        if isinstance(value, Integrator):  # its options, checked when it was made
            for kw, v in value.options().items():
                setattr(self, kw, v)

    @property
    def rtol(self) -> float:
        """Relative tolerance of ``"dopri5"``. Settable; see the class docstring."""
        return self._sim.tolerances[0]

    @rtol.setter
    def rtol(self, value: float) -> None:
        self._sim.set_tolerances(_check_tol(value, "rtol"), self.atol)

    @property
    def atol(self) -> float:
        """Absolute tolerance of ``"dopri5"`` (m for positions, m/s for velocities). Settable."""
        return self._sim.tolerances[1]

    @atol.setter
    def atol(self, value: float) -> None:
        self._sim.set_tolerances(self.rtol, _check_tol(value, "atol"))

    @property
    def xpbd_substeps(self) -> int:
        """Substeps per step of ``"xpbd"`` (see the class docstring). Settable."""
        return int(self._sim.substeps[0])

    @xpbd_substeps.setter
    def xpbd_substeps(self, value: int) -> None:
        self._sim.set_substeps(check_xpbd_substeps(value), self.xpbd_iterations)

    @property
    def xpbd_iterations(self) -> int:
        """Constraint iterations per substep of ``"xpbd"``. Settable."""
        return int(self._sim.substeps[1])

    @xpbd_iterations.setter
    def xpbd_iterations(self, value: int) -> None:
        self._sim.set_substeps(self.xpbd_substeps, check_xpbd_iterations(value))

    @property
    def wh_coordinates(self) -> str:
        """The coordinates of ``"wisdom_holman"``'s split (see :class:`WisdomHolman`). Settable;
        a change takes effect at the next step."""
        return str(self._sim.wh_coordinates)

    @wh_coordinates.setter
    def wh_coordinates(self, value: str) -> None:
        self._sim.set_wh_coordinates(check_wh_coordinates(value))

    @property
    def wh_corrector(self) -> int:
        """The order of ``"wisdom_holman"``'s symplectic corrector, 0 for none (see
        :class:`WisdomHolman`). Settable; a change takes effect at the next call."""
        return int(self._sim.wh_corrector)

    @wh_corrector.setter
    def wh_corrector(self, value: int) -> None:
        self._sim.set_wh_corrector(check_wh_corrector(value))

    @property
    def precision(self) -> str:
        """``"f64"`` or ``"f32"``: the precision of the stored state (set in the constructor; on
        a GPU, of the device's state and arithmetic)."""
        if self._device not in ("cpu", "auto"):
            return self._device_precision
        return "f32" if self._sim.single else "f64"

    @property
    def cg_tol(self) -> float:
        """Relative residual at which ``"implicit_euler"``'s conjugate gradients stop, in [1e-14, 1)."""
        return float(self._sim.solver_options[0])

    @cg_tol.setter
    def cg_tol(self, value: float) -> None:
        self._sim.set_solver_options(_check_tol(value, "cg_tol"), self.cg_max_iter)

    @property
    def cg_max_iter(self) -> int:
        """Iteration limit of ``"implicit_euler"``'s conjugate gradients, 1..1000000."""
        return int(self._sim.solver_options[1])

    @cg_max_iter.setter
    def cg_max_iter(self, value: int) -> None:
        self._sim.set_solver_options(self.cg_tol, check_cg_max_iter(value))

    @property
    def integrator_stats(self) -> dict[str, Any] | None:
        """For ``"dopri5"``: ``{"accepted", "rejected", "next_step"}`` — internal steps accepted and
        rejected so far by the step-size controller, and the internal step (s) it will try next.

        For ``"implicit_euler"``: ``{"cg_solves", "cg_iterations", "cg_max_iterations",
        "cg_unconverged", "cg_worst_residual"}`` — linear solves (one per step), conjugate-gradient
        iterations in all (one Jacobian product each), the most in one solve, the solves that
        stopped at ``cg_max_iter`` above ``cg_tol`` (their step keeps the last iterate), and the
        largest relative residual a solve ended with. They count every solve since the integrator
        was set, including those of calls later rolled back (divergence, Ctrl-C).

        ``None`` for the other integrators."""
        cg = self._sim.solver_stats()
        if cg is not None:
            return {
                "cg_solves": int(cg[0]),
                "cg_iterations": int(cg[1]),
                "cg_max_iterations": int(cg[2]),
                "cg_unconverged": int(cg[3]),
                "cg_worst_residual": float(cg[4]),
            }
        st = self._sim.adaptive_stats()
        if st is None:
            return None
        return {"accepted": int(st[0]), "rejected": int(st[1]), "next_step": float(st[2])}

    @property
    def integrator_info(self) -> dict[str, Any]:
        """``{"name", "order", "symplectic", "force_evals_per_step"}`` of the current integrator."""
        return dict(self._sim.integrator_info())

    @property
    def threads(self) -> int | None:
        return self._threads

    @property
    def force_evaluations(self) -> int:
        """Force evaluations so far (the cost unit of the work-precision tables)."""
        return self._sim.force_evaluations

    @property
    def positions(self) -> np.ndarray:
        """Positions, m: ``(N, dim)`` float64 (float32 with ``precision="f32"``), a copy.
        Assigning validates and replaces them."""
        x = self._sim.positions
        return x.astype(np.float32) if self._sim.single else x

    @positions.setter
    def positions(self, value: np.typing.ArrayLike) -> None:
        self._sim.set_state(positions=_points(value, "positions", self.dim, self.n_particles, precision=self.precision))
        self._e0 = None

    @property
    def velocities(self) -> np.ndarray:
        """Velocities, m/s: ``(N, dim)`` float64, a copy. Assigning validates and replaces them
        (pinned particles stay at rest). float32 with ``precision="f32"``."""
        v = self._sim.velocities
        return v.astype(np.float32) if self._sim.single else v

    @velocities.setter
    def velocities(self, value: np.typing.ArrayLike) -> None:
        self._sim.set_state(velocities=_points(value, "velocities", self.dim, self.n_particles, precision=self.precision))
        self._e0 = None

    @property
    def masses(self) -> np.ndarray:
        """Masses, kg: ``(N,)`` float64 copy."""
        return self._sim.masses

    @property
    def pinned(self) -> np.ndarray:
        """``(N,)`` bool copy: which particles are pinned."""
        return self._sim.pinned

    @property
    def attributes(self) -> dict[str, np.ndarray]:
        """The optional per-particle attributes set so far (see :meth:`set_attribute`): name ->
        ``(N,)`` float64 copy. On the GPU path, those the particles took to the device (they
        cannot change there)."""
        if self._device_attrs is not None and self._sim.on_device:
            return {k: v.copy() for k, v in self._device_attrs.items()}
        return dict(self._sim.attributes())

    def set_attribute(self, name: str, values: np.typing.ArrayLike) -> None:
        """Set an optional per-particle attribute, one value per particle: ``"charge"`` (C,
        read by :class:`~physcore.terms.ElectricField`) or ``"radius"`` (m, ≥ 0). A scene pays
        for an attribute only once it is set; particles added later hold 0 until it is set
        again. Saved and loaded with the scene.

        Parameters
        ----------
        name : str
            ``"charge"`` or ``"radius"``.
        values : array_like, shape (N,)
            Finite numbers in the attribute's SI unit.

        Raises
        ------
        TypeError
            ``name`` is not a str, or ``values`` is not numeric.
        InvalidInputError
            (a ``ValueError``) unknown ``name``, wrong length, a non-finite value, a negative
            radius or one below float64's normal range (not 0). Nothing changes.
        """
        if not isinstance(name, str):
            raise InvalidTypeError(f"name: expected a str, got {type(name).__name__}")
        _check.text("name", name)
        a = _check.real_array(name, values, sized=False)  # its length is checked before the copy
        if a.ndim != 1:
            one = " (one value per particle; a scalar is not broadcast: np.full(scene.n_particles, v))" if a.ndim == 0 else ""
            raise InvalidInputError(f"{name}: expected shape ({self.n_particles},), got {a.shape}{one}")
        if a.shape[0] != self.n_particles:  # before the copy: it may not fit in memory
            raise InvalidInputError(f"{name}: has {a.shape[0]} entries, the scene has {self.n_particles} particles")
        with allocating("set_attribute", f"a copy of {name}"):
            a = np.ascontiguousarray(a, dtype=np.float64)
        if name == "radius":  # a subnormal radius's r² (a ball's inertia) underflows: a spin of inf
            tiny = np.flatnonzero((a > 0) & (a < _check.MIN_NORMAL))
            if tiny.size:
                raise InvalidInputError(f"radius: entry {int(tiny[0])} is {a[tiny[0]]} m, below float64's normal range "
                                        f"(a radius is 0 or at least {_check.MIN_NORMAL:.3g} m)")
        self._exclusive(lambda sim: sim.set_attribute(name, a))
        self._e0 = None  # the potential of charge-dependent terms changed
        self._charge_checked = False

    def _section(self, section: str) -> list[Any]:
        """The parts of one section of the scene file, in the order added."""
        return [p for p in self._parts if p.section == section]

    @property
    def terms(self) -> tuple[Term, ...]:
        """The force terms, in the order added (names resolved)."""
        return tuple(self._section("terms"))

    @property
    def planes(self) -> list[Plane]:
        """The plane colliders, with the faces of :class:`Box` colliders as planes (a new list)."""
        return self._section("planes") + [f for b in self._section("boxes") for f in b.faces()]

    @property
    def boxes(self) -> list[Box]:
        """The box colliders (a copy of the list)."""
        return self._section("boxes")

    @property
    def spheres(self) -> list[Sphere]:
        """The sphere colliders (a copy of the list)."""
        return self._section("spheres")

    @property
    def colliders(self) -> list[Any]:
        """Every collider record, one list (a new one): the :class:`Plane`, :class:`Box` and
        :class:`Sphere` records, then those registered by key (:class:`~physcore.Capsule`,
        :class:`~physcore.OrientedBox`, ...), each kind in the order added. The order of the
        scene file's sections, so a loaded copy lists them alike. A box is listed as itself (in
        :attr:`planes` as its faces)."""
        return [p for section in COLLIDER_SECTIONS for p in self._section(section)]

    def spring_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(i, j, rest_length)`` of all springs of all :class:`Springs` terms: int64 (M,),
        int64 (M,), float64 (M,) in m."""
        springs = [t for t in self.terms if isinstance(t, Springs)]
        if not springs:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        return (
            np.concatenate([s.i for s in springs]),
            np.concatenate([s.j for s in springs]),
            np.concatenate([np.asarray(s.rest_length) for s in springs]),
        )

    # ---------------------------------------------------------------- diagnostics
    def energy(self) -> EnergyReport:
        """The energy books now (computed in Rust; pairwise gravity costs O(N²)).

        A part beyond float64 (huge masses or speeds) is reported as it comes out, ``±inf`` or
        NaN, not clamped; :meth:`energy_drift` is then NaN."""
        d = self._exclusive(lambda sim: sim.energy())
        pot = dict(d["potential"])
        dis = dict(d["dissipated"])
        mech = d["kinetic"] + left_sum(pot.values())
        return EnergyReport(d["kinetic"], pot, dis, mech + left_sum(dis.values()), mech)

    def energy_drift(self) -> float:
        """Relative change of ``energy().total`` since the first step (0 before any step).

        ``(E - E0) / max(|E0|, S0, S)`` where ``S0``, ``S`` are the sums of the magnitudes of the
        books' parts (kinetic, each potential, each dissipated) at the start and now: the change
        relative to the energy in play, which stays meaningful where ``E0`` is zero or near it
        by the choice of potential reference (a cloth at rest, an unbound pair). Where the books
        hold only kinetic energy this is ``(E - E0) / |E0|``; where potential and kinetic
        energy offset each other it is smaller. A bound orbit's scale is ``K + |U|``: a Kepler
        orbit of eccentricity e started at pericentre reads ``(1 - e) / (3 + e)`` of the
        conventional relative energy error ``(E - E0) / |E0|`` of N-body codes (REBOUND's), a
        circular one 1/3. For that error, read ``E0 = scene.energy().total`` before the first
        step and compare ``(scene.energy().total - E0) / abs(E0)``.

        NaN when the books at the start or now are not finite (e.g. ``½ m v²`` or ``G m² / r``
        beyond float64 for masses near 1e308): the drift is then unknown, never reported as 0.
        The trajectory itself may still be fine; :meth:`energy` shows which part overflowed.
        """
        if self._e0 is None:
            return 0.0
        return drift(self._session.reference_energy, *books(self._exclusive(lambda sim: sim.energy())))

    def momentum(self) -> np.ndarray:
        """Linear momentum ``Σ m v`` of free particles, kg·m/s: (dim,) float64."""
        return self._sim.momentum()

    def angular_momentum(self) -> float | np.ndarray:
        """Angular momentum ``Σ m x × v`` about the origin of free particles, plus the spins of
        grains under :class:`~physcore.Contacts` (``Σ I ω``), kg·m²/s: a float (the z
        component) in 2D, a (3,) float64 array in 3D."""
        am = self._sim.angular_momentum()
        return float(am[2]) if self.dim == 2 else am

    def contact_count(self) -> int:
        """Contacts between grains (pairs counted once) and between grains and walls at the
        last force evaluation, over every :class:`~physcore.Contacts` term (0 without one)."""
        return int(sum(v for _, key, v in self._sim.term_counts() if key == "contacts"))

    def particle_field(self, name: str) -> np.ndarray:
        """A per-particle quantity a term computes, ``(N,)`` float64 (0 for particles the term
        does not cover): the :class:`~physcore.Contacts` term's ``"angular_velocity"`` (rad/s,
        2D; ``"angular_velocity_x"``, ``"_y"``, ``"_z"`` in 3D), ``"angle"`` (rad, 2D) and
        ``"coordination"`` (contacts per grain); a fluid's ``"density"`` and ``"pressure"``.

        Raises
        ------
        ValueError
            ``name`` is not a field of any term of this scene (the message lists those that are).
        """
        known: list[str] = []
        for t in self.terms:
            names = ("density", "pressure") if isinstance(t, Fluid) else getattr(t, "particle_fields", lambda dim: ())(self.dim)
            known.extend(f for f in names if f not in known)
        if not isinstance(name, str) or name not in known:
            raise InvalidInputError(f"name: {name!r} is not a field of this scene's terms; known: {', '.join(known) or 'none'}")
        return self._exclusive(lambda sim: sim.particle_fields([name]))[0]

    def density(self) -> np.ndarray:
        """SPH density of every particle now, kg/m³ (kg/m² in 2D): ``(N,)`` float64, 0 for
        particles in no fluid (computed in float64)."""
        return self._exclusive(lambda sim: sim.fluid_fields())[0]

    def pressure(self) -> np.ndarray:
        """Pressure of every particle now, Pa: ``(N,)`` float64, 0 for particles in no fluid
        (computed in float64).

        A WCSPH fluid's is its equation of state's (Tait). A DFSPH fluid's is what the last
        step's two solves applied, ``ρ² (κ + κ^v)`` (Bender & Koschier 2017, eq. 10–11), plus
        the surface forces' virial with surface tension: a Lagrange multiplier of the
        incompressibility, not a function of the density, and it swings from step to step
        (a resting 24 × 24 layer at the default ``density_error`` 0.1 %: a bin's mean goes from 0
        to 6 times the hydrostatic value and back, a cycle of about 15 steps; at 0.01 %,
        0.35–1.74 times; at 0.001 %, within 8 %). Average it over every step, not every few
        steps (which aliases the cycle): so averaged, and pooled over 16 realizations, the
        layer's two-row bins are within 1.6 % of ρ0 g (H − y) (``tests/fluids/test_dfsph.py``)."""
        return self._exclusive(lambda sim: sim.fluid_fields())[1]

    def solver_stats(self, name: str | None = None) -> dict[str, float]:
        """The pressure solvers' books of a DFSPH fluid (``Fluid(method="dfsph")``), over every step
        this scene object has taken since the fluid was added (including steps later rolled back
        by a divergence or Ctrl-C). They describe this process's solves, not the scene's state: a
        scene loaded from a file or unpickled starts them from zero (its energy books carry on).

        Keys: ``steps``; ``density_iterations`` and ``divergence_iterations`` (totals);
        ``unconverged`` (solves stopped at ``max_iterations`` above tolerance); ``density_error``
        and ``divergence_error`` (the last solves' final mean errors, relative, as the tolerances
        define them) and their ``*_max`` over all steps; ``measured_density_error`` (the mean
        compression ``mean((ρ − ρ0)₊)/ρ0`` by summation at the start of the last step, i.e. what
        the previous density solve achieved) and its max; ``dissipated_density_solver`` and
        ``dissipated_divergence_solver`` (J, kinetic energy each projection removed). DFSPH fluids
        solved together (same ``h``, kernel, density and solver settings) report the same books:
        those of their one solve.

        Raises
        ------
        ValueError
            No DFSPH fluid named ``name`` (by default the scene's DFSPH fluid).
        """
        dfsph = [t.name for t in self.fluids if t.method == "dfsph"]
        if name is None and dfsph:
            name = dfsph[0]
        if name not in dfsph:
            raise InvalidInputError(f"name: {name!r} is not a DFSPH fluid of this scene; DFSPH fluids: {dfsph or 'none'}")
        return {k: float(v) for t, k, v in self._sim.term_stats() if t == name}

    def boundary_points(self) -> np.ndarray:
        """Static wall particles of all fluids, m: ``(M, dim)`` float64 (M may be 0)."""
        walls = [t.boundary for t in self.fluids if t.boundary is not None]
        return np.concatenate(walls) if walls else np.zeros((0, self.dim))

    @property
    def grids(self) -> tuple[Grid, ...]:
        """The grid systems, as added."""
        return tuple(self._section("grids"))

    @property
    def bodies(self) -> tuple[Any, ...]:
        """The :class:`~physcore.Bodies` groups of the scene (rigid bodies), in the order added."""
        from .bodies import Bodies

        return tuple(p for p in self._section("bodies") if isinstance(p, Bodies))

    @property
    def flows(self) -> tuple[Flow, ...]:
        """The :class:`~physcore.flows.Flow` systems of the scene, in the order added."""
        return tuple(self._section("flows"))

    @property
    def fluids(self) -> tuple[Fluid, ...]:
        """The fluids, as added (with ``first`` and ``sound_speed`` resolved): the terms that
        own a run of the scene's particles."""
        return tuple(t for t in self._section("terms") if type(t).owns_particles)

    def suggest_dt(self) -> float:
        """Half of the fastest time scale of the scene's terms, s (springs: 1/ω_max and, with
        dashpots, 1/λ_max = m/(2 Σc), both from Gershgorin bounds; pairwise gravity: closest
        free-fall time, an O(N²) sum computed only up to 2·10⁴ bodies and left out above; drag:
        m/b); the current dt if no term has one. Explicit integrators are stable at this dt;
        pairwise gravity can later reach shorter time scales than now."""
        return self._exclusive(lambda sim: sim.suggest_dt())

    # ---------------------------------------------------------------- persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write the whole scene to a ``.npz`` file, atomically (temporary file, then rename).

        Continuing a loaded scene reproduces the uninterrupted run bit for bit (the velocity
        Verlet force cache, the dopri5 step-size controller and the energy books are saved too).
        A scene on a GPU is read back for it (positions, velocities, the books, a grid's fields)
        and its device's own rows saved with it: :meth:`load` opens that device again and
        continues bit for bit, or continues on the CPU with ``device="cpu"``.
        The layout is described in ``physcore/_scenefile.py``. An energy-drift baseline that
        overflowed float64 is not saved (the loaded scene takes a new one at its next step).

        Raises
        ------
        TypeError
            ``path`` is not a str or os.PathLike.
        ValueError
            ``path`` does not end in ``.npz``; the energy books are not finite (they overflowed
            float64), so the file could not be loaded back.
        OSError
            The file cannot be written; ``path`` is then left as it was and no temporary file
            remains.
        OutOfMemoryError
            (a ``MemoryError``) The file's arrays (the rigid bodies' solver state: about 1.7 kB
            a body) cannot be had now; ``path`` is left as it was.
        """
        path = _scenefile.check_path(path)
        if path.suffix != ".npz":
            raise InvalidInputError(f"path: must end in .npz, got {str(path)!r}")
        with allocating("save", "the scene file's arrays", rename=_READS):
            arrays = self._file_arrays()
            atomic_write(path, lambda fh: np.savez(fh, **arrays))
        return path

    def state(self) -> dict[str, Any]:
        """A snapshot of everything that changes while the scene runs, for :meth:`set_state`:
        a flat dict of numpy arrays (copies) and scalars, named as the scene file's members.

        What stays fixed (masses, pins, the terms' records, colliders, grid sizes) is not in it;
        a snapshot goes back into the scene it came from, or into one of the same structure
        (:func:`physcore.batch.structure`, same attribute names). Keys:

        ``"time"`` : float
            Simulated time, s.
        ``"step"`` : int
            :attr:`step_count`.
        ``"dt"`` : float
            The time step, s (:meth:`advance` changes it, e.g. with a DFSPH fluid).
        ``"positions"``, ``"velocities"`` : ndarray, (N, dim) float64
            m and m/s (float64 even with ``precision="f32"``: the stored values, exactly).
        ``"attr_{name}"`` : ndarray, (N,) float64
            Each per-particle attribute set (:attr:`attributes`: ``attr_charge`` in C,
            ``attr_radius`` in m).
        ``"ledger"`` : ndarray, (K,) float64
            The energy books' dissipated energy so far, J, one entry per dissipative term.
        ``"collisions"`` : float
            Energy dissipated by the colliders so far, J.
        ``"cache_forces"`` : ndarray (float64) or None; ``"cache_power"`` : ndarray, (P,) float64, or None
            The integrator's cache (velocity Verlet's forces at the current positions, the
            dopri5 step-size controller, ``wisdom_holman``'s corrected state with a corrector:
            2N rows, positions then velocities, and its dt after the powers); None where it
            holds none.
        ``"reference_energy"`` : ndarray, (2,) float64, or None
            The books' reference ``(E0, S0)`` in J (:attr:`Session.reference_energy
            <physcore.session.Session.reference_energy>`); None until the next step takes it.
        ``"{prefix}{k}_{member}"`` : ndarray, float64
            The parts' own state, named as in the scene file (``{prefix}`` is the section's:
            ``term``, ``grid``, ``flow``, ``body``; ``k`` its index in the section):
            ``term{k}_history`` (contacts: particle spins and contact springs; DFSPH: the
            solvers' warm starts), a grid's fields (``grid{k}_u``, ``grid{k}_v``, ...), a flow's
            points and rates (``flow{k}_y``), the rigid bodies' whole solver state
            (``body0_state``, ``body0_state_bytes``: poses, velocities, contacts).

        ``"device_pos"``, ``"device_vel"``, ``"device_acc"``, ``"device_aux"`` : ndarray, (N, 4) float64; ``"device_hits"`` : ndarray, (N,) float64; ``"device_acc_valid"`` : ndarray, (1,) float64
            Only on the GPU path, once the particles are on the device: its rows as it holds
            them (each particle's position and mass, velocity, acceleration, its share of the
            books; the colliders' hits; whether the accelerations are those of the positions),
            as the scene file's ``device_*`` members. There, ``ledger`` and ``collisions`` are
            read from the device's books and ``cache_*`` are None (the device keeps its
            accelerations in its rows).

        Stepping after ``set_state(s)`` repeats, bit for bit, what stepping after ``s = state()``
        did, on the CPU and on the GPU path. The layout is described in
        docs/guide/architecture.md (Saving, checkpoints and the state protocol).

        Raises :class:`OutOfMemoryError` (a ``MemoryError``), naming ``state``, where the
        snapshot's arrays cannot be had now; nothing changes.
        """
        with allocating("state", "the snapshot's arrays", rename=("save", *_READS)):
            return self._snapshot()

    def _snapshot(self) -> dict[str, Any]:
        """:meth:`state`'s dict, unguarded."""
        sim = self._sim
        on_device = self._device != "cpu" and sim.on_device
        out: dict[str, Any] = {
            "time": sim.time,
            "step": sim.step_count,
            "dt": sim.dt,
            "positions": sim.positions,
            "velocities": sim.velocities,
            **{f"attr_{a}": v for a, v in self.attributes.items()},
        }
        ledger, collisions = self._device_books() if on_device else sim.ledger()
        out["ledger"] = np.asarray(ledger, dtype=np.float64)
        out["collisions"] = float(collisions)
        cache = None if on_device else sim.integrator_cache()
        out["cache_forces"] = None if cache is None else cache[0]
        out["cache_power"] = None if cache is None else np.asarray(cache[1], dtype=np.float64)
        ref = self._session.reference_energy
        out["reference_energy"] = None if ref is None else np.array(ref, dtype=np.float64)
        for part, prefix in self._prefixed_parts():
            out.update({f"{prefix}{m}": np.array(v, dtype=np.float64) for m, v in part._state(sim).items()})
        if on_device:
            out.update(self._device_rows())
        return out

    def _device_books(self) -> tuple[list[float], float]:
        """The ledger (each term's dissipated energy) and the collisions of a scene on a GPU,
        read from the device's books (the host keeps none once the terms moved)."""
        dissipated = self.energy().dissipated
        return [float(dissipated.get(t.name, 0.0)) for t in self.terms], float(dissipated.get("collisions", 0.0))

    def _device_rows(self) -> dict[str, np.ndarray]:
        """The device's own rows, named as the scene file's ``device_*`` members (see
        :meth:`state`); {} where no particles are on it."""
        sim = self._sim
        if _DEVICE_PARTICLES not in sim.system_names():
            return {}
        raw = dict(sim.system_save(_DEVICE_PARTICLES))
        rows = {f"device_{k}": np.asarray(raw[k], dtype=np.float64).reshape(-1, 4) for k in ("pos", "vel", "acc", "aux")}
        rows["device_hits"] = np.asarray(raw["hits"], dtype=np.float64)
        rows["device_acc_valid"] = np.asarray(raw["acc_valid"], dtype=np.float64)
        return rows

    def _as_on_device(self, a: np.ndarray) -> np.ndarray:
        """Float64 values as the device holds them: rounded to float32 on an f32 device."""
        return a.astype(np.float32).astype(np.float64) if self.precision == "f32" else a

    def _put_device_state(self, sim: _core.Simulation, s: dict[str, Any]) -> None:
        """:meth:`set_state`'s work on the GPU path (``s`` checked): the device's rows put back,
        with ``positions`` and ``velocities`` written into them (rounded to the device's
        precision), and its accelerations marked stale where either changed, so that the next
        step evaluates the forces first; then the parts, the step and the host's clock."""
        if "device_pos" in s:
            dim = self.dim
            rows = {k: s[f"device_{k}"].copy() for k in ("pos", "vel", "acc", "aux")}
            valid = float(s["device_acc_valid"][0])
            for key, row in (("positions", rows["pos"]), ("velocities", rows["vel"])):
                want = self._as_on_device(s[key])
                if not np.array_equal(row[:, :dim], want):
                    row[:, :dim] = want
                    valid = 0.0
            arrays = [(k, np.ascontiguousarray(rows[k]).reshape(-1)) for k in ("pos", "vel", "acc", "aux")]
            arrays += [("hits", np.ascontiguousarray(s["device_hits"])), ("acc_valid", np.array([valid]))]
            sim.system_load(_DEVICE_PARTICLES, arrays)
        for part, prefix in self._prefixed_parts():
            own = {key[len(prefix):]: v for key, v in s.items() if key.startswith(prefix)}
            if own:
                part._set_state(sim, own)
        sim.dt = s["dt"]
        # The books are the device's, in its rows (`ledger` and `collisions` are what they add
        # up to); the host keeps none once the terms moved, so its clock alone is set here.
        host_ledger, host_collisions = sim.ledger()
        sim.restore(s["time"], s["step"], list(host_ledger), host_collisions, None, None)

    def _prefixed_parts(self) -> Iterator[tuple[Part, str]]:
        """Each part with the prefix of its members, ``{section's prefix}{k}_`` with k counted
        within its section: the scene file's names, which :meth:`state` uses too."""
        count = dict.fromkeys(SECTIONS, 0)
        for part in self._parts:
            k = count[part.section]
            count[part.section] += 1
            yield part, f"{MEMBER_PREFIX[part.section]}{k}_"

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Put back a snapshot taken by :meth:`state` (see there for the keys).

        Every key is checked first (the same keys as this scene's :meth:`state`; each array's
        dtype, shape and finiteness; each scalar's type and range); the core then checks the
        parts' contents, and if it refuses one, the scene is put back as it was before the call.

        Raises
        ------
        TypeError
            ``state`` is not a mapping, or a value is of the wrong type; names the key.
        InvalidInputError
            (a ``ValueError``) A key missing or unknown, an array of the wrong dtype or shape, a
            non-finite number, a scalar out of range; names the key (``state['positions']``).
            Nothing changes.
        """
        if not isinstance(state, Mapping):
            raise InvalidTypeError(f"state: expected a dict from Scene.state(), got {type(state).__name__}")
        now = self.state()
        missing = [k for k in now if k not in state]
        if missing:
            raise InvalidInputError(f"state: missing key {missing[0]!r} (this scene's state has {', '.join(map(repr, now))})")
        extra = [k for k in state if k not in now]
        if extra:
            raise InvalidInputError(f"state[{extra[0]!r}]: not a key of this scene's state (see Scene.state)")
        new = {k: _check_state_value(k, state[k], now[k], self) for k in now}

        on_device = self._device != "cpu" and self._sim.on_device
        if on_device:
            # Attributes live in the device's buffers, uploaded once: a snapshot puts back the
            # ones it was taken with (changing them is not yet on the GPU path).
            for key, v in new.items():
                if key.startswith("attr_") and not np.array_equal(v, now[key]):
                    raise InvalidInputError(f"state[{key!r}]: changing a particle attribute is not yet on the GPU path "
                                            f"(device={self._device!r}); set it before the first step")
            if "device_pos" in new:
                if not np.array_equal(new["device_pos"][:, 3], self._as_on_device(self.masses)):
                    raise InvalidInputError("state['device_pos']: its mass column differs from this scene's masses")

        def put(sim: _core.Simulation, s: dict[str, Any]) -> None:
            if on_device:
                self._put_device_state(sim, s)
                return
            sim.set_state(positions=s["positions"], velocities=s["velocities"])
            for key, v in s.items():
                if key.startswith("attr_"):
                    sim.set_attribute(key[5:], v)
            for part, prefix in self._prefixed_parts():
                own = {key[len(prefix):]: v for key, v in s.items() if key.startswith(prefix)}
                if own:
                    part._set_state(sim, own)
            sim.dt = s["dt"]
            power = s["cache_power"]
            sim.restore(s["time"], s["step"], s["ledger"].tolist(), s["collisions"], s["cache_forces"],
                        None if power is None else power.tolist())

        def apply(sim: _core.Simulation) -> None:
            try:
                put(sim, new)
            except BaseException:
                put(sim, now)  # the core refused a part's contents: back as it was
                raise

        self._exclusive(apply)
        ref = new["reference_energy"]
        self._session.reference_energy = None if ref is None else (float(ref[0]), float(ref[1]))

    def _file_arrays(self) -> dict[str, np.ndarray]:
        """The members of the scene file (see :meth:`save`), ``meta`` included."""
        problem = self._unrecorded()
        if problem is not None:  # the file would not load: refused before anything is written
            raise InvalidInputError(f"scene: its core holds {problem} (an add interrupted by Ctrl-C); a file of it would "
                                    "not load, so none was written. Build the scene again")
        on_device = self._device != "cpu" and self._sim.on_device
        # A file of precision "f32" holds the state as float32: a device's f32 state read back
        # is exact in it (before the first step, the upload would round it so anyway).
        fx = np.float32 if self.precision == "f32" else np.float64
        arrays: dict[str, np.ndarray] = {
            "positions": self.positions.astype(fx, copy=False),
            "velocities": self.velocities.astype(fx, copy=False),
            "masses": self.masses,
            "pinned": self.pinned,
            **{f"attr_{a}": v for a, v in self.attributes.items()},
        }
        # One loop over the parts: each gives its entry and members (physcore._parts); they are
        # grouped by section, each section's members named {prefix}{k}_{member}, in the order
        # of SECTIONS.
        sim = self._sim
        entries: dict[str, list[dict[str, Any]]] = {s: [] for s in SECTIONS}
        members: dict[str, dict[str, np.ndarray]] = {s: {} for s in SECTIONS}
        for part, prefix in self._prefixed_parts():
            entry, own = part._entry(sim)
            entries[part.section].append(entry)
            members[part.section].update({f"{prefix}{a}": v for a, v in own.items()})
        for section in SECTIONS:
            arrays.update(members[section])
        if on_device:
            # The books live on the device: the ledger (each term's dissipated energy) and the
            # collisions read from them, so that the file also continues on the CPU; the device's
            # raw rows (device_*) let a load onto the device continue bit for bit.
            ledger, collisions = self._device_books()
            rows = self._device_rows()
            if rows:
                device_acc_valid = bool(rows.pop("device_acc_valid")[0])  # a flag of the meta
                arrays.update(rows)
        else:
            ledger, collisions = self._sim.ledger()
        arrays["ledger"] = np.asarray(ledger, dtype=np.float64)
        # The loader refuses non-finite books; say so now rather than write a file it refuses.
        for field, v in (("time", [self.time]), ("ledger", ledger), ("collisions", [collisions])):
            if not np.isfinite(v).all():
                raise InvalidInputError(f"{field}: {list(v)} overflowed float64; a scene file holds finite values only, so this scene cannot be saved")
        cache = None if on_device else self._sim.integrator_cache()
        if cache is not None:
            arrays["cache_forces"] = cache[0]
            arrays["cache_power"] = np.asarray(cache[1], dtype=np.float64)
        e0_finite = self._e0 is not None and math.isfinite(self._e0) and math.isfinite(self._e0_scale)
        meta = {
            "format": _scenefile.FORMAT_VERSION,
            "dim": self.dim,
            "integrator": self.integrator,
            "dt": self.dt,
            "rtol": self.rtol,
            "atol": self.atol,
            "cg_tol": self.cg_tol,
            "cg_max_iter": self.cg_max_iter,
            "precision": self.precision,
            "xpbd_substeps": self.xpbd_substeps,
            "xpbd_iterations": self.xpbd_iterations,
            # Where it matters only: other scenes' files keep their bytes (`_scenefile`).
            **({"wh_coordinates": self.wh_coordinates}
               if self.integrator == "wisdom_holman" or self.wh_coordinates != _scenefile.WH_DEFAULT else {}),
            **({"wh_corrector": self.wh_corrector} if self.wh_corrector else {}),
            "threads": self._threads,
            "time": self.time,
            "step": self.step_count,
            "collisions": collisions,
            "e0": self._e0 if e0_finite else None,
            "e0_scale": self._e0_scale if e0_finite else 0.0,
            # "terms", "planes", "boxes", "spheres", "grids", "flows"; "colliders" if it holds one
            **{s: e for s, e in entries.items() if e or s not in OPTIONAL_SECTIONS},
        }
        if self._device != "cpu":
            meta["device"] = self._device
            if "device_pos" in arrays:
                meta["device_acc_valid"] = device_acc_valid
        # float.hex keeps every float bit-exact through JSON.
        arrays["meta"] = np.array(json.dumps(meta, default=float, allow_nan=False))
        arrays["time_hex"] = np.array(float(self.time).hex())
        return arrays

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickling goes through the scene file format (:meth:`save`), held in memory: a scene
        built on one machine continues bit for bit on another (a Dask worker, a process pool),
        and unpickling checks the bytes as strictly as :meth:`load` checks a file. The saved
        thread count travels too (``None``: the receiving process's default), and so do the
        ``render_defaults``. Raises what :meth:`save` raises for books that are not finite, and
        :class:`OutOfMemoryError` as :meth:`to_bytes` does; unpickling raises what
        :meth:`from_bytes` raises."""
        return (_unpickle_scene, (self.to_bytes(), self.render_defaults))

    def to_bytes(self) -> bytes:
        """The scene file :meth:`save` writes, as bytes (no file is written). Raises what
        :meth:`save` raises for books that are not finite, and :class:`OutOfMemoryError` (a
        ``MemoryError``) where the file's arrays or their bytes cannot be had now."""
        with allocating("to_bytes", "the scene file's arrays", rename=("save", *_READS)):
            buf = io.BytesIO()
            np.savez(buf, **self._file_arrays())
            return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes, *, threads: int | None = None, source: str = "<bytes>", device: str | None = None) -> Scene:
        """A scene from the bytes of a scene file (:meth:`to_bytes`, or a file's contents),
        checked as strictly as :meth:`load` checks a file; ``threads`` and ``device`` as for :meth:`load`;
        ``source`` names the bytes in error messages.

        Raises
        ------
        TypeError
            ``data`` is not bytes; ``threads`` is not an int.
        SceneFileError
            (a ``ValueError``) As :meth:`load` raises it, naming ``source`` and the field.
        OutOfMemoryError
            (a ``MemoryError``) As :meth:`load` raises it.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise InvalidTypeError(f"data: expected the bytes of a scene file, got {type(data).__name__}")
        if threads is not None:
            threads = _check_int(threads, "threads", 1)
        if device is not None:
            device = _check_device(device)
        with allocating("load", "the scene file's arrays"):
            return cls._from_file(_scenefile.read_bytes(data, source), threads, device)
    @classmethod
    def load(cls, path: str | os.PathLike, *, threads: int | None = None, device: str | None = None) -> Scene:
        """Read a scene written by :meth:`save`.

        The file is treated as hostile (see ``physcore/_scenefile.py``): every field is checked
        as strictly as the API checks arguments, then the API validates again; object arrays are
        never read, nothing is executed, and the loader allocates no more array memory than the
        file's size (sizes claimed in headers are checked against the bytes present first).

        Parameters
        ----------
        path : str or os.PathLike
            A ``.npz`` file written by :meth:`save`.
        threads : int or None
            Overrides the saved thread count. Without it the saved count is used, capped at the
            number of CPUs this process may use (results do not depend on it, and a file should
            not decide how many threads start); ``None`` saved stays ``None`` (all cores).
        device : str or None
            Where the loaded scene steps (as :class:`Scene`'s ``device``). Without it, where it
            was saved: a scene saved on a GPU opens that device again and continues there bit for
            bit (the device's own rows are in the file, read back at the save). ``"cpu"``
            continues a GPU scene on the CPU from its state read back (positions, velocities,
            books; the velocity Verlet force is evaluated again at the first step, so the run
            differs from the device's in the last bits, and f32 state stays as the device
            rounded it).

        Raises
        ------
        TypeError
            ``path`` is not a str or os.PathLike; ``threads`` is not an int.
        ValueError
            ``threads`` < 1.
        SceneFileError
            (a ``ValueError``) for anything wrong with the file's contents: not a zip, truncated
            or damaged, a member missing, extra, compressed or of the wrong dtype or shape, a
            non-finite number, a field of the wrong type or out of range (``step`` must be an
            integer in [0, 2**63)), or a value the API refuses. The message names the file and
            the field.
        OSError
            The file cannot be opened (missing, no permission).
        OutOfMemoryError
            (a ``MemoryError``) The scene cannot be held in memory now: its parts (named
            ``add``, as :meth:`add` names them), the rigid bodies' solver state (``load``: taken
            as four times its bytes while it is read) or the file's arrays (``load``).
        """
        path = _scenefile.check_path(path)
        if threads is not None:
            threads = _check_int(threads, "threads", 1)
        if device is not None:
            device = _check_device(device)
        with allocating("load", "the scene file's arrays"):
            return cls._from_file(_scenefile.read(path), threads, device)

    @classmethod
    def _from_file(cls, sf: _scenefile.SceneFile, threads: int | None, device: str | None = None) -> Scene:
        meta, z, r = sf.meta, sf.arrays, sf.reader
        device = meta["device"] if device is None else device
        if threads is None and meta["threads"] is not None:
            threads = min(meta["threads"], usable_cpus())
        with r.api("meta"), _quiet_options():
            scene = cls(
                meta["dim"],
                integrator=_check_integrator(meta["integrator"], warn=False),  # old files: "rk45"
                dt=meta["dt"],
                rtol=meta["rtol"],
                atol=meta["atol"],
                cg_tol=meta["cg_tol"],
                cg_max_iter=meta["cg_max_iter"],
                precision=meta["precision"],
                threads=threads,
                xpbd_substeps=meta["xpbd_substeps"],
                xpbd_iterations=meta["xpbd_iterations"],
                wh_coordinates=meta["wh_coordinates"],
                wh_corrector=meta["wh_corrector"],
                device=device,
            )
        if z["positions"].shape[0]:
            with r.api(""):  # the API's argument names are the members' names
                scene.add_particles(z["positions"], z["velocities"], z["masses"], z["pinned"])
        for a, _ in _core.particle_attributes():
            if f"attr_{a}" in z:
                with r.api("", {a: f"attr_{a}"}):
                    scene.set_attribute(a, z[f"attr_{a}"])
        # One loop over the sections, in the order written; each entry is read by its part class,
        # which adds it as Scene.add does (a MemoryError named as Scene.add names it).
        add = allocating("add", "a copy of the item's arrays for the core")(scene._add)
        for section in SECTIONS:
            for k, entry in enumerate(meta.get(section, ())):
                part = entry_class(section, entry)
                prefix = f"{MEMBER_PREFIX[section]}{k}_"
                own = {a[len(prefix):]: z[a] for a in z if a.startswith(prefix)}
                ctx = LoadContext(dim=scene.dim, sim=scene._sim, index=k, field=f"meta.{section}[{k}]", add=add, api=r.api)
                with r.api(*part._load_names(ctx, own)):
                    part._load(ctx, entry, own)
        with r.api("", {"dissipated": "ledger", "cache": "cache_forces/cache_power"}):
            scene._sim.restore(
                sf.time,
                meta["step"],
                z["ledger"].tolist(),
                meta["collisions"],
                z.get("cache_forces"),
                z["cache_power"].tolist() if "cache_power" in z else None,
            )
        if device != "cpu":
            try:
                scene._to_device()
            except InvalidInputError as e:  # no such device here, or a part it lacks
                raise InvalidInputError(f"{e} (the file was saved with device={meta['device']!r}; "
                                        "Scene.load(..., device='cpu') continues it on the CPU)") from None
            with r.api(""):
                scene._load_device(meta, z)
        scene._session.reference_energy = None if meta["e0"] is None else (meta["e0"], meta["e0_scale"])
        return scene

    def _load_device(self, meta: dict[str, Any], z: Mapping[str, np.ndarray]) -> None:
        """Puts back the device's rows of a loaded GPU scene, now on its device, where the file
        holds them (a scene saved there), so that it continues bit for bit. The books and the
        clock were restored on the host first; the rows carry the device's books."""
        if "device_pos" not in z or _DEVICE_PARTICLES not in self._sim.system_names():
            return
        if not np.array_equal(z["device_pos"][:, 3], self._as_on_device(z["masses"])):
            raise InvalidInputError("device_pos: its mass column differs from masses")
        arrays = [(k, np.ascontiguousarray(z[f"device_{k}"], dtype=np.float64).reshape(-1)) for k in ("pos", "vel", "acc", "aux", "hits")]
        arrays.append(("acc_valid", np.array([float(meta["device_acc_valid"])])))
        self._exclusive(lambda sim: sim.system_load(_DEVICE_PARTICLES, arrays))

    def __setattr__(self, name: str, value: Any) -> None:
        # A name the scene does not have is refused, not stored and ignored: `scene.gravity =
        # [0, -9.81]` did nothing, silently (physics is added as terms).
        if not name.startswith("_") and name != "render_defaults" and not hasattr(type(self), name) \
                and name not in self.__dict__:
            term = name[:1].upper() + name[1:]
            hint = f": physics is added as a term, scene.add(pc.{term}(...))" if hasattr(_terms_pkg, term) else ""
            raise AttributeError(f"Scene has no attribute {name!r} to set{hint}")
        object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        terms = ", ".join(t.name for t in self.terms) or "no terms"
        boxes, spheres, grids = self.boxes, self.spheres, self.grids
        return (
            f"Scene(dim={self.dim}, n_particles={self.n_particles}, integrator={self.integrator!r}, "
            + (f"rtol={self.rtol:g}, atol={self.atol:g}, " if self.integrator == "dopri5" else "")
            + (f"cg_tol={self.cg_tol:g}, cg_max_iter={self.cg_max_iter}, " if self.integrator == "implicit_euler" else "")
            + ("precision='f32', " if self.precision == "f32" else "")
            + f"dt={self.dt:g}, t={self.time:g}, terms: {terms}, planes: {len(self._section('planes'))}, boxes: {len(boxes)}"
            + (f", spheres: {len(spheres)}" if spheres else "")
            + (f", grids: {', '.join(g.name for g in grids)}" if grids else "")
            + (f", bodies: {', '.join(f'{g.name} ({g.n} {g.shape})' for g in self.bodies)}" if self.bodies else "")
            + ")"
        )


def _unpickle_scene(data: bytes, render_defaults: dict[str, Any] | None) -> Scene:
    """Rebuilds a pickled :class:`Scene` (see ``Scene.__reduce__``)."""
    with allocating("load", "the scene file's arrays"):
        scene = Scene._from_file(_scenefile.read_bytes(data), None)
    scene.render_defaults = render_defaults
    return scene


def _copies(scene: Scene, m: int) -> Iterator[Scene]:
    """`m` copies of `scene`, each what ``pickle.loads(pickle.dumps(scene))`` gives (bit-exact,
    through its scene file), the file read and checked once: its meta and arrays copied for
    each (a scene's parts may keep what they load), not parsed again (the parse was 85 % of a
    three-body copy's 3.6 ms; ``Batch.from_scene`` makes thousands)."""
    data, render_defaults = scene.to_bytes(), scene.render_defaults
    with allocating("load", "the scene file's arrays"):
        sf = _scenefile.read_bytes(data)
    for _ in range(m):
        with allocating("load", "the scene file's arrays"):
            own = dataclasses.replace(sf, meta=copy.deepcopy(sf.meta), arrays={k: a.copy() for k, a in sf.arrays.items()})
            c = Scene._from_file(own, None)
        c.render_defaults = copy.deepcopy(render_defaults)
        yield c
