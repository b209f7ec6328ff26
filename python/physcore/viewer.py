"""The live viewer: a scene running in a window, drawn as its GIF would be, that the mouse and
the keyboard can reach into. ``physcore view SCENE`` on the command line, :func:`view` here.

The loop (Fiedler, "Fix your timestep!", 2004)
----------------------------------------------
The simulation advances in fixed *ticks*, each the scene's frame of its GIF: ``frame_time``
simulated seconds (``scene.advance(frame_time)`` for scenes with automatic substeps, else
``round(frame_time / dt)`` steps of dt), exactly as ``physcore render`` steps it. A tick is due
every ``1 / fps`` seconds of wall time (the scene's ``fps``), so the window plays at the GIF's
speed. Wall time goes into an accumulator; every drawn frame runs the ticks that are due (at
most :data:`MAX_TICKS_PER_DRAW`, the rest dropped: a scene too slow for real time then plays
slower rather than falling further and further behind) and draws the state interpolated between the last two ticks
by the accumulator's fraction, so motion is smooth at any display rate (up to 60 Hz). Ticks
also stop for a frame to be drawn once they have taken 50 ms, so that a slow scene still draws
and follows the pointer at about 20 Hz (the HUD then says "slower than real time"). The
simulation itself never sees the display rate: its steps are those of the GIF.

Drawing
-------
The frames are rasterised by :mod:`physcore.render` with the scene's ``render_defaults``
(colouring, theme, view, radius, size) and shown with the same palette. The camera and the colour
scale are fixed once, at the start, from a short preview run on a copy of the scene (the same
fit a GIF makes to its whole run); a preview cut short by its wall-time budget (`preview`) gets
a 10 % margin around what it covered. A line at the top shows the parameters the keys change,
the bottom band the clock and the viewer's state.

Mouse and keys
--------------
See :data:`KEYS`. Dragging picks the free particle nearest the pointer (within a few pixels of
its disc) and moves it to the pointer: in 2D directly, in 3D within the plane through the
particle parallel to the screen. While held, the particle is pinned (the scene is rebuilt with
its pinned flag set, as for a parameter key below), so it is a kinematic constraint: it goes
only where it is put, along the pointer's path at the middle of each of up to 8 parts of a
tick, and its springs never pull it off between (setting the position of a free particle each
part instead pumps energy into a stiff cloth until it flies apart). Letting go unpins it with
the pointer's velocity over the last tick (a throw). **Dragging does work on the system**: the
energy books do not balance over a drag (a pinned particle's motion is imposed, outside them),
and every write of the state restarts the scene's energy-drift reference
(:attr:`physcore.Scene.positions`), so :meth:`~physcore.Scene.energy_drift` afterwards measures
from the last write.

Terms are immutable records (:mod:`physcore.terms`); a parameter key puts a new record in place
of the old one with :meth:`physcore.Scene.replace` (the core's ``replace_term``: no scene file is
written): positions, velocities, time, step count and the dissipated-energy ledger stay; the
integrator's force cache is dropped (the forces are recomputed with the new parameter), and the
energy-drift reference restarts (the potential changed with the parameter). A fixed-step
scene whose change shortens its stability limit (:meth:`physcore.Scene.suggest_dt`) gets a
proportionally smaller dt, never a larger one than it started with, so stiffening stays stable.

Examples
--------
Run the hanging cloth for 2 s of wall time and keep a screenshot (needs a display, or Xvfb)::

    physcore view cloth --seconds 2 --screenshot cloth.png

>>> from physcore.viewer import FixedStep
>>> clock = FixedStep(1 / 30)
>>> clock.advance(0.05), round(clock.alpha, 3)
(1, 0.5)
"""
from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from . import _check
from ._errors import InvalidInputError, InvalidTypeError, PhyscoreError, SimulationDiverged

__all__ = [
    "view", "Viewer", "ViewResult", "FixedStep", "interpolate", "pick", "screen_to_world", "param_value",
    "scale_param", "keys_text", "KEYS", "MAX_TICKS_PER_DRAW", "STEP_FACTOR", "PARAM_RANGE", "INSTALL",
]

#: What to install when pygame is missing.
INSTALL = 'pip install "physcore[view]"'

#: Most ticks run before one drawn frame; beyond it the accumulator drops the backlog.
MAX_TICKS_PER_DRAW = 4

#: The keys and the mouse: (key, what it does).
KEYS: tuple[tuple[str, str], ...] = (
    ("mouse", "drag a particle (left button)"),
    ("space", "pause / run"),
    (". or Right", "one tick (one GIF frame) while paused"),
    ("[ / ]", "spring stiffness ÷ 1.25 / × 1.25 (each key within 100× of the start)"),
    ("- / =", "spring damping ÷ 1.25 / × 1.25 (from 0: 1 % of critical)"),
    ("g / G", "gravity ÷ 1.25 / × 1.25"),
    ("d / D", "drag coefficient ÷ 1.25 / × 1.25"),
    ("p", "screenshot: SCENE-NNN.png in the current directory"),
    ("r", "reset to the start (keeps the parameters)"),
    ("q or Esc", "quit"),
)

#: Factor of one parameter key press.
STEP_FACTOR = 1.25
#: The keys keep each parameter within this factor of its start value either way (20 presses):
#: 110 presses of ] once stiffened a cloth 4·10¹⁰ times and froze the window for 4 s a frame.
PARAM_RANGE = 100.0
#: Largest display rate, Hz.
_MAX_DRAW_RATE = 60
#: Wall seconds of ticks before a frame is drawn anyway (the ticks still due are dropped), so
#: that a scene slower than real time still draws and follows the pointer at about 20 Hz.
_TICK_BUDGET = 0.05
#: Parts of a tick while dragging (the grabbed particle is placed before each).
_DRAG_PARTS = 8
#: Margin (fraction of the extent) around a preview cut short by its budget.
_MARGIN = 0.1


def keys_text() -> str:
    """The key help, one key a line (printed at start and in ``physcore view --help``)."""
    width = max(len(k) for k, _ in KEYS) + 2
    return "\n".join(f"  {k.ljust(width)}{what}" for k, what in KEYS)


# --------------------------------------------------------------------------- pure parts
class FixedStep:
    """Fiedler's fixed-timestep accumulator, in wall seconds.

    Parameters
    ----------
    tick : float
        Wall seconds per tick (> 0, finite): ``1 / fps``.
    max_ticks : int, default MAX_TICKS_PER_DRAW
        Most ticks :meth:`advance` returns at once; the backlog beyond is dropped.

    Raises
    ------
    InvalidTypeError, InvalidInputError
        A `tick` that is not a finite number > 0, or `max_ticks` not an int >= 1.
    """

    def __init__(self, tick: float, max_ticks: int = MAX_TICKS_PER_DRAW) -> None:
        tick = _check.real("tick", tick)
        if not (tick > 0 and math.isfinite(tick)):
            raise InvalidInputError(f"tick: must be a finite number of seconds > 0, got {tick!r}")
        if isinstance(max_ticks, bool) or not isinstance(max_ticks, int):
            raise InvalidTypeError(f"max_ticks: expected an int, got {type(max_ticks).__name__}")
        if max_ticks < 1:
            raise InvalidInputError(f"max_ticks: must be >= 1, got {max_ticks}")
        self.tick = float(tick)
        self.max_ticks = max_ticks
        self.accumulator = 0.0
        self.paused = False
        #: Wall seconds dropped because ticks fell behind (the scene ran slower than real time).
        self.dropped = 0.0

    def advance(self, wall_dt: float) -> int:
        """Add `wall_dt` seconds (negative or non-finite counts as 0) and return the ticks due
        now; paused, nothing accumulates and 0 is returned."""
        if self.paused or not (wall_dt > 0 and math.isfinite(wall_dt)):
            return 0
        self.accumulator += wall_dt
        n = int(self.accumulator // self.tick)
        self.accumulator -= n * self.tick
        if n > self.max_ticks:
            self.dropped += (n - self.max_ticks) * self.tick
            n = self.max_ticks
        return n

    @property
    def alpha(self) -> float:
        """Fraction in [0, 1] of the way from the previous tick's state to the current one to
        draw; 1 (the current state) while paused."""
        return 1.0 if self.paused else min(1.0, max(0.0, self.accumulator / self.tick))

    def pause(self, paused: bool = True) -> None:
        """Pause (or run again); the accumulator restarts from 0 either way."""
        self.paused = bool(paused)
        self.accumulator = 0.0


def interpolate(prev: np.ndarray, curr: np.ndarray, alpha: float) -> np.ndarray:
    """``prev + alpha (curr - prev)``: the state drawn between two ticks (arrays of one shape)."""
    return prev + alpha * (curr - prev)


def pick(col: np.ndarray, row: np.ndarray, point: tuple[float, float], radius: float,
         free: np.ndarray | None = None, depth: np.ndarray | None = None) -> int | None:
    """The particle nearest `point` on screen within `radius` pixels, or None.

    Parameters
    ----------
    col, row : (N,) float
        Pixel positions of the particles (as :class:`physcore.render` draws them).
    point : (float, float)
        Pixel (column, row) of the pointer; its centre is taken, + 0.5.
    radius : float
        Pick radius, pixels.
    free : (N,) bool, optional
        Only these may be picked (the pinned ones cannot be dragged).
    depth : (N,) float, optional
        3D: among particles at the same distance, the nearest the viewer (largest) wins.
    """
    d2 = (col - (point[0] + 0.5)) ** 2 + (row - (point[1] + 0.5)) ** 2
    ok = np.isfinite(d2) & (d2 <= radius * radius)
    if free is not None:
        ok &= free
    if not ok.any():
        return None
    idx = np.flatnonzero(ok)
    keys = (d2[idx],) if depth is None else (-depth[idx], d2[idx])
    return int(idx[np.lexsort(keys)[0]])


def screen_to_world(cam: Any, origin: np.ndarray, point: tuple[float, float], through: np.ndarray) -> np.ndarray:
    """The world point (dim,) under the pixel `point` of camera `cam` (a fitted
    ``physcore.render`` camera, positions relative to `origin`): in 2D the point itself, in 3D
    the one in the plane parallel to the screen through `through` (dim,) m."""
    s0 = (point[0] + 0.5 - 0.5 * cam.width) / cam.scale + cam.centre[0]
    s1 = (cam.row0 - (point[1] + 0.5)) / cam.scale + cam.centre[1]
    if cam.dim == 2:
        return np.array([s0, s1]) + origin
    depth = float((np.asarray(through, dtype=np.float64) - origin) @ cam.basis[:, 2])
    return cam.basis @ np.array([s0, s1, depth]) + origin


def _pointer(event: Any) -> tuple[float, float] | None:
    """An event's ``pos`` as two finite floats, or None: a synthetic event may carry anything."""
    try:
        c, r = getattr(event, "pos", None)  # type: ignore[misc]
        return _check.finite("pos", c), _check.finite("pos", r)
    except (TypeError, ValueError):  # not two real numbers (PhyscoreError's are ValueError/TypeError)
        return None


def _int_attr(event: Any, name: str) -> int | None:
    """An event's int attribute (``key``, ``button``, ``mod``), or None for anything else."""
    v = getattr(event, name, None)
    return None if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) else int(v)


def _parts(k: int, m: int) -> list[int]:
    """`k` steps in min(k, m) near-equal parts."""
    m = max(1, min(k, m))
    return [k // m + (1 if p < k % m else 0) for p in range(m)]


# --------------------------------------------------------------------------- parameters
class _Param(NamedTuple):
    name: str  # "stiffness", "damping", "gravity", "drag"
    keys: tuple[str, str]  # down, up
    label: str  # HUD symbol
    unit: str


_PARAMS = (
    _Param("stiffness", ("[", "]"), "k", "N/m"),
    _Param("damping", ("-", "="), "c", "N·s/m"),
    _Param("gravity", ("g", "G"), "g", "m/s²"),
    _Param("drag", ("d", "D"), "b", "kg/s"),
)


def _terms_of(scene: Any, name: str) -> list[tuple[int, Any]]:
    from .terms import Drag, Gravity, Springs

    kind = {"stiffness": Springs, "damping": Springs, "gravity": Gravity, "drag": Drag}[name]
    return [(k, t) for k, t in enumerate(scene.terms) if type(t) is kind]


def param_value(scene: Any, name: str) -> float | None:
    """The value a parameter key changes, or None where the scene has no such term:
    ``"stiffness"`` / ``"damping"`` the mean over all springs (N/m, N·s/m), ``"gravity"`` |g|
    (m/s², the first Gravity term), ``"drag"`` the first Drag coefficient (kg/s)."""
    terms = _terms_of(scene, name)
    if not terms:
        return None
    if name in ("stiffness", "damping"):
        values = np.concatenate([np.asarray(getattr(t, name), dtype=np.float64).reshape(-1) for _, t in terms])
        return float(values.mean()) if values.size else None
    if name == "gravity":
        return float(np.linalg.norm(terms[0][1].g))
    return float(terms[0][1].coefficient)


def _rebuild(scene: Any, edit: Callable[[dict, dict], None], like: Any = None) -> Any:
    """A new Scene from `scene`'s in-memory scene file after ``edit(meta, arrays)``, without the
    integrator's force cache and with a fresh energy-drift reference. `like` (default `scene`)
    gives the term records, dt and integrator when `scene` is an earlier state (reset)."""
    from . import _scenefile
    from .scene import Scene

    arrays = scene._file_arrays()
    meta = json.loads(arrays["meta"].item())
    if like is not None and like is not scene:
        now = like._file_arrays()
        now_meta = json.loads(now["meta"].item())
        for key in ("terms", "dt", "integrator", "rtol", "atol"):
            meta[key] = now_meta[key]
        for key in [a for a in arrays if a.startswith("term")]:
            del arrays[key]
        arrays.update({a: v for a, v in now.items() if a.startswith("term")})
    edit(meta, arrays)
    arrays.pop("cache_forces", None)
    arrays.pop("cache_power", None)
    meta["e0"], meta["e0_scale"] = None, 0.0
    arrays["meta"] = np.array(json.dumps(meta, default=float, allow_nan=False))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    new = Scene._from_file(_scenefile.read_bytes(buf.getvalue(), "<viewer>"), scene.threads)
    new.render_defaults = scene.render_defaults
    return new


def scale_param(scene: Any, name: str, factor: float) -> Any:
    """Multiply parameter `name` (see :func:`param_value`) by `factor` in every term of `scene`
    that has it, in place (:meth:`physcore.Scene.replace`: the core swaps the terms, the state,
    time and books stay; no scene file is written), and return `scene`. Damping at 0 that is
    increased starts at 1 % of the critical damping 2 √(k m) of the mean spring and particle.

    Raises InvalidInputError naming `name` where the scene has no such term, or `factor` is not
    a finite number > 0; nothing changes then.
    """
    factor = _check.real("factor", factor)
    if not (factor > 0 and math.isfinite(factor)):
        raise InvalidInputError(f"factor: must be a finite number > 0, got {factor!r}")
    names = [p.name for p in _PARAMS]
    if name not in names:
        raise InvalidInputError(f"name: expected one of {', '.join(names)}, got {name!r}")
    terms = _terms_of(scene, name)
    if not terms:
        raise InvalidInputError(f"name: the scene has no term with a {name!r} parameter")
    start = param_value(scene, "damping") if name == "damping" else None
    kick = name == "damping" and start == 0.0 and factor > 1
    if kick:
        k, m = param_value(scene, "stiffness") or 0.0, float(np.mean(scene.masses)) if scene.n_particles else 0.0
        base = 0.01 * 2.0 * math.sqrt(max(k * m, 0.0))
    for _, t in terms:
        if name in ("stiffness", "damping"):
            a = np.asarray(getattr(t, name), dtype=np.float64)
            new = dataclasses.replace(t, **{name: np.full_like(a, base) if kick else a * factor})
        elif name == "gravity":
            new = dataclasses.replace(t, g=np.array([factor * float(c) for c in t.g]))
        else:
            new = dataclasses.replace(t, coefficient=factor * float(t.coefficient))
        scene.replace(t.name, new)
    return scene


# --------------------------------------------------------------------------- the live state
class _Live:
    """The running scene and the two latest ticks' states (for interpolation), the drag and the
    parameter keys. No display: testable on its own."""

    def __init__(self, scene: Any, color_by: str) -> None:
        from .render._recording import default_stepping, scene_defaults

        # Stepped in place, and parameter keys replace its terms in place (Scene.replace).
        self.scene = scene
        self.start = _rebuild(scene, lambda meta, arrays: None)  # the state to reset to
        d = scene_defaults(scene)
        spf, ft = default_stepping(d, scene.dt)
        self.advance = ft is not None
        #: Simulated seconds per tick.
        self.frame_time = float(ft) if ft is not None else spf * float(scene.dt)
        self.steps = spf
        self.dt0 = float(scene.dt)
        self.suggest0 = self._suggest(scene)
        self.params0: dict[str, float] = {}
        self.pressure = color_by == "pressure"
        self.pinned = np.asarray(scene.pinned, dtype=bool).copy()
        self.grabbed: int | None = None
        self.target: np.ndarray | None = None  # where the pointer holds the grabbed particle
        self.held: np.ndarray | None = None  # where the last tick left it
        self.vel: np.ndarray | None = None  # the pointer's velocity over the last tick, m/s
        self.ticks = 0
        self.params0 = self.params()  # the start values the keys stay within PARAM_RANGE of
        self._read()
        self._snap()

    @property
    def tick_time(self) -> float:
        """Simulated seconds one tick advances: ``frame_time``, or the whole steps of dt nearest
        it (as ``physcore render`` steps)."""
        return self.frame_time if self.advance else self.steps * float(self.scene.dt)

    @staticmethod
    def _suggest(scene: Any) -> float:
        try:
            s = float(scene.suggest_dt())
        except (AttributeError, ValueError):
            return math.inf
        return s if s > 0 else math.inf

    def _read(self) -> None:
        s = self.scene
        self.x = np.asarray(s.positions, dtype=np.float64).copy()
        self.v = np.asarray(s.velocities, dtype=np.float64).copy()
        self.t = float(s.time)
        self.p = np.asarray(s.pressure(), dtype=np.float64).copy() if self.pressure else None
        if self.grabbed is not None:  # pinned while held: its velocity is the pointer's
            self.v[self.grabbed] = self.vel

    def _snap(self) -> None:
        """The previous state := the current one (nothing to interpolate)."""
        self.px, self.pv, self.pt = self.x, self.v, self.t
        self.pp = self.p

    def drawn(self, alpha: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None]:
        """Positions, velocities, time and pressures interpolated by `alpha` between ticks."""
        p = None if self.p is None else interpolate(self.pp, self.p, alpha)
        return interpolate(self.px, self.x, alpha), interpolate(self.pv, self.v, alpha), self.pt + alpha * (self.t - self.pt), p

    # -------------------------------------------------------------- stepping
    def tick(self) -> None:
        """One tick (the GIF's frame): raises SimulationDiverged with the scene rolled back to
        the start of the failing call."""
        self.px, self.pv, self.pt, self.pp = self.x, self.v, self.t, self.p
        s = self.scene
        if self.grabbed is None:
            if self.advance:
                s.advance(self.frame_time)
            else:
                s.step(self.steps)
        else:
            # The grabbed particle is pinned: it moves only where it is put, along the
            # pointer's path, at the middle of each part of the tick.
            i, a, b = self.grabbed, self.held, self.target
            self.vel = (b - a) / self.tick_time
            parts = [1] * _DRAG_PARTS if self.advance else _parts(self.steps, _DRAG_PARTS)
            for k, n in enumerate(parts):
                self._place(i, a + (b - a) * ((k + 0.5) / len(parts)))
                if self.advance:
                    s.advance(self.frame_time / len(parts))
                else:
                    s.step(n)
            self._place(i, b)
            self.held = b.copy()
        self.ticks += 1
        self._read()

    def _place(self, i: int, x: np.ndarray) -> None:
        pos = np.asarray(self.scene.positions, dtype=np.float64).copy()
        pos[i] = x
        self.scene.positions = pos

    # -------------------------------------------------------------- drag
    def grab(self, i: int) -> None:
        """Hold particle `i` (not one of the scene's pinned ones): the scene is rebuilt with it
        pinned, so that it goes exactly where the pointer puts it."""
        if self.pinned[i]:
            raise InvalidInputError(f"i: particle {i} is pinned and cannot be dragged")
        if self.grabbed is not None:
            self.release()

        def pin(meta: dict, arrays: dict) -> None:
            arrays["pinned"] = arrays["pinned"].copy()
            arrays["pinned"][i] = True

        self.scene = _rebuild(self.scene, pin)
        self.grabbed = int(i)
        self.held = self.x[i].copy()
        self.target = self.x[i].copy()
        self.vel = np.zeros_like(self.target)
        self._read()

    def move(self, target: np.ndarray, paused: bool) -> None:
        """Hold the grabbed particle at `target` (dim,) m; paused, it is put there at once."""
        if self.grabbed is None:
            return
        self.target = np.asarray(target, dtype=np.float64).copy()
        if paused:
            self._place(self.grabbed, self.target)
            self.held = self.target.copy()
            self._read()
            self._snap()

    def release(self) -> None:
        """Let go: the particle is free again (rebuilt unpinned), with the pointer's velocity."""
        if self.grabbed is None:
            return
        i, vel = self.grabbed, self.vel

        def unpin(meta: dict, arrays: dict) -> None:
            arrays["pinned"] = arrays["pinned"].copy()
            arrays["pinned"][i] = False
            arrays["velocities"] = arrays["velocities"].copy()
            arrays["velocities"][i] = vel

        self.scene = _rebuild(self.scene, unpin)
        self._forget()
        self._read()

    def _forget(self) -> None:
        self.grabbed = self.target = self.held = self.vel = None

    # -------------------------------------------------------------- parameters and reset
    def params(self) -> dict[str, float]:
        """The parameters the scene has: name -> value (see :func:`param_value`)."""
        out = {}
        for p in _PARAMS:
            value = param_value(self.scene, p.name)
            if value is not None:
                out[p.name] = value
        return out

    def scale(self, name: str, factor: float) -> bool:
        """Multiply parameter `name` by `factor`, unless that takes it beyond
        :data:`PARAM_RANGE` times its start value either way; returns whether it changed."""
        start, now = self.params0.get(name), param_value(self.scene, name)
        if start and now and not (start / PARAM_RANGE <= now * factor <= start * PARAM_RANGE):
            return False
        self.scene = scale_param(self.scene, name, factor)
        if not start:
            # From 0 (damping's 1 % of critical) the range is about the first value above 0:
            # else a held = key raised it without bound, and dt shrank with it.
            self.params0[name] = param_value(self.scene, name) or 0.0
        self._restep()
        return True

    def _restep(self) -> None:
        """Fixed steps: dt shrinks with the stability limit, never above its start value."""
        if self.advance:
            return
        s = self.scene
        dt = self.dt0 * min(1.0, self._suggest(s) / self.suggest0) if math.isfinite(self.suggest0) else self.dt0
        if dt != s.dt:
            s.dt = dt
        from .render._recording import steps_for

        self.steps = steps_for(self.frame_time, s.dt)

    def reset(self) -> None:
        """Back to the start state, keeping the current parameters."""
        self.scene = _rebuild(self.start, lambda meta, arrays: None, like=self.scene)
        self._forget()
        self._read()
        self._snap()


# --------------------------------------------------------------------------- drawing
class _Painter:
    """Rasterises the live state as :func:`physcore.render.gif` draws the scene's frames, with
    one camera and colour scale fitted once to a preview run."""

    def __init__(self, scene: Any, settings: dict[str, Any], preview: float, hud: bool) -> None:
        from .render._raster import _Rasteriser
        from .render._recording import _simulate, default_stepping, scene_defaults
        from .render._scene_state import _scene_springs

        d = scene_defaults(scene)
        self.size = settings["size"]
        color_by = settings["color_by"]
        spf, ft = default_stepping(d, scene.dt)
        frames = int(d.get("frames", 90))
        # The preview: as many of the GIF's frames as `preview` wall seconds allow (one tick
        # timed first, on a copy of its own), simulated on a copy.
        budget = frames
        if preview <= 0:
            budget = 1
        elif frames > 1:
            probe = _rebuild(scene, lambda meta, arrays: None)
            t0 = time.perf_counter()
            try:
                if ft is not None:
                    probe.advance(ft)
                else:
                    probe.step(spf)
            except SimulationDiverged:
                pass
            cost = max(time.perf_counter() - t0, 1e-6)
            budget = max(2, min(frames, int(preview / cost)))
        copy = _rebuild(scene, lambda meta, arrays: None)
        copy.render_defaults = scene.render_defaults
        try:
            rec = _simulate(copy, budget, spf, color_by == "speed", settings["springs"], False,
                            need_pressure=color_by == "pressure", frame_time=ft)
        except SimulationDiverged:
            rec = _simulate(_rebuild(scene, lambda meta, arrays: None), 1, spf, color_by == "speed",
                            settings["springs"], False, need_pressure=color_by == "pressure", frame_time=ft)
        self.complete = rec.frames >= frames
        fit = None
        if not self.complete:
            pts = rec.positions.reshape(-1, rec.positions.shape[-1]).astype(np.float64)
            if rec.walls is not None and len(rec.walls):
                pts = np.concatenate([pts, rec.walls])
            pts = pts[np.all(np.isfinite(pts), axis=1)]
            if len(pts):
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                c, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * (1 + _MARGIN)
                # The grown box's corners: every combination of lower/upper per axis.
                corners = np.array([[c[a] + (half[a] if (k >> a) & 1 else -half[a]) for a in range(len(c))]
                                    for k in range(2 ** len(c))])
                fit = np.concatenate([pts, corners])
        trail = min(int(settings.get("trail") or 0), 240)
        kw: dict[str, Any] = {"colorbar": settings["colorbar"], "size_by": settings["size_by"], "annotate": True,
                              "title": (settings.get("title") or "physcore") if hud else (settings.get("title") or None),
                              "trail": trail}
        if fit is not None:
            kw["fit"] = fit
        # A shaded surface where the scene's GIF has one (the cloth), and soft discs where it has
        # them, exactly as gif() picks them.
        from .render._mesh import check_mesh, check_texture

        mesh = None if color_by == "density" else check_mesh(d.get("mesh"), rec.positions.shape[1])
        kw.update(mesh=mesh, texture=check_texture(d.get("texture"), mesh), theme=settings["theme"],
                  antialias=bool(d.get("antialias", False)))
        self.ras = _Rasteriser(rec, self.size, color_by, settings["radius"], settings["view"], **kw)
        self.hud = hud and self.ras.title is not None
        # The live recording: the trail's history of ticks, then the drawn state, last.
        f = trail + 1 if trail and hasattr(self.ras, "_pix") else 1
        n, dim = rec.positions.shape[1:]
        self.origin = rec.origin
        m = 0 if rec.pairs is None else rec.pairs[0].size
        self.springs = None if rec.pairs is None else _scene_springs(scene)
        self.live = rec._replace(
            positions=np.repeat(rec.positions[:1], f, axis=0),
            speeds=None if rec.speeds is None else np.zeros((f, n), np.float32),
            strain=None if rec.strain is None else np.zeros((f, m), np.float32),
            pressures=None if rec.pressures is None else np.zeros((f, n), np.float32),
            times=np.zeros(f),
            fields=None, field_points=None,
        )
        self.ras.rec = self.live
        self.ras.trail = f - 1
        self.frames = f
        self.cam = self.ras.cam

    def push(self, x: np.ndarray) -> None:
        """A tick's state joins the trail's history."""
        if self.frames > 1:
            pos = self.live.positions
            pos[:-2] = pos[1:-1]
            with np.errstate(over="ignore", invalid="ignore"):
                pos[-2] = x - self.origin

    def pixels(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Pixel column, row and (3D) depth of world positions (N, dim)."""
        s, depth = self.cam.project(np.asarray(x, dtype=np.float64) - self.origin)
        col, row = self.cam.pixels(s)
        return col, row, depth

    def draw(self, x: np.ndarray, v: np.ndarray, t: float, p: np.ndarray | None, params: str, status: str) -> np.ndarray:
        """(H, W, 3) uint8 RGB image of the state, with the HUD."""
        from .render._colorbar import _CB_MARGIN, _draw_text, _text_mask
        from .render._palette import _BACKGROUND, _TEXT
        from .render._raster import _draw_title, _overlay, _paste
        from .render._rows import _row_norms
        from .render._scene_state import _strain

        live, k = self.live, self.frames - 1
        with np.errstate(over="ignore", invalid="ignore"):
            live.positions[k] = x - self.origin
            if live.speeds is not None:
                live.speeds[k] = _row_norms(v)
            if live.strain is not None and self.springs is not None:
                live.strain[k] = _strain(x, *self.springs)
            if live.pressures is not None and p is not None:
                live.pressures[k] = p
        live.times[k] = t
        if self.frames > 1:
            self.ras._pix = None  # the history moved: project it again
        # Full colour where the renderer has it (a shaded mesh), else the palette image.
        rgb = self.ras.frame_rgb(k)  # a new C-contiguous array
        if self.hud:
            # Drawn as palette indices on an overlay (-1: nothing), in the labels' font of this
            # image size where the renderer has several (else the bitmap font).
            px = self.ras.font_px
            line = _text_mask("0", px).shape[0]
            h, w = rgb.shape[:2]
            over = _overlay((h, w))
            right = w - 8 if self.ras.colorbar is None else self.ras.colorbar.lo_x - 8
            over[: _CB_MARGIN + line + 1, : max(right, 0)] = _BACKGROUND
            _draw_title(over, params or " ", right, px)
            if status:
                _draw_text(over, status, min(8 * line, w // 4), h - 4 - line, _TEXT, _BACKGROUND, px=px)
            _paste(rgb, over, self.ras.palette)
        return rgb


# --------------------------------------------------------------------------- the window
class ViewResult(NamedTuple):
    """What :func:`view` returns.

    Attributes
    ----------
    scene : physcore.Scene
        The scene as the viewer left it: the scene given, stepped and with its parameter keys'
        terms replaced in place, unless a reset replaced it by a copy of its start.
    ticks : int
        Ticks run (each the scene's GIF frame: ``frame_time`` simulated seconds).
    draws : int
        Frames drawn.
    wall : float
        Wall seconds the window was open (after the preview).
    screenshots : list of pathlib.Path
        PNGs written (key ``p`` and `screenshot`), in order.
    image : (H, W, 3) uint8
        The window's last frame, as read back from the display.
    """

    scene: Any
    ticks: int
    draws: int
    wall: float
    screenshots: list
    image: np.ndarray


def _import_pygame() -> Any:
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
    except ImportError as e:
        raise ImportError(f"the live viewer needs pygame-ce: {INSTALL}") from e
    return pygame


class Viewer:
    """The window and its loop (see the module docstring); :func:`view` makes and runs one.

    A `script` item's callable receives this object: it reads ``scene``, ``time``, ``paused``,
    ``ticks``, ``draws``, ``params`` and ``grabbed``, and finds where a particle is drawn with
    :meth:`pixel_of`.
    """

    def __init__(self, scene: Any, *, name: str, settings: dict[str, Any], fps: float, preview: float, hud: bool,
                 out: Any) -> None:
        self.pygame = _import_pygame()
        self.name = name
        self.out = out
        self.live = _Live(scene, settings["color_by"])
        self.painter = _Painter(scene, settings, preview, hud)
        self.clock = FixedStep(1.0 / fps)
        self.draws = 0
        self.status = ""
        self.screenshots: list[Path] = []
        self.quit = False
        self.alpha = 1.0
        self.image: np.ndarray | None = None
        self.slow = 0.0

    # -------------------------------------------------------------- read by scripts
    @property
    def scene(self) -> Any:
        return self.live.scene

    @property
    def time(self) -> float:
        """The scene's simulated time (s) at the latest tick."""
        return self.live.t

    @property
    def paused(self) -> bool:
        return self.clock.paused

    @property
    def ticks(self) -> int:
        return self.live.ticks

    @property
    def tick_time(self) -> float:
        """Simulated seconds per tick (the scene's GIF frame)."""
        return self.live.tick_time

    @property
    def grabbed(self) -> int | None:
        return self.live.grabbed

    @property
    def params(self) -> dict[str, float]:
        return self.live.params()

    def pixel_of(self, i: int) -> tuple[int, int]:
        """The pixel (column, row) where particle `i` is drawn now (its interpolated position).

        Raises InvalidTypeError / InvalidInputError naming `i` for a bad index, or a particle
        so far away that it is at no finite pixel."""
        x, _, _, _ = self.live.drawn(self.alpha)
        i = _check.int_in_range("i", i, 0, len(x) - 1)
        with np.errstate(over="ignore", invalid="ignore"):
            col, row, _ = self.painter.pixels(x[i : i + 1])
        if not (math.isfinite(col[0]) and math.isfinite(row[0])):
            raise InvalidInputError(f"i: particle {i} at {x[i].tolist()} m is at no finite pixel of this camera")
        return int(math.floor(col[0])), int(math.floor(row[0]))

    # -------------------------------------------------------------- input
    def _key(self, event: Any) -> str:
        """The key's character, or "" (ignored) for an event naming no key pygame knows."""
        pg = self.pygame
        key = _int_attr(event, "key")
        if key is None:
            return ""
        special = {pg.K_ESCAPE: "esc", pg.K_SPACE: " ", pg.K_RIGHT: "."}
        if key in special:
            return special[key]
        ch = getattr(event, "unicode", "")
        ch = ch if isinstance(ch, str) else ""
        if not ch:
            try:
                ch = pg.key.name(key)
            except (OverflowError, ValueError, TypeError, pg.error):  # beyond SDL's key codes
                return ""
            if len(ch) == 1 and (_int_attr(event, "mod") or 0) & pg.KMOD_SHIFT:
                ch = ch.upper()
        return ch

    def _on_key(self, ch: str) -> None:
        live = self.live
        if not isinstance(ch, str):
            return
        ch = {"+": "=", "_": "-"}.get(ch, ch)
        if ch in ("q", "esc"):
            self.quit = True
        elif ch == " ":
            self.clock.pause(not self.clock.paused)
            live._snap()
            if not self.clock.paused:
                self.status = ""
        elif ch == ".":
            if not self.clock.paused:
                self.clock.pause(True)
                live._snap()
            self._tick()
            live._snap()
        elif ch == "p":
            try:
                self.screenshots.append(self.save_screenshot(self._next_name()))
            except (OSError, PhyscoreError) as e:  # a full disk; no window (before run, after close)
                print(f"screenshot not written: {e}", file=self.out)
        elif ch == "r":
            live.reset()
            self.painter.push(live.x)
            self.status = ""
            print("reset to the start", file=self.out)
        else:
            for p in _PARAMS:
                if ch in p.keys:
                    if p.name not in live.params():
                        print(f"{p.name}: this scene has none", file=self.out)
                        return
                    factor = STEP_FACTOR if ch == p.keys[1] else 1.0 / STEP_FACTOR
                    try:
                        live.scale(p.name, factor)
                    except (ValueError, TypeError) as e:
                        print(f"{p.name}: not changed ({e})", file=self.out)
                        return
                    value = live.params()[p.name]
                    extra = f", dt now {live.scene.dt:.3g} s" if not live.advance and live.scene.dt != live.dt0 else ""
                    print(f"{p.name}: {p.label} = {value:.4g} {p.unit}{extra}", file=self.out)
                    return

    def _handle(self, event: Any) -> None:
        """One event from the queue: quit, a key or the mouse; any other is ignored."""
        pg = self.pygame
        kind = getattr(event, "type", None)
        if kind == pg.QUIT:
            self.quit = True
        elif kind == pg.KEYDOWN:
            self._on_key(self._key(event))
        elif kind in (pg.MOUSEBUTTONDOWN, pg.MOUSEMOTION, pg.MOUSEBUTTONUP):
            self._on_mouse(event)

    def _on_mouse(self, event: Any) -> None:
        pg, live = self.pygame, self.live
        kind, pos = getattr(event, "type", None), _pointer(event)
        left = not hasattr(event, "button") or _int_attr(event, "button") == 1
        w, h = self.painter.size
        if kind == pg.MOUSEBUTTONDOWN and left:
            if pos is None or not (0 <= pos[0] < w and 0 <= pos[1] < h):
                return  # a press outside the window (or at no point) grabs nothing
            x, _, _, _ = live.drawn(self.alpha)
            radius = max(8.0, 3.0 * self.painter.ras.radius + 2.0)
            with np.errstate(over="ignore", invalid="ignore"):  # a particle far off screen: no pixel
                col, row, depth = self.painter.pixels(x)
                i = pick(col, row, pos, radius, ~live.pinned, depth)
            if i is not None:
                live.grab(i)
                self.status = f"dragging particle {i}"
        elif kind == pg.MOUSEMOTION and live.grabbed is not None and pos is not None:
            # A held pointer may leave the window (SDL captures it), but not to 1e308: the
            # particle follows it at most 10 window sizes beyond the edge.
            pos = (min(max(pos[0], -10.0 * w), 11.0 * w), min(max(pos[1], -10.0 * h), 11.0 * h))
            through = live.x[live.grabbed]
            with np.errstate(over="ignore", invalid="ignore"):
                target = screen_to_world(self.painter.cam, self.painter.origin, pos, through)
            if np.isfinite(target).all():
                live.move(target, self.clock.paused)
        elif kind == pg.MOUSEBUTTONUP and left and live.grabbed is not None:
            live.release()
            self.status = ""

    def _tick(self) -> None:
        try:
            self.live.tick()
        except SimulationDiverged as e:
            self.clock.pause(True)
            if self.live.grabbed is not None:
                self.live.vel = np.zeros_like(self.live.vel)  # let go at rest
                self.live.release()
            self.live._read()
            self.live._snap()
            self.status = "diverged: r resets"
            print(f"simulation diverged, paused (r resets): {e}", file=self.out)
            return
        self.painter.push(self.live.px)

    # -------------------------------------------------------------- output
    def _hud(self) -> tuple[str, str]:
        params = self.live.params()
        parts = []
        for p in _PARAMS:
            if p.name in params:
                parts.append(f"{p.label} {params[p.name]:.4g} {p.unit}")
        status = self.status
        if self.clock.paused and not status.startswith("diverged"):
            status = "paused" + (f" - {status}" if status else "")
        elif self.slow > 0.5:
            status = (status + "  " if status else "") + "slower than real time"
        return "  ".join(parts) or self.name, status

    def _next_name(self) -> Path:
        k = 1
        while Path(f"{self.name}-{k:03d}.png").exists():
            k += 1
        return Path(f"{self.name}-{k:03d}.png")

    def read_screen(self) -> np.ndarray:
        """(H, W, 3) uint8: the window's pixels, read back from the display surface."""
        pg = self.pygame
        try:
            surface = pg.display.get_surface()
        except pg.error:
            surface = None
        if surface is None:
            raise PhyscoreError("read_screen: the viewer's window is not open (before run() or after it closed)")
        w, h = surface.get_size()
        return np.frombuffer(pg.image.tobytes(surface, "RGB"), dtype=np.uint8).reshape(h, w, 3).copy()

    def save_screenshot(self, path: Path) -> Path:
        """Write the window's pixels as a PNG at `path`, atomically."""
        from PIL import Image

        from ._atomic import atomic_write

        image = Image.fromarray(self.read_screen())
        atomic_write(path, lambda fh: image.save(fh, format="PNG"))
        print(f"wrote {path}", file=self.out)
        return Path(path)

    # -------------------------------------------------------------- the loop
    def run(self, *, seconds: float | None, draws: int | None, script: Sequence[tuple[int, Any]],
            screenshot: Path | None) -> ViewResult:
        pg = self.pygame
        # The display is opened (and closed) by view().
        w, h = self.painter.size
        screen = pg.display.set_mode((w, h))
        pg.display.set_caption(f"physcore view: {self.name}")
        pending = sorted(script, key=lambda item: item[0])
        limiter = pg.time.Clock()
        start = last = time.perf_counter()
        while not self.quit:
            now = time.perf_counter()
            due = self.clock.advance(now - last)
            last = now
            while pending and pending[0][0] <= self.draws:
                k, item = pending.pop(0)
                made = item(self) if callable(item) else item
                for event in _script_events(pg, k, made):
                    pg.event.post(event)
            for event in pg.event.get():
                self._handle(event)
            t0 = time.perf_counter()
            ran = 0
            while ran < due and not self.clock.paused:
                self._tick()
                ran += 1
                if time.perf_counter() - t0 > _TICK_BUDGET:
                    break  # keep drawing (and the pointer) responsive: drop the rest
            if ran < due and not self.clock.paused:
                self.clock.dropped += (due - ran) * self.clock.tick
            # How often ticks fell behind lately (for the HUD).
            self.slow = 0.9 * self.slow + 0.1 * (1.0 if ran < due and not self.clock.paused else 0.0)
            self.alpha = self.clock.alpha
            x, v, t, p = self.live.drawn(self.alpha)
            params, status = self._hud()
            rgb = self.painter.draw(x, v, t, p, params, status)
            screen.blit(pg.image.frombuffer(rgb.tobytes(), (w, h), "RGB"), (0, 0))
            pg.display.flip()
            self.draws += 1
            if seconds is not None and time.perf_counter() - start >= seconds:
                break
            if draws is not None and self.draws >= draws:
                break
            limiter.tick(_MAX_DRAW_RATE)
        wall = time.perf_counter() - start
        image = self.read_screen()
        if screenshot is not None:
            self.screenshots.append(self.save_screenshot(screenshot))
        return ViewResult(self.live.scene, self.live.ticks, self.draws, wall, list(self.screenshots), image)


def _script_events(pg: Any, k: int, made: Any) -> list[Any]:
    """The events of a script item (an event, a list of them, or None); InvalidTypeError naming
    ``script`` for anything else, which pygame's queue would refuse with a bare TypeError."""
    events = [] if made is None else list(made) if isinstance(made, (list, tuple)) else [made]
    for e in events:
        if not isinstance(e, pg.event.EventType):
            raise InvalidTypeError(f"script: the item for frame {k} gave {type(e).__name__} {e!r:.40}, expected a pygame event, a list of them or None")
    return events


def _settings(scene: Any, size: Any, view_angles: Any) -> dict[str, Any]:
    """The drawing settings of ``gif(scene)``: the scene's render_defaults, else gif's."""
    from .render._checks import _check_color_by, _check_radius, _check_size, _check_view
    from .render._palette import THEMES
    from .render._recording import scene_defaults

    d = scene_defaults(scene)
    theme = d.get("theme", "light")
    if theme not in THEMES:
        theme = "light"
    return {
        "size": _check_size(tuple(d.get("size", (480, 360))) if size is None else size),
        "color_by": _check_color_by(d.get("color_by", "speed")),
        "radius": _check_radius(d.get("radius")),
        "view": _check_view(d.get("view") if view_angles is None else view_angles),
        "theme": theme,
        "trail": int(d.get("trail", 0) or 0),
        "size_by": d.get("size_by", "none") if d.get("size_by") in ("none", "mass") else "none",
        "title": d.get("title"),
        "colorbar": True,
        "springs": True,
    }


def view(
    scene: Any,
    *,
    name: str = "scene",
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    view: tuple[float, float] | None = None,
    seconds: float | None = None,
    draws: int | None = None,
    screenshot: str | os.PathLike | None = None,
    script: Sequence[tuple[int, Any]] = (),
    preview: float = 1.0,
    hud: bool = True,
    out: Any = None,
) -> ViewResult:
    """Open a window running `scene` live (see the module docstring and :data:`KEYS`) until it
    is closed, ``q``/Esc is pressed, or `seconds` / `draws` run out.

    Parameters
    ----------
    scene : physcore.Scene
        A scene with particles (2D or 3D); its ``render_defaults`` give the stepping (as
        ``physcore render``), colours, size and playback rate. It is stepped, and its terms
        changed by parameter keys, in place until a reset replaces it by a copy of its start
        (the result's ``scene`` is the last one).
    name : str, default "scene"
        For the window's title and the screenshots' names (``NAME-001.png``).
    size : (int, int), optional
        Window width and height in pixels, each >= 16. Default: the scene's, else 480 × 360.
    fps : float, optional
        Ticks per wall second (each tick is the scene's GIF frame), > 0: default the scene's
        ``fps``, else 30, so that the window plays at the GIF's speed.
    view : (float, float), optional
        3D camera (azimuth, elevation) in degrees; default the scene's, else (-60, 25).
    seconds : float, optional
        Close after this many seconds of wall time (> 0), counted from when the window opens.
    draws : int, optional
        Close after this many drawn frames (>= 1).
    screenshot : str or os.PathLike, optional
        Write the window's last frame as a PNG (must end in ``.png``) when it closes, atomically.
    script : sequence of (int, item)
        Input for scripted runs and tests: before drawn frame ``k`` each item given with ``k``
        is posted to pygame's event queue, and so goes through the same handling as the user's
        input. An item is a ``pygame.event.Event`` (or a list of them), or a callable taking
        the :class:`Viewer` and returning an event, a list of them or None (it may also just
        look); anything else is an InvalidTypeError naming ``script``. Events the viewer cannot
        use (unknown keys, a pointer at no finite point, resizes) are ignored.
    preview : float, default 1.0
        Wall seconds to spend at the start simulating a copy of the scene, to fit the camera and
        the colour scale to its motion (0: to the start state alone).
    hud : bool, default True
        Draw the parameter line and the state (paused, dragging); False draws exactly the GIF's
        frames.
    out : file, optional
        Where the viewer reports (key help, parameter changes, screenshots): default stdout.

    Returns
    -------
    ViewResult

    Raises
    ------
    ImportError
        pygame-ce is not installed (the message says ``pip install "physcore[view]"``).
    InvalidTypeError, InvalidInputError
        A bad argument, naming it, or a scene without particles; before any window opens (a
        script callable's bad return: when it runs).
    pygame.error
        No display to open a window on (set DISPLAY, or run under ``xvfb-run``).
    """
    from .render._checks import _check_fps

    if not (hasattr(scene, "positions") and hasattr(scene, "terms") and hasattr(scene, "_file_arrays")):
        raise InvalidTypeError(f"scene: expected a physcore.Scene, got {type(scene).__name__}")
    if int(scene.n_particles) == 0:
        raise InvalidInputError("scene: it has no particles; the live viewer shows particle scenes (render grids and flows with physcore render)")
    if not isinstance(name, str) or not name:
        raise InvalidTypeError(f"name: expected a non-empty str, got {name!r}")
    settings = _settings(scene, size, view)
    from .render._recording import scene_defaults

    fps = _check_fps(scene_defaults(scene).get("fps", 30.0) if fps is None else fps)
    if seconds is not None:
        seconds = _check.real("seconds", seconds)
        if not (seconds > 0 and math.isfinite(seconds)):
            raise InvalidInputError(f"seconds: must be a finite number > 0, got {seconds!r}")
    if draws is not None:
        if isinstance(draws, bool) or not isinstance(draws, int):
            raise InvalidTypeError(f"draws: expected an int, got {type(draws).__name__}")
        if draws < 1:
            raise InvalidInputError(f"draws: must be >= 1, got {draws}")
    if screenshot is not None:
        from .render._checks import _check_path

        screenshot = _check_path(screenshot, "png")
    preview = _check.real("preview", preview)
    if not (preview >= 0 and math.isfinite(preview)):
        raise InvalidInputError(f"preview: must be a finite number of seconds >= 0, got {preview!r}")
    hud = _check.flag("hud", hud)
    script = list(script)
    for item in script:
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], int)):
            raise InvalidInputError(f"script: expected (frame, event or callable) pairs, got {item!r}")
    out = sys.stdout if out is None else out
    pg = _import_pygame()
    for k, item in script:
        if not callable(item):
            _script_events(pg, k, item)
    pg.display.init()  # no display: pygame.error now, before the preview's simulation
    try:
        print(f"physcore view: {name}\n{keys_text()}", file=out)
        viewer = Viewer(scene, name=name, settings=settings, fps=fps, preview=preview, hud=hud, out=out)
        return viewer.run(seconds=seconds, draws=draws, script=script, screenshot=screenshot)
    finally:
        pg.display.quit()


# --------------------------------------------------------------------------- command line
