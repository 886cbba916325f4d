"""Runs that cannot succeed stop early and say why (issue 39; pdem.plugins.no_progress,
docs/workflow.md "Solves that cannot succeed"), and the snapshot count is bounded
(``limits.max_snapshots``, pdem.plugins.output).

The rule under test, with ``W = solve.no_progress_steps``: the ratio is sampled every
``W / SAMPLES`` steps, its level is the largest of the last ``LEVEL`` samples, and a solve whose
level has not fallen 5% (or doubled) for ``W`` steps stops. So a block that falls with no
contacts stops the solve at most ``W + 2 W / SAMPLES`` steps after its last contact (the rise
of the ratio is seen at the next sample), a ratio that never improves at most
``W + (LEVEL + 1) W / SAMPLES`` steps after the solve began; a model that settles, however
long it takes, is not stopped.
"""

from __future__ import annotations

import logging
import re

import h5py
import pytest
from mpi4py import MPI

from pdem.cases import make_simulation
from pdem.cases.oscillator import cube_on_floor
from pdem.cases.runaway import SLAB_FRICTION, cohesive_slab_scene, slide_off_scene, slide_scene
from pdem.cases.stacks import cube_stack_scene
from pdem.cases.staged import slab_fos
from pdem.config import ConfigError, parse_scene
from pdem.errors import NoProgressError
from pdem.plugins.no_progress import LEVEL, SAMPLES
from pdem.simulation import Simulation


def swap(text: str, old: str, new: str) -> str:
    """``text`` with ``old`` replaced, which must be there."""
    assert old in text, old
    return text.replace(old, new)


def last_contact(text: str, window: int) -> int:
    """The step (to a sample interval) after which the slider has no contact: the scene run
    by steps, not to its ratio."""
    sim = make_simulation(text)
    every = window // SAMPLES
    while sim.step < 20 * window:
        sim.runner.run(steps=every)
        c = sim.contacts
        if not (c.n and (c.sc_un > 0.0).any()):
            return sim.step - every
    raise AssertionError("the slider never lost its contacts")


def stop_message(text: str) -> tuple[str, int]:
    """Run the scene in ``text`` until the no-progress watch stops it: (its one-line message,
    the step it stopped after); the output is closed either way."""
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    try:
        with pytest.raises(NoProgressError) as err:
            sim.run()
    finally:
        sim.close()
    return str(err.value), sim.step


def test_a_block_that_slides_off_its_base_and_falls_stops_the_stage(tmp_path):
    window = 10_000
    out = str(tmp_path / "off.h5")
    # (max_steps: without the watch the stage would end there, without an error)
    text = slide_off_scene(window, "ratio: 1.0e-5, max_steps: 60000", output=out)
    lost = last_contact(text, window)
    msg, step = stop_message(text)
    print(f"\nlast contact at step {lost}, stopped at step {step}: {msg}")
    assert "\n" not in msg
    assert msg.startswith("stages[0] 'equilibrium': the ratio cannot reach 1e-05: no progress "
                          "in 10000 steps (solve.no_progress_steps)")
    assert "block 'slider' is falling with no contacts at" in msg
    assert "a domain:" in msg
    # it slid and tipped first (the ratio rose as it went): not stopped while it still could
    # have come to rest, and stopped within the bound once it fell
    assert lost < step <= lost + window + 2 * (window // SAMPLES)
    # the output is flushed up to the stop; no stage checkpoint (the stage did not end)
    with h5py.File(out) as f:
        assert int(f["step"][-1]) == step
    assert not (tmp_path / "off-stage0-equilibrium.h5").exists()


def test_a_block_sliding_down_a_weak_joint_stops_the_stage(tmp_path):
    window = 4_000
    # the scene's solve does not watch (0); the stage's own window does
    text = slide_scene(0, f"ratio: 1.0e-5, no_progress_steps: {window}, max_steps: 20000",
                       output=str(tmp_path / "slide.h5"))
    sim = make_simulation(text)
    with pytest.raises(NoProgressError, match=r"stages\[0\] 'equilibrium'") as err:
        sim.run()
    msg = str(err.value)
    assert "no progress in 4000 steps (stages[0].solve.no_progress_steps)" in msg
    print(f"\nstopped at step {sim.step}: {msg}")
    assert "block 'slider' is sliding on block 'base' at" in msg
    assert "speeding up from" in msg  # local damping takes only part of its unbalanced force
    assert "stronger joints for the equilibrium stage" in msg
    assert window < sim.step <= window + (LEVEL + 1) * (window // SAMPLES)


def test_the_stop_is_off_with_a_zero_window(tmp_path, caplog):
    text = slide_scene(0, "ratio: 1.0e-5, max_steps: 6000", output=str(tmp_path / "slide.h5"))
    sim = make_simulation(text)
    with caplog.at_level(logging.WARNING, logger="pdem"):
        summary = sim.run()
    assert sim.step == 6000 and summary["ratio"] > 1e-5
    assert any("solve.max_steps=6000" in r.getMessage() for r in caplog.records)


def test_a_model_that_settles_slowly_is_not_stopped():
    # 27 cubes under adaptive damping to 1e-8: ~3500 steps, through the servo's slow start and
    # contact ringing; the watch samples them from step 100 and could stop them from 2500 on
    window = 2_000
    sim = make_simulation(swap(cube_stack_scene(3, "fast", "adaptive"), "steps: 1,",
                               f"ratio: 1.0e-8, no_progress_steps: {window},"))
    summary = sim.run()
    print(f"\nsettled in {summary['steps']} steps")
    assert summary["ratio"] <= 1e-8
    assert summary["steps"] > window + LEVEL * (window // SAMPLES)


def test_weak_cohesive_joints_need_strong_joints_for_the_equilibrium_stage(tmp_path):
    # FS 1.18 by the closed form: the joint holds the slab's weight, not the overshoot of the
    # shear force while gravity comes on (about 1.33 x the static load under local damping)
    cohesion = 400.0
    exact = slab_fos(SLAB_FRICTION, cohesion)
    msg, step = stop_message(cohesive_slab_scene(cohesion, False,
                                                 output=str(tmp_path / "plain.h5")))
    print(f"\nFS {exact:.4f}, one equilibrium stage: stopped at step {step}: {msg}")
    assert msg.startswith("stages[0] 'equilibrium': the ratio cannot reach 1e-06")
    assert "block 'slab' is sliding on block 'base'" in msg
    assert "stronger joints for the equilibrium stage" in msg
    # 3DEC's remedy: strong joints to equilibrium, then the real strength, then the search
    sim = Simulation(parse_scene(cohesive_slab_scene(cohesion, True,
                                                     output=str(tmp_path / "strong.h5"))),
                     MPI.COMM_SELF)
    try:
        summary = sim.run()
    finally:
        sim.close()
    steps = [(st["stage"], st["steps"]) for st in summary["stages"]]
    print(f"strong joints first: FS {summary['factor']:.4f} ({summary['factor'] / exact - 1:+.2%}"
          f", {len(summary['trials'])} trials); steps {steps}")
    assert [name for name, _ in steps] == ["equilibrium", "real-strength", "strength"]
    assert summary["bounded"] and abs(summary["factor"] / exact - 1.0) < 0.02


@pytest.mark.parametrize("where", ["solve", "stages[0].solve"])
def test_the_window_is_validated_naming_the_key(where):
    if where == "solve":
        text = slide_scene(500)
    else:
        text = slide_scene(20_000, "ratio: 1.0e-5, no_progress_steps: 500")
    with pytest.raises(ConfigError, match=re.escape(f"{where}.no_progress_steps: 500 steps is "
                                                    "too short")):
        parse_scene(text)
    assert parse_scene(slide_scene(20_000)).solve.no_progress_steps == 20_000
    assert parse_scene(cube_on_floor(0.0)).solve.no_progress_steps == 20_000  # the default


# ------------------------------------------------------------------ the snapshot count
def test_a_scene_that_would_write_too_many_snapshots_is_refused(tmp_path):
    out = str(tmp_path / "many.h5")
    text = cube_on_floor(0.0, end="time: 10.0") + f"output: {{file: {out}, every: 1.0e-4}}\n"
    with pytest.raises(ConfigError) as err:
        Simulation(parse_scene(text), MPI.COMM_SELF)
    msg = str(err.value)
    print("\n" + msg)
    assert "output.every = 0.0001 s: a snapshot every" in msg
    assert "over solve.time = 10 s" in msg
    assert "snapshots, more than limits.max_snapshots = 10000" in msg
    assert "give output.every >= 0.001" in msg
    # the bound is the scene's to raise (or lift)
    sim = Simulation(parse_scene(text + "limits: {max_snapshots: null}"), MPI.COMM_SELF)
    sim.close()


def test_a_solve_to_a_ratio_stops_its_periodic_snapshots_at_the_bound(tmp_path, caplog):
    out = str(tmp_path / "capped.h5")
    text = swap(slide_scene(4_000, "ratio: 1.0e-5, max_steps: 20000", output=out),
                "every_steps: 1000", "every_steps: 100") \
        + "limits: {max_snapshots: 5}\n"
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    try:
        with caplog.at_level(logging.WARNING, logger="pdem"), pytest.raises(NoProgressError):
            sim.run()
    finally:
        sim.close()
    with h5py.File(out) as f:
        steps = list(f["step"][()])
    assert steps == [0, 100, 200, 300, 400, sim.step]  # five, then the last state
    warned = [r.getMessage() for r in caplog.records if "limits.max_snapshots" in r.getMessage()]
    assert len(warned) == 1 and "raise output.every (now every 100 steps)" in warned[0]
