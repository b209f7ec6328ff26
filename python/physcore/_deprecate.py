"""Deprecated names, kept for one release (issue 45 step 4, "One vocabulary"; docs/naming.md).

One place for the three kinds of old call that still work, each with a
:class:`DeprecationWarning` naming the new spelling:

* :func:`renamed` — a keyword that was renamed (``dx=`` → ``spacing=``);
* :func:`args` — a function or record that became keyword-only after its natural one or two
  positionals: extra positionals are mapped onto the old parameter order; keywords the function
  no longer has (``integrator=`` of the grid scenes, which did nothing) are accepted and ignored;
* :func:`alias` — an attribute that was renamed (``grid.dx`` → ``grid.spacing``).

This module imports nothing from physcore.
"""
from __future__ import annotations

import functools
import os
import sys
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

__all__ = ["args", "alias", "renamed", "warn"]

F = TypeVar("F", bound=Callable[..., Any])


_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def user_stacklevel() -> int:
    """The ``stacklevel`` at which :func:`warnings.warn`, called by the caller of this function,
    points at the first frame outside the physcore package: the user's line, however deep in
    physcore the warning starts (a fixed level blamed a scene's wrapper, ``_common.py``, which
    Python's default filters then hid: they show a DeprecationWarning only in ``__main__``)."""
    f, level = sys._getframe(1), 1
    while f is not None and os.path.abspath(f.f_code.co_filename).startswith(_PACKAGE):
        f, level = f.f_back, level + 1
    return level


def warn(message: str, stacklevel: int = 3) -> None:
    """A :class:`DeprecationWarning` pointing at the user's line (the first frame outside
    physcore; `stacklevel` is where that search starts being needed, kept for callers)."""
    warnings.warn(message + " (deprecated; the old spelling goes in the next release; see docs/naming.md)",
                  DeprecationWarning, stacklevel=max(stacklevel, user_stacklevel()))


def _rename(where: str, kwargs: dict[str, Any], renames: Mapping[str, str]) -> None:
    for old, new in renames.items():
        if old in kwargs:
            if new in kwargs:
                raise TypeError(f"{where}() got both {old}= and {new}=; {old}= is the old name of {new}=")
            warn(f"{where}: {old}= is now {new}=", stacklevel=4)
            kwargs[new] = kwargs.pop(old)


def args(
    old_order: Sequence[str] = (),
    *,
    keep: int = 0,
    renames: Mapping[str, str] | None = None,
    ignored: Sequence[str] = (),
    name: str | None = None,
    skip_self: bool = False,
) -> Callable[[F], F]:
    """Wraps a function whose signature was tidied:

    * ``old_order``/``keep``: it used to take ``old_order`` positionally and now takes only the
      first ``keep`` of them; positionals beyond ``keep`` become the keywords of ``old_order``
      (with a warning). ``skip_self``: the first positional (``self``) is not counted.
    * ``renames``: old keyword → new keyword (with a warning; both given: TypeError).
    * ``ignored``: keywords that did nothing, accepted and dropped (with a warning).
    """
    renames = dict(renames or {})

    def wrap(fn: F) -> F:
        where = name or getattr(fn, "__qualname__", fn.__name__).replace(".__init__", "")

        @functools.wraps(fn)
        def call(*a: Any, **kw: Any) -> Any:
            lead = 1 if skip_self else 0
            limit = lead + keep
            if old_order and len(a) > limit:
                extra = a[limit:]
                names = list(old_order[keep:keep + len(extra)])
                if len(extra) > len(old_order) - keep:
                    raise TypeError(f"{where}() takes at most {len(old_order)} positional arguments ({len(extra) + keep} given)")
                for n in names:
                    if n in kw:
                        raise TypeError(f"{where}() got multiple values for argument {n!r}")
                warn(f"{where}: pass {', '.join(n + '=' for n in names)} by keyword (it takes {keep or 'no'} positional argument{'s' if keep != 1 else ''})", stacklevel=3)
                kw.update(zip(names, extra, strict=True))
                a = a[:limit]
            if renames:
                _rename(where, kw, renames)
            for n in ignored:
                if n in kw:
                    warn(f"{where}: {n}= does nothing here and is ignored", stacklevel=3)
                    kw.pop(n)
            return fn(*a, **kw)

        return call  # type: ignore[return-value]

    return wrap


def renamed(**renames: str) -> Callable[[F], F]:
    """``@renamed(dx="spacing")``: the old keyword ``dx=`` still works, with a warning."""
    return args(renames=renames)


def alias(new: str, old: str, settable: bool = False, where: str = "") -> property:
    """A property ``old`` reading (and, if ``settable``, writing) attribute ``new``, with a warning."""

    def get(self: Any) -> Any:
        warn(f"{where or type(self).__name__}.{old} is now .{new}")
        return getattr(self, new)

    def put(self: Any, value: Any) -> None:
        warn(f"{where or type(self).__name__}.{old} is now .{new}")
        setattr(self, new, value)

    return property(get, put if settable else None, doc=f"Deprecated alias of :attr:`{new}`.")


def record(positional: Sequence[str] = (), keep: int = 0, renames: Mapping[str, str] | None = None) -> Callable[[type], type]:
    """Class decorator (above ``@dataclass``) for a record whose fields after the first ``keep``
    became keyword-only (``positional``: its fields in their old positional order, new names) and
    whose fields ``renames`` (old -> new) were renamed: the old calls and the old attribute names
    keep working one release, with a DeprecationWarning naming the new spelling."""
    renames = dict(renames or {})

    def wrap(cls: type) -> type:
        init = cls.__init__
        cls.__init__ = args(positional, keep=keep, renames=renames, skip_self=True, name=cls.__name__)(init)  # type: ignore[misc]
        for old, new in renames.items():
            if old not in cls.__dict__:
                setattr(cls, old, alias(new, old, where=cls.__name__))
        return cls

    return wrap
