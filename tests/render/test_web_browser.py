"""The HTML player (``render.html``) in a real browser (issue 67): Debian's Chromium, driven by
Playwright (headless; WebGL through its software rasteriser; no browser download), opens the
page of each of the issue's four scenes (and a 3D spring chain: points and lines) from a file and finds no console error or page error;
the canvas draws the scene (pixels other than the background); the frames change (the first and
the last frame differ on the canvas, and playing advances the clock); the play button and the
time slider work; a drag with the mouse turns the camera (the picture changes, the camera moves
about its target at the same distance). Skips, saying why, only where Chromium, Playwright or
pygltflib is missing.
"""
from __future__ import annotations

import base64
import io
import shutil
import time

import numpy as np
import pytest

import physcore as pc

pytest.importorskip("pygltflib", reason='pygltflib is not installed (pip install "physcore[web]")')

FRAMES = 8
SCENES = {
    "tablecloth": lambda: pc.scenes.tablecloth(),
    "pyramid": lambda: pc.scenes.pyramid(),
    "cloth_on_ball": lambda: pc.scenes.cloth_on_ball(),
    "drop": lambda: pc.scenes.drop(dim=3, n=20),  # a 3D fluid, coarse
    # Points with springs between them: lines moving by morph targets (r111 lacked their
    # updateMorphTargets, and the page failed to load before the player supplied it).
    "spring_chain": lambda: pc.scenes.spring_chain(dim=3),
}
#: Headless Chromium writes these for readPixels on its software GL; they are no page's error.
_GL_NOISE = ("GPU stall due to ReadPixels",)


def _browser():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("no Chromium on the PATH (apt-get install chromium)")
    return sync_api, chromium


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("web")
    out = {}
    for name, make in SCENES.items():
        t0 = time.perf_counter()
        rec = pc.render.record(make(), frames=FRAMES, color_by="none")
        t1 = time.perf_counter()
        path = pc.render.html(rec, tmp / f"{name}.html", title=name)
        print(f"\n{name}: recorded {FRAMES} frames in {t1 - t0:.2f} s, page written in {time.perf_counter() - t1:.2f} s, "
              f"{path.stat().st_size / 1e6:.2f} MB")
        out[name] = path
    return out


def _shot(page) -> np.ndarray:
    """The canvas as (H, W, 3) int16, once the player has drawn the time last set, and twice more: its own pixels
    (toDataURL: the player keeps its drawing buffer), 0.02 s against 1.7 s for a screenshot
    through the compositor on the software GL."""
    from PIL import Image

    # The time last set is on the canvas (the player counts what it showed and what it drew; two
    # animation frames alone once read a canvas still showing the time before, in CI).
    page.wait_for_function("physcore.drawn === physcore.shown", timeout=10_000)
    page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    url = page.evaluate("document.querySelector('#physcore-view canvas').toDataURL('image/png')")
    png = base64.b64decode(url.split(",", 1)[1])
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)
    if not img.any() and np.asarray(page.evaluate("physcore.background")).any():
        # Not the player's drawing (it clears to its background): under load in CI the
        # headless software GL handed back an all-black canvas for both frames of a page.
        raise _BlankCanvas(page.evaluate("physcore.renderer.getContext().isContextLost()"))
    return img


class _BlankCanvas(Exception):
    """The browser's GL gave back a black canvas: the page is opened again (once)."""


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose colour differs by more than 24 in some channel."""
    return float((np.abs(a - b).max(axis=2) > 24).mean())


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the file's tests (launching one costs 0.3 s)."""
    sync_api, chromium = _browser()
    p = sync_api.sync_playwright().start()
    try:
        b = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
        yield b
        b.close()
    finally:
        p.stop()


def _click(page, selector: str) -> None:
    """A real mouse click at the element's centre (Playwright's element click waits for the
    compositor's stability checks: 0.6 s a click on the software GL, against 0.03 s)."""
    box = page.locator(selector).bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)


@pytest.mark.parametrize("name", list(SCENES))
def test_the_player_draws_plays_and_turns(pages, browser, name, tmp_path):
    try:
        problems = _player_draws_plays_and_turns(pages, browser, name, tmp_path)
    except _BlankCanvas as blank:  # the browser's GL, not the player: a fresh page, once
        print(f"{name}: a blank canvas (context lost: {blank}); the page opened again")
        problems = _player_draws_plays_and_turns(pages, browser, name, tmp_path)
    assert not problems, problems


def _player_draws_plays_and_turns(pages, browser, name, tmp_path) -> list[str]:
    """Opens `name`'s page, checks that it draws, plays and turns (asserting each), and returns
    the console errors and page errors it logged meanwhile."""
    problems: list[str] = []
    page = browser.new_page(viewport={"width": 320, "height": 256})
    try:
        page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}")
                if m.type == "error" and not any(s in m.text for s in _GL_NOISE) else None)
        page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
        page.goto(pages[name].as_uri())
        page.wait_for_function("window.physcore && (window.physcore.ready || window.physcore.error !== null)", timeout=30_000)
        assert page.evaluate("physcore.error") is None
        assert page.evaluate("physcore.frames") == FRAMES
        duration = page.evaluate("physcore.duration")
        assert duration == pytest.approx((FRAMES - 1) / 30.0)

        # Playing: the clock and the frame advance.
        page.wait_for_function("physcore.time > 0.05 && physcore.frame > 0", timeout=10_000)

        # The scene is drawn: against the background, many pixels are something else.
        _click(page, "#physcore-play")
        assert page.evaluate("physcore.playing") is False
        page.evaluate("physcore.setTime(0)")
        first = _shot(page)
        bg = np.asarray(page.evaluate("physcore.background"))
        drawn = float((np.abs(first - bg).max(axis=2) > 24).mean())
        assert drawn > 0.02, f"{name}: only {drawn:.2%} of the canvas differs from the background"
        Image = pytest.importorskip("PIL.Image")
        Image.fromarray(first.astype(np.uint8)).save(tmp_path / f"{name}_first.png")

        # The frames change: the last frame is not the first.
        page.evaluate("physcore.setTime(physcore.duration)")
        assert page.evaluate("physcore.frame") == FRAMES - 1
        last = _shot(page)
        assert _changed(first, last) > 0.0005, f"{name}: the last frame looks like the first"
        # The slider: halfway along is halfway through, and it pauses.
        page.evaluate("physcore.play()")
        page.locator("#physcore-time").evaluate("e => { e.value = '0.5'; e.dispatchEvent(new Event('input')); }")
        assert page.evaluate("physcore.playing") is False
        assert page.evaluate("physcore.time") == pytest.approx(duration / 2)
        assert page.text_content("#physcore-clock").startswith("t = ")

        # A drag turns the camera about its target: the picture changes, the distance stays.
        page.evaluate("physcore.setTime(0)")
        before = _shot(page)
        cam0 = np.asarray(page.evaluate("physcore.camera.position.toArray()"))
        target = np.asarray(page.evaluate("physcore.controls.target.toArray()"))
        box = page.locator("#physcore-view canvas").bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x + 80, y + 20, steps=4)
        page.mouse.up()
        after = _shot(page)
        cam1 = np.asarray(page.evaluate("physcore.camera.position.toArray()"))
        assert np.linalg.norm(cam1 - cam0) > 1e-3 * np.linalg.norm(cam0 - target)
        assert np.linalg.norm(cam1 - target) == pytest.approx(np.linalg.norm(cam0 - target), rel=1e-6)
        assert _changed(before, after) > 0.01, f"{name}: the drag did not change the picture"
        Image.fromarray(after.astype(np.uint8)).save(tmp_path / f"{name}_turned.png")
    finally:
        page.close()
    return problems
