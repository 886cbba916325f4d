"""Partial mass scaling (issue 10): steps and wall time for 0.5 s of the 1 m block + 1 cm pebble
scene (pdem.cases.pebble: mass ratio 1e6, kn = ks = 1e9 Pa/m, the big block sliding down a
20 deg tilted-gravity incline at phi = 10 deg), without and with
``solve.mass_scaling: {timestep: DT}`` (DT default 9e-5 s, just below the big block's own
critical step 9.43e-5 s).

    PYTHONPATH=. .venv/bin/python bench/mass_scaling.py [--dt 9e-5] [--sample 3000] [--full]

For each: the step, the steps 0.5 s needs, the wall time per step (over ``--sample`` steps after
a warm-up) and the wall time 0.5 s takes (extrapolated; measured with ``--full``), and the big
block's displacement after 0.5 s against the closed form ``a t^2 / 2`` (the scaled run always
runs the whole 0.5 s; the unscaled one only with ``--full``). That displacement error is
mostly the start-up transient of the unloaded shear spring (a ~2e-3 m/s velocity offset,
tests/verification/test_incline.py), the same with and without scaling; a fit of
``x0 + v0 t + a t^2/2`` (tests/verification/test_mass_scaling.py) matches ``a`` to 3e-10.
"""

from __future__ import annotations

import argparse
import logging
import math
import time

from pdem.cases import make_simulation
from pdem.cases.pebble import pebble_scene, sliding_acceleration

T_END = 0.5


def measure(scaling: str, sample: int, full: bool) -> dict:
    text = pebble_scene(f"time: {T_END}", psi=20.0, phi=10.0, scaling=scaling)
    s = make_simulation(text)
    steps = math.ceil(T_END / s.dt - 1e-9)
    for _ in range(min(200, steps)):  # warm-up: kernels compiled, contacts formed
        s.advance()
    n = min(sample, steps - s.step)
    t0 = time.perf_counter()
    for _ in range(n):
        s.advance()
    per_step = (time.perf_counter() - t0) / max(n, 1)
    out = {"dt": s.dt, "steps": steps, "per_step": per_step, "wall": per_step * steps,
           "measured": False, "scale": float(s.blocks.mscale[s.blocks.fixed == 0].max())}
    if full or steps <= 20_000:
        s = make_simulation(text)  # the whole run, energy budget and all
        t0 = time.perf_counter()
        s.run()
        out["wall"] = time.perf_counter() - t0
        out["measured"] = True
        big = [s.specs[g].name for g in s.blocks.gid].index("big")
        u = s.blocks.x[big, 0] - s.blocks.x0[big, 0]
        out["slide_err"] = u / (0.5 * sliding_acceleration(20.0, 10.0) * s.time**2) - 1.0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dt", type=float, default=9.0e-5, help="mass_scaling timestep (s)")
    ap.add_argument("--sample", type=int, default=3000, help="steps timed per run")
    ap.add_argument("--full", action="store_true", help="also run the unscaled 0.5 s")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="  log: %(message)s")
    rows = []
    for label, scaling in (("unscaled", "false"), ("partial", f"{{timestep: {args.dt!r}}}")):
        print(f"{label}:")
        r = measure(scaling, args.sample, args.full)
        rows.append((label, r))
    print("\n0.5 s of the 1 m block + 1 cm pebble scene (largest factor, steps, wall time):")
    print(f"{'':10s} {'dt (s)':>10s} {'steps':>10s} {'us/step':>8s} {'wall (s)':>10s} "
          f"{'factor':>8s} {'slide err':>10s}")
    for label, r in rows:
        wall = f"{r['wall']:.4g}" + ("" if r["measured"] else "*")
        err = f"{r['slide_err']:.1e}" if "slide_err" in r else "-"
        print(f"{label:10s} {r['dt']:10.3g} {r['steps']:10d} {1e6 * r['per_step']:8.1f} "
              f"{wall:>10s} {r['scale']:8.4g} {err:>10s}")
    print(f"steps saved: {rows[0][1]['steps'] / rows[1][1]['steps']:.0f} x   "
          "(* extrapolated from the timed sample)")


if __name__ == "__main__":
    main()
