"""The scene functions' shared argument checks (the shared ones of :mod:`physcore._check`, plus
checks of what a scene derives from its arguments, naming the arguments involved) and
:func:`_stamped`, which wraps each scene function once."""
from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _check, _deprecate
from .._errors import InvalidInputError, InvalidTypeError
from ..scene import Scene

#: The 2-D scenes' backdrop (a render look's ``"backdrop"``): a pale sky fading to grey-blue.
SKY_2D = ((236, 240, 246), (196, 204, 216))


# Argument checks: the shared ones of physcore._check (TypeError for bool/str/None, names the
# argument), plus checks of what the scene derives from them, naming the arguments involved.
def _positive(value: object, arg: str) -> float:
    return _check.positive_float(arg, value)


def _nonneg(value: object, arg: str) -> float:
    return _check.nonneg_float(arg, value)


def _count(value: object, arg: str, minimum: int) -> int:
    return _check.int_in_range(arg, value, minimum)


def _flag(value: object, arg: str) -> bool:
    return _check.flag(arg, value)


def _dim(dim: object) -> int:
    if isinstance(dim, (bool, np.bool_)) or not isinstance(dim, (int, np.integer)):
        raise InvalidTypeError(f"dim: expected 2 or 3, got {type(dim).__name__}")
    if dim not in (2, 3):
        raise InvalidInputError(f"dim: must be 2 or 3, got {dim}")
    return int(dim)


def _optional(value: object, arg: str) -> float | None:
    """None, or a finite number > 0."""
    return None if value is None else _check.positive_float(arg, value)


def _particle_mass(value: float, args: str) -> float:
    """A per-particle mass derived from ``args``; refused by their names if 1/m would overflow."""
    if not (math.isfinite(value) and value >= _check.MIN_MASS):
        raise InvalidInputError(
            f"{args}: give each particle a mass of {value:.3g} kg, outside float64's usable range "
            f"[{_check.MIN_MASS:.3g} kg, max] (its reciprocal must be finite)"
        )
    return value


def _particles(args: str, n_particles: float, n_springs: float = 0) -> None:
    """Refuse, naming ``args``, a scene too large for memory (estimated before allocating)."""
    _check.memory(
        args,
        n_particles * _check.PARTICLE_BYTES + n_springs * _check.SPRING_BYTES,
        f"{_big(n_particles)} particles" + (f" and {_big(n_springs)} springs" if n_springs else ""),
    )


def _cfl_step(wave: Any, arg: str) -> float:
    """The wave's automatic step, or an error naming `arg` if it is not a usable float step."""
    dt = wave.cfl * wave.cfl_limit
    if not (math.isfinite(dt) and dt >= 1e-300):
        raise InvalidInputError(f"{arg}: the CFL step dx/(c√2) = {dt:.3g} s is beyond float64's usable range")
    return dt


def _cells(args: str, cells: float, arrays: int = 6) -> None:
    """Refuse, naming ``args``, a grid too large for memory (`arrays` float64 values per cell:
    state, scratch and a rollback copy)."""
    _check.memory(args, cells * 8 * arrays, f"{_big(cells)} grid cells")


def _big(count: float) -> str:
    if count < 1e15:
        return str(math.ceil(count))  # an estimate may be fractional; a count is whole
    if isinstance(count, int):  # may be beyond float64: give its order of magnitude
        return f"about 1e{int(count.bit_length() * math.log10(2))}"
    return f"{count:.3g}"


def _per(total: float, count: int) -> float:
    """``total / count`` for a count that may be beyond float64 (then 0.0)."""
    try:
        return total / count
    except OverflowError:
        return 0.0


def _set_stable_dt(scene: Scene, factor: float, args: str) -> None:
    """``scene.dt = factor · scene.suggest_dt()``, refused by ``args`` outside float64's normal range."""
    dt = factor * scene.suggest_dt()
    if not (math.isfinite(dt) and dt >= _check.MIN_NORMAL):
        raise InvalidInputError(
            f"{args}: the stable time step for these values, {dt:.3g} s, is outside float64's normal range; "
            "change them or give dt="
        )
    scene.dt = dt


def _finite_books(scene: Scene, args: str) -> Scene:
    """The scene, once its energy books are finite; else refused naming ``args``."""
    e = scene.energy()
    if not math.isfinite(e.total) or not math.isfinite(e.kinetic):
        raise InvalidInputError(
            f"{args}: the scene's energy (kinetic {e.kinetic:.3g} J, total {e.total:.3g} J) is beyond float64"
        )
    return scene


def _stamped(fn: Callable[..., Scene], **deprecated: Any) -> Callable[..., Scene]:
    """`fn` returning scenes that carry its ``render_defaults`` (so ``render.gif(scene)`` shows
    the motion ``physcore render NAME`` shows); same name, docs, signature and attributes.
    ``deprecated``: the old spellings it still takes this release (see :func:`_deprecate.args`)."""
    if deprecated:
        fn = _deprecate.args(name=fn.__name__, **deprecated)(fn)

    @functools.wraps(fn)
    def scene_function(*args: Any, **kwargs: Any) -> Scene:
        scene = fn(*args, **kwargs)
        own = scene.render_defaults or {}  # what the function set from its arguments
        scene.render_defaults = {**fn.render_defaults, **own}  # type: ignore[attr-defined]
        return scene

    # Old keyword names the CLI's --param still takes this release (old -> new; new None: ignored).
    scene_function.deprecated_params = {  # type: ignore[attr-defined]
        **deprecated.get("renames", {}), **dict.fromkeys(deprecated.get("ignored", ()))
    }
    return scene_function
