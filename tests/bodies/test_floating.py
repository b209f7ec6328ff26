"""Bodies in a DFSPH fluid through boundary particles (Akinci et al., ACM TOG 31 (2012) 62):
each moving body's surface sampled at the fluid's spacing, the fluid's pressure solve pushing
the bodies iteration by iteration (``physcore.bodies``, "Bodies in a fluid").

* a floating box's draft against Archimedes (ρ_body/ρ_fluid × height), converging with the
  resolution; the same boundary under a WCSPH fluid;
* momentum: a box shot into a weightless blob of water keeps the total to rounding (both);
* one and two threads, and a saved scene, step the same bits.
"""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc
from physcore.fluids import lattice, tank_walls

G, RHO = 9.81, 1000.0
W, DEPTH, HX, HY = 1.0, 0.4, 0.1, 0.05


def _pool(n: int, rho_body: float, threads: int | None = None, method: str = "dfsph") -> tuple[pc.Scene, pc.Bodies, float]:
    """A pool W × DEPTH (n particles across, DFSPH unless `method` says, α = 0.5: a layer that
    settles) with a box 2 HX × 2 HY of density rho_body dropped on it from 2 cm. Returns
    (scene, box, spacing)."""
    dx = W / n
    s = pc.Scene(2, integrator="semi_implicit_euler", threads=threads)
    s.add(pc.Gravity([0.0, -G]))
    s.add_fluid(lattice([0, 0], [W, DEPTH], dx), spacing=dx, boundary=tank_walls([0, 0], [W, 1.0], dx, layers=3),
                method=method, alpha=0.5)
    box = s.add(pc.Bodies("box", size=[(HX, HY)], positions=[(0.5 * W, DEPTH + HY + 0.02)], density=rho_body,
                          friction=0.2, restitution=0.0))
    return s, box, dx


def _draft(n: int, rho_body: float, method: str = "dfsph") -> float:
    """The settled draft: the water's surface away from the box (its top particles, plus half a
    spacing: the fluid's edge) less the box's bottom, both averaged over t = 2.5 .. 4 s."""
    s, box, dx = _pool(n, rho_body, method=method)
    drafts = []
    while s.time < 4.0:
        s.dt = min(s.suggest_dt(), 2e-3) if method == "dfsph" else s.suggest_dt()
        s.step(1)
        if s.time > 2.5:
            x = s.positions
            far = x[np.abs(x[:, 0] - 0.5 * W) > 0.3, 1]
            surface = np.sort(far)[-10:].mean() + 0.5 * dx
            drafts.append(surface - (box.positions[0, 1] - HY))
    return float(np.mean(drafts))


@pytest.mark.parametrize("rho_body", [500.0, 900.0])
def test_a_floating_box_sinks_to_its_archimedes_draft_as_the_resolution_grows(rho_body):
    """A box floats at draft ρ_b/ρ_w × 2 HY. Measured (draft from the far surface, cm), at 40 and
    80 particles across the pool (spacing 2.5 and 1.25 cm):

    ======  ==========  ======  ======  ==============
    ρ_b     Archimedes  n = 40  n = 80  error at 80
    ======  ==========  ======  ======  ==============
    250     2.5         0.79    1.95    −22 % (0.44 Δx)
    500     5.0         3.75    4.81    −3.8 % (0.15 Δx)
    900     9.0         7.95    9.09    +1.0 % (0.07 Δx)
    ======  ==========  ======  ======  ==============

    The error is a boundary offset that shrinks with the spacing: within half a spacing at 80
    across, and within 5 % where the draft is 4 spacings or more (the 250 row, a draft of two
    spacings, is measured by the same `_draft` and left out of the run: 13 s for a figure the
    guide states). (The impulse exchange alone,
    before the boundary particles, sank a box of half the water's density 20 % too deep.)"""
    archimedes = rho_body / RHO * 2 * HY
    coarse, fine = _draft(40, rho_body), _draft(80, rho_body)
    assert abs(fine - archimedes) < abs(coarse - archimedes)
    assert abs(fine - archimedes) < 0.5 * W / 80
    if archimedes >= 4 * W / 80:
        assert fine == pytest.approx(archimedes, rel=0.05)


def test_a_wcsph_fluid_floats_a_box_too():
    """WCSPH (Tait equation of state) through the same boundary particles, its pressure force
    −m_i Ψ_b (p_i/ρ_i²) ∇W_ib (Akinci 2012, eq. 10) and the reaction on the body: at 40 across,
    draft 4.68 cm against 5.00 (−6.4 %, 0.13 Δx; the box 4 spacings high), within half a spacing
    (and 9.47 against 9.00 at 900 kg/m², +5.2 %, not run here)."""
    assert abs(_draft(40, 500.0, "wcsph") - 0.05) < 0.5 * W / 40


@pytest.mark.parametrize("method", ["dfsph", "wcsph"])
def test_a_box_shot_into_weightless_water_keeps_the_momentum(method):
    """No gravity, no walls: a box flies at 1 m/s into a blob of water at rest; the fluid's
    pushes on the box are equal and opposite to the water's, so the total momentum is kept to
    rounding, and the box is slowed (the water takes some of it)."""
    dx = 0.02
    s = pc.Scene(2, integrator="semi_implicit_euler", dt=1e-3 if method == "dfsph" else 2e-4)
    water = lattice([0, 0], [0.4, 0.4], dx)
    s.add_fluid(water, spacing=dx, method=method, alpha=0.5, sound_speed=10.0)
    box = s.add(pc.Bodies("box", size=[(0.05, 0.05)], positions=[(-0.1, 0.2)], velocities=[(1.0, 0.0)], density=500.0))
    m_box, m = float(box.masses[0]), s.masses
    p0 = m_box * box.velocities[0] + (m[:, None] * s.velocities).sum(axis=0)
    s.step(250 if method == "dfsph" else 1250)
    p1 = m_box * box.velocities[0] + (m[:, None] * s.velocities).sum(axis=0)
    assert np.allclose(p1, p0, rtol=0, atol=1e-12 * m_box)
    assert 0.05 < box.velocities[0, 0] < 0.95  # it hit the water and gave it momentum
    assert (s.velocities[:, 0] > 1e-3).sum() > 10


def test_floating_bodies_step_the_same_bits_on_one_and_two_threads_and_after_a_save(tmp_path):
    a, ba, _ = _pool(24, 500.0, threads=1)
    b, bb, _ = _pool(24, 500.0, threads=2)
    a.dt = b.dt = 2e-3
    a.step(150)
    b.step(150)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(ba.positions, bb.positions)
    a.save(tmp_path / "pool.npz")
    r = pc.Scene.load(tmp_path / "pool.npz")
    a.step(100)
    r.step(100)
    assert np.array_equal(a.positions, r.positions)
    assert np.array_equal(a.bodies[0].positions, r.bodies[0].positions)
    assert a.energy().total == r.energy().total
