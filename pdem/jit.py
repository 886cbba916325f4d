"""The one place numba's compile flags are set, so every kernel compiles alike."""

from __future__ import annotations

import numba

# cache=True: warm starts in ~0.2 s instead of recompiling on every rank.
# fastmath stays off: the determinism contract needs IEEE-exact, order-fixed arithmetic.
# boundscheck off in production; tests may set NUMBA_BOUNDSCHECK=1 to catch indexing bugs.
njit = numba.njit(cache=True, fastmath=False, nogil=True)


def kernel(fn):
    """Compile ``fn`` as a pdem kernel (pure function over arrays, no Python objects)."""
    return njit(fn)
