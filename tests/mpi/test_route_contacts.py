"""A restart's contacts routed in batches (pdem.parallel.migrate.route_contacts): each contact
reaches the ranks named for it with its sub-contacts, in key order, whatever the batches (a
different number on each rank, empty ranks, one contact a batch), as if every rank had sent
its whole share at once and each receiver had sorted what came."""

import numpy as np
import pytest
from mpi4py import MPI

from pdem.model import csr
from pdem.model.contacts import ContactStore
from pdem.parallel.migrate import route_contacts


def _share(rank, size, seed, empty):
    """Rank ``rank``'s contacts: globally unique keys, 0-3 sub-contacts each, destinations
    (-1: none) drawn; with ``empty`` the last rank has none."""
    rng = np.random.default_rng(seed + rank)
    n = 0 if empty and rank == size - 1 else int(rng.integers(5, 40))
    keys = (np.sort(rng.choice(10**6, n, replace=False)) * size + rank).astype(np.int64)
    nsub = rng.integers(0, 4, n)
    to_a = rng.integers(-1, size, n).astype(np.int32)
    to_b = rng.integers(-1, size, n).astype(np.int32)
    start = csr.starts(nsub)
    m = int(start[-1])
    store = ContactStore(
        {"ia": np.arange(n, dtype=np.int32), "key": keys,
         "normal": rng.standard_normal((n, 3))},
        {"sc_x": rng.standard_normal((m, 3)),
         "sc_of": np.repeat(keys, nsub), "sc_hist": np.zeros((m, 0))}, start)
    return store, to_a, to_b, nsub


@pytest.mark.mpi(min_size=2)
@pytest.mark.parametrize("empty", [False, True])
@pytest.mark.parametrize("batch", [1, 3, 1000])
@pytest.mark.parametrize("count_type", [np.int64, np.int32])
def test_routed_contacts_arrive_whole_and_in_key_order(batch, empty, count_type):
    comm = MPI.COMM_WORLD
    mine, to_a, to_b, nsub = _share(comm.rank, comm.size, 7, empty)
    nsub = nsub.astype(count_type)  # a restart passes int32 counts (held through the routing)
    reads = []
    events = []

    def read(lo, hi):
        reads.append((lo, hi))
        events.append("read")
        return mine.take(np.arange(lo, hi))

    def keys(lo, hi):
        events.append("keys")
        return mine.arrays["key"][lo:hi]

    # batches of `batch` contacts, so the ranks give different numbers of them
    bounds = np.unique(np.r_[np.arange(0, len(nsub), batch), len(nsub)])
    got = route_contacts(comm, to_a, to_b, nsub, keys, bounds, read,
                         keys_done=lambda: events.append("done"))
    # the keys are all asked for before the caller is told it may drop them, and that before
    # the first contact is read
    assert events.count("done") == 1
    assert set(events[:events.index("done")]) <= {"keys"}
    assert set(events[events.index("done") + 1:]) <= {"read"}
    # what it must be: every rank's contacts naming this one, sorted by key
    every = comm.allgather((mine, to_a, to_b))
    want = [(s, np.nonzero((a == comm.rank) | (b == comm.rank))[0]) for s, a, b in every]
    keys = np.concatenate([s.arrays["key"][rows] for s, rows in want])
    order = np.argsort(keys, kind="stable")
    assert np.array_equal(got.arrays["key"], keys[order])
    assert np.all(np.diff(got.arrays["key"]) > 0)
    normal = np.concatenate([s.arrays["normal"][rows] for s, rows in want])[order]
    assert np.array_equal(got.arrays["normal"], normal)
    # each contact's sub-contacts follow it, in their order
    subs = [s.take(rows) for s, rows in want]
    n_want = np.concatenate([np.diff(s.sc_start) for s in subs])[order]
    assert np.array_equal(np.diff(got.sc_start), n_want)
    assert np.array_equal(got.sub["sc_of"], np.repeat(got.arrays["key"], n_want))
    sub_rows, _ = csr.take(csr.starts(np.concatenate([np.diff(s.sc_start) for s in subs])),
                           order)
    x = np.concatenate([s.sub["sc_x"] for s in subs])[sub_rows]
    assert np.array_equal(got.sub["sc_x"], x) and got.sub["sc_hist"].shape == (len(x), 0)
    # every batch read once, in order; ranks with fewer batches read empty ones
    n_batches = comm.allreduce(len(bounds) - 1, op=MPI.MAX)
    assert len(reads) == n_batches
    assert [r for r in reads if r[1] > r[0]] == list(zip(bounds[:-1], bounds[1:], strict=True))
