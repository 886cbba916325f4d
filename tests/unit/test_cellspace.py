"""Cell space: the neighbour search finds exactly the envelope-overlapping pairs."""

import numpy as np

from pdem.contact.cellspace import CellSpace


def brute(lo, hi, active):
    out = set()
    n = len(lo)
    for i in range(n):
        for j in range(i + 1, n):
            if (active[i] or active[j]) and np.all(lo[i] <= hi[j]) and np.all(lo[j] <= hi[i]):
                out.add((i, j))
    return out


def random_boxes(n, seed):
    rng = np.random.default_rng(seed)
    c = rng.uniform(0, 10, (n, 3))
    h = rng.uniform(0.1, 0.8, (n, 3))
    return c - h, c + h


def test_all_pairs_match_brute_force():
    lo, hi = random_boxes(300, 1)
    cells = CellSpace(lo, hi, 1.0)
    pi, pj = cells.candidates(lo, hi, np.ones(len(lo), np.uint8))
    found = set(zip(pi.tolist(), pj.tolist(), strict=True))
    assert len(found) == len(pi)  # no duplicates
    assert found == brute(lo, hi, np.ones(len(lo), bool))


def test_only_active_blocks_are_searched():
    lo, hi = random_boxes(200, 2)
    active = np.zeros(len(lo), np.uint8)
    active[::7] = 1
    cells = CellSpace(lo, hi, 0.7)
    pi, pj = cells.candidates(lo, hi, active)
    assert set(zip(pi.tolist(), pj.tolist(), strict=True)) == brute(lo, hi, active.astype(bool))


def test_huge_block_and_growth():
    lo, hi = random_boxes(50, 3)
    lo = np.vstack([lo, [[-100, -100, -1]]])
    hi = np.vstack([hi, [[100, 100, 0.05]]])  # a floor under everything
    cells = CellSpace(lo, hi, 1.0)
    assert np.prod(cells.dims) <= 8_000_000
    lo2, hi2 = lo.copy(), hi.copy()
    lo2[0] -= 500.0  # a block flies out of the cell space
    hi2[0] -= 500.0
    assert cells.grow_to(lo2, hi2)
    assert np.all(cells.origin <= lo2.min(0)) and np.all(cells.hi >= hi2.max(0))
    pi, pj = cells.candidates(lo2, hi2, np.ones(len(lo2), np.uint8))
    assert set(zip(pi.tolist(), pj.tolist(), strict=True)) == brute(lo2, hi2, np.ones(len(lo2), bool))
