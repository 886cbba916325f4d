"""Solves that cannot reach their ratio stop early and say why (``solve.no_progress_steps``).

A solve to an unbalanced-force ratio (``solve.ratio``, a stage's ``solve.ratio``) may never get
there: a block sliding off its base and falling with no contacts, a block sliding down a joint
weaker than its slope, a model ringing without damping. Its ratio then stays where it is, and
without a bound the run would go on to ``solve.max_steps`` (10^7 by default), for hours.

The rule, with ``W = no_progress_steps`` (docs/workflow.md, "Solves that cannot succeed"):

* the ratio is sampled every ``W / SAMPLES`` steps (at fixed step numbers); its **level** is
  the largest of the last ``LEVEL`` samples (``W / 4`` steps): the envelope of a ratio that
  rings as contacts oscillate, which the ratio of a single step is not;
* the level **improves** when it falls to ``GAIN`` (95 %) of the level at its last
  improvement (a solve's first level counts as one). A level above ``RISE`` (2) times that is
  a new event (a block landing, a joint failing): it restarts the count too;
* a solve whose level has not improved for ``W`` steps stops: every rank alike (the ratio and
  the step are the same on every rank; the diagnosis is gathered), once the plugins have
  flushed the output, with :class:`pdem.errors.NoProgressError`: one line naming the blocks
  with the largest unbalanced forces (those that keep the ratio up), what each does (falling
  with no contacts, sliding on block X at a steady speed or speeding up, not at rest on block
  X) and the scene keys that help.

So a solve stops ``W`` steps (and at most one sample interval more) after its level last
improved or rose; a ratio that never improves, ``W + W / 4`` steps (and at most one sample
interval more) after the solve began. A solve that ends by time or
steps is not watched (falling blocks may be what it models), nor a factor-of-safety trial
(bounded by its own ``max_steps``). The window starts afresh at a restart.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..contact.laws import SLIPPING
from ..dynamics import motion
from ..errors import NoProgressError
from ..mpi import allgather
from .base import PLUGINS, Plugin, PluginEntry, next_multiple

SAMPLES = 20  # ratio samples per window
LEVEL = 5  # samples whose largest is the level (a quarter of the window)
GAIN = 0.95  # an improvement: the level falls to this fraction of the last improved level
RISE = 2.0  # a level this many times the last improved one: something new, counted afresh
NAMED = 3  # blocks named in the message
STEADY = 0.05  # a speed that changed by at most this fraction since the last improvement


class NoProgress(Plugin):
    """Watches a solve to a ratio (``run.ratio_target``) and ends it (``run.halt``) when its
    ratio has not improved for ``run.no_progress_steps`` steps."""

    name = "no-progress"

    def __init__(self, state):
        self.state = state
        self.window = 0

    def start(self, run):
        s = self.state
        self.window = run.no_progress_steps if run.ratio_target is not None else 0
        self.every = max(1, self.window // SAMPLES)
        self.samples: deque[float] = deque(maxlen=LEVEL)
        self.level = None  # the level at the last improvement
        self.since = s.step  # the step of the last improvement
        self.before = None  # (gids, velocities) of this rank's free blocks at ``since``

    def horizon(self, run):
        if not self.window:
            return None, None
        return next_multiple(self.state.step, self.every), None

    def after_step(self, run):
        s = self.state
        if not self.window or s.step % self.every:
            return
        self.samples.append(s.ratio)
        if len(self.samples) == LEVEL:
            level = max(self.samples)
            if self.level is None or level <= GAIN * self.level or level > RISE * self.level:
                self.level, self.since = level, s.step
                self.before = self._velocities()
            elif s.step - self.since >= self.window:
                run.halt = NoProgressError(self._verdict(run))

    def _velocities(self):
        """This rank's free blocks' gids (sorted) and velocities now."""
        b, n = self.state.blocks, self.state.n_owned
        rows = np.nonzero(_free(b, n))[0]
        order = np.argsort(b.gid[rows], kind="stable")
        return b.gid[rows][order].copy(), b.v[rows][order].copy()

    def _verdict(self, run) -> str:
        """The one-line message (collective: every rank returns the same)."""
        s = self.state
        target = run.ratio_target
        found = allgather(s.comm, _candidates(s, self.before, target * s.resolved.ref_force))
        rows = sorted((c for part in found for c in part[0]), key=lambda c: (-c["force"],
                                                                              c["gid"]))
        above = sum(part[1] for part in found)
        where = (f"stages[{s.stage}] {s.scene.stages[s.stage].name!r}" if s.scene.stages
                 else "solve")
        st = s.scene.stages[s.stage].solve if s.scene.stages else None
        key = (f"stages[{s.stage}].solve.no_progress_steps"
               if st is not None and st.no_progress_steps is not None
               else "solve.no_progress_steps")
        text = (f"{where}: the ratio cannot reach {target:g}: no progress in {self.window} "
                f"steps ({key}): it is {s.ratio:.3g} at step {s.step} and has "
                f"not fallen {100 * (1 - GAIN):g}% below {self.level:.3g}, its level at step "
                f"{self.since}")
        named = rows[:NAMED]
        if named:
            parts = [_doing(s, c, s.step - self.since) for c in named]
            more = above - len(named)
            text += "; " + "; ".join(parts) + (
                f"; {more} more block{'s' if more != 1 else ''} above the target" if more > 0
                else "")
        elif s.grids is not None:
            text += "; the zoned blocks' gridpoints are not at rest"
        return text + "; " + _remedies(named, _damping_mode(s)) + " (docs/workflow.md)"


def _free(b, n: int) -> np.ndarray:
    """Owned rows that move under the forces: not fixed, in the model, not prescribed."""
    return (b.fixed[:n] == 0) & (b.out[:n] == 0) & (b.vfix[:n] != motion.VFIX_ALL)


def _candidates(s, before, threshold: float) -> tuple[list[dict], int]:
    """This rank's free blocks with the largest unbalanced forces (at most NAMED, each as a
    small record every rank can read) and how many are above ``threshold`` (N)."""
    b, n = s.blocks, s.n_owned
    rows = np.nonzero(_free(b, n))[0]
    if not len(rows):
        return [], 0
    f = b.prev_force[rows].copy()  # the last step's unbalanced force (pdem.dynamics.motion)
    code = b.vfix[rows]
    for k, bit in enumerate((motion.VFIX_X, motion.VFIX_Y, motion.VFIX_Z)):
        f[(code & bit) != 0, k] = 0.0  # a prescribed component's force is a reaction
    size = np.linalg.norm(f, axis=1)
    gids = b.gid[rows]
    top = np.lexsort((gids, -size))[:NAMED]
    c = s.contacts
    touching = np.zeros(c.n, bool)
    slipping = np.zeros(c.n, bool)
    load = np.zeros(c.n)
    if c.n:
        per = np.diff(c.sc_start)
        owner = np.repeat(np.arange(c.n), per)
        pressed = c.sc_un > 0.0
        np.logical_or.at(touching, owner, pressed)
        np.logical_or.at(slipping, owner, pressed & ((c.sc_state & SLIPPING) != 0))
        np.add.at(load, owner, np.where(pressed, c.sc_un * c.sc_area, 0.0))
    g = np.asarray(s.scene.gravity, float)
    down = g / np.linalg.norm(g) if np.any(g) else np.zeros(3)
    out = []
    for i in top:
        row = int(rows[i])
        mine = np.nonzero(((c.ia == row) | (c.ib == row)) & touching)[0] if c.n else []
        partner, slip = -1, False
        if len(mine):
            k = int(mine[np.argmax(load[mine])])
            other = int(c.ib[k]) if int(c.ia[k]) == row else int(c.ia[k])
            partner = int(b.gid[other])
            slip = bool(slipping[mine].any())
        v = b.v[row]
        speed0 = math.nan
        if before is not None:
            j = int(np.searchsorted(before[0], b.gid[row]))
            if j < len(before[0]) and before[0][j] == b.gid[row]:
                speed0 = float(np.linalg.norm(before[1][j]))
        out.append({"gid": int(b.gid[row]), "force": float(size[i]),
                    "weight": float(b.mass[row] * np.linalg.norm(g)),
                    "speed": float(np.linalg.norm(v)), "speed0": speed0,
                    "down": float(v @ down), "drop": float((b.x[row] - b.x0[row]) @ down),
                    "contacts": int(len(mine)), "partner": partner, "slipping": slip})
    return out, int((size > threshold).sum())


def _pace(c: dict, steps: int) -> str:
    """'steady', 'speeding up' or 'slowing down', from the speed ``steps`` steps ago (the
    last improvement; unknown for a block that came from another rank since)."""
    v, v0 = c["speed"], c["speed0"]
    if math.isnan(v0):
        return ""
    if abs(v - v0) <= STEADY * max(v, v0):
        return " at a steady speed"
    return (f", {'speeding up' if v > v0 else 'slowing down'} from {v0:.3g} m/s {steps} steps "
            "before")


def _doing(s, c: dict, steps: int) -> str:
    """What block ``c`` does, in words."""
    name = f"block {s.specs[c['gid']].name!r}"
    if c["contacts"] == 0:
        if c["down"] > 0.0:
            return (f"{name} is falling with no contacts at {c['speed']:.3g} m/s, "
                    f"{c['drop']:.3g} m below where it started")
        return f"{name} is moving with no contacts at {c['speed']:.3g} m/s"
    on = f"block {s.specs[c['partner']].name!r}"
    if c["slipping"]:
        return f"{name} is sliding on {on} at {c['speed']:.3g} m/s{_pace(c, steps)}"
    frac = c["force"] / c["weight"] if c["weight"] > 0 else math.inf
    return (f"{name} is not at rest on {on} (unbalanced force {c['force']:.3g} N, "
            f"{frac:.2g} of its weight; {c['speed']:.3g} m/s)")


def _damping_mode(s) -> str:
    """The damping mode of the solve in progress (the stage's, else the scene's)."""
    st = s.scene.stages[s.stage].solve if s.scene.stages else None
    d = st.damping if st is not None and st.damping is not None else s.scene.solve.damping
    return d.mode


def _remedies(named: list[dict], damping: str) -> str:
    """The scene keys that help with what the named blocks do (``damping``: the solve's)."""
    tips = []
    if any(c["contacts"] == 0 for c in named):
        tips.append("a domain: (blocks that leave it are taken out of the model)")
    if any(c["slipping"] for c in named):
        tips.append("stronger joints for the equilibrium stage (stages[k].joints: friction, "
                    "cohesion), the real strength in a later stage")
    if damping == "none":
        tips.append("damping (solve.damping: local; it is none)")
    elif not tips:
        tips.append(f"more damping (solve.damping.alpha; it is {damping})")
    tips.append("a larger solve.no_progress_steps if the model is still settling")
    return "what helps: " + ", ".join(tips)


def solves_to_a_ratio(scene) -> bool:
    """Whether the scene or one of its stages solves to a ratio (what this plugin watches)."""
    return scene.solve.ratio is not None or any(
        st.solve is not None and st.solve.ratio is not None for st in scene.stages)


PLUGINS.register("no-progress", PluginEntry(
    72, lambda state, output, made: NoProgress(state) if solves_to_a_ratio(state.scene)
    else None))
