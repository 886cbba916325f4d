"""Run plugins: what happens between steps (output, histories, checkpoints, progress).

Each plugin owns its interval, its scene section and its restart state; the run calls its
hooks (:class:`Plugin`). To add one, write a class here and add it in :func:`default_plugins`.
"""

from __future__ import annotations

import numpy as np

from .base import Plugin, interval_steps
from .checkpoints import Checkpoints
from .energy import EnergyBudget
from .excavation import Excavations
from .output import Histories, Snapshots
from .progress import LoadReport, Progress
from .stage_state import StageState

__all__ = ["Checkpoints", "EnergyBudget", "Excavations", "Histories", "LoadReport", "Plugin",
           "Progress", "Snapshots", "StageState", "default_plugins", "interval_steps"]


def default_plugins(state, output: bool = True) -> list[Plugin]:
    """The plugins a scene asks for, in the order their hooks run after a step."""
    plugins: list[Plugin] = []
    if state.scene.stages:
        plugins.append(StageState(state))
    if not np.isnan(state.specs.excavation_times()).all():
        plugins.append(Excavations(state))  # first: a checkpoint after it sees it done
    if state.scene.checkpoint is not None:
        plugins.append(Checkpoints(state))
    snaps = None
    if output:
        snaps = Snapshots(state)
        plugins += [snaps, LoadReport(state, snaps.every), Histories(state, snaps)]
    plugins += [EnergyBudget(state, snaps), Progress(state)]
    return plugins
