"""Run plugins: what happens between steps (output, histories, checkpoints, progress).

Each plugin owns its interval, its scene section and its restart state; the run calls its
hooks (:class:`Plugin`). To add one, write its class and register it in :data:`PLUGINS` with
the order of its hooks and what makes it (:class:`PluginEntry`); a plugin from outside pdem's
tree registers the same way.
"""

from __future__ import annotations

from .base import PLUGINS, Plugin, PluginEntry, interval_steps
from .checkpoints import Checkpoints
from .energy import EnergyBudget
from .excavation import Excavations
from .no_progress import NoProgress
from .output import Histories, Snapshots
from .progress import LoadReport, Progress
from .stage_state import StageState

__all__ = ["PLUGINS", "Checkpoints", "EnergyBudget", "Excavations", "Histories", "LoadReport",
           "NoProgress", "Plugin", "PluginEntry", "Progress", "Snapshots", "StageState",
           "default_plugins", "interval_steps"]


def default_plugins(state, output: bool = True) -> list[Plugin]:
    """The plugins a scene asks for, in the order their hooks run after a step: every
    registered plugin (:data:`PLUGINS`, by ``order``) whose entry makes one for it."""
    made: dict[str, Plugin] = {}
    for name, entry in sorted(PLUGINS.items(), key=lambda item: item[1].order):
        plugin = entry.make(state, output, made)
        if plugin is not None:
            made[name] = plugin
    return list(made.values())
