"""A stop signal ends the march at a step boundary with a checkpoint that restarts to the same
result; output that cannot be written is refused early or stops the run naming the file."""

import errno
import os
import signal

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem import cli, signals
from pdem.config import parse_scene
from pdem.errors import OutputError, UserError
from pdem.io import checkpoint as ckmod
from pdem.io.checkpoint import read_checkpoint
from pdem.io.writer import OutputWriter
from pdem.plugins import Plugin
from pdem.simulation import Simulation

SCENE = """
name: stop-pile
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 1.0e8, ks: 5.0e7, friction: 30.0, cohesion: 1.0e4, tension: 1.0e4}}}}
blocks:
  - {{name: floor, box: {{min: [-3, -3, -0.5], max: [3, 3, 0.0]}}, material: rock, fixed: true}}
  - name: rock
    random: {{count: 12, region: {{min: [-2, -2, 0.05], max: [2, 2, 1.3]}}, size: [0.45, 0.6], seed: 3}}
    material: rock
    velocity: [0.5, 0.0, -3.0]
solve: {{steps: {steps}, damping: local}}
output: {{file: {out}, every_steps: 50}}
"""
CHECKPOINTS = "checkpoint: {{every_steps: 50, keep: 2, file: {ck}}}\n"
FIELDS = ("centroid", "orientation", "velocity", "angular_velocity")


@pytest.fixture
def handlers():
    """The stop handlers installed for the test, the previous ones restored after it."""
    saved = {s: signal.getsignal(s) for s in signals.SIGNALS}
    yield signals.install()
    for s, h in saved.items():
        signal.signal(s, h)


class KillAt(Plugin):
    """Sends ``signum`` to this process after step ``step`` (as a batch system would)."""

    name = "kill"

    def __init__(self, step, signum):
        self.step, self.signum = step, signum

    def after_step(self, run):
        if run.state.step == self.step:
            os.kill(os.getpid(), self.signum)


def last_state(path):
    with h5py.File(path, "r") as f:
        return {k: f[f"blocks/{k}"][-1] for k in FIELDS}, int(f["step"][-1])


def test_signal_stops_with_checkpoint_that_restarts_bitwise(tmp_path, handlers):
    text = SCENE.format(steps=300, out=tmp_path / "straight.h5")
    s = Simulation(parse_scene(text), MPI.COMM_SELF)
    s.run()
    s.close()
    ref, ref_step = last_state(tmp_path / "straight.h5")

    scene = parse_scene(SCENE.format(steps=300, out=tmp_path / "stopped.h5"))
    s = Simulation(scene, MPI.COMM_SELF, stop=handlers)
    s.runner.plugins.append(KillAt(117, signal.SIGUSR1))
    summary = s.run()
    s.close()
    # raised after step 117, seen in step 118's reduction: every rank stops after step 118
    assert summary["stopped"] == signal.SIGUSR1 and s.step == 118
    assert summary["checkpoint"] == f"{tmp_path}/stopped-stop-000000118.h5"
    assert last_state(tmp_path / "stopped.h5")[1] == 118  # the output is flushed to the stop
    ck = read_checkpoint(summary["checkpoint"])
    assert int(ck["attrs"]["step"]) == 118

    out = str(tmp_path / "restarted.h5")
    r = Simulation(scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": out})}), MPI.COMM_SELF, checkpoint=ck)
    r.run()
    r.close()
    got, step = last_state(out)
    assert step == ref_step == 300
    for k in FIELDS:
        assert np.array_equal(got[k], ref[k]), k


def test_second_signal_during_the_checkpoint_write_is_ignored(tmp_path, handlers, monkeypatch):
    text = SCENE.format(steps=300, out=tmp_path / "o.h5") + CHECKPOINTS.format(ck=tmp_path / "ck")
    s = Simulation(parse_scene(text), MPI.COMM_SELF, stop=handlers)
    s.runner.plugins.append(KillAt(60, signal.SIGTERM))
    fill = ckmod._fill

    def interrupted(f, attrs, *args):
        fill(f, attrs, *args)
        if attrs["step"] == 61:  # the stop's checkpoint, mid-write: before close and rename
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(ckmod, "_fill", interrupted)
    summary = s.run()
    s.close()
    assert summary["stopped"] == signal.SIGTERM and s.step == 61
    assert int(read_checkpoint(summary["checkpoint"])["attrs"]["step"]) == 61
    assert int(read_checkpoint(tmp_path / "ck-000000050.h5")["attrs"]["step"]) == 50
    assert not list(tmp_path.glob("*.tmp"))


def test_stop_on_a_checkpoint_step_writes_it_once(tmp_path, handlers):
    text = SCENE.format(steps=300, out=tmp_path / "o.h5") + CHECKPOINTS.format(ck=tmp_path / "ck")
    s = Simulation(parse_scene(text), MPI.COMM_SELF, stop=handlers)
    s.runner.plugins.append(KillAt(99, signal.SIGTERM))
    summary = s.run()
    s.close()
    assert s.step == 100 and summary["checkpoint"] == f"{tmp_path}/ck-000000100.h5"
    assert sorted(p.name for p in tmp_path.glob("ck-*")) == ["ck-000000050.h5", "ck-000000100.h5"]


def test_unwritable_output_is_refused_before_the_first_step(tmp_path, capsys):
    missing = tmp_path / "no" / "such" / "out.h5"
    with pytest.raises(UserError, match=f"cannot write output.file {missing}: directory "):
        Simulation(parse_scene(SCENE.format(steps=10, out=missing)), MPI.COMM_SELF)
    text = SCENE.format(steps=10, out=tmp_path / "o.h5") + CHECKPOINTS.format(
        ck=tmp_path / "nodir" / "ck")
    with pytest.raises(UserError, match="cannot write checkpoint.file .*nodir/ck: directory"):
        Simulation(parse_scene(text), MPI.COMM_SELF)
    # the command line: one line, exit status 1
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE.format(steps=10, out=missing))
    saved = {s: signal.getsignal(s) for s in signals.SIGNALS}
    try:
        assert cli.main(["run", str(path), "-q"]) == 1
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"pdem: cannot write output.file {missing}: directory {missing.parent} "
                   "does not exist"]


def test_disk_full_stops_naming_the_file_and_keeps_the_last_checkpoint(tmp_path, monkeypatch):
    out = tmp_path / "o.h5"
    text = SCENE.format(steps=300, out=out) + CHECKPOINTS.format(ck=tmp_path / "ck")
    s = Simulation(parse_scene(text), MPI.COMM_SELF)
    write = OutputWriter.write_snapshot

    def full(self, step, *args, **kw):
        if step >= 150:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return write(self, step, *args, **kw)

    monkeypatch.setattr(OutputWriter, "write_snapshot", full)
    with pytest.raises(OutputError) as info:
        s.run()
    s.close()
    last = f"{tmp_path}/ck-000000150.h5"  # checkpoints come before snapshots in a step
    assert str(info.value) == (f"cannot write {out}: No space left on device; the last good "
                               f"checkpoint is {last}")
    assert int(read_checkpoint(last)["attrs"]["step"]) == 150


def test_failed_checkpoint_write_keeps_the_previous_one(tmp_path, monkeypatch):
    text = SCENE.format(steps=300, out=tmp_path / "o.h5") + CHECKPOINTS.format(ck=tmp_path / "ck")
    s = Simulation(parse_scene(text), MPI.COMM_SELF)
    fill = ckmod._fill

    def full(f, attrs, *args):
        if attrs["step"] >= 100:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        fill(f, attrs, *args)

    monkeypatch.setattr(ckmod, "_fill", full)
    with pytest.raises(OutputError, match=f"cannot write {tmp_path}/ck-000000100.h5: No space "
                       f"left on device; the last good checkpoint is {tmp_path}/ck-000000050.h5"):
        s.run()
    s.close()
    assert sorted(p.name for p in tmp_path.glob("ck-*")) == ["ck-000000050.h5"]
