"""Joint properties by joint set: a contact across two faces made by the same cut uses the
joint named by that cut (``cuts[i].joint``), as 3DEC assigns properties by joint set.

Faces remember the cut that made them (``face_tag``, see :mod:`pdem.geometry.cutting`). Two
pieces cut apart by a plane of set ``t`` touch across a pair of faces tagged ``t`` that are
antiparallel and coplanar, and their common plane is that joint plane; pieces that slid along
the joint still do. Decided when a contact's common plane is first found. Any other contact
keeps its group-pair joint (``joint_pairs``/``default``).
"""

from __future__ import annotations

import numpy as np

from ..jit import kernel

# faces count as antiparallel when n_a . n_b is below this (about 2.6 degrees apart)
_ANTIPARALLEL = -0.999


@kernel
def _face_plane(R, x, b, normals_local, offsets_local, f):
    """World unit normal and offset of face ``f`` of a piece of body ``b``."""
    n = np.empty(3)
    for k in range(3):
        n[k] = R[b, k, 0] * normals_local[f, 0] + R[b, k, 1] * normals_local[f, 1] + \
            R[b, k, 2] * normals_local[f, 2]
    return n, offsets_local[f] + n[0] * x[b, 0] + n[1] * x[b, 1] + n[2] * x[b, 2]


@kernel
def set_joints(todo, ia, ib, ka, kb, normal, x, R, face_start, normals_local, offsets_local,
               face_tag, cut_joint, tol, joint):
    """Set ``joint[c]`` of the contacts with ``todo[c] != 0`` whose common plane (unit
    ``normal``, A -> B) is a joint plane: A's face along the normal and B's face against it
    lie in one plane and were made by one cut that names a joint (the lowest such cut index
    wins: deterministic). A contact across the edge of two joint planes keeps its
    group-pair joint."""
    for c in range(ia.shape[0]):
        if todo[c] == 0:
            continue
        best = -1
        n = normal[c]
        for fa in range(face_start[ka[c]], face_start[ka[c] + 1]):
            t = face_tag[fa]
            if t < 0 or cut_joint[t] < 0 or (best >= 0 and t >= best):
                continue
            na, da = _face_plane(R, x, ia[c], normals_local, offsets_local, fa)
            if na[0] * n[0] + na[1] * n[1] + na[2] * n[2] < -_ANTIPARALLEL:
                continue
            for fb in range(face_start[kb[c]], face_start[kb[c] + 1]):
                if face_tag[fb] != t:
                    continue
                nb, db = _face_plane(R, x, ib[c], normals_local, offsets_local, fb)
                if na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2] < _ANTIPARALLEL \
                        and abs(da + db) <= tol:
                    best = t
                    break
        if best >= 0:
            joint[c] = cut_joint[best]
