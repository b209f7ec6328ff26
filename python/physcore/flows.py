"""Points advected by a first-order flow ``dx/dt = u(x)``: a cloud of points paints a strange
attractor (:class:`Flow`), and :func:`lyapunov` measures how fast the flow separates neighbours.

A flow is a system of a :class:`~physcore.Scene`, stepped with it (same clock, rollback on
divergence, save/load) by an explicit Runge–Kutta method (``"rk4"`` by default; ``"euler"``,
``"heun"``, ``"rk4"``, ``"dopri5"``'s fifth-order weights without step control). The points
have no mass and no energy: a flow is not a mechanical system.

Flows (``kind``), with their parameters and customary values:

================  ===  ==============================================================  ==========================================
kind              dim  u(x, y, z)                                                      parameters (defaults)
================  ===  ==============================================================  ==========================================
``lorenz``        3    σ(y − x), x(ρ − z) − y, xy − βz                                 sigma=10, rho=28, beta=8/3
``rossler``       3    −y − z, x + ay, b + z(x − c)                                    a=0.2, b=0.2, c=5.7
``thomas``        3    sin y − bx, sin z − by, sin x − bz                              b=0.208186
``aizawa``        3    (z−b)x − dy, dx + (z−b)y, c + az − z³/3 − (x²+y²)(1+ez) + fzx³  a=0.95, b=0.7, c=0.6, d=3.5, e=0.25, f=0.1
``halvorsen``     3    −ax − 4y − 4z − y², and cyclically                              a=1.27
``van_der_pol``   2    y, μ(1 − x²)y − x                                               mu=1
================  ===  ==============================================================  ==========================================

Sources: Lorenz, J. Atmos. Sci. 20 (1963) 130, eqs. 25–27; Rössler, Phys. Lett. A 57 (1976)
397; Thomas, Int. J. Bifurcation Chaos 9 (1999) 1889; Sprott, "Chaos and Time-Series
Analysis" (2003), Table A.3 (Halvorsen, a = 1.27: largest Lyapunov exponent 0.7899; the
a = 1.89 met in many drawings of it is a limit cycle, exponent 0) and "Elegant Chaos" (2010) (Aizawa); van der Pol,
Phil. Mag. 2 (1926) 978.

Examples
--------
>>> import physcore as pc
>>> scene = pc.Scene(dim=3, dt=0.005)
>>> cloud = scene.add(pc.Flow("lorenz", points=1000, seed=1))
>>> scene.step(200)
>>> cloud.points.shape
(1000, 3)
>>> round(pc.flows.lyapunov("lorenz", t=200.0), 1)
0.9
"""
from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from . import _check, _core
from ._errors import InvalidInputError, InvalidTypeError, allocating
from ._parts import AttachContext, Host, LoadContext, Part, check_system

__all__ = ["Flow", "FLOWS", "lyapunov"]

#: Every flow: dimension, parameters with their defaults, a start on (or near) its attractor,
#: and the largest step (s) :meth:`Scene.advance` takes by default (RK4 well inside stability).
FLOWS: dict[str, dict[str, Any]] = {
    "lorenz": {"dim": 3, "params": {"sigma": 10.0, "rho": 28.0, "beta": 8.0 / 3.0}, "start": (1.0, 1.0, 20.0), "max_dt": 0.005},
    "rossler": {"dim": 3, "params": {"a": 0.2, "b": 0.2, "c": 5.7}, "start": (1.0, 1.0, 0.0), "max_dt": 0.02},
    "thomas": {"dim": 3, "params": {"b": 0.208186}, "start": (1.1, 1.1, -0.01), "max_dt": 0.05},
    "aizawa": {
        "dim": 3,
        "params": {"a": 0.95, "b": 0.7, "c": 0.6, "d": 3.5, "e": 0.25, "f": 0.1},
        "start": (0.1, 0.0, 0.0),
        "max_dt": 0.01,
    },
    "halvorsen": {"dim": 3, "params": {"a": 1.27}, "start": (-1.48, -1.51, 2.04), "max_dt": 0.005},
    "van_der_pol": {"dim": 2, "params": {"mu": 1.0}, "start": (0.5, 0.0), "max_dt": 0.01},
}
_METHODS = ("euler", "heun", "rk4", "dopri5")


class Flow(Part):
    """Points advected by a first-order autonomous flow ``dx/dt = u(x)`` (see the module table).

    Parameters
    ----------
    kind : str
        A key of :data:`FLOWS` (``"lorenz"``, ``"rossler"``, ``"thomas"``, ``"aizawa"``,
        ``"halvorsen"``, ``"van_der_pol"``).
    points : int or (N, dim) array_like of float, default 1
        The starting points, or how many to start in a small ball (radius `spread`) around
        the flow's customary start (:data:`FLOWS`), drawn with `seed`: chaos then spreads them
        over the attractor.
    spread : float, default 0.1
        Radius of that ball (the flow's units).
    seed : int, optional
        Seed of the ball's points (numpy ``default_rng``).
    method : str, default "rk4"
        The explicit Runge–Kutta method (``"euler"``, ``"heun"``, ``"rk4"``, ``"dopri5"``).
    max_dt : float, optional
        The largest step :meth:`Scene.advance` takes (default per flow, :data:`FLOWS`).
    name : str, optional
        Unique within the scene; default `kind`.
    **params : float
        The flow's parameters (e.g. ``rho=28``); the others keep their defaults.

    Attributes
    ----------
    points : (N, dim) float64
        Once added to a scene: the points now (settable, same shape).
    velocity : (N, dim) float64
        Once added to a scene: u at each point now.

    Raises
    ------
    InvalidInputError
        Unknown kind, parameter or method; non-finite or wrong-shaped points; N < 1.
    InvalidTypeError
        A parameter that is not a real number.
    """

    section: ClassVar[str] = "flows"
    part_kind: ClassVar[str] = "flow"
    changes_energy: ClassVar[bool] = False  # a flow is not in the energy books
    #: Every flow kind (:data:`FLOWS`), for the scene file reader.
    catalog: ClassVar[dict[str, dict[str, Any]]] = FLOWS

    @allocating("Flow", "its starting points")
    def __init__(
        self,
        kind: str = "lorenz",
        points: Any = 1,
        *,
        spread: float = 0.1,
        seed: int | None = None,
        method: str = "rk4",
        max_dt: float | None = None,
        name: str | None = None,
        **params: float,
    ) -> None:
        if not isinstance(kind, str) or kind not in FLOWS:
            raise InvalidInputError(f"kind: unknown flow {kind!r}; valid names: {', '.join(FLOWS)}")
        spec = FLOWS[kind]
        self.kind = kind
        self.dim = int(spec["dim"])
        for key in params:
            if key not in spec["params"]:
                raise InvalidInputError(f"{key}: not a parameter of the {kind} flow (it has {', '.join(spec['params'])})")
        self.params = {k: _finite(k, params.get(k, v)) for k, v in spec["params"].items()}
        self.method = _check.choice("method", method, _METHODS)
        self.max_dt = float(spec["max_dt"]) if max_dt is None else _finite("max_dt", max_dt)
        if not self.max_dt > 0:
            raise InvalidInputError(f"max_dt: must be > 0 (s), got {self.max_dt}")
        if name is None:
            name = kind
        if not isinstance(name, str) or not name:
            raise InvalidInputError(f"name: expected a non-empty str, got {name!r}")
        self.name = _check.text("name", name)
        self.start = self._points(points, spread, seed)
        self.start.setflags(write=False)  # the record save writes: read-only (see Bodies)
        self._host: Host | None = None

    def _points(self, points: Any, spread: float, seed: int | None) -> np.ndarray:
        if isinstance(points, (int, np.integer)) and not isinstance(points, bool):
            n = _check.int_in_range("points", points, 1, 1 << 27)
            spread = _finite("spread", spread)
            if spread < 0:
                raise InvalidInputError(f"spread: must be >= 0, got {spread}")
            if seed is not None:
                seed = _check.int_in_range("seed", seed, 0)
            rng = np.random.default_rng(seed)
            d = rng.normal(size=(n, self.dim))
            d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
            r = spread * rng.random(n) ** (1.0 / self.dim)
            return np.asarray(FLOWS[self.kind]["start"], dtype=np.float64) + d * r[:, None]
        if isinstance(points, bool):
            raise InvalidTypeError("points: expected a count or an (N, dim) array, got bool")
        a = _check.real_array("points", points).astype(np.float64)
        if a.ndim != 2 or a.shape[1] != self.dim or a.shape[0] < 1:
            raise InvalidInputError(f"points: expected shape (N, {self.dim}) with N >= 1, got {a.shape}")
        if not np.isfinite(a).all():
            raise InvalidInputError(f"points: row {int(np.argwhere(~np.isfinite(a))[0, 0])} is not finite")
        return a

    @property
    def n(self) -> int:
        """Number of points."""
        return int(self.start.shape[0])

    def _params(self, points: np.ndarray | None = None) -> dict[str, Any]:
        p = points if points is not None else self.start
        return {
            "points": np.ascontiguousarray(p.T).reshape(-1),
            "method": self.method,
            "max_dt": self.max_dt,
            **self.params,
        }

    # -- bound to a scene
    def _bound(self) -> Host:
        if self._host is None:
            raise InvalidInputError(f"Flow {self.name!r} is not in a scene yet: scene.add(it) first")
        return self._host

    @allocating("field", "the flow's points by row")
    def _field(self, name: str) -> np.ndarray:
        host = self._bound()
        (flat,) = host.exclusive(lambda sim: sim.system_fields(self.name, [name]))
        return np.asarray(flat).reshape(self.dim, -1).T.copy()

    @property
    def points(self) -> np.ndarray:
        """The points now, (N, dim) float64 (a copy). Settable (same shape, finite)."""
        return self._field("y")

    @points.setter
    def points(self, values: Any) -> None:
        # Named errors, as the constructor's (not numpy's bare ValueError for "abc" or ragged rows).
        a = _check.real_array("points", values).astype(np.float64)
        if a.shape != (self.n, self.dim):
            raise InvalidInputError(f"points: expected shape {(self.n, self.dim)}, got {a.shape}")
        if not np.isfinite(a).all():
            raise InvalidInputError("points: must be finite")
        host = self._bound()
        flat = np.ascontiguousarray(a.T).reshape(-1)
        host.exclusive(lambda sim: sim.system_load(self.name, [("y", flat)]))

    @property
    def velocity(self) -> np.ndarray:
        """u at every point now, (N, dim) float64."""
        return self._field("rate")

    def _record(self) -> dict[str, Any]:
        return {"kind": self.kind, "params": dict(self.params), "method": self.method, "max_dt": self.max_dt, "n": self.n}

    # -- the part protocol
    def _claim_name(self, ctx: AttachContext) -> str:
        return self.name  # checked by _attach, after the dimension

    def _attach(self, ctx: AttachContext, name: str) -> Flow:
        """Joins the scene: one scene only, under a free name; returns the flow itself, bound."""
        check_system(ctx, self, "flow")
        ctx.sim.add_flow(self.kind, self.name, self._params())
        self._host = ctx.host
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """``{"name", "record"}`` and the points now, ``y`` (the core's layout)."""
        ((_, y),) = sim.system_save(self.name)
        return {"name": self.name, "record": self._record()}, {"y": y}

    def _state(self, sim: Any) -> dict[str, np.ndarray]:
        """``{"y": ...}``: the points and their rates in the core's layout (as the scene file)."""
        return dict(sim.system_save(self.name))

    def _set_state(self, sim: Any, arrays: Any) -> None:
        sim.system_load(self.name, list(arrays.items()))

    @classmethod
    def _load_names(cls, ctx: LoadContext, arrays: Any) -> tuple[str, dict[str, str]]:
        return f"{ctx.field}.record", {"points": f"flow{ctx.index}_y"}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        rec = entry["record"]
        points = arrays["y"].reshape(ctx.dim, -1).T
        params = rec.get("params")
        if not isinstance(params, dict):
            raise InvalidInputError(f"params: expected an object, got {type(params).__name__}")
        ctx.add(cls(rec["kind"], points, method=rec.get("method"), max_dt=rec.get("max_dt"), name=entry["name"], **params))

    def __repr__(self) -> str:
        return f"Flow({self.kind!r}, points={self.n}, name={self.name!r}, {', '.join(f'{k}={v:g}' for k, v in self.params.items())})"


def _finite(name: str, v: Any) -> float:
    x = _check.real(name, v)
    if not math.isfinite(x):
        raise InvalidInputError(f"{name}: must be finite, got {x}")
    return x


def lyapunov(
    kind: str = "lorenz",
    *,
    t: float = 1000.0,
    dt: float | None = None,
    transient: float = 50.0,
    d0: float = 1e-9,
    renormalize: float = 0.5,
    start: Any = None,
    method: str = "rk4",
    **params: float,
) -> float:
    """The largest Lyapunov exponent of a flow (1/time), by Benettin's two-trajectory method
    (Benettin, Galgani & Strelcyn, Phys. Rev. A 14 (1976) 2338; Sprott, "Chaos and Time-Series
    Analysis", 2003, §5.6): a reference point and a neighbour `d0` away are stepped together by
    physcore; every `renormalize` time units the separation d is measured, ``ln(d/d0)`` is
    accumulated, and the neighbour is put back at distance `d0` along the separation. The
    exponent is the sum over `t`. The first `transient` time units (onto the attractor) are
    not counted.

    Parameters
    ----------
    kind, method, **params
        As for :class:`Flow`.
    t : float
        Averaging time (the flow's units), > 0. The estimate's error falls roughly as 1/√t.
    dt : float, optional
        Step; default the flow's ``max_dt``.
    transient, d0, renormalize : float
        Time discarded first (≥ 0), the neighbour's distance (> 0) and the renormalisation
        interval (> 0).
    start : (dim,) array_like, optional
        Starting point; default the flow's customary start (:data:`FLOWS`).

    Returns
    -------
    float
        The exponent, per unit time. Lorenz at σ = 10, ρ = 28, β = 8/3: 0.9056 (Sprott 2003,
        Table A.3).

    Raises
    ------
    InvalidInputError
        Bad arguments (named); :class:`physcore.SimulationDiverged` if the flow blows up.
    """
    if not isinstance(kind, str) or kind not in FLOWS:
        raise InvalidInputError(f"kind: unknown flow {kind!r}; valid names: {', '.join(FLOWS)}")
    spec = FLOWS[kind]
    t = _finite("t", t)
    transient = _finite("transient", transient)
    d0 = _finite("d0", d0)
    renormalize = _finite("renormalize", renormalize)
    if not t > 0:
        raise InvalidInputError(f"t: must be > 0, got {t}")
    if transient < 0:
        raise InvalidInputError(f"transient: must be >= 0, got {transient}")
    if not d0 > 0:
        raise InvalidInputError(f"d0: must be > 0, got {d0}")
    if not renormalize > 0:
        raise InvalidInputError(f"renormalize: must be > 0, got {renormalize}")
    dt = float(spec["max_dt"]) if dt is None else _finite("dt", dt)
    if not dt > 0:
        raise InvalidInputError(f"dt: must be > 0, got {dt}")
    if not dt >= _check.MIN_NORMAL:  # as Scene(dt=...) refuses it
        raise InvalidInputError(f"dt: must be > 0 and finite (at least {_check.MIN_NORMAL:.3g} s, the smallest normal float64), got {dt}")
    x0 = _check.real_array("start", spec["start"] if start is None else start).astype(np.float64).reshape(-1)
    if x0.shape != (spec["dim"],) or not np.isfinite(x0).all():
        raise InvalidInputError(f"start: expected {spec['dim']} finite coordinates, got {start!r}")
    sim, flow = _alone(Flow(kind, x0[None, :], method=method, **params), dt)
    sim.step(max(0, round(transient / dt)))
    k = max(1, round(renormalize / dt))
    rounds = max(1, round(t / (k * dt)))
    direction = np.zeros(spec["dim"])
    direction[0] = 1.0
    p = flow.points[0]
    flow_pair = Flow(kind, np.stack([p, p + d0 * direction]), method=method, name="pair", **params)
    sim, pair = _alone(flow_pair, dt)
    total = 0.0
    for _ in range(rounds):
        sim.step(k)
        a, b = pair.points
        sep = b - a
        d = float(np.linalg.norm(sep))
        if not (d > 0 and math.isfinite(d)):
            raise InvalidInputError(f"d0: the neighbour's separation became {d}; use a larger d0 or a smaller renormalize")
        total += math.log(d / d0)
        pair.points = np.stack([a, a + sep * (d0 / d)])
    return total / (rounds * k * dt)


class _Alone:
    """The host of a flow stepped on its own clock (:func:`lyapunov`): the core alone, no scene."""

    def __init__(self, sim: Any) -> None:
        self.sim = sim

    def exclusive(self, call: Any) -> Any:
        return call(self.sim)

    def energy_changed(self) -> None:
        pass


def _alone(flow: Flow, dt: float) -> tuple[Any, Flow]:
    """A core Simulation (one thread, step ``dt``) holding only ``flow``, bound to it. A flow
    needs no scene around it: this is what ``Scene(dim, dt=dt, threads=1).add(flow)`` sets up,
    with no import of the scene module (flows.py is a part module, below it)."""
    sim = _core.Simulation(flow.dim, "verlet", dt, 1)
    sim.add_flow(flow.kind, flow.name, flow._params())
    flow._host = _Alone(sim)
    return sim, flow
