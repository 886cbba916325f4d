"""Restart benchmark: time and memory to continue the cube stack from a checkpoint.

The model is the cube stack of bench/setup.py (n x n x n unit cubes on a floor, every cube in
face contact: ~10 contacts a cube). A first job builds it, steps it ``--steps`` times and writes
a checkpoint; a second job (a fresh process per rank, the kernels loaded first on a small model)
restarts from it and takes one step. Each job runs under ``mpiexec -n RANKS``.

    .venv/bin/python bench/restart.py                    # N = 64,000 on 2 ranks
    .venv/bin/python bench/restart.py --n 20 40 --ranks 3

Prints per size the restart's seconds to the first step (slowest rank), its peak resident MB
per rank (getrusage; the largest over the ranks; ``restored``: the peak once the model is
restored, before the first step's start-up) and the rows of contacts and sub-contacts each
rank read from the file (the largest over the ranks, and the file's totals). Run it against
another tree with PYTHONPATH=that/tree to compare. Not a test: timings on shared machines are
noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _scene(n: int, steps: int, ck: str) -> str:
    from pdem.cases.stacks import cube_stack_scene

    text = cube_stack_scene(n, "fast").replace("solve: {steps: 1,", f"solve: {{steps: {steps},")
    return text + f"checkpoint: {{every_steps: {steps}, file: {ck}}}\n"


def write(n: int, steps: int, ck: str) -> None:
    """Build, step and checkpoint the n^3 stack (no output file)."""
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    sim = Simulation(parse_scene(_scene(n, steps, ck)), MPI.COMM_WORLD, output=False)
    sim.run()
    sim.close()


def restart(n: int, steps: int, ck: str) -> None:
    """Restart from the checkpoint, step once; print one JSON line (rank 0)."""
    from mpi4py import MPI

    import pdem.io.checkpoint as checkpoint_io
    from pdem.cases.stacks import cube_stack_scene
    from pdem.config import parse_scene
    from pdem.io.checkpoint import open_checkpoint
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    Simulation(parse_scene(cube_stack_scene(2, "fast")), comm, output=False).run(steps=1)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    read: dict[str, int] = {}
    whole = checkpoint_io._read_rows

    def counted(dset, rows):
        read[dset.name] = read.get(dset.name, 0) + len(rows)
        return whole(dset, rows)

    checkpoint_io._read_rows = counted
    path = f"{ck}-{steps:09d}.h5"
    comm.Barrier()
    t0 = time.perf_counter()
    ck_state = open_checkpoint(path)
    scene = parse_scene(ck_state["attrs"]["scene"])
    sim = Simulation(scene.model_copy(update={"checkpoint": None}), comm, checkpoint=ck_state,
                     output=False)
    rss_restored = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    sim.run(steps=1)
    elapsed = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    import h5py

    with h5py.File(path, "r") as f:
        totals = (len(f["contacts/nsub"]), len(f["subcontacts/sc_un"]))
    rows = comm.gather((elapsed, rss, rss0, read.get("/contacts/normal", 0),
                        read.get("/subcontacts/sc_un", 0), rss_restored), root=0)
    if comm.rank == 0:
        print("RESULT " + json.dumps({
            "n": n, "cubes": n ** 3, "ranks": comm.size, "seconds": max(r[0] for r in rows),
            "peak_mb": max(r[1] for r in rows), "base_mb": max(r[2] for r in rows),
            "contacts_read": max(r[3] for r in rows), "subs_read": max(r[4] for r in rows),
            "contacts": totals[0], "subs": totals[1],
            "restored_mb": max(r[5] for r in rows)}), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[40], help="cubes per side; default 40")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks (mpiexec), default 2")
    ap.add_argument("--steps", type=int, default=20, help="steps before the checkpoint")
    ap.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        what, n, steps, ck = args.child
        (write if what == "write" else restart)(int(n), int(steps), ck)
        return
    py = sys.executable
    launch = [str(Path(py).with_name("mpiexec")), "-n", str(args.ranks), py, __file__, "--child"]
    print(f"restart of the cube stack from a checkpoint after {args.steps} steps, "
          f"{args.ranks} rank(s)")
    print(f"{'cubes':>10} {'seconds':>8} {'peak MB':>8} {'restored':>8} {'base MB':>8} "
          f"{'contacts read / in file':>24} {'sub-contacts read / in file':>28}")
    with tempfile.TemporaryDirectory() as d:
        for n in args.n:
            ck = os.path.join(d, f"ck{n}")
            for what in ("write", "restart"):
                proc = subprocess.run([*launch, what, str(n), str(args.steps), ck],
                                      capture_output=True, text=True, env=os.environ)
                if proc.returncode:
                    print(f"n={n} {what}: failed (exit {proc.returncode})\n"
                          f"{proc.stderr[-2000:]}")
                    break
            else:
                line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
                r = json.loads(line[0][7:])
                print(f"{r['cubes']:>10,} {r['seconds']:>8.2f} {r['peak_mb']:>8.0f} "
                      f"{r.get('restored_mb', 0.0):>8.0f} "
                      f"{r['base_mb']:>8.0f} {r['contacts_read']:>11,} / {r['contacts']:<11,}"
                      f" {r['subs_read']:>13,} / {r['subs']:<13,}")


if __name__ == "__main__":
    main()
