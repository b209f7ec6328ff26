"""The ``physcore`` command line: list the ready-made scenes and render them to animated GIFs.

Usage::

    physcore scenes
    physcore render SCENE [-o OUT.gif|OUT.mp4|OUT.webm|OUT.png|OUT.glb|OUT.gltf|OUT.html] [--frames N] [--fps F] [--size WxH] [--integrator NAME]
                          [--dt DT] [--steps-per-frame K | --frame-time SECONDS]
                          [--color-by speed|pressure|none] [--no-colorbar]
                          [--camera fit|follow|zoom|orbit] [--arrows velocity|acceleration]
                          [--no-mesh] [--texture IMAGE] [--[no-]antialias] [--cmap NAME] [--background #RRGGBB]
                          [--param key=value ...]
    physcore view SCENE [--param key=value ...] [--size WxH] [--fps F] [--seconds S] [--screenshot OUT.png]

``-o OUT.glb`` (or ``.gltf``) writes the motion as glTF 2.0 and ``-o OUT.html`` a page that
plays it in a browser (:func:`physcore.render.gltf`, :func:`physcore.render.html`; both need
pygltflib, the web extra); of the drawing options they take ``--fps`` and ``--theme``.

``physcore view`` runs a scene live in a window (:mod:`physcore.viewer`; needs pygame-ce).

A scene function's ``render_defaults`` dict gives its animation defaults: ``frames``, ``fps``,
``size``, ``color_by``, ``view``, ``radius``, and either ``steps_per_frame`` or ``frame_time``
(simulated seconds per frame, rendered as ``round(frame_time / dt)`` steps of dt). With
``"substeps": "auto"`` next to ``frame_time`` each frame calls ``scene.advance(frame_time)``,
which picks its own substeps (fluids: CFL and stability limits), unless ``--steps-per-frame``
is given. ``lead_in`` (simulated seconds, default 0) is simulated before the first frame, so
that it shows something (a Turing pattern already grown from its seeds, a wave already at the
slits); the scene's clock in the frames says so.

Exit codes: 0 success, 1 the simulation diverged or the file could not be written, 2 bad usage
(unknown scene, parameter or option value, or a request too large for memory). Every usage error
is one line on stderr, ``physcore render: error: ...``, with no traceback.

Before anything is built or simulated, the frames buffer (``frames × width × height`` palette
bytes, twice over while encoding) is estimated and refused above half the physical memory
(:func:`physcore._check.memory_limit`); the scene functions then refuse particle counts that
would not fit (e.g. ``--param n=100000``), and :func:`physcore.render.gif` the whole recording.

Examples
--------
:func:`main` takes the arguments as a list and returns the exit code:

>>> from physcore.cli import main
>>> main(["render", "no_such_scene"])
2
"""
from __future__ import annotations

import argparse
import inspect
import math
import os
import re
import sys
import textwrap
import time
import typing
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["main"]

# Animation defaults when a scene function has no ``render_defaults`` entry.
_FALLBACK = {"frames": 90, "fps": 30.0, "size": (480, 360), "color_by": "speed"}

# Most steps per frame: render.MAX_STEPS (2**53), as a float for the comparison with frame_time/dt.
_MAX_STEPS = float(2**53)

# Scene-function keywords that have their own options rather than --param.
_OWN_OPTION = {"integrator": "--integrator", "dt": "--dt"}

_TRUE = {"true", "1", "yes", "on", "y", "t"}
_FALSE = {"false", "0", "no", "off", "n", "f"}


class _UsageError(Exception):
    """A bad command line; reported on stderr with exit code 2."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr (no usage dump), exit 2."""

    def error(self, message: str) -> typing.NoReturn:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {' '.join(str(message).split())}\n")


# --------------------------------------------------------------------------- argument types
def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _int_in(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An integer argument in [lo, hi], refused by argparse (exit 2) before anything runs."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {value}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"must be <= {hi}, got {value}")
        return value

    return parse


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*[xX×,]\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, e.g. 480x360; got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"width and height must be >= 16 pixels, got {w}x{h}")
    return w, h


def _view(text: str) -> tuple[float, float]:
    try:
        az, el = (float(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected AZIMUTH,ELEVATION in degrees, e.g. -60,25; got {text!r}") from None
    return az, el


def _camera_arg(text: str) -> Any:
    """--camera: fit, follow, zoom, orbit, follow:INDEX or zoom:INDEX (a particle) or orbit:DEG_PER_S."""
    mode, sep, param = text.partition(":")
    if mode in ("fit", "follow", "zoom", "orbit") and not sep:
        return mode
    try:
        if mode in ("follow", "zoom") and sep:
            return (mode, int(param))
        if mode == "orbit" and sep:
            return ("orbit", float(param))
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(
        f"expected fit, follow, zoom, orbit, follow:INDEX, zoom:INDEX or orbit:DEGREES_PER_SECOND; got {text!r}"
    )


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"expected key=value, got {text!r}")
    return key.strip(), value.strip()


# --------------------------------------------------------------------------- scene parameters
def _scene_params(fn: Callable[..., Any]) -> dict[str, inspect.Parameter]:
    """Keyword parameters (with defaults) of a scene function, in order."""
    return {
        name: p
        for name, p in inspect.signature(fn).parameters.items()
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }


def _param_type(fn: Callable[..., Any], name: str, default: Any) -> type | None:
    """The type a --param value converts to: the default's type, else the annotation's."""
    if default is not None and default is not inspect.Parameter.empty:
        return type(default)
    try:
        hint = typing.get_type_hints(fn).get(name)
    except Exception:  # noqa: BLE001 - unresolvable annotations (e.g. newer syntax on an older Python)
        return None
    # Optional[X] is Union[X, None]: take X.
    args = [a for a in getattr(hint, "__args__", ()) if a is not type(None)]
    if len(args) == 1 and isinstance(args[0], type):
        return args[0]
    return hint if isinstance(hint, type) else None


def _convert(name: str, text: str, kind: type | None, default: Any) -> Any:
    """Convert a --param string to `kind`; 'none' gives None where the default is None."""
    if default is None and text.lower() == "none":
        return None
    try:
        if kind is bool:
            low = text.lower()
            if low in _TRUE:
                return True
            if low in _FALSE:
                return False
            raise ValueError
        if kind is int:
            return int(text)
        if kind is float:
            return float(text)
        if kind in (tuple, list):
            items = [float(t) for t in text.replace(" ", "").strip("()[]").split(",") if t]
            return kind(items)
        if kind is None or kind is str:
            if kind is None:  # no type to go by: the most specific that parses
                for conv in (int, float):
                    try:
                        return conv(text)
                    except ValueError:
                        pass
            return text
        return kind(text)
    except (TypeError, ValueError):
        pass
    what = {bool: "true/false (or 1/0, yes/no)", int: "an integer", float: "a number"}.get(
        kind, "a comma-separated list of numbers" if kind in (tuple, list) else getattr(kind, "__name__", "?")
    )
    raise _UsageError(f"--param {name}: expected {what}, got {text!r}")


def _scene_kwargs(scene_name: str, fn: Callable[..., Any], pairs: Sequence[tuple[str, str]]) -> dict[str, Any]:
    params = _scene_params(fn)
    kwargs: dict[str, Any] = {}
    old_names = getattr(fn, "deprecated_params", {})
    given: dict[str, str] = {}
    for key, text in pairs:
        if key in given:  # the last would win unseen
            raise _UsageError(f"--param {key} given twice ({given[key]}, {text})")
        given[key] = text
        if key in old_names and key not in params:
            new = old_names[key]
            print(f"physcore: --param {key} is deprecated: " + (f"it is now {new}" if new else "it did nothing and is ignored"), file=sys.stderr)
            if new is None:
                continue
            key = new
        if key in _OWN_OPTION:
            raise _UsageError(f"--param {key}: use the {_OWN_OPTION[key]} option instead")
        if key not in params:
            valid = ", ".join(k for k in params if k not in _OWN_OPTION) or "(none)"
            raise _UsageError(f"unknown parameter {key!r} for scene {scene_name!r}; valid parameters: {valid}")
        default = params[key].default
        kwargs[key] = _convert(key, text, _param_type(fn, key, default), default)
    return kwargs


def _summary(fn: Callable[..., Any]) -> str:
    """The docstring's first sentence as plain text: its first paragraph joined (a summary may
    wrap), cut after the first full stop that is not an abbreviation's ("Annu.", "Am."), reST
    roles unwrapped to their names and literals to `name`."""
    doc = (inspect.getdoc(fn) or "").strip()
    para = " ".join(line.strip() for line in doc.split("\n\n", 1)[0].splitlines())
    para = re.sub(r":[a-z]+:`~?([^`]+)`", lambda m: m.group(1).rsplit(".", 1)[-1], para)
    para = para.replace("``", "`")
    for end in re.finditer(r"\.(\s|$)", para):
        word = para[: end.start()].rsplit(" ", 1)[-1]
        if not re.fullmatch(r"\(?[A-Z][a-z]{0,4}", word):
            return para[: end.start() + 1]
    return para


def _defaults_text(fn: Callable[..., Any]) -> str:
    """The scene function's keywords as ``physcore scenes`` lists them: the ``--param`` ones, then
    those set by their own options (``--integrator``, ``--dt``), which ``--param`` refuses."""
    params, options = [], []
    for name, p in _scene_params(fn).items():
        text = name if p.default is inspect.Parameter.empty else f"{name}={p.default!r}"
        if name in _OWN_OPTION:
            default = "the scene's own" if p.default is None else repr(p.default)
            options.append(f"{_OWN_OPTION[name]} (default {default})")
        else:
            params.append(text)
    out = "parameters (--param key=value): " + (", ".join(params) or "none")
    return out + ("; options: " + ", ".join(options) if options else "")


# --------------------------------------------------------------------------- commands
def _registry() -> dict[str, Callable[..., Any]]:
    from . import scenes

    return dict(scenes.REGISTRY)


def _unknown_scene(name: str, registry: dict[str, Any], parser: argparse.ArgumentParser) -> None:
    """Exits through ``parser.error``: the scene `name` is not registered (with the closest name)."""
    import difflib

    close = difflib.get_close_matches(name.lower(), list(registry), n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    parser.error(f"unknown scene {name!r}; {hint}valid scenes: {', '.join(registry)}")


def _cmd_scenes(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    registry = _registry()
    width = max((len(n) for n in registry), default=0) + 2
    out = sys.stdout
    one = getattr(args, "scene", None)
    if one is not None:
        if one not in registry:
            _unknown_scene(one, registry, parser)
        fn = registry[one]
        doc = inspect.getdoc(fn) or ""
        out.write(f"{one}\n\n{doc}\n\n{_defaults_text(fn)}\n\nRender it with: physcore render {one} -o {one}.gif\n")
        return 0
    for name, fn in registry.items():
        out.write(textwrap.fill(_summary(fn), width=100, initial_indent=name.ljust(width), subsequent_indent=" " * width) + "\n")
        body = textwrap.fill(
            _defaults_text(fn),
            width=100,
            initial_indent=" " * (width + 2),
            subsequent_indent=" " * (width + 4),
            break_on_hyphens=False,
        )
        out.write(body + "\n")
    out.write("\nRender one with: physcore render NAME -o NAME.gif [--param key=value ...]\n")
    return 0


def _cmd_info() -> int:
    from ._system import info

    d = info()
    print(f"physcore {d['version']} ({d['build']} build)")
    print(f"cpu: {d['cpu']}")
    print(f"simd level: {d['simd_level']} (available: {', '.join(d['simd_levels'])}; set PHYSCORE_SIMD to force one)")
    print(f"threads: {d['threads']}")
    gpus = d["gpu_adapters"]
    if not gpus:
        print("gpu: no adapter (no Vulkan, Metal or DX12 driver found); Scene(device='gpu') is refused")
    for a in gpus:
        f64 = "f64" if a["f64"] else "f32 only"
        note = "  (a CPU implementation: taken only as device='gpu:...' by name)" if a["kind"] == "cpu" else ""
        print(f"gpu: {a['name']} ({a['kind']}, {a['backend']}, {f64}, "
              f"storage binding up to {a['max_storage_binding'] / 2**20:.0f} MiB){note}")
    return 1 if d["simd_level"].startswith("invalid") else 0


def _substeps_arg(text: str) -> Any:
    return text if text == "auto" else _positive_int(text)


def _defaults(fn: Callable[..., Any], scene: Any = None) -> dict[str, Any]:
    """The scene function's ``render_defaults``, updated by the built scene's own where there is
    one: a scene function sets some from its arguments (double_slit's frame_time from ``speed``)."""
    return {**(getattr(fn, "render_defaults", None) or {}), **(getattr(scene, "render_defaults", None) or {})}


def _frames_and_size(fn: Callable[..., Any], args: argparse.Namespace, scene: Any = None) -> tuple[int, tuple[int, int]]:
    """Frames and (width, height): the command line's, else the scene's render_defaults."""
    d = _defaults(fn, scene)
    frames = args.frames if args.frames is not None else int(d.get("frames", _FALLBACK["frames"]))
    size = args.size if args.size is not None else d.get("size", _FALLBACK["size"])
    if isinstance(size, str):
        size = _size(size)
    return frames, (int(size[0]), int(size[1]))


def _check_frames_memory(fn: Callable[..., Any], args: argparse.Namespace, scene: Any = None) -> None:
    """Refuse, before the scene is built, a frames buffer too large for memory (the palette
    index buffer and its Pillow image, one byte per pixel each, for every frame); with the
    built `scene`, again by its own render_defaults (a scene function may set frames or size
    from its arguments), before it is simulated."""
    from ._check import memory

    frames, (w, h) = _frames_and_size(fn, args, scene)
    memory("--frames, --size", 2 * frames * w * h, f"{frames} frames of {w}x{h} pixels")


def _too_many_steps(frame_time: float, dt: float) -> _UsageError:
    return _UsageError(
        f"--frame-time: {frame_time:.3g} s per frame is {frame_time / dt:.3g} steps of dt = {dt:.3g} s, "
        f"above {_MAX_STEPS:.3g}; give a shorter --frame-time or a larger --dt"
    )


def _render_settings(fn: Callable[..., Any], args: argparse.Namespace, dt: float, scene: Any = None) -> dict[str, Any]:
    """Animation settings: command-line options, else the built scene's render_defaults (the
    function's, updated by what it set from its arguments), else fallbacks.

    The result holds either ``steps_per_frame`` (fixed steps of dt) or ``frame_time`` (automatic
    substeps: ``scene.advance``), never both.
    """
    d = _defaults(fn, scene)
    frames, size = _frames_and_size(fn, args, scene)
    auto = str(d.get("substeps", "")).lower() == "auto"
    frame_time = args.frame_time if args.frame_time is not None else d.get("frame_time")
    stepping: dict[str, Any]
    substeps = getattr(args, "substeps", None)
    if substeps is not None:
        if args.steps_per_frame is not None:
            raise _UsageError("--substeps goes with --frame-time, not --steps-per-frame")
        if frame_time is None:
            raise _UsageError("--substeps needs --frame-time (this scene has no default frame time)")
        stepping = {"frame_time": float(frame_time)}
        if substeps != "auto":
            stepping["substeps"] = int(substeps)
    elif args.steps_per_frame is not None:
        stepping = {"steps_per_frame": args.steps_per_frame}
    elif args.frame_time is None:
        # The scene's defaults, chosen exactly as render.record() chooses them.
        from .render.painter import default_stepping

        if "frame_time" in d and not auto and not float(d["frame_time"]) / dt <= _MAX_STEPS:
            raise _too_many_steps(float(d["frame_time"]), dt)
        spf, ft = default_stepping(d, dt)
        stepping = {"steps_per_frame": spf} if ft is None else {"frame_time": ft}
    elif auto:
        stepping = {"frame_time": float(frame_time)}
    else:
        # Simulated seconds per frame: keeps the animation's time span whatever dt is (the
        # conversion record() uses for a scene's defaults).
        from .render.painter import steps_for

        if not float(frame_time) / dt <= _MAX_STEPS:
            raise _too_many_steps(float(frame_time), dt)
        stepping = {"steps_per_frame": steps_for(float(frame_time), dt)}
    fps = args.fps if args.fps is not None else float(d.get("fps", _FALLBACK["fps"]))
    color_by = args.color_by if args.color_by is not None else d.get("color_by", _FALLBACK["color_by"])
    settings = {"frames": frames, **stepping, "fps": fps, "size": tuple(size), "color_by": color_by}
    trail = args.trail if getattr(args, "trail", None) is not None else d.get("trail")
    if trail:
        settings["trail"] = min(int(trail), frames)
    if d.get("size_by"):
        settings["size_by"] = d["size_by"]
    view = args.view if args.view is not None else d.get("view")
    if view is not None:
        settings["view"] = tuple(view)
    radius = args.radius if args.radius is not None else d.get("radius")
    if radius is not None:
        settings["radius"] = radius
    for key in ("cmap", "background"):  # checked in _cmd_render before anything is simulated
        if getattr(args, key, None) is not None:
            settings[key] = getattr(args, key)
    theme = getattr(args, "theme", None) or d.get("theme")
    if theme is not None:
        settings["theme"] = theme
    title = getattr(args, "title", None) or d.get("title")
    if title:
        from ._check import text

        settings["title"] = text("--title", title)  # before simulating: bytes not UTF-8 in argv
    camera = getattr(args, "camera", None) or d.get("camera")
    if camera is not None:
        settings["camera"] = camera
    arrows = getattr(args, "arrows", None) or d.get("arrows")
    if arrows is not None:
        settings["arrows"] = arrows
    if getattr(args, "no_mesh", False):
        settings["mesh"] = False
    if getattr(args, "texture", None) is not None:
        settings["texture"] = args.texture
    if getattr(args, "antialias", None) is not None:
        settings["antialias"] = args.antialias
    return settings


def _human_bytes(n: int) -> str:
    from ._check import human_bytes

    return human_bytes(n)


def _substeps_text(counts: Sequence[Any]) -> str:
    """'N in all, automatic: M per frame on average (min a, max b)' from advance()'s returns."""
    if not counts:
        return "automatic (no frame advanced)"
    try:
        n = [int(c) for c in counts]
    except (TypeError, ValueError):
        return f"automatic ({len(counts)} frames advanced; the scene did not report substep counts)"
    return (
        f"{sum(n)} in all, automatic: {sum(n) / len(n):.1f} per frame on average "
        f"(min {min(n)}, max {max(n)})"
    )


def _scene_call(args: argparse.Namespace, parser: argparse.ArgumentParser) -> tuple[str, Callable[..., Any], dict[str, Any]]:
    """The scene named on the command line (``render``, ``view``): its name, its function and
    the keyword arguments from ``--param``, ``--integrator`` and ``--dt``; usage errors exit
    through ``parser.error``."""
    registry = _registry()
    name = args.scene
    if name not in registry:
        _unknown_scene(name, registry, parser)
    fn = registry[name]
    try:
        kwargs = _scene_kwargs(name, fn, args.param or [])
    except _UsageError as e:
        parser.error(str(e))
    if args.integrator is not None and "integrator" in getattr(fn, "deprecated_params", {}):
        # The grid scenes take integrator= only to ignore it (their fields step by their own
        # schemes): said here, not left to a warning and a summary naming another integrator.
        parser.error(f"--integrator: {name} steps its fields by its own scheme; it takes no integrator")
    if args.integrator is not None:
        from .scene import INTEGRATOR_ALIASES

        integrator = args.integrator
        if integrator in INTEGRATOR_ALIASES:
            # An old name on the command line: said once on stderr (a DeprecationWarning from
            # inside the scene would be an exception under -W error, and is hidden otherwise).
            integrator = INTEGRATOR_ALIASES[integrator]
            print(f"note: --integrator {args.integrator} is now {integrator} (the old name goes in the next release)", file=sys.stderr)
        kwargs["integrator"] = integrator
    if args.dt is not None:
        kwargs["dt"] = args.dt
    return name, fn, kwargs


def _cmd_view(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``physcore view``: the named scene live in a window (:func:`physcore.viewer.view`)."""
    from ._live import _has_bodies
    from .render import painter
    from .viewer import _import_pygame, view

    name, fn, kwargs = _scene_call(args, parser)
    shot = None
    if args.screenshot is not None:
        try:
            shot = painter.check_path(args.screenshot, "png")
        except (TypeError, ValueError) as e:
            parser.error(f"--screenshot: {e}")
        try:
            painter.check_writable(shot)
        except OSError as e:
            print(f"physcore view: error: cannot write {shot}: {e}", file=sys.stderr)
            return 1
    try:
        pygame = _import_pygame()
    except ImportError as e:
        parser.error(str(e))
    try:
        scene = fn(**kwargs)
    except (TypeError, ValueError, OverflowError) as e:
        parser.error(f"scene {name!r}: {e}")
    if int(scene.n_particles) == 0 and not _has_bodies(scene):
        parser.error(f"scene {name!r} has no particles or rigid bodies; the live viewer shows those (try: physcore render {name})")
    try:
        result = view(scene, name=name, size=args.size, fps=args.fps, view=args.view, seconds=args.seconds,
                      screenshot=shot)
    except (TypeError, ValueError) as e:
        parser.error(str(e))
    except OSError as e:
        print(f"physcore view: error: cannot write the screenshot: {e}", file=sys.stderr)
        return 1
    except pygame.error as e:
        print(f"physcore view: error: cannot open a window ({e}); set DISPLAY, or run under xvfb-run", file=sys.stderr)
        return 1
    print(f"  ticks:          {result.ticks} ({result.draws} frames drawn in {result.wall:.1f} s)")
    print(f"  simulated time: {result.scene.time:.4g} s")
    return 0


def _as_option(message: str, parser: argparse.ArgumentParser) -> str:
    """A render function's message naming its keyword (``cmap must be one of ...``, ``trail:
    ...``) as the command line's option (``--cmap: must be one of ...``), where it has one."""
    m = re.match(r"^([a-z_]+)(?::\s*| (?=must ))(.*)$", message, re.S)
    if m:
        option = "--" + m.group(1).replace("_", "-")
        if option in parser._option_string_actions:
            return f"{option}: {m.group(2)}"
    return message


def _stepper(scene: Any) -> str:
    """What steps the scene, for the summary: its integrator, or for a scene of grids alone (no
    particles: Gray–Scott, waves, flows) their own schemes, which the integrator does not touch."""
    if int(getattr(scene, "n_particles", 0)) == 0 and getattr(scene, "grids", ()):
        return "the grids' own schemes"
    return str(getattr(scene, "integrator", "?"))


def _cmd_render(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from . import render
    from ._errors import ContactStepWarning, EnergyBooksWarning, SimulationDiverged, StabilityWarning
    from .render import painter
    from .render.painter import wants_velocities

    name, fn, kwargs = _scene_call(args, parser)
    out = Path(args.output if args.output is not None else f"{name}.gif")
    # Everything that can be checked without the scene is, before it is built (seconds for big
    # fluids) and simulated (minutes): the frames buffer's memory, the output paths.
    try:
        _check_frames_memory(fn, args)
        fmt = render.FORMATS.get(out.suffix.lower())
        if fmt is None:
            raise _UsageError(f"-o: the output's extension picks the format, one of {', '.join(render.FORMATS)}; got {str(out)!r}")
        try:
            painter.check_path(out, fmt)
        except (TypeError, ValueError) as e:  # named as the user typed it, not as `path`
            raise _UsageError(f"-o: {re.sub(r'^path: ', '', str(e))}") from None
        if args.energy_plot is not None:  # a usage error (exit 2) like -o's, before building the scene
            try:
                painter.check_path(Path(args.energy_plot), "png")
            except (TypeError, ValueError) as e:
                raise _UsageError(f"--energy-plot: {e}") from None
        if fmt in ("mp4", "webm"):
            try:
                import av  # noqa: F401 - fail before simulating, not after
            except ImportError:
                raise _UsageError(f'-o {out.name}: MP4 and WebM output need PyAV: pip install "physcore[video]"') from None
        if fmt in ("glb", "gltf", "html"):
            try:
                import pygltflib  # noqa: F401 - fail before simulating, not after
            except ImportError:
                raise _UsageError(f'-o {out.name}: glTF and HTML output need pygltflib: pip install "physcore[web]"') from None
    except _UsageError as e:
        parser.error(str(e))
    except (TypeError, ValueError) as e:
        parser.error(str(e))
    for target_path in [out] + ([Path(args.energy_plot)] if args.energy_plot is not None else []):
        try:
            painter.check_writable(target_path)
        except OSError as e:
            reason = os.strerror(e.errno) if e.errno else str(e)
            print(f"physcore render: error: cannot write {target_path}: {reason}", file=sys.stderr)
            return 1

    t0 = time.perf_counter()
    try:
        scene = fn(**kwargs)
    except (TypeError, ValueError, OverflowError) as e:
        # OverflowError: an argument beyond float64 that a scene function did not name itself.
        parser.error(f"scene {name!r}: {e}")
    if args.rtol is not None or args.atol is not None:
        if scene.integrator != "dopri5":
            parser.error("--rtol/--atol apply to the adaptive integrator: add --integrator dopri5")
        try:
            if args.rtol is not None:
                scene.rtol = args.rtol
            if args.atol is not None:
                scene.atol = args.atol
        except ValueError as e:
            parser.error(str(e))
    try:
        settings = _render_settings(fn, args, scene.dt, scene)
        _check_frames_memory(fn, args, scene)
        if args.view is not None and int(getattr(scene, "dim", 0)) == 2:  # before simulating
            parser.error("--view: a 2D scene is drawn in its plane; --view AZ,EL turns 3D scenes only")
        if "camera" in settings:  # before simulating: orbit needs 3D, follow:I a particle I
            from .render.painter import check_camera, points_view

            check_camera(settings["camera"], int(getattr(scene, "dim", 0)), int(getattr(points_view(scene), "n_particles", 0)))
        if "cmap" in settings or "background" in settings:  # before simulating
            from .render.painter import check_background, check_cmap

            check_cmap(settings.get("cmap"))
            check_background(settings.get("background"))
        if "texture" in settings:  # before simulating: the image must load onto a mesh with uv
            from .render.painter import check_mesh, check_texture

            mesh = settings.get("mesh", (getattr(scene, "render_defaults", None) or {}).get("mesh"))
            check_texture(settings["texture"], check_mesh(mesh, int(getattr(scene, "n_particles", 0))))
    except _UsageError as e:
        parser.error(str(e))
    except (TypeError, ValueError) as e:
        parser.error(_as_option(str(e), parser))
    time0 = scene.time
    counts: list[Any] = []  # substeps taken per frame (frame_time with automatic substeps)
    recorder = None
    if args.energy_plot is not None:
        if not str(args.energy_plot).lower().endswith(".png"):
            parser.error(f"--energy-plot: must end in .png, got {args.energy_plot!r}")
        try:
            import matplotlib  # noqa: F401 - fail before simulating, not after
        except ImportError:
            parser.error('--energy-plot needs matplotlib: pip install "physcore[plot]"')
        from .diagnostics import EnergyRecorder

        recorder = EnergyRecorder()
        recorder.record(scene)

    def on_frame(k: int, scene: Any, substeps: Any) -> None:  # observers, not proxies
        if k and substeps is not None:
            counts.append(substeps)
        if k and recorder is not None:
            recorder.record(scene)

    produce = ("frames", "steps_per_frame", "frame_time", "substeps", "color_by")
    try:
        ours = (EnergyBooksWarning, StabilityWarning, ContactStepWarning)
        with warnings.catch_warnings(record=True) as caught:
            for category in ours:
                warnings.simplefilter("always", category)
            recording = render.record(
                scene,
                springs=not args.no_springs,
                progress=not args.quiet,
                on_frame=on_frame,
                # Arrows, swept areas and curved trail pieces (pythagorean's) draw from them.
                velocities=wants_velocities(settings.get("arrows"), _defaults(fn, scene).get("look"), settings.get("trail")),
                **{k: v for k, v in settings.items() if k in produce},
            )
        for w in caught:  # ours said as the command's own; others as Python would have
            if issubclass(w.category, ours):
                print(f"physcore render: warning: {w.message}", file=sys.stderr)
            else:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        if fmt in ("glb", "gltf", "html"):  # the motion, not pixels: only what a player uses
            web = {k: settings[k] for k in ("fps", "theme", "view") if k in settings}
            if settings.get("mesh") is False:
                web["mesh"] = False
            if fmt == "html":
                web["title"] = settings.get("title") or name
            written = render.save(recording, out, **web)
        else:
            written = render.save(
                recording,
                out,
                springs=not args.no_springs,
                colorbar=not args.no_colorbar,
                **{k: v for k, v in settings.items() if k not in produce or k == "color_by"},
            )
    except SimulationDiverged as e:
        msg = f"physcore render: error: {e}"  # the message says "simulation diverged at step ..."
        dt_hint = getattr(e, "suggested_dt", float("nan"))
        if getattr(scene, "integrator", None) == "euler":
            msg += "\n  try --integrator verlet (a smaller --dt does not make explicit Euler stable)"
        elif dt_hint == dt_hint and dt_hint > 0 and "frame_time" in settings:  # not NaN; frame_time set
            k = max(1, math.ceil(settings["frame_time"] / dt_hint))
            if "substeps" in settings:  # fixed by --substeps N: the user's own count was too few
                msg += (
                    f"\n  {settings['substeps']} substeps of {settings['frame_time'] / settings['substeps']:.3g} s "
                    f"a frame are too long; try --substeps {k} (steps of {dt_hint:.3g} s)"
                )
            else:
                msg += (
                    f"\n  the automatic substeps were too long; try fixed ones, e.g. "
                    f"--dt {dt_hint:.3g} --steps-per-frame {k}"
                )
        elif dt_hint == dt_hint and dt_hint > 0:  # not NaN
            msg += f"\n  try a smaller time step, e.g. --dt {dt_hint:.3g} (now {scene.dt:.3g} s)"
        print(msg + f"\n  no file written ({out})", file=sys.stderr)
        return 1
    except (TypeError, ValueError) as e:
        parser.error(_as_option(str(e), parser))
    except OSError as e:
        print(f"physcore render: error: cannot write {out}: {e}", file=sys.stderr)
        return 1
    wall = time.perf_counter() - t0

    if recorder is not None:
        try:
            recorder.plot(args.energy_plot, title=f"{name}: energy books")
        except OSError as e:
            print(f"physcore render: error: cannot write {args.energy_plot}: {e}", file=sys.stderr)
            return 1
    frames, fps, (w, h) = settings["frames"], settings["fps"], settings["size"]
    drift = scene.energy_drift()
    paths = written if isinstance(written, list) else [written]
    path = paths[0]
    print(f"wrote {path}" if len(paths) == 1 else f"wrote {len(paths)} frames, {paths[0]} … {paths[-1].name}")
    if recorder is not None:
        print(f"wrote {args.energy_plot} (energy books at {len(recorder)} frames)")
    pixels = "" if fmt in ("glb", "gltf", "html") else f", {w}x{h} px"
    played = ""
    if fmt == "gif":
        # A GIF's delays are whole centiseconds from 2 to 65535: say what it plays at.
        gif_fps = 100.0 / min(max(100.0 / fps, 2.0), 65535.0)
        if abs(gif_fps / fps - 1.0) > 0.01:
            played = f"; a GIF's frame delays are 0.02 to 655.35 s, so it plays at {gif_fps:.4g} fps"
    print(f"  frames:         {frames} at {fps:g} fps ({frames / fps:.2f} s){pixels}{played}")
    print(f"  file size:      {_human_bytes(sum(p.stat().st_size for p in paths))}")
    lead = float((getattr(scene, "render_defaults", None) or {}).get("lead_in", 0.0) or 0.0)
    lead_text = f"a lead-in of {lead:.4g} s before the first frame, then " if lead > 0 else ""
    if "frame_time" in settings:
        print(
            f"  simulated time: {scene.time - time0:.4g} s ({lead_text}{frames - 1} interval{'s' if frames != 2 else ''} of "
            f"{settings['frame_time']:.4g} s between frames, {_stepper(scene)})"
        )
        if "substeps" in settings:
            print(f"  substeps:       {settings['substeps']} per frame (fixed by --substeps)")
        else:
            print(f"  substeps:       {_substeps_text(counts)}")
    else:
        steps = (frames - 1) * settings["steps_per_frame"]
        print(
            f"  simulated time: {scene.time - time0:.4g} s ({lead_text}{steps} steps of dt = {scene.dt:.4g} s, "
            f"{settings['steps_per_frame']} per frame, {_stepper(scene)})"
        )
    stats = getattr(scene, "integrator_stats", None)
    if stats and "cg_solves" in stats:
        print(
            f"  implicit_euler: {stats['cg_iterations']} CG iterations in {stats['cg_solves']} solves "
            f"(at most {stats['cg_max_iterations']}), {stats['cg_unconverged']} stopped unconverged at "
            f"cg_max_iter {scene.cg_max_iter} (cg_tol {scene.cg_tol:g}); the energy drift below is "
            "mostly the method's numerical damping"
        )
    elif stats:
        print(
            f"  dopri5:         {stats['accepted']} internal steps accepted, {stats['rejected']} rejected "
            f"(rtol {scene.rtol:g}, atol {scene.atol:g})"
        )
    print(f"  energy drift:   {drift:+.1e} (relative)")
    print(f"  wall time:      {wall:.2f} s")
    return 0


# --------------------------------------------------------------------------- parser
def _build_parser() -> tuple[argparse.ArgumentParser, argparse.ArgumentParser]:
    """The top-level parser and the ``render`` subparser (whose .error() reports usage errors)."""
    from . import render

    try:
        from .scene import INTEGRATOR_ALIASES, INTEGRATORS

        integrators: list[str] | None = [d["name"] for d in INTEGRATORS]
        # Old names stay valid choices this release (the Scene warns); the help lists the new ones.
        accepted: list[str] | None = [*integrators, *INTEGRATOR_ALIASES]
    except Exception:  # noqa: BLE001 - the extension failed to load: let the scene call report it
        integrators = accepted = None
    try:
        from importlib.metadata import version

        ver = version("physcore")
    except Exception:  # noqa: BLE001 - any failure means the same here
        ver = "unknown"

    parser = _Parser(
        prog="physcore",
        description="physcore: fast, honest particle physics. Render ready-made scenes to GIFs.",
    )
    parser.add_argument("--version", action="version", version=f"physcore {ver}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    sc = sub.add_parser("scenes", help="list the ready-made scenes and their parameters",
                        description="List the ready-made scenes, their one-line descriptions and parameters; "
                        "given a NAME, that scene's whole description.")
    sc.add_argument("scene", metavar="NAME", nargs="?", help="one scene to describe in full")
    sub.add_parser("info", help="show the version, CPU, SIMD level, threads and GPU adapters",
                   description="Show physcore's version and build, the CPU, the SIMD level the kernels run at "
                   "(set PHYSCORE_SIMD=scalar|avx2|avx512|neon|auto to force one) and the levels this CPU has, "
                   "the default thread count, and the GPU adapters (Scene(device='gpu'|'gpu:NAME')).")

    r = sub.add_parser(
        "render",
        help="simulate a scene and write a GIF, a video, PNG frames or a 3D player",
        description="Simulate a ready-made scene and write it as an animated GIF (the default), an MP4 or "
        "WebM video, PNG frames, glTF or an HTML 3D player: the extension of -o picks. Animation "
        "defaults come from the scene (see `physcore scenes`).",
    )
    r.add_argument("scene", metavar="SCENE", help="scene name (see `physcore scenes`)")
    r.add_argument("-o", "--output", metavar="OUT.gif", help="output file (default: SCENE.gif); the extension picks the "
                   "format: .gif, .mp4 (H.264) or .webm (VP9; both need the video extra), .png (one file per frame), "
                   ".glb or .gltf (glTF 2.0) or .html (a 3D player; both need the web extra)")
    r.add_argument("--frames", type=_positive_int, metavar="N", help="number of frames")
    r.add_argument("--fps", type=_positive_float, metavar="F", help="frames per second of playback")
    r.add_argument("--size", type=_size, metavar="WxH", help="image size in pixels, e.g. 480x360")
    stepping = r.add_mutually_exclusive_group()
    stepping.add_argument("--steps-per-frame", type=_positive_int, metavar="K",
                          help="simulation steps of dt between frames (default: the scene's simulated time "
                          "per frame; also turns off a scene's automatic substeps)")
    stepping.add_argument("--frame-time", type=_positive_float, metavar="SECONDS",
                          help="simulated seconds between frames (default: the scene's); scenes with automatic "
                          "substeps (fluids) pick their own, others take round(SECONDS/dt) steps of dt")
    r.add_argument("--substeps", type=_substeps_arg, metavar="auto|N",
                   help="with the frame time: 'auto' picks each frame's substeps inside the integrator's "
                   "stability region (and reports them), N fixes them")
    r.add_argument("--integrator", choices=accepted, metavar="NAME",
                   help="integrator" + (f" ({', '.join(integrators)}; rk45 is the old name of dopri5)"
                                        if integrators else ""))
    r.add_argument("--dt", type=_positive_float, metavar="DT", help="time step in s (default: the scene's)")
    r.add_argument("--rtol", type=_positive_float, metavar="R", help="relative tolerance of --integrator dopri5 (default 1e-6)")
    r.add_argument("--atol", type=float, metavar="A", help="absolute tolerance of --integrator dopri5 (default 1e-9)")
    r.add_argument("--color-by", choices=render.COLOR_BY,
                   help="particle colouring (default: the scene's, else speed)")
    r.add_argument("--no-colorbar", action="store_true", help="do not draw the colour bar")
    r.add_argument(
        "--energy-plot",
        metavar="PNG",
        help="also write a plot of the energy books over time (kinetic, potential by term, "
        "dissipated, total, relative drift), sampled every frame; needs matplotlib",
    )
    r.add_argument("--radius", type=_int_in(0, 200), metavar="PX", help="particle radius in pixels, 0-200 (default: automatic)")
    r.add_argument("--view", type=_view, metavar="AZ,EL", help="3D camera azimuth,elevation in degrees")
    r.add_argument("--theme", choices=("light", "dark"), help="colours of particle animations (default: the scene's)")
    r.add_argument("--title", metavar="TEXT", help="a caption in the top-left corner of particle animations")
    r.add_argument("--cmap", metavar="NAME",
                   help="colour map of speed and pressure: viridis, plasma, magma, inferno, cividis, turbo or ice")
    r.add_argument("--background", metavar="#RRGGBB", help="background colour of particle animations (default: the theme's)")
    r.add_argument("--camera", type=_camera_arg, metavar="MODE",
                   help="fit (still, the default), follow (the moving particles' centre of mass; follow:I "
                   "particle I), zoom (follow, widening as the motion spreads; the scale bar shows each frame's "
                   "scale), orbit (3D: one turn over the animation; orbit:D at D degrees a second)")
    r.add_argument("--arrows", choices=("none", "velocity", "acceleration"),
                   help="arrows on up to 300 moving particles (default: the scene's, else none)")
    r.add_argument("--no-springs", action="store_true", help="do not draw springs")
    r.add_argument("--no-mesh", action="store_true",
                   help="draw a cloth's particles and springs rather than its shaded surface")
    r.add_argument("--antialias", action=argparse.BooleanOptionalAction, default=None,
                   help="soft-edged discs (default: the scene's; the ready-made particle scenes have them)")
    r.add_argument("--texture", metavar="IMAGE",
                   help="an image (PNG, JPEG, ...) mapped onto the scene's shaded surface (cloth)")
    r.add_argument("--trail", type=_int_in(0), metavar="N",
                   help="draw each particle's path over the last N frames, fading (0: none; default: the scene's)")
    r.add_argument("--param", type=_key_value, action="append", metavar="KEY=VALUE",
                   help="scene parameter, repeatable (e.g. --param n=48 --param ground=true)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")

    from .viewer import keys_text

    v = sub.add_parser(
        "view",
        help="run a scene live in a window: drag particles, change parameters",
        description="Run a ready-made scene live in a window (needs pygame-ce: pip install \"physcore[view]\"),\n"
        "stepped as `physcore render` steps it and drawn as its GIF, at the GIF's speed.",
        epilog="keys:\n" + keys_text(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    v.set_defaults(view_parser=v)
    v.add_argument("scene", metavar="SCENE", help="scene name (see `physcore scenes`)")
    v.add_argument("--param", type=_key_value, action="append", metavar="KEY=VALUE",
                   help="scene parameter, repeatable (e.g. --param n=24)")
    v.add_argument("--integrator", choices=accepted, metavar="NAME", help="integrator" + (f" ({', '.join(integrators)})" if integrators else ""))
    v.add_argument("--dt", type=_positive_float, metavar="DT", help="time step in s (default: the scene's)")
    v.add_argument("--size", type=_size, metavar="WxH", help="window size in pixels (default: the scene's GIF size)")
    v.add_argument("--fps", type=_positive_float, metavar="F",
                   help="ticks (GIF frames) per second of wall time (default: the scene's fps: the GIF's speed)")
    v.add_argument("--view", type=_view, metavar="AZ,EL", help="3D camera azimuth,elevation in degrees")
    v.add_argument("--seconds", type=_positive_float, metavar="S", help="close after S seconds of wall time")
    v.add_argument("--screenshot", metavar="PNG", help="write the last frame as a PNG when the window closes")
    return parser, r


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``physcore`` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit code: 0 success, 1 simulation diverged or write failure, 2 usage error or out of
        memory, 130 interrupted (Ctrl-C).
    """
    parser, render_parser = _build_parser()
    try:
        args = parser.parse_args(None if argv is None else list(argv))
        if args.command == "scenes":
            return _cmd_scenes(args, parser)
        if args.command == "info":
            return _cmd_info()
        if args.command == "view":
            return _cmd_view(args, args.view_parser)
        return _cmd_render(args, render_parser)
    except SystemExit as e:  # argparse errors (2) and --help/--version (0)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except KeyboardInterrupt:
        print("physcore: interrupted", file=sys.stderr)
        return 130
    except MemoryError as e:  # pc.OutOfMemoryError names what needed how much; numpy's may not
        print(f"physcore: error: out of memory: {e or 'an allocation failed'}; nothing was written", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `physcore scenes | head`: the reader left; say nothing more
        # Python's documented recipe: point stdout at devnull so the exit flush cannot fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
