"""Give freed heap memory back to the system (glibc), after set-up and rebuilds.

Building a model makes many small numpy arrays and Python objects (the scene's pieces, the
candidate pairs of the first search) that are freed once each rank holds its share. glibc keeps
such memory in its heap: the process would stay at its set-up peak, about 40% above what the
model needs (bench/setup.py). ``malloc_trim`` returns it. Elsewhere (macOS, musl) a no-op.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _trim():
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        return libc.malloc_trim if libc is not None and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def return_freed_memory() -> None:
    trim = _trim()
    if trim is not None:
        trim(0)


def resident_mb() -> float:
    """This process's resident memory now (MB), 0 where /proc is missing."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0
