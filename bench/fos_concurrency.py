"""Should strength-reduction trials run concurrently on sub-communicators? A measurement.

    .venv/bin/python bench/fos_concurrency.py [--scene configs/slope.yaml] [--steps 1500]
                                              [--ranks 2] [--tolerance 0.01] [--high 4]

A factor-of-safety search (pdem.strength) is a sequence of trials; bisection needs each
result before choosing the next F. With P ranks it can instead split them into k groups and try
k factors at once (a (k+1)-section search): fewer rounds, log(range/tol)/log(k+1) instead of
/log 2, but each trial on P/k ranks. Whether that wins depends on how well one trial scales
from P/k to P ranks. This script measures exactly that on the given scene: the same
``--steps`` steps (a trial's worth of work) on ``--ranks`` ranks and on ``ranks/k`` ranks with k
runs at once (the concurrent trials compete for the machine as they would), then prints the
predicted time of a search both ways.

Not a test: timings on shared machines are noisy; quote ratios from one run.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MPIEXEC = os.path.join(ROOT, ".venv", "bin", "mpiexec")
PDEM = os.path.join(ROOT, ".venv", "bin", "pdem")


def _job(n: int, scene: str, steps: int, out: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([MPIEXEC, "-n", str(n), PDEM, "run", scene, "--steps", str(steps),
                             "-o", out, "-q"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=env)


def timed(jobs: list[subprocess.Popen]) -> float:
    t0 = time.perf_counter()
    for j in jobs:
        out, _ = j.communicate()
        if j.returncode != 0:
            sys.exit(f"a run failed:\n{out[-2000:]}")
    return time.perf_counter() - t0


def rounds(k: int, high: float, tol: float) -> int:
    """Rounds of a (k+1)-section search of [1, high] down to a relative gap ``tol``."""
    return max(1, math.ceil(math.log((high - 1.0) / tol) / math.log(k + 1)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=os.path.join(ROOT, "configs", "slope.yaml"))
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--tolerance", type=float, default=0.01)
    p.add_argument("--high", type=float, default=4.0)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        # warm the numba cache so neither variant pays the compile
        timed([_job(1, a.scene, 5, f"{d}/warm.h5")])
        whole = timed([_job(a.ranks, a.scene, a.steps, f"{d}/whole.h5")])
        print(f"one trial's {a.steps} steps on {a.ranks} ranks: {whole:.1f} s")
        for k in range(2, a.ranks + 1):
            if a.ranks % k:
                continue
            split = timed([_job(a.ranks // k, a.scene, a.steps, f"{d}/part{i}.h5")
                           for i in range(k)])
            seq = rounds(1, a.high, a.tolerance) * whole
            con = rounds(k, a.high, a.tolerance) * split
            print(f"{k} trials at once on {a.ranks // k} rank(s) each: {split:.1f} s per round")
            print(f"  search of [1, {a.high:g}] to {a.tolerance:g}: bisection "
                  f"{rounds(1, a.high, a.tolerance)} rounds = {seq:.0f} s; {k + 1}-section "
                  f"{rounds(k, a.high, a.tolerance)} rounds = {con:.0f} s; concurrent / "
                  f"sequential = {con / seq:.2f}")


if __name__ == "__main__":
    main()
