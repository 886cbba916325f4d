"""What a study case costs (docs/studies.md): the planar slide of pdem.cases.studies, one
factor-of-safety search per case, in one process on MPI.COMM_SELF, each variant warmed
(compiled) first, then timed:

- ``case_fused``: one case as a study runs it (the search's trials in compiled runs of steps,
  pdem.driver.Run.march);
- ``case_python``: the same case with ``solve.fused: false`` (every step in Python, as the
  search stepped before this round); both must find the same factor, bit for bit;
- ``study``: a study of ``--cases`` cases (build, settle, search, write, measure, record each).

    .venv/bin/python bench/study.py [--cases 24] [--record [--host TEXT]]   # appends bench/results/study.csv
"""

from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mpi4py import MPI  # noqa: E402

import pdem  # noqa: E402
from pdem.cases.studies import planar_study_scene  # noqa: E402
from pdem.study.runner import run_study  # noqa: E402

COMMAND = "bench/study.py"


def one_case(work: Path, fused: bool, repeat: int = 3) -> tuple[float, float]:
    """(median wall seconds, factor) of one planar case at phi = 21 deg."""
    scene = pdem.Scene.from_yaml(planar_study_scene(1)).with_(
        {"joints.default.friction": 21.0, "stages.strength.joints.default.friction": 21.0,
         "solve.fused": fused, "studies": {}}, output=str(work / f"case-{fused}.h5"))
    pdem.run(scene, MPI.COMM_SELF).close()  # warm
    walls, factor = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = pdem.run(scene, MPI.COMM_SELF)
        walls.append(time.perf_counter() - t0)
        factor = r.factor_of_safety.value
        r.close()
    return sorted(walls)[len(walls) // 2], factor


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=24)
    ap.add_argument("--record", action="store_true")
    ap.add_argument("--host", default="2-core shared machine",
                    help="the host's description in the record (bench/results/README.md)")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp())
    fused, f1 = one_case(work, True)
    python, f2 = one_case(work, False)
    assert f1 == f2, (f1, f2)
    path = work / "planar.yaml"
    path.write_text(planar_study_scene(args.cases))
    t0 = time.perf_counter()
    run_study(path, MPI.COMM_SELF, echo=False)
    study = time.perf_counter() - t0
    rows = [("case_fused", fused, "s", f"factor {f1:.6g}"),
            ("case_python", python, "s", f"factor {f2:.6g} (the same bits)"),
            ("python_over_fused", python / fused, "", "one case, median of 3"),
            ("study_per_case", study / args.cases, "s", f"{args.cases} cases, 1 rank")]
    for q, v, unit, note in rows:
        print(f"{q:>20}: {v:.4g} {unit}  ({note})")
    if args.record:
        out = Path(ROOT) / "bench" / "results" / "study.csv"
        new = not out.exists()
        with out.open("a", newline="") as fh:
            w = csv.writer(fh)
            if new:
                w.writerow(["date", "host", "command", "quantity", "value", "unit", "note"])
            for q, v, unit, note in rows:
                w.writerow([datetime.date.today().isoformat(), args.host,
                            f"{COMMAND} --cases {args.cases}", q, f"{v:.6g}", unit, note])


if __name__ == "__main__":
    main()
