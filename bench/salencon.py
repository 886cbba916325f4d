"""Salencon's Mohr-Coulomb cavity on the Kirsch model (docs/deformable.md, "Salencon"): the
quarter ring of tests/verification/test_deformable_kirsch.py in Mohr-Coulomb rock (c = 0.2 MPa,
phi = 30, psi = 0) under 1 MPa hydrostatic in-situ stress, the tunnel excavated unsupported;
prints the plastic radius (the closed form on the finite ring, and the infinite one) and, by
radial band, the zones' yield and their radial and hoop stresses against the closed form. Not in
the test suite (~70 s alone on one core).

    PYTHONPATH=. .venv/bin/python bench/salencon.py [max_steps]
"""

import math
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "verification"))
from test_deformable_kirsch import A, R, scene  # noqa: E402

from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402

P, C, PHI = 1.0e6, 0.2e6, 30.0
S = math.sin(math.radians(PHI))
KP = (1 + S) / (1 - S)
SC = 2 * C * math.cos(math.radians(PHI)) / (1 - S)
Q = SC / (KP - 1)


def plastic(r):
    """Radial and hoop stress (compression positive) in the plastic ring, no support."""
    sr = -Q + Q * (r / A) ** (KP - 1)
    return sr, KP * sr + SC


def elastic(r0):
    """Lame's (A, B) of the elastic ring r0 < r < R meeting the plastic one at r0."""
    sr, st = plastic(r0)
    return (sr + st) / 2, (st - sr) / 2 * r0**2


def plastic_radius() -> float:
    """r0 where the elastic ring's outer radial stress is p (bisection)."""
    def f(r0):
        a, b = elastic(r0)
        return a - b / R**2 - P
    lo, hi = A, R
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if f(lo) * f(mid) <= 0 else (mid, hi)
    return 0.5 * (lo + hi)


def closed_form(r, r0):
    a, b = elastic(r0)
    sr, st = plastic(r)
    return np.where(r < r0, sr, a - b / r**2), np.where(r < r0, st, a + b / r**2)


def main(max_steps: int) -> None:
    mc = (f"rock: {{density: 2500, young: 1000000000.0, poisson: 0.25, model: mohr_coulomb, "
          f"cohesion: {C}, friction: {PHI}, tension: 1.0e7, dilation: 0}}")
    text = scene(1.0).replace("rock: {density: 2500, young: 1000000000.0, poisson: 0.25}", mc)
    text = text.replace("-750000.0", "-1000000.0")  # hydrostatic, out of plane too
    text = text.replace("solve: {ratio: 2.0e-3, max_steps: 20000}",
                        f"solve: {{ratio: 1.0e-3, max_steps: {max_steps}}}")
    assert "mohr_coulomb" in text and "-750000.0" not in text
    t0 = time.time()
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    out = sim.run()
    print(f"steps {out['steps']}, ratio {out['ratio']:.2e}, {time.time() - t0:.0f} s")
    r0 = plastic_radius()
    inf = A * (2 / (KP + 1) * (P + Q) / Q) ** (1 / (KP - 1))
    print(f"plastic radius, closed form: {r0:.3f} m on this ring ({inf:.3f} m infinite)")
    rows = []
    for b in sim.state.grids.bodies:
        if not b.active:
            continue
        c = b.nodes0[b.tets].mean(axis=1)
        rc, tc = np.hypot(c[:, 0], c[:, 2]), np.arctan2(c[:, 2], c[:, 0])
        cs, sn, s = np.cos(tc), np.sin(tc), b.stress
        srr = s[:, 0] * cs**2 + s[:, 2] * sn**2 + 2 * s[:, 5] * cs * sn
        stt = s[:, 0] * sn**2 + s[:, 2] * cs**2 - 2 * s[:, 5] * cs * sn
        rows.append(np.c_[rc, -srr, -stt, b.plastic > 0])
    z = np.vstack(rows)
    ex_r, ex_t = closed_form(z[:, 0], r0)
    print("band (m)   zones  yielded  sr err/p  st err/p")
    for lo, hi in ((1.0, 1.2), (1.2, 1.4), (1.4, 1.5), (1.5, 1.6), (1.6, 2.0), (2.0, 3.0)):
        m = (z[:, 0] >= lo) & (z[:, 0] < hi)
        print(f"{lo:.1f}-{hi:.1f}  {m.sum():6d}  {z[m, 3].mean():7.2f}  "
              f"{(z[m, 1] - ex_r[m]).mean() / P:+8.3f}  {(z[m, 2] - ex_t[m]).mean() / P:+8.3f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
