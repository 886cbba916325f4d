"""Output locations checked before the first step: a run that cannot write is refused at once,
not after hours of stepping."""

from __future__ import annotations

import os
import tempfile

from ..errors import UserError
from ..mpi import broadcast


def _problem(path: str) -> str | None:
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        return f"directory {d} does not exist"
    try:
        # creating a file is the only reliable test: os.access says yes to root and knows
        # nothing of read-only mounts
        with tempfile.NamedTemporaryFile(dir=d, prefix=".pdem-probe-"):
            pass
    except OSError as exc:
        return f"directory {d} is not writable ({exc.strerror or exc})"
    return None


def check_writable(comm, paths: dict[str, str]) -> None:
    """Raise the same UserError on every rank if a file of ``paths`` ({what: path}) cannot be
    created (collective: rank 0 looks, every rank gets its answer, so no rank waits alone)."""
    problem = None
    if comm.rank == 0:
        for what, path in paths.items():
            why = _problem(path)
            if why:
                problem = f"cannot write {what} {path}: {why}"
                break
    problem = broadcast(comm, problem)
    if problem:
        raise UserError(problem)
