"""The README's Python example, the docstring examples, and the _core.pyi stub are checked."""
from __future__ import annotations

import ast
import doctest
import re
from pathlib import Path

import pytest

import physcore
import physcore.scene
import physcore.terms
from physcore import _core

ROOT = Path(__file__).resolve().parent.parent


def _readme_blocks():
    text = (ROOT / "README.md").read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_readme_has_python_examples():
    assert _readme_blocks(), "README.md must contain a ```python example"


@pytest.mark.parametrize("k", range(len(_readme_blocks())))
def test_readme_python_example_runs(k, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(_readme_blocks()[k], f"README.md[python block {k}]", "exec"), namespace)
    # Examples that write a GIF must leave a real one behind.
    for gif in tmp_path.glob("*.gif"):
        assert gif.stat().st_size > 1000


@pytest.mark.parametrize("module", [physcore.scene, physcore.terms])
def test_docstring_examples(module):
    result = doctest.testmod(module, verbose=False)
    assert result.failed == 0


def test_stub_matches_compiled_module():
    stub = ast.parse((ROOT / "python" / "physcore" / "_core.pyi").read_text())
    top = set()
    methods = set()
    for node in stub.body:
        if isinstance(node, ast.FunctionDef):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign):
            top.add(node.target.id)
        elif isinstance(node, ast.ClassDef):
            top.add(node.name)
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name != "__init__":
                    methods.add(item.name)
                elif isinstance(item, ast.AnnAssign):
                    methods.add(item.target.id)
    public = {n for n in dir(_core) if not n.startswith("_")} | {"__version__"}
    assert top == public
    compiled_methods = {n for n in dir(_core.Simulation2) if not n.startswith("_")}
    assert methods == compiled_methods
