"""Which contacts a periodic geometry update re-detects (pdem.contact.staleness): the motion of
B relative to A since the contact's last update, and the first press of a contact found apart."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.contact.staleness import TOUCH_SHARE, mark_fresh, stale_contacts
from pdem.dynamics.kinematics import rotation_matrices
from pdem.dynamics.rotation import quat_from_rotvec, quat_mul
from pdem.simulation import Simulation

TOL = 1e-3  # refresh tolerance in metres


class Pair:
    """Two blocks (rows 0 = A, 1 = B) and one contact between them, fresh at the start."""

    def __init__(self, radius_b=0.7, gap=-1e-4, un=(1e-4,)):
        self.x = np.array([[0.0, 0.0, 0.0], [0.3, 0.2, 1.0]])
        self.q = np.array([quat_from_rotvec(np.array([0.1, -0.2, 0.3])),
                           quat_from_rotvec(np.array([-0.4, 0.1, 0.2]))])
        self.R = np.zeros((2, 3, 3))
        self.radius = np.array([0.5, radius_b])
        self.ia = np.array([0], np.int64)
        self.ib = np.array([1], np.int64)
        self.rel_x = np.zeros((1, 3))
        self.rel_q = np.zeros((1, 4))
        self.gap = np.array([gap])
        self.warm = np.ones(1, np.uint8)
        self.sc_start = np.array([0, len(un)], np.int64)
        self.sc_un = np.array(un, float)
        self.moved = np.zeros(1)
        rotation_matrices(self.q, self.R)
        mark_fresh(self.x, self.q, self.R, self.ia, self.ib, self.rel_x, self.rel_q,
                   np.ones(1, np.uint8))

    def check(self):
        rotation_matrices(self.q, self.R)
        todo = np.zeros(1, np.uint8)
        n = stale_contacts(self.x, self.q, self.R, self.radius, self.ia, self.ib, self.rel_x,
                           self.rel_q, self.gap, self.warm, self.sc_start, self.sc_un, TOL,
                           self.moved, todo)
        assert n == int(todo[0])
        return bool(todo[0]), float(self.moved[0])

    def turn(self, row, rotvec):
        """Rotate block ``row`` about its centroid (world rotation vector)."""
        self.q[row] = quat_mul(quat_from_rotvec(np.asarray(rotvec, float)), self.q[row])


def test_fresh_contact_is_not_stale():
    stale, moved = Pair().check()
    assert not stale
    assert moved < 1e-15


def test_blocks_moving_together_keep_their_contact():
    """The two blocks translated by 10 m and turned together by 1 rad about A's centroid:
    nothing changed between them, whatever each block's own path."""
    p = Pair()
    turn = np.array([0.3, -0.8, 0.52])
    rot = quat_from_rotvec(turn)
    R = np.zeros((1, 3, 3))
    rotation_matrices(rot[None, :], R)
    p.x[1] = R[0] @ p.x[1]  # B's centroid turns about A's
    for row in (0, 1):
        p.turn(row, turn)
        p.x[row] += [10.0, -3.0, 7.0]
    stale, moved = p.check()
    assert not stale
    assert moved < 1e-12


@pytest.mark.parametrize("slide, stale", [(0.9 * TOL, False), (1.1 * TOL, True)])
def test_sliding_past_the_tolerance(slide, stale):
    p = Pair()
    p.x[1] += slide * np.array([0.6, 0.8, 0.0])
    got, moved = p.check()
    assert got is stale
    assert moved == pytest.approx(slide, rel=1e-9)


def test_turn_of_b_counts_its_radius():
    """B turned by θ about its own centroid: its farthest point moved up to θ r_B."""
    p = Pair(radius_b=0.7)
    theta = 1e-3
    p.turn(1, [0.0, theta, 0.0])
    stale, moved = p.check()
    assert moved == pytest.approx(theta * 0.7, rel=1e-6)
    assert not stale  # 0.7 mm < 1 mm
    p.turn(1, [0.0, theta, 0.0])
    assert p.check()[0]


def test_turn_of_a_moves_b_in_its_frame():
    """A turned about its own centroid by θ: B's centroid, at distance d, moved θ d in A's
    frame (B turned with respect to A by θ too)."""
    p = Pair(radius_b=0.0)
    theta = 5e-4
    p.turn(0, [theta, 0.0, 0.0])
    _, moved = p.check()
    d = np.linalg.norm(p.x[1] - p.x[0])
    # chord of the turn, |x_B| projected off the axis
    off_axis = math.hypot(p.x[1, 1], p.x[1, 2])
    assert moved == pytest.approx(2 * math.sin(theta / 2) * off_axis, rel=1e-6)
    assert moved <= theta * d


def test_unknown_reference_and_new_contacts_are_stale():
    p = Pair()
    p.rel_q[:] = 0.0  # a checkpoint written before the reference was kept
    assert p.check()[0]
    p = Pair()
    p.warm[:] = 0
    assert p.check()[0]


@pytest.mark.parametrize("gap, un, closing, stale", [
    (0.0, 2 * TOUCH_SHARE * TOL, 3, True),     # found touching, now pressed: a tied plane
    (1e-5, 2 * TOUCH_SHARE * TOL, 3, True),    # found apart, now pressed
    (0.0, 0.5 * TOUCH_SHARE * TOL, 3, False),  # not yet pressed beyond the share
    (-1e-5, 2 * TOUCH_SHARE * TOL, 3, False),  # found pressed: its plane is the one that carries
    (0.0, 2 * TOUCH_SHARE * TOL, 0, False),    # pressed without moving: in-situ stress
])
def test_first_press_of_a_contact_found_apart(gap, un, closing, stale):
    p = Pair(gap=gap, un=(-1e-6, un))
    p.x[1, 2] -= closing * TOUCH_SHARE * TOL  # B moved towards A by that much
    assert p.check()[0] is stale


STACK = """
name: moving-stack
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
gravity: [0.0, 0.0, 0.0]
contact: {ctol: 0.02, refresh_tolerance: 0.01}
blocks:
  - {name: low, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock, velocity: [2.0, 1.0, 0.0]}
  - {name: high, box: {min: [0, 0, 1.0], max: [1, 1, 2]}, material: rock,
     velocity: [2.0, 1.0, 0.0]}
solve: {steps: 1, damping: none}
"""


def _updates(scene: str, steps: int, monkeypatch) -> int:
    """Contacts re-detected by periodic updates over ``steps`` steps (after the start's), each
    step in Python (a compiled run of steps updates inside its loop, pdem.cycle: the same
    contacts, tests/unit/test_fused.py)."""
    import pdem.stepper as stepper

    sim = Simulation(parse_scene(scene.replace("damping: none}", "damping: none, fused: false}")),
                     MPI.COMM_SELF, output=False)
    count = [0]
    real = stepper.refresh_contacts

    def counting(*args):
        count[0] += int(np.count_nonzero(args[6]))
        return real(*args)

    monkeypatch.setattr(stepper, "refresh_contacts", counting)
    sim.run(steps=steps)
    return count[0]


def test_a_pair_gliding_together_is_never_redetected(monkeypatch):
    """Two cubes face to face gliding at 2.2 m/s, 44 CTOL in 400 steps: their contact is the
    same throughout and no update re-detects it; one sliding over the other is re-detected."""
    assert _updates(STACK, 400, monkeypatch) == 0
    sliding = STACK.replace("velocity: [2.0, 1.0, 0.0]}\nsolve", "velocity: [2.0, 1.5, 0.0]}\nsolve")
    assert sliding != STACK
    assert _updates(sliding, 400, monkeypatch) > 0


def test_a_checkpoint_without_the_reference_pose_restarts(tmp_path):
    """A checkpoint written before contacts kept their reference pose (no contacts/rel_x,
    rel_q) continues: its contacts are re-detected at the first periodic update, and the
    sliding cube ends where the straight run's does to well within the refresh tolerance."""
    import os

    import h5py
    from test_state import SCENE  # the sliding cube, a checkpoint at 0.03 s of 0.06 s

    from pdem.io.checkpoint import read_checkpoint

    text = SCENE.replace("CK", os.path.join(tmp_path, "ck"))
    straight = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    straight.run()
    path = os.path.join(tmp_path, sorted(p for p in os.listdir(tmp_path)
                                         if p.startswith("ck-"))[0])
    same = Simulation(parse_scene(text), MPI.COMM_SELF, output=False,
                      checkpoint=read_checkpoint(path))
    same.run()
    assert np.array_equal(same.blocks.x, straight.blocks.x)  # with the pose: bitwise
    with h5py.File(path, "r+") as f:
        assert np.any(f["contacts/rel_q"][()] != 0.0)
        del f["contacts/rel_x"], f["contacts/rel_q"]
    old = Simulation(parse_scene(text), MPI.COMM_SELF, output=False,
                     checkpoint=read_checkpoint(path))
    assert not old.contacts.arrays["rel_q"].any()  # unknown: stale at the first check
    old.run()
    assert old.contacts.arrays["rel_q"].any()
    assert np.abs(old.blocks.x - straight.blocks.x).max() < 1e-6
