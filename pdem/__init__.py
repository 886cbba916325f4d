"""pdem: parallel distinct element method for 3D polyhedral blocks."""

import hashlib as _hashlib
import os as _os
from pathlib import Path as _Path

__version__ = "0.1.0"


def _numba_cache_dir() -> None:
    """Point numba's cache at a directory keyed by a hash of pdem's sources.

    numba's ``cache=True`` checks only the source file of the function it loads, not the files
    of the kernels that function calls: after an edit (or a ``git pull``) a stale cached kernel
    could run old code. Keying the cache on all of pdem's sources makes every change compile
    afresh, and keeps the cache out of the (possibly read-only) package directory. Set
    ``NUMBA_CACHE_DIR`` yourself to override.
    """
    if "NUMBA_CACHE_DIR" in _os.environ:
        return
    root = _Path(__file__).resolve().parent
    h = _hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    base = _Path(_os.environ.get("XDG_CACHE_HOME", _Path.home() / ".cache"))
    _os.environ["NUMBA_CACHE_DIR"] = str(base / "pdem-numba" / h.hexdigest()[:16])


_numba_cache_dir()
