"""The gallery scenes built on tree gravity and charges: galaxies (two Plummer spheres) and
cyclotron (gyration and E×B drift), and the Plummer sampler they start from."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc


def test_plummer_sphere_is_in_virial_equilibrium():
    # Plummer (1911): W = −3πGM²/(32a), and 2K + W = 0 in equilibrium (virial theorem).
    x, v = pc.scenes.plummer_sphere(4000, seed=1)
    s = pc.Scene(3)
    s.add_particles(x, v, masses=1 / 4000)
    s.add(pc.PairwiseGravity(G=1.0))
    e = s.energy()
    w = sum(e.potential.values())
    assert w == pytest.approx(-3 * math.pi / 32, rel=0.03)  # measured −0.2970 vs −0.2945
    assert 2 * e.kinetic / abs(w) == pytest.approx(1.0, abs=0.05)  # measured 1.018
    # Half the mass within 1.305 a (the cumulative mass r³/(r² + a²)^{3/2} = ½).
    assert np.median(np.linalg.norm(x, axis=1)) == pytest.approx(1.305, rel=0.05)
    np.testing.assert_allclose(x.mean(axis=0), 0, atol=1e-12)
    with pytest.raises(ValueError, match="cutoff"):
        pc.scenes.plummer_sphere(10, cutoff=1.0)


def test_galaxies_collide_under_tree_gravity():
    s = pc.scenes.galaxies(n=2000, threads=1)
    assert any(isinstance(t, pc.TreeGravity) for t in s.terms)
    x0 = s.positions
    a, b = x0[:1000].mean(axis=0), x0[1000:].mean(axis=0)
    assert np.linalg.norm(a - b) == pytest.approx(math.hypot(10.0, 2.4), rel=0.05)
    s.step(400)  # t = 10: the two cores have fallen together
    x = s.positions
    assert np.linalg.norm(x[:1000].mean(axis=0) - x[1000:].mean(axis=0)) < 0.5 * np.linalg.norm(a - b)
    assert abs(s.energy_drift()) < 5e-3  # θ = 0.6 monopoles and dt = 0.025: measured 3.7e-4 at n = 12000
    np.testing.assert_allclose(s.momentum(), 0.0, atol=1e-3)  # tree forces are not exactly pairwise


def test_cyclotron_charges_all_drift_at_e_over_b():
    # Every particle's guiding centre moves at E×B/B² = (E/B, 0) whatever its charge and mass;
    # averaged over 20 cyclotron periods of the heaviest (2π·4/1), the mean velocity is that drift
    # to within the gyration's leftover (radius / time).
    s = pc.scenes.cyclotron(n=6, B=1.0, E=0.3)
    x0 = s.positions
    t = 20 * 2 * math.pi * 4
    s.step(round(t / s.dt))
    mean_v = (s.positions - x0) / s.time
    np.testing.assert_allclose(mean_v[:, 0], 0.3, atol=2 * 4.0 * 1.3 / s.time)
    np.testing.assert_allclose(mean_v[:, 1], 0.0, atol=2 * 4.0 * 1.3 / s.time)
    assert abs(s.energy_drift()) < 1e-9  # B does no work; E's work is in its potential


def test_cyclotron_without_e_keeps_every_speed():
    s = pc.scenes.cyclotron(E=0.0)
    v0 = np.linalg.norm(s.velocities, axis=1)
    s.step(2000)
    np.testing.assert_allclose(np.linalg.norm(s.velocities, axis=1), v0, rtol=1e-12)


@pytest.mark.parametrize("name, kw", [("galaxies", {"n": 400}), ("cyclotron", {})])
def test_gallery_scenes_render(tmp_path, name, kw):
    from PIL import Image

    path = pc.render.gif(pc.scenes.REGISTRY[name](**kw), tmp_path / "g.gif", frames=4, size=(120, 100))
    with Image.open(path) as im:
        assert im.n_frames >= 2


def test_gallery_scenes_refuse_bad_arguments():
    with pytest.raises(ValueError, match="theta"):
        pc.scenes.galaxies(theta=-1.0)
    with pytest.raises(ValueError, match="softening"):
        pc.scenes.galaxies(softening=0.0)
    with pytest.raises(ValueError, match=r"\bB\b"):
        pc.scenes.cyclotron(B=0.0)
    with pytest.raises(TypeError, match=r"\bn\b"):
        pc.scenes.galaxies(n=2.5)
    with pytest.raises(ValueError, match=r"\bB\b"):  # found by the long scene fuzz: dt = 0.02/B underflows
        pc.scenes.cyclotron(B=8.988465674311581e305)
    with pytest.raises(ValueError, match=r"\bB\b"):  # and overflows
        pc.scenes.cyclotron(B=5e-324)
    with pytest.raises(ValueError, match=r"\bE\b"):  # the field's potential q E·x overflows
        pc.scenes.cyclotron(E=1e308)
