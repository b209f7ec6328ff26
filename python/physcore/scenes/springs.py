"""Spring networks: the spring chain."""
from __future__ import annotations

import math

import numpy as np

from .. import _check
from .._errors import InvalidInputError
from ..scene import Scene
from ..terms import Gravity, Springs
from ._common import (
    _count,
    _dim,
    _finite_books,
    _nonneg,
    _optional,
    _particle_mass,
    _particles,
    _positive,
    _set_stable_dt,
    _stamped,
)


def spring_chain(
    n: int = 40,
    *,
    length: float = 1.0,
    mass: float = 1.0,
    stiffness: float = 34000.0,
    damping: float = 0.5,
    dim: int = 2,
    integrator: str = "verlet",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """Spring chain: n particles joined by springs, first one pinned, released horizontally.

    It swings down under gravity like a heavy rope. Total mass (kg) shared equally, spring
    stiffness (N/m) and dashpot damping (N·s/m) per link. ``dt=None`` uses a quarter of the
    suggested step: the whip at the end of the swing reaches energy errors (``energy_drift()``
    at t = 3 s, the defaults) of 5.6e-3 at the suggested step (stable, but visible in the
    books), 1.1e-3 at half of it and 2.8e-4 at a quarter (converging at second order; undamped,
    −3.6e-4 at half the step).

    The defaults make a rope that stretches a few per cent (each link's stiffness × length,
    34000 N/m × 1/39 m, holds the whip's tension to about 4 % strain; 2000 N/m stretched links
    by 41 %, a bungee) with a light dashpot (0.5 N·s/m, a damping ratio of about 0.01 for a
    link's fastest mode). The whip at the end of the first swing puts about a quarter of the
    energy into the links' stretch oscillations (1.0-1.4 J of the 4.5 J the fall releases by
    t = 3.3 s, for any dashpot from 0.05 to 0.5 N·s/m); the dashpot takes it out within about
    0.2 s, as a real rope's internal friction does, and the books count it as dissipated.
    Undamped, it rings on, and ``color_by="strain"`` drew the rope as red and blue speckle.
    ``damping=0`` gives the undamped chain.

    Raises TypeError / InvalidInputError naming the argument (see the module docstring).
    """
    n = _count(n, "n", 2)
    _particles("n", n, n)
    length, mass, stiffness = _positive(length, "length"), _positive(mass, "mass"), _positive(stiffness, "stiffness")
    damping = _nonneg(damping, "damping")
    dim = _dim(dim)
    dt = _optional(dt, "dt")
    link = length / (n - 1)
    # Spring lengths come from squared lengths: link², with a margin for rounding.
    if not (link >= _check.MIN_NORMAL and math.isfinite(2 * link * link)):
        raise InvalidInputError(f"length: a link of length/(n - 1) = {link:.3g} m is outside float64's usable range")
    m = _particle_mass(mass / n, "mass, n")
    x = np.zeros((n, dim))
    x[:, 0] = np.linspace(0.0, length, n)
    pinned = np.zeros(n, dtype=bool)
    pinned[0] = True
    scene = Scene(dim, integrator=integrator, dt=1e-3 if dt is None else dt, threads=threads)
    scene.add_particles(x, masses=m, pinned=pinned)
    scene.add(Springs(np.arange(n - 1), np.arange(1, n), stiffness=stiffness, damping=damping))
    g = [0.0] * dim
    g[1 if dim == 2 else 2] = -9.81
    scene.add(Gravity(g))
    if dt is None:
        _set_stable_dt(scene, 0.25, "stiffness, damping, mass")
    # The pivot's ceiling bracket (a render prop), in the plane the chain swings in.
    up = 1 if dim == 2 else 2
    bracket = np.zeros((4, dim))
    bracket[:, 0] = [-0.1 * length, 0.1 * length, 0.1 * length, -0.1 * length]
    bracket[:, up] = [0.0, 0.0, 0.03 * length, 0.03 * length]
    # The free end's path (the whip's tip), fading: one trail, not every link's.
    scene.render_defaults = {"look": {**_CHAIN_STYLE, "decor": [{"polygon": bracket.tolist(), "color": (110, 104, 98)}],
                                      "trail_of": (n - 1,)}}
    return _finite_books(scene, "length, mass")


#: ``spring_chain``'s look: the links as a rope 10 px wide coloured by strain before a pale
#: backdrop, trails 3 px wide fading to nothing (the scene adds the pivot's bracket and draws
#: the free end's trail only).
_CHAIN_STYLE = {"spring_width": 10, "backdrop": ((250, 248, 244), (218, 222, 232)), "trail_fade": 0.0, "trail_width": 3}


# The swing spans the chain's length either side of the pivot and 1.2 of it below (the links
# stretch): a wide frame. The chain reads as a rope coloured by its links' strain (tension red,
# the whip's compression blue: the colour bar's ends are the run's 99th percentile), no beads
# over it, the pivot on a ceiling bracket; the free end's path over the last 0.8 s, fading (one
# trace, not every link's: it spans the frame while the rope lies level and draws the whip).
spring_chain.render_defaults = {"antialias": True, "frames": 100, "fps": 30, "frame_time": 1 / 30, "size": (430, 300),
                                "radius": 0, "trail": 24, "color_by": "strain"}
spring_chain = _stamped(spring_chain, old_order=('n', 'length', 'mass', 'stiffness', 'damping', 'dim', 'integrator', 'dt', 'threads'), keep=1)
