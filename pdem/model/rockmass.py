"""Scene -> rock mass: blocks cut by joint sets (``cuts:``), joined into concave blocks
(``join:``) and excavated (``excavate:``), as 3DEC's ``block cut joint-set``, ``block join``
and ``block excavate``.

Applied in that order to the blocks the ``blocks:`` entries make (pdem.model.build). Everything
here runs once at model build, on every rank alike, so it is plain numpy (the geometry it
calls per piece is compiled: the clips, the touch areas of pdem.geometry.intersection); the
order of the resulting blocks (their gids) depends only on the scene.

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
from ..parallel.mpi import shared_work

# Relative sliver size: pieces thinner than this fraction of the cut block's size (cube root
# of its volume) are not created, unless ``cut_tolerance`` says otherwise.
AUTO_CUT_TOLERANCE = 0.01
# Two convex pieces "touch" (may be joined) when they share a face patch larger than this
# fraction of the smaller piece's size squared.
TOUCH_AREA = 1e-4


def build_rock_mass(scene, specs, max_blocks: int | None = None, comm=None):
    """The scene's blocks after its cuts, joins and excavations (gid order).

    ``comm``: the ranks share the cutting of each joint set and sliver joining's face areas
    (:func:`pdem.parallel.mpi.shared_work`) and each gets the whole result, the same on any
    number of ranks (collective); None: this process does it all."""
    if scene.cuts:
        specs = apply_cuts(scene, specs, max_blocks, comm)
    if scene.join:
        specs = apply_joins(scene, specs)
    if scene.excavate or any(st.excavate for st in scene.stages):
        specs = apply_excavations(scene, specs, comm)
    return specs


def _size(poly: ConvexPolyhedron) -> float:
    return float(poly.volume) ** (1.0 / 3.0)


def _cut_tolerance(scene, poly) -> float:
    if scene.cut_tolerance == "auto":
        return AUTO_CUT_TOLERANCE * _size(poly)
    return float(scene.cut_tolerance)


def _in_box(point, box) -> bool:
    return bool(np.all(np.asarray(point) >= box.min) and np.all(np.asarray(point) <= box.max))


def apply_cuts(scene, specs, max_blocks=None, comm=None):
    for i, cut in enumerate(scene.cuts):
        where = f"{scene.at('cuts', i)} ({cut.name!r})"
        chosen = [
            len(s.pieces) == 1
            and (cut.groups is None or s.group in cut.groups)
            and (cut.range is None or _in_box(s.centroid, cut.range.box))
            for s in specs
        ]
        if not any(chosen):
            raise ConfigError([f"{where}: selects no block (range/groups; joined blocks are "
                               "not cut)"])
        verts = np.concatenate([s.pieces[0].vertices for s, c in zip(specs, chosen, strict=True) if c])
        try:
            normal, offsets = joint_set_planes(cut.dip, cut.dip_direction, cut.origin,
                                               cut.spacing, cut.count,
                                               (verts.min(axis=0), verts.max(axis=0)))
        except GeometryError as exc:
            raise ConfigError([f"{where}: {exc}"]) from None
        out, made = [], 0
        limit = max_blocks if max_blocks is not None else np.inf
        # refuse a set that would make too many blocks before cutting (a tiny spacing would
        # otherwise take hours): each block gets at most one piece per plane crossing it, +1
        crossing = 0
        todo, planes = [], []  # the chosen blocks and how many planes cross each
        for k, (s, c) in enumerate(zip(specs, chosen, strict=True)):
            if c:
                proj = s.pieces[0].vertices @ normal
                m = int(np.searchsorted(offsets, proj.max())
                        - np.searchsorted(offsets, proj.min(), side="right"))
                crossing += m
                todo.append(k)
                planes.append(m)
        if len(specs) + crossing > limit:
            raise ConfigError([f"{where}: would make up to {len(specs) + crossing} blocks, more "
                               f"than {int(limit)} (limits.max_blocks): a larger spacing, a "
                               "range, or a higher limits.max_blocks"])

        def cut_share(lo, hi, i=i, normal=normal, offsets=offsets, todo=todo, specs=specs):
            out = []
            for k in todo[lo:hi]:
                poly = specs[k].pieces[0]
                out.append(cut_blocks([poly], i, normal, offsets,
                                      tol=_cut_tolerance(scene, poly))[0])
            return out

        # the ranks cut shares of the blocks (weighted by the planes crossing them) and each
        # gets every block's pieces, in block order: the same list as one rank cutting all
        cut_pieces = dict(zip(todo, shared_work(comm, np.asarray(planes) + 1.0, cut_share),
                              strict=True))
        for k, (s, c) in enumerate(zip(specs, chosen, strict=True)):
            if not c:
                out.append(s)
                continue
            pieces = cut_pieces.pop(k)
            made += len(pieces) - 1
            out.extend(dataclasses.replace(s, pieces=[p]) for p in pieces)
            if len(out) + len(specs) - k - 1 > limit:
                raise ConfigError([f"{where}: makes more than {int(limit)} blocks "
                                   "(limits.max_blocks): a larger spacing, a range, or a "
                                   "higher limits.max_blocks"])
        if made == 0:
            raise ConfigError([f"{where}: misses every block (no plane of the set cuts one; "
                               f"{len(offsets)} plane(s) through origin {list(cut.origin)})"])
        specs = out
    if scene.join_slivers > 0.0:
        specs = join_slivers(specs, scene.join_slivers, comm=comm)
    return _name_pieces(specs)


def join_slivers(specs, fraction: float, same_parent: bool = True, comm=None):
    """Join every cut piece smaller than ``fraction`` of the median cut piece (by volume) to
    the block it shares the largest face with (smallest first; same material, group and
    excavation time; of the same parent block with ``same_parent``).

    Three sets leave small corner pieces even when no piece is thin along any one normal, and
    an excavation leaves corner bits of the blocks it cuts; the smallest block sets the
    timestep (eq. 87), so one sliver can cost 100x in run time. 3DEC users join them by hand;
    here they go into a neighbour, making it concave (fixed if the neighbour is).

    The face areas between each small piece and its neighbours (nearly all the work) are
    measured first, shared over the ranks (``comm``, :func:`pdem.parallel.mpi.shared_work`),
    then the pieces are joined in order as before: the same blocks on any number of ranks."""
    count: dict[str, int] = {}
    for s in specs:
        count[s.parent] = count.get(s.parent, 0) + 1
    cut = [k for k, s in enumerate(specs) if count[s.parent] > 1]
    if not cut:
        return specs
    vol = np.array([s.volume for s in specs])
    limit = fraction * float(np.median(vol[cut]))
    small = sorted((k for k in cut if vol[k] < limit), key=lambda k: (vol[k], k))
    if not small:
        return specs
    owner = list(range(len(specs)))  # union-find over blocks

    def find(i):
        while owner[i] != i:
            owner[i] = owner[owner[i]]
            i = owner[i]
        return i

    def kind(s):
        return (s.material, s.group, s.excavate_at, s.excavate_stage,
                s.parent if same_parent else None)

    lo = np.array([np.min([p.vertices.min(axis=0) for p in s.pieces], axis=0) for s in specs])
    hi = np.array([np.max([p.vertices.max(axis=0) for p in s.pieces], axis=0) for s in specs])
    boxes = _BoxQuery(lo, hi)
    # every (small piece, neighbour of its kind) pair whose face area the joining may read
    near_of = {}
    pairs = []
    for k in small:
        pad = 1e-6 * vol[k] ** (1.0 / 3.0)
        near = boxes.meeting(lo[k] - pad, hi[k] + pad)
        near_of[k] = [int(j) for j in near if int(j) != k and kind(specs[j]) == kind(specs[k])]
        pairs.extend((k, j) for j in near_of[k])

    def areas(a, b):
        return [sum(touch_area(p, q) for p in specs[k].pieces for q in specs[j].pieces)
                for k, j in pairs[a:b]]

    weights = [len(specs[k].pieces) * len(specs[j].pieces) for k, j in pairs]
    area_of = dict(zip(pairs, shared_work(comm, weights, areas), strict=True))
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
    # the groups of more than one (a group's root is its lowest index: members in order); a
    # block joined to none is passed on as it is, not remade (every block's spec made anew
    # was ~35 MB on every rank at 88,000 blocks, the set-up's peak on 4 ranks)
    members: dict[int, list[int]] = {}
    for k in range(len(specs)):
        root = find(k)
        if root != k:
            members.setdefault(root, [root]).append(k)
    out = []
    for k, s in enumerate(specs):
        if k not in members:
            if find(k) == k:
                out.append(s)
            continue
        group = [specs[j] for j in members[k]]
        spec = s.spec
        if any(m.spec.fixed for m in group) and not spec.fixed:
            spec = spec.model_copy(update={"fixed": True})
        out.append(dataclasses.replace(s, pieces=[p for m in group for p in m.pieces],
                                       spec=spec))
    return out


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


def _name_pieces(specs):
    """Pieces of scene block ``P`` (more than one) are named ``P[k]`` in build order."""
    count: dict[str, int] = {}
    for s in specs:
        count[s.parent] = count.get(s.parent, 0) + 1
    seen: dict[str, int] = {}
    out = []
    for s in specs:
        if count[s.parent] == 1:
            out.append(dataclasses.replace(s, name=s.parent))
            continue
        k = seen.get(s.parent, 0)
        seen[s.parent] = k + 1
        out.append(dataclasses.replace(s, name=f"{s.parent}[{k}]"))
    return out


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
def apply_joins(scene, specs):
    by_name = {s.name: k for k, s in enumerate(specs)}
    member_of: dict[int, int] = {}
    errors = []
    for i, names in enumerate(scene.join):
        where = scene.at("join", i)
        rows = []
        for name in names:
            k = by_name.get(name)
            if k is None:
                errors.append(f"{where}: unknown block {name!r}")
            elif k in member_of:
                errors.append(f"{where}: block {name!r} is already in join[{member_of[k]}]")
            else:
                member_of[k] = i
                rows.append(k)
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
    for k, s in enumerate(specs):
        i = member_of.get(k)
        if i is None:
            out.append(s)
        elif by_name[scene.join[i][0]] == k:  # the first member leads: name and place
            members = [specs[by_name[name]] for name in scene.join[i]]
            pieces = [p for m in members for p in m.pieces]
            spec = s.spec
            if any(m.spec.fixed for m in members):  # joined to a fixed block: part of it
                spec = spec.model_copy(update={"fixed": True})
            out.append(dataclasses.replace(s, pieces=pieces, spec=spec))
    return out


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


def apply_excavations(scene, specs, comm=None):
    for where, exc, stage in _excavations(scene):
        later = exc.time > 0.0 or stage is not None  # the inside stays a block until then
        try:
            normals, offsets = region_planes(exc)
        except GeometryError as exc_:
            raise ConfigError([f"{where}: {exc_}"]) from None
        out, touched = [], 0
        for s in specs:
            if s.excavate_at is not None or s.excavate_stage is not None or (
                    exc.groups is not None and s.group not in exc.groups):
                out.append(s)  # inside an earlier excavation, or not of its groups
                continue
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
                out.append(s)
                continue
            touched += 1
            made = [dataclasses.replace(s, pieces=[outside[i] for i in g])
                    for g in components(outside)]
            made += [dataclasses.replace(s, pieces=[inside[i] for i in g],
                                         excavate_at=exc.time if stage is None else None,
                                         excavate_stage=stage) for g in components(inside)]
            if len(made) == 1:
                made[0] = dataclasses.replace(made[0], name=s.name)
            else:
                made = [dataclasses.replace(m, name=f"{s.name}[{k}]")
                        for k, m in enumerate(made)]
            out.extend(made)
        if touched == 0:
            raise ConfigError([f"{where}: the region meets no block"])
        if not out:
            raise ConfigError([f"{where}: removes every block"])
        specs = out
    if scene.join_slivers > 0.0:
        specs = join_slivers(specs, scene.join_slivers, same_parent=False, comm=comm)
    return specs
