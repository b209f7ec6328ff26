"""Charges in electromagnetic fields: the cyclotron's E×B drift."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from ..scene import Scene
from ..terms import ElectricField, MagneticField
from ._common import _count, _finite_books, _nonneg, _particles, _positive, _stamped


def cyclotron(
    n: int = 6,
    *,
    B: float = 1.0,
    E: float = 0.3,
    seed: int = 5,
    integrator: str = "boris",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Charges gyrating in a magnetic field and drifting together across an electric one.

    2D, B_z = `B` out of the plane and a uniform E = (0, `E`): `n` particles of charge ±1
    (alternating, first +1) and mass 1, 2 or 4 (cycling; units where these are 1). Each turns
    at its cyclotron frequency ``ω_c = |q|B/m`` on a circle of radius ``m w/(|q|B)`` (w its speed in the
    frame drifting at E×B/B² = (E/B, 0)), positive and negative charges in opposite senses, and
    every one drifts at E/B along x whatever its charge and mass: trochoids (Jackson,
    *Classical Electrodynamics*, 3rd ed., §12.3). Each starts at x = 0 moving along x at
    E/B − w, w drawn uniformly in [0.15, 0.6] (`seed`): w < E/B gives a wave, w = E/B a
    cycloid with cusps, w > E/B loops. Each is at the edge of its gyration circle, so it
    sweeps a band ``2 m w/(|q|B)`` high (above its start if positive, below if negative); the
    bands are stacked 0.6/B apart, in index order from the bottom, centred on y = 0. Boris push;
    ``dt=None`` takes 0.02/B (ω_c dt ≤ 0.02). The render colours positive charges red and
    negative blue (:data:`CHARGE_COLORS`), and draws under them, faintly, each charge's
    trochoid as the theory predicts it (:func:`trochoids`) over the default animation's 45 time
    units: the first frame already shows the paths, and the charges trace them.
    """
    n = _count(n, "n", 1)
    B = _positive(B, "B")
    E = _nonneg(E, "E")
    seed = _count(seed, "seed", 0)
    _particles("n", n)
    step = 0.02 / B if B < math.inf else 0.0
    if dt is None and not _check.MIN_NORMAL <= step < math.inf:
        raise InvalidInputError(f"B: the step 0.02/B = {step:.3g} s is outside float64's normal range; give another B or a dt")
    rng = np.random.default_rng(seed)
    q = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    m = np.array([1.0, 2.0, 4.0])[np.arange(n) % 3]
    w = rng.uniform(0.15, 0.6, n)
    with np.errstate(over="ignore"):  # E/B beyond float64 is refused by _finite_books below
        height = 2.0 * m * w / B  # each band: the gyration circle's diameter
        top = np.cumsum(height + 0.6 / B)
    if not (np.isfinite(top[-1]) and top[-1] < 1e300):
        raise InvalidInputError(f"B: the gyration bands, 2 m w/(|q| B) each, span {top[-1]:.3g} m at B = {B:.3g}: beyond float64")
    with np.errstate(over="ignore"):
        y = np.where(q > 0, top - height, top)  # a positive charge turns up first (q v×B)
        y -= 0.5 * (top[0] - height[0] + top[-1])  # the stack's bottom and top about y = 0
        x = np.stack([np.zeros(n), y], axis=1)
        v = np.stack([E / B - w, np.zeros(n)], axis=1)
    scene = Scene(2, integrator=integrator, dt=step if dt is None else dt, threads=threads)
    scene.add_particles(x, v, masses=m)
    scene.set_attribute("charge", q)
    scene.add(MagneticField(B))
    if E:
        scene.add(ElectricField([0.0, E]))
    colors = [CHARGE_COLORS[0] if c > 0 else CHARGE_COLORS[1] for c in q]
    scene = _finite_books(scene, "E, B")  # the drift E/B: a huge E or a tiny B
    # The predicted paths, faint, under the trails (plain lists: render_defaults compare with ==).
    paths = trochoids(x, v[:, 0] - E / B, q, m, B, E, GUIDE_TIME)
    night = np.array([12.0, 14.0, 26.0])  # the dark theme's background
    decor = [{"line": path.tolist(), "width": 1, "color": tuple(int(c) for c in np.rint(0.7 * night + 0.3 * np.array(col)))}
             for path, col in zip(paths, colors, strict=True) if np.isfinite(path).all()]
    scene.render_defaults = {"colors": colors, "look": {"decor": decor}}
    return scene


#: ``cyclotron``: how long (q=m=B=1 time units) the guide paths run: the default animation's span;
#: and the most points a guide path has.
GUIDE_TIME = 45.0
GUIDE_POINTS = 4096


def trochoids(x0: np.ndarray, u0: np.ndarray, q: np.ndarray, m: np.ndarray, B: float, E: float, duration: float,
              points_per_turn: int = 96) -> list[np.ndarray]:
    """Each charge's exact path in B_z = `B` and E = (0, `E`) from (N, 2) positions `x0` with
    velocities (E/B + u0, 0) (`u0`: the speed along x in the frame drifting at E/B), over
    [0, `duration`]: a circle of angular speed ω = q B/m in the drifting frame,
    ``x = x0 + (E/B) t + (u0/ω) sin ωt``, ``y = y0 − (u0/ω)(1 − cos ωt)``. A list of (K, 2)
    arrays, `points_per_turn` points to a gyration (at most GUIDE_POINTS in all)."""
    out = []
    for p, u, qi, mi in zip(np.asarray(x0, float), np.asarray(u0, float), q, m, strict=True):
        omega = qi * B / mi
        turns = abs(omega) * duration / (2 * math.pi)
        # At most GUIDE_POINTS (a strong B: many tiny turns, which a guide cannot show anyway).
        k = max(64, min(GUIDE_POINTS, int(math.ceil(turns * points_per_turn)) + 1)) if math.isfinite(turns) else GUIDE_POINTS
        t = np.linspace(0.0, duration, k)
        with np.errstate(all="ignore"):
            px = p[0] + (E / B) * t + (u / omega) * np.sin(omega * t)
            py = p[1] - (u / omega) * (1.0 - np.cos(omega * t))
        out.append(np.stack([px, py], axis=1))
    return out


#: ``cyclotron``: colours of positive (red) and negative (blue) charges, RGB.
CHARGE_COLORS = ((235, 85, 70), (80, 150, 255))

# 45 (q=m=B=1) time units: about seven turns of the lightest charges, two of the heaviest, and a
# drift of 13.5 (E = 0.3); the trails draw the whole trochoids, band by band.
cyclotron.render_defaults = {"antialias": True,
    "frames": 150, "fps": 30, "frame_time": 0.3, "size": (480, 400), "speed_unit": "(q=m=B=1)", "trail": 150,
    "size_by": "mass", "radius": 4, "theme": "dark", "color_by": "none",
}
cyclotron = _stamped(cyclotron, old_order=('n', 'B', 'E', 'seed', 'integrator', 'dt', 'threads'), keep=1)
