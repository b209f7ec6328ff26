"""Divergence-free SPH (``Fluid(method="dfsph")``; Bender & Koschier, IEEE TVCG 23, 2017):

* the density solve keeps the mean compression below its tolerance at every step of a dam break
  (0.1 %, and 0.01 % as an option, which also holds the density measured by summation after
  the step below 0.1 %); the divergence solve ends below its own tolerance;
* hydrostatics: a settled layer's pressure against ρ0 g (surface − y);
* the Martin & Moyce (1952) surge front, as the WCSPH test (tests/fluids/test_sph.py) checks it;
* what a step costs: far fewer steps than WCSPH for the same dam break;
* energy books (the solvers' dissipation), thread-count determinism, save/load, bad input.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_sph import MARTIN_MOYCE_1952, MM_TIME_SHIFT, front, penetration

import physcore as pc
from physcore.fluids import lattice, tank_walls

G = 9.81
RHO0 = 1000.0


def column(n, *, a=0.25, tank=(5.0, 2.5), top=False, threads=None, alpha=0.05, **fluid):
    """Martin & Moyce's column a × 2a in the corner of a tank tank[0]·a × tank[1]·a, n particles
    across, as a DFSPH fluid. Returns (scene, dx, upper corner)."""
    dx = a / n
    scene = pc.Scene(2, integrator="semi_implicit_euler", threads=threads)
    scene.add(pc.Gravity([0.0, -G]))
    up = [tank[0] * a, tank[1] * a]
    scene.add_fluid(
        lattice([0, 0], [a, 2 * a], dx), spacing=dx, boundary=tank_walls([0, 0], up, dx, layers=3, top=top),
        method="dfsph", alpha=alpha, **fluid,
    )
    return scene, dx, np.array(up)


def step_cfl(scene, n):
    """n steps, each at the fluid's CFL limit (what Scene.advance does within a call)."""
    for _ in range(n):
        scene.dt = scene.suggest_dt()
        scene.step(1)


# --------------------------------------------------------------------------- the solvers
@pytest.mark.parametrize("tol", [1e-3, 1e-4])
def test_density_error_stays_below_the_tolerance_at_every_step(tol):
    """A dam break (16 particles across, T = 0..2.5, through the surge): after every step's
    density solve the mean predicted compression mean((ρ* − ρ0)₊)/ρ0 is at most the tolerance, no
    solve stops unconverged, and the divergence solve ends below its tolerance. With the 0.01 %
    option the compression measured by summation at the next step's positions stays below 0.1 %
    (measured ≤ 0.039 %); at 0.1 % it overshoots the prediction slightly (≤ 0.123 % measured:
    the drift is not the linear prediction), so there it must stay below twice the tolerance."""
    scene, _, _ = column(16, density_error=tol)
    tscale = math.sqrt(2 * G / 0.25)
    worst, worst_measured, worst_div, steps = 0.0, 0.0, 0.0, 0
    while scene.time * tscale < 2.5:
        step_cfl(scene, 1)
        steps += 1
        st = scene.solver_stats()
        worst = max(worst, st["density_error"])
        worst_div = max(worst_div, st["divergence_error"])
        worst_measured = max(worst_measured, st["measured_density_error"])
    st = scene.solver_stats()
    assert st["steps"] == steps
    assert st["unconverged"] == 0
    assert 0 < worst <= tol and st["density_error_max"] == worst
    assert worst_div <= 1e-3
    assert worst_measured < (1e-3 if tol < 1e-3 else 2 * tol), worst_measured
    # It works for it: at least 2 density iterations a step (the paper's minimum).
    assert st["density_iterations"] >= 2 * steps


def _resting_layer(seed: int):
    """A layer 0.5 × 0.5 m (24 × 24 particles, lattice start moved by 1e-9 m at random with
    ``seed``; 0: not moved) settled for 0.5 s, then averaged over every step of 1 s (about 580
    steps): (mean pressure, mean positions, mean kinetic energy).

    Every step, not every few: at the default tolerance a resting layer's pressure is a
    relaxation cycle about 15 steps long (a bin's mean goes from 0 to 6 times the hydrostatic
    value and back over 240 steps: the solves stop at a mean compression of 0.1 %, so the deep
    rows sag until the solve catches up), and a sample every 0.01 s (about 6 steps) aliased it:
    one realization's worst bin then read anywhere from 2.4 % to 20 % off."""
    W, H, n = 0.5, 0.5, 24
    dx = H / n
    x0 = lattice([0, 0], [W, H], dx)
    if seed:
        x0 = x0 + np.random.default_rng(seed).normal(0.0, 1e-9, x0.shape)
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(x0, spacing=dx, boundary=tank_walls([0, 0], [W, H + 0.1], dx), method="dfsph")
    scene.advance(0.5)
    ps, xs, ke = [], [], []
    t_end = scene.time + 1.0
    while scene.time < t_end:
        step_cfl(scene, 1)
        ps.append(scene.pressure())
        xs.append(scene.positions)
        ke.append(scene.energy().kinetic)
    assert len(ps) > 100
    return np.mean(ps, axis=0), np.mean(xs, axis=0), float(np.mean(ke))


def test_a_resting_layer_comes_to_rest_at_default_settings():
    """The layer of ``_resting_layer`` (0.5 × 0.5 m, 24 × 24 particles, lattice start) at every
    default (α = 0.05) settles as WCSPH's does: rms speed below 0.025 m/s at t = 4 s, and the
    books' total within 2e-4 from t = 1 to 4 s (issue "Physics you can trust, round 2", item 1;
    the guards were 0.05 m/s and 1 % until 2026-12-03). Measured: rms 0.013–0.018 m/s between
    t = 1 and 4 s, depending on how ``advance`` is split (advance(1), (1), (2): 0.0145 and 0.0141
    at 2 and 4 s, alike at scalar, avx2 and avx512); books −7e-5 here, +5.4e-5 so split. Before the static
    walls mirrored the hydrostatic part of the pressure (``hydrostatic_walls``, Adami et al.
    2012) a circulation down the walls and up the middle ran at 0.19–0.23 m/s, and the books,
    which counted the kick's ½ m (g dt)² that the density solve takes out as dissipation, rose
    41 % in those 3 s."""
    W, H, n = 0.5, 0.5, 24
    dx = H / n
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(lattice([0, 0], [W, H], dx), spacing=dx, boundary=tank_walls([0, 0], [W, H + 0.1], dx), method="dfsph")
    scene.advance(1.0)
    e1 = scene.energy().total
    scene.advance(3.0)
    v = np.linalg.norm(scene.velocities, axis=1)
    rms = float(np.sqrt((v**2).mean()))
    assert rms < 0.025, rms
    assert abs(scene.energy().total - e1) < 2e-4 * abs(e1), (scene.energy().total, e1)


LAYERS = 16


@pytest.mark.slow  # 10 s or more (tests/README.md)
def test_hydrostatic_layer_pressure():
    """A resting layer (``_resting_layer``, every default: α = 0.05; α = 0.5, which the layer
    needed to settle before the walls' hydrostatic pressure, reads 1.7–2.4 % low: under the
    layer's jitter Monaghan's viscosity, which acts on approaching pairs only, carries part of
    the weight as a pressure of its own), over an ensemble of LAYERS realizations: the solvers' pressure
    ρ² (Σκ + Σκ^v), averaged over every step, against ρ0 g (H − y), with H the surface of the
    fluid's volume (the lattice start fills the tank to H at the rest density, and the fluid is
    incompressible to 0.1 %). Every two-row bin from 4h above the floor to 3h below the surface
    within 2.5 % and the slope dp/dy within 2 % of −ρ0 g.

    Measured at the default α (seeds 0–15): worst bin −1.75 %, the top one (3h–5h deep), the
    others −0.66 to −1.48 %, slope −0.28 %. Before the walls' hydrostatic pressure, at α = 0.5,
    over four ensembles of 16 (seeds 0–15, …, 48–63): worst bins −1.54, −1.41, −1.55,
    −1.60 %, always the top one, which reads low: the pressure's zero, extrapolated
    from the bulk, lies 0.14 Δx below H (the rows within 2h of the free surface have deficient
    kernel sums and carry the pressure unevenly: the top three rows read 0.64, 1.12 and 0.88 of
    ρ0 g (H − y)); the other bins within 0.91 %; slopes −0.14 to −0.28 %. (Before the divergence
    solve folded its warm start into its first iteration: −1.46 to −1.86 %, slopes −0.34 to
    −0.70 %.) Per realization the worst bin of one realization is 0.7–4.1 %: each settles
    into its own packing. (Against the highest
    particle + Δx/2 instead of H the bins read 1.3 % lower: the top row is rough, and its highest
    particle sits 0.16 Δx above the row's mean.)"""
    W, H, n = 0.5, 0.5, 24
    dx = H / n
    h = 1.3 * dx
    runs = [_resting_layer(seed) for seed in range(LAYERS)]
    # Settled: the relaxation cycle keeps a jitter of about 0.4 J on average (of 613 J of
    # potential energy above the floor).
    assert max(r[2] for r in runs) < 1e-3 * RHO0 * G * H * H * W / 2
    # The ensemble: every realization's particles, pooled.
    p, x = np.concatenate([r[0] for r in runs]), np.concatenate([r[1] for r in runs])
    surface = H
    inner = (x[:, 0] > 3 * dx) & (x[:, 0] < W - 3 * dx)
    edges = np.arange(4 * h, surface - 3 * h, 2 * dx)
    assert len(edges) >= 6
    bulk = inner & (x[:, 1] >= edges[0]) & (x[:, 1] < edges[-1])
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=False):
        m = inner & (x[:, 1] >= lo) & (x[:, 1] < hi)
        y = x[m, 1].mean()
        expect = RHO0 * G * (surface - y)
        rows.append((y, p[m].mean(), expect, p[m].mean() / expect - 1.0))
    slope = np.polyfit(x[bulk, 1], p[bulk], 1)[0]
    table = "\n".join(f"  y={y:.4f} p={pm:8.1f} ρ0g(H−y)={pe:8.1f} err={e:+.3%}" for y, pm, pe, e in rows)
    print(f"\nDFSPH hydrostatic layer: dp/dy = {slope:.1f} Pa/m ({-slope / (RHO0 * G) - 1:+.2%} from −ρ0 g)\n{table}")
    assert abs(-slope / (RHO0 * G) - 1.0) < 0.02, slope
    assert max(abs(r[3]) for r in rows) < 0.025, table


# --------------------------------------------------------------------------- dam break
def test_dam_break_front_matches_martin_and_moyce():
    """The WCSPH test's dam break (20 particles across a, T = 0..3) with DFSPH: every measured point
    within 10 % (with the gate shift, MM_TIME_SHIFT; measured worst 9.6 % at T = 0.41, where WCSPH
    has 9.7 %; the others ≤ 3.3 %), mass exact, nothing through a wall (measured 0.07 dx past a
    face, 2026-12-03)."""
    a, n = 0.25, 20
    scene, dx, upper = column(n, a=a)
    h = 1.3 * dx
    mass0 = scene.masses.sum()
    tscale = math.sqrt(2 * G / a)
    ts, zs, worst_pen = [0.0], [1.0], 0.0
    while ts[-1] < MARTIN_MOYCE_1952[-1][0] + 0.05:
        scene.advance(0.05 / tscale)
        x = scene.positions
        ts.append(scene.time * tscale)
        zs.append(front(x, h) / a)
        worst_pen = max(worst_pen, penetration(x, upper, top=False))
    assert scene.masses.sum() == mass0
    assert worst_pen < dx, worst_pen / dx
    t_exp = np.array([T for T, _ in MARTIN_MOYCE_1952])
    z_exp = np.array([Z for _, Z in MARTIN_MOYCE_1952])
    err = np.interp(t_exp - MM_TIME_SHIFT, ts, zs) / z_exp - 1.0
    print("\nDFSPH vs Martin & Moyce:", " ".join(f"T={T:.2f}:{e:+.1%}" for T, e in zip(t_exp, err, strict=False)))
    assert np.abs(err).max() < 0.10
    assert 3.0 < zs[-1] < 4.6


def test_dfsph_takes_far_fewer_steps_than_wcsph():
    """The same dam break to T = 1 (16 particles across): DFSPH steps at the flow's CFL limit,
    WCSPH at the sound speed's (c0 = 10 v_max). At least 5× fewer steps (measured in the table
    the test prints)."""
    tscale = math.sqrt(2 * G / 0.25)
    counts = {}
    for method in ("wcsph", "dfsph"):
        scene = pc.Scene(2, integrator="semi_implicit_euler")
        scene.add(pc.Gravity([0.0, -G]))
        dx = 0.25 / 16
        scene.add_fluid(lattice([0, 0], [0.25, 0.5], dx), spacing=dx, boundary=tank_walls([0, 0], [1.25, 0.625], dx), method=method)
        counts[method] = sum(scene.advance(0.1 / tscale) for _ in range(10))
    print(f"\nsteps to T = 1: {counts}")
    assert counts["dfsph"] * 5 < counts["wcsph"], counts


def test_energy_books_balance_and_the_solvers_dissipate():
    """Dam break to T = 2 (16 particles across), step by step at the CFL limit: E_kin + E_grav +
    dissipated moves by exactly semi-implicit Euler's own error, −½ dt Σ m g·(v₁ − v₀) a step
    (the solves' and the viscosity's work is booked over the step's mean velocity, so that the
    drift x₁ = x₀ + dt v₁ leaves only that term), summed to rounding; that error is first order
    (measured −8.1e-3 of the initial energy here); the fluid stores no internal energy, and the
    two projections together remove kinetic energy (they are inelastic: 665 J of 19.6 kJ on
    ``dam_break(n=12)`` to 1 s, where the density solve's pressure alone does +597 J of work
    and the divergence solve takes out 1262 J)."""
    scene, _, _ = column(16)
    tscale = math.sqrt(2 * G / 0.25)
    m, e0 = scene.masses, scene.energy().total
    integrator_error = 0.0
    while scene.time * tscale < 2.0:
        v0 = scene.velocities
        scene.dt = scene.suggest_dt()
        scene.step(1)
        integrator_error += -0.5 * scene.dt * float(np.sum(m * -G * (scene.velocities[:, 1] - v0[:, 1])))
    e = scene.energy()
    st = scene.solver_stats()
    solvers = st["dissipated_density_solver"] + st["dissipated_divergence_solver"]
    assert e.potential["fluid"] == 0.0
    assert solvers > 0
    assert e.dissipated["fluid"] > solvers  # the viscosity's share is a loss too
    assert abs(scene.energy_drift() * abs(e0) - integrator_error) < 1e-9 * abs(e0)
    assert abs(scene.energy_drift()) < 0.02, scene.energy_drift()


def test_the_drift_of_the_default_dam_break_converges_with_the_step():
    """``dam_break(n=12)`` (DFSPH, its default) for 1 s at CFL numbers 0.4 (default), 0.2, 0.1,
    each step at the limit: the energy drift is semi-implicit Euler's first-order error
    (measured −5.14e-3, −2.60e-3, −1.33e-3: ×1.97 and ×1.95 a halving), not the books'. Advanced
    per frame as a render does, the default's drift is −2.7e-3 (a frame's last step is cut
    short, so those runs do not halve cleanly)."""
    import dataclasses

    drifts = []
    for cfl in (0.4, 0.2, 0.1):
        base = pc.scenes.dam_break(n=12)
        scene = pc.Scene(2, integrator="semi_implicit_euler")
        scene.add(pc.Gravity([0.0, -G]))
        scene.add(dataclasses.replace(base.fluids[0], cfl=cfl, first=None, name="water"))
        while scene.time < 1.0:
            step_cfl(scene, 1)
        drifts.append(abs(scene.energy_drift()))
    assert drifts[0] < 0.03
    # First order: a halving divides the drift by 2 (by at least 1.8 here).
    assert drifts[1] < drifts[0] / 1.8 and drifts[2] < drifts[1] / 1.8, drifts


# --------------------------------------------------------------------------- determinism, files
def test_thread_count_does_not_change_a_single_bit():
    """4608 particles (above the parallel threshold), 30 steps: threads=1 and 2 agree bit for bit."""
    runs = []
    for threads in (1, 2):
        scene, _, _ = column(48, tank=(4.0, 3.0), threads=threads)
        assert scene.n_particles >= 4096
        step_cfl(scene, 30)
        runs.append((scene.positions, scene.velocities, scene.pressure(), scene.solver_stats(), scene.energy()))
    (x1, v1, p1, s1, e1), (x2, v2, p2, s2, e2) = runs
    assert np.array_equal(x1, x2) and np.array_equal(v1, v2) and np.array_equal(p1, p2)
    assert s1 == s2 and e1 == e2


def test_save_and_load_continue_bit_for_bit(tmp_path):
    """The warm starts are saved with the scene: a loaded copy continues exactly as the original."""
    scene, _, _ = column(12)
    step_cfl(scene, 20)
    path = scene.save(tmp_path / "dfsph.npz")
    copy = pc.Scene.load(path)
    assert copy.fluids[0].method == "dfsph" and copy.fluids[0].density_error == 1e-3
    for s in (scene, copy):
        s.dt = 1e-3
        s.step(15)
    assert np.array_equal(scene.positions, copy.positions)
    assert np.array_equal(scene.velocities, copy.velocities)
    assert np.array_equal(scene.pressure(), copy.pressure())


@pytest.mark.parametrize("name,kw", [("dam_break", {"n": 16}), ("floating", {"n": 16}), ("drop", {"n": 16}),
                                     ("floating", {"n": 8, "method": "wcsph"})])
def test_ready_made_fluid_scenes_continue_bit_for_bit_after_a_load(name, kw):
    """A file held each wall sample's Psi_b as the volume Psi_b/rho0, which a load turned back
    into rho0 (Psi_b/rho0): not always Psi_b (the lattice rule's Psi_b = m, at n = 16, came back
    an ulp off for all 708 samples, and the dam break then stepped 3e-14 m/s, 1.4e-5 m after 30
    steps, from the run it was saved from). The file now says which rule made them."""
    scene = getattr(pc.scenes, name)(**kw)
    scene.step(3)
    copy = pc.Scene.from_bytes(scene.to_bytes())
    for a, b in zip(scene.fluids, copy.fluids, strict=True):
        assert np.array_equal(a.boundary_psi(), b.boundary_psi())
    for s in (scene, copy):
        s.step(20)
    assert np.array_equal(scene.positions, copy.positions)
    assert np.array_equal(scene.velocities, copy.velocities)


@pytest.mark.parametrize("rule", ["lattice", "akinci", "given"])
def test_each_boundary_volume_rule_loads_the_same_psi(rule, tmp_path):
    dx = 0.02
    walls = tank_walls([0, 0], [0.4, 0.4], dx, layers=3)
    volume = rule if rule != "given" else np.linspace(0.7, 1.3, len(walls)) * dx * dx / 3.0
    s = pc.Scene(2, integrator="semi_implicit_euler")
    s.add(pc.Gravity([0.0, -9.81]))
    s.add_fluid(lattice([0.05, 0.05], [0.2, 0.2], dx), spacing=dx, boundary=walls, boundary_volume=volume,
                density=997.0, method="dfsph")
    psi = s.fluids[0].boundary_psi()
    copy = pc.Scene.load(s.save(tmp_path / "walls.npz"))
    assert np.array_equal(copy.fluids[0].boundary_psi(), psi)
    again = pc.Scene.load(copy.save(tmp_path / "again.npz"))
    assert np.array_equal(again.fluids[0].boundary_psi(), psi)


def test_a_3d_dfsph_fluid_takes_the_papers_reach_unless_told_otherwise(tmp_path):
    """``Fluid(smoothing=None)`` resolves, when the fluid is made, to 1.0 for a 3D DFSPH fluid
    without surface tension or adhesion (Bender & Koschier's reach: docs/guide/fluids_dfsph.md,
    "Choosing h in 3D") and to 1.3 otherwise, whether the solver comes as ``method`` or as a
    record; a given smoothing is kept, and a 3D DFSPH file saved at 1.3 (as every file before
    2026-12-01) loads and steps at 1.3, its masses those it was saved with."""
    from physcore.fluids import default_smoothing

    x3, x2 = lattice([0, 0, 0], [0.1, 0.1, 0.1], 0.025), lattice([0, 0], [0.1, 0.1], 0.025)
    assert pc.Fluid(x3, 0.025, method="dfsph").smoothing == 1.0
    assert pc.Fluid(x3, 0.025, solver=pc.DFSPH(cfl=0.3)).smoothing == 1.0
    assert pc.Fluid(x3, 0.025, method="dfsph", surface_tension=0.072).smoothing == 1.3
    assert pc.Fluid(x3, 0.025, solver=pc.DFSPH(adhesion=0.01)).smoothing == 1.3
    assert pc.Fluid(x3, 0.025).smoothing == 1.3  # WCSPH
    assert pc.Fluid(x2, 0.025, method="dfsph").smoothing == 1.3
    assert pc.Fluid(x3, 0.025, method="dfsph", smoothing=1.5).smoothing == 1.5
    assert [default_smoothing(d, m) for d in (2, 3) for m in ("wcsph", "dfsph")] == [1.3, 1.3, 1.3, 1.0]
    # The default sets h, and with it the masses (ρ0 over the lattice's kernel sum at that h).
    f10, f13 = pc.Fluid(x3, 0.025, method="dfsph"), pc.Fluid(x3, 0.025, method="dfsph", smoothing=1.3)
    assert f10.h == 0.025 and f13.h == pytest.approx(1.3 * 0.025)
    assert f10.particle_mass() != f13.particle_mass()
    assert pc.scenes.dam_break(dim=3, n=4).fluids[0].smoothing == 1.0
    assert pc.scenes.dam_break(dim=3, n=4, smoothing=1.3).fluids[0].smoothing == 1.3
    assert pc.scenes.dam_break(dim=2, n=4).fluids[0].smoothing == 1.3
    old = pc.scenes.dam_break(dim=3, n=4, smoothing=1.3)
    path = old.save(tmp_path / "old.npz")
    copy = pc.Scene.load(path)
    assert copy.fluids[0].smoothing == 1.3 and np.array_equal(copy.masses, old.masses)
    old.step(3)
    copy.step(3)
    assert np.array_equal(copy.positions, old.positions)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "arg"),
    [
        ({"method": "iisph"}, "method"),
        ({"density_error": 0.0}, "density_error"),
        ({"density_error": 1.5}, "density_error"),
        ({"divergence_error": float("nan")}, "divergence_error"),
        ({"max_iterations": 0}, "max_iterations"),
        ({"cfl": 1.5}, "cfl"),
        ({"cfl": -0.1}, "cfl"),
    ],
)
def test_bad_dfsph_parameters_name_the_argument(kwargs, arg):
    params = {"method": "dfsph"} | kwargs
    with pytest.raises(ValueError, match=arg):
        pc.fluids.Fluid(lattice([0, 0], [0.1, 0.1], 0.01), 0.01, **params)


def test_a_scene_dfsph_cannot_step_is_refused_before_anything_changes():
    x = lattice([0, 0], [0.1, 0.1], 0.01)
    scene = pc.Scene(2, integrator="verlet")
    scene.add(pc.Gravity([0.0, -G]))
    with pytest.raises(ValueError, match="semi_implicit_euler"):
        scene.add_fluid(x, spacing=0.01, method="dfsph")
    assert scene.n_particles == 0
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(x, spacing=0.01, method="dfsph")
    with pytest.raises(ValueError, match="integrator"):
        scene.integrator = "rk4"
    with pytest.raises(ValueError, match="name"):
        scene.solver_stats("nope")


@pytest.mark.parametrize("solver", [{"method": "dfsph"}, {"solver": pc.DFSPH()}], ids=["method", "record"])
def test_a_step_too_short_for_the_density_solve_is_refused_by_name(solver):
    # The solve divides by dt², which overflows below 7.5e-155 s: a step of 1e-160 s
    # "diverged" at step 1 advising a smaller dt. Refused by name; 1e-150 s still steps.
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(lattice([0, 0], [0.1, 0.1], 0.01), spacing=0.01, **solver)
    before = scene.to_bytes()
    scene.dt = 1e-160
    with pytest.raises(pc.InvalidInputError, match=r"^dt: a step of 1\.000e-160 s is too short for a DFSPH fluid"):
        scene.step()
    for kwargs, arg in [({"duration": 1e-200}, "duration"), ({"duration": 1e-140, "substeps": 10**12}, "substeps")]:
        with pytest.raises(pc.InvalidInputError, match=rf"^{arg}: a step of .* too short for a DFSPH fluid"):
            scene.advance(**kwargs)
    scene.dt = 1e-3
    assert scene.to_bytes() == before
    scene.dt = 1e-150
    scene.step(2)
    assert np.isfinite(scene.positions).all() and scene.step_count == 2


def _edit_meta(src, dst, edit):
    """Copy the scene file ``src`` to ``dst`` with ``edit(meta)`` applied to its JSON meta."""
    import io
    import json
    import zipfile

    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_STORED) as zout:
        for info in zin.infolist():
            data = zin.read(info.filename)
            if info.filename == "meta.npy":
                meta = json.loads(str(np.load(io.BytesIO(data), allow_pickle=False)))
                edit(meta)
                buf = io.BytesIO()
                np.save(buf, np.array(json.dumps(meta)))
                data = buf.getvalue()
            zout.writestr(info, data)
    return dst


def test_a_file_from_before_dfsph_still_loads(tmp_path):
    """A fluid's record without the DFSPH fields (as files written before DFSPH are) loads as
    WCSPH, and continues exactly as the scene it was saved from."""

    def strip(meta):
        for t in meta["terms"]:
            for f in ("method", "density_error", "divergence_error", "max_iterations", "cfl"):
                t.pop(f, None)

    scene = pc.scenes.dam_break(n=6, method="wcsph")
    scene.step(5)
    old = _edit_meta(scene.save(tmp_path / "new.npz"), tmp_path / "old.npz", strip)
    copy = pc.Scene.load(old)
    assert copy.fluids[0].method == "wcsph"
    for s in (scene, copy):
        s.step(5)
    assert np.array_equal(scene.positions, copy.positions)


def test_a_file_pairing_dfsph_with_another_fluid_loads_and_steps(tmp_path):
    """A file whose fluids are one DFSPH and one WCSPH (they pass through each other, as the
    API warns when it builds them) loads and continues exactly as the scene it was saved from."""
    x = lattice([0, 0], [0.05, 0.05], 0.01)
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(x, spacing=0.01, name="a", method="dfsph")
    with pytest.warns(pc.SeparateFluidsWarning, match="a WCSPH fluid pushes only on WCSPH fluids"):
        scene.add_fluid(x + [0.2, 0.0], spacing=0.01, name="b")
    step_cfl(scene, 5)
    copy = pc.Scene.load(scene.save(tmp_path / "two.npz"))
    assert [f.method for f in copy.fluids] == ["dfsph", "wcsph"]
    for s in (scene, copy):
        s.dt = 1e-4
        s.step(5)
    assert np.array_equal(scene.positions, copy.positions)


# --------------------------------------------------------------------------- several fluids
def _split_column(n, parts, **fluid):
    """``column(n)``'s particles added as ``parts`` DFSPH fluids (the same rows in the same
    order, each with the tank's walls and the same c0), or as one fluid for ``parts=1``."""
    a = 0.25
    dx = a / n
    x = lattice([0, 0], [a, 2 * a], dx)
    walls = tank_walls([0, 0], [5.0 * a, 2.5 * a], dx, layers=3)
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    for k, rows in enumerate(np.array_split(np.arange(len(x)), parts)):
        scene.add_fluid(x[rows], spacing=dx, boundary=walls, method="dfsph", alpha=0.05, sound_speed=20.0,
                        name=f"w{k}", **fluid)
    return scene


def test_dfsph_fluids_with_the_same_settings_are_one_solve_bit_for_bit():
    """The dam-break column as three DFSPH fluids (each given the tank: its walls counted once)
    steps bit for bit as the same particles in one fluid: one neighbour search, one pair of
    projections over all of them; every fluid reports the solve's books, and the energy books
    (kept by the solve's first fluid) balance the same."""
    one, three = _split_column(12, 1), _split_column(12, 3)
    for s in (one, three):
        step_cfl(s, 40)
    assert np.array_equal(one.positions, three.positions)
    assert np.array_equal(one.velocities, three.velocities)
    assert np.array_equal(one.pressure(), three.pressure())
    assert three.solver_stats("w0") == three.solver_stats("w2") == one.solver_stats()
    e1, e3 = one.energy(), three.energy()
    assert e3.dissipated["w0"] == e1.dissipated["w0"] and e3.dissipated["w1"] == e3.dissipated["w2"] == 0.0
    assert e1.total == e3.total


def test_a_dfsph_drop_lands_on_a_dfsph_pool_instead_of_passing_through():
    """A block of water dropped onto a resting layer, each its own DFSPH fluid: with one solve
    the block lands in the layer and stays on top of it (measured at t = 1 s: mean heights
    0.069 against 0.044 m, the drop's lowest particle 4 cm above the floor), the compression
    stays at the tolerance, and the books drift as those of the same particles in one fluid
    (−4.0e-4 against −5.7e-4 of the initial energy; 0.310 against 0.316 before the resting
    layer stopped boiling and the books counted the solves' work over the step's mean
    velocity). The drop has no walls of its own: in the solve it
    sees the pool's. As fluids with different tolerances (two solves, which the scene warns
    about) it falls through the pool, and the floor."""
    dx = 0.01
    walls = tank_walls([0, 0], [0.6, 0.5], dx, layers=3)
    pool, drop = lattice([0, 0], [0.6, 0.08], dx), lattice([0.25, 0.12], [0.35, 0.2], dx)

    def build(tol=None):
        scene = pc.Scene(2, integrator="semi_implicit_euler")
        scene.add(pc.Gravity([0.0, -G]))
        if tol is None:
            scene.add_fluid(np.concatenate([pool, drop]), spacing=dx, boundary=walls, method="dfsph", name="all")
            return scene
        scene.add_fluid(pool, spacing=dx, boundary=walls, method="dfsph", name="pool")
        scene.add_fluid(drop, spacing=dx, method="dfsph", name="drop", density_error=tol)
        return scene

    together, one = build(1e-3), build()
    with pytest.warns(pc.SeparateFluidsWarning, match="DFSPH fluid pushes only on DFSPH fluids"):
        apart = build(2e-3)
    n = len(pool)
    for s in (together, one, apart):
        for _ in range(50):
            s.advance(0.02)
    y = together.positions[:, 1]
    assert y[n:].mean() > y[:n].mean() + 0.01, (y[n:].mean(), y[:n].mean())
    assert y[n:].min() > 0.0
    assert together.solver_stats("drop")["measured_density_error"] < 2e-3
    d1, d2 = one.energy_drift(), together.energy_drift()
    assert abs(d1) < 2e-3 and abs(d2 - d1) < 1e-3, (d1, d2)
    # Apart, the drop passes through the pool.
    assert apart.positions[n:, 1].mean() < apart.positions[:n, 1].mean()


def test_pinned_fluid_particles_stay_and_the_books_balance():
    """A pinned particle of a DFSPH fluid (the viewer pins the one it drags) keeps its velocity
    through the solves, which push on it as on a wall; the energy books still balance."""
    from physcore._live import _rebuild

    def pin(meta, arrays):
        arrays["pinned"] = arrays["pinned"].copy()
        arrays["pinned"][5] = True

    scene = _rebuild(column(12)[0], pin)  # as the viewer's grab does
    assert scene.pinned[5] and scene.fluids[0].method == "dfsph"
    x5 = scene.positions[5].copy()
    tscale = math.sqrt(2 * G / 0.25)
    scene.advance(1.0 / tscale)
    assert np.array_equal(scene.positions[5], x5)
    assert np.array_equal(scene.velocities[5], np.zeros(2))
    assert abs(scene.energy_drift()) < 0.01


def test_3d_dam_break_converges_keeps_its_walls_and_its_books():
    """The 3D dam break (``dam_break(dim=3, n=8, depth=0.5)``, 512 particles, T = 0..3): every
    solve converges (none stopped at max_iterations, the density error at most 0.1 % every step),
    nothing goes a spacing past a wall (measured 0.16 dx), the books balance to the
    integrator's error (measured drift −5.6e-3), and both solves dissipate (measured: the density
    solve 402 J, the divergence solve 191 J). At the default h = 1.0 Δx (3D DFSPH's since
    2026-12-01); at h = 1.3 Δx, the default before: 0.27 dx, −3.8e-3, 854 and 213 J. Before the
    solves' relaxation (ω = 0.585 in 3D at h = 1.3 Δx, rust_core/src/sph/dfsph/relax.rs) the
    density solve put 446 J in there (the divergence solve took 305 J out), past a wall 0.36 dx,
    drift +2.2e-4."""
    scene = pc.scenes.dam_break(dim=3, n=8, depth=0.5)
    assert scene.fluids[0].method == "dfsph"
    dx, scale = 1.0 / 8, math.sqrt(2 * G)
    worst = 0.0
    while scene.time * scale < 3.0:
        scene.advance(0.05 / scale)
        worst = max(worst, scene.solver_stats()["density_error"])
        x = scene.positions
        past = max((-x).max(), (x[:, 0] - 4.0).max(), (x[:, 1] - 0.5).max(), (x[:, 2] - 3.0).max())
        assert past < dx, past / dx
    st = scene.solver_stats()
    assert st["unconverged"] == 0 and st["density_error_max"] <= 1e-3
    assert st["dissipated_density_solver"] > 0 and st["dissipated_divergence_solver"] > 0
    assert scene.positions[:, 0].max() > 3.0  # the surge crossed the tank
    assert abs(scene.energy_drift()) < 0.01, scene.energy_drift()


def test_the_3d_dam_break_front_matches_martin_and_moyce():
    """The 3D dam break at its defaults (``dam_break(dim=3, n=16)``: 8,192 particles, DFSPH,
    h = 1.0 Δx) against Martin & Moyce (1952), with the 2D test's gate shift (MM_TIME_SHIFT):
    the first point (T = 0.41, where the front has hardly moved and the gate's lag is largest)
    within 12 %, every later one within 5 %. Measured: −10.2 % at T = 0.41, then −2.8 … +2.7 %
    (within 1.6 % from T = 1.98); at n = 24 −9.1 %, then −0.4 … +4.5 %. At h = 1.3 Δx (3D's
    default until 2026-12-01) n = 16 read −10.3 %, then +0.2 … −4.6 %: the later front lagged."""
    scene = pc.scenes.dam_break(dim=3, n=16)
    assert scene.fluids[0].smoothing == 1.0
    h, scale = scene.fluids[0].h, math.sqrt(2 * G)  # width 1 m: T = t √(2g/a)
    ts, zs = [0.0], [1.0]
    while ts[-1] < MARTIN_MOYCE_1952[-1][0] + 0.05:
        scene.advance(0.05 / scale)
        ts.append(scene.time * scale)
        zs.append(front(scene.positions, h))
    t_exp = np.array([T for T, _ in MARTIN_MOYCE_1952])
    z_exp = np.array([Z for _, Z in MARTIN_MOYCE_1952])
    err = np.interp(t_exp - MM_TIME_SHIFT, ts, zs) / z_exp - 1.0
    print("\n3D DFSPH vs Martin & Moyce:", " ".join(f"T={T:.2f}:{e:+.1%}" for T, e in zip(t_exp, err, strict=False)))
    assert abs(err[0]) < 0.12 and np.abs(err[1:]).max() < 0.05, err
    assert scene.solver_stats()["unconverged"] == 0


@pytest.mark.parametrize("dim, n, smoothing", [(2, 32, 2.0), (3, 12, 2.0), (3, 16, 1.5), (3, 24, 1.3), (3, 24, 1.0)])
def test_the_solves_stay_stable_however_wide_the_neighbourhood(dim, n, smoothing):
    """A dam-break column (1 × 2 m, 1 m deep in 3D, ``n`` particles across) for 12 steps of 1 ms
    at h = ``smoothing`` Δx: the fastest particle stays below 3.5 g t (the surge's toe reaches
    about 2 g t: measured 0.21 m/s at 11 ms) and every solve converges. The solves' Jacobi
    iterations multiply a lattice wave's error by 1 − ω λ/D, and λ/D grows with the
    neighbourhood (rust_core/src/sph/dfsph/relax.rs). Unrelaxed (ω = 1, before the relaxation)
    these columns reached 10⁶¹ m/s (2D, h = 2 Δx, by step 4), 10⁶⁸ (3D, h = 2 Δx, step 1) and
    10⁵⁵ (3D, h = 1.5 Δx); 3D at h = 1.3 Δx (the default then) grew a jitter above the floor
    ×1.8 a step: 0.82 m/s by step 8 at 24 across, 2.5 km/s by step 24 at 40 across. At 3D's
    default h = 1.0 Δx the ratio is under 2D's at 1.3, so ω is 1 there: unrelaxed, as the
    DFSPH paper's solves."""
    dx = 1.0 / n
    scene = pc.Scene(dim, integrator="semi_implicit_euler", dt=1e-3)
    scene.add(pc.Gravity([0.0] * (dim - 1) + [-G]))
    top, tank = ([1.0, 2.0], [4.0, 3.0]) if dim == 2 else ([1.0, 1.0, 2.0], [4.0, 1.0, 3.0])
    scene.add_fluid(
        lattice([0.0] * dim, top, dx), spacing=dx, boundary=tank_walls([0.0] * dim, tank, dx, layers=3, top=True),
        method="dfsph", alpha=0.05, smoothing=smoothing,
    )
    assert scene.dt == 1e-3
    scene.step(12)
    speed = np.linalg.norm(scene.velocities, axis=1).max()
    assert np.isfinite(speed) and speed < 3.5 * G * scene.time, speed
    assert scene.solver_stats()["unconverged"] == 0


def test_the_density_tolerance_bounds_the_mean_of_the_predicted_state():
    """Issue 44 item 14: ``density_error`` bounds the mean over the particles of the *predicted*
    compression (Bender & Koschier 2015, Alg. 3), as its docstring says, not the compression a
    state reaches. A settled layer (24 × 24, α = 0.5 as in ``_resting_layer``, default
    tolerance 1e-3), every step of its second and third half-second: the predicted mean is
    within the tolerance at every step; the reached mean (by summation at the next step) is
    a little above it (measured 0.1006–0.1009 % for seeds 0–2; the docstring says up to
    0.1016 %), and single particles are far above it (measured up to 0.70–0.81 %; the docstring
    says up to 0.83 %)."""
    W, H, n = 0.5, 0.5, 24
    dx = H / n
    x0 = lattice([0, 0], [W, H], dx) + np.random.default_rng(1).normal(0.0, 1e-9, (n * n, 2))
    scene = pc.Scene(2, integrator="semi_implicit_euler")
    scene.add(pc.Gravity([0.0, -G]))
    scene.add_fluid(x0, spacing=dx, boundary=tank_walls([0, 0], [W, H + 0.1], dx), alpha=0.5, method="dfsph")
    tol = scene.fluids[0].density_error
    assert tol == 1e-3
    scene.advance(0.5)
    predicted, reached, particle = [], [], []
    while scene.time < 1.5:
        step_cfl(scene, 1)
        st = scene.solver_stats()
        predicted.append(st["density_error"])
        reached.append(st["measured_density_error"])
        particle.append((scene.density().max() - 1000.0) / 1000.0)
    assert st["unconverged"] == 0
    assert max(predicted) <= tol
    assert tol < max(reached) < 1.02 * tol, max(reached)  # above the bound, by little
    assert 5 * tol < max(particle) < 10 * tol, max(particle)  # single particles: far above
