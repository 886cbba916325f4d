"""Rock mass build benchmark: a 40 x 40 x 30 m region on a fixed base, cut by three joint sets
of one spacing (pdem.model.rockmass: the cuts, then sliver joining), set up to the first step.

    .venv/bin/python bench/rock_mass_build.py                   # spacings 2 and 1.5, 1 and 2 ranks
    .venv/bin/python bench/rock_mass_build.py --spacing 4 2 --ranks 1 2 3
    .venv/bin/python bench/rock_mass_build.py --mesh 30 --ranks 2   # a mesh of 30^3 cells

Prints, per spacing and rank count, the blocks made, the seconds of the build (the cuts and
sliver joining: every rank gets every block) and of the whole set-up to the first step (the
slowest rank), and the largest rank's resident memory before the set-up (kernels loaded) and
at its peak, with what the model added per block. Run it against another tree with
PYTHONPATH=that/tree to compare. Not a test: timings on shared machines are noisy.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from pdem.memory import resident_mb

SCENE = """
name: jointed-{spacing}
materials:
  granite: {{density: 2600}}
joints:
  default: {{kn: 5.0e9, ks: 2.5e9, friction: 35}}
blocks:
  - {{name: rock, box: {{min: [0, 0, 0], max: [40, 40, 30]}}, material: granite, group: rock}}
  - {{name: base, box: {{min: [-5, -5, -5], max: [45, 45, 0]}}, material: granite, group: base,
     fixed: true}}
cuts:
  - {{name: J1, dip: 60, dip_direction: 120, origin: [20, 20, 15], spacing: {spacing}, groups: [rock]}}
  - {{name: J2, dip: 50, dip_direction: 220, origin: [20, 20, 15], spacing: {spacing}, groups: [rock]}}
  - {{name: B, dip: 5, dip_direction: 180, origin: [20, 20, 15], spacing: {spacing}, groups: [rock]}}
solve: {{steps: 1}}
"""


# the cut region's scene with the region a mesh (its materials and joints)
MESH_SCENE = SCENE[:SCENE.index("blocks:")].replace("jointed-{spacing}", "meshed-{n}") + """\
blocks:
  - {{name: rock, mesh: {{file: {path}, cell_data_group: pair}}, material: granite}}
  - {{name: base, box: {{min: [-1, -1, -1], max: [{top}, {top}, 0]}}, material: granite,
     fixed: true}}
solve: {{steps: 1}}
"""


def mesh_scene(n: int, comm) -> str:
    """A lattice of n^3 unit hexahedra joined two by two along x (a .vtu rank 0 writes), on
    a fixed base."""
    import tempfile

    import meshio
    import numpy as np

    path = Path(tempfile.gettempdir()) / f"pdem-bench-mesh-{n}.vtu"
    if comm.rank == 0:
        x = np.arange(n + 1, dtype=float)
        pts = np.stack(np.meshgrid(x, x, x, indexing="ij"), axis=-1).reshape(-1, 3)
        i, j, k = (a.ravel() for a in np.meshgrid(*(np.arange(n),) * 3, indexing="ij"))

        def node(a, b, c):
            return (a * (n + 1) + b) * (n + 1) + c

        cells = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k),
                          node(i, j + 1, k), node(i, j, k + 1), node(i + 1, j, k + 1),
                          node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)], axis=1)
        pair = ((i // 2) * n * n + j * n + k).astype(float)
        meshio.write(path, meshio.Mesh(pts, [("hexahedron", cells)],
                                       cell_data={"pair": [pair]}))
    comm.Barrier()
    return MESH_SCENE.format(n=n, path=path, top=n + 1)


def child(spacing: float) -> None:
    from mpi4py import MPI

    import pdem.state as st
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    build = [0.0]
    expand = st.expand_blocks

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return expand(*args, **kwargs)
        finally:
            build[0] += time.perf_counter() - t0

    st.expand_blocks = timed
    # the kernels loaded on a small rock mass first: the memory figures are the model's
    Simulation(parse_scene(SCENE.format(spacing=20.0)), comm, output=False).run(steps=1)
    build[0] = 0.0
    gc.collect()
    before = resident_mb()
    # a negative spacing -n: the mesh of n^3 cells (--mesh)
    scene = parse_scene(SCENE.format(spacing=spacing) if spacing > 0
                        else mesh_scene(int(-spacing), comm))
    comm.Barrier()
    t0 = time.perf_counter()
    sim = Simulation(scene, comm, output=False)
    sim.run(steps=1)
    total = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    gc.collect()
    after = resident_mb()
    rows = comm.gather((build[0], total, before, peak, after), root=0)
    if comm.rank == 0:
        print("RESULT " + json.dumps({"spacing": spacing, "ranks": comm.size,
                                      "blocks": sim.state.glob.n,
                                      "build": max(r[0] for r in rows),
                                      "total": max(r[1] for r in rows),
                                      "before": max(r[2] for r in rows),
                                      "peak": max(r[3] for r in rows),
                                      "after": max(r[4] for r in rows)}), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spacing", type=float, nargs="+", default=[2.0, 1.5])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--mesh", type=int, nargs="+", default=[],
                    help="instead of the cut region: a mesh of n^3 hexahedra joined two by two")
    ap.add_argument("--child", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child)
        return
    py = sys.executable
    mpiexec = Path(py).with_name("mpiexec")
    print(f"{'spacing':>8} {'ranks':>6} {'blocks':>8} {'build s':>9} {'set-up s':>9} "
          f"{'MB before':>10} {'peak MB':>8} {'after MB':>9} {'kB/block':>9} {'after':>6}")
    for spacing in [-float(n) for n in args.mesh] if args.mesh else args.spacing:
        for ranks in args.ranks:
            cmd = [str(mpiexec), "-n", str(ranks), py, __file__, "--child", str(spacing)]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ)
            line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
            if proc.returncode or not line:
                print(f"spacing {spacing}, {ranks} ranks: failed (exit {proc.returncode})\n"
                      f"{proc.stderr[-2000:]}")
                continue
            r = json.loads(line[0][7:])
            # kB/block: what the model added to a rank's resident memory (at the peak and
            # after set-up), per block of the scene
            per = 1024.0 * (r["peak"] - r["before"]) / r["blocks"]
            kept = 1024.0 * (r["after"] - r["before"]) / r["blocks"]
            print(f"{spacing:>8g} {ranks:>6} {r['blocks']:>8} {r['build']:>9.2f} "
                  f"{r['total']:>9.2f} {r['before']:>10.0f} {r['peak']:>8.0f} "
                  f"{r['after']:>9.0f} {per:>9.2f} {kept:>6.2f}", flush=True)


if __name__ == "__main__":
    main()
