"""A rock mass is built spread over the ranks (pdem.model.spread): each rank cuts, joins and
excavates the blocks of its slice and keeps its build share's pieces; the other blocks it
knows by name and scalars only. The share's blocks must be bit for bit those one process
builds, the names, parents, groups, materials, entries and excavation columns of every block
the same as from the whole list, and no rank may hold most of the pieces at any point of the
build. The list's moves and fetches return what was asked, and an error on one rank is
raised on every rank.

Run with ``mpiexec -n N python -m mpi4py -m pytest --with-mpi tests/mpi/test_spread_build.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import shared_dir
from test_shared_build import JOINTED, MESHED, build_digest, hex_mesh

from pdem.cases.rock_mass import tunnel_scene
from pdem.config import ConfigError, parse_scene
from pdem.model import spread as spread_module
from pdem.model.build import SpecTable, block_store, expand_blocks, geometry_columns
from pdem.model.spread import Spread
from pdem.mpi import run_together, weighted_share
from pdem.state import build_share

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def table_rows(table: SpecTable) -> list:
    return [(s.name, s.parent, s.group, s.material, s.entry, s.excavate_at, s.excavate_stage)
            for s in table]


@pytest.mark.parametrize("text", [JOINTED, tunnel_scene(0.1, 0.2)], ids=["jointed", "tunnel"])
def test_each_rank_builds_its_share_and_knows_every_block_by_name(text, monkeypatch):
    check_spread_build(parse_scene(text), monkeypatch)


def test_a_meshs_cells_are_made_and_joined_spread(tmp_path, monkeypatch):
    """A mesh's cells joined two by two across the ranks' shares of the cells: each rank
    makes the polyhedra of its share only, and the blocks come out as above."""
    from pdem.geometry import mesh_import

    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    if comm.rank == 0:
        hex_mesh(f"{base}/good.vtu", 6)
    comm.Barrier()
    scene = parse_scene(MESHED.format(path=f"{base}/good.vtu"))
    made = [0]
    real = mesh_import.cell_polyhedron

    def counted(*args, **kwargs):
        made[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(mesh_import, "cell_polyhedron", counted)
    specs = expand_blocks(scene, 10**6, lambda n: build_share(comm, n), comm)
    assert made[0] <= -(-216 // comm.size), made[0]  # its share of the 216 cells
    assert len(specs) == 108
    monkeypatch.undo()
    check_spread_build(scene, monkeypatch)


def check_spread_build(scene, monkeypatch):
    comm = MPI.COMM_WORLD
    whole = expand_blocks(scene, 10**6)
    largest = [0]
    real_init = Spread.__init__

    def counted(self, comm_, local):  # the most specs a rank holds at once during the build
        if local and hasattr(local[0], "pieces"):  # (a mesh's cells are spread as polyhedra)
            largest[0] = max(largest[0], len(local))
        real_init(self, comm_, local)

    monkeypatch.setattr(spread_module.Spread, "__init__", counted)
    specs = expand_blocks(scene, 10**6, lambda n: build_share(comm, n), comm)
    monkeypatch.undo()
    n = len(whole)
    assert len(specs) == n
    lo, hi = build_share(comm, n)
    # this rank's share: the very blocks one process builds; the others: no pieces
    assert all(specs[g].pieces is not None for g in range(lo, hi))
    assert all(specs[g].pieces is None for g in [*range(lo), *range(hi, n)])
    assert build_digest(specs[lo:hi]) == build_digest(whole[lo:hi])
    # every block's names and scalars, as the whole list gives them
    columns = geometry_columns(whole)
    spread_table, whole_table = SpecTable(specs, scene.blocks, columns), SpecTable(
        whole, scene.blocks, columns)
    assert table_rows(spread_table) == table_rows(whole_table)
    assert (spread_table.labels, spread_table.parents) == (whole_table.labels, whole_table.parents)
    assert np.array_equal(spread_table.excavation_times(), whole_table.excavation_times(),
                          equal_nan=True)
    # the share's store: the same piece numbering and groups as from the whole list
    a, groups_a = block_store(scene, specs, lo, hi)
    b, groups_b = block_store(scene, whole, lo, hi)
    assert groups_a == groups_b
    assert np.array_equal(a.piece_gid, b.piece_gid) and np.array_equal(a.x, b.x)
    # no rank held much more than its share of the pieces at any point (each cuts its slice,
    # evened out by each joint set's work: 58 % of the jointed region on 2 ranks, 30 % on 4)
    most = comm.allreduce(largest[0], op=MPI.MAX)
    assert most <= 1.5 * n / comm.size + 2, (most, n)


def test_moves_and_fetches_return_what_was_asked():
    """Slices of uneven sizes moved by random weights keep the list's order and take the
    weighted shares; fetching any gids gives those items on every rank; the whole list is the
    concatenation."""
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(7)
    sizes = rng.integers(0, 40, comm.size)
    sizes[1] = 0  # a rank holding nothing
    items = [("item", k) for k in range(int(sizes.sum()))]
    start = int(sizes[:comm.rank].sum())
    spread = Spread(comm, items[start:start + int(sizes[comm.rank])])
    assert (spread.start, spread.total) == (start, len(items))
    weights = rng.random(len(items)) ** 4
    moved = spread.rebalance(weights[start:start + int(sizes[comm.rank])])
    lo, hi = weighted_share(comm.rank, comm.size, weights)
    assert moved.local == items[lo:hi] and moved.start == lo
    assert moved.whole() == items
    asked = rng.integers(0, len(items), 25 + comm.rank)
    got = moved.fetch(asked)
    assert got == {int(g): items[g] for g in asked}
    assert moved.fetch([]) == {}


def test_an_error_in_one_ranks_part_is_raised_on_every_rank():
    """``run_together``: the lowest failing rank's exception on every rank (a scene error with
    its messages); none is left waiting in the next collective."""
    comm = MPI.COMM_WORLD
    last = comm.size - 1
    assert run_together(comm, lambda: comm.rank) == comm.rank

    def part():
        if comm.rank >= last - 1:
            raise ConfigError([f"cuts[0]: rank {comm.rank} failed"])
        return comm.rank

    with pytest.raises(ConfigError) as err:
        run_together(comm, part)
    assert err.value.messages == [f"cuts[0]: rank {max(last - 1, 0)} failed"]
    comm.Barrier()
