"""ContactStore: contacts sorted by key (piece gid A, piece gid B) with their sub-contacts as CSR.

A contact is between two convex pieces of two different blocks (a block of one piece: the
piece gid is the block gid, so the key is the block pair's).

Fields are declared in :mod:`pdem.model.fields` (``CONTACT``, ``SUB`` and the joint laws'
history columns ``sc_hist``).
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from ..contact.detect import Planes
from ..contact.forces import normal_forces as law_normal_forces
from . import csr
from .fields import CONTACT, CONTACT_KERNEL_FIELDS, HELD_WIDTH, SUB, allocate, kernel_columns

# What the force kernel reads and writes of the contacts and sub-contacts. The kernel records
# (these and pdem.contact.detect.Planes) are filled by field name from the declarations
# (pdem.model.fields: a sub-contact field's ``kernel`` name, ``pa`` for ``sc_pa``); the
# kernels take them by position, so a record's field order is fixed.
Pairs = namedtuple("Pairs", "ia ib joint normal sc_start held frozen")
# No normal force: the law gives it from the stored state (:meth:`ContactStore.normal_forces`),
# so a sub-contact does not keep a column only the force step would write.
Subs = namedtuple("Subs", "pa area un fs us dil state hist")
# the store's name of each field of the records, in their order
PAIR_COLUMNS = kernel_columns(Pairs, CONTACT_KERNEL_FIELDS, own=("sc_start",))
SUB_COLUMNS = kernel_columns(Subs, CONTACT_KERNEL_FIELDS)
PLANE_COLUMNS = kernel_columns(Planes, CONTACT_KERNEL_FIELDS)


def sub_columns(subs: Subs) -> dict[str, np.ndarray]:
    """The store's sub-contact columns of a :data:`Subs` record (a kernel's result)."""
    return dict(zip(SUB_COLUMNS, subs, strict=True))


@dataclass
class ContactStore:
    """Struct of arrays; ``sc_start`` (n+1,) indexes the sub-contact arrays."""

    arrays: dict[str, np.ndarray]
    sub: dict[str, np.ndarray]
    sc_start: np.ndarray

    @property
    def n(self) -> int:
        return len(self.arrays["ia"])

    @property
    def n_sub(self) -> int:
        return int(self.sc_start[-1])

    @property
    def hist_width(self) -> int:
        return self.sub["sc_hist"].shape[1]

    def __getattr__(self, name):
        try:
            arrays = self.__dict__["arrays"]
            return arrays[name] if name in arrays else self.__dict__["sub"][name]
        except KeyError:
            raise AttributeError(name) from None

    @property
    def held_width(self) -> int:
        return self.arrays["held"].shape[1]

    @staticmethod
    def empty(hist_width: int = 0, grid_width: int = 0, held: int = HELD_WIDTH) -> ContactStore:
        """No contacts; ``grid_width``: the zoned blocks' sub-contact columns ``sc_grid``
        (pdem.deformable.columns.GRID_WIDTH; absent in scenes without zoned blocks); ``held``:
        the columns of ``held`` (pdem.model.fields.held_width: 0 without solve.inactive).
        Contacts added to a store take its columns and dtypes."""
        sub = allocate(SUB, 0)
        sub["sc_hist"] = np.zeros((0, hist_width))
        if grid_width:
            sub["sc_grid"] = np.zeros((0, grid_width))
        arrays = allocate(CONTACT, 0)
        arrays["held"] = np.zeros((0, held))
        return ContactStore(arrays, sub, np.zeros(1, np.int64))

    def with_held(self, width: int) -> ContactStore:
        """This store with ``held`` of ``width`` columns (a checkpoint's contacts in a scene
        with or without solve.inactive); a changed width voids every held force (``frozen``
        0: the next step updates the joints)."""
        if self.held_width == width:
            return self
        arrays = dict(self.arrays)
        arrays["held"] = np.zeros((self.n, width))
        arrays["frozen"] = np.zeros(self.n, arrays["frozen"].dtype)
        return ContactStore(arrays, self.sub, self.sc_start)

    def keys(self) -> np.ndarray:
        return self.arrays["pga"].astype(np.int64) * csr.KEY_SHIFT + self.arrays["pgb"]

    def record(self, record, columns: tuple[str, ...]):
        """The kernel record ``record`` of this store's arrays (not copies: a kernel writes
        into the store), ``columns`` its fields' store names (:func:`kernel_columns`)."""
        a, sub = self.arrays, self.sub
        return record(*[a[k] if k in a else sub[k] if k in sub else getattr(self, k)
                        for k in columns])

    def pairs(self) -> Pairs:
        return self.record(Pairs, PAIR_COLUMNS)

    def subs(self) -> Subs:
        return self.record(Subs, SUB_COLUMNS)

    def planes(self) -> Planes:
        """What a contact geometry update reads and writes of the contacts
        (:data:`pdem.contact.detect.Planes`)."""
        return self.record(Planes, PLANE_COLUMNS)

    def normal_forces(self, joints) -> np.ndarray:
        """Each sub-contact's normal force by its joint law in its stored state (overlap,
        dilation, state bits), as the force step computed it; ``joints``: the scene's
        ``Joints.kernel_args``."""
        fn = np.zeros(self.n_sub)
        law_normal_forces(self.pairs(), self.subs(), joints, fn)
        return fn

    def take(self, idx: np.ndarray) -> ContactStore:
        """Contacts ``idx`` (in that order), their sub-contacts carried along."""
        sub_idx, start = csr.take(self.sc_start, idx)
        return ContactStore({k: a[idx] for k, a in self.arrays.items()},
                            {k: a[sub_idx] for k, a in self.sub.items()}, start)

    def take_consumed(self, idx: np.ndarray) -> ContactStore:
        """:meth:`take`, each column dropped from this store once taken (the store is not
        read after): one column's copy on top of the store, not a second store (the start's
        first update of a rock mass keeps ~2/3 of the pairs its search found: a copy of
        them all was its set-up's peak). When the contacts left out hold no sub-contacts (the
        pairs that update found apart) and the order is kept, the sub-contact columns are
        kept as they are: no gather of every sub-contact, and no copy of the largest column
        on top of the store (~27 MB a rank for a cut rock mass of 88,000 blocks on 2 ranks)."""
        idx = np.asarray(idx, np.int64)
        if csr.takes_every_row(self.sc_start, idx):
            start = csr.kept_starts(self.sc_start, idx)
            sub = {k: self.sub.pop(k) for k in list(self.sub)}
        else:
            sub_idx, start = csr.take(self.sc_start, idx)
            sub = {k: self.sub.pop(k)[sub_idx] for k in list(self.sub)}
            del sub_idx
        arrays = {k: self.arrays.pop(k)[idx] for k in list(self.arrays)}
        return ContactStore(arrays, sub, start)

    def select(self, keep: np.ndarray) -> ContactStore:
        """Contacts where ``keep`` is true, sub-contacts carried along."""
        return self.take(np.nonzero(keep)[0])

    def with_new_pairs(self, **fields) -> ContactStore:
        """Merge new pairs (no sub-contacts yet, cold common plane) keeping key order;
        ``fields``: ia, ib, ka, kb, ga, gb, pga, pgb, joint."""
        m = len(fields["ia"])
        if m == 0:
            return self
        # the store's columns and dtypes (``held`` has none without solve.inactive)
        have = self.arrays
        new = {f.name: np.asarray(fields[f.name], have[f.name].dtype) if f.name in fields
               else np.zeros((m, *have[f.name].shape[1:]), have[f.name].dtype) for f in CONTACT}
        if self.n == 0:  # the start's search: no copies of a store as large as the model's
            merged = ContactStore(new, self.sub, np.zeros(m + 1, np.int64))
            keys = merged.keys()
            if np.all(keys[1:] > keys[:-1]):  # found in key order (as the search makes them)
                return merged
        else:
            arrays = {k: np.concatenate([self.arrays[k], new[k]]) for k in self.arrays}
            del new
            merged = ContactStore(arrays, self.sub,
                                  np.concatenate([self.sc_start, np.full(m, self.sc_start[-1])]))
        return merged.take(np.argsort(merged.keys(), kind="stable"))

    @staticmethod
    def concatenate(stores: list[ContactStore], hist_width: int) -> ContactStore:
        """The contacts of several stores one after the other (no sorting); all empty: an
        empty store with the first's columns (a zoned scene's ``sc_grid``)."""
        given = stores
        stores = [s for s in stores if s.n]
        if not stores:
            return given[0].take(np.zeros(0, np.int64)) if given else \
                ContactStore.empty(hist_width)
        arrays = {k: np.concatenate([s.arrays[k] for s in stores]) for k in stores[0].arrays}
        sub = {k: np.concatenate([s.sub[k] for s in stores]) for k in stores[0].sub}
        return ContactStore(arrays, sub, csr.starts(np.concatenate([np.diff(s.sc_start)
                                                                    for s in stores])))
