"""Diagnostics over time: the energy books as a time series, and a plot of them.

:class:`EnergyRecorder` costs nothing unless it is used: it reads ``scene.energy()`` only when
:meth:`~EnergyRecorder.record` is called (``physcore render ... --energy-plot energy.png`` calls
it once per frame). Plotting uses matplotlib (``pip install "physcore[plot]"``).

Examples
--------
>>> import physcore as pc
>>> from physcore.diagnostics import EnergyRecorder
>>> scene = pc.scenes.spring_chain(n=8)
>>> rec = EnergyRecorder()
>>> for _ in range(5):
...     rec.record(scene)
...     scene.step(100)
>>> rec.record(scene)
>>> len(rec), bool(abs(rec.drift[-1]) < 1e-3)
(6, True)
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ._atomic import atomic_write
from ._errors import InvalidInputError, InvalidTypeError
from .session import left_sum

__all__ = ["EnergyRecorder"]


class EnergyRecorder:
    """Samples of a scene's energy books (J) at chosen times (s).

    Attributes (after at least one :meth:`record`)
    ----------------------------------------------
    time, kinetic, total, drift : numpy.ndarray, shape (S,), float64
        ``drift`` is the relative change of ``total`` since the first sample, with the same
        scale as :meth:`Scene.energy_drift`: the largest of ``|E0|`` and the sums of the books'
        magnitudes at the start and at the sample (the energy in play).
    potential, dissipated : dict[str, numpy.ndarray]
        Each term's potential energy and each source's dissipated energy, shape (S,).
    """

    def __init__(self) -> None:
        self._t: list[float] = []
        self._kin: list[float] = []
        self._pot: dict[str, list[float]] = {}
        self._dis: dict[str, list[float]] = {}
        self._tot: list[float] = []
        self._scale: list[float] = []
        self._scene: object = None  # the scene of the samples

    def record(self, scene) -> None:
        """Append the books of ``scene`` now (one ``scene.energy()`` call).

        Raises
        ------
        InvalidTypeError
            ``scene`` has no energy books (not a :class:`~physcore.Scene`).
        InvalidInputError
            ``scene`` is not the scene of the first sample: one recorder follows one scene
            (samples of two would make a drift of neither).
        """
        if not (callable(getattr(scene, "energy", None)) and hasattr(scene, "time")):
            raise InvalidTypeError(f"scene: expected a physcore Scene (with energy books), got {type(scene).__name__}")
        if self._t and scene is not self._scene:
            raise InvalidInputError("scene: this recorder follows another scene (its first sample's); use one recorder per scene")
        e = scene.energy()
        self._scene = scene
        k = len(self._t)
        for book, src in ((self._pot, e.potential), (self._dis, e.dissipated)):
            for name, value in src.items():
                book.setdefault(name, [0.0] * k).append(float(value))
            for values in book.values():
                if len(values) == k:  # a book that disappeared
                    values.append(0.0)
        self._t.append(float(scene.time))
        self._kin.append(float(e.kinetic))
        self._tot.append(float(e.total))
        self._scale.append(abs(e.kinetic) + left_sum(abs(u) for u in e.potential.values()) + left_sum(abs(d) for d in e.dissipated.values()))

    def __len__(self) -> int:
        return len(self._t)

    @property
    def time(self) -> np.ndarray:
        return np.asarray(self._t)

    @property
    def kinetic(self) -> np.ndarray:
        return np.asarray(self._kin)

    @property
    def total(self) -> np.ndarray:
        return np.asarray(self._tot)

    @property
    def potential(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self._pot.items()}

    @property
    def dissipated(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self._dis.items()}

    @property
    def drift(self) -> np.ndarray:
        if not self._t:
            return np.zeros(0)
        tot = self.total
        denom = np.maximum(np.maximum(abs(tot[0]), self._scale[0]), np.asarray(self._scale))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(denom > 0, (tot - tot[0]) / denom, 0.0)

    def plot(self, path: str | os.PathLike, *, title: str = "energy books") -> Path:
        """Write a PNG: the books over time (kinetic, potential by term, dissipated by source,
        total) above the relative drift of the total. Written atomically.

        Raises
        ------
        ValueError
            No samples, or ``path`` does not end in ``.png``.
        ImportError
            matplotlib is not installed (``pip install "physcore[plot]"``).
        """
        path = Path(path)
        if path.suffix.lower() != ".png":
            raise InvalidInputError(f"path: must end in .png, got {str(path)!r}")
        if not self._t:
            raise InvalidInputError("recorder: no samples recorded")
        try:
            import matplotlib

            matplotlib.use("Agg", force=False)
            from matplotlib.figure import Figure
        except ImportError as exc:
            raise ImportError('the energy plot needs matplotlib: pip install "physcore[plot]"') from exc
        t = self.time
        fig = Figure(figsize=(7.0, 6.0), dpi=100, layout="constrained")
        ax, ad = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
        ax.plot(t, self.kinetic, label="kinetic")
        for name, u in self.potential.items():
            ax.plot(t, u, label=f"potential: {name}")
        for name, d in self.dissipated.items():
            ax.plot(t, d, "--", label=f"dissipated: {name}")
        ax.plot(t, self.total, "k", lw=2, label="total")
        ax.set_ylabel("energy (J)")
        ax.set_title(title)
        ax.legend(fontsize=8, loc="best")
        ad.plot(t, self.drift, "k")
        ad.set_ylabel("relative drift")
        ad.set_xlabel("time (s)")
        ad.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
        atomic_write(path, lambda fh: fig.savefig(fh, format="png"))
        return path
