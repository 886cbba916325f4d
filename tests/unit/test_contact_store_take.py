"""ContactStore.take_consumed (the start's first contact update drops the pairs found apart
column by column): the same store as take, in the order asked, sub-contacts carried along;
the source gives up each column as it is taken."""

from __future__ import annotations

import numpy as np

from pdem.model import csr
from pdem.model.contacts import ContactStore


def _store(rng, n):
    nsub = rng.integers(0, 5, n)
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
