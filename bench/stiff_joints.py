"""A tunnel in jointed zoned rock with stiff fictitious joints (docs/deformable.md, "The
contacts of the step"): the scene of tests/mpi/test_deformable_mpi.py's jointed tunnel (a
4 x 0.5 x 4 m zoned block cut by two joint sets and a 12-sided tunnel, in-situ 1 MPa, mass
scaling) with the fictitious joints' kn and ks set to KN, each stage STEPS long. Prints the
steps run, the largest gridpoint speed, the ratio at the end, how many gridpoints the step's
contacts made heavier than the stage's estimate, and the energy balance. Before the per-step
contact stiffness, KN = 1e11 ran away at step 5.

    PYTHONPATH=. .venv/bin/python bench/stiff_joints.py [KN [STEPS]]     # 1e11 6000: ~60 s
"""

import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "mpi"))
from test_deformable_mpi import JOINTED_TUNNEL  # noqa: E402

from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402


def main(kn: float, steps: int) -> None:
    out = str(Path(tempfile.mkdtemp()) / "stiff.h5")
    text = JOINTED_TUNNEL.format(out=out, checkpoint="")
    text = text.replace("default: {kn: 1.0e10, ks: 1.0e10", f"default: {{kn: {kn:g}, ks: {kn:g}")
    text = text.replace("solve: {steps: 80}", f"solve: {{steps: {steps}}}")
    t0 = time.perf_counter()
    s = Simulation(parse_scene(text), MPI.COMM_WORLD)
    s.run()
    g = s.state.grids
    raised = sum(int(np.count_nonzero(b.emass > b.mass)) for b in g.bodies)
    print(f"kn {kn:g}: {s.step} steps in {time.perf_counter() - t0:.1f} s; largest gridpoint "
          f"speed {np.abs(g.vel).max():.3g} m/s; ratio {s.state.ratio:.3g}; gridpoints made "
          f"heavier by the step's contacts {raised} of {len(g.vel)}")
    s.close()
    with h5py.File(out, "r") as f:
        e = f["histories/energy"]
        last = dict(zip(e.attrs["columns"].split(","), e["value"][-1], strict=True))
    put_in = last["gravity_work"] + last["applied_work"] + last["boundary_work"]
    print(f"energy balance error {last['balance_error']:.3g} J of {put_in:.4g} J put in "
          f"(from contact geometry updates {last['geometry_created']:.3g} J)")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 1e11,
         int(sys.argv[2]) if len(sys.argv) > 2 else 6000)
