"""Factor of safety by strength reduction with zoned blocks (pdem.strength, docs/deformable.md):

(a) a rigid block on a zoned base on an incline (pdem.cases.staged.zoned_fos_scene), the
    joint between them deciding:
    ``FS = tan(phi) / tan(psi)`` (Hoek-Bray's planar slide) within the search's tolerance, and
    the grids are restored between the trials: after the search the model is, bitwise, the
    equilibrium it started from (gridpoints, velocities, zone stresses);
(b) a trial weakens Mohr-Coulomb zones as the joints (cohesion, tan(friction) and tension over
    F, dilation not above the reduced friction) and leaves elastic zones as they are.
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.staged import RHO, zoned_fos, zoned_fos_scene
from pdem.config import parse_scene
from pdem.deformable.constitutive import material, reduced_table
from pdem.deformable.store import GridStore
from pdem.simulation import Simulation


def test_block_on_a_zoned_base_slides_at_the_planar_factor(tmp_path, monkeypatch):
    tol = 0.01
    weakened = []  # the factors the trials weakened the zones by
    own_weaken = GridStore.weaken
    monkeypatch.setattr(GridStore, "weaken",
                        lambda self, f: (weakened.append(f), own_weaken(self, f))[1])
    out, ck = str(tmp_path / "fos.h5"), str(tmp_path / "ck")
    sim = Simulation(parse_scene(zoned_fos_scene(out, ck, tol)), MPI.COMM_SELF)
    try:
        summary = sim.run()
        g = sim.state.grids
        after = {k: getattr(g, k).copy() for k in ("nodes", "vel")}
        after["stress"] = g.bodies[0].stress.copy()
        after["model"] = g.bodies[0].model
        own = g.bodies[0].params
    finally:
        sim.close()
    exact = zoned_fos()
    got = summary["factor"]
    print(f"\nzoned base: FS {got:.4f}, closed form {exact:.4f}, error {got / exact - 1:+.2%}, "
          f"{len(summary['trials'])} trials")
    assert summary["bounded"]
    assert weakened == [f for f, _, _ in summary["trials"]]
    # bisection: the factor is the middle of a bracket narrower than tol (relative)
    assert abs(got / exact - 1.0) < tol
    stable = [f for f, s, _ in summary["trials"] if s]
    unstable = [f for f, s, _ in summary["trials"] if not s]
    assert max(stable) < exact * (1 + 0.5 * tol) and min(unstable) > exact * (1 - 0.5 * tol)
    # the model goes on from the equilibrium the search started from: the grid as the settle
    # stage's checkpoint holds it, bitwise, and the material's own strength (the trials'
    # weakened tables gone)
    with h5py.File(f"{ck}-stage0-settle.h5") as f:
        saved = {k: f[f"grids/{k}"][()] for k in ("nodes", "vel", "stress")}
    for k, v in saved.items():
        assert np.array_equal(after[k], v), k
    assert after["model"] == material(own.model_dump())[1]
    assert after["model"].two_c_sqrt_n_phi > 2.0e6


@pytest.mark.parametrize("factor", [1.0, 1.5])
def test_trial_weakens_mohr_coulomb_zones_only(factor):
    mc = dict(model="mohr_coulomb", density=RHO, young=1e9, poisson=0.25, cohesion=1.0e5,
              friction=35.0, tension=2.0e4, dilation=30.0)
    params, table = material(mc)
    got = reduced_table(params, factor)
    phi = math.degrees(math.atan(math.tan(math.radians(35.0)) / factor))
    expect = material(dict(mc, cohesion=1.0e5 / factor, friction=phi, tension=2.0e4 / factor,
                           dilation=min(30.0, phi)))[1]
    assert got == (table if factor == 1.0 else expect)
    if factor > 1.0:  # the dilation capped at the reduced friction (27.0 degrees)
        assert phi < 30.0 and got.n_psi == got.n_phi
    elastic, el_table = material(dict(density=RHO, young=1e9, poisson=0.25))
    assert reduced_table(elastic, factor) == el_table
