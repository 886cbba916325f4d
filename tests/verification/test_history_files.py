"""History files driving a prescribed velocity (``history: {file: ...}``; pdem.config.records,
pdem.boundary), in runs.

Closed forms, computed here:

* a block driven by an AT2 record of constant acceleration ``a`` (0.1 g, scale 9.81, no
  baseline) for T = 0.2 s moves at ``a t`` at every step's mid-step time (to 1e-12 m/s: the
  record's trapezoid integral of a constant is exact up to the cumulative sum's round-off)
  and is at ``a t^2 / 2`` at T, then holds ``a T`` and is at ``a T^2 / 2 + a T (t - T)``
  (the leap-frog's midpoint rule is exact for a velocity linear over each step; relative
  1e-12);
* a stage's file history runs on the time since the stage began (the file's table
  interpolated at ``t - t0``, to 1e-14 m/s: the recorder's time rounds differently);
* a checkpoint taken mid-record restarts (the scene stored in it names the file, made
  absolute from the scene file's folder, and is read again) and ends bit for bit where the
  straight run ends.
"""

from __future__ import annotations

import glob
import shutil
from pathlib import Path

import numpy as np
import yaml
from mpi4py import MPI

from pdem.cases import make_simulation
from pdem.config import load_scene, parse_scene
from pdem.config import records as R
from pdem.io.checkpoint import read_checkpoint
from pdem.plugins.base import Plugin
from pdem.simulation import Simulation

RECORDS = Path(__file__).resolve().parents[2] / "configs" / "records"
RHO, KN, G = 2500.0, 1.0e9, 9.81
A_G, T_REC, DT_REC = 0.1, 0.2, 0.001  # g, s, s: the constant-acceleration record


class Recorder(Plugin):
    """A block's velocity after every step, with its time level t + dt/2, and its centroid."""

    name = "recorder"

    def __init__(self, state, name):
        self.state = state
        self.gid = next(i for i, sp in enumerate(state.specs) if sp.name == name)
        self.rows = []

    def after_step(self, run):
        s = self.state
        r = int(np.nonzero(s.blocks.gid == self.gid)[0][0])
        self.rows.append((s.time - 0.5 * s.dt, *s.blocks.v[r], s.time, *s.blocks.x[r]))


def constant_at2(path) -> None:
    n = int(round(T_REC / DT_REC)) + 1
    body = "\n".join(" ".join([f"{A_G:.4E}"] * min(5, n - k)) for k in range(0, n, 5))
    path.write_text("constant acceleration, for tests/verification/test_history_files.py\n"
                    "x\nACCELERATION TIME SERIES IN UNITS OF G\n"
                    f"NPTS= {n}, DT= {DT_REC} SEC\n{body}\n")


def test_block_follows_a_constant_acceleration_record(tmp_path):
    rec = tmp_path / "const.at2"
    constant_at2(rec)
    text = f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}}}}}
blocks:
  - {{name: b, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
boundary:
  velocity:
    - names: [b]
      history: {{file: {rec}, quantity: acceleration, direction: [1, 0, 0], scale: 9.81,
                baseline: false}}
solve: {{time: 0.3, damping: none, timestep: {{dt: 1.0e-3}}}}
"""
    sim = make_simulation(text)
    r = Recorder(sim.state, "b")
    sim.runner.plugins.append(r)
    sim.run()
    rows = np.array(r.rows)
    a = A_G * 9.81
    t_mid, v = rows[:, 0], rows[:, 1:4]
    want = a * np.minimum(t_mid, T_REC)
    err_v = np.abs(v[:, 0] - want).max()
    assert np.abs(v[:, 1:]).max() == 0.0
    t_end, x = rows[:, 4], rows[:, 5]
    x_want = np.where(t_end <= T_REC + 1e-9, 0.5 * a * t_end**2,
                      0.5 * a * T_REC**2 + a * T_REC * (t_end - T_REC))
    k = len(t_end) // 4  # from 0.075 s on: the relative error of a position well away from 0
    err_x = (np.abs(x[k:] - x_want[k:]) / x_want[k:]).max()
    print(f"\nvelocity error {err_v:.3g} m/s (a T = {a * T_REC:.4g}), position relative error "
          f"{err_x:.3g}; {len(rows)} steps to t = {t_end[-1]:.6g}")
    assert len(rows) == 300 and t_mid[-1] > T_REC
    assert err_v <= 1e-12
    assert err_x <= 1e-12
    assert np.abs(rows[:, 6:8] - [0.0, 0.5]).max() == 0.0  # y and z stay (prescribed at 0)


def stage_scene(history: str, extra: str = "") -> str:
    return f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: base, box: {{min: [-3, -3, -1], max: [3, 3, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
solve: {{damping: local}}
stages:
  - {{name: settle, solve: {{steps: 100}}}}
  - name: shake
    velocity: [{{names: [base], history: {history}}}]
    solve: {{time: 0.35, damping: none}}
{extra}"""


def test_stage_history_file_runs_on_the_stage_clock(tmp_path):
    """The shipped Ricker pulse (10 Hz, peak 0.1 m/s over 0.3 s) along y shakes the base in
    the second stage: the base's velocity at each step is the file's table at t - t0."""
    csv = RECORDS / "ricker-10hz.csv"
    sim = make_simulation(stage_scene(f"{{file: {csv}, direction: [0, 2, 0]}}"))
    r = Recorder(sim.state, "base")
    sim.runner.plugins.append(r)
    sim.run()
    rows = np.array(r.rows)
    t0 = sim.state.stage_times[1]
    shaking = rows[rows[:, 0] > t0]
    t, v = R.read_series(str(csv))
    want = np.interp(shaking[:, 0] - t0, t, v)
    print(f"\n{len(shaking)} shaking steps, peak base velocity {np.abs(shaking[:, 2]).max():.4g}")
    assert t0 > 0.0 and len(shaking) > 100
    # (the recorded time (t + dt) - dt/2 rounds unlike the condition's t + dt/2: 1e-14 m/s,
    # as the harmonic history's test in test_boundary.py)
    err = np.abs(shaking[:, 2] - want).max()
    print(f"largest difference from the file's table {err:.3g} m/s")
    assert err <= 1e-14
    assert np.abs(shaking[:, [1, 3]]).max() == 0.0
    assert np.abs(rows[rows[:, 0] < t0, 1:4]).max() == 0.0  # fixed while settling
    assert np.abs(shaking[:, 2]).max() > 0.099


def test_restart_mid_record_reads_the_file_again_bitwise(tmp_path):
    """The scene file names the record relative to itself (``records/...``); a checkpoint
    taken while it plays restarts from the scene it stores and ends where the straight run
    ends, bit for bit."""
    (tmp_path / "records").mkdir()
    shutil.copy(RECORDS / "synthetic-0.3g.at2", tmp_path / "records" / "quake.at2")
    extra = (f"output: {{file: {tmp_path}/straight.h5, every_steps: 500}}\n"
             f"checkpoint: {{every_steps: 600, keep: 5, file: {tmp_path}/ck}}\n")
    scene_file = tmp_path / "scene.yaml"
    scene_file.write_text(stage_scene("{file: records/quake.at2, quantity: acceleration, "
                                      "direction: [1, 0, 0], scale: 9.81}", extra))
    scene = load_scene(scene_file)
    assert scene.stages[1].velocity[0].history.file == str(tmp_path / "records/quake.at2")
    straight = Simulation(scene, MPI.COMM_SELF)
    straight.run()
    straight.close()
    ck_file = sorted(glob.glob(f"{tmp_path}/ck-*.h5"))[0]
    ck = read_checkpoint(ck_file)
    text = ck["attrs"]["scene"]
    stored = yaml.safe_load(text)["stages"][1]["velocity"][0]["history"]
    assert stored["file"] == str(tmp_path / "records/quake.at2") and "E-0" not in text
    again_scene = parse_scene(text)
    again_scene = again_scene.model_copy(update={"output": again_scene.output.model_copy(
        update={"file": str(tmp_path / "again.h5")}), "checkpoint": None})
    again = Simulation(again_scene, MPI.COMM_SELF, checkpoint=ck)
    again.run()
    again.close()
    assert ck["attrs"]["step"] > 100  # taken in the shaking stage
    for k in ("x", "q", "v", "w"):
        assert np.array_equal(getattr(again.blocks, k), getattr(straight.blocks, k)), k
    assert np.abs(straight.blocks.v).max() > 0.0
