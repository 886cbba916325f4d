"""Staged runs and the factor of safety by strength reduction (pdem.stages, pdem.strength).

Closed form: a slab on an incline with friction and cohesion,
``FS = (N tan(phi) + c A) / (W sin(psi))`` (pdem.cases.staged), found by bisection to 0.5%;
asserted within 2% (the residual non-uniformity of the normal stress under the slab makes the
weakest edge yield a little early: 0.3% at these numbers).
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.staged import slab_fos, slab_fos_scene, stack_stages_scene
from pdem.config import ConfigError, parse_scene
from pdem.errors import UserError
from pdem.io.checkpoint import read_checkpoint
from pdem.simulation import Simulation


@pytest.mark.parametrize("phi, cohesion", [(25.0, 0.0), (12.0, 1000.0)])
def test_factor_of_safety_of_a_slab_on_an_incline(tmp_path, phi, cohesion):
    out = str(tmp_path / "fos.h5")
    sim = Simulation(parse_scene(slab_fos_scene(phi, cohesion, output=out)), MPI.COMM_SELF)
    try:
        summary = sim.run()
    finally:
        sim.close()
    exact = slab_fos(phi, cohesion)
    got = summary["factor"]
    print(f"\nslab phi={phi} c={cohesion}: FS {got:.4f}, closed form {exact:.4f}, "
          f"error {got / exact - 1:+.2%}, {len(summary['trials'])} trials")
    assert summary["bounded"]
    assert abs(got / exact - 1.0) < 0.02
    with h5py.File(out) as f:
        assert math.isclose(f.attrs["factor_of_safety"], got)
        fs = f["factor_of_safety"]
        # the slab (gid 1) fails at the factor; the mechanism is its slide down the slope (+x)
        assert abs(fs["block_safety"][1] / exact - 1.0) < 0.03
        mech = fs["mechanism"][1]
        assert mech[0] > 0.0 and abs(mech[0]) > 10 * abs(mech[2])
        assert list(f["stage"][()]) == sorted(f["stage"][()])
    # the safety map is a cell field of the block surfaces in ParaView's sidecar
    xdmf = open(out.replace(".h5", ".xdmf")).read()
    assert 'Attribute Name="block_safety"' in xdmf and "surface_block_safety" in xdmf


def test_stages_change_the_model_and_restart_from_a_stage_checkpoint(tmp_path):
    out = str(tmp_path / "stack.h5")
    ck = str(tmp_path / "ck")
    sim = Simulation(parse_scene(stack_stages_scene(out, ck)), MPI.COMM_SELF)
    summary = sim.run()
    sim.close()
    assert [s["stage"] for s in summary["stages"]] == ["settle", "load", "dig"]
    b = sim.blocks
    row = {sim.specs[g].name: r for r, g in enumerate(b.gid)}
    assert b.out[row["second"]] == 2  # excavated when `dig` started
    assert b.fixed[row["third"]] == 0 and b.vfix[row["first"]] == 1
    assert np.allclose(b.v[row["first"]], [0, 0.1, 0])
    assert np.allclose(b.applied_force[row["third"]], [-2.0e4, 0, 0])
    # the weak joint changed in `load`: the contact first-floor uses friction 5
    assert sim.state.joints.params[1].friction == 5.0
    with h5py.File(out) as f:
        stage = f["stage"][()]
        assert set(stage) == {0, 1, 2} and list(stage) == sorted(stage)
        # stage displacement: measured from where the stage began
        last = int(np.nonzero(stage == 2)[0][0])
        assert np.allclose(f["blocks/stage_origin"][last, row["first"]],
                           f["blocks/centroid"][last - 1, row["first"]], atol=1e-3)
        straight = {k: f[f"blocks/{k}"][-1] for k in ("centroid", "velocity", "removed")}
    # restart from the checkpoint that ended `load`: replays settle and load, runs dig
    ck_load = read_checkpoint(f"{ck}-stage1-load.h5")
    assert int(ck_load["attrs"]["stage_next"]) == 2
    scene = parse_scene(ck_load["attrs"]["scene"])
    out2 = str(tmp_path / "again.h5")
    scene = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out2})})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck_load)
    s2 = again.run()
    again.close()
    assert [s["stage"] for s in s2["stages"]] == ["dig"]
    with h5py.File(out2) as f:
        for k, v in straight.items():
            assert np.array_equal(f[f"blocks/{k}"][-1], v), k


@pytest.mark.parametrize("patch, words", [
    ("joints: {weak: {friction: 5.0}}", None),
    ("joints: {nosuch: {friction: 5.0}}", "stages[1].joints: unknown joint 'nosuch'"),
    ("joints: {weak: {frictoin: 5.0}}", "stages[1].joints.weak.frictoin: not a parameter"),
])
def test_bad_stages_are_refused_naming_the_key(tmp_path, patch, words):
    text = stack_stages_scene(str(tmp_path / "x.h5")).replace(
        "joints: {weak: {friction: 5.0}}", patch)
    if words is None:
        parse_scene(text)
        return
    with pytest.raises(ConfigError, match=words.replace("[", r"\[").replace("]", r"\]")):
        parse_scene(text)


def test_a_search_on_a_model_out_of_equilibrium_is_refused(tmp_path):
    # the slab cannot hold at phi = 12 < psi without cohesion: not in equilibrium at F = 1
    text = slab_fos_scene(12.0, 0.0, output=str(tmp_path / "f.h5")).replace(
        "friction: 12.0, cohesion: 0.0", "friction: 12.0, cohesion: 0.0").replace(
        "{name: settle, solve: {ratio: 1.0e-6, max_steps: 20000}}",
        "{name: settle, solve: {steps: 10}}").replace("friction: 12.0", "friction: 15.0")
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    try:
        with pytest.raises(UserError, match=r"stages\[1\].factor_of_safety.*not in equilibrium"):
            sim.run()
    finally:
        sim.close()
    # the settle stage's checkpoint is there: nothing lost
    assert (tmp_path / "f-stage0-settle.h5").exists()
