"""Per-block columns kept as runs of equal values: what every rank keeps for every block.

Every rank keeps a few labels of every scene block after set-up (its scene entry, group,
material, parent, excavation time and stage, a few geometric scalars: pdem.model.build's
SpecTable), read one block at a time (a message, a selection, a stage's excavations) or
whole at a stage's start. In the scenes pdem is built for they come in long runs: an
``array:`` of 10^6 cubes is one entry, one group, one material, one volume. A run costs its
start (8 bytes) and its value, so such a column is a few hundred bytes at any block count
instead of 4-8 bytes a block on every rank (the O(N) a rank keeps, docs/parallel.md). A
column whose values change too often to gain (the volumes of a cut rock mass) stays a plain
array: :class:`RunColumn` picks the smaller.
"""

from __future__ import annotations

import numpy as np

from ..mpi import allgather, allgather_rows

# one run costs its start (int64) and its value; a column is kept as runs only when that is
# at most this fraction of the plain array (else the lookups' searchsorted buys nothing)
RUNS_WORTH = 0.5


def run_starts(values: np.ndarray) -> np.ndarray:
    """Rows where a new run of equal values begins (row 0 first; bitwise equality, so that
    NaN runs too and -0.0 is not 0.0)."""
    n = len(values)
    if n == 0:
        return np.zeros(0, np.int64)
    bits = np.ascontiguousarray(values).view(np.dtype(f"u{values.dtype.itemsize}"))
    return np.concatenate([[0], np.flatnonzero(bits[1:] != bits[:-1]) + 1]).astype(np.int64)


class RunColumn:
    """A read-only 1-D column of numbers stored as runs of equal values, or plain when runs
    would not be smaller. Indexing by an int gives the value, by an integer array (or a
    boolean mask, or a slice) an array; ``np.asarray`` expands it."""

    __slots__ = ("_n", "_starts", "_values", "_plain")

    def __init__(self, values, dtype=None):
        v = np.ascontiguousarray(np.asarray(values, dtype))
        if v.ndim != 1:
            raise ValueError("RunColumn: a 1-D column")
        self._n = len(v)
        starts = run_starts(v)
        if len(starts) * (8 + v.dtype.itemsize) <= RUNS_WORTH * v.nbytes:
            self._starts, self._values, self._plain = starts, v[starts].copy(), None
        else:
            self._starts = self._values = None
            self._plain = v

    @classmethod
    def gathered(cls, comm, values) -> RunColumn:
        """The column of every rank's ``values`` in rank order (collective): the ranks
        gather their runs, not their rows, when runs are worth keeping (an ``array:``'s
        volumes: a few runs, not 8 bytes of every block on every rank); the same column as
        ``RunColumn`` of the rows gathered."""
        v = np.ascontiguousarray(np.asarray(values))
        starts = run_starts(v)
        parts = allgather(comm, (len(v), starts, v[starts]))
        col = cls._from_runs(parts, v.dtype)
        return col if col is not None else cls(allgather_rows(comm, v))

    @classmethod
    def from_parts(cls, parts, dtype) -> RunColumn:
        """The column of ``parts`` in order, each an array of values or ``(count, value)``
        (a run made as such: an unbuilt family's members, pdem.model.speclist): the same
        column as ``RunColumn`` of them expanded, without expanding them when runs are worth
        keeping."""
        dtype = np.dtype(dtype)
        runs = []
        for p in parts:
            if isinstance(p, tuple):
                count, value = p
                runs.append((count, np.zeros(1 if count else 0, np.int64),
                             np.full(1 if count else 0, value, dtype)))
            else:
                v = np.ascontiguousarray(np.asarray(p, dtype))
                starts = run_starts(v)
                runs.append((len(v), starts, v[starts]))
        col = cls._from_runs(runs, dtype)
        if col is not None:
            return col
        return cls(np.concatenate([np.full(p[0], p[1], dtype) if isinstance(p, tuple)
                                   else np.asarray(p, dtype) for p in parts]
                                  or [np.zeros(0, dtype)]))

    @classmethod
    def _from_runs(cls, parts, dtype) -> RunColumn | None:
        """The column of consecutive pieces ``(rows, run starts, run values)``, runs that
        continue across a piece's end merged (bitwise equal values); None when runs are not
        worth keeping (the caller makes it plain)."""
        dtype = np.dtype(dtype)
        n = sum(p[0] for p in parts)
        offset = np.cumsum([0] + [p[0] for p in parts])[:-1]
        starts = np.concatenate([p[1] + o for p, o in zip(parts, offset, strict=True)]
                                + [np.zeros(0, np.int64)]).astype(np.int64)
        values = np.concatenate([np.asarray(p[2], dtype) for p in parts]
                                + [np.zeros(0, dtype)])
        if len(values):
            bits = values.view(np.dtype(f"u{dtype.itemsize}"))
            keep = np.concatenate([[True], bits[1:] != bits[:-1]])
            starts, values = starts[keep], values[keep]
        if len(starts) * (8 + dtype.itemsize) > RUNS_WORTH * n * dtype.itemsize:
            return None
        col = cls.__new__(cls)
        col._n, col._starts, col._values, col._plain = n, starts, values.copy(), None
        return col

    def run_values(self) -> np.ndarray:
        """The values, one per run (every row's when plain): what a minimum, a maximum or a
        set of the column's values needs."""
        return self._values if self._plain is None else self._plain

    @property
    def is_runs(self) -> bool:
        return self._plain is None

    @property
    def dtype(self) -> np.dtype:
        return (self._values if self._plain is None else self._plain).dtype

    @property
    def shape(self) -> tuple[int]:
        return (self._n,)

    @property
    def nbytes(self) -> int:
        if self._plain is not None:
            return self._plain.nbytes
        return self._starts.nbytes + self._values.nbytes

    def __len__(self) -> int:
        return self._n

    def _run_of(self, rows: np.ndarray) -> np.ndarray:
        return np.searchsorted(self._starts, rows, side="right") - 1

    def __getitem__(self, i):
        if self._plain is not None:
            return self._plain[i]
        if isinstance(i, (int, np.integer)):
            k = int(i)
            if k < 0:
                k += self._n
            if not 0 <= k < self._n:
                raise IndexError(f"row {int(i)} of {self._n}")
            return self._values[int(self._run_of(k))]
        if isinstance(i, slice):
            rows = np.arange(self._n)[i]
        else:
            rows = np.asarray(i)
            if rows.dtype == bool:
                if rows.shape != (self._n,):
                    raise IndexError(f"a mask of {rows.shape} rows for a column of {self._n}")
                rows = np.flatnonzero(rows)
            rows = np.where(rows < 0, rows + self._n, rows)
            if rows.size and (rows.min() < 0 or rows.max() >= self._n):
                raise IndexError(f"rows outside a column of {self._n}")
        return self._values[self._run_of(rows)]

    def __array__(self, dtype=None, copy=None):
        if self._plain is not None:
            out = self._plain
        else:
            out = np.repeat(self._values, np.diff(self._starts, append=self._n))
        return out if dtype is None else out.astype(dtype, copy=False)

    def __iter__(self):
        return iter(np.asarray(self).tolist())

    def __eq__(self, other):
        return np.asarray(self) == np.asarray(other)

    __hash__ = None
