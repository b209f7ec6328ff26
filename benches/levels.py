"""Speed by SIMD level (issue 9): physcore at each of its SIMD levels next to the numba peers,
on the WORKLOADS.md workloads, in one table per level.

For each level (default: all of ``physcore.simd_levels()``), a subprocess runs with
``PHYSCORE_SIMD=<level>``, so the level is fixed for the whole process, and measures there, physcore
and the numba peer alternating in the same process (WORKLOADS.md protocol: warm-up steps, then 3
blocks of S steps in a row, median; each pair is measured ``--rounds`` times from a fresh state and
the best median is kept), both on ``--threads`` threads (default 2):

* cloth 128² and 256² (§2): physcore float64 (bench_cloth.build) vs numba float64
  (peer_numba.NumbaCloth); 20 warm-up steps, S = 1000 / 250; particle-steps/s.
* N-body 4096 (§3): physcore float64 vs numba float64, physcore f32 state vs numba float32
  (bench_nbody.build, peer_numba.NumbaNBody); 5 warm-up steps, S = 40; pair interactions/s (N²).
* SPH-2D 10k, 40k, 160k (§1, "from rest"): physcore f32 vs numba float32 (bench_sph.build/measure,
  peer_numba_sph.NumbaSPH2D); 1 + 19 warm-up steps, S = 800 / 200 / 50; particle-steps/s.
* SPH-3D 97k (bench_sph's 3D variant): physcore f32 only (no numba peer), S = 20.
* The default cloth scene of ``physcore render cloth`` (``physcore.scenes.cloth()``, 40×40) for 4 s
  of simulated time, stepped exactly as the CLI steps it between frames (its default frame time
  and steps per frame, taken from physcore.cli) but with no drawing: wall time of the stepping
  alone (one untimed warm-up frame, then 3 blocks of 4 s, median), and how many times faster than
  real time that is. physcore only.

numba is not affected by PHYSCORE_SIMD: it compiles for the CPU it runs on (its native ISA, what a
user gets), in every level's run; its column is thus the same code each time, and its spread
over the runs shows the noise of the machine.

Output: one markdown table per level (workload, physcore rate, numba rate, ratio physcore/numba),
each under a line naming the CPU and the level, then a summary across levels; ``--out FILE.md``
also writes all of it to FILE.md (atomically).

Usage::

    python benches/levels.py [--levels scalar,avx2,avx512] [--only cloth,nbody,sph,render]
                             [--threads 2] [--rounds 2] [--out results.md]
    python benches/levels.py --quick     # tiny sizes: checks the script works (< 1 min)

Needs numba (``pip install ".[bench]"``) for the peers.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)  # run from anywhere

from _common import header, median_block_time, require_release, si, table  # first: sets up the environment
import numpy as np

import physcore as pc

GROUPS = ("cloth", "nbody", "sph", "render")

# Sizes and block lengths. quick: tiny, only to check that everything runs.
FULL = {
    "cloth": [(128, 1000), (256, 250)],  # (G, S)
    "nbody": [(4096, 40)],  # (N, S)
    "sph": [("10k", 72, 800), ("40k", 144, 200), ("160k", 288, 50)],  # (name, nx, S)
    "sph3d": [("97k", 46, 20)],
    "render_seconds": 4.0,
    "rounds": 2,
}
QUICK = {
    "cloth": [(16, 20)],
    "nbody": [(256, 4)],
    "sph": [("quick", 12, 5)],
    "sph3d": [("quick", 8, 3)],
    "render_seconds": 0.2,
    "rounds": 1,
}


# --------------------------------------------------------------------------------------------
# Child: one level, fixed by PHYSCORE_SIMD for the whole process
# --------------------------------------------------------------------------------------------


def _log(msg: str) -> None:
    print(f"[{os.environ.get('PHYSCORE_SIMD', '?')}] {msg}", file=sys.stderr, flush=True)


def _timed(sim, warm, steps: int) -> float:
    """Median block time after the warm-up steps `warm` (a list of step counts)."""
    for w in warm:
        sim.step(w)
    t = median_block_time(sim.step, steps)
    x = sim.positions if hasattr(sim, "positions") else sim.x  # NumbaCloth keeps its state in .x
    assert np.isfinite(np.asarray(x)).all(), "non-finite positions after timing"
    return t


def _pair(label: str, unit: str, rounds: int, physcore_rate, numba_rate=None) -> dict:
    """Best over `rounds` of (physcore, numba) measured alternately; each callable builds a fresh
    simulation and returns its rate (the median of 3 blocks)."""
    ours, theirs = [], []
    for _ in range(rounds):
        ours.append(physcore_rate())
        if numba_rate is not None:
            theirs.append(numba_rate())
    row = {"workload": label, "unit": unit, "physcore": max(ours), "numba": max(theirs) if theirs else None}
    _log(f"{label}: physcore {si(row['physcore'])}" + (f", numba {si(row['numba'])}" if theirs else "") + f" {unit}")
    return row


def _cli_stepping(fn, dt: float):
    """How ``physcore render <scene>`` steps between frames with its default options:
    {"steps_per_frame": k} or {"frame_time": t[, "substeps": k]}, and where that came from."""
    try:
        from physcore.cli import _render_settings

        class _NoOptions:  # every command-line option left at its default (None)
            def __getattr__(self, name):
                return None

        s = _render_settings(fn, _NoOptions(), dt)
        return {k: s[k] for k in ("steps_per_frame", "frame_time", "substeps") if k in s}, "physcore.cli"
    except Exception as e:  # noqa: BLE001 - the CLI's private helper changed: same rules, restated
        _log(f"physcore.cli._render_settings unusable ({e!r}); restating its rules")
    d = dict(getattr(fn, "render_defaults", None) or {})
    auto = str(d.get("substeps", "")).lower() == "auto"
    ft = d.get("frame_time")
    if "steps_per_frame" in d and not auto:
        return {"steps_per_frame": int(d["steps_per_frame"])}, "render_defaults"
    if ft is not None and auto:
        return {"frame_time": float(ft)}, "render_defaults"
    if ft is not None:
        return {"steps_per_frame": max(1, int(round(float(ft) / dt)))}, "render_defaults"
    return {"steps_per_frame": 10}, "CLI fallback"


def _render_row(threads: int, seconds: float, rounds: int) -> dict:
    fn = pc.scenes.cloth
    probe = fn(threads=threads)
    stepping, source = _cli_stepping(fn, probe.dt)
    n = int(round(math.sqrt(probe.n_particles)))
    if "steps_per_frame" in stepping:
        spf = stepping["steps_per_frame"]
        per_frame = spf * probe.dt
        how = f"{spf} steps of {probe.dt:.3g} s per frame, {probe.integrator}"
    else:
        per_frame = stepping["frame_time"]
        how = f"advance({per_frame:.4g} s, substeps={stepping.get('substeps', 'auto')}) per frame, {probe.integrator}"
    frames = max(1, int(round(seconds / per_frame)))
    del probe

    best = None
    for _ in range(rounds):
        scene = fn(threads=threads)
        if "steps_per_frame" in stepping:
            def frame(scene=scene):
                scene.step(spf)
        else:
            def frame(scene=scene):
                scene.advance(stepping["frame_time"], substeps=stepping.get("substeps", "auto"))
        frame()  # warm-up frame, untimed
        walls, sims = [], []
        for _ in range(3):
            t_sim = scene.time
            t0 = time.perf_counter()
            for _ in range(frames):
                frame()
            walls.append(time.perf_counter() - t0)
            sims.append(scene.time - t_sim)
        assert np.isfinite(scene.positions).all()
        k = sorted(range(3), key=walls.__getitem__)[1]  # the median block
        if best is None or walls[k] < best[0]:
            best = (walls[k], sims[k])
    wall, sim = best
    label = (f"cloth scene of `physcore render cloth` ({n}×{n}; {how}, from {source}): "
             f"{sim:.2f} s simulated, stepping only")
    _log(f"{label}: {wall:.3f} s wall, {sim / wall:.2f}x real time")
    return {"workload": label, "unit": "× real time", "physcore": sim / wall, "numba": None,
            "physcore_text": f"{sim / wall:.2f}× real time ({wall:.2f} s wall)"}


def child(level: str, groups, threads: int, quick: bool, rounds: int) -> dict:
    active = pc.simd_level()  # raises if PHYSCORE_SIMD is invalid here
    if active != level:
        raise SystemExit(f"PHYSCORE_SIMD={level} but physcore runs at {active!r}")
    cfg = QUICK if quick else FULL
    rounds = rounds or cfg["rounds"]
    need_numba = bool({"cloth", "nbody", "sph"} & set(groups))
    numba_info = None
    if need_numba:
        import numba

        import peer_numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        numba_info = {"version": numba.__version__, "cpu": peer_numba.numba_cpu(),
                      "threads": numba.get_num_threads()}
    rows = []

    if "cloth" in groups:
        import bench_cloth
        import peer_numba

        for g, steps in cfg["cloth"]:
            n = g * g
            rows.append(_pair(
                f"cloth {g}² (N={n:,}), f64", "particle-steps/s", rounds,
                lambda: n * steps / _timed(bench_cloth.build(g, threads), [20], steps),
                lambda: n * steps / _timed(peer_numba.NumbaCloth(g, np.float64), [20], steps)))

    if "nbody" in groups:
        import bench_nbody
        import peer_numba

        for n, steps in cfg["nbody"]:
            for prec, dtype in (("f64", np.float64), ("f32", np.float32)):
                rows.append(_pair(
                    f"N-body {n}, {prec}", "pair interactions/s", rounds,
                    lambda: n * n * steps / _timed(bench_nbody.build(n, threads, prec), [5], steps),
                    lambda: n * n * steps / _timed(peer_numba.NumbaNBody(n, dtype=dtype), [5], steps)))

    if "sph" in groups:
        import bench_sph
        import peer_numba_sph

        for name, nx, steps in cfg["sph"]:
            n = 2 * nx * nx
            rows.append(_pair(
                f"SPH-2D {name} (N={n:,}), f32", "particle-steps/s", rounds,
                lambda: bench_sph.measure(bench_sph.build(nx, "f32", threads), steps)["rate"],
                lambda: n * steps / _timed(peer_numba_sph.NumbaSPH2D(nx, threads), [1, 19], steps)))
        for name, nx, steps in cfg["sph3d"]:
            box = {}

            def rate(nx=nx, steps=steps, box=box):
                r = bench_sph.measure(bench_sph.build(nx, "f32", threads, dim=3), steps)
                box["N"] = r["N"]
                return r["rate"]

            row = _pair(f"SPH-3D {name}, f32 (no numba peer)", "particle-steps/s", rounds, rate)
            row["workload"] = f"SPH-3D {name} (N={box['N']:,}), f32 (no numba peer)"
            rows.append(row)

    if "render" in groups:
        rows.append(_render_row(threads, cfg["render_seconds"], rounds))

    return {"level": level, "header": header(threads), "numba": numba_info, "rows": rows, "rounds": rounds}


# --------------------------------------------------------------------------------------------
# Parent: one subprocess per level, tables
# --------------------------------------------------------------------------------------------


def _rate(x, unit: str) -> str:
    if x is None:
        return "—"
    return f"{x:.2f}×" if unit.startswith("×") else si(x)


def level_table(res: dict) -> str:
    body = []
    for r in res["rows"]:
        unit = r["unit"]
        ours = r.get("physcore_text") or _rate(r["physcore"], unit)
        ratio = f"{r['physcore'] / r['numba']:.2f}" if r["numba"] else "—"
        wl = r["workload"] if unit.startswith("×") else f"{r['workload']}, {unit}"
        body.append([wl, ours, _rate(r["numba"], unit), ratio])
    return table(["workload", "physcore", "numba", "ratio (physcore / numba)"], body)


def summary_table(results) -> str:
    """physcore's rate at each level, and the numba peer's spread over the runs (same code each time)."""
    levels = [r["level"] for r in results]
    names = []
    for res in results:
        for r in res["rows"]:
            if r["workload"] not in names:
                names.append(r["workload"])
    body = []
    for name in names:
        cells, nb, unit = [], [], ""
        for res in results:
            row = next((r for r in res["rows"] if r["workload"] == name), None)
            cells.append(_rate(row["physcore"], row["unit"]) if row else "—")
            if row:
                unit = row["unit"]
                if row["numba"]:
                    nb.append(row["numba"])
        spread = "—" if not nb else (f"{si(min(nb))} – {si(max(nb))}" if len(nb) > 1 else si(nb[0]))
        body.append([name if unit.startswith("×") else f"{name}, {unit}"] + cells + [spread])
    return table(["workload"] + [f"physcore {lv}" for lv in levels] + ["numba (min – max over the runs)"], body)


def _atomic_write_text(path: str, text: str) -> None:
    path = os.path.abspath(path)
    d = os.path.dirname(path)
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".levels-", suffix=".md.tmp", dir=d)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it 0600
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="See the module docstring for the workloads and protocol.")
    ap.add_argument("--levels", help="comma-separated subset of physcore.simd_levels() "
                    f"(default: all of {', '.join(pc.simd_levels())})")
    ap.add_argument("--only", help="comma-separated workload groups: " + ", ".join(GROUPS) + " (default: all)")
    ap.add_argument("--threads", type=int, default=2, help="threads for physcore and numba (default 2)")
    ap.add_argument("--rounds", type=int, default=None,
                    help="alternating physcore/numba rounds per workload, best median kept (default 2; --quick 1)")
    ap.add_argument("--quick", action="store_true", help="tiny sizes and few steps: checks that the script works")
    ap.add_argument("--out", help="also write the tables as markdown to this file (atomically)")
    ap.add_argument("--child", help=argparse.SUPPRESS)  # internal: the level this subprocess measures
    ap.add_argument("--json", help=argparse.SUPPRESS)  # internal: where the subprocess writes its rows
    args = ap.parse_args()

    groups = list(GROUPS)
    if args.only:
        groups = [g.strip() for g in args.only.split(",") if g.strip()]
        bad = [g for g in groups if g not in GROUPS]
        if bad or not groups:
            ap.error(f"--only: unknown {bad}; choose from {', '.join(GROUPS)}")
    if args.threads < 1 or (args.rounds is not None and args.rounds < 1):
        ap.error("--threads and --rounds must be >= 1")

    if args.child:
        res = child(args.child, groups, args.threads, args.quick, args.rounds)
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(res, f)
        return 0

    if not args.quick:
        require_release()
    available = pc.simd_levels()
    levels = [s.strip() for s in args.levels.split(",") if s.strip()] if args.levels else available
    bad = [lv for lv in levels if lv not in available]
    if bad or not levels:
        ap.error(f"--levels: {bad} not available on this CPU; it has {', '.join(available)}")

    command = "python benches/levels.py " + " ".join(sys.argv[1:])
    t_start = time.perf_counter()
    results, failed = [], []
    for level in levels:
        fd, jpath = tempfile.mkstemp(prefix="physcore-levels-", suffix=".json")
        os.close(fd)
        try:
            cmd = [sys.executable, os.path.abspath(__file__), "--child", level, "--json", jpath,
                   "--threads", str(args.threads), "--only", ",".join(groups)]
            if args.quick:
                cmd.append("--quick")
            if args.rounds:
                cmd += ["--rounds", str(args.rounds)]
            print(f"level {level}: measuring in a subprocess with PHYSCORE_SIMD={level} ...", file=sys.stderr, flush=True)
            rc = subprocess.run(cmd, env=dict(os.environ, PHYSCORE_SIMD=level)).returncode
            if rc != 0:
                failed.append(f"{level} (subprocess exit code {rc})")
                print(f"level {level}: FAILED (exit code {rc})", file=sys.stderr, flush=True)
                continue
            with open(jpath, encoding="utf-8") as f:
                res = json.load(f)
        finally:
            os.unlink(jpath)
        results.append(res)
        print(f"\n### SIMD level {level}\n\n{res['header']}\n\n{level_table(res)}\n", flush=True)

    nb = next((r["numba"] for r in results if r["numba"]), None)
    rounds = results[0]["rounds"] if results else "?"
    notes = [
        f"- command: `{command}`" + (" (quick: tiny sizes, not a measurement)" if args.quick else ""),
        f"- date: {datetime.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}; "
        f"{platform.platform()}, os.cpu_count() = {os.cpu_count()}, Python {platform.python_version()}",
        f"- each level measured in its own process with PHYSCORE_SIMD=<level>; physcore and numba alternate "
        f"in that process on {args.threads} threads each; rates are the best of {rounds} round(s), each the "
        f"median of 3 blocks (WORKLOADS.md protocol)",
    ]
    if nb:
        notes.append(f"- numba {nb['version']} ({nb['threads']} threads) compiles for LLVM target `{nb['cpu']}`: "
                     f"its native ISA, what a user gets, whatever PHYSCORE_SIMD says; only physcore changes level")
    notes.append("- ratio = physcore / numba at the same precision (f64 vs f64, f32 vs f32)")

    # The machine and the day in the title: the docs keep several of these pages (one a machine).
    cpu = results[0]["header"].split(" · ")[0].removeprefix("CPU: ") if results else platform.machine()
    day = datetime.datetime.now().astimezone().strftime("%Y-%m-%d")
    md = [f"# physcore speed by SIMD level: {cpu}, {day}", ""] + notes + [""]
    for res in results:
        md += [f"## SIMD level {res['level']}", "", res["header"], "", level_table(res), ""]
    if len(results) > 1:
        summary = summary_table(results)
        md += ["## Summary across levels", "", summary, ""]
        print(f"### Summary across levels\n\n{summary}\n")
    if failed:
        md += [f"FAILED levels: {', '.join(failed)}", ""]
    md.append(f"Total time of the command: {time.perf_counter() - t_start:.0f} s.")
    print("\n".join(notes))
    if failed:
        print(f"FAILED levels: {', '.join(failed)}")
    if args.out:
        _atomic_write_text(args.out, "\n".join(md) + "\n")
        print(f"wrote {args.out}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
