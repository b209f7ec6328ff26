"""The HTML player: :func:`html` writes one self-contained page that plays a recording in WebGL
(three.js r111, vendored under ``_vendor/`` and inlined; the recording as its binary glTF,
base64) with an orbit camera, play/pause and a time slider; nothing is fetched from a network."""
from __future__ import annotations

import base64
import html as _html_escape
import os
from importlib import resources
from pathlib import Path
from typing import Any

from .._errors import refusing_memory
from ._gltf import _check_out, _prepare, glb_bytes, pygltflib_module

#: The vendored scripts, in the order the page loads them (THREE first).
_SCRIPTS = ("_vendor/three.min.js", "_vendor/OrbitControls.min.js", "_vendor/GLTFLoader.min.js", "_player.js")

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="physcore">
<title>{title}</title>
<style>
html, body {{ margin: 0; height: 100%; background: {bg}; color: {fg}; font: 14px system-ui, sans-serif; }}
#physcore-view {{ position: absolute; left: 0; right: 0; top: 0; bottom: 40px; overflow: hidden; }}
#physcore-view canvas {{ display: block; cursor: grab; }}
#physcore-bar {{ position: absolute; left: 0; right: 0; bottom: 0; height: 40px; display: flex; align-items: center; gap: 10px;
  padding: 0 10px; box-sizing: border-box; }}
#physcore-time {{ flex: 1; }}
#physcore-play {{ width: 5em; }}
#physcore-clock {{ font-variant-numeric: tabular-nums; white-space: nowrap; }}
#physcore-title {{ position: absolute; left: 10px; top: 8px; pointer-events: none; }}
#physcore-message {{ display: none; position: absolute; left: 10px; top: 30px; right: 10px; color: #b00; }}
</style>
</head>
<body>
<div id="physcore-view"></div>
<div id="physcore-title">{title}</div>
<div id="physcore-message"></div>
<div id="physcore-bar"><button id="physcore-play" type="button">Pause</button>
<input id="physcore-time" type="range" min="0" max="1" step="any" value="0" aria-label="time">
<span id="physcore-clock"></span></div>
<script id="physcore-glb" type="application/octet-stream">
{glb}
</script>
{scripts}
</body>
</html>
"""


def _script(name: str) -> str:
    text = resources.files(__package__).joinpath(name).read_text(encoding="utf-8")
    if "</script" in text.lower():  # would end the inline script early
        raise RuntimeError(f"physcore: the vendored {name} holds '</script'; it cannot be inlined")
    return f"<script>\n{text}\n</script>"


def page(glb: bytes, title: str, background: tuple[int, int, int], scripts_at: str | None = None) -> str:
    """The player's page around the binary glTF `glb`: its scripts inlined (what :func:`html`
    writes), or, with `scripts_at` (a relative URL prefix such as ``"../_players/"``), loaded
    from the files :func:`write_scripts` put there, so that the pages of one site share a copy
    of three.js (the docs' gallery)."""
    b64 = base64.b64encode(glb).decode("ascii")
    lines = "\n".join(b64[i:i + 120] for i in range(0, len(b64), 120))
    light = sum(background) > 3 * 128
    if scripts_at is None:
        scripts = "\n".join(_script(s) for s in _SCRIPTS)
    else:
        scripts = "\n".join(f'<script src="{_html_escape.escape(scripts_at + Path(s).name)}"></script>' for s in _SCRIPTS)
    return _PAGE.format(title=_html_escape.escape(title), bg="rgb({},{},{})".format(*background),
                        fg="#222" if light else "#ddd", glb=lines, scripts=scripts)


def write_scripts(folder: str | os.PathLike) -> list[Path]:
    """Copy the player's scripts (three.js r111 and its licence, the player) into `folder`, for
    pages written by :func:`page` with ``scripts_at``; return the files written."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name in (*_SCRIPTS, "_vendor/LICENSE-three.js"):
        data = resources.files(__package__).joinpath(name).read_bytes()
        dest = out / Path(name).name
        if not dest.exists() or dest.read_bytes() != data:
            dest.write_bytes(data)
        written.append(dest)
    return written


@refusing_memory("html", "the frames")
def html(
    scene: Any,
    path: str | os.PathLike,
    *,
    frames: int | None = None,
    steps_per_frame: int | None = None,
    frame_time: float | None = None,
    substeps: str | int | None = None,
    fps: float | None = None,
    mesh: Any = None,
    theme: str | None = None,
    view: tuple[float, float] | None = None,
    title: str | None = None,
    progress: bool = False,
) -> Path:
    """Write one self-contained HTML file that plays a scene in a browser, in 3D: WebGL through
    three.js (r111, inlined), an orbit camera (drag to turn, wheel to zoom, right-drag to pan),
    play/pause (button or space bar) and a time slider showing the scene's time.

    The page embeds the recording as the binary glTF :func:`gltf` writes (base64) and every
    script it runs, so it opens from a file, offline, or inside another page (an ``<iframe>``);
    it fills its window. Its size is about 0.65 MB of scripts plus 4/3 of the glTF's.

    Parameters
    ----------
    scene : physcore.Scene or Recording
        As for :func:`gltf`.
    path : str or os.PathLike
        Ends in ``.html`` (or ``.htm``); its directory must exist and be writable (checked
        before simulating). Written atomically.
    frames, steps_per_frame, frame_time, substeps, fps, mesh, theme, view, progress
        As for :func:`gltf` (`view`: the camera's initial azimuth and elevation, degrees).
    title : str, optional
        The page's title and caption (default: the scene's, else "physcore").

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    As :func:`gltf` (`path` must end in .html or .htm).

    Examples
    --------
    >>> import os, tempfile
    >>> import physcore as pc
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = pc.render.html(pc.scenes.cloth_on_ball(n=8), os.path.join(tmp, "cloth.html"), frames=4)
    ...     out.read_text().startswith("<!DOCTYPE html>")
    True
    """
    from .._atomic import atomic_write
    from .._errors import InvalidInputError, InvalidTypeError
    from ._checks import _check_writable, _short

    p = _check_out(path, (".html", ".htm"))
    if title is not None:
        if not isinstance(title, str):
            raise InvalidTypeError(f"title must be a str, got {type(title).__name__}")
        if "\n" in title or len(title) > 200:
            raise InvalidInputError(f"title must be one line of at most 200 characters, got {_short(title)}")
        from .. import _check

        _check.text("title", title)
    text = player_text(scene, frames=frames, steps_per_frame=steps_per_frame, frame_time=frame_time, substeps=substeps,
                       fps=fps, mesh=mesh, theme=theme, view=view, title=title, progress=progress,
                       before_simulating=lambda: _check_writable(p))
    return atomic_write(p, lambda fh: fh.write(text), binary=False)


def player_text(scene: Any, *, frames: Any = None, steps_per_frame: Any = None, frame_time: Any = None,
                substeps: Any = None, fps: Any = None, mesh: Any = None, theme: Any = None, view: Any = None,
                title: str | None = None, progress: bool = False, before_simulating: Any = None,
                scripts_at: str | None = None) -> str:
    """The player page's text for `scene` (options as :func:`html`'s, checked there; `title`
    already checked): what :func:`html` writes, or with `scripts_at` a page whose scripts are
    shared files (:func:`page`)."""
    pygltflib_module()
    rec, opts = _prepare(scene, frames=frames, steps_per_frame=steps_per_frame, frame_time=frame_time, substeps=substeps,
                         fps=fps, mesh=mesh, theme=theme, view=view, progress=progress,
                         before_simulating=before_simulating or (lambda: None))
    glb = glb_bytes(rec, opts["fps"], opts["theme"], opts["view"], opts["mesh"], opts["colors"], opts["defaults"])
    d = opts["defaults"]
    if title is None:
        title = d.get("title") if isinstance(d.get("title"), str) else "physcore"
    from ._palette import _BACKGROUND, theme_palette

    bg = d.get("background")
    bg = tuple(int(v) for v in (theme_palette(opts["theme"])[_BACKGROUND] if bg is None else bg))
    return page(glb, title, bg, scripts_at=scripts_at)
