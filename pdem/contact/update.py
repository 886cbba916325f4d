"""A contact geometry update of the marked contacts, with its bookkeeping, in compiled calls.

An update is three kernel calls: :func:`begin_update`, the re-detection
(:func:`.detect.refresh_contacts`) and :func:`end_update`. The stepper's update
(:meth:`pdem.stepper.Stepper.refresh`) and the compiled run of steps (:mod:`pdem.cycle`)
make the same three calls on the same arrays, so a periodic update done inside the compiled
loop is the same bits as the stepper's (tests/unit/test_fused.py compares every column). The
loop then no longer returns to Python for each periodic update with work (nearly every one of
a settling stack). The calls are not wrapped in one kernel: numba optimises a kernel together
with everything it calls, so each wrapper around the re-detection compiled it again (~6 s a
layer in a fresh process, docs/validation.md).

What an update does, in order: each marked contact's relative motion is zeroed and its
relative pose recorded (:mod:`.staleness`), the marked contacts' stored spring energy is read,
their planes and sub-contacts are found again, new contacts on a joint plane take the set's
joint (:func:`.joint_sets.set_joints`), held forces of the updated contacts are void, and the
change of the stored energy is booked on the blocks (``WORK_GEOMETRY``). Contacts found apart
keep their rows with no sub-contact: the caller drops them
(:meth:`pdem.model.contacts.ContactStore.take_consumed`). A dropped contact's energy after the
update is zero: it has no sub-contact left, so summing over the rows before they are dropped
books the same numbers as summing over the kept ones.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..jit import access, kernel
from .forces import book_on_blocks, book_stored_energy, spring_energy
from .joint_sets import set_joints
from .rigid import WORK_GEOMETRY
from .staleness import mark_fresh

# What an update reads besides the poses and the contacts: ``shapes``
# (pdem.model.blocks.Shapes), ``planes`` (pdem.contact.detect.Planes), CTOL, the touch
# fraction, the common-plane algorithm, whether an update of every contact trims its slack and
# whether the update may write over the old sub-contact rows (pdem.contact.detect
# .refresh_contacts: not with zoned blocks, whose regrid reads them), and ``sets``
# (:data:`JointSets`, or None when no cut names a joint).
GeometryUpdate = namedtuple("GeometryUpdate",
                            "shapes planes ctol touch_frac alg trim in_place sets")
# the block faces' planes and cut tags, and each cut's joint row (pdem.contact.joint_sets)
JointSets = namedtuple("JointSets", "face_start normals_local offsets_local face_tag cut_joint")


@access(reads="x q R ia ib warm joint sc_area sc_un sc_fs sc_dil sc_state sc_hist",
        writes="moved rel_x rel_q")
@kernel
def begin_update(x, q, R, up, pairs, subs, joints, moved, rel_x, rel_q, todo):
    """What an update of the contacts with ``todo[c] != 0`` does before their re-detection:
    their relative motion zeroed and relative pose recorded; returns ``(before, new)``, their
    stored energy before, in contact order (empty when there was no sub-contact: then
    :func:`end_update` books the energy after, and no array is made at the start's first
    update, the set-up's peak), and with joint sets the contacts never updated (found by a
    search since), which may lie on a joint plane."""
    planes = up.planes
    nc = planes.ia.shape[0]
    for c in range(nc):
        if todo[c] != 0:
            moved[c] = 0.0
    mark_fresh(x, q, R, planes.ia, planes.ib, rel_x, rel_q, todo)
    before = _marked_energies(pairs, subs, joints, todo) if pairs.sc_start[nc] > 0 \
        else np.empty(0)
    return before, _unseen(up.sets, planes.warm)


@access(reads="x R fixed work ia ib ka kb normal joint sc_area sc_un sc_fs sc_dil sc_state sc_hist",
        writes="joint frozen work")
@kernel
def end_update(x, R, up, pairs, subs, joints, bodies, todo, keep, new, before, book):
    """What an update does after the re-detection (:func:`.detect.refresh_contacts`, whose
    ``keep`` and new CSR start and columns ``pairs``/``subs`` hold, found-apart contacts still
    in their rows): a new contact kept on a joint plane takes the set's joint, the updated
    contacts' held forces are void and, with ``book``, the change of their stored energy is
    booked (:func:`book_update`; zoned blocks book theirs after the regrid)."""
    _set_joints(up.sets, new, keep, up.planes, x, R, up.ctol, pairs.joint)
    for c in range(todo.shape[0]):
        if todo[c] != 0:  # new sub-contacts: held forces are void
            pairs.frozen[c] = 0
    if book:
        book_update(bodies, pairs, subs, joints, todo, before)


@kernel
def _unseen(sets, warm):
    """With joint sets, the contacts never updated (found by a search since): the ones that may
    lie on a joint plane. (Empty without: ``sets`` None compiles to nothing here.)"""
    if sets is None:
        return np.empty(0, np.uint8)
    new = np.empty(warm.shape[0], np.uint8)
    for c in range(warm.shape[0]):
        new[c] = 1 if warm[c] == 0 else 0
    return new


@kernel
def _set_joints(sets, new, keep, planes, x, R, ctol, joint):
    """A new contact kept on a joint plane takes the set's joint (:func:`.joint_sets.set_joints`)."""
    if sets is None:
        return
    any_new = False
    for c in range(new.shape[0]):
        new[c] &= keep[c]
        any_new |= new[c] != 0
    if any_new:
        set_joints(new, planes.ia, planes.ib, planes.ka, planes.kb, planes.normal, x, R,
                   sets.face_start, sets.normals_local, sets.offsets_local, sets.face_tag,
                   sets.cut_joint, ctol, joint)


@kernel
def _marked_energies(pairs, subs, joints, todo):
    """The stored spring energy of each contact with ``todo[c] != 0``, in contact order (an
    array of the marked ones only: a periodic update marks a few per cent of the contacts)."""
    n = 0
    for c in range(todo.shape[0]):
        n += todo[c] != 0
    out = np.empty(n)
    k = 0
    for c in range(todo.shape[0]):
        if todo[c] != 0:
            out[k] = spring_energy(pairs, subs, joints, c)
            k += 1
    return out


@kernel
def book_update(bodies, pairs, subs, joints, todo, before):
    """Book what the update changed in the marked contacts' stored energy on their blocks
    (``WORK_GEOMETRY``): no work is done, so the change is the geometry's. ``pairs``/``subs``
    after the update, found-apart contacts still in their rows (no sub-contact: zero energy);
    ``before`` from :func:`begin_update`. (An unmarked contact's change is 0, whose booking would
    add +0 to its blocks' sums and leave them as they are: they are not visited.)"""
    if before.shape[0] == 0:
        book_stored_energy(bodies, pairs, subs, joints, todo, WORK_GEOMETRY)
        return
    k = 0
    for c in range(todo.shape[0]):
        if todo[c] == 0:
            continue
        e = spring_energy(pairs, subs, joints, c) - before[k]
        k += 1
        book_on_blocks(bodies, pairs.ia[c], pairs.ib[c], e, WORK_GEOMETRY)


@kernel
def keeps_all(keep):
    """Whether an update kept every contact."""
    for c in range(keep.shape[0]):
        if keep[c] == 0:
            return False
    return True
