"""What the zoned blocks cost the output file: bytes per zone per snapshot, and the writer's time.

    PYTHONPATH=. .venv/bin/python bench/zone_output.py                 # pillar, 2000 steps
    PYTHONPATH=. .venv/bin/python bench/zone_output.py --steps 800 --every 100 --size 0.25
    PYTHONPATH=. .venv/bin/python bench/zone_output.py --compare       # deflate on, then off

Runs the pillar of ``configs/pillar.yaml`` (a Mohr-Coulomb pillar zoned at ``--size`` under a
rigid roof on a fixed floor) for ``--steps`` steps with a snapshot every ``--every`` steps, on
this process alone, and prints from the file:

- per dataset of ``zones/`` with a time axis: dtype, the bytes stored (HDF5's storage size,
  i.e. after the filter) and the raw bytes (elements x item size), per snapshot;
- ``zones/`` per snapshot in bytes per zone (stored and raw): the figure of docs/output.md;
- the block surfaces (``surface/points`` and the per-triangle viewer fields) per snapshot, with
  the zoned block's share of the triangles and vertices (its grid's boundary since the
  deformed surfaces of ``run.xdmf``);
- the whole file per snapshot, and the writer's wall time per snapshot
  and CPU time per snapshot (``OutputWriter.write_snapshot``: the blocks, contacts and zones;
  median over the run's snapshots but the first).

``--compare`` runs twice, the zone series deflated (the writer's setting) then unfiltered
(``pdem.io.zone_series.COMPRESSION = {}``), to give what the filter saves and costs. Works on
older trees too (no ``COMPRESSION`` there: one run, as that tree writes). Not a test: timings on
a shared machine are noisy (the bytes are not).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import yaml
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]


def scene_text(out: Path, steps: int, every: int, size: float) -> str:
    scene = yaml.safe_load((ROOT / "configs" / "pillar.yaml").read_text())
    scene["blocks"][1]["zones"]["size"] = size
    scene["solve"]["steps"] = steps
    scene["output"] = {"file": str(out), "every_steps": every}
    return yaml.safe_dump(scene, sort_keys=False)


def run(out: Path, steps: int, every: int, size: float) -> list[tuple[float, float]]:
    """Run the pillar; the (CPU, wall) seconds of each snapshot's write."""
    import pdem.io.writer as writer_mod
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    times: list[tuple[float, float]] = []
    orig = writer_mod.OutputWriter.write_snapshot

    def timed(self, *args, **kwargs):
        c0, t0 = time.process_time(), time.perf_counter()
        orig(self, *args, **kwargs)
        times.append((time.process_time() - c0, time.perf_counter() - t0))

    writer_mod.OutputWriter.write_snapshot = timed
    try:
        sim = Simulation(parse_scene(scene_text(out, steps, every, size)), MPI.COMM_SELF)
        sim.run()
        sim.close()
    finally:
        writer_mod.OutputWriter.write_snapshot = orig
    return times


def measure(path: Path, times: list[tuple[float, float]]) -> dict:
    with h5py.File(path, "r") as f:
        n_snap = f["time"].shape[0]
        z = f["zones"]
        n_z, n_gp = len(z["connectivity"]), len(z["initial_points"])
        series = {}
        for name, d in z.items():
            if d.ndim >= 2 and d.maxshape[0] is None:  # a time series
                series[name] = (str(d.dtype), d.id.get_storage_size() / n_snap,
                                d.size * d.dtype.itemsize / n_snap, d.compression)
        surf = {name: d.id.get_storage_size() / n_snap for name, d in f["surface"].items()
                if d.maxshape[0] is None}
        bid = f["surface/block_id"][()]
        zoned = np.isin(bid, z["block"][()])
        conn = f["surface/connectivity"][()]
        out = {"n_snap": n_snap, "n_zones": n_z, "n_gridpoints": n_gp, "series": series,
               "zones_stored": sum(s[1] for s in series.values()),
               "zones_raw": sum(s[2] for s in series.values()),
               "surface": surf, "n_tri": len(bid), "zoned_tri": int(zoned.sum()),
               "n_vertices": f["surface/points"].shape[1],
               "zoned_vertices": len(np.unique(conn[zoned]))}
    out["file"] = os.path.getsize(path) / n_snap
    # the first snapshot left out (it makes the datasets); CPU time: other jobs on a shared
    # machine inflate the wall time more
    out["write_cpu_s"], out["write_s"] = np.median(times[1:], axis=0) if len(times) > 1 \
        else (float("nan"), float("nan"))
    return out


def report(label: str, m: dict) -> None:
    nz = m["n_zones"]
    print(f"\n{label}: {m['n_zones']} zones, {m['n_gridpoints']} gridpoints, {m['n_snap']} "
          "snapshots")
    print(f"  {'zones/ series':<14} {'dtype':>8} {'stored B/snap':>14} {'raw B/snap':>12}"
          f" {'stored B/zone':>14}  filter")
    for name, (dtype, stored, raw, comp) in m["series"].items():
        print(f"  {name:<14} {dtype:>8} {stored:14.0f} {raw:12.0f} {stored / nz:14.2f}  {comp}")
    print(f"  zones/ per snapshot: {m['zones_stored'] / nz:.2f} bytes per zone stored, "
          f"{m['zones_raw'] / nz:.2f} raw ({m['zones_stored'] / 1e6:.3f} MB, "
          f"{m['zones_raw'] / 1e6:.3f} MB raw)")
    s = sum(m["surface"].values())
    print(f"  surface/ per snapshot: {s / 1e3:.1f} kB stored (points "
          f"{m['surface']['points'] / 1e3:.1f} kB); the zoned block's {m['zoned_tri']} of "
          f"{m['n_tri']} triangles, {m['zoned_vertices']} of {m['n_vertices']} vertices")
    print(f"  file per snapshot: {m['file'] / 1e6:.3f} MB; write_snapshot "
          f"{1e3 * m['write_cpu_s']:.1f} ms CPU, {1e3 * m['write_s']:.1f} ms wall a snapshot "
          "(median, the first left out)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--every", type=int, default=100)
    ap.add_argument("--size", type=float, default=0.25, help="the pillar's zone size (m)")
    ap.add_argument("--compare", action="store_true",
                    help="also run with the zone series unfiltered")
    args = ap.parse_args()
    import pdem.io.zone_series as zs

    settings = [("as written", None)]
    if args.compare and hasattr(zs, "COMPRESSION"):
        settings.append(("unfiltered", {}))
    with tempfile.TemporaryDirectory() as d:
        # a warm-up run: compiling the kernels is not the writer's time
        run(Path(d) / "warm.h5", 2 * args.every, args.every, args.size)
        for label, comp in settings:
            saved = getattr(zs, "COMPRESSION", None)
            if comp is not None:
                zs.COMPRESSION = comp
            try:
                path = Path(d) / f"{label.replace(' ', '_')}.h5"
                report(label, measure(path, run(path, args.steps, args.every, args.size)))
            finally:
                if comp is not None:
                    zs.COMPRESSION = saved


if __name__ == "__main__":
    main()
