"""Scale-out benchmark: the cube stack at 10^4, 10^5 and 10^6 blocks on 1 and 2 ranks, and a
model of memory and halo traffic per rank at 64-4096 ranks fitted to those runs.

    .venv/bin/python bench/scale.py                        # n = 22 46 100 on 1 and 2 ranks
    .venv/bin/python bench/scale.py --n 22 46 --ranks 1 2  # skip 10^6 (it takes minutes)
    .venv/bin/python bench/scale.py --model-only FILE.json # the model from a saved run

Measured (each size and rank count in a fresh job, bench/setup.py's child): seconds to the
first step, peak resident MB per rank (the set-up) and after set-up (what the run keeps), the
same as proportional set sizes (PSS: the libraries' pages shared by the ranks split among
them, bench/setup.py), block-steps/s over 20 steps. The model is fitted to the resident
figures. Saved as JSON (``--save``, default bench/scale-last.json).

Model: a rank's memory after set-up is ``base + a N + h (owned + ghosts)``: ``a`` the bytes
every rank keeps per scene block (the scene's per-block fields and block names), ``h`` the bytes
per block it holds (its row and geometry, and its share of the contacts: the stack has ~12 per
cube). The set-up peak is ``base + s N + h' (owned + ghosts)``: ``s`` what every rank still
makes for every block at set-up (the specs' names and entries, the gathered per-block
fields), ``h'`` per block held (a rank builds an even share of the blocks, about what it
holds, and receives its own). ``a, h, s, h'`` are least-squares fits to the measured runs,
``a`` held at what bench/setup.py counts a rank keeps (``scene_b``) and ``s`` at least ``a``;
the peak is also at least the set-up's gathered catalogue (``catalogue_bytes`` a scene block)
and what every rank makes of every block at set-up (the specs, the gathered geometric scalars
and the spec table: ``spec_bytes``, measured in a process of its own: at 2 ranks the fit
cannot tell them from the blocks held) beside the build share, which bind at many ranks;
owned blocks,
ghosts and halo bytes per rank come from bench/scaling.py's decomposition model (exact for
the stack's lattice). Strong scaling: N fixed (10^6, 10^7); weak: 10^4 blocks per rank.

Not a test: timings on shared machines are noisy; memory is not.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _module(name: str):
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def measure(ns, ranks, memory) -> list[dict]:
    py = sys.executable
    mpiexec = str(Path(py).with_name("mpiexec"))
    env = dict(os.environ)
    if memory:
        env["PDEM_BENCH_MEMORY"] = memory
    out = []
    for n in ns:
        for p in ranks:
            cmd = [mpiexec, "-n", str(p), py, str(HERE / "setup.py"), "--child", str(n)]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
            if proc.returncode or not line:
                print(f"n={n} ranks={p}: failed (exit {proc.returncode})\n{proc.stderr[-1500:]}")
                continue
            r = json.loads(line[0][7:])
            out.append(r)
            print(f"{r['cubes']:>10,} blocks {p} rank(s): first step {r['total']:7.1f} s, "
                  f"peak {r['peak_mb']:7.0f} MB, after set-up {r['steady_mb']:7.0f} MB per rank "
                  f"(PSS: {r['pss_peak_mb']:7.0f}, {r['pss_mb']:7.0f}), "
                  f"{r['rate']:.3g} block-steps/s", flush=True)
    return out


def held_per_rank(n: int, size: int):
    """(owned + ghosts) mean and max over the ranks, halo KB/step received mean and max."""
    m = _module("scaling").model(n, size)
    held = m["owned"] + m["ghosts"]
    return held.mean(), held.max(), m["recv"].mean() / 1e3, m["recv"].max() / 1e3, m["dims"]


def fit(runs, key, per_scene_block=None):
    """Least squares ``mb - base = x0 N + x1 held`` over the runs (MB per block), ``x0`` at
    least ``per_scene_block`` (MB; 0 without). With what a rank keeps of every block down to
    bytes, N and the blocks held are too alike over these runs to split freely: an
    unconstrained fit gave ``x0`` < 0, and memory < 0 at 4096 ranks."""
    rows, rhs = [], []
    for r in runs:
        _, held, _, _, _ = held_per_rank(r["n"], r["ranks"])
        rows.append([r["cubes"], held])
        rhs.append(r[key] - r["base_mb"])
    rows, rhs = np.array(rows, float), np.array(rhs, float)
    x, *_ = np.linalg.lstsq(rows, rhs, rcond=None)
    floor = per_scene_block or 0.0
    if x[0] < floor:  # on the bound: the blocks held take the rest
        h, *_ = np.linalg.lstsq(rows[:, 1:], rhs - floor * rows[:, 0], rcond=None)
        x = np.array([floor, h[0]])
    return x


def catalogue_bytes() -> int:
    """Bytes a block of the per-block fields every rank gathers at set-up (pdem.state's
    GATHERED: the catalogue and the envelopes), held until the first distribution."""
    from pdem.model.fields import BLOCK
    from pdem.selection import GATHERED

    return sum(f.width * np.dtype(f.dtype).itemsize for f in BLOCK if f.name in GATHERED)


def spec_bytes(n: int = 100) -> float:
    """Bytes a block of what every rank makes of every scene block at set-up, at its peak:
    the specs (pdem.model.build.expand_blocks), the gathered geometric scalars (as runs: the
    other rank's run of cubes stood in) and the spec table made from them, with a build
    share of two blocks (peak resident growth, in a process of its own, of the n^3 cube
    stack)."""
    code = "\n".join([
        "import sys", f"sys.path.insert(0, {str(HERE.parent)!r})",
        "import numpy as np",
        "from pdem.cases.stacks import cube_stack_scene",
        "from pdem.config import parse_scene",
        "from pdem.model.build import SpecTable, expand_blocks",
        "def hwm():",
        "    for line in open('/proc/self/status'):",
        "        if line.startswith('VmHWM'):",
        "            return int(line.split()[1]) * 1024",
        f"scene = parse_scene(cube_stack_scene({n}, 'fast'))",
        "r0 = hwm()",
        "from pdem.model.build import geometry_columns",
        "from pdem.model.runs import RunColumn",
        "specs = expand_blocks(scene, 10**7, lambda n: (0, 2))",
        "n = len(specs)",
        # the share (the floor and one cube) gathers the other rank's runs: the other cubes
        "class Ranks:",
        "    size = 2",
        "    def __init__(self, cube):",
        "        self.cube = cube",
        "    def allgather(self, value):",
        "        return [value, (n - 2, np.zeros(1, np.int64), self.cube)]",
        "mine = geometry_columns(specs[0:2])",
        "cols = {k: RunColumn.gathered(Ranks(v[1:2]), v) for k, v in mine.items()}",
        "table = SpecTable(specs, scene.blocks, cols)",
        "del cols",
        "print((hwm() - r0) / n)"])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return float(out.stdout.split()[-1])


def report_model(runs):
    base = float(np.mean([r["base_mb"] for r in runs]))
    # what a rank keeps of every block, counted by nbytes (bench/setup.py), where measured
    kept = [r["scene_b"] for r in runs if "scene_b" in r]
    a, h = fit(runs, "steady_mb", max(kept) / 2**20 if kept else None)
    s, hp = fit(runs, "peak_mb", a)
    c = catalogue_bytes() / 2**20
    sp = spec_bytes() / 2**20
    kb = 1024.0
    print(f"\nfit over {len(runs)} runs: base {base:.0f} MB; after set-up {a * kb:.3f} KB per "
          f"scene block on every rank + {h * kb:.2f} KB per block held; set-up peak "
          f"{s * kb:.3f} KB per scene block + {hp * kb:.2f} KB per block held; the set-up's "
          f"gathered catalogue {c * kb:.3f} KB per scene block until the first distribution; "
          f"the specs, geometric scalars and spec table made of every block {sp * kb:.3f} KB "
          "per scene block (measured; peak GB: the largest of the three)")
    print("\nthe fit against the runs (MB per rank, max over ranks):")
    print(f"{'blocks':>10} {'ranks':>5} {'after set-up meas/model':>25} {'peak meas/model':>18}")
    for r in runs:
        _, held, _, _, _ = held_per_rank(r["n"], r["ranks"])
        print(f"{r['cubes']:>10,} {r['ranks']:>5} {r['steady_mb']:>12.0f}/"
              f"{base + a * r['cubes'] + h * held:<12.0f} {r['peak_mb']:>8.0f}/"
              f"{base + s * r['cubes'] + hp * held:<8.0f}")
    print("\nmodel, per rank (max over ranks): memory after set-up and set-up peak (GB), "
          "blocks held, halo KB received per step")
    print(f"{'scaling':>8} {'blocks':>10} {'ranks':>6} {'grid':>9} {'held':>8} "
          f"{'after set-up GB':>15} {'peak GB':>8} {'halo KB/step':>13}")
    cases = [("strong", 100, p) for p in (64, 512, 4096)] + \
        [("strong", 215, p) for p in (64, 512, 4096)] + \
        [("weak", round((1e4 * p) ** (1 / 3)), p) for p in (64, 512, 4096)]
    for kind, n, p in cases:
        _, held, _, halo, dims = held_per_rank(n, p)
        N = n ** 3
        steady = (base + a * N + h * held) / 1024.0
        # the peak: the start's first contact update, or the gathered catalogue beside the
        # build share (about what a rank holds) when the scene is large enough
        peak = max(base + s * N + hp * held, base + max(c, sp) * N + hp * N / p) / 1024.0
        print(f"{kind:>8} {N:>10.3g} {p:>6} {'x'.join(map(str, dims)):>9} {held:>8.0f} "
              f"{steady:>15.2f} {peak:>8.2f} {halo:>13.1f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[22, 46, 100],
                    help="cubes per edge (22: 10,648; 46: 97,336; 100: 10^6)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--memory", default="20GiB",
                    help="limits.max_memory_per_rank for the runs (the pre-flight's limit)")
    ap.add_argument("--save", default=str(HERE / "scale-last.json"))
    ap.add_argument("--model-only", metavar="FILE", help="fit the model to a saved run")
    args = ap.parse_args()
    if args.model_only:
        runs = json.loads(Path(args.model_only).read_text())
    else:
        runs = measure(args.n, args.ranks, args.memory)
        Path(args.save).write_text(json.dumps(runs, indent=1))
        rate = {(r["n"], r["ranks"]): r["rate"] for r in runs}
        for n in args.n:
            if (n, 1) in rate and (n, 2) in rate:
                print(f"n={n}: strong-scaling efficiency on 2 ranks "
                      f"{rate[(n, 2)] / (2 * rate[(n, 1)]):.2f}")
    if len(runs) >= 2:
        report_model(runs)


if __name__ == "__main__":
    main()
