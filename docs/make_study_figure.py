"""docs/figures/study-wedge.png: the worked example of docs/studies.md, the probabilistic wedge
of configs/wedge-study.yaml (200 cases), drawn by ``pdem plot``.

    .venv/bin/mpiexec -n 2 .venv/bin/python docs/make_study_figure.py   # ~2 min on 2 cores

(run from the repository's root; the study's files go to a temporary folder).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from mpi4py import MPI

from pdem.plot import plot
from pdem.study.runner import run_study

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    comm = MPI.COMM_WORLD
    work = Path(tempfile.mkdtemp()) if comm.rank == 0 else None
    work = comm.bcast(work)
    scene = work / "wedge-study.yaml"
    if comm.rank == 0:
        shutil.copy(ROOT / "configs" / "wedge-study.yaml", scene)
    comm.Barrier()
    table = run_study(scene, comm)
    if comm.rank == 0:
        out = plot(table.path, out=ROOT / "docs" / "figures" / "study-wedge.png")
        print(f"wrote {out}")
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
