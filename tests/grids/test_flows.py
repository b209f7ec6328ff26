"""Flows (physcore.Flow): points advected by dx/dt = u(x). The velocity field against its
formula, RK4's order on a chaotic trajectory, equilibria, the largest Lyapunov exponent of
Lorenz against the published value, determinism, save/load, bad input and rendering."""
from __future__ import annotations

import math

import numpy as np
import pytest

import physcore as pc
from physcore.flows import FLOWS


def _u(kind: str, p: np.ndarray, c: dict[str, float]) -> np.ndarray:
    """The flows' formulas, written independently of the core (module docstring table)."""
    x, y = p[:, 0], p[:, 1]
    z = p[:, 2] if p.shape[1] == 3 else None
    if kind == "lorenz":
        return np.stack([c["sigma"] * (y - x), x * (c["rho"] - z) - y, x * y - c["beta"] * z], 1)
    if kind == "rossler":
        return np.stack([-y - z, x + c["a"] * y, c["b"] + z * (x - c["c"])], 1)
    if kind == "thomas":
        return np.stack([np.sin(y) - c["b"] * x, np.sin(z) - c["b"] * y, np.sin(x) - c["b"] * z], 1)
    if kind == "aizawa":
        a, b, cc, d, e, f = (c[k] for k in "abcdef")
        return np.stack([(z - b) * x - d * y, d * x + (z - b) * y, cc + a * z - z**3 / 3 - (x * x + y * y) * (1 + e * z) + f * z * x**3], 1)
    if kind == "halvorsen":
        a = c["a"]
        return np.stack([-a * x - 4 * y - 4 * z - y * y, -a * y - 4 * z - 4 * x - z * z, -a * z - 4 * x - 4 * y - x * x], 1)
    assert kind == "van_der_pol"
    return np.stack([y, c["mu"] * (1 - x * x) * y - x], 1)


@pytest.mark.parametrize("kind", list(FLOWS))
def test_velocity_is_the_flows_formula(kind):
    dim = FLOWS[kind]["dim"]
    rng = np.random.default_rng(3)
    p = rng.normal(size=(50, dim)) * 2
    params = {k: v * (1 + 0.1 * i) for i, (k, v) in enumerate(FLOWS[kind]["params"].items())}  # not the defaults
    scene = pc.Scene(dim, dt=1e-3)
    f = scene.add(pc.Flow(kind, p, **params))
    np.testing.assert_array_equal(f.points, p)
    np.testing.assert_allclose(f.velocity, _u(kind, p, params), rtol=1e-13, atol=1e-12)


def test_rk4_is_fourth_order_on_lorenz():
    # Self-convergence at t = 1 (before chaos amplifies round-off): differences between
    # successive halvings of dt fall 16× each once dt is in the asymptotic range (measured
    # log2 ratios 4.84, 4.61, 4.32, 4.12, 4.04 from dt = 0.01 down).
    def end(dt: float) -> np.ndarray:
        scene = pc.Scene(3, dt=dt)
        f = scene.add(pc.Flow("lorenz", [[1.0, 1.0, 20.0]]))
        scene.step(round(1.0 / dt))
        return f.points[0]

    x = [end(0.01 / 2**k) for k in range(3, 7)]
    d = [np.linalg.norm(a - b) for a, b in zip(x, x[1:], strict=False)]
    for a, b in zip(d, d[1:], strict=False):
        assert math.log2(a / b) == pytest.approx(4.0, abs=0.15), d
    # Euler is first order on the same problem.
    def end_euler(dt: float) -> np.ndarray:
        scene = pc.Scene(3, dt=dt)
        f = scene.add(pc.Flow("lorenz", [[1.0, 1.0, 20.0]], method="euler"))
        scene.step(round(0.2 / dt))
        return f.points[0]

    y = [end_euler(1e-4 / 2**k) for k in range(3)]
    r = np.linalg.norm(y[0] - y[1]) / np.linalg.norm(y[1] - y[2])
    assert math.log2(r) == pytest.approx(1.0, abs=0.1)


def test_lorenz_equilibria_stay_put():
    # The origin and C± = (±√(β(ρ−1)), ±√(β(ρ−1)), ρ − 1) are fixed points (Lorenz 1963, eq. 30).
    q = math.sqrt(8 / 3 * 27)
    p = np.array([[0.0, 0.0, 0.0], [q, q, 27.0], [-q, -q, 27.0]])
    scene = pc.Scene(3, dt=0.005)
    f = scene.add(pc.Flow("lorenz", p))
    np.testing.assert_allclose(f.velocity, 0.0, atol=1e-12)
    scene.step(200)
    np.testing.assert_allclose(f.points, p, atol=1e-9)


def test_largest_lyapunov_exponent_of_lorenz_matches_sprott():
    # Sprott, "Chaos and Time-Series Analysis" (2003), Table A.3: λ₁ = 0.9056 at σ = 10,
    # ρ = 28, β = 8/3. The issue asks for 2 %; measured: 0.9076 at t = 5000 (0.2 %).
    lam = pc.flows.lyapunov("lorenz", t=5000.0, dt=0.005)
    assert abs(lam / 0.9056 - 1) < 0.02, lam


def test_largest_lyapunov_exponent_of_halvorsen_matches_sprott():
    # Sprott (2003), Table A.3: λ₁ = 0.7899 at a = 1.27, the default. (The default was 1.89,
    # the value of many drawings of this flow: a limit cycle there, λ₁ = 0.00 ± 0.003, so the
    # scene drew a loop where its docs promised a strange attractor.) Measured 0.7846 at t = 5000.
    lam = pc.flows.lyapunov("halvorsen", t=5000.0)
    assert abs(lam / 0.7899 - 1) < 0.02, lam


@pytest.mark.parametrize("kind", ["lorenz", "rossler", "thomas", "aizawa", "halvorsen"])
def test_every_3d_flow_is_chaotic_at_its_defaults(kind):
    # The gallery's attractors must be strange ones: a positive largest exponent from the
    # flow's start and one 0.05 beside it, well above the finite-time scatter of a limit cycle's
    # 0 (±0.003 at t = 2000). Measured at t = 2000: lorenz 0.91, rossler 0.079, thomas 0.013,
    # aizawa 0.095, halvorsen 0.80. (Thomas's b = 0.208186 lies just inside chaos: its exponent
    # is small, and from some starts far from the default it measures 0.005.)
    for shift in (0.0, 0.05):
        start = np.asarray(FLOWS[kind]["start"]) + shift
        lam = pc.flows.lyapunov(kind, t=2000.0, start=start)
        assert lam > 0.008, (kind, shift, lam)


def test_lyapunov_exponent_of_a_limit_cycle_is_zero():
    # Every start is drawn to van der Pol's limit cycle: the largest exponent is 0 (the
    # direction along the cycle), not positive as on a strange attractor.
    lam = pc.flows.lyapunov("van_der_pol", t=500.0, dt=0.01)
    assert abs(lam) < 0.02, lam


def test_points_spread_over_the_attractor():
    # A ball of radius 1e-3 grows to the attractor's size: chaos, not a bug in the right-hand
    # side, and every point stays bounded (the Lorenz attractor lies within |x|, |y| < 30,
    # 0 < z < 55).
    scene = pc.Scene(3, dt=0.005)
    f = scene.add(pc.Flow("lorenz", 2000, spread=1e-3, seed=2))
    scene.step(4000)
    p = f.points
    assert np.ptp(p[:, 2]) > 20
    assert np.all(np.abs(p[:, :2]) < 30) and np.all((p[:, 2] > 0) & (p[:, 2] < 55))


def test_an_rk4_step_is_the_ode_layers_stage_sums_bit_for_bit():
    """Each point after a step is y + h Σ_j a_ij k_j with every term, summed from +0 in j order
    (the ODE layer's sums, zero weights included), to the bit, at every SIMD level: here in
    numpy, term by term, over points spread across the attractor (above the parallel threshold,
    so the vectorised chunks run). The textbook form y + h/6 (k1 + 2k2 + 2k3 + k4) differs in
    about 6 % of the coordinates."""
    sigma, rho, beta, h = 10.0, 28.0, 8.0 / 3.0, 0.005
    a = [[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]]
    b = [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0]

    def u(p):
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        return np.stack([sigma * (y - x), x * (rho - z) - y, x * y - beta * z], 1)

    def combine(p, w, k):
        acc = np.zeros_like(p)
        for wj, kj in zip(w, k, strict=False):
            acc = acc + wj * kj
        return p + h * acc

    scene = pc.Scene(3, dt=h, threads=2)
    f = scene.add(pc.Flow("lorenz", 9000, spread=0.5, seed=5))
    scene.step(300)  # onto the attractor
    p = f.points
    k = [u(p)]
    for i in range(1, 4):
        k.append(u(combine(p, a[i], k)))
    want = combine(p, b, k)
    scene.step(1)
    assert np.array_equal(f.points, want)


def test_results_do_not_depend_on_the_thread_count():
    out = []
    for threads in (1, 2, 3):
        scene = pc.Scene(3, dt=0.005, threads=threads)
        f = scene.add(pc.Flow("aizawa", 9000, spread=0.5, seed=4))  # above the parallel threshold
        scene.step(50)
        out.append(f.points)
    assert all(np.array_equal(out[0], o) for o in out[1:])


def test_save_load_continues_bit_identically(tmp_path):
    scene = pc.Scene(3, dt=0.005)
    scene.add(pc.Flow("rossler", 100, seed=1, c=5.0, name="cloud"))
    scene.step(30)
    path = scene.save(tmp_path / "f.npz")
    scene.step(40)
    back = pc.Scene.load(path)
    (f,) = back.flows
    assert (f.kind, f.name, f.params["c"], f.n) == ("rossler", "cloud", 5.0, 100)
    back.step(40)
    assert np.array_equal(f.points, scene.flows[0].points)
    assert back.time == scene.time


def test_divergence_is_caught_and_rolled_back():
    scene = pc.Scene(3, dt=0.5)  # a hundred times Lorenz's stable RK4 step
    f = scene.add(pc.Flow("lorenz", [[1.0, 1.0, 20.0]]))
    before = f.points
    with pytest.raises(pc.SimulationDiverged):
        scene.step(100)
    assert np.isfinite(f.points).all()
    assert scene.step_count < 100
    assert np.isfinite(before).all()


def test_advance_keeps_to_the_flows_step():
    scene = pc.Scene(3)
    scene.add(pc.Flow("lorenz", 3))
    n = scene.advance(1.0)
    assert n == 200  # max_dt 0.005
    scene2 = pc.Scene(3)
    scene2.add(pc.Flow("lorenz", 3, max_dt=0.01))
    assert scene2.advance(1.0) == 100


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"kind": "lorentz"}, "kind"),
        ({"kind": "lorenz", "rho": float("nan")}, "rho"),
        ({"kind": "lorenz", "mu": 1.0}, "mu"),
        ({"kind": "lorenz", "points": np.zeros((3, 2))}, "points"),
        ({"kind": "lorenz", "points": [[0.0, 0.0, np.inf]]}, "points"),
        ({"kind": "lorenz", "points": 0}, "points"),
        ({"kind": "lorenz", "method": "rk5"}, "method"),
        ({"kind": "lorenz", "max_dt": -1.0}, "max_dt"),
        ({"kind": "lorenz", "spread": -1.0}, "spread"),
        ({"kind": "lorenz", "name": ""}, "name"),
    ],
)
def test_bad_input_names_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        pc.Flow(**kwargs)


def test_bad_input_in_a_scene():
    with pytest.raises(TypeError, match="sigma"):
        pc.Flow("lorenz", sigma="10")
    with pytest.raises(ValueError, match="2D"):
        pc.Scene(3).add(pc.Flow("van_der_pol"))
    scene = pc.Scene(3)
    f = scene.add(pc.Flow("lorenz", 4))
    with pytest.raises(ValueError, match="taken"):
        scene.add(pc.Flow("lorenz", 4))
    with pytest.raises(ValueError, match="points"):
        f.points = np.zeros((5, 3))
    with pytest.raises(ValueError, match="scene"):
        _ = pc.Flow("lorenz").points
    for arg, value in (("t", 0.0), ("d0", -1.0), ("renormalize", 0.0), ("transient", -1.0), ("dt", 0.0)):
        with pytest.raises(ValueError, match=arg):
            pc.flows.lyapunov("lorenz", **{arg: value})


def test_lorenz_scene_renders(tmp_path):
    from PIL import Image

    scene = pc.scenes.lorenz(n=500)
    path = pc.render.gif(scene, tmp_path / "l.gif", frames=6, size=(120, 100))
    with Image.open(path) as im:
        assert im.n_frames >= 2
        first = np.asarray(im.convert("RGB"))
        im.seek(im.n_frames - 1)
        last = np.asarray(im.convert("RGB"))
    # The cloud starts as a dot and spreads: more of the picture is painted at the end.
    background = first[-1, 0]
    painted = lambda a: int((np.abs(a.astype(int) - background).sum(axis=2) > 60).sum())  # noqa: E731
    assert painted(last) > painted(first)


def test_a_tampered_flow_in_a_scene_file_is_refused_by_name(tmp_path):
    scene = pc.Scene(3, dt=0.005)
    scene.add(pc.Flow("lorenz", 5, seed=1))
    path = scene.save(tmp_path / "f.npz")
    with np.load(path) as z:
        members = dict(z)
    members["flow0_y"] = members["flow0_y"][:-3]  # one point short of the record's n
    np.savez(tmp_path / "bad.npz", **members)
    with pytest.raises(pc.SceneFileError, match="flow0_y"):
        pc.Scene.load(tmp_path / "bad.npz")
    members["flow0_y"] = np.full(15, np.nan)
    np.savez(tmp_path / "nan.npz", **members)
    with pytest.raises(pc.SceneFileError):
        pc.Scene.load(tmp_path / "nan.npz")
