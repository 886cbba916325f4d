"""The one MPI module: start-up, abort-on-error, rank-aware logging, small reductions.

Library code receives ``comm`` explicitly; only the entry points name ``MPI.COMM_WORLD``: the
command line (``pdem.cli``) and the Python API's default (``pdem.api.run``, ``pdem.study``).
"""

from __future__ import annotations

import logging
import math
import os
import pickle
import sys
import time
import traceback

import numpy as np

from .errors import UserError
from .jit import kernel


class RankFilter(logging.Filter):
    def __init__(self, rank: int, size: int):
        super().__init__()
        self.tag = f"{rank}/{size}"

    def filter(self, record):
        record.rank = self.tag
        return True


def setup_logging(comm, level=logging.INFO) -> logging.Logger:
    """Log lines carry ``rank/size``; ranks other than 0 only show warnings and errors."""
    log = logging.getLogger("pdem")
    log.handlers.clear()
    handler = logging.StreamHandler(sys.stdout if comm.rank == 0 else sys.stderr)
    handler.addFilter(RankFilter(comm.rank, comm.size))
    handler.setFormatter(logging.Formatter("[pdem %(rank)s] %(message)s"))
    log.addHandler(handler)
    log.setLevel(level if comm.rank == 0 else logging.WARNING)
    log.propagate = False
    return log


def install_abort_hook(comm) -> None:
    """An uncaught exception on any rank prints its message and aborts every rank.

    Without this, one rank's error leaves the others waiting forever in a collective.
    """
    if comm.size == 1:
        return
    previous = sys.excepthook

    def hook(kind, value, tb):
        try:
            abort_with_message(comm, value)
        finally:
            previous(kind, value, tb)

    sys.excepthook = hook


def abort_with_message(comm, exc: BaseException) -> None:
    """Print this rank's error in one write, let the launcher forward it, abort every rank."""
    if isinstance(exc, UserError):
        text = f"pdem: error on rank {comm.rank}: {exc}\n"
    else:
        text = f"pdem: internal error on rank {comm.rank}:\n" + "".join(
            traceback.format_exception(type(exc), exc, exc.__traceback__))
    sys.stdout.flush()
    os.write(2, text.encode())  # one unbuffered write: the message cannot be cut in half
    time.sleep(0.5)  # the launcher forwards stderr asynchronously; Abort kills it quickly
    comm.Abort(1)


# How a rank waits for the per-step messages (the halo, the step's reduction). MPICH spins in
# a blocking wait, which is the fastest wait while every rank has a core of its own; with more
# ranks than cores on a node (a laptop, a 2-core CI machine running 3 or 4 ranks) the spinning
# rank takes the core from the rank it waits for, and every step costs scheduler time slices
# (the pile of tests/mpi/test_decomposition.py: 4 s on 2 ranks, 47 s on 3). Such ranks test
# their requests and sleep between tests instead. PDEM_MPI_WAIT=spin|sleep|auto (default auto:
# sleep only where the node is oversubscribed).
WAIT_MODES = ("auto", "spin", "sleep")
SLEEP_POLL = 2e-5  # s between tests of a sleeping wait (a sleep takes ~85 us on our machines)
_sleeping: set[int] = set()  # handles of the communicators whose ranks sleep while waiting
# handles of the communicators on which some rank sleeps: there every rank reduces with the
# non-blocking collective (a blocking one must not meet it). Elsewhere the blocking one: an
# Iallreduce waited for in MPICH took the 2-rank cube stack (bench/scaling.py) from 1.4-1.5e6
# to 1.0e6 block-steps/s.
_nonblocking: set[int] = set()


def reduces_nonblocking(comm) -> bool:
    """Whether some rank of ``comm`` sleeps while it waits, so every rank reduces with the
    non-blocking collective (decided by :func:`configure_waits`)."""
    return comm.py2f() in _nonblocking


def configure_waits(comm) -> bool:
    """Decide (collectively) how this rank waits on ``comm`` (see :data:`WAIT_MODES`); True
    if it sleeps. Oversubscribed: the ranks sharing this node are more than the distinct CPUs
    they may run on (the union of their affinity masks, so ranks bound one per core are
    not). Decided per node: on a cluster only an oversubscribed node's ranks sleep."""
    mode = os.environ.get("PDEM_MPI_WAIT", "auto").strip().lower() or "auto"
    if mode not in WAIT_MODES:
        raise UserError(f"PDEM_MPI_WAIT: must be one of {', '.join(WAIT_MODES)} (got {mode!r})")
    if comm.size == 1:
        return False
    from mpi4py import MPI

    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        cpus = set().union(*node.allgather(sorted(os.sched_getaffinity(0))))
        oversubscribed = node.size > len(cpus)
    finally:
        node.Free()
    sleep = mode == "sleep" or (mode == "auto" and oversubscribed)
    key = comm.py2f()
    for handles, on in ((_sleeping, sleep), (_nonblocking, comm.allreduce(sleep, op=MPI.LOR))):
        if on:
            handles.add(key)
        else:
            handles.discard(key)
    return sleep


def wait_all(comm, requests: list) -> None:
    """Complete ``requests`` (of ``comm``): spinning in MPI, or testing and sleeping where
    :func:`configure_waits` said so."""
    from mpi4py import MPI

    if comm.py2f() not in _sleeping:
        MPI.Request.Waitall(requests)
        return
    while not MPI.Request.Testall(requests):
        time.sleep(SLEEP_POLL)


def allreduce_max_array(comm, values: np.ndarray) -> np.ndarray:
    """Element-wise maximum over ranks (order-independent, so deterministic)."""
    if comm.size == 1:
        return values
    from mpi4py import MPI

    if comm.py2f() in _nonblocking:  # some rank sleeps while it waits
        wait_all(comm, [comm.Iallreduce(MPI.IN_PLACE, values, op=MPI.MAX)])
    else:
        comm.Allreduce(MPI.IN_PLACE, values, op=MPI.MAX)
    return values


def min_over_ranks(comm, value: int) -> int:
    """The smallest of every rank's ``value`` (an int)."""
    if comm.size == 1:
        return value
    from mpi4py import MPI

    return int(comm.allreduce(int(value), op=MPI.MIN))


def allreduce_sum_array(comm, values: np.ndarray) -> np.ndarray:
    """Element-wise sum over ranks (floating-point: reproducible for a fixed rank count)."""
    if comm.size == 1:
        return values
    from mpi4py import MPI

    comm.Allreduce(MPI.IN_PLACE, values, op=MPI.SUM)
    return values


# partials of finite doubles never outnumber the exponent range (2098 binades / 2, rounded up)
MAX_PARTIALS = 1100


@kernel
def _column_partials(values, out, counts):
    """Shewchuk's non-overlapping partials of each column of ``values`` (n, k) into
    ``out[c]`` (k, MAX_PARTIALS), their count into ``counts[c]``; -1 for a column with a
    non-finite value (exactness is moot there). The exact sum of column c is the exact sum of
    ``out[c, :counts[c]]``."""
    for c in range(values.shape[1]):
        n = 0
        for k in range(values.shape[0]):
            v = values[k, c]
            if not math.isfinite(v):
                n = -1
                break
            i = 0
            for m in range(n):
                y = out[c, m]
                if abs(v) < abs(y):
                    v, y = y, v
                hi = v + y
                lo = y - (hi - v)
                if lo != 0.0:
                    out[c, i] = lo
                    i += 1
                v = hi
            out[c, i] = v
            n = i + 1
        counts[c] = n


def exact_sum(comm, values: np.ndarray) -> np.ndarray:
    """Column sums of ``values`` (n, k) over all ranks' rows, correctly rounded: the same bits
    for any distribution of the rows over any number of ranks. One rank takes the same path
    without the gather. Every column's partials come from one compiled call (an energy sample
    of a small serial scene spent ~45 us in eleven calls of one column each)."""
    values = np.asarray(values, np.float64)
    if values.ndim == 1:
        values = values[:, None]
    out = np.empty((values.shape[1], MAX_PARTIALS))
    counts = np.empty(values.shape[1], np.int64)
    _column_partials(values, out, counts)
    parts = [out[c, :m].copy() if m >= 0 else np.array([np.sum(values[:, c])])
             for c, m in enumerate(counts.tolist())]
    gathered = allgather(comm, parts) if comm.size > 1 else [parts]
    sums = np.empty(values.shape[1])
    for c in range(values.shape[1]):
        terms = np.concatenate([g[c] for g in gathered]) if len(gathered) > 1 else gathered[0][c]
        try:
            sums[c] = math.fsum(terms)
        except (ValueError, OverflowError):  # inf - inf, or an overflowing partial
            sums[c] = float(np.sum(terms))
    return sums


class _Local:
    """A communicator of this process alone, for reductions over rows that are all here:
    the reductions below return at once for it (no MPI call)."""

    size = 1
    rank = 0

    def allgather(self, value) -> list:
        return [value]


# reduce rows every rank holds whole (pdem check, a scene built whole on every rank)
LOCAL = _Local()


def exact_mean(comm, values: np.ndarray) -> float:
    """The mean of ``values`` over all ranks' rows, correctly rounded sum over the count:
    the same bits for any distribution of the rows (NaN for none)."""
    count = sum(allgather(comm, len(values)))
    return float(exact_sum(comm, values)[0]) / count if count else math.nan


def kth_smallest(comm, values: np.ndarray, k: int) -> float:
    """The ``k``-th smallest (from 0) of all ranks' ``values`` (finite, non-negative), exactly
    and without gathering them: a bisection over the doubles' bit patterns (in the order of
    the values for non-negative ones), one integer reduction a step (at most 64)."""
    values = np.asarray(values, np.float64) + 0.0  # -0.0 -> +0.0: its bits sort first
    if comm.size == 1:
        return float(np.partition(values, k)[k])
    from mpi4py import MPI

    keys = values.view(np.int64)
    lo = comm.allreduce(int(keys.min(initial=np.iinfo(np.int64).max)), op=MPI.MIN)
    hi = comm.allreduce(int(keys.max(initial=0)), op=MPI.MAX)
    while lo < hi:  # the smallest key with more than k keys at or below it
        mid = lo + (hi - lo) // 2
        if comm.allreduce(int((keys <= mid).sum()), op=MPI.SUM) > k:
            hi = mid
        else:
            lo = mid + 1
    return float(np.array([lo], np.int64).view(np.float64)[0])


def first_extreme(comm, found):
    """The first of the ranks' ``(value, gid, ...)`` tuples with the smallest value (None:
    the rank has none): smallest value, then smallest gid, as an argmin over every block in
    gid order gives; None if no rank has one."""
    cands = [f for f in allgather(comm, found) if f is not None]
    return min(cands, key=lambda f: (f[0], f[1])) if cands else None


def allgather(comm, value) -> list:
    """Every rank's ``value``, in rank order."""
    return comm.allgather(value) if comm.size > 1 else [value]


def weighted_share(rank: int, size: int, weights) -> tuple[int, int]:
    """Rank ``rank``'s contiguous items ``[lo, hi)`` of items with these (non-negative)
    weights, so that each of ``size`` ranks gets about an even share of the total weight."""
    w = np.asarray(weights, np.float64)
    if len(w) == 0:
        return 0, 0
    edges = np.concatenate([[0.0], np.cumsum(w)])
    total = edges[-1]
    if total <= 0.0:  # all weightless: an even split by count
        return len(w) * rank // size, len(w) * (rank + 1) // size
    # item i goes to the rank whose share holds the middle of its weight
    middle = 0.5 * (edges[:-1] + edges[1:]) / total
    owner = np.minimum((middle * size).astype(np.int64), size - 1)
    return int(np.searchsorted(owner, rank)), int(np.searchsorted(owner, rank, side="right"))


def _as_sent(exc: BaseException) -> tuple:
    """An exception as another rank can raise it: pickled, and its text (if it does not
    pickle, or not unpickle there)."""
    try:
        return ("raised", pickle.dumps(exc), str(exc))
    except Exception:  # noqa: BLE001 - an unpicklable exception: its text
        return ("raised", None, f"{type(exc).__name__}: {exc}")


def _raise_first(comm, parts, failure) -> None:
    """Raise the failure of the lowest rank among ``parts`` (one per rank, a failure as
    :func:`_as_sent` made it): this rank's own ``failure`` as itself, another's unpickled (a
    :class:`RuntimeError` naming the rank if it does not unpickle)."""
    for r, part in enumerate(parts):
        if isinstance(part, tuple) and part and part[0] == "raised":
            if r == comm.rank:
                raise failure
            try:
                exc = pickle.loads(part[1]) if part[1] is not None else None
            except Exception:  # noqa: BLE001
                exc = None
            raise exc if isinstance(exc, BaseException) else RuntimeError(
                f"rank {r}: {part[2]}")


def run_together(comm, work):
    """``work()`` on every rank, returning its result; if it raised on any rank, the
    exception of the lowest rank that failed is raised on every rank (collective: each
    rank's own part of a distributed computation, so that none is left waiting in the next
    collective)."""
    failure = result = None
    try:
        result = work()
    except Exception as exc:  # noqa: BLE001 - every rank must hear of it
        failure = exc
    _raise_first(comm, allgather(comm, None if failure is None else _as_sent(failure)),
                 failure)
    return result


def on_root(comm, work, root: int = 0):
    """``work()`` on ``root`` alone, its result sent to every rank; if it raised there, the
    same exception is raised on every rank (collective). For a file every rank needs whole:
    one rank reads it, not every rank of a cluster job at once from the shared file system
    (a scene's mesh, pdem.model.mesh_blocks)."""
    failure = sent = None
    if comm.rank == root:
        try:
            sent = ("done", work())
        except Exception as exc:  # noqa: BLE001 - every rank must hear of it
            failure, sent = exc, _as_sent(exc)
    if comm.size > 1:
        sent = _broadcast_large(comm, sent, root)
    if sent[0] == "done":
        return sent[1]
    if failure is not None:  # root's own exception, as itself
        raise failure
    try:
        exc = pickle.loads(sent[1]) if sent[1] is not None else None
    except Exception:  # noqa: BLE001
        exc = None
    raise exc if isinstance(exc, BaseException) else RuntimeError(f"rank {root}: {sent[2]}")


# bytes a broadcast of a large pickle sends at a time: below MPI's 2**31 count, whatever the
# MPI version (a mesh of tens of millions of cells pickles to gigabytes)
BCAST_CHUNK = 1 << 30


def _broadcast_large(comm, value, root: int):
    """``value`` of ``root`` on every rank, pickled once and sent in chunks of raw bytes;
    a value that does not pickle becomes the error it raised (:func:`_as_sent`)."""
    blob = None
    if comm.rank == root:
        try:
            blob = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # noqa: BLE001 - every rank must hear of it
            value = _as_sent(exc)
            blob = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    n = comm.bcast(len(blob) if blob is not None else None, root=root)
    buf = np.frombuffer(blob, np.uint8) if blob is not None else np.empty(n, np.uint8)
    for at in range(0, n, BCAST_CHUNK):
        comm.Bcast(buf[at:at + BCAST_CHUNK], root=root)
    return value if comm.rank == root else pickle.loads(buf)


def allgather_rows(comm, values: np.ndarray) -> np.ndarray:
    """Every rank's rows of ``values`` concatenated in rank order (the same dtype and row
    shape on every rank; a rank may have none): one Allgatherv of the raw bytes, not a pickle
    of each part (the scene's per-block columns at set-up: hundreds of MB at 10^6 blocks)."""
    values = np.ascontiguousarray(values)
    if comm.size == 1:
        return values.copy()
    from mpi4py import MPI

    row_bytes = values.dtype.itemsize * int(np.prod(values.shape[1:], dtype=np.int64))
    counts = np.array(comm.allgather(len(values)), np.int64)
    out = np.empty((int(counts.sum()), *values.shape[1:]), values.dtype)
    sizes = counts * row_bytes
    displs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    comm.Allgatherv(values.view(np.uint8).reshape(-1),
                    [out.view(np.uint8).reshape(-1), sizes, displs, MPI.BYTE])
    return out


def alltoall_rows(comm, values: np.ndarray, counts, out: np.ndarray | None = None
                  ) -> np.ndarray:
    """Rows of ``values``, grouped by destination (``counts[r]`` rows, in order, to rank r),
    sent to their ranks; returns the rows received, in rank order (into ``out`` if given: it
    must hold exactly the rows received). One Alltoallv of the raw bytes, not a pickle of
    each part: a restart's contacts (hundreds of MB at 10^6 blocks)."""
    values = np.ascontiguousarray(values)
    if comm.size == 1:
        if out is None:
            return values
        out[...] = values
        return out
    from mpi4py import MPI

    counts = np.asarray(counts, np.int64)
    got = np.empty(comm.size, np.int64)
    comm.Alltoall(counts, got)
    shape = (int(got.sum()), *values.shape[1:])
    if out is None:
        out = np.empty(shape, values.dtype)
    elif out.shape != shape or out.dtype != values.dtype or not out.flags.c_contiguous:
        raise ValueError(f"alltoall_rows: out is {out.dtype}{out.shape}, the rows received "
                         f"{values.dtype}{shape}")
    row_bytes = values.dtype.itemsize * int(np.prod(values.shape[1:], dtype=np.int64))
    if row_bytes == 0:  # the same column on every rank: all skip alike
        return out
    send, recv = counts * row_bytes, got * row_bytes
    comm.Alltoallv([values.view(np.uint8).reshape(-1), send,
                    np.concatenate([[0], np.cumsum(send)[:-1]]), MPI.BYTE],
                   [out.view(np.uint8).reshape(-1), recv,
                    np.concatenate([[0], np.cumsum(recv)[:-1]]), MPI.BYTE])
    return out


def alltoall(comm, values: list) -> list:
    """``values[r]`` goes to rank r; returns what each rank sent here (pickled: rare path)."""
    return comm.alltoall(values) if comm.size > 1 else values


def gather(comm, value, root: int = 0):
    """Every rank's ``value`` on ``root`` (a list), None elsewhere (pickled: rare path)."""
    return comm.gather(value, root=root) if comm.size > 1 else [value]


def broadcast(comm, value, root: int = 0):
    return comm.bcast(value, root=root) if comm.size > 1 else value


def barrier(comm) -> None:
    if comm.size > 1:
        comm.Barrier()


# --------------------------------------------------------------------------- sparse exchanges
# The rebuild's messages go to the ranks that need them only (neighbours), not to every rank:
# with P ranks an alltoall of per-rank lists costs every rank O(P) messages, pickles and
# arrays at each migration, whatever the model (docs/parallel.md, Scaling: what grows with P).
SPARSE_TAGS = (23, 24)  # sparse_exchange alternates them (see there)
NEIGHBOUR_TAG = 25
_round_key = None  # MPI attribute key: a communicator's count of sparse exchanges


def _sparse_tag(comm) -> int:
    """The tag of this sparse exchange on ``comm``: alternating between two, counted on the
    communicator itself (an MPI attribute, freed with it), so every rank agrees."""
    global _round_key
    from mpi4py import MPI

    if _round_key is None:
        _round_key = MPI.Comm.Create_keyval()
    k = comm.Get_attr(_round_key) or 0
    comm.Set_attr(_round_key, k + 1)
    return SPARSE_TAGS[k % 2]


def sparse_exchange(comm, messages: dict) -> dict:
    """Each ``messages[r]`` (``r`` another rank) goes to rank ``r``; returns the messages sent
    here as ``{source: message}`` in source order (collective; pickled: a rare path). No rank
    needs to know who sends to it, and no array of ``comm.size`` is made: the NBX algorithm
    (Hoefler, Siebert, Lumsdaine 2010): synchronous sends, arrivals probed for, and a
    non-blocking barrier entered once this rank's sends have all been received; done when the
    barrier completes. O(messages + log P) per rank. Consecutive exchanges alternate two tags:
    a rank still waiting for one's barrier never takes the next one's messages (those of the
    one after cannot be sent before it has left)."""
    if comm.size == 1:
        return {}
    from mpi4py import MPI

    tag = _sparse_tag(comm)
    sleep = comm.py2f() in _sleeping
    sends = [comm.issend(m, dest=int(r), tag=tag) for r, m in sorted(messages.items())]
    got = {}
    status = MPI.Status()
    barrier = None
    while True:
        if comm.iprobe(source=MPI.ANY_SOURCE, tag=tag, status=status):
            src = status.Get_source()
            got[src] = comm.recv(source=src, tag=tag)
            continue
        if barrier is None:
            if MPI.Request.Testall(sends):
                barrier = comm.Ibarrier()
        elif barrier.Test():
            break
        if sleep:
            time.sleep(SLEEP_POLL)
    return dict(sorted(got.items()))


def neighbour_exchange(comm, messages: dict, sources) -> dict:
    """Each ``messages[r]`` goes to rank ``r``; returns ``{s: message}`` from each rank of
    ``sources`` (each must send one here), in source order. Point-to-point (pickled), between
    ranks that know each other already (after a :func:`sparse_exchange`)."""
    if comm.size == 1:
        return {}
    sends = [comm.isend(m, dest=int(r), tag=NEIGHBOUR_TAG) for r, m in sorted(messages.items())]
    got = {int(s): comm.recv(source=int(s), tag=NEIGHBOUR_TAG) for s in sorted(sources)}
    wait_all(comm, sends)
    return got


def max_over_ranks(comm, value: float) -> float:
    """The largest of every rank's ``value`` (a float; exact)."""
    if comm.size == 1:
        return float(value)
    from mpi4py import MPI

    return float(comm.allreduce(float(value), op=MPI.MAX))
