"""ContactStore.take_consumed (the start's first contact update drops the pairs found apart
column by column): the same store as take, in the order asked, sub-contacts carried along;
the source gives up each column as it is taken."""

from __future__ import annotations

import numpy as np

from pdem.model import csr
from pdem.model.contacts import ContactStore


def _store(rng, n, empty=None):
    nsub = rng.integers(0, 5, n)
    if empty is not None:  # these contacts hold no sub-contacts (pairs found apart)
        nsub[empty] = 0
    m = int(nsub.sum())
    return ContactStore({"ia": rng.integers(0, 99, n).astype(np.int32),
                         "normal": rng.standard_normal((n, 3))},
                        {"sc_un": rng.standard_normal(m), "sc_pa": rng.standard_normal((m, 3)),
                         "sc_hist": np.zeros((m, 0))}, csr.starts(nsub))


def test_take_consumed_equals_take_and_empties_the_source():
    rng = np.random.default_rng(5)
    for n, pick in ((40, lambda n: np.nonzero(rng.random(n) < 0.6)[0]),
                    (40, lambda n: rng.permutation(n)[:7]), (0, lambda n: np.arange(0)),
                    (12, lambda n: np.arange(n))):
        a = _store(np.random.default_rng(n), n)
        b = _store(np.random.default_rng(n), n)
        idx = pick(n)
        want, got = a.take(idx), b.take_consumed(idx)
        assert np.array_equal(got.sc_start, want.sc_start)
        for cols in ("arrays", "sub"):
            w, g = getattr(want, cols), getattr(got, cols)
            assert w.keys() == g.keys()
            for k in w:
                assert g[k].dtype == w[k].dtype and np.array_equal(g[k], w[k]), k
        assert b.arrays == {} and b.sub == {}


def test_leaving_out_only_contacts_without_sub_contacts_keeps_the_sub_columns():
    """The start's update drops pairs found apart, which hold no sub-contacts: the sub-contact
    columns are then kept as they are (the same arrays, no gather); anything else (a dropped
    contact with sub-contacts, an order changed) gathers them, and both equal take."""
    rng = np.random.default_rng(11)
    n = 60
    apart = np.nonzero(rng.random(n) < 0.35)[0]
    kept = np.setdiff1d(np.arange(n), apart)
    cases = [(apart, kept, True), (apart, kept[::-1].copy(), False),
             (np.arange(0), np.arange(n), True), (apart, kept[1:], None)]
    for empty, idx, same in cases:
        a = _store(np.random.default_rng(3), n, empty)
        b = _store(np.random.default_rng(3), n, empty)
        if same is None:  # kept[0] holds sub-contacts? then leaving it out must gather
            same = a.sc_start[kept[0] + 1] == a.sc_start[kept[0]]
        columns = dict(b.sub)
        assert csr.takes_every_row(b.sc_start, idx) == same
        want, got = a.take(idx), b.take_consumed(idx)
        assert np.array_equal(got.sc_start, want.sc_start) and got.sc_start.dtype == np.int64
        for k in want.sub:
            assert np.array_equal(got.sub[k], want.sub[k]), k
            assert (got.sub[k] is columns[k]) == same, k
        for k in want.arrays:
            assert np.array_equal(got.arrays[k], want.arrays[k]), k
