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

from pdem.cases import make_simulation, rotation_matrix
from pdem.cases.tumbling import SHAPES, angular_momentum, kinetic_energy, tumbling_scene


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_free_tumbling_invariants(shape):
    """|H(t) - H(0)| / |H(0)| < 1e-10 and |K(t) - K(0)| / K(0) < 1e-5 at every step."""
    s = make_simulation(tumbling_scene(shape))
    b = s.blocks
    # the angular velocity is not along a principal axis (the motion is a genuine tumble)
    R0 = rotation_matrix(b.q[0])
    wb = R0.T @ b.w[0]
    assert np.abs(wb).max() / np.linalg.norm(wb) < 0.97

    def momentum() -> np.ndarray:
        return angular_momentum(b)

    def energy() -> float:
        return kinetic_energy(b)

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
    w_end = rotation_matrix(b.q[0]).T @ b.w[0]
    print(f"{shape}: |dH|/|H| = {dh:.2e}, |dK|/K = {dk:.2e}, turned {turned:.2f} rad, body w "
          f"{wb.round(3)} -> {w_end.round(3)}")
    assert s.contacts.n == 0
    assert turned > 2.0
    assert abs(float(q0 @ b.q[0])) < 0.99  # the orientation did change
    assert dh < 1e-10
    assert dk < 1e-5
