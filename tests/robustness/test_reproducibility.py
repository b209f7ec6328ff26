"""The published reproducibility contract (docs/reproducibility.md) holds on this machine: each
row's `=` is bit-identical and each figure is not exceeded more than tenfold, for thread counts,
the SIMD levels this CPU has, save/load and pickling; every gallery scene and every particle
integrator has a row."""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

import physcore as pc

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "reproducibility.md"


def _bench():
    spec = importlib.util.spec_from_file_location("reproducibility_bench", ROOT / "benches" / "robustness" / "reproducibility.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


BENCH = _bench()
TEXT = DOC.read_text(encoding="utf-8")
TABLE = BENCH.parse(TEXT[TEXT.index(BENCH.BEGIN) : TEXT.index(BENCH.END)])


def test_the_table_covers_every_gallery_scene_and_integrator():
    assert set(TABLE) == set(BENCH.cases()), "rerun: python benches/robustness/reproducibility.py --against DUMP --write docs/reproducibility.md"
    integrators = {name.split("/", 1)[1] for name in TABLE if name.startswith(("spring_chain/", "solar/"))}
    # boris and xpbd have their own gallery scenes (cyclotron, xpbd_cloth).
    assert integrators | {"boris", "xpbd"} == {d["name"] for d in pc.INTEGRATORS}
    assert set(pc.scenes.REGISTRY) <= set(TABLE)
    for name, row in TABLE.items():
        for col in ("threads", "save/load", "pickle"):
            assert row[col] == "=", f"{name}: the contract promises bit-identical {col}, the table says {row[col]}"


def _claim(cell: str) -> float | None:
    """0.0 for `=`, the figure for a number, None when not measured."""
    if cell == "=":
        return 0.0
    if re.fullmatch(r"\d(\.\d+)?e[-+]\d+", cell):
        return float(cell)
    assert cell == "–", f"unreadable cell {cell!r}"
    return None


@pytest.mark.parametrize("name", sorted(TABLE))
def test_the_published_claims_hold_here(name):
    claims = TABLE[name]
    levels = [lv for lv in pc.simd_levels() if lv in claims]
    row = BENCH.measure(name, levels)
    for col, measured in row.items():
        claim = _claim(claims[col])
        if claim is None:
            continue
        if claim == 0.0:
            assert measured == 0.0, f"{name}: {col} promised bit-identical, differs by {measured:.1e}"
        else:
            assert measured <= 10 * claim, f"{name}: {col} differs by {measured:.1e}, published {claim:.0e}"


def test_the_measure_sees_a_one_bit_difference():
    # The comparison must not round a last-bit difference to "=".
    import numpy as np

    a = {"x": np.array([1.0, 2.0])}
    b = {"x": np.array([1.0, np.nextafter(2.0, 3.0)])}
    assert BENCH.difference(a, a) == 0.0
    assert 0.0 < BENCH.difference(a, b) < 1e-15
    assert BENCH.difference(a, {"x": np.array([1.0, 2.0, 3.0])}) == float("inf")
