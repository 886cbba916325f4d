"""Salencon's Mohr-Coulomb cavity on the Kirsch model, in detail (docs/deformable.md,
"Salencon"): the scene and closed forms of tests/verification/test_deformable_salencon.py
(which asserts the plastic radius, the wall displacement and the radial stress); prints, by
radial band, the zones' yielded fraction and their radial and hoop stresses against the
closed form, and the wall's radial displacement. RATIO: the solve's target (the test's 2e-3).

    PYTHONPATH=. .venv/bin/python bench/salencon.py [max_steps [ratio]]
"""

import sys
import time
from pathlib import Path

from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "verification"))
from test_deformable_salencon import (  # noqa: E402
    P,
    closed_form,
    measured,
    mohr_coulomb_scene,
    plastic_radius,
    wall_displacement,
    yield_radius,
)

from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402


def main(max_steps: int, ratio: float) -> None:
    t0 = time.time()
    sim = Simulation(parse_scene(mohr_coulomb_scene(ratio, max_steps)), MPI.COMM_SELF,
                     output=False)
    out = sim.run()
    print(f"steps {out['steps']}, ratio {out['ratio']:.2e}, {time.time() - t0:.0f} s")
    z, wall = measured(sim)
    r0 = plastic_radius()
    print(f"plastic radius {yield_radius(z):.3f} m, closed form {r0:.3f} m on this ring")
    print(f"wall radial displacement {wall.mean():.4g} m ({wall.min():.4g} .. {wall.max():.4g}),"
          f" closed form {wall_displacement(r0):.4g} m")
    ex_r, ex_t = closed_form(z[:, 0], r0)
    print("band (m)   zones  yielded  sr err/p  st err/p")
    for lo, hi in ((1.0, 1.2), (1.2, 1.4), (1.4, 1.5), (1.5, 1.6), (1.6, 2.0), (2.0, 3.0)):
        m = (z[:, 0] >= lo) & (z[:, 0] < hi)
        print(f"{lo:.1f}-{hi:.1f}  {m.sum():6d}  {z[m, 3].mean():7.2f}  "
              f"{(z[m, 1] - ex_r[m]).mean() / P:+8.3f}  {(z[m, 2] - ex_t[m]).mean() / P:+8.3f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000,
         float(sys.argv[2]) if len(sys.argv) > 2 else 2.0e-3)
