"""The Wisdom–Holman map's symplectic correctors (``wh_corrector``; Wisdom, Holman & Touma 1996,
as REBOUND's WHFast): the error of first order in the planets' masses removed through the
corrector's order, what it leaves (second order in the masses), a call's ends as the only
place the corrected state differs from the visible one, determinism and restarts, the option
and the scenes it refuses."""
from __future__ import annotations

import io
import json
import math
import zipfile

import numpy as np
import pytest
import test_wisdom_holman as wh
from test_interrupt import _interrupt
from test_wisdom_holman import TWO_PI, _planets

import physcore as pc


def _scene(x, v, m, corrector, **kw) -> pc.Scene:
    """test_wisdom_holman's scene (G = 1, P/20, one thread, Jacobi) with the corrector of `corrector`."""
    return wh._scene(x, v, m, corrector=corrector, **kw)


def _energy_error(s: pc.Scene, steps: int) -> float:
    """|E/E0 − 1| at its worst of 20 samples (20 calls: the corrector runs at each one's ends)."""
    return wh._energy_error(s, steps, samples=20)


def _refused_unchanged(s: pc.Scene, words: str) -> None:
    """A step of `s` refused naming ``wh_corrector`` (its message holding `words`), the scene as before."""
    before = (s.positions.copy(), s.velocities.copy())
    with pytest.raises(pc.InvalidInputError, match="wh_corrector") as info:
        s.step(10)
    assert words in str(info.value)
    assert np.array_equal(s.positions, before[0]) and np.array_equal(s.velocities, before[1]) and s.time == 0.0


# ------------------------------------------------------------------------------ its error
#: REBOUND 5.2.2's WHFast (Jacobi, ``safe_mode = 0``, ``synchronize()`` before each sample) on the
#: same problems, |E/E0 − 1| at its worst of 20 samples: (planets' mass, steps an inner orbit,
#: steps) -> {corrector order: error}. physcore's map and correctors are WHFast's, so its
#: errors are these to rounding (measured within 1.4e-4 of them, most to 5 digits).
REBOUND = {
    (1e-3, 20, 2000): {0: 7.6546e-06, 3: 4.5710e-07, 5: 7.0866e-08, 7: 4.0144e-08, 11: 3.1807e-08, 17: 3.1609e-08},
    (1e-4, 20, 2000): {0: 6.7740e-07, 3: 4.3085e-08, 5: 5.9185e-09, 7: 1.3246e-09, 11: 9.8648e-11, 17: 9.3652e-11},
}


@pytest.mark.parametrize("case", sorted(REBOUND))
def test_the_errors_are_rebound_whfasts_with_its_correctors(case):
    """Two planets (a = 1 and 1.6) of a unit star at P/20 over 100 inner orbits: each corrector
    takes the energy error where REBOUND's does (the table above), at 1e-3: orders 3, 5, 7, 11,
    17 cut 7.7e-6 (planets of 1e-3) to 4.6e-7, 7.1e-8, 4.0e-8, 3.2e-8, 3.2e-8, and 6.8e-7
    (1e-4) to 4.3e-8, 5.9e-9, 1.3e-9, 9.9e-11, 9.4e-11."""
    mu, per_orbit, steps = case
    for order, want in REBOUND[case].items():
        got = _energy_error(_scene(*_planets(mu), order, dt=TWO_PI / per_orbit), steps)
        assert got == pytest.approx(want, rel=1e-3), (order, got, want)


def test_each_order_removes_more_until_the_second_order_floor():
    """Planets of 1e-4: orders 3, 5, 7, 11 each cut the error by 3 or more (measured 16, 7.3, 4.5,
    13: 6.8e-7, 4.3e-8, 5.9e-9, 1.3e-9, 9.9e-11); order 17 gains little more (9.4e-11), what is
    left being of second order in the masses (next test)."""
    errs = [_energy_error(_scene(*_planets(1e-4), c), 2000) for c in (0, 3, 5, 7, 11)]
    assert all(b < a / 3 for a, b in zip(errs, errs[1:], strict=False)), errs


def test_what_is_left_is_of_higher_order_in_the_masses():
    """Without a corrector the error is of first order in the planets' masses: ten times lighter
    planets, 11.3 times less error (test_wisdom_holman). With the corrector of order 17 what is
    left is of higher order: 338 times less (3.2e-8 and 9.4e-11 at 1e-3 and 1e-4)."""
    plain = [_energy_error(_scene(*_planets(mu), 0), 2000) for mu in (1e-4, 1e-3)]
    corrected = [_energy_error(_scene(*_planets(mu), 17), 2000) for mu in (1e-4, 1e-3)]
    assert 8 < plain[1] / plain[0] < 15, plain
    assert corrected[1] / corrected[0] > 100, corrected


# ---------------------------------------------------------------------- calls and restarts
def test_calls_go_on_from_the_kept_state_so_outputs_do_not_perturb_the_run():
    """C is applied at the first step; each call hands back C⁻¹ of the corrected state and the
    next call goes on from that state (WHFast's ``keep_unsynchronized``): ``step(200)``, 200
    calls of ``step(1)`` and calls of uneven lengths give the same bits."""
    one = _scene(*_planets(1e-3), 17)
    one.step(200)
    many = _scene(*_planets(1e-3), 17)
    for _ in range(200):
        many.step(1)
    uneven = _scene(*_planets(1e-3), 17)
    for n in (1, 7, 50, 2, 140):
        uneven.step(n)
    for s in (many, uneven):
        assert np.array_equal(s.positions, one.positions) and np.array_equal(s.velocities, one.velocities)
    # The corrector changes the state handed back: the plain map's differs by the first-order error.
    plain = _scene(*_planets(1e-3), 0)
    plain.step(200)
    assert np.abs(one.positions - plain.positions).max() / np.abs(one.positions).max() > 1e-6


def _fresh_from(s: pc.Scene, corrector: int, dt: float) -> pc.Scene:
    """A new scene at `s`'s visible state (same masses), with the corrector of `corrector`."""
    return _scene(s.positions.copy(), s.velocities.copy(), s.masses.copy(), corrector, dt=dt)


@pytest.mark.parametrize("change", ["state", "dt", "order"])
def test_a_change_between_calls_applies_the_corrector_afresh(change):
    """Setting the state, dt or the order between calls drops the kept state: the next call
    applies C to the state it is given, as a new scene from that state does (the same bits),
    not to the kept one (which would step other bits)."""
    s = _scene(*_planets(1e-3), 11)
    s.step(30)
    dt, order = TWO_PI / 20, 11
    if change == "state":
        s.velocities = s.velocities * (1 + 1e-12)
    elif change == "dt":
        dt = s.dt = TWO_PI / 25
    else:
        order = s.wh_corrector = 17
    fresh = _fresh_from(s, order, dt)
    s.step(30)
    fresh.step(30)
    assert np.array_equal(s.positions, fresh.positions) and np.array_equal(s.velocities, fresh.velocities)


def test_the_state_dict_holds_the_corrected_state_and_continues_bit_for_bit():
    """``Scene.state`` holds the kept corrected state (2N rows: positions, then velocities; its
    dt after the term powers), and ``set_state`` on a twin continues as the original does;
    without it (the cache dropped) the twin applies C afresh and steps other bits."""
    s = _scene(*_planets(1e-3), 7)
    s.step(25)
    snap = s.state()
    assert snap["cache_forces"].shape == (6, 3) and snap["cache_power"][-1] == s.dt
    twin, cold = _scene(*_planets(1e-3), 7), _scene(*_planets(1e-3), 7)
    twin.set_state(snap)
    cold.set_state(snap | {"cache_forces": None, "cache_power": None})
    for x in (s, twin, cold):
        x.step(25)
    assert np.array_equal(twin.positions, s.positions) and np.array_equal(twin.velocities, s.velocities)
    assert not np.array_equal(cold.positions, s.positions)
    assert np.abs(cold.positions - s.positions).max() < 1e-9  # the same orbit, to the corrector's rounding


def test_threads_give_the_same_bits():
    runs = wh._thread_runs(5, 2, corrector=3)
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_save_load_continues_bit_for_bit_and_files_hold_the_order_where_set(tmp_path):
    straight = _scene(*_planets(1e-3), 11)
    straight.step(20)
    straight.step(20)
    s = _scene(*_planets(1e-3), 11)
    s.step(20)
    path = s.save(tmp_path / "planets.npz")
    with np.load(path) as z:
        assert json.loads(str(z["meta"]))["wh_corrector"] == 11
        assert z["cache_forces"].shape == (6, 3)  # the corrected state: positions, then velocities
    again = pc.Scene.load(path)
    assert again.wh_corrector == 11
    again.step(20)
    assert np.array_equal(again.positions, straight.positions)
    assert np.array_equal(again.velocities, straight.velocities)
    # Without a corrector the key is not written (other scenes' files keep their bytes).
    path = _scene(*_planets(1e-3), 0).save(tmp_path / "plain.npz")
    with np.load(path) as z:
        assert "wh_corrector" not in json.loads(str(z["meta"]))
    assert pc.Scene.load(path).wh_corrector == 0


def _rewritten(path, out, meta=None, **members) -> None:
    """`path`'s scene file with `members` (name -> array) and `meta` (key -> value, None to drop)
    replaced, written to `out` as Scene.save writes (stored .npy members)."""
    with zipfile.ZipFile(path) as z:
        data = {i.filename: z.read(i) for i in z.infolist()}
    for name, a in members.items():
        buf = io.BytesIO()
        np.save(buf, a)
        data[f"{name}.npy"] = buf.getvalue()
    if meta:
        m = json.loads(str(np.load(io.BytesIO(data["meta.npy"]))))
        for k, val in meta.items():
            m.pop(k) if val is None else m.__setitem__(k, val)
        buf = io.BytesIO()
        np.save(buf, np.array(json.dumps(m)))
        data["meta.npy"] = buf.getvalue()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
        for name, b in data.items():
            z.writestr(name, b)


def test_a_file_whose_corrected_state_does_not_fit_is_refused_naming_the_cache(tmp_path):
    """The kept state is checked on load: its dt must be a positive step, it needs a scene
    with the corrector (a file edited to wh_corrector 0), and its 2N rows come whole."""
    s = _scene(*_planets(1e-3), 5)
    s.step(10)
    path = s.save(tmp_path / "ok.npz")
    with np.load(path) as z:
        forces, power = z["cache_forces"], z["cache_power"]
    assert pc.Scene.load(path).wh_corrector == 5  # the untouched file loads
    bad = tmp_path / "bad.npz"
    for meta, members in (
        (None, {"cache_power": np.append(power[:-1], 0.0)}),
        (None, {"cache_power": np.append(power[:-1], -s.dt)}),
        ({"wh_corrector": None}, {}),
        (None, {"cache_forces": forces[:3]}),
    ):
        _rewritten(path, bad, meta, **members)
        with pytest.raises(pc.SceneFileError, match="cache"):
            pc.Scene.load(bad)


def test_a_call_rolled_back_leaves_nothing_for_the_next():
    """Ctrl-C part-way through a long call rolls the scene back to its state before the call,
    the kept corrected state included; the next call then goes on from it as in a scene that
    was never interrupted (the same bits)."""
    fresh = _scene(*_planets(1e-3), 5)
    fresh.step(7)
    s = _scene(*_planets(1e-3), 5)
    s.step(3)
    before = (s.positions.copy(), s.velocities.copy(), s.state()["cache_forces"].copy())
    _interrupt(lambda: s.step(10**9), 0.2)
    assert np.array_equal(s.positions, before[0]) and np.array_equal(s.velocities, before[1]) and s.step_count == 3
    assert np.array_equal(s.state()["cache_forces"], before[2])
    s.step(4)
    assert np.array_equal(s.positions, fresh.positions) and np.array_equal(s.velocities, fresh.velocities)


# ------------------------------------------------------------------ the option and refusals
def test_the_default_is_none_and_the_record_is_the_keyword():
    assert pc.Scene(3, integrator="wisdom_holman").wh_corrector == 0
    s = pc.Scene(3, integrator=pc.WisdomHolman(corrector=17))
    assert s.wh_corrector == 17 and s.integrator == "wisdom_holman"
    s.wh_corrector = 5
    assert s.wh_corrector == 5
    with pytest.raises(pc.InvalidInputError, match="wh_corrector"):
        pc.Scene(3, integrator=pc.WisdomHolman(corrector=17), wh_corrector=5)


@pytest.mark.parametrize("bad", [1, 2, 4, 9, 13, 18, -1, 2**40])
def test_an_order_without_a_corrector_is_refused_naming_it(bad):
    with pytest.raises(pc.InvalidInputError, match="wh_corrector"):
        pc.Scene(3, integrator="wisdom_holman", wh_corrector=bad)
    with pytest.raises(pc.InvalidInputError, match="corrector"):
        pc.WisdomHolman(corrector=bad)
    s = pc.Scene(3, integrator="wisdom_holman", wh_corrector=3)
    with pytest.raises(pc.InvalidInputError, match="wh_corrector"):
        s.wh_corrector = bad
    assert s.wh_corrector == 3


@pytest.mark.parametrize("bad", [None, "17", 17.0, True, [17]])
def test_an_order_not_an_int_is_a_type_error_naming_it(bad):
    with pytest.raises(TypeError, match="wh_corrector"):
        pc.Scene(3, integrator="wisdom_holman", wh_corrector=bad)


@pytest.mark.parametrize("why", ["democratic_heliocentric", "pinned"])
def test_scenes_it_is_not_derived_for_are_refused_before_a_step(why):
    x, v, m = _planets(1e-3)
    s = pc.Scene(3, integrator="wisdom_holman", dt=TWO_PI / 20, wh_corrector=17,
                 wh_coordinates="democratic_heliocentric" if why == "democratic_heliocentric" else "jacobi")
    s.add_particles(x, v, masses=m, pinned=[why == "pinned", False, False])
    s.add(pc.PairwiseGravity(G=1.0))
    _refused_unchanged(s, "Jacobi")
    s.wh_corrector = 0
    s.step(1)  # the plain map steps it
    assert math.isfinite(s.energy().total)


def test_a_scene_with_colliders_is_refused_with_the_corrector():
    """Between the steps of a corrected call the state is private (the corrected coordinates,
    a half drift owed), so a collider acting between steps would act on the wrong state: such a
    scene is refused by name when it steps, and steps without the corrector."""
    x, v, m = _planets(1e-3)
    s = _scene(x, v, m, 17)
    s.add(pc.Plane([0.0, 0.0, -50.0], [0.0, 0.0, 1.0]))
    _refused_unchanged(s, "colliders")
    s.wh_corrector = 0
    s.step(10)
    assert s.step_count == 10
