"""Parameter sweeps and ensembles of scenes, run in parallel on Dask (``dask.distributed``).

One run is one task: ``build(**params)`` makes a :class:`~physcore.Scene`, ``measure(scene)``
runs it and returns a dict of results (or, with ``steps=``, the sweep steps the scenes itself,
many runs a task, those of one structure together as a :class:`~physcore.Batch`, and
``measure`` reads them). :func:`sweep` runs a grid of parameters that way and
returns a pandas DataFrame, one row per run; :func:`ensemble` runs one scene from perturbed
initial conditions and gathers an observable over time (:class:`Ensemble`).

Where the runs go (the ``client`` argument)
-------------------------------------------
``None`` (default)
    A ``distributed.LocalCluster`` of worker *processes*, one per usable core, one thread each,
    started for the call and closed after it. Each run's scene steps on one core thread
    (scenes made with ``threads=None`` inside a run get 1, see ``DEFAULT_THREADS``), so runs
    never oversubscribe the cores: the parallelism is across runs.
a ``distributed.Client``
    Whatever cluster it is connected to (a ``LocalCluster`` you keep between sweeps, a
    scheduler on other machines, ``dask-jobqueue`` on a batch system, ``dask-kubernetes``).
    Every worker needs physcore installed, and the functions you pass must be importable there
    or defined in ``__main__`` / a notebook (cloudpickle then ships them by value).
a str
    A scheduler address such as ``"tcp://10.0.0.5:8786"``: connected to for the call.
``"serial"``
    A plain loop in this process, no Dask needed (debugging, and the reference the parallel
    runs are tested against: they agree bit for bit, since the core is deterministic for any
    thread count and every run's seed derives from its parameters, not from its order).

Dask is an optional dependency: ``pip install "physcore[sweep]"`` (dask[distributed], pandas).
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import numbers
import os
import pickle
import re
import socket
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import _check
from ._atomic import TEMP_PREFIX, TEMP_SUFFIX, atomic_write
from ._errors import InvalidInputError, InvalidTypeError, SceneFileError, SimulationDiverged
from ._system import usable_cpus
from .scene import DEFAULT_THREADS, Scene

__all__ = ["sweep", "ensemble", "Ensemble", "expand", "run_seed", "RESERVED"]

#: Columns every sweep row has besides its parameters and results.
RESERVED = ("run", "seed", "error", "diverged_step", "wall_s", "worker", "run_key")

_INSTALL = 'pip install "physcore[sweep]"'


def _need(module: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"physcore.sweep needs {module.split('.')[0]} for this; install it with: {_INSTALL}") from exc


# ------------------------------------------------------------------------------ parameters
def expand(params: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The runs of a parameter grid: a dict of lists gives their Cartesian product (the first
    key varies slowest), a list of dicts is taken as it is. Keys must be strings that are valid
    Python identifiers (they become keyword arguments of ``build``) and not one of
    :data:`RESERVED`.

    >>> expand({"dt": [0.1, 0.01], "integrator": ["verlet"]})
    [{'dt': 0.1, 'integrator': 'verlet'}, {'dt': 0.01, 'integrator': 'verlet'}]

    Raises ``TypeError`` / ``ValueError`` naming ``params`` for anything else, and for an empty
    grid."""
    if isinstance(params, Mapping):
        if not params:
            raise InvalidInputError("params: no runs (an empty grid)")
        for k, v in params.items():
            _check_name(k)
            if isinstance(v, (str, bytes)) or not isinstance(v, (Sequence, np.ndarray, range)):
                raise InvalidTypeError(f"params[{k!r}]: expected a list of values, got {type(v).__name__}")
            if len(v) == 0:
                raise InvalidInputError(f"params[{k!r}]: the list of values is empty")
        keys = list(params)
        runs = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(list(params[k]) for k in keys))]
    elif isinstance(params, Sequence) and not isinstance(params, (str, bytes)):
        runs = []
        for i, p in enumerate(params):
            if not isinstance(p, Mapping):
                raise InvalidTypeError(f"params[{i}]: expected a dict of parameters, got {type(p).__name__}")
            for k in p:
                _check_name(k)
            runs.append(dict(p))
    else:
        raise InvalidTypeError(f"params: expected a dict of lists or a list of dicts, got {type(params).__name__}")
    if not runs:
        raise InvalidInputError("params: no runs (an empty grid)")
    return runs


def _check_name(k: object) -> None:
    if not isinstance(k, str) or not k.isidentifier():
        raise InvalidInputError(f"params: parameter names must be Python identifiers (build's keyword arguments), got {k!r}")
    if k in RESERVED:
        raise InvalidInputError(f"params: {k!r} is a column every sweep row has; rename the parameter")


def _plain(v: Any) -> Any:
    """A value as JSON writes it faithfully (numpy scalars and arrays to Python)."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return repr(v)  # anything else: its repr, for the key only


def run_key(params: Mapping[str, Any]) -> str:
    """A run's identity: its parameters as canonical JSON (sorted keys). A resumed sweep skips
    the rows of the file whose key it finds again; seeds derive from it (:func:`run_seed`)."""
    return json.dumps(dict(params), sort_keys=True, default=_plain, allow_nan=True)


def run_seed(seed: int, params: Mapping[str, Any]) -> int:
    """The seed of one run: 63 bits of SHA-256 of the sweep's `seed` and the run's key, so it
    does not depend on the run's place in the grid, on the worker, or on what ran before."""
    digest = hashlib.sha256(f"{seed}\0{run_key(params)}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


# ------------------------------------------------------------------------------ one run
def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def _error_text(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 2000 else text[:2000] + " [...]"


def _where(exc: BaseException) -> str:
    """Where `exc` was raised: the last frame of its traceback, as a row's error names it."""
    tb = traceback.extract_tb(exc.__traceback__)
    if not tb:
        return ""
    f = tb[-1]
    # A function shipped to a worker by value (distributed 2026.8 does so for a test's or a
    # script's functions) has a synthetic file name, "<dynamic-code>": its name and line still
    # say where.
    return f" (in {f.name}, line {f.lineno})" if f.filename.startswith("<") else f" (at {Path(f.filename).name}:{f.lineno} in {f.name})"


def _failed(exc: BaseException) -> dict[str, Any]:
    """The row fields of a run that raised `exc` (a divergence keeps its step)."""
    if isinstance(exc, SimulationDiverged):
        return {"results": {}, "error": _error_text(exc), "diverged_step": exc.step}
    return {"results": {}, "error": _error_text(exc) + _where(exc), "diverged_step": None}


def _cells(result: Any, params: Mapping[str, Any]) -> dict[str, Any]:
    """A run's results as row cells; raises for what `measure` must not return."""
    if not isinstance(result, Mapping):
        raise InvalidTypeError(f"measure: must return a dict of results, returned {type(result).__name__}")
    clash = [k for k in result if not isinstance(k, str) or k in RESERVED or k in params]
    if clash:
        raise InvalidInputError(f"measure: result name {clash[0]!r} is a parameter or one of {RESERVED}; rename it")
    # Cells are made here, on the worker: the row then holds only plain values that can travel
    # back (a generator or a lock becomes its repr, as in a serial run).
    return {k: _cell(v) for k, v in result.items()}


def _run_one(build: Callable[..., Any], measure: Callable[[Any], Any], params: dict[str, Any], seed: int | None,
             threads: int | None) -> dict[str, Any]:
    """One sweep task: never raises for the run's own failures (they become the row's error)."""
    t0 = time.perf_counter()
    token = DEFAULT_THREADS.set(threads) if threads is not None else None
    row: dict[str, Any] = {"error": None, "diverged_step": None}
    try:
        kwargs = dict(params)
        if seed is not None:
            kwargs["seed"] = seed
        scene = build(**kwargs)
        row["results"] = _cells(measure(scene), params)
    except Exception as exc:  # noqa: BLE001 - any failure of a user's run is a row, not a failed sweep
        row.update(_failed(exc))
    finally:
        if token is not None:
            DEFAULT_THREADS.reset(token)
    row["wall_s"] = time.perf_counter() - t0
    row["worker"] = _worker_name()
    return row


#: Runs a task holds built at once when the sweep steps them (``steps=``): they are built, stepped
#: and measured a wave at a time, so that memory stays bounded whatever the chunk's size.
_WAVE_RUNS = 64
#: ... and particles (about 0.5 GB of scenes at :data:`physcore._check.PARTICLE_BYTES` each).
_WAVE_PARTICLES = 1 << 20


def _run_chunk(build: Callable[..., Any], measure: Callable[[Any], Any], steps: int | Callable[[Any], Any],
               chunk: list[tuple[dict[str, Any], int | None]], threads: int | None,
               emit: Callable[[int, dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """The runs ``chunk`` (parameters, seed) of a sweep with ``steps=``, as one task: each run's
    scene is built, then the sweep steps it (scenes of the same structure and step count
    together, as one :class:`~physcore.Batch`), then it is measured. Every row is the one
    :func:`_run_one` gives for a `measure` that steps the scene itself first: a run's failure
    (in build, steps, stepping or measure) is its own row's error. `emit(j, row)`, where given,
    gets each row as soon as it is made (the serial sweep's progress); the rows are returned
    in the order of `chunk`."""
    from .batch import Batch, structure

    worker = _worker_name()
    rows: list[dict[str, Any] | None] = [None] * len(chunk)
    token = DEFAULT_THREADS.set(threads) if threads is not None else None
    try:
        start = 0
        while start < len(chunk):
            built: dict[int, Any] = {}  # run -> its scene, built and not failed
            counts: dict[int, int] = {}  # run -> the steps the sweep takes
            wall: dict[int, float] = {}  # run -> seconds spent on it alone so far
            failed: dict[int, dict[str, Any]] = {}
            particles = 0
            j = start
            while j < len(chunk) and j - start < _WAVE_RUNS and particles < _WAVE_PARTICLES:
                params, seed = chunk[j]
                t0 = time.perf_counter()
                try:
                    kwargs = dict(params)
                    if seed is not None:
                        kwargs["seed"] = seed
                    scene = build(**kwargs)
                    n = _check.int_in_range("steps", steps(scene) if callable(steps) else steps, 0, (1 << 63) - 1)
                    built[j], counts[j] = scene, n
                    particles += scene.n_particles if isinstance(scene, Scene) else 0
                except Exception as exc:  # noqa: BLE001 - a run's failure is its row
                    failed[j] = _failed(exc)
                wall[j] = time.perf_counter() - t0
                j += 1
            stop = j
            # Groups that step together: Scenes of one structure and one step count, each scene
            # once, whose step count stays below 2**63 (else Scene.step refuses it, alone).
            groups: dict[Any, list[int]] = {}
            alone: list[int] = []
            seen: set[int] = set()
            for j, scene in built.items():
                n = counts[j]
                if isinstance(scene, Scene) and id(scene) not in seen and n <= (1 << 63) - 1 - scene.step_count:
                    seen.add(id(scene))
                    groups.setdefault((structure(scene), n), []).append(j)
                else:
                    alone.append(j)
            for (_, n), members in groups.items():
                if len(members) == 1:
                    alone.extend(members)
                    continue
                t0 = time.perf_counter()
                diverged: dict[int, SimulationDiverged] = {}
                try:
                    batch = Batch([built[j] for j in members], threads=threads)
                    diverged = batch.diverged
                    batch.step(n)
                except Exception as exc:  # noqa: BLE001 - the batch call itself failed: every run left in it
                    for k, j in enumerate(members):
                        if k not in diverged:
                            failed[j] = _failed(exc)
                for k, exc in diverged.items():
                    failed[members[k]] = _failed(exc)
                share = (time.perf_counter() - t0) / len(members)
                for j in members:
                    wall[j] += share
            for j in sorted(alone):
                t0 = time.perf_counter()
                try:
                    built[j].step(counts[j])
                except Exception as exc:  # noqa: BLE001 - a run's failure is its row
                    failed[j] = _failed(exc)
                wall[j] += time.perf_counter() - t0
            for j in range(start, stop):
                t0 = time.perf_counter()
                row: dict[str, Any] = {"error": None, "diverged_step": None}
                if j in failed:
                    row.update(failed[j])
                else:
                    try:
                        row["results"] = _cells(measure(built[j]), chunk[j][0])
                    except Exception as exc:  # noqa: BLE001 - a run's failure is its row
                        row.update(_failed(exc))
                    if emit is None:  # on a worker: a result that cannot travel fails its run alone, not the chunk
                        try:
                            pickle.dumps(row["results"])
                        except Exception as exc:  # noqa: BLE001 - becomes that run's row
                            row.update(results={}, error=f"{_error_text(exc)} (its results could not be serialized to come back from the worker)")
                built.pop(j, None)
                row["wall_s"] = wall[j] + (time.perf_counter() - t0)
                row["worker"] = worker
                rows[j] = row
                if emit is not None:
                    emit(j, dict(row))
            start = stop
    finally:
        if token is not None:
            DEFAULT_THREADS.reset(token)
    return rows  # type: ignore[return-value]


# ------------------------------------------------------------------------------ the engine
def _check_client(client: Any) -> Any:
    if client is None or client == "serial":
        return client
    if isinstance(client, str):
        if client == "local":  # the default, by name
            return None
        # A scheme's address (tcp://host:port, tls://, ucx://, inproc://..., IPv6 in brackets)
        # or a bare host:port; anything else is no scheduler's.
        if not re.fullmatch(r"[a-z][a-z0-9+.-]*://\S+|[^\s/]+:\d+", client):
            raise InvalidInputError(
                f"client: {client!r} is not a scheduler address (tcp://host:port); None or 'local' for a local "
                "cluster, 'serial' for this process"
            )
        return client
    if type(client).__name__ == "Client" and hasattr(client, "submit"):
        return client
    raise InvalidTypeError(f"client: expected None, 'serial', a scheduler address or a distributed.Client, got {type(client).__name__}")


def _importing_main() -> bool:
    """Whether a caller on the stack is a script's top level run as ``__mp_main__`` (a process
    multiprocessing started, importing the parent's main script)."""
    f = sys._getframe(1)
    while f is not None:
        if f.f_globals.get("__name__") == "__mp_main__" and f.f_code.co_name == "<module>":
            return True
        f = f.f_back
    return False


class _Cluster:
    """The client a call runs on: the caller's, one connected to an address, or a LocalCluster
    made (and closed) here."""

    def __init__(self, client: Any, workers: int | None) -> None:
        self.own: list[Any] = []
        self.started: int | None = None  # workers of a LocalCluster started here
        if client is None or isinstance(client, str):
            distributed = _need("distributed")
            if client is None:
                import logging

                if _importing_main():
                    # A worker process Dask started runs the script's top level again as
                    # __mp_main__: without the guard it would start a cluster of its own, and
                    # each failed worker would print a page of Dask's tracebacks.
                    raise RuntimeError(
                        "physcore.sweep started a local cluster while a worker process was importing your "
                        'script: put the sweep under `if __name__ == "__main__":` (Dask starts its workers '
                        "as new processes, which run the script's top level again)"
                    )

                n = workers if workers is not None else usable_cpus()
                try:
                    cluster = distributed.LocalCluster(
                        n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                        silence_logs=logging.ERROR,
                    )
                except RuntimeError as e:
                    raise RuntimeError(
                        f"physcore.sweep: the local cluster's workers failed to start ({e}); in a script, the "
                        'sweep must run under `if __name__ == "__main__":` (see the first traceback above)'
                    ) from e
                self.own.append(cluster)
                self.started = n
                client = distributed.Client(cluster)
            else:
                client = distributed.Client(client)
            self.own.insert(0, client)
        self.client = client

    def slots(self) -> int:
        """Tasks the cluster runs side by side: the workers started here (one thread each), else
        its workers' threads now (at least 1)."""
        if self.started is not None:
            return self.started
        try:
            return max(1, sum(self.client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a client that cannot say: one
            return 1

    def close(self) -> None:
        for c in self.own:
            c.close()


def _map(fn: Callable[..., Any], args: list[tuple[Any, ...]] | Callable[[int], list[tuple[Any, ...]]], client: Any,
         workers: int | None, on_result: Callable[[int, Any], None], shared: tuple[Any, ...] = ()) -> None:
    """Runs ``fn(*shared, *args[i])`` for every i, on `client`, calling ``on_result(i, value)``
    as each finishes (in completion order). `args` may be a function of the number of tasks the
    cluster runs side by side (1 in this process) that returns the list. `shared` is sent to the
    cluster once. A task whose worker dies (or whose result cannot be sent back) gives
    ``on_result(i, exc)`` with the exception. Ctrl-C cancels what is still queued."""
    if client == "serial":
        for i, a in enumerate(args(1) if callable(args) else args):
            on_result(i, fn(*shared, *a))
        return
    distributed = _need("distributed")
    cl = _Cluster(client, workers)
    futures: list[Any] = []
    try:
        c = cl.client
        if callable(args):
            args = args(cl.slots())
        shared_f = c.scatter(list(shared), broadcast=False, hash=False) if shared else []
        futures = [c.submit(fn, *shared_f, *a, pure=False) for a in args]
        index = {f.key: i for i, f in enumerate(futures)}
        # Results are fetched a batch at a time (whatever finished since the last batch): one
        # gather per batch, not one per task as as_completed(with_results=True) does.
        for batch in distributed.as_completed(futures).batches():
            done = [f for f in batch if f.status == "finished"]
            for f, value in zip(done, _gather(c, done), strict=True):
                on_result(index[f.key], value)
            for f in batch:
                if f.status != "finished":
                    exc = f.exception() if f.status == "error" else RuntimeError(f"the task was {f.status}")
                    on_result(index[f.key], exc)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            cl.client.cancel(pending)
        cl.close()


def _gather(client: Any, done: list[Any]) -> list[Any]:
    """The results of finished futures; one that cannot come back (it does not pickle) is its
    exception instead, so that it fails alone rather than the whole batch with it."""
    if not done:
        return []
    try:
        return list(client.gather(done))
    except Exception:  # noqa: BLE001 - find which ones failed, one at a time
        out: list[Any] = []
        for f in done:
            try:
                out.append(client.gather(f))
            except Exception as exc:  # noqa: BLE001 - becomes that run's row
                out.append(exc)
        return out


# ------------------------------------------------------------------------------ results file
def _cell(v: Any) -> Any:
    """A result as a CSV cell: numbers, strings, bools and None as they are, anything else as
    its JSON text."""
    if v is None or isinstance(v, (str, bool, numbers.Number)):
        return v.item() if isinstance(v, np.generic) else v
    if isinstance(v, np.generic):
        return v.item()
    try:
        return json.dumps(np.asarray(v).tolist())
    except (TypeError, ValueError):
        return repr(v)


def _parse(text: str) -> Any:
    """A CSV cell back as the value pandas wrote: None, bool, int, float or str."""
    if text == "":
        return None
    if text in ("True", "False"):
        return text == "True"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _shown(names: list[str], most: int = 12) -> str:
    """Column names for a message, the first `most` of them (a damaged header may hold thousands)."""
    text = ", ".join(repr(n[:40]) for n in names[:most])
    return text + (f" and {len(names) - most} more" if len(names) > most else "")


class _ResultsFile:
    """Results streamed to a CSV file as runs finish, rewritten atomically (temporary file, then
    rename), so the file is always a complete table. Rewrites are spaced so that they cost at
    most ~10 % of the sweep's time on long sweeps; the last one happens however the sweep ends."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.last = -math.inf
        self.cost = 0.0
        self.dirty = False
        self.failed: OSError | None = None

    def load(self) -> Any:
        if self.path is None or not self.path.exists():
            return None
        # The csv module and Python's own int()/float() rather than a CSV parser's fast float
        # path: float() is correctly rounded, so every float comes back bit for bit.
        from ._scenefile import _open_regular

        try:
            try:  # a FIFO would block the read forever, a device could be endless
                fh, _ = _open_regular(self.path, str(self.path))
            except SceneFileError:
                raise InvalidInputError(f"out: {str(self.path)!r} is not a regular file (a directory, pipe or device); give a .csv file or a new name") from None
            with fh:
                data = fh.read().decode("utf-8")
            records = list(csv.DictReader(io.StringIO(data, newline="")))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InvalidInputError(f"out: {str(self.path)!r} is not a results file of a sweep ({type(exc).__name__}: {exc})") from None
        if records and not data.endswith("\n"):
            # Every row the sweep writes ends with a newline: a file cut short (a crash of the
            # machine, a copy interrupted) ends inside its last row, which is dropped and run again.
            records.pop()
        if not records or "run_key" not in records[0] or any(None in r for r in records):
            raise InvalidInputError(f"out: {str(self.path)!r} has no run_key column or ragged rows (not written by physcore.sweep); give another path")
        for n, r in enumerate(records):
            if any(v is None for v in r.values()):
                missing = [k for k, v in r.items() if v is None]
                raise InvalidInputError(
                    f"out: {str(self.path)!r}: data row {n + 1} of {len(records)} (run_key {(r.get('run_key') or '?')[:80]!r}) lacks "
                    f"{', '.join(missing)}: the file is damaged; repair or remove that row, or give another path"
                )
        text = ("run_key", "error", "worker")
        return [{k: (v or None if k in text else _parse(v)) for k, v in r.items()} for r in records]

    def check_writable(self) -> None:
        """Create and remove a file in the directory of `path`, as every write will: an
        unwritable directory then fails before the first run, not after it. Raises OSError
        naming ``out``."""
        if self.path is None:
            return
        directory = self.path.parent if str(self.path.parent) else Path(".")
        try:
            fd, probe = tempfile.mkstemp(dir=directory, prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX)
        except OSError as exc:
            raise type(exc)(exc.errno, f"out: cannot create files in {str(directory)!r} ({exc.strerror}); give a writable directory") from None
        os.close(fd)
        os.unlink(probe)

    def write(self, frame: Callable[[], Any], force: bool = False) -> None:
        if self.path is None:
            return
        self.dirty = True
        now = time.perf_counter()
        if not force and now - self.last < 10.0 * self.cost:
            return
        df = frame()
        atomic_write(self.path, lambda fh: df.to_csv(fh, index=False), binary=False, arg="out")
        self.last = time.perf_counter()
        self.cost = self.last - now
        self.dirty = False
        self.failed = None

    def write_soon(self, frame: Callable[[], Any]) -> None:
        """:meth:`write`, but a failure (a full disk) does not stop the sweep: the file keeps
        its last whole table, the rows stay in memory, and the next write (the next row's, the
        last one) tries again."""
        try:
            self.write(frame)
        except OSError as exc:
            self.failed = exc


def _unwritten(exc: OSError, path: Path | None, df: Any, n_runs: int) -> OSError:
    """The OSError :func:`sweep` raises when its last write of `out` fails (a full disk): it
    names the file, and its ``results`` attribute holds every row computed (nothing is lost)."""
    err = type(exc)(
        exc.errno,
        f"out: could not write {str(path)!r} ({exc.strerror or exc}); every run finished and its row is kept: this "
        f"exception's .results holds the {n_runs} rows (DataFrame), and the file keeps its last whole table; free "
        f"space and run the sweep again with the same out= (runs already in the file are not run again)",
    )
    err.results = df  # type: ignore[attr-defined]
    return err


# ------------------------------------------------------------------------------ sweep
def sweep(
    build: Callable[..., Any],
    params: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]],
    *,
    measure: Callable[[Any], Mapping[str, Any]],
    steps: int | Callable[[Any], int] | None = None,
    client: Any = None,
    workers: int | None = None,
    out: str | os.PathLike | None = None,
    seed: int | None = None,
    threads: int | None = 1,
    retry_errors: bool = False,
    progress: bool = True,
) -> Any:
    """Run ``measure(build(**p))`` for every parameter set ``p`` of a grid, in parallel on Dask,
    and return the results as a pandas DataFrame.

    Parameters
    ----------
    build : callable
        ``build(**p)`` returns a :class:`~physcore.Scene` (or anything `measure` accepts). With
        `seed`, it is also given ``seed=`` (an int, see :func:`run_seed`).
    params : dict of lists, or list of dicts
        The runs (see :func:`expand`): ``{"dt": [1e-3, 1e-4], "integrator": ["verlet", "rk4"]}``
        is four runs.
    measure : callable
        ``measure(scene)`` runs the scene and returns a dict of results (names must not repeat
        a parameter or a :data:`RESERVED` column). Numbers, strings and bools are stored as
        they are; other values (arrays) go into the file as JSON text, and what has none (a
        generator, a lock) as its repr, made where the run ran, as in a serial run. A result
        that still cannot come back from its worker is that run's ``error``; the other rows
        are kept.
    steps : int or callable, optional
        Steps the sweep itself takes on each run's scene, of the scene's own ``dt``, between
        ``build`` and ``measure`` (which then only reads the stepped scene): an int >= 0, or
        ``steps(scene)`` -> int for a count that depends on the run (a fixed duration over a
        ``dt`` sweep: ``lambda s: round(2.0 / s.dt)``). Without it (default), ``measure`` steps
        the scene and every run is its own task. With it, the runs go in chunks, about four
        chunks a worker on Dask (one task each) and one in this process with
        ``client="serial"``; in a chunk, the scenes of the same structure (dimension, particle
        count, parts) and step count are stepped together as one :class:`~physcore.Batch` (one
        call into the core, on `threads` threads), so small runs stop paying a task and a call
        each. Every row is the one a `measure` that calls ``scene.step(n)`` first gives, bit for
        bit in every result, error and ``diverged_step``: a member that diverges fails its own
        run, the others go on. Anything `build` returns that is not a Scene (it needs a
        ``step(n)`` method) is stepped alone, in the same task. A chunk is built, stepped and
        measured in waves of at most 64 runs (and about 10^6 particles), which bounds the
        memory it holds; on Dask a chunk's rows come back when the whole chunk is done (the
        progress bar moves a chunk at a time, and Ctrl-C loses the chunks under way), in this
        process a row at a time. `build` and `measure` must not depend on running one after
        the other for the same run (a wave builds all its runs first), as on Dask they must
        not depend on other runs.
    client : None, "local", "serial", str or distributed.Client
        Where the runs go (module docstring): by default (or ``"local"``) a LocalCluster of
        `workers` processes; a str other than those is a scheduler's address
        (``tcp://host:port``). In a script, call the sweep under ``if __name__ == "__main__":``
        (the local cluster's workers run the script's top level again).
    workers : int, optional
        Worker processes of the default LocalCluster, >= 1; default one per usable core.
    out : str or os.PathLike, optional
        A ``.csv`` file the rows stream to as runs finish (rewritten atomically, so it is always
        a whole table). If it exists, the sweep *resumes*: runs whose key (:func:`run_key`) is
        in it are not run again and their rows are returned from the file (with
        `retry_errors`, failed ones are run again). A file cut short inside its last row (a
        crash) loses that row, whose run is run again. Its directory is checked writable
        before the first run. If a write fails on the way (a full disk), the runs go on, the
        file keeps its last whole table and the next write tries again.
    seed : int, optional
        Base seed: every run gets ``seed=run_seed(seed, p)`` as a keyword of `build`, the same
        on any worker and in any order, so every run is reproducible alone.
    threads : int or None, default 1
        Core threads of each run's scenes made with ``threads=None`` (a scene given its own
        count keeps it). 1 suits one worker thread per core; None: all cores per run.
    retry_errors : bool, default False
        Resuming, run again the rows of `out` that have an error.
    progress : bool, default True
        A tqdm bar on stderr: runs done, rate and ETA.

    Returns
    -------
    pandas.DataFrame
        One row per run in the order of `params`: ``run`` (its index), the parameters,
        ``seed`` (None without `seed`), the results (NaN where a run failed), ``error`` (None
        or ``"Type: message"``), ``diverged_step`` (the step of a
        :class:`~physcore.SimulationDiverged`, else None), ``wall_s`` (build + measure, s;
        with `steps`, build + its share of its batch's step, that call's wall time over the
        batch's runs, + measure, so that the rows of a chunk add up to the chunk's time),
        ``worker`` (its address) and ``run_key``.

    Raises
    ------
    TypeError, ValueError
        A bad argument, naming it, before anything runs (a run's own failure is its row's
        ``error``, never an exception here; so is a count a `steps` callable returns that is
        not an int >= 0); an `out` file that is not a sweep's or has a damaged row before its
        last (naming the file and the row). Both are :class:`~physcore.PhyscoreError`.
    ImportError
        Dask or pandas is not installed (``pip install "physcore[sweep]"``).
    OSError
        `out`'s directory is not writable (before any run); or its last write failed (a full
        disk): the exception names the file and its ``results`` attribute holds every row.
    KeyboardInterrupt
        Ctrl-C: queued runs are cancelled, and the rows finished so far are in `out`.

    Examples
    --------
    A ball dropped for 1 s with two steps and two integrators (``client="serial"`` runs them
    in this process; leave it out to run them on a local cluster):

    >>> import physcore as pc
    >>> def build(dt, integrator):
    ...     scene = pc.Scene(dim=2, dt=dt, integrator=integrator)
    ...     scene.add_particles([[0.0, 0.0]])
    ...     scene.add(pc.Gravity([0.0, -9.81]))
    ...     return scene
    >>> def measure(scene):
    ...     scene.step(round(1.0 / scene.dt))
    ...     return {"y": float(scene.positions[0, 1])}
    >>> df = pc.sweep(build, {"dt": [0.1, 0.01], "integrator": ["euler", "verlet"]},
    ...               measure=measure, client="serial", progress=False)
    >>> bool(df["error"].isna().all())  # no run failed
    True
    >>> (df["y"] + 9.81 / 2).abs().round(5).tolist()  # against y = -g t²/2: Euler 1st order, Verlet exact
    [0.4905, 0.0, 0.04905, 0.0]

    The same runs with the sweep stepping them (``steps``: here a duration of 1 s in each run's
    own dt), the runs of one dt stepped together as a Batch; `measure` only reads:

    >>> df2 = pc.sweep(build, {"dt": [0.1, 0.01], "integrator": ["euler", "verlet"]},
    ...                measure=lambda s: {"y": float(s.positions[0, 1])}, steps=lambda s: round(1.0 / s.dt),
    ...                client="serial", progress=False)
    >>> df2["y"].tolist() == df["y"].tolist()  # bit for bit
    True

    Why a step count and not a `measure` that is batched as it is: `measure` is any code, and
    may step, read, step again; the sweep can step runs together only where it does the
    stepping itself. Why not ``duration`` (seconds): :meth:`Scene.advance` picks its own
    substeps and changes ``dt`` per scene, which a batch does not; a duration in the run's own
    ``dt`` is the callable above.
    """
    if not callable(build):
        raise InvalidTypeError(f"build: expected a callable returning a Scene, got {type(build).__name__}")
    if not callable(measure):
        raise InvalidTypeError(f"measure: expected a callable (scene -> dict of results), got {type(measure).__name__}")
    runs = expand(params)
    client = _check_client(client)
    if workers is not None:
        workers = _check.int_in_range("workers", workers, 1, 4096)
    if seed is not None:
        seed = _check.int_in_range("seed", seed, 0)
        if any("seed" in p for p in runs):
            raise InvalidInputError("seed: the parameters already have a 'seed'; give one or the other")
    if threads is not None:
        threads = _check.int_in_range("threads", threads, 1, 65535)
    retry_errors = _check.flag("retry_errors", retry_errors)
    progress = _check.flag("progress", progress)
    if steps is not None and not callable(steps):
        steps = _check.int_in_range("steps", steps, 0, (1 << 63) - 1)
    path: Path | None = None
    if out is not None:
        from ._scenefile import check_path

        path = check_path(out, "out")
        if path.suffix != ".csv":
            raise InvalidInputError(f"out: must end in .csv, got {str(path)!r}")
    pd = _need("pandas")

    file = _ResultsFile(path)
    file.check_writable()
    keys = [run_key(p) for p in runs]
    if len(set(keys)) != len(keys):
        dup = next(k for k in keys if keys.count(k) > 1)
        raise InvalidInputError(f"params: the run {dup} appears twice")
    seeds = [None if seed is None else run_seed(seed, p) for p in runs]
    rows: dict[int, dict[str, Any]] = {}
    old = file.load()
    kept_old: list[dict[str, Any]] = []  # rows of the file that are not runs of this grid
    if old is not None:
        where = {k: i for i, k in enumerate(keys)}
        columns = old[0].keys()  # every record has the header's columns (load refuses ragged rows)
        for rec in old:
            i = where.get(rec["run_key"])
            # A run found again must find its parameters as columns: else the header was edited
            # (a parameter renamed) and resuming would mix rows of two layouts.
            missing = [] if i is None else [k for k in runs[i] if k not in columns]
            if missing:
                raise InvalidInputError(
                    f"out: {str(path)!r}: its columns differ from the sweep's parameters: no column {', '.join(map(repr, missing))} "
                    f"(the file has {_shown(list(columns))}); was its header edited? Repair it, or give another path"
                )
            failed = rec.get("error") is not None
            if i is None:
                kept_old.append(rec)
            elif not (retry_errors and failed):
                rec["run"] = i
                rows[i] = rec
    todo = [i for i in range(len(runs)) if i not in rows]

    def frame() -> Any:
        recs = [rows[i] for i in sorted(rows)] + kept_old
        df = pd.DataFrame.from_records(recs)
        cols = ["run", *dict.fromkeys(k for p in runs for k in p), "seed"]
        rest = [c for c in df.columns if c not in cols and c not in RESERVED]
        order = [c for c in cols if c in df.columns] + rest + [c for c in RESERVED[2:] if c in df.columns]
        return df[order]

    def on_result(j: int, value: Any) -> None:
        i = todo[j]
        if isinstance(value, BaseException):  # the worker died, or the result could not come back
            value = {"results": {}, "error": _error_text(value), "diverged_step": None, "wall_s": math.nan, "worker": None}
        res = value.pop("results")
        rows[i] = {"run": i, **runs[i], "seed": seeds[i], **res, **value, "run_key": keys[i]}
        bar.update(1)
        file.write_soon(frame)

    from tqdm.auto import tqdm

    bar = tqdm(total=len(runs), initial=len(runs) - len(todo), desc="sweep", unit="run", disable=not progress, leave=False)
    finished = False
    try:
        if todo and steps is None:
            _map(_run_one, [(runs[i], seeds[i], threads) for i in todo], client, workers, on_result, shared=(build, measure))
        elif todo and client == "serial":
            # One task holding every run (built, stepped and measured a wave at a time), its
            # rows reported as they are made: the bar and `out` move run by run.
            _run_chunk(build, measure, steps, [(runs[i], seeds[i]) for i in todo], threads, emit=on_result)
        elif todo:
            chunks: list[range] = []

            def plan(slots: int) -> list[tuple[Any, ...]]:
                # About four chunks a worker: few enough that a run stops paying a task, enough
                # that the workers stay busy to the end when chunks take unequal times.
                size = max(1, math.ceil(len(todo) / (4 * slots)))
                chunks.extend(range(a, min(a + size, len(todo))) for a in range(0, len(todo), size))
                return [([(runs[todo[j]], seeds[todo[j]]) for j in c], threads) for c in chunks]

            def on_chunk(c: int, value: Any) -> None:
                for k, j in enumerate(chunks[c]):  # a chunk whose task failed (its worker died): each of its runs
                    on_result(j, value if isinstance(value, BaseException) else value[k])

            _map(_run_chunk, plan, client, workers, on_chunk, shared=(build, measure, steps))
        finished = True
    finally:
        bar.close()
        if rows and (file.dirty or (path is not None and not path.exists())):
            try:
                file.write(frame, force=True)
            except OSError as exc:
                if finished:  # else the interruption propagates; the file keeps its last whole table
                    raise _unwritten(exc, path, frame(), len(runs)) from exc
    df = frame()
    df = df[df["run"].isin(range(len(runs)))].reset_index(drop=True) if kept_old else df
    errors = df["error"] if "error" in df else None
    if errors is not None and len(df) and errors.notna().all():
        # Every run failed (a parameter name build() does not take, a typo in measure): say it
        # here, not only in a column the caller may not read.
        import warnings

        warnings.warn(f"physcore.sweep: all {len(df)} runs failed; the first: {errors.iloc[0]}", RuntimeWarning, stacklevel=2)
    return df


# ------------------------------------------------------------------------------ ensembles
@dataclass(frozen=True)
class Ensemble:
    """What :func:`ensemble` returns.

    Attributes
    ----------
    times : (T,) float64 ndarray
        Sample times, s (the scene's time at each sample; the first is its time at the start).
    values : (M, T, ...) float64 ndarray
        The observable of each member that finished, at each sample.
    members : (M,) int ndarray
        Which members those are (0 is the unperturbed scene).
    failed : dict of int to str
        Members that raised (a :class:`~physcore.SimulationDiverged`, say), with the error.
    """

    times: np.ndarray
    values: np.ndarray
    members: np.ndarray
    failed: dict[int, str]

    def mean(self) -> np.ndarray:
        """The ensemble mean of the observable, shape (T, ...)."""
        return self.values.mean(axis=0)

    def spread(self) -> np.ndarray:
        """The RMS distance of the members from the ensemble mean at each sample, shape (T,):
        ``sqrt(mean over members of |v_m(t) - mean(t)|^2)``, the norm over the observable's own
        axes. For a chaotic system it grows as exp(λ t) until it saturates (λ: the largest
        Lyapunov exponent)."""
        d = self.values - self.mean()[None]
        return np.sqrt(np.mean(np.sum(d.reshape(d.shape[0], d.shape[1], -1) ** 2, axis=2), axis=0))

    def distance(self) -> np.ndarray:
        """Each member's distance from the unperturbed member 0, shape (M, T) (needs member 0)."""
        if not len(self.members) or self.members[0] != 0:
            raise InvalidInputError("member 0 (the unperturbed run) failed; distance() needs it")
        d = self.values - self.values[0][None]
        return np.sqrt(np.sum(d.reshape(d.shape[0], d.shape[1], -1) ** 2, axis=2))


def _positions(scene: Any) -> np.ndarray:
    return np.asarray(scene.positions, dtype=np.float64)


def _perturb_positions(scene: Any, rng: np.random.Generator, scale: float) -> None:
    x = np.asarray(scene.positions, dtype=np.float64)
    free = ~np.asarray(scene.pinned, dtype=bool)
    x[free] += scale * rng.standard_normal((int(free.sum()), x.shape[1]))
    scene.positions = x


def _run_member(data: bytes, member: int, seed: int, perturb: Any, observe: Callable[[Any], Any] | None,
                samples: int, steps: int, threads: int | None) -> tuple[np.ndarray, np.ndarray] | str:
    """One ensemble member: unpickle the scene, perturb it (member 0 stays as it is), sample
    the observable `samples` times, `steps` steps apart. An error comes back as its text."""
    token = DEFAULT_THREADS.set(threads) if threads is not None else None
    try:
        scene = pickle.loads(data)
        if member:
            rng = np.random.default_rng([seed, member])
            if callable(perturb):
                perturb(scene, rng)
            else:
                _perturb_positions(scene, rng, perturb)
        look = observe or _positions
        times, values = [], []
        for k in range(samples):
            if k:
                scene.step(steps)
            times.append(scene.time)
            values.append(np.array(look(scene), dtype=np.float64))
            if not np.isfinite(values[-1]).all():
                raise InvalidInputError(f"observe: returned a non-finite value at sample {k}")
        return np.asarray(times), np.stack(values)
    except Exception as exc:  # noqa: BLE001 - a member's failure is reported, not raised
        return _error_text(exc)
    finally:
        if token is not None:
            DEFAULT_THREADS.reset(token)


def _run_members(data: bytes, chunk: list[int], seed: int, perturb: Any, observe: Callable[[Any], Any] | None,
                 samples: int, steps: int, threads: int | None) -> list[tuple[np.ndarray, np.ndarray] | str]:
    """Ensemble members ``chunk`` as one task, stepped together as a :class:`~physcore.Batch`
    (one call into the core per sample, members side by side on ``threads`` threads, each
    member's own stepping single-threaded): every member's values are the bits
    :func:`_run_member` gives it alone. Members a ``perturb`` made of another structure than
    the first run one by one instead. A member's error comes back as its text."""
    from .batch import Batch

    out: dict[int, Any] = {}
    token = DEFAULT_THREADS.set(1)
    try:
        scenes: dict[int, Scene] = {}
        for m in chunk:
            try:
                scene = pickle.loads(data)
                if m:
                    rng = np.random.default_rng([seed, m])
                    if callable(perturb):
                        perturb(scene, rng)
                    else:
                        _perturb_positions(scene, rng, perturb)
                scenes[m] = scene
            except Exception as exc:  # noqa: BLE001 - a member's failure is reported, not raised
                out[m] = _error_text(exc)
        live = list(scenes)
        try:
            batch = Batch([scenes[m] for m in live], threads=threads) if live else None
        except (InvalidInputError, InvalidTypeError):
            batch = None  # members of different structures: one at a time
        if batch is None and live:
            for m in live:
                out[m] = _run_member(data, m, seed, perturb, observe, samples, steps, threads)
            return [out[m] for m in chunk]
        look = observe or _positions
        times: dict[int, list[float]] = {m: [] for m in live}
        values: dict[int, list[np.ndarray]] = {m: [] for m in live}
        for k in range(samples):
            if k and batch is not None:
                batch.step(steps)
                for i, e in batch.diverged.items():
                    out.setdefault(live[i], _error_text(e))
            for m in live:
                if m in out:
                    continue
                try:
                    v = np.array(look(scenes[m]), dtype=np.float64)
                    if not np.isfinite(v).all():
                        raise InvalidInputError(f"observe: returned a non-finite value at sample {k}")
                except Exception as exc:  # noqa: BLE001 - a member's failure is reported, not raised
                    out[m] = _error_text(exc)
                    continue
                times[m].append(scenes[m].time)
                values[m].append(v)
        for m in live:
            if m not in out:
                out[m] = (np.asarray(times[m]), np.stack(values[m]))
        return [out[m] for m in chunk]
    finally:
        DEFAULT_THREADS.reset(token)


def ensemble(
    scene: Scene,
    members: int,
    *,
    samples: int,
    steps_per_sample: int,
    perturb: float | Callable[[Any, np.random.Generator], None] = 1e-9,
    observe: Callable[[Any], Any] | None = None,
    seed: int = 0,
    client: Any = None,
    workers: int | None = None,
    threads: int | None = 1,
    progress: bool = True,
) -> Ensemble:
    """Run `members` copies of `scene` from perturbed initial conditions and gather an
    observable over time: the spread of an ensemble of chaotic runs, the sensitivity of a
    measurement to its initial state.

    Member 0 is the scene as given; member m >= 1 has each free particle's position moved by
    ``perturb`` times a standard normal vector drawn from ``numpy.random.default_rng([seed,
    m])`` (or ``perturb(scene, rng)`` does it, for any other perturbation). Each member
    steps ``steps_per_sample`` steps of ``scene.dt`` between samples; the scene itself is not
    changed (members run on copies, pickled through the scene file format).

    Parameters
    ----------
    scene : physcore.Scene
        The starting state.
    members : int
        Ensemble size, >= 1 (member 0 unperturbed).
    samples : int
        Samples of the observable, >= 1 (the first at the start).
    steps_per_sample : int
        Steps between samples, >= 1.
    perturb : float or callable, default 1e-9
        Position perturbation scale, m (>= 0), or ``perturb(scene, rng)``, which changes the
        copy in place.
    observe : callable, optional
        ``observe(scene)`` -> array-like of floats, the same shape at every sample. Default:
        the positions, (N, dim).
    seed : int, default 0
        Seed of the perturbations (>= 0).
    client, workers, threads, progress
        As for :func:`sweep` (``client="serial"`` runs the members in this process).

    Returns
    -------
    Ensemble
        Times, values (M, T, ...) and the failures; :meth:`Ensemble.spread` is the RMS spread.

    Raises
    ------
    TypeError, ValueError
        A bad argument, naming it, before anything runs.
    ImportError
        Dask is not installed and `client` is not ``"serial"``.

    Examples
    --------
    >>> import physcore as pc
    >>> ens = pc.ensemble(pc.scenes.figure_eight(), 4, samples=3, steps_per_sample=200,
    ...                   client="serial", progress=False)
    >>> ens.values.shape
    (4, 3, 3, 2)
    >>> bool(ens.spread()[0] < 1e-8)
    True
    """
    if not isinstance(scene, Scene):
        raise InvalidTypeError(f"scene: expected a physcore.Scene, got {type(scene).__name__}")
    members = _check.int_in_range("members", members, 1, 10**7)
    samples = _check.int_in_range("samples", samples, 1, 10**7)
    steps = _check.int_in_range("steps_per_sample", steps_per_sample, 1, 2**53)
    if not callable(perturb):
        perturb = _check.nonneg_float("perturb", perturb, unit="m")
        if perturb > 1e150:  # times a normal draw it overflowed float64 (numpy's bare warning)
            raise InvalidInputError(f"perturb: at most 1e150 m (a perturbation of a physical size), got {perturb:g}")
    if observe is not None and not callable(observe):
        raise InvalidTypeError(f"observe: expected a callable (scene -> array), got {type(observe).__name__}")
    seed = _check.int_in_range("seed", seed, 0)
    client = _check_client(client)
    if workers is not None:
        workers = _check.int_in_range("workers", workers, 1, 4096)
    if threads is not None:
        threads = _check.int_in_range("threads", threads, 1, 65535)
    progress = _check.flag("progress", progress)
    data = pickle.dumps(scene)

    got: dict[int, Any] = {}
    from tqdm.auto import tqdm

    bar = tqdm(total=members, desc="ensemble", unit="run", disable=not progress, leave=False)

    # Members go in chunks, each chunk one task stepped as a Batch (one call into the core per
    # sample for the whole chunk): all of them in one chunk in this process, about four chunks
    # a worker on Dask (so that small members stop paying a task each).
    if client == "serial":
        size = members
    else:
        size = max(1, math.ceil(members / (4 * (workers or usable_cpus()))))
    chunks = [list(range(a, min(a + size, members))) for a in range(0, members, size)]

    def on_result(c: int, value: Any) -> None:
        for i, m in enumerate(chunks[c]):
            if isinstance(value, BaseException):
                got[m] = _error_text(value)
            else:
                got[m] = _error_text(value[i]) if isinstance(value[i], BaseException) else value[i]
        bar.update(len(chunks[c]))

    try:
        _map(_run_members, [(chunk, seed, perturb, observe, samples, steps, threads) for chunk in chunks], client, workers,
             on_result, shared=(data,))
    finally:
        bar.close()
    ok = [m for m in range(members) if not isinstance(got[m], str)]
    failed = {m: got[m] for m in range(members) if isinstance(got[m], str)}
    shapes = {got[m][1].shape for m in ok}
    if len(shapes) > 1:
        raise InvalidInputError(f"observe: returned different shapes in different members: {sorted(shapes)}")
    if ok:
        times = got[ok[0]][0]
        values = np.stack([got[m][1] for m in ok])
    else:
        times, values = np.zeros(0), np.zeros((0, 0))
    return Ensemble(times=times, values=values, members=np.asarray(ok, dtype=np.int64), failed=failed)

