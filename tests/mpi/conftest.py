"""Which MPI tests run at which rank count. run/test runs tests/mpi on 2, 3 and 4 ranks; every
test that can runs on 2 (each file's 1-rank comparison included). On 3 and 4 ranks, which on
the 2-core CI machine oversubscribe its cores (a step costs scheduler time slices: the
tiers took 731 s and 303 s of a 2,115 s suite), only the modules whose subject is the rank
count itself run: the decomposition (odd and 2 x 2 splits, a rank owning nothing, a block
ghosted on several ranks), output rows shared out unevenly, routing, compiled ranks, and on 4
also the restarts on another rank count. A module not listed here is a 2-rank comparison
whose code paths do not depend on how many ranks there are beyond two; PDEM_MPI_TESTS=all
runs every module on any rank count (as the comparisons were verified on 3 and 4 ranks when
written: ``PDEM_MPI_TESTS=all .venv/bin/mpiexec -n 3 run/mpi-pytest --with-mpi tests/mpi``).
"""

from __future__ import annotations

import os

import pytest
from mpi4py import MPI

AT_MORE_RANKS = {
    3: {"test_decomposition.py", "test_output_mpi.py", "test_zone_output_mpi.py",
        "test_route_contacts.py", "test_compiled_ranks.py", "test_gathered_columns.py",
        "test_on_root.py"},
    4: {"test_decomposition.py", "test_output_mpi.py", "test_zone_output_mpi.py",
        "test_route_contacts.py", "test_compiled_ranks.py", "test_gathered_columns.py",
        "test_on_root.py", "test_restart.py"},
}


def pytest_collection_modifyitems(config, items):
    size = MPI.COMM_WORLD.size
    if size <= 2 or os.environ.get("PDEM_MPI_TESTS") == "all":
        return
    keep = AT_MORE_RANKS.get(size)
    skip = pytest.mark.skip(reason=f"a 2-rank comparison (on {size} ranks: tests/mpi/conftest.py)")
    for item in items:
        if keep is not None and item.path.name not in keep:
            item.add_marker(skip)
