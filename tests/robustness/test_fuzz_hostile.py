"""Hostile-argument fuzzing of the public calls (issue 17): the Scene constructor and its add_*
methods, the terms, physcore.scenes.*, render.gif and the CLI's main(argv).

Every call gets one hostile argument (NaN, infinities, subnormals, float64's extremes, ints beyond
float64 or int64, bools, strings, None, numpy scalars and arrays) and must either succeed with a
usable result or raise the documented error, TypeError or InvalidInputError, whose message names
that argument, with nothing changed. Anything else (OverflowError, ZeroDivisionError, a
RuntimeWarning, which ``filterwarnings = error`` turns into an exception, a traceback from the
CLI) fails. The fast versions run in the default suite (FAST examples each); the ``_long``
versions run the same properties with LONG examples under ``pytest -m fuzz``.

Valid values that are merely large (10**7 particles, 2**40 steps per frame) would make a test
slow rather than find a bug, so each argument draws its valid values from a cheap range, and the
memory limit is lowered while fuzzing so that the refusal path is exercised instead.
"""
from __future__ import annotations

import inspect
import io
import math
import re
import tempfile
import warnings
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import physcore as pc
from physcore import _check, render
from physcore.cli import main
from physcore.fluids import lattice

FAST = 300  # examples per property in the default run (about 5 s in all)
LONG = 5000  # examples per property under -m fuzz (about a minute and a half in all)
TINY = float(np.finfo(np.float64).tiny)

SPECIAL_FLOATS = [0.0, -0.0, 5e-324, 1e-310, TINY, 1e-300, 1e-100, 1e100, 1e200, 1e300, 1e308,
                  float(np.finfo(np.float64).max), -1.0, -1e308, math.nan, math.inf, -math.inf]
HOSTILE_INTS = [-(2**64), -1, 0, 1, 2, 3, 10**12, 2**53 + 1, 2**63, 2**64, 10**400]
NOT_NUMBERS = [True, False, None, "0.5", "", "nan", b"1", [1.0], (1.0, 2.0), {}, object(),
               np.bool_(True), np.array([0.5, 1.0]), 1 + 2j]
NUMPY_SCALARS = [np.float32(3e38), np.float64(np.nan), np.int64(2**62), np.float16(65504.0),
                 np.uint64(2**64 - 1), np.array(0.5), np.longdouble(1e300)]

#: Any hostile scalar.
hostile = st.one_of(
    st.floats(),
    st.sampled_from(SPECIAL_FLOATS),
    st.sampled_from(HOSTILE_INTS),
    st.sampled_from(NOT_NUMBERS),
    st.sampled_from(NUMPY_SCALARS),
)
#: Hostile where a count of steps is meant: no valid value above 3 (2**40 steps would just be slow).
hostile_steps = st.one_of(
    st.sampled_from([-(2**64), -1, 0, 1, 2, 2**53 + 1, 2**63, 2**64, 10**400]),
    st.sampled_from(NOT_NUMBERS),
    st.floats(),
)


def _row(dim: int):
    return st.lists(st.one_of(st.floats(), st.sampled_from(SPECIAL_FLOATS)), min_size=dim, max_size=dim)


#: Hostile where an (N, dim) array is meant.
hostile_points = st.one_of(
    hostile,
    st.lists(_row(2), min_size=0, max_size=3),
    st.lists(_row(3), min_size=1, max_size=2),
    st.sampled_from([[[1.0, 2.0], [3.0]], [["a", "b"]], np.zeros((2, 2), dtype=bool), np.zeros((2, 2), dtype=complex),
                     np.zeros((2, 2, 2)), [[10**400, 0]], np.array([[np.nan, 0.0]]), np.zeros((0, 2))]),
)


def _names(exc: BaseException, arg: str) -> bool:
    return re.search(rf"\b{re.escape(arg)}\b", str(exc)) is not None


def _refused_by_name(exc: BaseException, arg: str) -> None:
    assert isinstance(exc, (TypeError, pc.InvalidInputError)), f"{type(exc).__name__}: {exc}"
    assert _names(exc, arg), f"{type(exc).__name__} does not name {arg!r}: {exc}"


@contextmanager
def _memory_limit(nbytes: int):
    """Lower physcore's memory limit: large valid requests are refused quickly instead of built."""
    with mock.patch.object(_check, "memory_limit", lambda: nbytes):
        yield


def _state(s: pc.Scene):
    return (s.n_particles, s.positions.tobytes(), s.velocities.tobytes(), s.masses.tobytes(), s.pinned.tobytes(),
            tuple(t.name for t in s.terms), len(s.planes), s.dt, s.step_count, s.time, s.integrator)


def _call(arg: str, fn):
    """``fn()``'s result, or None when it raised the documented error naming ``arg``."""
    try:
        return fn()
    except (TypeError, ValueError) as e:
        _refused_by_name(e, arg)
        return None


def _books_are_honest(s: pc.Scene) -> None:
    """After a step (or a reported divergence): books beyond float64 give a NaN drift, never 0."""
    try:
        with warnings.catch_warnings():
            # A valid but extreme value (G = 5.7e6) may put dt past the stability limit, which
            # the step warns of: the books must still be honest.
            warnings.simplefilter("ignore", pc.StabilityWarning)
            s.step(1)
    except pc.SimulationDiverged:
        return
    e = s.energy()
    d = s.energy_drift()
    if not math.isfinite(e.total):
        assert math.isnan(d), f"drift {d} for books {e}"


# --------------------------------------------------------------------------- Scene(...)
CTOR_ARGS = ["dim", "integrator", "dt", "rtol", "atol", "precision", "threads"]


def _ctor_case():
    def safe(arg, value):
        # A valid thread count above 3 would start that many threads: slow, not hostile.
        if arg == "threads" and isinstance(value, (int, np.integer)) and not isinstance(value, bool) and 3 < value <= 65535:
            value = -value
        return arg, value

    return st.tuples(st.sampled_from(CTOR_ARGS), hostile).map(lambda t: safe(*t))


def _check_ctor(case) -> str:
    """"built" (and stepped with honest books) or "refused" (by name; see `_call`)."""
    arg, value = case
    with warnings.catch_warnings():
        # A valid option of another integrator (rtol=0.5 with verlet) is kept, and warned of.
        warnings.simplefilter("ignore", pc.UnusedOptionWarning)
        s = _call(arg, lambda: pc.Scene(2, **{arg: value}) if arg != "dim" else pc.Scene(value))
    if s is None:
        return "refused"
    x = np.eye(2, s.dim)
    s.add_particles(x, x[::-1])
    s.add(pc.Springs([0], [1], stiffness=1.0))
    _books_are_honest(s)
    return "built"


@settings(max_examples=FAST)
@given(_ctor_case())
def test_fuzz_scene_constructor(case):
    assert _check_ctor(case) in ("built", "refused")


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_ctor_case())
def test_fuzz_scene_constructor_long(case):
    assert _check_ctor(case) in ("built", "refused")


# --------------------------------------------------------------------------- add_particles
def _base_scene() -> pc.Scene:
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.5], [0.0, 0.0]], masses=[1.0, 2.0], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=10.0))
    s.add(pc.Gravity([0.0, -9.81]))
    s.step(2)
    return s


ADD_ARGS = {
    "positions": hostile_points,
    "velocities": hostile_points,
    "masses": st.one_of(hostile, st.lists(st.one_of(st.floats(), st.sampled_from(SPECIAL_FLOATS)), min_size=2, max_size=2)),
    "pinned": st.one_of(hostile, st.sampled_from([[True, 1], np.array([1, 0]), [True], [[True, False]]])),
}
_add_case = st.sampled_from(sorted(ADD_ARGS)).flatmap(lambda a: st.tuples(st.just(a), ADD_ARGS[a]))


def _check_add_particles(case):
    """(added, scene state before, after); an added call's books are checked here."""
    arg, value = case
    s = _base_scene()
    before = _state(s)
    kwargs = {"positions": [[2.0, 0.0], [3.0, 1.0]], arg: value}
    added = _call(arg, lambda: s.add_particles(**kwargs)) is not None
    if added:
        _books_are_honest(s)
    return added, before, _state(s)


@settings(max_examples=FAST)
@given(_add_case)
def test_fuzz_add_particles(case):
    added, before, after = _check_add_particles(case)
    assert added or after == before, "refused, but the scene changed"


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_add_case)
def test_fuzz_add_particles_long(case):
    added, before, after = _check_add_particles(case)
    assert added or after == before, "refused, but the scene changed"


# --------------------------------------------------------------------------- terms and add()
vector = st.one_of(hostile, _row(2), _row(3), st.sampled_from([[1e308, 1e308], [0.0, 0.0], ["1", "2"]]))
index = st.one_of(hostile, st.sampled_from([[0], [1], [2], [-1], [2**63], [0.5], [[0]], [0, 1]]))
TERMS = {
    "g": (lambda v: pc.Gravity(v), vector),
    "coefficient": (lambda v: pc.Drag(v), hostile),
    "G": (lambda v: pc.PairwiseGravity(G=v), hostile),
    "softening": (lambda v: pc.PairwiseGravity(softening=v), hostile),
    "i": (lambda v: pc.Springs(v, [1]), index),
    "j": (lambda v: pc.Springs([0], v), index),
    "stiffness": (lambda v: pc.Springs([0], [1], stiffness=v), hostile),
    "damping": (lambda v: pc.Springs([0], [1], damping=v), hostile),
    "rest_length": (lambda v: pc.Springs([0], [1], rest_length=v), hostile),
    "point": (lambda v: pc.Plane(v, [0.0, 1.0]), vector),
    "normal": (lambda v: pc.Plane([0.0, 0.0], v), vector),
    "restitution": (lambda v: pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=v), hostile),
    "friction": (lambda v: pc.Box([0.0, 0.0], [1.0, 1.0], friction=v), hostile),
    "upper": (lambda v: pc.Box([0.0, 0.0], v), vector),
}
_term_case = st.sampled_from(sorted(TERMS)).flatmap(lambda a: st.tuples(st.just(a), TERMS[a][1]))


def _check_term(case):
    """(added, scene state before, after); a term refused when built never meets a scene."""
    arg, value = case
    s = _base_scene()
    before = _state(s)
    term = _call(arg, lambda: TERMS[arg][0](value))
    # add() checks what depends on the scene (dimension, indices), naming the argument.
    added = term is not None and _call(arg, lambda: s.add(term)) is not None
    if added:
        _books_are_honest(s)
    return added, before, _state(s)


@settings(max_examples=FAST)
@given(_term_case)
def test_fuzz_terms_and_add(case):
    added, before, after = _check_term(case)
    assert added or after == before, "refused, but the scene changed"


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_term_case)
def test_fuzz_terms_and_add_long(case):
    added, before, after = _check_term(case)
    assert added or after == before, "refused, but the scene changed"


# --------------------------------------------------------------------------- add_fluid
FLUID_ARGS = {
    "positions": hostile_points,
    "spacing": hostile,
    "velocities": hostile_points,
    "density": hostile,
    "sound_speed": hostile,
    "alpha": hostile,
    "smoothing": hostile,
    "kernel": st.one_of(hostile, st.sampled_from(["wendland_c2", "gaussian"])),
    "gamma": hostile,
    "clamp_pressure": hostile,
    "mass": hostile,
    "boundary": hostile_points,
    "boundary_volume": st.one_of(hostile, st.sampled_from(["akinci", "mirror", np.full(4, 1e308), np.zeros(4)])),
    "pass_precision": st.one_of(hostile, st.sampled_from(["f32", "f16", np.array(["f32"])])),
    "name": st.one_of(hostile, st.sampled_from(["water", "gravity"])),
}
_fluid_case = st.sampled_from(sorted(FLUID_ARGS)).flatmap(lambda a: st.tuples(st.just(a), FLUID_ARGS[a]))


def _check_add_fluid(case):
    arg, value = case
    s = _base_scene()
    before = _state(s)
    kwargs = {"spacing": 0.1, "boundary": [[0.0, -0.1], [0.1, -0.1], [0.2, -0.1], [0.3, -0.1]], arg: value}
    positions = kwargs.pop("positions", lattice([0.0, 0.0], [0.4, 0.2], 0.1))
    with _memory_limit(64 << 20):
        added = _call(arg, lambda: s.add_fluid(positions, **kwargs)) is not None
    if added:
        assert s.dt >= TINY
        _books_are_honest(s)  # huge masses may overflow the books: reported, not refused
    return added, before, _state(s)


@settings(max_examples=FAST)
@given(_fluid_case)
def test_fuzz_add_fluid(case):
    added, before, after = _check_add_fluid(case)
    assert added or after == before, "refused, but the scene changed"


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_fluid_case)
def test_fuzz_add_fluid_long(case):
    added, before, after = _check_add_fluid(case)
    assert added or after == before, "refused, but the scene changed"


# --------------------------------------------------------------------------- physcore.scenes
#: Small but valid base arguments, so a hostile value that is accepted builds quickly.
SCENE_BASE = {"dam_break": {"n": 4}, "floating": {"n": 4}, "drop": {"n": 10}, "droplets": {"n": 40, "drops": 1}, "crown": {"n": 70}, "cloth": {"n": 6}, "ripple": {"n": 16}, "double_slit": {"n": 64}, "turing": {"n": 16}}
pair = st.one_of(hostile, st.tuples(hostile, hostile), st.sampled_from([(4.0, 3.0, 1.0), "4,3", [1e308, 1e308]]))


def _scene_value(fn: str, arg: str):
    if arg in ("n", "steps_per_orbit"):
        return st.one_of(st.sampled_from(HOSTILE_INTS), st.sampled_from(NOT_NUMBERS), st.floats())
    if arg == "threads":
        return st.one_of(st.sampled_from([-1, 0, 1, 2, 65536, 2**64, 10**400]), st.sampled_from(NOT_NUMBERS))
    if arg == "tank":
        return pair
    if arg in ("integrator", "pin", "precision", "pass_precision", "kernel"):
        return st.one_of(hostile, st.sampled_from(["rk4", "leapfrog", "corners", "f32", "wendland_c2"]))
    return hostile


def _scene_args():
    out = []
    for name, fn in pc.scenes.REGISTRY.items():
        out += [(name, a) for a in inspect.signature(fn).parameters]
    return out


_scene_case = st.sampled_from(_scene_args()).flatmap(lambda t: st.tuples(st.just(t[0]), st.just(t[1]), _scene_value(*t)))


def _check_scene_function(case):
    fn, arg, value = case
    kwargs = {**SCENE_BASE.get(fn, {}), arg: value}
    with _memory_limit(16 << 20):
        scene = _call(arg, lambda: pc.scenes.REGISTRY[fn](**kwargs))
    if scene is None:
        return True  # refused by name (see `_call`)
    e = scene.energy()
    assert math.isfinite(e.total) and math.isfinite(e.kinetic), f"{fn}({arg}={value!r}): books {e}"
    return scene.dt >= TINY and math.isfinite(scene.dt)


@settings(max_examples=FAST)
@given(_scene_case)
@example(("xpbd_cloth", "size", 1e-300))  # found by this fuzz: NaN rest angles, refused as rest_angle
@example(("xpbd_cloth", "size", 1e100))
@example(("jelly", "damping", 3.2510364852110764e303))  # found by this fuzz: dt underflowed
@example(("galton_board", "drag", 2.921251344151264e303))  # found by this fuzz: dt underflowed
@example(("newtons_cradle", "law", np.array([0.5, 1.0])))  # found by this fuzz: ValueError, not naming law
@example(("shape_matched_boxes", "mass", 1.6190612999995960e303))  # found by this fuzz: refused as dt, substeps
@example(("galton_board", "balls", 10**400))  # found by this fuzz: OverflowError
@example(("droplets", "speed", 4.24e151))  # found by this fuzz: refused as sound_speed
@example(("crown", "tank", (1.0, 2.0)))  # found by this fuzz: refused as n, pool, radius
@example(("crown", "adhesion", 2.8611174857570283e307))  # found by this fuzz: refused without naming adhesion
@example(("dam_break", "integrator", np.array([0.5, 1.0])))  # found by this fuzz: ValueError of numpy's, not naming it
@example(("droplets", "surface_tension", 3.505501612981517e303))  # found by this fuzz: refused as sound_speed
@example(("vortex_street", "n", 10**400))  # found by this fuzz: OverflowError
@example(("pyramid", "ball_density", 2.1319675335445308e306))  # found by this fuzz: books inf (gravity's potential)
def test_fuzz_scene_functions(case):
    assert _check_scene_function(case), f"{case}: the scene's dt is not a usable step"


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_scene_case)
def test_fuzz_scene_functions_long(case):
    assert _check_scene_function(case), f"{case}: the scene's dt is not a usable step"


# --------------------------------------------------------------------------- render.gif
GIF_ARGS = {
    "frames": st.one_of(st.sampled_from([-1, 0, 1, 2, 10**12, 2**64, 10**400]), st.sampled_from(NOT_NUMBERS), st.floats()),
    "steps_per_frame": hostile_steps,
    "frame_time": st.one_of(st.floats(max_value=0.1), st.sampled_from(NOT_NUMBERS), st.sampled_from([10**400, 1e300])),
    "substeps": st.one_of(hostile_steps, st.sampled_from(["auto", "fixed"])),
    "fps": hostile,
    "size": st.one_of(hostile, st.tuples(st.sampled_from(HOSTILE_INTS + [16, 40]), st.sampled_from(HOSTILE_INTS + [16, 40]))),
    "color_by": st.one_of(hostile, st.sampled_from(["speed", "pressure", "none", "mass"])),
    "colorbar": hostile,
    "radius": st.one_of(st.sampled_from(HOSTILE_INTS + [200, 201]), st.sampled_from(NOT_NUMBERS)),
    "springs": hostile,
    "view": st.one_of(hostile, st.tuples(hostile, hostile)),
    "progress": st.sampled_from(NOT_NUMBERS[2:] + [False]),
    "path": st.sampled_from([None, 42, "x.png", "missing/x.gif", "", ".", "x.GIF"]),
}
_gif_case = st.sampled_from(sorted(GIF_ARGS)).flatmap(lambda a: st.tuples(st.just(a), GIF_ARGS[a]))


def _pendulum() -> pc.Scene:
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=50.0))
    s.add(pc.Gravity([0.0, -9.81]))
    return s


def _check_gif(case):
    arg, value = case
    s = _pendulum()
    with tempfile.TemporaryDirectory() as tmp:
        kwargs = {"frames": 2, "size": (32, 24), arg: value}
        path = kwargs.pop("path", Path(tmp) / "x.gif")
        if isinstance(path, str) and path:
            path = Path(tmp) / path
        with _memory_limit(1 << 20):
            out = _call(arg, lambda: render.gif(s, path, **kwargs))
        if out is None:
            assert s.step_count == 0 and s.time == 0.0, "refused after stepping"
            return "refused", list(Path(tmp).iterdir())
        return "written", [Path(out)] if Path(out).is_file() else []


@settings(max_examples=FAST)
@given(_gif_case)
def test_fuzz_gif(case):
    outcome, files = _check_gif(case)
    assert len(files) == (outcome == "written"), f"{outcome}, files left: {files}"


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_gif_case)
def test_fuzz_gif_long(case):
    outcome, files = _check_gif(case)
    assert len(files) == (outcome == "written"), f"{outcome}, files left: {files}"


# --------------------------------------------------------------------------- the CLI
HOSTILE_TEXT = ["0", "-1", "1", "2", "nan", "inf", "-inf", "1e-320", "1e400", "1e200", "18446744073709551616",
                "99999999999999999999", "abc", "", " ", "0x10", "1_0", "１", "1e-100", "none", "true", "1,2", "2**64"]
CLI_OPTIONS = ["--frames", "--fps", "--size", "--dt", "--frame-time", "--steps-per-frame", "--substeps",
               "--rtol", "--atol", "--radius", "--view", "--integrator", "--color-by", "--param"]
KEPLER_KEYS = ["a", "e", "mass_ratio", "steps_per_orbit", "threads", "dt", "bogus"]
SIZES = ["16x16", "65535x65535", "15x15", "0x0", "4294967296x2", "40x", "x", "40X30", "40,30"]


def _cli_case():
    text = st.one_of(st.sampled_from(HOSTILE_TEXT), st.text(max_size=6))
    size_text = st.one_of(st.sampled_from(SIZES), text)
    param = st.tuples(st.sampled_from(KEPLER_KEYS), text).map(lambda kv: f"{kv[0]}={kv[1]}")
    return st.sampled_from(CLI_OPTIONS).flatmap(
        lambda opt: st.tuples(st.just(opt), param if opt == "--param" else size_text if opt == "--size" else text)
    )


def _run_cli(case):
    """Run the CLI on one hostile option; returns (argv, exit code, stderr, whether a GIF was
    left), or None for a value no argv can hold (NUL)."""
    opt, value = case
    if "\x00" in value:
        return None  # argv strings cannot hold NUL; a shell never passes one
    with tempfile.TemporaryDirectory() as tmp:
        argv = ["render", "kepler", "-o", str(Path(tmp) / "k.gif"), "-q", "--frames", "2", "--size", "32x32", f"{opt}={value}"]
        err_buf = io.StringIO()
        with _memory_limit(1 << 20), redirect_stderr(err_buf), redirect_stdout(io.StringIO()):
            code = main(argv)
        return argv, code, err_buf.getvalue(), (Path(tmp) / "k.gif").exists()


def _cli_ok(run) -> str | None:
    """None if the run behaved (no traceback; exit 0, 1 or 2; a usage error is one line; no file
    left on failure), else what went wrong."""
    if run is None:
        return None
    argv, code, err, left = run
    if "Traceback" in err or code not in (0, 1, 2):
        return f"{argv}: exit {code}, {err!r}"
    lines = err.strip().splitlines()
    if code == 2 and not (len(lines) == 1 and "error:" in lines[0]):
        return f"{argv}: usage error not one line: {err!r}"
    if code != 0 and left:
        return f"{argv}: failed (exit {code}) but left a file"
    return None


@settings(max_examples=FAST)
@given(_cli_case())
def test_fuzz_cli(case):
    problem = _cli_ok(_run_cli(case))
    assert problem is None, problem


@pytest.mark.fuzz
@settings(max_examples=LONG)
@given(_cli_case())
def test_fuzz_cli_long(case):
    problem = _cli_ok(_run_cli(case))
    assert problem is None, problem
