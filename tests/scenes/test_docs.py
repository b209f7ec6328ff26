"""The README's and the guide's Python examples, their links, the docstring examples, and the _core.pyi
stub are checked."""
from __future__ import annotations

import doctest
import importlib
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import physcore

ROOT = Path(__file__).resolve().parents[2]


#: The pages whose Python blocks run here: the README and the guide (docs/guide/).
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]


def _blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


def _readme_blocks():
    return _blocks(ROOT / "README.md")


#: Every Python block of every page, by (page, index).
BLOCKS = [(p.relative_to(ROOT).as_posix(), k) for p in PAGES for k in range(len(_blocks(p)))]


def test_readme_has_python_examples():
    assert _readme_blocks(), "README.md must contain a ```python example"
    assert len(BLOCKS) >= 20, "the guide's examples are collected"


@pytest.mark.parametrize(("page", "k"), BLOCKS)
def test_python_example_runs(page, k, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # Run as a script would be: the sweep example keeps its cluster start under
    # `if __name__ == "__main__":`, as Dask's worker processes need in a script.
    namespace: dict = {"__name__": "__main__"}
    exec(compile(_blocks(ROOT / page)[k], f"{page}[python block {k}]", "exec"), namespace)
    # Examples that write a GIF must leave a real one behind.
    for gif in tmp_path.glob("*.gif"):
        assert gif.stat().st_size > 1000


def _anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    h = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return h.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    out, fence = set(), False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        m = re.match(r"^#+ (.*)", line)
        if m and not fence:
            out.add(_anchor(m.group(1)))
    return out


@pytest.mark.parametrize("page", [p.relative_to(ROOT).as_posix() for p in [*PAGES, *sorted((ROOT / "docs").glob("*.md"))]])
def test_every_internal_link_resolves(page):
    """Every relative link of the README, the guide and the docs names a file of the checkout,
    and every #anchor a heading of the page it names."""
    path = ROOT / page
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    targets = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'<img src="([^"]+)"', text)
    if "/guide/" in page:  # each chapter leads back to the guide's contents
        assert "../../README.md#the-guide" in targets, f"{page}: no link back to the README's guide"
    for t in targets:
        if re.match(r"^[a-z]+:", t):
            continue
        file, _, anchor = t.partition("#")
        dest = (path.parent / file).resolve() if file else path
        assert dest.exists(), f"{page}: {t} (no such file)"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{page}: {t} (no such heading)"


PUBLIC_MODULES = sorted(m.name for m in pkgutil.iter_modules(physcore.__path__) if not m.name.startswith("_"))


def test_public_modules_are_found():
    assert {"scene", "terms", "scenes", "render", "cli"} <= set(PUBLIC_MODULES)


@pytest.mark.parametrize("name", PUBLIC_MODULES)
def test_docstring_examples(name):
    # Every public module carries runnable examples, and all of them pass (a module without any
    # would pass vacuously, so it fails here).
    module = importlib.import_module(f"physcore.{name}")
    result = doctest.testmod(module, verbose=False)
    assert result.attempted > 0, f"physcore.{name} has no docstring examples"
    assert result.failed == 0


def _stubtest(stub_text: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """mypy's stubtest of ``stub_text`` (as physcore/_core.pyi) against the compiled module: every
    name, signature (parameter names, kinds, defaults), property and class flag. The stub is
    copied beside an empty package stub so that mypy reads this checkout's stub, not the
    installed copy, and checks only the stub."""
    pkg = tmp_path / "stubs" / "physcore"
    pkg.mkdir(parents=True)
    (pkg / "__init__.pyi").write_text("")
    (pkg / "_core.pyi").write_text(stub_text)
    env = {**os.environ, "MYPYPATH": str(pkg.parent)}
    return subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "physcore._core", "--mypy-config-file", os.devnull],
        capture_output=True, text=True, env=env, cwd=tmp_path, check=False,
    )


def test_stub_matches_compiled_module(tmp_path):
    result = _stubtest((ROOT / "python" / "physcore" / "_core.pyi").read_text(), tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr


def test_stub_check_catches_a_wrong_signature(tmp_path):
    # The check above must be able to fail: a parameter the compiled function lacks is reported.
    stub = (ROOT / "python" / "physcore" / "_core.pyi").read_text()
    wrong = stub.replace("def simd_levels() -> list[str]: ...", "def simd_levels(x: int) -> list[str]: ...")
    assert wrong != stub
    result = _stubtest(wrong, tmp_path)
    assert result.returncode != 0 and "simd_levels" in result.stdout, result.stdout + result.stderr


def test_readme_opens_with_the_gallery():
    # Every ready-made scene has a thumbnail in the README's gallery, with the command that makes
    # it, before the first word about solvers; thumbnails stay small (≤ 200 kB each, ≤ 5 MB in
    # all) so the repository stays light (issue "A gallery people share").
    import re

    import physcore as pc

    text = (ROOT / "README.md").read_text()
    gallery = text[: text.index("## Quick start")]
    shown = re.findall(r'<img src="docs/gallery/(\w+)\.gif"', gallery)
    assert set(shown) == set(pc.scenes.REGISTRY), set(pc.scenes.REGISTRY) ^ set(shown)
    for name in shown:
        assert f"physcore render {name}</code>" in gallery, name
    sizes = {name: (ROOT / "docs" / "gallery" / f"{name}.gif").stat().st_size for name in shown}
    assert max(sizes.values()) <= 200_000, max(sizes.items(), key=lambda kv: kv[1])
    assert sum(sizes.values()) <= 5_000_000
    assert "solver" not in gallery.lower()
