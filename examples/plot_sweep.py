"""
A parameter sweep
=================

:func:`physcore.sweep` runs ``measure(build(**p))`` for every ``p`` of a grid and returns a
pandas DataFrame, one row per run. Here: a mass on a spring, for 10 periods, with three
integrators and four step sizes, measuring the energy drift. ``client="serial"`` runs the
12 runs in this process, one after another (no Dask cluster); leave it out to spread them
over a local cluster's worker processes, one per core.

Verlet's drift falls as dt², Yoshida's as dt⁴ down to round-off; explicit Euler gains energy
every step, and its relative drift (``Scene.energy_drift``, relative to the energy now when
that is larger) is near 1: the energy has grown many times over.
"""
import math

import matplotlib.pyplot as plt

import physcore as pc


def build(dt, integrator):
    scene = pc.Scene(dim=2, dt=dt, integrator=integrator)
    scene.add_particles([[1.0, 0.0]])
    scene.add(pc.HarmonicTrap(4 * math.pi**2))  # k = (2 pi)^2 N/m, m = 1 kg: a period of 1 s
    return scene


def measure(scene):
    # The worst drift over the run, sampled every 0.2 s: at a whole number of periods the
    # symplectic schemes' bounded energy error passes near zero (Verlet's read 64x smaller per
    # halving of dt there, not its 4x).
    worst = 0.0
    for _ in range(50):
        scene.step(round(0.2 / scene.dt))
        worst = max(worst, abs(scene.energy_drift()))
    return {"drift": worst}


df = pc.sweep(build, {"integrator": ["euler", "verlet", "yoshida4"], "dt": [0.04, 0.02, 0.01, 0.005]},
              measure=measure, client="serial", progress=False)
assert df["error"].isna().all(), df["error"]
print(df[["integrator", "dt", "drift", "wall_s"]].to_string(index=False))

for name, rows in df.groupby("integrator"):
    plt.loglog(rows["dt"], rows["drift"], "o-", label=name)
plt.xlabel("dt (s)")
plt.ylabel("max |relative energy drift| over 10 periods")
plt.legend()
plt.show()
