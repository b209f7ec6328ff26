"""Issue 17, items 7-9: numbers beyond float64 are refused by name, a NaN energy is never a drift
of 0, the CLI refuses what would not fit in memory with one line and exit code 2, and a GIF
bound for an unwritable directory fails before the simulation."""
from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import tempfile
from unittest import mock

import numpy as np
import pytest

import physcore as pc

# Imported before any test patches render._recording._simulate: the painter binds it by name at
# import, and a first import inside the patch kept the mock for every later test of the worker.
import physcore.render.painter  # noqa: F401
from physcore import _check, render
from physcore.cli import main
from physcore.fluids import lattice, tank_walls

TINY = float(np.finfo(np.float64).tiny)  # smallest normal float64


def _names(exc: BaseException, arg: str) -> bool:
    return re.search(rf"\b{re.escape(arg)}\b", str(exc)) is not None


def _state(s: pc.Scene):
    return (s.n_particles, s.positions.tobytes(), s.velocities.tobytes(), s.masses.tobytes(),
            tuple(t.name for t in s.terms), s.dt, s.step_count)


def _small_scene() -> pc.Scene:
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, 2.0])
    return s


# --------------------------------------------------------------------------- masses
# 1/1e-310 and 1/5e-324 overflow; the largest subnormal's reciprocal does not, but a subnormal
# mass has lost precision already and is refused with the others.
@pytest.mark.parametrize("mass", [1e-310, 5e-324, float(np.nextafter(TINY, 0.0))])
def test_subnormal_masses_are_refused(mass):
    s = _small_scene()
    before = _state(s)
    with pytest.raises(pc.InvalidInputError) as info:
        s.add_particles([[0.0, 1.0], [2.0, 0.0]], masses=[1.0, mass])
    assert _names(info.value, "masses") and "entry 1" in str(info.value)
    assert _state(s) == before


def test_the_smallest_normal_mass_is_accepted_and_steps():
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[TINY, 1e-300])
    s.add(pc.Gravity([0.0, -9.81]))
    s.step(10)
    # Free fall does not depend on the mass: y = -g t²/2 after 10 steps of 1 ms.
    assert np.allclose(s.positions[:, 1], -0.5 * 9.81 * 0.01**2, rtol=1e-12)


def test_a_fluid_whose_particle_mass_underflows_names_density():
    s = pc.Scene(2, threads=1)
    before = _state(s)
    with pytest.raises(pc.InvalidInputError) as info:
        s.add_fluid(lattice([0, 0], [0.05, 0.05], 0.01), spacing=0.01, density=1e-305, sound_speed=10.0)
    assert _names(info.value, "density")
    with pytest.raises(pc.InvalidInputError) as info:
        s.add_fluid(lattice([0, 0], [0.05, 0.05], 0.01), spacing=0.01, mass=1e-310, sound_speed=10.0)
    assert _names(info.value, "mass")
    assert _state(s) == before


# --------------------------------------------------------------------------- energies
def test_energy_drift_is_nan_when_the_starting_books_are_nan():
    # ½ m v² = +inf and -m g·x = -inf: the total is NaN from the start; the old code divided by
    # max(NaN, ...) = NaN, found it not > 0 and reported a drift of 0.
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, -1e10]], [[1e10, 0.0]], masses=1e308)
    s.add(pc.Gravity([0.0, -9.81]))
    e = s.energy()
    assert math.isinf(e.kinetic) and math.isinf(e.potential["gravity"]) and math.isnan(e.total)
    s.step(1)
    assert math.isnan(s.energy_drift())


def test_energy_drift_is_nan_once_huge_masses_overflow_the_books():
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=1e308)
    s.add(pc.Gravity([0.0, -9.81]))
    s.step(10)
    assert math.isfinite(s.energy().total) and abs(s.energy_drift()) < 1e-12  # still representable
    s.step(1000)
    assert not math.isfinite(s.energy().total)
    assert math.isnan(s.energy_drift())
    assert np.all(np.isfinite(s.positions))  # the trajectory itself is fine


# --------------------------------------------------------------------------- OverflowError → named
@pytest.mark.parametrize("threads", [2**64, 2**100, pc.scene.MAX_THREADS + 1])
def test_huge_thread_counts_are_refused_by_name(threads):
    with pytest.raises(pc.InvalidInputError) as info:
        pc.Scene(2, threads=threads)
    assert _names(info.value, "threads")


@pytest.mark.parametrize("spacing", [1e200, 1e-200, 1e101])
def test_add_fluid_spacing_beyond_float64_is_refused_by_name(spacing):
    s = pc.Scene(2, threads=1)
    s.add(pc.Gravity([0.0, -9.81]))
    before = _state(s)
    with pytest.raises(pc.InvalidInputError) as info:
        s.add_fluid([[0.0, 0.0], [1.0, 0.0]], spacing=spacing)
    assert _names(info.value, "spacing")
    assert _state(s) == before


def test_add_fluid_spacing_range_ends_are_accepted():
    for spacing in pc.fluids.SPACING_RANGE:
        s = pc.Scene(2, threads=1)
        pts = np.array([[0.0, 0.0], [spacing, 0.0]])
        s.add_fluid(pts, spacing=spacing, sound_speed=1.0)
        assert s.n_particles == 2 and math.isfinite(s.energy().total)


def test_an_estimated_sound_speed_that_overflows_is_refused_by_name():
    s = pc.Scene(2, threads=1)
    s.add(pc.Gravity([0.0, -1e308]))
    before = _state(s)
    with pytest.raises(pc.InvalidInputError) as info:
        s.add_fluid(lattice([0, 0], [1.0, 1.0], 0.1), spacing=0.1)
    assert _names(info.value, "sound_speed")
    assert _state(s) == before


def test_a_density_that_overflows_the_tait_stiffness_is_refused_as_the_density():
    # The sound speed estimated (10 v_max, ~44 m/s) is fine: density · c0² overflows by the
    # density alone, which the refusal named sound_speed.
    s = pc.Scene(2, threads=1)
    s.add(pc.Gravity([0.0, -9.81]))
    before = _state(s)
    with pytest.raises(pc.InvalidInputError, match=r"^density: 1e308 kg/m³ makes the Tait stiffness") as info:
        s.add_fluid(lattice([0, 0], [1.0, 1.0], 0.1), spacing=0.1, density=1e308)
    assert _names(info.value, "density")
    assert _state(s) == before


def test_springs_between_particles_too_far_apart_for_float64_name_rest_length():
    s = pc.Scene(2, threads=1)
    s.add_particles([[-1e308, 0.0], [1e308, 0.0]])
    before = _state(s)
    with pytest.raises(pc.InvalidInputError) as info:  # no RuntimeWarning on the way
        s.add(pc.Springs([0], [1], stiffness=1.0))
    assert _names(info.value, "rest_length")
    assert _state(s) == before


@pytest.mark.parametrize("value", [10**400, 2**1100])
def test_ints_beyond_float64_are_refused_by_name(value):
    for make, arg in ((lambda v: pc.Drag(v), "coefficient"), (lambda v: pc.Scene(2, dt=v), "dt"),
                      (lambda v: pc.scenes.kepler(a=v), "a"), (lambda v: pc.PairwiseGravity(G=v), "G")):
        with pytest.raises(pc.InvalidInputError) as info:
            make(value)
        assert _names(info.value, arg)


@pytest.mark.parametrize("dt", [1e-310, 5e-324])
def test_a_subnormal_dt_is_refused(dt):
    with pytest.raises(pc.InvalidInputError, match=r"\bdt\b"):
        pc.Scene(2, dt=dt)
    s = _small_scene()
    with pytest.raises(pc.InvalidInputError, match=r"\bdt\b"):
        s.dt = dt
    assert s.dt == 1e-3
    pc.Scene(2, dt=TINY)  # the smallest normal step is accepted


# --------------------------------------------------------------------------- scene functions
@pytest.mark.parametrize(
    "fn, kwargs, arg",
    [
        ("kepler", {"a": 1e200}, "a"),
        ("kepler", {"a": 1e-200}, "a"),
        ("kepler", {"a": 1.0, "e": 1 - 1e-16, "steps_per_orbit": 10}, None),  # valid: rp = 1.1e-16
        ("kepler", {"mass_ratio": 1e-310}, "mass_ratio"),
        ("kepler", {"mass_ratio": 1e308}, "mass_ratio"),
        ("kepler", {"steps_per_orbit": 10**400}, "steps_per_orbit"),
        ("cloth", {"n": 10**6}, "n"),
        ("cloth", {"size": 1e-320}, "size"),
        ("cloth", {"mass": 5e-324}, "mass"),
        ("cloth", {"stiffness": 1e308, "n": 3}, "stiffness"),
        ("cloth", {"air_drag": 1e308, "mass": 1e308, "n": 3}, "air_drag"),
        ("projectile", {"speed": 1e200}, "speed"),
        ("projectile", {"n": 10**12}, "n"),
        ("spring_chain", {"mass": 1e-307, "n": 100}, "mass"),
        ("dam_break", {"n": 10**5}, "n"),
        ("dam_break", {"n": 4, "width": 1e-300, "height": 1e-300, "tank": (1.0, 1.0)}, "width"),
        ("drop", {"n": 10**9}, "n"),
        ("drop", {"n": 10, "pool": 1e308}, "pool"),
    ],
)
def test_scene_functions_refuse_what_float64_or_memory_cannot_hold(fn, kwargs, arg):
    f = getattr(pc.scenes, fn)
    if arg is None:
        scene = f(**kwargs)
        assert math.isfinite(scene.energy().total) and scene.dt >= TINY
        return
    with pytest.raises(pc.InvalidInputError) as info:
        f(**kwargs)
    assert _names(info.value, arg), f"message does not name {arg!r}: {info.value}"


@pytest.mark.parametrize(
    "fn, kwargs, arg",
    [
        ("kepler", {"e": "0.5"}, "e"),
        ("kepler", {"a": "1"}, "a"),
        ("kepler", {"mass_ratio": True}, "mass_ratio"),
        ("cloth", {"size": "1.0"}, "size"),
        ("cloth", {"ground": "no"}, "ground"),  # was truthy, so "no" meant a ground
        ("cloth", {"pin": 3}, "pin"),
        ("projectile", {"speed": None}, "speed"),
        ("projectile", {"drag": "0.1"}, "drag"),
        ("projectile", {"ground": 1}, "ground"),
        ("spring_chain", {"dim": 2.0}, "dim"),
        ("spring_chain", {"damping": "0"}, "damping"),
        ("dam_break", {"tank": "4,3"}, "tank"),
        ("dam_break", {"tank": ("4", "3")}, "tank"),
        ("drop", {"pool": "0.6"}, "pool"),
    ],
)
def test_scene_functions_refuse_strings_and_bools_for_numbers(fn, kwargs, arg):
    with pytest.raises(TypeError) as info:
        getattr(pc.scenes, fn)(**kwargs)
    assert _names(info.value, arg), f"message does not name {arg!r}: {info.value}"


def test_projectile_drag_error_names_drag_not_the_term_field():
    with pytest.raises(pc.InvalidInputError) as info:
        pc.scenes.projectile(drag=-1)
    assert _names(info.value, "drag") and "coefficient" not in str(info.value)
    with pytest.raises(pc.InvalidInputError, match=r"\brestitution\b"):
        pc.scenes.projectile(restitution=1.5)


def test_memory_refusals_follow_the_limit():
    # The same request is built under a limit above its estimate and refused under one below.
    n = 30
    need = n * n * _check.PARTICLE_BYTES + 6 * n * n * _check.SPRING_BYTES
    with mock.patch.object(_check, "memory_limit", lambda: need):
        assert pc.scenes.cloth(n=n).n_particles == n * n
    with mock.patch.object(_check, "memory_limit", lambda: need - 1):
        with pytest.raises(pc.InvalidInputError, match=r"\bn\b.*900 particles"):
            pc.scenes.cloth(n=n)


def test_lattice_refuses_a_lattice_beyond_memory():
    with pytest.raises(pc.InvalidInputError, match=r"\bspacing\b"):
        lattice([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], 1e-6)
    with pytest.raises(pc.InvalidInputError, match=r"\bspacing\b"):
        tank_walls([0.0, 0.0], [1.0, 1.0], 1e-9)
    with pytest.raises(TypeError, match=r"\bspacing\b"):
        tank_walls([0.0, 0.0], [1.0, 1.0], "0.1")


# --------------------------------------------------------------------------- render.gif
def _pendulum() -> pc.Scene:
    s = pc.Scene(2, threads=1)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], pinned=[True, False])
    s.add(pc.Springs([0], [1], stiffness=50.0))
    s.add(pc.Gravity([0.0, -9.81]))
    return s


def _refusing_mkstemp(*args, **kwargs):
    raise PermissionError(13, "Permission denied")


def test_gif_to_an_unwritable_directory_fails_before_simulating(tmp_path):
    s = _pendulum()
    with mock.patch.object(tempfile, "mkstemp", _refusing_mkstemp):
        with pytest.raises(PermissionError, match="path"):
            render.gif(s, tmp_path / "x.gif", frames=3, size=(32, 32))
    assert s.time == 0.0 and s.step_count == 0
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes into read-only directories")
def test_gif_to_a_read_only_directory_fails_before_simulating(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    s = _pendulum()
    try:
        with pytest.raises(PermissionError):
            render.gif(s, ro / "x.gif", frames=3, size=(32, 32))
    finally:
        ro.chmod(0o755)
    assert s.time == 0.0


def test_gif_probe_leaves_nothing_behind(tmp_path):
    render.gif(_pendulum(), tmp_path / "x.gif", frames=2, size=(32, 32))
    assert [p.name for p in tmp_path.iterdir()] == ["x.gif"]


@pytest.mark.parametrize(
    "kwargs, arg",
    [
        ({"frames": 10**12}, "frames"),
        ({"frames": 2**64}, "frames"),
        ({"size": (65535, 65535), "frames": 200}, "size"),
        ({"steps_per_frame": 2**64}, "steps_per_frame"),
        ({"steps_per_frame": render.MAX_STEPS + 1}, "steps_per_frame"),
        ({"frame_time": 0.1, "substeps": 2**64}, "substeps"),
        ({"fps": 10**400}, "fps"),
        ({"view": (10**400, 0)}, "view"),
        ({"view": ("1", "2")}, "view"),
        ({"color_by": np.array(["speed"])}, "color_by"),
        ({"springs": "no"}, "springs"),
    ],
)
def test_gif_refuses_unrepresentable_arguments_before_simulating(tmp_path, kwargs, arg):
    s = _pendulum()
    with pytest.raises((pc.InvalidInputError, TypeError)) as info:
        render.gif(s, tmp_path / "x.gif", **kwargs)
    assert _names(info.value, arg), f"message does not name {arg!r}: {info.value}"
    assert s.time == 0.0 and list(tmp_path.iterdir()) == []


def test_gif_memory_estimate_follows_the_limit(tmp_path):
    s = _pendulum()
    frames, size = 4, (32, 32)
    need = frames * (4 * 2 * (2 + 2) + 4 * 1 + 2 * 32 * 32)
    with mock.patch.object(_check, "memory_limit", lambda: need - 1):
        with pytest.raises(pc.InvalidInputError, match=r"\bframes\b"):
            render.gif(s, tmp_path / "x.gif", frames=frames, size=size)
    assert s.time == 0.0
    with mock.patch.object(_check, "memory_limit", lambda: need):
        render.gif(s, tmp_path / "x.gif", frames=frames, size=size)
    assert s.step_count == 3 * 33  # the default frame time 1/30 s = 33 steps of dt = 1e-3 s


# --------------------------------------------------------------------------- CLI
def _one_line_usage_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("physcore") and "error:" in lines[0]
    return lines[0]


@pytest.mark.parametrize(
    "argv, mentions",
    [
        (["render", "kepler", "--param", "a=1e200"], r"\ba\b"),
        (["render", "kepler", "--param", "e=0.5x"], r"\be\b"),
        (["render", "kepler", "--param", "steps_per_orbit=100000000000000000000000"], "frame-time"),
        (["render", "kepler", "--param", "threads=18446744073709551616"], "threads"),
        (["render", "kepler", "--param", "mass_ratio=1e-310"], "mass_ratio"),
        (["render", "cloth", "--size", "65535x65535"], "--size"),
        (["render", "cloth", "--frames", "100000000000000000000"], "--frames"),
        (["render", "cloth", "--param", "n=1000000"], r"\bn\b"),
        (["render", "dam_break", "--param", "n=1000000"], r"\bn\b"),
        (["render", "projectile", "--param", "n=1000000000000"], r"\bn\b"),
        (["render", "cloth", "--param", "n"], "key=value"),
        (["render", "cloth", "--size", "big"], "WIDTHxHEIGHT"),
        (["render", "cloth", "--frame-time", "1e300"], "frame-time"),
        (["render", "nosuchscene"], "nosuchscene"),
        (["render", "cloth", "--bogus"], "bogus"),
    ],
)
def test_cli_user_errors_are_one_line_and_exit_2(tmp_path, capsys, argv, mentions):
    out = tmp_path / "x.gif"
    with mock.patch.object(render._recording, "_simulate", side_effect=AssertionError("simulated")):
        assert main(argv + ["-o", str(out), "-q"]) == 2
    assert re.search(mentions, _one_line_usage_error(capsys))
    assert list(tmp_path.iterdir()) == []


def test_cli_unwritable_output_fails_before_building_the_scene(tmp_path, capsys):
    built = []
    real = pc.scenes.REGISTRY["spring_chain"]
    with mock.patch.dict(pc.scenes.REGISTRY, {"spring_chain": lambda **kw: built.append(1) or real(**kw)}), \
            mock.patch.object(tempfile, "mkstemp", _refusing_mkstemp):
        assert main(["render", "spring_chain", "-o", str(tmp_path / "x.gif"), "-q", "--frames", "3"]) == 1
    err = capsys.readouterr().err
    assert "cannot write" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert built == []


def test_cli_user_error_in_a_real_process_has_no_traceback(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "physcore", "render", "kepler", "--param", "a=1e200", "-o", str(tmp_path / "k.gif")],
        capture_output=True, text=True, timeout=120,
    )
    assert res.returncode == 2
    assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert re.search(r"\ba\b", res.stderr)
