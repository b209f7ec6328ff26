"""The SIMD levels: selection, errors, and the agreement tests.

Each hot kernel (springs, pairwise gravity in f64 and f32, SPH density and forces in f32 and f64)
is one source compiled for every level; these tests run each scene at every level this CPU has
(the ``simd_level`` fixture skips the others with the reason) and compare it with the scalar
level, and check that at that level 1 and 2 threads give bit-identical results. Tolerances come
from the rsqrt primitive's accuracy (a few ulp) amplified by a few steps of dynamics, not from
a previous run.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import physcore as pc

# ------------------------------------------------------------------------------- selection


def test_the_active_level_is_one_this_cpu_has():
    levels = pc.simd_levels()
    assert levels[0] == "scalar"
    assert set(levels) <= {"scalar", "avx2", "avx512", "neon"}
    assert pc.simd_level() in levels
    info = pc.info()
    assert info["simd_level"] == pc.simd_level() and info["simd_levels"] == levels
    assert info["cpu"] and info["threads"] >= 1


def test_set_simd_level_refuses_unknown_and_unsupported_levels():
    before = pc.simd_level()
    with pytest.raises(pc.InvalidInputError, match="level"):
        pc.set_simd_level("sse9")
    missing = [lv for lv in ("avx2", "avx512", "neon") if lv not in pc.simd_levels()]
    for lv in missing:
        with pytest.raises(pc.InvalidInputError, match="cannot run"):
            pc.set_simd_level(lv)
    assert pc.simd_level() == before  # a refused call changes nothing


def _run(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env={**os.environ, **env}, capture_output=True, text=True, timeout=120)


def test_physcore_simd_environment_variable_forces_a_level():
    for lv in pc.simd_levels() + ["auto"]:
        r = _run("import physcore as pc, json; print(json.dumps(pc.simd_level()))", {"PHYSCORE_SIMD": lv.upper()})
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout) == (pc.simd_levels()[-1] if lv == "auto" else lv)


@pytest.mark.parametrize("value", ["avx1024", "neon" if sys.platform != "darwin" else "avx2"])
def test_an_invalid_physcore_simd_is_a_clear_error_not_a_crash(value):
    if value in pc.simd_levels():
        pytest.skip(f"this CPU has {value}")
    code = (
        "import physcore as pc\n"
        "try:\n    pc.Scene(2)\nexcept pc.InvalidInputError as e:\n    print('refused:', e)\n"
    )
    r = _run(code, {"PHYSCORE_SIMD": value})
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("refused: PHYSCORE_SIMD") and value in r.stdout
    cli = subprocess.run([sys.executable, "-m", "physcore", "info"], env={**os.environ, "PHYSCORE_SIMD": value},
                         capture_output=True, text=True, timeout=120)
    assert cli.returncode == 1 and "invalid" in cli.stdout and "Traceback" not in cli.stderr


def test_cli_info_names_the_cpu_and_level():
    r = subprocess.run([sys.executable, "-m", "physcore", "info"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"simd level: {pc.simd_level()}" in r.stdout and "cpu:" in r.stdout


# ------------------------------------------------------------------------------- agreement


def _cloth(threads):
    return pc.scenes.cloth(n=72, threads=threads)  # 5184 particles: past the parallel threshold


def _nbody(threads, precision):
    rng = np.random.default_rng(3)
    s = pc.Scene(3, integrator="verlet", dt=1e-3, threads=threads, precision=precision)
    s.add_particles(rng.normal(size=(301, 3)), masses=1.0 / 301)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.01))
    return s


def _fluid(threads, precision, dim):
    # WCSPH: its passes are the SIMD f32/f64 ones (agreement to rounding; DFSPH is below).
    return pc.scenes.dam_break(dim=dim, n=40 if dim == 2 else 10, pass_precision=precision, threads=threads, method="wcsph")


def _dfsph(threads, dim):
    # DFSPH's pair build runs on the SIMD layer with the scalar operations lane by lane, its
    # passes are scalar: the same bits at every level (2D past the parallel threshold).
    return pc.scenes.dam_break(dim=dim, n=48 if dim == 2 else 10, threads=threads, method="dfsph")


def _grains(threads, dim):
    """A pile of grains in a box: every branch of the contact pair pass (contacts that form, slip,
    end; pinned partners; walls); 2D linear with equal masses, 3D Hertz with unequal ones."""
    rng = np.random.default_rng(5 + dim)
    n = 4500 if dim == 2 else 1500  # past the parallel threshold in 2D
    size = 0.25 if dim == 2 else 0.06
    x = rng.uniform(0.0, size, (n, dim))
    r = np.full(n, 0.002) if dim == 2 else rng.uniform(0.002, 0.003, n)
    s = pc.Scene(dim, integrator="semi_implicit_euler", dt=1e-5, threads=threads)
    s.add_particles(x, rng.normal(0.0, 0.2, (n, dim)), masses=1e-3 * (r / 0.002) ** dim,
                    pinned=rng.uniform(size=n) < 0.03)
    s.set_attribute("radius", r)
    s.add(pc.Gravity([0.0] * (dim - 1) + [-9.81]))
    s.add(pc.Contacts(stiffness=1e4 if dim == 2 else 1e6, restitution=0.5, friction=0.4,
                      law="linear" if dim == 2 else "hertz",
                      walls=pc.Box([0.0] * dim, [size] * dim, restitution=0.7, friction=0.3)))
    s.dt = s.suggest_dt()
    return s


SCENES = {
    "cloth-springs-f64": (lambda t: _cloth(t), 20, 1e-12),
    "nbody-f64": (lambda t: _nbody(t, "f64"), 20, 1e-12),
    "nbody-f32": (lambda t: _nbody(t, "f32"), 20, 1e-5),
    "sph2d-f32": (lambda t: _fluid(t, "f32", 2), 10, 1e-4),
    "sph2d-f64": (lambda t: _fluid(t, "f64", 2), 10, 1e-11),
    "sph3d-f32": (lambda t: _fluid(t, "f32", 3), 5, 1e-4),
    "dfsph2d": (lambda t: _dfsph(t, 2), 10, 0.0),
    "dfsph3d": (lambda t: _dfsph(t, 3), 5, 0.0),
    # The contact pair pass does the scalar operations lane by lane: the same bits at every level.
    "grains2d-linear": (lambda t: _grains(t, 2), 60, 0.0),
    "grains3d-hertz": (lambda t: _grains(t, 3), 60, 0.0),
}


def _final(name, threads):
    build, steps, _ = SCENES[name]
    s = build(threads)
    x0 = s.positions
    s.step(steps)
    return x0, s.positions


@pytest.mark.parametrize("name", SCENES)
def test_every_level_agrees_with_scalar_and_is_thread_count_deterministic(name, simd_level):
    x0, x1 = _final(name, 1)
    _, x2 = _final(name, 2)
    assert np.array_equal(x1, x2), f"{name} at {simd_level}: 1 and 2 threads differ"
    pc.set_simd_level("scalar")
    _, ref = _final(name, 1)
    pc.set_simd_level(simd_level)
    moved = np.abs(ref - x0).max()
    assert moved > 0
    tol = SCENES[name][2]
    # Relative to how far the particles moved: float32 state rounding is shared by all levels.
    assert np.abs(x1 - ref).max() <= tol * max(moved, np.abs(ref).max() * 1e-3), (
        f"{name} at {simd_level}: max deviation {np.abs(x1 - ref).max():.3e} from scalar (moved {moved:.3e})"
    )


def _gray_scott(threads, fused):
    """Gray–Scott past the parallel threshold: `step(n)` takes fused sweeps of several steps, `step()`
    single ones; both, at every level, are the scalar expression cell by cell."""
    s = pc.Scene(dim=2, dt=1.0, threads=threads)
    g = s.add(pc.GrayScott((300, 260), 2.5 / 256, preset="maze"))
    g.seed(1, squares=12)
    if fused:
        s.step(23)
    else:
        for _ in range(23):
            s.step()
    return g.u.copy(), g.v.copy(), g.books()


def test_gray_scott_has_the_same_bits_at_every_level_thread_count_and_fusion(simd_level):
    runs = [_gray_scott(t, f) for t in (1, 2) for f in (True, False)]
    pc.set_simd_level("scalar")
    ref = _gray_scott(1, False)
    pc.set_simd_level(simd_level)
    assert ref[1].max() > 0.1  # the seeded squares of v are there
    for u, v, books in runs:
        assert np.array_equal(u, ref[0]) and np.array_equal(v, ref[1]), f"Gray–Scott fields at {simd_level}"
        # The books sum one partial per lane: the same bits for any thread count and fusion at
        # one level, the lane count's rounding between levels.
        assert books == runs[0][2], f"Gray–Scott books at {simd_level} differ between runs: {books}"
        for key, x in ref[2].items():
            assert abs(books[key] - x) <= 1e-13 * max(abs(x), 1.0), f"{key} at {simd_level}: {books[key]} vs {x}"


def _wave(threads, fused):
    """A plain wave (fused sweeps of up to 6 steps by `step(n)`) past the parallel threshold."""
    s = pc.Scene(dim=2, threads=threads)
    w = s.add(pc.Wave((300, 260), 1.0 / 300, c=1.0))
    x, y = (np.arange(300) + 0.5) / 300, (np.arange(260) + 0.5) / 300
    w.u = np.exp(-((x[:, None] - 0.4) ** 2 + (y[None, :] - 0.5) ** 2) / 0.003)
    s.dt = 0.9 * w.cfl_limit
    if fused:
        s.step(23)
    else:
        for _ in range(23):
            s.step()
    return w.u.copy(), w.velocity.copy()


def test_the_wave_has_the_same_bits_at_every_level_thread_count_and_fusion(simd_level):
    runs = [_wave(t, f) for t in (1, 2) for f in (True, False)]
    pc.set_simd_level("scalar")
    ref = _wave(1, False)
    pc.set_simd_level(simd_level)
    assert np.abs(ref[1]).max() > 0.1  # the pulse moves
    for u, v in runs:
        assert np.array_equal(u, ref[0]) and np.array_equal(v, ref[1]), f"wave at {simd_level}"
