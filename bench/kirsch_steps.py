"""Steps to a static ratio for the zoned Kirsch model (docs/deformable.md, "Kirsch"): the
scene of tests/verification/test_deformable_kirsch.py (a quarter ring at size 0.25, ~5,400
zones, the tunnel excavated by a stage, fictitious joints kn = 1e11, local damping, mass
scaling), its excavation stage solved to the test's ratio 2e-3 (the first line is the test's
run), then marched on to each smaller target in turn (``Run.run(ratio=...)``); at each, the
test's measures: the wall's radial displacement at the springline and the crown against the
closed form, and the largest error of the zones' stresses averaged by band.

    PYTHONPATH=. .venv/bin/python bench/kirsch_steps.py [K [max_steps [kn]]]

K: the in-situ ratio (1.0 hydrostatic, 0.5); kn: the fictitious joints' stiffness (1e11).
Prints one line per target: steps to reach it (or the ratio at max_steps).
"""

import math
import sys
import time
from pathlib import Path

from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "verification"))
from test_deformable_kirsch import A, G, P, measured, scene  # noqa: E402

from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402

TARGETS = (2e-3, 1e-3, 1e-4, 1e-5)  # the first is the test's


def errors(sim, K):
    """The test's measures: wall errors at the springline and the crown, of ``p a / 2G``;
    the largest band stress error, of p."""
    at_wall, bands = measured(sim, K)
    scale = P * A / (2 * G)
    (s0, e0), (s1, e1) = at_wall[0.0], at_wall[math.pi / 2]
    worst = max(max(abs(a), abs(b)) for a, b, _ in bands.values())
    return (s0 - e0) / scale, (s1 - e1) / scale, worst


def main(K: float, max_steps: int, kn: float) -> None:
    text = scene(K).replace("ratio: 2.0e-3, max_steps: 20000",
                            f"ratio: {TARGETS[0]}, max_steps: {max_steps}")
    text = text.replace("kn: 1.0e11, ks: 1.0e11", f"kn: {kn}, ks: {kn}")
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    t0 = time.time()
    out = sim.run()
    steps = out["steps"]
    print(f"K = {K}, kn = {kn:g}; target, steps of the excavation stage, ratio, wall errors "
          f"(measured - closed form, of p a / 2G), largest band stress error (of p), "
          f"wall seconds", flush=True)
    for target in TARGETS:
        if target < TARGETS[0]:
            if out["ratio"] > TARGETS[0] or steps >= max_steps:
                break
            out = sim.runner.run(ratio=target, max_steps=max_steps - steps, no_progress=0)
            steps += out["steps"]
        sp, cr, band = errors(sim, K)
        print(f"{target:.0e}  {steps:6d}  {out['ratio']:.2e}  springline {sp:+.4f} crown {cr:+.4f}"
              f"  bands {band:.4f}  {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    a = sys.argv[1:]
    main(float(a[0]) if a else 1.0, int(a[1]) if len(a) > 1 else 60000,
         float(a[2]) if len(a) > 2 else 1.0e11)
