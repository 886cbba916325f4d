"""What a dynamic analysis costs (docs/dynamics.md): the price of a quiet base per step, and
of Rayleigh damping's stiffness-proportional term in steps (it lowers the stable step).

The S-wave column of tests/verification/test_dynamics_waves.py (20 m, zones of 0.5 m, 960
zones; pdem.cases.waves) in one process, each variant warmed (compiled) first, then timed:

- ``quiet``: the column with a quiet base and the wave put in through it, against the same
  column driven by its held base's velocity (``held``): seconds per step;
- ``rayleigh``: the free-vibration column of the Rayleigh decay test (10 m) over 0.2 s with
  ``damping: none``, ``viscous`` (mass-proportional only, alpha of Rayleigh at f1), and
  ``rayleigh`` at its fundamental f1 and at 3 and 10 times it: the step, the steps, the wall.

    .venv/bin/python bench/dynamics.py [--record]   # --record appends bench/results/dynamics.csv
"""

from __future__ import annotations

import argparse
import csv
import datetime
import math
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mpi4py import MPI  # noqa: E402

from pdem.cases.waves import CS, column_scene, decay_scene  # noqa: E402
from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402

COMMAND = "bench/dynamics.py"


def timed(text: str, steps: int | None = None, time_: float | None = None):
    """(dt, steps, wall seconds) of ``text`` stepped ``steps`` times or for ``time_``."""
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    s = sim.state
    sim.stepper.advance()  # compile outside the timing
    t0 = time.perf_counter()
    n = 0
    while (steps is not None and n < steps) or (time_ is not None and s.time < time_):
        sim.stepper.advance()
        n += 1
    return s.dt, n, time.perf_counter() - t0


def decay_text(damping: str) -> str:
    return decay_scene(10.0, 0.0, None, damping)


def main(record: bool) -> None:
    rows = []
    per = {}
    for base in ("held", "quiet"):
        timed(column_scene("S", 20.0, 0.5, base=base), steps=50)  # warm
        _, n, wall = timed(column_scene("S", 20.0, 0.5, base=base), steps=2000)
        per[base] = wall / n
        print(f"column, {base} base: {1e3 * per[base]:.3f} ms a step")
    ratio = per["quiet"] / per["held"]
    print(f"quiet base and wave input: {ratio:.3f} x the held base's step time")
    rows.append(("quiet_over_held_step_time", f"{ratio:.3f}", "x",
                 f"20 m S column, 960 zones, 2000 steps each; held {1e3 * per['held']:.3f} "
                 f"ms, quiet {1e3 * per['quiet']:.3f} ms a step"))
    f1 = CS / 40.0
    alpha = 0.05 * 2.0 * math.pi * f1
    variants = [("none", "none"), ("viscous (alpha of f1)", f"{{mode: viscous, alpha: {alpha}}}")]
    variants += [(f"rayleigh 0.05 at {k:g} f1",
                  f"{{mode: rayleigh, fraction: 0.05, frequency: {k * f1}}}") for k in (1, 3, 10)]
    base_steps = None
    for name, damping in variants:
        timed(decay_text(damping), steps=20)  # warm
        dt, n, wall = timed(decay_text(damping), time_=0.2)
        base_steps = base_steps or n
        print(f"{name:24s}: dt {dt:.3g} s, {n} steps to 0.2 s ({n / base_steps:.2f} x), "
              f"{wall:.2f} s")
        rows.append((f"steps_0.2s_{name.split()[0]}" + ("" if "rayleigh" not in name else
                                                        f"_{name.split()[-2]}f1"),
                     str(n), "steps", f"10 m decay column, dt {dt:.3g} s, {n / base_steps:.2f} "
                     f"x undamped, {wall:.2f} s wall"))
    if record:
        path = os.path.join(ROOT, "bench", "results", "dynamics.csv")
        new = not os.path.exists(path)
        with open(path, "a", newline="") as f:
            w = csv.writer(f)
            if new:
                w.writerow(["date", "host", "command", "quantity", "value", "unit", "note"])
            for q, v, u, note in rows:
                w.writerow([datetime.date.today().isoformat(), "2-core shared machine (loaded)",
                            COMMAND, q, v, u, note])
        print(f"appended {len(rows)} rows to {os.path.relpath(path, ROOT)}")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--record", action="store_true")
    main(p.parse_args().record)
