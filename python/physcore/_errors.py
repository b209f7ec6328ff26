"""physcore's exception hierarchy (raised from Rust through ``physcore._core`` as well)."""
from __future__ import annotations

__all__ = ["PhyscoreError", "InvalidInputError", "SimulationDiverged", "SceneBusyError"]


class PhyscoreError(Exception):
    """Base class of every error physcore raises on purpose."""


class InvalidInputError(PhyscoreError, ValueError):
    """An argument is invalid. Raised before any state changes; the message names the argument."""


class SimulationDiverged(PhyscoreError, RuntimeError):
    """NaN or infinity appeared while stepping.

    The scene is rolled back to where the failing ``step(n)`` call started, so it never holds
    non-finite values. Attributes: ``step`` (the step at which the non-finite value appeared),
    ``time`` (s), ``particle`` (index of the first bad particle), ``quantity`` (``"position"`` or
    ``"velocity"``), ``suggested_dt`` (s) and ``rolled_back_to`` (step count after the rollback).
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
