"""ContactStore: contacts sorted by key (gid_a, gid_b) with their sub-contacts as CSR."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONTACT_FIELDS: dict[str, tuple[tuple[int, ...], type]] = {
    "ia": ((), np.int64),  # row of block A in the block store
    "ib": ((), np.int64),
    "ga": ((), np.int64),  # gid of A (ga < gb)
    "gb": ((), np.int64),
    "joint": ((), np.int32),  # row in the joint table
    "normal": ((3,), np.float64),  # common-plane unit normal, A -> B
    "point": ((3,), np.float64),  # common-plane reference point
    "gap": ((), np.float64),
    "ctype": ((), np.int32),  # contact type code (Table 1)
    "warm": ((), np.uint8),  # common plane known (warm start)
    "moved": ((), np.float64),  # motion of the two blocks since the last geometry update
}

SUB_FIELDS: dict[str, tuple[tuple[int, ...], type]] = {
    "sc_pa": ((3,), np.float64),  # point in A's body frame
    "sc_area": ((), np.float64),
    "sc_un": ((), np.float64),  # overlap, + closing
    "sc_fn": ((), np.float64),
    "sc_fs": ((3,), np.float64),  # shear force on B
    "sc_us": ((3,), np.float64),  # total shear displacement
    "sc_dil": ((), np.float64),
    "sc_state": ((), np.int64),
}


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

    def __getattr__(self, name):
        try:
            return self.arrays[name] if name in CONTACT_FIELDS else self.sub[name]
        except KeyError:
            raise AttributeError(name) from None

    @staticmethod
    def empty() -> ContactStore:
        return ContactStore(
            {k: np.zeros((0, *s), dt) for k, (s, dt) in CONTACT_FIELDS.items()},
            {k: np.zeros((0, *s), dt) for k, (s, dt) in SUB_FIELDS.items()},
            np.zeros(1, np.int64),
        )

    def keys(self) -> np.ndarray:
        return self.arrays["ga"] * (1 << 31) + self.arrays["gb"]

    def select(self, keep: np.ndarray) -> ContactStore:
        """Contacts where ``keep`` is true, sub-contacts carried along."""
        idx = np.nonzero(keep)[0]
        counts = np.diff(self.sc_start)[idx]
        starts = self.sc_start[idx]
        sub_idx = np.repeat(starts - np.concatenate(([0], np.cumsum(counts)[:-1])), counts) + \
            np.arange(counts.sum())
        return ContactStore(
            {k: a[idx] for k, a in self.arrays.items()},
            {k: a[sub_idx] for k, a in self.sub.items()},
            np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
        )

    def with_new_pairs(self, ia, ib, ga, gb, joint) -> ContactStore:
        """Merge new pairs (no sub-contacts yet, cold common plane) keeping key order."""
        m = len(ia)
        if m == 0:
            return self
        new = {k: np.zeros((m, *s), dt) for k, (s, dt) in CONTACT_FIELDS.items()}
        new.update(ia=ia, ib=ib, ga=ga, gb=gb, joint=joint)
        arrays = {k: np.concatenate([self.arrays[k], new[k]]) for k in CONTACT_FIELDS}
        counts = np.concatenate([np.diff(self.sc_start), np.zeros(m, np.int64)])
        keys = arrays["ga"] * (1 << 31) + arrays["gb"]
        order = np.argsort(keys, kind="stable")
        starts = np.concatenate([self.sc_start[:-1], np.full(m, self.sc_start[-1])])[order]
        counts = counts[order]
        sub_idx = np.repeat(starts - np.concatenate(([0], np.cumsum(counts)[:-1])), counts) + \
            np.arange(counts.sum())
        return ContactStore(
            {k: a[order] for k, a in arrays.items()},
            {k: a[sub_idx] for k, a in self.sub.items()},
            np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
        )
