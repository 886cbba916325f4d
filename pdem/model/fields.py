"""The one declaration of pdem's state: every block, contact and sub-contact field.

Each field says its trailing shape, dtype, units and where it travels:

* ``static``     built from the scene at set-up; sent with the block to a rank that did not
                 hold it (pdem.parallel.migrate);
* ``migrate``    moves with a block (or contact) to its new owner at a rebuild;
* ``checkpoint`` stored in checkpoints (always a subset of what migrates or is static);
* ``halo``       sent from a block's owner to its ghost copies every step;
* ``output``     the snapshot dataset name in the output file (``blocks/<output>``).

A field with none of these is per-rank scratch, (re)allocated with the store. The stores, the
halo, migration, checkpoints and snapshots are all driven by these tables: adding a field is
one line here. The kernels' records are filled from the stores by field name
(:func:`kernel_record`, :func:`kernel_columns`), and each main kernel declares the fields it
reads and writes (pdem.jit.access).
"""

from __future__ import annotations

import functools
import math
import operator
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Field:
    name: str
    shape: tuple[int, ...]
    dtype: type
    units: str
    doc: str
    static: bool = False
    migrate: bool = False
    checkpoint: bool = False
    halo: bool = False
    output: str | None = None
    # a point attribute of the centroid cloud in ParaView (run-centroids.xdmf), each snapshot
    # of blocks/<output> (pdem.io.xdmf); needs ``output``
    view: bool = False
    # the field's name in the kernels' records (pdem.dynamics.motion.Motion,
    # pdem.model.contacts.Subs, ...) where it is not its own (``applied_force`` is the motion
    # kernel's ``applied``, ``sc_un`` the sub-contact record's ``un``)
    kernel: str | None = None

    @property
    def width(self) -> int:
        """Number of scalars per row (read every step by the halo: math.prod, not np.prod's
        ~5 us)."""
        return math.prod(self.shape)


F, F32, I64, I32, I8, U8 = np.float64, np.float32, np.int64, np.int32, np.int8, np.uint8
_S = {"static": True}
_D = {"migrate": True, "checkpoint": True}

BLOCK: tuple[Field, ...] = (
    Field("gid", (), I64, "1", "global id: index of the block in the expanded scene", **_S),
    Field("owned", (), U8, "1", "1 for blocks this rank owns (rows [0, n_owned)), 0 for ghosts"),
    Field("x", (3,), F, "m", "centroid (world)", **_D, halo=True, output="centroid"),
    Field("q", (4,), F, "1", "orientation quaternion (w, x, y, z), body -> world", **_D,
          halo=True, output="orientation"),
    Field("v", (3,), F, "m/s", "velocity at t - dt/2", **_D, halo=True, output="velocity",
          view=True),
    Field("w", (3,), F, "rad/s", "angular velocity (world) at t - dt/2", **_D, halo=True,
          output="angular_velocity", view=True),
    Field("L", (3,), F, "kg m2/s", "angular momentum (world) at t - dt/2", **_D),
    Field("mass", (), F, "kg", "mass", **_S),
    Field("inertia", (3,), F, "kg m2", "principal moments (body frame = principal axes)", **_S),
    Field("mscale", (), F, "1", "inertial mass scale (static solves), 1 otherwise", **_S),
    Field("fixed", (), U8, "1", "1: the block never moves", **_S),
    Field("vfix", (), U8, "1", "prescribed velocity: 0 none, 1 velocity and angular velocity, "
          "else a mask of prescribed components 2 x, 4 y, 8 z (pdem.dynamics.motion.VFIX_*)",
          **_S),
    Field("material", (), I32, "1", "row in the scene's materials", **_S),
    Field("group", (), I32, "1", "row in the sorted group names", **_S),
    Field("applied_force", (3,), F, "N", "constant applied force", **_S, kernel="applied"),
    Field("radius", (), F, "m", "largest centroid-to-vertex distance", **_S),
    Field("x0", (3,), F, "m", "centroid at start (displacements)", **_S),
    Field("force", (3,), F, "N", "contact force sum of the current step", **_D),
    Field("moment", (3,), F, "N m", "contact moment sum about the centroid", **_D),
    Field("prev_force", (3,), F, "N", "last step's unbalanced force (combined damping)", **_D),
    Field("prev_moment", (3,), F, "N m", "last step's unbalanced moment", **_D),
    Field("u_acc", (), F, "m", "motion since the last remap (eq. 1)", **_D, halo=True),
    Field("u_geo", (), F, "m", "motion since the last periodic geometry update", **_D,
          halo=True),
    Field("u_mig", (), F, "m", "motion since the last ghost rebuild", **_D),
    Field("calm", (), I32, "1", "consecutive steps at rest; inactive from solve.inactive.steps "
          "(pdem.dynamics.inactive)", **_D),
    Field("still", (), U8, "1", "1: fixed or held inactive this step (derived from fixed and "
          "calm; what the integrator and the joints read); in the halo with solve.inactive",
          **_D, halo=True),
    Field("out", (), U8, "1", "taken out of the model (left the domain, excavated): 1 frozen, "
          "2 deleted", **_D, output="removed"),
    Field("x_stage", (3,), F, "m", "centroid when the current stage began (stage "
          "displacements are measured from it)", **_D, output="stage_origin"),
    Field("work", (10,), F, "J", "energy budget accumulators of the block since the start: "
          "work of gravity, of applied forces, of contact forces, damping dissipation, work of a "
          "prescribed motion, joint dissipation, energy the joints' force update created, "
          "stored energy changed by contact geometry updates, energy taken out with blocks that "
          "left the model domain, energy absorbed by quiet faces (pdem.dynamics.motion.WORK_*)",
          **_D),
    # scratch: per-rank working arrays, derived from the state above
    Field("dtheta", (3,), F, "rad", "this step's rotation increment (contact planes turn)",
          halo=True),
    Field("dx", (3,), F, "m", "this step's centroid displacement"),
    Field("bforce", (3,), F, "N", "boundary-stress force at t (pdem.boundary), set before the "
          "step"),
    Field("bmoment", (3,), F, "N m", "boundary-stress moment about the centroid at t"),
    Field("R", (3, 3), F, "1", "rotation matrix of q"),
    Field("lo", (3,), F, "m", "envelope lower corner (padded by CTOL/2)"),
    Field("hi", (3,), F, "m", "envelope upper corner"),
    Field("point_area", (), F, "m2", "area of a vertex/edge sub-contact of this block", **_S),
)

CONTACT: tuple[Field, ...] = (
    # local rows: a rank holds far fewer than 2**31 blocks and pieces (int32 halves them)
    Field("ia", (), I32, "1", "row of block A in the block store (local)"),
    Field("ib", (), I32, "1", "row of block B in the block store (local)"),
    Field("ka", (), I32, "1", "row of A's convex piece in the store's piece geometry (local)"),
    Field("kb", (), I32, "1", "row of B's convex piece (local)"),
    # global ids: below csr.KEY_SHIFT = 2**31 (contact keys), so int32 holds them; key
    # arithmetic casts to int64 (csr.pair_key, ContactStore.keys)
    Field("ga", (), I32, "1", "gid of A", **_D),
    Field("gb", (), I32, "1", "gid of B", **_D),
    Field("pga", (), I32, "1", "global id of A's convex piece (pga < pgb); equals ga for a "
          "block of one piece", **_D),
    Field("pgb", (), I32, "1", "global id of B's convex piece", **_D),
    Field("joint", (), I32, "1", "row in the joint table", **_D),
    Field("normal", (3,), F, "1", "common-plane unit normal, A -> B", **_D),
    Field("point", (3,), F, "m", "common-plane reference point", **_D),
    Field("gap", (), F, "m", "common-plane gap at the last geometry update (< 0: overlap; a "
          "joint loaded by the in-situ stress: minus its largest elastic closure)", **_D),
    Field("ctype", (), I8, "1", "contact type code (Table 1: 0..6)", **_D),
    Field("warm", (), U8, "1", "common plane known (warm start)", **_D),
    Field("moved", (), F, "m", "motion of B relative to A since the last geometry update, as "
          "of the last periodic check (pdem.contact.staleness; zoned scenes: the two blocks' "
          "accumulated motion)", **_D),
    # float32: a reference for a tolerance of ~1e-4 CTOL needs ~1e-7 of a block, not 1e-16
    Field("rel_x", (3,), F32, "m", "B's centroid in A's body frame at the last geometry update "
          "(pdem.contact.staleness)", **_D),
    Field("rel_q", (4,), F32, "1", "B's orientation relative to A's (q_a* q_b) at the last "
          "geometry update; zero: unknown", **_D),
    Field("held", (6,), F, "N, N m", "force on B and its moment about A's centroid, kept while "
          "both blocks are inactive (pdem.dynamics.inactive); width 0 in a scene without "
          "solve.inactive (HELD_WIDTH: no contact is ever held there)", **_D),
    Field("frozen", (), U8, "1", "1: ``held`` is valid, the joint is not updated", **_D),
)

# contact fields a checkpoint may lack (written before they were added): they start from zero
CONTACT_ADDED = ("held", "frozen", "rel_x", "rel_q")
# the columns of ``held`` with solve.inactive; without it the store's ``held`` is (n, 0) and
# the force kernel never treats a contact as held (pdem.contact.forces.contact_forces)
HELD_WIDTH = 6


def held_width(inactive: bool) -> int:
    """Columns of the contacts' ``held`` in a scene with (or without) solve.inactive."""
    return HELD_WIDTH if inactive else 0

# (the kernels' records name them without the prefix: pdem.model.contacts.Subs)
SUB: tuple[Field, ...] = (
    Field("sc_pa", (3,), F, "m", "point in A's body frame", **_D, kernel="pa"),
    Field("sc_area", (), F, "m2", "area carried", **_D, kernel="area"),
    Field("sc_un", (), F, "m", "overlap, + closing", **_D, kernel="un"),
    Field("sc_fs", (3,), F, "N", "shear force on B", **_D, kernel="fs"),
    Field("sc_us", (3,), F, "m", "total shear displacement", **_D, kernel="us"),
    Field("sc_dil", (), F, "m", "accumulated dilation", **_D, kernel="dil"),
    Field("sc_state", (), U8, "1", "state bits (SLIPPING 1, FAILED 2, OPEN 4)", **_D,
          kernel="state"),
)

# Joint laws may keep history of their own: ``sc_hist`` has one column per history field of
# the laws a scene uses (width 0 when none), see pdem.contact.laws.
SUB_HIST = Field("sc_hist", (0,), F, "law-defined", "joint-law history columns", **_D,
                 kernel="hist")
# Scenes with zoned blocks: each sub-contact's gridpoint and triangle weights on the zoned
# side(s), pdem.deformable.columns.GRID_WIDTH columns (absent in other scenes)
SUB_GRID = Field("sc_grid", (0,), F, "1", "zoned blocks: the sub-contact's gridpoint and its "
                 "triangles' gridpoints and weights (block-local)", **_D)


def select(fields: tuple[Field, ...], **flags) -> tuple[Field, ...]:
    """The fields with every given flag set, e.g. ``select(BLOCK, halo=True)``."""
    return tuple(f for f in fields if all(bool(getattr(f, k)) == v for k, v in flags.items()))


def names(fields: tuple[Field, ...], **flags) -> tuple[str, ...]:
    return tuple(f.name for f in select(fields, **flags))


def allocate(fields: tuple[Field, ...], n: int) -> dict[str, np.ndarray]:
    """Zeroed arrays of ``n`` rows for ``fields``."""
    return {f.name: np.zeros((n, *f.shape), f.dtype) for f in fields}


def pack(arrays: dict[str, np.ndarray], fields: tuple[Field, ...], rows, out: np.ndarray):
    """Rows ``rows`` of ``fields`` side by side into the float64 matrix ``out``."""
    col = 0
    for f in fields:
        w = f.width
        out[:, col:col + w] = arrays[f.name][rows].reshape(-1, w)
        col += w


def unpack(arrays: dict[str, np.ndarray], fields: tuple[Field, ...], rows, buf: np.ndarray):
    """Inverse of :func:`pack`."""
    col = 0
    for f in fields:
        w = f.width
        arrays[f.name][rows] = buf[:, col:col + w].reshape(-1, *f.shape)
        col += w


def row_width(fields: tuple[Field, ...]) -> int:
    return sum(f.width for f in fields)


BLOCK_BY_NAME = {f.name: f for f in BLOCK}
STATIC = names(BLOCK, static=True)
MIGRATE = names(BLOCK, migrate=True)
CHECKPOINT = names(BLOCK, checkpoint=True)
HALO = select(BLOCK, halo=True)
# halo fields only a feature reads: a scene without it does not send them (pdem.parallel.halo)
HALO_INACTIVE = ("still",)  # solve.inactive (pdem.dynamics.inactive)
# zoned blocks: their contacts' motion since the last update (pdem.stepper.refresh) sums the
# path of both blocks; rigid scenes measure B relative to A (pdem.contact.staleness)
HALO_ZONED = ("u_geo",)


def halo_fields(inactive: bool, zoned: bool = True) -> tuple[Field, ...]:
    """The halo row of a scene: every halo field, less those of features it does not use."""
    skip = (() if inactive else HALO_INACTIVE) + (() if zoned else HALO_ZONED)
    return tuple(f for f in HALO if f.name not in skip)
OUTPUT = tuple(f for f in BLOCK if f.output)


def kernel_names(fields: tuple[Field, ...]) -> dict[str, str]:
    """A kernel record's field name -> the declared field it is: each field by its own name
    and by its declared ``kernel`` name."""
    return {f.name: f.name for f in fields} | {f.kernel: f.name for f in fields if f.kernel}


# the block fields by the names of the kernels' block records (pdem.dynamics.motion.Motion,
# pdem.contact.rigid.Bodies)
KERNEL_FIELDS = kernel_names(BLOCK)
# the contact and sub-contact fields by the names of the kernels' contact records
# (pdem.model.contacts.Pairs and Subs, pdem.contact.detect.Planes): one table, their names
# are distinct
CONTACT_KERNEL_FIELDS = kernel_names(CONTACT + SUB + (SUB_HIST, SUB_GRID))


def kernel_columns(record, table: dict[str, str], own: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The store's name of each of a kernel record's fields, in the record's order: the
    declared field of that (kernel) name in ``table`` (:func:`kernel_names`); ``own``: record
    fields that are the store's own members, no declared field (the contacts' CSR start
    ``sc_start``). A KeyError names a record field that is neither."""
    return tuple(name if name in own else table[name] for name in record._fields)


@functools.cache
def _store_getter(record):
    """The block store's arrays of a kernel record's fields, in its order
    (:func:`kernel_record`): one C call, the names looked up once per record type."""
    names = [KERNEL_FIELDS[name] for name in record._fields]
    if len(names) == 1:  # (attrgetter of one name gives the value, not a tuple)
        return lambda store: (getattr(store, names[0]),)
    return operator.attrgetter(*names)


def kernel_record(record, store, n: int | None = None, **given):
    """A kernel record (a namedtuple type such as pdem.dynamics.motion.Motion) filled by field
    name from a block store: each of the record's fields is the declared block field of that
    name (or whose ``kernel`` name it is), its first ``n`` rows (all with None); ``given``
    overrides fields by record name (e.g. the still flags in place of ``fixed``)."""
    values = _store_getter(record)(store)
    if n is not None:
        values = [a[:n] for a in values]
    if given:
        values = list(values)
        for name, a in given.items():
            values[record._fields.index(name)] = a if n is None else a[:n]
    return record(*values)
