"""Scene -> blocks: shapes from the scene file, mass properties, the BlockStore."""

from __future__ import annotations

import numpy as np

from ..config import ConfigError
from ..config.schema import Scene
from ..deformable.zoning import identity_frames, zone_specs
from ..dynamics.rotation import quat_to_matrix
from ..geometry import GeometryError, face_areas
from ..mpi import LOCAL, allgather, run_together
from ..registry import Registry
from .blocks import VERT_ROW, BlockStore
from .fields import BLOCK, allocate
from .mesh_blocks import mesh_blocks
from .names import NameColumn
from .rockmass import build_rock_mass
from .runs import RunColumn
from .shapes import SHAPES, family_size
from .spec import BlockSpec
from .speclist import RemoteRun, SpecList, UnbuiltRun, spec_parts, spec_summary


class SpecView:
    """One block of a :class:`SpecTable`, read like a released :class:`BlockSpec`."""

    __slots__ = ("_t", "_g")

    def __init__(self, table: SpecTable, gid: int):
        self._t, self._g = table, gid

    pieces = None  # released: the geometry lives with the blocks' owners

    name = property(lambda self: self._t.names[self._g])
    parent = property(lambda self: self._t.parent_of(self._g))
    entry = property(lambda self: int(self._t.entry[self._g]))
    spec = property(lambda self: self._t.scene_blocks[self.entry])
    group = property(lambda self: self._t.labels[self._t.group[self._g]])
    material = property(lambda self: self._t.labels[self._t.material[self._g]])
    volume = property(lambda self: float(self._t.volume[self._g]))
    surface = property(lambda self: float(self._t.surface[self._g]))
    max_face = property(lambda self: float(self._t.max_face[self._g]))
    n_pieces = property(lambda self: int(self._t.n_pieces[self._g]))

    @property
    def excavate_at(self):
        if self._t.excavate_at is None:
            return None
        t = self._t.excavate_at[self._g]
        return None if np.isnan(t) else float(t)

    @property
    def excavate_stage(self):
        if self._t.excavate_stage is None:
            return None
        k = self._t.excavate_stage[self._g]
        return None if k < 0 else int(k)


def _names(parts):
    """Every block's name, part by part (an unbuilt run's made as they are read)."""
    for part in parts:
        if isinstance(part, UnbuiltRun):
            yield from (part.name(j) for j in range(part.count))
        elif isinstance(part, RemoteRun):
            yield from part.names
        else:
            yield from (sp.name for sp in part)


def _column(parts, of_spec, of_run, dtype, of_remote) -> RunColumn:
    """A per-block column, part by part: ``of_spec(spec)`` of each built spec, ``of_run(run)``
    for every member of an unbuilt run (one run: not expanded), ``of_remote(run)`` the rows
    of another rank's blocks."""
    return RunColumn.from_parts(
        [(part.count, of_run(part)) if isinstance(part, UnbuiltRun)
         else np.asarray(of_remote(part), dtype) if isinstance(part, RemoteRun)
         else np.fromiter((of_spec(sp) for sp in part), dtype, len(part)) for part in parts],
        dtype)


def _renumbered(values: list, index: np.ndarray, table: dict) -> np.ndarray:
    """``index`` into ``values`` (-1: none) as indices into ``table``, which takes the values
    it lacks in their order (as the built specs' values are taken, one by one)."""
    to = np.array([table.setdefault(v, len(table)) for v in values] + [-1], np.int32)
    return to[index]


class SpecTable:
    """The blocks' specs after set-up, as columns by gid instead of one Python object each:
    every rank keeps them for every block (names in messages, selections by name, group or
    stage). The names are runs of ``prefix[k]`` (:class:`pdem.model.names.NameColumn`) and
    the other columns runs of equal values (:class:`pdem.model.runs.RunColumn`), each plain
    where runs would not be smaller: an ``array:`` of cubes costs a few bytes an entry, a cut
    rock mass its geometric scalars (28 bytes a block). Indexing and iteration give
    :class:`SpecView` objects with the released spec's attributes."""

    def __init__(self, specs: list[BlockSpec], scene_blocks, columns: dict | None = None):
        """``columns``: the geometric scalars (:func:`geometry_columns`) of every block when
        the specs' pieces were dropped unmeasured (each rank measured its share and the
        columns were gathered, pdem.state); else read from the released specs."""
        self.scene_blocks = scene_blocks
        n = len(specs)
        parts = [part for _, part in spec_parts(specs)]
        self.names = NameColumn(_names(parts))
        # a block's parent (the scene block it was cut from): -1 for its own name (every
        # uncut block), else its row in ``parents`` (the few names that differ)
        parents: dict[str, int] = {}
        self.parent = _column(
            parts, lambda sp: -1 if sp.parent == sp.name
            else parents.setdefault(sp.parent, len(parents)), lambda run: -1, np.int32,
            lambda run: _renumbered(run.parents, run.parent, parents))
        self.parents = list(parents)
        labels: dict[str, int] = {}
        self.group = _column(
            parts, lambda sp: labels.setdefault(sp.group, len(labels)),
            lambda run: labels.setdefault(run.block.group, len(labels)), np.int32,
            lambda run: _renumbered(run.groups, run.group, labels))
        self.material = _column(
            parts, lambda sp: labels.setdefault(sp.material, len(labels)),
            lambda run: labels.setdefault(run.block.material, len(labels)), np.int32,
            lambda run: _renumbered(run.materials, run.material, labels))
        self.labels = list(labels)
        self.entry = _column(parts, lambda sp: sp.entry, lambda run: run.entry, np.int32,
                             lambda run: run.entry)
        if columns is None:
            columns = {k: np.fromiter((getattr(sp, k) for sp in specs), dt, n)
                       for k, dt in GEOMETRY_COLUMNS.items()}
        for k in GEOMETRY_COLUMNS:  # gathered as runs already (RunColumn.gathered), or rows
            c = columns[k]
            setattr(self, k, c if isinstance(c, RunColumn) else RunColumn(c))
        # excavation times and stages: columns only in scenes that excavate (unbuilt family
        # members never are: a scene that excavates builds every block)
        self.excavate_at = self.excavate_stage = None
        if any(sp.excavate_at is not None or sp.excavate_stage is not None
               for part in parts if isinstance(part, list) for sp in part) or any(
                (~np.isnan(part.excavate_at)).any() or (part.excavate_stage >= 0).any()
                for part in parts if isinstance(part, RemoteRun)):
            self.excavate_at = RunColumn(np.concatenate([np.zeros(0)] + [
                part.excavate_at if isinstance(part, RemoteRun)
                else np.full(part.count, np.nan) if isinstance(part, UnbuiltRun)
                else np.fromiter((np.nan if sp.excavate_at is None else sp.excavate_at
                                  for sp in part), float, len(part)) for part in parts]))
            self.excavate_stage = RunColumn(np.concatenate([np.zeros(0, np.int32)] + [
                part.excavate_stage if isinstance(part, RemoteRun)
                else np.full(part.count, -1, np.int32) if isinstance(part, UnbuiltRun)
                else np.fromiter((-1 if sp.excavate_stage is None else sp.excavate_stage
                                  for sp in part), np.int32, len(part)) for part in parts]))

    def excavation_times(self) -> np.ndarray:
        """Every block's excavation time (NaN: none), gid order."""
        if self.excavate_at is None:
            return np.full(len(self), np.nan)
        return np.asarray(self.excavate_at)

    def excavated_by_stage(self, k: int) -> np.ndarray:
        """Gids of the blocks stage ``k`` excavates."""
        if self.excavate_stage is None:
            return np.zeros(0, np.int64)
        return np.flatnonzero(np.asarray(self.excavate_stage) == k).astype(np.int64)

    def matching(self, gids, names=None, groups=None) -> np.ndarray:
        """Which of the blocks ``gids`` a selection's ``names`` and ``groups`` take (a mask;
        None: no condition): a block is named by its own name, its scene entry's or its
        parent's (the block it was cut from). From the columns, without a name or object a
        block (a selection over 10^6 blocks: milliseconds, not a second)."""
        gids = np.asarray(gids, np.int64)
        keep = np.ones(len(gids), bool)
        if names is not None:
            want = set(names)
            own = np.fromiter(self.names.positions(want).values(), np.int64)
            entries = [i for i, b in enumerate(self.scene_blocks) if b.name in want]
            parents = [k for k, p in enumerate(self.parents) if p in want]
            keep &= (np.isin(gids, own) | np.isin(self.entry[gids], entries)
                     | np.isin(self.parent[gids], parents))
        if groups is not None:
            want = set(groups)
            keep &= np.isin(self.group[gids], [k for k, g in enumerate(self.labels) if g in want])
        return keep

    @property
    def nbytes(self) -> int:
        """What the table keeps for its blocks (the columns and the names)."""
        return sum(c.nbytes for c in vars(self).values()
                   if isinstance(c, (RunColumn, NameColumn)))

    def parent_of(self, gid: int) -> str:
        k = self.parent[gid]
        return self.names[gid] if k < 0 else self.parents[k]

    def parent_names(self) -> ParentNames:
        """Every block's parent name, read one at a time (the output's ``blocks/parent``)."""
        return ParentNames(self)

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, gid) -> SpecView:
        return SpecView(self, int(gid))

    def __iter__(self):
        return (SpecView(self, g) for g in range(len(self.names)))


class ParentNames:
    """The sequence of a :class:`SpecTable`'s parent names, without a list of them."""

    def __init__(self, table: SpecTable):
        self._t = table

    def __len__(self) -> int:
        return len(self._t.names)

    def __getitem__(self, gid) -> str:
        return self._t.parent_of(int(gid))

    @property
    def max_bytes(self) -> int:
        own = self._t.names.lengths()[np.asarray(self._t.parent) < 0]
        return max([int(own.max(initial=0)), *(len(p.encode("utf-8")) for p in self._t.parents)])


# the per-block scalars of a spec's geometry that set-up reads for every block (stiffness
# estimate, contact tolerance, start checks, mass): the SpecTable's columns
GEOMETRY_COLUMNS = {"volume": float, "surface": float, "max_face": float, "n_pieces": np.int32}


def geometry_columns(specs: list[BlockSpec]) -> dict[str, np.ndarray]:
    """:data:`GEOMETRY_COLUMNS` of ``specs`` (with their pieces), each as the spec's own
    property computes it (bitwise): the face areas in one batch, one-piece blocks reduced in
    stacks of equal face counts (numpy reduces each row as it reduces the block's 1-D
    array), joined blocks one by one."""
    n = len(specs)
    face_areas([p for s in specs for p in s.pieces])  # one batch, kept on the pieces
    cols = {k: np.empty(n, dt) for k, dt in GEOMETRY_COLUMNS.items()}
    stacks: dict[int, list[int]] = {}
    for r, s in enumerate(specs):
        cols["n_pieces"][r] = len(s.pieces)
        if len(s.pieces) == 1:
            stacks.setdefault(s.pieces[0].n_faces, []).append(r)
            cols["volume"][r] = s.pieces[0].volume
        else:
            cols["volume"][r] = s.volume
            cols["surface"][r] = s.surface
            cols["max_face"][r] = s.max_face
    for rows in stacks.values():
        areas = np.array([specs[r].pieces[0].face_areas() for r in rows])
        cols["surface"][rows] = areas.sum(axis=1)
        cols["max_face"][rows] = areas.max(axis=1)
    return cols


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of rotation matrix R (Shepperd's method), w >= 0."""
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    if q[0] < 0:
        q = -q
    return q / np.linalg.norm(q)


def expand_blocks(scene: Scene, max_blocks: int | None = None, share=None,
                  comm=None) -> list[BlockSpec]:
    """Every block of the scene in gid order, shapes in the world frame: the ``blocks:``
    entries, then their cuts, joins and excavations (pdem.model.rockmass).

    ``share(n)``: the gids ``[lo, hi)`` whose shapes this rank needs, of ``n`` blocks; the
    members of families (``array``, ``random``) outside it are specs without pieces (a
    name, an entry, one piece), an array's never built. Only when the scene's blocks are
    known without building them: no cuts, joins, excavations or meshes (:func:`lazy_scene`).
    ``comm``: the ranks share the work of the cuts, joins and excavations (collective,
    pdem.model.rockmass.build_rock_mass); with ``share``, a scene that has them gives this
    rank's share of the blocks built and the others' names and scalars only (a
    :class:`SpecList` of :class:`RemoteRun` parts), else every rank gets every block."""
    errors: list[str] = []
    lo, hi = share(sum(family_size(b) or 1 for b in scene.blocks)) \
        if share is not None and lazy_scene(scene) else (0, None)
    # with a share, the family members outside it are runs, not an object each
    out = SpecList() if hi is not None else []
    # the list in segments: every rank's whole (True) or this rank's slice of a mesh (False)
    segments: list[tuple[bool, list]] = []
    for i, b in enumerate(scene.blocks):
        kind = b.shape_kind
        if kind == "mesh":
            segments += [(True, out), (False, mesh_blocks(scene, i, b, comm))]
            out = []
            continue
        entry = SHAPES[kind]
        size = family_size(b)
        g0 = len(out)
        built = None
        if hi is not None and size is not None:  # a family: its members in the share only
            built = range(min(max(lo - g0, 0), size), min(max(hi - g0, 0), size))
        # an array (builds_share) builds the members asked for; a random family draws every
        # member (one random sequence) and those outside the share are dropped as they come
        members = built if entry.builds_share and built is not None else None
        if members is not None:
            out.append_unbuilt(b, i, 0, members.start)
        try:
            args = (getattr(b, kind),) if members is None else (getattr(b, kind), members)
            for k, shape in entry.build(*args):
                if built is not None and k not in built:  # drawn for the sequence only
                    out.append_unbuilt(b, i, k, 1)
                    continue
                name = b.name if k is None else f"{b.name}[{k}]"
                pieces = shape if isinstance(shape, list) else [shape]
                out.append(BlockSpec(name, i, pieces, b, parent=name))
        except (GeometryError, ValueError) as exc:
            errors.append(f"blocks[{i}] ({b.name!r}).{kind}: {exc}")
            continue
        if members is not None:
            out.append_unbuilt(b, i, members.stop, size - members.stop)
    if errors:
        raise ConfigError(errors)
    comm = LOCAL if comm is None else comm
    if lazy_scene(scene):
        _zone(scene, comm, out)
        return out
    # the cuts, joins and excavations work on the list spread over the ranks; then each rank
    # keeps its build share's blocks and the others' names and scalars (``share``), or gets
    # every block
    spread = build_rock_mass(scene, [*segments, (True, out)], max_blocks, comm)
    del out, segments
    if share is not None:
        spread = spread.move_to(allgather(comm, share(spread.total)))
    _zone(scene, comm, spread.local)
    if share is None:
        return spread.whole()
    return SpecList.spread(spread.local, spread.start, spread.total,
                           allgather(comm, spec_summary(spread.local)), comm.rank, scene.blocks)


def _zone(scene: Scene, comm, specs) -> None:
    """Zone the zoned blocks among ``specs`` (those with pieces; collective: an error on one
    rank is raised on every rank)."""
    if any(b.zones is not None for b in scene.blocks):
        run_together(comm, lambda: zone_specs(scene, specs))


def lazy_scene(scene: Scene) -> bool:
    """Whether every block of the scene is known by its entry and member index alone (no
    cut, join, excavation or mesh changes what the entries make)."""
    return not (scene.cuts or scene.join or scene.excavate
                or any(st.excavate for st in scene.stages)
                or any(b.mesh is not None for b in scene.blocks))


def _fixed(spec, arr, r):
    arr["fixed"][r] = spec.fixed


def _velocity(spec, arr, r):
    # a fixed block has no velocity; a prescribed one keeps it (velocity_fixed)
    arr["vfix"][r] = spec.velocity_fixed
    if not spec.fixed:
        arr["v"][r] = spec.velocity
        arr["w"][r] = spec.angular_velocity


def _force(spec, arr, r):
    arr["applied_force"][r] = spec.force


# Conditions on blocks by scene key: each sets the block's static fields (pdem.model.fields)
# from its ``blocks[i]`` entry; the motion kernel reads those fields. ``apply(spec, arr, r)``
# is called once per entry with ``r`` the index array of all its blocks' rows (an array's
# members at once), so it must assign with numpy indexing, not take ``r`` as one int.
BLOCK_CONDITIONS: Registry = Registry("block condition")
for _name, _apply in (("fixed", _fixed), ("velocity", _velocity), ("force", _force)):
    BLOCK_CONDITIONS.register(_name, _apply)


def block_store(scene: Scene, specs: list[BlockSpec], lo: int = 0, hi: int | None = None):
    """BlockStore of the scene's blocks ``lo .. hi-1`` (gids; default: every block), body
    frame = principal axes; returns (store, sorted group names of the whole scene).

    Only the specs of ``lo .. hi-1`` need their pieces (a rank builds its share, pdem.state);
    the others give their group and piece count. Vectorised over the blocks (one-piece
    blocks in batches of the same vertex and face counts, joined blocks one by one), with
    numpy and LAPACK called on the same per-block operands as the per-block code it
    replaces: the store is bitwise the same (tests compare it) for any share, in a fraction
    of the time for a large model."""
    hi = len(specs) if hi is None else hi
    runs = isinstance(specs, SpecList)
    groups = sorted({b.group for b in scene.blocks if b.mesh is None}
                    | (specs.groups() if runs else {s.group for s in specs}))
    # the global ordinal of the share's first piece (contact keys name pieces by it)
    first_piece = specs.n_pieces_before(lo) if runs else sum(s.n_pieces for s in specs[:lo])
    specs = specs[lo:hi]
    n = len(specs)
    arr = allocate(BLOCK, n)
    frames = _body_frames(specs)
    # per piece, gid order: the world piece (topology) and its body-frame geometry
    pieces = [p for s in specs for p in s.pieces]
    piece_start = np.zeros(n + 1, np.int64)
    np.cumsum([len(s.pieces) for s in specs], out=piece_start[1:])
    counts = np.array([(len(p.vertices), len(p.face_start) - 1, len(p.face_verts), len(p.edges))
                       for p in pieces], np.int64).reshape(-1, 4)
    starts = np.zeros((len(pieces) + 1, 4), np.int64)
    np.cumsum(counts, axis=0, out=starts[1:])
    body, radius = _place_frames(frames, arr, piece_start, starts)
    arr["gid"][:] = np.arange(lo, lo + n)
    arr["owned"][:] = 1
    arr["x0"][:] = arr["x"]
    arr["x_stage"][:] = arr["x"]
    _frame_quaternions(frames, arr)
    _block_fields(scene, specs, arr, groups, radius)
    # a zoned piece's edge directions are all its edges (identity_frames): no merging
    zoned = np.array([s.zoning is not None for s in specs for _ in s.pieces], bool)
    geometry = _store_geometry(pieces, counts, starts, piece_start, first_piece, zoned, **body)
    if zoned.any():
        identity_frames(geometry, arr, specs)
    return BlockStore(arr, geometry), groups


def _place_frames(frames, arr, piece_start: np.ndarray, starts: np.ndarray):
    """The blocks' principal frames (:func:`_body_frames`) into their rows: centroid ``x``
    and per-unit-density ``inertia`` into ``arr``; returns the pieces' body-frame geometry
    (``verts_local``, ``normals_local``, ``offsets_local``, ``centers``: of a joined block's
    pieces, else zero) by the CSR ``starts`` (vertices, faces) and every block's radius."""
    n, n_pieces = len(piece_start) - 1, len(starts) - 1
    vert_start, face_start = starts[:, 0], starts[:, 1]
    verts_local = np.empty((starts[-1, 0], 3))
    normals_local = np.empty((starts[-1, 1], 3))
    offsets_local = np.empty(starts[-1, 1])
    centers = np.zeros((n_pieces, 3))
    radius = np.empty(n)
    for rows, c, _, moments, bv, bn, bo in frames:
        arr["x"][rows] = c
        arr["inertia"][rows] = moments  # per unit density here, times rho below
        if isinstance(rows, np.ndarray):  # a batch of one-piece blocks
            prow = piece_start[rows]
            idx = vert_start[prow, None] + np.arange(bv.shape[1])
            verts_local[idx] = bv
            fidx = face_start[prow, None] + np.arange(bn.shape[1])
            normals_local[fidx] = bn
            offsets_local[fidx] = bo
            radius[rows] = np.linalg.norm(bv, axis=2).max(axis=1)
        else:  # a joined block: its pieces in the body frame (bv: the bodies)
            for j, body in enumerate(bv):
                k = piece_start[rows] + j
                verts_local[vert_start[k]:vert_start[k + 1]] = body.vertices
                normals_local[face_start[k]:face_start[k + 1]] = body.normals
                offsets_local[face_start[k]:face_start[k + 1]] = body.offsets
                centers[k] = body.centroid
            radius[rows] = max(np.linalg.norm(b.vertices, axis=1).max() for b in bv)
    return dict(verts_local=verts_local, normals_local=normals_local,
                offsets_local=offsets_local, centers=centers), radius


def _frame_quaternions(frames, arr) -> None:
    """Every block's orientation ``q`` from its frame's R: one quaternion per distinct R
    (bitwise): blocks of one shape share a few frames."""
    for rows, _, R, _, _, _, _ in frames:
        if R.ndim == 2:  # a joined block: its one frame (np.unique of one row: ~75 us)
            arr["q"][rows] = quat_from_matrix(R)
            continue
        R = R.reshape(-1, 3, 3)
        _, first, inverse = np.unique(R.reshape(len(R), 9).view(np.uint64), axis=0,
                                      return_index=True, return_inverse=True)
        q = np.array([quat_from_matrix(R[i]) for i in first])
        arr["q"][rows] = q[inverse.ravel()].reshape(-1, 4) if np.ndim(rows) else q[0]


def _block_fields(scene: Scene, specs, arr, groups: list[str], radius: np.ndarray) -> None:
    """The per-block fields from the scene: mass and inertia (the frames' per unit density,
    times the material's), material and group ids, the conditions of each block's entry
    (:data:`BLOCK_CONDITIONS`), the radius and the initial angular momentum."""
    mats = {m: i for i, m in enumerate(scene.materials)}
    group_index = {g: i for i, g in enumerate(groups)}
    rho = np.array([scene.materials[s.material].density for s in specs], float)
    arr["mass"][:] = rho * np.array([s.volume for s in specs], float)
    arr["inertia"][:] *= rho[:, None]
    arr["mscale"][:] = 1.0
    arr["material"][:] = [mats[s.material] for s in specs]
    arr["group"][:] = [group_index[s.group] for s in specs]
    by_entry: dict[int, list[int]] = {}
    for r, s in enumerate(specs):
        by_entry.setdefault(id(s.spec), []).append(r)
    for rows in by_entry.values():
        for apply in BLOCK_CONDITIONS.values():
            apply(specs[rows[0]].spec, arr, np.array(rows, np.int64))
    arr["radius"][:] = radius
    # world angular momentum from the initial angular velocity: L = R diag(I) R^T w (zero
    # for a block at rest)
    for r in np.nonzero((arr["w"] != 0.0).any(axis=1))[0]:
        Rm = quat_to_matrix(arr["q"][r])
        arr["L"][r] = Rm @ (arr["inertia"][r] * (Rm.T @ arr["w"][r]))


def _store_geometry(pieces, counts: np.ndarray, starts: np.ndarray, piece_start: np.ndarray,
                    first_piece: int, zoned: np.ndarray, verts_local, normals_local, offsets_local, centers
                    ) -> dict[str, np.ndarray]:
    """The store's geometry columns (pdem.model.blocks) of ``pieces`` (gid order; ``counts``:
    each one's vertices, faces, face vertices and edges, ``starts`` their running sums):
    the world pieces' topology (a rigid motion keeps it) with vertex ids made store rows,
    and the body-frame geometry (:func:`_place_frames`); ``zoned``: by piece, its edge
    directions are left unmerged."""
    n, n_pieces = len(piece_start) - 1, len(pieces)
    vert_start, face_start, edge_start = starts[:, 0], starts[:, 1], starts[:, 3]
    v0 = vert_start[:-1]
    face_verts = np.concatenate([p.face_verts for p in pieces]) + np.repeat(v0, counts[:, 2]) \
        if pieces else np.zeros(0, np.int64)
    # a face's vertex count: the difference of the concatenated face_start, less the one
    # across each piece's end; their running sum is fvert_start
    fs = np.concatenate([p.face_start for p in pieces]) if pieces else np.zeros(1, np.int64)
    fsizes = np.delete(np.diff(fs), np.cumsum(counts[:, 1] + 1)[:-1] - 1)
    fvert_start = np.zeros(len(fsizes) + 1, np.int64)
    np.cumsum(fsizes, out=fvert_start[1:])
    edges = np.concatenate([p.edges for p in pieces]).reshape(-1, 2) \
        + np.repeat(v0, counts[:, 3])[:, None] if pieces else np.zeros((0, 2), np.int64)
    face_tag = np.full(starts[-1, 1], -1, np.int32)  # -1: a face no cut made
    for k, p in enumerate(pieces):
        if p.face_tag is not None:
            face_tag[face_start[k]:face_start[k + 1]] = p.face_tag
    edirs, edir_start = _edge_directions(verts_local, edges.astype(np.int64), edge_start,
                                       zoned)
    return dict(
        piece_start=piece_start,
        piece_block=np.repeat(np.arange(n), np.diff(piece_start)),
        piece_gid=np.arange(first_piece, first_piece + n_pieces, dtype=np.int64),
        piece_center=centers,
        piece_x=np.zeros((n_pieces, 3)),
        piece_lo=np.zeros((n_pieces, 3)),
        piece_hi=np.zeros((n_pieces, 3)),
        vert_start=vert_start.copy(),
        verts_local=verts_local,
        verts_world=np.zeros_like(verts_local),
        face_start=face_start.copy(),
        face_tag=face_tag,
        fvert_start=fvert_start,
        face_verts=face_verts.astype(VERT_ROW),
        normals_local=normals_local,
        offsets_local=offsets_local,
        edge_start=edge_start.copy(),
        edges=edges.astype(VERT_ROW),
        edir_start=edir_start,
        edirs_local=edirs,
    )


def _body_frames(specs: list[BlockSpec]):
    """The blocks' principal frames and body-frame geometry, as
    ``(rows, centroid, R, moments, verts, normals, offsets)`` records: ``rows`` an index
    array for a batch of one-piece blocks of equal vertex and face counts (stacked arrays,
    computed as :meth:`ConvexPolyhedron.principal_frame` computes one: batched ``eigh`` and
    ``matmul`` run the same LAPACK/BLAS call per block), or one int for a joined block
    (``verts``: its body-frame pieces, :meth:`BlockSpec.principal_frame`)."""
    batches: dict[tuple[int, int], list[int]] = {}
    out = []
    for r, s in enumerate(specs):
        if len(s.pieces) == 1:
            p = s.pieces[0]
            batches.setdefault((p.n_vertices, p.n_faces), []).append(r)
        else:
            bodies, c, R, moments = s.principal_frame()
            out.append((r, c, R, moments, bodies, None, None))
    for rows in batches.values():
        polys = [specs[r].pieces[0] for r in rows]
        moments, R = np.linalg.eigh(np.array([p.inertia for p in polys]))
        flip = np.linalg.det(R) < 0.0
        R[flip, :, 2] = -R[flip, :, 2]  # a right-handed frame, as principal_frame picks
        c = np.array([p.centroid for p in polys])
        normals = np.array([p.normals for p in polys])
        verts = (np.array([p.vertices for p in polys]) - c[:, None, :]) @ R
        offsets = np.array([p.offsets for p in polys]) - (normals @ c[:, :, None])[:, :, 0]
        out.append((np.array(rows, np.int64), c, R, moments, verts, normals @ R, offsets))
    return out


def _edge_directions(verts: np.ndarray, edges: np.ndarray, edge_start: np.ndarray,
                     unmerged: np.ndarray):
    """:func:`unique_directions` of every piece's edges (body frame), batched over the pieces
    with the same edge count: (directions, their CSR starts by piece). Same arithmetic per
    piece (the dot products are numpy's vector dot), so bitwise the same directions. Pieces
    ``unmerged`` keep every edge's direction (a zoned piece's surface grid: thousands of
    edges, whose pairwise test here is quadratic; pdem.deformable.zoning sets them)."""
    vec = verts[edges[:, 1]] - verts[edges[:, 0]]
    d = vec / np.linalg.norm(vec, axis=1)[:, None]
    n_edges = np.diff(edge_start)
    keep = np.zeros(len(d), bool)
    for k in np.nonzero(unmerged)[0]:
        keep[edge_start[k]:edge_start[k + 1]] = True
    for m in np.unique(n_edges[~unmerged]):
        sel = np.nonzero((n_edges == m) & ~unmerged)[0]
        D = d[edge_start[sel, None] + np.arange(m)]  # (pieces, m, 3)
        # pieces of one shape often have bitwise the same directions: decide each distinct
        # set once (the same operands give the same decisions)
        _, first, inverse = np.unique(D.reshape(len(sel), -1).view(np.uint64), axis=0,
                                      return_index=True, return_inverse=True)
        D = D[first]
        kept = np.zeros((len(first), m), bool)
        for i in range(m):
            merged = np.zeros(len(D), bool)
            for j in range(i):  # an earlier kept direction parallel to this one
                dot = np.matmul(D[:, i, None, :], D[:, j, :, None])[:, 0, 0]
                merged |= kept[:, j] & (np.abs(np.abs(dot) - 1.0) < _PARALLEL_TOL)
            kept[:, i] = ~merged
        keep[edge_start[sel, None] + np.arange(m)] = kept[inverse.ravel()]
    edir_start = np.zeros(len(edge_start), np.int64)
    piece_of = np.repeat(np.arange(len(n_edges)), n_edges)
    np.cumsum(np.bincount(piece_of[keep], minlength=len(n_edges)), out=edir_start[1:])
    return d[keep].reshape(-1, 3), edir_start


_PARALLEL_TOL = 1e-9


def unique_directions(vectors: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Unit directions of ``vectors`` with parallel ones (either sense) merged: the fast common
    plane's cost grows with the product of the two blocks' edge-direction counts."""
    d = vectors / np.linalg.norm(vectors, axis=1)[:, None]
    out: list[np.ndarray] = []
    for v in d:
        if not any(abs(abs(float(v @ u)) - 1.0) < tol for u in out):
            out.append(v)
    return np.array(out).reshape(-1, 3)
