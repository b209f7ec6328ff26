"""The :class:`Session`: a scene's core simulation, its one-thread-at-a-time rule and its energy
books' reference, shared by the scene, its live parts and the code that drives many scenes.

A :class:`~physcore.Scene` holds one session for life (:attr:`Scene.session
<physcore.Scene.session>`). What steps scenes from outside the scene itself, a
:class:`~physcore.Batch`, :func:`~physcore.sweep`, the live viewer and the notebook widget, goes
through this object's public members and never through the scene's private ones; a second
backend needs only to provide the same members.

A part that joined a scene (a grid, a flow, bodies) holds the session, not the scene: it works on
after its scene is dropped, and the scene is freed by reference counting alone (the scene and its
parts form no reference cycle, which only the cyclic garbage collector would free: it counts
Python objects, not the memory the core holds; rebuilding a scene 20 times in a loop once held
643 MB).
"""
from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterable
from typing import Any

from ._errors import SceneBusyError

__all__ = ["Session"]


def left_sum(values: Iterable[float]) -> float:
    """The floats `values` added left to right from 0.0: how the energy books' parts are summed
    here and in the core (`_core.reference_energies`), so that a total has the same bits in
    both and under every Python (3.12's ``sum()`` compensates its rounding; 3.11's does not)."""
    total = 0.0
    for v in values:
        total += v
    return total


def books(d: dict[str, Any]) -> tuple[float, float]:
    """The core's energy books `d` (``Simulation.energy()``) reduced: ``(total, scale)`` with
    total = (kinetic + Σ potential) + Σ dissipated and scale the same sum of the parts'
    magnitudes (J; a repeated name counted once, as a dict keeps it)."""
    pot, dis = dict(d["potential"]), dict(d["dissipated"])
    total = d["kinetic"] + left_sum(pot.values()) + left_sum(dis.values())
    scale = abs(d["kinetic"]) + left_sum(abs(u) for u in pot.values()) + left_sum(abs(v) for v in dis.values())
    return total, scale


def drift(reference: tuple[float, float] | None, total: float, scale: float) -> float:
    """The relative energy drift of books now at (`total`, `scale`) from their `reference`
    ``(E0, S0)`` (:meth:`Scene.energy_drift <physcore.Scene.energy_drift>`): 0.0 without one,
    NaN where a value is not finite."""
    if reference is None:
        return 0.0
    e0, s0 = reference
    if not all(math.isfinite(v) for v in (e0, s0, total, scale)):
        return math.nan
    denom = max(abs(e0), s0, scale)
    return (total - e0) / denom if denom > 0 else 0.0


_BUSY = (
    "this Scene is being stepped by another thread; use a Scene from one thread at a time (wait for "
    "that call to return, e.g. join the thread), or one Scene per thread"
)


class Session:
    """A core simulation and the rule that one thread at a time uses it.

    Parameters
    ----------
    sim : physcore._core.Simulation
        The core simulation (a scene makes it; user code never needs to).

    Attributes
    ----------
    sim : physcore._core.Simulation
        The core simulation, unchecked: read it only while holding :attr:`lock` and with
        :attr:`pending` None (as :class:`~physcore.Batch` does), otherwise use :meth:`checked`
        or :meth:`exclusive`.
    lock : threading.Lock
        Taken without waiting by every call that releases the GIL for long (stepping, energies,
        fields); a caller that cannot take it raises :class:`~physcore.SceneBusyError`.
    busy : int or None
        The ``threading.get_ident()`` of the thread inside such a call (set by whoever holds
        :attr:`lock`), else None.
    reference_energy : tuple of (float, float), or None
        The energy books' reference ``(E0, S0)`` in J: the total energy at the first step and
        the sum of the magnitudes of its parts (see :meth:`Scene.energy_drift
        <physcore.Scene.energy_drift>`); None until the next step takes it (it is dropped
        whenever the energy's definition or the state changes).
    pending : object or None
        Where the scene's newest state is kept when not in :attr:`sim`: a GPU
        :class:`~physcore.Batch` keeps its members' state on the device between calls, and
        ``pending(session)`` writes it into :attr:`sim` (:meth:`checked` and :meth:`exclusive`
        call it, so every use of the scene sees its newest state). None when :attr:`sim` is
        current.
    parts : list
        The scene's parts as it stores them (a list it appends to and never rebinds; read
        only): a driver of many scenes counts them to see a member's structure change
        (:class:`~physcore.Batch`).

    Examples
    --------
    Run a call on a scene's core as its only user, as a driver of many scenes does:

    >>> import physcore as pc
    >>> scene = pc.scenes.kepler()
    >>> session = scene.session
    >>> session.exclusive(lambda sim: sim.step(10))
    >>> scene.step_count
    10
    >>> session.busy is None  # nobody is inside a call now
    True
    """

    __slots__ = ("busy", "lock", "parts", "pending", "reference_energy", "sim")

    def __init__(self, sim: Any, parts: list[Any] | None = None) -> None:
        self.sim = sim
        self.parts: list[Any] = [] if parts is None else parts
        # A re-entrant lock for its owner check, not for re-entry (refused by `busy`): Ctrl-C
        # can land between any call's return and the next line, so a call cannot learn from a
        # returned value that it took the lock; it releases in `finally` whatever this thread
        # holds (an RLock's release refuses a lock this thread does not hold), see `exclusive`.
        self.lock = threading.RLock()
        self.busy: int | None = None
        self.reference_energy: tuple[float, float] | None = None
        self.pending: Callable[[Session], None] | None = None

    def checked(self) -> Any:
        """The simulation, unless another thread is inside a call; its newest state written
        into it first where a GPU batch keeps that (:attr:`pending`).

        Raises
        ------
        SceneBusyError
            Another thread holds the session (instead of pyo3's bare "Already mutably borrowed"
            RuntimeError), or is stepping the GPU batch that keeps its state.
        """
        busy = self.busy
        if busy is not None and busy != threading.get_ident():
            raise SceneBusyError(_BUSY)
        if self.pending is not None:
            self.pending(self)
        return self.sim

    def exclusive(self, call: Callable[[Any], Any]) -> Any:
        """Runs ``call(sim)`` (a call that releases the GIL) as the only user and returns what it
        returns; another thread's use meanwhile raises :class:`~physcore.SceneBusyError`.

        Raises
        ------
        SceneBusyError
            Another thread is inside a call (nothing runs).
        """
        sim = self.checked()
        me = threading.get_ident()
        if self.busy == me:  # a call from inside a call on this thread (the lock would let it in)
            raise SceneBusyError(_BUSY)
        # Taken inside `try`: a KeyboardInterrupt raised as acquire() returns (Python checks for
        # signals there) left the lock taken and every later call refused (13 % of real Ctrl-Cs
        # in a loop of step(1), found by a fault audit). `finally` does nothing that can be
        # interrupted before the release (an assignment and a comparison), and the release is
        # refused, harmlessly, where this thread does not hold the lock.
        try:
            if not self.lock.acquire(blocking=False):
                raise SceneBusyError(_BUSY)
            self.busy = me
            if self.pending is not None:  # a GPU batch stepped it between the check and the lock
                self.pending(self)
            return call(sim)
        finally:
            if self.busy == me:
                self.busy = None
            try:
                self.lock.release()
            except RuntimeError:  # not this thread's: another thread's, or not yet taken
                pass

    def take_reference_energy(self) -> tuple[float, float]:
        """Takes the books' reference now (:attr:`reference_energy`) and returns it: the total
        energy ``E0`` (J) and ``S0``, the sum of the magnitudes of kinetic, potential and
        dissipated energy (J). Raises what :meth:`exclusive` raises."""
        self.reference_energy = books(self.exclusive(lambda sim: sim.energy()))
        return self.reference_energy

    def energy_changed(self) -> None:
        """The books' reference is to be taken anew at the next step (a part's field was set)."""
        self.reference_energy = None
