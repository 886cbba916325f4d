"""Compiled runs of steps on several ranks (pdem.cycle with pdem.parallel.native): the MPI
calls made from numba give mpi4py's answers, and a run whose ranks step in the compiled loop
gives the same bits as ranks stepping in Python and as one rank, through migrations, searches
and contact updates that send one rank to Python for a step while the others stay compiled.

The compiled loop is used where ranks spin while they wait (as many ranks as cores: the 2-rank
tier here); on the oversubscribed 3- and 4-rank tiers the ranks sleep in Python, and these
tests check that the calls still work and the fallback is taken.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from support import collective, on_rank0
from test_decomposition import pile_scene

from pdem import mpi
from pdem.compiled_runs import CompiledRuns
from pdem.config import parse_scene
from pdem.cycle import DROPS, NEEDS_PYTHON
from pdem.errors import UserError
from pdem.parallel import native
from pdem.parallel.halo import Halo, halo_columns
from pdem.simulation import Simulation

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(300, method="thread")]


def test_compiled_halo_and_reduction_match_mpi4py():
    """Every rank ghosts rows of every other (several neighbours, uneven counts): the compiled
    forward halo fills the ghost rows as :meth:`Halo.forward` does, and the compiled maximum is
    mpi4py's."""
    comm = MPI.COMM_WORLD
    r, p = comm.rank, comm.size
    rng = np.random.default_rng(r)
    owned = 3 + r  # rows 0..owned-1 owned; then the ghosts of every other rank, in rank order
    send = {q: np.arange(owned)[: 1 + (q + r) % owned] for q in range(p) if q != r}
    counts = comm.allgather({q: len(v) for q, v in send.items()})
    recv, row = {}, owned
    for q in range(p):
        if q != r:
            recv[q] = np.arange(row, row + counts[q][r])
            row += counts[q][r]

    class Rows:  # two halo fields of widths 3 and 4
        pass

    def fields():
        b = Rows()
        b.x = np.full((row, 3), np.nan)
        b.q = np.full((row, 4), np.nan)
        b.x[:owned] = rng.standard_normal((owned, 3)) + 10 * r
        b.q[:owned] = rng.standard_normal((owned, 4)) - 10 * r
        return b

    from pdem.model.fields import HALO

    spec = tuple(f for f in HALO if f.name in ("x", "q"))
    assert [f.width for f in spec] == [3, 4]
    halo = Halo(comm, send, recv, fields=spec)
    want, got = fields(), fields()
    got.x[:owned], got.q[:owned] = want.x[:owned], want.q[:owned]
    halo.forward(want)
    net = native.make_net(comm, halo, 5)
    assert net is not None, "the MPI functions were not found"
    assert native.forward_halo(net, halo_columns(got, spec)) == 0
    assert np.array_equal(got.x, want.x) and np.array_equal(got.q, want.q)
    assert not np.isnan(got.x).any()
    flags = rng.standard_normal(5)
    net.flags[:] = flags
    assert native.allreduce_max(net) == 0
    assert np.array_equal(net.reduced, mpi.allreduce_max_array(comm, flags.copy()))


def test_link_switch_and_fallback(monkeypatch):
    """``PDEM_MPI_NATIVE=0``, MPI functions not found on one rank and a self-check that fails
    on one rank leave every rank on the Python path (none waits for a message that will not
    come); a bad value is a one-line error naming the variable."""
    comm = MPI.COMM_WORLD
    monkeypatch.setenv("PDEM_MPI_NATIVE", "0")
    c1 = comm.Dup()
    assert native.link(c1) is False
    monkeypatch.setenv("PDEM_MPI_NATIVE", "maybe")
    with pytest.raises(UserError, match="PDEM_MPI_NATIVE"):
        native.enabled()
    monkeypatch.setenv("PDEM_MPI_NATIVE", "1")
    c2 = comm.Dup()
    if comm.rank == 1:
        monkeypatch.setattr(native, "_addresses", lambda: None)
    assert native.link(c2) is False  # agreed on every rank
    monkeypatch.undo()
    c3 = comm.Dup()
    if comm.rank == 0:
        check = native._self_check
        monkeypatch.setattr(native, "_self_check", lambda c, net: check(c, net) and False)
    assert native.link(c3) is False
    monkeypatch.undo()
    c4 = comm.Dup()
    assert native.link(c4) is True
    for c in (c1, c2, c3, c4):
        c.Free()


def _pile(fused: bool, steps: int):
    text = pile_scene(steps=steps, dims="[2, 1, 1]" if MPI.COMM_WORLD.size == 2 else "auto")
    text = text.replace("solve: {", f"solve: {{fused: {str(fused).lower()}, ", 1)
    return parse_scene(text)


def _final_state(sim):
    """Every block's pose and velocities by gid, gathered on every rank."""
    b, n = sim.blocks, sim.n_owned
    rows = np.hstack([b.gid[:n, None].astype(float), b.x[:n], b.q[:n], b.v[:n], b.w[:n]])
    rows = np.vstack(sim.state.comm.allgather(rows))
    return rows[np.argsort(rows[:, 0], kind="stable")]


def _run(scene, comm):
    with collective(comm, f"a pile on {comm.size} ranks"):
        sim = Simulation(scene, comm, output=False)
        sim.run()
        state = _final_state(sim)
        compiled = "fused" in sim.state.timers.report()
        sim.close()
    return state, compiled


def test_compiled_ranks_match_python_ranks_and_one_rank(monkeypatch):
    """The pile of tests/mpi/test_decomposition.py (blocks migrate, ghosts are rebuilt, every
    rank searches and updates contacts at its own steps): the same final state, bit for bit,
    with the ranks' steps compiled, in Python, and on one rank. On the 2-rank tier the ranks
    step compiled and, at some step, one of them made the step's reduction in Python while the
    other made it in the loop."""
    if MPI.COMM_WORLD.size > 3:  # ~10-35 s each on the oversubscribed 4-rank tier
        pytest.skip("the compiled steps on the 2- and 3-rank tiers (the pile runs on 4 "
                    "ranks in test_decomposition)")
    comm = MPI.COMM_WORLD
    steps = 600
    ends = []  # (step, why) of each compiled run of steps on this rank
    fused = CompiledRuns.run

    def recording(self, *args):
        out = fused(self, *args)
        ends.append((self.stepper.s.step, out[1]))
        return out

    monkeypatch.setattr(CompiledRuns, "run", recording)
    compiled_state, compiled = _run(_pile(True, steps), comm)
    mine = list(ends)
    spinning = not mpi.reduces_nonblocking(comm)
    assert compiled == spinning, (compiled, spinning)
    if spinning:  # (else that run was the Python path already)
        python_state, python_used_fused = _run(_pile(False, steps), comm)
        assert not python_used_fused
        assert np.array_equal(compiled_state, python_state), \
            "compiled and Python rank steps differ"
    serial = _pile(True, steps)
    serial = serial.model_copy(update={"parallel": type(serial.parallel)()})
    one = on_rank0(comm, lambda: _run(serial, MPI.COMM_SELF)[0])
    assert np.array_equal(compiled_state, one), "the ranks differ from one rank"
    if not spinning:
        return
    # a step this rank ended in Python alone (a search or a contact update that dropped
    # contacts) while another rank's loop went on past it
    all_ends = comm.allgather(mine)
    alone = [(r, step) for r, mine in enumerate(all_ends) for step, why in mine
             if why in (NEEDS_PYTHON, DROPS)
             and any(step not in {s for s, _ in other}
                     for q, other in enumerate(all_ends) if q != r)]
    assert alone, "no rank ever left the loop alone: the mixed path was not exercised"
