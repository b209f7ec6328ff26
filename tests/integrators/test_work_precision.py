"""Smoke test of benches/integrators/work_precision.py: its --quick sweep runs in-process (a few seconds, any
build), writes the CSV, markdown and PNG, covers every integrator on every problem, and shows the
expected convergence orders on the circular Kepler orbit."""
from __future__ import annotations

import csv
import importlib.util
import math
import sys
from pathlib import Path

import physcore as pc

SCRIPT = Path(__file__).resolve().parents[2] / "benches" / "integrators" / "work_precision.py"
PROBLEMS = ("kepler_e0", "kepler_e0.5", "kepler_e0.9", "chain", "cloth")


def _load():
    spec = importlib.util.spec_from_file_location("work_precision", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up while the class is built
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules[spec.name]
        raise
    return mod


def _order(rows, integrator):
    """Convergence order of the position error between the two smallest dts (float64)."""
    pts = sorted((float(r["dt"]), float(r["position_error"])) for r in rows
                 if r["problem"] == "kepler_e0" and r["integrator"] == integrator
                 and r["precision"] == "f64" and r["status"] == "ok")
    assert len(pts) >= 2, f"{integrator}: fewer than two runs on kepler_e0"
    (dt1, e1), (dt2, e2) = pts[0], pts[1]
    assert 0 < e1 < e2, f"{integrator}: error does not decrease with dt: {pts}"
    return math.log(e2 / e1) / math.log(dt2 / dt1)


def test_quick_sweep(tmp_path, capsys):
    wp = _load()
    assert wp.main(["--quick", "--out", str(tmp_path)]) == 0
    files = [tmp_path / f"work_precision.{ext}" for ext in ("csv", "md", "png")]
    for f in files:
        assert f.is_file() and f.stat().st_size > 0, f
    assert files[2].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob("*.tmp")), "temporary files left behind"

    with open(files[0], newline="") as f:
        rows = list(csv.DictReader(f))
    names = [d["name"] for d in pc.INTEGRATORS]
    for problem in PROBLEMS:
        # The Wisdom–Holman map steps planetary systems only: the Kepler problems.
        for name in [n for n in names if n != "wisdom_holman" or problem.startswith("kepler")]:
            mine = [r for r in rows if r["problem"] == problem and r["integrator"] == name and r["status"] != "reference"]
            assert mine, f"no run of {name} on {problem}"
            assert all(int(r["force_evals"]) > 0 and float(r["wall_s"]) >= 0 for r in mine)
            if name == "dopri5":
                assert all(r["rtol"] for r in mine)
            else:
                assert not any(r["rtol"] for r in mine)
        if problem in ("chain", "cloth"):
            assert any(r["problem"] == problem and r["status"] == "reference" for r in rows)
    if wp.has_precision():
        assert {r["precision"] for r in rows} == {"f64", "f32"}

    # The quick Kepler e = 0 sweep (dt = P/64, P/128, P/256, 2 orbits) is in the asymptotic
    # regime: Verlet converges at order 2, RK4 at order 4 (phase error of a circular orbit).
    assert _order(rows, "verlet") >= 1.5
    assert _order(rows, "rk4") >= 3.0

    md = files[1].read_text(encoding="utf-8")
    for problem in PROBLEMS:
        assert f"## {problem}" in md
    assert "| integrator |" in md
    assert md.strip() in capsys.readouterr().out
