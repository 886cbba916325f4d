"""The model step of a scene with zoned blocks (docs/deformable.md, "Timestep").

Without mass scaling the step is the smaller of the rigid blocks' estimate (eq. 87 and the
rotational bound over the free rigid blocks only: a zoned block is no rigid block) and
``GRID_FRAC`` of the grids' Gershgorin step (eq. 84 with the joints' ``2 kn A_i``):

(a) the elastic column on a fixed floor (no free rigid block) steps at the grid's own step,
    recomputed here from the zones' geometry in numpy (element stiffness rows of
    ``|K_e|``, gridpoint masses a quarter of each zone's, surface shares a third of each
    boundary triangle), at the build and in a stage;
(b) a light, stiff rigid cube on the column: its own rigid bound, below the grid's, is the
    step (not its mass against the column's contact stiffness, as when the column counted
    as a rigid block).
"""

import logging

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.deformable.store import GRID_FRAC
from pdem.simulation import Simulation

RHO, E, KN, ALPHA = 2000.0, 1.0e8, 1.0e9, 0.8
FRAC = 0.1  # solve.timestep.frac's default: the rigid estimate's margin

SCENE = """
name: column
materials:
  rock: {{density: {rho}}}
  heavy: {{density: {density}}}
  soft: {{density: {rho}, young: {E}, poisson: 0.0}}
joints: {{default: {{kn: {kn}, ks: {kn}, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: column, box: {{min: [0, 0, 0], max: [1, 1, {H}]}}, material: soft, zones: {{size: {size}}}}}
{extra}
solve: {{steps: 2, damping: {{mode: local, alpha: {alpha}}}}}
{stages}
"""


def build(H=2.0, size=0.35, extra="", stages="", density=RHO):
    text = SCENE.format(rho=RHO, E=E, kn=KN, H=H, size=size, extra=extra, stages=stages,
                        alpha=ALPHA, density=density)
    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


def grid_step(body) -> float:
    """``GRID_FRAC`` times eq. 84 for the zoned block at its true masses, from its reference
    gridpoints and zones: ``2 min_i sqrt(m_i / ((1 + alpha) k_i))``, ``k_i`` the largest row
    sum over the gridpoint's three rows of ``|K_e|`` summed over its zones plus ``2 kn A_i``."""
    x, tets = np.asarray(body.nodes0), np.asarray(body.tets)
    G = E / 2.0  # poisson 0: lambda = 0
    lam = 0.0
    rows = np.zeros((len(x), 3))
    mass = np.zeros(len(x))
    faces = {}
    for tet in tets:
        p = x[tet]
        jac = np.array([p[1] - p[0], p[2] - p[0], p[3] - p[0]])
        vol = abs(np.linalg.det(jac)) / 6.0
        inv = np.linalg.inv(jac)  # shape functions N1..3 = inv @ (x - p0): gradients its columns
        grad = np.vstack([-inv.sum(axis=1), inv.T])
        ke = vol * (lam * np.einsum("ai,bj->aibj", grad, grad)
                    + G * np.einsum("aj,bi->aibj", grad, grad)
                    + G * np.einsum("ij,ab->aibj", np.eye(3), grad @ grad.T))
        rows[tet] += np.abs(ke.reshape(4, 3, 12)).sum(axis=2)
        mass[tet] += 0.25 * RHO * vol
        for f in ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)):
            key = tuple(sorted(int(tet[i]) for i in f))
            faces[key] = faces.get(key, 0) + 1
    share = np.zeros(len(x))
    for (a, b, c), count in faces.items():
        if count == 1:  # a boundary triangle: a third of its area to each corner
            area = 0.5 * np.linalg.norm(np.cross(x[b] - x[a], x[c] - x[a]))
            share[[a, b, c]] += area / 3.0
    k = rows.max(axis=1) + 2.0 * KN * share
    return GRID_FRAC * 2.0 * float(np.sqrt(np.min(mass / ((1.0 + ALPHA) * k))))


def rigid_steps(blocks) -> float:
    """Eq. 87 and the rotational bound over box blocks ``(mass, I_min / (m l^2), r^2 / l^2,
    stiffness)`` (``l``: 1 m): ``FRAC 2 min(sqrt(M_min / K_max), sqrt(I_min / (K r^2)))``."""
    m_min = min(b[0] for b in blocks)
    k_max = max(b[3] for b in blocks)
    rot = min(b[0] * b[1] / (b[3] * b[2]) for b in blocks)
    return FRAC * 2.0 * float(np.sqrt(min(m_min / k_max, rot)))


def test_zoned_column_steps_at_its_grids_own_step(caplog):
    """No free rigid block: the step is the grid's own, not the column's mass against its
    contacts' stiffness (the rigid estimate, which made it 7.3e-5 s at size 0.35), at the
    build and at a stage (the replay of a restart decides it there the same way)."""
    stages = "stages: [{name: more, solve: {steps: 2}}]"
    with caplog.at_level(logging.INFO, logger="pdem"):
        sim = build(stages=stages)
    s = sim.state
    body = s.grids.bodies[0]
    expect = grid_step(body)
    assert abs(s.dt / expect - 1.0) < 1e-12, (s.dt, expect)
    assert abs(expect - 1.76e-4) < 0.005e-4, expect  # the figure of docs/deformable.md
    # the column as a rigid block (1 x 1 x 2 m, kn x 10/3 m2): its rotational bound
    rigid = rigid_steps([(RHO * 2.0, 1.0 / 6.0, 1.5, KN * 10.0 / 3.0)])
    assert abs(rigid - 7.3e-5) < 0.05e-5 and s.dt > 2.0 * rigid, (s.dt, rigid)
    assert "no free rigid block" in caplog.text and "block 'column'" not in caplog.text
    with caplog.at_level(logging.INFO, logger="pdem"):
        sim.run()
    assert s.stage == 0 and s.step == 2
    assert "stage 1: the zoned blocks' grids limit the step" in caplog.text
    assert s.dt == expect or abs(s.dt / expect - 1.0) < 1e-12, (s.dt, expect)
    assert (body.mass == body.gravity_mass).all()  # no mass scaling: the true masses


@pytest.mark.parametrize("side, density", [(0.2, RHO), (0.6, 25.0 * RHO)])
def test_rigid_cube_on_zoned_column(side, density, caplog):
    """A rigid cube of side ``side`` on the column (size 0.5): its own rigid bound (eq. 87
    with its own mass and stiffness ``kn`` x a third of its surface, and the rotational
    bound, ``I_min / r^2 = 2 m / 9``) is the step where it is below the grid's (0.2 m: the
    light, stiff one), the grid's where not (0.6 m, 25 times denser); never the cube's mass
    against the column's contact stiffness nor the column's rotation, as when the column
    counted as a rigid block."""
    lo, hi = 0.5 - side / 2.0, 0.5 + side / 2.0
    cube = (f"  - {{name: cube, box: {{min: [{lo}, {lo}, 1.0], max: [{hi}, {hi}, "
            f"{1.0 + side}]}}, material: heavy}}")
    with caplog.at_level(logging.INFO, logger="pdem"):
        sim = build(H=1.0, size=0.5, extra=cube, density=density)
    s = sim.state
    cube_row = (density * side ** 3, side ** 2 / 6.0, 0.75 * side ** 2, KN * 2.0 * side ** 2)
    rigid = rigid_steps([cube_row])
    grid = grid_step(s.grids.bodies[0])
    expect = min(rigid, grid)
    assert abs(s.dt / expect - 1.0) < 1e-12, (s.dt, rigid, grid)
    old = min(grid, rigid_steps([cube_row, (RHO, 1.0 / 6.0, 0.75, KN * 2.0)]))
    assert s.dt > 1.5 * old, (s.dt, old)
    assert "block 'cube' limits the rigid blocks' step" in caplog.text
    if side == 0.2:
        assert rigid < grid and "grids limit" not in caplog.text
    else:
        assert grid < rigid and "grids limit the step" in caplog.text
