"""Errors shown to users as one clear message (never a traceback)."""

from __future__ import annotations

import contextlib


class UserError(Exception):
    """Base of the errors caused by input or by the run itself, reported without traceback."""


class SimulationError(UserError):
    """The run cannot go on (a NaN, a runaway block); names the block, step and likely cause."""


class NoProgressError(SimulationError):
    """A solve to a ratio stopped improving (``solve.no_progress_steps``): names the blocks
    that keep it from its target, what they do, and the scene keys that help."""


class ConditionError(Exception):
    """A boundary condition that cannot act on what it selects, whatever else it takes
    (pdem.boundary.apply_conditions names it with the condition's key path)."""


class OutputError(UserError):
    """A file of the run could not be written (disk full, quota, a vanished directory)."""


@contextlib.contextmanager
def writing(path):
    """Turn an OSError raised while writing ``path`` into an OutputError naming the file."""
    try:
        yield
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
