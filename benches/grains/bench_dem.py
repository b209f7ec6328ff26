"""DEM workload "10^5 discs in a box": 2D soft-sphere discrete element method with linear
spring-dashpot contacts, Coulomb friction and a tangential spring, in a closed box under gravity.

Workload (``build_initial(n_x=400, n_y=250, seed=42)``):

* N = n_x·n_y = 100,000 equal discs, radius r = 1e-3 m, mass m = 1e-5 kg (float64), moment of
  inertia I = ½ m r² (a disc); on a square lattice of spacing s = 1.98 r (1 % overlap, so every
  disc starts in contact with its lattice neighbours), disc (i, j) at ((i + ½)s, (j + ½)s),
  i < n_x, j < n_y, row-major in i (index = j·n_x + i).
* Velocities uniform in [−0.05, 0.05] m/s per component (``numpy.random.default_rng(seed)``,
  one ``uniform(-0.05, 0.05, (N, 2))`` draw); angular velocity ω = 0.
* Box walls x = 0, x = n_x s, y = 0, y = n_y s (half-planes with inward normals).
* k_n = 1e3 N/m, restitution e = 0.8, friction μ = 0.3 (grain–grain and grain–wall), gravity
  (0, −9.81) m/s², dt = 4e-6 s (about the grain–grain contact duration / 50), semi-implicit Euler.

Contact model (the same in physcore's ``Contacts`` term and in the numba peer; see
benches/grains/peer_numba_dem.py for the full statement): linear spring-dashpot normal force
f_n = max(k_n δ + γ_n v_n, 0), γ_n = 2ζ√(k_n m_eff), ζ from e (exact for the clamped model);
Cundall & Strack (1979) tangential spring k_t = (2/7) k_n with dashpot γ_t = 2ζ√(k_t m_eff) and
Coulomb cap |f_t| ≤ μ f_n; walls are half-planes with their own e and μ.

Metrics: particle-steps/s and contacts/s (pairs in contact counted once plus disc–wall contacts,
summed over the timed steps / the time). Protocol: 1 untimed warm-up step (compiles / warms the
caches), then 3 blocks of S = 50 consecutive steps; median block time. Each timed block is one
``scene.step(S)`` call; ``scene.contact_count()`` (the contacts at the last force evaluation)
is read after each block, untimed. contacts/s = mean contacts per step × steps / median block
time. The numba peer counts the same contacts inside its step loop.

physcore needs its contact term (``pc.Contacts``); on a build without it this bench says so and
exits. The numba peer, side by side: ``python benches/grains/peer_numba_dem.py``.

Usage: python benches/grains/bench_dem.py [--n-x 400] [--n-y 250] [--threads 1,2]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from typing import NamedTuple

import os

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benches/: _common, which puts every bench folder on the path

from _common import header, require_release, si, table  # first: sets up the environment before numpy loads
import numpy as np

import physcore as pc

RADIUS = 1e-3  # m
MASS = 1e-5  # kg
SPACING = 1.98  # lattice spacing / r
SPEED = 0.05  # m/s, half-width of the uniform initial velocity distribution per component
K_N = 1e3  # N/m, normal stiffness
RESTITUTION = 0.8
FRICTION = 0.3
GRAVITY = (0.0, -9.81)  # m/s²
DT = 4e-6  # s
STEPS = 50  # S, steps per timed block
BLOCKS = 3


class Initial(NamedTuple):
    """The initial state. x, v: (N, 2) float64 (m, m/s); omega, r, m: (N,) float64 (rad/s, m, kg);
    lower, upper: (2,) float64, the box corners (m)."""

    x: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    r: np.ndarray
    m: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def build_initial(n_x: int = 400, n_y: int = 250, seed: int = 42) -> Initial:
    """The workload's initial state (see the module docstring); N = n_x·n_y discs."""
    n = n_x * n_y
    s = SPACING * RADIUS
    gi, gj = np.meshgrid(np.arange(n_x), np.arange(n_y))  # (n_y, n_x): index = j·n_x + i
    x = np.stack([(gi.ravel() + 0.5) * s, (gj.ravel() + 0.5) * s], axis=1)
    v = np.random.default_rng(seed).uniform(-SPEED, SPEED, (n, 2))
    return Initial(x=np.ascontiguousarray(x), v=v, omega=np.zeros(n), r=np.full(n, RADIUS), m=np.full(n, MASS),
                   lower=np.array([0.0, 0.0]), upper=np.array([n_x * s, n_y * s]))


def build(n_x: int = 400, n_y: int = 250, threads: int = 2, seed: int = 42) -> pc.Scene:
    """The physcore scene of the workload (needs ``pc.Contacts``)."""
    ini = build_initial(n_x, n_y, seed)
    scene = pc.Scene(dim=2, dt=DT, integrator="semi_implicit_euler", threads=threads)
    scene.add_particles(ini.x, velocities=ini.v, masses=ini.m)
    scene.set_attribute("radius", ini.r)
    scene.add(pc.Gravity(list(GRAVITY)))
    # k_t = (2/7) k_n as the workload (and the numba peer) states: not the 2D default, 1/3.
    scene.add(pc.Contacts(stiffness=K_N, restitution=RESTITUTION, friction=FRICTION, tangential_ratio=2.0 / 7.0,
                          walls=pc.Box(ini.lower, ini.upper, restitution=RESTITUTION, friction=FRICTION)))
    return scene


def timed_blocks(scene, steps: int = STEPS, blocks: int = BLOCKS) -> tuple[float, float]:
    """(median block time in s, mean contacts per step) over `blocks` consecutive blocks of
    `steps` steps, each block one ``scene.step(steps)`` call (how a script steps a scene: the
    per-call work, a rollback snapshot of the state and the contacts' springs, is part of it);
    ``scene.contact_count()`` (the contacts at the last force evaluation) is read after each
    block, untimed, and averaged over the blocks."""
    times, contacts = [], 0
    for _ in range(blocks):
        t0 = time.perf_counter()
        scene.step(steps)
        times.append(time.perf_counter() - t0)
        contacts += scene.contact_count()
    return statistics.median(times), contacts / blocks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-x", type=int, default=400)
    ap.add_argument("--n-y", type=int, default=250)
    ap.add_argument("--threads", default="1,2")
    args = ap.parse_args()
    require_release()
    if not hasattr(pc, "Contacts"):
        sys.exit("physcore in this build has no contact term (pc.Contacts); "
                 "`python benches/grains/peer_numba_dem.py` runs the numba peer alone")
    n = args.n_x * args.n_y
    rows = []
    for th in map(int, args.threads.split(",")):
        scene = build(args.n_x, args.n_y, th)
        scene.step(1)  # warm-up, untimed
        t, cps = timed_blocks(scene)
        assert np.isfinite(scene.positions).all()
        rows.append([f"{args.n_x}×{args.n_y}", n, th, f"{cps:.0f}", f"{t / STEPS * 1e3:.3f}",
                     si(n * STEPS / t), si(cps * STEPS / t)])
    print(header(args.threads))
    print(table(["DEM discs", "N", "threads", "contacts/step", "ms/step", "particle-steps/s", "contacts/s"], rows))


if __name__ == "__main__":
    main()
