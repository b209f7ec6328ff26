"""Sweeps and ensembles on Dask (physcore.sweep, physcore.ensemble) and scenes through pickle.

The parallel runs are checked against the same runs in a plain loop in this process
(``client="serial"``), bit for bit: the core is deterministic for any thread count and each run's
seed derives from its parameters, so where a run happens must not change a single bit.
"""
from __future__ import annotations

import errno
import math
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import physcore as pc
from physcore import scene as scene_mod
from physcore import sweeps

distributed = pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")
cloudpickle = pytest.importorskip("cloudpickle")
# The workers are other processes: ship this module's functions by value, as cloudpickle does
# for a script's or a notebook's own functions.
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def client():
    """One LocalCluster of 2 worker processes (1 thread each) for the module: starting one
    takes seconds."""
    import logging

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as c:
        yield c


def _workers(c) -> list[str]:
    """The cluster's worker addresses, asked of the scheduler now. (``scheduler_info()`` hands
    back its cached identity, whose worker list is empty, when the query meets an OSError: a
    CI run under load compared the sweep's workers with that empty list.)"""
    return list(c.nthreads())


# ------------------------------------------------------------------------------ runs
def chain(k: float, dt: float, seed: int | None = None) -> pc.Scene:
    """A hanging spring chain, started from slightly random positions when seeded: nonlinear
    enough that any change of arithmetic shows in the last bits."""
    x = np.stack([np.arange(8) * 0.1, np.zeros(8)], axis=1)
    if seed is not None:
        x[1:] += 1e-3 * np.random.default_rng(seed).standard_normal((7, 2))
    s = pc.Scene(dim=2, dt=dt)
    s.add_particles(x, masses=0.1, pinned=[True] + [False] * 7)
    s.add(pc.Springs(np.arange(7), np.arange(1, 8), stiffness=k, damping=0.0))
    s.add(pc.Gravity([0.0, -9.81]))
    return s


def settle(scene: pc.Scene) -> dict:
    scene.step(400)
    e = scene.energy()
    return {"x_end": float(scene.positions[-1, 0]), "y_end": float(scene.positions[-1, 1]), "energy": e.total,
            "drift": scene.energy_drift()}


def results(df) -> list:
    """The columns a run's physics decides (not its wall time or worker)."""
    cols = [c for c in df.columns if c not in ("wall_s", "worker")]
    return df[cols].to_dict("records")


GRID = {"k": [500.0, 2000.0, 8000.0], "dt": [1e-4, 2e-4]}


def test_expand_grid_and_list():
    assert sweeps.expand({"a": [1, 2], "b": ["x"]}) == [{"a": 1, "b": "x"}, {"a": 2, "b": "x"}]
    assert sweeps.expand({"a": [1, 2], "b": [3, 4]})[1] == {"a": 1, "b": 4}  # the last key varies fastest
    assert sweeps.expand([{"a": 1}, {"a": 2, "b": 3}]) == [{"a": 1}, {"a": 2, "b": 3}]
    assert len(sweeps.expand({"a": np.linspace(0, 1, 5)})) == 5


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({}, "no runs"),
        ([], "no runs"),
        ({"a": []}, r"params\['a'\]: the list of values is empty"),
        ({"a": "xyz"}, r"params\['a'\]: expected a list"),
        ({"a": 3}, r"params\['a'\]: expected a list"),
        ({"not valid": [1]}, "identifiers"),
        ({"error": [1]}, "'error' is a column"),
        ([{"a": 1}, 3], r"params\[1\]: expected a dict"),
        ("a=1", "params: expected a dict of lists"),
    ],
)
def test_expand_refuses(params, match):
    with pytest.raises((ValueError, TypeError), match=match):
        sweeps.expand(params)


def test_run_seed_depends_on_parameters_not_order():
    a = sweeps.run_seed(7, {"k": 1.0, "dt": 2.0})
    assert a == sweeps.run_seed(7, {"dt": 2.0, "k": 1.0})
    assert a != sweeps.run_seed(8, {"k": 1.0, "dt": 2.0})
    assert a != sweeps.run_seed(7, {"k": 1.0, "dt": 3.0})
    assert 0 <= a < 2**63


# ------------------------------------------------------------------------------ sweep
def test_cluster_sweep_equals_plain_loop_bit_for_bit(client):
    loop = []
    for p in sweeps.expand(GRID):
        s = chain(p["k"], p["dt"], seed=sweeps.run_seed(3, p))
        loop.append({**p, **settle(s)})
    serial = pc.sweep(chain, GRID, measure=settle, client="serial", seed=3, progress=False)
    par = pc.sweep(chain, GRID, measure=settle, client=client, seed=3, progress=False)
    assert results(par) == results(serial)
    for row, want in zip(serial.to_dict("records"), loop, strict=True):
        for k, v in want.items():
            assert row[k] == v, k
    assert list(par["run"]) == list(range(6))
    assert set(par["worker"]) <= set(_workers(client))
    assert par["error"].isna().all()
    assert (par["wall_s"] > 0).all()


def test_default_local_cluster_runs_one_core_thread_per_run():
    def threads_seen(_scene):
        return {"default_threads": scene_mod.DEFAULT_THREADS.get()}

    df = pc.sweep(lambda i: None, {"i": [0, 1]}, measure=threads_seen, workers=2, progress=False)
    assert df["error"].isna().all(), df["error"].tolist()
    assert list(df["default_threads"]) == [1, 1]
    assert df["worker"].str.startswith("tcp://").all()


def test_default_threads_reach_the_core(monkeypatch):
    made = []
    real = scene_mod._core.Simulation

    def spy(dim, integrator, dt, threads=None):
        made.append(threads)
        return real(dim, integrator, dt, threads)

    monkeypatch.setattr(scene_mod._core, "Simulation", spy)
    token = scene_mod.DEFAULT_THREADS.set(1)
    try:
        s = pc.Scene(dim=2)
        pc.Scene(dim=2, threads=2)
    finally:
        scene_mod.DEFAULT_THREADS.reset(token)
    pc.Scene(dim=2)
    assert made == [1, 2, None]
    assert s.threads is None  # what the scene was given, and what its file records


def explode(k: float, dt: float) -> pc.Scene:
    if k < 0:
        raise ValueError("negative stiffness in this build")
    return chain(k, dt)


@pytest.mark.filterwarnings("ignore::physcore.StabilityWarning")  # diverges on purpose; warned before it steps
def test_diverging_and_failing_runs_are_rows(client):
    params = [{"k": 1000.0, "dt": 1e-4}, {"k": 1e9, "dt": 0.05}, {"k": -1.0, "dt": 1e-4}]
    for c in ("serial", client):
        df = pc.sweep(explode, params, measure=settle, client=c, progress=False)
        ok, diverged, failed = df.to_dict("records")
        assert ok["error"] is None or (isinstance(ok["error"], float) and math.isnan(ok["error"]))
        assert np.isfinite(ok["energy"])
        assert diverged["error"].startswith("SimulationDiverged")
        assert diverged["diverged_step"] >= 0
        assert math.isnan(diverged["energy"])  # no value where there is none
        assert failed["error"].startswith("ValueError: negative stiffness")
        # Where it was raised: the function and its line, and the file where the worker has it
        # (a Dask worker given the function by value has only "<dynamic-code>").
        line = explode.__code__.co_firstlineno + 2
        assert f"explode, line {line}" in failed["error"] or f"test_sweep.py:{line} in explode" in failed["error"]
        if c == "serial":
            assert f"test_sweep.py:{line} in explode" in failed["error"]


class Unpicklable:
    """A result that cannot travel between processes (like a generator or a lock)."""

    def __reduce__(self):
        raise TypeError("cannot pickle 'Unpicklable' object")

    def __repr__(self) -> str:
        return "Unpicklable()"


class UnpicklableNumber(float):
    """A number (kept as it is in a row) that cannot travel between processes."""

    def __reduce__(self):
        raise TypeError("cannot pickle 'UnpicklableNumber' object")


def odd_result(scene: pc.Scene) -> dict:
    k = scene.terms[0].stiffness[0]
    out = {"n": scene.n_particles}
    if k == 2000.0:
        out["odd"] = Unpicklable()
    if k == 8000.0:
        out["odd"] = UnpicklableNumber(1.5)
    return out


@pytest.mark.parametrize("steps", [None, 5])
def test_an_unpicklable_result_is_a_row_and_keeps_the_others(client, steps):
    # Issue 44: one result that did not pickle failed the whole batch's gather on Dask, raising
    # "Could not serialize object" and dropping the rows not yet written. With steps=, several
    # runs come back from one task: such a result still fails its own run alone.
    grid = {"k": [500.0, 2000.0, 8000.0, 1000.0], "dt": [1e-4, 2e-4]}
    serial = pc.sweep(chain, grid, measure=odd_result, steps=steps, client="serial", progress=False)
    par = pc.sweep(chain, grid, measure=odd_result, steps=steps, client=client, progress=False)
    assert list(par["run"]) == list(range(8)) and list(par["k"]) == list(serial["k"])
    # A value with no cell of its own is its repr on a worker as in this process.
    for df in (serial, par):
        assert list(df.loc[df["k"] == 2000.0, "odd"]) == ["Unpicklable()"] * 2
    kept = par["k"] != 8000.0
    for col in ("n", "odd"):
        assert par.loc[kept, col].fillna("-").tolist() == serial.loc[kept, col].fillna("-").tolist()
    # A number that cannot come back from its worker fails that run alone, as its row's error.
    bad = par[par["k"] == 8000.0]
    assert bad["error"].str.contains("serialize|pickle").all() and bad["n"].isna().all()
    assert par.loc[par["k"] != 8000.0, "error"].isna().all()


CALLS: list[float] = []


def counted(scene: pc.Scene) -> dict:
    CALLS.append(scene.dt)
    if len(CALLS) == STOP_AT[0]:
        raise KeyboardInterrupt
    return settle(scene)


STOP_AT = [0]


def test_interrupted_sweep_resumes_and_skips_finished_rows(tmp_path):
    out = tmp_path / "runs.csv"
    full = pc.sweep(chain, GRID, measure=settle, client="serial", seed=1, progress=False)
    CALLS.clear()
    STOP_AT[0] = 4  # Ctrl-C during the 4th run
    with pytest.raises(KeyboardInterrupt):
        pc.sweep(chain, GRID, measure=counted, client="serial", seed=1, out=out, progress=False)
    part = pd.read_csv(out)
    assert len(part) == 3 and list(part["run"]) == [0, 1, 2]
    assert not list(tmp_path.glob(".physcore-*"))  # no temporary file left behind
    CALLS.clear()
    STOP_AT[0] = 0
    resumed = pc.sweep(chain, GRID, measure=counted, client="serial", seed=1, out=out, progress=False)
    assert len(CALLS) == 3  # only the runs that had not finished
    assert results(resumed) == results(full)  # floats survive the CSV bit for bit
    CALLS.clear()
    pc.sweep(chain, GRID, measure=counted, client="serial", seed=1, out=out, progress=False)
    assert CALLS == []


def test_resume_can_retry_errors_and_keeps_other_rows(tmp_path):
    out = tmp_path / "runs.csv"
    pc.sweep(explode, {"k": [1000.0, -1.0], "dt": [1e-4]}, measure=settle, client="serial", out=out, progress=False)
    CALLS.clear()
    df = pc.sweep(explode, {"k": [1000.0, -1.0], "dt": [1e-4]}, measure=counted, client="serial", out=out,
                  retry_errors=True, progress=False)
    assert len(CALLS) == 0  # the failing build raised again before measure
    assert df["error"].iloc[1].startswith("ValueError")
    # A narrower grid on the same file: its own rows come back, the others stay in the file.
    df = pc.sweep(explode, {"k": [1000.0], "dt": [1e-4]}, measure=settle, client="serial", out=out, progress=False)
    assert len(df) == 1 and len(pd.read_csv(out)) == 2


def test_seed_reaches_build_and_reproduces_a_run():
    df = pc.sweep(chain, {"k": [1000.0], "dt": [1e-4, 2e-4]}, measure=settle, client="serial", seed=11, progress=False)
    row = df.iloc[1]
    again = settle(chain(1000.0, 2e-4, seed=int(row["seed"])))
    assert again["x_end"] == row["x_end"] and again["energy"] == row["energy"]


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"build": 3}, TypeError, "build"),
        ({"measure": None}, TypeError, "measure"),
        ({"client": 3.5}, TypeError, "client"),
        ({"workers": 0}, ValueError, "workers"),
        ({"out": "runs.parquet"}, ValueError, r"out: must end in \.csv"),
        ({"seed": -1}, ValueError, "seed"),
        ({"threads": 0}, ValueError, "threads"),
        ({"params": [{"k": 1.0, "dt": 1.0}, {"dt": 1.0, "k": 1.0}]}, ValueError, "appears twice"),
        ({"params": {"seed": [1]}, "seed": 1}, ValueError, "seed"),
        ({"progress": "yes"}, TypeError, "progress"),
    ],
)
def test_sweep_refuses_bad_arguments_before_running(kwargs, error, match):
    CALLS.clear()
    args = {"build": chain, "params": GRID, "measure": counted, "client": "serial", "progress": False, **kwargs}
    build, params = args.pop("build"), args.pop("params")
    with pytest.raises(error, match=match):
        pc.sweep(build, params, **args)
    assert CALLS == []


def test_measure_must_return_a_dict_with_new_names():
    with pytest.warns(RuntimeWarning, match="all 1 runs failed; the first: .*must return a dict"):
        df = pc.sweep(chain, [{"k": 1.0, "dt": 1e-4}], measure=lambda s: 3.0, client="serial", progress=False)
    assert "must return a dict" in df["error"][0]
    with pytest.warns(RuntimeWarning, match="all 1 runs failed"):
        df = pc.sweep(chain, [{"k": 1.0, "dt": 1e-4}], measure=lambda s: {"k": 1.0}, client="serial", progress=False)
    assert "'k' is a parameter" in df["error"][0]


def test_a_sweep_whose_every_run_failed_says_so_and_one_with_a_success_does_not():
    """A misspelt parameter fails every run: the rows' error column said so, and nothing else."""
    with pytest.warns(RuntimeWarning, match=r"all 2 runs failed; the first: TypeError: .*unexpected keyword argument 'kk'"):
        df = pc.sweep(chain, {"kk": [1.0, 2.0], "dt": [1e-4]}, measure=settle, client="serial", progress=False)
    assert df["error"].notna().all()
    df = pc.sweep(chain, [{"k": 1.0, "dt": 1e-4}, {"kk": 1.0, "dt": 1e-4}], measure=settle, client="serial",
                  progress=False)
    assert df["error"].isna().tolist() == [True, False]


@pytest.mark.parametrize("client", ["local?", "tcp://", "my cluster", "localhost"])
def test_a_client_string_that_is_no_address_is_refused_by_name(client):
    with pytest.raises(pc.InvalidInputError, match=r"^client: .* is not a scheduler address \(tcp://host:port\)"):
        pc.sweep(chain, GRID, measure=settle, client=client, progress=False)


def test_missing_dask_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r'pip install "physcore\[sweep\]"'):
        pc.sweep(chain, GRID, measure=settle, progress=False)


def test_an_unreadable_results_file_is_refused(tmp_path):
    out = tmp_path / "other.csv"
    out.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="no run_key column"):
        pc.sweep(chain, GRID, measure=settle, client="serial", out=out, progress=False)
    assert out.read_text() == "a,b\n1,2\n"


SMALL = {"k": [500.0, 2000.0], "dt": [1e-4, 2e-4]}


def _quick(scene: pc.Scene) -> dict:
    CALLS.append(scene.dt)
    scene.step(20)
    return {"y_end": float(scene.positions[-1, 1])}


@pytest.mark.parametrize("cut", [1, 10, 40])
def test_resume_of_a_file_cut_inside_its_last_row_runs_that_row_once(tmp_path, cut):
    # Issue 44, item 11: a file cut inside its last row gave a duplicate row (runs 0, 1, 2, 3, 3).
    out = tmp_path / "runs.csv"
    full = pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    text = out.read_text()
    assert text.endswith("\n")
    out.write_text(text[: len(text) - cut])  # the machine died while the last row was written
    CALLS.clear()
    resumed = pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    assert len(CALLS) == 1  # the cut row's run, once
    assert list(resumed["run"]) == [0, 1, 2, 3] and list(pd.read_csv(out)["run"]) == [0, 1, 2, 3]
    assert results(resumed) == results(full)


def test_a_damaged_row_before_the_last_is_refused_naming_file_and_row(tmp_path):
    out = tmp_path / "runs.csv"
    pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    lines = out.read_text().splitlines(keepends=True)
    lines[2] = lines[2][:20] + "\n"  # data row 2 of 4 cut short, the rest whole
    out.write_text("".join(lines))
    before = out.read_text()
    CALLS.clear()
    with pytest.raises(ValueError, match=r"out: '.*runs\.csv': data row 2 of 4 .* lacks .*damaged"):
        pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    assert CALLS == [] and out.read_text() == before


@pytest.mark.parametrize("how", ["missing", "unwritable"])
def test_an_unwritable_out_directory_fails_before_the_first_run(tmp_path, monkeypatch, how):
    if how == "missing":
        out = tmp_path / "no_such_dir" / "runs.csv"
    else:  # a read-only directory (simulated: root may write anywhere)
        out = tmp_path / "runs.csv"
        real = tempfile.mkstemp

        def mkstemp(*args, **kwargs):
            if Path(kwargs.get("dir", "")) == tmp_path:
                raise PermissionError(errno.EACCES, "Permission denied")
            return real(*args, **kwargs)

        monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    CALLS.clear()
    with pytest.raises(OSError, match=r"out: cannot create files in"):
        pc.sweep(chain, SMALL, measure=_quick, client="serial", out=out, progress=False)
    assert CALLS == []


def test_a_full_disk_keeps_every_computed_row(tmp_path, monkeypatch):
    # The disk fills after the first row is written: the sweep runs on, the file keeps its last
    # whole table, and the final error names the file and carries every row.
    out = tmp_path / "runs.csv"
    full = pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, progress=False)
    real = sweeps.atomic_write
    writes = []

    def atomic_write(path, write, **kw):
        writes.append(path)
        if len(writes) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, write, **kw)

    monkeypatch.setattr(sweeps, "atomic_write", atomic_write)
    CALLS.clear()
    with pytest.raises(OSError, match=r"out: could not write .*runs\.csv.*No space left") as ei:
        pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    assert len(CALLS) == 4  # every run ran
    assert results(ei.value.results) == results(full)
    assert list(pd.read_csv(out)["run"]) == [0]  # the last whole table written
    assert not list(tmp_path.glob(".physcore-*"))
    monkeypatch.setattr(sweeps, "atomic_write", real)  # space freed: the resume runs the 3 others
    CALLS.clear()
    resumed = pc.sweep(chain, SMALL, measure=_quick, client="serial", seed=1, out=out, progress=False)
    assert len(CALLS) == 3 and results(resumed) == results(full)


# ------------------------------------------------------------------------------ pickle
@pytest.mark.parametrize("name", ["cloth", "projectile", "kepler", "dam_break", "figure_eight", "galaxies", "cyclotron", "lorenz"])
def test_scenes_round_trip_through_pickle(name):
    kw = {"cloth": {"n": 8}, "dam_break": {"n": 10}, "galaxies": {"n": 200}}.get(name, {})
    a = pc.scenes.REGISTRY[name](**kw)
    a.step(3)
    b = pickle.loads(pickle.dumps(a))
    assert b.render_defaults == a.render_defaults
    a.step(5)
    b.step(5)
    assert b.time == a.time and b.step_count == a.step_count
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities)
    assert a.energy().total == b.energy().total
    for fa, fb in zip(a.flows, b.flows, strict=True):
        assert np.array_equal(fa.points, fb.points)


def test_grid_scene_round_trips_through_pickle():
    a = pc.scenes.ripple(n=48)
    a.step(3)
    b = pickle.loads(pickle.dumps(a))
    a.step(4)
    b.step(4)
    for ga, gb in zip(a.grids, b.grids, strict=True):
        assert np.array_equal(ga.u, gb.u)


def test_damaged_pickle_is_a_scene_file_error():
    data = pickle.dumps(pc.scenes.kepler())
    cut = data[: len(data) // 2] + data[len(data) // 2 + 10:]
    with pytest.raises((pc.SceneFileError, pickle.UnpicklingError)):
        pickle.loads(cut)
    with pytest.raises(pc.SceneFileError, match="not a readable zip"):
        scene_mod._unpickle_scene(b"not a zip at all", None)


# ------------------------------------------------------------------------------ ensembles
def test_ensemble_on_cluster_equals_serial(client):
    scene = pc.scenes.figure_eight(steps_per_period=400)
    a = pc.ensemble(scene, 5, samples=4, steps_per_sample=50, perturb=1e-6, seed=2, client="serial", progress=False)
    b = pc.ensemble(scene, 5, samples=4, steps_per_sample=50, perturb=1e-6, seed=2, client=client, progress=False)
    assert np.array_equal(a.values, b.values) and np.array_equal(a.times, b.times)
    assert a.values.shape == (5, 4, 3, 2) and list(a.members) == [0, 1, 2, 3, 4]
    assert scene.time == 0.0  # the scene itself was not stepped
    # Member 0 is the scene as given.
    ref = pickle.loads(pickle.dumps(scene))
    ref.step(150)
    assert np.array_equal(a.values[0, -1], ref.positions)
    # At t = 0 the members differ from member 0 by the perturbation alone: sqrt(6) * 1e-6 RMS.
    d0 = a.distance()[1:, 0]
    assert 1e-7 < np.median(d0) < 1e-5


def test_ensemble_spread_grows_for_chaos_not_for_a_linear_system():
    # Pythagorean three-body problem (chaotic) against a harmonic chain (linear: perturbations
    # stay the size they started, up to the ratio of the normal modes' amplitudes).
    chaos = pc.ensemble(pc.scenes.pythagorean(), 3, samples=2, steps_per_sample=500, perturb=1e-9, client="serial",
                        progress=False)
    lin = pc.Scene(dim=2, dt=1e-3)
    lin.add_particles([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], pinned=[True, False, False])
    lin.add(pc.Springs([0, 1], [1, 2], stiffness=50.0))
    calm = pc.ensemble(lin, 4, samples=4, steps_per_sample=2000, perturb=1e-9, client="serial", progress=False)
    assert chaos.spread()[-1] > 1e3 * chaos.spread()[0]
    assert calm.spread()[-1] < 20 * calm.spread()[0]


def test_ensemble_records_a_failing_member():
    def perturb(scene, rng):
        v = scene.velocities
        v[1:] += 1e200 * rng.standard_normal(v[1:].shape)
        scene.velocities = v

    # A spring chain at an explicit step about 9× its stability limit (2/ω): any motion grows by
    # two orders of magnitude a step and overflows within a few, on every SIMD level (measured:
    # at step 2 on scalar and avx2); unperturbed, the chain rests at its rest lengths, feels no
    # force and stays. (This test used huge velocities in the figure-eight, whose bodies then fly
    # apart with finite positions: physically right, since gravity at 1e198 m is 0, and no
    # divergence at all once every level computed 1/√inf as 0.)
    scene = pc.Scene(dim=2, dt=1.0)
    scene.add_particles([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    scene.add(pc.Springs([0, 1], [1, 2], stiffness=100.0))
    ens = pc.ensemble(scene, 3, samples=2, steps_per_sample=10, perturb=perturb, client="serial", progress=False)
    assert list(ens.members) == [0] and set(ens.failed) == {1, 2}
    assert ens.failed[1].startswith("SimulationDiverged")
    assert np.isfinite(ens.values).all()


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"scene": "kepler"}, TypeError, "scene"),
        ({"members": 0}, ValueError, "members"),
        ({"samples": 0}, ValueError, "samples"),
        ({"steps_per_sample": 0}, ValueError, "steps_per_sample"),
        ({"perturb": -1.0}, ValueError, "perturb"),
        ({"perturb": math.nan}, ValueError, "perturb"),
        ({"perturb": 1e308}, ValueError, r"^perturb: at most 1e150 m"),  # overflowed with numpy's bare warning
        ({"observe": 3}, TypeError, "observe"),
        ({"client": object()}, TypeError, "client"),
    ],
)
def test_ensemble_refuses_bad_arguments(kwargs, error, match):
    args = {"scene": pc.scenes.kepler(), "members": 2, "samples": 2, "steps_per_sample": 1, "client": "serial",
            "progress": False, **kwargs}
    with pytest.raises(error, match=match):
        pc.ensemble(**args)


# ------------------------------------------------------------------------------ contact sheets
def _frames(path):
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        return [(np.asarray(f.convert("RGB")).astype(int), f.info["duration"]) for f in ImageSequence.Iterator(im)]


def test_contact_sheet_tiles_each_scenes_own_gif(tmp_path, client):
    scenes = {f"e={e}": pc.scenes.kepler(e=e) for e in (0.0, 0.6, 0.9)}
    out = pc.render.contact_sheet(scenes, tmp_path / "sheet.gif", frames=12, tile=(96, 72), fps=20)
    assert all(s.time == 0.0 for s in scenes.values())  # drawn from copies
    sheet = _frames(out)
    assert sheet[0][0].shape == (2 * 72 + 2, 2 * 96 + 2, 3)  # 2 x 2 grid, 2-pixel gaps
    assert sum(d for _, d in sheet) == 600  # 12 frames at 20 fps
    # The third tile (second row, first column) is that scene's own GIF, up to the sheet's palette.
    pc.render.gif(pc.scenes.kepler(e=0.9), tmp_path / "one.gif", frames=12, size=(96, 72), fps=20)
    one = _frames(tmp_path / "one.gif")
    tile = sheet[-1][0][74:, :96]
    assert np.abs(tile[14:] - one[-1][0][14:]).mean() < 3.0  # below the label band
    assert not np.array_equal(sheet[0][0][74:, :96], sheet[0][0][:72, :96])  # the tiles differ
    # Rendered on Dask workers: the same file, byte for byte.
    again = pc.render.contact_sheet(scenes, tmp_path / "sheet2.gif", frames=12, tile=(96, 72), fps=20, client=client)
    assert again.read_bytes() == out.read_bytes()


def test_contact_sheet_labels_outside_latin1_are_drawn(tmp_path):
    out = pc.render.contact_sheet({"σ = 10": pc.scenes.kepler(), "ρ = 28": pc.scenes.kepler(e=0.2)}, tmp_path / "s.gif",
                                  frames=2, tile=(64, 48))
    assert out.stat().st_size > 0


def test_contact_sheet_holds_the_last_frame_of_a_shorter_tile(tmp_path):
    a, b = pc.scenes.kepler(), pc.scenes.kepler(e=0.3)
    b.render_defaults = {**b.render_defaults, "frames": 4}
    a.render_defaults = {**a.render_defaults, "frames": 8}
    out = pc.render.contact_sheet([a, b], tmp_path / "s.gif", tile=(64, 48), fps=10, columns=2)
    frames = _frames(out)
    assert sum(d for _, d in frames) == 800
    right = [f[:, 66:] for f, _ in frames]
    assert np.array_equal(right[-1], right[-2])  # held


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"scenes": []}, ValueError, "scenes: no scenes"),
        ({"scenes": [3]}, TypeError, r"scenes\[0\]"),
        ({"labels": ["a", "b"]}, ValueError, "labels: 2 labels for 1 scenes"),
        ({"columns": 0}, ValueError, "columns"),
        ({"tile": (8, 8)}, ValueError, "size"),
        ({"size": (64, 64)}, ValueError, "size: set by contact_sheet"),
        ({"colour": "speed"}, TypeError, "unexpected option 'colour'"),
        ({"path": "sheet.png"}, ValueError, "gif"),
    ],
)
def test_contact_sheet_refuses_bad_arguments(tmp_path, kwargs, error, match):
    args = {"scenes": [pc.scenes.kepler()], "path": tmp_path / "s.gif", "frames": 2, **kwargs}
    with pytest.raises(error, match=match):
        pc.render.contact_sheet(args.pop("scenes"), args.pop("path"), **args)
    assert not (tmp_path / "s.gif").exists()


@pytest.mark.filterwarnings("ignore::physcore.StabilityWarning")  # diverges on purpose; warned before it steps
def test_contact_sheet_tile_that_diverges_writes_nothing(tmp_path):
    with pytest.raises(pc.SimulationDiverged):
        pc.render.contact_sheet([chain(1000.0, 1e-4), chain(1e9, 0.05)], tmp_path / "s.gif", frames=3, steps_per_frame=50)
    assert list(tmp_path.iterdir()) == []


def test_ensemble_members_run_as_one_batch_give_the_bits_of_each_alone():
    """The serial ensemble steps its members together as one Batch; every member's samples are
    the bits of that member run alone (the one-by-one path, ``_run_member``), and a member that
    diverges fails alone."""
    import pickle

    from physcore.sweeps import _run_member

    scene = pc.scenes.spring_chain()
    ens = pc.ensemble(scene, 5, samples=4, steps_per_sample=50, perturb=1e-3, client="serial", progress=False)
    data = pickle.dumps(scene)
    for k, m in enumerate(ens.members):
        times, values = _run_member(data, int(m), 0, 1e-3, None, 4, 50, 1)
        assert np.array_equal(ens.values[k], values) and np.array_equal(ens.times, times)

    def blow_up(s, rng):  # member 3 only: a step far past the chain's stability limit
        if rng.bit_generator.state == np.random.default_rng([0, 3]).bit_generator.state:
            s.dt = 1.0

    ens = pc.ensemble(scene, 5, samples=3, steps_per_sample=50, perturb=blow_up, client="serial", progress=False)
    assert list(ens.members) == [0, 1, 2, 4] and list(ens.failed) == [3] and "diverged" in ens.failed[3]


# ------------------------------------------------------------------------------ sweeps that step (steps=)
BUILDS: list[tuple] = []


class Wrapped:
    """Not a Scene, but steps like one: such a run is stepped alone, in the same task."""

    def __init__(self, scene: pc.Scene) -> None:
        self.scene = scene

    def step(self, n: int) -> None:
        self.scene.step(n)


def varied(k: float, dt: float, n: int, seed: int | None = None):
    """A chain of `n` particles (`n` changes the structure); k < 0 raises, n == 3 is wrapped."""
    BUILDS.append((k, dt, n))
    if k < 0:
        raise ValueError("negative stiffness in this build")
    x = np.stack([np.arange(n) * 0.1, np.zeros(n)], axis=1)
    if seed is not None:
        x[1:] += 1e-3 * np.random.default_rng(seed).standard_normal((n - 1, 2))
    s = pc.Scene(dim=2, dt=dt)
    s.add_particles(x, masses=0.1, pinned=[True] + [False] * (n - 1))
    s.add(pc.Springs(np.arange(n - 1), np.arange(1, n), stiffness=k, damping=0.0))
    s.add(pc.Gravity([0.0, -9.81]))
    return Wrapped(s) if n == 3 else s


STEPS = 300


def looked(scene) -> dict:
    s = getattr(scene, "scene", scene)
    return {"x_end": float(s.positions[-1, 0]), "y_end": float(s.positions[-1, 1]), "energy": s.energy().total,
            "drift": s.energy_drift(), "steps_taken": s.step_count, "t": s.time}


def stepped_then_looked(scene) -> dict:
    scene.step(STEPS)
    return looked(scene)


def steps_for(scene) -> int:
    """A fixed duration, 0.03 s, in each run's own dt."""
    return round(0.03 / getattr(scene, "scene", scene).dt)


def stepped_for_then_looked(scene) -> dict:
    scene.step(steps_for(scene))
    return looked(scene)


# Three structures (8, 5 and 3 particles, the last not a Scene), a diverging run among the 8s, two
# dt (so two step counts under steps_for), a build that raises.
VARIED = ([{"k": k, "dt": dt, "n": 8} for k in (500.0, 2000.0, 8000.0) for dt in (1e-4, 2e-4)]
          + [{"k": 1e12, "dt": 5e-4, "n": 8}, {"k": -1.0, "dt": 1e-4, "n": 8}]
          + [{"k": k, "dt": 1e-4, "n": 5} for k in (700.0, 900.0, 1100.0)]
          + [{"k": 600.0, "dt": 1e-4, "n": 3}, {"k": 1200.0, "dt": 1e-4, "n": 8}])


def physics(df):
    """The columns a run's physics decides, as a frame (NaN where a run failed)."""
    return df[[c for c in df.columns if c not in ("wall_s", "worker")]]


@pytest.mark.filterwarnings("ignore::physcore.StabilityWarning")  # diverges on purpose; warned before it steps
@pytest.mark.parametrize("how", ["int", "callable"])
@pytest.mark.parametrize("where", ["serial", "cluster"])
def test_a_sweep_that_steps_gives_the_rows_of_measure_stepping_alone(how, where, request, monkeypatch):
    """``steps=`` (the sweep builds, steps the scenes of one structure together as a Batch, then
    measures) gives every row, bit for bit, that a `measure` stepping the scene itself gives:
    the results, the error of the diverging run and of the build that raises, the rest."""
    c = "serial" if where == "serial" else request.getfixturevalue("client")
    steps, alone = (STEPS, stepped_then_looked) if how == "int" else (steps_for, stepped_for_then_looked)
    sizes: list[int] = []
    real = pc.Batch.step

    def spy(self, n=1):
        sizes.append(len(self))
        return real(self, n)

    monkeypatch.setattr(pc.Batch, "step", spy)
    ref = pc.sweep(varied, VARIED, measure=alone, client=c, seed=5, progress=False)
    assert sizes == []
    got = pc.sweep(varied, VARIED, measure=looked, steps=steps, client=c, seed=5, progress=False)
    pd.testing.assert_frame_equal(physics(got), physics(ref), check_exact=True)
    assert got["error"].notna().sum() == 2
    assert got.loc[6, "error"].startswith("SimulationDiverged") and got.loc[6, "diverged_step"] >= 0
    assert got.loc[7, "error"].startswith("ValueError: negative stiffness")
    assert (got.loc[got["error"].isna(), "steps_taken"] > 0).all()
    assert (got["wall_s"] > 0).all()
    if where == "serial":
        # Batches in this process: with steps=300, the eight 8-particle runs that built and the
        # three 5-particle runs; with a duration, one batch per (structure, step count): 4 runs
        # at dt 1e-4, 3 at 2e-4 and the 5-particle ones (the one at 5e-4 and the wrapped
        # 3-particle run step alone).
        assert sorted(sizes) == ([3, 8] if how == "int" else [3, 3, 4])
        assert set(got["worker"]) == set(ref["worker"])
    else:
        assert set(got["worker"]) <= set(_workers(c))


@pytest.mark.filterwarnings("ignore::physcore.StabilityWarning")  # diverges on purpose; warned before it steps
def test_a_sweep_that_steps_resumes_running_only_the_missing_runs(tmp_path):
    out = tmp_path / "runs.csv"
    ref = pc.sweep(varied, VARIED, measure=stepped_then_looked, client="serial", seed=5, progress=False)
    pc.sweep(varied, VARIED, measure=looked, steps=STEPS, client="serial", seed=5, out=out, progress=False)
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(lines[:5]))  # the header and the first four rows
    BUILDS.clear()
    got = pc.sweep(varied, VARIED, measure=looked, steps=STEPS, client="serial", seed=5, out=out, progress=False)
    assert len(BUILDS) == len(VARIED) - 4
    pd.testing.assert_frame_equal(physics(got), physics(ref), check_exact=True)
    BUILDS.clear()
    pc.sweep(varied, VARIED, measure=looked, steps=STEPS, client="serial", seed=5, out=out, retry_errors=True, progress=False)
    assert len(BUILDS) == 2  # the diverged run and the failing build, again


@pytest.mark.parametrize(("steps", "error"), [(-1, ValueError), (2**63, ValueError), (2.0, TypeError), (True, TypeError),
                                              ("300", TypeError), (np.float64(3.0), TypeError)])
def test_bad_steps_are_refused_by_name_before_anything_runs(steps, error):
    BUILDS.clear()
    with pytest.raises(error, match="^steps: ") as ei:
        pc.sweep(varied, VARIED, measure=looked, steps=steps, client="serial", progress=False)
    assert isinstance(ei.value, pc.PhyscoreError)
    assert BUILDS == []


def test_a_steps_callable_that_fails_fails_its_own_run():
    def steps(scene):
        if scene.n_particles == 5:
            return 2.5
        return 10

    df = pc.sweep(varied, VARIED[:2] + VARIED[8:10], measure=looked, steps=steps, client="serial", progress=False)
    assert df["error"].isna().tolist() == [True, True, False, False]
    assert df.loc[2, "error"].startswith("InvalidTypeError: steps: expected an int, got float 2.5")
    assert list(df.loc[:1, "steps_taken"]) == [10, 10]


def counted_look(scene) -> dict:
    CALLS.append(getattr(scene, "scene", scene).dt)
    if len(CALLS) == STOP_AT[0]:
        raise KeyboardInterrupt
    return looked(scene)


@pytest.mark.filterwarnings("ignore::physcore.StabilityWarning")  # diverges on purpose; warned before it steps
def test_an_interrupted_sweep_that_steps_keeps_the_rows_made_and_resumes(tmp_path):
    # In this process the rows of a sweep with steps= arrive one by one: Ctrl-C during the 4th
    # run's measure keeps the three before it in `out`, and the resume runs only the others.
    out = tmp_path / "runs.csv"
    ref = pc.sweep(varied, VARIED, measure=stepped_then_looked, client="serial", seed=5, progress=False)
    CALLS.clear()
    STOP_AT[0] = 4
    with pytest.raises(KeyboardInterrupt):
        pc.sweep(varied, VARIED, measure=counted_look, steps=STEPS, client="serial", seed=5, out=out, progress=False)
    assert list(pd.read_csv(out)["run"]) == [0, 1, 2]
    CALLS.clear()
    STOP_AT[0] = 0
    BUILDS.clear()
    got = pc.sweep(varied, VARIED, measure=counted_look, steps=STEPS, client="serial", seed=5, out=out, progress=False)
    assert len(BUILDS) == len(VARIED) - 3
    pd.testing.assert_frame_equal(physics(got), physics(ref), check_exact=True)
