"""Argument checks shared by the public calls.

Each check names the argument in its message, refuses ``bool``, ``str`` and ``None`` where a
number is meant (``TypeError``), and raises :class:`InvalidInputError` (a ``ValueError``) for a
value out of range or outside what float64 can represent, never ``OverflowError``. Callers run
them before changing any state.
"""
from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import Any

import numpy as np

from ._errors import InvalidInputError, InvalidTypeError, OutOfMemoryError

__all__ = [
    "MIN_NORMAL",
    "MIN_MASS",
    "PARTICLE_BYTES",
    "SPRING_BYTES",
    "real",
    "finite",
    "positive_float",
    "nonneg_float",
    "float_in_range",
    "int_in_range",
    "flag",
    "choice",
    "mass",
    "array",
    "memory_limit",
    "memory",
    "room",
    "human_bytes",
]

#: The smallest normal float64, about 2.2e-308: below it a quantity has no finite reciprocal.
MIN_NORMAL = float(np.finfo(np.float64).tiny)

#: Smallest mass accepted, kg (:data:`MIN_NORMAL`): below it the inverse mass every integrator
#: uses overflows to infinity.
MIN_MASS = MIN_NORMAL

#: Rough upper bounds of what a scene keeps per particle and per spring, bytes (state, inverse
#: masses, integrator stages, neighbour lists; measured on a 90 000-particle cloth at about 1.3 kB
#: per particle with its 6 springs). Used only to refuse requests orders of magnitude too large.
PARTICLE_BYTES = 512
SPRING_BYTES = 256

_REAL = (int, float, np.integer, np.floating)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def text(name: str, value: str) -> str:
    """``value``, a str, refused (naming ``name``) where it cannot be written as UTF-8: a lone
    surrogate (what Python makes of undecodable bytes in argv or a file name) would raise
    UnicodeEncodeError deep in the core or at a file's write, after the work."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as e:
        raise InvalidInputError(f"{name}: not valid text (an unpaired surrogate {value[e.start]!r} at {e.start}), got {value!r:.80}") from None
    return value


def real(name: str, value: Any) -> float:
    """``value`` as a float: a Python or numpy real number (or a 0-d numeric array).

    Raises TypeError for anything else (bool, str and None included) and InvalidInputError for an
    int beyond float64's range; NaN and infinity pass (see :func:`finite`).
    """
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, _REAL):
        raise InvalidTypeError(f"{name}: expected a real number, got {type(value).__name__} {_short(value)}")
    try:
        return float(value)
    except OverflowError:  # an int beyond float64
        raise InvalidInputError(f"{name}: {_short(value)} is outside the float64 range") from None


def finite(name: str, value: Any) -> float:
    """A finite real number (TypeError / InvalidInputError naming ``name``)."""
    v = real(name, value)
    if not math.isfinite(v):
        raise InvalidInputError(f"{name}: must be finite, got {v}")
    return v


def positive_float(name: str, value: Any, *, unit: str = "") -> float:
    """A finite real number > 0."""
    v = real(name, value)
    if not (math.isfinite(v) and v > 0):
        raise InvalidInputError(f"{name}: must be finite and > 0{_unit(unit)}, got {v}")
    return v


def nonneg_float(name: str, value: Any, *, unit: str = "") -> float:
    """A finite real number >= 0."""
    v = real(name, value)
    if not (math.isfinite(v) and v >= 0):
        raise InvalidInputError(f"{name}: must be finite and >= 0{_unit(unit)}, got {v}")
    return v


def float_in_range(
    name: str, value: Any, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False, unit: str = ""
) -> float:
    """A real number in ``[lo, hi]`` (either end open on request); NaN is out of every range."""
    v = real(name, value)
    ok = (lo < v if lo_open else lo <= v) and (v < hi if hi_open else v <= hi)
    if not ok:
        interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise InvalidInputError(f"{name}: must be in {interval}{_unit(unit)}, got {v}")
    return v


def int_in_range(name: str, value: Any, lo: int, hi: int | None = None) -> int:
    """An int (Python or numpy, not bool) with ``lo <= value <= hi``."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InvalidTypeError(f"{name}: expected an int, got {type(value).__name__} {_short(value)}")
    v = int(value)
    if v < lo:
        raise InvalidInputError(f"{name}: must be >= {lo}, got {v}")
    if hi is not None and v > hi:
        raise InvalidInputError(f"{name}: must be <= {hi}, got {_short(v)}")
    return v


def flag(name: str, value: Any) -> bool:
    """True or False (Python or numpy bool); anything else, truthy or not, is a TypeError."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidTypeError(f"{name}: expected True or False, got {type(value).__name__} {_short(value)}")
    return bool(value)


def choice(name: str, value: Any, options: Iterable[str]) -> str:
    """One of the names in ``options`` (TypeError for a non-str, InvalidInputError listing them)."""
    options = tuple(options)
    if not isinstance(value, str):
        raise InvalidTypeError(f"{name}: expected one of {', '.join(map(repr, options))}, got {type(value).__name__}")
    if value not in options:
        raise InvalidInputError(f"{name}: must be one of {', '.join(map(repr, options))}, got {_short(value)}")
    return str(value)


def mass(name: str, value: Any) -> float:
    """A mass, kg: finite and >= :data:`MIN_MASS`, so that its reciprocal is finite too."""
    m = real(name, value)
    if not (math.isfinite(m) and m >= MIN_MASS):
        raise InvalidInputError(f"{name}: {m} kg is not a usable mass (must be finite and >= {MIN_MASS:.3g} kg, so that 1/m is finite)")
    return m


def array(name: str, value: Any, *, sized: bool = True) -> np.ndarray:
    """``np.asarray(value)``, with a ragged nested sequence refused by name (InvalidInputError)
    instead of numpy's unnamed ValueError, and (``sized``) one of more values than memory could
    copy as float64 refused by name (OutOfMemoryError) before any copy. ``sized=False`` where
    the caller checks the shape, or its own need, before it copies."""
    try:
        a = np.asarray(value)
    except (ValueError, TypeError) as e:
        raise InvalidInputError(f"{name}: not a rectangular array of numbers ({' '.join(str(e).split())[:80]})") from None
    # A zero-stride (broadcast) array can stand for more values than memory holds, and every
    # part copies what it is given (as float64 or int64, 8 bytes a value): refused before any
    # copy, which would raise a bare MemoryError or let the OOM killer end the process (a
    # fault audit: Bodies of 10**9 broadcast rows took 24 GB and were killed).
    if sized:
        room(name, a.size * max(8, a.itemsize), f"{a.size:,} values")
    return a


def real_array(name: str, value: Any, *, sized: bool = True) -> np.ndarray:
    """:func:`array` of real numbers: InvalidTypeError naming ``name`` for any other dtype
    (bools, strings, objects, complex)."""
    a = array(name, value, sized=sized)
    if a.dtype.kind not in "iuf" or a.dtype == bool:
        raise InvalidTypeError(f"{name}: expected real numbers, got dtype {a.dtype}")
    return a


def memory_limit() -> int:
    """Largest memory, bytes, that physcore plans for one request before refusing it: half the
    physical memory, or 4 GiB where that cannot be read."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 0
    return total // 2 if total > 0 else 4 << 30


def human_bytes(n: float) -> str:
    """``n`` bytes in decimal units: "512 B", "1.5 GB"; beyond petabytes "3.1e+21 B"."""
    if n >= 1e18:
        return f"{n:.2g} B"
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n} B"  # pragma: no cover


def memory(name: str, nbytes: float, what: str) -> None:
    """Refuse, naming ``name``, a request whose estimated memory ``nbytes`` (bytes, may be inf)
    is above :func:`memory_limit`; ``what`` says what would be allocated."""
    limit = memory_limit()
    try:
        nb = float(nbytes)
    except OverflowError:  # an int beyond float64
        nb = math.inf
    if not nb <= limit:
        need = f"about {human_bytes(nb)}" if math.isfinite(nb) else "more than float64 can count"
        raise InvalidInputError(
            f"{name}: {what} would need {need}, above physcore's limit of {human_bytes(limit)} (half the physical memory)"
        )


def room(name: str, nbytes: int, what: str) -> None:
    """Refuse with :class:`OutOfMemoryError`, naming ``name``, copies of an input that would need
    ``nbytes`` (bytes) above :func:`memory_limit`, before any is attempted: a zero-stride
    (broadcast) array can stand for far more rows than memory holds, and numpy's copy of it
    would raise a bare MemoryError or let the OOM killer end the process."""
    limit = memory_limit()
    if nbytes > limit:
        raise OutOfMemoryError(
            f"{name}: needs about {human_bytes(nbytes)} for {what}, above physcore's limit of "
            f"{human_bytes(limit)} (half the physical memory). Make the input smaller",
            int(nbytes),
        )


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def finite_float(value: object, arg: str, *, minimum: float | None = None, strict: bool = False) -> float:
    v = real(arg, value)  # TypeError for bool/str/None; an int beyond float64 is refused
    if not np.isfinite(v):
        raise InvalidInputError(f"{arg}: must be finite, got {v}")
    if minimum is not None and (v < minimum or (strict and v == minimum)):
        op = ">" if strict else ">="
        raise InvalidInputError(f"{arg}: must be {op} {minimum}, got {v}")
    return v
