"""The one place numba is configured: compile flags and where compiled kernels are cached."""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path
from typing import NamedTuple

import numba

try:  # (older numba names them with a leading underscore)
    from numba.core.caching import CacheImpl, UserProvidedCacheLocator
except ImportError:  # pragma: no cover
    from numba.core.caching import _CacheImpl as CacheImpl
    from numba.core.caching import _UserProvidedCacheLocator as UserProvidedCacheLocator

ROOT = Path(__file__).resolve().parent  # the package, wherever it is checked out or installed


def source_key(root: Path = ROOT) -> str:
    """A digest of every source file of the package (path inside it and content).

    numba's ``cache=True`` checks only the source file of the function it loads, not the files
    of the kernels that function calls: after an edit (or a ``git pull``) a stale cached kernel
    could run old code. Keying the cache directory on every source file's content makes any
    change compile afresh, and only a change: a fresh checkout, a ``pip install`` or a ``git
    pull`` that brings the same sources find the kernels compiled (~5 ms to read them).
    """
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def cache_dir() -> str:
    """Where compiled kernels are kept: ``$NUMBA_CACHE_DIR`` (e.g. node-local scratch on a
    cluster) or ``~/.cache/pdem-numba``, then the sources' key (:func:`source_key`)."""
    base = os.environ.get("NUMBA_CACHE_DIR") or str(
        Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pdem-numba")
    return str(Path(base) / source_key())


CACHE_DIR = cache_dir()


class PackageLocator(UserProvidedCacheLocator):
    """numba's cache locator for pdem's kernels: each under :data:`CACHE_DIR` by its file's
    place in the package, not by the checkout's absolute path (numba's own locator hashes the
    directory's path, so every checkout compiled everything again). numba's index still checks
    the file's content, the signature, numba's version and the CPU the code was made for."""

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        inside = Path(py_file).resolve().parent.relative_to(ROOT)
        self._cache_path = os.path.join(CACHE_DIR, "pdem", *inside.parts)

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            Path(py_file).resolve().relative_to(ROOT)
        except ValueError:  # not pdem's: numba's own locators
            return None
        return super().from_function(py_func, py_file)


# numba reads its cache location when a kernel is declared, so it is set before any is.
numba.config.CACHE_DIR = CACHE_DIR
if PackageLocator not in CacheImpl._locator_classes:
    CacheImpl._locator_classes.insert(0, PackageLocator)


class _CompileLock:
    """One process per cache directory compiles a kernel at a time (an exclusive ``flock`` on
    a file of that kernel's beside the compiled code), so that ranks started together on a
    node do not compile the same kernel side by side: the first compiles and saves it, the
    others wait and then load it from the cache (numba looks there first on every compile).
    Different kernels compile side by side (test workers share a fresh cache's compiles out).
    A compile holds its kernel's lock and those of the callees it compiles, a path down the
    call graph, which has no cycle: two processes cannot wait for each other. Where the file
    system refuses the lock (some network file systems) compiles go on unlocked."""

    def __init__(self, name: str):
        self.name = name
        self.depth = 0
        self.file = None

    def __enter__(self):
        self.depth += 1
        if self.depth == 1:
            try:
                folder = os.path.join(CACHE_DIR, "locks")
                os.makedirs(folder, exist_ok=True)
                self.file = open(os.path.join(folder, self.name + ".lock"), "a")  # noqa: SIM115
                fcntl.flock(self.file, fcntl.LOCK_EX)
            except OSError:
                self._close()
        return self

    def __exit__(self, *exc):
        self.depth -= 1
        if self.depth == 0:
            self._close()

    def _close(self):
        if self.file is not None:
            self.file.close()  # (closing releases the lock)
            self.file = None


def _locked(dispatcher):
    """``dispatcher`` whose compiles hold its :class:`_CompileLock`."""
    fn = dispatcher.py_func
    lock = _CompileLock(f"{fn.__module__}.{fn.__qualname__}")
    compile_unlocked = dispatcher.compile

    def compile(sig):
        with lock:
            return compile_unlocked(sig)

    dispatcher.compile = compile
    return dispatcher


# cache=True: warm starts in ~0.2 s instead of recompiling on every rank.
# fastmath stays off: the determinism contract needs IEEE-exact, order-fixed arithmetic.
# boundscheck off in production; tests may set NUMBA_BOUNDSCHECK=1 to catch indexing bugs.
njit = numba.njit(cache=True, fastmath=False, nogil=True)


def kernel(fn):
    """Compile ``fn`` as a pdem kernel (pure function over arrays, no Python objects)."""
    return _locked(njit(fn))


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
    return _locked(force_njit(fn))


# Small helpers called in the inner loops (per sub-contact, per block) with records or many
# scalars: inlined into the caller at numba's IR level, so a call never passes the records'
# array structs through memory (LLVM would not always inline them by itself).
inline_njit = numba.njit(cache=True, fastmath=False, nogil=True, inline="always")


def inline_kernel(fn):
    """A kernel inlined into every kernel that calls it (see ``inline_njit``)."""
    return _locked(inline_njit(fn))


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
