"""A zoned block's piece planes (triangle normals and offsets, edge directions) are made from
its vertices when read, not every step (pdem.deformable.store.GridStore.fresh_planes): after
steps they lag the moved vertices, and a contact update makes them first."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

# two zoned cubes in a column on a fixed floor, thrown sideways and down so that the grids
# deform from the first step; no periodic contact update in the steps taken
SCENE = """
name: planes
materials:
  rock: {density: 2500.0}
  soft: {density: 2500.0, young: 1.0e8, poisson: 0.25}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: soft, zones: {size: 0.5},
     velocity: [0.5, 0, -0.5]}
  - {name: b, box: {min: [0, 0, 1], max: [1, 1, 2]}, material: soft, zones: {size: 0.5},
     velocity: [-0.5, 0.2, -1.0]}
contact: {detect_every: 1000}
solve: {steps: 100, damping: none}
"""


def planes_from_vertices(b, g):
    """The zoned pieces' unit normals, offsets and edge directions by numpy from their
    vertices (the kernel's formulas, numpy's order: within a few ulps)."""
    normals, offsets, edirs = [], [], []
    for r in g.rows:
        k = b.piece_start[r]
        for f in range(b.face_start[k], b.face_start[k + 1]):
            j = b.fvert_start[f]
            p, q, t = b.verts_local[b.face_verts[j:j + 3]]
            n = np.cross(q - p, t - p)
            n /= np.sqrt(n @ n)
            normals.append(n)
            offsets.append(n @ (p + q + t) / 3.0)
        e0 = b.edge_start[k]
        for i in range(b.edir_start[k + 1] - b.edir_start[k]):
            p, q = b.verts_local[b.edges[e0 + i]]
            edirs.append((q - p) / np.sqrt((q - p) @ (q - p)))
    return np.array(normals), np.array(offsets), np.array(edirs)


def zoned_planes(b, g):
    faces = np.concatenate([np.arange(b.face_start[b.piece_start[r]],
                                      b.face_start[b.piece_start[r] + 1]) for r in g.rows])
    dirs = np.concatenate([np.arange(b.edir_start[b.piece_start[r]],
                                     b.edir_start[b.piece_start[r] + 1]) for r in g.rows])
    return b.normals_local[faces], b.offsets_local[faces], b.edirs_local[dirs]


def test_planes_lag_the_steps_and_a_contact_update_makes_them():
    sim = Simulation(parse_scene(SCENE), MPI.COMM_SELF, output=False)
    s = sim.state
    b, g = s.blocks, s.grids
    for _ in range(30):
        sim.stepper.advance()
    want = planes_from_vertices(b, g)
    lag = max(np.abs(x - y).max() for x, y in zip(zoned_planes(b, g), want, strict=True))
    # the gridpoints moved up to 3.2 mm in 30 steps, the grids deforming: the planes of the
    # set-up are off by far more than rounding (measured 3.3e-3)
    assert lag > 1e-6, lag
    sim.stepper.refresh(all_contacts=True)
    err = max(np.abs(x - y).max() for x, y in zip(zoned_planes(b, g), want, strict=True))
    # made from the vertices: numpy's order of the same formulas, measured 2.2e-16
    assert err < 1e-14, err
