"""Weighted load balance (parallel.balance: rcb, docs/parallel.md): the RCB cuts are the same
whichever rank holds which block, and a run that rebalances its cuts on the way gives block
states bitwise identical to the 1-rank run, with a better balance than the uniform grid.

Run with ``mpiexec -n 2 python -m mpi4py -m pytest --with-mpi tests/mpi/test_balance_mpi.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import TWO_RANKS_ONLY, compare_on_rank0, run, shared_dir

from pdem.config import parse_scene
from pdem.parallel.decomposition import (
    ZONES_PER_WORK,
    Decomposition,
    block_work,
    choose_dims,
    rcb_tree,
)

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def skewed_points(n: int = 3000, seed: int = 7):
    """A dense clump in a corner and a sparse scatter; integer weights 1-20."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.random((n * 4 // 5, 3)) * 0.5, rng.random((n - n * 4 // 5, 3)) * 8.0])
    return x, rng.integers(1, 21, n)


@pytest.mark.parametrize("parts", [2, 3, 5])
def test_cuts_do_not_depend_on_which_rank_holds_which_point(parts):
    """Every rank holds a random share of the points (a different split for each ``parts``):
    the cut tree is the one rank 0 computes alone from all of them, exactly."""
    comm = MPI.COMM_WORLD
    x, w = skewed_points()
    holder = np.random.default_rng(parts).integers(0, comm.size, len(x))
    mine = holder == comm.rank
    tree = rcb_tree(comm, x[mine], w[mine], parts, [0, 0, 0], [8, 8, 8])
    alone = rcb_tree(MPI.COMM_SELF, x, w, parts, [0, 0, 0], [8, 8, 8])
    for k in ("axis", "cut", "left", "right", "rank", "leaf_work"):
        assert np.array_equal(getattr(tree, k), getattr(alone, k)), k
    owner = tree.owner_of(x)
    assert np.array_equal(np.bincount(owner, w, parts).astype(np.int64), alone.leaf_work)
    # the same tree on every rank
    assert all(np.array_equal(c, tree.cut) for c in comm.allgather(tree.cut))


def stack_and_scatter(steps: int) -> str:
    """A dense stack of 32 touching 0.5 m cubes in one corner of the floor (many contacts per
    block) and 16 small cubes on the floor spread over the rest, sliding (few contacts). The
    start's cuts (every block weighing 1) give the rank holding most of the stack most of the
    work: the first rebuild points (every few dozen steps: a small margin) rebalance."""
    return f"""
name: stack-and-scatter
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 1.0e8, ks: 5.0e7, friction: 20.0}}}}
blocks:
  - {{name: floor, box: {{min: [-4, -4, -0.5], max: [4, 4, 0]}}, material: rock, fixed: true}}
  - name: stack
    array: {{box: {{min: [-3.9, -3.9, 0.0], max: [-3.4, -3.4, 0.5]}}, count: [4, 4, 2],
             spacing: [0.5, 0.5, 0.5]}}
    material: rock
  - name: scatter
    array: {{box: {{min: [-1.0, -1.0, 0.0], max: [-0.7, -0.7, 0.3]}}, count: [4, 4, 1],
             spacing: [1.4, 1.4, 1.0]}}
    material: rock
    velocity: [1.5, 1.0, 0.0]
parallel: {{balance: rcb, rebalance: 1.1, margin: 0.05}}
solve: {{steps: {steps}, damping: {{mode: local, alpha: 0.8}}}}
output: {{every_steps: {steps // 4}}}
"""


class GridStandIn:
    """The uniform grid's ``owner_of`` without its communicator (tests/unit/test_decomposition)."""

    owner_of = Decomposition.owner_of

    def __init__(self, lo, hi, dims):
        self.dims = np.array(dims, np.int64)
        self.edges = [np.linspace(lo[k], hi[k], dims[k] + 1) for k in range(3)]


def works(comm, state, owner=None) -> np.ndarray:
    """The owned work of every rank (``owner``: the rank each owned block would have)."""
    w = block_work(state.blocks, state.n_owned, state.contacts)
    if owner is None:
        return np.array(comm.allgather(int(w.sum())), float)
    return comm.allreduce(np.bincount(owner, w, comm.size))


@TWO_RANKS_ONLY
def test_rebalanced_run_matches_one_rank_and_beats_the_grid(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    text = stack_and_scatter(600)
    scene = parse_scene(text)
    scene = scene.model_copy(update={"output": scene.output.model_copy(
        update={"file": f"{base}/rcb.h5", "contacts": False})})

    def probe(solver):
        s = solver.state
        return s.decomp.n_balanced, s.decomp.tree.cut.copy()

    solver, (n0, cut0), (n1, cut1), report = run(scene, comm, probe=probe)
    s = solver.state
    assert n0 == 0 and n1 >= 1, "the run did not rebalance"
    assert not np.array_equal(cut0, cut1)
    # the work now, and on the uniform grid of the same ranks over the same blocks
    rcb = works(comm, s)
    lo, hi = np.array(s.resolved.domain_lo), np.array(s.resolved.domain_hi)
    dims = choose_dims(comm.size, hi - lo, s.gravity)
    grid = GridStandIn(lo, hi, dims)
    uniform = works(comm, s, grid.owner_of(s.blocks.x[:s.n_owned]))
    imb_rcb, imb_grid = rcb.max() / rcb.mean(), uniform.max() / uniform.mean()
    if comm.rank == 0:
        print(f"\nstack and scatter on {comm.size} ranks: rebalanced {n1} times, owned "
              f"{report['owned']}, work rcb {rcb.tolist()} (imbalance {imb_rcb:.3f}), on the "
              f"{dims} grid {uniform.tolist()} (imbalance {imb_grid:.3f})")
    assert imb_rcb < imb_grid
    assert imb_rcb < 1.2
    compare_on_rank0(comm, f"{base}/rcb.h5", scene, f"{base}/rcb-ref.h5")


# two zoned cubes (0.25 m zones: a few hundred zones each) at one end of a row of ten cubes on
# a floor, eight rigid at the other: counted as blocks, the start's cuts split the row in the
# middle and give one rank both grids; RCB's weights count the zones (zone_work)
ZONED_ROW = """
name: zoned-row-balance
materials:
  rock: {density: 2000}
  soft: {density: 2000, young: 5.0e7, poisson: 0.25}
joints: {default: {kn: 5.0e8, ks: 2.0e8, friction: 20.0}}
blocks:
  - {name: floor, box: {min: [-0.5, -1, -1], max: [10.5, 1, 0]}, material: rock, fixed: true}
  - {name: z, array: {box: {min: [0, -0.5, 0], max: [1, 0.5, 1]}, count: [2, 1, 1],
     spacing: [1.05, 0, 0]}, material: soft, zones: {size: 0.25}}
  - {name: r, array: {box: {min: [2.1, -0.5, 0], max: [3.1, 0.5, 1]}, count: [8, 1, 1],
     spacing: [1.05, 0, 0]}, material: rock}
solve: {steps: 20, damping: local}
output: {file: OUT, every_steps: 20, contacts: false}
"""


@TWO_RANKS_ONLY
def test_zoned_blocks_weigh_their_zones_in_the_cuts(tmp_path):
    comm = MPI.COMM_WORLD
    base = shared_dir(comm, tmp_path)
    scene = parse_scene(ZONED_ROW.replace("OUT", f"{base}/zb.h5"))
    solver, _, _, report = run(scene, comm)
    s = solver.state
    zones = s.grids.zones_at(s.owned_gids())
    mine = int(np.count_nonzero(zones))
    assert comm.allgather(mine) == [1, 1], "each rank owns one of the two grids"
    w = comm.allgather(int(block_work(s.blocks, s.n_owned, s.contacts, zones).sum()))
    # the zones' work is ~85 % of the model's; counted as blocks one rank would hold all of it
    assert max(w) / (sum(w) / 2) < 1.3, w
    assert int(zones.max()) // ZONES_PER_WORK > 10  # a grid outweighs ten rigid blocks
    # the cuts of the same blocks counted as blocks put both grids on one rank
    x = s.blocks.x[:s.n_owned]
    plain = rcb_tree(comm, x, np.ones(len(x), np.int64), comm.size, s.decomp.lo, s.decomp.hi)
    held = comm.allreduce(np.bincount(plain.owner_of(x[zones > 0]), minlength=comm.size))
    assert held.max() == 2, held
    compare_on_rank0(comm, f"{base}/zb.h5", scene, f"{base}/zb-ref.h5")
