"""Sphinx configuration of physcore's documentation site (issue 47).

Build (offline, warnings as errors), from the repository root::

    pip install ".[docs]" && python -m sphinx -W --keep-going -b html docs docs/_build/html

The pages are the Markdown of ``docs/`` as they are (MyST), the API from the docstrings
(autodoc + autosummary, numpydoc sections), and the gallery, one page per ready-made scene,
written at build time by ``docs/_ext/physcore_gallery.py`` into ``docs/gallery_pages/``, with
the examples of ``examples/`` run by sphinx-gallery into ``docs/gallery_pages/examples/``.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# This checkout's package when it holds the compiled core (an in-place build: `pip install -e .`,
# `maturin develop`), else the installed one (`pip install ".[docs]"` from this checkout): the
# source tree without its `_core` cannot be imported. Then the gallery extension.
if any(p.suffix in (".so", ".pyd") for p in (ROOT / "python" / "physcore").glob("_core*")):
    sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(DOCS / "_ext"))

import physcore  # noqa: E402

project = "physcore"
author = "physcore contributors"
copyright = "physcore contributors, MIT licence"
release = physcore.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "myst_parser",  # docs/*.md and docs/guide/*.md, included as they are
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",  # the docstrings' Parameters / Returns / Raises / Examples sections
    # Before physcore_gallery: both write pages on builder-inited, and the gallery index lists
    # the examples' index when it exists.
    "sphinx_gallery.gen_gallery",  # docs/gallery_pages/examples/: examples/plot_*.py, executed
    "physcore_gallery",  # docs/gallery_pages/: one page per scene of physcore.scenes.REGISTRY
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "Thumbs.db",
    ".DS_Store",
]
templates_path = ["_templates"]

# --- MyST: the Markdown pages as they are -------------------------------------------------------
# GitHub's heading anchors (`file.md#some-heading`), which the guide's links use throughout.
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence", "html_image"]

# --- API: autodoc, autosummary, numpydoc --------------------------------------------------------
autosummary_generate = True  # docs/api/generated/, one page per public name (not committed)
autosummary_imported_members = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"  # the signature shows them; numpydoc's sections say the rest
autodoc_preserve_defaults = True  # `dt=None`, `1 / 30` as written, not as evaluated
numpydoc_show_class_members = False  # autosummary's class template lists the members
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False  # types like "(N, dim) float64" are prose, not references
numpydoc_validation_checks: set[str] = set()

# --- Examples: sphinx-gallery -------------------------------------------------------------------
# examples/plot_*.py run at build time, each in a few seconds (small frames and sizes, which
# each example says); their GIFs and videos are collected by docs/_ext/physcore_scraper.py,
# their matplotlib figures by sphinx-gallery's own scraper. An example that fails fails the
# build. An unchanged example is not run again (sphinx-gallery keeps an MD5 of each) unless
# PHYSCORE_DOCS_RERUN=1 (as tests/scenes/test_docs_site.py sets): physcore itself may have changed.
sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "gallery_pages/examples",  # where physcore_gallery looks for them
    "filename_pattern": r"/plot_",  # run every plot_*.py
    "image_scrapers": ("matplotlib", "physcore_scraper.scraper"),
    "abort_on_example_error": True,
    "run_stale_examples": os.environ.get("PHYSCORE_DOCS_RERUN", "") not in ("", "0"),
    # `sphinx-build -j N` runs the examples on N processes too (needs joblib); serial otherwise.
    "parallel": True,
    "within_subsection_order": "physcore_scraper.example_order",
    "download_all_examples": False,  # each page keeps its .py / .ipynb download; no zip of all, no Binder
    "binder": {},
    "jupyterlite": {},
    "show_signature": False,
    "show_memory": False,
    "remove_config_comments": True,
    "write_computation_times": False,  # no sg_execution_times page written into docs/
    "min_reported_time": 0,
}

# --- HTML ---------------------------------------------------------------------------------------
# Furo rather than pydata-sphinx-theme: physcore's site is mostly long-form prose (19 guide
# chapters, reference notes) with one API section, which furo's single left sidebar and
# readable line length suit; it needs no JavaScript bundle or network at build time, adds one
# small dependency, and builds faster than pydata's on the 2-core machine. pydata's top-level
# tabs fit a site of several equal sections (numpy, pandas), which this is not (yet).
html_theme = "furo"
html_title = f"physcore {release}"
html_static_path = ["_static"]
# A tab icon (a frame of the galaxies scene): without one, browsers ask for /favicon.ico and log a 404.
html_favicon = "_static/favicon.png"
html_show_sourcelink = False
html_copy_source = False

# -W turns every warning into an error; none is silenced.


# --- Build-time hooks ---------------------------------------------------------------------------
def _site_links(app, docname, source):
    """The guide's chapters link back to the README's contents (``../../README.md#the-guide``),
    which is not a page of the site (it lies outside docs/): on the site that link leads to the
    front page, which holds the guide's contents, instead. The files are unchanged."""
    if docname.startswith("guide/"):
        source[0] = source[0].replace("](../../README.md#the-guide)", "](../index.md)")


def _data_docs(app, what, name, obj, options, lines):
    """Module-level data re-exported from a private module (``physcore.render.COLOR_BY`` from
    ``render._checks``) has its ``#:`` comment where it is defined, which autodoc does not read;
    it would show the docstring of the value's type (tuple, float, ndarray) instead. Use the
    defining module's ``#:`` comment, or nothing."""
    if what != "data" or not lines:
        return
    from sphinx.pycode import ModuleAnalyzer

    value_doc = getattr(obj, "__doc__", None) or ""  # an instance's is its type's
    first = next((line.strip() for line in lines if line.strip()), "")
    if not first or first not in value_doc:
        return  # the data's own comment
    attr = name.rsplit(".", 1)[1]
    found: list[str] = []
    for modname, module in sorted(sys.modules.items()):
        if modname.startswith("physcore") and getattr(module, attr, None) is obj:
            try:
                docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
            except Exception:  # noqa: BLE001 - a module without source: no comment there
                continue
            if ("", attr) in docs:
                found = list(docs[("", attr)])
                break
    lines[:] = found


def _collapsed_navigation(app, pagename, templatename, context, doctree):
    """Furo draws the whole site's toctree, every branch open, into each page's sidebar and
    parses it again per page: with the API's ~200 generated pages that was about 40 % of the
    build (a known furo cost: pradyunsg/furo#674, #748). The sidebar here shows the branch
    that leads to the page and the top-level entries (``collapse=True``, as the Read the Docs
    theme does); the other branches are a click away, on their own pages. Runs before furo's
    handler (priority 400 < 500), which calls ``context["toctree"]``."""
    toctree = context.get("toctree")
    if toctree is None:
        return

    def collapsed(**kwargs):
        kwargs["collapse"] = True
        return toctree(**kwargs)

    context["toctree"] = collapsed


def setup(app):
    app.connect("source-read", _site_links)
    app.connect("autodoc-process-docstring", _data_docs, priority=400)
    app.connect("html-page-context", _collapsed_navigation, priority=400)
