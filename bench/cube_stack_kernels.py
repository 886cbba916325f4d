"""Per-kernel profile of the cube stack (bench/cube_stack.py): CPU time of each kernel of a
step, called on its own on the model after ``warm`` steps, and of the contact update split into
its common planes, contact regions and the rest.

    .venv/bin/python bench/cube_stack_kernels.py [n=20] [warm=300] [reps=20]

CPU time (``time.process_time``), best of a few rounds: on a shared machine wall-clock figures
swing by tens of percent. The kernels are called on a copy of the state, so repeated calls do
not drift the model. Not a test.
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np
from mpi4py import MPI

from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.contact.detect import Planes, _plane, plane_scratch, refresh_contacts
from pdem.contact.forces import contact_forces
from pdem.contact.subcontacts import region_in, region_scratch
from pdem.cycle import motion_record
from pdem.dynamics import motion
from pdem.dynamics.kinematics import rotation_matrices, update_world_vertices
from pdem.resolve import TOUCH_FRACTION
from pdem.simulation import Simulation


@numba.njit
def _planes_only(shapes, R, ka, kb, normal, point, warm, alg):
    scratch = plane_scratch(shapes)
    g = 0.0
    for c in range(ka.shape[0]):
        _, _, gap = _plane(ka[c], kb[c], shapes, R, scratch, normal[c], point[c], warm[c] == 1,
                           alg)
        g += gap
    return g


@numba.njit
def _regions_only(shapes, ka, kb, normal, point, tol):
    """The contact regions as the update makes them: one scratch for all."""
    vs = shapes.vert_start
    vw = shapes.verts_world
    max_verts = 0
    for k in range(vs.shape[0] - 1):
        max_verts = max(max_verts, vs[k + 1] - vs[k])
    scratch = region_scratch(max_verts)
    g = 0.0
    for c in range(ka.shape[0]):
        _, ovl, _, _, _, _ = region_in(vw[vs[ka[c]]:vs[ka[c] + 1]], vw[vs[kb[c]]:vs[kb[c] + 1]],
                                       normal[c], point[c], tol, scratch)
        g += ovl[0]
    return g


def best_time(fn, reps: int, rounds: int = 3) -> float:
    fn()
    best = np.inf
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(reps):
            fn()
        best = min(best, (time.process_time() - t0) / reps)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int, nargs="?", default=20)
    ap.add_argument("warm", type=int, nargs="?", default=300)
    ap.add_argument("reps", type=int, nargs="?", default=20)
    args = ap.parse_args()
    sim = Simulation(parse_scene(cube_stack_scene(args.n, "fast")), MPI.COMM_SELF, output=False)
    sim.run(steps=args.warm)
    s = sim.state
    b = s.blocks
    c = s.contacts
    n = s.n_owned
    update_world_vertices(b)
    st = sim.runner.stepper
    bodies, pairs, subs, joints = st.bodies(), c.pairs(), c.subs(), s.joints.kernel_args
    # the kernels write the state: each is timed from the same state, restored after it
    state = (*motion_record(b, n), *bodies, *pairs, *subs, b.R, b.u_acc, b.u_geo, b.u_mig)
    saved = [a.copy() for a in state]

    def timed(fn):
        v = best_time(fn, args.reps)
        for arr, x in zip(state, saved, strict=True):
            arr[...] = x
        return v

    stats = motion.new_stats()
    t = {
        "integrate": timed(lambda: motion.integrate(
            motion_record(b, n), s.gravity, s.dt, s.damping_args(), s.scalar_inertia, stats)),
        "motion_bookkeeping": timed(lambda: motion.motion_bookkeeping(
            b.dx[:n], b.dtheta[:n], b.radius[:n], b.fixed[:n], b.u_acc[:n], b.u_geo[:n],
            b.u_mig[:n], b.v[:n], b.x[:n], np.inf, np.inf)),
        "rotation_matrices": timed(lambda: rotation_matrices(b.q, b.R)),
        "contact_forces": timed(lambda: contact_forces(s.dt, bodies, pairs, subs, joints,
                                                       b.still)),
    }
    step = sum(t.values())
    print(f"cube stack {args.n}^3 after {args.warm} steps: {n - 1} cubes, {c.n} contacts, "
          f"{c.n_sub} sub-contacts (CPU time per call)")
    for k, v in t.items():
        print(f"  {k:22s} {v * 1e3:8.3f} ms  {100 * v / step:5.1f}% of a step without updates")
    print(f"  contact_forces per sub-contact {t['contact_forces'] / max(c.n_sub, 1) * 1e9:.1f} ns")
    a = c.arrays
    sh = b.shapes()
    todo = np.ones(c.n, np.uint8)

    def full():
        planes = Planes(*(a[k].copy() for k in ("ia", "ib", "ka", "kb", "normal", "point", "gap",
                                                "ctype", "warm")))
        refresh_contacts(b.x, b.R, sh, planes, c.sc_start, subs, todo, s.ctol, TOUCH_FRACTION,
                         s.algorithm)

    r = {
        "refresh_contacts (all)": best_time(full, 2),
        "  common planes": best_time(lambda: _planes_only(sh, b.R, c.ka, c.kb, c.normal, c.point,
                                                          c.warm, s.algorithm), 2),
        "  contact regions": best_time(lambda: _regions_only(sh, c.ka, c.kb, c.normal, c.point,
                                                             TOUCH_FRACTION * s.ctol), 2),
    }
    for k, v in r.items():
        print(f"  {k:24s} {v * 1e3:8.2f} ms  {v / c.n * 1e9:6.0f} ns per contact")


if __name__ == "__main__":
    main()
