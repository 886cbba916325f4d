"""Progress lines (``solve.progress_every`` wall seconds) and the per-rank load report."""

from __future__ import annotations

import logging
import time as wallclock

from .base import PLUGINS, Plugin, PluginEntry, next_multiple

log = logging.getLogger("pdem")


class Progress(Plugin):
    """Rank 0 logs step, time, ratio, contacts, rate and ETA every ``progress_every`` s."""

    name = "progress"

    def __init__(self, state):
        self.state = state
        self.every = state.scene.solve.progress_every

    def start(self, run):
        self.t0 = self.last = wallclock.perf_counter()
        self.s0 = self.state.step

    def horizon(self, run):
        return None, None  # by the wall clock: pdem.driver bounds a compiled run's duration

    def after_step(self, run):
        now = wallclock.perf_counter()
        s = self.state
        if now - self.last < self.every or s.comm.rank != 0:
            return
        self.last = now
        rate = (s.step - self.s0) / (now - self.t0)
        n_est = run.n_estimate
        left = (n_est - (s.step - self.s0)) / rate if rate > 0 and n_est else float("nan")
        log.info("step %d  t=%.5g s  ratio=%.3g  contacts=%d  %.0f steps/s  ETA %.0f s",
                 s.step, s.time, s.ratio, s.contacts.n, rate, left)


class LoadReport(Plugin):
    """Blocks, ghosts, contacts and halo bytes per rank (MPI), read with each snapshot and
    logged when they changed since the last line (a settled model prints one line, not one a
    snapshot)."""

    name = "load-report"

    def __init__(self, state, every: int):
        self.state = state
        self.every = every
        self.last = None  # the last line's values

    def log(self):
        s = self.state
        r = s.load_report()  # collective: every rank reads it, rank 0 logs
        values = (r["owned"], r["ghosts"], r["contacts"], r["halo_bytes"], r["imbalance"],
                  r["rebuilds"])
        if s.comm.size > 1 and values != self.last:
            log.info("load: owned %s ghosts %s contacts %s halo B/step %s; imbalance %.2f; "
                     "rebuilds %d", *values)
        self.last = values

    def start(self, run):
        self.log()

    def horizon(self, run):
        return next_multiple(self.state.step, self.every), None

    def after_step(self, run):
        if self.state.step % self.every == 0:
            self.log()


PLUGINS.register("load-report", PluginEntry(
    50, lambda state, output, made: LoadReport(state, made["snapshots"].every)
    if "snapshots" in made else None))
PLUGINS.register("progress", PluginEntry(80, lambda state, output, made: Progress(state)))
