"""Give freed heap memory back to the system (glibc), after set-up and rebuilds.

Building a model makes many small numpy arrays and Python objects (the scene's pieces, the
candidate pairs of the first search) that are freed once each rank holds its share. glibc keeps
such memory in its heap: the process would stay at its set-up peak, about 40% above what the
model needs (bench/setup.py). ``malloc_trim`` returns it. Elsewhere (macOS, musl) a no-op.

glibc also serves large blocks from that heap once a large one has been freed (its mmap
threshold grows with what is freed, up to 32 MB): the model's arrays (a few MB each) then land
between small objects, a freed one leaves a hole that trimming cannot give back, and set-up's
temporaries stack on the kept arrays. :func:`map_large_blocks` fixes the threshold, so that an
array of 128 KB or more (a per-block column of 5,000 rows) is its own mapping, returned to the
system when freed (64,000 cubes on 2 ranks: ~20 MB less kept and ~65 MB less peak per rank,
bench/setup.py). Once the model is set up, :func:`reuse_large_blocks` gives large blocks back to
the heap: the step allocates and frees the same arrays over and over, and fresh mappings would
be faulted in at every contact update.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools

# mallopt parameters (glibc malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
# blocks of this size or more are mapped on their own (arrays), smaller ones from the heap
LARGE_BLOCK = 128 * 1024
# while stepping, blocks up to this size come from the heap (glibc's largest dynamic threshold)
STEP_BLOCK = 32 * 1024 * 1024


@functools.cache
def _libc():
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name) if name else None
    except OSError:
        return None


@functools.cache
def _trim():
    libc = _libc()
    return libc.malloc_trim if libc is not None and hasattr(libc, "malloc_trim") else None


def _mallopt(mmap_threshold: int, trim_threshold: int) -> bool:
    libc = _libc()
    if libc is None or not hasattr(libc, "mallopt"):
        return False
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, mmap_threshold)) and \
        bool(libc.mallopt(_M_TRIM_THRESHOLD, trim_threshold))


_mapped = [False]  # whether map_large_blocks is in force (set-up)


def map_large_blocks() -> bool:
    """Allocations of :data:`LARGE_BLOCK` bytes or more get their own mapping from now on (and
    the heap is trimmed above 4 of them): freed, they go back to the system at once. For the
    model's set-up; False where glibc's ``mallopt`` is missing."""
    _mapped[0] = _mallopt(LARGE_BLOCK, 4 * LARGE_BLOCK)
    return _mapped[0]


def large_blocks_mapped() -> bool:
    """True while every large array is its own mapping (:func:`map_large_blocks`): pages of
    an array never written are never resident, so an over-allocated array costs no memory."""
    return _mapped[0]


def reuse_large_blocks() -> bool:
    """Once the model is set up: blocks up to :data:`STEP_BLOCK` come from the heap again and
    up to twice that of freed heap is kept. A contact update builds its sub-contact arrays
    afresh (a few MB each): mapped, each was faulted in page by page at every update, which
    made the 20³ cube stack step 1.27x slower (bench/cube_stack.py); from the heap they reuse
    the pages the last update freed."""
    _mapped[0] = False
    return _mallopt(STEP_BLOCK, 2 * STEP_BLOCK)


@contextlib.contextmanager
def mapping_large_blocks():
    """:func:`map_large_blocks` for a burst of large temporaries between steps (an output
    snapshot), then back to the step's heap (:func:`reuse_large_blocks`) unless set-up's mapping
    was in force. From the heap, a snapshot's arrays left it grown where the step's arrays
    could not reuse it, and each array of the snapshot came on top of the last one's hole
    (64,000 cubes on 2 ranks: ~25 MB a rank, bench/output_memory.py); mapped, each goes back
    to the system when freed."""
    was = _mapped[0]
    map_large_blocks()
    try:
        yield
    finally:
        if not was:
            reuse_large_blocks()


def return_freed_memory() -> None:
    trim = _trim()
    if trim is not None:
        trim(0)


def _proc_mb(path: str, key: str) -> float:
    """Field ``key`` (kB) of a /proc file of this process, in MB; 0 where /proc is missing."""
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def proportional_mb() -> float:
    """This process's proportional set size now (MB; Linux ``smaps_rollup``, 0 elsewhere): its
    resident pages, each page it shares with other processes counted as its share. Ranks on one
    node share the libraries' pages (numba's LLVM alone is ~66 MB resident in every rank, once
    in the node's memory), so the node holds the sum of its ranks' PSS, not of their RSS."""
    return _proc_mb("/proc/self/smaps_rollup", "Pss:")


def resident_mb() -> float:
    """This process's resident memory now (MB), 0 where /proc is missing."""
    return _proc_mb("/proc/self/status", "VmRSS:")
