"""The gallery of physcore's documentation site: one page per ready-made scene, written at build time.

On ``builder-inited`` (before Sphinx reads any source) this writes, into ``docs/gallery_pages/``:

- ``<name>.rst`` for every scene of :data:`physcore.scenes.REGISTRY`: its thumbnail
  (``docs/gallery/<name>.gif``, which Sphinx copies into the build's ``_images/``), the one command
  that renders it, the Python that makes the same GIF, its parameters (the function's signature,
  with the descriptions of a numpydoc ``Parameters`` section where it has one), the animation
  defaults of the command (``render_defaults``) and the rest of its docstring;
- ``index.rst``: the grid of thumbnails, in the README's order, linking to those pages.

A file is rewritten only when its text changes, so an unchanged scene does not make Sphinx read
its page again; pages of scenes no longer in the registry are removed. The folder is generated
(ignored by git): edit this file or the scene's docstring, never a page.

Every 3D scene's page also embeds its HTML player (issue 67: :func:`physcore.render.html`,
three.js; drag to turn): an ``<iframe>`` of ``_players/<name>.html``, which ``build-finished``
writes into the build (not into ``docs/``) by recording the scene when it builds the site, with
the player's scripts once in ``_players/`` for all of them (:data:`PLAYER_BUDGET` says how big a
page may be, :data:`PLAYER_PARAMS` what a page changes of a scene). A player already in the
build folder is kept unless ``PHYSCORE_DOCS_RERUN=1`` (as for the examples).

The executed examples (issue 47, item 2): sphinx-gallery runs ``examples/plot_*.py`` into
``gallery_pages/examples/`` (``sphinx_gallery_conf["gallery_dirs"]`` in docs/conf.py, connected
before this extension so that its pages exist when these are written); when that folder's
``index.rst`` exists, the gallery index below links it and lists it in its toctree, and each
scene page links to ``examples/plot_<name>`` when that page exists. Nothing here executes a scene.
"""
from __future__ import annotations

import inspect
import math
import os
import re
import textwrap
import time
from pathlib import Path

from numpydoc.docscrape_sphinx import SphinxFunctionDoc

OUT = "gallery_pages"  # relative to the source folder (docs/)
THUMBS = "gallery"  # docs/gallery/<name>.gif
PLAYERS = "_players"  # <build>/_players/<name>.html and the scripts they share
#: Most bytes of a player's recording (its glTF; the page holds 4/3 of it, base64): a scene
#: whose recording at its defaults would be larger keeps every k-th frame (the same simulated
#: time; the player interpolates between frames).
PLAYER_BUDGET = 2_000_000
#: What a scene's player changes of its parameters, and why (said on its page).
PLAYER_PARAMS = {"galaxies": ({"n": 2000}, "2 000 stars of the GIF's 10 000, to stay small")}


def is_3d(fn) -> bool:
    """Whether a scene function builds a 3D scene (one with a 3D camera ``view`` in its
    defaults, built to be sure: 2D scenes are not built)."""
    if "view" not in (getattr(fn, "render_defaults", {}) or {}):
        return False
    return int(getattr(fn(**PLAYER_PARAMS.get(fn.__name__, ({}, ""))[0]), "dim", 0)) == 3


def scene_order(registry: dict, readme: Path) -> list[str]:
    """The scenes in the README gallery's order, then any the README does not show."""
    shown = re.findall(r'src="docs/gallery/(\w+)\.gif"', readme.read_text()) if readme.exists() else []
    order = [n for n in dict.fromkeys(shown) if n in registry]
    return order + [n for n in registry if n not in order]


def _rst_cell(text: str) -> str:
    """One line of text for a list-table cell."""
    return " ".join(str(text).split()) or "\\-"


def _literal(value: object, limit: int = 70) -> str:
    text = repr(value)
    if len(text) > limit:
        text = text[: limit - 5] + " ...)"
    return "``" + text.replace("``", "` `") + "``"


def _param_descriptions(doc: SphinxFunctionDoc) -> dict[str, str]:
    out = {}
    for p in doc["Parameters"]:
        for name in p.name.split(","):
            out[name.strip().lstrip("*")] = " ".join(" ".join(p.desc).split())
    return out


def scene_page(name: str, fn, examples: bool = False, player: bool = False) -> str:
    """The reStructuredText of one scene's gallery page."""
    doc = SphinxFunctionDoc(fn, config={"show_class_members": False})
    described = _param_descriptions(doc)
    summary = " ".join(doc["Summary"])
    sig = inspect.signature(fn)
    title = f"``{name}``"
    lines = [
        f".. _gallery-{name}:",
        "",
        title,
        "=" * len(title),
        "",
        ".. currentmodule:: physcore.scenes",
        "",
        f".. image:: ../{THUMBS}/{name}.gif",
        f"   :alt: {name}: {summary}" if summary else f"   :alt: {name}",
        "   :width: 240px",
        "   :class: pc-scene-gif",
        "",
        summary,
        "",
        "The command (``--param key=value`` sets any parameter below; ``physcore render "
        f"{name} --help`` lists the options)::",
        "",
        f"   physcore render {name}",
        "",
        "The same GIF from Python:",
        "",
        ".. code-block:: python",
        "",
        "   import physcore as pc",
        "",
        f'   pc.render.gif(pc.scenes.{name}(), "{name}.gif")',
        "",
    ]
    if player:
        params, why = PLAYER_PARAMS.get(name, ({}, ""))
        args = ", ".join(f"{k}={v!r}" for k, v in params.items())
        lines += [
            "In 3D",
            "-----",
            "",
            "The same motion in a browser (:func:`physcore.render.html`, three.js): drag to turn the "
            "camera, the wheel to zoom, a right drag to pan; play/pause and the time slider below it."
            + (f" This page's recording has {why} (``{name}({args})``)." if why else ""),
            "",
            ".. raw:: html",
            "",
            f'   <iframe class="pc-player" src="../{PLAYERS}/{name}.html" title="{name} in 3D" loading="lazy"></iframe>',
            "",
            "The page on its own (a file that plays offline):",
            "",
            ".. code-block:: python",
            "",
            f'   pc.render.html(pc.scenes.{name}({args}), "{name}.html")',
            "",
        ]
    if examples:
        lines += [f"A runnable example: :doc:`examples/plot_{name}`.", ""]
    # The signature's parameters; their meanings from a numpydoc Parameters section where the
    # docstring has one (otherwise its prose, under "About this scene", describes them).
    meaning = any(p in described for p in sig.parameters)
    lines += ["Parameters", "----------", "",
              f"Each is a keyword of :func:`physcore.scenes.{name}` and a ``--param name=value`` of the command.", "",
              ".. list-table::", "   :header-rows: 1", "   :widths: " + ("15 15 20 50" if meaning else "30 30 40"), "",
              "   * - name", "     - default", "     - type"]
    if meaning:
        lines.append("     - meaning")
    for p in sig.parameters.values():
        default = "(required)" if p.default is inspect.Parameter.empty else _literal(p.default)
        ann = "" if p.annotation is inspect.Parameter.empty else p.annotation
        ann = ann if isinstance(ann, str) else getattr(ann, "__name__", str(ann))
        lines += [f"   * - ``{p.name}``", f"     - {default}", f"     - {_rst_cell(ann)}"]
        if meaning:
            lines.append(f"     - {_rst_cell(described.get(p.name, ''))}")
    lines.append("")
    defaults = getattr(fn, "render_defaults", {}) or {}
    if defaults:
        lines += ["The command's animation defaults", "--------------------------------", "",
                  f"``{name}.render_defaults``: what ``physcore render {name}`` and "
                  f"``pc.render.gif(pc.scenes.{name}(), ...)`` use unless told otherwise "
                  "(``frame_time`` is simulated seconds per frame).", "",
                  ".. list-table::", "   :header-rows: 1", "", "   * - key", "     - value"]
        for key, value in defaults.items():
            lines += [f"   * - ``{key}``", f"     - {_literal(value)}"]
        lines.append("")
    # The docstring itself, as numpydoc renders it, less the summary and the parameters (above).
    doc["Summary"] = []
    doc["Parameters"] = []
    body = str(doc).strip("\n")
    if body.strip():
        lines += ["About this scene", "----------------", "", textwrap.dedent(body), ""]
    return "\n".join(lines)


def index_page(order: list[str], registry: dict, examples: bool = False) -> str:
    lines = [
        ".. _gallery:",
        "",
        "Gallery",
        "=======",
        "",
        f"The {len(order)} ready-made scenes of :mod:`physcore.scenes`. Each is one command, "
        "``physcore render NAME``, rendered with the scene's defaults; the thumbnails are 240 "
        "pixels wide and the command writes the full-size GIF. Click a scene for its command, "
        "its Python, its parameters and its physics. What each costs to render is measured in "
        ":doc:`../gallery` (the gallery's budgets).",
        "",
    ]
    if examples:
        lines += ["Runnable examples, run when this site is built (a scene of your own, a force of your own, "
                  "a video, a parameter sweep, a batch): :doc:`examples/index`.", ""]
    lines += [
        ".. container:: pc-gallery",
        "",
    ]
    for name in order:
        summary = " ".join(SphinxFunctionDoc(registry[name], config={})["Summary"])
        lines += [
            "   .. container:: pc-gallery-item",
            "",
            f"      .. image:: ../{THUMBS}/{name}.gif",
            f"         :alt: {name}",
            "         :width: 240px",
            f"         :target: {name}.html",
            "",
            f"      :doc:`{name} <{name}>`: {summary}",
            "",
        ]
    lines += [".. toctree::", "   :hidden:", "", *(f"   {name}" for name in order)]
    if examples:
        lines.append("   examples/index")
    lines.append("")
    return "\n".join(lines)


def _write(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def write_pages(srcdir: Path) -> list[Path]:
    """Write the gallery's pages under ``srcdir / OUT``; return the paths written or kept."""
    import physcore.scenes

    registry = physcore.scenes.REGISTRY
    out = srcdir / OUT
    out.mkdir(exist_ok=True)
    examples = (out / "examples" / "index.rst").exists()
    order = scene_order(registry, srcdir.parent / "README.md")
    pages = []
    for name in order:
        missing = [p for p in [srcdir / THUMBS / f"{name}.gif"] if not p.exists()]
        if missing:
            raise FileNotFoundError(f"gallery: no thumbnail for scene {name!r}: {missing[0]}")
        has_example = (out / "examples" / f"plot_{name}.rst").exists()
        page = out / f"{name}.rst"
        _write(page, scene_page(name, registry[name], examples=has_example, player=name in players(registry)))
        pages.append(page)
    index = out / "index.rst"
    _write(index, index_page(order, registry, examples=examples))
    pages.append(index)
    for stale in set(out.glob("*.rst")) - set(pages):
        stale.unlink()
    return pages


_PLAYERS_3D: dict[int, list[str]] = {}


def players(registry: dict) -> list[str]:
    """The scenes whose pages embed a player: the 3D ones, in the registry's order."""
    key = id(registry)
    if key not in _PLAYERS_3D:
        _PLAYERS_3D[key] = [name for name, fn in registry.items() if is_3d(fn)]
    return _PLAYERS_3D[key]


def player_options(name: str, fn) -> dict:
    """The recording options of a scene's player: its defaults, every k-th frame kept when a
    frame of the scene's glTF (measured from recordings of 2 and 3 frames) times its frames
    would pass :data:`PLAYER_BUDGET`."""
    from physcore.render._html import player_text

    params = PLAYER_PARAMS.get(name, ({}, ""))[0]
    d = getattr(fn, "render_defaults", {}) or {}
    frames = int(d.get("frames", 90))
    per_frame = (len(player_text(fn(**params), frames=3)) - len(player_text(fn(**params), frames=2))) * 3 / 4
    k = max(1, math.ceil(frames * per_frame / PLAYER_BUDGET))
    if k == 1:
        return {}
    opts = {"frames": (frames - 1) // k + 1, "fps": float(d.get("fps", 30)) / k}
    if "steps_per_frame" in d:
        opts["steps_per_frame"] = int(d["steps_per_frame"]) * k
    else:
        opts["frame_time"] = float(d["frame_time"]) * k
    return opts


def write_players(outdir: Path, registry: dict, rerun: bool = False, log=print) -> list[Path]:
    """Write ``outdir/_players/<name>.html`` for every 3D scene (kept when there unless `rerun`)
    and the scripts they share; return the pages."""
    from physcore.render._html import player_text, write_scripts

    folder = outdir / PLAYERS
    write_scripts(folder)
    pages = []
    for name in players(registry):
        path = folder / f"{name}.html"
        if rerun or not path.exists():
            fn = registry[name]
            t0 = time.perf_counter()
            opts = player_options(name, fn)
            text = player_text(fn(**PLAYER_PARAMS.get(name, ({}, ""))[0]), title=name, scripts_at="", **opts)
            path.write_text(text)
            log(f"physcore gallery: the {name} player, {len(text) / 1e6:.2f} MB ({opts or 'defaults'}), "
                f"{time.perf_counter() - t0:.1f} s")
        pages.append(path)
    return pages


def _builder_inited(app) -> None:
    write_pages(Path(app.srcdir))


def _build_finished(app, exception) -> None:
    if exception is not None or app.builder.format != "html":
        return
    from sphinx.util import logging

    import physcore.scenes

    rerun = os.environ.get("PHYSCORE_DOCS_RERUN", "") not in ("", "0")
    write_players(Path(app.outdir), physcore.scenes.REGISTRY, rerun=rerun, log=logging.getLogger(__name__).info)


def setup(app):
    app.connect("builder-inited", _builder_inited)
    app.connect("build-finished", _build_finished)
    app.add_css_file("gallery.css")
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
