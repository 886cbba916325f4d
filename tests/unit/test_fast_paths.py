"""Shortcuts in the step's kernels that must not change an answer: the Coulomb law's slip
test on squares (bit for bit the rounded root's decision) and the isotropic block's angular
velocity (``L / I`` exactly, no midpoint iteration)."""

from __future__ import annotations

import math

import numba
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_dynamics import Blocks  # the tests directory is on sys.path (rootdir conftest)

from pdem.contact.laws.coulomb import below_limit
from pdem.dynamics import motion as M
from pdem.dynamics.rotation import quat_from_rotvec


@numba.njit
def _below(fx, fy, fz, fs_max):
    return below_limit(fx, fy, fz, fs_max)


finite = st.floats(-1e12, 1e12, allow_nan=False, allow_infinity=False)


def _slips(fx, fy, fz, fs_max):
    """The decision as the law made it before the shortcut: the rounded root against the
    limit."""
    return math.sqrt(fx * fx + fy * fy + fz * fz) > fs_max


@settings(max_examples=3000, deadline=None)
@given(finite, finite, finite, st.floats(0.0, 1e12, allow_nan=False),
       st.integers(-40, 40))
def test_below_limit_never_contradicts_the_rounded_root(fx, fy, fz, fs_max, ulps):
    """``below_limit`` may only say yes where the root is surely not above the limit; tried
    on random forces and on forces scaled to within a few ulps of the limit, where a decision
    on the squares alone would go wrong."""
    assert not (_below(fx, fy, fz, fs_max) and _slips(fx, fy, fz, fs_max))
    mag = math.sqrt(fx * fx + fy * fy + fz * fz)
    if mag > 0.0 and fs_max > 0.0:
        k = fs_max / mag * (1.0 + ulps * 2.0 ** -52)
        gx, gy, gz = fx * k, fy * k, fz * k
        assert not (_below(gx, gy, gz, fs_max) and _slips(gx, gy, gz, fs_max))


def test_below_limit_takes_the_common_case():
    """A sticking joint (shear well below the limit) skips the root; at, above and just below
    the limit, and for a zero or tiny limit, the root decides."""
    assert _below(1.0, 2.0, 2.0, 4.0)  # |f| = 3
    assert not _below(1.0, 2.0, 2.0, 3.0)  # at the limit
    assert not _below(1.0, 2.0, 2.0, 2.0)
    assert not _below(1.0, 2.0, 2.0, 3.0 * (1.0 + 1e-16))
    assert not _below(0.0, 0.0, 0.0, 0.0)
    assert not _below(1e-160, 0.0, 0.0, 1e-150)  # squares outside the normal range


def test_isotropic_block_turns_with_L_over_I():
    """A cube's principal moments are equal: its angular velocity is ``L / I`` at any
    orientation, under a moment, with no midpoint iteration (the asymmetric block of
    test_dynamics iterates)."""
    b = Blocks(1, inertia=(2.0, 2.0, 2.0))
    b.q[0] = quat_from_rotvec(np.array([0.7, -0.3, 1.1]))
    b.set_omega(np.array([0.4, 0.1, -0.6]))
    b.moment[0] = [3.0, -1.0, 0.5]
    for _ in range(20):
        b.step(1e-2)
        np.testing.assert_array_equal(b.w[0], b.L[0] / 2.0)
    assert b.stats[M.STAT_ROT_ITER] == 0
    np.testing.assert_allclose(b.L[0], np.array([0.4, 0.1, -0.6]) * 2.0
                               + 20 * 1e-2 * np.array([3.0, -1.0, 0.5]), rtol=0, atol=1e-14)
    a = Blocks(1, inertia=(1.0, 2.0, 4.0))
    a.q[0] = b.q[0]
    a.set_omega(np.array([0.4, 0.1, -0.6]))
    a.step(1e-2)
    assert a.stats[M.STAT_ROT_ITER] > 0
