"""Joint state in the output file: the contacts and sub-contacts of every snapshot.

Ragged per snapshot, so stored flat: ``contacts/*`` holds every snapshot's contacts one after
the other (snapshot ``i`` is rows ``contacts/offset[i] .. contacts/offset[i+1]-1``), likewise
``subcontacts/*`` with ``subcontacts/offset``; a contact's sub-contacts follow in its order
(``contacts/n_sub``). Within a snapshot contacts are sorted by key (piece gid A, piece gid B),
so the file does not depend on the rank count (docs/output.md, Contacts).

The per-contact quantities are reduced from the sub-contacts here, by explicit sums in
sub-contact order (no BLAS, no pairwise reductions over a rank's rows): bitwise the same
whatever the partition.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..contact.laws.base import FAILED, OPEN, SLIPPING
from ..model import csr

__all__ = ["CONTACT_COLS", "SUB_COLS", "STATE_NAMES", "CONTACT_SERIES", "SUB_SERIES",
           "CONTACT_FIELDS", "SUB_FIELDS",
           "OutputColumn", "pack", "reduce_contacts", "viewer_attributes", "xdmf_number"]

# contact state codes (contacts/state), in order of precedence: open > slipping > failed > intact
INTACT, SLIPPING_CODE, OPEN_CODE, FAILED_CODE = 0, 1, 2, 3
STATE_NAMES = ("intact", "slipping", "open", "failed")

class OutputColumn(NamedTuple):
    """One dataset of ``contacts/`` or ``subcontacts/`` (docs/output.md): trailing shape,
    dtype, units, doc, ``view``: its place among the point attributes of the ParaView
    sidecar (``<run>-contacts.xdmf``, pdem.io.xdmf), None where it is not shown, and
    ``field``: the contact or sub-contact field (pdem.model.fields) it is, written as it is
    stored (pdem.plugins.output.contact_rows passes it), None for a column made here from the
    sub-contacts (:func:`reduce_contacts`) or by the caller. A stored field shown in ParaView
    is one line here, with its ``field`` and ``view``."""

    name: str
    shape: tuple[int, ...]
    dtype: type
    units: str
    doc: str
    view: int | None = None
    field: str | None = None


CONTACT_SERIES = (
    OutputColumn("block", (2,), np.int64, "1", "gids of blocks A and B"),
    OutputColumn("piece", (2,), np.int64, "1", "convex piece gids of A and B (the sort key)"),
    OutputColumn("joint", (), np.int32, "1", "row in the scene's joints (root attribute "
                 "joint_names)", field="joint"),
    OutputColumn("point", (3,), np.float64, "m", "common-plane reference point",
                 field="point"),
    OutputColumn("normal", (3,), np.float64, "1", "common-plane unit normal, A -> B", view=2,
                 field="normal"),
    OutputColumn("normal_force", (), np.float64, "N", "sum of the sub-contacts' normal forces "
                 "(+ compression)", view=0),
    OutputColumn("shear_force", (3,), np.float64, "N", "sum of the sub-contacts' shear forces, "
                 "on B", view=1),
    OutputColumn("normal_stress", (), np.float64, "Pa", "normal_force / contact area (0 without "
                 "area)", view=4),
    OutputColumn("shear_displacement", (), np.float64, "m", "area-weighted mean of |shear "
                 "displacement|", view=5),
    OutputColumn("opening", (), np.float64, "m", "max(0, -min overlap): the widest opening",
                 view=6),
    OutputColumn("area", (), np.float64, "m2", "sum of the sub-contacts' areas"),
    OutputColumn("state", (), np.uint8, "1", "0 intact, 1 slipping, 2 open, 3 failed", view=3),
    OutputColumn("n_sub", (), np.int32, "1", "number of sub-contacts"),
)
SUB_SERIES = (
    OutputColumn("point", (3,), np.float64, "m", "world position (from the body-frame point on "
                 "A)"),
    OutputColumn("area", (), np.float64, "m2", "area carried", field="sc_area"),
    OutputColumn("overlap", (), np.float64, "m", "overlap, + closing", field="sc_un"),
    OutputColumn("normal_force", (), np.float64, "N", "normal force, + compression", view=0),
    OutputColumn("shear_force", (3,), np.float64, "N", "shear force on B", view=1,
                 field="sc_fs"),
    OutputColumn("shear_displacement", (3,), np.float64, "m", "total shear displacement",
                 field="sc_us"),
    OutputColumn("state", (), np.uint8, "1", "state bits: 1 slipping, 2 failed, 4 open", view=2),
)
# the columns written as stored: (output name, store field), per contact and per sub-contact
CONTACT_FIELDS = tuple((c.name, c.field) for c in CONTACT_SERIES if c.field)
SUB_FIELDS = tuple((c.name, c.field) for c in SUB_SERIES if c.field)
# What a rank passes per contact and per sub-contact (pdem.plugins.output builds it: the stored
# columns above and the rest), packed as float64 rows for the exchange (ids and counts are
# exact below 2**53). Every sub-contact column is passed; the contacts' others are reduced
# from them (:func:`reduce_contacts`).
CONTACT_COLS = (("piece", 2), ("block", 2),
                *((c.name, math.prod(c.shape)) for c in CONTACT_SERIES if c.field),
                ("n_sub", 1))
SUB_COLS = tuple((c.name, math.prod(c.shape)) for c in SUB_SERIES)
# XDMF number type and precision of a dataset's dtype
_XDMF_TYPES = {np.dtype(np.float64): ("Float", 8), np.dtype(np.float32): ("Float", 4),
               np.dtype(np.uint8): ("UChar", 1), np.dtype(np.int32): ("Int", 4),
               np.dtype(np.int64): ("Int", 8)}


def xdmf_number(dtype) -> tuple[str, int]:
    """The XDMF number type and precision of a dataset's dtype."""
    return _XDMF_TYPES[np.dtype(dtype)]


def viewer_attributes(series) -> tuple[tuple[str, int, str, int], ...]:
    """The sidecar's point attributes of a series, in view order: (name, components, XDMF
    number type, precision), from the columns' declarations."""
    shown = sorted((c for c in series if c.view is not None), key=lambda c: c.view)
    return tuple((c.name, math.prod(c.shape), *xdmf_number(c.dtype)) for c in shown)


def _widths(cols):
    out, c = {}, 0
    for name, w in cols:
        out[name] = (c, w)
        c += w
    return out, c


C_AT, C_WIDTH = _widths(CONTACT_COLS)
S_AT, S_WIDTH = _widths(SUB_COLS)


def pack(values: dict, cols, at, width: int) -> np.ndarray:
    """The named arrays side by side in a float64 matrix (``ValueError`` on a bad shape)."""
    k = None
    for name, w in cols:
        a = np.asarray(values[name])
        n = a.size // w if w else 0
        if k is None:
            k = n
        if a.size != k * w:
            raise ValueError(f"write_snapshot: contacts {name} has shape {a.shape}, need "
                             f"({k}, {w})")
    out = np.empty((k or 0, width))
    for name, w in cols:
        c, _ = at[name]
        out[:, c:c + w] = np.asarray(values[name], np.float64).reshape(-1, w)
    return out


def col(rows: np.ndarray, at, name: str) -> np.ndarray:
    c, w = at[name]
    return rows[:, c] if w == 1 else rows[:, c:c + w]


def sort_contacts(crows: np.ndarray, srows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Contacts in key order (piece A, piece B), their sub-contacts carried along."""
    piece = col(crows, C_AT, "piece").astype(np.int64)
    order = np.lexsort((piece[:, 1], piece[:, 0]))
    start = csr.starts(col(crows, C_AT, "n_sub").astype(np.int64))
    sub_idx, _ = csr.take(start, order)
    return crows[order], srows[sub_idx]


def reduce_contacts(crows: np.ndarray, srows: np.ndarray) -> tuple[dict, dict]:
    """The contact and sub-contact datasets' rows of sorted packed rows."""
    n = len(crows)
    nsub = col(crows, C_AT, "n_sub").astype(np.int64)
    start = csr.starts(nsub)[:-1]
    fn, area = col(srows, S_AT, "normal_force"), col(srows, S_AT, "area")
    fs, us = col(srows, S_AT, "shear_force"), col(srows, S_AT, "shear_displacement")
    un = col(srows, S_AT, "overlap")
    bits = col(srows, S_AT, "state").astype(np.int64)
    us_mag = np.sqrt(us[:, 0] * us[:, 0] + us[:, 1] * us[:, 1] + us[:, 2] * us[:, 2])
    is_open = (bits & OPEN) != 0
    slip = ((bits & SLIPPING) != 0) & ~is_open
    failed = ((bits & FAILED) != 0) & ~is_open
    f_n, a_sum, a_us = np.zeros(n), np.zeros(n), np.zeros(n)
    f_s = np.zeros((n, 3))
    min_un = np.full(n, np.inf)
    n_open, any_slip, any_failed = np.zeros(n, np.int64), np.zeros(n, bool), np.zeros(n, bool)
    # column j of every contact with more than j sub-contacts: sums in sub-contact order
    for j in range(int(nsub.max()) if n else 0):
        has = nsub > j
        s = start[has] + j
        f_n[has] += fn[s]
        f_s[has] += fs[s]
        a_sum[has] += area[s]
        a_us[has] += area[s] * us_mag[s]
        min_un[has] = np.minimum(min_un[has], un[s])
        n_open[has] += is_open[s]
        any_slip[has] |= slip[s]
        any_failed[has] |= failed[s]
    pos = a_sum > 0.0
    safe = np.where(pos, a_sum, 1.0)
    state = np.where(n_open == nsub, OPEN_CODE,
                     np.where(any_slip, SLIPPING_CODE,
                              np.where(any_failed, FAILED_CODE, INTACT)))
    contacts = {
        "block": col(crows, C_AT, "block"), "piece": col(crows, C_AT, "piece"),
        **{name: col(crows, C_AT, name) for name, _ in CONTACT_FIELDS},
        "normal_force": f_n, "shear_force": f_s,
        "normal_stress": np.where(pos, f_n / safe, 0.0),
        "shear_displacement": np.where(pos, a_us / safe, 0.0),
        "opening": np.where(nsub > 0, np.maximum(0.0, -min_un), 0.0), "area": a_sum,
        "state": state, "n_sub": nsub,
    }
    subs = {name: col(srows, S_AT, name) for name, _ in SUB_COLS}
    return contacts, subs
