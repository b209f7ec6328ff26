"""Granular column collapse in 2D: the deposit's runout against the column's aspect ratio, with
and without rolling resistance, compared with the planar experiments.

Issue 44, item 16: discs with Coulomb friction alone roll too freely, so a collapsing column of
them runs out too far. This script builds 2D columns of discs, releases them and measures the
normalised runout (L∞ − L0)/L0 against the aspect ratio a = H0/L0, for several coefficients of
rolling friction μ_r (``pc.Contacts(rolling_friction=...)``, Ai et al. 2011 model C).

Set-up (every length in grain radii r0 = 1 mm):

* polydisperse discs, radii uniform in [0.8, 1.2] r0 (a 2D packing of equal discs crystallises),
  mass ρ π r² · 2r with ρ = 2500 kg/m³ (glass beads, a slice one grain thick); grain–grain and
  grain–wall restitution 0.6 and friction μ = 0.5 (glass beads: μ ≈ 0.4–0.5);
* linear contacts, stiffness such that the static overlap at the foot of the tallest column is
  0.5 % of r0 (k = 200 m̄ g N_rows / r0); the step is the automatic 50th of a contact;
* a column L0 = 2 r0 × width wide (width = 20 grains here, 10 in the fast test) between a
  back wall x = 0 and a gate x = L0, on a floor y = 0: grains dropped from a loose lattice
  settle under gravity (with the run's μ_r, so the column's packing is that of its material),
  then the gate goes (the contacts' springs with the floor, the back wall and each other are
  kept; only the gate's go);
* the run ends when the deposit's front has moved less than 0.05 r0 in the last √(H0/g)
  (at most 30 √(H0/g) after the release);
* runout: L∞ is the front of the deposit, the right edge of the last grain reached from the
  back wall without a gap wider than a grain diameter (a grain that rolled away on its own,
  which without rolling resistance never stops, is not the deposit); a = H0/L0 with H0 the
  settled column's height (the top of its highest grain).

Experiments (planar, quasi-2D channels; glass beads and sand): the runout grows linearly,
(L∞ − L0)/L0 ≈ λ a, up to a ≈ 2–3, then as a^{2/3}: Lube, Huppert, Sparks & Freundt (2005,
Phys. Rev. E 72, 041301) give λ ≈ 1.2 (and 1.9 a^{2/3} beyond a ≈ 2.3); Lajeunesse, Monnier &
Homsy (2005, Phys. Fluids 17, 103302) give a larger coefficient for their channel (secondary
sources quote 1.8 for one and 1.2 for the other; docs/granular.md compares with the band
1.2–1.8 and with Lube et al.'s law). These coefficients are quoted from the literature as
remembered, not re-read from the papers here.

Usage: python benches/grains/collapse.py [--aspect 0.5,1,2,3] [--rolling 0,0.1,0.2,0.3] [--width 20]
       [--threads 1] [--seeds 1,2,3]
Prints each run (its time included) and a markdown table of λ = runout/a, the mean over the
seeds (each seed another random column) with their range: the table in docs/granular.md. The
runs are deterministic (bit-identical for any thread count), so a seed's row can be re-run alone.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

import physcore as pc

G = 9.81
R0 = 1e-3  # m
RHO = 2500.0  # kg/m³
E = 0.6
MU = 0.5


def _mass(r: np.ndarray) -> np.ndarray:
    return RHO * math.pi * r**2 * 2.0 * r


def _walls(gate: float | None) -> list[pc.Plane]:
    walls = [pc.Plane([0.0, 0.0], [0.0, 1.0], restitution=E, friction=MU), pc.Plane([0.0, 0.0], [1.0, 0.0], restitution=E, friction=MU)]
    if gate is not None:
        walls.append(pc.Plane([gate, 0.0], [-1.0, 0.0], restitution=E, friction=MU))
    return walls


def _contacts(k: float, mu_r: float, gate: float | None) -> pc.Contacts:
    return pc.Contacts(stiffness=k, restitution=E, friction=MU, rolling_friction=mu_r, walls=_walls(gate))


def build(aspect: float, mu_r: float, *, width: int = 10, seed: int = 1, threads: int = 1,
          stiffness_rows: int | None = None) -> tuple[pc.Scene, float, float]:
    """A settled column of about `aspect` × `width` grains' worth of height, `width` grains wide,
    released: (the scene at the release, L0, H0). `stiffness_rows`: the column height (rows)
    the stiffness is set for (default this column's)."""
    rng = np.random.default_rng(seed)
    L0 = 2.0 * R0 * width
    # A loose square lattice of pitch 2.4 r0 (no overlaps at 1.2 r0), as many rows as make
    # the settled column about aspect·L0 high (a random 2D packing fills about 0.8).
    pitch = 2.42 * R0
    cols = int(L0 // pitch)
    rows = max(1, int(round(aspect * L0 * 0.8 * L0 / (cols * math.pi * R0**2 * 1.013) )))
    gx, gy = np.meshgrid((np.arange(cols) + 0.5) * (L0 / cols), (np.arange(rows) + 0.5) * pitch + 0.2 * R0)
    x = np.column_stack([gx.ravel(), gy.ravel()])
    x[:, 0] += rng.uniform(-0.05, 0.05, len(x)) * R0
    r = rng.uniform(0.8, 1.2, len(x)) * R0
    m = _mass(r)
    n_rows = stiffness_rows if stiffness_rows is not None else rows
    k = 200.0 * float(np.mean(m)) * G * n_rows / R0
    s = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=threads)
    s.add_particles(x, masses=m)
    s.set_attribute("radius", r)
    s.add(pc.Gravity([0.0, -G]))
    s.add(_contacts(k, mu_r, L0))
    h = rows * pitch
    s.advance(6.0 * math.sqrt(2.0 * h / G))
    # Settled: let it rest until the kinetic energy is a millionth of the potential.
    pe = float(np.sum(m * G * s.positions[:, 1]))
    for _ in range(20):
        if 0.5 * float(np.sum(m * np.sum(s.velocities**2, axis=1))) < 1e-7 * pe:
            break
        s.advance(math.sqrt(2.0 * h / G))
    H0 = float(np.max(s.positions[:, 1] + r))
    # The release: the same grains and contacts, less the gate (wall 2) and its springs.
    t = pc.Scene(dim=2, integrator="semi_implicit_euler", threads=threads)
    t.add_particles(s.positions, s.velocities, masses=m)
    t.set_attribute("radius", r)
    t.add(pc.Gravity([0.0, -G]))
    t.add(_contacts(k, mu_r, None))
    name = next(term.name for term in s.terms if isinstance(term, pc.Contacts))
    hist = np.asarray(s._sim.term_history(name), dtype=np.float64)
    n = len(x)
    head = 1 + 2 * n + 2
    width_rec = 3 + 2 + (2 if mu_r > 0 else 0)
    rec = hist[head:].reshape(-1, width_rec)
    rec = rec[rec[:, 1] != n + 2]
    t._sim.set_term_history(name, np.concatenate([hist[:head], rec.ravel()]))
    return t, L0, H0


def front(s: pc.Scene) -> float:
    """The right edge of the deposit: the last grain reached from the back wall without a gap
    wider than a grain diameter."""
    r = s.attributes["radius"]
    x = s.positions[:, 0]
    order = np.argsort(x - r)
    edge = 0.0
    gap = 2.0 * float(r.max())
    for i in order:
        if x[i] - r[i] > edge + gap:
            break
        edge = max(edge, float(x[i] + r[i]))
    return edge


def collapse(aspect: float, mu_r: float, *, width: int = 10, seed: int = 1, threads: int = 1,
             stiffness_rows: int | None = None, max_tau: int = 30) -> dict:
    """Builds, releases and runs one column to rest (at most `max_tau` √(H0/g)); returns its a,
    runout and timings."""
    t0 = time.perf_counter()
    s, L0, H0 = build(aspect, mu_r, width=width, seed=seed, threads=threads, stiffness_rows=stiffness_rows)
    t1 = time.perf_counter()
    tau = math.sqrt(H0 / G)
    last = front(s)
    rested = False
    for _ in range(max_tau):
        s.advance(tau)
        f = front(s)
        if abs(f - last) < 0.05 * R0 and s.time > 3.0 * tau:
            rested = True
            break
        last = f
    L = front(s)
    return {
        "a": H0 / L0, "runout": (L - L0) / L0, "mu_r": mu_r, "n": s.n_particles, "rested": rested,
        "t_rest": s.time / tau, "build_s": t1 - t0, "run_s": time.perf_counter() - t1,
        "strays": int(np.sum(s.positions[:, 0] - s.attributes["radius"] > L)),
    }


def main(argv: list[str] | None = None) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benches/: _common
    from _common import header, require_release

    require_release()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aspect", default="0.5,1,2,3")
    ap.add_argument("--rolling", default="0,0.1,0.2,0.3")
    ap.add_argument("--width", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--rows-for-stiffness", type=int, default=61,
                    help="column height (rows) the stiffness is set for; 61: a = 3 at width 20")
    args = ap.parse_args(argv)
    aspects = [float(a) for a in args.aspect.split(",")]
    rolls = [float(m) for m in args.rolling.split(",")]
    seeds = [int(k) for k in args.seeds.split(",")]
    print(header(args.threads))
    print(f"width {args.width} grains (L0 = {2 * args.width} r0), seeds {seeds}\n")
    results = {}
    for a in aspects:
        for mu_r in rolls:
            for seed in seeds:
                res = collapse(a, mu_r, width=args.width, seed=seed, threads=args.threads,
                               stiffness_rows=args.rows_for_stiffness)
                results[a, mu_r, seed] = res
                print(f"  a≈{a}: μ_r={mu_r}, seed {seed}: a={res['a']:.2f} runout {res['runout']:.2f} "
                      f"(λ = {res['runout'] / res['a']:.2f}; {res['n']} grains, "
                      f"{'rest at' if res['rested'] else 'still moving at'} {res['t_rest']:.1f} √(H0/g), "
                      f"{res['strays']} strays; build {res['build_s']:.0f} s, run {res['run_s']:.0f} s)", flush=True)
    cols = " | ".join(f"μ_r = {m:g}" for m in rolls)
    print(f"\nλ = (L∞ − L0)/(L0 a), mean over seeds {seeds} [range]\n")
    print(f"| a = H0/L0 | {cols} |")
    print("|---|" + "---|" * len(rolls))
    for a in aspects:
        a_mean = float(np.mean([results[a, m, k]["a"] for m in rolls for k in seeds]))
        cells = []
        for m in rolls:
            lam = [results[a, m, k]["runout"] / results[a, m, k]["a"] for k in seeds]
            cells.append(f"{np.mean(lam):.2f} [{min(lam):.2f}–{max(lam):.2f}]")
        print(f"| {a_mean:.2f} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
