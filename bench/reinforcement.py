"""What reinforcement costs a step (docs/reinforcement.md): a row of cubes on a fixed floor,
with and without cables through it, in one process, each variant warmed (compiled) first,
then timed over the same steps.

- ``bare``: the row alone (it steps in the compiled loop of steps);
- ``bare_python``: the row alone with ``solve.fused: false`` (steps in Python, as a scene
  with elements does);
- ``cables_<k>``: the row with ``k`` grouted cables of 20 segments along it.

Printed: seconds per step, and the elements' share per node-step against the Python-stepped
row. A scene with elements steps in Python: ``bare_python / bare`` is the price of that;
``(cables_k - bare_python) / nodes`` the elements' own.

    .venv/bin/python bench/reinforcement.py [--record]   # --record appends bench/results/reinforcement.csv
"""

from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mpi4py import MPI  # noqa: E402

from pdem.config import parse_scene  # noqa: E402
from pdem.simulation import Simulation  # noqa: E402

COMMAND = "bench/reinforcement.py"
STEPS = 2000
ROW = 20  # cubes


def scene(cables: int, fused: bool = True) -> str:
    text = f"""
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [{ROW + 1}, 2, 0]}}, material: rock, fixed: true}}
  - name: row
    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, count: [{ROW}, 1, 1], spacing: [1.0, 1, 1]}}
    material: rock
solve: {{steps: {STEPS}, damping: local, fused: {str(fused).lower()}}}
"""
    if cables:
        text += "reinforcement:\n" + "".join(
            f"  - {{name: c{k}, from: [0.05, 0.5, {0.1 + 0.8 * k / cables!r}], to: [{ROW - 0.05}, "
            f"0.5, {0.1 + 0.8 * k / cables!r}], segments: 20, young: 2.0e11, area: 2.0e-4, "
            f"grout: {{stiffness: 1.0e9, strength: 1.0e5}}}}\n" for k in range(cables))
    return text


def per_step(text: str) -> tuple[float, int]:
    Simulation(parse_scene(text), MPI.COMM_SELF, output=False).run(steps=50)  # compile
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    t0 = time.perf_counter()
    sim.run()
    wall = time.perf_counter() - t0
    e = sim.state.reinforcement
    return wall / STEPS, 0 if e is None else e.n_nodes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", action="store_true")
    args = ap.parse_args()
    rows = []
    bare, _ = per_step(scene(0))
    python, _ = per_step(scene(0, fused=False))
    rows.append(("bare_step_time", bare * 1e3, "ms", f"{ROW} cubes, compiled loop"))
    rows.append(("python_over_compiled", python / bare, "x", f"{ROW} cubes stepped in Python"))
    for k in (1, 10, 50):
        t, nodes = per_step(scene(k))
        rows.append((f"cables_{k}_step_time", t * 1e3, "ms", f"{nodes} nodes"))
        rows.append((f"cables_{k}_per_node_step", (t - python) / nodes * 1e9, "ns",
                     f"over the Python-stepped row; {k} cables"))
    for q, v, unit, note in rows:
        print(f"{q:28s} {v:10.4g} {unit:3s} {note}")
    if args.record:
        path = os.path.join(ROOT, "bench", "results", "reinforcement.csv")
        new = not os.path.exists(path)
        with open(path, "a", newline="") as f:
            w = csv.writer(f)
            if new:
                w.writerow(["date", "host", "command", "quantity", "value", "unit", "note"])
            for q, v, unit, note in rows:
                w.writerow([datetime.date.today().isoformat(), "2-core shared machine (loaded)",
                            COMMAND, q, f"{v:.4g}", unit, note])


if __name__ == "__main__":
    main()
