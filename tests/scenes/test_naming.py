"""One vocabulary (issue 45 step 4, docs/naming.md): scene files written with the old names load
and continue as files written with the new ones, and every deprecated alias warns with a
DeprecationWarning that names the new spelling and builds the same thing as the new name.

tests/scenes/data/old_names.npz and old_names_fluid.npz were written by physcore before the renames
(commit 72f6db1) with the old spellings: ``Scene(integrator="rk45")``, ``Wave(dx=, gamma=)``,
``GrayScott(dx=)``, ``StableFluid(dx=, viscosity=)`` (grid kind ``"fluid"`` in the file) and
``Fluid(viscosity=, walls=, wall_volume=, precision=)``; see the builders below, which make the
same scenes with the new names.
"""
from __future__ import annotations

import io
import json
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

import physcore as pc
from physcore import cli, scenes
from physcore._parts import PART_ALIASES, PARTS
from physcore.fluids import Fluid, lattice, tank_walls
from physcore.grids import KIND_ALIASES

DATA = Path(__file__).parent / "data"
#: The SIMD level the files in DATA were written at (x86-64, AVX2). Every level computes the same
#: physics to a few ulp, not bit for bit (``physcore.set_simd_level``), and these tests compare
#: bits: a file stepped here must be stepped at the level that wrote it.
WRITTEN_AT = "avx2"


@pytest.fixture
def written_level():
    """Run the test at the level DATA was written at (skipped where the CPU lacks it)."""
    if WRITTEN_AT not in pc.simd_levels():
        pytest.skip(f"the files were written at {WRITTEN_AT!r}, which this CPU lacks; other levels differ in the last bits")
    before = pc.simd_level()
    pc.set_simd_level(WRITTEN_AT)
    yield
    pc.set_simd_level(None)  # the process default (PHYSCORE_SIMD or the best level) ...
    if pc.simd_level() != before:
        pc.set_simd_level(before)  # ... unless another test had forced one


def _members(path: Path) -> dict[str, np.ndarray]:
    with zipfile.ZipFile(path) as z:
        return {n.removesuffix(".npy"): np.load(io.BytesIO(z.read(n)), allow_pickle=False) for n in z.namelist()}


def _grids_scene() -> pc.Scene:
    """tests/scenes/data/old_names.npz's scene, in the new names."""
    s = pc.Scene(2, integrator="dopri5", dt=1e-3, threads=1, rtol=1e-8, atol=1e-11)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.1], [0.0, -0.1]], masses=[1.0, 2.0])
    s.add(pc.Springs([0], [1], stiffness=10.0, damping=0.1))
    s.add(pc.Wave((8, 6), spacing=0.1, c=0.5, damping=0.2, drops=[pc.Drop(0.0, (0.4, 0.3), radius=0.1, amplitude=0.01)], name="pond"))
    s.add(pc.GrayScott((8, 8), spacing=0.05, preset="spots", name="gs"))
    # projection="chorin": the old file's fluid stepped by Chorin's splitting, as a file without
    # the "projection" key still loads (the default became "incremental" in issue 64).
    s.add(pc.StableFluid((8, 8), spacing=0.1, nu=1e-3, buoyancy=(0.0, 0.5), name="smoke", projection="chorin",
                         sources=[pc.Source(density=1.0, temperature=1.0, velocity=(0.0, 0.2), center=(0.4, 0.2), radius=0.15)]))
    s.step(3)
    return s


def _fluid_scene() -> pc.Scene:
    """tests/scenes/data/old_names_fluid.npz's scene, in the new names."""
    f = pc.Scene(2, integrator="semi_implicit_euler", threads=1)
    f.add(pc.Gravity([0.0, -9.81]))
    f.add(Fluid(lattice([0, 0], [0.04, 0.03], 0.01), 0.01, alpha=0.1, boundary=tank_walls([0, 0], [0.06, 0.05], 0.01),
                boundary_volume="akinci", pass_precision="f32"))
    f.step(2)
    return f


# --------------------------------------------------------------------------- old files
def test_an_old_grid_and_dopri5_file_loads_under_the_new_names_and_continues_bit_for_bit(tmp_path, written_level):
    old = DATA / "old_names.npz"
    meta = json.loads(str(_members(old)["meta"][()]))
    assert meta["integrator"] == "rk45" and [g["kind"] for g in meta["grids"]] == ["wave", "gray_scott", "fluid"]
    loaded = pc.Scene.load(old)  # no warning: the file is not the user's code (warnings are errors here)
    assert loaded.integrator == "dopri5" and loaded.integrator_info["name"] == "dopri5"
    assert [g.kind for g in loaded.grids] == ["wave", "gray_scott", "stable_fluid"]
    pond, gs, smoke = loaded.grids
    assert (pond.spacing, pond.damping, gs.spacing, smoke.spacing, smoke.nu) == (0.1, 0.2, 0.05, 0.1, 1e-3)
    built = _grids_scene()
    # The file written now holds the new stored names, the wave's book of its changes of dt (a
    # member added after the old file was written: 0 here, nothing has stepped), and otherwise
    # the old file's bytes.
    new = built.save(tmp_path / "new.npz")
    assert loaded.save(tmp_path / "again.npz").read_bytes() == new.read_bytes()
    a, b = _members(old), _members(new)
    assert b.keys() - a.keys() == {"grid0_dt_changes"} and a.keys() <= b.keys()
    assert b["grid0_dt_changes"].dtype == np.float64 and b["grid0_dt_changes"].tolist() == [0.0]
    for k in a:
        if k != "meta":
            assert a[k].dtype == b[k].dtype and a[k].tobytes() == b[k].tobytes(), k
    renamed = str(a["meta"][()]).replace('"kind": "fluid"', '"kind": "stable_fluid"').replace('"integrator": "rk45"', '"integrator": "dopri5"')
    assert renamed == str(b["meta"][()])
    loaded.step(5)
    built.step(5)
    assert loaded.positions.tobytes() == built.positions.tobytes()
    for g, h in zip(loaded.grids, built.grids, strict=True):
        assert g.field("u").tobytes() == h.field("u").tobytes()


def test_an_old_sph_fluid_file_loads_under_the_new_names(tmp_path, written_level):
    old = DATA / "old_names_fluid.npz"
    assert {"term1_walls", "term1_wall_volume"} <= _members(old).keys()  # the file keeps these keys
    loaded = pc.Scene.load(old)
    (f,) = loaded.fluids
    assert (f.alpha, f.pass_precision, len(f.boundary)) == (0.1, "f32", len(tank_walls([0, 0], [0.06, 0.05], 0.01)))
    # The file written now is the old one's bytes but for the boundary's rule, a meta key added
    # after it was written (Psi_b recomputed by its rule, bit for bit, on load): "akinci" as
    # built, "given" (the file's volumes) as loaded from a file that does not say.
    a = _members(old)
    for scene, rule in ((_fluid_scene(), "akinci"), (loaded, "given")):
        b = _members(scene.save(tmp_path / f"{rule}.npz"))
        assert a.keys() == b.keys()
        for k in a:
            if k != "meta":
                assert a[k].dtype == b[k].dtype and a[k].tobytes() == b[k].tobytes(), k
        ma, mb = json.loads(str(a["meta"][()])), json.loads(str(b["meta"][()]))
        assert [t.pop("wall_rule", None) for t in mb["terms"]] == [None, rule]
        assert ma == mb


def test_the_old_grid_kind_is_an_alias_in_the_registry():
    assert PART_ALIASES["grids/fluid"] == "grids/stable_fluid" and PARTS["grids/stable_fluid"] is pc.StableFluid
    assert KIND_ALIASES == {"fluid": "stable_fluid"}
    assert "grids/fluid" not in PARTS  # one kind, one part: "fluid" is the SPH term's


# --------------------------------------------------------------------------- aliases
def _warns(new: str):
    """A DeprecationWarning whose message names the new spelling."""
    return pytest.warns(DeprecationWarning, match=new)


def _grid_fields(g):
    return (type(g), g.shape, g.spacing, g.edges, g._params().keys(), repr(g))


@pytest.mark.parametrize(
    ("old", "new", "attr", "value"),
    [
        (lambda: pc.Wave((8, 8), dx=0.1), lambda: pc.Wave((8, 8), spacing=0.1), "dx", 0.1),
        (lambda: pc.Wave((8, 8), gamma=0.3), lambda: pc.Wave((8, 8), damping=0.3), "gamma", 0.3),
        (lambda: pc.GrayScott((8, 8), dx=0.1, preset="spots"), lambda: pc.GrayScott((8, 8), spacing=0.1, preset="spots"), "dx", 0.1),
        (lambda: pc.StableFluid((8, 8), dx=0.1), lambda: pc.StableFluid((8, 8), spacing=0.1), "dx", 0.1),
        (lambda: pc.StableFluid((8, 8), viscosity=0.01), lambda: pc.StableFluid((8, 8), nu=0.01), "viscosity", 0.01),
    ],
)
def test_grid_aliases_warn_and_build_the_same_grid(old, new, attr, value):
    news = {"dx": "spacing", "gamma": "damping", "viscosity": "nu"}[attr]
    with _warns(f"{attr}= is now {news}="):
        a = old()
    b = new()
    assert _grid_fields(a) == _grid_fields(b) and a._params().keys() == b._params().keys()
    assert all(np.array_equal(np.asarray(a._params()[k]), np.asarray(b._params()[k])) for k in a._params())
    with _warns(f"{attr} is now .{news}"):
        assert getattr(b, attr) == value == getattr(b, news)


_X = lattice([0, 0], [0.04, 0.03], 0.01)
_W = tank_walls([0, 0], [0.06, 0.05], 0.01)


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ({"viscosity": 0.2}, {"alpha": 0.2}),
        ({"walls": _W}, {"boundary": _W}),
        ({"walls": _W, "wall_volume": "akinci"}, {"boundary": _W, "boundary_volume": "akinci"}),
        ({"precision": "f32"}, {"pass_precision": "f32"}),
    ],
)
def test_fluid_aliases_warn_and_build_the_same_fluid(old, new):
    with _warns(" is now "):
        a = Fluid(_X, 0.01, **old)
    b = Fluid(_X, 0.01, **new)
    assert a == b
    for o, n in zip(old, new, strict=True):
        with _warns(f"Fluid.{o} is now .{n}"):
            v = getattr(b, o)
        assert v is getattr(b, n)
    if "walls" in old:
        with _warns(r"wall_psi\(\) is now .boundary_psi\(\)"):
            assert np.array_equal(b.wall_psi(), b.boundary_psi())


def test_old_and_new_names_together_are_refused():
    with pytest.raises(TypeError, match="old name of alpha"):
        Fluid(_X, 0.01, alpha=0.1, viscosity=0.1)
    with pytest.raises(TypeError, match="old name of spacing"):
        pc.Wave((8, 8), spacing=0.1, dx=0.1)


def test_rk45_is_an_alias_of_dopri5():
    with _warns("'rk45' is now 'dopri5'"):
        s = pc.Scene(2, integrator="rk45")
    assert s.integrator == "dopri5" and s.integrator_info["name"] == "dopri5"
    t = pc.Scene(2)
    with _warns("'rk45' is now 'dopri5'"):
        t.integrator = "rk45"
    assert t.integrator == "dopri5" and repr(t) == repr(pc.Scene(2, integrator="dopri5"))
    assert "dopri5" in [d["name"] for d in pc.INTEGRATORS] and "rk45" not in [d["name"] for d in pc.INTEGRATORS]
    assert "dopri5" in pc.flows._METHODS  # one name for Dormand–Prince, particles and flows


@pytest.mark.parametrize(
    ("make", "old", "new"),
    [
        (scenes.dam_break, {"viscosity": 0.1, "precision": "f64"}, {"alpha": 0.1, "pass_precision": "f64"}),
        (scenes.drop, {"viscosity": 0.1}, {"alpha": 0.1}),
        (scenes.droplets, {"viscosity": 0.1}, {"alpha": 0.1}),
        (scenes.crown, {"viscosity": 0.1}, {"alpha": 0.1}),
    ],
)
def test_sph_scene_aliases_warn_and_build_the_same_scene(tmp_path, make, old, new):
    with _warns(" is now "):
        a = make(n=80, **old)
    b = make(n=80, **new)
    assert a.save(tmp_path / "a.npz").read_bytes() == b.save(tmp_path / "b.npz").read_bytes()


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        (lambda: pc.Springs([0], [1], 10.0, 0.5), lambda: pc.Springs([0], [1], stiffness=10.0, damping=0.5), "stiffness=, damping="),
        (lambda: pc.Plane([0.0, 0.0], [0.0, 1.0], 0.7, 0.1), lambda: pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=0.7, friction=0.1), "restitution="),
        (lambda: pc.Box([0.0, 0.0], [1.0, 1.0], 0.7), lambda: pc.Box([0.0, 0.0], [1.0, 1.0], restitution=0.7), "restitution="),
        (lambda: pc.Sphere([0.0, 0.0], 1.0, 0.7), lambda: pc.Sphere([0.0, 0.0], 1.0, restitution=0.7), "restitution="),
        (lambda: pc.PairwiseGravity(1.0, 0.1), lambda: pc.PairwiseGravity(1.0, softening=0.1), "softening="),
        (lambda: pc.Contacts(1e3, 0.5), lambda: pc.Contacts(1e3, restitution=0.5), "restitution="),
        (lambda: pc.GridElectricField(np.ones((3, 3, 2)), [0.0, 0.0], 1.0), lambda: pc.GridElectricField(np.ones((3, 3, 2)), [0.0, 0.0], spacing=1.0), "spacing="),
        (lambda: pc.PotentialGrid(np.zeros((3, 3)), 0.5, [0.0, 0.0]), lambda: pc.PotentialGrid(np.zeros((3, 3)), 0.5, origin=[0.0, 0.0]), "origin="),
        (lambda: pc.Drop(0.0, (1.0, 1.0), 0.1, 0.01), lambda: pc.Drop(0.0, (1.0, 1.0), radius=0.1, amplitude=0.01), "radius="),
        (lambda: pc.Source(1.0, 0.5), lambda: pc.Source(density=1.0, temperature=0.5), "density="),
        (lambda: Fluid(_X, 0.01, None, 900.0), lambda: Fluid(_X, 0.01, density=900.0), "velocities=, density="),
    ],
)
def test_old_positionals_warn_and_build_the_same_record(old, new, named):
    with _warns(f"pass {named}"):
        a = old()
    assert repr(a) == repr(new())  # (colliders compare arrays: by their repr)


def test_old_scene_positionals_and_the_grid_scenes_integrator_warn_and_build_the_same_scene(tmp_path):
    with _warns("pass size= by keyword"):
        a = scenes.cloth(8, 0.5)
    b = scenes.cloth(8, size=0.5)
    assert a.save(tmp_path / "a.npz").read_bytes() == b.save(tmp_path / "b.npz").read_bytes()
    with _warns("integrator= does nothing here and is ignored"):
        c = scenes.ripple(16, integrator="rk4")
    assert c.save(tmp_path / "c.npz").read_bytes() == scenes.ripple(16).save(tmp_path / "d.npz").read_bytes()
    # The old order, integrator included (then ignored: two warnings).
    with _warns("integrator= does nothing here"), _warns("pass drops=, speed=, damping=, seed=, integrator="):
        e = scenes.ripple(16, 6, 0.25, 0.15, 3, "verlet")
    assert e.save(tmp_path / "e.npz").read_bytes() == tmp_path.joinpath("d.npz").read_bytes()


def test_the_cli_takes_the_old_param_names_with_a_note(capsys):
    kwargs = cli._scene_kwargs("dam_break", scenes.dam_break, [("viscosity", "0.1"), ("precision", "f64")])
    assert kwargs == {"alpha": 0.1, "pass_precision": "f64"}
    err = capsys.readouterr().err
    assert "--param viscosity is deprecated: it is now alpha" in err and "--param precision is deprecated: it is now pass_precision" in err
    assert cli._scene_kwargs("ripple", scenes.ripple, [("n", "16")]) == {"n": 16}


def test_no_warning_from_the_new_names():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _grids_scene()
        _fluid_scene()
        scenes.smoke(n=16)
        scenes.pythagorean()
    assert [str(w.message) for w in caught] == []


def test_a_deprecation_is_blamed_on_the_users_line_however_deep_it_starts():
    """A fixed stacklevel blamed the scenes' wrapper (``scenes/_common.py``), which Python's
    default filters then hide (they show a DeprecationWarning only where ``__main__`` is
    blamed): the warning names the first frame outside physcore."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pc.scenes.turing(integrator="rk4", n=32)
        pc.scenes.kepler(0.5, 2.0)
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert len(deprecations) == 2
    assert all(w.filename == __file__ for w in deprecations), [w.filename for w in deprecations]
