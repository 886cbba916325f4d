"""The state declaration drives the halo, migration, checkpoints and snapshots; a restart
continues every plugin's schedule (histories sample at the same times as a straight run)."""

from __future__ import annotations

import os

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.io.checkpoint import read_checkpoint
from pdem.model import fields as F
from pdem.parallel.halo import ROW
from pdem.simulation import Simulation


def test_declared_travel_sets_are_consistent():
    names = [f.name for f in F.BLOCK]
    assert len(names) == len(set(names))
    # everything a checkpoint restores must also move with a block (or be rebuilt: static)
    assert set(F.CHECKPOINT) <= set(F.MIGRATE) | set(F.STATIC)
    # the halo row is exactly the declared halo fields, and ghosts get the pose they render
    assert ROW == sum(f.width for f in F.HALO) == 19
    # a scene pays only for the halo of the features it uses: without solve.inactive the
    # hold flag is not sent
    assert F.row_width(F.halo_fields(False)) == 18 and F.halo_fields(True) == F.HALO
    # nor the path since the last update, which only zoned blocks' contacts read
    assert F.row_width(F.halo_fields(False, zoned=False)) == 17
    assert "u_geo" not in {f.name for f in F.halo_fields(True, zoned=False)}
    assert {"x", "q", "v", "w", "dtheta"} <= {f.name for f in F.HALO}
    assert {f.output for f in F.OUTPUT} == {"centroid", "orientation", "velocity",
                                            "angular_velocity", "removed", "stage_origin"}
    for table in (F.BLOCK, F.CONTACT, F.SUB):
        for f in table:
            assert f.units and f.doc, f.name


SCENE = """
name: slider
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 20.0}}
gravity: [5.0, 0.0, -9.81]
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [6, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock}
solve: {time: 0.06}
output:
  file: OUT
  every: 0.02
  histories: [{block: cube, quantity: displacement, every: 0.0075}]
checkpoint: {every: 0.03, file: CK}
"""


def _history(path):
    with h5py.File(path, "r") as f:
        g = f["histories/cube.displacement"]
        return g["time"][()], g["value"][()]


def test_restart_continues_history_schedule_and_state(tmp_path):
    straight = os.path.join(tmp_path, "straight.h5")
    text = SCENE.replace("CK", os.path.join(tmp_path, "ck"))
    sim = Simulation(parse_scene(text.replace("OUT", straight)), MPI.COMM_SELF)
    sim.run()
    sim.close()
    cks = sorted(p for p in os.listdir(tmp_path) if p.startswith("ck-"))
    ck = read_checkpoint(os.path.join(tmp_path, cks[0]))
    assert "history_next_time" in ck["attrs"] and "resolved" in ck["attrs"]
    resumed = os.path.join(tmp_path, "resumed.h5")
    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(update={"file": resumed})})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    again.run()
    again.close()
    t0, v0 = _history(straight)
    t1, v1 = _history(resumed)
    tail = t0 > float(ck["attrs"]["time"]) + 1e-12
    np.testing.assert_array_equal(t1, t0[tail])  # no extra sample at the restart
    np.testing.assert_array_equal(v1, v0[tail])
    assert np.array_equal(again.blocks.x, sim.blocks.x)
    from pdem.io import summarise

    assert "energy (J" in summarise(straight) and "balance error" in summarise(straight)
    assert v0[-1, 0] > 1e-3  # it slides (5 / 9.81 > tan 20 deg): 1.43 m/s2, 2.6 mm by 0.06 s


def test_restart_from_the_last_checkpoint_marches_nothing_and_ends_cleanly(tmp_path):
    # found: the energy budget's end-of-run line read a sample the restart never took
    text = SCENE.replace("CK", os.path.join(tmp_path, "ck")).replace(
        "{time: 0.06}", "{steps: 100}").replace("every: 0.02", "every_steps: 50").replace(
        "every: 0.03", "every_steps: 50")  # the last step a multiple of the energy sampling's
    sim = Simulation(parse_scene(text.replace("OUT", os.path.join(tmp_path, "a.h5"))),
                     MPI.COMM_SELF)
    sim.run()
    sim.close()
    last = sorted(p for p in os.listdir(tmp_path) if p.startswith("ck-"))[-1]
    ck = read_checkpoint(os.path.join(tmp_path, last))
    assert int(ck["attrs"]["step"]) == sim.step  # the run's last step
    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": os.path.join(tmp_path, "b.h5")})})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    again.run()
    again.close()
    assert again.step == sim.step and np.array_equal(again.blocks.x, sim.blocks.x)


def test_exact_sum_does_not_depend_on_how_rows_are_split():
    """The energy budget's reduction: correctly rounded, so any partition gives the same bits
    (a plain sum of these values depends on the order); a rank with no rows takes part."""
    from pdem.mpi import exact_sum

    rng = np.random.default_rng(5)
    v = rng.normal(size=(1000, 3)) * 10.0 ** rng.integers(-8, 8, size=(1000, 1))
    whole = exact_sum(MPI.COMM_SELF, v)
    assert not np.array_equal(v[::-1].sum(axis=0), v.sum(axis=0))  # order matters to np.sum
    perm = rng.permutation(1000)
    np.testing.assert_array_equal(exact_sum(MPI.COMM_SELF, v[perm]), whole)
    import math

    np.testing.assert_array_equal(whole, [math.fsum(v[:, k]) for k in range(3)])
    assert exact_sum(MPI.COMM_SELF, np.zeros((0, 3))).tolist() == [0.0, 0.0, 0.0]
    bad = v.copy()
    bad[3, 1], bad[4, 2] = np.inf, np.nan  # a column that is not finite sums as numpy does
    got = exact_sum(MPI.COMM_SELF, bad)
    assert got[0] == whole[0] and got[1] == np.inf and np.isnan(got[2])


def _as_format_3(path):
    """Rewrite a checkpoint in the layout of format 3: int64 sub-contact state bits, int32
    contact types, ``held`` of 6 columns (zeros: no solve.inactive), a normal force column
    ``sc_fn`` (formats 1-4; nonsense values: a restart must not read it), and the blocks'
    ``work`` of 9 columns (before the quiet faces' ``WORK_QUIET``)."""
    with h5py.File(path, "a") as f:
        work = f["blocks/work"][()]
        assert work.shape[1] == 10 and not work[:, 9].any()
        del f["blocks/work"]
        f.create_dataset("blocks/work", data=work[:, :9])
        for name, dtype in (("subcontacts/sc_state", np.int64), ("contacts/ctype", np.int32)):
            data = f[name][()].astype(dtype)
            del f[name]
            f.create_dataset(name, data=data)
        n = len(f["contacts/nsub"])
        del f["contacts/held"]
        f.create_dataset("contacts/held", data=np.zeros((n, 6)))
        f.create_dataset("subcontacts/sc_fn", data=np.full(len(f["subcontacts/sc_un"]), -1e9))
        f.attrs["format_version"] = 3


def test_contacts_hold_forces_only_with_solve_inactive_and_old_checkpoints_restart(tmp_path):
    """``held`` has columns only with solve.inactive (48 bytes a contact otherwise), the state
    bits are uint8, and a checkpoint of format 3 (int64 bits, int32 types, 6 held columns,
    9 work columns) restarts bitwise; a state value that uint8 cannot hold is refused."""
    from pdem.io.checkpoint import FORMAT_VERSION

    text = SCENE.replace("CK", os.path.join(tmp_path, "ck"))
    sim = Simulation(parse_scene(text.replace("OUT", os.path.join(tmp_path, "a.h5"))),
                     MPI.COMM_SELF)
    sim.run()
    sim.close()
    c = sim.contacts
    assert c.n and c.held.shape == (c.n, 0) and c.sc_state.dtype == np.uint8
    assert c.ia.dtype == np.int32 and c.ctype.dtype == np.int8
    path = os.path.join(tmp_path, sorted(p for p in os.listdir(tmp_path) if p.startswith("ck-"))[0])
    assert read_checkpoint(path)["attrs"]["format_version"] == FORMAT_VERSION
    _as_format_3(path)
    ck = read_checkpoint(path)
    assert ck["contacts"].sc_state.dtype == np.uint8 and ck["contacts"].held.shape[1] == 6
    assert ck["blocks"]["work"].shape[1] == 10  # (widened: the new column zero)
    scene = parse_scene(ck["attrs"]["scene"])
    scene = scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": os.path.join(tmp_path, "b.h5")}), "checkpoint": None})
    again = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    assert again.contacts.held.shape[1] == 0
    again.run()
    again.close()
    for k in ("x", "q", "v", "w", "work"):
        assert np.array_equal(getattr(again.blocks, k), getattr(sim.blocks, k)), k
    for k in ("sc_fs", "sc_us", "sc_un", "sc_state"):
        assert np.array_equal(again.contacts.sub[k], sim.contacts.sub[k]), k
    assert len(ck["contacts"].sc_state)  # the cube rests on sub-contacts at the checkpoint
    with h5py.File(path, "a") as f:
        f["subcontacts/sc_state"][0] = 300
    with pytest.raises(ValueError, match="outside uint8"):
        read_checkpoint(path)
    # with solve.inactive the contacts hold 6 columns (force and moment)
    held = parse_scene(SCENE.replace("CK", os.path.join(tmp_path, "ck2")).replace(
        "OUT", os.path.join(tmp_path, "c.h5")).replace(
        "solve: {time: 0.06}", "solve: {time: 0.06, inactive: {speed: 1.0e-4}}"))
    sim = Simulation(held, MPI.COMM_SELF, output=False)
    sim.run(steps=2)
    assert sim.contacts.n and sim.contacts.held.shape == (sim.contacts.n, 6)


def test_scene_store_keeps_only_the_run_catalogue_after_set_up(tmp_path):
    """Once the output is open, every rank keeps of every scene block only what the rebuild,
    the checkpoint and the excavations read (RUN_CATALOGUE: fixed, out); the set-up's other
    per-block fields are gone, the centroids, masses and inertias too. A stage then still
    stops blocks by a selection (asking the owners) and deletes one leaving the domain: the
    changes reach the blocks a rank holds and the fields the store kept."""
    from pdem.selection import CATALOGUE, RUN_CATALOGUE

    text = """
name: staged
materials: {rock: {density: 2500.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -1, -1], max: [2, 1, 0]}, material: rock, fixed: true}
  - {name: a, box: {min: [-1.5, -0.5, 0.0], max: [-0.5, 0.5, 1.0]}, material: rock,
     velocity: [0.5, 0.0, 0.0]}
  - {name: b, box: {min: [0.5, -0.5, 0.0], max: [1.5, 0.5, 1.0]}, material: rock,
     velocity: [0.0, 0.0, 4.0]}
solve: {damping: none}
domain: {min: [-3, -2, -2], max: [3, 2, 1.2], action: delete}
stages:
  - {name: hold, fix: {names: [a]}, solve: {time: 0.5}}
"""
    scene = parse_scene(text + f"output: {{file: {tmp_path}/s.h5}}\n")
    sim = Simulation(scene, MPI.COMM_SELF)
    kept = {f.name for f in F.BLOCK if f.name in vars(sim.state.glob)}
    assert kept == set(RUN_CATALOGUE) == {"fixed", "out"} and set(RUN_CATALOGUE) < set(CATALOGUE)
    assert sim.state.glob.n == 3
    sim.run()
    g, b = sim.state.glob, sim.blocks
    names = [s.name for s in sim.state.specs]
    a_row, b_row = (int(np.nonzero(b.gid == names.index(n))[0][0]) for n in "ab")
    assert g.fixed[b.gid[a_row]] == 1 and b.fixed[a_row] == 1  # the stage's fix reached both
    assert np.all(b.v[a_row] == 0.0)
    assert g.out[b.gid[b_row]] == 2 and b.out[b_row] == 2  # b left the domain upwards
    sim.close()
    # pdem check keeps the whole scene
    whole = Simulation(parse_scene(text), MPI.COMM_SELF, output=False, release=False)
    assert set(CATALOGUE) <= set(vars(whole.state.glob))
