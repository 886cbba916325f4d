"""BlockStore: the struct of arrays holding every block a rank knows (owned or ghost)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

# Per-block arrays and their trailing shape/dtype. Geometry (ragged) is listed separately.
BLOCK_FIELDS: dict[str, tuple[tuple[int, ...], type]] = {
    "gid": ((), np.int64),
    "owned": ((), np.uint8),
    "x": ((3,), np.float64),  # centroid (world)
    "q": ((4,), np.float64),  # orientation quaternion (w, x, y, z), body -> world
    "v": ((3,), np.float64),  # velocity at t - dt/2
    "w": ((3,), np.float64),  # angular velocity (world) at t - dt/2
    "L": ((3,), np.float64),  # angular momentum (world) at t - dt/2
    "mass": ((), np.float64),
    "inertia": ((3,), np.float64),  # principal moments (body frame = principal axes)
    "mscale": ((), np.float64),  # inertial mass scale (static solves), 1 otherwise
    "fixed": ((), np.uint8),
    "vfix": ((), np.uint8),  # velocity prescribed
    "material": ((), np.int32),
    "group": ((), np.int32),
    "force": ((3,), np.float64),  # contact force sum of the current step
    "moment": ((3,), np.float64),
    "applied_force": ((3,), np.float64),
    "prev_force": ((3,), np.float64),  # last step's unbalanced force (combined damping)
    "prev_moment": ((3,), np.float64),
    "u_acc": ((), np.float64),  # accumulated motion since the last remap (eq. 1)
    "u_geo": ((), np.float64),  # motion since the last periodic contact-geometry update
    "u_mig": ((), np.float64),  # motion since the last ghost rebuild / migration
    "radius": ((), np.float64),  # largest centroid-to-vertex distance
    "x0": ((3,), np.float64),  # centroid at start (for displacement histories)
}


@dataclass
class BlockStore:
    """Blocks as flat arrays; geometry is CSR in the body frame (see docs/architecture.md)."""

    gid: np.ndarray
    owned: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray
    L: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    mscale: np.ndarray
    fixed: np.ndarray
    vfix: np.ndarray
    material: np.ndarray
    group: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    applied_force: np.ndarray
    prev_force: np.ndarray
    prev_moment: np.ndarray
    u_acc: np.ndarray
    u_geo: np.ndarray
    u_mig: np.ndarray
    radius: np.ndarray
    x0: np.ndarray
    # geometry (CSR)
    vert_start: np.ndarray  # (n+1,) into verts_local / verts_world
    verts_local: np.ndarray  # (V, 3) body frame
    verts_world: np.ndarray  # (V, 3) refreshed from the pose
    face_start: np.ndarray  # (n+1,) into faces
    fvert_start: np.ndarray  # (F+1,) into face_verts
    face_verts: np.ndarray  # global vertex rows, CCW from outside
    normals_local: np.ndarray  # (F, 3)
    offsets_local: np.ndarray  # (F,)
    edge_start: np.ndarray  # (n+1,) into edges
    edges: np.ndarray  # (E, 2) global vertex rows
    edir_start: np.ndarray  # (n+1,) into edirs_local
    edirs_local: np.ndarray  # unique edge directions (body frame), for the fast common plane

    @property
    def n(self) -> int:
        return len(self.gid)


def empty_block_arrays(n: int) -> dict[str, np.ndarray]:
    return {k: np.zeros((n, *shape), dtype=dt) for k, (shape, dt) in BLOCK_FIELDS.items()}


def store_field_names() -> list[str]:
    return [f.name for f in fields(BlockStore)]


# The state that moves with a block when it migrates (the rest is static: rebuilt from the
# scene on every rank, keyed by gid).
DYNAMIC_FIELDS = ("x", "q", "v", "w", "L", "force", "moment", "prev_force", "prev_moment",
                  "u_acc", "u_geo", "u_mig")
STATIC_FIELDS = tuple(k for k in BLOCK_FIELDS if k not in DYNAMIC_FIELDS and k != "owned")
# What ghosts receive from their owner every step: pose, velocities, this step's rotation
# increment (the contact normal turns with it) and the motion accumulators (remap triggers).
HALO_FIELDS = ("x", "q", "v", "w", "u_acc", "u_geo")


def _csr_take(start: np.ndarray, rows: np.ndarray):
    """Index array selecting the CSR entries of ``rows`` in order, and the new start array."""
    counts = start[rows + 1] - start[rows]
    new_start = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(counts, out=new_start[1:])
    idx = np.repeat(start[rows] - new_start[:-1], counts) + np.arange(new_start[-1])
    return idx, new_start


def take_rows(glob: BlockStore, gids: np.ndarray, owned: np.ndarray) -> BlockStore:
    """A local store holding blocks ``gids`` of the global (replicated, static) store.

    Dynamic fields come from ``glob`` too; callers overwrite them with migrated state."""
    gids = np.asarray(gids, np.int64)
    per_block = {k: getattr(glob, k)[gids].copy() for k in BLOCK_FIELDS}
    per_block["owned"] = np.asarray(owned, np.uint8)
    vidx, vert_start = _csr_take(glob.vert_start, gids)
    fidx, face_start = _csr_take(glob.face_start, gids)
    fvidx, fvert_start = _csr_take(glob.fvert_start, fidx)
    eidx, edge_start = _csr_take(glob.edge_start, gids)
    didx, edir_start = _csr_take(glob.edir_start, gids)
    # vertex ids inside faces and edges are global vertex rows: renumber to local rows
    vmap = np.full(len(glob.verts_local), -1, np.int64)
    vmap[vidx] = np.arange(len(vidx))
    return BlockStore(
        **per_block,
        vert_start=vert_start,
        verts_local=glob.verts_local[vidx],
        verts_world=glob.verts_world[vidx].copy(),
        face_start=face_start,
        fvert_start=fvert_start,
        face_verts=vmap[glob.face_verts[fvidx]],
        normals_local=glob.normals_local[fidx],
        offsets_local=glob.offsets_local[fidx],
        edge_start=edge_start,
        edges=vmap[glob.edges[eidx]],
        edir_start=edir_start,
        edirs_local=glob.edirs_local[didx],
    )
