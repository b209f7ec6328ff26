"""physcore.terms is a package of one module per family (issue 45 step 5): its records still
read, pickle and resolve their annotations as ``physcore.terms.NAME``, so pickles written before
the split load and new ones are byte-identical; and no family module imports the package."""
from __future__ import annotations

import ast
import pickle
import typing
from pathlib import Path

import numpy as np
import pytest

import physcore.terms as terms

RECORDS = [
    terms.Gravity([0.0, -9.81]),
    terms.Drag(0.1),
    terms.Springs([0], [1], stiffness=10.0, rest_length=1.0),
    terms.PairwiseGravity(),
    terms.TreeGravity(),
    terms.ElectricField([1.0, 0.0]),
    terms.Coulomb(),
    terms.MagneticField(2.0),
    terms.GridElectricField(np.zeros((2, 2, 2)), [0.0, 0.0], spacing=1.0),
    terms.GridMagneticField(np.zeros((2, 2)), [0.0, 0.0], spacing=1.0),
    terms.XpbdConstraints(distance=[[0, 1]]),
    terms.Plane([0.0, 0.0], [0.0, 1.0]),
    terms.Box([0.0, 0.0], [1.0, 1.0]),
    terms.Sphere([0.0, 0.0], 1.0),
    terms.Capsule([0.0, 0.0], [1.0, 0.0], 0.1),
    terms.OrientedBox([0.0, 0.0], [1.0, 0.5], 0.3),
]


def test_every_public_record_is_covered():
    classes = {name for name in terms.__all__ if isinstance(getattr(terms, name), type)} - {"Term", "Collider"}
    assert classes == {type(r).__name__ for r in RECORDS}


@pytest.mark.parametrize("name", terms.__all__)
def test_public_names_keep_the_module_path(name):
    obj = getattr(terms, name)
    assert obj.__module__ == "physcore.terms"
    typing.get_type_hints(obj)  # the string annotations resolve in that module's namespace


@pytest.mark.parametrize("record", RECORDS, ids=lambda r: type(r).__name__)
def test_pickle_round_trip(record):
    data = pickle.dumps(record, protocol=4)
    assert b"\x8c\x0ephyscore.terms\x94" in data
    back = pickle.loads(data)
    assert type(back) is type(record)
    assert pickle.dumps(back, protocol=4) == data


def test_pickles_from_the_single_module_load_byte_identical():
    # Written by physcore.terms as one module (terms.py), before the split.
    old = {
        b"\x80\x04\x95H\x00\x00\x00\x00\x00\x00\x00\x8c\x0ephyscore.terms\x94\x8c\x04Drag\x94\x93\x94)\x81\x94}\x94("
        b"\x8c\x0bcoefficient\x94G?\xb9\x99\x99\x99\x99\x99\x9a\x8c\x04name\x94\x8c\x04drag\x94ub.": terms.Drag(0.1),
    }
    for data, record in old.items():
        assert pickle.loads(data) == record
        assert pickle.dumps(record, protocol=4) == data


def test_family_modules_do_not_import_the_package():
    """A family module imports ``_base`` and other family modules (the capsule builds on the
    colliders' base), never the package (which would run ``__init__`` first), and the family
    modules' imports have no circle."""
    package = Path(terms.__file__).parent
    graph: dict[str, set[str]] = {}
    for path in sorted(package.glob("*.py")):
        if path.name == "__init__.py":
            continue
        graph[path.stem] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                # ``from . import x`` or ``from physcore.terms import x`` would run __init__ first.
                assert not (node.level == 1 and node.module is None), f"{path.name}: from . import"
                assert node.module not in ("physcore.terms",), f"{path.name}: imports physcore.terms"
                if node.level == 1:
                    assert (package / f"{node.module}.py").exists(), f"{path.name}: imports .{node.module}"
                    graph[path.stem].add(node.module)
    done: set[str] = set()

    def visit(m: str, path: tuple[str, ...]) -> None:
        assert m not in path, f"import circle: {' -> '.join((*path, m))}"
        if m not in done:
            for n in graph[m]:
                visit(n, (*path, m))
            done.add(m)

    for m in graph:
        visit(m, ())
    assert graph["capsule"] == {"_base", "colliders"}


def test_registry_keeps_the_definition_order():
    assert list(terms.REGISTRY)[:11] == [
        "gravity", "drag", "springs", "pairwise_gravity", "tree_gravity", "uniform_electric_field", "coulomb",
        "uniform_magnetic_field", "grid_electric_field", "grid_magnetic_field", "xpbd_constraints",
    ]
