"""The live scene, shared by the window (:mod:`physcore.viewer`) and the notebook widget
(:mod:`physcore.notebook`): one loop, one state, one painter, no display.

The loop (Fiedler, "Fix your timestep!", 2004)
----------------------------------------------
The simulation advances in fixed *ticks*, each the scene's frame of its GIF: ``frame_time``
simulated seconds (``scene.advance(frame_time)`` for scenes with automatic substeps, else
``round(frame_time / dt)`` steps of dt), exactly as ``physcore render`` steps it. A tick is due
every ``1 / fps`` seconds of wall time (:class:`FixedStep`); every drawn frame runs the ticks
that are due (at most :data:`MAX_TICKS_PER_DRAW`, and stopping once they have taken
``_TICK_BUDGET`` seconds; the rest dropped) and draws the state interpolated between the last
two ticks. :class:`_LiveRun` holds that loop with the live state (:class:`_Live`: the scene, its
drag and its parameters) and the painter (:class:`_Painter`: :mod:`physcore.render`'s rasteriser
with one camera and colour scale fitted to a preview). The window feeds it pygame's events and
wall clock; the widget feeds it the browser's messages, and sends its frames as images. The
widget steps in the background by default (``_LiveRun(..., background=True)``): one tick at a
time on a worker thread (the core releases the GIL), the frames drawing the last two states
interpolated meanwhile, every scene write waiting for the tick in flight (:meth:`_LiveRun.settle`).
The keys of both (:meth:`_LiveRun.key`) are the viewer's.

See :mod:`physcore.viewer` for the drag (a pinned, kinematic particle) and the parameter keys.
"""
from __future__ import annotations

import dataclasses
import io
import json
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from . import _check
from ._errors import InvalidInputError, InvalidTypeError, SimulationDiverged

#: Most ticks run before one drawn frame; beyond it the accumulator drops the backlog.
MAX_TICKS_PER_DRAW = 4
#: Factor of one parameter key press.
STEP_FACTOR = 1.25
#: The keys (and the widget's sliders) keep each parameter within this factor of its start value
#: either way (20 presses): 110 presses of ] once stiffened a cloth 4·10¹⁰ times and froze the
#: window for 4 s a frame.
PARAM_RANGE = 100.0
#: Wall seconds of ticks before a frame is drawn anyway (the ticks still due are dropped), so
#: that a scene slower than real time still draws and follows the pointer at about 20 Hz.
_TICK_BUDGET = 0.05
#: Parts of a tick while dragging (the grabbed particle is placed before each).
_DRAG_PARTS = 8
#: Margin (fraction of the extent) around a preview cut short by its budget.
_MARGIN = 0.1

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



def _parts(k: int, m: int) -> list[int]:
    """`k` steps in min(k, m) near-equal parts."""
    m = max(1, min(k, m))
    return [k // m + (1 if p < k % m else 0) for p in range(m)]


# --------------------------------------------------------------------------- parameters
def _params() -> tuple[Any, ...]:
    """The live parameters every registered term class declares (``Term.live_params``,
    :class:`physcore.terms.LiveParam`), by rank: the keys, sliders and heads-up line offer
    these, so a new term brings its own."""
    from ._parts import PARTS

    seen: dict[str, Any] = {}
    for cls in PARTS.values():
        for p in getattr(cls, "live_params", ()):
            seen.setdefault(p.name, p)
    return tuple(sorted(seen.values(), key=lambda p: (p.rank, p.name)))


def _terms_of(scene: Any, name: str) -> list[tuple[int, Any]]:
    return [(k, t) for k, t in enumerate(scene.terms) if any(p.name == name for p in type(t).live_params)]


def param_value(scene: Any, name: str) -> float | None:
    """The value a parameter key changes, or None where the scene has no such term:
    ``"stiffness"`` / ``"damping"`` the mean over all springs (N/m, N·s/m), ``"gravity"`` |g|
    (m/s², the first Gravity term), ``"drag"`` the first Drag coefficient (kg/s)."""
    terms = _terms_of(scene, name)
    if not terms:
        return None
    p = _param(name)
    if p.reduce == "mean":
        values = np.concatenate([np.asarray(getattr(t, p.attribute), dtype=np.float64).reshape(-1) for _, t in terms])
        return float(values.mean()) if values.size else None
    if p.reduce == "norm":
        return float(np.linalg.norm(getattr(terms[0][1], p.attribute)))
    return float(getattr(terms[0][1], p.attribute))


def _file_members(scene: Any) -> dict[str, np.ndarray]:
    """The members of ``scene``'s scene file (:meth:`Scene.to_bytes`), by name."""
    with np.load(io.BytesIO(scene.to_bytes()), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _rebuild(scene: Any, edit: Callable[[dict, dict], None], like: Any = None) -> Any:
    """A new Scene from `scene`'s in-memory scene file after ``edit(meta, arrays)``, without the
    integrator's force cache and with a fresh energy-drift reference. `like` (default `scene`)
    gives the term records, dt and integrator when `scene` is an earlier state (reset)."""
    from .scene import Scene

    arrays = _file_members(scene)
    meta = json.loads(arrays["meta"].item())
    if like is not None and like is not scene:
        now = _file_members(like)
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
    new = Scene.from_bytes(buf.getvalue(), threads=scene.threads, source="<viewer>")
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
    names = [p.name for p in _params()]
    if name not in names:
        raise InvalidInputError(f"name: expected one of {', '.join(names)}, got {name!r}")
    terms = _terms_of(scene, name)
    if not terms:
        raise InvalidInputError(f"name: the scene has no term with a {name!r} parameter")
    p = _param(name)
    start = param_value(scene, name) if p.at_zero == "critical" else None
    kick = p.at_zero == "critical" and start == 0.0 and factor > 1
    if kick:
        base = _critical_percent(scene)
    for _, t in terms:
        if p.reduce == "mean":
            a = np.asarray(getattr(t, p.attribute), dtype=np.float64)
            new = dataclasses.replace(t, **{p.attribute: np.full_like(a, base) if kick else a * factor})
        elif p.reduce == "norm":
            new = dataclasses.replace(t, **{p.attribute: np.array([factor * float(c) for c in getattr(t, p.attribute)])})
        else:
            new = dataclasses.replace(t, **{p.attribute: factor * float(getattr(t, p.attribute))})
        scene.replace(t.name, new)
    return scene


def _turn(p: np.ndarray, angle: float) -> np.ndarray:
    """`p` (2,) rotated by `angle` rad (counter-clockwise)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])


def _inside(outline: np.ndarray, p: np.ndarray) -> bool:
    """Whether the point `p` (2,) is inside the convex polygon `outline` (V, 2), either winding."""
    e = np.roll(outline, -1, axis=0) - outline
    cross = e[:, 0] * (p[1] - outline[:, 1]) - e[:, 1] * (p[0] - outline[:, 0])
    return bool((cross >= 0).all() or (cross <= 0).all())


def _has_bodies(scene: Any) -> bool:
    """Whether the scene holds rigid bodies (drawn live like its particles)."""
    return any(getattr(g, "first", None) is not None and g.n for g in getattr(scene, "bodies", ()))


# --------------------------------------------------------------------------- the live state
class _Live:
    """The running scene and the two latest ticks' states (for interpolation), the drag and the
    parameter keys. No display: testable on its own."""

    def __init__(self, scene: Any, color_by: str) -> None:
        from .render.painter import default_stepping, scene_defaults

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
        self._params: dict[str, float] | None = None  # the parameters, read once per change
        self._ranges: dict[str, tuple[float, float] | None] = {}  # the sliders' ranges
        self.params0 = self.params()  # the start values the keys stay within PARAM_RANGE of
        # The rigid bodies' poses reader and outlines, for the scene they were made for (drag,
        # reset and the parameter keys rebuild the scene: then they are made again).
        self._poses: Any = None
        self._poses_of: Any = None
        self.outlines: list[np.ndarray] = []
        #: The body held by the pointer (its number in the scene), the point of it held (m, in
        #: its own frame) and where the pointer holds that point (m); None: no body held.
        self.body: int | None = None
        self.body_anchor: np.ndarray | None = None
        self.body_target: np.ndarray | None = None
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
        if self._poses_of is not s:
            from .render.painter import body_track

            track, self._poses = body_track(s, 1)
            self._poses_of, self.outlines = s, list(getattr(track, "outlines", []))
        #: The rigid bodies' poses (B, 3) float64 ``(x, y, angle)``, m and rad; None without bodies.
        self.b = None if self._poses is None else np.asarray(self._poses(), dtype=np.float64)

    def _snap(self) -> None:
        """The previous state := the current one (nothing to interpolate)."""
        self.px, self.pv, self.pt = self.x, self.v, self.t
        self.pp, self.pb = self.p, self.b

    def drawn(self, alpha: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None]:
        """Positions, velocities, time and pressures interpolated by `alpha` between ticks."""
        p = None if self.p is None else interpolate(self.pp, self.p, alpha)
        return interpolate(self.px, self.x, alpha), interpolate(self.pv, self.v, alpha), self.pt + alpha * (self.t - self.pt), p

    def drawn_bodies(self, alpha: float) -> np.ndarray | None:
        """The rigid bodies' poses (B, 3) interpolated by `alpha` between ticks (each angle the
        short way round), or None without bodies."""
        b, pb = self.b, self.pb
        if b is None or pb is None or pb.shape != b.shape:
            return b
        if b.shape[1] == 7:  # 3D: (x, y, z, qx, qy, qz, qw), each quaternion the short way (nlerp)
            q, pq = b[:, 3:], pb[:, 3:]
            q = np.where((np.sum(q * pq, axis=1) < 0)[:, None], -q, q)
            out = interpolate(pb, b, alpha)
            mid = pq + alpha * (q - pq)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[:, 3:] = mid / np.linalg.norm(mid, axis=1, keepdims=True)
            return out
        turn = np.remainder(b[:, 2] - pb[:, 2] + np.pi, 2 * np.pi) - np.pi
        out = interpolate(pb, b, alpha)
        out[:, 2] = pb[:, 2] + alpha * turn
        return out

    # -------------------------------------------------------------- stepping
    def tick(self) -> None:
        """One tick (the GIF's frame): raises SimulationDiverged with the scene rolled back to
        the start of the failing call."""
        self._advance()
        self._advanced()

    def _advance(self) -> None:
        """A tick's stepping: the scene only (no state of this object that drawing reads), so
        that a background thread may run it while the last states are drawn."""
        s = self.scene
        if self.body is not None:
            # The held body is pulled: before each part of the tick its velocity is set so that
            # the held point reaches the pointer by the part's end (a velocity-level mouse
            # joint); contacts and gravity act on it as on any body.
            parts = [1] * _DRAG_PARTS if self.advance else _parts(self.steps, _DRAG_PARTS)
            for n in parts:
                part = self.frame_time / len(parts) if self.advance else n * float(s.dt)
                group, j = self._body_group(self.body)
                x, a = group.positions[j], float(group.angles[j])
                held = x + _turn(self.body_anchor, a)
                v = group.velocities
                v[j] = (self.body_target - held) / part
                group.velocities = v
                if self.advance:
                    s.advance(self.frame_time / len(parts))
                else:
                    s.step(n)
        elif self.grabbed is None:
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

    def _advanced(self) -> None:
        """A tick's end: the new state read back, the one before kept to interpolate from."""
        self.px, self.pv, self.pt, self.pp, self.pb = self.x, self.v, self.t, self.p, self.b
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
        self.release_body()
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
        self.body = self.body_anchor = self.body_target = None

    # -------------------------------------------------------------- body drag (2D)
    def _body_group(self, b: int) -> tuple[Any, int]:
        """The Bodies part holding body `b` (numbered in the scene) and its index there."""
        for g in getattr(self.scene, "bodies", ()):
            if g.first is not None and g.first <= b < g.first + g.n:
                return g, b - g.first
        raise InvalidInputError(f"b: the scene has no body {b}")

    def body_at(self, point: np.ndarray) -> int | None:
        """The dynamic body whose outline holds the world point `point` (2,) m (the topmost
        drawn: the last), or None."""
        if self.b is None or len(point) != 2:
            return None
        for b in range(len(self.outlines) - 1, -1, -1):
            x, y, a = self.b[b]
            local = _turn(np.asarray(point, dtype=np.float64) - [x, y], -a)
            if _inside(self.outlines[b], local) and self._body_group(b)[0].kind == "dynamic":
                return b
        return None

    def grab_body(self, b: int, point: np.ndarray) -> None:
        """Hold body `b` by its point now at `point` (2,) m (world)."""
        self.release()
        x, y, a = self.b[b]
        self.body, self.body_anchor = int(b), _turn(np.asarray(point, dtype=np.float64) - [x, y], -a)
        self.body_target = np.asarray(point, dtype=np.float64).copy()

    def move_body(self, target: np.ndarray, paused: bool) -> None:
        """Pull the held body's point to `target` (2,) m; paused, the body is put there at once
        (at rest)."""
        if self.body is None:
            return
        self.body_target = np.asarray(target, dtype=np.float64).copy()
        if paused:
            group, j = self._body_group(self.body)
            pos, v = group.positions, group.velocities
            pos[j] = self.body_target - _turn(self.body_anchor, float(group.angles[j]))
            v[j] = 0.0
            group.positions, group.velocities = pos, v
            self._read()
            self._snap()

    def release_body(self) -> None:
        """Let go of the held body (it keeps the velocity the pull gave it)."""
        self.body = self.body_anchor = self.body_target = None

    # -------------------------------------------------------------- parameters and reset
    def params(self) -> dict[str, float]:
        """The parameters the scene has: name -> value (see :func:`param_value`); read from
        the terms once after each change (:meth:`scale`, :meth:`set`)."""
        if self._params is None:
            out = {}
            for p in _params():
                value = param_value(self.scene, p.name)
                if value is not None:
                    out[p.name] = value
            self._params = out
        return dict(self._params)

    def scale(self, name: str, factor: float) -> bool:
        """Multiply parameter `name` by `factor`, unless that takes it beyond
        :data:`PARAM_RANGE` times its start value either way; returns whether it changed."""
        start, now = self.params0.get(name), param_value(self.scene, name)
        if start and now and not (start / PARAM_RANGE <= now * factor <= start * PARAM_RANGE):
            return False
        self.scene = scale_param(self.scene, name, factor)
        self._params = None
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
        from .render.painter import steps_for

        self.steps = steps_for(self.frame_time, s.dt)

    def param_range(self, name: str) -> tuple[float, float] | None:
        """The values parameter `name` may take from a slider, fixed at its first use: within
        :data:`PARAM_RANGE` times its start value either way. One that starts at 0: a damping
        from 0 to PARAM_RANGE times 1 % of critical, a drag from 0 to PARAM_RANGE times the
        mean particle mass per second (kg/s); a stiffness or gravity, None (no slider: a
        gravity of 0 has no direction to grow along).

        Raises InvalidInputError naming `name` where the scene has no such term."""
        if name in self._ranges:
            return self._ranges[name]
        start = self.params0.get(name)
        if start is None:
            raise InvalidInputError(f"name: the scene has no term with a {name!r} parameter")
        r: tuple[float, float] | None = None
        if start > 0:
            r = (start / PARAM_RANGE, start * PARAM_RANGE)
        elif _param(name).at_zero == "critical":
            r = (0.0, (_critical_percent(self.scene) or 1.0) * PARAM_RANGE)
        elif _param(name).at_zero == "mass":
            r = (0.0, (float(np.mean(self.scene.masses)) if self.scene.n_particles else 1.0) * PARAM_RANGE)
        self._ranges[name] = r
        return r

    def set(self, name: str, value: float) -> float:
        """Set parameter `name` to `value` clipped to :meth:`param_range` (stiffening shortens
        a fixed dt as a key does); returns the value set.

        Raises InvalidInputError naming `name` (no such term) or `value` (not a finite number)."""
        r = self.param_range(name)
        if r is None:
            raise InvalidInputError(f"name: the scene's {name} starts at 0; a slider scales it from there, and cannot")
        lo, hi = r
        value = _check.real("value", value)
        if not math.isfinite(value):
            raise InvalidInputError(f"value: must be a finite number, got {value!r}")
        value = min(max(value, lo), hi)
        self.scene = set_param(self.scene, name, value)
        self._params = None
        self._restep()
        return float(param_value(self.scene, name) or 0.0)

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
        from .render.painter import Rasteriser, default_stepping, scene_defaults, scene_springs, simulate

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
            budget = max(2, int(min(frames, preview / cost)))  # preview / cost may overflow to inf
        copy = _rebuild(scene, lambda meta, arrays: None)
        copy.render_defaults = scene.render_defaults
        try:
            rec = simulate(copy, budget, spf, color_by == "speed", settings["springs"], False,
                            need_pressure=color_by == "pressure", frame_time=ft)
        except SimulationDiverged:
            rec = simulate(_rebuild(scene, lambda meta, arrays: None), 1, spf, color_by == "speed",
                            settings["springs"], False, need_pressure=color_by == "pressure", frame_time=ft)
        self.complete = rec.frames >= frames
        #: The preview's recording: the scene's first GIF frames (the widget's fallback draws it).
        self.preview = rec._replace(color_by=color_by, defaults=dict(d))
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
        if d.get("extent") is not None:  # the scene's own view box, as gif() fits it
            from .render.painter import extent_box

            box = extent_box(d.get("extent"), rec.positions.shape[-1])
            if box is not None:
                fit = box - rec.origin
        trail = min(int(settings.get("trail") or 0), 240)
        kw: dict[str, Any] = {"colorbar": settings["colorbar"], "size_by": settings["size_by"], "annotate": True,
                              "title": (settings.get("title") or "physcore") if hud else (settings.get("title") or None),
                              "trail": trail}
        if fit is not None:
            kw["fit"] = fit
        # A shaded surface where the scene's GIF has one (the cloth), and soft discs where it has
        # them, exactly as gif() picks them.
        from .render.painter import check_mesh, check_texture

        mesh = None if color_by == "density" else check_mesh(d.get("mesh"), rec.positions.shape[1])
        from .render.painter import check_look

        look = check_look(None, d.get("look"))  # the scene's backdrop and props, as gif() draws them
        fabric = d.get("texture") if color_by == "none" and mesh is not None and mesh.uv is not None else None
        kw.update(mesh=mesh, texture=check_texture(fabric, mesh), theme=settings["theme"], look=look,
                  antialias=bool(d.get("antialias", False)) or look.full_colour)
        # The rest of what gif() takes from the scene's defaults: the colour map, a fluid's
        # surface, the background, each particle's own colour and halo.
        from .render.painter import check_background, check_cmap, check_colors, check_halo

        n = rec.positions.shape[1]
        kw.update(cmap=check_cmap(d.get("cmap")), surface=bool(d.get("surface", False)),
                  background=check_background(d.get("background")), colors=check_colors(d.get("colors"), n),
                  halo=check_halo(d.get("halo"), n))
        self.ras = Rasteriser(rec, self.size, color_by, settings["radius"], settings["view"], **kw)
        self.hud = hud and self.ras.title is not None
        # The live recording: the trail's history of ticks, then the drawn state, last.
        f = trail + 1 if trail and hasattr(self.ras, "_pix") else 1
        n, dim = rec.positions.shape[1:]
        self.origin = rec.origin
        m = 0 if rec.pairs is None else rec.pairs[0].size
        self.springs = None if rec.pairs is None else scene_springs(scene)
        bodies = None
        if rec.bodies is not None:  # the live poses go in its last frame, as the particles'
            bodies = rec.bodies.with_frames(f)
        self.live = rec._replace(
            bodies=bodies,
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

    def draw(self, x: np.ndarray, v: np.ndarray, t: float, p: np.ndarray | None, params: str, status: str,
             bodies: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 3) uint8 RGB image of the state (with the rigid bodies' poses `bodies`, (B, 3)
        ``(x, y, angle)``, where the scene has them), with the HUD."""
        from .render.painter import (
            BACKGROUND,
            CB_MARGIN,
            TEXT,
            draw_text,
            draw_title,
            overlay,
            paste,
            row_norms,
            strain,
            text_mask,
        )

        live, k = self.live, self.frames - 1
        with np.errstate(over="ignore", invalid="ignore"):
            live.positions[k] = x - self.origin
            if live.speeds is not None:
                live.speeds[k] = row_norms(v)
            if live.strain is not None and self.springs is not None:
                live.strain[k] = strain(x, *self.springs)
            if live.pressures is not None and p is not None:
                live.pressures[k] = p
            if live.bodies is not None and bodies is not None and bodies.shape == live.bodies.poses[k].shape:
                d = len(self.origin)
                live.bodies.poses[k, :, :d] = bodies[:, :d] - self.origin
                live.bodies.poses[k, :, d:] = bodies[:, d:]
        live.times[k] = t
        if self.frames > 1:
            self.ras.forget_projection()  # the history moved: project it again
        # Full colour where the renderer has it (a shaded mesh), else the palette image.
        rgb = self.ras.frame_rgb(k)  # a new C-contiguous array
        if self.hud:
            # Drawn as palette indices on an overlay (-1: nothing), in the labels' font of this
            # image size where the renderer has several (else the bitmap font).
            px = self.ras.font_px
            line = text_mask("0", px).shape[0]
            h, w = rgb.shape[:2]
            over = overlay((h, w))
            right = w - 8 if self.ras.colorbar is None else self.ras.colorbar.lo_x - 8
            over[: CB_MARGIN + line + 1, : max(right, 0)] = BACKGROUND
            draw_title(over, params or " ", right, px)
            if status:
                draw_text(over, status, min(8 * line, w // 4), h - 4 - line, TEXT, BACKGROUND, px=px)
            paste(rgb, over, self.ras.palette)
        return rgb



def _settings(scene: Any, size: Any, view_angles: Any) -> dict[str, Any]:
    """The drawing settings of ``gif(scene)``: the scene's render_defaults, else gif's."""
    from .render.painter import THEMES, check_color_by, check_radius, check_size, check_view, scene_defaults

    d = scene_defaults(scene)
    theme = d.get("theme", "light")
    if theme not in THEMES:
        theme = "light"
    return {
        "size": check_size(tuple(d.get("size", (480, 360))) if size is None else size),
        "color_by": check_color_by(d.get("color_by", "speed")),
        "radius": check_radius(d.get("radius")),
        "view": check_view(d.get("view") if view_angles is None else view_angles),
        "theme": theme,
        "trail": int(d.get("trail", 0) or 0),
        "size_by": d.get("size_by", "none") if d.get("size_by") in ("none", "mass") else "none",
        "title": d.get("title"),
        "colorbar": True,
        "springs": True,
    }



# --------------------------------------------------------------------------- absolute values (sliders)
def set_param(scene: Any, name: str, value: float) -> Any:
    """Set parameter `name` (see :func:`param_value`) to `value` in every term of `scene` that has
    it, in place (:meth:`physcore.Scene.replace`), and return `scene`: springs keep their ratios
    to one another (each is scaled by ``value / mean``; all set to `value` where the mean is 0),
    gravity keeps its direction.

    Raises InvalidInputError naming `name` where the scene has no such term, and naming `value`
    where it is not finite and >= 0 (> 0 for stiffness and gravity); nothing changes then.
    """
    names = [p.name for p in _params()]
    if name not in names:
        raise InvalidInputError(f"name: expected one of {', '.join(names)}, got {name!r}")
    value = _check.real("value", value)
    positive = name in ("stiffness", "gravity")
    if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
        raise InvalidInputError(f"value: {name} must be a finite number {'>' if positive else '>='} 0, got {value!r}")
    now = param_value(scene, name)
    if now is None:
        raise InvalidInputError(f"name: the scene has no term with a {name!r} parameter")
    if name == "gravity" and now == 0:
        raise InvalidInputError("name: the scene's gravity is 0, so it has no direction to set a magnitude along")
    if now == value:
        return scene
    for _, t in _terms_of(scene, name):
        if name in ("stiffness", "damping"):
            a = np.asarray(getattr(t, name), dtype=np.float64)
            new = dataclasses.replace(t, **{name: a * (value / now) if now > 0 else np.full_like(a, value)})
        elif name == "gravity":
            new = dataclasses.replace(t, g=np.array([float(c) * (value / now) for c in t.g]))
        else:
            new = dataclasses.replace(t, coefficient=float(value))
        scene.replace(t.name, new)
    return scene


def _critical_percent(scene: Any) -> float:
    """1 % of the critical damping 2 √(k m) of the mean spring and particle, N·s/m (where the
    keys raise a damping of 0 to)."""
    k, m = param_value(scene, "stiffness") or 0.0, float(np.mean(scene.masses)) if scene.n_particles else 0.0
    return 0.01 * 2.0 * math.sqrt(max(k * m, 0.0))


# --------------------------------------------------------------------------- the loop
class _LiveRun:
    """The loop shared by the window and the widget: the live state, the painter and the clock,
    and what the user can do to them (pause, one tick, reset, a parameter, the pointer). No
    display and no event types: each front end turns its input into these calls, and shows
    the messages they return (a parameter changed, a divergence).

    Parameters
    ----------
    scene : physcore.Scene
        Stepped in place (and its terms replaced) until a reset replaces it by its start.
    settings : dict
        :func:`_settings` of the scene.
    fps : float
        Ticks per wall second.
    preview : float
        Wall seconds of preview run to fit the camera and the colour scale (:class:`_Painter`).
    hud : bool
        Draw the parameter line and the state on the frames.
    background : bool, default False
        Step in a background thread (the core releases the GIL while it steps), one tick at a
        time, while the frames draw the last two states interpolated over the time states have
        lately taken to come: frames then come as fast as they are drawn even where one tick
        takes longer than a frame (a 10⁴-particle fluid), and the motion stays smooth. Every
        call that touches the scene first waits for the tick in flight (:meth:`settle`).
    """

    def __init__(self, scene: Any, *, settings: dict[str, Any], fps: float, preview: float, hud: bool,
                 background: bool = False) -> None:
        self.live = _Live(scene, settings["color_by"])
        self.painter = _Painter(scene, settings, preview, hud)
        self.clock = FixedStep(1.0 / fps)
        self.status = ""
        self.alpha = 1.0
        #: How often ticks fell behind lately (a moving average of 0/1 per frame).
        self.slow = 0.0
        self._pool: Any = None
        if background:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="physcore-tick")
        self._job: Any = None  # the tick running in the background
        self._backlog = 0  # ticks due and not yet started (background)
        self._since = time.perf_counter()  # when the latest state came (background)
        self._period = self.clock.tick  # wall seconds between states lately (background)

    @property
    def background(self) -> bool:
        """Whether ticks run in a background thread."""
        return self._pool is not None

    def close(self) -> None:
        """Wait for a tick in flight and stop the background thread (if any)."""
        self.settle()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def settle(self) -> str | None:
        """Wait for the tick running in the background (if any) and take its state; a
        divergence's message, else None."""
        job, self._job = self._job, None
        if job is None:
            return None
        try:
            job.result()
        except SimulationDiverged as e:
            return self._diverged(e)
        self.live._advanced()
        self.painter.push(self.live.x)
        now = time.perf_counter()
        self._period = 0.7 * self._period + 0.3 * max(now - self._since, self.clock.tick)
        self._since = now
        return None

    # -------------------------------------------------------------- the clock
    def run(self, due: int) -> str | None:
        """Run up to `due` ticks (as many as fit :data:`_TICK_BUDGET` wall seconds; the rest
        are dropped) and set the drawing fraction; a divergence's message, else None. In the
        background: take a finished tick's state, start the next tick due (at most
        :data:`MAX_TICKS_PER_DRAW` wait; the rest are dropped), and return at once."""
        if self._pool is not None:
            return self._run_background(due)
        t0 = time.perf_counter()
        ran, message = 0, None
        while ran < due and not self.clock.paused:
            message = self.tick()
            ran += 1
            if time.perf_counter() - t0 > _TICK_BUDGET:
                break  # keep drawing (and the pointer) responsive: drop the rest
        behind = ran < due and not self.clock.paused
        if behind:
            self.clock.dropped += (due - ran) * self.clock.tick
        self.slow = 0.9 * self.slow + 0.1 * (1.0 if behind else 0.0)
        self.alpha = self.clock.alpha
        return message

    def _run_background(self, due: int) -> str | None:
        message = None
        if self._job is not None and self._job.done():
            message = self.settle()
        if not self.clock.paused:
            self._backlog += due
            if self._backlog > MAX_TICKS_PER_DRAW:
                self.clock.dropped += (self._backlog - MAX_TICKS_PER_DRAW) * self.clock.tick
                self._backlog = MAX_TICKS_PER_DRAW
            if self._job is None and self._backlog > 0:
                self._backlog -= 1
                self._job = self._pool.submit(self.live._advance)
        self.slow = 0.9 * self.slow + 0.1 * (1.0 if self._backlog > 1 else 0.0)
        # Between the last two states, over the time states have lately taken to come.
        self.alpha = 1.0 if self.clock.paused else min(1.0, (time.perf_counter() - self._since) / self._period)
        return message

    def tick(self) -> str | None:
        """One tick, now (after any tick in the background); a divergence pauses, lets go of a
        held particle at rest, keeps the state rolled back to the start of the failing call,
        and returns its message."""
        message = self.settle()
        if message:
            return message
        live = self.live
        try:
            live.tick()
        except SimulationDiverged as e:
            return self._diverged(e)
        self.painter.push(live.x)
        return None

    def _diverged(self, e: SimulationDiverged) -> str:
        live = self.live
        self.clock.pause(True)
        self._backlog = 0
        if live.grabbed is not None:
            live.vel = np.zeros_like(live.vel)  # let go at rest
            live.release()
        live._read()
        live._snap()
        self.status = "diverged: r resets"
        return f"simulation diverged, paused (r resets): {e}"

    def set_paused(self, paused: bool) -> None:
        """Pause or run; the drawn state is the latest tick's from here on."""
        self.settle()
        self._backlog = 0
        self._since = time.perf_counter()
        self.clock.pause(bool(paused))
        self.live._snap()
        if not self.clock.paused:
            self.status = ""

    def step_once(self) -> str | None:
        """Pause (if running) and run one tick; a divergence's message, else None."""
        if not self.clock.paused:
            self.set_paused(True)
        message = self.tick()
        self.live._snap()
        return message

    def reset(self) -> str:
        """Back to the start state, keeping the parameters."""
        self.settle()
        self._backlog = 0
        self.live.reset()
        self.painter.push(self.live.x)
        self.status = ""
        return "reset to the start"

    def key(self, ch: str) -> str | None:
        """What the viewer's keys (``physcore.viewer.KEYS``) do to the loop, shared by the
        window and the widget: space pauses or runs, ``.`` runs one tick, ``r`` resets, the
        parameter keys scale their parameter by :data:`STEP_FACTOR` (``+`` and ``_`` are ``=``
        and ``-``); any other key nothing. The line to show, if any."""
        if not isinstance(ch, str):
            return None
        ch = {"+": "=", "_": "-"}.get(ch, ch)
        if ch == " ":
            self.set_paused(not self.clock.paused)
            return None
        if ch == ".":
            return self.step_once()
        if ch == "r":
            return self.reset()
        for p in _params():
            if ch in p.keys:
                return self.scale(p.name, STEP_FACTOR if ch == p.keys[1] else 1.0 / STEP_FACTOR)
        return None

    # -------------------------------------------------------------- parameters
    def params(self) -> dict[str, float]:
        """The parameters the scene has: name -> value (see :func:`param_value`)."""
        return self.live.params()

    def _said(self, p: Any) -> str:
        live = self.live
        value = live.params()[p.name]
        extra = f", dt now {live.scene.dt:.3g} s" if not live.advance and live.scene.dt != live.dt0 else ""
        return f"{p.name}: {p.label} = {value:.4g} {p.unit}{extra}"

    def scale(self, name: str, factor: float) -> str:
        """Multiply parameter `name` by `factor` as a key does (within :data:`PARAM_RANGE`);
        what changed, or why not, as a line to show."""
        p = _param(name)
        if p.name not in self.live.params():
            return f"{p.name}: this scene has none"
        self.settle()
        try:
            self.live.scale(p.name, factor)
        except (ValueError, TypeError) as e:
            return f"{p.name}: not changed ({e})"
        return self._said(p)

    def set(self, name: str, value: float, *, strict: bool = False) -> str:
        """Set parameter `name` to `value` as a slider does (clipped to its range); what changed,
        or why not, as a line to show (`strict`: why not is raised instead, an
        InvalidInputError or InvalidTypeError naming `name` or `value`)."""
        p = _param(name)
        if p.name not in self.live.params():
            if strict:
                raise InvalidInputError(f"name: the scene has no {name!r} parameter; it has {', '.join(self.live.params()) or 'none'}")
            return f"{p.name}: this scene has none"
        self.settle()
        try:
            self.live.set(p.name, value)
        except (ValueError, TypeError) as e:
            if strict:
                raise
            return f"{p.name}: not changed ({e})"
        return self._said(p)

    def sliders(self) -> list[dict[str, Any]]:
        """One slider per parameter the scene's terms have, in :func:`_params` order: name,
        label, unit, value now, and the range (lo may be 0: a damping or drag that starts at 0;
        a stiffness or gravity that starts at 0 has none)."""
        self.settle()
        out = []
        for p in _params():
            value = self.live.params().get(p.name)
            if value is None:
                continue
            r = self.live.param_range(p.name)
            if r is None:
                continue
            lo, hi = r
            out.append({"name": p.name, "label": p.label, "unit": p.unit, "value": value, "lo": lo, "hi": hi})
        return out

    # -------------------------------------------------------------- the pointer
    def press(self, pos: tuple[float, float]) -> int | None:
        """Grab the free particle drawn nearest the pixel `pos` (column, row), within a few
        pixels of its disc; the particle's index, or None (nothing there, or outside)."""
        live, painter = self.live, self.painter
        w, h = painter.size
        if not (0 <= pos[0] < w and 0 <= pos[1] < h):
            return None  # a press outside the image grabs nothing
        self.settle()
        x, _, _, _ = live.drawn(self.alpha)
        radius = max(8.0, 3.0 * painter.ras.radius + 2.0)
        with np.errstate(over="ignore", invalid="ignore"):  # a particle far off screen: no pixel
            col, row, depth = painter.pixels(x)
            i = pick(col, row, pos, radius, ~live.pinned, depth)
        if i is not None:
            live.grab(i)
            self.status = f"dragging particle {i}"
            return i
        # No particle there: a dynamic rigid body under the pointer (2D) is held instead.
        if live.b is not None and painter.cam.dim == 2:
            with np.errstate(over="ignore", invalid="ignore"):
                point = screen_to_world(painter.cam, painter.origin, pos, np.zeros(2))
            b = live.body_at(point) if np.isfinite(point).all() else None
            if b is not None:
                live.grab_body(b, point)
                self.status = f"dragging body {b}"
        return None

    def drag(self, pos: tuple[float, float]) -> None:
        """Hold the grabbed particle under the pixel `pos` (in 3D in the plane through it
        parallel to the screen); paused, it is put there at once. Nothing held: nothing."""
        live = self.live
        if live.grabbed is None and live.body is None:
            return
        # The pointer may leave the image, but not to 1e308: the particle follows it at most 10
        # image sizes beyond the edge.
        w, h = self.painter.size
        pos = (min(max(pos[0], -10.0 * w), 11.0 * w), min(max(pos[1], -10.0 * h), 11.0 * h))
        if live.body is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                target = screen_to_world(self.painter.cam, self.painter.origin, pos, np.zeros(2))
            if np.isfinite(target).all():
                if self.clock.paused:
                    self.settle()
                live.move_body(target, self.clock.paused)
            return
        through = live.x[live.grabbed]
        with np.errstate(over="ignore", invalid="ignore"):
            target = screen_to_world(self.painter.cam, self.painter.origin, pos, through)
        if np.isfinite(target).all():
            if self.clock.paused:
                self.settle()  # paused, it is put there now: the scene is written
            live.move(target, self.clock.paused)

    def release(self) -> None:
        """Let go of the grabbed particle (with the pointer's velocity) or body, if any."""
        if self.live.grabbed is not None or self.live.body is not None:
            self.settle()
            self.live.release()
            self.live.release_body()
            self.status = ""

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

    # -------------------------------------------------------------- drawing
    def hud(self, name: str = "") -> tuple[str, str]:
        """The parameter line (or `name` where the scene has none) and the state line."""
        params = self.live.params()
        parts = [f"{p.label} {params[p.name]:.4g} {p.unit}" for p in _params() if p.name in params]
        status = self.status
        if self.clock.paused and not status.startswith("diverged"):
            status = "paused" + (f" - {status}" if status else "")
        elif self.slow > 0.5:
            status = (status + "  " if status else "") + "slower than real time"
        return "  ".join(parts) or name, status

    def frame(self, name: str = "") -> np.ndarray:
        """(H, W, 3) uint8 RGB: the state interpolated by the clock's fraction, as the GIF draws
        it (with the HUD where the painter has one)."""
        x, v, t, p = self.live.drawn(self.alpha)
        bodies = self.live.drawn_bodies(self.alpha)
        params, status = self.hud(name)
        # A scene blowing up (before the core calls it diverged) puts particles at pixels beyond
        # int64: they are drawn nowhere, without a warning per frame.
        with np.errstate(over="ignore", invalid="ignore"):
            return self.painter.draw(x, v, t, p, params, status, bodies)


def _param(name: str) -> Any:
    for p in _params():
        if p.name == name:
            return p
    raise InvalidInputError(f"name: expected one of {', '.join(q.name for q in _params())}, got {name!r}")
