"""Compressed-row (CSR) helpers and the contact pair key, written once."""

from __future__ import annotations

import numpy as np

from ..jit import kernel

# A contact's key packs the two global ids; gids stay below 2**31.
KEY_SHIFT = 1 << 31


def pair_key(ga: np.ndarray, gb: np.ndarray) -> np.ndarray:
    """Canonical key of unordered pairs: (min gid, max gid) packed in one int64."""
    return np.minimum(ga, gb).astype(np.int64) * KEY_SHIFT + np.maximum(ga, gb)


def starts(counts: np.ndarray) -> np.ndarray:
    """CSR start array (n+1,) of per-row ``counts``."""
    out = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=out[1:])
    return out


def take(start: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry indices of CSR ``rows`` (in that order) and the start array of the selection."""
    rows = np.asarray(rows, np.int64)
    counts = start[rows + 1] - start[rows]
    new_start = starts(counts)
    idx = np.repeat(start[rows] - new_start[:-1], counts) + np.arange(new_start[-1])
    return idx, new_start


@kernel
def takes_every_row(start, rows) -> bool:
    """Whether ``rows`` (of a CSR array with ``start``) ascend and leave out only rows with
    no entries: :func:`take` would then give every entry, in order (no array made)."""
    total = 0
    prev = -1
    for i in range(rows.shape[0]):
        r = rows[i]
        if r <= prev:
            return False
        total += start[r + 1] - start[r]
        prev = r
    return total == start[start.shape[0] - 1]


def kept_starts(start: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """:func:`take`'s start array when :func:`takes_every_row`: the rows left out add
    nothing, so row ``rows[i]`` ends where it ended (no per-row counts made)."""
    out = np.zeros(len(rows) + 1, np.int64)
    np.take(start[1:], rows, out=out[1:])
    return out
