"""The granular column collapse of benches/grains/collapse.py, at one aspect ratio and a small size
(issue 44, item 16): with rolling resistance a 2D column of discs runs out as far as the planar
experiments say, (L∞ − L0)/L0 = λ a with λ between 1.2 and 1.8 (Lube et al. 2005; Lajeunesse,
Monnier & Homsy 2005: see docs/granular.md); without it, further.

Honest tolerance: the band 1.2–1.8 is the experiments' own spread, and is the whole tolerance.
These columns are small (10 grains wide, about 110 grains, a ≈ 1.2), so one random column
scatters a lot: measured over seeds 1–6, λ = 1.16–1.64 at μ_r = 0.15 (mean 1.41) and 1.48–2.48
without rolling resistance (mean 2.21, at 30 √(H0/g)); the test takes the mean of seeds 1–3
(measured 1.49 and 2.29). docs/granular.md has the 20-grain-wide columns at a = 0.5–3.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[2] / "benches" / "grains" / "collapse.py"


def _load():
    spec = importlib.util.spec_from_file_location("collapse_bench", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules[spec.name]
        raise
    return mod


def test_a_column_with_rolling_friction_runs_out_as_far_as_the_experiments():
    bench = _load()
    rolling = [bench.collapse(1.0, 0.15, width=10, seed=seed) for seed in (1, 2, 3)]
    lam = np.mean([r["runout"] / r["a"] for r in rolling])
    assert all(1.0 < r["a"] < 1.4 for r in rolling), [r["a"] for r in rolling]
    assert 1.2 <= lam <= 1.8, lam
    # It comes to rest (the front stops within 10 √(H0/g)), with at most a few grains apart.
    assert all(r["rested"] and r["t_rest"] < 10.0 and r["strays"] <= 3 for r in rolling), rolling
    # Without rolling resistance the deposit overshoots the band (the λ ≈ 2.1–2.2), and
    # it does not stop: grains keep rolling off its front.
    free = [bench.collapse(1.0, 0.0, width=10, seed=seed, max_tau=10) for seed in (1, 2, 3)]
    assert np.mean([r["runout"] / r["a"] for r in free]) > 1.8
    assert not any(r["rested"] for r in free)
