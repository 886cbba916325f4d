"""A partial contact update (pdem.contact.detect.refresh_contacts) moves the untouched contacts'
sub-contacts unchanged, whether it copies them in long runs, row by row (short runs) or
leaves them where they are (``in_place``: no contact deleted, every updated one keeping its
number of sub-contacts)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.contact.detect import SHORT_RUN, Planes, refresh_contacts
from pdem.model.contacts import Subs
from pdem.resolve import TOUCH_FRACTION
from pdem.simulation import Simulation

OUT = ("keep", "start", "pa", "area", "un", "fs", "us", "dil", "state", "hist")


@pytest.fixture(scope="module")
def stack():
    """A settling 4³ stack: its contacts carry overlaps, shear forces and displacements, and
    were all just re-detected (so re-detecting them again keeps their counts)."""
    sim = Simulation(parse_scene(cube_stack_scene(4, "fast")), MPI.COMM_SELF, output=False)
    sim.run(steps=60)
    sim.stepper.refresh(all_contacts=True)
    return sim


def inputs(sim, drop_row=None):
    """Copies of what the stepper passes: (planes, sc_start, subs). ``drop_row``: that
    sub-contact row is left out of the old sub-contacts (its contact loses one), so a
    re-detection of its contact changes its count."""
    c = sim.contacts
    a = c.arrays
    planes = Planes(*(a[k].copy() for k in ("ia", "ib", "ka", "kb", "normal", "point", "gap",
                                            "ctype", "warm")))
    start = c.sc_start.copy()
    subs = [np.array(col) for col in c.subs()]
    if drop_row is not None:
        subs = [np.delete(col, drop_row, axis=0) for col in subs]
        start[np.searchsorted(start, drop_row, side="right"):] -= 1
    return planes, start, Subs(*subs)


def update(sim, todo, in_place, drop_row=None):
    """The update's outputs as a dict, and whether they are the old columns themselves."""
    planes, start, subs = inputs(sim, drop_row)
    b = sim.blocks
    res = refresh_contacts(b.x, b.R, b.shapes(), planes, start, subs, todo.astype(np.uint8),
                           sim.state.ctol, TOUCH_FRACTION, sim.state.algorithm, True, in_place)
    return dict(zip(OUT, res, strict=True)), start, subs, res[2] is subs.pa


def run_lengths(todo, start):
    """The untouched runs' numbers of sub-contacts."""
    runs, c = [], 0
    while c < len(todo):
        if todo[c]:
            c += 1
            continue
        c1 = c
        while c1 < len(todo) and not todo[c1]:
            c1 += 1
        runs.append(int(start[c1] - start[c]))
        c = c1
    return runs


def patterns(n):
    rng = np.random.default_rng(7)
    return {
        "none": np.zeros(n, bool),
        "one": np.arange(n) == n // 2,
        "every third": np.arange(n) % 3 == 0,
        "random 30 %": rng.random(n) < 0.3,
        "random 3 %": rng.random(n) < 0.03,
        "first half": np.arange(n) < n // 2,
        "all": np.ones(n, bool),
    }


@pytest.mark.parametrize("drop", [False, True], ids=["same counts", "a count changes"])
@pytest.mark.parametrize("name", list(patterns(1)))
def test_untouched_rows_move_unchanged_and_in_place_is_the_copy(stack, name, drop):
    n = stack.contacts.n
    todo = patterns(n)[name]
    drop_row = None
    if drop:  # the old rows of an updated contact with two sub-contacts or more lose one
        start = stack.contacts.sc_start
        cands = [c for c in np.nonzero(todo)[0] if start[c + 1] - start[c] >= 2]
        if not cands:
            pytest.skip("no updated contact to take a sub-contact from")
        drop_row = int(start[cands[0]])
    copied, start, old, _ = update(stack, todo, False, drop_row)
    placed, _, _, same_arrays = update(stack, todo, True, drop_row)
    for k in OUT:
        assert np.array_equal(copied[k], placed[k]), k
    new_start = copied["start"]
    assert copied["keep"].all()  # a resting stack deletes none
    for c in np.nonzero(~todo)[0]:  # an untouched contact's rows, moved as they were
        o0, o1, n0, n1 = start[c], start[c + 1], new_start[c], new_start[c + 1]
        assert o1 - o0 == n1 - n0
        for k, col in zip(OUT[2:], old, strict=True):
            assert np.array_equal(copied[k][n0:n1], col[o0:o1]), (k, c)
    counts_kept = np.array_equal(new_start, start)
    # in place exactly when the layout allows it and the update is partial
    assert same_arrays == (counts_kept and not todo.all())
    assert counts_kept == (not drop)


def test_patterns_copy_both_short_and_long_runs(stack):
    """The patterns above exercise the row-by-row copy and the slice copy alike."""
    start = stack.contacts.sc_start
    runs = [r for todo in patterns(stack.contacts.n).values() for r in run_lengths(todo, start)]
    assert min(runs) < SHORT_RUN <= max(runs)
