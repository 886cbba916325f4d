"""Output memory benchmark: peak memory per rank of the cube stack with and without output.

The model is the cube stack of bench/setup.py (pdem.cases.stacks: n x n x n unit cubes on a
floor, N = n^3). A throwaway run of each configuration on the 2^3 stack first fills the kernel
cache, so that no measured process compiles. Each configuration runs in fresh processes under
``mpiexec -n RANKS``: the kernels are loaded on a small model first, then the n^3 stack is
built and stepped ``--steps`` times, once without output and once writing a snapshot every
``--every`` steps (the joint state included, as by default).

    .venv/bin/python bench/output_memory.py                      # n = 40 (64,000 cubes), 2 ranks
    .venv/bin/python bench/output_memory.py --n 24 --steps 40    # a quicker proxy
    .venv/bin/python bench/output_memory.py --trace              # + tracemalloc of rank 0's
                                                                 #   largest snapshot write

Prints per configuration each rank's peak resident memory (getrusage), its resident memory
after set-up and the largest rise of the resident peak during a snapshot write, the sampled PSS
peak (shared pages split among the ranks, bench/setup.py), the ratio with/without output, the
file's size and its bytes per block per snapshot. Run it against another tree with
PYTHONPATH=that/tree to compare. Not a test: the figures of a shared machine are noisy.
Issue 39's target: with output <= 1.15x without, <= 450 MB per rank at 64,000 cubes on 2 ranks.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from setup import PeakSampler  # bench/setup.py (this folder is first on the path)

from pdem.memory import resident_mb


def _maxrss_mb() -> float:
    """The resident peak (MB): ``VmHWM`` since the last :func:`_reset_peak` (getrusage's
    lifetime peak where /proc is missing)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_peak() -> bool:
    """Restart the resident peak from the current resident size (Linux ``clear_refs`` 5), so
    that loading (or compiling) the kernels on the small model does not count."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def child(n: int, steps: int, every: int, path: str, trace: bool) -> None:
    """Build the n^3 stack on MPI.COMM_WORLD, run ``steps`` steps with output every ``every``
    steps to ``path`` (``-``: no output); print one JSON line (rank 0)."""
    from mpi4py import MPI

    import pdem.io.writer as writer_mod
    from pdem.cases.stacks import cube_stack_scene
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    comm = MPI.COMM_WORLD
    output = path != "-"
    # load the kernels (the output's too) on a small model: compiling them (a cold cache) is
    # not the run's memory; what they keep loaded still counts (the peak restarts from now)
    warm = cube_stack_scene(2, "fast")
    if output:
        warm += f"output: {{file: {path}.warm.h5, every_steps: 1}}\n"
    Simulation(parse_scene(warm), comm, output=output).run(steps=2)
    base = resident_mb()
    _reset_peak()
    writes: list[tuple[float, float, float]] = []  # per snapshot: maxrss before, after, s
    traced: list = []
    orig = writer_mod.OutputWriter.write_snapshot

    def spied(self, *args, **kwargs):
        before = _maxrss_mb()
        t0 = time.perf_counter()
        if trace and comm.rank == 0 and len(writes) == 2:
            import tracemalloc

            tracemalloc.start(8)
            try:
                orig(self, *args, **kwargs)
                snap = tracemalloc.take_snapshot()
                peak = tracemalloc.get_traced_memory()[1]
            finally:
                tracemalloc.stop()
            traced.append((peak, [str(s) for s in snap.statistics("lineno")[:15]]))
        else:
            orig(self, *args, **kwargs)
        writes.append((before, _maxrss_mb(), time.perf_counter() - t0))

    writer_mod.OutputWriter.write_snapshot = spied
    text = cube_stack_scene(n, "fast")
    if output:
        text += f"output: {{file: {path}, every_steps: {every}}}\n"
    comm.Barrier()
    sampler = PeakSampler()
    t0 = time.perf_counter()
    sim = Simulation(parse_scene(text), comm, output=output)
    setup_rss = resident_mb()
    setup_peak = _maxrss_mb()
    sim.run(steps=steps)
    sim.close()
    wall = time.perf_counter() - t0
    pss_peak = sampler.stop()
    rise = max((b - a for a, b, _ in writes), default=0.0)
    io_s = sum(s for _, _, s in writes)
    rows = comm.gather(dict(rank=comm.rank, peak_mb=_maxrss_mb(), base_mb=base,
                            setup_mb=setup_rss, setup_peak_mb=setup_peak, pss_peak_mb=pss_peak,
                            write_rise_mb=rise, io_s=io_s, snapshots=len(writes),
                            blocks=sim.state.glob.n, wall_s=wall), root=0)
    if comm.rank == 0:
        out = {"ranks": rows, "n": n, "steps": steps, "every": every, "output": output}
        if output:
            out["file_bytes"] = os.path.getsize(path)
        if traced:
            out["trace_peak_mb"] = traced[0][0] / 2**20
            out["trace_top"] = traced[0][1]
        print("RESULT " + json.dumps(out), flush=True)


def run(args, path: str) -> dict | None:
    py = sys.executable
    cmd = [py, __file__, "--child", str(args.n), str(args.steps), str(args.every), path]
    if args.trace:
        cmd.append("--trace")
    if args.ranks > 1:
        cmd = [str(Path(py).with_name("mpiexec")), "-n", str(args.ranks), *cmd]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode or not line:
        print(f"{'with' if path != '-' else 'without'} output: failed (exit {proc.returncode})"
              f"\n{proc.stderr[-3000:]}")
        return None
    return json.loads(line[0][7:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=40, help="cubes per side (N = n^3); default 40")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks (mpiexec), default 2")
    ap.add_argument("--steps", type=int, default=100, help="steps run; default 100")
    ap.add_argument("--every", type=int, default=10, help="steps between snapshots; default 10")
    ap.add_argument("--only", choices=("with", "without"), help="run one configuration")
    ap.add_argument("--trace", action="store_true",
                    help="tracemalloc rank 0's third snapshot write (slow)")
    ap.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        n, steps, every, path = args.child
        child(int(n), int(steps), int(every), path, args.trace)
        return
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        # fill the kernel cache first (a throwaway run of each configuration on the 2^3 stack):
        # a kernel compiled in a measured run stays resident (LLVM, ~100-300 MB a rank) and
        # reads as a swing of "kernels loaded" (the run without output at 220 -> 313 MB)
        small = argparse.Namespace(**{**vars(args), "n": 2, "steps": 2, "trace": False})
        for key in ("without", "with"):
            run(small, "-" if key == "without" else str(Path(tmp) / "warm.h5"))
        for key in ("without", "with"):
            if args.only and args.only != key:
                continue
            res[key] = run(args, "-" if key == "without" else str(Path(tmp) / "out.h5"))
    print(f"cube stack {args.n}^3, {args.ranks} rank(s), {args.steps} steps, a snapshot every "
          f"{args.every} steps; MB per rank")
    for key, r in res.items():
        if r is None:
            continue
        for row in r["ranks"]:
            print(f"  {key:>7} output, rank {row['rank']}: peak {row['peak_mb']:.0f} "
                  f"(kernels loaded {row['base_mb']:.0f}, set up {row['setup_mb']:.0f}, "
                  f"set-up peak {row['setup_peak_mb']:.0f}), PSS peak {row['pss_peak_mb']:.0f}, "
                  f"largest rise in a snapshot write {row['write_rise_mb']:.0f}, "
                  f"{row['snapshots']} snapshots {row['io_s']:.1f} s, run {row['wall_s']:.1f} s")
        if "file_bytes" in r:
            blocks = r["ranks"][0]["blocks"]
            snaps = r["ranks"][0]["snapshots"]
            print(f"  file {r['file_bytes'] / 1e6:.1f} MB: {r['file_bytes'] / blocks / snaps:.0f}"
                  f" bytes per block per snapshot ({blocks} blocks, {snaps} snapshots)")
        if "trace_top" in r:
            print(f"  tracemalloc peak in rank 0's third write: {r['trace_peak_mb']:.1f} MB")
            for line in r["trace_top"]:
                print("    " + line)
    if res.get("with") and res.get("without"):
        w = max(row["peak_mb"] for row in res["with"]["ranks"])
        wo = max(row["peak_mb"] for row in res["without"]["ranks"])
        pw = max(row["pss_peak_mb"] for row in res["with"]["ranks"])
        pwo = max(row["pss_peak_mb"] for row in res["without"]["ranks"])
        print(f"  peak per rank with/without: {w:.0f} / {wo:.0f} MB = {w / wo:.3f}; "
              f"PSS {pw:.0f} / {pwo:.0f} MB = {pw / pwo:.3f}")
    print("RESULTS " + json.dumps(res))


if __name__ == "__main__":
    main()
