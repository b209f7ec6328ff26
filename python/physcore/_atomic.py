"""One atomic file writer for every output physcore makes (scenes, GIFs, plots, tables)."""
from __future__ import annotations

import contextlib
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from ._errors import InvalidInputError

__all__ = ["atomic_write", "ctrl_c_held", "TEMP_PREFIX", "TEMP_SUFFIX"]

#: The temporary file is ``.physcore-XXXXXXXX.tmp`` (22 bytes) in the target's directory: short
#: whatever the target's name, so any name the file system allows (up to NAME_MAX, 255 bytes)
#: can be written, and recognisable if a power cut ever leaves one behind.
TEMP_PREFIX = ".physcore-"
TEMP_SUFFIX = ".tmp"


#: What :func:`atomic_write` calls a target it refuses, by its file type.
_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a device"),
          (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))


@contextlib.contextmanager
def ctrl_c_held() -> Iterator[None]:
    """Holds back SIGINT (Ctrl-C) for the block, then hands one that came to the handler it
    held back (Python's raises KeyboardInterrupt): for steps that must not be parted, such as
    a temporary file made and its name kept for the clean-up. In the main thread, where Python
    handles signals; elsewhere it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, _frame: came.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
    if came:
        if callable(old):
            old(signal.SIGINT, None)
        elif old == signal.SIG_DFL:
            raise KeyboardInterrupt


def atomic_write(path: str | os.PathLike, write: Callable[[IO[Any]], None], *, binary: bool = True,
                 arg: str = "path") -> Path:
    """Call ``write(fh)`` on a temporary file in ``path``'s directory, then rename it onto
    ``path`` (atomic on POSIX and Windows), so ``path`` is either the old file or the complete new
    one. On any exception (Ctrl-C included) the temporary file is removed and ``path`` is left
    untouched. The new file gets the mode an ordinary new file would (0666 minus the umask;
    mkstemp makes 0600). Text mode writes UTF-8 with no newline translation.

    The temporary name does not derive from ``path``'s (see :data:`TEMP_PREFIX`), so a target
    name of up to the file system's limit works.

    An existing ``path`` must be a regular file (followed through a symbolic link, which is then
    replaced by the new file): a directory, named pipe, device or socket there raises
    :class:`~physcore.InvalidInputError` naming ``arg``, before anything is written (the rename
    would have replaced a FIFO or, as root, a device node such as /dev/full by a plain file)."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:  # nothing there yet, or a dangling link: the write goes on as before
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        kind = next((name for test, name in _KINDS if test(mode)), "a special file")
        raise InvalidInputError(f"{arg}: {str(path)!r} is {kind}, not a regular file; give the name of a regular file or of a new one")
    kw: dict = {} if binary else {"newline": "", "encoding": "utf-8"}
    tmp = fh = None
    try:
        # Made, named and opened with Ctrl-C held: one landing as mkstemp returned left the
        # temporary file and its descriptor behind (a fault audit).
        with ctrl_c_held():
            try:
                fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX)
            except OSError as e:  # name the target, not the temporary file mkstemp tried
                raise type(e)(e.errno, f"{arg}: cannot write {str(path)!r} ({e.strerror})") from None
            fh = os.fdopen(fd, "wb" if binary else "w", **kw)
        with fh:
            write(fh)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException as e:
        if fh is not None:
            fh.close()
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        # Ctrl-C inside a writer that cleans up on the way out (np.savez's ZipFile: "Can't
        # close the ZIP file while there is an open writing handle") came out as that error,
        # with the interrupt only its context: an `except KeyboardInterrupt` missed it.
        cause = e.__context__
        if not isinstance(e, KeyboardInterrupt) and isinstance(cause, KeyboardInterrupt):
            raise cause from None
        raise
    return path
