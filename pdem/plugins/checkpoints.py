"""Full-state checkpoints (``checkpoint:``), and the final one when a run fails."""

from __future__ import annotations

import logging

from ..io.checkpoint import prune, write_checkpoint
from .base import Plugin, interval_steps

log = logging.getLogger("pdem")


class Checkpoints(Plugin):
    """Every ``checkpoint.every`` model seconds (or ``every_steps``); the newest ``keep`` are
    kept. The other plugins' restart state is stored with the model state."""

    name = "checkpoints"

    def __init__(self, state):
        self.state = state
        ck = state.scene.checkpoint
        self.prefix = ck.file
        self.keep = ck.keep
        self.every = interval_steps(state, ck.every_steps, ck.every)

    def write(self, run, final: bool = False) -> str:
        """Write a checkpoint now (collective); keep the newest ``keep``."""
        s = self.state
        name = f"{self.prefix}-{s.step:09d}{'-failed' if final else ''}.h5"
        extra = {}
        for p in run.plugins:
            extra.update(p.restart_state())
        with s.timers.phase("io"):
            path = write_checkpoint(name, s, extra)
            if not final:
                prune(self.prefix, self.keep, s.comm)
        log.info("checkpoint %s", path)
        return path

    def after_step(self, run):
        if self.state.step % self.every == 0:
            self.write(run)

    def on_failure(self, run):
        path = self.write(run, final=True)
        log.error("final checkpoint written: %s", path)
