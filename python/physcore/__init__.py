"""physcore: fast, honest particle physics for Python.

Build a :class:`Scene` from only the physics it needs, step it in parallel in Rust, check the
energy books, and render it to an animated GIF with :func:`physcore.render.gif`.
"""
from __future__ import annotations

from . import _core, bodies, flows, shapes, sweeps
from . import potentials as _potentials
from . import terms as _terms
from ._errors import (
    ContactStepWarning,
    DeviceError,
    EnergyBooksWarning,
    InvalidInputError,
    InvalidTypeError,
    OutOfMemoryError,
    PhyscoreError,
    SceneBusyError,
    SceneFileError,
    SeparateFluidsWarning,
    SimulationDiverged,
    StabilityWarning,
    ThreadPoolError,
    ThreadPoolWarning,
    UnchargedWarning,
    UnusedOptionWarning,
)
from ._integrators import (
    RK4,
    XPBD,
    Boris,
    Dopri5,
    Euler,
    ImplicitEuler,
    SemiImplicitEuler,
    Verlet,
    WisdomHolman,
    Yoshida4,
)
from ._system import gpu_adapters, info, set_simd_level, simd_level, simd_levels
from .batch import Batch
from .bodies import Bodies, Joints, Pins
from .contacts import Contacts
from .flows import Flow
from .fluids import DFSPH, WCSPH, Fluid, neighbors
from .grids import Drop, GrayScott, Oscillator, Source, StableFluid, Wave
from .potentials import *  # noqa: F403 - the potential fields, as potentials.__all__ lists them
from .scene import INTEGRATORS, EnergyReport, Scene
from .sweeps import Ensemble, ensemble, sweep
from .terms import *  # noqa: F403 - every term record, as terms.__all__ lists them

__version__ = _core.__version__

__all__ = [
    "Scene",
    "EnergyReport",
    "INTEGRATORS",
    "Euler",
    "SemiImplicitEuler",
    "Verlet",
    "Yoshida4",
    "RK4",
    "Dopri5",
    "WisdomHolman",
    "Boris",
    "XPBD",
    "ImplicitEuler",
    *_terms.__all__,
    *_potentials.__all__,
    "Contacts",
    "Fluid",
    "WCSPH",
    "DFSPH",
    "neighbors",
    "Wave",
    "GrayScott",
    "StableFluid",
    "Source",
    "Drop",
    "Oscillator",
    "Flow",
    "sweep",
    "ensemble",
    "Ensemble",
    "Batch",
    "Bodies",
    "Joints",
    "Pins",
    "bodies",
    "sweeps",
    "flows",
    "grids",
    "fluids",
    "shapes",
    "PhyscoreError",
    "InvalidInputError",
    "InvalidTypeError",
    "SceneFileError",
    "SimulationDiverged",
    "SceneBusyError",
    "OutOfMemoryError",
    "DeviceError",
    "ThreadPoolError",
    "ThreadPoolWarning",
    "ContactStepWarning",
    "StabilityWarning",
    "UnchargedWarning",
    "UnusedOptionWarning",
    "EnergyBooksWarning",
    "SeparateFluidsWarning",
    "scenes",
    "render",
    "simd_level",
    "simd_levels",
    "set_simd_level",
    "info",
    "gpu_adapters",
    "__version__",
]


_LAZY = ("scenes", "render", "cli", "viewer", "notebook")


def _show(self: Scene, **options: object) -> None:
    """Display this scene running live in a Jupyter notebook: ``physcore.widget(self,
    **options)`` (see :func:`physcore.notebook.widget`) shown with IPython's ``display``.
    Needs ``pip install "physcore[notebook]"`` (ImportError saying so otherwise)."""
    from .notebook import show

    show(self, **options)


# Presentation sits above the scene: the package attaches it (scene.py imports nothing of it).
_show.__name__ = "show"
_show.__qualname__ = "Scene.show"
Scene.show = _show  # type: ignore[attr-defined]


def __getattr__(name: str):  # lazy submodules: importing physcore stays cheap
    if name == "widget":  # the notebook widget (physcore.notebook.widget), imported on first use
        from .notebook import widget

        return widget
    if name in _LAZY:
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'physcore' has no attribute {name!r}")


def __dir__() -> list[str]:
    # The lazy submodules are part of the package's surface (tab completion, dir()).
    # Less `annotations`, the name `from __future__ import annotations` binds (not an API).
    return sorted((set(globals()) - {"annotations"}) | set(_LAZY) | {"widget"})
