"""The Python contract of Scene, the terms and the package namespace."""
from __future__ import annotations

import dataclasses
import inspect
import math

import numpy as np
import pytest

import physcore as pc


@pytest.fixture(params=[2, 3])
def scene(request) -> pc.Scene:
    dim = request.param
    rng = np.random.default_rng(dim)
    s = pc.Scene(dim, integrator="verlet", dt=1e-3, threads=1)
    s.add_particles(rng.uniform(-1, 1, size=(5, dim)), rng.normal(size=(5, dim)), masses=rng.uniform(0.5, 2, size=5))
    s.add(pc.Springs([0, 1, 2, 3], [1, 2, 3, 4], stiffness=20.0))
    return s


# ----------------------------------------------------------------------------- state arrays
def test_positions_and_velocities_are_float64_copies(scene):
    for name in ("positions", "velocities"):
        a = getattr(scene, name)
        b = getattr(scene, name)
        assert isinstance(a, np.ndarray)
        assert a.dtype == np.float64
        assert a.shape == (scene.n_particles, scene.dim)
        assert a.flags.c_contiguous
        assert not np.shares_memory(a, b)
        original = a.copy()
        a[:] = 123.0  # writing to the copy does not reach the scene
        assert np.array_equal(getattr(scene, name), original)
    for name, dtype in (("masses", np.float64), ("pinned", np.bool_)):
        a = getattr(scene, name)
        assert a.shape == (scene.n_particles,) and a.dtype == dtype
        original = a.copy()
        a[...] = ~a if dtype == np.bool_ else -a
        assert np.array_equal(getattr(scene, name), original)


def test_setters_replace_state(scene):
    n, dim = scene.n_particles, scene.dim
    x = np.arange(n * dim, dtype=float).reshape(n, dim)
    v = -x / 10
    scene.positions = x
    scene.velocities = v.tolist()  # any array-like
    assert np.array_equal(scene.positions, x)
    assert np.array_equal(scene.velocities, v)
    x[0, 0] = 99.0  # the scene took a copy
    assert scene.positions[0, 0] == 0.0
    # Integer input is accepted and converted.
    scene.positions = np.ones((n, dim), dtype=np.int32)
    assert scene.positions.dtype == np.float64
    assert np.array_equal(scene.positions, np.ones((n, dim)))


def test_setter_resets_energy_drift_baseline(scene):
    scene.step(100)
    scene.velocities = scene.velocities * 2  # a new physical situation
    assert scene.energy_drift() == 0.0
    scene.step(10)
    assert abs(scene.energy_drift()) < 1e-3


def test_pinned_particles_never_move():
    s = pc.Scene(3, integrator="rk4", dt=1e-3, threads=1)
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]])
    v = np.ones((4, 3))
    ids = s.add_particles(x, v, masses=[1.0, 1.0, 1.0, 5.0], pinned=[True, False, True, False])
    assert ids.dtype == np.int64
    assert s.pinned.tolist() == [True, False, True, False]
    # Given velocities of pinned particles are ignored.
    assert np.array_equal(s.velocities[[0, 2]], np.zeros((2, 3)))
    s.add(pc.Springs([0, 1, 2], [1, 2, 3], stiffness=50.0))
    s.add(pc.Gravity([0.0, 0.0, -9.81]))
    s.add(pc.PairwiseGravity(G=1.0, softening=0.1))
    s.add(pc.Drag(0.1))
    s.add(pc.Plane([0.0, 0.0, -0.5], [0.0, 0.0, 1.0]))
    s.step(500)
    assert np.array_equal(s.positions[[0, 2]], x[[0, 2]])
    assert np.array_equal(s.velocities[[0, 2]], np.zeros((2, 3)))
    assert not np.array_equal(s.positions[[1, 3]], x[[1, 3]])
    # Setting velocities cannot make a pinned particle move either.
    s.velocities = np.full((4, 3), 3.0)
    assert np.array_equal(s.velocities[[0, 2]], np.zeros((2, 3)))
    s.step(10)
    assert np.array_equal(s.positions[[0, 2]], x[[0, 2]])
    # Pinned particles carry no kinetic energy and no momentum.
    p = s.momentum()
    m, vel = s.masses, s.velocities
    assert np.allclose(p, (m[[1, 3], None] * vel[[1, 3]]).sum(axis=0), rtol=1e-14, atol=0)


def test_add_particles_returns_int64_indices(scene):
    n = scene.n_particles
    ids = scene.add_particles(np.zeros((3, scene.dim)))
    assert isinstance(ids, np.ndarray)
    assert ids.dtype == np.int64
    assert ids.tolist() == [n, n + 1, n + 2]
    assert scene.n_particles == n + 3
    one = scene.add_particles(np.ones(scene.dim))  # a single point as a 1-D array
    assert one.tolist() == [n + 3]
    assert np.array_equal(scene.positions[-1], np.ones(scene.dim))
    # Defaults: mass 1, at rest, not pinned.
    assert scene.masses[-1] == 1.0
    assert np.array_equal(scene.velocities[-1], np.zeros(scene.dim))
    assert not scene.pinned[-1]


def test_particles_added_after_springs_are_free(scene):
    scene.add_particles(np.full((1, scene.dim), 5.0), np.full((1, scene.dim), 1.0))
    scene.step(100)
    # No force on the newcomer: it coasts.
    assert scene.positions[-1] == pytest.approx(np.full(scene.dim, 5.0 + 100 * 1e-3), rel=1e-12)


# ----------------------------------------------------------------------------- terms
def test_term_names_are_deduplicated(scene):
    first = scene.terms[0]
    assert first.name == "springs"
    second = scene.add(pc.Springs([0], [2], stiffness=1.0))
    third = scene.add(pc.Springs([1], [3], stiffness=1.0))
    assert second.name == "springs_2"
    assert third.name == "springs_3"
    g = scene.add(pc.Gravity([0.0] * scene.dim, name="g"))
    g2 = scene.add(pc.Gravity([0.0] * scene.dim, name="g"))
    assert (g.name, g2.name) == ("g", "g_2")
    assert [t.name for t in scene.terms] == ["springs", "springs_2", "springs_3", "g", "g_2"]
    assert set(scene.energy().potential) == {"springs", "springs_2", "springs_3", "g", "g_2"}
    # "collisions" is reserved for the colliders' account.
    d = scene.add(pc.Drag(0.1, name="collisions"))
    assert d.name == "collisions_2"


def test_springs_rest_length_resolved_from_geometry(scene):
    x = scene.positions
    s = scene.add(pc.Springs([0, 4], [2, 1], stiffness=3.0))
    np.testing.assert_allclose(s.rest_length, [np.linalg.norm(x[2] - x[0]), np.linalg.norm(x[1] - x[4])], rtol=1e-15)
    i, j, rest = scene.spring_pairs()
    assert i.dtype == np.int64 and j.dtype == np.int64 and rest.dtype == np.float64
    assert i.tolist() == [0, 1, 2, 3, 0, 4]
    assert j.tolist() == [1, 2, 3, 4, 2, 1]
    # A spring at its rest length stores no energy.
    assert scene.energy().potential["springs_2"] == pytest.approx(0.0, abs=1e-28)


def test_terms_are_immutable():
    g = pc.Gravity([0.0, -9.81])
    with pytest.raises(ValueError, match="read-only"):
        g.g[1] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.name = "other"
    assert g.name == "gravity" and np.array_equal(g.g, [0.0, -9.81])
    p = pc.Plane([0.0, 0.0], [0.0, 3.0])
    assert np.array_equal(p.normal, [0.0, 1.0])  # normalised


# ----------------------------------------------------------------------------- diagnostics
def test_energy_report_fields():
    s = pc.Scene(2, integrator="verlet", dt=1e-3, threads=1)
    m = np.array([1.0, 2.0])
    x = np.array([[0.0, 1.0], [2.0, 3.0]])
    v = np.array([[1.0, 0.0], [0.5, -1.0]])
    s.add_particles(x, v, masses=m)
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.Springs([0], [1], stiffness=4.0, rest_length=1.0, damping=0.1))
    s.add(pc.PairwiseGravity(G=2.0, softening=0.5))
    s.add(pc.Drag(0.2))
    s.add(pc.Plane([0.0, -5.0], [0.0, 1.0]))
    e = s.energy()
    assert isinstance(e, pc.EnergyReport)
    assert e.kinetic == pytest.approx(0.5 * (m * (v**2).sum(axis=1)).sum(), rel=1e-15)
    r = np.linalg.norm(x[1] - x[0])
    assert e.potential == pytest.approx(
        {
            "gravity": 9.81 * (m * x[:, 1]).sum(),
            "springs": 0.5 * 4.0 * (r - 1.0) ** 2,
            "pairwise_gravity": -2.0 * m[0] * m[1] / math.sqrt(r * r + 0.25),
        },
        rel=1e-14,
    )
    assert e.dissipated == {"springs": 0.0, "drag": 0.0, "collisions": 0.0}
    assert e.mechanical == pytest.approx(e.kinetic + sum(e.potential.values()), rel=1e-15)
    assert e.total == pytest.approx(e.mechanical + sum(e.dissipated.values()), rel=1e-15)
    assert s.energy_drift() == 0.0  # before any step
    s.step(100)
    e2 = s.energy()
    assert all(d > 0 for k, d in e2.dissipated.items() if k != "collisions")
    assert abs(s.energy_drift()) < 1e-3


def test_undamped_springs_have_no_dissipation_account():
    s = pc.Scene(2)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]])
    s.add(pc.Springs([0], [1]))
    s.add(pc.Drag(0.0))
    assert s.energy().dissipated == {}


def test_momentum_and_angular_momentum_shapes():
    s2 = pc.Scene(2)
    s2.add_particles([[1.0, 0.0], [0.0, 2.0]], [[0.0, 3.0], [1.0, 0.0]], masses=[2.0, 0.5])
    L2 = s2.angular_momentum()
    assert isinstance(L2, float)
    # L_z = Σ m (x v_y - y v_x) = 2·(1·3) + 0.5·(0 - 2·1) = 5
    assert L2 == pytest.approx(5.0, rel=1e-15)
    p2 = s2.momentum()
    assert p2.shape == (2,) and p2.dtype == np.float64
    assert p2.tolist() == pytest.approx([0.5, 6.0])

    s3 = pc.Scene(3)
    x = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    v = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
    s3.add_particles(x, v, masses=[1.0, 3.0])
    L3 = s3.angular_momentum()
    assert isinstance(L3, np.ndarray) and L3.shape == (3,) and L3.dtype == np.float64
    np.testing.assert_allclose(L3, np.cross(x, v * np.array([[1.0], [3.0]])).sum(axis=0), rtol=1e-15)
    assert s3.momentum().shape == (3,)


def test_suggest_dt_for_a_single_spring():
    # One free mass on a spring to a pinned anchor: ω = sqrt(k/m). The Gershgorin bound used is
    # ω_max² ≤ 2k/m, and suggest_dt is half of 1/ω_max: it must be well inside Verlet's 2/ω.
    k, m = 400.0, 4.0
    s = pc.Scene(2, dt=0.5)
    s.add_particles([[0.0, 0.0], [1.0, 0.0]], masses=[1.0, m], pinned=[True, False])
    assert s.suggest_dt() == 0.5  # no term with a time scale yet: the current dt
    s.add(pc.Springs([0], [1], stiffness=k))
    dt = s.suggest_dt()
    omega = math.sqrt(k / m)
    assert 0 < dt * omega < 1
    assert dt == pytest.approx(0.5 / math.sqrt(2 * k / m), rel=1e-12)


def test_scene_properties_and_repr(scene):
    assert scene.dim in (2, 3)
    assert scene.threads == 1
    assert scene.integrator == "verlet"
    scene.integrator = "rk4"
    assert scene.integrator == "rk4"
    assert scene.integrator_info["order"] == 4
    scene.dt = 2e-3
    assert scene.dt == 2e-3
    t0 = scene.time
    scene.step(5)
    assert scene.step_count == 5
    assert scene.time == pytest.approx(t0 + 5 * 2e-3, rel=1e-15)
    r = repr(scene)
    assert "Scene(" in r and "rk4" in r and "springs" in r
    assert pc.Scene().threads is None


# ----------------------------------------------------------------------------- package
def test_all_names_exist():
    for name in pc.__all__:
        assert getattr(pc, name) is not None, name
    assert isinstance(pc.__version__, str) and pc.__version__
    with pytest.raises(AttributeError):
        pc.no_such_thing  # noqa: B018


def test_build_profile_is_a_string():
    assert isinstance(pc._core.build_profile, str)
    assert pc._core.build_profile in ("debug", "release")


def test_readme_style_example():
    # The docstring example of Scene: a mass hanging on a spring from a pinned particle.
    scene = pc.Scene(dim=2, integrator="verlet", dt=1e-3)
    ids = scene.add_particles(np.array([[0.0, 0.0], [1.0, 0.0]]), pinned=[True, False])
    assert ids.tolist() == [0, 1]
    g = scene.add(pc.Gravity([0.0, -9.81]))
    sp = scene.add(pc.Springs([0], [1], stiffness=100.0))
    assert g.name == "gravity" and sp.name == "springs"
    scene.step(1000)
    assert round(scene.time, 6) == 1.0
    assert scene.step_count == 1000
    # The mass fell and swings below the pivot; energy is conserved to Verlet accuracy.
    assert scene.positions[1, 1] < 0
    assert abs(scene.energy_drift()) < 1e-3


GRAIN_SCENES = ("galton_board", "billiards", "newtons_cradle", "jelly")
# Surface tension is DFSPH's, which steps with semi-implicit Euler only (tests/fluids/test_surface_tension.py).
SEMI_IMPLICIT_ONLY = GRAIN_SCENES + ("droplets", "crown")
#: Scenes of XpbdConstraints, which only the "xpbd" integrator projects.
XPBD_ONLY = ("xpbd_cloth", "shape_matched_boxes")


GRID_SCENES = {"ripple", "double_slit", "turing", "smoke", "cavity", "vortex_street"}
#: Scenes of rigid bodies only: rapier steps them with its own scheme, so they take no integrator.
BODY_SCENES = {"dominoes", "pyramid", "tumbling_boxes"}


@pytest.mark.parametrize("name", sorted(pc.scenes.REGISTRY))
def test_every_registered_scene_builds_and_steps(name):
    s = pc.scenes.REGISTRY[name]()
    assert isinstance(s, pc.Scene)
    assert s.n_particles > 0 or s.grids or s.flows or s.bodies  # field, flow, body scenes may have no particles
    e0 = s.energy()
    assert math.isfinite(e0.total)
    n0 = s.step_count  # 0, or the steps of a scene returned already started (turing, double_slit: start=)
    s.step(10)
    e = s.energy()
    assert s.step_count == n0 + 10
    assert math.isfinite(e.total) and math.isfinite(e.kinetic)
    assert np.all(np.isfinite(s.positions)) and np.all(np.isfinite(s.velocities))
    assert abs(s.energy_drift()) < 1e-2
    # Every scene also accepts integrator= and threads= (grains step only with the DEM
    # scheme, semi-implicit Euler, and refuse others by name: tests/grains/test_contacts.py; so do
    # the surface-tension scenes, DFSPH's). The grid scenes' integrator= did nothing: since
    # issue 45 it is deprecated and ignored (their grids step with their own schemes).
    integrator = "semi_implicit_euler" if name in SEMI_IMPLICIT_ONLY else "rk4"
    if name in XPBD_ONLY:  # XpbdConstraints: any other integrator is refused by name
        with pytest.raises(pc.InvalidInputError, match="integrator"):
            pc.scenes.REGISTRY[name](integrator=integrator, threads=1)
        integrator = "xpbd"
    if name in GRID_SCENES:
        assert "integrator" not in inspect.signature(pc.scenes.REGISTRY[name]).parameters
        with pytest.warns(DeprecationWarning, match="integrator= does nothing here and is ignored"):
            s2 = pc.scenes.REGISTRY[name](integrator=integrator, threads=1)
        integrator = "verlet"
    elif name in BODY_SCENES:
        assert "integrator" not in inspect.signature(pc.scenes.REGISTRY[name]).parameters
        s2 = pc.scenes.REGISTRY[name](threads=1)
        integrator = s.integrator
    else:
        s2 = pc.scenes.REGISTRY[name](integrator=integrator, threads=1)
    assert s2.integrator == integrator and s2.threads == 1
    s2.step(10)
    assert np.all(np.isfinite(s2.positions))


def test_scene_functions_validate_arguments():
    with pytest.raises(ValueError, match=r"\be\b"):
        pc.scenes.kepler(e=1.0)
    with pytest.raises(ValueError, match="mass_ratio"):
        pc.scenes.kepler(mass_ratio=-1.0)
    with pytest.raises(ValueError, match=r"\bn\b"):
        pc.scenes.cloth(n=1)
    with pytest.raises(TypeError, match=r"\bn\b"):
        pc.scenes.projectile(n=2.5)
    with pytest.raises(ValueError, match="pin"):
        pc.scenes.cloth(pin="middle")


def test_setting_an_attribute_the_scene_does_not_have_is_refused():
    """``scene.gravity = [0, -9.81]`` was stored and ignored: the scene fell without gravity."""
    s = pc.Scene(2)
    with pytest.raises(AttributeError, match=r"^Scene has no attribute 'gravity' to set: physics is added as a "
                                             r"term, scene\.add\(pc\.Gravity\(\.\.\.\)\)"):
        s.gravity = [0.0, -9.81]
    with pytest.raises(AttributeError, match="^Scene has no attribute 'stepsize' to set$"):
        s.stepsize = 0.1
    s.dt = 0.01  # what the scene has stays settable
    s.render_defaults = {"frames": 3}
    assert s.dt == 0.01 and s.render_defaults == {"frames": 3} and not hasattr(s, "gravity")
