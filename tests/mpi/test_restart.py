"""Checkpoint/restart continuity: 2N steps straight == N steps + checkpoint + restart + N,
bitwise, when the checkpoint written on 2 ranks is restarted on 1 rank and on all ranks; on
all ranks each reads the rows of its build share's blocks and their contacts only (as ``pdem
restart``)."""

import os

import h5py
import numpy as np
import pytest
from mpi4py import MPI

import pdem.io.checkpoint as checkpoint_io
import pdem.restart as restart_module
from pdem.config import parse_scene
from pdem.io.checkpoint import open_checkpoint, read_checkpoint
from pdem.simulation import Simulation
from pdem.state import build_share

SCENE = """
name: restart-pile
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 1.0e8, ks: 5.0e7, friction: 30.0, cohesion: 1.0e4, tension: 1.0e4}}}}
blocks:
  - {{name: floor, box: {{min: [-3, -3, -0.5], max: [3, 3, 0.0]}}, material: rock, fixed: true}}
  - name: rock
    random: {{count: 30, region: {{min: [-2, -2, 0.05], max: [2, 2, 1.3]}}, size: [0.45, 0.6], seed: 3}}
    material: rock
    velocity: [0.5, 0.0, -3.0]
solve: {{steps: {steps}, damping: local}}
output: {{file: {out}, every_steps: {half}, contacts: false}}
checkpoint: {{every_steps: {half}, keep: 3, file: {ck}}}
"""
N = 1000
FIELDS = ("centroid", "orientation", "velocity", "angular_velocity")


def final_state(path):
    with h5py.File(path, "r") as f:
        return {k: f[f"blocks/{k}"][-1] for k in FIELDS}, int(f["step"][-1])


def _straight_run(comm, tmp_path, half):
    """The pile run 2 ``half`` steps on every rank, checkpointed at ``half``: its folder,
    scene text and final state."""
    d = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    os.makedirs(d, exist_ok=True)
    text = SCENE.format(steps=2 * half, half=half, out=f"{d}/straight.h5", ck=f"{d}/ck")
    s = Simulation(parse_scene(text), comm)
    s.run()
    s.close()
    return d, text, final_state(f"{d}/straight.h5")[0]


def _continues_bitwise(sim, out, end, ref, label):
    """Run the restarted ``sim`` to its end: its last output frame is step ``end`` and bitwise
    ``ref``."""
    sim.run()
    sim.close()
    got, step = final_state(out)
    assert step == end
    for k in FIELDS:
        assert np.array_equal(got[k], ref[k]), (label, k)


@pytest.mark.mpi(min_size=2)
def test_restart_on_other_rank_counts_is_bitwise(tmp_path):
    comm = MPI.COMM_WORLD
    d = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    os.makedirs(d, exist_ok=True)
    text = SCENE.format(steps=2 * N, half=N, out=f"{d}/straight.h5", ck=f"{d}/ck")
    # the straight run and its checkpoint at step N, on 2 ranks
    pair = comm.Split(0 if comm.rank < 2 else MPI.UNDEFINED, comm.rank)
    if pair != MPI.COMM_NULL:
        s = Simulation(parse_scene(text), pair)
        s.run()
        assert s.contacts.n > 0  # history matters: blocks are in contact when checkpointed
        s.close()
        pair.Free()
    comm.Barrier()
    ck_path = f"{d}/ck-{N:09d}.h5"
    ck = read_checkpoint(ck_path)
    assert ck["attrs"]["n_ranks"] == 2 and ck["contacts"].n > 0
    assert np.any(ck["contacts"].sub["sc_fs"] != 0.0)  # shear-force history is in the checkpoint
    scene = parse_scene(ck["attrs"]["scene"])
    ref, ref_step = final_state(f"{d}/straight.h5")
    assert ref_step == 2 * N

    def restart(c, out, state):
        sc = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out}),
                                      "checkpoint": None})
        r = Simulation(sc, c, checkpoint=state)
        assert r.step == N
        owned = r.n_owned
        at_start["owned"] = r.state.owned_gids().copy()
        r.run()
        r.close()
        return final_state(out), owned

    at_start = {}
    if comm.rank == 0:  # on 1 rank, the whole file read at once
        (got, step), _ = restart(MPI.COMM_SELF, f"{d}/r1.h5", ck)
        assert step == 2 * N
        for k in FIELDS:
            assert np.array_equal(got[k], ref[k]), k
    comm.Barrier()
    # on every rank of the job, each reading its share (rows counted per dataset)
    read = {}
    whole = checkpoint_io._read_rows

    def counted(dset, rows):
        read[dset.name] = read.get(dset.name, 0) + len(rows)
        return whole(dset, rows)

    # and the contacts each rank receives from the readers
    route = restart_module.route_contacts
    routed = []

    def recorded(*args, **kwargs):
        got = route(*args, **kwargs)
        routed.append((got.ga.copy(), got.gb.copy()))
        return got

    checkpoint_io._read_rows = counted
    restart_module.route_contacts = recorded
    try:
        (got, step), owned = restart(comm, f"{d}/r{comm.size}.h5", open_checkpoint(ck_path))
    finally:
        checkpoint_io._read_rows = whole
        restart_module.route_contacts = route
    assert step == 2 * N
    for k in FIELDS:
        assert np.array_equal(got[k], ref[k]), k
    n_blocks, n_contacts = len(ck["blocks"]["x"]), ck["contacts"].n
    # the rows of its build share only (no rank reads every block's centroid), which the
    # rebuild sends to their owners; gathered before asserting, so that no rank waits in a
    # collective for one that failed
    lo, hi = build_share(comm, n_blocks)
    rows = comm.allgather((read["/blocks/x"], read["/blocks/q"], hi - lo, owned))
    assert all(x == share and q == share for x, q, share, _ in rows), rows
    assert sum(o for *_, o in rows) == n_blocks
    if comm.size > 1:
        assert owned < n_blocks
    # each contact read once, by one rank, in even shares (its sub-contacts with it); then sent
    # straight to the ranks that own one of its free blocks (not first to the build shares)
    (ga, gb), = routed
    here = np.isin(ga, at_start["owned"]) | np.isin(gb, at_start["owned"])
    travelled = comm.allgather((len(ga), int(here.sum())))
    assert all(n == k for n, k in travelled) and sum(n for n, _ in travelled) >= n_contacts, \
        travelled
    counts = comm.allgather((read.get("/contacts/normal", 0), read.get("/contacts/ga", 0),
                             read.get("/subcontacts/sc_fs", 0)))
    # (the blocks and pieces are read twice: first to route, then with the rest of each batch,
    # so that they are not held while the contacts travel)
    assert [2 * c[0] for c in counts] == [c[1] for c in counts], counts
    assert sum(c[0] for c in counts) == n_contacts, counts
    assert max(c[0] for c in counts) - min(c[0] for c in counts) <= 1, counts
    assert sum(c[2] for c in counts) == ck["contacts"].n_sub, counts


@pytest.mark.mpi(min_size=2)
def test_damaged_contact_counts_are_refused_alike_by_every_rank(tmp_path):
    """The ranks read the sub-contact counts in shares: a negative count in the last rank's
    share, or counts summing to more sub-contacts than the file holds, are refused by every
    rank with the same line (no rank reads past a dataset or waits for one that failed)."""
    if MPI.COMM_WORLD.size > 3:  # ~10-35 s each on the oversubscribed 4-rank tier
        pytest.skip("the refusal path on the 2- and 3-rank tiers")
    import shutil

    from pdem.errors import UserError

    comm = MPI.COMM_WORLD
    d = comm.bcast(str(tmp_path) if comm.rank == 0 else None, root=0)
    os.makedirs(d, exist_ok=True)
    half = N  # the pile has landed: contacts for every rank's share
    text = SCENE.format(steps=half, half=half, out=f"{d}/straight.h5", ck=f"{d}/ck")
    s = Simulation(parse_scene(text), comm)
    s.run()
    s.close()
    comm.Barrier()
    good = f"{d}/ck-{half:09d}.h5"
    for damage in ("negative", "sum"):
        path = f"{d}/{damage}.h5"
        n_contacts = 0
        if comm.rank == 0:
            shutil.copy(good, path)
            with h5py.File(path, "r+") as f:
                nsub = f["contacts/nsub"]
                n_contacts = len(nsub)
                row = n_contacts - 1 if damage == "negative" else 0
                nsub[row] = -1 if damage == "negative" else nsub[row] + 5
        # every rank has a share of the contacts (checked on all: none left in a collective)
        assert comm.bcast(n_contacts, root=0) > comm.size
        sc = parse_scene(text)
        sc = sc.model_copy(update={"output": sc.output.model_copy(update={"file": f"{d}/r.h5"}),
                                   "checkpoint": None})
        try:
            Simulation(sc, comm, checkpoint=open_checkpoint(path))
            why = None
        except UserError as exc:
            why = str(exc)
        whys = comm.allgather(why)
        assert whys[0] is not None and len(set(whys)) == 1, whys
        assert whys[0].startswith(f"cannot restart from {path}: ") and "\n" not in whys[0]
        assert ("negative counts" if damage == "negative" else "sub-contacts, the file holds") \
            in whys[0], whys[0]


@pytest.mark.mpi(min_size=2)
def test_restart_with_the_whole_scene_on_every_rank_is_bitwise(tmp_path):
    """A run that keeps every block's geometry on every rank (a boundary stress finds exposed
    faces among all blocks; here ``release=False``) restarts through the whole-scene path:
    each rank takes the blocks it owns and reads the contacts of its free ones. It continues
    bitwise as the straight run and as the restart by shares."""
    if MPI.COMM_WORLD.size > 3:  # ~10-35 s each on the oversubscribed 4-rank tier
        pytest.skip("the whole-scene restart path on the 2- and 3-rank tiers (the 4-rank "
                    "tier restarts by shares)")
    comm = MPI.COMM_WORLD
    half = 400
    d, text, ref = _straight_run(comm, tmp_path, half)
    for release in (True, False):
        sc = parse_scene(text)
        sc = sc.model_copy(update={"output": sc.output.model_copy(update={"file": f"{d}/r.h5"}),
                                   "checkpoint": None})
        r = Simulation(sc, comm, checkpoint=open_checkpoint(f"{d}/ck-{half:09d}.h5"),
                       release=release)
        assert comm.allreduce(r.contacts.n) > 0  # the history matters
        _continues_bitwise(r, f"{d}/r.h5", 2 * half, ref, release)


@pytest.mark.mpi(min_size=2)
def test_restart_read_in_small_batches_and_from_format_2_is_bitwise(tmp_path, monkeypatch):
    """Each rank reads and sends its share of the contacts in batches (pdem.io.checkpoint
    READ_BATCH, here a contact or two each, so the ranks read different numbers of batches),
    from the current format and from one in format 2's layout (no piece columns, int64
    state bits, int32 types, 6 held columns, a stored normal force): the restart continues
    bitwise as the straight run, with its contacts in key order."""
    if MPI.COMM_WORLD.size > 3:  # ~10-35 s each on the oversubscribed 4-rank tier
        pytest.skip("reading in batches and the old layout do not depend on the brick "
                    "layout: the 2- and 3-rank tiers'")
    comm = MPI.COMM_WORLD
    half = 400
    d, text, ref = _straight_run(comm, tmp_path, half)
    good = f"{d}/ck-{half:09d}.h5"
    old = f"{d}/old.h5"
    if comm.rank == 0:
        import shutil

        shutil.copy(good, old)
        with h5py.File(old, "a") as f:
            for name, dtype in (("subcontacts/sc_state", np.int64),
                                ("contacts/ctype", np.int32)):
                data = f[name][()].astype(dtype)
                del f[name]
                f.create_dataset(name, data=data)
            n = len(f["contacts/nsub"])
            del f["contacts/held"], f["contacts/pga"], f["contacts/pgb"]
            f.create_dataset("contacts/held", data=np.zeros((n, 6)))
            f.create_dataset("subcontacts/sc_fn", data=np.full(len(f["subcontacts/sc_un"]),
                                                               -1e9))
            f.attrs["format_version"] = 2
    comm.Barrier()
    monkeypatch.setattr(checkpoint_io, "READ_BATCH", 300)  # bytes: a contact or two
    read = []
    ranged = checkpoint_io.CheckpointReader.contact_range

    def counted(self, c0, c1, *args, **kwargs):
        read.append(c1 - c0)
        return ranged(self, c0, c1, *args, **kwargs)

    monkeypatch.setattr(checkpoint_io.CheckpointReader, "contact_range", counted)
    for path in (good, old):
        read.clear()
        sc = parse_scene(text)
        sc = sc.model_copy(update={"output": sc.output.model_copy(update={"file": f"{d}/r.h5"}),
                                   "checkpoint": None})
        r = Simulation(sc, comm, checkpoint=open_checkpoint(path))
        keys = r.contacts.keys()
        assert np.all(keys[1:] > keys[:-1]) and r.contacts.held.shape[1] == 0
        with h5py.File(path, "r") as f:
            n_file = len(f["contacts/nsub"])
        # every contact read once, one or two a batch (the ranks pad with empty batches)
        assert sum(comm.allgather(sum(read))) == n_file and max(read) <= 2, read
        assert len([n for n in read if n]) >= sum(read) / 2, read
        _continues_bitwise(r, f"{d}/r.h5", 2 * half, ref, path)
