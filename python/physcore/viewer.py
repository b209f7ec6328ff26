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
The loop, the live state and the painter live in ``physcore._live`` (its ``_LiveRun``), shared
with the notebook widget (:mod:`physcore.notebook`); this module adds the window, the keys and the
mouse.

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

import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from . import _check
from ._errors import InvalidInputError, InvalidTypeError, PhyscoreError
from ._live import (
    MAX_TICKS_PER_DRAW,
    PARAM_RANGE,
    STEP_FACTOR,
    FixedStep,
    _has_bodies,
    _LiveRun,
    _settings,
    interpolate,
    param_value,
    pick,
    scale_param,
    screen_to_world,
)

# The loop, the live state and the painter are shared with the notebook widget (physcore._live);
# the names the viewer's tests and users reach through this module are re-exported here.
from ._live import _Live as _Live
from ._live import _Painter as _Painter

__all__ = [
    "view", "Viewer", "ViewResult", "FixedStep", "interpolate", "pick", "screen_to_world", "param_value",
    "scale_param", "keys_text", "KEYS", "MAX_TICKS_PER_DRAW", "STEP_FACTOR", "PARAM_RANGE", "INSTALL",
]

#: What to install when pygame is missing.
INSTALL = 'pip install "physcore[view]"'

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

#: Largest display rate, Hz.
_MAX_DRAW_RATE = 60


def keys_text() -> str:
    """The key help, one key a line (printed at start and in ``physcore view --help``)."""
    width = max(len(k) for k, _ in KEYS) + 2
    return "\n".join(f"  {k.ljust(width)}{what}" for k, what in KEYS)


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
    The loop, the live state and the painter are :class:`physcore._live._LiveRun`'s, shared
    with the notebook widget; this class turns pygame's events into its calls.

    A `script` item's callable receives this object: it reads ``scene``, ``time``, ``paused``,
    ``ticks``, ``draws``, ``params`` and ``grabbed``, and finds where a particle is drawn with
    :meth:`pixel_of`.
    """

    def __init__(self, scene: Any, *, name: str, settings: dict[str, Any], fps: float, preview: float, hud: bool,
                 out: Any) -> None:
        self.pygame = _import_pygame()
        self.name = name
        self.out = out
        self.session = _LiveRun(scene, settings=settings, fps=fps, preview=preview, hud=hud)
        self.live, self.painter, self.clock = self.session.live, self.session.painter, self.session.clock
        self.draws = 0
        self.screenshots: list[Path] = []
        self.quit = False
        self.image: np.ndarray | None = None

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

    @property
    def status(self) -> str:
        return self.session.status

    @property
    def alpha(self) -> float:
        return self.session.alpha

    def pixel_of(self, i: int) -> tuple[int, int]:
        """The pixel (column, row) where particle `i` is drawn now (its interpolated position).

        Raises InvalidTypeError / InvalidInputError naming `i` for a bad index, or a particle
        so far away that it is at no finite pixel."""
        return self.session.pixel_of(i)

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

    def _say(self, message: str | None) -> None:
        if message:
            print(message, file=self.out)

    def _on_key(self, ch: str) -> None:
        session = self.session
        if not isinstance(ch, str):
            return
        if ch in ("q", "esc"):
            self.quit = True
        elif ch == "p":
            try:
                self.screenshots.append(self.save_screenshot(self._next_name()))
            except (OSError, PhyscoreError) as e:  # a full disk; no window (before run, after close)
                print(f"screenshot not written: {e}", file=self.out)
        else:
            self._say(session.key(ch))

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
        pg, session = self.pygame, self.session
        kind, pos = getattr(event, "type", None), _pointer(event)
        left = not hasattr(event, "button") or _int_attr(event, "button") == 1
        if kind == pg.MOUSEBUTTONDOWN and left:
            if pos is not None:  # a press at no point grabs nothing
                session.press(pos)
        elif kind == pg.MOUSEMOTION and pos is not None:
            session.drag(pos)
        elif kind == pg.MOUSEBUTTONUP and left:
            session.release()

    # -------------------------------------------------------------- output
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
            self._say(self.session.run(due))
            rgb = self.session.frame(self.name)
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
    from .render.painter import check_fps

    if not (hasattr(scene, "positions") and hasattr(scene, "terms") and hasattr(scene, "to_bytes")):
        raise InvalidTypeError(f"scene: expected a physcore.Scene, got {type(scene).__name__}")
    if int(scene.n_particles) == 0 and not _has_bodies(scene):
        raise InvalidInputError("scene: it has no particles or rigid bodies; the live viewer shows those (render grids and flows with physcore render)")
    if not isinstance(name, str) or not name:
        raise InvalidTypeError(f"name: expected a non-empty str, got {name!r}")
    settings = _settings(scene, size, view)
    from .render.painter import scene_defaults

    fps = check_fps(scene_defaults(scene).get("fps", 30.0) if fps is None else fps)
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
        from .render.painter import check_path

        screenshot = check_path(screenshot, "png")
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
    from ._system import quiet_wayland_probe

    quiet_wayland_probe()
    pg.display.init()  # no display: pygame.error now, before the preview's simulation
    driver = pg.display.get_driver()
    if driver in ("offscreen", "dummy") and not os.environ.get("SDL_VIDEODRIVER"):
        # SDL fell back to a driver that shows nothing: the viewer would run unseen, for ever.
        pg.display.quit()
        raise pg.error(f"no display: SDL fell back to its {driver!r} driver, which shows nothing")
    try:
        print(f"physcore view: {name}\n{keys_text()}", file=out)
        viewer = Viewer(scene, name=name, settings=settings, fps=fps, preview=preview, hud=hud, out=out)
        return viewer.run(seconds=seconds, draws=draws, script=script, screenshot=screenshot)
    finally:
        pg.display.quit()


# --------------------------------------------------------------------------- command line
