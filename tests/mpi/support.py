"""Support module of the MPI tests (``from support import ...``): run a scene on the world communicator and
on one rank, compare the output files bit for bit, and never leave ranks hanging when one of
them fails.

A rank that raises inside pdem while the others wait in a collective would hang the job until
pytest-timeout fires; ``collective`` turns such an error into MPI_Abort with the rank's
traceback instead (the job fails at once, loudly). Assertions are made after the collective
part, on data every rank has, so an ordinary test failure is reported on every rank.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import traceback

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MPIEXEC = os.path.join(ROOT, ".venv", "bin", "mpiexec")

# every block state the output file holds; all must match the 1-rank run bit for bit
STATE = ("blocks/centroid", "blocks/orientation", "blocks/velocity", "blocks/angular_velocity")
# and, in scenes with zoned blocks, every gridpoint and zone state
ZONE_STATE = ("zones/points", "zones/velocity", "zones/stress", "zones/plastic")


@contextlib.contextmanager
def collective(comm, what: str):
    """Abort the whole job (not hang) if this rank fails while the others may be in MPI calls."""
    try:
        yield
    except Exception:
        sys.stderr.write(f"\n*** rank {comm.rank}/{comm.size} failed in {what}; aborting the job "
                         f"so the other ranks do not hang:\n{traceback.format_exc()}\n")
        sys.stderr.flush()
        comm.Abort(1)


def shared_dir(comm, tmp_path) -> str:
    """Rank 0's pytest tmp_path: file names must be the same on every rank."""
    return comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)


def sleep_barrier(comm, poll: float = 0.005):
    """A barrier whose waiting ranks sleep instead of spinning (MPICH busy-polls in blocking
    calls, which on an oversubscribed machine steals the CPU from the rank doing the work)."""
    req = comm.Ibarrier()
    while not req.Test():
        time.sleep(poll)


def on_rank0(comm, fn, *args, **kw):
    """Run ``fn`` on rank 0 only (the others sleep); its result, or its error re-raised as an
    AssertionError, on every rank."""
    result = err = None
    if comm.rank == 0:
        try:
            result = fn(*args, **kw)
        except Exception:
            err = traceback.format_exc()
    sleep_barrier(comm)
    result, err = comm.bcast((result, err), root=0)
    assert err is None, f"on rank 0:\n{err}"
    return result


def with_parallel(text: str, dims, path: str | None, every_steps: int | None = None,
                  contacts: bool = False, **solve):
    """The scene in ``text`` with ``parallel.dims`` set, output to ``path`` (or none). The
    joint state is left out of the output unless ``contacts`` (its collective compressed writes
    dominate oversubscribed runs; tests/mpi/test_joint_output_mpi.py checks it)."""
    scene = parse_scene(text)
    scene = scene.model_copy(update={"parallel": scene.parallel.model_copy(
        update={"dims": dims if dims == "auto" else tuple(int(d) for d in dims)})})
    if path is not None:
        out = {"file": path, "contacts": contacts}
        if every_steps is not None:
            out.update(every_steps=every_steps, every=None)
        scene = scene.model_copy(update={"output": scene.output.model_copy(update=out)})
    return scene


def run(scene, comm, *, output: bool = True, steps: int | None = None, probe=None):
    """Build and run ``scene`` on ``comm`` (collective); ``probe(solver)`` is called before and
    after the run and its results returned: ``(solver, before, after, load_report)``."""
    # a 1-rank run (the reference, on rank 0) raises normally: on_rank0 reports its error
    guard = collective(comm, f"a run on {comm.size} ranks") if comm.size > 1 \
        else contextlib.nullcontext()
    with guard:
        solver = Simulation(scene, comm, output=output)
        before = probe(solver) if probe else None
        solver.run(steps=steps)
        after = probe(solver) if probe else None
        report = solver.state.load_report()
        solver.close()
    return solver, before, after, report


def reference(scene, path: str | None, steps: int | None = None):
    """The 1-rank run of ``scene`` (dims [1, 1, 1]) on MPI.COMM_SELF, writing ``path``."""
    ref = scene.model_copy(update={"parallel": scene.parallel.model_copy(update={"dims": (1, 1, 1)})})
    if path is not None:
        ref = ref.model_copy(update={"output": ref.output.model_copy(update={"file": path})})
    return run(ref, MPI.COMM_SELF, output=path is not None, steps=steps)


def cached_reference(scene, path: str, steps: int | None = None) -> np.ndarray:
    """:func:`reference` writing ``path``, run once per scene for the whole suite: the 1-rank
    run does not depend on ``parallel:`` (the rank-count contract these tests check), so the
    run/test tiers on 2, 3 and 4 ranks and the variants of one scene by decomposition share it.
    Keyed on the scene (its parallel settings and output file left out), ``steps`` and pdem's
    sources (pdem.jit's cache key); kept in ``$PDEM_TEST_REFS`` (default: the temp dir).
    Returns the final contact keys."""
    import hashlib
    import shutil
    import tempfile
    from pathlib import Path

    import pdem.jit
    from pdem.config.load import dump_scene

    plain = scene.model_copy(update={
        "parallel": type(scene.parallel)(),
        "output": scene.output.model_copy(update={"file": "reference.h5"})})
    key = hashlib.sha256(f"{dump_scene(plain)}\n{steps}\n{Path(pdem.jit.CACHE_DIR).name}"
                         .encode()).hexdigest()[:24]
    cache = Path(os.environ.get("PDEM_TEST_REFS", tempfile.gettempdir())) / "pdem-test-refs"
    h5, keys = cache / f"{key}.h5", cache / f"{key}.keys.npy"
    if h5.exists() and keys.exists():
        shutil.copyfile(h5, path)
        return np.load(keys)
    solver = reference(plain, path, steps=steps)[0]
    found = solver.contacts.keys()
    cache.mkdir(parents=True, exist_ok=True)
    tmp = cache / f"{key}.{os.getpid()}.tmp"  # written whole, then renamed: concurrent suites
    shutil.copyfile(path, tmp)
    os.replace(tmp, h5)
    with open(tmp, "wb") as f:
        np.save(f, found)
    os.replace(tmp, keys)
    return found


def read_states(path: str) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        out = {k: f[k][()] for k in STATE + ZONE_STATE if k in STATE or k in f}
        if "zones" in f:  # the zoned blocks' deformed surfaces in run.xdmf (boundary gridpoints)
            out["surface/points"] = f["surface/points"][()]
        out["time"] = f["time"][()]
        out["step"] = f["step"][()] if "step" in f else None
        for i in f.get("reinforcement", {}):  # cables and bolts (pdem.io.elements)
            for k in ("points", "axial", "shear", "slip", "state"):
                out[f"reinforcement/{i}/{k}"] = f[f"reinforcement/{i}/{k}"][()]
        for name in f.get("histories", {}):
            out[f"histories/{name}/time"] = f[f"histories/{name}/time"][()]
            out[f"histories/{name}/value"] = f[f"histories/{name}/value"][()]
    return out


def differences(path: str, ref: str) -> list[str]:
    """What differs between two output files' block states and histories (empty: identical)."""
    a, b = read_states(path), read_states(ref)
    bad = []
    if a.keys() != b.keys():
        return [f"datasets differ: {sorted(a.keys() ^ b.keys())}"]
    for k in a:
        x, y = a[k], b[k]
        if x is None and y is None:
            continue
        if x.shape != y.shape:
            bad.append(f"{k}: shape {x.shape} vs {y.shape}")
        elif not np.array_equal(x, y):
            diff = np.abs(np.asarray(x, float) - np.asarray(y, float))
            where = np.unravel_index(int(np.nanargmax(diff)), diff.shape) if diff.size else ()
            bad.append(f"{k}: {int((x != y).sum())} values differ, max |diff| "
                       f"{np.nanmax(diff):.3g} at {tuple(map(int, where))}")
    return bad


def compare_on_rank0(comm, path: str, ref_scene, ref_path: str, steps: int | None = None):
    """Rank 0 runs the 1-rank reference and compares the files; every rank asserts."""

    def check():
        cached_reference(ref_scene, ref_path, steps=steps)
        return differences(path, ref_path)

    bad = on_rank0(comm, check)
    assert not bad, f"{comm.size}-rank output differs from the 1-rank run:\n" + "\n".join(bad)


def slabs_match_one_rank(tmp_path, text: str, stem: str, every_steps: int) -> None:
    """``text`` run on one slab per rank along x (output every ``every_steps``), its file
    compared with the 1-rank run's."""
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    path = f"{base}/{stem}.h5"
    scene = with_parallel(text, [comm.size, 1, 1], path, every_steps=every_steps)
    run(scene, comm)
    compare_on_rank0(comm, path, scene, f"{base}/{stem}-ref.h5")


def child_env() -> dict[str, str]:
    """This environment without the launcher's variables: a child mpiexec starts its own job."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMI_", "PMIX_", "MPI", "HYDRA"))}
    env.update(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return env


def launch_job(n: int, argv: list[str], timeout: float = 120.0):
    """``mpiexec -n n python argv...`` as a separate job in its own session (call it from one
    rank). Returns (exit code, or None if it was killed after ``timeout`` s; stdout; stderr;
    seconds)."""
    cmd = [MPIEXEC, "-n", str(n), sys.executable, *argv]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), cwd=ROOT, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out, err, time.monotonic() - t0
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return None, out, err, time.monotonic() - t0


# Feature tests that compare a 2-rank run with the 1-rank run: the rank split is what they
# exercise, and 3 or 4 ranks oversubscribe a 2-core CI machine several-fold (MPICH busy-polls),
# so they run at 2 ranks only; tests/mpi/test_decomposition.py covers 3 and 4 ranks.
TWO_RANKS_ONLY = pytest.mark.skipif(MPI.COMM_WORLD.size != 2,
                                    reason="a 2-rank comparison (3-4 ranks: test_decomposition)")


def restart_from(comm, ck: dict, out: str) -> None:
    """Continue the run of the checkpoint ``ck`` (read_checkpoint's) on ``comm`` to its end,
    writing ``out``, no checkpoints (collective; the files are complete when it returns)."""
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out}),
                                     "checkpoint": None})
    r = Simulation(scene, comm, checkpoint=ck)
    r.run()
    r.close()
    comm.Barrier()


def straight_with_checkpoint(comm, base: str, text: str, at: int) -> dict:
    """``text`` (a scene with ``output: {energy_every: 25}``) run to its end on ``comm``,
    writing ``base/straight.h5`` every 200 steps and a checkpoint at step ``at``; that
    checkpoint, read (collective)."""
    import glob

    from pdem.config import parse_scene
    from pdem.io.checkpoint import read_checkpoint
    from pdem.simulation import Simulation

    text = text.replace("output: {energy_every: 25}\n", "") + (
        f"output: {{file: {base}/straight.h5, every_steps: 200, energy_every: 25}}\n"
        f"checkpoint: {{every_steps: {at}, keep: 5, file: {base}/ck}}\n")
    s = Simulation(parse_scene(text), comm)
    s.run()
    s.close()
    ck = read_checkpoint(sorted(glob.glob(f"{base}/ck-*.h5"))[0])
    assert int(ck["attrs"]["step"]) == at
    return ck
