"""A contact geometry update carries the springs' energy over (issue 16).

``carry_spring_energy`` rescales a refreshed contact's new sub-contacts so that their normal
(``sum kn A (un + dil)^2 / 2``, compressed ones) and shear (``sum |fs|^2 / (2 ks A)``) spring
energies equal the old ones: the geometry keeps the distribution, the history the energy."""

from __future__ import annotations

import numpy as np

from pdem.contact.detect import carry_spring_energy


def energies(area, un, dil, fs):
    d = np.maximum(un + dil, 0.0)
    return float((area * d * d).sum()), float(((fs**2).sum(axis=1) / area).sum())


def test_edge_to_face_retype_stores_no_energy():
    # an edge contact (two point_area springs, 1.5 cm deep) becomes a face contact: four
    # corners of 20x the area, two at the tracked depth, two newly overlapped
    old_area = np.array([0.005, 0.005])
    old_un = np.array([0.015, 0.016])
    old_dil = np.zeros(2)
    old_fs = np.array([[3e5, 0.0, 0.0], [4e5, 0.0, 0.0]])
    area = np.full(4, 0.1)
    un = np.array([0.015, 0.016, 0.010, 0.011])
    dil = np.zeros(4)
    fs = np.array([[6e6, 0.0, 0.0], [8e6, 0.0, 0.0], [6e6, 0.0, 0.0], [8e6, 0.0, 0.0]])
    un0 = un.copy()
    carry_spring_energy(old_area, old_un, old_dil, old_fs, area, un, dil, fs)
    en0, es0 = energies(old_area, old_un, old_dil, old_fs)
    en1, es1 = energies(area, un, dil, fs)
    assert abs(en1 - en0) <= 1e-12 * en0
    assert abs(es1 - es0) <= 1e-12 * es0
    # the geometric distribution is kept (uniform scaling of the compressions)
    assert np.allclose(un / un0, un[0] / un0[0])


def test_dropped_corner_energy_moves_to_the_remaining_ones():
    old_area = np.array([0.005, 0.005])
    old_un = np.array([0.017, 0.024])
    old_dil = np.zeros(2)
    old_fs = np.zeros((2, 3))
    area = np.array([0.005])
    un = np.array([0.027])
    fs = np.zeros((1, 3))
    carry_spring_energy(old_area, old_un, old_dil, old_fs, area, un, np.zeros(1), fs)
    en0, _ = energies(old_area, old_un, old_dil, old_fs)
    en1, _ = energies(area, un, np.zeros(1), fs)
    assert abs(en1 - en0) <= 1e-12 * en0


def test_unchanged_region_is_left_alone_and_open_springs_stay_open():
    old_area = np.array([0.1, 0.1, 0.1])
    old_un = np.array([1e-4, 2e-4, -3e-3])
    old_fs = np.array([[1e3, 2e3, 0.0], [0.0, 5e2, 0.0], [0.0, 0.0, 0.0]])
    area = old_area.copy()
    un = old_un.copy()
    fs = old_fs.copy()
    carry_spring_energy(old_area, old_un, np.zeros(3), old_fs, area, un, np.zeros(3), fs)
    assert np.array_equal(un, old_un) and np.array_equal(fs, old_fs)
    # a contact that held no compression: a corner found overlapped starts unloaded
    un = np.array([-1e-3, 5e-3, -2e-3])
    carry_spring_energy(old_area, np.full(3, -1e-3), np.zeros(3), np.zeros((3, 3)), area, un,
                        np.zeros(3), fs)
    assert un[1] == 0.0 and un[0] == -1e-3 and un[2] == -2e-3
