"""Full-state checkpoints (``checkpoint:``), the final one when a run fails, and the one a
stop signal asks for (:func:`stop_checkpoint`)."""

from __future__ import annotations

import logging
import os

from ..errors import writing
from ..io.checkpoint import prune, write_checkpoint
from .base import PLUGINS, Plugin, PluginEntry, interval_steps, next_multiple

log = logging.getLogger("pdem")


def _write(run, name: str) -> str:
    """The model state and every plugin's restart state to ``name`` (collective)."""
    s = run.state
    extra = {}
    for p in run.plugins:
        extra.update(p.restart_state())
    with s.timers.phase("io"), writing(name):
        path = write_checkpoint(name, s, extra)
    log.info("checkpoint %s", path)
    return path


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
        self.last = None  # the newest complete checkpoint written by this run

    def write(self, run, final: bool = False) -> str:
        """Write a checkpoint now (collective); keep the newest ``keep``."""
        s = self.state
        path = _write(run, f"{self.prefix}-{s.step:09d}{'-failed' if final else ''}.h5")
        if not final:
            self.last = path
            prune(self.prefix, self.keep, s.comm)
        return path

    def after_step(self, run):
        if self.state.step % self.every == 0:
            self.write(run)

    def horizon(self, run):
        return next_multiple(self.state.step, self.every), None

    def on_failure(self, run):
        path = self.write(run, final=True)
        log.error("final checkpoint written: %s", path)


def stop_checkpoint(run) -> str:
    """The checkpoint of a stopped run (collective): the scene's ``checkpoint:`` series (not
    written twice if the stop falls on its interval), else ``{output stem}-stop-{step}.h5``
    beside the output file, which the run has already found writable."""
    s = run.state
    ck = run.plugin("checkpoints")
    if ck is not None:
        return ck.last if ck.last == f"{ck.prefix}-{s.step:09d}.h5" else ck.write(run)
    stem = os.path.splitext(s.scene.output.file)[0]
    return _write(run, f"{stem}-stop-{s.step:09d}.h5")


def stage_checkpoint(run, k: int) -> str:
    """The checkpoint ending stage ``k`` (collective): ``{checkpoint.file}-stage{k}-{name}.h5``,
    or beside the output file without ``checkpoint:``. ``pdem restart`` of it goes on with
    stage ``k + 1``."""
    s = run.state
    name = s.scene.stages[k].name
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
    prefix = s.scene.checkpoint.file if s.scene.checkpoint is not None \
        else os.path.splitext(s.scene.output.file)[0]
    return _write(run, f"{prefix}-stage{k}-{safe}.h5")


PLUGINS.register("checkpoints", PluginEntry(
    30, lambda state, output, made: Checkpoints(state) if state.scene.checkpoint is not None
    else None))
