"""Constant-strain tet kernels (pdem.deformable.zones, .nmd): the patch test, the face-normal
form of the gridpoint forces, mass lumping, the Jaumann rotation and NMD's patch property."""

from __future__ import annotations

import numpy as np
import pytest

from pdem.deformable.mesh import min_dihedral_angles, tetrahedralise
from pdem.deformable.nmd import nmd_strain, nmd_stress
from pdem.deformable.zones import (
    add_zone_forces,
    lumped_mass,
    rotate_stress,
    strain_rates,
    surface_load,
    zone_geometry,
)
from pdem.geometry import from_vertices

VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))


@pytest.fixture(scope="module")
def grid():
    d = np.random.default_rng(3).normal(size=(16, 3))
    poly = from_vertices(d)
    m = tetrahedralise(poly, 0.6)
    grad = np.empty((len(m.tets), 4, 3))
    vol = np.empty(len(m.tets))
    zone_geometry(m.nodes, m.tets, grad, vol)
    return poly, m, grad, vol


def _tensor(row):
    t = np.empty((3, 3))
    for r, (i, j) in enumerate(VOIGT):
        t[i, j] = t[j, i] = row[r]
    return t


def test_patch_linear_velocity_gives_exact_strain_rate(grid):
    _, m, grad, vol = grid
    rng = np.random.default_rng(0)
    L = rng.normal(size=(3, 3))
    vel = m.nodes @ L.T + rng.normal(size=3)
    rate = np.empty((len(m.tets), 6))
    spin = np.empty((len(m.tets), 3))
    strain_rates(vel, m.tets, grad, rate, spin)
    D = 0.5 * (L + L.T)
    W = 0.5 * (L - L.T)
    want = np.array([D[i, j] for i, j in VOIGT])
    err = np.abs(rate - want).max(axis=1) / np.abs(D).max()
    # round-off grows as a zone flattens: this hull has two faces 0.0024 deg from coplanar,
    # and the zone with a gridpoint on each next to their edge is that flat
    angle = np.radians(min_dihedral_angles(m.nodes, m.tets))
    print(f"patch test: max relative strain-rate error {err.max():.1e}, "
          f"{(err * np.sin(angle)).max():.1e} times the sine of the zone's angle")
    assert np.all(err * np.sin(angle) < 1e-13)
    spin_err = np.abs(spin - [W[0, 1], W[1, 2], W[2, 0]]).max(axis=1) / np.abs(W).max()
    assert np.all(spin_err * np.sin(angle) < 1e-13)
    # NMD changes nothing in a uniform field (the patch test survives it)
    before = rate.copy()
    nmd_strain(m.tets, vol, rate, len(m.nodes))
    change = np.abs(rate - before).max(axis=1) / np.abs(D).max()
    assert np.all(change * np.sin(angle) < 1e-13)


def test_zone_forces_are_face_tractions_and_balance(grid):
    """f_a = -V sigma.grad N_a equals sigma.(A n)_a / 3 (eq. 55); a uniform stress gives zero
    net force on interior gridpoints and the boundary forces equal the surface tractions."""
    _, m, grad, vol = grid
    sigma = np.array([3.0, -1.0, 2.0, 0.5, -0.7, 0.2])
    stress = np.tile(sigma, (len(m.tets), 1))
    f = np.zeros_like(m.nodes)
    add_zone_forces(m.tets, grad, vol, stress, f)
    # one tet by hand: face opposite node 0 is (1, 2, 3), its outward area vector
    x = m.nodes[m.tets[0]]
    area0 = 0.5 * np.cross(x[2] - x[1], x[3] - x[1])
    one = np.zeros_like(m.nodes)
    add_zone_forces(m.tets[:1], grad[:1], vol[:1], stress[:1], one)
    assert np.allclose(one[m.tets[0, 0]], _tensor(sigma) @ area0 / 3.0, rtol=1e-12, atol=1e-14)
    scale = np.abs(f).max()
    assert np.abs(f[~m.on_surface]).max() < 1e-12 * scale
    # boundary gridpoint forces balance the consistent loads of the traction sigma.n
    want = np.zeros_like(m.nodes)
    x = m.nodes[m.surface]
    for k, tri in enumerate(m.surface):
        an = 0.5 * np.cross(x[k, 1] - x[k, 0], x[k, 2] - x[k, 0])
        want[tri] += _tensor(sigma) @ an / 3.0
    assert np.abs(f + want).max() < 1e-12 * scale
    # and surface_load reproduces one face's share
    face_n = np.asarray(grid[0].normals)[0]
    sel = m.surface_face == 0
    t = _tensor(sigma) @ face_n
    g = surface_load(m.nodes, m.surface[sel], t)
    assert np.allclose(g.sum(axis=0), t * grid[0].face_area(0), rtol=1e-12)


def test_lumped_mass_total(grid):
    poly, m, _, vol = grid
    mass = lumped_mass(len(m.nodes), m.tets, vol, 2500.0)
    assert mass.sum() == pytest.approx(2500.0 * poly.volume, rel=1e-12)
    assert mass.min() > 0.0


def test_jaumann_rotation_turns_stress_with_the_spin():
    """Many small steps of sigma += (W sigma - sigma W) dt under a constant spin reproduce
    R sigma R^T (first order: error ~ (omega dt) * angle)."""
    omega = np.array([0.3, -0.5, 0.8])
    Wm = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    spin = np.array([[Wm[0, 1], Wm[1, 2], Wm[2, 0]]])
    s0 = np.array([[5.0, -2.0, 1.0, 0.7, 0.3, -0.4]])
    s = s0.copy()
    n, total = 20000, 1.0
    for _ in range(n):
        rotate_stress(s, spin, total / n)
    th = np.linalg.norm(omega) * total
    k = omega / np.linalg.norm(omega)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
    want = R @ _tensor(s0[0]) @ R.T
    err = np.abs(_tensor(s[0]) - want).max() / np.abs(want).max()
    print(f"Jaumann rotation by {np.degrees(th):.0f} deg in {n} steps: relative error {err:.1e}")
    assert err < 2e-4


def test_nmd_stress_keeps_uniform_correction():
    """A uniform plastic correction is its own nodal average: eq. 76 leaves stresses alone; a
    non-uniform one is smoothed with the total (volume-weighted) correction nearly kept."""
    d = np.random.default_rng(5).normal(size=(12, 3))
    m = tetrahedralise(from_vertices(d), 0.8)
    grad = np.empty((len(m.tets), 4, 3))
    vol = np.empty(len(m.tets))
    zone_geometry(m.nodes, m.tets, grad, vol)
    stress = np.zeros((len(m.tets), 6))
    nmd_stress(m.tets, vol, np.full(len(m.tets), 2.5), stress, len(m.nodes))
    assert np.abs(stress).max() < 1e-14
    sp = np.zeros(len(m.tets))
    sp[0] = 1.0
    nmd_stress(m.tets, vol, sp, stress, len(m.nodes))
    assert stress[0, 0] > 0.0 and np.all(stress[1:, 0] <= 1e-15)  # spread from zone 0
