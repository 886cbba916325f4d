"""The one place numba is configured: compile flags and where compiled kernels are cached."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import NamedTuple

import numba


def _cache_dir() -> str:
    """numba's cache directory, keyed on pdem's sources (names, sizes, modification times).

    numba's ``cache=True`` checks only the source file of the function it loads, not the files
    of the kernels that function calls: after an edit (or a ``git pull``) a stale cached kernel
    could run old code. Keying the directory on every source file makes any change compile
    afresh (stat only: no file is read). ``NUMBA_CACHE_DIR`` set by the user wins.
    """
    if "NUMBA_CACHE_DIR" in os.environ:
        return os.environ["NUMBA_CACHE_DIR"]
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        st = path.stat()
        h.update(f"{path.relative_to(root).as_posix()}:{st.st_size}:{st.st_mtime_ns}".encode())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return str(base / "pdem-numba" / h.hexdigest()[:16])


# numba reads its cache location when a kernel is declared, so it is set before any is.
numba.config.CACHE_DIR = _cache_dir()

# cache=True: warm starts in ~0.2 s instead of recompiling on every rank.
# fastmath stays off: the determinism contract needs IEEE-exact, order-fixed arithmetic.
# boundscheck off in production; tests may set NUMBA_BOUNDSCHECK=1 to catch indexing bugs.
njit = numba.njit(cache=True, fastmath=False, nogil=True)


def kernel(fn):
    """Compile ``fn`` as a pdem kernel (pure function over arrays, no Python objects)."""
    return njit(fn)


# The contact force loops, and only they, let LLVM fuse a multiply and an add into one
# fused multiply-add ("contract", none of fastmath's other licences: no reassociation, no
# reciprocals, signed zeros and NaNs kept). A sub-contact's update is chains of products and
# sums; fused, the loop is ~9 % faster (bench/cube_stack.py, docs/validation.md). The result
# is still a fixed function of the inputs on one CPU type, so any rank count and a restart
# give the same bits; what changes is that a product that cancelled exactly (a*b - c*d with
# a*b == c*d) may leave its rounding error (~1e-16 relative) instead of zero. Ranks on CPUs
# with and without FMA would differ: every x86-64 CPU since 2013 and every 64-bit ARM has
# it, and NUMBA_CPU_NAME=generic (portable caches) compiles it out everywhere alike.
force_njit = numba.njit(cache=True, fastmath={"contract"}, nogil=True)


def force_kernel(fn):
    """A contact force loop (see ``force_njit``): one that sums sub-contact forces."""
    return force_njit(fn)


# Small helpers called in the inner loops (per sub-contact, per block) with records or many
# scalars: inlined into the caller at numba's IR level, so a call never passes the records'
# array structs through memory (LLVM would not always inline them by itself).
inline_njit = numba.njit(cache=True, fastmath=False, nogil=True, inline="always")


def inline_kernel(fn):
    """A kernel inlined into every kernel that calls it (see ``inline_njit``)."""
    return inline_njit(fn)


def drop_linking_ir(dispatcher) -> None:
    """Free the LLVM IR numba keeps beside the machine code of ``dispatcher``'s compiled
    versions, for inlining them into functions compiled later (its "shared module"). Only for
    kernels no other kernel calls (pdem.cycle.fused_steps, ~15 MB of IR a version for ~1.5 MB
    of code): nothing will link them. Tolerates numba versions without the attribute."""
    for cres in list(dispatcher.overloads.values()):
        library = getattr(cres, "library", None)
        if getattr(library, "_shared_module", None) is not None:
            library._shared_module = None


class Access(NamedTuple):
    """What a kernel reads and writes of the model's stores, by declared field name
    (pdem.model.fields: the block, contact and sub-contact fields by their store names,
    ``applied_force`` and ``sc_un`` rather than the records' ``applied`` and ``un``): every
    field it reads (written ones included, where also read) and every field it may change.
    Arrays that are no declared field (the pieces' geometry, the CSR start, the joints'
    tables, statistics) are not named."""

    reads: tuple[str, ...]
    writes: tuple[str, ...]


# the declared kernels' access, by "module.kernel" (tests/unit/test_kernel_access.py runs each
# on a scene and checks that it changes no field it does not declare)
ACCESS: dict[str, Access] = {}


def access(reads: str, writes: str = ""):
    """Declare what the kernel below reads and writes (:class:`Access`; field names separated
    by blanks); put above its ``@kernel``, it returns the kernel unchanged."""

    def declare(dispatcher):
        fn = getattr(dispatcher, "py_func", dispatcher)  # (a plain function with the JIT off)
        ACCESS[f"{fn.__module__}.{fn.__name__}"] = Access(tuple(reads.split()),
                                                          tuple(writes.split()))
        return dispatcher

    return declare
