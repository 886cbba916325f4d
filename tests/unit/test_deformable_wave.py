"""Wave speed in a zoned bar (issue 12's verification list), at the DeformableBody level.

A bar of length L = 2 m and 0.1 m x 0.1 m section (E = 1 GPa, nu = 0.25, rho = 1000 kg/m3,
undamped) is pushed at its end z = 0 by a prescribed axial velocity that rises smoothly,
``V (1 - cos(pi t / T)) / 2`` over T = 1 ms, then holds V. The far end z = L is free, so the
wave doubles there: its mean axial velocity goes from 0 to 2V. Arrival criterion: the far end
reaches V (half its final 2V) at ``t_V``; the source reaches half its V at T/2, so the travel
time is ``t_V - T/2`` (the half-amplitude point of a smooth front, which a weakly dispersive
grid moves at the long-wave speed).

- laterally free: the bar speed ``sqrt(E / rho)`` (the pulse, ~1 m long, is 10x the section:
  the lateral-inertia correction is ~(nu pi a / lambda)^2 ~ 1e-3);
- every gridpoint held laterally (uniaxial strain): ``sqrt((K + 4G/3) / rho)``, 9.5 % faster
  at nu = 0.25, so the two cases are told apart well beyond the tolerance (1.5 %).
"""

import itertools

import numpy as np
import pytest

from pdem.deformable.body import DeformableBody
from pdem.deformable.mesh import TetMesh, signed_volumes

E, NU, RHO = 1.0e9, 0.25, 1000.0
L, W = 2.0, 0.1
T_RISE = 1.0e-3
V = 0.01


H_CELL = 0.05  # structured grid: cubes of this side, 6 tets each


def structured_bar() -> TetMesh:
    """The bar as 2 x 2 x 40 cubes, each split into the 6 tets around its main diagonal (Kuhn's
    triangulation: conforming between cubes), the lattice pdem.deformable.mesh makes for a box
    with these spacings, built here so that the test owns its grid."""
    n = (round(W / H_CELL), round(W / H_CELL), round(L / H_CELL))
    idx = np.arange((n[0] + 1) * (n[1] + 1) * (n[2] + 1)).reshape(n[0] + 1, n[1] + 1, n[2] + 1)
    ijk = np.stack(np.meshgrid(*[np.arange(k + 1) for k in n], indexing="ij"), -1)
    nodes = ijk.reshape(-1, 3) * H_CELL
    tets = []
    for i, j, k in np.ndindex(*n):
        for perm in itertools.permutations(range(3)):
            c = np.array([i, j, k])
            path = [idx[tuple(c)]]
            for axis in perm:
                c[axis] += 1
                path.append(idx[tuple(c)])
            tets.append(path)
    tets = np.array(tets, np.int64)
    neg = signed_volumes(nodes, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    on = np.zeros(len(nodes), bool)
    on[idx[[0, -1]].ravel()] = on[idx[:, [0, -1]].ravel()] = on[idx[:, :, [0, -1]].ravel()] = True
    return TetMesh(nodes, tets, np.zeros((0, 3), np.int64), np.zeros(0, np.int64), on)


@pytest.fixture(scope="module")
def bar_mesh():
    return structured_bar()


def arrival(mesh, confined: bool) -> tuple[float, float]:
    """(travel time of the half-amplitude point, the closed-form speed)."""
    b = DeformableBody(mesh, dict(density=RHO, young=E, poisson=NU))
    x0 = b.nodes0
    end = np.isclose(x0[:, 2], 0.0)
    far = np.isclose(x0[:, 2], L)
    if confined:
        b.fix(np.ones(len(x0), bool), dofs=(0, 1))
        speed = np.sqrt((b.params.bulk + 4.0 * b.params.shear / 3.0) / RHO)
    else:
        speed = np.sqrt(E / RHO)
    dt = b.timestep()
    n = int((1.5 * L / speed + T_RISE) / dt)
    vz = np.empty(n)
    for k in range(n):
        t = (k + 0.5) * dt  # the velocity this step sets is v(t + dt/2)
        ramp = V * 0.5 * (1.0 - np.cos(np.pi * min(t / T_RISE, 1.0)))
        b.fix(end, dofs=(2,), velocity=ramp)
        b.step(1, dt)
        vz[k] = b.vel[far, 2].mean()
    t = (np.arange(n) + 0.5) * dt
    i = int(np.argmax(vz >= V))
    assert i > 0 and vz[-1] > 1.5 * V, "the wave did not reach the far end"
    t_v = t[i - 1] + (V - vz[i - 1]) * dt / (vz[i] - vz[i - 1])
    return t_v - 0.5 * T_RISE, speed


@pytest.mark.parametrize("confined", [False, True], ids=["free", "confined"])
def test_wave_arrives_at_the_bar_or_p_wave_speed(bar_mesh, confined):
    travel, speed = arrival(bar_mesh, confined)
    measured = L / travel
    print(f"wave ({'confined' if confined else 'free'}): {len(bar_mesh.tets)} zones, speed "
          f"{measured:.5g} vs {speed:.5g} ({measured / speed - 1:+.2e})")
    assert abs(measured / speed - 1.0) < 1.5e-2
