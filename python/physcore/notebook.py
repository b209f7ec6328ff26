"""Live in the notebook: a scene running in a Jupyter widget, drawn as its GIF would be, with
play/pause, one tick, reset, a time read-out, dragging with the pointer and a slider for each
parameter the viewer's keys change (the keys work too, on the focused picture). ``physcore.widget(scene)`` makes one, ``scene.show()``
displays one.

The kernel runs the scene exactly as the live window does (:mod:`physcore.viewer`): one loop
(``physcore._live``), the same fixed ticks (each the scene's GIF frame, due every ``1 / fps`` wall
seconds, the state drawn interpolated between the last two), the same painter (the camera and
colour scale fitted once to a preview run) and the same drag (the grabbed particle pinned and
moved along the pointer's path). The front end is an anywidget ES module (JupyterLab, Notebook
7, VS Code, Colab) that draws the frames on a canvas.

Frames and flow control
-----------------------
Each frame is encoded as JPEG (default, quality 85) or PNG by Pillow and sent in a binary
buffer of a custom widget message (no base64), with the time, the parameters and the state.
The kernel sends a frame only against a credit from the front end: it grants two when a view
opens and gives one back each time it has drawn a frame (on the browser's next animation frame,
and at most ``max_fps`` times a second, default 30). Frames therefore come as fast as the kernel
makes them and the browser draws them, never faster than ``max_fps`` or the display, and never
piling up in a slow link; paused, a frame is sent only after something changed (a step, a drag,
a slider, a reset). By default the scene steps in a background thread (the core releases the
GIL), one tick at a time, while frames draw the last two states interpolated: a scene whose
tick takes longer than a frame (a 10⁴-particle fluid) still gets frames at the drawing's rate,
moving smoothly at the simulation's own pace (``background=False``: each frame runs the ticks
due first, as the window does). The kernel makes frames between cells: a long cell in the
same kernel holds the widget still until it ends.

Where no kernel runs (a notebook saved and exported to static HTML, a viewer of notebooks),
the widget's output carries a ``text/html`` fallback: the scene's GIF over the preview run (its
first frames from the start, as :func:`physcore.render.gif` draws them; the frames are the
preview's, so only the encoding costs; ``fallback=False`` leaves it out).
nbconvert's HTML shows it for a notebook saved without its widget state (JupyterLab's default).

Examples
--------
Build a widget without displaying it (a notebook shows it as a cell's last value, or with
``scene.show()``), and drive it from Python:

>>> import physcore as pc
>>> w = pc.widget(pc.scenes.spring_chain(n=6), preview=0.0, fallback=False)
>>> w.pause(); w.step()
>>> w.ticks, round(w.time / w.tick_time, 6)
(1, 1.0)
>>> info, data = w.produce_frame()
>>> info["mime"], data[:2] == b"\\xff\\xd8"  # a JPEG
('image/jpeg', True)
>>> [s["name"] for s in w.sliders]
['stiffness', 'damping', 'gravity']
"""
from __future__ import annotations

import io
import math
import time
from pathlib import Path
from typing import Any

from . import _check
from ._errors import InvalidInputError, InvalidTypeError, PhyscoreError
from ._live import PARAM_RANGE, _has_bodies, _LiveRun, _settings

try:
    import anywidget
    import traitlets
except ImportError as _e:  # pragma: no cover - the notebook extra brings both
    raise ImportError('the notebook widget needs anywidget: pip install "physcore[notebook]"') from _e

__all__ = ["widget", "show", "Widget", "FORMATS", "SLIDER_POSITIONS", "slider_value", "slider_position", "INSTALL"]

#: What to install for the widget.
INSTALL = 'pip install "physcore[notebook]"'
#: Image formats of the frames: name -> (Pillow format, MIME type).
FORMATS = {"jpeg": ("JPEG", "image/jpeg"), "png": ("PNG", "image/png")}
#: Steps of a slider (an HTML range input from 0 to this).
SLIDER_POSITIONS = 1000
#: Frames the kernel may have sent and the front end not yet drawn.
_MAX_CREDITS = 2


# --------------------------------------------------------------------------- sliders
def slider_value(spec: dict[str, Any], position: int) -> float:
    """The parameter value at slider `position` (0 to :data:`SLIDER_POSITIONS`): logarithmic
    from ``spec["lo"]`` to ``spec["hi"]``; where ``lo`` is 0 (a damping or drag that starts at
    0), position 0 is 0 and the others are logarithmic from ``hi / PARAM_RANGE²`` up.

    Raises InvalidTypeError / InvalidInputError naming `position` where it is not an int in range.
    """
    position = _check.int_in_range("position", position, 0, SLIDER_POSITIONS)
    lo, hi = float(spec["lo"]), float(spec["hi"])
    if lo > 0:
        return lo * (hi / lo) ** (position / SLIDER_POSITIONS)
    if position == 0:
        return 0.0
    a = hi / PARAM_RANGE**2
    return a * (hi / a) ** ((position - 1) / (SLIDER_POSITIONS - 1))


def slider_position(spec: dict[str, Any], value: float) -> int:
    """The slider position nearest `value` (the inverse of :func:`slider_value`, clipped to the
    range)."""
    lo, hi = float(spec["lo"]), float(spec["hi"])
    value = float(value)
    if lo > 0:
        f = math.log(max(value, lo) / lo) / math.log(hi / lo)
        return int(min(max(round(f * SLIDER_POSITIONS), 0), SLIDER_POSITIONS))
    a = hi / PARAM_RANGE**2
    if value < a:
        return 0 if value < 0.5 * a else 1
    f = math.log(min(value, hi) / a) / math.log(hi / a)
    return int(min(1 + round(f * (SLIDER_POSITIONS - 1)), SLIDER_POSITIONS))


def _point(content: dict[str, Any]) -> tuple[float, float] | None:
    """A message's (x, y) as two finite floats, or None: a front end may send anything."""
    try:
        return _check.finite("x", content.get("x")), _check.finite("y", content.get("y"))
    except (TypeError, ValueError):  # PhyscoreError's bad-input classes are ValueError/TypeError
        return None


# --------------------------------------------------------------------------- the widget
class Widget(anywidget.AnyWidget):
    """A scene running live in a notebook; made by :func:`widget` (see there for the options).

    It reads ``scene``, ``time``, ``ticks``, ``tick_time``, ``params``, ``grabbed``,
    ``sliders`` and ``playing`` (settable), and is driven from Python with :meth:`play`,
    :meth:`pause`, :meth:`step`, :meth:`reset`, :meth:`set_param`, and the pointer's
    :meth:`press`, :meth:`drag`, :meth:`release` (pixels of the frame), as the front end drives it.
    """

    _esm = (Path(__file__).parent / "_widget.js").read_text(encoding="utf-8")
    _css = (Path(__file__).parent / "_widget.css").read_text(encoding="utf-8")

    #: Running (True) or paused; the front end's play button sets it.
    playing = traitlets.Bool(True).tag(sync=True)
    #: (width, height) of the frames, pixels.
    size = traitlets.List(traitlets.Int(), [480, 360]).tag(sync=True)
    #: Most frames a second the front end asks for (it gives a credit back no sooner).
    max_fps = traitlets.Float(30.0).tag(sync=True)
    #: One slider per parameter the scene's terms have (:meth:`physcore._live._LiveRun.sliders`,
    #: with ``position`` and ``positions``).
    sliders = traitlets.List(traitlets.Dict()).tag(sync=True)

    def __init__(self, session: _LiveRun, *, name: str, image_format: str, quality: int, playing: bool,
                 fallback: bool, max_fps: float) -> None:
        self._session = session
        self._name = name
        self._format = image_format
        self._quality = quality
        self._fallback = fallback
        self._fallback_html: str | None = None
        self._credits = 0
        self._dirty = True
        self._seq = 0
        self._last = time.perf_counter()
        self._message = ""
        session.set_paused(not playing)
        w, h = session.painter.size
        super().__init__(playing=playing, size=[int(w), int(h)], sliders=self._slider_specs(), max_fps=max_fps)
        self.on_msg(self._on_msg)

    # -------------------------------------------------------------- read
    @property
    def scene(self) -> Any:
        """The live :class:`physcore.Scene` (a new one after a drag or a reset: read it again),
        once any tick running in the background has ended."""
        self._say(self._session.settle())
        return self._session.live.scene

    @property
    def time(self) -> float:
        """The scene's simulated time at the latest tick, s."""
        return self._session.live.t

    @property
    def ticks(self) -> int:
        """Ticks run (each the scene's GIF frame)."""
        return self._session.live.ticks

    @property
    def tick_time(self) -> float:
        """Simulated seconds per tick."""
        return self._session.live.tick_time

    @property
    def params(self) -> dict[str, float]:
        """The parameters the sliders change: name -> value (N/m, N·s/m, m/s², kg/s)."""
        return self._session.params()

    @property
    def grabbed(self) -> int | None:
        """The particle held by the pointer, or None."""
        return self._session.live.grabbed

    @property
    def status(self) -> str:
        """The state line the front end shows (paused, dragging, the last change)."""
        _, status = self._session.hud(self._name)
        return "  ".join(s for s in (status, self._message) if s)

    def pixel_of(self, i: int) -> tuple[int, int]:
        """The pixel (column, row) of the frame where particle `i` is drawn now.

        Raises InvalidTypeError / InvalidInputError naming `i` (a bad index, or at no pixel)."""
        return self._session.pixel_of(i)

    # -------------------------------------------------------------- drive
    def play(self) -> None:
        """Run (the front end's play button)."""
        self.playing = True

    def pause(self) -> None:
        """Pause (the front end's pause button)."""
        self.playing = False

    def step(self) -> None:
        """Pause and run one tick (one GIF frame)."""
        self._say(self._session.step_once())
        self.playing = False
        self._changed()

    def reset(self) -> None:
        """Back to the start state, keeping the parameters."""
        self._say(self._session.reset())
        self._changed()

    def set_param(self, name: str, value: float) -> float:
        """Set parameter `name` ("stiffness", "damping", "gravity", "drag") to `value`, clipped to
        its slider's range (:data:`physcore.viewer.PARAM_RANGE` times its start value either
        way), in every term that has it; the value set. A fixed dt shrinks with a stiffer
        scene's stability limit, as with the viewer's keys.

        Raises InvalidInputError naming `name` where the scene has no such term (or a stiffness
        or gravity that starts at 0, which no slider scales), InvalidTypeError /
        InvalidInputError naming `value` where it is not a finite number."""
        self._say(self._session.set(name, value, strict=True))
        self.sliders = self._slider_specs()
        self._changed()
        return self.params[name]

    def press(self, col: float, row: float) -> int | None:
        """Press the pointer at pixel (`col`, `row`) of the frame: grab the free particle drawn
        there (within a few pixels of its disc); its index, or None."""
        i = self._session.press((float(col), float(row)))
        self._changed()
        return i

    def drag(self, col: float, row: float) -> None:
        """Move the pointer to pixel (`col`, `row`): the grabbed particle follows (at once
        while paused, along the path during the next tick while running)."""
        self._session.drag((float(col), float(row)))
        self._changed()

    def release(self) -> None:
        """Let go of the grabbed particle, with the pointer's velocity."""
        self._session.release()
        self._changed()

    # -------------------------------------------------------------- frames
    def produce_frame(self) -> tuple[dict[str, Any], bytes]:
        """Run the ticks due since the last frame (wall time; none while paused), draw the state
        and encode it: the message's content (``type``, ``seq``, ``time`` s, ``ticks``,
        ``status``, ``params``, ``playing``, ``grabbed`` (the held particle or None), ``body``
        (the held rigid body or None), ``mime``) and the image's bytes. This is what the widget
        sends against each credit of the front end."""
        session = self._session
        now = time.perf_counter()
        due = session.clock.advance(now - self._last)
        self._last = now
        self._say(session.run(due))
        if session.clock.paused and self.playing:  # diverged: paused by the loop
            self.playing = False
        rgb = session.frame(self._name)
        fmt, mime = FORMATS[self._format]
        buf = io.BytesIO()
        from PIL import Image

        options = {"quality": self._quality} if fmt == "JPEG" else {"compress_level": 1}
        Image.fromarray(rgb).save(buf, format=fmt, **options)
        self._seq += 1
        self._dirty = False
        live = session.live
        drawn_time = live.pt + session.alpha * (live.t - live.pt)
        content = {"type": "frame", "seq": self._seq, "time": drawn_time, "ticks": session.live.ticks,
                   "status": self.status, "params": self.params, "playing": bool(self.playing),
                   "grabbed": live.grabbed, "body": live.body, "mime": mime}
        return content, buf.getvalue()

    def _pump(self) -> None:
        """Send frames while the front end has credits and there is something new to draw:
        running, two frames are in flight (one drawn while the next is made); paused, one
        after each change."""
        while self._credits > 0 and (self.playing or self._dirty):
            content, data = self.produce_frame()
            self._credits -= 1
            self.send(content, [data])

    def _changed(self) -> None:
        self._dirty = True
        self._pump()

    def _say(self, message: str | None) -> None:
        if message:
            self._message = message

    @traitlets.observe("playing")
    def _on_playing(self, change: dict[str, Any]) -> None:
        session = self._session
        if session.clock.paused == (not change["new"]):
            return
        session.set_paused(not change["new"])
        self._last = time.perf_counter()
        self._changed()

    def _slider_specs(self) -> list[dict[str, Any]]:
        out = []
        for spec in self._session.sliders():
            out.append({**spec, "positions": SLIDER_POSITIONS, "position": slider_position(spec, spec["value"])})
        return out

    def _key(self, ch: Any) -> None:
        """A key pressed on the picture: the viewer's keys (``physcore.viewer.KEYS``), but for
        quit and screenshot; Right is ``.``."""
        if not isinstance(ch, str) or ch in ("q", "p", "Escape"):
            return
        ch = "." if ch == "ArrowRight" else ch
        if ch == " ":
            self.playing = not self.playing
            return
        before = self.params
        self._say(self._session.key(ch))
        self.playing = not self._session.clock.paused
        if self.params != before:
            self.sliders = self._slider_specs()
        self._dirty = True

    def _on_msg(self, _widget: Any, content: Any, buffers: Any) -> None:
        """A message from the front end (see ``_widget.js``); anything malformed is ignored."""
        kind = content.get("type") if isinstance(content, dict) else None
        session = self._session
        try:
            if kind == "ready":
                self._credits = _MAX_CREDITS
                self._dirty = True
            elif kind == "ack":
                self._credits = min(self._credits + 1, _MAX_CREDITS)
            elif kind in ("down", "move", "up"):
                pos = _point(content)
                if kind == "down" and pos is not None:
                    session.press(pos)
                elif kind == "move" and pos is not None:
                    session.drag(pos)
                elif kind == "up":
                    session.release()
                self._dirty = True
            elif kind == "key":
                self._key(content.get("key"))
            elif kind == "step":
                self.step()
            elif kind == "reset":
                self.reset()
            elif kind == "param":
                spec = next((s for s in self.sliders if s["name"] == content.get("name")), None)
                if spec is not None:
                    self._say(session.set(spec["name"], slider_value(spec, content.get("position"))))
                    self._dirty = True
        except PhyscoreError as e:  # a bad position, a pinned particle: shown, not raised
            self._message = str(e)
            self._dirty = True
        self._pump()

    def close(self) -> None:
        """Close the widget (its views go) and stop its background thread."""
        self._session.close()
        super().close()

    # -------------------------------------------------------------- where no kernel runs
    def fallback_html(self) -> str:
        """An ``<img>`` of the scene's GIF over the preview run (its first frames from the start,
        drawn as :func:`physcore.render.gif` draws them, with the widget's camera), as a data
        URL: what a page without a kernel shows. Only the GIF's encoding costs: the frames are
        the preview's; ``preview=0`` gives the start alone."""
        if self._fallback_html is None:
            from .render import recording_html

            self._fallback_html = recording_html(self._session.painter.preview)
        return self._fallback_html

    def _repr_mimebundle_(self, **kwargs: Any) -> Any:
        bundle = super()._repr_mimebundle_(**kwargs)
        if not self._fallback or bundle is None:
            return bundle
        data, meta = bundle if isinstance(bundle, tuple) else (bundle, {})
        return {**data, "text/html": self.fallback_html()}, meta


def widget(
    scene: Any,
    *,
    name: str = "scene",
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    view: tuple[float, float] | None = None,
    preview: float = 1.0,
    hud: bool = False,
    image_format: str = "jpeg",
    quality: int = 85,
    playing: bool = True,
    fallback: bool = True,
    background: bool = True,
    max_fps: float = 30.0,
) -> Widget:
    """A live notebook widget running `scene` (see the module docstring); display it as a cell's
    last value or with ``IPython.display.display``.

    Parameters
    ----------
    scene : physcore.Scene
        A scene with particles (2D or 3D); its ``render_defaults`` give the stepping (as
        ``physcore render``), colours, size and playback rate. It is stepped, and its terms
        changed by the sliders, in place, until a drag or a reset replaces it by a copy (read
        the widget's ``scene``).
    name : str, default "scene"
        Shown where the scene has no parameter to show.
    size : (int, int), optional
        Frame width and height in pixels, each >= 16. Default: the scene's, else 480 × 360.
    fps : float, optional
        Ticks per wall second (each tick is the scene's GIF frame), > 0: default the scene's
        ``fps``, else 30, so that the widget plays at the GIF's speed.
    view : (float, float), optional
        3D camera (azimuth, elevation) in degrees; default the scene's, else (-60, 25).
    preview : float, default 1.0
        Wall seconds spent now simulating a copy of the scene, to fit the camera and the colour
        scale to its motion (0: to the start state alone).
    hud : bool, default False
        Draw the viewer's parameter line and state on the frames (the widget shows them beside
        the image); False draws exactly the GIF's frames.
    image_format : {"jpeg", "png"}, default "jpeg"
        How frames travel: JPEG is smaller and faster to encode; PNG is exact.
    quality : int, default 85
        JPEG quality, 1 to 95.
    playing : bool, default True
        Start running (False: paused, showing the start).
    fallback : bool, default True
        Put the scene's GIF over the preview run in the output, for pages without a kernel
        (encoded when the widget is first displayed; see :meth:`Widget.fallback_html`).
    background : bool, default True
        Step in a background thread, one tick at a time, while frames draw the last two states
        interpolated: frames keep coming, and the motion stays smooth, where a tick takes
        longer than a frame. False: each frame runs the ticks due first, as the window does.
    max_fps : float, default 30
        Most frames a second the front end asks for, > 0 (the kernel's and the browser's
        share of a small machine; the display's rate caps it too).

    Returns
    -------
    Widget

    Raises
    ------
    ImportError
        anywidget is not installed (the message says ``pip install "physcore[notebook]"``): on
        importing :mod:`physcore.notebook`.
    InvalidTypeError, InvalidInputError
        A bad argument, naming it, or a scene without particles.
    """
    from .render.painter import check_fps, scene_defaults

    if not (hasattr(scene, "positions") and hasattr(scene, "terms") and hasattr(scene, "to_bytes")):
        raise InvalidTypeError(f"scene: expected a physcore.Scene, got {type(scene).__name__}")
    if int(scene.n_particles) == 0 and not _has_bodies(scene):
        raise InvalidInputError("scene: it has no particles or rigid bodies; the widget shows those (render grids and flows with physcore.render.gif)")
    if not isinstance(name, str) or not name:
        raise InvalidTypeError(f"name: expected a non-empty str, got {name!r}")
    settings = _settings(scene, size, view)
    # A frame's buffers (colour, depth, the antialiased canvas at twice the size, the encoded
    # image): about 64 bytes a pixel, refused up front rather than as a MemoryError out of the
    # first frame's message handler (widget(size=(40000, 30000)), issue 64's hostile run).
    w, h = settings["size"]
    _check.memory("size", 64.0 * w * h, f"a {w}x{h} widget frame")
    fps = check_fps(scene_defaults(scene).get("fps", 30.0) if fps is None else fps)
    preview = _check.real("preview", preview)
    if not (preview >= 0 and math.isfinite(preview)):
        raise InvalidInputError(f"preview: must be a finite number of seconds >= 0, got {preview!r}")
    hud = _check.flag("hud", hud)
    if image_format not in FORMATS:
        raise InvalidInputError(f"image_format: expected one of {', '.join(FORMATS)}, got {image_format!r}")
    quality = _check.int_in_range("quality", quality, 1, 95)
    playing = _check.flag("playing", playing)
    fallback = _check.flag("fallback", fallback)
    background = _check.flag("background", background)
    max_fps = _check.real("max_fps", max_fps)
    if not (max_fps > 0 and math.isfinite(max_fps)):
        raise InvalidInputError(f"max_fps: must be a finite number > 0, got {max_fps!r}")
    session = _LiveRun(scene, settings=settings, fps=fps, preview=preview, hud=hud, background=background)
    return Widget(session, name=name, image_format=image_format, quality=quality, playing=playing, fallback=fallback,
                  max_fps=max_fps)


def _frames_per_second(w: Widget, seconds: float) -> float:
    """Frames :meth:`Widget.produce_frame` makes per wall second, running, over `seconds`
    (the kernel's side of the frame rate: ticks, drawing and encoding)."""
    w.play()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        w.produce_frame()
        n += 1
    return n / (time.perf_counter() - t0)


def show(scene: Any, **options: Any) -> None:
    """Display ``scene`` running live in a Jupyter notebook: :func:`widget` ``(scene, **options)``
    shown with IPython's ``display``. ``Scene.show(**options)`` calls this (the package attaches
    it, so that ``scene.py`` needs nothing of the presentation layer)."""
    from IPython.display import display

    display(widget(scene, **options))
