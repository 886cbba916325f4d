"""Factor of safety by strength reduction (a stage with ``factor_of_safety:``), as 3DEC's
``model factor-of-safety``.

From the equilibrium state the stage starts in, trial solves run with every joint's strength
divided by F: the parameters each joint law declares (``JointLaw.strength``), angles through
their tangents (``tan(friction) / F``), strengths divided (``cohesion / F``, ``tension / F``);
with every joint (no ``joints`` list), the zoned blocks' zones alike (a Mohr-Coulomb
material's cohesion, tan(friction) and tension; elastic zones unchanged: 3DEC's and FLAC3D's
strength reduction).
A trial is **stable** when the unbalanced-force ratio falls below ``ratio`` within
``max_steps`` and no block moved more than ``max_displacement``; when
the ratio has not fallen by then, it is stable if the motion died away (the largest
displacement grew by at most half as much in the second half of the budget as in the first)
and **unstable** if it went on (a sliding mechanism); beyond ``max_displacement`` it is
unstable. F = 1 must be stable (else the model is not in equilibrium and the search
is refused); the factor of safety is bracketed by bisection between the largest stable and the
smallest unstable F until their gap is below ``tolerance`` (relative). Every trial starts from
the same state (held in memory on each rank: the blocks, contacts and the zoned blocks'
grids) and the model goes on from it, at F = 1, after the search.

Results: the log line, the output file's root attribute ``factor_of_safety`` and the group
``factor_of_safety/`` (trials, the failure mechanism: the displacement field of the last
unstable trial, and per block the largest F at which it was not part of a mechanism (moved
less than a tenth of the most any block moved): a safety map).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from . import mpi
from .config.stages import stage_scene
from .contact.laws import JOINT_LAWS, joint_table
from .distribute import distribute
from .errors import UserError
from .model.blocks import take_rows
from .model.fields import MIGRATE
from .plugins.checkpoints import stop_checkpoint

log = logging.getLogger("pdem")


def reduced_joints(joints: dict, factor: float, names=None) -> dict:
    """The scene's joints with their strength divided by ``factor`` (``names``: only these):
    the parameters each joint's law declares (``JointLaw.strength``), angles through their
    tangents, strengths divided. A joint whose law declares no strength is a UserError."""
    out = {}
    for name, j in joints.items():
        if names is not None and name not in names:
            out[name] = j
            continue
        law = JOINT_LAWS[j.model]
        strength = law.strength
        if strength is None or not (strength.angles or strength.strengths):
            raise UserError(
                f"joints.{name}: no factor of safety with this joint: its law {law.name!r} "
                "declares no strength to reduce (JointLaw.strength); name the joints to weaken "
                "in factor_of_safety.joints, without this one, or declare the law's strength")
        out[name] = j.model_copy(update=strength.reduced(j, factor))
    return out


class _Snapshot:
    """The state a search starts every trial from (this rank's share)."""

    def __init__(self, s):
        b, n = s.blocks, s.n_owned
        self.gids = b.gid[:n].copy()
        self.rows = {k: getattr(b, k)[:n].copy() for k in MIGRATE}
        self.contacts = s.contacts.take(np.arange(s.contacts.n))
        self.clock = (s.step, s.time, s.ratio, s.alpha)
        self.glob = {k: getattr(s.glob, k).copy() for k in ("fixed", "out")}
        # the owned blocks' geometry: a trial's migration may take them to other ranks, and
        # no rank keeps the geometry of blocks it does not hold (the zoned pieces' planes
        # made from their vertices first)
        if s.grids is not None:
            s.grids.fresh_planes(b)
        self.store = take_rows(b, np.arange(n), np.ones(n, np.uint8))
        # the owned zoned blocks' grids (gridpoints, zone stresses, plastic state, ...)
        self.grids = s.grids.saved() if s.grids is not None else None
        # the reinforcement (every rank holds it whole): not weakened, but loaded by a trial
        self.elements = s.reinforcement.held() if s.reinforcement is not None else None

    def restore(self, s):
        for k, v in self.glob.items():
            getattr(s.glob, k)[:] = v
        s.step, s.time, s.ratio, s.alpha = self.clock
        if self.grids is not None:  # they travel with their blocks to the owners
            s.grids = s.grids.restored(self.grids)
        distribute(s, self.gids, {k: v.copy() for k, v in self.rows.items()},
                   self.contacts.take(np.arange(self.contacts.n)), source=self.store)
        if self.elements is not None:
            s.reinforcement.put_back(self.elements)


def _displacements(s, snap: _Snapshot) -> np.ndarray:
    """(n_blocks, 3) displacement of every block since the search began (every rank)."""
    b, n = s.blocks, s.n_owned
    start = dict(zip(snap.gids.tolist(), range(len(snap.gids)), strict=True))
    d = np.zeros((s.glob.n, 3))
    rows = [start.get(int(g), -1) for g in b.gid[:n]]
    for r, (g, i) in enumerate(zip(b.gid[:n], rows, strict=True)):
        if i >= 0:
            d[g] = b.x[r] - snap.rows["x"][i]
    return mpi.allreduce_sum_array(s.comm, d)


def _trial(run, factor: float, fos, snap: _Snapshot, base_scene):
    """One trial at ``factor``: (stable, steps, ratio, displacement field)."""
    s = run.state
    snap.restore(s)
    scene = base_scene.model_copy(update={"joints": reduced_joints(base_scene.joints, factor,
                                                                   fos.joints)})
    s.joints = joint_table(scene, s.group_names)
    if s.grids is not None and fos.joints is None:  # the whole model's strength
        s.grids.weaken(factor)
    s.ratio = math.inf
    stable = False
    half = None  # the largest displacement half way through the step budget
    too_far = False
    # the steps run in compiled runs between the marks the trial looks at: the first 10 steps
    # (the ratio is not judged before), every 200th (max_displacement) and the half-way step
    marks = sorted(m for m in {10, fos.max_steps // 2, fos.max_steps,
                               *range(200, fos.max_steps, 200)} if 0 < m <= fos.max_steps)
    steps = 0
    for mark in marks:
        if mark <= steps:
            continue
        steps += run.march(mark - steps, ratio=fos.ratio if steps >= 10 else None)
        if run.stepper.stop_signal:
            break
        if steps >= 10 and s.ratio <= fos.ratio:
            stable = True
            break
        if steps == fos.max_steps // 2:
            half = np.linalg.norm(_displacements(s, snap), axis=1).max()
        if steps % 200 == 0 and fos.max_displacement is not None:
            if np.linalg.norm(_displacements(s, snap), axis=1).max() > fos.max_displacement:
                too_far = True
                break
    d = _displacements(s, snap)
    end = np.linalg.norm(d, axis=1).max()
    if fos.max_displacement is not None and end > fos.max_displacement:
        too_far = True
    if not stable and not too_far and half is not None and steps >= fos.max_steps:
        # the ratio did not fall in time: still failing if the motion went on growing (a
        # sliding block: the displacement of the second half exceeds half that of the first),
        # settling if it died away (a creeping approach to equilibrium)
        stable = end - half <= 0.5 * half
    stable = stable and not too_far
    log.info("factor of safety trial F = %.4f: %s after %d steps (ratio %.3g, largest "
             "displacement %.3g m)", factor, "stable" if stable else "unstable", steps, s.ratio,
             np.linalg.norm(d, axis=1).max())
    size = np.linalg.norm(d, axis=1)
    # the mechanism of an unstable trial: the blocks that moved a tenth of the most any block
    # did, however slowly they go near the factor of safety
    moved = size > 0.1 * size.max() if not stable else np.zeros(len(d), bool)
    return stable, steps, d, moved


def factor_of_safety(run, k: int) -> dict:
    """The search of stage ``k`` (collective); returns the run summary with ``factor``."""
    s = run.state
    fos = s.scene.stages[k].factor_of_safety
    where = s.scene.at("stages", k, "factor_of_safety")
    base_scene = stage_scene(s.scene, k)
    snap = _Snapshot(s)
    trials = []
    safety = np.zeros(s.glob.n)
    mechanism = np.zeros((s.glob.n, 3))

    def trial(f):
        stable, steps, d, moved = _trial(run, f, fos, snap, base_scene)
        trials.append((f, float(stable), steps))
        if not stable:
            mechanism[:] = d
        np.maximum(safety, np.where(moved, 0.0, f), out=safety)
        return stable

    stopped = 0
    lo, hi = 1.0, fos.high
    if trial(1.0):
        factor, bounded = (hi, False) if trial(hi) else (None, True)
    elif fos.low is None:
        snap.restore(s)
        raise UserError(f"{where}: the model is not in equilibrium at F = 1 (the ratio stays "
                        f"above {fos.ratio:g} for {fos.max_steps} steps): bring it to "
                        "equilibrium in an earlier stage, or give factor_of_safety.low (< 1) "
                        "to search below 1 (a study's cases that may fail)")
    else:  # a model that fails at its own strength: the factor is below 1
        lo, hi = fos.low, 1.0
        factor, bounded = (None, True) if trial(lo) else (lo, False)
    if factor is None:
        while hi - lo > fos.tolerance * lo and not run.stepper.stop_signal:
            mid = 0.5 * (lo + hi)
            if trial(mid):
                lo = mid
            else:
                hi = mid
        factor, bounded = 0.5 * (lo + hi), True
    stopped = run.stepper.stop_signal
    # the model goes on from the equilibrium state, at full strength
    snap.restore(s)
    s.joints = joint_table(base_scene, s.group_names)
    s.ratio = math.inf
    if bounded:
        log.info("%s: factor of safety %.4g (stable at %.4g, unstable at %.4g; %d trials)",
                 s.scene.stages[k].name, factor, lo, hi, len(trials))
    else:
        log.info("%s: factor of safety at %s %.4g (%s at factor_of_safety.%s; %d trials)",
                 s.scene.stages[k].name, "least" if factor > 1 else "most", factor,
                 "stable" if factor > 1 else "unstable", "high" if factor > 1 else "low",
                 len(trials))
    snaps = run.plugin("snapshots")
    if snaps is not None:
        snaps.writer.write_result("factor_of_safety", {
            "factor_of_safety": factor,
            "factor_of_safety_bounded": int(bounded),
            "factor_of_safety_stage": s.scene.stages[k].name,
        }, {"trials": np.array(trials, float).reshape(-1, 3),
            "mechanism": mechanism, "block_safety": safety}, surface=("block_safety",))
    summary = {"steps": sum(int(t[2]) for t in trials), "time": s.time, "ratio": s.ratio,
               "stopped": stopped, "checkpoint": None, "factor": factor, "bounded": bounded,
               "trials": trials, "mechanism": mechanism, "block_safety": safety}
    if stopped:
        summary["checkpoint"] = stop_checkpoint(run)
    return summary
