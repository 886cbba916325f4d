"""How the rows of a parallel HDF5 file are shared out: even contiguous shares per rank, or
all on rank 0 where h5py was built without MPI (the gathered fallback)."""

from __future__ import annotations

import h5py


def h5py_has_mpi() -> bool:
    """h5py was built against parallel HDF5 (the ``mpio`` driver)."""
    return bool(h5py.get_config().mpi)


def even_share(rank: int, size: int, n: int) -> tuple[int, int]:
    """Contiguous share ``[lo, hi)`` of ``n`` rows for ``rank``."""
    return rank * n // size, (rank + 1) * n // size


def writer_range(comm, n: int) -> tuple[int, int]:
    """The gids ``[lo, hi)`` whose surfaces this rank's OutputWriter assembles and writes (an
    even share; in the fallback without parallel h5py, rank 0 all of them)."""
    if h5py_has_mpi():
        return even_share(comm.rank, comm.size, n)
    return (0, n) if comm.rank == 0 else (n, n)
