"""Zoned cubes stacked in an array bear on their faces, not on the edges they share with
their diagonal neighbours (pdem.deformable.subcontacts): two columns of two zoned unit cubes
side by side on a rigid floor, under gravity, solved to equilibrium.

Closed form: each contact between cubes stacked in a column carries the weight above it
(``rho g`` per cube of 1 m3); the contact between a top cube and the bottom cube of the other
column touches along an edge only: it carries nothing but what a strip of the touch
tolerance's width along the edge bears. Before the cells of the gridpoints beside such an
edge were cut to where the other block is (not only to its outline), that edge contact bore on
0.83 m2 of cells (docs/deformable.md, "Sub-contacts"; in a 1,000-cube array the edge and
corner contacts held 6,260 m2 beside the faces' 2,800)."""

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.resolve import TOUCH_FRACTION
from pdem.simulation import Simulation

RHO, G, KN = 2000.0, 9.81, 1.0e9
SCENE = f"""
name: zoned-array
gravity: [0, 0, -{G}]
materials:
  rock: {{density: {RHO}}}
  stiff: {{density: {RHO}, young: 1.0e10, poisson: 0.25}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [3, 2, 0]}}, material: rock, fixed: true}}
  - name: c
    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, count: [2, 1, 2], spacing: [1, 1, 1]}}
    material: stiff
    zones: {{size: 0.5}}
solve: {{ratio: 1.0e-5, max_steps: 10000, damping: local, mass_scaling: true}}
"""


def areas(sim) -> dict:
    """The sub-contact area of each contact, by the pair of block names."""
    s = sim.state
    c = s.contacts
    names = [s.specs[g].name for g in s.blocks.gid]
    return {tuple(sorted((names[c.ia[k]], names[c.ib[k]]))):
            float(c.sub["sc_area"][c.sc_start[k]:c.sc_start[k + 1]].sum()) for k in range(c.n)}


def normal_forces(sim) -> dict:
    """The normal force of each contact (``kn A un`` summed over its sub-contacts), by the
    pair of block names."""
    s = sim.state
    c = s.contacts
    names = [s.specs[g].name for g in s.blocks.gid]
    fn = KN * c.sub["sc_area"] * np.maximum(c.sub["sc_un"], 0.0)
    out = {}
    for k in range(c.n):
        pair = tuple(sorted((names[c.ia[k]], names[c.ib[k]])))
        out[pair] = float(fn[c.sc_start[k]:c.sc_start[k + 1]].sum())
    return out


def test_an_array_of_zoned_cubes_bears_on_its_faces_not_on_its_edges():
    sim = Simulation(parse_scene(SCENE), MPI.COMM_SELF, output=False)
    sim.run()
    s = sim.state
    assert s.ratio <= 1e-5
    w = RHO * G  # a cube's weight (1 m3)
    f = normal_forces(sim)
    print({k: round(v / w, 4) for k, v in f.items()})
    at = {s.specs[g].name: s.blocks.x[r] for r, g in enumerate(s.blocks.gid)}
    cubes = [n for n in at if n != "floor"]
    assert len(cubes) == 4
    low = [n for n in cubes if at[n][2] < 1.0]
    high = [n for n in cubes if at[n][2] > 1.0]
    area = areas(sim)
    tol = TOUCH_FRACTION * s.ctol
    for top in high:
        below = min(low, key=lambda n: abs(at[n][0] - at[top][0]))
        beside = next(n for n in low if n != below)  # its diagonal neighbour: an edge
        # a face bears on its 1 m2; an edge on the strips within the touch tolerance of the
        # other cube beside it, on both faces: 2 x (tol / sqrt 2) x 1 m x cos 45 = tol m2
        # (0.83 m2 before)
        assert area[tuple(sorted((top, below)))] == pytest.approx(1.0, rel=1e-6)
        assert area.get(tuple(sorted((top, beside))), 0.0) <= 1.01 * tol * 1.0
        # (measured 0.993 w and 0.0063 w: the edge strips and the Poisson push between the
        # bottom cubes)
        assert f[tuple(sorted((top, below)))] == pytest.approx(w, rel=0.01)  # its weight
        assert f.get(tuple(sorted((top, beside))), 0.0) < 0.01 * w
    for bottom in low:  # on the floor: two cubes' weight
        assert f[tuple(sorted((bottom, "floor")))] == pytest.approx(2 * w, rel=0.01)
