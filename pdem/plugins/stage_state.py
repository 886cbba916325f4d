"""The stage bookkeeping of a staged run in checkpoints (pdem.stages): which stages are done,
which one is in progress and where it started, so a restart goes on exactly there."""

from __future__ import annotations

import json

from .base import PLUGINS, Plugin, PluginEntry

_KEYS = {"stage": int, "stage_next": int, "stage_started": int, "stage_t0": float,
         "stage_step0": int}


class StageState(Plugin):
    name = "stages"

    def __init__(self, state):
        self.state = state

    def horizon(self, run):
        return None, None  # acts only at checkpoints

    def restart_state(self) -> dict:
        attrs = {k: getattr(self.state, k) for k in _KEYS}
        if self.state.stage_times:  # read back by pdem.stages.replay_stages
            attrs["stage_times"] = json.dumps(self.state.stage_times)
        if len(self.state.boundary.rigid.r_gid):  # a stage's replay frees them, these hold them
            attrs["released_loads"] = self.state.boundary.rigid.released()
        return attrs

    def restore(self, attrs: dict) -> None:
        for k, cast in _KEYS.items():
            if k in attrs:
                setattr(self.state, k, cast(attrs[k]))
        if "released_loads" in attrs:
            self.state.boundary.rigid.restore_released(attrs["released_loads"])


PLUGINS.register("stages", PluginEntry(
    10, lambda state, output, made: StageState(state) if state.scene.stages else None))
