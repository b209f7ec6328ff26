"""The package's import layering (issue 62): no import circle anywhere in physcore (function-local
imports included), no private name taken across package lines, and the code that drives scenes
from outside (Batch, sweeps, the live loop, the notebook) uses only the public members of Scene
and Session."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[2] / "python" / "physcore"


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PKG.rglob("*.py"):
        parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    mods["physcore._core"] = PKG / "_core.pyi"  # the compiled core: a leaf
    return mods


MODULES = _modules()


def _package(module: str) -> str:
    return module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]


def _imports(module: str) -> list[tuple[str, str | None, int]]:
    """``(target module, imported name or None, line)`` for every import anywhere in ``module``
    (inside functions and ``if TYPE_CHECKING`` too); a name that is a module is its own target."""
    path = MODULES[module]
    if path.suffix != ".py":
        return []
    out: list[tuple[str, str | None, int]] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = _package(module).split(".")[: len(_package(module).split(".")) - (node.level - 1)]
                base_name = ".".join(base + ([node.module] if node.module else []))
            else:
                base_name = node.module or ""
            for alias in node.names:
                full = f"{base_name}.{alias.name}"
                if full in MODULES:
                    out.append((full, None, node.lineno))
                elif base_name in MODULES:
                    out.append((base_name, alias.name, node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, None, node.lineno) for a in node.names if a.name in MODULES]
    return out


def _graph() -> dict[str, set[str]]:
    return {m: {t for t, _, _ in _imports(m) if t != m} for m in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_function_local_imports() -> None:
    # notebook.show imports IPython inside the function; the live loop imports the painter in
    # methods: both are edges of the graph.
    assert "physcore.render.painter" in _graph()["physcore._live"]


def test_there_is_no_import_circle_in_physcore() -> None:
    assert _cycles(_graph()) == []


def _owner(module: str, name: str | None) -> str | None:
    """The package a private thing belongs to: for a name ``_x`` of module ``m``, ``m``'s package;
    for a module whose path has a private part (``a.b._c.d``), the package holding that part;
    None when nothing is private."""
    parts = module.split(".")
    for k, p in enumerate(parts):
        if p.startswith("_") and k > 0:
            return ".".join(parts[:k])
    if name is not None and name.startswith("_"):
        return _package(module)
    return None


def test_no_module_imports_a_private_name_across_package_lines() -> None:
    bad = []
    for m in MODULES:
        for target, name, line in _imports(m):
            owner = _owner(target, name)
            if owner is not None and not (_package(m) + ".").startswith(owner + "."):
                bad.append(f"{m}:{line} takes {target}{'' if name is None else '.' + name} (private to {owner})")
    assert bad == []


def test_the_private_name_rule_can_fail() -> None:
    assert _owner("physcore.render._raster", "paste") == "physcore.render"
    assert _owner("physcore.terms", "_finite_float") == "physcore.terms"
    assert _owner("physcore.render.painter", "paste") is None
    assert not ("physcore" + ".").startswith("physcore.render.")


DRIVERS = ("batch.py", "sweeps.py", "_live.py", "notebook.py", "viewer.py")
PRIVATE_SCENE_MEMBERS = {
    name
    for node in ast.walk(ast.parse((PKG / "scene.py").read_text()))
    if isinstance(node, ast.ClassDef) and node.name == "Scene"
    for item in node.body
    if isinstance(item, ast.FunctionDef) and item.name.startswith("_") and not item.name.startswith("__")
    for name in [item.name]
} | {"_session", "_parts", "_threads", "_step_checked"}


@pytest.mark.parametrize("module", DRIVERS)
def test_the_drivers_use_no_private_member_of_scene_or_session(module: str) -> None:
    assert {"_sim", "_file_arrays", "_exclusive", "_from_file"} <= PRIVATE_SCENE_MEMBERS
    used = []
    for node in ast.walk(ast.parse((PKG / module).read_text())):
        if isinstance(node, ast.Attribute) and node.attr in PRIVATE_SCENE_MEMBERS:
            owner = node.value
            # a module's own objects keep their own private members (self._session of a widget)
            if not (isinstance(owner, ast.Name) and owner.id == "self"):
                used.append(f"{module}:{node.lineno} .{node.attr}")
    assert used == []


def test_scene_imports_no_presentation() -> None:
    targets = {t for t, _, _ in _imports("physcore.scene")}
    assert not {t for t in targets if t.startswith(("physcore.notebook", "physcore.render", "physcore._live", "physcore.viewer"))}
