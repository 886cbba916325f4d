"""Pose kernels: rotation matrices from quaternions, world vertices and vectors, envelopes."""

from __future__ import annotations

import numpy as np

from ..jit import access, kernel
from .rotation import quat_to_matrix_s


@access(reads="q", writes="R")
@kernel
def rotation_matrices(q, out):
    """Rotation matrix of each unit quaternion (w, x, y, z): ``out[b] = R(q[b])``."""
    for b in range(q.shape[0]):
        m = quat_to_matrix_s(q[b, 0], q[b, 1], q[b, 2], q[b, 3])
        for i in range(3):
            for j in range(3):
                out[b, i, j] = m[3 * i + j]


@kernel
def thinnest_width(vert_start, verts_local, face_start, normals_local, offsets_local) -> float:
    """The smallest width of any convex piece: over its faces, the distance from the face's
    plane to the piece's farthest vertex behind it (inf without pieces)."""
    out = np.inf
    for p in range(vert_start.shape[0] - 1):
        for f in range(face_start[p], face_start[p + 1]):
            lo = np.inf
            for v in range(vert_start[p], vert_start[p + 1]):
                d = normals_local[f, 0] * verts_local[v, 0] + normals_local[f, 1] * \
                    verts_local[v, 1] + normals_local[f, 2] * verts_local[v, 2]
                lo = min(lo, d)
            out = min(out, offsets_local[f] - lo)
    return out


@kernel
def world_vertices(x, R, piece_block, piece_center, piece_x, vert_start, verts_local,
                   verts_world):
    """World piece centres and vertices from the pose (no drift: always from the body-frame
    geometry). A one-piece block's centre offset is zero, so its piece centre is x exactly."""
    for p in range(piece_block.shape[0]):
        b = piece_block[p]
        for k in range(3):
            piece_x[p, k] = x[b, k] + R[b, k, 0] * piece_center[p, 0] + \
                R[b, k, 1] * piece_center[p, 1] + R[b, k, 2] * piece_center[p, 2]
        for v in range(vert_start[p], vert_start[p + 1]):
            for k in range(3):
                verts_world[v, k] = x[b, k] + R[b, k, 0] * verts_local[v, 0] + \
                    R[b, k, 1] * verts_local[v, 1] + R[b, k, 2] * verts_local[v, 2]


@kernel
def envelopes(piece_block, vert_start, verts_world, pad, piece_lo, piece_hi, lo, hi):
    """Axis-aligned envelope of each piece and of each block (the union of its pieces'),
    enlarged by ``pad`` on every side."""
    for b in range(lo.shape[0]):
        for k in range(3):
            lo[b, k] = np.inf
            hi[b, k] = -np.inf
    for p in range(piece_block.shape[0]):
        b = piece_block[p]
        for k in range(3):
            piece_lo[p, k] = np.inf
            piece_hi[p, k] = -np.inf
        for v in range(vert_start[p], vert_start[p + 1]):
            for k in range(3):
                c = verts_world[v, k]
                if c < piece_lo[p, k]:
                    piece_lo[p, k] = c
                if c > piece_hi[p, k]:
                    piece_hi[p, k] = c
        for k in range(3):
            piece_lo[p, k] -= pad
            piece_hi[p, k] += pad
            if piece_lo[p, k] < lo[b, k]:
                lo[b, k] = piece_lo[p, k]
            if piece_hi[p, k] > hi[b, k]:
                hi[b, k] = piece_hi[p, k]


def update_world_vertices(blocks) -> None:
    """World piece centres and vertices of every row of ``blocks`` from x and R."""
    world_vertices(blocks.x, blocks.R, blocks.piece_block, blocks.piece_center, blocks.piece_x,
                   blocks.vert_start, blocks.verts_local, blocks.verts_world)


def update_envelopes(blocks, pad: float) -> None:
    """Piece and block envelopes of every row of ``blocks`` from the world vertices."""
    envelopes(blocks.piece_block, blocks.vert_start, blocks.verts_world, pad, blocks.piece_lo,
              blocks.piece_hi, blocks.lo, blocks.hi)


def refresh_pose(blocks, pad: float) -> None:
    """R, world vertices and envelopes of every row of ``blocks`` from x and q."""
    rotation_matrices(blocks.q, blocks.R)
    update_world_vertices(blocks)
    update_envelopes(blocks, pad)
