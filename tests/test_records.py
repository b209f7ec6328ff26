"""Integrator records (``pc.Dopri5(rtol=...)``) and particle-fluid solver records
(``pc.DFSPH(...)``), issue 62: each is the same scene as its name with the same keywords (same
bits after stepping, same saved file), checks its own fields, and refuses an option given twice."""
from __future__ import annotations

import dataclasses
import doctest
import inspect

import numpy as np
import pytest

import physcore as pc
from physcore import _integrators, fluids
from physcore.shapes import lattice, tank_walls


# ----------------------------------------------------------------------------- coverage
def test_every_integrator_has_an_exported_record():
    names = [d["name"] for d in pc.INTEGRATORS]
    assert sorted(_integrators.REGISTRY) == sorted(names)
    for name in names:
        cls = _integrators.REGISTRY[name]
        assert cls.name == name
        assert getattr(pc, cls.__name__) is cls and cls.__name__ in pc.__all__
        assert pc.Scene(integrator=cls()).integrator == name


def test_every_fluid_method_has_an_exported_record():
    assert sorted(fluids.SOLVERS) == sorted(fluids.METHODS)
    for name, cls in fluids.SOLVERS.items():
        assert cls.name == name
        assert getattr(pc, cls.__name__) is cls and cls.__name__ in pc.__all__


def test_record_defaults_are_the_scenes_and_the_fluids():
    # What a default scene holds in the core, and Scene's own keyword defaults.
    scene = pc.Scene()
    params = inspect.signature(pc.Scene).parameters
    for cls in _integrators.REGISTRY.values():
        for kw, value in cls().options().items():
            assert getattr(scene, kw) == value, (cls.__name__, kw)
            assert params[kw].default == value, (cls.__name__, kw)
    fluid = pc.Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01)
    for cls in fluids.SOLVERS.values():
        for f, value in cls().options().items():
            assert getattr(fluid, f) == value, (cls.__name__, f)


def test_integrator_record_docstring_examples():
    # The records live in a private module, which the public modules' doctest run skips.
    result = doctest.testmod(_integrators, verbose=False)
    assert result.attempted > 0 and result.failed == 0


# ----------------------------------------------------------------------------- equivalence
def _chain(integrator, **kw) -> pc.Scene:
    """A stiff hanging chain with drag and an XPBD distance constraint, stepped 40 steps of a
    coarse dt, so that every integrator option changes the bits."""
    scene = pc.Scene(dim=2, integrator=integrator, dt=2e-2, threads=1, **kw)
    n = 8
    scene.add_particles(np.c_[np.arange(n, dtype=float) * 0.5, np.zeros(n)], pinned=[True] + [False] * (n - 1))
    scene.add(pc.Gravity([0.0, -9.81]))
    scene.add(pc.Springs(np.arange(n - 1), np.arange(1, n), stiffness=2e3, damping=0.5))
    scene.add(pc.Drag(0.1))
    if scene.integrator == "xpbd":  # the other integrators refuse them (they would step as if they were not there)
        scene.add(pc.XpbdConstraints(distance=[[0, n - 1]], rest_length=[3.0]))
    scene.step(40)
    return scene


RECORDS = [
    (pc.Dopri5(rtol=1e-9, atol=1e-12), "dopri5", {"rtol": 1e-9, "atol": 1e-12}),
    (pc.ImplicitEuler(cg_tol=1e-3, cg_max_iter=3), "implicit_euler", {"cg_tol": 1e-3, "cg_max_iter": 3}),
    (pc.XPBD(substeps=3, iterations=4), "xpbd", {"xpbd_substeps": 3, "xpbd_iterations": 4}),
]


def _same_scene(a: pc.Scene, b: pc.Scene, tmp_path) -> None:
    assert a.integrator == b.integrator
    assert np.array_equal(a.positions.view(np.uint64), b.positions.view(np.uint64))
    assert np.array_equal(a.velocities.view(np.uint64), b.velocities.view(np.uint64))
    assert a.save(tmp_path / "a.npz").read_bytes() == b.save(tmp_path / "b.npz").read_bytes()


@pytest.mark.parametrize(("record", "name", "kwargs"), RECORDS, ids=[r[1] for r in RECORDS])
def test_integrator_record_is_the_name_and_keywords(record, name, kwargs, tmp_path):
    by_record, by_name = _chain(record), _chain(name, **kwargs)
    assert by_record.integrator == name  # still the name, not the record
    _same_scene(by_record, by_name, tmp_path)
    # The options took effect: at the defaults the run differs (else the test proves nothing).
    assert not np.array_equal(by_record.positions, _chain(name).positions)
    # Given both ways with the same values: no conflict, the same scene.
    _same_scene(_chain(record, **kwargs), by_name, tmp_path)


@pytest.mark.parametrize(("record", "name", "kwargs"), RECORDS, ids=[r[1] for r in RECORDS])
def test_setting_an_integrator_record_sets_its_options(record, name, kwargs, tmp_path):
    a, b = pc.Scene(dim=2, threads=1), pc.Scene(dim=2, threads=1)
    a.integrator = record
    b.integrator = name
    for kw, value in kwargs.items():
        setattr(b, kw, value)
    assert a.integrator == name and all(getattr(a, kw) == v for kw, v in kwargs.items())
    _same_scene(a, b, tmp_path)


def _tank(**fluid_kw) -> pc.Scene:
    """A block of fluid thrown into the corner of a tank, advanced 0.03 s (3 to 100 substeps)."""
    dx = 0.02
    scene = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=1)
    scene.add(pc.Gravity([0.0, -9.81]))
    x = lattice([0, 0.1], [0.2, 0.3], dx)
    scene.add_fluid(x, spacing=dx, velocities=np.tile([1.0, -1.0], (len(x), 1)),
                    boundary=tank_walls([0, 0], [0.5, 0.4], dx, layers=3), **fluid_kw)
    scene.advance(0.03)
    return scene


def test_dfsph_record_is_the_method_and_keywords(tmp_path):
    opts = {"density_error": 2e-3, "divergence_error": 5e-3, "max_iterations": 1, "cfl": 0.7,
            "surface_tension": 0.01, "adhesion": 0.005}
    by_record, by_name = _tank(solver=pc.DFSPH(**opts)), _tank(method="dfsph", **opts)
    assert by_record.fluids[0].method == "dfsph" and by_record.fluids[0].cfl == 0.7
    _same_scene(by_record, by_name, tmp_path)
    assert by_record.solver_stats() == by_name.solver_stats()
    assert not np.array_equal(by_record.positions, _tank(method="dfsph").positions)


def test_wcsph_record_is_the_method_and_keywords(tmp_path):
    opts = {"gamma": 3, "clamp_pressure": False, "pass_precision": "f32"}
    by_record = _tank(solver=pc.WCSPH(**opts))
    _same_scene(by_record, _tank(**opts), tmp_path)
    assert not np.array_equal(by_record.positions, _tank().positions)
    assert _tank(solver=pc.WCSPH()).fluids[0].method == "wcsph"


# ----------------------------------------------------------------------------- bad fields
BAD_FIELDS = [
    (lambda: pc.Dopri5(rtol=0.0), "rtol", pc.InvalidInputError),
    (lambda: pc.Dopri5(rtol=1.0), "rtol", pc.InvalidInputError),
    (lambda: pc.Dopri5(rtol="1e-6"), "rtol", pc.InvalidTypeError),
    (lambda: pc.Dopri5(atol=-1e-9), "atol", pc.InvalidInputError),
    (lambda: pc.Dopri5(atol=float("nan")), "atol", pc.InvalidInputError),
    (lambda: pc.ImplicitEuler(cg_tol=1e-15), "cg_tol", pc.InvalidInputError),
    (lambda: pc.ImplicitEuler(cg_max_iter=0), "cg_max_iter", pc.InvalidInputError),
    (lambda: pc.ImplicitEuler(cg_max_iter=2.0), "cg_max_iter", pc.InvalidTypeError),
    (lambda: pc.XPBD(substeps=0), "substeps", pc.InvalidInputError),
    (lambda: pc.XPBD(substeps=True), "substeps", pc.InvalidTypeError),
    (lambda: pc.XPBD(iterations=10_001), "iterations", pc.InvalidInputError),
    (lambda: pc.WisdomHolman(coordinates="heliocentric"), "coordinates", pc.InvalidInputError),
    (lambda: pc.WisdomHolman(coordinates=0), "coordinates", pc.InvalidTypeError),
    (lambda: pc.WCSPH(gamma=16), "gamma", pc.InvalidInputError),
    (lambda: pc.WCSPH(clamp_pressure=1), "clamp_pressure", pc.InvalidTypeError),
    (lambda: pc.WCSPH(pass_precision="f16"), "pass_precision", pc.InvalidInputError),
    (lambda: pc.DFSPH(density_error=1.0), "density_error", pc.InvalidInputError),
    (lambda: pc.DFSPH(divergence_error=0.0), "divergence_error", pc.InvalidInputError),
    (lambda: pc.DFSPH(max_iterations=0), "max_iterations", pc.InvalidInputError),
    (lambda: pc.DFSPH(cfl=1.5), "cfl", pc.InvalidInputError),
    (lambda: pc.DFSPH(surface_tension=-0.1), "surface_tension", pc.InvalidInputError),
    (lambda: pc.DFSPH(adhesion="x"), "adhesion", pc.InvalidTypeError),
]


@pytest.mark.parametrize(("make", "field", "error"), BAD_FIELDS, ids=[f"{i}-{b[1]}" for i, b in enumerate(BAD_FIELDS)])
def test_a_bad_record_field_is_refused_by_name(make, field, error):
    with pytest.raises(error, match=rf"^{field}:"):
        make()


def test_records_are_immutable_values():
    r = pc.Dopri5(rtol=1e-8)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.rtol = 1e-3  # type: ignore[misc]
    assert r == pc.Dopri5(rtol=1e-8) and r != pc.Dopri5() and hash(r) == hash(pc.Dopri5(rtol=1e-8))
    assert pc.DFSPH(cfl=0.3) == pc.DFSPH(cfl=0.3) != pc.DFSPH()
    with pytest.raises(TypeError):
        pc.Dopri5(1e-8)  # keyword-only


def test_not_a_record_is_refused_by_name():
    with pytest.raises(pc.InvalidTypeError, match="^integrator:"):
        pc.Scene(integrator=pc.DFSPH())
    with pytest.raises(pc.InvalidTypeError, match="^solver:"):
        pc.Fluid(lattice([0, 0], [0.05, 0.05], 0.01), 0.01, solver="dfsph")


# ----------------------------------------------------------------------------- given twice
CONFLICTS = [
    ({"integrator": pc.Dopri5(rtol=1e-8), "rtol": 1e-7}, "rtol"),
    ({"integrator": pc.Dopri5(atol=1e-12), "atol": 1e-10}, "atol"),
    ({"integrator": pc.ImplicitEuler(cg_tol=1e-6), "cg_tol": 1e-5}, "cg_tol"),
    ({"integrator": pc.ImplicitEuler(cg_max_iter=7), "cg_max_iter": 8}, "cg_max_iter"),
    ({"integrator": pc.XPBD(substeps=4), "xpbd_substeps": 5}, "xpbd_substeps"),
    ({"integrator": pc.XPBD(iterations=2), "xpbd_iterations": 3}, "xpbd_iterations"),
    ({"integrator": pc.WisdomHolman(coordinates="jacobi"), "wh_coordinates": "democratic_heliocentric"}, "wh_coordinates"),
]


@pytest.mark.parametrize(("kwargs", "keyword"), CONFLICTS, ids=[c[1] for c in CONFLICTS])
def test_a_record_and_a_conflicting_scene_keyword_raise_naming_it(kwargs, keyword):
    with pytest.raises(pc.InvalidInputError, match=rf"^{keyword}: .* conflicts with integrator="):
        pc.Scene(dim=2, **kwargs)


def test_keywords_of_other_integrators_are_kept_beside_a_record():
    # As with a name: the other integrators' options are kept (and ignored until switched to),
    # with a warning naming each and the integrator that uses it.
    with pytest.warns(pc.UnusedOptionWarning, match=r"^integrator='dopri5' does not use cg_tol \('implicit_euler'\), "
                      r"xpbd_substeps \('xpbd'\); kept for a later switch of integrator, they change nothing"):
        scene = pc.Scene(integrator=pc.Dopri5(rtol=1e-8), cg_tol=1e-5, xpbd_substeps=3)
    assert (scene.rtol, scene.cg_tol, scene.xpbd_substeps) == (1e-8, 1e-5, 3)


UNUSED = [
    ("verlet", {"rtol": 1e-8}, "rtol ('dopri5')"),
    ("rk4", {"atol": 1e-12}, "atol ('dopri5')"),
    ("dopri5", {"cg_max_iter": 5}, "cg_max_iter ('implicit_euler')"),
    ("implicit_euler", {"xpbd_iterations": 3}, "xpbd_iterations ('xpbd')"),
    ("xpbd", {"wh_coordinates": "democratic_heliocentric"}, "wh_coordinates ('wisdom_holman')"),
    ("boris", {"wh_corrector": 5}, "wh_corrector ('wisdom_holman')"),
]


@pytest.mark.parametrize(("integrator", "kwargs", "named"), UNUSED, ids=[u[2].split()[0] for u in UNUSED])
def test_an_option_the_integrator_does_not_use_warns_naming_it_and_is_kept(integrator, kwargs, named):
    with pytest.warns(pc.UnusedOptionWarning) as caught:
        scene = pc.Scene(dim=2, integrator=integrator, **kwargs)
    assert len(caught) == 1 and f"does not use {named};" in str(caught[0].message)
    assert caught[0].filename == __file__  # points at the caller's line
    (kw, value), = kwargs.items()
    assert getattr(scene, kw) == value
    # A switch to the integrator that uses it takes it up.
    scene.integrator = _OWNER[kw]
    assert getattr(scene, kw) == value


_OWNER = {"rtol": "dopri5", "atol": "dopri5", "cg_tol": "implicit_euler", "cg_max_iter": "implicit_euler",
          "xpbd_substeps": "xpbd", "xpbd_iterations": "xpbd", "wh_coordinates": "wisdom_holman",
          "wh_corrector": "wisdom_holman"}


def test_options_at_their_defaults_used_options_and_reloads_do_not_warn(tmp_path):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pc.Scene(integrator="verlet", rtol=1e-6, atol=1e-9, cg_tol=1e-8, xpbd_substeps=10)  # the defaults
        pc.Scene(integrator="dopri5", rtol=1e-10, atol=1e-12)
        pc.Scene(integrator="implicit_euler", cg_tol=1e-10, cg_max_iter=50)
        pc.Scene(integrator="xpbd", xpbd_substeps=3, xpbd_iterations=2)
        pc.Scene(integrator="wisdom_holman", wh_coordinates="democratic_heliocentric", wh_corrector=3)
        # A scene that switched integrators keeps (and saves) the options of the last one.
        a = pc.Scene(integrator="dopri5", rtol=1e-10)
        a.integrator = "verlet"
        b = pc.Scene.load(a.save(tmp_path / "a.npz"))
        c = pc.Scene.from_bytes(a.to_bytes())
        # Ready-made scenes keep their own options whatever the integrator asked for.
        pc.scenes.pythagorean(integrator="verlet")
    assert b.rtol == c.rtol == 1e-10 and b.integrator == c.integrator == "verlet"


FLUID_CONFLICTS = [
    ({"solver": pc.DFSPH(), "method": "wcsph"}, "method"),
    ({"solver": pc.WCSPH(), "method": "dfsph"}, "method"),
    ({"solver": pc.DFSPH(cfl=0.3), "cfl": 0.2}, "cfl"),
    ({"solver": pc.DFSPH(max_iterations=50), "max_iterations": 20}, "max_iterations"),
    ({"solver": pc.WCSPH(gamma=3), "gamma": 5}, "gamma"),
]


@pytest.mark.parametrize(("kwargs", "arg"), FLUID_CONFLICTS, ids=[f"{c[1]}-{i}" for i, c in enumerate(FLUID_CONFLICTS)])
def test_a_solver_record_and_a_conflicting_fluid_argument_raise_naming_it(kwargs, arg):
    scene = pc.Scene(dim=2, integrator="semi_implicit_euler")
    with pytest.raises(pc.InvalidInputError, match=rf"^{arg}: .*conflicts with solver="):
        scene.add_fluid(lattice([0, 0], [0.05, 0.05], 0.01), spacing=0.01, **kwargs)
    assert scene.n_particles == 0 and not scene.fluids  # refused before anything was added


def test_a_solver_record_with_the_same_values_given_again_is_accepted():
    x = lattice([0, 0], [0.05, 0.05], 0.01)
    a = pc.Fluid(x, 0.01, solver=pc.DFSPH(cfl=0.3), method="dfsph", cfl=0.3)
    assert a == pc.Fluid(x, 0.01, method="dfsph", cfl=0.3)
    # A fluid copied with dataclasses.replace keeps its solver and takes the change.
    assert dataclasses.replace(a, cfl=0.2).cfl == 0.2 and dataclasses.replace(a, cfl=0.2).method == "dfsph"
