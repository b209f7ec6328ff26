"""Flow scenes: strange attractors painted by clouds of points (lorenz)."""
from __future__ import annotations

from .. import _check
from .._errors import InvalidInputError
from ..scene import Scene
from ._common import _big, _count, _nonneg, _positive, _stamped


def lorenz(
    n: int = 600,
    *,
    kind: str = "lorenz",
    spread: float = 0.5,
    seed: int = 7,
    integrator: str = "rk4",
    dt: float | None = None,
    threads: int | None = None,
) -> Scene:
    """A strange attractor painted by a cloud of points (Lorenz's by default).

    `n` points start in a ball of radius `spread` near the attractor and chaos stretches them
    over it, each drawn as a glowing streak that fades (the render's ``trail``: 600 streaks draw
    the butterfly's sheets and holes, where 40 000 dots blurred into one fuzzy blob)
    (:class:`~physcore.flows.Flow`; the
    Lorenz system by default, ``kind="rossler"``, ``"thomas"``, ``"aizawa"`` or ``"halvorsen"``
    for the others). `integrator` is the flow's Runge–Kutta method (``"rk4"``, ``"euler"``,
    ``"heun"`` or ``"dopri5"``); ``dt=None`` takes the flow's default step.
    """
    from ..flows import _METHODS, FLOWS, Flow

    n = _count(n, "n", 1)
    if not isinstance(kind, str) or kind not in FLOWS or FLOWS[kind]["dim"] != 3:
        raise InvalidInputError(f"kind: expected one of {', '.join(k for k, v in FLOWS.items() if v['dim'] == 3)}, got {kind!r}")
    if not isinstance(integrator, str) or integrator not in _METHODS:
        raise InvalidInputError(f"integrator: the flow's method must be one of {', '.join(_METHODS)}, got {integrator!r}")
    spread = _nonneg(spread, "spread")
    seed = _count(seed, "seed", 0)
    step = FLOWS[kind]["max_dt"] if dt is None else _positive(dt, "dt")
    # Last, once every other argument is checked: a point is 3 float64 coordinates, a snapshot
    # of them and the rate field read for colouring (about 72 B), not a particle's 512 B.
    _check.memory("n", 72 * n, f"{_big(n)} flow points")
    scene = Scene(3, integrator="rk4" if integrator == "rk4" else "verlet", dt=step, threads=threads)
    scene.add(Flow(kind, n, spread=spread, seed=seed, method=integrator))
    # Frames every 6 steps of the default dt (0.03 time units for Lorenz), after a lead-in of 420
    # (t = 2.1 for Lorenz: the ball of points already drawn out into a thread along both wings,
    # so the first frame, the thumbnail, shows the butterfly begun); the 120 frames reach
    # t = 5.7, the cloud spread over the whole attractor by the second half.
    max_dt = FLOWS[kind]["max_dt"]
    scene.render_defaults = {"steps_per_frame": max(1, round(6 * max_dt / step)), "lead_in": 420 * max_dt}
    return scene


lorenz.render_defaults = {
    "frames": 120, "fps": 30, "steps_per_frame": 6, "size": (480, 400), "view": (-80.0, 8.0), "radius": 1,
    "speed_unit": "(flow units)", "theme": "dark", "color_by": "density",  # glow: the cloud paints the attractor
    "trail": 30,  # a second of fading streaks behind each point (a still camera: a turning one would smear them)
}
lorenz = _stamped(lorenz, old_order=('n', 'kind', 'spread', 'seed', 'integrator', 'dt', 'threads'), keep=1)
