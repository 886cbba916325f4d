"""The Slurm recipe run/slurm/pdem-array.sbatch (docs/parallel.md, "On a Slurm cluster"),
under a mocked scheduler: SLURM_* variables as Slurm sets them for an array task, and fake
``srun``/``mpiexec``/``scancel`` on PATH that record their arguments (the launchers pass
SIGUSR1 on to what they started, as srun does). The fake ``pdem`` plays a run that stops on
a signal (a checkpoint and status 138), ends, fails, or waits for SIGUSR1.

What is checked is the script's logic: the first task runs the scene, later ones restart from
the newest complete checkpoint, the kernel cache is node-local (and seeded from and back to a
shared one), SIGUSR1 to the batch shell reaches the ranks, and an ended or failed run leaves a
marker and cancels the pending tasks.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "run" / "slurm" / "pdem-array.sbatch"

LAUNCHER = r"""#!/bin/bash
# records its arguments and the kernel cache it passes on, then runs the command after its
# options, passing SIGUSR1 on to it (as srun and MPICH's mpiexec do)
echo "$(basename "$0") $* | NUMBA_CACHE_DIR=${NUMBA_CACHE_DIR:-}" >> "$FAKE_LOG"
while [[ $# -gt 0 && ( "$1" == -* || "$1" =~ ^[0-9]+$ ) ]]; do shift; done
"$@" &
child=$!
trap 'kill -USR1 $child' USR1
while kill -0 $child 2>/dev/null; do wait $child; done
wait $child
"""

SCANCEL = r"""#!/bin/bash
echo "scancel $*" >> "$FAKE_LOG"
"""

PDEM = r"""#!/bin/bash
# a pdem run: FAKE_PDEM = stop | stop0 | finish | fail | wait
echo "pdem $*" >> "$FAKE_LOG"
mkdir -p "$NUMBA_CACHE_DIR/key2" && echo compiled > "$NUMBA_CACHE_DIR/key2/kernel"
[[ -e "$NUMBA_CACHE_DIR/key1/kernel" ]] && echo "seeded kernel found" >> "$FAKE_LOG"
stop() {
  touch ck-000000200.h5
  echo "pdem: stopped by SIGUSR1 at step 200 (t = 2 s); continue with: pdem restart ck-000000200.h5" >&2
  exit "${1:-138}"
}
case $FAKE_PDEM in
  stop) stop ;;
  stop0) stop 0 ;;
  finish) echo "done: 300 steps"; exit 0 ;;
  fail) echo "pdem: stages[0] 'equilibrium': the ratio cannot reach 1e-05: no progress" >&2; exit 1 ;;
  wait)
    trap 'echo "pdem got SIGUSR1" >> "$FAKE_LOG"; stop' USR1
    touch "$FAKE_READY"
    for _ in $(seq 600); do sleep 0.1; done
    exit 3 ;;
esac
"""

SCENE = """name: x
materials: {rock: {density: 2000}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks: [{name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
solve: {time: 1.0}
checkpoint: {every: 0.1, file: ck}
"""


@pytest.fixture
def cluster(tmp_path):
    """A shared run directory, a node's TMPDIR, fake tools on PATH; ``run(task, mode)`` runs
    the script as Slurm would run array task ``task`` and returns (status, output, log)."""
    shared, node, bindir = tmp_path / "shared", tmp_path / "node-tmp", tmp_path / "bin"
    for d in (shared, node, bindir):
        d.mkdir()
    for name, text in (("srun", LAUNCHER), ("mpiexec", LAUNCHER), ("scancel", SCANCEL),
                       ("pdem", PDEM)):
        (bindir / name).write_text(text)
        (bindir / name).chmod(0o755)
    (shared / "scene.yaml").write_text(SCENE)
    log = tmp_path / "calls.log"

    def env(task: int, mode: str, **extra) -> dict:
        e = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "PDEM_"))}
        e.update(PATH=f"{bindir}:{e['PATH']}", TMPDIR=str(node), FAKE_LOG=str(log),
                 FAKE_PDEM=mode, FAKE_READY=str(tmp_path / "ready"), PDEM=str(bindir / "pdem"),
                 PDEM_PYTHON=sys.executable, SLURM_SUBMIT_DIR=str(shared),
                 SLURM_JOB_ID=str(5000 + task), SLURM_ARRAY_JOB_ID="5000",
                 SLURM_ARRAY_TASK_ID=str(task), SLURM_NTASKS="4", SLURM_JOB_NUM_NODES="1")
        e.pop("NUMBA_CACHE_DIR", None)
        e.update(extra)
        return e

    def run(task: int, mode: str, scene: str = "scene.yaml", **extra):
        if log.exists():
            log.unlink()
        p = subprocess.run(["bash", str(SCRIPT), scene], cwd=tmp_path, env=env(task, mode, **extra),
                           capture_output=True, text=True, timeout=60)
        calls = log.read_text() if log.exists() else ""
        return p.returncode, p.stdout + p.stderr, calls

    run.env, run.shared, run.node, run.log, run.tmp = env, shared, node, log, tmp_path
    return run


def test_the_script_asks_slurm_for_the_early_warning_and_runs_one_task_at_a_time():
    head = [ln for ln in SCRIPT.read_text().splitlines() if ln.startswith("#SBATCH")]
    assert "#SBATCH --signal=B:USR1@300" in head
    assert any(ln.startswith("#SBATCH --array=") and ln.endswith("%1") for ln in head)
    # bash reads it (the #SBATCH lines are comments to it)
    assert subprocess.run(["bash", "-n", str(SCRIPT)]).returncode == 0


def test_the_first_task_runs_the_scene_with_a_node_local_cache_then_stops_cleanly(cluster):
    rc, out, calls = cluster(0, "stop")
    assert rc == 0, out
    lines = calls.splitlines()
    assert lines[0] == f"srun pdem run scene.yaml | NUMBA_CACHE_DIR={cluster.node}/pdem-numba" \
        .replace("srun pdem", f"srun {cluster.env(0, 'stop')['PDEM']}")
    assert "pdem run scene.yaml" in lines[1]
    assert "stopped cleanly (status 138)" in out
    assert (cluster.shared / "ck-000000200.h5").exists()  # on the shared filesystem
    assert (cluster.shared / "pdem-5000-0.log").exists()
    assert not list(cluster.shared.glob("ck-array.*"))  # neither done nor failed
    assert "scancel" not in calls


def test_a_later_task_restarts_from_the_newest_complete_checkpoint(cluster):
    shared = cluster.shared
    for k, name in enumerate(["ck-000000100.h5", "ck-stage0-settle.h5", "ck-000000400.h5",
                              "ck-000000500-failed.h5"]):
        (shared / name).touch()
        os.utime(shared / name, (1000 + k, 1000 + k))  # written in this order
    rc, out, calls = cluster(3, "stop")
    assert rc == 0, out
    assert "pdem restart ck-000000400.h5" in calls  # not the failed one, written after it
    assert "restarting from ck-000000400.h5" in out


def test_a_task_without_any_checkpoint_runs_the_scene_again(cluster):
    rc, out, calls = cluster(2, "stop")
    assert rc == 0 and "pdem run scene.yaml" in calls
    assert "no checkpoint of ck yet" in out


def test_a_finished_run_leaves_a_marker_and_cancels_the_pending_tasks(cluster):
    rc, out, calls = cluster(4, "finish")
    assert rc == 0, out
    assert "scancel --state=PENDING 5000" in calls
    marker = cluster.shared / "ck-array.done"
    assert marker.read_text().strip() == "finished by task 4 of job 5000"
    rc, out, calls = cluster(5, "finish")  # a task that started anyway
    assert rc == 0 and "nothing to do" in out and "srun" not in calls


def test_a_failed_run_stops_the_chain_with_its_message(cluster):
    rc, out, calls = cluster(1, "fail")
    assert rc == 1
    assert "scancel --state=PENDING 5000" in calls
    text = (cluster.shared / "ck-array.failed").read_text()
    assert text.startswith("failed with status 1 in task 1 of job 5000: pdem: stages[0]")
    rc, out, calls = cluster(2, "stop")
    assert rc == 0 and "nothing to do" in out and "pdem " not in calls


def test_sigusr1_to_the_batch_shell_reaches_the_ranks(cluster):
    p = subprocess.Popen(["bash", str(SCRIPT), "scene.yaml"], cwd=cluster.tmp,
                         env=cluster.env(0, "wait"), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    ready = cluster.tmp / "ready"
    for _ in range(300):
        if ready.exists():
            break
        time.sleep(0.1)
    assert ready.exists(), "the fake run did not start"
    time.sleep(0.3)  # (the launcher's trap is set once it runs its child)
    p.send_signal(signal.SIGUSR1)  # what --signal=B:USR1@300 does
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0, out
    calls = cluster.log.read_text()
    assert "pdem got SIGUSR1" in calls
    assert "asking the ranks to stop with a checkpoint" in out
    assert "stopped cleanly (status 138)" in out


def test_mpiexec_and_a_launcher_that_hides_the_stop_status(cluster):
    rc, out, calls = cluster(0, "stop0", PDEM_LAUNCH="mpiexec")
    assert rc == 0, out
    assert calls.splitlines()[0].startswith(f"mpiexec -n 4 {cluster.env(0, 'x')['PDEM']} run")
    assert "stopped cleanly (status 138)" in out  # from pdem's stop line, not the status
    assert not (cluster.shared / "ck-array.done").exists()


def test_the_kernel_cache_is_seeded_from_and_back_to_the_shared_one(cluster):
    seed = cluster.tmp / "seed"
    (seed / "key1").mkdir(parents=True)
    (seed / "key1" / "kernel").write_text("compiled before")
    rc, out, calls = cluster(0, "stop", PDEM_CACHE_SEED=str(seed))
    assert rc == 0, out
    assert "seeded kernel found" in calls  # the node had the shared kernels before the run
    assert (seed / "key2" / "kernel").read_text() == "compiled\n"  # what the node compiled
    assert sorted(p.name for p in seed.iterdir()) == ["key1", "key2"]  # no temporary left


def test_a_scene_without_checkpoints_is_refused(cluster):
    (cluster.shared / "plain.yaml").write_text(SCENE.replace("checkpoint: {every: 0.1, file: ck}\n",
                                                             ""))
    rc, out, calls = cluster(0, "stop", scene="plain.yaml")
    assert rc == 2 and "has no checkpoint: section" in out and not calls
