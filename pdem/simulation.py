"""Simulation: a scene's model state, stepper and run with its plugins, built in one call.

This is the public entry point for scripts and tests::

    sim = Simulation(parse_scene(text), comm, output=False)
    sim.run(time=1.0)
    sim.blocks.x  # owned rows first, then ghosts
"""

from __future__ import annotations

from .distribute import release_scene_geometry, release_setup_fields
from .driver import Run
from .io.paths import check_writable
from .memory import reuse_large_blocks
from .plugins import default_plugins
from .stages import replay_stages, run_stages
from .state import ModelState
from .stepper import Stepper


class Simulation:
    """Build (collective) and march a model; ``checkpoint``: a read checkpoint to continue;
    ``stop``: a :class:`pdem.signals.StopRequest` that ends the march early (with a checkpoint);
    ``release``: once set up, keep only the geometry of the blocks each rank holds (False: keep
    the whole scene's, for reports such as ``pdem check``'s)."""

    def __init__(self, scene, comm, *, output: bool = True, checkpoint: dict | None = None,
                 plugins=None, stop=None, release: bool = True):
        paths = {"output.file": scene.output.file} if output else {}
        if scene.checkpoint is not None:
            paths["checkpoint.file"] = scene.checkpoint.file
        check_writable(comm, paths)
        self.state = ModelState.create(scene, comm, check_overlaps=checkpoint is None,
                                       whole=not release)
        self.state.keep_scene_geometry = not release
        self.state.output_surfaces = output  # no output: no writer's share of the surfaces
        self.stepper = Stepper(self.state)
        self.stepper.stop = stop
        if checkpoint is None:
            self.stepper.start()
        else:
            if scene.stages:  # the model the checkpoint's stages had made, then its state
                replay_stages(self.state, checkpoint["attrs"])
            self.state.restore(checkpoint)
            # the start's cuts (balance: rcb) fit the scene's start, not the checkpoint's
            if self.state.rebalance():
                self.state.redistribute()
        if plugins is None:
            plugins = default_plugins(self.state, output)
        self.runner = Run(self.state, self.stepper, plugins)
        if checkpoint is not None:
            for p in self.runner.plugins:
                p.restore(checkpoint["attrs"])
        if release:
            # the output writer has taken its share of the surfaces (it keeps its own copy)
            self.state.writer_mesh = self.state.writer_static = None
            release_scene_geometry(self.state)
            release_setup_fields(self.state)
        reuse_large_blocks()  # set up: the step's arrays come from the heap (pdem.memory)

    # the model, as scripts and tests read it
    @property
    def blocks(self):
        return self.state.blocks

    @property
    def contacts(self):
        return self.state.contacts

    @property
    def step(self) -> int:
        return self.state.step

    @property
    def time(self) -> float:
        return self.state.time

    @property
    def dt(self) -> float:
        return self.state.dt

    @property
    def specs(self):
        return self.state.specs

    @property
    def comm(self):
        return self.state.comm

    @property
    def n_owned(self) -> int:
        return self.state.n_owned

    def run(self, *, time: float | None = None, steps: int | None = None) -> dict:
        """March to the scene's end (every stage not done, for a staged scene), or for the
        given model time / step count."""
        if self.state.scene.stages and time is None and steps is None:
            summaries = run_stages(self.runner)
            last = dict(summaries[-1]) if summaries else {"steps": 0, "stopped": 0,
                                                          "checkpoint": None}
            last["stages"] = summaries
            return last
        return self.runner.run(time=time, steps=steps)

    def advance(self):
        self.runner.advance()

    def checkpoint(self) -> str:
        """Write a checkpoint now (needs ``checkpoint:`` in the scene)."""
        return self.runner.plugin("checkpoints").write(self.runner)

    def close(self):
        self.runner.close()
