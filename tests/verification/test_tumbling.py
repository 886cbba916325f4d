"""Torque-free rotation of an asymmetric rigid block (no gravity, no contacts).

Closed form: with no external force or moment, the world angular momentum about the origin,
``H = L + m x * v`` (``L`` = spin angular momentum about the centroid, world frame), and the
kinetic energy ``K = 1/2 m |v|^2 + 1/2 w . L`` are constants of the motion, whatever the
(chaotic-looking) tumbling about a non-principal axis does.

pdem keeps the world L as rotational state and turns the block with an implicit-midpoint
step (pdem/dynamics/motion.py), so H is conserved to round-off (asserted 1e-10 relative) and
the kinetic-energy error stays bounded (asserted 1e-5 relative) over 5000 steps, during which
the block turns through several radians about a wandering axis.
"""

from __future__ import annotations

import numpy as np
import pytest
from vhelpers import make_solver, vec


def random_polyhedron_vertices(seed: int = 7, n: int = 14) -> np.ndarray:
    """Points on an ellipsoid with semi-axes (0.6, 1.0, 1.5), off the origin: all on the hull,
    with no symmetry, so the principal axes are not the coordinate axes."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    return p * np.array([0.6, 1.0, 1.5]) + np.array([2.0, -1.0, 3.0])


# shape and initial angular velocity (world), chosen well off every principal axis
SHAPES = {
    "box123": ("box: {min: [0, 0, 0], max: [1, 2, 3]}", (2.0, 5.0, -7.0)),
    "random": ("polyhedron: {vertices: [" + ", ".join(vec(p) for p in random_polyhedron_vertices())
               + "]}", (5.0, -3.0, 4.0)),
}


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_free_tumbling_invariants(shape):
    """|H(t) - H(0)| / |H(0)| < 1e-10 and |K(t) - K(0)| / K(0) < 1e-5 at every step."""
    text = f"""
gravity: [0, 0, 0]
materials: {{rock: {{density: 2500}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - name: tumbler
    {SHAPES[shape][0]}
    material: rock
    velocity: [0.3, -0.2, 0.5]
    angular_velocity: {vec(SHAPES[shape][1])}
solve: {{steps: 5000, damping: none}}
"""
    s = make_solver(text)
    b = s.blocks
    m = float(b.mass[0])
    # the angular velocity is not along a principal axis (the motion is a genuine tumble)
    R0 = _rotation(b.q[0])
    wb = R0.T @ b.w[0]
    assert np.abs(wb).max() / np.linalg.norm(wb) < 0.97

    def momentum() -> np.ndarray:
        return b.L[0] + m * np.cross(b.x[0], b.v[0])

    def energy() -> float:
        return 0.5 * m * float(b.v[0] @ b.v[0]) + 0.5 * float(b.w[0] @ b.L[0])

    h0 = momentum()
    k0 = energy()
    q0 = b.q[0].copy()
    dh = dk = 0.0
    turned = 0.0
    for _ in range(5000):
        s.advance()
        dh = max(dh, float(np.linalg.norm(momentum() - h0)) / float(np.linalg.norm(h0)))
        dk = max(dk, abs(energy() - k0) / k0)
        turned += float(np.linalg.norm(b.w[0])) * s.dt
    w_end = _rotation(b.q[0]).T @ b.w[0]
    print(f"{shape}: |dH|/|H| = {dh:.2e}, |dK|/K = {dk:.2e}, turned {turned:.2f} rad, body w "
          f"{wb.round(3)} -> {w_end.round(3)}")
    assert s.contacts.n == 0
    assert turned > 2.0
    assert abs(float(q0 @ b.q[0])) < 0.99  # the orientation did change
    assert dh < 1e-10
    assert dk < 1e-5


def _rotation(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
