"""Zoned blocks in a scene: their grids, the block row's piece geometry from the surface grid.

A zoned block keeps its one row in the :class:`~pdem.model.blocks.BlockStore` (gid, centroid,
mass, envelopes, contacts) and ONE convex piece whose vertices are its surface gridpoints and
whose faces are its surface triangles (3DEC: "each original polygonal face is discretized into
triangular sub-faces ... each sub-face is exactly like a regular face"). Its pose is the
identity, so the piece's body frame is the world frame shifted to ``x``, the gridpoints'
mass-weighted centroid; every step :func:`pdem.deformable.contact.refresh_pieces` rewrites the
piece from the moved gridpoints, and the common plane and sub-contacts work unchanged.

:class:`GridStore` holds the grids of the zoned blocks of one rank (serial runs today), the
node arrays of all of them flat (``nodes``, ``vel``, ``force``: CSR by ``node_start``), each
block stepped by :func:`pdem.deformable.motion.cycle` on its own slice.
"""

from __future__ import annotations

import numpy as np

from ..geometry.polyhedron import ConvexPolyhedron
from .body import DeformableBody
from .mesh import tetrahedralise
from .motion import critical_timestep
from .zones import gravity_forces


def surface_polyhedron(poly: ConvexPolyhedron, mesh) -> tuple[ConvexPolyhedron, np.ndarray]:
    """The block as its surface grid: vertices the surface gridpoints (ascending node id),
    faces the surface triangles (in ``mesh.surface`` order) on their block face's exact plane.
    Returns (polyhedron, surface node ids)."""
    surf_nodes = np.unique(mesh.surface)
    tris = np.searchsorted(surf_nodes, mesh.surface)
    normals = np.asarray(poly.normals)[mesh.surface_face]
    offsets = np.asarray(poly.offsets)[mesh.surface_face]
    return ConvexPolyhedron.from_faces(mesh.nodes[surf_nodes], list(tris), normals, offsets), \
        surf_nodes


def zone_specs(scene, specs) -> None:
    """Zone every zoned block's shape (``blocks[i].zones``): its spec's one piece becomes the
    surface polyhedron, ``spec.zoning`` the (mesh, surface node ids). Specs without pieces
    (outside a build share) are left alone."""
    from ..config import ConfigError

    errors = []
    for s in specs:
        z = s.spec.zones
        if z is None or s.pieces is None:
            continue
        if len(s.pieces) != 1:
            errors.append(f"blocks[{s.entry}] ({s.name!r}).zones: the block is joined from "
                          f"{len(s.pieces)} convex pieces; zoned blocks must be convex yet")
            continue
        mesh = tetrahedralise(s.pieces[0], z.size)
        poly, surf = surface_polyhedron(s.pieces[0], mesh)
        s.pieces = [poly]
        s.zoning = (mesh, surf)
    if errors:
        raise ConfigError(errors)


def identity_frames(geometry: dict, arr: dict, specs) -> None:
    """Zoned rows of a freshly built store: pose the identity (the body frame is the world
    frame shifted to the centroid), piece geometry in that frame, and every edge its own
    direction (the fast common plane's directions; merging parallel ones would change their
    count as the surface deforms)."""
    g = geometry
    dirs, counts = [], []
    for r, s in enumerate(specs):
        k = g["piece_start"][r]
        e0, e1 = g["edge_start"][k], g["edge_start"][k + 1]
        if getattr(s, "zoning", None) is None:
            dirs.append(g["edirs_local"][g["edir_start"][k]:g["edir_start"][k + 1]])
            counts.append(len(dirs[-1]))
            continue
        poly = s.pieces[0]
        c = arr["x"][r]
        v0, v1 = g["vert_start"][k], g["vert_start"][k + 1]
        f0, f1 = g["face_start"][k], g["face_start"][k + 1]
        g["verts_local"][v0:v1] = poly.vertices - c
        g["normals_local"][f0:f1] = poly.normals
        g["offsets_local"][f0:f1] = poly.offsets - poly.normals @ c
        arr["q"][r] = (1.0, 0.0, 0.0, 0.0)
        ends = g["verts_local"][g["edges"][e0:e1]]
        d = ends[:, 1] - ends[:, 0]
        dirs.append(d / np.linalg.norm(d, axis=1)[:, None])
        counts.append(e1 - e0)
    # one-piece blocks only reach here with zones (joined zoned blocks are refused)
    g["edirs_local"] = np.concatenate(dirs).reshape(-1, 3) if dirs else g["edirs_local"]
    g["edir_start"] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


# margin under the grids' Gershgorin step (a guaranteed bound of the elastic grid with its
# joint springs; the margin covers the coupling to rigid blocks through their contacts)
GRID_FRAC = 0.9


class GridStore:
    """The grids of a rank's zoned blocks (see module doc), keyed by gid."""

    def __init__(self, scene, specs, first_gid: int):
        self.gids = []
        self.names = []
        bodies = []
        surf = []
        for i, s in enumerate(specs):
            if s.zoning is None:
                continue
            mesh, surf_nodes = s.zoning
            mat = scene.materials[s.material]
            bodies.append(DeformableBody(mesh, mat.zone_spec(), nmd=s.spec.zones.nmd))
            surf.append(surf_nodes)
            self.gids.append(first_gid + i)
            self.names.append(s.name)
        self.bodies = bodies
        self.surf = surf
        counts = [len(b.nodes) for b in bodies]
        self.node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        n = int(self.node_start[-1])
        self.nodes = np.empty((n, 3))
        self.vel = np.zeros((n, 3))
        self.force = np.zeros((n, 3))  # contact forces on the gridpoints (F^c of eq. 54)
        self.gmass = np.empty(n)
        for d, b in enumerate(bodies):  # the bodies' node arrays become views of the flat ones
            a, e = self.node_start[d], self.node_start[d + 1]
            self.nodes[a:e] = b.nodes
            self.vel[a:e] = b.vel
            self.gmass[a:e] = b.gravity_mass
            b.nodes, b.vel = self.nodes[a:e], self.vel[a:e]
        self.gravity = np.asarray(scene.gravity, float)
        self.rows = np.zeros(len(bodies), np.int64)

    def __len__(self) -> int:
        return len(self.bodies)

    def set_damping(self, alpha: float) -> None:
        """The grids' local damping coefficient (``solve.damping``: local, or none)."""
        for b in self.bodies:
            b.damping = float(alpha)

    def timestep(self, kn: float) -> float:
        """The zone term of eq. 88 with the joints' normal stiffness at the surface
        gridpoints (eq. 85: ``k_i += kn A_i``, ``A_i`` a third of its surface triangles'
        area): the smallest over the grids."""
        dt = np.inf
        for b in self.bodies:
            k = b.stiffness()
            tri = b.mesh.surface
            x = b.nodes
            area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]],
                                                 x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
            np.add.at(k, tri.ravel(), np.repeat(kn * area / 3.0, 3))
            dt = min(dt, critical_timestep(k, b.mass, b.damping))
        return float(dt)

    def resolve(self, scene, resolved):
        """The model step: the rigid one or the grids' (eq. 88, with the largest joint normal
        stiffness at the surface gridpoints, times ``GRID_FRAC``), the smaller; the grids'
        local damping from ``solve.damping``. Not the scene's ``timestep.frac`` (0.1 by
        default): that is the rigid estimate's margin, the Gershgorin step is a bound."""
        import dataclasses

        self.set_damping(resolved.alpha if scene.solve.damping.mode == "local" else 0.0)
        kn = max(float(getattr(j, "kn", 0.0)) for j in scene.joints.values())
        self.dt = GRID_FRAC * self.timestep(kn)
        if self.dt < resolved.dt:
            import logging

            logging.getLogger("pdem").info(
                "the zoned blocks' grids limit the step: %.3g s (%.2f of their Gershgorin "
                "bound with kn %.3g; the rigid step %.3g s)", self.dt, GRID_FRAC, kn, resolved.dt)
        return dataclasses.replace(resolved, dt=min(resolved.dt, self.dt))

    # ------------------------------------------------------------------ in a model state
    def bind(self, blocks, row_of) -> None:
        """Rows of the zoned blocks in ``blocks`` (after a distribution) and the maps the
        kernels use: block row -> zoned index, vertex row -> gridpoint."""
        self.rows = np.array([row_of(g) for g in self.gids], np.int64)
        self.dindex = np.full(blocks.n, -1, np.int64)
        self.dindex[self.rows] = np.arange(len(self.rows))
        self.vnode_rows = self.vnode(blocks)
        self.surf_flat = np.concatenate(self.surf).astype(np.int64)
        self.surf_start = np.concatenate([[0], np.cumsum([len(x) for x in self.surf])]
                                         ).astype(np.int64)
        self.gnode = {}  # contact key -> the gridpoint of each of its sub-contacts
        self.located = None  # the ContactStore the sub-contact weights were found for
        self.sc_node = np.zeros((0, 2, 3), np.int64)
        self.sc_w = np.zeros((0, 2, 3))

    def regrid(self, old, new, todo, b, tol):
        """Sub-contacts of the updated contacts of zoned blocks at their gridpoints
        (:func:`pdem.deformable.subcontacts.regrid`)."""
        from .subcontacts import regrid

        return regrid(self, old, new, todo, b, tol)

    def rigid_fixed(self, fixed: np.ndarray) -> np.ndarray:
        """``fixed`` with the zoned rows set: the rigid integration leaves them alone."""
        out = fixed.copy()
        out[self.rows[self.rows < len(out)]] = 1
        return out

    def sync(self, b) -> None:
        """Block rows and piece geometry from the gridpoints (after a grid step)."""
        from .contact import refresh_pieces

        refresh_pieces(self.rows, self.node_start, self.surf_start, self.surf_flat, self.nodes,
                       self.vel, self.gmass, b.x, b.v, b.dx, b.radius, b.piece_start,
                       b.vert_start, b.verts_local, b.face_start, b.fvert_start, b.face_verts,
                       b.normals_local, b.offsets_local, b.edge_start, b.edges, b.edir_start,
                       b.edirs_local)
        b.dtheta[self.rows] = 0.0
        b.w[self.rows] = 0.0
        b.L[self.rows] = 0.0

    def record(self, b, contacts):
        """The contact kernel's :class:`~pdem.deformable.contact.Grid`, the sub-contacts
        located afresh when the contact store changed (an update, a selection)."""
        from .contact import Grid, locate

        if self.located is not contacts:
            n = len(contacts.sub["sc_area"])
            self.sc_node = np.zeros((n, 2, 3), np.int64)
            self.sc_w = np.zeros((n, 2, 3))
            a = contacts.arrays
            locate(a["ia"], a["ib"], a["ka"], a["kb"], contacts.sc_start, contacts.sub["sc_pa"],
                   b.x, b.R, b.face_start, b.fvert_start, b.face_verts, self.nodes,
                   self.vnode_rows, self.dindex, self.sc_node, self.sc_w)
            self.located = contacts
        return Grid(self.dindex, self.vel, self.force, self.sc_node, self.sc_w)

    # ------------------------------------------------------------------ checkpoints
    def write(self, f, contacts) -> None:
        """The grids' state into group ``grids`` of an open checkpoint file (serial): gridpoint
        positions, velocities and contact forces, zone stresses and plastic bits, each
        sub-contact's gridpoints and weights (for ``contacts``, checked by their keys on
        reading) and the gridpoint of each gridpoint sub-contact by contact key."""
        g = f.create_group("grids")
        g.create_dataset("gid", data=np.asarray(self.gids, np.int64))
        for k in ("nodes", "vel", "force"):
            g.create_dataset(k, data=getattr(self, k))
        g.create_dataset("stress", data=np.concatenate([b.stress for b in self.bodies]))
        g.create_dataset("plastic", data=np.concatenate([b.plastic for b in self.bodies]))
        located = self.located is contacts
        g.create_dataset("sc_keys", data=contacts.keys() if located else np.zeros(0, np.int64))
        g.create_dataset("sc_node", data=self.sc_node if located else np.zeros((0, 2, 3), np.int64))
        g.create_dataset("sc_w", data=self.sc_w if located else np.zeros((0, 2, 3)))
        keys = np.array(sorted(self.gnode), np.int64)
        g.create_dataset("gnode_keys", data=keys)
        g.create_dataset("gnode_count", data=np.array([len(self.gnode[int(k)]) for k in keys],
                                                      np.int64))
        g.create_dataset("gnode", data=np.concatenate([self.gnode[int(k)] for k in keys])
                         if len(keys) else np.zeros(0, np.int64))

    def read(self, path, state) -> None:
        """Continue from the grids of a checkpoint written by :meth:`write` (after the blocks
        and contacts are restored): the arrays, the zones' geometry, the rows and pieces."""
        import h5py

        from ..errors import UserError
        from .zones import zone_geometry

        with h5py.File(path, "r") as f:
            if "grids" not in f or not np.array_equal(f["grids/gid"][()], self.gids) \
                    or f["grids/nodes"].shape != self.nodes.shape:
                raise UserError(f"checkpoint {path}: no grids of this scene's zoned blocks")
            g = f["grids"]
            for k in ("nodes", "vel", "force"):
                getattr(self, k)[:] = g[k][()]
            stress, plastic = g["stress"][()], g["plastic"][()]
            sc_keys, sc_node, sc_w = g["sc_keys"][()], g["sc_node"][()], g["sc_w"][()]
            keys, counts, flat = g["gnode_keys"][()], g["gnode_count"][()], g["gnode"][()]
        z = 0
        for b in self.bodies:
            m = len(b.tets)
            b.stress[:] = stress[z:z + m]
            b.plastic[:] = plastic[z:z + m]
            z += m
            zone_geometry(b.nodes, b.tets, b.grad, b.vol)
        starts = np.concatenate([[0], np.cumsum(counts)])
        blocks = state.blocks
        self.bind(blocks, state.owned_row)
        self.gnode = {int(k): flat[starts[i]:starts[i + 1]] for i, k in enumerate(keys)}
        c = state.contacts
        if len(sc_keys) and np.array_equal(sc_keys, c.keys()) and len(sc_node) == c.n_sub:
            self.sc_node, self.sc_w, self.located = sc_node, sc_w, c
        x_saved = blocks.x[self.rows].copy()
        self.sync(blocks)
        blocks.x[self.rows] = x_saved  # the stored centroids (the same numbers, recomputed)
        blocks.dx[self.rows] = 0.0

    def vnode(self, blocks) -> np.ndarray:
        """The gridpoint (flat index) of every vertex row of ``blocks``; -1 for rigid pieces."""
        out = np.full(len(blocks.verts_local), -1, np.int64)
        for d, r in enumerate(self.rows):
            k = blocks.piece_start[r]
            out[blocks.vert_start[k]:blocks.vert_start[k + 1]] = self.node_start[d] + self.surf[d]
        return out

    def step(self, dt: float) -> None:
        """One grid step of every zoned block: forces at t (contacts + gravity + zones)."""
        for d, b in enumerate(self.bodies):
            a, e = self.node_start[d], self.node_start[d + 1]
            applied = self.force[a:e] + gravity_forces(b.gravity_mass, self.gravity)
            done = _cycle(b, applied, dt)
            if done < 1:
                from ..errors import SimulationError

                raise SimulationError(f"zoned block {self.names[d]!r}: a zone inverted (the "
                                      "grid folded: a load or speed too large for its zones)")


def _cycle(b: DeformableBody, applied: np.ndarray, dt: float) -> int:
    from .motion import cycle

    return cycle(1, dt, b.nodes, b.vel, b.mass, applied, b.fixed, b.fixed_vel, b.tets, b.grad,
                 b.vol, b.stress, b.plastic, b.model, b.nmd, b.damping)
