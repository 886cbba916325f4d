"""MPI called from compiled code: the forward halo and the step's reduction inside a compiled
run of steps (pdem.cycle) on several ranks.

A rank steps in Python only because its halo and its reduction are MPI calls. This module
lets numba make those calls itself: the C functions ``MPI_Isend``, ``MPI_Irecv``,
``MPI_Waitall`` and ``MPI_Allreduce`` of the MPI library mpi4py is linked to, called through
their addresses, with the handles mpi4py holds (its communicator, ``MPI_DOUBLE``,
``MPI_MAX``). The addresses and handles are arguments, not constants, so the compiled loop
stays cached and one cache serves any MPI.

Handles are ``int`` in MPICH and its derivatives and pointers in Open MPI: every handle is
passed as an int64 and the call is made with the width the library uses (``wide``, from
mpi4py's ``_sizeof``). Requests and statuses live in byte buffers of the library's sizes.
:func:`link` checks the calls against mpi4py's on every rank before a run uses them (an
exchange and a reduction with known answers) and otherwise leaves the ranks on the Python
path, as does ``PDEM_MPI_NATIVE=0``.

The messages are those of :class:`pdem.parallel.halo.Halo` (the same buffers, tag and
order), so a rank that returned to Python for a step meets the others' compiled calls.
"""

from __future__ import annotations

import ctypes
import logging
import os
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ..errors import UserError
from ..jit import kernel
from .halo import HALO_TAG, copy_rows

log = logging.getLogger("pdem")

# argument kinds of the MPI functions called: ``i`` a C int, ``h`` a handle (int or pointer,
# see ``wide``), ``p`` a pointer (a buffer, the request or status arrays)
_KINDS = {"MPI_Isend": "pihiihp", "MPI_Irecv": "pihiihp", "MPI_Waitall": "ipp",
          "MPI_Allreduce": "ppihhh"}
FUNCTIONS = tuple(_KINDS)


def _pointer_call(kinds: str):
    """An intrinsic ``call(address, wide, args)`` calling the C function at ``address`` (int64)
    with ``args`` (a tuple of ``len(kinds)`` int64) converted to ``kinds``; returns the C int
    it returns. ``wide``: handles are 64-bit pointers (else 32-bit ints)."""

    @intrinsic
    def call(typingctx, address, wide, args):
        if not (isinstance(args, types.UniTuple) and args.count == len(kinds)
                and isinstance(args.dtype, types.Integer)):
            return None
        sig = types.int32(types.int64, types.boolean, args)

        def codegen(context, builder, signature, llargs):
            addr, is_wide, tup = llargs
            i32, i64, ptr = ir.IntType(32), ir.IntType(64), ir.IntType(8).as_pointer()
            values = [builder.extract_value(tup, k) for k in range(len(kinds))]

            def emit(handle_type):
                tys, vals = [], []
                for kind, v in zip(kinds, values, strict=True):
                    ty = {"i": i32, "p": ptr, "h": handle_type}[kind]
                    tys.append(ty)
                    if ty is ptr:
                        vals.append(builder.inttoptr(v, ptr))
                    elif ty is i32:
                        vals.append(builder.trunc(v, i32))
                    else:
                        vals.append(v)
                fnty = ir.FunctionType(i32, tys)
                return builder.call(builder.inttoptr(addr, fnty.as_pointer()), vals)

            with builder.if_else(is_wide) as (then, otherwise):
                with then:
                    wide_rc = emit(i64)
                    wide_block = builder.block
                with otherwise:
                    narrow_rc = emit(i32)
                    narrow_block = builder.block
            rc = builder.phi(i32)
            rc.add_incoming(wide_rc, wide_block)
            rc.add_incoming(narrow_rc, narrow_block)
            return rc

        return sig, codegen

    return call


_call7 = _pointer_call(_KINDS["MPI_Isend"])
_call3 = _pointer_call(_KINDS["MPI_Waitall"])
_call6 = _pointer_call(_KINDS["MPI_Allreduce"])


class Net(NamedTuple):
    """What the compiled calls need (every field an int64, a bool or an array):

    ``single``: one rank, no MPI call is made (:func:`idle_net`); ``fn``: the addresses of
    :data:`FUNCTIONS`, in that order; ``wide``: 64-bit handles;
    ``comm``, ``double``, ``op_max``: the handles; ``tag``: the messages' tag (the blocks'
    halo's, or the gridpoints': :data:`pdem.parallel.halo.GRID_HALO_TAG`); ``req_size``:
    bytes of an ``MPI_Request``;
    ``requests``, ``statuses``: byte buffers for one of each per neighbour and direction;
    ``send_rank``/``recv_rank`` (int32) the neighbours, ``send_start``/``recv_start`` the
    CSR of their rows in ``send_rows``/``recv_rows`` and in the buffers ``sbuf``/``rbuf``
    (float64, one row a block, :class:`pdem.parallel.halo.Halo`'s widths); ``flags``: the
    reduction's buffer (its result is written to ``reduced``)."""

    single: bool
    fn: np.ndarray
    wide: bool
    comm: int
    double: int
    op_max: int
    tag: int
    req_size: int
    requests: np.ndarray
    statuses: np.ndarray
    send_rank: np.ndarray
    send_start: np.ndarray
    send_rows: np.ndarray
    sbuf: np.ndarray
    recv_rank: np.ndarray
    recv_start: np.ndarray
    recv_rows: np.ndarray
    rbuf: np.ndarray
    flags: np.ndarray
    reduced: np.ndarray


@kernel
def _address(a):
    """The address of ``a``'s first element, as an int64 (numba's is unsigned, and unsigned
    plus signed is a float there)."""
    return np.int64(a.ctypes.data)


@kernel
def _post(net, fn, rows, peer, k):
    """``MPI_Isend`` (``fn`` 0) or ``MPI_Irecv`` (1) of the buffer ``rows`` to or from rank
    ``peer``, its request the ``k``-th; MPI's error code."""
    return _call7(net.fn[fn], net.wide, (
        _address(rows), np.int64(rows.size), net.double, np.int64(peer),
        np.int64(net.tag), net.comm, _address(net.requests) + k * net.req_size))


@kernel
def forward_halo(net, columns):
    """:meth:`pdem.parallel.halo.Halo.forward` compiled: receive the ghosts' rows, send the
    owned rows the neighbours ghost, wait for all, unpack. Returns MPI's error code (0)."""
    n_recv = net.recv_rank.shape[0]
    for j in range(n_recv):
        rc = _post(net, 1, net.rbuf[net.recv_start[j]:net.recv_start[j + 1]],
                   net.recv_rank[j], j)
        if rc != 0:
            return rc
    for j in range(net.send_rank.shape[0]):
        lo, hi = net.send_start[j], net.send_start[j + 1]
        copy_rows(columns, net.send_rows[lo:hi], net.sbuf[lo:hi], True)
        rc = _post(net, 0, net.sbuf[lo:hi], net.send_rank[j], n_recv + j)
        if rc != 0:
            return rc
    k = n_recv + net.send_rank.shape[0]
    if k:
        rc = _call3(net.fn[2], net.wide, (np.int64(k), _address(net.requests),
                                          _address(net.statuses)))
        if rc != 0:
            return rc
    for j in range(n_recv):
        lo, hi = net.recv_start[j], net.recv_start[j + 1]
        copy_rows(columns, net.recv_rows[lo:hi], net.rbuf[lo:hi], False)
    return 0


@kernel
def allreduce_max(net):
    """``net.reduced`` = the element-wise maximum of every rank's ``net.flags`` (the step's
    reduction, :func:`pdem.mpi.allreduce_max_array`). Returns MPI's error code."""
    return _call6(net.fn[3], net.wide, (
        _address(net.flags), _address(net.reduced), np.int64(net.flags.shape[0]),
        net.double, net.op_max, net.comm))


# --------------------------------------------------------------------------- set-up
def _addresses() -> np.ndarray | None:
    """The addresses of :data:`FUNCTIONS` in the MPI library mpi4py uses, or None."""
    from mpi4py import MPI

    for name in (MPI.__file__, None):  # the extension module's dependencies, else global
        try:
            lib = ctypes.CDLL(name)
            return np.array([ctypes.cast(getattr(lib, f), ctypes.c_void_p).value
                             for f in FUNCTIONS], np.int64)
        except (OSError, AttributeError, TypeError):
            continue
    return None


def _handle(obj) -> int:
    from mpi4py import MPI

    h = int(MPI._handleof(obj))
    return h - (1 << 64) if h >= 1 << 63 else h  # int64 bits


def _rows_csr(plan: dict[int, np.ndarray]):
    ranks = np.array(sorted(plan), np.int32)
    start = np.zeros(len(ranks) + 1, np.int64)
    start[1:] = np.cumsum([len(plan[r]) for r in ranks])
    rows = (np.concatenate([plan[r] for r in ranks]).astype(np.int64) if len(ranks)
            else np.zeros(0, np.int64))
    return ranks, start, rows


def make_net(comm, halo, n_flags: int, tag: int = HALO_TAG) -> Net | None:
    """The compiled calls' record for ``halo`` (a :class:`pdem.parallel.halo.Halo`, or a
    :class:`~pdem.parallel.halo.RowHalo` with its ``tag``) and a reduction of ``n_flags``
    float64; None if this MPI's functions are not found (this rank
    only: :func:`link` agrees collectively)."""
    from mpi4py import MPI

    fn = _addresses()
    if fn is None:
        return None
    size = MPI._sizeof(MPI.Comm)
    if size not in (4, 8) or MPI._sizeof(MPI.Datatype) != size or \
            MPI._sizeof(MPI.Op) != size:
        return None
    req_size = int(MPI._sizeof(MPI.Request))
    n_req = len(halo.send) + len(halo.recv)
    send_rank, send_start, send_rows = _rows_csr(halo.send)
    recv_rank, recv_start, recv_rows = _rows_csr(halo.recv)
    width = next(iter(halo.sbuf.values()), next(iter(halo.rbuf.values()), np.empty((0, 1))))
    width = width.shape[1]
    return Net(False, fn, size == 8, _handle(comm), _handle(MPI.DOUBLE), _handle(MPI.MAX),
               int(tag), req_size,
               np.zeros(max(n_req, 1) * req_size, np.uint8),
               np.zeros(max(n_req, 1) * int(MPI._sizeof(MPI.Status)), np.uint8),
               send_rank, send_start, send_rows, np.empty((send_start[-1], width)),
               recv_rank, recv_start, recv_rows, np.empty((recv_start[-1], width)),
               np.zeros(n_flags), np.zeros(n_flags))


def idle_net(width: int, n_flags: int) -> Net:
    """The record a serial run passes (``single``: nothing is sent or reduced): the same
    numba type as a rank's, so one compiled loop serves both."""
    no_rank, start, no_row = np.zeros(0, np.int32), np.zeros(1, np.int64), np.zeros(0, np.int64)
    return Net(True, np.zeros(len(FUNCTIONS), np.int64), False, 0, 0, 0, HALO_TAG, 0,
               np.zeros(1, np.uint8), np.zeros(1, np.uint8), no_rank, start, no_row,
               np.empty((0, width)), no_rank, start, no_row, np.empty((0, width)),
               np.zeros(n_flags), np.zeros(n_flags))


def enabled() -> bool:
    """``PDEM_MPI_NATIVE`` (default 1): 0 keeps every rank's steps in Python."""
    v = os.environ.get("PDEM_MPI_NATIVE", "1").strip().lower() or "1"
    if v not in ("0", "1", "off", "on", "no", "yes", "false", "true"):
        raise UserError(f"PDEM_MPI_NATIVE: must be 0 or 1 (got {v!r})")
    return v in ("1", "on", "yes", "true")


def _check_net(comm) -> Net | None:
    """The self-check's record (a ring: rows 0-1 go right, rows 2-3 come from the left), or
    None when this MPI's functions or handles are not usable here."""
    r, p = comm.rank, comm.size
    return make_net(comm, _Plan({(r + 1) % p: np.array([0, 1])},
                                {(r - 1) % p: np.array([2, 3])}, 2), 3)


def _self_check(comm, net: Net) -> bool:
    """Whether the compiled calls give the expected answers on this rank: the ring exchange
    of known rows and a maximum of known values (collective: every rank calls it)."""
    r, p = comm.rank, comm.size
    left = (r - 1) % p
    x = np.full((4, 2), -1.0)
    x[:2] = np.array([[r, 0.5], [r + 0.25, -r]])
    if forward_halo(net, (x,)) != 0:
        return False
    net.flags[:] = (r, -r, 0.5 * r)
    if allreduce_max(net) != 0:
        return False
    want = np.array([[left, 0.5], [left + 0.25, -left]])
    return bool((x[2:] == want).all() and (net.reduced == (p - 1, 0.0, 0.5 * (p - 1))).all())


class _Plan:
    """A halo plan of ``width`` columns (the self-check's made-up rows)."""

    def __init__(self, send, recv, width):
        self.send, self.recv = send, recv
        self.sbuf = {q: np.empty((len(v), width)) for q, v in send.items()}
        self.rbuf = {q: np.empty((len(v), width)) for q, v in recv.items()}


_checked: dict[int, bool] = {}  # communicator handle -> the self-check's collective verdict


def link(comm) -> bool:
    """Whether compiled runs of steps may call MPI on ``comm`` (collective on first use per
    communicator): ``PDEM_MPI_NATIVE`` on, the functions and handles usable on every rank
    (agreed before any compiled call, so no rank waits for one that will not send), and the
    self-check passed on every rank. A failure is logged once and leaves the ranks on the
    Python path."""
    from mpi4py import MPI

    key = comm.py2f()
    if key not in _checked:
        on = enabled()
        net = None
        try:
            net = _check_net(comm) if on else None
        except Exception as exc:  # an MPI we cannot call this way: stay on the Python path
            log.debug("compiled MPI calls unavailable: %s", exc)
        ok = False
        if comm.allreduce(net is not None, op=MPI.LAND):
            try:
                ok = _self_check(comm, net)
            except Exception as exc:
                log.debug("compiled MPI calls failed their check: %s", exc)
        agreed = comm.allreduce(ok, op=MPI.LAND)
        if comm.allreduce(on, op=MPI.LOR) and not agreed:
            log.info("MPI calls from compiled code unavailable here: ranks step in Python")
        _checked[key] = agreed
    return _checked[key]
