"""The notebook widget in a real browser (issue 49): a JupyterLab server on loopback with a
generated notebook, opened in Debian's Chromium (driven by Playwright, headless; no browser
download), the cells run as a user runs them (Shift+Enter). Checked: frames arrive and change
while playing, stop on pause, a drag with the mouse moves the particle in the kernel, a slider
changes the term, a key on the picture works as the viewer's. Skips, saying why, only where Chromium, JupyterLab or anywidget is missing.

The frame rate the browser drew (the default cloth at 480 × 360) is printed (``pytest -s``)
and must be live (>= 5 frames/s even on a busy 2-core machine; the closing note of issue 49
has the measured numbers).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow  # a server, a kernel and a browser: 10 s or more

# The particle dragged: the free particle of the cloth drawn nearest the picture's centre when
# the test pauses. (It was the free corner; but the camera is fitted to a 0.5 s preview, and by
# the pause the swinging corner may hang below the picture: two CI runs' presses then landed on
# the sliders under it.)
# The free particle drawn nearest the picture's centre that a press at its own pixel grabs: in
# 3D the press takes the particle nearest the viewer within the pick radius, and where the
# paused cloth folds another may lie in front (a run under load grabbed such a neighbour).
PICK = (
    "from physcore._live import pick\n"
    "W, H = w.size\n"
    "free = [i for i in range(w.scene.n_particles) if not w.scene.pinned[i]]\n"
    "_s = w._session\n"
    "_col, _row, _depth = _s.painter.pixels(_s.live.drawn(_s.alpha)[0])\n"
    "_radius = max(8.0, 3.0 * _s.painter.ras.radius + 2.0)\n"
    "k = next(i for i in sorted(free, key=lambda i: (w.pixel_of(i)[0] - W / 2) ** 2 + (w.pixel_of(i)[1] - H / 2) ** 2)\n"
    "         if pick(_col, _row, w.pixel_of(i), _radius, ~_s.live.pinned, _depth) == i)\n"
)


def _needs():
    pytest.importorskip("anywidget", reason='anywidget is not installed (pip install "physcore[notebook]")')
    pytest.importorskip("jupyterlab", reason="JupyterLab is not installed (pip install jupyterlab; the test extra has it)")
    pytest.importorskip("ipykernel", reason="ipykernel is not installed (JupyterLab brings it)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("no Chromium on the PATH (apt-get install chromium)")
    return sync_api, chromium


def _cell(source: str) -> dict:
    return {"cell_type": "code", "execution_count": None, "metadata": {}, "outputs": [], "source": source}


def _notebook(path: Path) -> None:
    cells = [
        _cell("import json\nimport physcore as pc\n\n\ndef j(x):\n    return json.dumps(x, separators=(',', ':'))\n\n\n"
              "w = pc.widget(pc.scenes.cloth(), preview=0.5, fallback=False)\nw"),
        _cell(PICK + "print('PIXEL', k, j(w.pixel_of(k)), w.ticks, j(w.scene.positions.tolist()))"),
        _cell("print('AFTER', w.grabbed, w.ticks, j(w.scene.positions.tolist()))"),
        _cell("print('PARAMS', j(w.params), j([float(t.stiffness.mean()) for t in w.scene.terms if isinstance(t, pc.Springs)]))"),
        _cell("w.pause()\nf = pc.widget(pc.scenes.dam_break(), preview=0.5, fallback=False)\nf"),
    ]
    nb = {"cells": cells, "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
          "nbformat": 4, "nbformat_minor": 5}
    path.write_text(json.dumps(nb))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: The front ends: JupyterLab (the test extra has it), and Notebook 7 where it is installed.
FRONT_ENDS = {"lab": ("jupyterlab", "/lab/tree/widget.ipynb"), "notebook": ("notebook", "/notebooks/widget.ipynb")}


@pytest.fixture(params=list(FRONT_ENDS))
def lab(request, tmp_path):
    """A JupyterLab (or Notebook 7) server on 127.0.0.1 serving a generated notebook, with its
    own config, data and runtime folders (nothing of the user's), and physcore importable in
    its kernels."""
    _needs()
    module, path = FRONT_ENDS[request.param]
    if request.param == "notebook":
        pytest.importorskip("notebook", minversion="7", reason="Notebook 7 is not installed (pip install notebook); JupyterLab's run covers the widget")
    work = tmp_path / "work"
    work.mkdir()
    _notebook(work / "widget.ipynb")
    port, token = _free_port(), "physcore-test"
    import physcore

    package_root = str(Path(physcore.__file__).resolve().parents[1])
    env = {**os.environ, "JUPYTER_CONFIG_DIR": str(tmp_path / "config"), "JUPYTER_RUNTIME_DIR": str(tmp_path / "runtime"),
           "IPYTHONDIR": str(tmp_path / "ipython"), "JUPYTER_PLATFORM_DIRS": "1",
           "PYTHONPATH": os.pathsep.join([package_root, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
    log = open(tmp_path / "lab.log", "w")  # noqa: SIM115 - closed below
    proc = subprocess.Popen(
        [sys.executable, "-m", module, "--no-browser", "--ip=127.0.0.1", f"--port={port}", "--port-retries=0",
         f"--ServerApp.token={token}", f"--ServerApp.root_dir={work}", "--ServerApp.open_browser=False",
         f"--LabApp.workspaces_dir={tmp_path / 'workspaces'}", "--LabApp.news_url=None",
         "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate", "--allow-root"],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=work,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(f"{base}/api/status?token={token}", timeout=2) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                log.flush()
                pytest.fail("JupyterLab did not start:\n" + (tmp_path / "lab.log").read_text()[-3000:])
            time.sleep(0.3)
        yield {"url": f"{base}{path}?token={token}", "sessions": f"{base}/api/sessions?token={token}"}
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


def _known_front_end_error(error) -> bool:
    """Notebook 7.6 throws this in its own core bundle on opening any notebook with a fresh
    config (no physcore widget needed to see it): not ours to fail on."""
    stack = getattr(error, "stack", "") or ""
    return "reading 'schema'" in str(error) and "/static/notebook/notebook_core." in stack.split("\n", 2)[1]


def _wait_for_an_idle_kernel(sessions: str, timeout: float = 60.0) -> None:
    """Until the server says the notebook's kernel is idle (its REST API: the same for every
    front end)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with urllib.request.urlopen(sessions, timeout=5) as r:
            states = [s["kernel"]["execution_state"] for s in json.load(r)]
        if "idle" in states:
            return
        time.sleep(0.3)
    raise AssertionError(f"no idle kernel after {timeout} s")


def _run_cell(page, k: int) -> None:
    """Select cell `k` of the notebook and run it (Shift+Enter), as a user does."""
    cell = page.locator(".jp-Notebook .jp-Cell").nth(k)
    cell.locator(".jp-InputArea-editor").click()
    page.keyboard.press("Shift+Enter")


def _output(page, k: int, tag: str, timeout: float = 60.0) -> str:
    """The printed line of cell `k` that starts with `tag`."""
    out = page.locator(".jp-Notebook .jp-Cell").nth(k).locator(".jp-OutputArea-output")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if out.count():
            m = re.search(rf"^{tag} (.*)$", out.first.inner_text(), flags=re.M)
            if m:
                return m.group(1)
        time.sleep(0.2)
    raise AssertionError(f"cell {k} printed no {tag} line")


def _frames(page, k: int = 0) -> int:
    return int(page.locator(".physcore-widget").nth(k).get_attribute("data-frames") or 0)


def _pixels(page) -> str:
    return page.evaluate("document.querySelector('.physcore-widget canvas').toDataURL()")


def _settled_box(locator, timeout: float = 15.0) -> dict:
    """The element's bounding box once it has stood still for 1 s (4 reads 0.25 s apart)."""
    deadline, last, same = time.monotonic() + timeout, None, 0
    while time.monotonic() < deadline:
        box = locator.bounding_box()
        same = same + 1 if box == last else 0
        if same >= 4:
            return box
        last = box
        time.sleep(0.25)
    raise AssertionError(f"the canvas kept moving for {timeout} s (last box {last})")


def test_widget_plays_pauses_drags_and_turns_a_knob(lab, tmp_path):
    sync_api, chromium = _needs()
    problems: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 1000})
            page.on("pageerror", lambda e: None if _known_front_end_error(e) else problems.append(f"page error: {e}"))
            page.on("console", lambda m: problems.append(f"console: {m.text}") if m.type == "error" and "physcore" in m.text else None)
            page.goto(lab["url"], wait_until="domcontentloaded")
            page.wait_for_selector(".jp-Notebook .jp-Cell .jp-InputArea-editor", timeout=60_000)
            _wait_for_an_idle_kernel(lab["sessions"])
            _run_cell(page, 0)
            page.wait_for_selector(".physcore-widget canvas", timeout=90_000)

            # Playing: frames arrive and the picture changes.
            page.wait_for_function("Number(document.querySelector('.physcore-widget').dataset.frames) > 3", timeout=60_000)
            # Liveness, not speed: a frame rate depends on what else the machine runs (CI runs two
            # test workers on 2 cores); the rate is printed for the record and benchmarked by
            # benches/render/bench_widget.py.
            n0, t0, first = _frames(page), time.monotonic(), _pixels(page)
            page.wait_for_function(f"Number(document.querySelector('.physcore-widget').dataset.frames) > {n0 + 10}", timeout=30_000)
            n1, t1 = _frames(page), time.monotonic()
            print(f"\nbrowser: {(n1 - n0) / (t1 - t0):.1f} frames/s drawn (default cloth, "
                  f"{page.evaluate('navigator.hardwareConcurrency')} CPUs)")
            assert _pixels(page) != first
            page.wait_for_function("Number(document.querySelector('.physcore-widget').dataset.time) > 0.5", timeout=30_000)
            page.screenshot(path=str(tmp_path / "playing.png"))

            # Pause: frames stop, the picture stands. A frame asked for before the pause may
            # still land, late on a loaded machine (it did 0.5 s after the pause, beside the
            # suite's other worker): wait until none has landed for 2 s, then nothing may change.
            page.click(".physcore-widget .pc-play")
            page.wait_for_function("document.querySelector('.physcore-widget').dataset.playing === '0'")
            n2, quiet, deadline = _frames(page), time.monotonic(), time.monotonic() + 30.0
            while time.monotonic() - quiet < 2.0 and time.monotonic() < deadline:
                time.sleep(0.1)
                if _frames(page) != n2:
                    n2, quiet = _frames(page), time.monotonic()
            still = _pixels(page)
            time.sleep(1.5)
            assert _frames(page) == n2
            assert _pixels(page) == still

            # Drag that particle 60 pixels to the right with the mouse: in the kernel it
            # moves there (paused, a dragged particle is put under the pointer at once).
            _run_cell(page, 1)
            pick, pixel, ticks, before = _output(page, 1, "PIXEL").split(" ", 3)
            col, row = json.loads(pixel)
            before = json.loads(before)
            canvas = page.locator(".physcore-widget canvas").first
            size = page.evaluate("[document.querySelector('.physcore-widget canvas').width, document.querySelector('.physcore-widget canvas').height]")
            # The press is made where the canvas is on the page; the test then waits for the
            # kernel's answer (each frame carries the held particle, shown as data-grabbed).
            # JupyterLab re-lays out the notebook while outputs land (the widget widens, a
            # scroll bar comes and goes): a press measured before such a shift lands beside the
            # canvas (a CI run's landed on the damping slider). So the box is measured until it
            # stands still, the point is checked to be the canvas's (elementFromPoint) just
            # before the press, and a press that grabbed nothing is released and made again
            # (twice at most; every box and what was at the point are in the failure message).
            boxes: list = []
            for _attempt in range(3):
                canvas.evaluate("e => e.scrollIntoView({block: 'center'})")  # in view, clear of pop-ups
                box = _settled_box(canvas)
                boxes.append(box)
                sx, sy = box["width"] / size[0], box["height"] / size[1]
                start = (box["x"] + (col + 0.5) * sx, box["y"] + (row + 0.5) * sy)
                there = page.evaluate("""([x, y]) => { const e = document.elementFromPoint(x, y);
                    return e === document.querySelector('.physcore-widget canvas') ? 'canvas' : String(e && e.outerHTML).slice(0, 120); }""",
                                      list(start))
                if there != "canvas":
                    boxes.append(f"at the point: {there}")
                    continue
                page.mouse.move(*start)
                page.mouse.down()
                try:
                    # Held: `pick`, or a particle beside it (the cloth folds; a press a pixel off
                    # as the layout shifts takes the one nearest the viewer there): that one moves.
                    page.wait_for_function("document.querySelector('.physcore-widget').dataset.grabbed !== ''", timeout=10_000)
                    held = int(page.get_attribute(".physcore-widget", "data-grabbed"))
                    break
                except sync_api.TimeoutError:
                    page.mouse.up()
                    boxes.append(canvas.bounding_box())
            else:
                raise AssertionError(f"the press at pixel {(col, row)} grabbed nothing; boxes {boxes}, "
                                     f"status {page.text_content('.physcore-widget .pc-status')!r}")
            for k in range(1, 11):
                page.mouse.move(start[0] + 6 * k * sx, start[1])
                time.sleep(0.05)
            time.sleep(0.5)
            page.mouse.up()
            page.wait_for_function("document.querySelector('.physcore-widget').dataset.grabbed === ''", timeout=10_000)
            _run_cell(page, 2)
            grabbed, ticks_after, after = _output(page, 2, "AFTER").split(" ", 2)
            after = json.loads(after)[held]
            moved = sum((a - b) ** 2 for a, b in zip(after, before[held], strict=True)) ** 0.5
            assert moved > 0.05, (held, pick, before[held], after)
            assert grabbed == "None" and ticks_after == ticks  # let go; paused: no tick ran

            # A slider: stiffness to position 750 of 1000 (log scale over 100× either way of
            # its start, so × 10), through an input event as the mouse would make.
            page.evaluate("""() => { const e = document.querySelector('.physcore-widget input[name=stiffness]');
                                     e.value = '750'; e.dispatchEvent(new Event('input', {bubbles: true})); }""")
            page.wait_for_function("document.querySelector('.physcore-widget .pc-slider[data-name=stiffness] .pc-value').textContent.startsWith('2.000e+4')",
                                   timeout=30_000)
            _run_cell(page, 3)
            params, springs = _output(page, 3, "PARAMS").split(" ", 1)
            assert json.loads(params)["stiffness"] == pytest.approx(20000.0, rel=1e-6)
            assert json.loads(springs) == pytest.approx([20000.0], rel=1e-6)

            # The viewer's key g on the focused picture: gravity ÷ 1.25 (JupyterLab's own
            # shortcuts stand aside there).
            page.locator(".physcore-widget canvas").first.focus()
            page.keyboard.press("g")
            page.wait_for_function("document.querySelector('.physcore-widget .pc-slider[data-name=gravity] .pc-value').textContent.startsWith('7.848')",
                                   timeout=30_000)
            assert page.locator(".jp-Notebook .jp-Cell").count() == 5  # no cell was added or changed by the key

            # Play again: frames flow again.
            page.click(".physcore-widget .pc-play")
            n3 = _frames(page)
            page.wait_for_function(f"Number(document.querySelector('.physcore-widget').dataset.frames) > {n3 + 5}", timeout=30_000)
            page.screenshot(path=str(tmp_path / "after.png"))

            # A 10⁴-particle fluid (the default dam break, 10 368 particles), the cloth paused:
            # frames keep coming while its ticks run in the background.
            _run_cell(page, 4)
            page.wait_for_function("document.querySelectorAll('.physcore-widget').length === 2 && "
                                   "Number(document.querySelectorAll('.physcore-widget')[1].dataset.frames) > 3", timeout=90_000)
            n4, t4 = _frames(page, 1), time.monotonic()
            page.wait_for_function(f"Number(document.querySelectorAll('.physcore-widget')[1].dataset.frames) > {n4 + 10}",
                                   timeout=30_000)
            print(f"browser: {(_frames(page, 1) - n4) / (time.monotonic() - t4):.1f} frames/s drawn "
                  f"(dam break, 10 368 particles)")
            page.locator(".physcore-widget").nth(1).scroll_into_view_if_needed()
            page.screenshot(path=str(tmp_path / "fluid.png"))
        finally:
            browser.close()
    assert not problems, problems
