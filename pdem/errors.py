"""Errors shown to users as one clear message (never a traceback)."""

from __future__ import annotations


class UserError(Exception):
    """Base of the errors caused by input or by the run itself, reported without traceback."""


class SimulationError(UserError):
    """The run cannot go on (a NaN, a runaway block); names the block, step and likely cause."""
