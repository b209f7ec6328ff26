"""physcore's exception hierarchy (raised from Rust through ``physcore._core`` as well)."""
from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

__all__ = [
    "PhyscoreError",
    "InvalidInputError",
    "InvalidTypeError",
    "SceneFileError",
    "SimulationDiverged",
    "SceneBusyError",
    "OutOfMemoryError",
    "ThreadPoolError",
    "ThreadPoolWarning",
    "SeparateFluidsWarning",
    "ContactStepWarning",
    "StabilityWarning",
    "EnergyBooksWarning",
    "UnchargedWarning",
    "UnusedOptionWarning",
]


class PhyscoreError(Exception):
    """Base class of every error physcore raises on purpose."""


class InvalidInputError(PhyscoreError, ValueError):
    """An argument is invalid. Raised before any state changes; the message names the argument."""


class InvalidTypeError(PhyscoreError, TypeError):
    """An argument has the wrong type (a ``TypeError``); the message starts with its name.
    Nothing was changed."""


class SceneFileError(InvalidInputError):
    """A file given to :meth:`Scene.load` is not a scene file physcore can read: not a zip
    archive, truncated or corrupted, a member missing, extra or malformed, a field of the wrong
    type or out of range, or sizes beyond what the file itself holds.

    It is the one error :meth:`Scene.load` raises for what is *in* a file (the file could be
    opened); failures to open it stay ``OSError``. The message starts with the file name and the
    offending field (``"meta.step"``, ``"positions"``, ``"meta.terms[2].g"``), also kept as the
    attributes ``path`` (str) and ``field`` (str, ``""`` for the archive as a whole). Nothing in
    the file is executed (object arrays are refused before their data is read).
    """

    def __init__(self, path: str, field: str, problem: str) -> None:
        super().__init__(f"{path}: {field}: {problem}" if field else f"{path}: {problem}")
        self.path = path
        self.field = field
        self.problem = problem

    def __reduce__(self):  # pickles (multiprocessing) despite the three-argument constructor
        return (type(self), (self.path, self.field, self.problem))


class OutOfMemoryError(PhyscoreError, MemoryError):
    """A buffer sized by the input could not be allocated. Nothing was changed.

    The message says what needed how much; ``bytes`` is that amount (the whole call's need
    where it is known up front, else the buffer that failed). Free memory or make the input
    smaller.
    """

    def __init__(self, message: str, bytes: int = -1) -> None:
        super().__init__(message)
        self.bytes = bytes


def _human(nbytes: int) -> str:
    """Bytes in decimal units, three significant digits, as the core writes them: "72.0 MB"."""
    units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"]
    x, u = float(nbytes), 0
    while x >= 999.5 and u + 1 < len(units):
        x, u = x / 1000.0, u + 1
    if u == 0:
        return f"{nbytes} bytes"
    return f"{x:.0f} {units[u]}" if x >= 99.95 else f"{x:.1f} {units[u]}" if x >= 9.995 else f"{x:.2f} {units[u]}"


def _memory_error_in(e: BaseException | None) -> MemoryError | None:
    """The ``MemoryError`` that ``e`` is, or that it was raised while handling (its context
    chain), if any."""
    seen = 0
    while e is not None and seen < 16:
        if isinstance(e, MemoryError):
            return e
        e, seen = e.__context__, seen + 1
    return None


@contextmanager
def allocating(what: str, context: str, rename: tuple[str, ...] = ()) -> Iterator[None]:
    """Turns a bare ``MemoryError`` raised in the block (numpy's, for an array the facade
    allocates) into :class:`OutOfMemoryError` naming the call ``what``, the array and
    ``context``, so that every refusal of memory reads the same as the core's. The core's own
    refusals named one of ``rename`` (its "save" of a system's state, read for
    ``Scene.to_bytes``) are named ``what`` too. Usable as a decorator."""
    try:
        yield
    except Exception as raised:
        # A MemoryError, or an error raised while cleaning up after one (np.savez into a full
        # BytesIO: zipfile's close then raises "I/O operation on closed file", a ValueError).
        e = raised if isinstance(raised, OutOfMemoryError) else _memory_error_in(raised)
        if e is None:
            raise
        if isinstance(e, OutOfMemoryError):
            # Made by an inner block of this kind (a part's constructor inside
            # Scene.add_fluid), or by the core under one of `rename`: named again as this, the
            # outer call, the one the user made.
            tail = getattr(e, "_allocating", None)
            inner = next((r for r in rename if e.args[0].startswith(f"{r}: ")), None)
            if tail is None and inner is not None:
                tail = e.args[0][len(inner) + 2:]
            if tail is None or e.args[0].startswith(f"{what}: "):
                if e is raised:
                    raise
                raise e from None
            again = OutOfMemoryError(f"{what}: {tail}", e.bytes)
            again._allocating = tail  # type: ignore[attr-defined]
            raise again from e.__cause__
        nbytes = getattr(e, "_total_size", -1)  # numpy's _ArrayMemoryError knows the size
        shape, dtype = getattr(e, "shape", None), getattr(e, "dtype", None)
        array = f"an array of shape {tuple(shape)}, {dtype}" if shape is not None else "an array"
        size = _human(nbytes) if nbytes >= 0 else "more memory"
        tail = f"needs {size} for {array} ({context}), more than can be allocated now. Free memory, or make the input smaller"
        err = OutOfMemoryError(f"{what}: {tail}", nbytes)
        err._allocating = tail  # type: ignore[attr-defined]
        raise err from e


def refusing_memory(what: str, context: str, rename: tuple[str, ...] = ()) -> Callable[[F], F]:
    """A decorator: the function's body under :func:`allocating` (``what``, ``context``). Its
    wrapper is a frame of this package, so a warning raised inside that points at the first
    frame outside physcore (``user_stacklevel``) still finds the caller's line (contextlib's
    decorator form would be that frame)."""

    def wrap(f: F) -> F:
        @functools.wraps(f)
        def inner(*args: Any, **kwargs: Any) -> Any:
            with allocating(what, context, rename):
                return f(*args, **kwargs)

        return inner  # type: ignore[return-value]

    return wrap


class ThreadPoolError(PhyscoreError, RuntimeError):
    """``threads=n`` was asked for but the n threads could not be started (the process's limit
    on threads, ``ulimit -u``). Ask for fewer, or pass ``threads=None``."""


class DeviceError(PhyscoreError, RuntimeError):
    """The GPU failed while stepping or reading back (a lost device, a driver error). The scene's
    state is as of the last step that completed."""


class ThreadPoolWarning(RuntimeWarning):
    """A scene built with ``threads=None`` could not start its threads and runs on the calling
    thread alone: same results, slower, and Ctrl-C takes effect when a call ends (the call is
    still undone)."""


class SeparateFluidsWarning(UserWarning):
    """A :class:`~physcore.fluids.Fluid` was added that will not interact with some fluid
    already in the scene, so the two pass through each other. Fluids share one neighbour search,
    and push on each other, when they have the same ``h`` (``smoothing · spacing``), kernel and
    precision, up to 8 per search; give the fluids that should meet the same three."""


class ContactStepWarning(UserWarning):
    """A scene with :class:`~physcore.Contacts` was stepped with :meth:`~physcore.Scene.step` at
    a ``dt`` more than twice its automatic step (a 50th of a contact's duration, or less where
    other forces need it): collisions then lose or gain energy and the restitution is wrong.
    :meth:`~physcore.Scene.advance` picks the step itself; or set
    ``scene.dt = scene.suggest_dt()``."""


class StabilityWarning(UserWarning):
    """A scene with a grid was stepped with :meth:`~physcore.Scene.step` at a ``dt`` above the
    grid's stability limit: the wave equation's CFL limit ``spacing / (c √dim)``
    (:attr:`~physcore.Wave.cfl_limit`) or Gray-Scott's explicit diffusion limit
    ``dx² / (2·dim·max(D))`` (:attr:`~physcore.GrayScott.diffusion_limit`). The scheme is
    unstable there: the field grows without bound until it overflows and the step raises
    :class:`SimulationDiverged`. A wave grid's energy books stay balanced meanwhile (leapfrog's
    conserved energy, whose potential part turns negative past the limit), so the books cannot
    show it. :meth:`~physcore.Scene.advance` steps within the limits; or set ``scene.dt =
    scene.suggest_dt()``. Checked once per ``dt`` value."""


class UnchargedWarning(UserWarning):
    """A scene with a term that acts on charges (:class:`~physcore.Coulomb`,
    :class:`~physcore.ElectricField`, :class:`~physcore.MagneticField`, their grid forms,
    :class:`~physcore.PointCharges`, a :class:`~physcore.PotentialGrid` with
    ``coupling="charge"``) was stepped while no particle has a charge (no ``"charge"``
    attribute, or all zero), so the term exerts nothing. Set the charges with
    ``scene.set_attribute("charge", q)`` (C). Checked at the first step after a term or an
    attribute changes."""


class UnusedOptionWarning(UserWarning):
    """A :class:`~physcore.Scene` was given an integrator option away from its default that its
    integrator does not use: ``rtol``/``atol`` (``"dopri5"`` only), ``cg_tol``/``cg_max_iter``
    (``"implicit_euler"``), ``xpbd_substeps``/``xpbd_iterations`` (``"xpbd"``),
    ``wh_coordinates``/``wh_corrector`` (``"wisdom_holman"``). The value is kept, and takes
    effect if the scene later switches to that integrator (``scene.integrator = "dopri5"``); until
    then it changes nothing. As SciPy's ``solve_ivp`` warns of options its method ignores."""


class EnergyBooksWarning(RuntimeWarning):
    """A recording (:func:`physcore.render.record`, and so :func:`~physcore.render.gif` and
    ``physcore render``) ended with the scene's energy books off by half the energy in play or
    more (``|scene.energy_drift()| ≥ 0.5``, or not a number): unless something the books do not
    count drives the scene, the run blew up before any value overflowed (a cloth at three
    substeps a frame reached 1e45 J in ten frames, its positions finite). Every ready-made
    scene's books close within 0.5 % at its defaults. Try a smaller ``dt`` or more substeps
    (``scene.suggest_dt()``)."""


class SimulationDiverged(PhyscoreError, RuntimeError):
    """NaN or infinity appeared while stepping, or the flow ran away.

    The scene is rolled back to where the failing ``step(n)`` or ``advance`` call started, so it
    never holds non-finite values. Attributes: ``step`` (the step at which it happened), ``time``
    (s), ``particle`` (index of the first bad particle), ``quantity`` (``"position"`` or
    ``"velocity"``: not finite; ``"cell"``: a grid cell, ``particle`` is its index; ``"error"``:
    ``"dopri5"`` could not meet its tolerances; ``"speed"``: within one ``advance``, or since the last
    step taken, the flow sped up until its step limit fell over a millionfold, ``particle`` the
    fastest; ``"spin"``: a
    grain's spin, rotation or contact spring (:class:`~physcore.Contacts`) is not finite;
    ``"books"``: a dissipated energy overflowed, ``particle`` the fastest; ``"solver"``: the
    rigid bodies' solver, rapier, failed on their state, which a damaged or crafted scene file
    can hold), ``suggested_dt``
    (s) and ``rolled_back_to`` (step count after the rollback).
    """

    def __init__(
        self,
        message: str,
        step: int = -1,
        time: float = float("nan"),
        particle: int = -1,
        quantity: str = "",
        suggested_dt: float = float("nan"),
        rolled_back_to: int = -1,
    ) -> None:
        super().__init__(message)
        self.step = step
        self.time = time
        self.particle = particle
        self.quantity = quantity
        self.suggested_dt = suggested_dt
        self.rolled_back_to = rolled_back_to


class SceneBusyError(PhyscoreError, RuntimeError):
    """A Scene was used from a second thread while another thread steps it (``step``,
    ``advance``, a render). A Scene belongs to one thread at a time: wait for the other call to
    return, or give each thread its own Scene."""
