"""A block on an incline: sliding acceleration and the just-stable case.

The incline is represented by tilting gravity: ``g = |g| (sin psi, 0, -cos psi)`` acting on a
unit cube resting on a fixed horizontal base box, so the contact is face-to-face on z = 0 and
"down the slope" is +x.

Closed form (rigid block, Coulomb friction phi, no cohesion): when ``phi < psi`` the block
slides with constant acceleration

    a = |g| (sin psi - cos psi tan phi)

and when ``phi > psi`` it stays put.

Start-up: the normal spring starts at the static overlap ``delta = m |g| cos psi / (kn A)``
(the slider's bottom is placed at z = -delta), so the normal contact starts in equilibrium and
no undamped bouncing disturbs the friction. The shear spring still starts unloaded: for the
first ~1 ms the block accelerates at ``|g| sin psi`` until the shear force reaches its Coulomb
limit, which leaves a constant velocity offset of ~2e-3 m/s (a genuine feature of the elastic
joint, not an error of the integrator). The displacement is therefore fitted as
``x = x0 + v0 t + a t^2/2`` over t in [0.1, 1] s; a fit of ``a t^2/2`` alone through the
origin would be biased by ~0.25 % by that offset.
"""

from __future__ import annotations

import numpy as np
import pytest

from pdem.cases import fit_acceleration, make_simulation
from pdem.cases.incline import PSI, incline_scene, sliding_acceleration


@pytest.mark.parametrize("algorithm", ["fast", "cundall"])
@pytest.mark.parametrize("phi", [10.0, 15.0])
def test_sliding_acceleration(phi, algorithm):
    """Sliding acceleration ``a = g (sin psi - cos psi tan phi)`` within 0.5 % (no damping),
    from a fit of the slider's x-displacement over 1 s of sliding."""
    s = make_simulation(incline_scene(phi, algorithm, "time: 1.0"))
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    n = int(round(1.0 / s.dt))
    t = np.empty(n)
    x = np.empty(n)
    for k in range(n):
        s.advance()
        t[k] = s.time
        x[k] = b.x[i, 0] - b.x0[i, 0]
    a_exact = sliding_acceleration(phi)
    late = t >= 0.1
    a_num = fit_acceleration(t[late], x[late])
    err = abs(a_num / a_exact - 1.0)
    print(f"phi={phi} {algorithm}: a={a_num:.6f} exact={a_exact:.6f} rel.err={err:.2e}")
    assert err < 5e-3
    # it slides straight down the slope and stays on the base
    assert abs(b.x[i, 1] - b.x0[i, 1]) < 1e-6
    assert abs(b.x[i, 2] - b.x0[i, 2]) < 1e-5


def run_stable(algorithm: str, damping: str) -> np.ndarray:
    """Displacement history of the slider over 10^4 steps at phi = psi + 1 deg."""
    text = incline_scene(PSI + 1.0, algorithm, "steps: 10000").replace(
        "damping: none", f"damping: {damping}")
    s = make_simulation(text)
    b = s.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    u = np.empty((10000, 3))
    for k in range(10000):
        s.advance()
        u[k] = b.x[i] - b.x0[i]
    assert s.step == 10000
    return u


@pytest.mark.parametrize("algorithm", ["fast", "cundall"])
def test_just_stable_no_drift(algorithm):
    """phi = psi + 1 deg: the block holds. Local damping (alpha = 0.8), to remove the start-up
    transient of the unloaded shear spring: over 10^4 steps (~0.94 s) the displacement never
    exceeds 0.1 mm, and after the first 2000 steps it changes by less than 1e-6 m (no creep).
    (The elastic shear deflection m g sin(psi) / (ks A) alone is ~7e-6 m.)"""
    u = run_stable(algorithm, "local")
    worst = float(np.linalg.norm(u, axis=1).max())
    creep = float(np.linalg.norm(u[2000:] - u[2000], axis=1).max())
    print(f"{algorithm}: max displacement {worst:.3e} m, creep after step 2000 {creep:.2e} m")
    assert worst < 1e-4
    assert creep < 1e-6


def test_just_stable_undamped_no_creep():
    """Same, without damping. The suddenly loaded shear spring overshoots twice its static
    load, above the Coulomb limit (tan 21 deg cos 20 deg < 2 sin 20 deg), so the block slips
    during the first few shear oscillations -- physically right, ~0.17 mm here, estimated by a
    one-spring energy balance at ~0.1 mm. After that (steps 2000..10000) it must not move by
    more than 5e-6 m: no ratcheting, only the undamped elastic vibration (~1e-6 m)."""
    u = run_stable("fast", "none")
    worst = float(np.linalg.norm(u, axis=1).max())
    creep = float(np.linalg.norm(u[2000:] - u[2000], axis=1).max())
    print(f"undamped: max displacement {worst:.3e} m, creep after step 2000 {creep:.2e} m")
    assert worst < 1e-3
    assert creep < 5e-6
