"""The driver: march a model to its end condition, calling the plugins between steps (``pdem.run``
is the Python API's run of a scene: pdem.api)."""

from __future__ import annotations

import logging
import math
import time as wallclock

from .errors import OutputError, SimulationError
from .mpi import min_over_ranks
from .plugins.checkpoints import stop_checkpoint

log = logging.getLogger("pdem")

# wall seconds one compiled run of steps may take at most (pdem.cycle)
FUSED_SLICE = 0.25


class Run:
    """The driver: a stepper, its state and the plugins (:mod:`pdem.plugins`)."""

    def __init__(self, state, stepper, plugins):
        self.state = state
        self.stepper = stepper
        self.plugins = list(plugins)
        self.n_estimate = None
        self._step_seconds = 1e-2  # measured once steps run fused
        # the march in progress, as the plugins read it: its ratio target (None: it ends by
        # time or steps) and the steps a ratio may go without improving (0: no bound)
        self.ratio_target = None
        self.no_progress_steps = 0
        # a plugin's verdict that the march cannot succeed (a UserError, set on every rank
        # alike): the march ends after the plugins' finish, and this is raised
        self.halt = None

    def plugin(self, name: str):
        """The plugin called ``name``, or None."""
        return next((p for p in self.plugins if p.name == name), None)

    def advance(self):
        """One step; blocks migrate after it when they moved far enough (collective)."""
        if self.stepper.advance():
            self._migrate()

    def march(self, steps: int, ratio: float | None = None) -> int:
        """Up to ``steps`` steps, fewer if the unbalanced-force ratio falls to ``ratio`` or a
        stop is requested, in compiled runs where the scene allows, no plugin called (a
        strength-reduction trial: pdem.strength). Returns the steps taken (every rank alike)."""
        s = self.state
        s0 = s.step
        while s.step - s0 < steps and not self.stepper.stop_signal:
            self._slice(steps - (s.step - s0), None, None, ratio)
            if ratio is not None and s.ratio <= ratio:
                break
        return s.step - s0

    def _slice(self, steps_left, stop_step, stop_time, ratio_target) -> None:
        """A run of steps in one compiled call, as many as take FUSED_SLICE wall seconds (at
        most ``steps_left``), ending early at the stops; migrates after it if due."""
        s = self.state
        budget = max(1, int(FUSED_SLICE / max(self._step_seconds, 1e-9)))
        if steps_left is not None:
            budget = min(budget, steps_left)
        if s.comm.size > 1:  # every rank's run of steps ends after the same step
            budget = min_over_ranks(s.comm, budget)
        t0 = wallclock.perf_counter()
        done = self.stepper.advance_many(budget, stop_step, stop_time, ratio_target)
        if self.stepper.migrate_due:
            self._migrate()
        # seconds per step, for the next slice; a single step is measured too, else a slow
        # first call (compiling fused_steps) would leave the budget at one step for good
        if done >= 1:
            self._step_seconds = (wallclock.perf_counter() - t0) / done

    def _migrate(self):
        for p in self.plugins:
            p.before_migration(self)
        self.state.rebalance()  # new cuts if the work is imbalanced (balance: rcb)
        self.state.redistribute()

    def _advance_to_event(self, end_step, end_time, ratio_target, steps_left):
        """One step, or the steps up to the next event (a plugin's horizon, the end
        condition, a wall-clock slice that keeps progress lines and stop signals prompt, on
        several ranks also a migration) in one compiled call (pdem.cycle)."""
        s = self.state
        if not self.stepper.fusable():
            self.advance()
            return
        stop_step, stop_time = end_step, None
        if end_time is not None:
            stop_time = end_time - 1e-9 * s.dt  # as the loop in run() decides the end
        for p in self.plugins:
            ps, pt = p.horizon(self)
            if ps is not None:
                stop_step = ps if stop_step is None else min(stop_step, ps)
            if pt is not None:
                stop_time = pt if stop_time is None else min(stop_time, pt)
        self._slice(steps_left, stop_step, stop_time, ratio_target)

    def _end(self, time, steps, ratio=None, max_steps=None, no_progress=None):
        s = self.state
        sv = s.scene.solve
        if time is None and steps is None and ratio is None:
            # the scene's end condition is absolute, so a restart runs to the same end
            end_step, end_time, ratio_target = sv.steps, sv.time, sv.ratio
        else:
            end_step = s.step + steps if steps is not None else None
            end_time = s.time + time if time is not None else None
            ratio_target = ratio
        max_steps = max_steps or sv.max_steps or (10_000_000 if ratio_target else None)
        self.ratio_target = ratio_target
        self.no_progress_steps = 0 if ratio_target is None else (
            sv.no_progress_steps if no_progress is None else no_progress)
        self.halt = None
        if end_time is not None:
            self.n_estimate = int(math.ceil((end_time - s.time) / s.dt))
        elif end_step is not None:
            self.n_estimate = end_step - s.step
        else:
            self.n_estimate = max_steps
        return end_step, end_time, ratio_target, max_steps

    def run(self, *, time: float | None = None, steps: int | None = None,
            ratio: float | None = None, max_steps: int | None = None,
            no_progress: int | None = None) -> dict:
        """March until the scene's end condition (or the given model time / step count), or
        until a stop request (``stepper.stop``): then the summary has ``stopped`` (the signal)
        and ``checkpoint`` (the file to restart from), written after the output is flushed.
        ``no_progress``: the steps a ``ratio`` may go without improving (None: the scene's
        ``solve.no_progress_steps``); a plugin that finds the march cannot succeed ends it
        (``halt``), and its error is raised once the output is flushed."""
        s = self.state
        end_step, end_time, ratio_target, max_steps = self._end(time, steps, ratio, max_steps,
                                                                no_progress)
        log.info("%s: %d blocks, %d contacts, dt=%.4g s, ctol=%.4g m, %s damping; %d steps",
                 s.scene.name, s.glob.n, s.contacts.n, s.dt, s.ctol, s.damping_name,
                 self.n_estimate)
        if s.comm.size > 1:
            log.info("decomposition: %s ranks, %s, ghost margin %.3g m",
                     s.comm.size, s.decomp.describe(), s.resolved.margin)
        for p in self.plugins:
            p.start(self)
        t0 = wallclock.perf_counter()
        s0 = s.step
        while True:
            if end_step is not None and s.step >= end_step:
                break
            if end_time is not None and s.time >= end_time - 1e-9 * s.dt:
                break
            if ratio_target is not None and s.ratio <= ratio_target:
                break
            if max_steps is not None and s.step - s0 >= max_steps:
                log.warning("stopped at solve.max_steps=%d before reaching the target",
                            max_steps)
                break
            if self.stepper.stop_signal:  # agreed by every rank in the last step's reduction
                break
            if self.halt is not None:  # set by a plugin on every rank alike
                break
            try:
                self._advance_to_event(end_step, end_time, ratio_target, max_steps - (s.step - s0)
                                       if max_steps is not None else None)
                for p in self.plugins:
                    p.after_step(self)
            except SimulationError:
                for p in self.plugins:  # raised on every rank alike, so this is collective
                    p.on_failure(self)
                raise
            except OutputError as exc:
                # no new checkpoint: the disk that refused this file would likely refuse it too
                self._name_last_checkpoint(exc)
                raise
        for p in self.plugins:
            p.finish(self)
        if self.halt is not None:  # every rank alike: the output is flushed, no checkpoint
            halt, self.halt = self.halt, None
            raise halt
        stopped = self.stepper.stop_signal
        checkpoint = None
        if stopped:
            checkpoint = stop_checkpoint(self)
        elapsed = wallclock.perf_counter() - t0
        summary = {"steps": s.step - s0, "time": s.time, "ratio": s.ratio, "wall": elapsed,
                   "contacts": s.contacts.n, "stopped": stopped, "checkpoint": checkpoint}
        log.info("time per phase (rank 0): %s", s.timers.report())
        log.info("done: %d steps in %.1f s (%.0f steps/s, %.3g block-steps/s), t=%.5g s, "
                 "ratio=%.3g", summary["steps"], elapsed, summary["steps"] / max(elapsed, 1e-9),
                 summary["steps"] * s.glob.n / max(elapsed, 1e-9), s.time, s.ratio)
        return summary

    def _name_last_checkpoint(self, exc: OutputError) -> None:
        ck = self.plugin("checkpoints")
        last = ck.last if ck is not None and ck.last else None
        if last:
            exc.args = (f"{exc}; the last good checkpoint is {last}",)

    def close(self):
        for p in self.plugins:
            p.close()
