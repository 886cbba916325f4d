"""Critical thickness of the semicircular masonry arch (issue 16, docs/validation.md section 8):
bisects t/R between 0.08 and 0.14, undamped and with local damping, on the scene of
pdem.cases.collapse.arch_scene (24 voussoirs, fixed base, friction 60 deg, kn = ks = 1e10 Pa/m).

    PYTHONPATH=. .venv/bin/python bench/arch_critical.py [--tol 0.001] [--time 3.0]
    PYTHONPATH=. .venv/bin/python bench/arch_critical.py --trace 0.100 0.110 --time 4   # by hand

Criterion: a trial arch starts at rest, unloaded, and gravity acts from t = 0; the largest
voussoir displacement max |x - x0| is checked every 0.25 model seconds.

* It *falls* as soon as that displacement exceeds ``--fall`` (default 0.25 m; the trial stops
  there).
* Undamped (``damping: none``) it *stands* if the displacement is still below ``--stand``
  (default 0.02 m) after ``--time`` model seconds (default 3 s). A standing undamped arch never
  comes to rest (it rings elastically) but settles by under a millimetre, so the criterion is
  a time window; between ``--stand`` and ``--fall`` at the end counts as falling.
* With local damping (``damping: local``, alpha 0.8) a falling arch creeps rather than runs
  away and a standing one near the critical thickness relaxes slowly, so both outcomes are
  decided positively: it *stands* when the unbalanced-force ratio falls below ``--ratio``
  (1e-5) with the displacement below ``--stand``, it *falls* as soon as the displacement
  exceeds ``--stand``, and a trial still undecided after ``--time-local`` model seconds
  (default 20 s) is printed as UNDECIDED and counted as falling.

After the bisection the undamped bracket is checked with twice the time: the arch at the
standing end must still stand.

Prints the criterion; the limit analysis of the thrust line (``thrust_line_critical``: t/R for
24 and for 1000 voussoirs, against the continuous arch's ``ARCH_CRITICAL_TR``); one line per
trial: its outcome, the model time it ran, the largest displacement and speed, the
unbalanced-force ratio, the energy budget's balance error (pdem.plugins.energy; J and % of the
work of gravity) and the wall time; then each mode's bracket (falls, stands) and its midpoint
against the limit analysis. ``--trace`` runs only the given t/R (each damping mode) and prints
the displacement, speed and ratio every 0.25 model seconds. The traces that size the time
windows and the recorded bisections are in bench/results/arch_critical.csv; the full log of
the table in docs/validation.md is docs/data/arch-critical.log.
"""

from __future__ import annotations

import argparse
import logging
import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from pdem.cases import make_simulation  # noqa: E402
from pdem.cases.collapse import ARCH_CRITICAL_TR, arch_scene  # noqa: E402
from pdem.plugins.energy import balance, energy_totals  # noqa: E402

CHUNK = 0.25  # model seconds between displacement checks


def thrust_line_feasible(tr: float, n: int, nz: int = 4001) -> bool:
    """Limit analysis of the rigid, no-sliding arch of ``n`` voussoirs (Heyman): does a thrust
    line exist that passes inside the section at every joint? Symmetric arch, so a horizontal
    thrust H at height z_c in the crown joint; on the joint at angle a the resultant of H and
    the weight W of the voussoirs above (moment S about the springing centre) crosses the joint
    at radius r = (z_c H + S) / (W cos a + H sin a), which must lie in [ri, ro]: linear in H for
    each z_c on a grid."""
    radius = 5.0
    t = tr * radius
    ri, ro = radius - t / 2, radius + t / 2
    d = np.pi / n
    half = n // 2
    rbar = (2 / 3) * (ro ** 3 - ri ** 3) / (ro ** 2 - ri ** 2) * np.sin(d / 2) / (d / 2)
    w = 0.5 * d * (ro ** 2 - ri ** 2)  # weight per unit weight density and depth
    xs = rbar * np.cos((np.arange(half) + 0.5) * d)
    zc = np.linspace(ri, ro, nz)
    lo = np.zeros(nz)
    hi = np.full(nz, np.inf)
    for j in range(half):  # joint j at angle j d; voussoirs j..half-1 above it
        a = j * d
        weight, moment = w * (half - j), w * xs[j:].sum()
        for rr, sgn in ((ri, 1.0), (ro, -1.0)):  # sgn ((z_c - rr sin a) H + S - rr W cos a) >= 0
            c1 = sgn * (zc - rr * np.sin(a))
            c0 = sgn * (moment - rr * weight * np.cos(a))
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = -c0 / c1
            lo = np.where(c1 > 0, np.maximum(lo, bound), lo)
            hi = np.where(c1 < 0, np.minimum(hi, bound), hi)
            hi = np.where((c1 == 0) & (c0 < 0), -1.0, hi)
    return bool(np.any((lo <= hi) & (hi > 0)))


def thrust_line_critical(n: int, tol: float = 1e-5) -> float:
    lo, hi = 0.05, 0.15
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if thrust_line_feasible(mid, n) else (mid, hi)
    return 0.5 * (lo + hi)


def trial(tr: float, damping: str, args, scale: float = 1.0, trace: bool = False) -> dict:
    """One arch, run for ``scale`` times the trial time of its damping mode (module docstring)."""
    t0 = time.perf_counter()
    t_end = scale * (args.time if damping == "none" else args.time_local)
    sim = make_simulation(arch_scene(tr, time=t_end, damping=damping))
    free = np.nonzero(sim.blocks.fixed[:sim.n_owned] == 0)[0]
    x0 = sim.blocks.x0[free].copy()
    disp = vmax = 0.0
    rest = False
    while sim.time < t_end - 1e-9:
        sim.run(time=min(CHUNK, t_end - sim.time))
        disp = float(np.linalg.norm(sim.blocks.x[free] - x0, axis=1).max())
        vmax = float(np.linalg.norm(sim.blocks.v[free], axis=1).max())
        if trace:
            print(f"    t = {sim.time:5.2f} s  max |x - x0| = {disp:.3e} m  max |v| = {vmax:.3e} m/s"
                  f"  ratio {sim.state.ratio:.2e}", flush=True)
        if disp > (args.fall if damping == "none" else args.stand):
            break
        rest = damping != "none" and sim.state.ratio <= args.ratio and disp < args.stand
        if rest:
            break
    falls = disp >= args.stand or (damping != "none" and not rest)
    tot = energy_totals(sim.state)
    err, _ = balance(tot, sim.runner.plugin("energy").e0)
    undecided = damping != "none" and not rest and disp < args.stand
    return {"falls": falls, "undecided": undecided, "t": sim.time, "disp": disp, "v": vmax,
            "ratio": sim.state.ratio,
            "err": err, "wg": tot["gravity_work"], "wd": tot["damping_dissipation"],
            "wall": time.perf_counter() - t0}


def report(tr, damping, r):
    rel = f"{100 * r['err'] / r['wg']:+.3f} %" if r["wg"] > 1.0 else "n/a"
    outcome = ("UNDECIDED" if r["undecided"] else "FALLS") if r["falls"] else "stands"
    print(f"  t/R = {tr:.6f}  {damping:5s}  {outcome:9s}  "
          f"t = {r['t']:4.2f} s  max|x-x0| = {r['disp']:.2e} m  max|v| = {r['v']:.1e} m/s  "
          f"ratio {r['ratio']:.1e}  balance error {r['err']:+.3e} J ({rel} of gravity work "
          f"{r['wg']:.4g} J)  wall {r['wall']:5.1f} s", flush=True)


def bisect(damping: str, lo: float, hi: float, args) -> tuple[float, float]:
    """Bracket [lo, hi]: lo falls, hi stands (both checked first)."""
    for tr, want in ((lo, True), (hi, False)):
        res = trial(tr, damping, args)
        report(tr, damping, res)
        if res["falls"] != want:
            raise SystemExit(f"t/R = {tr} {'falls' if res['falls'] else 'stands'}: not a bracket")
    while hi - lo > args.tol * (1 + 1e-9):
        mid = 0.5 * (lo + hi)
        res = trial(mid, damping, args)
        report(mid, damping, res)
        if res["falls"]:
            lo = mid
        else:
            hi = mid
    return lo, hi


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tol", type=float, default=0.001, help="bracket width in t/R")
    ap.add_argument("--time", type=float, default=3.0, help="model seconds per undamped trial")
    ap.add_argument("--time-local", type=float, default=20.0,
                    help="model seconds per locally damped trial (at most)")
    ap.add_argument("--ratio", type=float, default=1e-5, help="damped: at rest below this ratio")
    ap.add_argument("--no-check", action="store_true", help="skip the 2x-time checks")
    ap.add_argument("--stand", type=float, default=0.02, help="stands: max |x - x0| below (m)")
    ap.add_argument("--fall", type=float, default=0.25, help="falls: stop once above (m)")
    ap.add_argument("--lo", type=float, default=0.08)
    ap.add_argument("--hi", type=float, default=0.14)
    ap.add_argument("--damping", nargs="*", default=["none", "local"],
                    help="damping modes to bisect (none given: only the limit analysis)")
    ap.add_argument("--trace", type=float, nargs="+", metavar="TR",
                    help="only run these t/R (each damping mode), printing the displacement")
    args = ap.parse_args()
    logging.getLogger("pdem").setLevel(logging.WARNING)
    t_all = time.perf_counter()
    if args.trace:
        for damping in args.damping:
            for tr in args.trace:
                print(f"t/R = {tr}, damping {damping}:", flush=True)
                report(tr, damping, trial(tr, damping, args, trace=True))
        return
    print(f"arch: R = 5 m, 24 voussoirs, friction 60 deg, kn = ks = 1e10 Pa/m; falls once "
          f"max|x-x0| > {args.fall} m; undamped: stands if max|x-x0| < {args.stand} m after "
          f"{args.time} s; local damping: stands once ratio < {args.ratio:g} with max|x-x0| < "
          f"{args.stand} m, falls once max|x-x0| > {args.stand} m, at most {args.time_local} s; "
          f"tol {args.tol}", flush=True)
    la = {n: thrust_line_critical(n) for n in (24, 1000)}
    print(f"limit analysis (thrust line inside every joint): 24 voussoirs t/R = {la[24]:.5f}, "
          f"1000 voussoirs {la[1000]:.5f} (continuous arch: {ARCH_CRITICAL_TR})", flush=True)
    brackets = {}
    for damping in args.damping:
        print(f"damping {damping}:", flush=True)
        t0 = time.perf_counter()
        brackets[damping] = bisect(damping, args.lo, args.hi, args)
        if not args.no_check and damping == "none":
            tr = brackets[damping][1]
            print(f"  check with twice the time (t/R = {tr:.6f}, standing end):", flush=True)
            report(tr, damping, trial(tr, damping, args, scale=2.0))
        print(f"  ({time.perf_counter() - t0:.1f} s)", flush=True)
    print("critical t/R (falls, stands):")
    for damping, (lo, hi) in brackets.items():
        mid = 0.5 * (lo + hi)
        print(f"  {damping:5s}  [{lo:.6f}, {hi:.6f}]  mid {mid:.5f}  "
              f"({100 * (mid / ARCH_CRITICAL_TR - 1):+.1f} % vs limit analysis {ARCH_CRITICAL_TR}, "
              f"{100 * (mid / la[24] - 1):+.1f} % vs {la[24]:.4f} for 24 voussoirs)")
    print(f"total wall time {time.perf_counter() - t_all:.1f} s")


if __name__ == "__main__":
    main()
