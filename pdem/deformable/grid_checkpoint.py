"""The zoned blocks' grids in checkpoints: what each rank writes of the grids it owns, the
``grids`` group of a checkpoint file, and a restart's grids read back from it."""

from __future__ import annotations

import h5py
import numpy as np

from ..mpi import allgather, gather
from .motion import N_GW
from .zones import zone_geometry


def checkpoint_rows(grids, comm, parallel: bool):
    """What :func:`write` writes of the owned grids of ``grids`` (a GridStore; collective):
    the table of every writing rank's grids (gid, gridpoint and zone counts) and this rank's arrays;
    on one writer (``parallel`` False, several ranks) rank 0 gets every rank's arrays."""
    own = range(grids.n_owned)
    mine = {"gid": np.array([grids.gids[d] for d in own], np.int64),
            "n_nodes": np.array([len(grids.bodies[d].nodes) for d in own], np.int64),
            "n_zones": np.array([len(grids.bodies[d].tets) for d in own], np.int64),
            "work": np.array([grids.bodies[d].work for d in own]).reshape(-1, N_GW)}
    arrays = {k: [getattr(grids, k)[grids.node_start[d]:grids.node_start[d + 1]] for d in own]
              for k in ("nodes", "vel", "force", "kc")}
    arrays["stress"] = [grids.bodies[d].stress for d in own]
    arrays["plastic"] = [grids.bodies[d].plastic for d in own]
    arrays["prev"] = [grids.bodies[d].prev_force for d in own]
    # applied loads (a stage's force, a released quiet boundary's reactions)
    arrays["applied"] = [grids.bodies[d].applied for d in own]
    if not parallel and comm.size > 1:  # one writer: every grid to it
        parts = gather(comm, (mine, arrays))
        if comm.rank != 0:
            return None
        mine = {k: np.concatenate([p[0][k] for p in parts]) for k in mine}
        arrays = {k: [a for p in parts for a in p[1][k]] for k in arrays}
        return [mine], mine, arrays
    return (allgather(comm, mine) if parallel else [mine]), mine, arrays

def write(f, rows, rank: int) -> None:
    """The grids' state (:func:`checkpoint_rows`) into group ``grids`` of an open
    checkpoint file, in gid order over all ranks: gid, gridpoint and zone counts,
    gridpoint positions, velocities, contact forces, contact stiffness (``kc``: the next
    step's masses), last total forces (``prev``: combined damping's) and applied loads
    (``applied``: a stage's force, a released quiet boundary's reactions), zone stresses and
    plastic bits, the
    grids' energy accumulators (``work``, pdem.deformable.motion.GW_*; the sub-contacts' grid
    columns are in ``subcontacts/sc_grid``)."""
    table, mine, arrays = rows
    allt = {k: np.concatenate([t[k] for t in table]) for k in mine}
    order = np.argsort(allt["gid"], kind="stable")
    node_off = np.zeros(len(order) + 1, np.int64)
    zone_off = np.zeros(len(order) + 1, np.int64)
    np.cumsum(allt["n_nodes"][order], out=node_off[1:])
    np.cumsum(allt["n_zones"][order], out=zone_off[1:])
    where = {int(g): i for i, g in enumerate(allt["gid"][order])}
    g = f.create_group("grids")
    for k in ("gid", "n_nodes", "n_zones"):
        d = g.create_dataset(k, (len(order),), dtype=np.int64)
        if rank == 0:
            d[:] = allt[k][order]
    d = g.create_dataset("work", (len(order), N_GW), dtype=np.float64)
    if rank == 0:
        d[:] = allt["work"][order]
    shapes = {"nodes": (3,), "vel": (3,), "force": (3,), "kc": (), "prev": (3,), "applied": (3,),
              "stress": (6,), "plastic": ()}
    for k, shape in shapes.items():
        zones = k in ("stress", "plastic")
        off = zone_off if zones else node_off
        d = g.create_dataset(k, (int(off[-1]), *shape),
                             dtype=np.int32 if k == "plastic" else np.float64)
        for gid, a in zip(mine["gid"], arrays[k], strict=True):
            i = where[int(gid)]
            d[off[i]:off[i + 1]] = a

def load(grids, path) -> None:
    """Continue the grids held here from a checkpoint written by :func:`write` (before
    the blocks are distributed): gridpoints, velocities, contact forces, last total forces,
    stresses,
    plastic bits, energy accumulators, and the zones' geometry from the gridpoints. ValueError (agreed over
    the ranks by the restore) if the file has no such grids."""
    with h5py.File(path, "r") as f:
        if "grids" not in f or "n_nodes" not in f["grids"]:
            raise ValueError("no grids of this scene's zoned blocks (a checkpoint of "
                             "another scene, or of a pdem before zoned blocks ran on "
                             "several ranks: run its scene again)")
        g = f["grids"]
        gid = g["gid"][()]
        node_off = np.concatenate([[0], np.cumsum(g["n_nodes"][()])])
        zone_off = np.concatenate([[0], np.cumsum(g["n_zones"][()])])
        where = {int(x): i for i, x in enumerate(gid)}
        for d, gg in enumerate(grids.gids):
            i = where.get(gg)
            b = grids.bodies[d]
            if i is None or node_off[i + 1] - node_off[i] != len(b.nodes) \
                    or zone_off[i + 1] - zone_off[i] != len(b.tets):
                raise ValueError(f"no grid for zoned block {grids.names[d]!r} as this "
                                 "scene zones it")
            a, e = grids.node_start[d], grids.node_start[d + 1]
            for k in ("nodes", "vel", "force"):
                getattr(grids, k)[a:e] = g[k][node_off[i]:node_off[i + 1]]
            # the last force pass's contact stiffness (the next step's masses); a checkpoint
            # without it: the stage's masses
            grids.kc[a:e] = g["kc"][node_off[i]:node_off[i + 1]] if "kc" in g else 0.0
            b.stress[:] = g["stress"][zone_off[i]:zone_off[i + 1]]
            b.plastic[:] = g["plastic"][zone_off[i]:zone_off[i + 1]]
            # (a checkpoint without them: combined damping's dF/dt starts from nil)
            b.prev_force[:] = g["prev"][node_off[i]:node_off[i + 1]] if "prev" in g else 0.0
            # (a checkpoint without them: the budget's grid works start over)
            work = g["work"][i] if "work" in g else np.zeros(0)
            b.work[:] = 0.0
            b.work[:len(work)] = work  # (a checkpoint before quiet_absorbed: one column less)
            if "applied" in g:
                b.applied[:] = g["applied"][node_off[i]:node_off[i + 1]]
                b.loaded = bool(b.applied.any())
            zone_geometry(b.nodes, b.tets, b.grad, b.vol)
