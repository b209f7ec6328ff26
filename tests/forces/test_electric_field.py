"""ElectricField: a uniform field E acting on the ``charge`` attribute, F = qE, U = -q E·x."""
from __future__ import annotations

import numpy as np
import pytest

import physcore as pc


def _charged(n=3, dim=2, integrator="verlet", threads=1, dt=1e-3, seed=0):
    rng = np.random.default_rng(seed)
    s = pc.Scene(dim=dim, integrator=integrator, dt=dt, threads=threads)
    s.add_particles(rng.normal(size=(n, dim)), rng.normal(size=(n, dim)), masses=rng.uniform(0.5, 2.0, n))
    s.set_attribute("charge", rng.normal(size=n) * 1e-3)
    return s


@pytest.mark.parametrize("integrator", ["verlet", "rk4"])
def test_uniform_acceleration_is_exact(integrator):
    # A constant force: x(t) = x0 + v0 t + (qE/m) t²/2, which Verlet and RK4 reproduce to round-off.
    s = _charged(integrator=integrator)
    x0, v0, m, q = s.positions, s.velocities, s.masses, s.attributes["charge"]
    E = np.array([250.0, -40.0])
    s.add(pc.ElectricField(E))
    s.step(2000)
    t = s.time
    a = q[:, None] * E / m[:, None]
    expected = x0 + v0 * t + 0.5 * a * t**2
    assert np.allclose(s.positions, expected, rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))
    assert np.allclose(s.velocities, v0 + a * t, rtol=0, atol=1e-12 * (1 + np.abs(v0 + a * t).max()))


def test_energy_books_balance_and_momentum_grows_by_the_impulse():
    s = _charged(n=50, dim=3)
    E = np.array([10.0, 20.0, -30.0])
    s.add(pc.ElectricField(E, name="field"))
    e0 = s.energy()
    p0 = s.momentum()
    s.step(1000)
    e1 = s.energy()
    assert "field" in e1.potential
    assert e1.potential["field"] == pytest.approx(-np.sum(s.attributes["charge"] * (s.positions @ E)), rel=1e-12)
    assert abs(e1.total - e0.total) <= 1e-12 * (abs(e0.kinetic) + abs(e0.potential["field"]))
    impulse = np.sum(s.attributes["charge"]) * E * s.time
    assert np.allclose(s.momentum() - p0, impulse, rtol=1e-10, atol=1e-15)


def test_a_charge_hovers_where_the_field_balances_gravity():
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 1.0]], masses=[2e-3])
    s.set_attribute("charge", [1e-6])  # qE = mg for E = mg/q
    s.add(pc.Gravity([0.0, -9.81]))
    s.add(pc.ElectricField([0.0, 2e-3 * 9.81 / 1e-6]))
    s.step(5000)
    assert np.abs(s.positions - [[0.0, 1.0]]).max() < 1e-12
    assert np.abs(s.velocities).max() < 1e-12


def test_uncharged_scenes_and_later_particles_feel_nothing():
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[0.0, 0.0]], [[1.0, 0.0]], masses=[1.0])
    s.add(pc.ElectricField([1e3, 1e3]))
    with pytest.warns(pc.UnchargedWarning, match=r"ElectricField: no particle has a charge \(no charge attribute\), so it exerts no force; "
                      r"set them with scene.set_attribute\('charge', q\)"):
        s.step(100)
    assert np.allclose(s.positions, [[0.1, 0.0]], rtol=0, atol=1e-15)
    assert s.energy().potential["electric_field"] == 0.0
    s.set_attribute("charge", [0.0])
    s.add_particles([[5.0, 5.0]], masses=[1.0])  # added after: charge 0 until set again
    assert np.array_equal(s.attributes["charge"], [0.0, 0.0])
    x = s.positions
    with pytest.warns(pc.UnchargedWarning, match=r"\(every charge is 0\)"):
        s.advance(0.1, substeps=100)
    assert np.array_equal(s.positions[1], x[1])
    # Charged: no warning (filterwarnings = error would fail the test).
    s.set_attribute("charge", [0.0, 1.0])
    s.step(1)


def test_pinned_charges_do_not_move_and_store_no_potential():
    s = pc.Scene(dim=2, dt=1e-3, threads=1)
    s.add_particles([[1.0, 0.0], [2.0, 0.0]], masses=[1.0, 1.0], pinned=[True, False])
    s.set_attribute("charge", [1.0, 1.0])
    s.add(pc.ElectricField([3.0, 0.0]))
    assert s.energy().potential["electric_field"] == pytest.approx(-6.0)  # the free charge only
    s.step(10)
    assert np.array_equal(s.positions[0], [1.0, 0.0])


def test_thread_count_does_not_change_the_bits():
    runs = []
    for threads in (1, 2):
        s = _charged(n=20000, threads=threads)
        s.add(pc.ElectricField([1.0, -2.0]))
        s.step(20)
        runs.append((s.positions, s.energy().total))
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]


def test_save_and_load_keep_the_charges_and_continue_bit_for_bit(tmp_path):
    s = _charged(n=30, dim=3)
    s.add(pc.ElectricField([5.0, 0.0, -1.0]))
    s.step(10)
    s.save(tmp_path / "e.npz")
    back = pc.Scene.load(tmp_path / "e.npz")
    assert np.array_equal(back.attributes["charge"], s.attributes["charge"])
    assert back.terms == s.terms
    s.step(50)
    back.step(50)
    assert np.array_equal(back.positions, s.positions)
    assert back.energy_drift() == s.energy_drift()


@pytest.mark.parametrize(
    "call, exc, arg",
    [
        (lambda s: s.add(pc.ElectricField([1.0, 2.0, 3.0])), pc.InvalidInputError, "E"),
        (lambda s: pc.ElectricField([1.0, np.inf]), pc.InvalidInputError, "E"),
        (lambda s: pc.ElectricField("up"), TypeError, "E"),
        (lambda s: s.set_attribute("charj", [0.0, 0.0, 0.0]), pc.InvalidInputError, "name"),
        (lambda s: s.set_attribute("charge", [1.0, 2.0]), pc.InvalidInputError, "charge"),
        (lambda s: s.set_attribute("charge", [1.0, np.nan, 0.0]), pc.InvalidInputError, "charge"),
        (lambda s: s.set_attribute("radius", [1.0, -1.0, 0.0]), pc.InvalidInputError, "radius"),
        # subnormal: r² underflows, and a ball's spin went non-finite at the first contact
        (lambda s: s.set_attribute("radius", [1.0, 1e-310, 0.0]), pc.InvalidInputError, "radius"),
        (lambda s: s.set_attribute("radius", 0.5), pc.InvalidInputError, "radius"),
        (lambda s: s.set_attribute("charge", ["a", "b", "c"]), TypeError, "charge"),
        (lambda s: s.set_attribute(3, [1.0, 2.0, 3.0]), TypeError, "name"),
    ],
)
def test_bad_input_names_the_argument_and_changes_nothing(call, exc, arg):
    s = _charged()
    q, terms = s.attributes["charge"], s.terms
    with pytest.raises(exc) as info:
        call(s)
    assert str(info.value).startswith(arg), str(info.value)
    assert np.array_equal(s.attributes["charge"], q) and s.terms == terms
