"""The energy budget of a run (3DEC keeps one): kinetic energy, spring energy stored in the
joints, work of gravity, applied forces and prescribed motions, energy dissipated in the joints
and by damping, and the balance error, sampled into the history ``energy``."""

from __future__ import annotations

import json
import logging

import numpy as np

from ..contact.forces import stored_energy
from ..contact.rigid import Bodies
from ..deformable.motion import (
    GW_APPLIED,
    GW_BOUNDARY,
    GW_CONTACT,
    GW_DAMPING,
    GW_GRAVITY,
    GW_PLASTIC,
    GW_QUIET,
    GW_ZONE,
)
from ..dynamics import motion
from ..dynamics.cables import CW_DAMPING, CW_GRAVITY, CW_SLIP, CW_YIELD
from ..dynamics.diagnosis import explain
from ..dynamics.energy import kinetic_per_block
from ..errors import SimulationError, writing
from ..model.fields import kernel_record
from ..mpi import allgather, exact_sum
from .base import PLUGINS, Plugin, PluginEntry, next_multiple

log = logging.getLogger("pdem")

COLUMNS = ("kinetic", "strain", "gravity_work", "applied_work", "boundary_work",
           "joint_dissipation", "damping_dissipation", "contact_work", "joint_created",
           "geometry_created", "removed", "zone_strain", "plastic_work", "quiet_absorbed",
           "reinforcement_strain", "reinforcement_dissipation", "balance_error")
# the accumulated works of COLUMNS[2:-1], as columns of the block field ``work``
WORK_COLUMNS = np.array([motion.WORK_GRAVITY, motion.WORK_APPLIED, motion.WORK_BOUNDARY,
                         motion.WORK_JOINT, motion.WORK_DAMPING, motion.WORK_CONTACT,
                         motion.WORK_JOINT_MADE, motion.WORK_GEOMETRY, motion.WORK_REMOVED])
# the zoned blocks' grids' works (pdem.deformable.motion.GW_*) and the COLUMNS they add to
GRID_COLUMNS = ((GW_GRAVITY, 2), (GW_APPLIED, 3), (GW_BOUNDARY, 4), (GW_DAMPING, 6),
                (GW_CONTACT, 7))


def energy_totals(state) -> dict[str, float]:
    """The model's energies now (collective; the same bits on any rank count).

    ``kinetic``: free blocks at t - dt/2 (inertial mass, as integrated), a zoned block's its
    free gridpoints'; ``strain``: stored in the joints' springs (in a scene with zoned blocks
    at t - dt/2, below and ``GridStore.energy_rows``); the rest accumulated since
    the start (pdem.model.fields ``work``, and a zoned block's grid's
    ``DeformableBody.work``): ``zone_strain`` the work done on the zones less
    ``plastic_work``, what their plastic flow dissipated.
    """
    b, n = state.blocks, state.n_owned
    free = (b.fixed[:n] == 0) & (b.vfix[:n] != motion.VFIX_ALL)
    per_block = np.empty((n, len(COLUMNS) - 1))
    per_block[:, 0] = np.where(free, kinetic_per_block(b, slice(0, n)), 0.0)
    part = np.nonzero(free & (b.vfix[:n] != 0))[0]
    if part.size:
        ke = per_block[:, 0]
        for k in range(3):  # prescribed components hold no kinetic energy (as integrated)
            r = part[(b.vfix[part] & (motion.VFIX_X << k)) != 0]
            ke[r] -= 0.5 * b.mass[r] * b.mscale[r] * b.v[r, k] ** 2
    strain = np.zeros(b.n)
    c = state.contacts
    stored_energy(kernel_record(Bodies, b), c.pairs(), c.subs(), state.joints.kernel_args,
                  strain)
    per_block[:, 1] = strain[:n]
    per_block[:, 2:11] = b.work[:n, WORK_COLUMNS]
    per_block[:, 11:] = 0.0
    per_block[:, 13] = b.work[:n, motion.WORK_QUIET]  # rigid blocks' quiet faces
    if state.grids is not None:
        # with zoned blocks, the joints' energy at the kinetic energy's time t - dt/2: it
        # falls at the rate -F_c . v, so dt/2 (F . v + M . w) of each free block's contact
        # force and moment is added (and of each gridpoint's, below). Rigid scenes keep the
        # whole-step value, their bounded O(dt) offset (docs/output.md)
        f, v, mo, w = b.force[:n], b.v[:n], b.moment[:n], b.w[:n]
        half = 0.5 * state.dt * (f[:, 0] * v[:, 0] + f[:, 1] * v[:, 1] + f[:, 2] * v[:, 2]
                                 + mo[:, 0] * w[:, 0] + mo[:, 1] * w[:, 1] + mo[:, 2] * w[:, 2])
        half[b.fixed[:n] != 0] = 0.0
        rows, ke, gw, shift = state.grids.energy_rows(state.dt)
        half[rows] = shift
        per_block[:, 1] += half
        per_block[rows, 0] = ke
        for k, col in GRID_COLUMNS:
            per_block[rows, col] += gw[:, k]
        per_block[rows, 11] = gw[:, GW_ZONE] - gw[:, GW_PLASTIC]
        per_block[rows, 12] = gw[:, GW_PLASTIC]
        per_block[rows, 13] = gw[:, GW_QUIET]
    sums = exact_sum(state.comm, per_block)
    totals = dict(zip(COLUMNS[:-1], sums.tolist(), strict=True))
    elements = state.reinforcement
    if elements is not None:  # (every rank holds the same elements: added alike)
        stored, ke, work = elements.energies()
        totals["kinetic"] += ke
        totals["gravity_work"] += float(work[CW_GRAVITY])
        totals["damping_dissipation"] += float(work[CW_DAMPING])
        totals["reinforcement_strain"] = stored
        totals["reinforcement_dissipation"] = float(work[CW_YIELD] + work[CW_SLIP])
    return totals


def balance(t: dict[str, float], e0: float) -> tuple[float, float]:
    """(balance error, energy put in): what is held plus what was dissipated, less what was
    there at the start and what was put in. Zero for an exact scheme."""
    put_in = e0 + t["gravity_work"] + t["applied_work"] + t["boundary_work"]
    held = t["kinetic"] + t["strain"] + t["joint_dissipation"] + t["damping_dissipation"] \
        + t["removed"] + t["zone_strain"] + t["plastic_work"] + t["quiet_absorbed"] \
        + t["reinforcement_strain"] + t["reinforcement_dissipation"]
    return held - put_in, put_in


class EnergyBudget(Plugin):
    """Samples the budget every ``output.energy_every`` steps (default: ten per snapshot
    interval) into ``histories/energy`` and logs it at the end of a march."""

    name = "energy"

    def __init__(self, state, snapshots=None):
        self.state = state
        self.writer = snapshots.writer if snapshots is not None else None
        every = state.scene.output.energy_every
        self.every = every or max(1, (snapshots.every if snapshots else 1000) // 10)
        self.tolerance = state.scene.solve.energy_tolerance
        # below this a balance error is round-off: a millionth of the model's weight times its
        # size (a model at rest has almost no energy to compare with)
        r = state.resolved
        size = float(np.linalg.norm(np.subtract(r.domain_hi, r.domain_lo)))
        self.floor = 1e-6 * r.ref_force * state.glob.n * size
        self.e0 = None
        if self.writer is not None:
            self.writer.add_history("energy", len(COLUMNS), {
                "columns": ",".join(COLUMNS), "units": "J",
                "balance": "kinetic + strain + joint_dissipation + damping_dissipation + "
                           "removed + zone_strain + plastic_work + quiet_absorbed + "
                           "reinforcement_strain + reinforcement_dissipation - (kinetic "
                           "+ strain at start) - gravity_work - applied_work - boundary_work"})
        self.times: list[float] = []
        self.rows: list[np.ndarray] = []
        self.last = None

    def sample(self):
        s = self.state
        t = energy_totals(s)
        if self.e0 is None:
            self.e0 = t["kinetic"] + t["strain"]
            s.energy_start = (t["kinetic"], t["strain"])
        err, put_in = balance(t, self.e0)
        before = self.last["balance_error"] if self.last is not None else err
        self.last = t | {"balance_error": err}
        scale = max(abs(put_in), t["kinetic"] + t["strain"], self.floor)
        if self.tolerance and err - before > self.tolerance * scale:
            self.flush()
            self._stop(err - before, put_in)
        if self.writer is not None:
            self.times.append(s.time)
            self.rows.append(np.array([self.last[k] for k in COLUMNS]))

    def _stop(self, jump: float, put_in: float):
        """The balance error jumped: name the fastest block and what made the energy."""
        s = self.state
        b, n = s.blocks, s.n_owned
        speed = np.linalg.norm(b.v[:n], axis=1) if n else np.zeros(0)
        mine = (float(speed.max()), -int(b.gid[int(speed.argmax())])) if n else None
        top = max(m for m in allgather(s.comm, mine) if m is not None)
        gid = -top[1]
        raise SimulationError(
            f"step {s.step} (t={s.time:.6g} s): the energy balance error grew by {jump:.3g} J "
            f"since the last sample ({100 * jump / max(abs(put_in), 1e-300):.2g}% of the energy "
            f"put in, above solve.energy_tolerance = {self.tolerance:g}); fastest block "
            f"{s.specs[gid].name!r} at {top[0]:.3g} m/s." + explain(s, self.last, s.energy_start,
                                                                  gid))

    def flush(self):
        if self.writer is None:
            return
        mine = self.state.comm.rank == 0
        with writing(self.writer.path):
            self.writer.write_history("energy", np.array(self.times), np.array(
                self.rows).reshape(-1, len(COLUMNS)) if mine else None)
        self.times.clear()
        self.rows.clear()

    def start(self, run):
        if self.e0 is None or self.state.step == 0:
            self.sample()

    def after_step(self, run):
        if self.state.step % self.every == 0:
            self.sample()
            if len(self.rows) >= 256:
                self.flush()

    def horizon(self, run):
        return next_multiple(self.state.step, self.every), None

    def finish(self, run):
        if self.state.step % self.every != 0:
            self.sample()
        self.flush()
        t = self.last
        if t is None:  # a restart from the run's last checkpoint: no step marched, no sample
            return
        err, put_in = balance(t, self.e0)
        log.info("energy (J): kinetic %.4g, in joints %.4g; work of gravity %.4g, applied %.4g, "
                 "prescribed motion %.4g; dissipated in joints %.4g, by damping %.4g; balance "
                 "error %.3g (%.2g%% of %.4g put in)", t["kinetic"], t["strain"],
                 t["gravity_work"], t["applied_work"], t["boundary_work"],
                 t["joint_dissipation"], t["damping_dissipation"], err,
                 100.0 * abs(err) / max(abs(put_in), 1e-300), put_in)
        if self.state.grids is not None:
            log.info("energy (J) of the zoned blocks' zones: work done on them %.4g, of which "
                     "plastic %.4g", t["zone_strain"] + t["plastic_work"], t["plastic_work"])

    def on_failure(self, run):
        self.flush()

    def restart_state(self) -> dict:
        return {"energy_start": json.dumps(self.state.energy_start)}

    def restore(self, attrs: dict):
        if "energy_start" in attrs:
            start = json.loads(attrs["energy_start"])
            if start is not None:
                self.state.energy_start = tuple(start)
                self.e0 = start[0] + start[1]


PLUGINS.register("energy", PluginEntry(
    70, lambda state, output, made: EnergyBudget(state, made.get("snapshots"))))
