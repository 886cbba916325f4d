"""Dynamic analysis on several ranks (issue 41): a staged static-to-dynamic run of zoned
bars (a held base settled, then made quiet with its reactions kept, a wave put in through
it, the top quiet, Rayleigh damping, a recording station's acceleration) is bitwise the
1-rank run on 2 and 3 ranks, and a restart from a checkpoint in the shaking stage ends
bitwise where the straight run ends (pdem.cases.waves.shaken_bars_text)."""

import os

import numpy as np
import pytest
from mpi4py import MPI
from support import compare_on_rank0, on_rank0, run, shared_dir, with_parallel
from test_deformable_mpi import energy_history, grids, restarted, same_grids

from pdem.cases.waves import shaken_bars_text

pytestmark = [pytest.mark.mpi(min_size=2), pytest.mark.timeout(900, method="thread")]


def test_a_shaken_zoned_model_is_bitwise_on_any_rank_count_and_restart(tmp_path):
    comm = MPI.COMM_WORLD
    if comm.size > 3:
        pytest.skip("the 2- and 3-rank tiers'")
    d = shared_dir(comm, tmp_path)
    os.makedirs(d, exist_ok=True)
    at = 120  # in the shaking stage
    ck = f"checkpoint: {{every_steps: {at}, keep: 3, file: {d}/ck}}"
    path = f"{d}/sh.h5"
    scene = with_parallel(shaken_bars_text(path, ck), "auto", path, every_steps=60)
    straight = run(scene, comm, probe=grids)[2]
    compare_on_rank0(comm, path, scene, f"{d}/sh-ref.h5")
    got = restarted(comm, shaken_bars_text(f"{d}/r.h5"), f"{d}/ck-{at:09d}.h5", at)
    assert not same_grids(got, straight), same_grids(got, straight)
    a, b = on_rank0(comm, lambda: (energy_history(f"{d}/sh.h5"), energy_history(f"{d}/r.h5")))
    bad = [k for k in a if a[k][-1] != b[k][-1]]
    assert not bad, [(k, a[k][-1], b[k][-1]) for k in bad]
    # the dashpots and the Rayleigh damping took energy out, and the budget balances
    assert a["quiet_absorbed"][-1] > 0.0 and a["damping_dissipation"][-1] > 0.0
    put_in = a["kinetic"][0] + a["strain"][0] + a["gravity_work"] + a["applied_work"] \
        + a["boundary_work"]
    assert np.abs(a["balance_error"]).max() < 1e-2 * np.abs(put_in).max()
