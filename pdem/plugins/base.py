"""The plugin interface and the interval rule shared by the plugins."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from ..registry import Registry


class Plugin:
    """Hooks called by :class:`pdem.driver.Run`; every hook is collective over the ranks.

    ``restart_state`` returns attributes stored in checkpoints (str/int/float) and
    ``restore`` receives them back, so a restarted run behaves as the straight one.
    """

    name = "plugin"

    def start(self, run) -> None:
        """Before the first step of a march (also after a restart)."""

    def after_step(self, run) -> None:
        """After every step (after the last step of each compiled run of steps, see
        :meth:`horizon`)."""

    def horizon(self, run) -> tuple[int | None, float | None]:
        """``(step, time)``: the steps up to the first with ``state.step >= step`` or
        ``state.time >= time`` may run in one compiled call (pdem.cycle) with ``after_step``
        called only after the last of them; None for no bound. The default, the next step,
        calls ``after_step`` after every step, so a plugin that acts on its own schedule
        declares it here to let small scenes run fused."""
        return run.state.step + 1, None

    def before_migration(self, run) -> None:
        """Before blocks change owner (flush what is buffered by owner)."""

    def finish(self, run) -> None:
        """After the last step of a march."""

    def on_failure(self, run) -> None:
        """The march stopped with a SimulationError raised on every rank."""

    def restart_state(self) -> dict:
        return {}

    def restore(self, attrs: dict) -> None:
        """Restart state from a checkpoint's attributes (keys of ``restart_state``)."""

    def close(self) -> None:
        """Release files (idempotent)."""


def interval_steps(state, every_steps, every) -> int:
    """Steps between events: given, or from model seconds, or 100 per scene run."""
    if every_steps:
        return int(every_steps)
    if every:
        return max(1, int(round(every / state.dt)))
    sv = state.scene.solve
    total = sv.steps or (int(math.ceil(sv.time / state.dt)) if sv.time else 100_000)
    return max(1, total // 100)


def next_multiple(step: int, every: int) -> int:
    """The first step after ``step`` that is a multiple of ``every`` (an interval's event)."""
    return (step // every + 1) * every


@dataclass(frozen=True)
class PluginEntry:
    """How a run gets a plugin: ``make(state, output, made)`` returns the plugin a scene asks
    for, or None (``output``: the run writes files; ``made``: the plugins made before it, by
    name, e.g. the snapshots a plugin samples with). ``order``: where its hooks run after a
    step, lowest first."""

    order: int
    make: Callable[..., Plugin | None]


# The run plugins by name (their ``Plugin.name``): each plugin module registers its own, and
# a plugin from outside pdem's tree registers the same way before the Simulation is made.
PLUGINS: Registry[PluginEntry] = Registry("run plugin")
