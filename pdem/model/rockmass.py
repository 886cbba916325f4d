"""Scene -> rock mass: blocks cut by joint sets (``cuts:``), joined into concave blocks
(``join:``) and excavated (``excavate:``), as 3DEC's ``block cut joint-set``, ``block join``
and ``block excavate``.

Applied in that order to the blocks the ``blocks:`` entries make (pdem.model.build), once at
model build. The list of blocks is spread over the ranks (pdem.model.spread): each rank cuts,
joins and excavates the blocks of its slice, asking the others for the neighbours it needs,
so no rank holds every piece. It is plain numpy (the geometry it calls per piece is compiled:
the clips, the touch areas of pdem.geometry.intersection); the order of the resulting blocks
(their gids) depends only on the scene, not on the rank count.

* A cut splits every selected one-piece block by each plane of its set; faces made by cut ``i``
  carry face tag ``i`` (the contact between two faces of one set uses the set's joint,
  pdem.contact.joint_sets). After all cuts, the pieces of a scene block ``P`` are named
  ``P[k]``. Pieces thinner than ``cut_tolerance`` are not made (default: 1% of the size of the
  block being cut).
* A join makes one rigid body of several blocks that touch face to face (a concave block): one
  mass, centroid and inertia, contacts per convex piece, none between its own pieces. It takes
  the first member's name, place, motion and load; it is fixed if any member is (joining pieces
  to a fixed block makes them boundary); another member may not give a different motion/load.
* An excavation removes a convex region: blocks inside go, a straddling block is cut by the
  region's planes and the pieces of it outside the region that touch each other stay one
  (joined) block. With ``time > 0`` the inside pieces stay blocks of their own until then.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..config import ConfigError
from ..geometry import ConvexPolyhedron, GeometryError
from ..geometry.cutting import (
    UNTAGGED,
    box_planes,
    clip_below,
    cut_blocks,
    cylinder_planes,
    excavate,
    joint_set_planes,
)
from ..geometry.hull import default_tolerance
from ..geometry.intersection import halfspace_volume
from ..mpi import allgather, run_together
from .spread import Spread

# Relative sliver size: pieces thinner than this fraction of the cut block's size (cube root
# of its volume) are not created, unless ``cut_tolerance`` says otherwise.
AUTO_CUT_TOLERANCE = 0.01
# Two convex pieces "touch" (may be joined) when they share a face patch larger than this
# fraction of the smaller piece's size squared.
TOUCH_AREA = 1e-4


def build_rock_mass(scene, segments, max_blocks: int | None = None, comm=None) -> Spread:
    """The scene's blocks after its cuts, joins and excavations (gid order), spread over the
    ranks (:class:`pdem.model.spread.Spread`: each rank holds a contiguous slice, the slices
    in rank order the list one process builds; collective). ``segments``: the blocks the
    ``blocks:`` entries make, in order, as ``(whole, specs)``: every rank's specs alike
    (``whole``) or this rank's slice (a mesh's cells, pdem.model.mesh_blocks). ``comm``
    None: this process does it all."""
    spread = Spread.from_segments(comm, segments)
    if scene.cuts:
        spread = apply_cuts(scene, spread, max_blocks)
    if scene.join:
        spread = apply_joins(scene, spread)
    if scene.excavate or any(st.excavate for st in scene.stages):
        spread = apply_excavations(scene, spread)
    return spread


def _size(poly: ConvexPolyhedron) -> float:
    return float(poly.volume) ** (1.0 / 3.0)


def _cut_tolerance(scene, poly) -> float:
    if scene.cut_tolerance == "auto":
        return AUTO_CUT_TOLERANCE * _size(poly)
    return float(scene.cut_tolerance)


def _in_box(point, box) -> bool:
    return bool(np.all(np.asarray(point) >= box.min) and np.all(np.asarray(point) <= box.max))


def apply_cuts(scene, spread: Spread, max_blocks=None) -> Spread:
    """Cut the blocks by each joint set in turn (collective). Before each set the ranks'
    slices are moved so that each cuts about an even share of the set's work (the planes
    crossing its blocks); each rank cuts its own blocks and keeps their pieces in place."""
    comm = spread.comm
    limit = max_blocks if max_blocks is not None else np.inf
    for i, cut in enumerate(scene.cuts):
        where = f"{scene.at('cuts', i)} ({cut.name!r})"

        def chosen(s, cut=cut):
            return (len(s.pieces) == 1 and (cut.groups is None or s.group in cut.groups)
                    and (cut.range is None or _in_box(s.centroid, cut.range.box)))

        mine = [s.pieces[0].vertices for s in spread.local if chosen(s)]
        boxes = [b for b in allgather(comm, (np.min([v.min(axis=0) for v in mine], axis=0),
                                             np.max([v.max(axis=0) for v in mine], axis=0))
                                      if mine else None) if b is not None]
        del mine
        if not boxes:
            raise ConfigError([f"{where}: selects no block (range/groups; joined blocks are "
                               "not cut)"])
        try:
            normal, offsets = joint_set_planes(
                cut.dip, cut.dip_direction, cut.origin, cut.spacing, cut.count,
                (np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)))
        except GeometryError as exc:
            raise ConfigError([f"{where}: {exc}"]) from None

        def crossing(s, normal=normal, offsets=offsets):
            """The planes of the set crossing block ``s`` (each makes at most one more piece)."""
            proj = s.pieces[0].vertices @ normal
            return int(np.searchsorted(offsets, proj.max())
                       - np.searchsorted(offsets, proj.min(), side="right"))

        # refuse a set that would make too many blocks before cutting (a tiny spacing would
        # otherwise take hours): each block gets at most one piece per plane crossing it, +1
        planes = [crossing(s) if chosen(s) else -1 for s in spread.local]
        most = spread.total + sum(allgather(comm, sum(m for m in planes if m > 0)))
        if most > limit:
            raise ConfigError([f"{where}: would make up to {most} blocks, more than "
                               f"{int(limit)} (limits.max_blocks): a larger spacing, a range, "
                               "or a higher limits.max_blocks"])
        # the ranks' slices evened out by the set's work, then each cuts its own blocks
        spread = spread.rebalance([m + 1.0 if m >= 0 else 0.0 for m in planes])

        def cut_slice(spread=spread, i=i, normal=normal, offsets=offsets, chosen=chosen):
            out = []
            for s in spread.local:
                if not chosen(s):
                    out.append(s)
                    continue
                poly = s.pieces[0]
                pieces = cut_blocks([poly], i, normal, offsets,
                                    tol=_cut_tolerance(scene, poly))[0]
                out.extend(dataclasses.replace(s, pieces=[p]) for p in pieces)
            return out

        before = spread.total
        spread = spread.with_local(run_together(comm, cut_slice))
        if spread.total > limit:
            raise ConfigError([f"{where}: makes more than {int(limit)} blocks "
                               "(limits.max_blocks): a larger spacing, a range, or a higher "
                               "limits.max_blocks"])
        if spread.total == before:
            raise ConfigError([f"{where}: misses every block (no plane of the set cuts one; "
                               f"{len(offsets)} plane(s) through origin {list(cut.origin)})"])
    if scene.join_slivers > 0.0:
        spread = join_slivers(spread, scene.join_slivers)
    return _name_pieces(spread)


def join_slivers(spread: Spread, fraction: float, same_parent: bool = True) -> Spread:
    """Join every cut piece smaller than ``fraction`` of the median cut piece (by volume) to
    the block it shares the largest face with (smallest first; same material, group and
    excavation time; of the same parent block with ``same_parent``). Collective.

    Three sets leave small corner pieces even when no piece is thin along any one normal, and
    an excavation leaves corner bits of the blocks it cuts; the smallest block sets the
    timestep (eq. 87), so one sliver can cost 100x in run time. 3DEC users join them by hand;
    here they go into a neighbour, making it concave (fixed if the neighbour is).

    Every rank learns every block's volume, box and kind (~60 bytes a block), so each finds
    the same small pieces and neighbours. The face area between a small piece and each
    neighbour (nearly all the work) is measured by the rank holding the small piece, which
    asks for the neighbours it does not hold; the areas are shared, and every rank joins in
    the same order: the same blocks on any number of ranks. A group's pieces go to the rank
    holding its first block."""
    comm, local = spread.comm, spread.local
    count = spread.counts(lambda s: s.parent)
    vol = spread.gathered(np.array([s.volume for s in local], float))
    # a zoned piece is never joined (a zoned block is one convex piece; its step is its
    # zones', not its size's)
    is_cut = spread.gathered(np.array([count[s.parent] > 1 and s.spec.zones is None
                                       for s in local], bool))
    if not is_cut.any():
        return spread
    limit = fraction * float(np.median(vol[is_cut]))
    small = sorted((int(k) for k in np.flatnonzero(is_cut & (vol < limit))),
                   key=lambda k: (vol[k], k))
    if not small:
        return spread

    def kind(s):
        return (s.material, s.group, s.excavate_at, s.excavate_stage,
                s.parent if same_parent else None, s.spec.zones is not None)

    # every block's kind as a number, the same on every rank
    kinds: dict = {}
    for part in allgather(comm, list(dict.fromkeys(kind(s) for s in local))):
        for k in part:
            kinds.setdefault(k, len(kinds))
    kind_of = spread.gathered(np.array([kinds[kind(s)] for s in local], np.int64))
    del kinds
    lo = spread.gathered(np.array([np.min([p.vertices.min(axis=0) for p in s.pieces], axis=0)
                                   for s in local]).reshape(-1, 3))
    hi = spread.gathered(np.array([np.max([p.vertices.max(axis=0) for p in s.pieces], axis=0)
                                   for s in local]).reshape(-1, 3))
    boxes = _BoxQuery(lo, hi)
    # every (small piece, neighbour of its kind) pair whose face area the joining may read
    near_of = {}
    for k in small:
        pad = 1e-6 * vol[k] ** (1.0 / 3.0)
        near = boxes.meeting(lo[k] - pad, hi[k] + pad)
        near_of[k] = [int(j) for j in near if int(j) != k and kind_of[j] == kind_of[k]]
    del boxes, lo, hi, kind_of
    # the areas of the pairs of this rank's small pieces, with the neighbours it lacks asked for
    owner_rank = spread.owner_of(small)
    mine = [k for k, r in zip(small, owner_rank, strict=True) if r == comm.rank]
    first, last = spread.start, spread.start + len(local)
    held = spread.fetch([j for k in mine for j in near_of[k] if not first <= j < last])

    def spec(g):
        return local[g - first] if first <= g < last else held[g]

    def areas():
        return [sum(touch_area(p, q) for p in spec(k).pieces for q in spec(j).pieces)
                for k in mine for j in near_of[k]]

    measured = allgather(comm, run_together(comm, areas))
    held = {}
    area_of = {}
    for r, values in enumerate(measured):
        pairs = ((k, j) for k, o in zip(small, owner_rank, strict=True) if o == r
                 for j in near_of[k])
        area_of.update(zip(pairs, values, strict=True))
    owner = np.arange(spread.total)  # union-find over blocks

    def find(i):
        while owner[i] != i:
            owner[i] = owner[owner[i]]
            i = owner[i]
        return i

    for k in small:
        best, best_area = -1, 0.0
        for j in near_of[k]:
            if find(j) == find(k):
                continue
            area = area_of[k, j]
            if area > best_area:
                best, best_area = j, area
        if best >= 0 and best_area > TOUCH_AREA * vol[k] ** (2.0 / 3.0):
            a, b = find(k), find(best)
            owner[max(a, b)] = min(a, b)
    while True:  # every block's root (a group's root is its lowest index: members in order)
        up = owner[owner]
        if np.array_equal(up, owner):
            break
        owner = up
    joined = np.flatnonzero(owner != np.arange(spread.total))
    # this rank's groups: their other members' specs (wherever they are) come here
    roots = set(int(r) for r in owner[joined] if first <= r < last)
    members: dict[int, list[int]] = {r: [r] for r in sorted(roots)}
    for g in joined:
        if int(owner[g]) in members:
            members[int(owner[g])].append(int(g))
    held = spread.fetch([g for m in members.values() for g in m[1:] if not first <= g < last])
    out = []
    for g, s in enumerate(local, start=first):
        if g in members:
            group = [spec(j) for j in members[g]]
            block = s.spec
            if any(m.spec.fixed for m in group) and not block.fixed:
                block = block.model_copy(update={"fixed": True})
            out.append(dataclasses.replace(s, pieces=[p for m in group for p in m.pieces],
                                           spec=block))
        elif owner[g] == g:  # a block joined to none is passed on as it is, not remade
            out.append(s)
    return spread.with_local(out)


class _BoxQuery:
    """Which of many boxes meet a given box, without testing them all: the boxes sorted by
    their lower x, searched in the window a box of the usual width could start in; the few
    much wider ones (a base block under a cut region) are tested every time. Sliver joining
    asked every box for every small piece (quadratic: minutes at 10^5 pieces)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray):
        self.lo, self.hi = lo, hi
        width = hi[:, 0] - lo[:, 0]
        wide = width > 4.0 * float(np.median(width)) if len(width) else width > 0
        self.wide = np.flatnonzero(wide)
        self.order = np.flatnonzero(~wide)
        self.order = self.order[np.argsort(lo[self.order, 0], kind="stable")]
        self.starts = lo[self.order, 0]
        # (a hair wider than the widest: a width rounds, the window must not)
        self.reach = 1.000001 * float(width[~wide].max()) if (~wide).any() else 0.0

    def meeting(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Indices (ascending) of the boxes that meet ``[lo, hi]`` (touching counts)."""
        a = np.searchsorted(self.starts, lo[0] - self.reach, side="left")
        b = np.searchsorted(self.starts, hi[0], side="right")
        cand = np.concatenate([self.order[a:b], self.wide])
        meet = np.all((self.lo[cand] <= hi) & (self.hi[cand] >= lo), axis=1)
        return np.sort(cand[meet])


def _name_pieces(spread: Spread) -> Spread:
    """Pieces of scene block ``P`` (more than one) are named ``P[k]`` in build order
    (collective: a rank counts on from the pieces of ``P`` the ranks before it hold)."""
    count = spread.counts(lambda s: s.parent)
    seen = spread.counts_before(lambda s: s.parent)
    out = []
    for s in spread.local:
        if count[s.parent] == 1:
            out.append(dataclasses.replace(s, name=s.parent))
            continue
        k = seen[s.parent]
        seen[s.parent] = k + 1
        out.append(dataclasses.replace(s, name=f"{s.parent}[{k}]"))
    return spread.with_local(out)


# ---------------------------------------------------------------------------- contact of pieces
def touch_area(p: ConvexPolyhedron, q: ConvexPolyhedron) -> float:
    """Area of the face patch two convex pieces share (0 if they do not touch face to face):
    the volume of their intersection, each grown by a small ``eps`` (its face planes moved
    out by it), over ``2 eps``. Compiled (pdem.geometry.intersection): sliver joining asks it
    of every small piece and each neighbour."""
    eps = 1e-6 * min(_size(p), _size(q))
    normals = np.concatenate([p.normals, q.normals])
    offsets = np.concatenate([p.offsets, q.offsets]) + eps
    lo, hi = p.vertices.min(axis=0), p.vertices.max(axis=0)
    margin = float((hi - lo).max())  # holds p grown: its corners move by eps / sin(angle)
    return halfspace_volume(normals, offsets, lo - margin, hi + margin) / (2.0 * eps)


def _touch(p, q) -> bool:
    return touch_area(p, q) > TOUCH_AREA * min(_size(p), _size(q)) ** 2


def components(pieces: list[ConvexPolyhedron]) -> list[list[int]]:
    """Groups of pieces connected face to face (indices, each group ascending, groups by
    their first index)."""
    n = len(pieces)
    root = list(range(n))

    def find(i):
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    lo = np.array([p.vertices.min(axis=0) for p in pieces]).reshape(-1, 3)
    hi = np.array([p.vertices.max(axis=0) for p in pieces]).reshape(-1, 3)
    pad = 1e-6 * (hi - lo).max() if n else 0.0
    for i in range(n):
        # only pieces whose boxes meet can share a face
        near = np.nonzero(np.all((lo[i + 1:] <= hi[i] + pad) & (hi[i + 1:] >= lo[i] - pad),
                                 axis=1))[0] + i + 1
        for j in near:
            if find(i) != find(j) and _touch(pieces[i], pieces[int(j)]):
                root[find(int(j))] = find(i)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values())


# ---------------------------------------------------------------------------- joins
def apply_joins(scene, spread: Spread) -> Spread:
    """Join the blocks each ``join:`` entry names (collective: every rank learns where the
    named blocks are and gets their specs, checks every join alike and makes the joined
    block where its first member is)."""
    wanted = {name for names in scene.join for name in names}
    found: dict[str, int] = {}
    for part in allgather(spread.comm, {s.name: g for g, s in enumerate(spread.local,
                                                                        start=spread.start)
                                        if s.name in wanted}):
        for name, g in part.items():  # a repeated name: its last block, as one list reads
            found[name] = max(g, found.get(name, -1))
    specs = spread.fetch(list(found.values()))  # every rank checks every join alike
    member_of: dict[int, int] = {}
    errors = []
    for i, names in enumerate(scene.join):
        where = scene.at("join", i)
        rows = []
        for name in names:
            k = found.get(name)
            if k is None:
                errors.append(f"{where}: unknown block {name!r}")
            elif k in member_of:
                errors.append(f"{where}: block {name!r} is already in join[{member_of[k]}]")
            else:
                member_of[k] = i
                rows.append(k)
        zoned = [specs[k].name for k in rows if specs[k].spec.zones is not None]
        if zoned:
            # (a joined block is one body of convex pieces moving as one; a zoned one would be
            # one grid over pieces zoned apart, whose faces between them do not match)
            errors.append(f"{where}: {', '.join(map(repr, zoned))} zoned: a joined block is one "
                          "rigid concave body; keep zoned pieces as blocks of their own and "
                          "glue them with a joint_pairs joint of high cohesion and tension "
                          "(3DEC's glued contact; docs/deformable.md)")
            continue
        if len(rows) != len(names):
            continue
        first = specs[rows[0]]
        for k in rows[1:]:
            s = specs[k]
            # the joined block takes the first member's motion and load; another member may
            # repeat them or leave them unset, not contradict them
            moving = [(m.spec.velocity, m.spec.angular_velocity, m.spec.velocity_fixed,
                       m.spec.force) for m in (s, first)]
            unset = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), False, (0.0, 0.0, 0.0))
            if not (s.spec.fixed or first.spec.fixed) and moving[0] not in (moving[1], unset):
                errors.append(f"{where}: {s.name!r} and {first.name!r} differ in velocity, "
                              "angular_velocity, velocity_fixed or force: a joined block moves "
                              "as one (give them on the first member only)")
            if (s.material, s.group) != (first.material, first.group):
                errors.append(f"{where}: {s.name!r} has material/group {s.material!r}/"
                              f"{s.group!r}, {first.name!r} {first.material!r}/{first.group!r}: "
                              "a joined block has one of each")
        pieces = [p for k in rows for p in specs[k].pieces]
        groups = components(pieces)
        if len(groups) > 1:
            owner = np.repeat(rows, [len(specs[k].pieces) for k in rows])
            apart = sorted({specs[owner[j]].name for g in groups[1:] for j in g})
            errors.append(f"{where}: blocks {apart} do not touch the rest of the join face to "
                          f"face (joined blocks must form one connected body)")
    if errors:
        raise ConfigError(errors)
    out = []
    for k, s in enumerate(spread.local, start=spread.start):
        i = member_of.get(k)
        if i is None:
            out.append(s)
        elif found[scene.join[i][0]] == k:  # the first member leads: name and place
            members = [specs[found[name]] for name in scene.join[i]]
            pieces = [p for m in members for p in m.pieces]
            block = s.spec
            if any(m.spec.fixed for m in members):  # joined to a fixed block: part of it
                block = block.model_copy(update={"fixed": True})
            out.append(dataclasses.replace(s, pieces=pieces, spec=block))
    return spread.with_local(out)


# ---------------------------------------------------------------------------- excavations
def region_planes(exc) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals and offsets of an excavation's convex region."""
    kind = exc.region_kind
    r = getattr(exc, kind)
    if kind == "cylinder":
        return cylinder_planes(r.start, r.end, r.radius, r.sides)
    if kind == "box":
        return box_planes(r.min, r.max)
    n = np.asarray(r.normals, float)
    norm = np.linalg.norm(n, axis=1)
    if not (norm > 0).all():
        raise GeometryError("a plane normal is zero")
    return n / norm[:, None], np.asarray(r.offsets, float) / norm


def inside_part(poly: ConvexPolyhedron, normals, offsets, tol) -> ConvexPolyhedron | None:
    """The part of ``poly`` inside the convex region (None if thinner than ``tol``)."""
    inner = poly
    for n, d in zip(normals, offsets, strict=True):
        inner = clip_below(inner, n, d, tol, UNTAGGED)
        if inner is None:
            return None
    return inner


def _excavations(scene):
    """(where, excavation, stage index or None) in the order they are cut: the scene's, then
    each stage's (removed when that stage starts)."""
    for j, exc in enumerate(scene.excavate):
        yield f"{scene.at('excavate', j)} ({exc.region_kind})", exc, None
    for i, st in enumerate(scene.stages):
        for j, exc in enumerate(st.excavate):
            yield f"{scene.at('stages', i, 'excavate', j)} ({exc.region_kind})", exc, i


def apply_excavations(scene, spread: Spread) -> Spread:
    """Cut each excavation's region out of the blocks (collective: each rank its own
    blocks)."""
    comm = spread.comm
    for where, exc, stage in _excavations(scene):
        later = exc.time > 0.0 or stage is not None  # the inside stays a block until then
        try:
            normals, offsets = region_planes(exc)
        except GeometryError as exc_:
            raise ConfigError([f"{where}: {exc_}"]) from None

        def excavate_slice(exc=exc, stage=stage, later=later, normals=normals,
                           offsets=offsets, spread=spread):
            out, touched = [], 0
            for s in spread.local:
                if s.excavate_at is not None or s.excavate_stage is not None or (
                        exc.groups is not None and s.group not in exc.groups):
                    out.append(s)  # inside an earlier excavation, or not of its groups
                    continue
                made = _excavated(scene, s, exc, stage, later, normals, offsets)
                if made is None:
                    out.append(s)
                    continue
                touched += 1
                out.extend(made)
            return out, touched

        out, touched = run_together(comm, excavate_slice)
        if sum(allgather(comm, touched)) == 0:
            raise ConfigError([f"{where}: the region meets no block"])
        spread = spread.with_local(out)
        if spread.total == 0:
            raise ConfigError([f"{where}: removes every block"])
    if scene.join_slivers > 0.0:
        spread = join_slivers(spread, scene.join_slivers, same_parent=False)
    return spread


def _excavated(scene, s, exc, stage, later, normals, offsets):
    """The blocks an excavation's region leaves of block ``s`` (None: it misses ``s``): the
    groups of its pieces outside the region connected face to face, then (``later``) those
    inside, which go at the excavation's time or stage."""
    outside, inside, changed = [], [], False
    for poly in s.pieces:
        tol = _cut_tolerance(scene, poly)
        kept, removed = excavate(poly, (normals, offsets), tol, UNTAGGED)
        if removed == 0.0 and len(kept) == 1:
            outside.append(poly)
            continue
        changed = True
        outside.extend(kept)
        if removed > 0.0 and later:
            part = inside_part(poly, normals, offsets,
                               max(tol, default_tolerance(poly.vertices)))
            if part is not None:
                inside.append(part)
    if not changed:
        return None
    # a zoned block is one convex piece: its pieces stay apart, meeting at fictitious
    # joints (docs/deformable.md, "Excavations"); a rigid block's go whole where they touch
    groups = (lambda parts: [[i] for i in range(len(parts))]) if s.spec.zones is not None \
        else components
    made = [dataclasses.replace(s, pieces=[outside[i] for i in g]) for g in groups(outside)]
    made += [dataclasses.replace(s, pieces=[inside[i] for i in g],
                                 excavate_at=exc.time if stage is None else None,
                                 excavate_stage=stage) for g in groups(inside)]
    if len(made) == 1:
        return [dataclasses.replace(made[0], name=s.name)]
    return [dataclasses.replace(m, name=f"{s.name}[{k}]") for k, m in enumerate(made)]
