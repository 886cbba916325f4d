"""Pose kernels: rotation matrices from quaternions, world vertices and vectors, envelopes."""

from __future__ import annotations

import numpy as np

from ..jit import kernel
from .rotation import quat_to_matrix_s


@kernel
def rotation_matrices(q, out):
    """Rotation matrix of each unit quaternion (w, x, y, z): ``out[b] = R(q[b])``."""
    for b in range(q.shape[0]):
        m = quat_to_matrix_s(q[b, 0], q[b, 1], q[b, 2], q[b, 3])
        for i in range(3):
            for j in range(3):
                out[b, i, j] = m[3 * i + j]


@kernel
def world_vertices(x, R, vert_start, verts_local, verts_world):
    """World vertices from the pose (no drift: always from the body-frame geometry)."""
    for b in range(vert_start.shape[0] - 1):
        for v in range(vert_start[b], vert_start[b + 1]):
            for k in range(3):
                verts_world[v, k] = x[b, k] + R[b, k, 0] * verts_local[v, 0] + \
                    R[b, k, 1] * verts_local[v, 1] + R[b, k, 2] * verts_local[v, 2]


@kernel
def world_vectors(R, start, local, rows):
    """Body-frame vectors (CSR by block, ``start``) rotated to the world, for the blocks with
    ``rows[b] != 0`` (others are left uninitialised)."""
    out = np.empty_like(local)
    for b in range(start.shape[0] - 1):
        if rows[b] == 0:
            continue
        for f in range(start[b], start[b + 1]):
            for k in range(3):
                out[f, k] = R[b, k, 0] * local[f, 0] + R[b, k, 1] * local[f, 1] \
                    + R[b, k, 2] * local[f, 2]
    return out


@kernel
def envelopes(vert_start, verts_world, pad, lo, hi):
    """Axis-aligned envelope of each block, enlarged by ``pad`` on every side."""
    for b in range(vert_start.shape[0] - 1):
        for k in range(3):
            lo[b, k] = np.inf
            hi[b, k] = -np.inf
        for v in range(vert_start[b], vert_start[b + 1]):
            for k in range(3):
                c = verts_world[v, k]
                if c < lo[b, k]:
                    lo[b, k] = c
                if c > hi[b, k]:
                    hi[b, k] = c
        for k in range(3):
            lo[b, k] -= pad
            hi[b, k] += pad


def refresh_pose(blocks, pad: float) -> None:
    """R, world vertices and envelopes of every row of ``blocks`` from x and q."""
    rotation_matrices(blocks.q, blocks.R)
    world_vertices(blocks.x, blocks.R, blocks.vert_start, blocks.verts_local, blocks.verts_world)
    envelopes(blocks.vert_start, blocks.verts_world, pad, blocks.lo, blocks.hi)
