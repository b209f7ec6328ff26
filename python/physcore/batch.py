"""Many small scenes stepped in one call: :class:`Batch`.

A batch holds M scenes of the same structure (the same dimension, particle count and parts, in
the same order; their parameters, initial states and step sizes may differ) and steps all of
them with one call into the core, the GIL released, in parallel over members. Each member
steps exactly as it would alone: bit for bit, for any thread count (every member is its own
world; nothing is shared). A member that diverges is rolled back to where the call started and
retired (it is not stepped again; :attr:`Batch.diverged` keeps its exception); the others go on.
Ctrl-C rolls every member back to where the call started and raises ``KeyboardInterrupt``.

The state reads back as arrays over members: :attr:`Batch.positions` ``(M, N, dim)``,
:attr:`Batch.time` ``(M,)``, :meth:`Batch.energy_drift` ``(M,)``. :meth:`Batch.save` writes one
file holding every member's scene file, which :meth:`Batch.load` reads back; a loaded batch
continues bit for bit.

What it saves: one crossing of the boundary per call instead of one per member, and the
members run side by side on the cores (MuJoCo's ``rollout``, Genesis's ``n_envs`` are the
model). Members that are plain small N-body problems (float64, at most 16 bodies, pairwise
gravity or Coulomb plus uniform fields, velocity Verlet or Yoshida 4) are stepped by a fused
kernel, one member per SIMD lane, with the same bits; the others take their general step.
``benches/scenes/bench_batch.py`` measures the batch against a Python loop over the same scenes
(10,000 three-body problems × 1,000 steps: 23× the loop on 2 cores at avx2; see the sweeps
guide).

>>> import numpy as np
>>> import physcore as pc
>>> fan = pc.Batch.from_scene(pc.scenes.figure_eight(), 4, positions=lambda k, x: x * (1 + 1e-3 * k))
>>> fan.step(100)
>>> fan.positions.shape, fan.time.shape
((4, 3, 2), (4,))
>>> alone = pc.scenes.figure_eight()
>>> alone.positions = alone.positions * (1 + 1e-3 * 2)
>>> alone.step(100)
>>> bool(np.array_equal(fan.positions[2], alone.positions))  # the same bits as alone
True
"""
from __future__ import annotations

import json
import os
import pickle
import threading
import zipfile
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from itertools import chain, compress, repeat
from operator import attrgetter, eq, is_
from pathlib import Path
from typing import Any

import numpy as np

from . import _check, _core
from ._atomic import atomic_write
from ._errors import (
    InvalidInputError,
    InvalidTypeError,
    OutOfMemoryError,
    SceneBusyError,
    SceneFileError,
    SimulationDiverged,
)
from ._scenefile import _central_directory_size, _open_regular, _show, check_path
from ._system import quiet_wayland_probe, usable_cpus
from .contacts import Contacts
from .scene import Scene, _copies
from .session import Session, books

__all__ = ["Batch"]

#: Members of at most this many particles have their energy books read (the reference before
#: their first step, ``energy_total``, ``energy_drift``) in one call into the core (not
#: interruptible: an O(N²) potential of a few thousand bodies is milliseconds).
_REFERENCE_AT_ONCE = 4096
#: ``energy_total`` and ``energy_drift`` read every member's books in one call only where the
#: members' pairs together (M N²) are at most this many, about a tenth of a second of O(N²)
#: potential: a larger batch reads its members one by one, so that Ctrl-C is heard.
_BOOKS_AT_ONCE = 1 << 26
#: A call's per-member work runs as C-level maps over these (the lock's methods, an attribute's
#: getter), not as Python loops: the loops took tens of milliseconds a call at 16,384 members,
#: where an H200 stepped 1,024 worlds 1,000 steps in 3.3 ms (docs/guide/gpu.md).
_LOCK = type(threading.RLock())  # a Session's (see Session.exclusive: its owner check)
_REFERENCE = attrgetter("reference_energy")
_LOCK_OF = attrgetter("lock")
_BUSY = attrgetter("busy")
_N_PARTICLES = attrgetter("n_particles")  # of a core Simulation: no lock, no write-back

#: The batch file's format version (``Batch.save``).
FORMAT_VERSION = 1


def _each(values: Any) -> None:
    """Runs the iterator `values` to its end (its items' side effects), keeping nothing."""
    deque(values, maxlen=0)


@contextmanager
def _holding(sessions: Sequence[Session], locks: Sequence[Any]) -> Iterator[None]:
    """Every session of `sessions` (their `locks`) held for a call into the core, as
    :meth:`Session.exclusive <physcore.session.Session.exclusive>` holds one: another thread's
    use of a member meanwhile raises SceneBusyError, not pyo3's bare "Already mutably
    borrowed". SceneBusyError, with nothing held, if one is in use."""
    me = threading.get_ident()
    if me in set(map(_BUSY, sessions)):  # a call from inside a call on this thread
        raise SceneBusyError("a member of this Batch is being stepped by another thread")
    # Ctrl-C can land after any call returns, in `try` and in `finally` alike: what `finally`
    # undoes is therefore read from the sessions and locks themselves (this thread's marks, the
    # locks this thread holds), not from what acquire() returned, in one C-level pass built
    # here, lazily, so that nothing in `finally` runs before it. (Taking locks and keeping
    # what acquire() returned left them taken when the interrupt fell in between.)
    undo = partial(deque, chain(
        map(setattr, compress(sessions, map(eq, map(_BUSY, sessions), repeat(me))), repeat("busy"), repeat(None)),
        map(_LOCK.release, compress(locks, map(_LOCK._is_owned, locks)))), 0)
    try:
        if not all(map(_LOCK.acquire, locks, repeat(False))):
            raise SceneBusyError("a member of this Batch is being stepped by another thread")
        _each(map(setattr, sessions, repeat("busy"), repeat(me)))
        yield
    finally:
        undo()


_PENDING = attrgetter("pending")


def _settle(sessions: Sequence[Session]) -> None:
    """Writes each of `sessions` whose newest state a GPU batch keeps (:attr:`Session.pending
    <physcore.session.Session.pending>`) from there: one call into the core for each batch
    that keeps some. SceneBusyError if such a batch is being stepped by another thread."""
    owners = set(map(_PENDING, sessions))
    owners.discard(None)
    for p in owners:  # mostly one: each takes its own from `sessions`
        p.settle(sessions)


class _Resident:
    """A GPU batch's members as they live on the device between calls: the core's
    ``DeviceBatch`` keeps their state there and in a mirror on the host, and writes a member
    from the mirror only when it is used. After a call every member stepped is *pending*
    (:attr:`Session.pending <physcore.session.Session.pending>` is this object), so that any
    use of it through its scene (:meth:`Session.checked <physcore.session.Session.checked>`)
    first writes it back (:meth:`settle`); a member written back is *touched*: the next call
    compares it with the mirror and, if it was changed, writes it alone to the device (its
    forces evaluated anew, no other member's bits moved). A call's host work is then that of
    the touched members, not of every member (a call of one step of 16,384 worlds on
    lavapipe: 22–25 ms when every member was written back each call, 4.3–4.6 ms now, on a
    2-core EPYC; see docs/guide/gpu.md).

    ``lock`` is held by a call and by :meth:`settle`: a member used from another thread while
    the batch steps raises SceneBusyError, as a scene stepped by another thread does."""

    def __init__(self, gpu: Any, members: list[int], sessions: list[Session]) -> None:
        self.gpu = gpu
        self.lock = threading.RLock()  # for its owner check, as a Session's (see Session.exclusive)
        #: The batch index of each of the core's members, and each member's index by its
        #: session's id. It holds no session: a session pending here holds it, so a batch and
        #: its members dropped together are freed at once, not left to the cycle collector.
        self.members = members
        self.index = {id(x): j for j, x in enumerate(sessions)}
        #: Members whose scenes may differ from the mirror (written back since the last call;
        #: all of them until the first), and those retired (diverged; held still).
        self.touched: set[int] = set(range(len(sessions)))
        self.retired: set[int] = set()

    def __call__(self, session: Session) -> None:
        self.settle([session])

    def settle(self, sessions: Sequence[Session]) -> None:
        """Writes those of `sessions` that are pending here from the mirror (state, clock,
        books), in one call into the core; they are touched from then on."""
        try:  # taken inside `try`, released whatever acquire() returned: see Session.exclusive
            if not self.lock.acquire(blocking=False):
                raise SceneBusyError("the GPU Batch keeping this scene's state is being stepped by another thread")
            # C-level passes: a Python loop over 16,384 members took milliseconds.
            picked = list(compress(sessions, map(is_, map(_PENDING, sessions), repeat(self))))
            if picked:
                mine = list(map(self.index.__getitem__, map(id, picked)))
                self.gpu.settle(mine)
                _each(map(setattr, picked, repeat("pending"), repeat(None)))
                self.touched.update(mine)
        finally:
            try:
                self.lock.release()
            except RuntimeError:  # not this thread's
                pass


def structure(scene: Scene) -> tuple[Any, ...]:
    """What the members of a batch must share: ``(dim, n_particles, ((section, part_kind), ...))``,
    the dimension, the particle count, and each part's section and kind in order
    (:attr:`Scene.parts`). Two scenes of equal structure can be stepped together."""
    return (scene.dim, scene.n_particles, tuple((p.section, p.part_kind) for p in scene.parts))




def _same_structure(members: Sequence[Scene], name: str, after: str = "", ref: int = 0) -> None:
    """InvalidInputError naming the first member (``name`` and its index) whose
    :func:`structure` differs from member ``ref``'s, and what differs."""
    first = structure(members[ref])
    for k, s in enumerate(members):
        if k == ref:
            continue
        other = structure(s)
        if other != first:
            i = next(i for i in range(3) if other[i] != first[i])
            what = ("dimension", "particle count", "parts")[i]
            raise InvalidInputError(f"{name} {k} differs from entry {ref} in its {what}{after}: {other[i]} vs {first[i]}")

def _check_device(device: object, precision: object) -> tuple[str, str]:
    """A batch's ``device`` (``"cpu"``, ``"gpu"``, ``"gpu:NAME"``) and its precision (``"f32"``
    unless given; ``"f64"`` on the CPU, where members keep their own)."""
    if not isinstance(device, str):
        raise InvalidTypeError(f"device: expected 'cpu', 'gpu' or 'gpu:NAME', got {type(device).__name__}")
    if device != "cpu" and device != "gpu" and not device.startswith("gpu:"):
        raise InvalidInputError(f"device: must be 'cpu', 'gpu' or 'gpu:NAME', got {device!r}")
    if precision is None:
        return device, ("f64" if device == "cpu" else "f32")
    if not isinstance(precision, str):
        raise InvalidTypeError(f"precision: expected 'f32' or 'f64', got {type(precision).__name__}")
    if precision not in ("f32", "f64"):
        raise InvalidInputError(f"precision: must be 'f32' or 'f64', got {precision!r}")
    return device, precision


def _room() -> int:
    """Bytes a batch may plan for: physcore's limit (half the physical memory), or less where a
    memory cap (``RLIMIT_AS``) leaves less room above what the process maps now."""
    room = _check.memory_limit()
    try:
        import resource

        cap = resource.getrlimit(resource.RLIMIT_AS)[0]
        if cap != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                mapped = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            room = min(room, max(cap - mapped, 0))
    except (ImportError, OSError, ValueError):
        pass
    return room

class Batch:
    """M scenes of the same structure, stepped together (see the module docstring).

    Parameters
    ----------
    scenes : sequence of Scene
        The members, at least one, each once; they must have the same dimension, particle count
        and parts (kinds, in order). The batch steps these very scenes: a member read or stepped
        on its own afterwards is the same object.
    threads : int or None
        Threads stepping members side by side (``None``: all cores, or ``RAYON_NUM_THREADS``).
        Results do not depend on it.
    device : str
        ``"cpu"`` (default), or ``"gpu"`` / ``"gpu:NAME"``: every member on one GPU, each stage
        of a step one dispatch for all members (each member's pairwise sums kept to its own
        particles). The members stay CPU scenes whose state lives on the device between calls:
        a member is written back (state, clock, energy books, as if it had stepped alone in the
        device's ``precision``) when it is used, and read again by the next call only if it
        was, so that a call's host work does not grow with the members it leaves alone. A GPU
        batch holds particle scenes with the GPU path's terms (gravity, drag, pairwise gravity,
        Coulomb, springs) and colliders, and its members share the integrator, ``dt``, the
        fields' parameters (g, drag, G, k, softening) and the colliders (one dispatch runs
        them); masses, charges, springs and states may differ. Anything else is refused by name. A member that diverges is retired
        as on the CPU; the others' results do not depend on it. Measured agreement with the CPU
        path: docs/guide/gpu.md.
    precision : {"f32", "f64"} or None
        A GPU batch's precision (default ``"f32"``); ignored on the CPU (members keep their own).

    Raises
    ------
    TypeError
        ``scenes`` is not a sequence of :class:`~physcore.Scene`; ``threads`` not an int.
    InvalidInputError
        (a ``ValueError``) No scene, a scene given twice, or a member whose structure differs
        from the first's (the message names its index and what differs); with a GPU
        ``device``: no such device, f64 on an adapter without it, a part or a difference
        between members the GPU batch cannot hold (named).
    """

    def __init__(
        self,
        scenes: Sequence[Scene],
        *,
        threads: int | None = None,
        device: str = "cpu",
        precision: str | None = None,
    ) -> None:
        if isinstance(scenes, Scene) or not isinstance(scenes, Sequence):
            raise InvalidTypeError(f"scenes: expected a sequence of Scene, got {type(scenes).__name__}")
        members = list(scenes)
        if not members:
            raise InvalidInputError("scenes: a batch needs at least one scene")
        for k, s in enumerate(members):
            if not isinstance(s, Scene):
                raise InvalidTypeError(f"scenes: entry {k} is a {type(s).__name__}, not a Scene")
        seen: dict[int, int] = {}
        for k, s in enumerate(members):
            if id(s) in seen:
                raise InvalidInputError(f"scenes: entry {k} is entry {seen[id(s)]} again (each scene once)")
            seen[id(s)] = k
        _same_structure(members, "scenes: entry")
        self._threads = None if threads is None else _check.int_in_range("threads", threads, 1, 1 << 16)
        self._members: tuple[Scene, ...] = tuple(members)
        #: Retired members: index -> the :class:`~physcore.SimulationDiverged` it raised.
        self.diverged: dict[int, SimulationDiverged] = {}
        # What a call reads of every member, gathered once (a scene keeps its core simulation
        # and its lock for life): a call's Python work per member is then a few list steps.
        self._sessions = [s.session for s in members]
        self._sims = [x.sim for x in self._sessions]
        self._locks = [x.lock for x in self._sessions]
        #: Each member's parts as the scene stores them (a list it appends to, never rebinds),
        #: and each member's particle and part counts as last checked (see `_unchanged`).
        self._part_lists = [x.parts for x in self._sessions]
        self._stamp = self._counts()
        self._device, self._precision = _check_device(device, precision)
        #: The members on the GPU (`_core.DeviceBatch`), built again when they change, and
        #: what keeps their state between calls (`_Resident`).
        self._gpu: Any = None
        self._res: _Resident | None = None
        self._dev_sessions: list[Session] = []
        #: Whether every member has been put on its own device (`Scene.to_device`) already.
        self._placed = False
        if self._device != "cpu":
            for k, s in enumerate(members):
                if s.session.sim.on_device:
                    raise InvalidInputError(f"scenes: entry {k} is on a device already (a GPU batch moves its members itself)")
            # The core refuses by name a term, grid or system the GPU batch has no kernel for.
            _settle(self._sessions)
            self._build(list(range(len(members))))

    # ------------------------------------------------------------------------ building
    @classmethod
    def from_scene(
        cls,
        scene: Scene,
        m: int,
        *,
        positions: Callable[[int, np.ndarray], Any] | None = None,
        velocities: Callable[[int, np.ndarray], Any] | None = None,
        threads: int | None = None,
        device: str = "cpu",
        precision: str | None = None,
    ) -> Batch:
        """``m`` copies of ``scene`` (bit-exact, through its scene file), member ``k``'s positions
        and velocities set to ``positions(k, x)`` and ``velocities(k, v)`` where given (``x``,
        ``v``: the scene's, (N, dim) float64 m and m/s); ``threads``, ``device`` and
        ``precision`` as :class:`Batch` takes them.

        Raises TypeError / InvalidInputError naming ``scene``, ``m`` (an int ≥ 1) or the array a
        callable returned (as :attr:`Scene.positions` would); :class:`~physcore.InvalidTypeError`
        naming ``positions`` or ``velocities`` when it is neither None nor a callable (an array:
        set it on ``scene`` before, or return it from the callable); :class:`~physcore.OutOfMemoryError`
        naming ``m``, before any copy is made, when ``m`` copies would not fit: a copy takes
        about twice its pickled size plus 4 kB (measured: a 2-body scene 2.8 kB, a 32 × 32
        cloth 1.1 MB for 0.56 MB pickled), against half the physical memory or what a memory
        cap (``RLIMIT_AS``) leaves."""
        if not isinstance(scene, Scene):
            raise InvalidTypeError(f"scene: expected a Scene, got {type(scene).__name__}")
        m = _check.int_in_range("m", m, 1, 1 << 24)
        for name, f, arg in (("positions", positions, "x"), ("velocities", velocities, "v")):
            if f is not None and not callable(f):
                raise InvalidTypeError(
                    f"{name}: expected a callable f(k, {arg}) returning member k's {name}, or None, "
                    f"got {type(f).__name__}"
                )
        data = pickle.dumps(scene)  # its size sizes the copies
        need = m * (2 * len(data) + 4096)
        room = _room()
        if need > room:
            raise OutOfMemoryError(
                f"m: {m} copies of the scene would need about {_check.human_bytes(need)}, "
                f"above the {_check.human_bytes(room)} physcore plans for (half the physical memory, or what the "
                "memory cap leaves)",
                bytes=need,
            )
        members = []
        try:
            for k, s in enumerate(_copies(scene, m)):
                if positions is not None:
                    s.positions = positions(k, s.positions)
                if velocities is not None:
                    s.velocities = velocities(k, s.velocities)
                members.append(s)
        except MemoryError as e:
            if isinstance(e, OutOfMemoryError):
                raise
            raise OutOfMemoryError(f"m: out of memory after {len(members)} of {m} copies of the scene") from None
        return cls(members, threads=threads, device=device, precision=precision)

    def _build(self, live: list[int]) -> None:
        """The core's batch of the members ``live`` (batch indices, their state in their
        scenes) on this batch's device (InvalidInputError naming what it cannot hold)."""
        sessions = [self._sessions[k] for k in live]
        quiet_wayland_probe()
        self._gpu = _core.DeviceBatch([x.sim for x in sessions], self._device, self._precision)
        self._res = _Resident(self._gpu, live, sessions)
        #: The device's members' sessions, in its order.
        self._dev_sessions = sessions

    # ------------------------------------------------------------------------ members
    @property
    def device(self) -> str:
        """``"cpu"``, or the GPU the batch runs on, its backend and precision (e.g.
        ``"NVIDIA H100 80GB HBM3 (vulkan, f32)"``)."""
        return "cpu" if self._gpu is None else str(self._gpu.device)

    @property
    def members(self) -> tuple[Scene, ...]:
        """The scenes, in order."""
        return self._members

    def __len__(self) -> int:
        return len(self._members)

    def __getitem__(self, k: int) -> Scene:
        return self._members[k]

    def __repr__(self) -> str:
        s = self._members[0]
        return f"Batch({len(self)} × {s.dim}D scenes of {s.n_particles} particles, {len(self.diverged)} diverged)"

    def _counts(self) -> tuple[list[int], list[int]]:
        """Each member's particle count and part count. SceneBusyError if a member is inside a
        call (pyo3's bare "Already mutably borrowed" otherwise)."""
        try:
            return list(map(_N_PARTICLES, self._sims)), list(map(len, self._part_lists))
        except RuntimeError:
            raise SceneBusyError("a member of this Batch is being stepped by another thread") from None

    def _unchanged(self, particles: bool = True, among: Sequence[int] | None = None) -> None:
        """InvalidInputError naming the first member whose :func:`structure` differs from the
        others' since the batch was made (a particle, term or body group added to it alone):
        checked by every call that steps or reads the members as one, before anything else.
        Members changed alike still make a batch. ``particles=False`` leaves the particle
        counts to the caller; ``among``: the only members that can have changed (`_touched`).
        SceneBusyError as :meth:`_counts`."""
        # A structure changes only with a count (parts and particles are only added;
        # Scene.replace keeps the part's class, hence its kind): C-level passes, about 0.7 ms
        # for the parts and 0.9 ms for the particles at 16,384 members, where structure() of
        # each took 20 ms.
        n0, p0 = self._stamp
        parts, sims = self._part_lists, self._sims
        if among is not None:
            parts, sims = [parts[k] for k in among], [sims[k] for k in among]
            n0, p0 = [n0[k] for k in among], [p0[k] for k in among]
        try:
            if list(map(len, parts)) == p0 and (not particles or list(map(_N_PARTICLES, sims)) == n0):
                return
        except RuntimeError:
            raise SceneBusyError("a member of this Batch is being stepped by another thread") from None
        counts = self._counts()
        if counts == self._stamp:
            return
        _settle(self._sessions)  # structure() reads each scene: written back in one call
        # The member named is one that changed, against one that did not where one is left.
        ref = next((k for k, (n, p) in enumerate(zip(*counts, strict=True))
                    if (n, p) == (self._stamp[0][k], self._stamp[1][k])), 0)
        _same_structure(self._members, "member", after=" since the batch was made", ref=ref)
        self._stamp = counts

    def _touched(self) -> list[int]:
        """A GPU batch's members that can have changed since its last call: any use of a member
        through its scene writes it back first (:meth:`Session.checked
        <physcore.session.Session.checked>`), which marks it touched; and those retired. A
        check of these alone keeps a call's host work that of the members used (checking all
        16,384 took a 4.7 ms call on lavapipe to 6.7 ms)."""
        res = self._res
        assert res is not None
        return [res.members[j] for j in list(res.touched)] + list(self.diverged)  # list(): one C-level copy

    # ------------------------------------------------------------------------ stepping
    def _set_reference_energies(self, fresh: list[Scene]) -> list[Scene]:
        """The books' reference of each member before its first step, as its first step alone
        takes it (:meth:`Session.take_reference_energy <physcore.session.Session.take_reference_energy>`), for members whose locks the caller
        holds: all at once in the core (the same additions, in parallel, the GIL released). The
        members whose books could not be prepared are returned, their reference not taken."""
        refs = _core.reference_energies([s.session.sim for s in fresh], self._threads)
        missing = []
        for s, r in zip(fresh, refs, strict=True):
            if r is None:  # its books could not be prepared (memory): read alone, which says why
                missing.append(s)
            else:
                s.session.reference_energy = r
        return missing

    def step(self, n: int = 1) -> None:
        """Advance every member that has not diverged ``n`` steps of its own ``dt``, in one call
        into the core (GIL released), members in parallel.

        A member that diverges is rolled back to where this call started and retired: it is in
        :attr:`diverged` with its :class:`~physcore.SimulationDiverged` (step, time, particle,
        suggested dt) and is not stepped again; the others finish their ``n`` steps.

        Raises
        ------
        KeyboardInterrupt
            Ctrl-C: every member is rolled back to where this call started.
        SceneBusyError
            A member is being stepped by another thread (nothing is stepped).
        InvalidInputError
            ``n`` not an int ≥ 0, or it would take a member's step count past 2**63 - 1; or a
            member was changed since the batch was made so that its structure differs from the
            others' (a particle, term or body group added to it alone), naming it (nothing is
            stepped; change every member alike, or step that one on its own).

        Warns
        -----
        ContactStepWarning
            As :meth:`Scene.step` warns, for a member with contacts stepping far past their step.
        """
        n = _check.int_in_range("n", n, 0, (1 << 63) - 1)
        self._unchanged(among=None if self._res is None else self._touched())
        if self._res is not None:
            self._step_device(n)
            return
        if self.diverged:
            live = [k for k in range(len(self)) if k not in self.diverged]
            scenes = [self._members[k] for k in live]
            sessions = [self._sessions[k] for k in live]
            sims, locks = [self._sims[k] for k in live], [self._locks[k] for k in live]
        else:
            live, scenes, sessions, sims, locks = None, self._members, self._sessions, self._sims, self._locks
        _settle(sessions)  # a member a GPU batch stepped last: its state into its scene
        # A GPU member moves to its device at its first step, as Scene.step moves it: its parts
        # checked first (refused by name, for every member, before any moves), else the core
        # would step it on the CPU. Once moved, a member stays where it is: later calls skip it.
        if not self._placed:
            for s in scenes:
                s.to_device(check_only=True)
            for s in scenes:
                s.to_device()
            self._placed = live is None
        # The books' reference, as a member's first step alone takes it: large members one by
        # one (interruptible: their potential is O(N²)), the others in one call below.
        fresh = self._fresh(scenes, sessions)
        if scenes and any(isinstance(t, Contacts) for t in scenes[0].terms):  # members share their parts
            for s in scenes:
                s.warn_contact_step()  # as Scene.step warns (ContactStepWarning)
        with _holding(sessions, locks):
            missing = self._set_reference_energies([s for s in fresh if s.session.reference_energy is None]) if fresh else []
            # The core checks n against every member's step count before stepping any.
            try:
                failed = None if missing else _core.step_batch(sims, n, self._threads)
            except BaseException:
                # Every member rolled back (Ctrl-C, a refusal): as after a failed first
                # Scene.step, those whose first step this was have no reference either.
                for s in fresh:
                    s.session.reference_energy = None
                raise
        if failed is None:  # nothing stepped: read those books alone (raising what alone raises)
            for s in missing:
                s.session.take_reference_energy()
            return self.step(n)
        first = {id(s.session) for s in fresh}
        for j, e in failed:
            if not isinstance(e, SimulationDiverged):
                raise e
            self.diverged[j if live is None else live[j]] = e
            if id(sessions[j]) in first:  # rolled back to before its first step: no reference
                sessions[j].reference_energy = None

    def _fresh(self, scenes: Sequence[Scene], sessions: Sequence[Session]) -> list[Scene]:
        """Those of `scenes` whose books' reference is to be taken before this step; a large
        member's is taken here, one by one (interruptible: its potential is O(N²))."""
        fresh = ([s for s, x in zip(scenes, sessions, strict=True) if x.reference_energy is None]
                 if None in map(_REFERENCE, sessions) else [])
        if fresh and fresh[0].n_particles > _REFERENCE_AT_ONCE:  # members share their particle count
            for s in fresh:
                s.session.take_reference_energy()
        return fresh

    def _step_device(self, n: int) -> None:
        """:meth:`step` for a GPU batch: the members stay on the device between calls
        (:class:`_Resident`); only those touched since the last call are read from their
        scenes, and no member is written back until it is used."""
        res = self._res
        assert res is not None
        sessions = self._dev_sessions
        live = [j for j in range(len(sessions)) if j not in res.retired] if res.retired else range(len(sessions))
        # A C-level pass first: building the lists of 16,384 members took 2 ms a call.
        fresh = (self._fresh([self._members[res.members[j]] for j in live], [sessions[j] for j in live])
                 if None in map(_REFERENCE, sessions) else [])
        if fresh:  # their books' reference is read from their scenes: written back first
            _settle([s.session for s in fresh])
            with _holding([s.session for s in fresh], [s.session.lock for s in fresh]):
                missing = self._set_reference_energies([s for s in fresh if s.session.reference_energy is None])
            for s in missing:
                s.session.take_reference_energy()
        try:  # taken inside `try`, released whatever acquire() returned: see Session.exclusive
            if not res.lock.acquire(blocking=False):
                raise SceneBusyError("a member of this Batch is being stepped by another thread")
            touched = sorted(res.touched - res.retired)
            held = [sessions[j] for j in touched]
            # One a GPU batch stepped since (another batch of it): its state into its scene.
            _settle(list(compress(held, map(_PENDING, held))))
            with _holding(held, list(map(_LOCK_OF, held))):
                failed = res.gpu.step(touched, n)
            if failed is not None:
                for j in failed:  # retired where its call started, with what alone it would raise
                    res.gpu.settle([j])
                    sessions[j].pending = None
                    res.retired.add(j)
                    self.diverged[res.members[j]] = res.gpu.diverged(j)
                # The members stepped keep their state on the device until they are used.
                gone = res.retired
                _each(map(setattr, [x for x in held if res.index[id(x)] not in gone] if gone else held,
                          repeat("pending"), repeat(res)))
                res.touched = set(gone)
        finally:
            try:
                res.lock.release()
            except RuntimeError:  # not this thread's
                pass
        if failed is None:  # a touched member's terms or colliders changed: built again from them
            _settle(sessions)
            self._build([k for k in range(len(self)) if k not in self.diverged])
            self._step_device(n)

    # ------------------------------------------------------------------------ state
    def _rows(self, velocities: bool) -> np.ndarray:
        """Every member's positions or velocities: one copy in the core where every member is a
        float64 scene on the CPU, else each member's own (:attr:`Scene.positions`) stacked. A
        read, as :attr:`Scene.positions` is: it takes no lock (taking and marking 16,384 took
        11 ms, the copy 2 ms) and refuses, as each member's :meth:`Session.checked
        <physcore.session.Session.checked>` does, while another thread is inside a call."""
        me = threading.get_ident()
        if any(b is not None and b != me for b in set(map(_BUSY, self._sessions))):
            raise SceneBusyError("a member of this Batch is being stepped by another thread")
        if self._res is not None:
            self._unchanged(among=self._touched())
            return self._mirrored(velocities)[0]
        # The particle counts are checked where the core's copy answers None (it does where
        # they differ): numpy's bare shape error otherwise.
        self._unchanged(particles=False)
        _settle(self._sessions)
        rows = _core.batch_rows(self._sims, velocities)
        if rows is not None:
            return rows
        self._unchanged()
        return np.stack([s.velocities if velocities else s.positions for s in self._members])

    def _mirrored(self, velocities: bool, clock: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A GPU batch's members' positions or velocities ``(M, N, dim)`` float64, times
        ``(M,)`` float64 and step counts ``(M,)`` int64: the device's mirror for the members it
        keeps, each other member (written back since the last call, retired, or left out of
        the device's batch) read from its scene: its rows, or with `clock` its clock alone (the
        rows are then not to be used). SceneBusyError while another thread steps the batch."""
        res = self._res
        assert res is not None
        try:  # taken inside `try`, released whatever acquire() returned: see Session.exclusive
            if not res.lock.acquire(blocking=False):
                raise SceneBusyError("a member of this Batch is being stepped by another thread")
            rows, t, steps = res.gpu.mirror(velocities)
            read = [res.members[j] for j in sorted(res.touched)]
        finally:
            try:
                res.lock.release()
            except RuntimeError:  # not this thread's
                pass
        steps = steps.astype(np.int64)
        m = len(self)
        if len(res.members) != m:  # built again without the members retired before
            at = np.asarray(res.members)
            full, ft, fs = np.empty((m, *rows.shape[1:])), np.empty(m), np.empty(m, dtype=np.int64)
            full[at], ft[at], fs[at] = rows, t, steps
            rows, t, steps = full, ft, fs
            read += sorted(set(range(m)) - set(res.members))
        if read:  # from their scenes: in one call into the core where it can
            scenes = [self._members[k] for k in read]
            _settle([s.session for s in scenes])  # a member another GPU batch stepped since
            if clock:  # not the rows: a member changed alone has its clock, but not N rows
                t[read] = [s.time for s in scenes]
                steps[read] = [s.step_count for s in scenes]
            else:
                sub = _core.batch_rows([s.session.sim for s in scenes], velocities)
                rows[read] = sub if sub is not None else np.stack([s.velocities if velocities else s.positions for s in scenes])
        return rows, t, steps

    @property
    def positions(self) -> np.ndarray:
        """Every member's positions, m: ``(M, N, dim)`` float64 (float32 where the members have
        ``precision="f32"``; a new array). Raises SceneBusyError if a member is being stepped
        by another thread, InvalidInputError naming a member changed since the batch was made
        so that its structure differs from the others' (as :meth:`step`)."""
        return self._rows(False)

    @property
    def velocities(self) -> np.ndarray:
        """Every member's velocities, m/s: ``(M, N, dim)`` float64 (float32 where the members
        have ``precision="f32"``; a new array). Raises SceneBusyError and InvalidInputError as
        :attr:`positions`."""
        return self._rows(True)

    @property
    def time(self) -> np.ndarray:
        """Every member's simulated time, s: ``(M,)`` float64."""
        if self._res is not None:
            return self._mirrored(False, clock=True)[1]
        return np.array([s.time for s in self._members], dtype=np.float64)

    @property
    def step_count(self) -> np.ndarray:
        """Every member's step count: ``(M,)`` int64."""
        if self._res is not None:
            return self._mirrored(False, clock=True)[2]
        return np.array([s.step_count for s in self._members], dtype=np.int64)

    def _books(self) -> list[tuple[float, float]]:
        """Every member's energy books now, ``(total, scale)`` as :func:`physcore.session.books`
        reduces them: small members (_REFERENCE_AT_ONCE, _BOOKS_AT_ONCE) all in one call into
        the core (the same additions, in parallel; one Python call a member took 40-60 µs, a
        second at 16,384 members), larger ones alone (interruptible), as is a member whose
        books could not be prepared (which then raises what it raises alone)."""
        members = self._members
        _settle(self._sessions)
        out: list[tuple[float, float] | None] = [None] * len(members)
        n = members[0].n_particles  # members share their particle count
        if n <= _REFERENCE_AT_ONCE and n * n * len(members) <= _BOOKS_AT_ONCE:
            with _holding(self._sessions, self._locks):
                out = _core.reference_energies(self._sims, self._threads)
        return [r if r is not None else books(x.exclusive(lambda sim: sim.energy()))
                for r, x in zip(out, self._sessions, strict=True)]

    def energy_total(self) -> np.ndarray:
        """Every member's energy books' total now, J: ``(M,)`` float64 (kinetic + potential +
        dissipated, :meth:`Scene.energy`'s ``total``, bit for bit).

        Raises
        ------
        SceneBusyError
            A member is being stepped by another thread."""
        return np.array([total for total, _ in self._books()], dtype=np.float64)

    def energy_drift(self) -> np.ndarray:
        """Every member's relative energy drift since its first step (:meth:`Scene.energy_drift`,
        bit for bit): ``(M,)`` float64.

        Raises
        ------
        SceneBusyError
            A member is being stepped by another thread."""
        # Session.drift's arithmetic on arrays, elementwise in IEEE double: the same bits (a
        # Python call a member took some 0.5 µs, 8 ms at 16,384 members).
        now = np.array(self._books(), dtype=np.float64).reshape(-1, 2)
        refs = [x.reference_energy for x in self._sessions]
        have = np.array([r is not None for r in refs], dtype=bool)
        ref = np.array([r if r is not None else (0.0, 0.0) for r in refs], dtype=np.float64).reshape(-1, 2)
        e0, s0, total, scale = ref[:, 0], ref[:, 1], now[:, 0], now[:, 1]
        finite = np.isfinite(e0) & np.isfinite(s0) & np.isfinite(total) & np.isfinite(scale)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            denom = np.maximum(np.maximum(np.abs(e0), s0), scale)
            out = np.where(denom > 0, (total - e0) / np.where(denom > 0, denom, 1.0), 0.0)
        out[~finite] = np.nan
        out[~have] = 0.0
        return out

    # ------------------------------------------------------------------------ drawing
    @property
    def render_defaults(self) -> dict[str, Any]:
        """What a render of the batch uses by default: member 0's ``render_defaults``, with each
        member its own hue (``colors``, ``color_by="none"``) and no mesh. InvalidInputError as
        :attr:`positions`."""
        return _Overlay(self).render_defaults

    def _render_view(self) -> _Overlay:
        """What :func:`physcore.render.record` and :func:`~physcore.render.gif` draw for a batch:
        every member's particles in one frame, each member its own hue (see :class:`_Overlay`).
        InvalidInputError as :attr:`positions`, before anything is drawn."""
        return _Overlay(self)

    # ------------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the batch to one file, atomically: a zip of every member's scene file
        (``member{k}.npz``, as :meth:`Scene.save` writes it) and ``batch.json`` (the format,
        the thread count, and the retired members' messages). Returns the path. Any file name
        is taken: unlike :meth:`Scene.save`, no suffix is required (``.batch`` and ``.npz``
        are both in use).

        Raises, before anything is written:

        InvalidTypeError
            (a ``TypeError``) ``path`` is not a str or os.PathLike.
        InvalidInputError
            (a ``ValueError``) ``path`` contains a NUL, or names something that is not a
            regular file (a directory, pipe or device); or a member was changed since the
            batch was made so that its structure differs from the others' (a part added to one
            member), naming it: such a file could not be loaded as a batch; save that member on
            its own."""
        path = check_path(path)
        _settle(self._sessions)  # in one call, not member by member
        self._unchanged()
        blobs = [s.to_bytes() for s in self._members]
        meta = {
            "format": FORMAT_VERSION,
            "members": len(blobs),
            "threads": self._threads,
            "diverged": {str(k): str(e) for k, e in self.diverged.items()},
            "device": self._device,
            "precision": self._precision,
        }

        def write(fh: Any) -> None:
            with zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED) as z:
                z.writestr("batch.json", json.dumps(meta))
                for k, b in enumerate(blobs):
                    z.writestr(f"member{k}.npz", b)

        return atomic_write(path, write)

    @classmethod
    def load(cls, path: str | os.PathLike, *, device: str | None = None) -> Batch:
        """Read a file :meth:`save` wrote; each member is checked as :meth:`Scene.load` checks a
        file. A retired member comes back retired (its exception rebuilt from its message). A
        batch saved on a GPU comes back on a GPU of this machine; ``device`` (``"cpu"``,
        ``"gpu"``, ``"gpu:NAME"``) puts it elsewhere (a GPU batch continues on the CPU with
        ``device="cpu"``).

        The saved thread count is capped at the CPUs this process may use, as
        :meth:`Scene.load` caps it (a file should not decide how many threads start).

        Raises
        ------
        InvalidTypeError
            (a ``TypeError``) ``path`` is not a str or os.PathLike.
        SceneFileError
            Not a regular file (a directory, pipe or device), not a batch file, a ``batch.json``
            that is not a JSON object, an unknown format, a malformed field of it, a member
            missing or failing its checks (the message names the member).
        InvalidInputError
            The file's GPU (or ``device``) is not on this machine, naming ``device``.
        OSError
            The file cannot be opened (``FileNotFoundError``, ``PermissionError``), as
            :meth:`Scene.load` raises.
        """
        path = check_path(path)
        where = str(path)

        def stored(z: zipfile.ZipFile, name: str) -> bytes:
            # `save` stores every member: a compressed one is refused before it is inflated (a
            # 1 MB file could otherwise claim gigabytes), as Scene.load refuses one.
            info = z.getinfo(name)
            if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size:
                raise SceneFileError(where, name, "compressed (a batch file's members are stored, as save writes them)")
            return z.read(name)

        # A missing or unreadable file raises its OSError (FileNotFoundError, PermissionError),
        # as Scene.load does; what is read and is not a batch file is a SceneFileError.
        try:  # a FIFO would block the read forever, a device could be endless
            fh, size = _open_regular(path, where)
        except SceneFileError:
            raise SceneFileError(where, "", "not a regular file (a directory, pipe or device); give a file written by Batch.save") from None
        try:
            cd = _central_directory_size(fh, size)
            if cd is not None and cd > size:
                raise SceneFileError(where, "", f"zip central directory of {cd} bytes is larger than the file ({size} bytes)")
            fh.seek(0)
            z = zipfile.ZipFile(fh)
        except BaseException as e:
            fh.close()
            if isinstance(e, (OSError, zipfile.BadZipFile)):
                raise SceneFileError(where, "", f"not a batch file ({type(e).__name__}: {_show(str(e))})") from None
            raise
        try:
            with fh, z:
                # Members that claim more than the file holds overlap (a 1.5 MB file of nested
                # members claimed 5 GB, every byte read before any was checked): refused before
                # any is read, as Scene.load refuses them.
                infos = z.infolist()
                if sum(i.compress_size for i in infos) > size:
                    raise SceneFileError(where, "", f"members claim {sum(i.compress_size for i in infos)} bytes, more than the file's {size}")
                if len({i.filename for i in infos}) != len(infos):
                    raise SceneFileError(where, "", "a member appears twice in the archive")
                try:
                    raw = stored(z, "batch.json")
                except KeyError:
                    raise SceneFileError(where, "batch.json", "missing") from None
                try:
                    meta = json.loads(raw)
                except (ValueError, RecursionError) as e:  # RecursionError: nesting too deep
                    raise SceneFileError(where, "batch.json", f"not JSON ({type(e).__name__})") from None
                if not isinstance(meta, dict):  # save writes an object
                    kind = {bool: "a boolean", int: "a number", float: "a number", str: "a string",
                            list: "an array", type(None): "null"}.get(type(meta), type(meta).__name__)
                    raise SceneFileError(where, "batch.json", f"must be a JSON object, got {kind}")
                fmt = meta.get("format")
                if type(fmt) is not int or fmt != FORMAT_VERSION:  # not true, not 1.0: save writes 1
                    raise SceneFileError(where, "batch.json.format", f"unsupported batch format {fmt!r} (this physcore reads {FORMAT_VERSION})")
                count = meta.get("members")
                if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= 1 << 24:
                    raise SceneFileError(where, "batch.json.members", f"must be a count >= 1, got {count!r}")
                if len(infos) > count + 1:
                    extra = sorted({i.filename for i in infos} - {"batch.json", *(f"member{k}.npz" for k in range(count))})
                    raise SceneFileError(where, _show(extra[0]) if extra else "", "unexpected member (not written by Batch.save)")
                blobs = []
                for k in range(count):
                    try:
                        blobs.append(stored(z, f"member{k}.npz"))
                    except KeyError:
                        raise SceneFileError(where, f"member{k}.npz", "missing") from None
        except (OSError, zipfile.BadZipFile) as e:
            raise SceneFileError(where, "", f"not a batch file ({type(e).__name__}: {_show(str(e))})") from None
        members = []
        for k, b in enumerate(blobs):
            try:
                members.append(Scene.from_bytes(b, source="<pickled Scene>"))
            except SceneFileError as e:
                raise SceneFileError(where, f"member{k}.npz", e.problem if e.field == "" else f"{e.field}: {e.problem}") from None
        threads = meta.get("threads")
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise SceneFileError(where, "batch.json.threads", f"must be null or a count >= 1, got {threads!r}")
        if threads is not None:
            threads = min(threads, usable_cpus())
        diverged = meta.get("diverged") or {}
        if not isinstance(diverged, dict):
            raise SceneFileError(where, "batch.json.diverged", "must be an object")
        for k, msg in diverged.items():
            # ASCII digits only, at most 8 (count <= 2**24): int() refuses "²" and over 4300 digits.
            if not (k.isascii() and k.isdigit() and len(k) <= 8 and int(k) < count):
                raise SceneFileError(where, "batch.json.diverged", f"names no member ({_show(k)})")
            if not isinstance(msg, str):  # save writes the exception's message
                raise SceneFileError(where, f"batch.json.diverged.{k}", f"must be a message (a string), got {type(msg).__name__}")
        saved_device, precision = meta.get("device", "cpu"), meta.get("precision")
        try:
            saved_device, precision = _check_device(saved_device, precision)
        except (InvalidInputError, InvalidTypeError) as e:
            raise SceneFileError(where, "batch.json.device", str(e)) from None
        device = saved_device if device is None else device
        try:
            _same_structure(members, "member")
        except InvalidInputError as e:  # members of different structures: not a batch save wrote
            raise SceneFileError(where, "batch.json.members", str(e)) from None
        # A GPU batch comes back on a GPU of this machine (refused by name where it has none),
        # unless `device` says otherwise; its precision is the file's on a GPU.
        batch = cls(members, threads=threads, device=device, precision=None if device == "cpu" else precision)
        for k, msg in diverged.items():
            batch.diverged[int(k)] = SimulationDiverged(str(msg))
        return batch


class _Overlay:
    """A batch as the renderer reads a scene: the members overlaid, their particles one after the
    other (member k's particle i is particle k·N + i), each member its own hue around the colour
    wheel (its springs drawn too), over member 0's colliders and walls, with member 0's clock.
    Stepping it steps the batch: ``step(n)`` is ``batch.step(n)``; ``advance(duration)`` takes
    the steps of member 0's ``dt`` nearest ``duration`` (members keep their own ``dt``; the
    render's automatic CFL substeps of a fluid scene do not apply). A retired member stays
    where it diverged. Rigid bodies are drawn, every member's, in their own colours, and a
    member's surface (a cloth's ``render.Mesh``) once for each member. Grids and flows are not
    drawn."""

    def __init__(self, batch: Batch) -> None:
        batch._unchanged()  # its colours and counts are member 0's times M
        self._batch = batch
        self._first = batch.members[0]
        m, n = len(batch), self._first.n_particles
        hue = np.arange(m) / max(m, 1)
        rgb = np.clip(np.stack([np.abs(hue * 6 - 3) - 1, 2 - np.abs(hue * 6 - 2), 2 - np.abs(hue * 6 - 4)], axis=1), 0, 1)
        rgb = np.rint((0.25 + 0.75 * rgb) * 255).astype(np.uint8)
        defaults = dict(self._first.render_defaults or {})
        mesh = defaults.pop("mesh", None)
        if n and hasattr(mesh, "faces") and hasattr(mesh, "uv"):  # a render.Mesh: one copy a member
            uv = None if mesh.uv is None else np.tile(mesh.uv, (m, 1))
            defaults["mesh"] = type(mesh)(np.concatenate([np.asarray(mesh.faces) + k * n for k in range(m)]), uv)
        if n:
            defaults["colors"] = np.repeat(rgb, n, axis=0).tolist()
            defaults["color_by"] = "none"  # the hues tell the members apart (a speed scale would not)
        self.render_defaults = defaults
        self.dim = self._first.dim
        self.n_particles = m * n

    def _cat(self, name: str) -> np.ndarray:
        _settle(self._batch._sessions)  # a GPU batch's members written back in one call
        return np.concatenate([getattr(s, name) for s in self._batch.members])

    def _rows(self, velocities: bool) -> np.ndarray:
        """Every member's positions or velocities, member after member: the batch's one read
        (a GPU batch's from its mirror, no member written back)."""
        return self._batch._rows(velocities).reshape(-1, self.dim)

    positions = property(lambda self: self._rows(False))
    velocities = property(lambda self: self._rows(True))
    masses = property(lambda self: self._cat("masses"))
    pinned = property(lambda self: self._cat("pinned"))
    time = property(lambda self: self._first.time)
    dt = property(lambda self: self._first.dt)
    planes = property(lambda self: self._first.planes)
    spheres = property(lambda self: self._first.spheres)
    colliders = property(lambda self: self._first.colliders)
    terms = property(lambda self: self._first.terms)
    fluids = property(lambda self: self._first.fluids)
    grids = property(lambda self: ())
    flows = property(lambda self: ())
    #: Every member's rigid bodies, member after member (each body group keeps its colours).
    bodies = property(lambda self: tuple(g for s in self._batch.members for g in s.bodies))

    @property
    def attributes(self) -> dict[str, np.ndarray]:
        return {a: np.concatenate([s.attributes[a] for s in self._batch.members]) for a in self._first.attributes}

    def boundary_points(self) -> np.ndarray:
        return self._first.boundary_points()

    def pressure(self) -> np.ndarray:
        return self._cat_call("pressure")

    def _cat_call(self, name: str) -> np.ndarray:
        return np.concatenate([getattr(s, name)() for s in self._batch.members])

    def spring_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i, j, rest = self._first.spring_pairs()
        n, m = self._first.n_particles, len(self._batch)
        off = (np.arange(m) * n).repeat(len(i))
        return np.tile(i, m) + off, np.tile(j, m) + off, np.tile(rest, m)

    def auto_dt(self) -> float | None:
        return self._first.auto_dt()

    def step(self, n: int = 1) -> None:
        self._batch.step(n)

    def advance(self, duration: float, substeps: Any = "auto") -> int:
        n = max(1, int(round(float(duration) / self._first.dt))) if substeps == "auto" else int(substeps)
        self._batch.step(n)
        return n

