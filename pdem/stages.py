"""Staged runs (``stages:``): model changes, then a solve or a factor-of-safety search, stage
after stage, as a 3DEC user scripts them (equilibrium, excavation, loading, strength).

A stage's changes are declarative (joint properties, fixed/free blocks, prescribed velocities,
loads, the stage's solve settings), so a restart from a stage checkpoint replays the changes
of the stages before it on the rebuilt model and goes on: the replay sets exactly what the
straight run had set. Excavations were cut when the model was built (pdem.model.rockmass);
their inside blocks are deleted when the stage starts.
"""

from __future__ import annotations

import json
import logging
import math

import numpy as np

from .boundary import apply_conditions
from .config import ConfigError
from .config.stages import stage_scene
from .contact.laws import joint_table
from .deformable.conditions import gridpoints, owned_count, spread_force, zoned_mask
from .domain import DELETED, remove_blocks
from .dynamics.damping import DAMPING
from .dynamics.inactive import wake_all
from .parallel.migrate import hand_over_contacts
from .plugins.checkpoints import stage_checkpoint
from .reinforce import element_step, install_elements
from .resolve import damping_alpha, estimated_stiffness, scene_timestep, timestep_report
from .selection import selected, set_block_fields, timestep_rows
from .strength import factor_of_safety

log = logging.getLogger("pdem")


def stage_changes(s, k: int, motion: bool = True) -> None:
    """Stage ``k``'s changes of the model's static data (joints, fixed/free, prescribed
    velocities, loads, solve settings), on every rank alike. ``motion``: also set the
    prescribed velocities themselves (a restart takes them from its checkpoint)."""
    st = s.scene.stages[k]
    staged = stage_scene(s.scene, k)
    s.joints = joint_table(staged, s.group_names)
    zoned = s.grids is not None
    for key, sel, fixed in (("fix", st.fix, 1), ("free", st.free, 0)):
        if sel is None:
            continue
        gids = selected(s, sel)
        hit = 0
        if zoned:  # zoned blocks: their gridpoints (in range) held or released
            gids = gids[~zoned_mask(s, gids)]
            hits = gridpoints(s, sel)
            hit = owned_count(s, hits)
            # (the energy budget books the kinetic energy this moves in or out of the
            # prescribed components once it has started; a restart's replay is overwritten
            # by the checkpoint's grids)
            started = s.energy_start is not None
            if fixed:
                s.boundary.grid.fix(hits, (0, 1, 2), np.zeros(3), motion, book=motion and started)
            else:
                s.boundary.grid.free(hits, book=started)
        if not len(gids) and not hit:
            raise ConfigError([f"{s.scene.at('stages', k, key)}: selects no block"])
        set_block_fields(s, gids, fixed=fixed, vfix=0)
        s.boundary.release(gids)
        if fixed and motion:
            set_block_fields(s, gids, v=0.0, w=0.0, L=0.0)
    # (the zoned rows' fixed flags follow their grids at its end)
    apply_conditions(s, st, ("stages", k), s.stage_times.get(k, s.time), motion)
    for j, pf in enumerate(st.force):
        gids = selected(s, pf)
        if not len(gids):
            raise ConfigError([f"{s.scene.at('stages', k, 'force', j)}: selects no block"])
        if zoned:  # spread over the gridpoints of each zoned block selected
            on = zoned_mask(s, gids)
            g = s.grids
            pushed = set(gids[on].tolist())
            spread_force([(d, g.bodies[d], None) for d in range(len(g)) if g.gids[d] in pushed],
                         pf.force)
            gids = gids[~on]
        set_block_fields(s, gids, applied_force=pf.force)
    _solve_settings(s, staged, k, report=motion)
    s.stage = k


def replay_stages(s, attrs: dict) -> None:
    """Before a staged run's checkpoint is restored: the static changes of every stage it
    had made (done ones, and the one in progress), so that the restored contacts and halo
    are those of the same model (a block freed by a stage keeps its contacts)."""
    done = int(attrs.get("stage_next", 0))
    started = int(attrs.get("stage_started", -1))
    if "stage_times" in attrs:  # when each stage began: the time of its velocity histories
        s.stage_times = {int(k): float(t) for k, t in json.loads(attrs["stage_times"]).items()}
    for k in range(max(done, started + 1)):
        stage_changes(s, k, motion=False)


def apply_stage(run, k: int) -> None:
    """Start stage ``k`` (collective): its excavations, its changes, the contacts they make."""
    s = run.state
    st = s.scene.stages[k]
    gone = s.specs.excavated_by_stage(k)
    s.stage_times[k] = s.time
    if len(gone):
        remove_blocks(s, run.stepper.bodies(), gone, DELETED,
                      f"excavated (stages[{k}] {st.name!r})")
    held = s.glob.fixed.copy()
    stage_changes(s, k)
    freed = np.nonzero((held != 0) & (s.glob.fixed == 0) & (s.glob.out != DELETED))[0]
    s.ratio = math.inf  # the last stage's equilibrium says nothing about this one
    if st.reset_displacements:
        n = s.n_owned
        s.blocks.x_stage[:n] = s.blocks.x[:n]
    if len(freed):  # their owners compute all their contacts now: they get those they lack
        s.contacts = hand_over_contacts(s.comm, s.decomp, s.blocks, s.contacts, freed)
        s.redistribute()  # (rows renumbered: the rebalance below weighs the contacts)
    s.rebalance()  # excavated blocks weigh nothing now (balance: rcb)
    s.redistribute()  # fixed/free changed who is computed where, and the halo plan
    installed = s.reinforcement is not None and install_elements(s, stage_scene(s.scene, k), k)
    wake_all(s)
    # contacts between two freed blocks (none are kept between fixed blocks): found now,
    # not once they have sunk into each other (the geometry update would then make energy)
    run.stepper.search(np.ones(s.blocks.n, bool))
    run.stepper.refresh(all_contacts=False)
    if len(freed) or installed or (s.grids is not None and len(gone)):
        # the forces of the stage's first step: a freed block's row held only the contacts
        # its owner computed while it was fixed (on one rank: all of them); new elements'
        # (a pretension); the grids' without the excavated blocks' contacts (else the walls
        # of a tunnel excavated in zoned rock are held one step more, and that step's ratio,
        # still the equilibrium's, ended the stage at once)
        run.stepper.restate_forces()


def _solve_settings(s, staged, k: int, report: bool = True) -> None:
    """Timestep, mass scaling and damping of a stage (every rank alike). The mass-scale
    factors are recomputed from the stage's joints and fixed/free blocks, on every rank
    alike; a restart replays this (:func:`replay_stages`), so they need no checkpoint."""
    rows, n = timestep_rows(s)
    rows.mscale[:] = 1.0
    zoned = zoned_mask(s, rows.gid) if s.grids is not None else None
    if zoned is not None and staged.solve.mass_scaling:
        # the grids are scaled to the rigid step, which counts a zoned block as a free
        # block (held at its gridpoints it still steps its grid); without mass scaling the
        # rigid step leaves the zoned blocks out (pdem.resolve.scene_timestep)
        rows.fixed = np.where(zoned, 0, rows.fixed).astype(rows.fixed.dtype)
    stiffness = estimated_stiffness(s.specs, s.joints, rows.gid)
    names = s.specs.names  # read by index, in messages
    st = s.scene.stages[k].solve
    key = s.scene.at("stages", k, "solve", "mass_scaling", "timestep") \
        if st is not None and st.mass_scaling is not None else "solve.mass_scaling.timestep"
    s.dt = scene_timestep(staged, rows, stiffness, names, key, s.comm, n, zoned)
    if report:
        for line in timestep_report(staged, rows, stiffness, s.dt, names, s.comm, n, zoned):
            log.info("stage %d: %s", k + 1, line)
    element_step(s, staged)  # the installed elements' nodes
    d = staged.solve.damping
    s.damping = DAMPING[d.mode]
    s.damping_name = d.mode
    s.alpha = damping_alpha(d, s.alpha)
    if s.grids is not None:  # the grids' damping, masses and step for the stage
        rigid = s.dt
        s.dt = s.grids.restage(staged, rigid, s.alpha, s.comm)
        if report and s.dt < rigid and s.comm.rank == 0:
            log.info("stage %d: %s", k + 1, s.grids.limit_line(rigid))


def run_stages(run) -> list[dict]:
    """Every stage not yet done (collective); a checkpoint after each. A restarted run had
    its earlier stages' changes replayed before its checkpoint was restored
    (:func:`replay_stages`) and continues a stage in progress where it stopped."""
    s = run.state
    stages = s.scene.stages
    summaries = []
    for k in range(s.stage_next, len(stages)):
        st = stages[k]
        resumed = s.stage_started == k
        log.info("stage %d/%d %r %s at step %d (t = %.6g s)", k + 1, len(stages), st.name,
                 "resumed" if resumed else "starts", s.step, s.time)
        if not resumed:
            apply_stage(run, k)
            s.stage_started, s.stage_t0, s.stage_step0 = k, s.time, s.step
        if st.factor_of_safety is not None:
            summary = factor_of_safety(run, k)
        else:
            sv = st.solve
            summary = run.run(
                time=None if sv.time is None else s.stage_t0 + sv.time - s.time,
                steps=None if sv.steps is None else s.stage_step0 + sv.steps - s.step,
                ratio=sv.ratio, max_steps=sv.max_steps, no_progress=sv.no_progress_steps)
        summary["stage"] = st.name
        summaries.append(summary)
        if summary.get("stopped"):
            return summaries
        s.stage_next = k + 1
        stage_checkpoint(run, k)
    return summaries
