"""physcore.testing: its strategies generate valid scenes whose conservation laws hold, and its
assertions fail when the laws do not hold."""
import numpy as np
import pytest
from hypothesis import given, settings

import physcore as pc
import physcore.testing as pt

FEW = settings(max_examples=15, deadline=None)


# 400 steps at dt = suggest_dt()/4, i.e. ω·dt ≤ 1/8 for the stiffest linear mode. Bounds from
# the linear theory of each method at that ω·dt: semi-implicit Euler's energy oscillates by
# about ω·dt/2 = 6e-2 (bound 0.1; worst of 150 random networks 4.3e-2), Verlet's by
# (ω·dt)²/8 = 2e-3 (bound 1e-2 for the nonlinear springs; worst 3.4e-3), RK4 loses (ω·dt)⁶/72
# per step, 2.1e-5 over 400 steps (bound 1e-4; worst of 350 1.3e-5). N-body: Verlet at
# Ω·dt ≈ 0.0125 of the softened encounter, (Ω·dt)²/8 = 2e-5 (worst of 100 1.8e-6).
@FEW
@given(pt.spring_networks(integrator="verlet", damping=True))
def test_spring_networks_balance_their_books_with_verlet(scene):
    assert pt.assert_energy_conserved(scene, steps=400, rtol=1e-2) <= 1e-2


@FEW
@given(pt.spring_networks(integrator="rk4", damping=True))
def test_spring_networks_balance_their_books_with_rk4(scene):
    assert pt.assert_energy_conserved(scene, steps=400, rtol=1e-4) <= 1e-4


@settings(max_examples=300, deadline=None, derandomize=True)
@given(pt.spring_networks(integrator="rk4", damping=True))
def test_spring_networks_never_take_a_spring_near_zero_length(scene):
    # The strategy's promise |ΔL| ≤ L_min/2 (from its energy bound): soft springs between heavy
    # masses once reached 5 % of their rest length, and rk4 then drifted by 2e-3.
    springs = next(t for t in scene.terms if isinstance(t, pc.Springs))
    i, j = np.asarray(springs.i), np.asarray(springs.j)
    rest = np.linalg.norm(scene.positions[i] - scene.positions[j], axis=1)
    for _ in range(40):
        scene.step(10)
        length = np.linalg.norm(scene.positions[i] - scene.positions[j], axis=1)
        assert np.all(np.abs(length - rest) <= rest.min() / 2 * (1 + 1e-6))


@FEW
@given(pt.spring_networks(integrator="semi_implicit_euler"))
def test_spring_networks_stay_bounded_with_semi_implicit_euler(scene):
    assert pt.assert_energy_conserved(scene, steps=400, rtol=0.1) <= 0.1


@FEW
@given(pt.spring_networks(integrator="verlet"))
def test_spring_networks_conserve_momentum(scene):
    pt.assert_momentum_conserved(scene, 200, rtol=1e-12)


@FEW
@given(pt.nbody_systems())
def test_nbody_systems_conserve_energy_and_momentum(scene):
    assert pt.assert_energy_conserved(scene, steps=200, rtol=2e-5) <= 2e-5
    pt.assert_momentum_conserved(scene, 100, rtol=1e-12)


@FEW
@given(pt.particle_clouds())
def test_particle_clouds_gain_exactly_the_gravity_impulse(scene):
    pt.assert_momentum_conserved(scene, 50, rtol=1e-12)


def test_energy_assertion_catches_explicit_euler():
    # Explicit Euler amplifies every oscillation: (1 + (ω dt)²)^(n/2) grows without bound.
    from hypothesis import find

    scene = find(pt.spring_networks(integrator="euler"), lambda s: s.n_particles >= 3, settings=settings(database=None))
    with pytest.raises(AssertionError, match="energy drift"):
        pt.assert_energy_conserved(scene, steps=4000, rtol=1e-2)


def test_momentum_assertion_catches_external_forces_and_refuses_pins():
    scene = pc.Scene(2, dt=1e-2)
    scene.add_particles([[0.0, 0.0]], [[1.0, 0.0]])
    scene.add(pc.Drag(0.5))  # an outside force that is not a uniform field
    with pytest.raises(AssertionError, match="momentum error"):
        pt.assert_momentum_conserved(scene, 10)
    pinned = pc.Scene(2)
    pinned.add_particles([[0.0, 0.0], [1.0, 0.0]], pinned=[True, False])
    with pytest.raises(ValueError, match="scene"):
        pt.assert_momentum_conserved(pinned, 10)


@pytest.mark.parametrize(("kw", "error", "message"), [
    ({"steps": 100, "rtol": 1e13}, pc.InvalidInputError, r"^rtol: must be in \(0, 1\), got 1e\+13 \(energy_drift\(\) is at most 1"),
    ({"steps": 100, "rtol": -1.0}, pc.InvalidInputError, "^rtol: must be in"),
    ({"steps": 100, "rtol": float("nan")}, pc.InvalidInputError, "^rtol: must be in"),
    ({"steps": 100, "rtol": "1e-3"}, pc.InvalidTypeError, "^rtol: expected a real number"),
    ({"steps": 2.5, "rtol": 1e-3}, pc.InvalidTypeError, "^steps: expected an int, got float 2.5"),
    ({"steps": 100, "rtol": 1e-3, "samples": 0}, pc.InvalidInputError, "^samples: must be >= 1"),
])
def test_assert_energy_conserved_checks_its_arguments_before_stepping(kw, error, message):
    """An rtol of 1e13 (a typo for 1e-13) passed every scene: energy_drift() is at most 1."""
    s = pc.scenes.kepler()
    with pytest.raises(error, match=message):
        pt.assert_energy_conserved(s, **kw)
    assert s.step_count == 0


def test_the_assertions_and_strategies_name_a_bad_argument_when_called():
    with pytest.raises(pc.InvalidTypeError, match="^scene: expected a physcore.Scene, got str"):
        pt.assert_energy_conserved("kepler", 10, 1e-3)
    with pytest.raises(pc.InvalidTypeError, match="^steps:"):
        pt.assert_momentum_conserved(pc.scenes.kepler(), steps=1.5)
    with pytest.raises(pc.InvalidInputError, match="^max_particles: must be >= 2, got 0"):
        pt.spring_networks(max_particles=0)
    with pytest.raises(pc.InvalidInputError, match="^max_bodies: must be >= 2"):
        pt.nbody_systems(max_bodies=1)
    with pytest.raises(pc.InvalidInputError, match="^integrator: must be one of"):
        pt.particle_clouds(integrator="rk5")
