"""Zone-steps/s per core of one large zoned block and of a rock mass of many small zoned blocks
with about the same zones, and the rock mass's 2-rank efficiency (issue 40, part 3).

    PYTHONPATH=. .venv/bin/python bench/zoned_rock_mass.py --label after --save
    PYTHONPATH=. .venv/bin/mpiexec -n 2 .venv/bin/python bench/zoned_rock_mass.py \\
        --only rock_mass --label after --save

1. **Large block**: one ``n x n x n`` m elastic block zoned at ``--zone`` (E = 1e10, NMD on),
   standing on a fixed rigid floor (gravity, local damping).
2. **Rock mass**: ``n^3`` unit cubes (``array``, ``n = 10``: 1,000 zoned blocks, each zoned at
   ``--zone``, 0.5: 192 zones) in face contact, on the same floor: about the zones of 1.

Each scene steps by the stepper (``stepper.advance``: the Python path, whose parts can be
probed) or, with ``--fused``, as a run does (``Stepper.advance_many``: the compiled loop of steps,
pdem.cycle.fused_grid_steps; the parts are not probed, only the whole step); a timing
is the best of ``--chunks`` (5) chunks of ``--steps`` steps after ``--warm`` steps (numba compiles on the
first run of a fresh cache: run twice and quote the second). Printed and saved per scene: the
CPU time of the process per step (on several ranks the largest rank's) and its zone-steps/s
per core (zones x steps / CPU s / ranks); the same of the grids' step alone
(``GridStore.step``, probed inside the same chunks: the compiled cycle of every owned grid
with the Python around it), and of the step's other parts, probed alike: the contact forces
(``force_phase``: the sub-contact force kernel with the rotation matrices and the zeroed
force sums) and the piece refresh (``GridStore.sync``: the zoned blocks' rows and pieces from
their gridpoints, owned and ghosts), the rest being the rigid motion, the halo, the contact
updates, the reduction and the Python around them; the wall time per step. On several ranks,
the efficiency against the last 1-rank row of the same ``--label`` in the csv:
``T1 / (ranks x T_ranks)`` from the CPU times and from the wall times. Not a test: the
machines it ran on are shared and noisy (the csv says how).

``--kernel``: instead, the grids' step kernel alone (``motion.step_grids``) on the arguments
it had in the step after the warm steps, the best of ``--chunks`` chunks of ``--steps`` calls
(each chunk from copies of them), and for the rock mass the same arrays as one grid (the
cubes' tets renumbered into one grid: the same gridpoints, zones and arithmetic, one grid's
loops): the per-grid cost of stepping many grids is the difference.

``--save`` appends the rows to bench/results/zoned_rock_mass.csv. Runs on main's tree too
(``PYTHONPATH`` at it): the "before" rows.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import pdem.deformable.store as grid_store
from pdem import stepper
from pdem.config import parse_scene
from pdem.deformable.store import GridStore
from pdem.simulation import Simulation

CSV = Path(__file__).resolve().parent / "results" / "zoned_rock_mass.csv"
# bench/results/README.md's columns: a row per measured quantity
FIELDS = ["date", "host", "command", "quantity", "value", "unit", "note"]
QUANTITIES = {"cpu_ms_step": "ms", "wall_ms_step": "ms", "zone_steps_per_s_core": "1/s",
              "grid_cpu_ms_step": "ms", "grid_zone_steps_per_s_core": "1/s",
              "forces_cpu_ms_step": "ms", "refresh_cpu_ms_step": "ms", "rest_cpu_ms_step": "ms",
              "zones": "", "eff_cpu": "", "eff_wall": "", "kernel_ms_step": "ms",
              "kernel_one_grid_ms_step": "ms"}

HEAD = """
name: {name}
materials:
  rock: {{density: 2500.0}}
  soft: {{density: 2500.0, young: 1.0e10, poisson: 0.25}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [{m}, {m}, 0]}}, material: rock, fixed: true}}
"""
TAIL = "solve: {steps: 1000000000, damping: local}\n"


def large_text(n: int, zone: float) -> str:
    return HEAD.format(name="large", m=n + 1) + (
        f"  - {{name: big, box: {{min: [0, 0, 0], max: [{n}, {n}, {n}]}}, material: soft, "
        f"zones: {{size: {zone}}}}}\n") + TAIL


def rock_mass_text(n: int, zone: float) -> str:
    return HEAD.format(name="rock_mass", m=n + 1) + (
        f"  - name: c\n    array: {{box: {{min: [0, 0, 0], max: [1, 1, 1]}}, "
        f"count: [{n}, {n}, {n}], spacing: [1, 1, 1]}}\n"
        f"    material: soft\n    zones: {{size: {zone}}}\n") + TAIL


class Probe:
    """CPU time of this process spent in ``owner.name`` (a function looked up at each call:
    a method of GridStore, a kernel in pdem.stepper's namespace)."""

    def __init__(self, owner, name: str):
        self.cpu = 0.0
        self.owner, self.name = owner, name
        self.orig = getattr(owner, name)
        probe = self

        def timed_call(*a, **kw):
            t0 = time.process_time()
            try:
                return probe.orig(*a, **kw)
            finally:
                probe.cpu += time.process_time() - t0

        setattr(owner, name, timed_call)

    def undo(self):
        setattr(self.owner, self.name, self.orig)


def timed(text: str, steps: int, warm: int, chunks: int, comm, fused: bool = False) -> dict:
    """The scene of ``text`` on ``comm``: (see module doc) per step, the largest rank's."""
    t0 = time.perf_counter()
    sim = Simulation(parse_scene(text), comm, output=False)
    setup = time.perf_counter() - t0
    g = sim.state.grids
    zones = comm.allreduce(sum(len(g.bodies[d].tets) for d in range(g.n_owned)))
    blocks = comm.allreduce(g.n_owned)

    def march(n):
        while fused and n > 0:  # (as Run does, without its per-call plugins)
            n -= sim.stepper.advance_many(n)
            if sim.stepper.migrate_due:
                sim.runner._migrate()
        for _ in range(n):
            sim.stepper.advance()

    march(warm)
    probes = [] if fused else [Probe(GridStore, "step"), Probe(stepper, "force_phase"),
                               Probe(GridStore, "sync")]
    best = None
    try:
        for _ in range(chunks):
            comm.Barrier()
            for p in probes:
                p.cpu = 0.0
            c0, w0 = time.process_time(), time.perf_counter()
            march(steps)
            c, w = time.process_time() - c0, time.perf_counter() - w0
            top = np.empty(2 + len(probes))
            comm.Allreduce(np.array([c, w, *(p.cpu for p in probes)]), top, op=MPI.MAX)
            top /= steps
            if best is None or top[0] < best[0]:
                best = top
    finally:
        for p in reversed(probes):
            p.undo()
    if fused:  # (the parts are not probed)
        assert "fused" in sim.state.timers.report(), "the compiled loop did not run"
        best = np.concatenate([best, np.full(3, np.nan)])
    cpu, wall, grid, forces, refresh = best
    ranks = comm.size
    return {"scene": sim.state.scene.name, "ranks": ranks, "blocks": blocks, "zones": zones,
            "steps": steps, "cpu_ms_step": 1e3 * cpu, "wall_ms_step": 1e3 * wall,
            "zone_steps_per_s_core": zones / cpu / ranks,
            "grid_cpu_ms_step": 1e3 * grid, "grid_zone_steps_per_s_core": zones / grid / ranks,
            "forces_cpu_ms_step": 1e3 * forces, "refresh_cpu_ms_step": 1e3 * refresh,
            # (each part the largest rank's: on several ranks not exactly the rest of that rank)
            "rest_cpu_ms_step": 1e3 * (cpu - grid - forces - refresh),
            "setup_s": setup}


def kernel_timed(text: str, steps: int, warm: int, chunks: int) -> dict:
    """``--kernel`` (module doc): ms per call of ``step_grids`` on the scene's arguments."""
    sim = Simulation(parse_scene(text), MPI.COMM_SELF, output=False)
    g = sim.state.grids
    for _ in range(warm):
        sim.stepper.advance()
    got, step_grids = [], grid_store.step_grids

    def grab(*a):
        got.append([x.copy() if isinstance(x, np.ndarray) else x for x in a])
        return step_grids(*a)

    grid_store.step_grids = grab
    try:
        sim.stepper.advance()
    finally:
        grid_store.step_grids = step_grids
    assert len(got) == 1, "one constitutive table: one call"
    args = got[0]

    def best(a0) -> float:
        out = np.inf
        for _ in range(chunks):
            a = [x.copy() if isinstance(x, np.ndarray) else x for x in a0]
            step_grids(*a)
            t0 = time.process_time()
            for _ in range(steps):
                step_grids(*a)
            out = min(out, (time.process_time() - t0) / steps)
        return 1e3 * out

    zones = sum(len(b.tets) for b in g.bodies[:g.n_owned])
    row = {"scene": sim.state.scene.name, "ranks": 1, "blocks": g.n_owned, "zones": zones,
           "kernel_ms_step": best(args), "kernel_one_grid_ms_step": ""}
    if g.n_owned > 1:  # the same arrays as one grid (positions in step_grids' signature)
        one = list(args)
        d1, ns, zs = one[1], one[9], one[10]
        tets = one[29].copy()
        for d in range(d1):
            tets[zs[d]:zs[d + 1]] += ns[d]
        one[1], one[9], one[10], one[29] = 1, ns[[0, d1]], zs[[0, d1]], tets
        for k in (11, 12, 13, 14, 15):  # scalars, moduli, work, servo, unbalanced: row 0
            one[k] = one[k][:1].copy()
        row["kernel_one_grid_ms_step"] = best(one)
    return row


def quantity(scene: str, ranks: int, name: str) -> str:
    return f"{scene} {ranks}-rank {name}"


def efficiency(row: dict, label: str) -> None:
    """``row``'s efficiency against the last 1-rank row of ``label`` and its scene."""
    row["eff_cpu"] = row["eff_wall"] = ""
    if row["ranks"] == 1 or not CSV.exists():
        return
    with CSV.open() as f:
        rows = list(csv.DictReader(f))
    one = {}
    for r in rows:
        if r["note"].split(";")[0] == label:
            one[r["quantity"]] = r["value"]
    cpu = one.get(quantity(row["scene"], 1, "cpu_ms_step"))
    wall = one.get(quantity(row["scene"], 1, "wall_ms_step"))
    if cpu and wall:
        row["eff_cpu"] = float(cpu) / (row["ranks"] * row["cpu_ms_step"])
        row["eff_wall"] = float(wall) / (row["ranks"] * row["wall_ms_step"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10, help="rock mass: n^3 unit cubes; block: n m")
    ap.add_argument("--zone", type=float, default=0.5, help="zone size of both scenes")
    ap.add_argument("--large-zone", type=float, default=None,
                    help="zone size of the large block (default --zone)")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warm", type=int, default=10)
    ap.add_argument("--chunks", type=int, default=5)
    ap.add_argument("--only", choices=("large", "rock_mass"), default=None)
    ap.add_argument("--label", default="", help="the tree measured (before/after)")
    ap.add_argument("--note", default="")
    ap.add_argument("--kernel", action="store_true",
                    help="time the grids' step kernel alone (module doc; one rank)")
    ap.add_argument("--save", action="store_true", help=f"append the rows to {CSV}")
    ap.add_argument("--fused", action="store_true",
                    help="step as a run does, in the compiled loop (the parts not probed)")
    args = ap.parse_args()
    comm = MPI.COMM_WORLD
    scenes = []
    if args.only in (None, "large"):
        scenes.append(large_text(args.n, args.large_zone or args.zone))
    if args.only in (None, "rock_mass"):
        scenes.append(rock_mass_text(args.n, args.zone))
    rows = []
    for text in scenes:
        if args.kernel:
            r = kernel_timed(text, args.steps, args.warm, args.chunks)
            r.update(date=datetime.date.today().isoformat(), label=args.label, note=args.note)
            rows.append(r)
            one = r["kernel_one_grid_ms_step"]
            print(f"{r['scene']:10s} {r['blocks']:5d} grids {r['zones']:7d} zones: step_grids "
                  f"{r['kernel_ms_step']:.3f} ms/call"
                  + (f"; the same arrays as one grid {one:.3f} ms" if one != "" else ""),
                  flush=True)
            continue
        r = timed(text, args.steps, args.warm, args.chunks, comm, args.fused)
        r.update(date=datetime.date.today().isoformat(), label=args.label, note=args.note)
        efficiency(r, args.label)
        rows.append(r)
        if comm.rank == 0:
            eff = (f", efficiency {r['eff_cpu']:.2f} (CPU) {r['eff_wall']:.2f} (wall)"
                   if r["eff_cpu"] != "" else "")
            print(f"{r['scene']:10s} {r['ranks']} rank(s) {r['blocks']:5d} blocks {r['zones']:7d} "
                  f"zones: {r['cpu_ms_step']:8.2f} ms/step CPU ({r['wall_ms_step']:.2f} wall), "
                  f"{r['zone_steps_per_s_core']:.3g} zone-steps/s/core; grids' step "
                  f"{r['grid_cpu_ms_step']:.2f} ms, {r['grid_zone_steps_per_s_core']:.3g} "
                  f"zone-steps/s/core{eff} (set-up {r['setup_s']:.0f} s)\n"
                  f"{'':10s} parts, ms/step CPU: grids' step {r['grid_cpu_ms_step']:.2f}, "
                  f"contact forces {r['forces_cpu_ms_step']:.2f}, piece refresh "
                  f"{r['refresh_cpu_ms_step']:.2f}, the rest {r['rest_cpu_ms_step']:.2f}",
                  flush=True)
    if len(rows) == 2 and comm.rank == 0 and not args.kernel:
        a, b = rows
        print(f"rock mass / large block, CPU per zone-step: scene "
              f"{a['zone_steps_per_s_core'] / b['zone_steps_per_s_core']:.2f}x, grids' step "
              f"{a['grid_zone_steps_per_s_core'] / b['grid_zone_steps_per_s_core']:.2f}x")
    if args.save and comm.rank == 0:
        new = not CSV.exists()
        argv = sys.argv[1:]
        if "--note" in argv:  # (the note has its own column)
            k = argv.index("--note")
            argv = argv[:k] + argv[k + 2:]
        command = "bench/zoned_rock_mass.py " + " ".join(a for a in argv if a != "--save")
        if comm.size > 1:
            command = f"mpiexec -n {comm.size} {command}"
        with CSV.open("a", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            if new:
                w.writeheader()
            for r in rows:
                for name, unit in QUANTITIES.items():
                    v = r.get(name, "")
                    if v == "" or (isinstance(v, float) and np.isnan(v)):
                        continue
                    v = r[name]
                    w.writerow({"date": r["date"], "host": "2-core shared machine",
                                "command": command,
                                "quantity": quantity(r["scene"], r["ranks"], name),
                                "value": f"{v:.4g}" if isinstance(v, float) else v,
                                "unit": unit, "note": f"{args.label}; {args.note}"})

if __name__ == "__main__":
    main()
