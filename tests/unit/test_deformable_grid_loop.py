"""The grids of a GridStore stepped by one kernel call per run of one constitutive table
(pdem.deformable.motion.step_grids) give the bits of each grid stepped alone by ``cycle``
with the per-grid numpy it replaced (gravity forces, applied sums, inertial masses)."""

from __future__ import annotations

import copy

import numpy as np

from pdem.deformable.body import DeformableBody
from pdem.deformable.motion import COMBINED, VISCOUS, cycle, nodal_stiffness
from pdem.deformable.store import GridStore, ZonedGrid, inertial_masses
from pdem.deformable.zones import gravity_forces, zone_geometry
from pdem.geometry import box

ELASTIC = dict(density=2500.0, young=1e9, poisson=0.25)
WEAK = dict(density=2400.0, young=1e9, poisson=0.3, model="mohr_coulomb", cohesion=2e3,
            friction=30.0, tension=1e3, dilation=5.0)
GRAVITY = np.array([0.0, 0.0, -9.81])


def _grids(rng, specs):
    """Bodies of unit cubes zoned at 0.5 with random motion, stresses, masses and loads, and
    their contact forces and contact stiffness."""
    out = []
    for k, spec in enumerate(specs):
        b = DeformableBody(box([2.0 * k, 0, 0], [2.0 * k + 1, 1, 1]), spec, size=0.5)
        n = len(b.nodes)
        b.vel[:] = rng.normal(size=(n, 3)) * 1e-2
        b.stress[:] = rng.normal(size=b.stress.shape) * 1e3
        b.mass = b.gravity_mass * rng.uniform(1.0, 3.0, n)
        b.emass = b.mass.copy()
        b.fixed[0] = True
        b.fixed_vel[0] = (1e-3, 0.0, -1e-3)
        if k % 2:
            b.loaded = True
            b.applied[:] = rng.normal(size=(n, 3)) * 10.0
        zs = nodal_stiffness(b.tets, b.grad, b.vol, b.params.bulk, b.params.shear, n)
        # contact springs near the zones' stiffness: some gridpoints' masses are raised
        kc = np.where(rng.uniform(size=n) < 0.3, zs * rng.uniform(0.0, 20.0, n), 0.0)
        out.append(ZonedGrid(f"g{k}", b, np.flatnonzero(b.mesh.on_surface),
                             rng.normal(size=(n, 3)) * 50.0, kc))
    return out


def _reference_step(grids, bload, bloaded, dt, alpha, adaptive):
    """The per-grid path: each grid's loads and masses by numpy, then ``cycle``."""
    big = 0.0
    for z, bl in zip(grids, bload, strict=True):
        b = z.body
        if not b.active:
            continue
        if adaptive:
            b.damping = float(alpha)
        gforce = gravity_forces(b.gravity_mass, GRAVITY)
        applied = z.force + gforce
        load = np.zeros((0, 3))
        if b.loaded:
            applied += b.applied
            load = b.applied
        if bloaded:
            applied += bl
            load = bl + b.applied if b.loaded else bl
        grad, vol = np.empty_like(b.grad), np.empty_like(b.vol)
        zone_geometry(b.nodes0, b.tets, grad, vol)
        zs = nodal_stiffness(b.tets, grad, vol, b.params.bulk, b.params.shear, len(b.nodes))
        b.emass = inertial_masses(b.mass, zs, z.kc, dt, b.stability_alpha())
        if cycle(1, dt, b.nodes, b.vel, b.emass, applied, b.fixed, b.fixed_vel, b.tets, b.grad,
                 b.vol, b.stress, b.plastic, b.model, b.nmd, b.damping_mode, b.damping,
                 b.prev_force, b.unbalanced, b.servo, gforce, z.force, load, b.params.bulk,
                 b.params.shear, b.work) < 1:
            return z.name, big
        big = max(big, float(b.unbalanced[0]))
    return None, big


FIELDS = ("nodes", "vel", "emass", "stress", "plastic", "prev_force", "work", "servo", "grad",
          "vol", "unbalanced")


def _same(a, b):
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _run(mode, alpha, adaptive, bloaded, removed=(), steps=40):
    rng = np.random.default_rng(7)
    # interleaved materials: three runs of one table (elastic, Mohr-Coulomb x 2, elastic)
    grids = _grids(rng, [ELASTIC, WEAK, WEAK, ELASTIC])
    ref = copy.deepcopy(grids)
    store = GridStore(GRAVITY, [10, 11, 12, 13], grids)
    store.adaptive = adaptive
    for gz, rz in zip(grids, ref, strict=True):
        for b in (gz.body, rz.body):
            b.damping_mode, b.damping = mode, alpha
    store.remove(removed)
    for d in removed:
        ref[d - 10].body.active = False
        ref[d - 10].body.fixed[:] = True
        ref[d - 10].body.fixed_vel[:] = 0.0
        ref[d - 10].body.vel[:] = 0.0
        ref[d - 10].force[:] = 0.0
    bload = [rng.normal(size=(len(z.body.nodes), 3)) * 5.0 for z in grids]
    if bloaded:
        store.bload[:] = np.concatenate(bload)
        store.bloaded = True
    dt = 0.5 * min(z.body.timestep() for z in grids)
    for step in range(steps):
        a = 0.3 + 0.01 * step
        bad = store.step(dt, a)
        name, big = _reference_step(ref, bload, bloaded, dt, a, adaptive)
        assert bad == -1 and name is None
        assert store.ratio == big / store.ref_force
    for gz, rz in zip(grids, ref, strict=True):
        for f in FIELDS:
            assert _same(getattr(gz.body, f), getattr(rz.body, f)), (gz.name, f)
    return store


def test_one_call_per_table_run_keeps_each_grids_bits():
    store = _run(COMBINED, 0.6, adaptive=False, bloaded=True)
    assert len(store._runs) == 3  # elastic, Mohr-Coulomb (two grids), elastic
    assert store.plastic.any()  # the Mohr-Coulomb grids yielded: their return ran


def test_viscous_adaptive_with_a_removed_grid_keeps_the_bits():
    store = _run(VISCOUS, 0.0, adaptive=True, bloaded=False, removed=(12,))
    assert store.bodies[1].damping == 0.3 + 0.01 * 39  # the servo's alpha, followed
    assert store.bodies[2].damping == 0.0  # taken out: not stepped, not followed
    np.testing.assert_array_equal(store.servo_sums(),
                                  store.servo[0] + store.servo[1] + store.servo[3])


def test_a_folded_grid_stops_the_step_at_it():
    rng = np.random.default_rng(3)
    grids = _grids(rng, [ELASTIC, ELASTIC, ELASTIC])
    store = GridStore(GRAVITY, [5, 6, 7], grids)
    b = grids[1].body
    b.vel[:] = -1e4 * (b.nodes - b.nodes.mean(axis=0))  # collapses in a step
    last = grids[2].body.nodes.copy()
    assert store.step(1e-3) == 6
    assert _same(grids[2].body.nodes, last)  # the grids after it: not stepped
