"""What physcore runs on: the CPU, the SIMD level of the kernels, threads and build."""
from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from typing import Any

from . import _core
from ._errors import InvalidTypeError

__all__ = ["simd_level", "simd_levels", "set_simd_level", "info"]


def simd_level() -> str:
    """The instruction-set level the hot kernels run at.

    One of ``"scalar"``, ``"avx2"`` (x86-64-v3: AVX2 + FMA), ``"avx512"`` (x86-64-v4) or ``"neon"``
    (aarch64). By default the best level this CPU has; the environment variable
    ``PHYSCORE_SIMD=scalar|avx2|avx512|neon|auto`` (read once, at first use) or
    :func:`set_simd_level` forces one.

    Raises
    ------
    InvalidInputError
        ``PHYSCORE_SIMD`` names an unknown level or one this CPU lacks (scenes then refuse to be
        built with the same error).
    """
    return _core.simd_level()


def simd_levels() -> list[str]:
    """The SIMD levels this CPU supports, slowest first (``"scalar"`` is always there)."""
    return list(_core.simd_levels())


def set_simd_level(level: str | None = None) -> None:
    """Force the SIMD level of the kernels for this process (``None``: back to ``PHYSCORE_SIMD``,
    else the best level).

    Every level computes the same physics; results agree to a few ulp, not bit for bit, so switch
    before a run, not in the middle of one you want to reproduce exactly. Thread count never
    changes results at a given level.

    Raises
    ------
    InvalidTypeError
        ``level`` is neither a string nor ``None``.
    InvalidInputError
        ``level`` is not one of :func:`simd_levels` (unknown, or this CPU lacks it).
    """
    if level is not None and not isinstance(level, str):
        raise InvalidTypeError(f"level: expected a SIMD level name (one of {', '.join(simd_levels())}) or None, got {type(level).__name__}")
    _core.set_simd_level(level)


def info() -> dict[str, Any]:
    """physcore's version, build profile, CPU, SIMD level (active and available) and default threads."""
    try:
        level = _core.simd_level()
    except ValueError as e:  # an invalid PHYSCORE_SIMD: report it rather than fail
        level = f"invalid ({e})"
    return {
        "version": _core.__version__,
        "build": _core.build_profile,
        "cpu": _core.cpu_name(),
        "simd_level": level,
        "simd_levels": simd_levels(),
        "threads": _core.default_threads(),
        "gpu_adapters": gpu_adapters(),
    }


_RUNTIME_DIR_SET = False


def quiet_wayland_probe() -> None:
    """Gives a Linux process without ``XDG_RUNTIME_DIR`` (a container, a CI job, a shell without
    a login session) a private one, 0700 and removed at exit, as a login session would, before
    its first GPU probe or window: Mesa's Vulkan drivers and SDL probe Wayland there, and
    libwayland printed "error: XDG_RUNTIME_DIR is invalid or not set in the environment." at
    each probe, harmless but read as a failure. A set one is left alone; elsewhere it does
    nothing."""
    global _RUNTIME_DIR_SET
    if _RUNTIME_DIR_SET or not sys.platform.startswith("linux") or os.environ.get("XDG_RUNTIME_DIR", "").startswith("/"):
        return
    _RUNTIME_DIR_SET = True
    try:
        path = tempfile.mkdtemp(prefix="physcore-runtime-")
    except OSError:
        return
    atexit.register(shutil.rmtree, path, True)
    os.environ["XDG_RUNTIME_DIR"] = path


def gpu_adapters() -> list[dict[str, Any]]:
    """The GPU adapters this machine has (Vulkan, Metal, DX12; CPU ones such as lavapipe
    included, with ``kind="cpu"``): a list of dicts with ``name``, ``backend``, ``kind``
    (``"discrete"``, ``"integrated"``, ``"virtual"``, ``"cpu"``, ``"other"``), ``driver``,
    ``f64`` (bool: ``precision="f64"`` possible) and the largest ``max_storage_binding`` and
    ``max_buffer`` in bytes. Empty where there is no GPU driver. A scene picks one with
    ``Scene(device="gpu")`` or ``device="gpu:NAME"``."""
    quiet_wayland_probe()
    return list(_core.gpu_adapters())


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return os.cpu_count() or 1
