"""Common-plane algorithms by name (``contact.algorithm``), dispatched at compile time.

Each entry is a namedtuple type carrying the algorithm's constants; :func:`find_plane` is
resolved per type when the refresh kernel compiles, so a scene compiles only its algorithm.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba.extending import overload

from ..registry import Registry
from .common_plane import common_plane
from .fast_common_plane import fast_common_plane

# Cundall's iteration (eqs. 5-10): ridge-step bounds and the vertex snap tolerance.
CundallPlane = namedtuple("CundallPlane", "ctol k_max k_min snap_tol")
# The fast common plane (DDA §3): needs world face normals and edge directions.
FastPlane = namedtuple("FastPlane", "ctol")

K_MAX = float(np.tan(np.radians(5.0)))
K_MIN = float(np.tan(np.radians(0.01)))


def _cundall(ctol, snap_tol):
    return CundallPlane(ctol, K_MAX, K_MIN, snap_tol)


def _fast(ctol, snap_tol):
    return FastPlane(ctol)


# name -> factory(ctol, snap_tol) of the kernel's constants
ALGORITHMS: Registry = Registry("common-plane algorithm")
ALGORITHMS.register("fast", _fast)
ALGORITHMS.register("cundall", _cundall)


def uses_face_normals(alg) -> bool:
    """Does the algorithm read world face normals and edge directions? (compiled constant)"""
    return isinstance(alg, FastPlane)


@overload(uses_face_normals)
def _uses_face_normals(alg):
    flag = alg.instance_class is FastPlane
    return lambda alg: flag


def find_plane(alg, va, vb, ca, cb, na, nb, ea, eb, n_in, p_in, warm):
    """Common plane of two vertex sets: (n, p, gap); compiled per algorithm."""
    raise NotImplementedError("find_plane is only callable from numba kernels")


@overload(find_plane)
def _find_plane(alg, va, vb, ca, cb, na, nb, ea, eb, n_in, p_in, warm):
    if alg.instance_class is FastPlane:
        def fast(alg, va, vb, ca, cb, na, nb, ea, eb, n_in, p_in, warm):
            n, p, gap, _, _, _ = fast_common_plane(va, vb, ca, cb, na, nb, ea, eb, n_in, p_in,
                                                   warm, alg.ctol)
            return n, p, gap
        return fast

    def cundall(alg, va, vb, ca, cb, na, nb, ea, eb, n_in, p_in, warm):
        n, p, gap, _, _, _ = common_plane(va, vb, ca, cb, n_in, p_in, warm, alg.ctol, alg.k_max,
                                          alg.k_min, alg.snap_tol)
        return n, p, gap
    return cundall
