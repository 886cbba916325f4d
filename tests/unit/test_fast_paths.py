"""Shortcuts in the step's kernels that must not change an answer: the Coulomb law's slip
test on squares (bit for bit the rounded root's decision), the isotropic block's angular
velocity (``L / I`` exactly, no midpoint iteration) and the series for roots near 1 (the turned
normal and shear force, the staleness check's angle: within an ulp of the library)."""

from __future__ import annotations

import math

import numba
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_dynamics import Blocks  # the tests directory is on sys.path (rootdir conftest)

from pdem.contact.algorithms import find_plane
from pdem.contact.detect import _plane
from pdem.contact.forces import SERIES_RANGE, carry_shear, root_near_one, turn_normal, unit_scale
from pdem.contact.laws.coulomb import below_limit
from pdem.contact.staleness import _angle
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


@numba.njit
def _unit_scale(m2):
    return unit_scale(m2)


@numba.njit
def _root_near_one(r):
    return root_near_one(r)


@numba.njit
def _angle_of(half):
    return _angle(half)


def _ulps(a, b):
    return abs(a - b) / np.spacing(max(abs(a), abs(b)))


@settings(max_examples=3000, deadline=None)
@given(st.one_of(st.floats(-SERIES_RANGE, SERIES_RANGE), st.floats(-0.5, 0.5),
                 st.sampled_from([-SERIES_RANGE, SERIES_RANGE, 0.0, 1e-300, -1e-300])))
def test_series_roots_agree_with_the_library_to_an_ulp(e):
    """The force loop's series for ``1/sqrt`` and ``sqrt`` near 1 (the turned normal, the
    turned shear force): the truncation is below 4e-19, so the series and the library root
    differ by their roundings only, one ulp at most, inside the series' range and at its
    edges; outside it the library root is used as before, bit for bit."""
    m = 1.0 + e
    assert _ulps(_unit_scale(m), 1.0 / math.sqrt(m)) <= 1.0
    assert _ulps(_root_near_one(m), math.sqrt(m)) <= 1.0
    if abs(m - 1.0) >= SERIES_RANGE:
        assert _unit_scale(m) == 1.0 / math.sqrt(m)
        assert _root_near_one(m) == math.sqrt(m)


@settings(max_examples=2000, deadline=None)
@given(st.one_of(st.floats(0.0, 1e-3), st.floats(0.0, 1.0)))
def test_relative_turn_angle_series_agrees_with_asin(half):
    """The staleness check's rotation angle ``2 asin(h)`` by its series below 1e-3: within
    two ulps of the library's asin (each rounds once or twice), and the library above."""
    assert _ulps(_angle_of(half), 2.0 * math.asin(half)) <= 2.0


def test_turned_normal_stays_unit_and_shear_keeps_its_magnitude():
    """A contact's normal turned by small and large rotations stays a unit vector to rounding
    (the series' range and beyond it), and the shear force carried into the turned plane
    keeps its magnitude and lies in the plane: eq. 23."""
    rng = np.random.default_rng(3)
    for scale in (1e-9, 1e-6, 1e-4, 1e-2, 0.3):
        normal = rng.normal(size=(1, 3))
        normal /= np.linalg.norm(normal)
        dtheta = rng.normal(size=(2, 3)) * scale
        f = np.cross(normal[0], rng.normal(size=3)) * 1e5
        n = np.array(_turn(normal, dtheta))
        assert abs(np.linalg.norm(n) - 1.0) < 4e-16
        g = np.array(_carry(*f, *n))
        assert abs(np.linalg.norm(g) - np.linalg.norm(f)) < 4e-16 * np.linalg.norm(f)
        assert abs(g @ n) < 1e-15 * np.linalg.norm(f)


@numba.njit
def _turn(normal, dtheta):
    return turn_normal(normal, dtheta, 0, 0, 1)


@numba.njit
def _carry(fx, fy, fz, nx, ny, nz):
    return carry_shear(fx, fy, fz, nx, ny, nz)


def _settled_stack():
    """A 3³ cube stack after 150 steps: contacts sticking and slipping, the blocks turned."""
    from mpi4py import MPI

    from pdem.cases.stacks import cube_stack_scene
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    sim = Simulation(parse_scene(cube_stack_scene(3, "fast")), MPI.COMM_SELF, output=False)
    sim.run(steps=150)
    return sim


def test_booking_stored_energy_in_one_kernel_is_bitwise_the_two_step_booking():
    """The start's first contact update books every contact's stored energy without a
    per-contact array (pdem.stepper.refresh): the same operations, so the same bits."""
    from pdem.contact.forces import book_contact_energy, book_stored_energy, contact_energies
    from pdem.dynamics.motion import WORK_GEOMETRY

    sim = _settled_stack()
    s, c = sim.state, sim.state.contacts
    joints = s.joints.kernel_args
    which = (np.arange(c.n) % 3 != 0).astype(np.uint8)  # some contacts left out
    work0 = s.blocks.work.copy()
    energy = contact_energies(c.pairs(), c.subs(), joints, which)
    assert (energy > 0).sum() > 10  # the stack is loaded: the springs hold energy
    book_contact_energy(sim.stepper.bodies(), c.ia, c.ib, energy, WORK_GEOMETRY)
    two_step = s.blocks.work.copy()
    s.blocks.work[:] = work0
    book_stored_energy(sim.stepper.bodies(), c.pairs(), c.subs(), joints, which, WORK_GEOMETRY)
    assert np.array_equal(s.blocks.work.view(np.uint64), two_step.view(np.uint64))
    assert not np.array_equal(two_step, work0)


@numba.njit
def _plane_by_scratch(ka, kb, shapes, R, scratch, n, p, alg):
    return _plane(ka, kb, shapes, R, scratch, n, p, True, alg)


@numba.njit
def _plane_given(ka, kb, shapes, na, nb, ea, eb, n, p, alg):
    vs = shapes.vert_start
    va = shapes.verts_world[vs[ka]:vs[ka + 1]]
    vb = shapes.verts_world[vs[kb]:vs[kb + 1]]
    return find_plane(alg, va, vb, shapes.piece_x[ka], shapes.piece_x[kb], na, nb, ea, eb, n, p,
                      True)


def test_planes_from_per_contact_world_normals_are_those_from_whole_arrays():
    """The Fast Common Plane rotates each contact's two pieces' face normals and edge
    directions into scratch rows (pdem.contact.detect._plane) instead of reading arrays of
    every piece's: for every contact of a turned, settled stack the scratch rows are the
    rotated vectors and the plane is bit for bit the one found from vectors rotated whole."""
    from pdem.contact.detect import plane_scratch

    sim = _settled_stack()
    s, b, c = sim.state, sim.state.blocks, sim.state.contacts
    shapes = b.shapes()
    scratch = plane_scratch(shapes)
    fs, es, pb = shapes.face_start, shapes.edir_start, shapes.piece_block
    assert scratch[0].shape[0] == int(np.diff(fs).max())

    def world(start, local, k):
        rot = b.R[pb[k]]
        rows = local[start[k]:start[k + 1]]
        return np.stack([rot[i, 0] * rows[:, 0] + rot[i, 1] * rows[:, 1] + rot[i, 2] * rows[:, 2]
                         for i in range(3)], axis=1)

    turned = 0
    for k in range(c.n):
        ka, kb = int(c.ka[k]), int(c.kb[k])
        got = _plane_by_scratch(ka, kb, shapes, b.R, scratch, c.normal[k].copy(),
                                c.point[k].copy(), s.algorithm)
        na, nb = world(fs, shapes.normals_local, ka), world(fs, shapes.normals_local, kb)
        ea, eb = world(es, shapes.edirs_local, ka), world(es, shapes.edirs_local, kb)
        assert np.array_equal(scratch[1][:len(nb)], nb) and np.array_equal(scratch[3][:len(eb)], eb)
        want = _plane_given(ka, kb, shapes, na, nb, ea, eb, c.normal[k].copy(), c.point[k].copy(),
                            s.algorithm)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        assert got[2] == want[2]
        turned += not np.array_equal(nb, shapes.normals_local[fs[kb]:fs[kb + 1]])
    assert turned > c.n // 2  # the blocks have turned: the rotation was exercised
