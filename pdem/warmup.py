"""Fill the kernel cache (pdem.jit) before a job needs it.

    pdem warmup [SCENE.yaml ...] [--steps N] [--once]
    mpiexec -n 2 pdem warmup configs/default.yaml        # also the kernels of a parallel run

Runs each scene for ``--steps`` steps (default 20), its output into a temporary folder that is
removed after, so that the kernels it uses (stepping, contact updates, energy samples, output,
and under ``mpiexec`` the halo and migration) are compiled and saved; a later run of a scene of
the same kinds loads them and starts in seconds. Without scenes, a built-in two-block scene
with both common-plane algorithms. ``--once``: nothing to do when this cache (these sources)
was warmed with the same scenes on the same number of ranks already (a stamp in the cache
folder); ``run/setup`` warms the shipped scenes this way. On a cluster, run it on a node
before a job array (docs/parallel.md). Ranks started on a cold cache do not need it: one rank
of a node compiles each kernel and the others load it (pdem.jit's compile locks).
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import time
from pathlib import Path

from .jit import CACHE_DIR

SCENE = """
name: warmup
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock}
contact: {algorithm: ALGORITHM}
solve: {steps: 12, damping: DAMPING}
"""


def builtin_scenes(damping: str = "local") -> list[tuple[str, str]]:
    """(name, scene text) of the built-in warm-up: both common-plane algorithms."""
    return [(f"warmup-{a}", SCENE.replace("ALGORITHM", a).replace("DAMPING", damping))
            for a in ("fast", "cundall")]


def stamp_path(texts: list[str], steps: int, ranks: int) -> Path:
    """The stamp that says this cache was warmed with these scenes, steps and ranks."""
    h = hashlib.sha256(f"{steps} {ranks}".encode())
    for text in texts:
        h.update(b"\0" + text.encode())
    return Path(CACHE_DIR) / "warm" / h.hexdigest()[:16]


def warm(comm, scenes: list[tuple[str, str, object]], steps: int = 20,
         once: bool = False) -> float:
    """Run each ``(name, text, scene)`` (a validated scene and the text it was read from) for
    ``steps`` steps on ``comm``, output into a temporary folder; the seconds it took (0 when
    ``once`` found the stamp). Collective."""
    from .simulation import Simulation

    stamp = stamp_path([text for _, text, _ in scenes], steps, comm.size)
    if once and comm.bcast(stamp.exists() if comm.rank == 0 else None, root=0):
        return 0.0
    t0 = time.perf_counter()
    folder = comm.bcast(tempfile.mkdtemp(prefix="pdem-warmup-") if comm.rank == 0 else None,
                        root=0)
    try:
        for name, _, scene in scenes:
            out = scene.output.model_copy(update={"file": os.path.join(folder, name + ".h5")})
            scene = scene.model_copy(update={"output": out})
            sim = Simulation(scene, comm)
            sim.run(steps=steps)
            sim.close()
    finally:
        comm.Barrier()
        if comm.rank == 0:
            for path in Path(folder).iterdir():
                path.unlink()
            os.rmdir(folder)
    if comm.rank == 0:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(f"{[name for name, _, _ in scenes]} {steps} steps, {comm.size} ranks\n")
    return time.perf_counter() - t0


def main(comm, paths: list[str], steps: int, once: bool, log: logging.Logger) -> int:
    """``pdem warmup``: the scene files ``paths`` (none: the built-in scenes)."""
    from .config import load_scene, parse_scene

    if paths:
        loaded = [load_scene(p) for p in paths]  # (a missing or bad file: a UserError)
        scenes = [(Path(p).stem, Path(p).read_text(), scene)
                  for p, scene in zip(paths, loaded, strict=True)]
    else:
        scenes = [(name, text, parse_scene(text)) for name, text in builtin_scenes()]
    level = log.level
    log.setLevel(logging.WARNING)  # the scenes' progress lines say nothing here
    try:
        took = warm(comm, scenes, steps, once)
    finally:
        log.setLevel(level)
    names = ", ".join(name for name, _, _ in scenes)
    if took == 0.0:
        log.info("kernel cache %s: already warm for %s on %d rank(s)", CACHE_DIR, names,
                 comm.size)
    else:
        log.info("kernel cache %s: warmed for %s on %d rank(s) in %.0f s", CACHE_DIR, names,
                 comm.size, took)
    return 0

