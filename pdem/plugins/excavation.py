"""Excavations at a model time (``excavate: [{..., time: T}]``): the blocks inside the region
are deleted at the step nearest T, as 3DEC's ``block excavate`` between two solves.

The region was cut at model build (pdem.model.rockmass), so the blocks to delete are known by
gid; what is pending is read from the blocks' state (``out``), so a restart needs nothing else.
"""

from __future__ import annotations

import numpy as np

from ..domain import DELETED, remove_blocks
from .base import PLUGINS, Plugin, PluginEntry


class Excavations(Plugin):
    name = "excavations"

    def __init__(self, state):
        self.state = state
        self.pending: list[float] = []

    def start(self, run):
        s = self.state
        t = s.specs.excavation_times()
        self.pending = sorted(set(t[~np.isnan(t) & (s.glob.out == 0)].tolist()))
        self.after_step(run)  # an excavation due at the start time

    def horizon(self, run):
        s = self.state
        return None, (self.pending[0] - 0.5 * s.dt if self.pending else None)

    def after_step(self, run):
        s = self.state
        done = False
        while self.pending and s.time >= self.pending[0] - 0.5 * s.dt:
            t = self.pending.pop(0)
            gids = np.array([g for g, sp in enumerate(s.specs) if sp.excavate_at == t],
                            np.int64)
            remove_blocks(s, run.stepper.bodies(), gids, DELETED,
                          f"excavated (excavate at t = {t:g} s)")
            done = True
        if done and s.comm.size > 1:
            for p in run.plugins:
                p.before_migration(run)
            s.rebalance()  # excavated blocks weigh nothing now (balance: rcb)
            s.redistribute()


# first after the stage bookkeeping: a checkpoint after it sees it done
PLUGINS.register("excavations", PluginEntry(
    20, lambda state, output, made: None if np.isnan(state.specs.excavation_times()).all()
    else Excavations(state)))
