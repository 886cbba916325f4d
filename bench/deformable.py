"""Deformable (zoned) blocks: zone-steps/s on one core, and the cost of a zoned block against a
rigid one (issue 12). Prints the figures; ``--save FILE`` also writes them as JSON.

    PYTHONPATH=. .venv/bin/python bench/deformable.py                  # full set (~3 min warm)
    PYTHONPATH=. .venv/bin/python bench/deformable.py --sizes 0.2 0.1  # smaller columns only
    PYTHONPATH=. .venv/bin/python bench/deformable.py --blocks 27 --skip-column

1. **Column kernel**: an elastic column 1 x 1 x 4 m (E = 1 GPa, nu = 0.25, NMD on, undamped)
   zoned at each ``--sizes`` (0.13 gives 1.1e5 zones), stepped by ``DeformableBody.step``: the
   compiled cycle alone (one call for all the steps). zone-steps/s = zones x steps / wall.
2. **Column scene**: the same column standing on a fixed rigid floor in a scene (local
   damping, gravity), stepped by the stepper: the cycle plus the contacts at the base
   gridpoints, the piece refresh and the Python per step. Sizes up to ``--scene-max``.
3. **Zoned vs rigid**: ``--blocks`` unit cubes (a k x k x k stack, k^3 = N, on a fixed floor,
   every cube in face contact, local damping) rigid, and zoned at ``--cube-size`` (0.5: 192
   zones a cube): wall per step, per block-step, and per zone-step.
4. **Where a zoned step goes**: the zoned stack's step split into the stepper's phases and,
   inside, the grids' cycle kernel, the Python around it (per block), the piece refresh
   (``GridStore.sync``), the sub-contact location (``GridStore.record``), the contact kernel
   and the gridpoint regrid of the contact updates.

Each timing follows a warm-up (numba compiles on the first run of a fresh cache: run twice and
quote the second) and is the CPU time of this process, the best of 3 chunks (the wall time is
in the JSON): on a shared machine other jobs inflate the wall time. Not a test: timings on
shared machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.deformable.body import DeformableBody
from pdem.deformable.mesh import tetrahedralise
from pdem.geometry import box
from pdem.simulation import Simulation

E, NU, RHO = 1.0e9, 0.25, 2500.0
COLUMN_H = 4.0


REPEAT = 3  # timed chunks per figure: the best (least CPU) is quoted


def best_of(run_chunk, steps: int) -> tuple[float, float]:
    """(CPU s, wall s) per step: the chunk of ``steps`` steps that took the least CPU time of
    this process among REPEAT (a shared machine: other jobs inflate the wall time, and the CPU
    time less so)."""
    best = (np.inf, np.inf)
    for _ in range(REPEAT):
        c0, w0 = time.process_time(), time.perf_counter()
        run_chunk(steps)
        c, w = time.process_time() - c0, time.perf_counter() - w0
        best = min(best, (c / steps, w / steps))
    return best


def column_kernel(size: float, zone_steps: float) -> dict:
    t0 = time.perf_counter()
    mesh = tetrahedralise(box([0, 0, 0], [1, 1, COLUMN_H]), size)
    t_mesh = time.perf_counter() - t0
    b = DeformableBody(mesh, dict(density=RHO, young=E, poisson=NU))
    b.vel[:] = np.random.default_rng(0).normal(size=b.vel.shape) * 1e-4  # all modes moving
    dt = b.timestep()
    b.step(2, dt)  # compile / warm
    zones = len(b.tets)
    steps = max(10, int(zone_steps / zones / REPEAT))
    cpu, wall = best_of(lambda n: b.step(n, dt), steps)
    return {"size": size, "zones": zones, "nodes": len(b.nodes), "mesh_s": t_mesh,
            "steps": steps, "cpu_per_step_s": cpu, "wall_per_step_s": wall,
            "zone_steps_per_s": zones / cpu}


def column_scene_text(size: float) -> str:
    return f"""
name: column
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: {E}, poisson: {NU}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: column, box: {{min: [0, 0, 0], max: [1, 1, {COLUMN_H}]}}, material: soft,
     zones: {{size: {size}}}}}
solve: {{steps: 1000000000, damping: local}}
"""


def timed_steps(sim, steps: int, warm: int = 20, fused: bool = False) -> tuple[float, float]:
    """(CPU s, wall s) per step after ``warm`` steps (:func:`best_of`); ``fused``: by
    ``Stepper.advance_many`` (rigid serial scenes run their steps in one compiled call)."""
    for _ in range(warm):
        sim.stepper.advance()
    sim.state.timers.reset()

    def chunk(n):
        if fused:
            while n > 0:
                n -= sim.stepper.advance_many(n)
            return
        for _ in range(n):
            sim.stepper.advance()

    return best_of(chunk, steps)


def column_scene(size: float, steps: int) -> dict:
    sim = Simulation(parse_scene(column_scene_text(size)), MPI.COMM_SELF, output=False)
    cpu, wall = timed_steps(sim, steps)
    zones = sum(len(b.tets) for b in sim.state.grids.bodies)
    return {"size": size, "zones": zones, "steps": steps, "cpu_per_step_s": cpu,
            "wall_per_step_s": wall, "zone_steps_per_s": zones / cpu, "dt": sim.state.dt}


def stack_text(k: int, zone_size: float | None) -> str:
    zones = f", zones: {{size: {zone_size}}}" if zone_size else ""
    material = "soft" if zone_size else "rock"
    cubes = "\n".join(
        f"  - {{name: c{i}_{j}_{m}, box: {{min: [{i}, {j}, {m}], max: [{i + 1}, {j + 1}, "
        f"{m + 1}]}}, material: {material}{zones}}}"
        for m in range(k) for j in range(k) for i in range(k))
    return f"""
name: stack
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: 1.0e10, poisson: {NU}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [{k + 1}, {k + 1}, 0]}}, material: rock, fixed: true}}
{cubes}
solve: {{steps: 1000000000, damping: local}}
"""


class Probe:
    """CPU time of this process accumulated in wrapped functions (module attributes or
    methods); a call costs ~1 us more wrapped."""

    def __init__(self):
        self.total: dict[str, float] = {}
        self._undo = []

    def wrap(self, owner, attr: str, label: str):
        orig = getattr(owner, attr)

        def timed(*a, **kw):
            t0 = time.process_time()
            try:
                return orig(*a, **kw)
            finally:
                self.total[label] = self.total.get(label, 0.0) + time.process_time() - t0

        setattr(owner, attr, timed)
        self._undo.append((owner, attr, orig))

    def undo(self):
        for owner, attr, orig in reversed(self._undo):
            setattr(owner, attr, orig)


def stack(k: int, zone_size: float | None, steps: int, profile: bool = False,
          fused: bool = False) -> dict:
    sim = Simulation(parse_scene(stack_text(k, zone_size)), MPI.COMM_SELF, output=False)
    s = sim.state
    probe = None
    if profile:
        import pdem.deformable.store as dstore
        import pdem.stepper as stepper_module
        from pdem.dynamics import motion
        from pdem.stepper import Stepper

        probe = Probe()
        probe.wrap(dstore.GridStore, "step", "grids: step (Python + cycle)")
        probe.wrap(dstore, "step_grids", "grids:   cycle kernel")
        probe.wrap(dstore.GridStore, "sync", "grids: piece refresh (sync)")
        probe.wrap(motion, "integrate", "rigid integration")
        probe.wrap(dstore.GridStore, "record", "contacts: locate (record)")
        probe.wrap(stepper_module, "contact_forces_grid", "contacts: force kernel")
        probe.wrap(Stepper, "search", "contacts: search")
        probe.wrap(Stepper, "refresh", "contacts: updates (with regrid)")
        probe.wrap(dstore.GridStore, "regrid", "contacts:   gridpoint regrid")
    cpu, wall = timed_steps(sim, steps, fused=fused)
    out = {"blocks": k ** 3, "zone_size": zone_size, "steps": steps, "cpu_per_step_s": cpu,
           "wall_per_step_s": wall, "per_step_ms": 1e3 * cpu, "contacts": s.contacts.n,
           "sub_contacts": s.contacts.n_sub, "dt": s.dt,
           "phases_s": dict(s.timers.total)}
    if s.grids is not None:
        out["zones"] = sum(len(b.tets) for b in s.grids.bodies)
        out["nodes"] = int(s.grids.node_start[-1])
    if probe is not None:
        # the probe's own overhead is in the numbers: ~1 us a call
        probe.total = {}
        t0 = time.process_time()
        for _ in range(steps):
            sim.stepper.advance()
        out["profile_cpu_s"] = time.process_time() - t0
        probe.undo()
        out["profile_s"] = dict(probe.total)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.6, 0.4, 0.25, 0.13],
                    help="column zone sizes (0.13 m: 1.1e5 zones)")
    ap.add_argument("--zone-steps", type=float, default=2e7,
                    help="zone-steps timed per column (steps = this / zones, at least 20)")
    ap.add_argument("--scene-max", type=int, default=30000,
                    help="largest column (zones) also run as a scene")
    ap.add_argument("--blocks", type=int, default=64, help="cubes of the stack (a cube number)")
    ap.add_argument("--cube-size", type=float, default=0.5, help="zone size of a zoned cube")
    ap.add_argument("--stack-steps", type=int, default=300)
    ap.add_argument("--skip-column", action="store_true")
    ap.add_argument("--save", help="write the figures as JSON here (e.g. docs/data/deformable.json)")
    args = ap.parse_args()
    res = {"columns": [], "column_scenes": []}
    if not args.skip_column:
        print(f"1. elastic column 1 x 1 x {COLUMN_H} m, DeformableBody.step (the cycle kernel):")
        print(f"{'size':>6s} {'zones':>8s} {'nodes':>8s} {'mesh s':>7s} {'steps':>6s} "
              f"{'ms/step':>8s} {'zone-steps/s':>13s} {'ns/zone-step':>13s}")
        for size in args.sizes:
            r = column_kernel(size, args.zone_steps)
            steps = r["steps"]
            res["columns"].append(r)
            print(f"{size:6.3g} {r['zones']:8d} {r['nodes']:8d} {r['mesh_s']:7.2f} {steps:6d} "
                  f"{1e3 * r['cpu_per_step_s']:8.3f} {r['zone_steps_per_s']:13.4g} "
                  f"{1e9 / r['zone_steps_per_s']:13.1f}")
        print("\n2. the same column on a rigid floor, as a scene (stepper.advance per step):")
        print(f"{'size':>6s} {'zones':>8s} {'steps':>6s} {'ms/step':>8s} {'zone-steps/s':>13s} "
              f"{'ns/zone-step':>13s} {'vs kernel':>9s}")
        for r0 in res["columns"]:
            if r0["zones"] > args.scene_max:
                continue
            steps = max(10, int(args.zone_steps / 4 / REPEAT / r0["zones"]))
            r = column_scene(r0["size"], steps)
            res["column_scenes"].append(r)
            print(f"{r['size']:6.3g} {r['zones']:8d} {steps:6d} {1e3 * r['cpu_per_step_s']:8.3f} "
                  f"{r['zone_steps_per_s']:13.4g} {1e9 / r['zone_steps_per_s']:13.1f} "
                  f"{r0['zone_steps_per_s'] / r['zone_steps_per_s']:8.2f}x")
    k = round(args.blocks ** (1 / 3))
    rigid = stack(k, None, args.stack_steps)
    fused = stack(k, None, args.stack_steps, fused=True)
    zoned = stack(k, args.cube_size, args.stack_steps, profile=True)
    res["rigid_stack"], res["rigid_stack_fused"], res["zoned_stack"] = rigid, fused, zoned
    n = k ** 3
    zpb = zoned["zones"] / n
    print(f"\n3. stack of {n} unit cubes on a floor ({k}^3, face contacts, local damping), "
          f"{args.stack_steps} steps x {REPEAT}:")
    print(f"{'':8s} {'ms/step':>9s} {'us/block-step':>14s} {'contacts':>9s} {'sub-contacts':>13s}"
          f" {'zones':>7s} {'ns/zone-step':>13s}")
    for label, r in (("rigid", rigid), ("fused", fused), ("zoned", zoned)):
        zs = f"{r['zones']:7d} {1e9 * r['cpu_per_step_s'] / r['zones']:13.1f}" \
            if "zones" in r else f"{'-':>7s} {'-':>13s}"
        print(f"{label:8s} {r['per_step_ms']:9.3f} {1e3 * r['per_step_ms'] / n:14.2f} "
              f"{r['contacts']:9d} {r['sub_contacts']:13d} {zs}")
    ratio = zoned["per_step_ms"] / rigid["per_step_ms"]
    print(f"a zoned cube ({zpb:.0f} zones, size {args.cube_size}) costs {ratio:.1f}x a rigid one "
          f"per step; the grids' step is {zoned['dt'] / rigid['dt']:.3g}x the rigid step "
          f"({zoned['dt']:.3g} vs {rigid['dt']:.3g} s), so {ratio * rigid['dt'] / zoned['dt']:.0f}x "
          "per simulated second")
    print(f"(rigid: stepper.advance a step, as the zoned scene must; fused: the compiled loop a "
          f"rigid serial run takes, {zoned['per_step_ms'] / fused['per_step_ms']:.0f}x less than "
          f"the zoned step); a zone adds "
          f"{1e6 * (zoned['per_step_ms'] - rigid['per_step_ms']) / zoned['zones']:.0f} ns a step")
    print(f"\n4. where the zoned stack's step goes ({args.stack_steps} steps, probed, CPU):")
    pc = zoned["profile_cpu_s"]
    prof = zoned["profile_s"]
    top = 0.0
    for name, v in prof.items():
        print(f"   {name:34s} {1e3 * v / args.stack_steps:8.3f} ms/step {100 * v / pc:5.1f} %")
        top += v if "  " not in name.split(":")[-1][:3] else 0.0
    print(f"   {'the rest (bookkeeping, halo, ...)':34s} {1e3 * (pc - top) / args.stack_steps:8.3f}"
          f" ms/step {100 * (pc - top) / pc:5.1f} %")
    py = prof.get("grids: step (Python + cycle)", 0.0) - prof.get("grids:   cycle kernel", 0.0)
    kern = prof.get("grids:   cycle kernel", 0.0) / (args.stack_steps * zoned["zones"])
    print(f"   Python around the cycle: {1e6 * py / (args.stack_steps * n):.1f} us per block-step; "
          f"cycle kernel {1e9 * kern:.1f} ns per zone-step")
    if args.save:
        Path(args.save).write_text(json.dumps(res, indent=1) + "\n")
        print(f"saved {args.save}")


if __name__ == "__main__":
    main()
