"""Rock reinforcement in a run (``reinforcement:``, docs/reinforcement.md): cables and rock
bolts installed at the start or by a stage (``reinforce:``), stepped with the blocks.

The elements are few beside the blocks (a tunnel's bolts: thousands of nodes), so every rank
holds all of them and steps them alike, from the same inputs: each step the anchors' positions
and velocities are computed by their hosts' owners and summed over the ranks (one reduction of
6 doubles an installed node; every other rank adds zeros, exact), then every rank moves the
nodes and computes their forces (pdem.dynamics.cables), and the owner of each host adds the
reactions to its force node by node in element order: after its contact forces, in the same
order on any rank count. The elements' state is the same on every rank, so rank 0's copy
is the checkpoint's and the output's.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .config import ConfigError
from .dynamics import cables
from .io.elements import BROKEN, DOWEL_YIELDED, SLIPPING, YIELDED
from .mpi import allgather, allreduce_sum_array

log = logging.getLogger("pdem")

# node arrays (N rows) and segment arrays (S rows) of the installed elements: the state a
# checkpoint holds (the others are fixed at installation and recomputed from the scene)
NODE_STATE = ("x", "v", "force", "last", "slip", "imass", "anchored", "grout")
SEGMENT_STATE = ("eps_p", "broken", "dp", "shear", "axial")
# where each node is anchored, fixed at installation (a checkpoint's, for the restart's)
HOST_COLUMNS = ("host", "local", "zoned", "tet_nodes", "tet_w")
# the nodes' step: this fraction of their stable bound (a chain of springs and masses, whose
# bound is sharp, unlike the blocks' estimate from their joints: solve.timestep.frac)
NODE_STEP_FRACTION = 0.5
# a node this far outside every block (m) is still taken by the nearest one it touches
HOST_TOLERANCE_FRACTION = 0.5  # of the contact tolerance


def element_lines(entry) -> np.ndarray:
    """The straight elements of a ``reinforcement:`` entry: (k, 2, 3) from/to points."""
    if entry.pattern is None:
        return np.array([[entry.from_, entry.to]], float)
    return tunnel_pattern(entry.pattern.tunnel)


def tunnel_pattern(p) -> np.ndarray:
    """Rings of radial bolts (:class:`pdem.config.schema.TunnelPattern`): (k, 2, 3)."""
    start, end = np.asarray(p.start, float), np.asarray(p.end, float)
    axis = end - start
    length = float(np.linalg.norm(axis))
    if length == 0.0:
        raise ConfigError(["pattern.tunnel: start and end are the same point"])
    axis /= length
    up = np.array([0.0, 0.0, 1.0])
    if abs(axis @ up) > 0.99:  # a shaft: the crown towards +y
        up = np.array([0.0, 1.0, 0.0])
    crown = up - (up @ axis) * axis
    crown /= np.linalg.norm(crown)
    right = np.cross(axis, crown)  # the right hand looking from start to end
    a0, a1 = p.arc
    whole = math.isclose((a1 - a0) % 360.0, 0.0) and a1 != a0
    n = p.per_ring
    if whole:
        angles = a0 + 360.0 * np.arange(n) / n
    else:
        angles = np.array([a0]) if n == 1 else np.linspace(a0, a1, n)
    rings = np.arange(0.0, length + 1e-9 * length, p.spacing)
    lines = []
    for s in rings:
        c = start + s * axis
        for a in np.radians(angles):
            d = math.cos(a) * crown + math.sin(a) * right
            lines.append((c + p.radius * d, c + (p.radius + p.length) * d))
    return np.array(lines, float).reshape(-1, 2, 3)


class Elements:
    """The installed elements (every rank alike) and their stepping; ``names`` their
    entries in install order."""

    def __init__(self, scene):
        self.scene = scene
        self.entries = {r.name: r for r in scene.reinforcement}
        self.installed: list[str] = []
        z = np.zeros
        self.x, self.v, self.last = z((0, 3)), z((0, 3)), z((0, 3))
        self.ax, self.av, self.force, self.reaction = z((0, 3)), z((0, 3)), z((0, 3)), z((0, 3))
        self.mass, self.imass, self.kg, self.sg, self.slip = z(0), z(0), z(0), z(0), z(0)
        self.grout = z(0)  # the grout's axial force on each node (N)
        self.local = z((0, 3))  # a rigid host's anchor: the point in its body frame
        # a zoned host's: the host tetrahedron's gridpoints (the grid's own numbers) and the
        # anchor's barycentric weights in it
        self.zoned = z(0, np.uint8)
        self.tet_nodes, self.tet_w = z((0, 4), np.int64), z((0, 4))
        self.grid_base = z(0, np.int64)  # the host grid's first gridpoint here, -1 elsewhere
        self.host = z(0, np.int64)
        self.anchored, self.slaved = z(0, np.uint8), z(0, np.uint8)
        self.node_seg = z((0, 2), np.int64)
        self.seg_a, self.seg_b = z(0, np.int64), z(0, np.int64)
        self.L0, self.EA, self.y_t, self.y_c = z(0), z(0), z(0), z(0)
        self.eps_p, self.fail, self.ks, self.cap = z(0), z(0), z(0), z(0)
        self.eps_p0 = z(0)  # the plastic strain installed (a pretension's)
        self.broken = z(0, np.uint8)
        self.d0, self.dp = z((0, 3)), z((0, 3))
        self.axial, self.shear = z(0), z(0)
        self.seg_element = z(0, np.int64)
        self.element_entry: list[str] = []  # the entry of each element (line)
        self.work = z(cables.CW_WIDTH)
        self.stored = 0.0
        self.rows = z(0, np.int64)  # the hosts' rows here (owned), -1 elsewhere
        self.k_node = z(0)

    @property
    def n_nodes(self) -> int:
        return len(self.x)

    def pending(self, k: int | None) -> list[str]:
        """The entries installed at the start (``k`` None) or by stage ``k``."""
        by_stage = {n for st in self.scene.stages for n in st.reinforce}
        if k is None:
            return [r.name for r in self.scene.reinforcement if r.name not in by_stage]
        return list(self.scene.stages[k].reinforce)

    # ------------------------------------------------------------------ installation
    def install(self, s, names: list[str]) -> None:
        """Install the entries ``names`` (collective): nodes along each element, each in the
        block that holds it (its anchor: the block's material point there)."""
        if not names:
            return
        for name in names:
            self._install_entry(s, self.entries[name])
            self.installed.append(name)
        self.bind(s)
        self._node_stiffness()

    def _install_entry(self, s, e, hosts=None) -> None:
        """Nodes and segments of entry ``e``; ``hosts``: their hosts and body-frame points
        as installed (a restart), else found now."""
        lines = element_lines(e)
        nseg = e.segments
        t = np.linspace(0.0, 1.0, nseg + 1)
        pts = lines[:, 0, None, :] + t[None, :, None] * (lines[:, 1] - lines[:, 0])[:, None, :]
        pts = pts.reshape(-1, 3)
        host, local, zoned, tet_nodes, tet_w = self._hosts(s, pts, e.name) if hosts is None \
            else hosts
        k = len(lines)
        n0, s0, el0 = self.n_nodes, len(self.seg_a), len(self.element_entry)
        seg_len = np.linalg.norm(lines[:, 1] - lines[:, 0], axis=1) / nseg
        trib = np.repeat(seg_len, nseg + 1).reshape(k, nseg + 1).copy()
        trib[:, [0, -1]] *= 0.5  # (an end node carries half a segment)
        trib = trib.ravel()
        kg = (e.grout.stiffness if e.grout else 0.0) * trib
        sg = (e.grout.strength if e.grout else 0.0) * trib
        slaved = np.zeros((k, nseg + 1), np.uint8)
        if "from" in e.anchors:
            slaved[:, 0] = 1
        if "to" in e.anchors:
            slaved[:, -1] = 1
        idx = n0 + np.arange(k * (nseg + 1)).reshape(k, nseg + 1)
        a = idx[:, :-1].ravel()
        b = idx[:, 1:].ravel()
        segs = s0 + np.arange(k * nseg).reshape(k, nseg)
        node_seg = np.full((k, nseg + 1, 2), -1, np.int64)
        node_seg[:, 1:, 0] = segs
        node_seg[:, :-1, 1] = segs
        ea = e.young * e.area
        dowel = e.model == "rockbolt"
        crosses = host[a - n0] != host[b - n0]
        mass = e.density * e.area * trib
        self._append(
            x=pts, v=np.zeros_like(pts), last=np.zeros_like(pts), ax=pts.copy(),
            av=np.zeros_like(pts), force=np.zeros_like(pts), reaction=np.zeros_like(pts),
            mass=mass, imass=mass.copy(), kg=kg, sg=sg, slip=np.zeros(len(pts)), local=local,
            zoned=zoned, tet_nodes=tet_nodes, tet_w=tet_w, grid_base=np.full(len(pts), -1),
            grout=np.zeros(len(pts)),
            host=host, anchored=(host >= 0).astype(np.uint8), slaved=slaved.ravel(),
            node_seg=node_seg.reshape(-1, 2))
        m = k * nseg
        self._append(
            seg_a=a, seg_b=b, L0=np.repeat(seg_len, nseg), EA=np.full(m, ea),
            y_t=np.full(m, e.yield_tension), y_c=np.full(m, e.yield_compression),
            eps_p=np.full(m, -e.pretension / ea), eps_p0=np.full(m, -e.pretension / ea),
            fail=np.full(m, e.failure_strain),
            ks=np.where(crosses, e.shear_stiffness or 0.0, 0.0) if dowel else np.zeros(m),
            cap=np.full(m, e.shear_strength), broken=np.zeros(m, np.uint8),
            d0=pts[b - n0] - pts[a - n0], dp=np.zeros((m, 3)), axial=np.zeros(m),
            shear=np.zeros(m), seg_element=el0 + np.repeat(np.arange(k), nseg))
        self.element_entry += [e.name] * k

    def _append(self, **cols) -> None:
        for key, v in cols.items():
            setattr(self, key, np.concatenate([getattr(self, key), v]))

    def _hosts(self, s, pts: np.ndarray, name: str) -> tuple:
        """The block holding each point (the deepest inside; a tie: the lower gid) and its
        anchor there: the point in a rigid block's body frame, or a zoned block's
        tetrahedron and weights (collective: each rank looks among the blocks it owns).
        Returns the :data:`HOST_COLUMNS`."""
        b, n = s.blocks, s.n_owned
        tol = HOST_TOLERANCE_FRACTION * s.ctol
        k = len(pts)
        best = np.full(k, -np.inf)
        gid = np.full(k, -1, np.int64)
        local = np.zeros((k, 3))
        zoned = np.zeros(k, np.uint8)
        tet_nodes, tet_w = np.zeros((k, 4), np.int64), np.zeros((k, 4))
        grid_of = {} if s.grids is None else \
            {int(g): d for d, g in enumerate(s.grids.gids[:s.grids.n_owned])}
        for r in range(n):
            if b.out[r] != 0:
                continue
            near = np.all((pts >= b.lo[r] - tol) & (pts <= b.hi[r] + tol), axis=1)
            if not near.any():
                continue
            rows = np.nonzero(near)[0]
            g = int(b.gid[r])
            d = grid_of.get(g)
            if d is None:
                p = (pts[near] - b.x[r]) @ b.R[r]  # R^T (p - x), row by row
                depth = np.full(len(p), -np.inf)
                for pc in range(b.piece_start[r], b.piece_start[r + 1]):
                    f0, f1 = b.face_start[pc], b.face_start[pc + 1]
                    depth = np.maximum(depth, (b.offsets_local[f0:f1][None, :]
                                               - p @ b.normals_local[f0:f1].T).min(axis=1))
                nodes = weights = None
            else:
                depth, nodes, weights = _tetrahedra(s.grids, d, pts[near])
                p = np.zeros((len(rows), 3))
            take = (depth >= -tol) & ((depth > best[rows]) | ((depth == best[rows]) & (g < gid[rows])))
            hit = rows[take]
            best[hit], gid[hit], local[hit] = depth[take], g, p[take]
            zoned[hit] = d is not None
            if d is not None:
                tet_nodes[hit], tet_w[hit] = nodes[take], weights[take]
        found = allgather(s.comm, (best, gid, local, zoned, tet_nodes, tet_w))
        best = np.full(k, -np.inf)
        gid = np.full(k, -1, np.int64)
        for d_, g, p, zd, tn, tw in found:
            take = (g >= 0) & ((d_ > best) | ((d_ == best) & ((gid < 0) | (g < gid))))
            best[take], gid[take], local[take] = d_[take], g[take], p[take]
            zoned[take], tet_nodes[take], tet_w[take] = zd[take], tn[take], tw[take]
        missing = np.nonzero(gid < 0)[0]
        if len(missing):
            raise ConfigError([f"reinforcement {name!r}: node at ({', '.join(f'{c:.4g}' for c in pts[i])}) "
                               "lies in no block" for i in missing[:5]]
                              + ([f"... and {len(missing) - 5} more"] if len(missing) > 5 else []))
        return gid, local, zoned, tet_nodes, tet_w

    def bind(self, s) -> None:
        """The hosts' rows among this rank's owned blocks (after every rebuild), and the
        anchors of hosts that left the model released (their nodes' grout let go)."""
        b, n = s.blocks, s.n_owned
        owned = b.gid[:n]
        pos = np.searchsorted(owned, self.host)
        pos = np.minimum(pos, max(n - 1, 0))
        mine = owned[pos] == self.host if n else np.zeros(len(self.host), bool)
        self.rows = np.where(mine & (self.zoned == 0), pos, -1).astype(np.int64)
        self.grid_base[:] = -1
        g = s.grids
        if g is not None and self.zoned.any():
            base = {int(gid): int(g.node_start[d]) for d, gid in enumerate(g.gids[:g.n_owned])}
            for i in np.nonzero(self.zoned)[0]:
                self.grid_base[i] = base.get(int(self.host[i]), -1)
        gone = s.glob.out[np.maximum(self.host, 0)] != 0
        self.anchored[gone] = 0

    def _node_stiffness(self) -> None:
        """Each node's springs' stiffness (pdem.dynamics.cables.node_stiffness): its step's,
        and what a zoned host's gridpoints take into their masses."""
        self.k_node = cables.node_stiffness(self.n_nodes, self.seg_a, self.seg_b, self.L0,
                                            self.EA, self.ks, self.kg)

    # ------------------------------------------------------------------ stepping
    def anchors(self, s) -> None:
        """The anchors' positions and velocities, from their hosts' owners (collective)."""
        b = s.blocks
        both = np.zeros((self.n_nodes, 6))  # (positions and velocities: one reduction)
        ax, av = both[:, :3], both[:, 3:]
        cables.rigid_anchors(self.rows, self.local, b.x, b.R, b.v, b.w, ax, av)
        if s.grids is not None:
            cables.zoned_anchors(self.grid_base, self.tet_nodes, self.tet_w, s.grids.nodes,
                                 s.grids.vel, ax, av)
        both = allreduce_sum_array(s.comm, both)
        self.ax[:] = both[:, :3]
        self.av[:] = both[:, 3:]

    def step(self, s) -> None:
        """A step of the elements after the blocks' motion (collective): the nodes to t+dt
        from their forces at t, then the forces at t+dt onto the hosts."""
        if not self.n_nodes:
            return
        self.anchors(s)
        g = s.gravity
        cables.move_nodes(s.damping_args(), s.dt, g[0], g[1], g[2], self.x, self.v,
                          self.force, self.last, self.mass, self.imass, self.slaved,
                          self.anchored, self.ax, self.av, self.work)
        self._forces(s)

    def forces(self, s) -> None:
        """The elements' forces at the state as it stands onto the hosts (collective)."""
        if not self.n_nodes:
            return
        self.anchors(s)
        self._forces(s)

    def _forces(self, s) -> None:
        self.stored = cables.element_forces(
            self.x, self.ax, self.anchored, self.slaved, self.node_seg, self.kg, self.sg,
            self.slip, self.seg_a, self.seg_b, self.L0, self.EA, self.y_t, self.y_c, self.eps_p,
            self.fail, self.broken, self.ks, self.cap, self.d0, self.dp, self.force,
            self.reaction, self.axial, self.shear, self.grout, self.work)
        b = s.blocks
        cables.rigid_reactions(self.rows, self.ax, self.reaction, b.x, b.force, b.moment)
        if s.grids is not None:  # (and their stiffness into the gridpoints' masses)
            cables.zoned_reactions(self.grid_base, self.tet_nodes, self.tet_w, self.reaction,
                                   self.k_node, s.grids.force, s.grids.kc)

    # ------------------------------------------------------------------ step and energy
    def limit(self, dt: float, scaled: bool, frac: float = NODE_STEP_FRACTION) -> float:
        """The step with the nodes (every rank alike): without mass scaling the nodes'
        stable step ``frac sqrt(2 m / k)`` (``sqrt(2 m / k)`` bounds the critical step of a
        node with its springs from below: Gershgorin's bound of its row) lowers ``dt``; with
        it (``scaled``) the nodes are made heavy enough for ``dt``."""
        k = self.k_node
        moving = (self.slaved == 0) & (k > 0.0)
        self.imass[:] = self.mass
        if not moving.any():
            return dt
        if scaled:
            need = 0.5 * k * (dt / frac) ** 2
            self.imass[moving] = np.maximum(self.mass[moving], need[moving])
            return dt
        return min(dt, float(frac * np.sqrt(2.0 * self.mass[moving] / k[moving]).min()))

    def energies(self) -> tuple[float, float, np.ndarray]:
        """(elastic energy held, nodes' kinetic energy, the work accumulators)."""
        ke = cables.kinetic(self.v, self.imass, self.slaved, self.anchored) if self.n_nodes \
            else 0.0
        return self.stored, ke, self.work

    # ------------------------------------------------------------------ output
    def snapshot(self) -> dict[str, np.ndarray]:
        """The elements now as the output holds them (pdem.io.elements)."""
        state = np.zeros(len(self.seg_a), np.int64)
        state[(self.eps_p != self.eps_p0) & (self.broken == 0)] |= YIELDED
        on = (self.sg > 0) & (np.abs(self.grout) >= self.sg * (1 - 1e-12))
        state[on[self.seg_a] | on[self.seg_b]] |= SLIPPING
        state[self.broken != 0] |= BROKEN
        state[(self.cap > 0) & (self.shear >= self.cap * (1 - 1e-12))] |= DOWEL_YIELDED
        return {"points": self.x.copy(), "slip": self.slip.copy(),
                "segments": np.stack([self.seg_a, self.seg_b], axis=1),
                "axial": self.axial.copy(), "shear": self.shear.copy(), "state": state,
                "element": self.seg_element.copy()}

    def entries_of(self) -> list[str]:
        """The entry name of each element (line), in element order."""
        return list(self.element_entry)

    # ------------------------------------------------------------------ checkpoint
    def saved(self) -> dict[str, np.ndarray]:
        """The state a checkpoint holds (every rank alike)."""
        out = {k: getattr(self, k) for k in NODE_STATE + SEGMENT_STATE}
        out["work"] = self.work
        out.update({k: getattr(self, k) for k in HOST_COLUMNS})
        out["stored"] = np.array([self.stored])
        return out

    def held(self) -> dict[str, np.ndarray]:
        """A copy of the state (a factor-of-safety search starts each trial from it)."""
        return {k: np.array(v, copy=True) for k, v in self.saved().items()}

    def put_back(self, held: dict[str, np.ndarray]) -> None:
        """The state of :meth:`held` again (the hosts' rows are bound by the rebuild)."""
        for k in NODE_STATE + SEGMENT_STATE:
            getattr(self, k)[:] = held[k]
        self.work[:] = held["work"]
        self.stored = float(held["stored"][0])

    def restored(self, s, installed: list[str], saved: dict) -> None:
        """Reinstall ``installed`` with the checkpoint's hosts and body-frame points (the
        blocks have moved since) and continue from its state ``saved`` (every rank alike)."""
        self.installed = []
        for name in installed:
            e = self.entries[name]
            n0 = self.n_nodes
            n1 = n0 + len(element_lines(e)) * (e.segments + 1)
            self._install_entry(s, e, tuple(saved[k][n0:n1] for k in HOST_COLUMNS))
            self.installed.append(name)
        for k in NODE_STATE + SEGMENT_STATE:
            getattr(self, k)[:] = saved[k]
        self.work[:] = saved["work"]
        self.stored = float(saved["stored"][0])
        self.bind(s)
        self._node_stiffness()


def install_elements(s, scene, k: int | None) -> bool:
    """Install the entries of the start (``k`` None) or of stage ``k`` (collective) and take
    the nodes into the step (``scene``: the stage's, whose solve settings apply); whether any
    was installed."""
    elements = s.reinforcement
    names = elements.pending(k)
    elements.install(s, names)
    element_step(s, scene)
    return bool(names)


def element_step(s, scene) -> None:
    """The step with the installed nodes under ``scene``'s solve settings (every rank alike):
    lowered to theirs without mass scaling (logged), or their masses scaled to it."""
    elements = s.reinforcement
    if elements is None or not elements.n_nodes:
        return
    sv = scene.solve
    dt = elements.limit(s.dt, bool(sv.mass_scaling))
    if dt < s.dt and s.comm.rank == 0:
        log.info("reinforcement: the step is %.4g s (the nodes' stable step; the blocks' "
                 "%.4g s): give solve.mass_scaling to keep the blocks' step in a static "
                 "solve", dt, s.dt)
    s.dt = dt


def _tetrahedra(grids, d: int, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point, the tetrahedron of owned grid ``d`` that holds it best: (depth, its
    gridpoints (k, 4) in the grid's numbering, the barycentric weights (k, 4)); ``depth`` is
    the least weight times the tetrahedron's size (negative: outside every one)."""
    n0, n1 = grids.node_start[d], grids.node_start[d + 1]
    z0, z1 = grids.zone_start[d], grids.zone_start[d + 1]
    x = grids.nodes[n0:n1]
    tets = grids.tets[z0:z1]
    a = x[tets[:, 0]]
    m = np.stack([x[tets[:, 1]] - a, x[tets[:, 2]] - a, x[tets[:, 3]] - a], axis=2)  # (t, 3, 3)
    inv = np.linalg.inv(m)
    size = np.cbrt(np.abs(np.linalg.det(m)))
    depth = np.full(len(pts), -np.inf)
    nodes = np.zeros((len(pts), 4), np.int64)
    weights = np.zeros((len(pts), 4))
    for i, p in enumerate(pts):
        lam = np.einsum("tij,tj->ti", inv, p - a)
        w = np.concatenate([1.0 - lam.sum(axis=1)[:, None], lam], axis=1)
        score = w.min(axis=1) * size
        j = int(np.argmax(score))
        depth[i], nodes[i], weights[i] = score[j], tets[j], w[j]
    return depth, nodes, weights
