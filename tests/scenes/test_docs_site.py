"""The documentation site (issue 47): ``docs/`` builds with Sphinx, warnings as errors, into a
temporary folder, with a gallery page per ready-made scene (its GIF copied into the build), the
examples of ``examples/`` run by sphinx-gallery (each page embedding the GIF, video or figure its
run wrote), the user guide in the README's order, and an API page for every public name."""
from __future__ import annotations

import html
import importlib
import inspect
import os
import re
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

import physcore as pc

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
MODULES = ["render", "scenes", "shapes", "testing", "sweeps", "fluids", "grids", "flows", "potentials", "bodies"]
# Each example of examples/ and what its run puts on its page (sphinx-gallery's name for it).
EXAMPLES = {"plot_own_scene": ".gif", "plot_custom_force": ".gif", "plot_video": ".mp4", "plot_sweep": ".png",
            "plot_batch": ".png", "plot_gpu": ".png"}


def _text(page: Path) -> str:
    """A page's text, tags stripped (code blocks are split into highlighted spans)."""
    return html.unescape(re.sub(r"<[^>]+>", "", page.read_text()))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    for module in ("sphinx", "myst_parser", "numpydoc", "furo", "sphinx_gallery", "matplotlib", "pandas", "av"):
        pytest.importorskip(module, reason=f'the docs extra is not installed (pip install ".[docs]"): no {module}')
    out = tmp_path_factory.mktemp("site")
    # The documented command, into a temporary folder: -W makes any warning fail the build.
    # PHYSCORE_DOCS_RERUN=1: every example runs, even one unchanged since the last build in this
    # checkout (sphinx-gallery would keep its old output): this physcore is the one tested.
    result = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(out / "html"),
         "-d", str(out / "doctrees")],
        capture_output=True, text=True, cwd=ROOT, check=False, env={**os.environ, "PHYSCORE_DOCS_RERUN": "1"},
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return out / "html"


@pytest.mark.slow
def test_site_builds_with_the_main_pages(site):
    for page in ["index.html", "gallery_pages/index.html", "gallery_pages/cloth.html", "api/index.html",
                 "api/physcore.html", "api/scenes.html", "api/generated/physcore.Scene.html", "guide/install.html",
                 "naming.html", "reproducibility.html"]:
        assert (site / page).is_file(), page
    assert "Scene.step" in _text(site / "api/generated/physcore.Scene.html")


@pytest.mark.slow
def test_every_scene_has_a_gallery_page_with_its_gif(site):
    index = (site / "gallery_pages" / "index.html").read_text()
    for name, fn in pc.scenes.REGISTRY.items():
        page = site / "gallery_pages" / f"{name}.html"
        assert page.is_file(), name
        source = page.read_text()
        assert f'src="../_images/{name}.gif"' in source, name
        text = _text(page)
        assert f"physcore render {name}" in text, name
        assert f'pc.render.gif(pc.scenes.{name}(), "{name}.gif")' in text, name
        for param in list(inspect.signature(fn).parameters)[:3]:
            assert param in text, (name, param)
        # The GIF is copied into the build, byte for byte.
        gif = site / "_images" / f"{name}.gif"
        assert gif.read_bytes() == (DOCS / "gallery" / f"{name}.gif").read_bytes(), name
        # The index shows its thumbnail and links to its page.
        assert f'href="{name}.html"' in index and f'src="../_images/{name}.gif"' in index, name


#: The 3D scenes of the gallery, whose pages embed an HTML player (issue 67).
PLAYERS = ["cloth", "galaxies", "lorenz", "xpbd_cloth", "cloth_on_ball", "tablecloth"]


@pytest.mark.slow
def test_every_3d_scene_page_embeds_its_player(site):
    """A 3D scene's page holds an <iframe> of its player, built into _players/ with the scripts
    the players share (three.js and its licence once); each page under 3 MB; 2D pages have none."""
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import physcore_gallery
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    assert physcore_gallery.players(pc.scenes.REGISTRY) == PLAYERS
    for name in pc.scenes.REGISTRY:
        source = (site / "gallery_pages" / f"{name}.html").read_text()
        embedded = f'src="../_players/{name}.html"' in source
        assert embedded == (name in PLAYERS), name
    for script in ("three.min.js", "OrbitControls.min.js", "GLTFLoader.min.js", "_player.js", "LICENSE-three.js"):
        assert (site / "_players" / script).stat().st_size > 0, script
    assert "MIT" in (site / "_players" / "LICENSE-three.js").read_text()
    for name in PLAYERS:
        player = site / "_players" / f"{name}.html"
        text = player.read_text()
        assert '<script src="three.min.js"></script>' in text and 'id="physcore-glb"' in text, name
        assert player.stat().st_size < 3_000_000, (name, player.stat().st_size)


@pytest.mark.slow
def test_every_example_runs_into_its_page(site):
    """Each examples/plot_*.py has a page (linked from the examples' index, which the gallery's
    index links) showing its code and embedding what its run wrote: the GIF as an <img>, the MP4
    as a <video>, a matplotlib figure as a PNG, each copied into the build's _images/; the
    sweep's table is on its page; nothing is left behind in examples/."""
    assert sorted(p.stem for p in (ROOT / "examples").glob("plot_*.py")) == sorted(EXAMPLES)
    assert 'href="examples/index.html"' in (site / "gallery_pages" / "index.html").read_text()
    index = (site / "gallery_pages" / "examples" / "index.html").read_text()
    signature = {".gif": b"GIF89a", ".mp4": b"ftyp", ".png": b"\x89PNG"}
    for name, ext in EXAMPLES.items():
        assert f'href="{name}.html"' in index, name
        source = (site / "gallery_pages" / "examples" / f"{name}.html").read_text()
        image = f"sphx_glr_{name}_001{ext}"
        tag = "video" if ext == ".mp4" else "img"
        assert re.search(rf'<{tag}\b[^>]*\bsrc="../../_images/{re.escape(image)}"', source), (name, tag, image)
        built = (site / "_images" / image).read_bytes()
        assert signature[ext] in built[:16], (name, built[:16])
        assert built == (DOCS / "gallery_pages" / "examples" / "images" / image).read_bytes(), name
        code = (ROOT / "examples" / f"{name}.py").read_text()
        assert "import physcore as pc" in code and "import physcore as pc" in _text(site / "gallery_pages" / "examples" / f"{name}.html")
    assert "yoshida4" in _text(site / "gallery_pages" / "examples" / "plot_sweep.html")  # the printed table
    left = [p.name for p in (ROOT / "examples").iterdir() if p.suffix in (".gif", ".mp4", ".webm")]
    assert not left, left


def _inventory(site: Path) -> set[str]:
    """The Python objects the site documents (from its objects.inv)."""
    data = (site / "objects.inv").read_bytes()
    body = zlib.decompress(data.split(b"\n", 4)[4]).decode()
    return {line.split(" ", 1)[0] for line in body.splitlines() if re.match(r"^\S+ py:", line)}


@pytest.mark.slow
def test_every_public_name_has_an_api_entry(site):
    documented = _inventory(site)
    missing = [f"physcore.{n}" for n in pc.__all__ if f"physcore.{n}" not in documented]
    for modname in MODULES:
        module = importlib.import_module(f"physcore.{modname}")
        assert f"physcore.{modname}" in documented, modname
        for n in module.__all__:
            obj = getattr(module, n)
            # Documented under its module, or once where physcore or physcore.shapes re-exports it.
            homes = {f"physcore.{modname}.{n}"}
            if getattr(pc, n, None) is obj:
                homes.add(f"physcore.{n}")
            if getattr(pc.shapes, n, None) is obj:
                homes.add(f"physcore.shapes.{n}")
            if not homes & documented:
                missing.append(f"physcore.{modname}.{n}")
    assert not missing, missing


def _toctree(text: str, caption: str) -> list[str]:
    block = re.search(r"```\{toctree\}\n:caption: " + re.escape(caption) + r"\n(.*?)```", text, flags=re.S)
    assert block, caption
    return [line.strip() for line in block.group(1).splitlines() if line.strip() and not line.startswith(":")]


def test_guide_toctree_follows_the_readme():
    # Cheap, no Sphinx needed: the site's user guide lists the chapters in the README's order, and
    # every other page of docs/ is in the reference notes (or is the vocabulary).
    index = (DOCS / "index.md").read_text()
    readme = (ROOT / "README.md").read_text()
    guide = readme[readme.index("## The guide"): readme.index("## Development")]
    chapters = [f"guide/{m}" for m in re.findall(r"\]\(docs/guide/(\w+)\.md\)", guide)]
    assert chapters and _toctree(index, "User guide") == chapters
    assert sorted(_toctree(index, "User guide")) == sorted(f"guide/{p.stem}" for p in (DOCS / "guide").glob("*.md"))
    notes = _toctree(index, "Reference notes")
    assert _toctree(index, "Vocabulary") == ["naming"]
    others = {p.stem for p in DOCS.glob("*.md")} - {"index", "naming"}
    assert set(notes) == others, set(notes) ^ others


# --------------------------------------------------------------------------- as a reader sees it
def test_every_internal_link_of_the_site_resolves(site):
    """Every relative href and src of every built page names a file of the build, and every
    #fragment an id on the page it names (Sphinx's own pages and the generated ones)."""
    ids: dict[Path, set[str]] = {}

    def ids_of(page: Path) -> set[str]:
        if page not in ids:
            ids[page] = set(re.findall(r'\bid="([^"]+)"', page.read_text(errors="replace")))
        return ids[page]

    pages = sorted(site.rglob("*.html"))
    assert len(pages) > 100
    bad = []
    for page in pages:
        for target in re.findall(r'(?:href|src)="([^"]+)"', page.read_text(errors="replace")):
            target = html.unescape(target)
            if re.match(r"^[a-z]+:", target) or target.startswith("//"):
                continue
            file, _, fragment = target.partition("#")
            dest = (page.parent / file.split("?")[0]).resolve() if file else page
            if dest.is_dir():
                dest = dest / "index.html"
            if not dest.exists():
                bad.append(f"{page.relative_to(site)}: {target}")
            elif fragment and dest.suffix == ".html" and fragment not in ids_of(dest):
                bad.append(f"{page.relative_to(site)}: {target} (no such id)")
    assert not bad, bad[:20]


def _browser():
    import shutil

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("no Chromium on the PATH (apt-get install chromium)")
    return sync_api, chromium


def _canvas(frame) -> np.ndarray:
    """A player's canvas (in a page or an <iframe>) as (H, W, 3) int16, after two more draws."""
    import base64
    import io

    from PIL import Image

    frame.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    url = frame.evaluate("document.querySelector('#physcore-view canvas').toDataURL('image/png')")
    png = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


@pytest.mark.slow  # 10 s or more (tests/README.md), with the site's build
def test_pages_open_in_a_real_browser_without_errors(site, tmp_path):
    """The index, a gallery page and an API page, served over HTTP and opened in Chromium
    (Debian's, driven by Playwright): no console error and no page error, every image of the
    gallery page loaded (its GIF: natural width > 0), and the gallery index shows every scene's
    thumbnail; a 3D scene's page plays its player (it draws, a drag turns it, its frames
    differ). Screenshots land in the test's tmp folder."""
    import functools
    import http.server
    import threading

    sync_api, chromium = _browser()
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):  # no request log in the test output
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            problems: list[str] = []
            # Headless Chromium logs "GPU stall due to ReadPixels" for a read of the software GL's
            # pixels (the player's canvas): no page's error.
            page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}")
                    if m.type == "error" and "GPU stall due to ReadPixels" not in m.text else None)
            page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
            # A 3D scene's page: its player (an <iframe>) loads, draws and turns under a drag.
            page.goto(base + "gallery_pages/cloth_on_ball.html", wait_until="load")
            player = page.locator("iframe.pc-player")
            player.scroll_into_view_if_needed()
            # The iframe starts loading once scrolled to (lazily), later under load: waited for.
            deadline = time.monotonic() + 30
            while (frame := next((f for f in page.frames if f.url.endswith("_players/cloth_on_ball.html")), None)) is None:
                assert time.monotonic() < deadline, "the player's frame never loaded"
                page.wait_for_timeout(100)
            frame.wait_for_function("window.physcore && (physcore.ready || physcore.error !== null)", timeout=30_000)
            assert frame.evaluate("physcore.error") is None
            frame.evaluate("physcore.pause(); physcore.setTime(0)")
            before = _canvas(frame)
            bg = np.asarray(frame.evaluate("physcore.background"))
            assert (np.abs(before - bg).max(axis=2) > 24).mean() > 0.02, "the player draws next to nothing"
            box = player.bounding_box()
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 3
            page.mouse.move(x, y)
            page.mouse.down()
            page.mouse.move(x + 80, y + 20, steps=4)
            page.mouse.up()
            after = _canvas(frame)
            assert (np.abs(before - after).max(axis=2) > 24).mean() > 0.01, "a drag did not turn the player's camera"
            frame.evaluate("physcore.setTime(physcore.duration)")
            assert (np.abs(_canvas(frame) - after).max(axis=2) > 24).mean() > 0.0005, "the player's last frame is its first"
            page.screenshot(path=str(tmp_path / "gallery_pages_cloth_on_ball.png"))
            for path in ("index.html", "gallery_pages/kepler.html", "api/generated/physcore.Scene.html", "gallery_pages/index.html",
                         "gallery_pages/examples/plot_own_scene.html", "gallery_pages/examples/plot_video.html"):
                response = page.goto(base + path, wait_until="load")
                assert response is not None and response.ok, path
                page.screenshot(path=str(tmp_path / (path.replace("/", "_") + ".png")))
                broken = page.evaluate("[...document.images].filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src)")
                assert not broken, (path, broken)
                if path == "gallery_pages/kepler.html":
                    assert page.evaluate("[...document.images].some(i => i.src.endsWith('kepler.gif'))")
                if path == "gallery_pages/examples/plot_own_scene.html":
                    assert page.evaluate("[...document.images].some(i => i.src.endsWith('sphx_glr_plot_own_scene_001.gif'))")
                if path == "gallery_pages/examples/plot_video.html":
                    # The video's metadata loads (readyState >= 1, HAVE_METADATA): its file is served
                    # and Chromium reads its H.264 stream (duration: 90 frames at 30 fps).
                    page.wait_for_function("document.querySelector('video').readyState >= 1", timeout=10_000)
                    assert abs(page.evaluate("document.querySelector('video').duration") - 3.0) < 0.1
                if path == "gallery_pages/index.html":
                    shown = page.evaluate("[...document.images].map(i => i.src.split('/').pop())")
                    assert {f"{n}.gif" for n in pc.scenes.REGISTRY} <= set(shown)
            browser.close()
    finally:
        server.shutdown()
        server.server_close()
    assert not problems, problems
