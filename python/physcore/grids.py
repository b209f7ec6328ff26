"""Fields on grids: water ripples (:class:`Wave`) and Turing patterns (:class:`GrayScott`), as
systems of a :class:`~physcore.Scene` stepped with it (same clock, rollback, save/load, energy
books).

Every grid is cell-centred: with the cell size ``spacing`` (m; ``dx`` in the formulas below, the
name of the keyword before issue 45, still accepted with a DeprecationWarning), cell ``(i, j)``
has its centre at ``((i + ½) dx, (j + ½) dx)`` and the domain is ``[0, nx·dx] × [0, ny·dx]``. Fields are float64 arrays of shape ``shape = (nx, ny)``
(``(nx, ny, nz)`` in 3D), indexed ``u[i, j]`` with i along x. Faces (``edges``): ``"fixed"``
(u = 0 on the face), ``"free"`` (∂u/∂n = 0) or ``"periodic"``; one rule for all faces or one per
face in the order x-, x+, y-, y+ (z-, z+).

Examples
--------
>>> import numpy as np, physcore as pc
>>> scene = pc.Scene(dim=2)
>>> pond = scene.add(pc.Wave((64, 64), spacing=0.01, c=0.5, drops=[pc.Drop(0.0, (0.32, 0.32), radius=0.02, amplitude=0.01)]))
>>> n = scene.advance(0.2)
>>> pond.u.shape, bool(abs(scene.energy_drift()) < 1e-10)
((64, 64), True)
"""
from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass
from typing import Any, ClassVar

import numpy as np

from . import _check, _core, _deprecate
from ._errors import InvalidInputError, InvalidTypeError, allocating
from ._parts import AttachContext, Host, LoadContext, Part, check_system

__all__ = ["Wave", "GrayScott", "StableFluid", "Drop", "Oscillator", "Source", "PRESETS", "Grid"]

_FACES = ("x-", "x+", "y-", "y+", "z-", "z+")
_EDGE_RULES = ("fixed", "free", "periodic")


def _shape(shape: Any) -> tuple[int, ...]:
    if isinstance(shape, (str, bytes)) or not isinstance(shape, Sequence):
        raise InvalidTypeError(f"shape: expected a tuple of 2 or 3 cell counts, got {type(shape).__name__}")
    if len(shape) not in (2, 3):
        raise InvalidInputError(f"shape: expected 2 or 3 cell counts, got {len(shape)}")
    out = []
    for n in shape:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
            raise InvalidTypeError(f"shape: cell counts must be ints, got {type(n).__name__}")
        if not 3 <= int(n) <= 1 << 20:
            raise InvalidInputError(f"shape: every cell count must be in 3..{1 << 20}, got {int(n)}")
        out.append(int(n))
    if math.prod(out) > 1 << 31:
        raise InvalidInputError(f"shape: {tuple(out)} has {math.prod(out):,} cells, more than 2**31")
    return tuple(out)


def _edges(edges: Any, dim: int) -> tuple[str, ...]:
    if isinstance(edges, str):
        edges = (edges,) * (2 * dim)
    if not isinstance(edges, Sequence) or len(edges) != 2 * dim:
        raise InvalidInputError(f"edges: expected one rule or {2 * dim} (x-, x+, y-, y+{', z-, z+' if dim == 3 else ''}), got {edges!r}")
    for e in edges:
        if e not in _EDGE_RULES:
            raise InvalidInputError(f"edges: unknown rule {e!r}; valid: {', '.join(_EDGE_RULES)}")
    for a in range(dim):
        if (edges[2 * a] == "periodic") != (edges[2 * a + 1] == "periodic"):
            raise InvalidInputError(f"edges: axis {'xyz'[a]}: periodic must be on both faces or neither")
    return tuple(edges)


def _positive(name: str, v: Any, unit: str, allow_zero: bool = False) -> float:
    x = _check.real(name, v)
    if not (math.isfinite(x) and (x >= 0 if allow_zero else x > 0)):
        raise InvalidInputError(f"{name}: must be finite and {'>= 0' if allow_zero else '> 0'} ({unit}), got {x}")
    return x


def _cell_size(dx: float, shape: tuple[int, ...]) -> float:
    """``dx`` (m), refused by name where a cell's size dx^dim (what the books multiply each cell
    by, and 1/dx² the Laplacian's) or the domain (each side n·dx, its size Π n · dx^dim) is not
    a normal float64: a grid of spacing 1e308 stepped into infinite books and could not be
    saved; 1e-308, cells of zero area."""
    lg, dim = math.log(dx), len(shape)
    cell = dim * lg  # log of dx^dim
    worst = max(cell + sum(math.log(n) for n in shape), max(math.log(n) for n in shape) + lg)
    if not (_LOG_MIN_NORMAL <= cell and worst < _LOG_MAX):
        unit = "m²" if dim == 2 else "m³"
        raise InvalidInputError(
            f"spacing: {dx:g} m makes a cell of 10^{cell / math.log(10):.0f} {unit} (dx^{dim}; the books sum each "
            f"cell times it) or a domain of 10^{worst / math.log(10):.0f} (m or {unit}), outside float64's normal "
            "range; give a cell size of a physical size (e.g. 1e-100 to 1e100 m)"
        )
    return dx


_LOG_MIN_NORMAL, _LOG_MAX = math.log(sys.float_info.min), math.log(sys.float_info.max)


def _cells_mask(name: str, a: Any, shape: tuple[int, ...]) -> np.ndarray:
    m = _check.array(name, a)
    if m.shape != shape:
        raise InvalidInputError(f"{name}: expected shape {shape} (the grid), got {m.shape}")
    if m.dtype != bool:
        raise InvalidTypeError(f"{name}: expected a bool array, got dtype {m.dtype}")
    return m


def _point(name: str, value: Any, dim: int, unit: str = "m") -> np.ndarray:
    """`dim` finite real coordinates (a center, a velocity), as float64 (dim,), refused by name."""
    a = _check.real_array(name, value).astype(np.float64).reshape(-1)
    if a.shape != (dim,) or not np.isfinite(a).all():
        raise InvalidInputError(f"{name}: must be {dim} finite coordinates ({unit}), got {value!r:.60}")
    return a


def _records(name: str, value: Any, kind: type) -> tuple[Any, ...]:
    """A sequence of `kind` records (drops, oscillators, sources), refused by name."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise InvalidTypeError(f"{name}: expected a list of physcore.{kind.__name__}, got {type(value).__name__}")
    for k, r in enumerate(value):
        if not isinstance(r, kind):
            raise InvalidTypeError(f"{name}[{k}]: expected a physcore.{kind.__name__}, got {type(r).__name__}")
    return tuple(value)


def _field(name: str, doc: str, settable: bool = True) -> property:
    """A property reading (and setting) the bound grid's field `name`."""
    get = lambda self: self.field(name)  # noqa: E731
    put = (lambda self, values: self._set(name, values)) if settable else None
    return property(get, put, doc=doc)


def _layout(a: np.ndarray) -> np.ndarray:
    """(nx, ny[, nz]) → the core's flat layout (x fastest)."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64).T).reshape(-1)


def _unlayout(flat: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return np.asarray(flat).reshape(shape[::-1]).T


@_deprecate.record(('t', 'center', 'radius', 'amplitude'), keep=2)
@dataclass(frozen=True)
class Drop:
    """A stone dropped on a :class:`Wave` at time ``t`` (s): a Gaussian dent of depth
    ``amplitude`` (m) and standard deviation ``radius`` (m) centred at ``center`` (m), added to the
    displacement with no change of velocity. Its energy is booked as work done on the wave."""

    t: float
    center: Sequence[float]
    _: KW_ONLY
    radius: float
    amplitude: float


@_deprecate.record(('amplitude', 'frequency', 'center', 'radius', 'region', 'phase'), keep=2)
@dataclass(frozen=True)
class Oscillator:
    """A driven source on a :class:`Wave`: an acceleration ``amplitude · sin(2π frequency t +
    phase) · profile(x)`` (m/s², Hz, rad). The profile is a Gaussian of standard deviation
    ``radius`` (m) at ``center`` (m), or, with ``region`` (a bool array over the grid), 1 on those
    cells (a line of them makes a plane wave). Its work is booked."""

    amplitude: float
    frequency: float
    _: KW_ONLY
    center: Sequence[float] | None = None
    radius: float = 0.0
    region: Any = None
    phase: float = 0.0


class Grid(Part):
    """Base of the grid systems: geometry, the scene it joined, field access. A part of the
    ``"grids"`` section of scene files (see :mod:`physcore._parts`), registered by its ``kind``;
    a live handle: once added, its fields read the scene's state through the scene's
    :class:`~physcore._parts.Host`."""

    #: Its kind, the same in the core (``add_grid``, ``grid_limits``), in scene files and in
    #: :data:`physcore._parts.PARTS`.
    kind = ""
    section: ClassVar[str] = "grids"
    #: The names :meth:`field` reads (the core gives zeros for any other name).
    fields: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        if cls.__dict__.get("kind"):
            cls.part_kind = cls.kind  # Part.__init_subclass__ registers it in physcore._parts.PARTS
        super().__init_subclass__(**kwargs)

    def __init__(self, shape: Any, spacing: float, edges: Any, name: str) -> None:
        self.shape = _shape(shape)
        self.dim = len(self.shape)
        self.spacing = _cell_size(_positive("spacing", spacing, "m"), self.shape)
        self.edges = _edges(edges, self.dim)
        if not isinstance(name, str) or not name:
            raise InvalidInputError(f"name: expected a non-empty str, got {name!r}")
        self.name = _check.text("name", name)
        self._host: Host | None = None

    #: Deprecated alias of :attr:`spacing` (the cell size, m).
    dx = _deprecate.alias("spacing", "dx")

    # -- geometry
    @property
    def extent(self) -> tuple[float, ...]:
        """The domain's size along each axis, m: ``shape · spacing``."""
        return tuple(n * self.spacing for n in self.shape)

    def centers(self) -> list[np.ndarray]:
        """Cell-centre coordinates along each axis, m: ``(i + ½) spacing``."""
        return [(np.arange(n) + 0.5) * self.spacing for n in self.shape]

    def _gaussian(self, center: Any, radius: float, arg: str) -> tuple[np.ndarray, np.ndarray]:
        if center is None:
            raise InvalidInputError(f"{arg}.center: give a center of {self.dim} coordinates (m), or a region")
        c = _point(f"{arg}.center", center, self.dim)
        radius = _positive(f"{arg}.radius", radius, "m")
        grids = np.meshgrid(*self.centers(), indexing="ij")
        # A far centre, a huge or a subnormal radius: inf distances, weights 0, no warning.
        # (r/radius)² rather than r²/radius², whose denominator underflows to 0 (0/0 at the centre).
        with np.errstate(over="ignore", under="ignore"):
            r2 = sum((g - ci) ** 2 for g, ci in zip(grids, c, strict=False))
            w = np.exp(-0.5 * (np.sqrt(r2) / np.float64(radius)) ** 2)
            w[r2 > (4 * np.float64(radius)) ** 2] = 0.0
        flat = _layout(w)
        cells = np.flatnonzero(flat)
        if cells.size == 0:
            raise InvalidInputError(f"{arg}: the Gaussian at center {c.tolist()} (radius {radius} m) covers no cell of the grid")
        return cells.astype(np.uint32), flat[cells]

    # -- bound to a scene
    def _bound(self) -> Host:
        if self._host is None:
            raise InvalidInputError(f"{type(self).__name__} {self.name!r} is not in a scene yet: scene.add(it) first")
        return self._host

    @allocating("field", "a field of the grid")
    def field(self, name: str) -> np.ndarray:
        """The field ``name`` now (one of :attr:`fields`), shape :attr:`shape`, float64 (a copy).

        Raises
        ------
        InvalidInputError, TypeError
            ``name`` is not one of the grid's :attr:`fields` (an unknown name read as zeros)."""
        name = _check.choice("name", name, self.fields)
        host = self._bound()
        (flat,) = host.exclusive(lambda sim: sim.system_fields(self.name, [name]))
        return _unlayout(flat, self.shape)

    def books(self) -> dict[str, float]:
        """Books that are not energies (amounts, what reactions made), by name."""
        host = self._bound()
        return dict(host.exclusive(lambda sim: sim.system_books(self.name)))

    def _set(self, name: str, values: Any) -> None:
        a = _check.real_array(name, values).astype(np.float64)
        if a.shape != self.shape:
            raise InvalidInputError(f"{name}: expected shape {self.shape} (the grid), got {a.shape}")
        host = self._bound()
        host.exclusive(lambda sim: sim.set_system_field(self.name, name, _layout(a)))
        host.energy_changed()

    def _params(self) -> dict[str, Any]:
        return {"shape": np.asarray(self.shape, dtype=np.float64), "spacing": self.spacing, "edges": ",".join(self.edges)}

    def _record(self) -> dict[str, Any]:
        """What a scene file stores to rebuild this grid (JSON-able; arrays: `_record_arrays`)."""
        raise NotImplementedError

    def _record_arrays(self) -> dict[str, np.ndarray]:
        """Arrays a scene file stores to rebuild this grid (flat, the core's layout): its
        obstacle mask and the regions of its sources given by region."""
        mask = getattr(self, "mask", None)
        out = {} if mask is None else {"mask": _layout(mask).astype(bool)}
        for k, src in enumerate(getattr(self, "oscillators", ()) or getattr(self, "sources", ())):
            if src.region is not None:  # the region wins over a center given too (see _profiles)
                out[f"region{k}"] = _layout(np.asarray(src.region, dtype=bool)).astype(bool)
        return out

    # -- the part protocol
    def _claim_name(self, ctx: AttachContext) -> str:
        return self.name  # checked by _attach, after the dimension

    def _attach(self, ctx: AttachContext, name: str) -> Grid:
        """Joins the scene: one scene only, under a free name; returns the grid itself, bound."""
        check_system(ctx, self, "grid")
        ctx.sim.add_grid(self.kind, self.name, self._params())
        self._host = ctx.host
        return self

    def _entry(self, sim: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """``{"kind", "name", "record"}`` and the record's arrays, then the state the core saves."""
        members = self._record_arrays()
        for a, v in sim.system_save(self.name):
            if not np.isfinite(v).all():
                raise InvalidInputError(f"grid {self.name!r}: its {a} is not finite; a scene file holds finite values only")
            members[a] = v
        return {"kind": self.kind, "name": self.name, "record": self._record()}, members

    def _state(self, sim: Any) -> dict[str, np.ndarray]:
        """The fields the core saves (as the scene file's members)."""
        return dict(sim.system_save(self.name))

    def _set_state(self, sim: Any, arrays: Any) -> None:
        sim.system_load(self.name, list(arrays.items()))

    @classmethod
    def _load_names(cls, ctx: LoadContext, arrays: Any) -> tuple[str, dict[str, str]]:
        return f"{ctx.field}.record", {}

    @classmethod
    def _load(cls, ctx: LoadContext, entry: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        kind = KIND_ALIASES.get(entry["kind"], entry["kind"])
        state = _GRID_ARRAYS[kind]
        grid = ctx.add(_from_record(kind, entry["name"], entry["record"], {a: v for a, v in arrays.items() if a not in state}))
        with ctx.api(f"grid{ctx.index}"):
            ctx.sim.system_load(grid.name, [(a, v) for a, v in arrays.items() if a in state])

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, shape={self.shape}, spacing={self.spacing:g}, edges={self.edges})"


class Wave(Grid):
    """The damped wave equation ``u_tt = c² ∇²u − γ u_t + f`` on a grid: ripples on a pond, a drum,
    interference behind slits.

    Stepped by the leapfrog scheme (central differences, second order in time and space;
    Langtangen & Linge, "Finite Difference Computing with PDEs", 2017, §2.1), stable for
    ``c·dt/dx ≤ 1/√dim`` (the CFL condition): :meth:`Scene.advance` keeps ``cfl`` of that limit;
    :meth:`Scene.step` with a larger ``dt`` warns (:class:`StabilityWarning`), and the field
    grows without bound (the energy books still balance: leapfrog's conserved energy holds past
    the limit, its potential part negative) until it overflows and :class:`SimulationDiverged`
    is raised.

    Parameters
    ----------
    shape : tuple of int
        Cells along x, y (, z), each >= 3.
    spacing : float
        Cell size dx, m (old name ``dx``, deprecated).
    c : float
        Wave speed, m/s.
    damping : float
        Damping rate γ, 1/s (default 0: the energy books then balance to round-off). Old name
        ``gamma`` (deprecated: in physcore γ is the Tait exponent of :class:`~physcore.Fluid`).
    edges : str or sequence of str
        ``"fixed"`` (default), ``"free"`` or ``"periodic"``, for all faces or per face.
    absorbing : bool or sequence of str
        Faces with a damping layer that swallows outgoing waves: ``True`` for every non-periodic
        face, or names from ``"x-", "x+", "y-", "y+", "z-", "z+"``.
    layer : int
        Cells in a damping layer (default 24); its γ rises as the square of the depth to
        ``layer_strength · c/dx`` (default 0.5) at the face.
    mask : (nx, ny) bool array, optional
        Obstacle cells, held at u = 0 (walls, slits).
    drops : sequence of :class:`Drop`
    oscillators : sequence of :class:`Oscillator`
    cfl : float
        Fraction of the CFL limit that :meth:`Scene.advance` steps at (default 0.9).
    name : str

    Attributes
    ----------
    u : (nx, ny) float64
        Once added to a scene: the displacement now, m.
    velocity : (nx, ny) float64
        Once added to a scene: ``u_t`` at the half step before now, m/s.

    Energy books (per unit areal density): kinetic ½Σ u_t² dA and potential ½c²|∇u|² (written as
    the leapfrog-conserved cross term of the two time levels), damping as dissipated, the work of
    drops and oscillators as a negative dissipated entry ``"<name> sources"``, and what each
    change of ``dt`` moved that cross term by (the velocity kept: ½c² (dt′ − dt) Σ u_t·∇²u dA) as
    ``"<name> dt changes"``, so that the total holds across a change as across a step.
    """

    kind = "wave"
    fields: ClassVar[tuple[str, ...]] = ("u", "velocity", "mask")

    #: Deprecated alias of :attr:`damping` (1/s).
    gamma = _deprecate.alias("damping", "gamma")

    @_deprecate.args(("shape", "spacing"), keep=2, renames={"dx": "spacing", "gamma": "damping"}, skip_self=True, name="Wave")
    @allocating("Wave", "a copy of its mask or regions")
    def __init__(
        self,
        shape: Any,
        spacing: float = 1.0,
        *,
        c: float = 1.0,
        damping: float = 0.0,
        edges: Any = "fixed",
        absorbing: Any = (),
        layer: int = 24,
        layer_strength: float = 0.5,
        mask: Any = None,
        drops: Sequence[Drop] = (),
        oscillators: Sequence[Oscillator] = (),
        cfl: float = 0.9,
        name: str = "wave",
    ) -> None:
        super().__init__(shape, spacing, edges, name)
        self.c = _positive("c", c, "m/s")
        self.damping = _positive("damping", damping, "1/s", allow_zero=True)
        if absorbing is True:
            absorbing = tuple(f for f, e in zip(_FACES, self.edges, strict=False) if e != "periodic")
        elif absorbing is False or absorbing is None:
            absorbing = ()
        if isinstance(absorbing, str) or not isinstance(absorbing, Sequence):
            raise InvalidTypeError(f"absorbing: expected True or a sequence of face names, got {absorbing!r}")
        for f in absorbing:
            if f not in _FACES[: 2 * self.dim]:
                raise InvalidInputError(f"absorbing: unknown face {f!r}; valid: {', '.join(_FACES[: 2 * self.dim])}")
        self.absorbing = tuple(absorbing)
        self.layer = _check.int_in_range("layer", layer, 1, 1 << 20)
        self.layer_strength = _positive("layer_strength", layer_strength, "c/dx")
        self.mask = None if mask is None else _cells_mask("mask", mask, self.shape).copy()
        if self.mask is not None:  # the record save writes (the core holds its own): read-only
            self.mask.setflags(write=False)
        self.cfl = _positive("cfl", cfl, "fraction of the CFL limit")
        if self.cfl > 1:
            raise InvalidInputError(f"cfl: must be in (0, 1], got {self.cfl}")
        self.drops = _records("drops", drops, Drop)
        self.oscillators = _records("oscillators", oscillators, Oscillator)
        self._profiles()  # checks every source now, before any scene sees it

    @property
    def cfl_limit(self) -> float:
        """The largest stable step spacing / (c √dim), s (the core's formula)."""
        return float(_core.grid_limits(self.kind, self.dim, {**Grid._params(self), "c": self.c})["cfl_limit"])

    def _profiles(self) -> dict[str, Any]:
        p: dict[str, Any] = {}
        cells, weights, counts = [], [], []
        for k, d in enumerate(self.drops):
            c, w = self._gaussian(d.center, d.radius, f"drops[{k}]")
            cells.append(c), weights.append(w), counts.append(c.size)
        # Finite here, by name (the core refused them too, but only when the wave was added).
        p["drop_t"] = np.array([_check.finite(f"drops[{k}].t", d.t) for k, d in enumerate(self.drops)], dtype=np.float64)
        p["drop_amplitude"] = np.array([_check.finite(f"drops[{k}].amplitude", d.amplitude) for k, d in enumerate(self.drops)], dtype=np.float64)
        p["drop_counts"] = np.array(counts, dtype=np.float64)
        p["drop_cells"] = np.concatenate(cells) if cells else np.zeros(0, np.uint32)
        p["drop_weights"] = np.concatenate(weights) if weights else np.zeros(0)
        cells, weights, counts = [], [], []
        for k, o in enumerate(self.oscillators):
            if o.region is not None:
                flat = _layout(_cells_mask(f"oscillators[{k}].region", o.region, self.shape))
                c = np.flatnonzero(flat).astype(np.uint32)
                if c.size == 0:
                    raise InvalidInputError(f"oscillators[{k}].region: covers no cell")
                w = np.ones(c.size)
            else:
                c, w = self._gaussian(o.center, o.radius, f"oscillators[{k}]")
            cells.append(c), weights.append(w), counts.append(c.size)
        for key, attr in (("osc_amplitude", "amplitude"), ("osc_frequency", "frequency"), ("osc_phase", "phase")):
            p[key] = np.array([_check.finite(f"oscillators[{k}].{attr}", getattr(o, attr)) for k, o in enumerate(self.oscillators)], dtype=np.float64)
        for k, o in enumerate(self.oscillators):
            if o.frequency < 0:
                raise InvalidInputError(f"oscillators[{k}].frequency: must be >= 0 (Hz), got {o.frequency}")
        p["osc_counts"] = np.array(counts, dtype=np.float64)
        p["osc_cells"] = np.concatenate(cells) if cells else np.zeros(0, np.uint32)
        p["osc_weights"] = np.concatenate(weights) if weights else np.zeros(0)
        return p

    def _params(self) -> dict[str, Any]:
        p = super()._params()
        p.update(
            c=self.c,
            damping=self.damping,
            cfl=self.cfl,
            layer=float(self.layer),
            layer_strength=self.layer_strength,
            absorbing=np.array([f in self.absorbing for f in _FACES[: 2 * self.dim]], dtype=np.float64),
            **self._profiles(),
        )
        if self.mask is not None:
            p["mask"] = _layout(self.mask)
        return p

    u = _field("u", "Displacement now, (nx, ny) float64, m; setting it keeps the velocity.")
    velocity = _field("velocity", "u_t at the half step before now, (nx, ny) float64, m/s.")

    def _record(self) -> dict[str, Any]:
        return {
            # Scene files keep the keys they have always had ("dx", "gamma"): see docs/naming.md.
            "shape": list(self.shape), "dx": self.spacing, "edges": list(self.edges), "c": self.c, "gamma": self.damping,
            "absorbing": list(self.absorbing), "layer": self.layer, "layer_strength": self.layer_strength, "cfl": self.cfl,
            "mask": self.mask is not None,
            "drops": [[d.t, list(map(float, d.center)), d.radius, d.amplitude] for d in self.drops],
            "oscillators": [
                [o.amplitude, o.frequency, None if o.region is not None else list(map(float, o.center)), o.radius, o.phase]
                for o in self.oscillators
            ],
        }


#: Named (F, k) of Gray–Scott pattern classes, in Pearson's units (D_u = 2e-5, D_v = 1e-5, time
#: in the units of F and k). The classes are Pearson's (Science 261 (1993) 189, Fig. 3); the
#: values are representative points of each class from R. Munafo's catalogue of the (F, k)
#: plane (mrob.com/pub/comp/xmorphia), checked by the pattern tests in tests/grids/test_grids.py.
PRESETS: dict[str, tuple[float, float]] = {
    "spots": (0.030, 0.062),  # solitons that stay put (Pearson's kappa/lambda border)
    "mitosis": (0.0367, 0.0649),  # spots that grow and split (lambda)
    "stripes": (0.037, 0.060),  # fingerprint-like stripes (eta/theta)
    "maze": (0.029, 0.057),  # a labyrinth of connected stripes (theta/kappa)
    "coral": (0.0545, 0.062),  # branching growth (mu-like)
    "holes": (0.039, 0.058),  # a sheet with holes (iota)
    "chaos": (0.026, 0.051),  # turbulent waves that never settle (beta)
}


class GrayScott(Grid):
    """Gray–Scott reaction–diffusion (Turing patterns):
    ``u_t = D_u ∇²u − u v² + F (1 − u)``, ``v_t = D_v ∇²v + u v² − (F + k) v``
    (Pearson, "Complex patterns in a simple system", Science 261 (1993) 189–192, eq. 1–2).

    Forward Euler with the 5-point Laplacian (Pearson's scheme); diffusion alone is stable for
    ``dt ≤ dx² / (2·dim·max(D))`` (dx²/(4D) in 2D, :attr:`diffusion_limit`), the reactions
    bound the step too: :meth:`Scene.advance` keeps ``cfl`` of ``2 / (4·dim·max(D)/dx² + ρ_R)``,
    ρ_R = F + k + max(1, max v(v + 2u)) (a Gershgorin bound on the reactions' Jacobian).

    Parameters
    ----------
    shape : tuple of int
    spacing : float
        Cell size dx (m). Pearson: 2.5/256. Old name ``dx`` (deprecated).
    du, dv : float
        Diffusion coefficients, m²/s (Pearson: 2e-5, 1e-5).
    feed, kill : float
        F and k, 1/s; or give ``preset`` (a name of :data:`PRESETS`).
    edges : "periodic" (default) or "free"
    cfl : float
        Fraction of the diffusion limit :meth:`Scene.advance` steps at (default 0.8).

    Starts at the homogeneous state u = 1, v = 0: seed it with :meth:`seed` or set ``u``/``v``.
    Books (:meth:`books`): ``u`` and ``v`` (Σ·dA) and ``u_made``/``v_made`` (what the reactions
    made); ``u − u_made`` stays at its start value to round-off.
    """

    kind = "gray_scott"
    fields: ClassVar[tuple[str, ...]] = ("u", "v")

    @_deprecate.args(("shape", "spacing"), keep=2, renames={"dx": "spacing"}, skip_self=True, name="GrayScott")
    def __init__(
        self,
        shape: Any,
        spacing: float = 2.5 / 256,
        *,
        du: float = 2e-5,
        dv: float = 1e-5,
        feed: float | None = None,
        kill: float | None = None,
        preset: str | None = None,
        edges: Any = "periodic",
        cfl: float = 0.8,
        name: str = "gray_scott",
    ) -> None:
        super().__init__(shape, spacing, edges, name)
        if "fixed" in self.edges:
            raise InvalidInputError("edges: Gray–Scott takes 'periodic' or 'free' (no-flux) faces, not 'fixed'")
        if preset is not None:
            if not isinstance(preset, str):
                raise InvalidTypeError(f"preset: expected a name ({', '.join(PRESETS)}), got {type(preset).__name__}")
            if preset not in PRESETS:
                raise InvalidInputError(f"preset: unknown {preset!r}; valid: {', '.join(PRESETS)}")
            if feed is not None or kill is not None:
                raise InvalidInputError("preset: give a preset or feed/kill, not both")
            feed, kill = PRESETS[preset]
        if feed is None or kill is None:
            raise InvalidInputError("feed/kill: give both (1/s), or a preset")
        self.preset = preset
        self.du = _positive("du", du, "m²/s", allow_zero=True)
        self.dv = _positive("dv", dv, "m²/s", allow_zero=True)
        if self.du == 0 and self.dv == 0:
            raise InvalidInputError("du/dv: both are 0, nothing diffuses")
        self.feed = _positive("feed", feed, "1/s", allow_zero=True)
        self.kill = _positive("kill", kill, "1/s", allow_zero=True)
        self.cfl = _positive("cfl", cfl, "fraction of the diffusion limit")
        if self.cfl > 1:
            raise InvalidInputError(f"cfl: must be in (0, 1], got {self.cfl}")

    @property
    def diffusion_limit(self) -> float:
        """The largest stable step dx² / (2·dim·max(D_u, D_v)), s (the core's formula)."""
        params = {**Grid._params(self), "du": self.du, "dv": self.dv}
        return float(_core.grid_limits(self.kind, self.dim, params)["diffusion_limit"])

    def _params(self) -> dict[str, Any]:
        p = super()._params()
        p.update(du=self.du, dv=self.dv, feed=self.feed, kill=self.kill, cfl=self.cfl)
        return p

    u = _field("u", "Concentration of U, (nx, ny) float64.")
    v = _field("v", "Concentration of V, (nx, ny) float64.")

    def seed(self, seed: int = 0, *, squares: int = 1, size: float = 0.08, noise: float = 0.01) -> None:
        """Pearson's start: u = 1, v = 0, with ``squares`` squares of side ``size`` (a fraction of
        the domain) set to u = ½, v = ¼, placed at random (seeded; the first one at the centre),
        and ±``noise`` uniform noise on both (Pearson: 1 %).

        Raises
        ------
        InvalidTypeError
            ``seed`` or ``squares`` not an int, ``size`` or ``noise`` not a real number.
        InvalidInputError
            ``seed`` < 0, ``squares`` outside 0..10,000, ``size`` outside (0, 1] or ``noise``
            negative or not finite; nothing is changed.
        """
        rng = np.random.default_rng(_check.int_in_range("seed", seed, 0, 2**63 - 1))
        squares = _check.int_in_range("squares", squares, 0, 10_000)
        size = _check.float_in_range("size", size, 0.0, 1.0, lo_open=True, unit="a fraction of the domain")
        noise = _check.nonneg_float("noise", noise)
        with allocating("seed", "the start's u and v"):  # numpy's MemoryError, named; nothing changed
            u = np.ones(self.shape)
            v = np.zeros(self.shape)
            side = [max(1, int(round(size * n))) for n in self.shape]
            for k in range(squares):
                lo = [n // 2 - s // 2 if k == 0 else int(rng.integers(0, n - s + 1)) for n, s in zip(self.shape, side, strict=False)]
                sl = tuple(slice(a, a + s) for a, s in zip(lo, side, strict=False))
                u[sl] = 0.5
                v[sl] = 0.25
            u += noise * (2 * rng.random(self.shape) - 1)
            v += noise * (2 * rng.random(self.shape) - 1)
            u, v = np.clip(u, 0, None), np.clip(v, 0, None)
        self.u = u
        self.v = v

    def _record(self) -> dict[str, Any]:
        return {"shape": list(self.shape), "dx": self.spacing, "edges": list(self.edges), "du": self.du, "dv": self.dv,
                "feed": self.feed, "kill": self.kill, "cfl": self.cfl}


@_deprecate.record(('density', 'temperature', 'velocity', 'center', 'radius', 'region'), keep=0)
@dataclass(frozen=True)
class Source:
    """An inflow of a :class:`StableFluid`: on its cells, every step, the smoke density and the
    temperature are set to ``density`` and ``temperature`` and the velocity to ``velocity``
    (m/s). The cells are a disc of ``radius`` (m) at ``center`` (m), or ``region`` (a bool array
    over the grid)."""

    _: KW_ONLY
    density: float = 1.0
    temperature: float = 0.0
    velocity: Sequence[float] = (0.0, 0.0)
    center: Sequence[float] | None = None
    radius: float = 0.0
    region: Any = None


class StableFluid(Grid):
    """An incompressible fluid on a staggered (MAC) grid: Stam, "Stable Fluids", SIGGRAPH 1999.

    Each step: sources, buoyancy ``f_y = −α ρ_smoke + β (T − T_ambient)`` and vorticity
    confinement (Fedkiw, Stam & Jensen, "Visual simulation of smoke", SIGGRAPH 2001, eq. 8–11),
    advection with an RK2 backtrace (MacCormack with Selle et al.'s 2008 clamp to the values
    interpolated between, or plain semi-Lagrangian), implicit viscosity, then a pressure
    projection (incremental by default, see ``projection``) solved by conjugate gradients
    preconditioned with a multigrid V-cycle (MGPCG, McAdams et al. 2010) to ``tolerance``.
    Tracers ride the velocity (RK2); they start, and re-enter when they leave, at the first
    source (anywhere in the fluid without one). 2D.

    Parameters
    ----------
    shape : (nx, ny)
    spacing : float
        Cell size dx, m (old name ``dx``, deprecated).
    nu : float
        Kinematic viscosity ν, m²/s (0: none). Old name ``viscosity`` (deprecated: in physcore
        the SPH :class:`~physcore.Fluid`'s artificial viscosity is ``alpha``).
    buoyancy : (alpha, beta)
        α (m/s² per unit smoke density, pulls down), β (m/s² per kelvin above ambient, lifts).
    ambient_temperature : float
    vorticity : float
        Confinement strength ε (≥ 0).
    advection : {"maccormack", "semi_lagrangian"}
        MacCormack (default; Selle, Fedkiw, Kim, Liu & Rossignac, J. Sci. Comput. 35 (2008):
        second order in space where smooth, clamped to the min/max of the values the backtrace
        interpolated between, so it makes no new extrema) or semi-Lagrangian (first order,
        diffusive: −1.85 % of Taylor–Green's energy at the e-folding time at 256², ``cfl``
        below). MacCormack costs about 1.3× per step at 256².
    projection : {"incremental", "chorin"}
        How the pressure enters a step. ``"incremental"`` (default): an incremental pressure
        correction (van Kan, SIAM J. Sci. Stat. Comput. 7 (1986) 870) in semi-Lagrangian form:
        the last step's pressure acts along each path by the trapezoid rule, half of its
        gradient applied before the velocity is advected, the rest found by the projection,
        so the gradient the projection removes is O(dt²) a step and the splitting loses no
        energy to first order. ``"chorin"`` (Chorin, Math. Comp. 22 (1968) 745; the default
        before issue 64): advected without the pressure, then projected; it loses O(dt²)
        kinetic energy a step, first order in time. The pressure kept (``pressure``) is the
        whole pressure either way. Incremental costs about 4 % more per step at 256² (one
        more pressure iteration). Scene files written before this option load as ``"chorin"``.
    tolerance : float
        Relative residual of the pressure solve (default 1e-8).
    max_iterations : int
    walls : {"free_slip", "no_slip"}
        The domain's walls (all four are solid unless ``inflow`` opens the x faces). No-slip
        walls hold after the projection: the viscous solve gives the wall the value
        (1 − share)·dt·∂p/∂τ that the projection's gradient takes back (Kim & Moin, J. Comput.
        Phys. 59 (1985) 308), so a steady state does not depend on the step (plane Poiseuille
        flow's pressure gradient −0.78 % at 16 cells across, the grid's error, at any ``cfl``
        and either ``projection``). Obstacles (always no-slip) have their walls at their
        cells' edges and get the same term.
    lid : float, optional
        Speed (m/s, +x) of the top wall: a lid-driven cavity (needs ``walls="no_slip"``).
    inflow : float, optional
        Speed U (m/s, > 0) of a uniform inflow through the left face (x = 0): u = U, v = 0 there
        (U beside fluid cells, 0 beside obstacles). The right face (x = nx·dx) is then an open
        outflow: pressure 0 (Dirichlet) and velocity and smoke leaving with zero normal gradient,
        so fluid passes through the box; the bottom and top stay ``walls``. Smoke (``density``)
        enters only where sources or the initial field put it. None (default): a closed box.
    obstacles : (nx, ny) bool array, optional
    sources : sequence of :class:`Source`
    tracers : int
        Passive tracer particles (drawn as streaks by the renderer).
    cfl : float
        ``Scene.advance`` steps at ``cfl · dx / max|u|``. Default 1. A Taylor–Green vortex
        (peak speed 1 m/s, ν = 0.05 m²/s) at the defaults has its kinetic energy at the
        e-folding time t = 5 s within +0.17 % / +0.11 % / +0.057 % at 64² / 128² / 256²: what
        is left is mostly the backward-Euler viscosity's lag (too little decay, about
        4ν²·dt·t). With ``projection="chorin"`` the splitting's error is first order in the
        step and set by it, not by the grid: −7.0 % / −3.6 % / −1.84 % at t = 5 s, and at
        t = 1 s 0.54 % too little at dt = π/256 s, whether that is 256² at cfl 1 or 64² at
        cfl 0.25 (64² at cfl 1: 2.1 %). Flows that change shape keep a first-order part (the
        paths are traced through the velocity at the start of the step): the vortex street's
        Strouhal number moves 0.6 % between cfl 1 and 0.5 (4.0 % with Chorin's). Lower ``cfl``
        where decay rates or frequencies matter.

    On a GPU (``Scene(device="gpu")``) every stage runs on the device, the pressure by MGPCG
    and the tracers (re-seeded by the CPU's hash) too; f64 runs agree with
    the CPU path to round-off (within 4e-14 of each field's largest value after 100 steps),
    f32 runs to 1e-5 – 3e-4 (docs/guide/gpu.md, "Precision, stated").

    Attributes (in a scene): ``density``, ``temperature``, ``pressure``, ``vorticity``, ``speed``
    (nx, ny) float64; ``velocity`` (nx, ny, 2) at cell centres; ``tracers`` (T, 2) m.
    Energy books: kinetic ½Σ|u|² dA (unit density) and what each stage removed (or, negative,
    added) as dissipated; :meth:`books`: smoke amount and injection, solver iterations.
    """

    #: Its kind in scene files and in :data:`physcore._parts.PARTS` (``"grids/stable_fluid"``); files
    #: that say ``"fluid"`` (before issue 45) still load (:data:`KIND_ALIASES`).
    kind = "stable_fluid"
    fields: ClassVar[tuple[str, ...]] = ("u", "v", "speed", "vorticity", "density", "temperature", "pressure", "divergence", "solid")

    #: Deprecated alias of :attr:`nu` (m²/s).
    viscosity = _deprecate.alias("nu", "viscosity")

    @_deprecate.args(("shape", "spacing"), keep=2, renames={"dx": "spacing", "viscosity": "nu"}, skip_self=True, name="StableFluid")
    @allocating("StableFluid", "a copy of its obstacles or regions")
    def __init__(
        self,
        shape: Any,
        spacing: float = 1 / 64,
        *,
        nu: float = 0.0,
        buoyancy: Sequence[float] = (0.0, 0.0),
        ambient_temperature: float = 0.0,
        vorticity: float = 0.0,
        advection: str = "maccormack",
        projection: str = "incremental",
        tolerance: float = 1e-8,
        max_iterations: int = 500,
        walls: str = "free_slip",
        lid: float | None = None,
        inflow: float | None = None,
        obstacles: Any = None,
        sources: Sequence[Source] = (),
        tracers: int = 0,
        cfl: float = 1.0,
        name: str = "fluid",
    ) -> None:
        super().__init__(shape, spacing, "fixed", name)
        if self.dim != 2:
            raise InvalidInputError(f"shape: the grid fluid is 2D, got {len(self.shape)} cell counts")
        self.nu = _positive("nu", nu, "m²/s", allow_zero=True)
        if isinstance(buoyancy, (str, bytes)) or not isinstance(buoyancy, Sequence) or len(buoyancy) != 2:
            raise InvalidInputError(f"buoyancy: expected (alpha, beta), got {buoyancy!r}")
        self.buoyancy = tuple(_check.finite(f"buoyancy[{k}]", b) for k, b in enumerate(buoyancy))
        self.ambient_temperature = _check.finite("ambient_temperature", ambient_temperature)
        self.vorticity = _positive("vorticity", vorticity, "", allow_zero=True)
        self.advection = _check.choice("advection", advection, ("semi_lagrangian", "maccormack"))
        self.projection = _check.choice("projection", projection, ("incremental", "chorin"))
        self.tolerance = _positive("tolerance", tolerance, "relative residual")
        if self.tolerance >= 1:
            raise InvalidInputError(f"tolerance: must be in (0, 1), got {self.tolerance}")
        self.max_iterations = _check.int_in_range("max_iterations", max_iterations, 1, 1 << 30)
        self.walls = _check.choice("walls", walls, ("free_slip", "no_slip"))
        self.lid = None if lid is None else _check.finite("lid", lid)
        if self.lid is not None and self.walls != "no_slip":
            raise InvalidInputError("lid: a moving lid needs walls='no_slip' (free-slip walls do not feel it)")
        self.inflow = None if inflow is None else _positive("inflow", inflow, "m/s, +x")
        self.mask = None if obstacles is None else _cells_mask("obstacles", obstacles, self.shape).copy()
        if self.mask is not None:  # the record save writes (the core holds its own): read-only
            self.mask.setflags(write=False)
        self.sources = _records("sources", sources, Source)
        self.n_tracers = _check.int_in_range("tracers", tracers, 0, 1 << 24)
        self.cfl = _positive("cfl", cfl, "advection CFL number")
        self._source_params()

    def _source_params(self) -> dict[str, Any]:
        cells, weights, counts = [], [], []
        for k, src in enumerate(self.sources):
            if src.region is not None:
                flat = _layout(_cells_mask(f"sources[{k}].region", src.region, self.shape))
                c = np.flatnonzero(flat).astype(np.uint32)
                w = np.ones(c.size)
            else:
                if src.center is None:
                    raise InvalidInputError(f"sources[{k}].center: give a region, or a center of 2 finite coordinates (m)")
                c0 = _point(f"sources[{k}].center", src.center, 2)
                r = _positive(f"sources[{k}].radius", src.radius, "m")
                X, Y = np.meshgrid(*self.centers(), indexing="ij")
                with np.errstate(over="ignore"):  # a far centre: inf distances, no cell
                    flat = _layout(((X - c0[0]) ** 2 + (Y - c0[1]) ** 2 <= np.float64(r) ** 2).astype(np.float64))
                c = np.flatnonzero(flat).astype(np.uint32)
                w = np.ones(c.size)
            if c.size == 0:
                where = "region covers" if src.region is not None else "center and radius cover"
                raise InvalidInputError(f"sources[{k}]: its {where} no cell of the grid")
            _point(f"sources[{k}].velocity", src.velocity, 2, "m/s")
            _check.finite(f"sources[{k}].density", src.density)
            _check.finite(f"sources[{k}].temperature", src.temperature)
            cells.append(c), weights.append(w), counts.append(c.size)
        return {
            "src_density": np.array([float(s.density) for s in self.sources], dtype=np.float64),
            "src_temperature": np.array([float(s.temperature) for s in self.sources], dtype=np.float64),
            "src_velocity": np.array([float(x) for s in self.sources for x in s.velocity], dtype=np.float64),
            "src_counts": np.array(counts, dtype=np.float64),
            "src_cells": np.concatenate(cells) if cells else np.zeros(0, np.uint32),
            "src_weights": np.concatenate(weights) if weights else np.zeros(0),
        }

    def _params(self) -> dict[str, Any]:
        p = super()._params()
        p.update(
            nu=self.nu, buoyancy_alpha=self.buoyancy[0], buoyancy_beta=self.buoyancy[1],
            ambient_temperature=self.ambient_temperature, vorticity=self.vorticity, advection=self.advection,
            projection=self.projection,
            tolerance=self.tolerance, max_iterations=float(self.max_iterations), no_slip=self.walls == "no_slip",
            has_lid=self.lid is not None, lid=0.0 if self.lid is None else self.lid,
            has_inflow=self.inflow is not None, inflow=0.0 if self.inflow is None else self.inflow, n_tracers=float(self.n_tracers),
            cfl=self.cfl, **self._source_params(),
        )
        if self.mask is not None:
            p["obstacles"] = _layout(self.mask)
        return p

    density = _field("density", "Smoke density (nx, ny).")
    temperature = _field("temperature", "Temperature (nx, ny), K.")
    pressure = _field("pressure", "Pressure of the last projection (nx, ny) (kinematic, m²/s²).", False)
    vorticity_field = _field("vorticity", "Vorticity ∂v/∂x − ∂u/∂y at cell centres (nx, ny), 1/s.", False)
    speed = _field("speed", "``|u|`` at cell centres (nx, ny), m/s.", False)
    divergence = _field("divergence", "Discrete divergence (nx, ny), 1/s.", False)

    @property
    @allocating("velocity", "the cell-centred velocity")
    def velocity(self) -> np.ndarray:
        """Velocity at cell centres (averaged from the faces), (nx, ny, 2) float64, m/s."""
        return np.stack([self.field("u"), self.field("v")], axis=-1)

    def set_velocity(self, u: Any, v: Any) -> None:
        """Sets the face velocities: ``u`` (nx+1, ny) on the x faces, ``v`` (nx, ny+1) on the y
        faces, m/s (faces of solid cells are set to 0; not projected).

        Raises InvalidInputError / InvalidTypeError naming ``u`` or ``v`` (shape, dtype, a
        non-finite entry) before either is set."""
        nx, ny = self.shape
        checked = []
        for name, a, shape in (("u", u, (nx + 1, ny)), ("v", v, (nx, ny + 1))):
            arr = _check.real_array(name, a).astype(np.float64)
            if arr.shape != shape:
                raise InvalidInputError(f"{name}: expected shape {shape} (faces), got {arr.shape}")
            bad = np.argwhere(~np.isfinite(arr))
            if len(bad):
                raise InvalidInputError(f"{name}: entry {tuple(int(k) for k in bad[0])} is not finite")
            checked.append((name, arr))
        host = self._bound()
        for name, arr in checked:
            host.exclusive(lambda sim, name=name, arr=arr: sim.set_system_field(self.name, name, _layout(arr)))
        host.energy_changed()

    @property
    def tracers(self) -> np.ndarray:
        """Tracer positions, (T, 2) float64, m."""
        host = self._bound()
        (flat,) = host.exclusive(lambda sim: sim.system_fields(self.name, ["tracers"]))
        return np.asarray(flat).reshape(-1, 2)

    def _record(self) -> dict[str, Any]:
        # "projection" is written only where it is not Chorin's: a record without it is Chorin's
        # (files from before issue 64 ran it), and such files stay readable by older versions.
        extra = {} if self.projection == "chorin" else {"projection": self.projection}
        return {
            "shape": list(self.shape), "dx": self.spacing, "viscosity": self.nu, "buoyancy": list(self.buoyancy),
            "ambient_temperature": self.ambient_temperature, "vorticity": self.vorticity, "advection": self.advection,
            **extra, "tolerance": self.tolerance, "max_iterations": self.max_iterations, "walls": self.walls, "lid": self.lid,
            "inflow": self.inflow, "mask": self.mask is not None, "tracers": self.n_tracers, "cfl": self.cfl,
            "sources": [
                [s.density, s.temperature, list(map(float, s.velocity)), None if s.region is not None else list(map(float, s.center)), s.radius]
                for s in self.sources
            ],
        }


KINDS: dict[str, type[Grid]] = {"wave": Wave, "gray_scott": GrayScott, "stable_fluid": StableFluid}
#: Old kind names scene files may hold: ``"fluid"`` (the grid fluid before issue 45).
KIND_ALIASES: dict[str, str] = {"fluid": "stable_fluid"}
#: The state arrays each kind saves (``System::save`` in the core).
_GRID_ARRAYS: dict[str, tuple[str, ...]] = {
    "wave": ("u", "u_prev", "clock", "dt_changes"),
    "gray_scott": ("u", "v", "made"),
    "stable_fluid": ("u", "v", "density", "temperature", "pressure", "tracers", "steps", "books"),
}


def _from_record(kind: str, name: str, r: dict[str, Any], arrays: dict[str, np.ndarray]) -> Grid:
    """Rebuilds a grid from what :meth:`Grid._record` and its arrays wrote (old kinds too)."""
    kind = KIND_ALIASES.get(kind, kind)
    arrays = {k: _unlayout(a, tuple(r["shape"])) for k, a in arrays.items()}
    if kind == "wave":
        return Wave(
            tuple(r["shape"]), r["dx"], c=r["c"], damping=r["gamma"], edges=tuple(r["edges"]), absorbing=tuple(r["absorbing"]),
            layer=r["layer"], layer_strength=r["layer_strength"], cfl=r["cfl"], mask=arrays.get("mask"),
            drops=[Drop(t, tuple(c), radius=rad, amplitude=a) for t, c, rad, a in r["drops"]],
            oscillators=[
                Oscillator(a, f, center=None if c is None else tuple(c), radius=rad, region=arrays.get(f"region{k}") if c is None else None, phase=ph)
                for k, (a, f, c, rad, ph) in enumerate(r["oscillators"])
            ],
            name=name,
        )
    if kind == "gray_scott":
        return GrayScott(tuple(r["shape"]), r["dx"], du=r["du"], dv=r["dv"], feed=r["feed"], kill=r["kill"],
                         edges=tuple(r["edges"]), cfl=r["cfl"], name=name)
    if kind == "stable_fluid":
        return StableFluid(
            tuple(r["shape"]), r["dx"], nu=r["viscosity"], buoyancy=tuple(r["buoyancy"]),
            ambient_temperature=r["ambient_temperature"], vorticity=r["vorticity"], advection=r["advection"],
            projection=r.get("projection", "chorin"),  # files from before issue 64 ran Chorin's
            tolerance=r["tolerance"], max_iterations=r["max_iterations"], walls=r["walls"], lid=r["lid"],
            inflow=r.get("inflow"), obstacles=arrays.get("mask"), tracers=r["tracers"], cfl=r["cfl"], name=name,
            sources=[
                Source(density=d, temperature=t, velocity=tuple(v), center=None if c is None else tuple(c), radius=rad, region=arrays.get(f"region{k}") if c is None else None)
                for k, (d, t, v, c, rad) in enumerate(r["sources"])
            ],
        )
    raise InvalidInputError(f"kind: unknown grid kind {kind!r}; valid: {', '.join(KINDS)}")
