"""Friction between grains and rigid bodies turns the grains (issue 64, item 5): the coupling
pushes a grain that turns (a radius and a spin, under :class:`~physcore.Contacts`) at its
surface point, so the friction impulse carries its moment r × J to the grain's spin, and the
body takes −J at the same point. Checked against rigid impact theory and by the total angular
momentum of grains and a free box."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import physcore as pc

R = 0.05  # grain radius (m)
M = 1.0  # grain mass (kg)


def _impact(dim: int, mu: float, e: float = 0.5, dt: float = 1e-4) -> pc.Scene:
    """A grain of radius R meeting the top face of a fixed box at u_t = u_n = 1 m/s, no gravity,
    the box's friction μ and restitution e; stepped well past the impact."""
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", dt=dt)
    if dim == 2:
        s.add(pc.Bodies("box", size=[(1.0, 0.1)], positions=[(0.0, -0.1)], kind="fixed", friction=mu, restitution=e))
        s.add_particles([[0.0, R + 0.01]], velocities=[[1.0, -1.0]], masses=[M])
    else:
        s.add(pc.Bodies("box", size=[(1.0, 1.0, 0.1)], positions=[(0.0, 0.0, -0.1)], kind="fixed", friction=mu,
                        restitution=e))
        s.add_particles([[0.0, 0.0, R + 0.01]], velocities=[[1.0, 0.0, -1.0]], masses=[M])
    s.set_attribute("radius", [R])
    s.add(pc.Contacts(stiffness=1e5, friction=mu))
    s.step(int(round(0.1 / dt)))
    return s


def _spin(s: pc.Scene) -> float:
    """The grain's spin about the axis that rolls it along +x on a floor below it (rad/s):
    −ω_z in 2D, ω_y in 3D (ω × (−R n) = +x·ωR for rolling to the right)."""
    if s.dim == 2:
        return -float(s.particle_field("angular_velocity")[0])
    return float(s.particle_field("angular_velocity_y")[0])


@pytest.mark.parametrize("dim", [2, 3])
def test_a_grain_hitting_a_fixed_box_with_friction_leaves_rolling_as_rigid_impact_theory_says(dim):
    """Rigid impact with Coulomb friction (Stronge, *Impact Mechanics*, 2000, §4.2; Garwin,
    Am. J. Phys. 37 (1969) 88, the rough ball at tangential restitution 0). A grain of mass m,
    radius r, I = β m r² (β = ½ disc, ⅖ sphere) meets a fixed surface with normal approach u_n
    and tangential speed u_t, no spin. Normal impulse J_n = m(1 + e)u_n. Friction J_t acts at
    the contact point, r below the centre:

        m (v_t' − u_t) = −J_t,    I ω' = r J_t    (ω the rolling spin),

    and the contact point's slip is v_t' − ω' r. Sticking would need the slip to end at 0:
    J_t = u_t / (1/m + r²/I) = m u_t β/(1 + β), allowed when J_t ≤ μ J_n. Then

        v_t' = u_t − J_t/m = u_t/(1 + β),   ω' r = v_t'  (rolling off):

    ⅔ u_t for a disc, 5/7 u_t for a sphere. Here u_t = u_n = 1 m/s, e = 0.5, μ = 1 (μ J_n =
    1.5 m ≥ m β/(1+β)): 0.6667 and 0.7143 m/s. Before physcore pushed grains at their surface it
    left with v_t = 0 and no spin (the impulse at the centre with the centre's effective mass).
    With μ = 0.05 it slides throughout: J_t = μ J_n, v_t' = u_t − μ(1 + e)u_n = 0.925 m/s and
    ω' r = μ(1 + e)u_n/β."""
    beta = 0.5 if dim == 2 else 0.4
    rel = 1e-9  # the gate is 2 %; measured: exact to 3e-16
    s = _impact(dim, mu=1.0)
    v = s.velocities[0]
    assert v[0] == pytest.approx(1.0 / (1.0 + beta), rel=rel)
    assert v[-1] == pytest.approx(0.5, rel=rel)  # e u_n
    assert _spin(s) * R == pytest.approx(v[0], rel=rel)  # rolling: the contact point at rest
    assert np.abs(v[1:-1]).max(initial=0.0) < 1e-12  # no sideways motion in 3D
    s = _impact(dim, mu=0.05)
    v = s.velocities[0]
    assert v[0] == pytest.approx(1.0 - 0.05 * 1.5, rel=rel)
    assert _spin(s) * R == pytest.approx(0.05 * 1.5 / beta, rel=rel)


def _box_angular_momentum(box: pc.Bodies) -> np.ndarray:
    """L of a free box about the origin (kg·m²/s): m x × v + I ω, 3 components."""
    m = box.masses[0]
    if box.dim == 2:
        x, v = np.append(box.positions[0], 0.0), np.append(box.velocities[0], 0.0)
        return m * np.cross(x, v) + np.array([0.0, 0.0, box.inertia[0] * box.angular_velocities[0]])
    rot = Rotation.from_quat(box.orientations[0]).as_matrix()
    inertia = rot @ np.diag(box.inertia[0]) @ rot.T  # a box's principal axes are its own
    return m * np.cross(box.positions[0], box.velocities[0]) + inertia @ box.angular_velocities[0]


def _total(s: pc.Scene, box: pc.Bodies) -> np.ndarray:
    grains = s.angular_momentum()  # Σ m x × v + Σ I ω of the grains
    grains = np.array([0.0, 0.0, grains]) if s.dim == 2 else np.asarray(grains)
    return grains + _box_angular_momentum(box)


@pytest.mark.parametrize("dim", [2, 3])
def test_grains_and_a_free_box_keep_their_angular_momentum_through_impacts_with_friction(dim):
    """No gravity: eight grains thrown obliquely at the faces of a free box (μ = 1, e = 0.5);
    the total angular momentum (grains' orbits and spins, the box's) changes by under 1 % of
    what the box takes (measured: 0.03 % in 2D, 0.08 % in 3D). Before: 7.2 % and 8.1 % here,
    20–34 % in the issue's scenes (the box took the moment about the contact point, the grain
    none). What remains is the push back to the surface, m δ n × v for a grain found δ inside
    (δ about u_n dt): first order in dt (0.4 % and 1.5 % at dt = 1e-3, 3× the contacts' step)."""
    s = pc.Scene(dim=dim, integrator="semi_implicit_euler", dt=1e-4)
    rng = np.random.default_rng(3)
    if dim == 2:
        box = s.add(pc.Bodies("box", size=[(0.2, 0.15)], positions=[(0.0, 0.0)], density=100.0, friction=1.0,
                              restitution=0.5))
        ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
        x = 0.45 * np.stack([np.cos(ang), np.sin(ang)], 1)
        # Aimed at the box, with a sideways part of the speed and a spread.
        v = -2.0 * x / 0.45 + 0.8 * np.stack([-np.sin(ang), np.cos(ang)], 1) + rng.normal(0, 0.2, (8, 2))
    else:
        box = s.add(pc.Bodies("box", size=(0.2, 0.15, 0.1), positions=[(0.0, 0.0, 0.0)], density=100.0, friction=1.0,
                              restitution=0.5))
        d = rng.normal(size=(8, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        x = 0.45 * d
        side = np.cross(d, rng.normal(size=(8, 3)))
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        v = -2.0 * d + 0.8 * side
    s.add_particles(x, velocities=v, masses=np.full(8, 0.5))
    s.set_attribute("radius", np.full(8, 0.02))
    s.add(pc.Contacts(stiffness=1e4, friction=1.0, restitution=0.5))
    l0 = _total(s, box)
    s.step(4000)
    exchanged = np.linalg.norm(_box_angular_momentum(box))
    assert exchanged > 0.05  # the box was hit off-centre and turns
    assert np.linalg.norm(_total(s, box) - l0) < 0.01 * exchanged  # measured: 0.03 % (2D), 0.08 % (3D)
    names = ["angular_velocity"] if dim == 2 else [f"angular_velocity_{c}" for c in "xyz"]
    spins = np.stack([s.particle_field(n) for n in names], 1)
    hit = np.linalg.norm(s.velocities - v, axis=1) > 0.1
    assert hit.sum() >= 6 and (np.linalg.norm(spins[hit], axis=1) > 1.0).all()  # every grain that hit turns


def test_particles_without_spin_meet_bodies_at_their_centres_as_before():
    """A particle with a radius but no Contacts term (no spin) keeps the impulse at its
    centre with the centre's effective mass: it stops sliding on a fixed box (μ = 1), as
    before grains turned."""
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", dt=1e-4)
    s.add(pc.Bodies("box", size=[(1.0, 0.1)], positions=[(0.0, -0.1)], kind="fixed", friction=1.0, restitution=0.5))
    s.add_particles([[0.0, R + 0.01]], velocities=[[1.0, -1.0]], masses=[M])
    s.set_attribute("radius", [R])
    s.step(1000)
    assert s.velocities[0] == pytest.approx([0.0, 0.5], abs=1e-12)
