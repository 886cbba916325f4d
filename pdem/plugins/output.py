"""Snapshots of the blocks and block histories in the run's output file (``output:``)."""

from __future__ import annotations

import json
import logging
import math

import numpy as np

from .. import __version__
from ..config.errors import ConfigError
from ..config.schema import MassScaling
from ..contact.laws import FAILED
from ..errors import writing
from ..io.checkpoint import written_contacts
from ..io.joints import CONTACT_FIELDS, SUB_FIELDS
from ..io.layout import writer_range
from ..io.surfaces import body_surfaces
from ..io.writer import OutputWriter, quat_to_matrix
from ..memory import mapping_large_blocks
from ..model.fields import OUTPUT
from ..mpi import allgather, allreduce_sum_array
from ..resolve import mass_scaling_summary
from ..selection import timestep_rows
from .base import PLUGINS, Plugin, PluginEntry, interval_steps, next_multiple

log = logging.getLogger("pdem")


def owned_zoned(grids) -> list | None:
    """The zoned blocks this rank owns as ``(gid, body)`` pairs for the writer (None: a scene
    without zoned blocks). With zoned blocks on several ranks (``GridStore.n_owned``) the first
    ``n_owned`` bodies are the owned ones, the rest ghost copies that are not written."""
    if grids is None:
        return None
    n = getattr(grids, "n_owned", len(grids.bodies))
    return [(int(grids.gids[d]), grids.bodies[d]) for d in range(n)]


def _static_fields(state) -> dict:
    """The writer's initial centroids, groups and fixed flags: its gid range's, taken at
    set-up (``ModelState.writer_static``), or every block's from the scene's store."""
    if state.writer_static is None:
        g = state.glob
        return {"initial_centroid": g.x0, "group": g.group, "fixed": g.fixed}
    lo, hi = writer_range(state.comm, state.glob.n)
    x0, group = state.writer_static
    return {"initial_centroid": x0, "group": group, "fixed": state.glob.fixed[lo:hi],
            "ranged": True}


def _mass_scaling_attrs(state) -> dict:
    """Root attributes of partial mass scaling: the step it sets and the inertia it added
    (pdem.resolve.mass_scaling_summary). Runs without stages only: a stage sets its
    own scaling at its start (and a restart's factors may be a stage's), which the log
    reports."""
    ms = state.scene.solve.mass_scaling
    if not isinstance(ms, MassScaling) or state.scene.stages:
        return {}
    rows, n = timestep_rows(state)  # each rank its own blocks', summed over the ranks
    r = mass_scaling_summary(rows, state.comm, n)
    g = r["max_block"]
    return {"mass_scaling_timestep": ms.timestep, "mass_scaled_blocks": r["blocks"],
            "mass_scaling_added_mass": r["added_mass"],
            "mass_scaling_added_percent": r["added_percent"],
            "mass_scaling_max_factor": r["max_factor"],
            "mass_scaling_max_block": state.specs[g].name if g >= 0 else ""}


def bonded_joints(joints) -> np.ndarray:
    """Per joint row, whether it has a bond to lose (tension or cohesion > 0)."""
    return np.array([any(float(getattr(p, k, 0.0) or 0.0) > 0.0 for k in ("tension", "cohesion"))
                     for p in joints.params] or [False], bool)


def contact_rows(state, bonded: np.ndarray) -> dict:
    """This rank's share of the contacts for a snapshot: each contact once over the ranks (the
    checkpoints' rule), those with sub-contacts only. World sub-contact points are
    ``x_A + R(q_A) p_A`` (explicit sums: the same bits on every rank). A FAILED bit is kept
    only on joints with a bond (the contact detection marks a joint that forms open as
    failed, "no bond", whatever its law). Normal forces are the law's for the stored state
    (:func:`pdem.contact.forces.normal_forces`). The columns written as stored come by field
    name (pdem.io.joints.OutputColumn ``field``)."""
    c = state.contacts
    keep = np.nonzero(written_contacts(state) & (np.diff(c.sc_start) > 0))[0]
    return _contact_dict(state, bonded, keep)


class SnapshotContacts:
    """This rank's share of a snapshot's contacts as the writer streams them
    (:class:`pdem.io.contact_series.ContactSource`): :func:`contact_rows`' contacts, each
    round's rows made when the writer asks for them, so that no rank holds every contact's
    output rows at once (issue 39: they were most of the output's memory). Held for the
    snapshot: 12 bytes a contact written (int32 row, block A, sub-contact count)."""

    def __init__(self, state, bonded: np.ndarray) -> None:
        c = state.contacts
        self.state, self.bonded = state, bonded
        self.keep = np.flatnonzero(written_contacts(state) & (np.diff(c.sc_start) > 0)
                                   ).astype(np.int32)
        self.block_a = c.ga[self.keep]
        self.n_sub = np.diff(c.sc_start)[self.keep].astype(np.int32)
        self.n_subs = int(self.n_sub.sum())

    def rows(self, idx: np.ndarray) -> dict:
        """The contacts ``idx`` (of those this rank writes) in the writer's dict format."""
        return _contact_dict(self.state, self.bonded, self.keep[idx])


def _contact_dict(state, bonded: np.ndarray, keep: np.ndarray) -> dict:
    """:func:`contact_rows` of the contacts ``keep`` (rows of the store)."""
    c = state.contacts
    sel = c.take(keep)
    nsub = np.diff(sel.sc_start)
    # each sub-contact's force by its own law and state: the taken ones' alone, the same bits
    fn = sel.normal_forces(state.joints.kernel_args)
    b = state.blocks
    # each contact's rotation, taken by its sub-contacts (one matrix a sub-contact was 72 bytes
    # each of a round's sub-contacts); the same element-wise sums as before
    R = quat_to_matrix(b.q[sel.ia])
    of = np.repeat(np.arange(len(nsub)), nsub)
    pa = sel.sc_pa
    point = b.x[sel.ia][of] + (R[of, :, 0] * pa[:, 0:1] + R[of, :, 1] * pa[:, 1:2]
                               + R[of, :, 2] * pa[:, 2:3])
    del R, of
    bits = sel.sc_state.astype(np.int64)  # the output's int64 (the store's uint8)
    joint = np.repeat(sel.joint, nsub)
    bits[~bonded[joint]] &= ~FAILED
    return {
        # the output's int64 (the store's int32)
        "piece": np.stack([sel.pga, sel.pgb], axis=1).astype(np.int64),
        "block": np.stack([sel.ga, sel.gb], 1).astype(np.int64),
        **{name: sel.arrays[field] for name, field in CONTACT_FIELDS}, "n_sub": nsub,
        "sub": {"point": point, "normal_force": fn, "state": bits,
                **{name: sel.sub[field] for name, field in SUB_FIELDS}},
    }


def planned_steps(scene, dt: float) -> tuple[float, str] | None:
    """The steps the scene's ends fix in advance at the step ``dt`` (``solve.time`` or
    ``solve.steps``, or the stages' together, each capped by its ``max_steps``) and the keys
    they come from; None when none does (solves to a ratio, factor-of-safety searches)."""
    ends = [("solve", scene.solve)] if not scene.stages else [
        (f"stages[{k}].solve", st.solve) for k, st in enumerate(scene.stages)
        if st.solve is not None]
    total, keys = 0.0, []
    for key, sv in ends:
        if sv.time is not None:
            steps, keys = sv.time / dt, [*keys, f"{key}.time = {sv.time:g} s"]
        elif sv.steps is not None:
            steps, keys = float(sv.steps), [*keys, f"{key}.steps = {sv.steps}"]
        else:
            continue
        total += min(steps, sv.max_steps or math.inf)
    return (total, ", ".join(keys)) if keys else None


def check_snapshot_count(scene, dt: float, every: int) -> None:
    """Refuse a scene whose ends fix more snapshots (one every ``every`` steps, and the first)
    than ``limits.max_snapshots``, naming the interval's key and the interval that fits (every
    rank alike: the scene and dt are the same on every rank)."""
    limit = scene.limits.max_snapshots
    planned = planned_steps(scene, dt)
    if limit is None or planned is None:
        return
    steps, ends = planned
    count = int(steps // every) + 1
    if count <= limit:
        return
    out = scene.output
    key = (f"output.every = {out.every:g} s" if out.every is not None
           else f"output.every_steps = {out.every_steps}" if out.every_steps is not None
           else "output.every (default: 100 snapshots per scene run)")
    fits = max(1, math.ceil(steps / max(limit - 1, 1)))
    raise ConfigError([
        f"{key}: a snapshot every {every} step{'s' if every != 1 else ''} (dt = {dt:.4g} s) "
        f"over {ends} ({steps:.4g} "
        f"steps) is {count} snapshots, more than limits.max_snapshots = {limit}: give "
        f"output.every >= {fits * dt:.3g} s (or output.every_steps >= {fits}), or raise "
        "limits.max_snapshots"])


class Snapshots(Plugin):
    """Every ``output.every`` model seconds (or ``every_steps``) the owned blocks' output
    fields (pdem.model.fields, ``output=``) go to the HDF5 file; opened at construction.
    ``limits.max_snapshots``: a scene whose ends fix more is refused before the file is
    made; a solve to a ratio writes no periodic snapshot past it (the last state of each solve
    still is), with a warning."""

    name = "snapshots"

    def __init__(self, state):
        self.state = state
        out = state.scene.output
        self.every = interval_steps(state, out.every_steps, out.every)
        check_snapshot_count(state.scene, state.dt, self.every)
        self.limit = state.scene.limits.max_snapshots
        self.written = 0  # snapshots in this run's file
        self.last = None  # the step of the last one
        self.full = False  # the file holds limits.max_snapshots: no more periodic ones
        self.after_write = []  # callbacks run after each snapshot (histories flush)
        r = state.resolved
        self.contacts = bool(out.contacts)
        self.bonded = bonded_joints(state.joints)
        attrs = {"pdem_version": __version__, "scene_name": state.scene.name, "dt": state.dt,
                 "ctol": r.ctol, "run_id": state.run_id, "first_step": state.step,
                 "resolved": r.to_json()}
        attrs.update(_mass_scaling_attrs(state))
        self.writer = OutputWriter(
            out.file, state.comm, block_names=state.specs.names,
            block_parents=state.specs.parent_names(),
            body_mesh=state.writer_mesh if state.writer_mesh is not None
            else body_surfaces(state.glob),
            scene_yaml=state.scene_yaml, **_static_fields(state),
            group_names=state.group_names,
            attrs=attrs,
            contacts=self.contacts, joint_names=state.joints.names,
            zones=owned_zoned(state.grids), zone_fields=out.zones.fields)

    def write(self):
        s = self.state
        b, n = s.blocks, s.n_owned
        # mapped: the snapshot's contact arrays too go back to the system when freed
        with s.timers.phase("io"), writing(self.writer.path), mapping_large_blocks():
            contacts = SnapshotContacts(s, self.bonded) if self.contacts else None
            self.writer.write_snapshot(s.step, s.time, b.gid[:n],
                                       {f.output: getattr(b, f.name)[:n] for f in OUTPUT},
                                       contacts=contacts, stage=s.stage,
                                       zones=owned_zoned(s.grids))
            if s.reinforcement is not None and s.reinforcement.n_nodes:
                self.writer.write_elements(s.reinforcement.snapshot(), s.reinforcement.entries_of())
            self.written += 1
            self.last = s.step
            for callback in self.after_write:
                callback()

    def _room(self) -> bool:
        """Whether a periodic snapshot may still be written (limits.max_snapshots)."""
        if self.limit is None or self.written < self.limit:
            return True
        if not self.full:
            s = self.state
            log.warning("output: %s holds limits.max_snapshots = %d snapshots at step %d; no "
                        "more periodic snapshots in this run (the last state of each solve is "
                        "still written): raise output.every (now every %d steps) or "
                        "limits.max_snapshots", self.writer.path, self.limit, s.step,
                        self.every)
            self.full = True
        return False

    def start(self, run):
        if self.state.step == 0:
            self.write()

    def after_step(self, run):
        if self.state.step % self.every == 0:
            if self._room():
                self.write()
            else:
                for callback in self.after_write:  # histories flush on the same schedule
                    callback()

    def horizon(self, run):
        return next_multiple(self.state.step, self.every), None

    def finish(self, run):
        if self.state.step % self.every != 0 or (self.full and self.last != self.state.step):
            self.write()

    def close(self):
        with writing(self.writer.path):
            self.writer.close()


class Histories(Plugin):
    """``output.histories``: a block's quantity, or a recording station's (a point: the
    gridpoint or rigid block :func:`station` finds), sampled every ``every`` model seconds (or
    every step), buffered by the owner and written with the snapshots. An ``acceleration``
    is the velocity's change over the step before the sample over the step: its velocities
    are followed every step on every rank (a sum over the ranks of the owner's, so the same
    bits whoever owns it, and after a restart, which starts from the restored velocities)."""

    name = "histories"
    QUANTITIES = {
        "displacement": lambda b, i: b.x[i] - b.x0[i],
        "position": lambda b, i: b.x[i],
        "velocity": lambda b, i: b.v[i],
        "angular_velocity": lambda b, i: b.w[i],
    }
    NODE_QUANTITIES = {
        "displacement": lambda g, i: g.nodes[i] - g.nodes0[i],
        "position": lambda g, i: g.nodes[i],
        "velocity": lambda g, i: g.vel[i],
    }

    def __init__(self, state, snapshots: Snapshots):
        self.state = state
        self.writer = snapshots.writer
        hs = state.scene.output.histories
        names = state.specs.names.positions(h.block for h in hs if h.block is not None)
        self.items = []
        for k, h in enumerate(hs):
            if h.block is not None:
                name, where = f"{h.block}.{h.quantity}", ("block", names[h.block])
                attrs = {"block": h.block, "quantity": h.quantity}
            else:
                where = station(state, h.point)
                name = f"point-{k}.{h.quantity}"
                attrs = {"point": np.asarray(h.point, float), "quantity": h.quantity,
                         "at": ("gridpoint" if where[0] == "node" else "block"),
                         "name": state.specs[where[1]].name}
                if where[0] == "node":
                    attrs["gridpoint"] = int(where[2])
            self.writer.add_history(name, 3, attrs)
            self.items.append((name, where, h.quantity, h.every))
        self.next_time = {it[0]: 0.0 for it in self.items}
        self.buffer = {it[0]: ([], []) for it in self.items}
        # the velocities of the acceleration items at the last step (every rank alike)
        self.accelerating = [it for it in self.items if it[2] == "acceleration"]
        self.last_v = None
        self.restored = False
        snapshots.after_write.append(self.flush)

    def _value(self, where, qty):
        """This rank's value of ``qty`` at ``where`` (None: another rank owns it)."""
        s = self.state
        if where[0] == "block":
            row = s.owned_row(where[1])
            return None if row < 0 else self.QUANTITIES[qty](s.blocks, row).copy()
        g = s.grids
        d = g.gids.index(where[1]) if g is not None and where[1] in g.gids[:g.n_owned] else -1
        if d < 0:
            return None
        return self.NODE_QUANTITIES[qty](g.bodies[d], where[2]).copy()

    def _velocities(self) -> np.ndarray:
        """The acceleration items' velocities now, on every rank (collective)."""
        out = np.zeros((len(self.accelerating), 3))
        for k, (_, where, _, _) in enumerate(self.accelerating):
            v = self._value(where, "velocity")
            if v is not None:
                out[k] = v
        return allreduce_sum_array(self.state.comm, out)

    def sample(self, force: bool = False):
        """Buffer the samples that are due."""
        s = self.state
        eps = 1e-9 * s.dt
        acc = None
        if self.accelerating:
            v = self._velocities()
            last = v if self.last_v is None else self.last_v
            acc = {it[0]: (v[k] - last[k]) / s.dt for k, it in enumerate(self.accelerating)}
            self.last_v = v
        for name, where, qty, every in self.items:
            if not (force or every is None or s.time >= self.next_time[name] - eps):
                continue
            if every is not None:
                while self.next_time[name] <= s.time + eps:
                    self.next_time[name] += every
            value = self._value(where, "velocity" if qty == "acceleration" else qty)
            if value is None:
                continue
            times, values = self.buffer[name]
            times.append(s.time)
            values.append(acc[name] if qty == "acceleration" else value)

    def flush(self):
        """Collective: the owner of each history's block writes its buffered rows."""
        with writing(self.writer.path):
            self._flush()

    def _flush(self):
        for name, where, _, _ in self.items:
            times, values = self.buffer[name]
            mine = self._value(where, "position") is not None
            self.writer.write_history(name, np.array(times), np.array(values).reshape(-1, 3)
                                      if mine else None)
            times.clear()
            values.clear()

    def start(self, run):
        if self.state.step == 0:
            self.sample(force=True)

    def after_step(self, run):
        self.sample()

    def horizon(self, run):
        s = self.state
        if self.accelerating or any(every is None for _, _, _, every in self.items):
            return s.step + 1, None  # sampled every step
        eps = 1e-9 * s.dt  # as sample() decides what is due
        return None, min((self.next_time[name] - eps for name, *_ in self.items),
                         default=None)

    def before_migration(self, run):
        self.flush()

    def finish(self, run):
        self.flush()

    def restart_state(self) -> dict:
        return {"history_next_time": json.dumps(self.next_time),
                "history_stations": json.dumps({it[0]: list(it[1]) for it in self.items})}

    def restore(self, attrs: dict):
        if "history_next_time" in attrs:
            saved = json.loads(attrs["history_next_time"])
            self.next_time.update({k: v for k, v in saved.items() if k in self.next_time})
        if "history_stations" in attrs:  # the straight run's stations
            saved = json.loads(attrs["history_stations"])
            self.items = [(n, tuple(saved.get(n, w)), q, e) for n, w, q, e in self.items]
            self.accelerating = [it for it in self.items if it[2] == "acceleration"]


def station(state, point) -> tuple:
    """A recording station's target (collective, every rank alike): ``("node", gid, i)``, the
    gridpoint ``i`` of zoned block ``gid`` nearest to ``point`` on the grids' reference
    positions, among the zoned blocks whose reference box (padded by a thousandth of its
    size) holds the point; else ``("block", gid)``, the rigid block whose centroid is nearest
    now (at the run's start: a restart keeps the run's, :meth:`Histories.restore`). Ties go
    to the lower gid."""
    p = np.asarray(point, float)
    g = state.grids
    mine = []
    if g is not None:
        for d in range(g.n_owned):
            x = g.bodies[d].nodes0
            lo, hi = x.min(axis=0), x.max(axis=0)
            pad = 1e-3 * float(np.linalg.norm(hi - lo))
            if np.all(p >= lo - pad) and np.all(p <= hi + pad):
                dist = np.linalg.norm(x - p, axis=1)
                i = int(np.argmin(dist))
                mine.append((float(dist[i]), int(g.gids[d]), i))
    found = [c for part in allgather(state.comm, mine) for c in part]
    if found:
        _, gid, i = min(found)
        return ("node", gid, i)
    gl = state.glob
    zoned = np.zeros(len(gl.x), bool)
    if g is not None:
        zoned[[gid for part in allgather(state.comm, list(g.gids[:g.n_owned]))
               for gid in part]] = True
    live = np.nonzero(~zoned)[0]
    dist = np.linalg.norm(gl.x[live] - p, axis=1)
    return ("block", int(live[int(np.argmin(dist))]))


PLUGINS.register("snapshots", PluginEntry(
    40, lambda state, output, made: Snapshots(state) if output else None))
PLUGINS.register("histories", PluginEntry(
    60, lambda state, output, made: Histories(state, made["snapshots"]) if "snapshots" in made
    else None))
