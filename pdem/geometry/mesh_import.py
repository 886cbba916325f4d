"""Reading a volume mesh into convex blocks: one :class:`ConvexPolyhedron` per 3D cell.

A rock mass meshed elsewhere (gmsh, a VTK pipeline, a commercial mesher) arrives as a file
meshio reads. Every linear 3D cell -- tetra, hexahedron, wedge, pyramid, or meshio's explicit
``polyhedronN`` -- becomes one block, built from its node coordinates and its faces, with the
cell's scalar cell data attached (the caller groups cells into blocks or materials by them).

Cells must be convex: a block is a convex polyhedron everywhere else in pdem, and silently
taking a hull would change the rock's volume and its contacts with its neighbours. Each
face's plane is fitted (Newell normal, mean offset); a face is *warped* if one of its own
nodes lies off that plane by more than the tolerance, and the cell is *not convex* if any of
its nodes lies outside any face plane by more than the tolerance. The tolerance is
``rel_tol`` (default :data:`REL_TOL`) times the cell's bounding-box diagonal, floored by the
round-off of the file's coordinates (see :func:`cell_tolerance`).

Faces are oriented outward per face (away from the mean of the cell's nodes, which is inside
a convex cell), so the node ordering's handedness does not matter: an inverted tetrahedron
or a hexahedron numbered clockwise gives the same block as the positive one. The half-edge
construction in :meth:`ConvexPolyhedron.from_faces` then checks that the faces close.

Collapsed cells (a hexahedron with repeated node ids standing for a wedge, as some meshers
write them) are accepted: repeated ids are merged and faces that collapse to an edge dropped.
Higher-order cells (``tetra10``, ``hexahedron20``, ...) are refused: dropping their mid-side
nodes would silently straighten curved edges, so the user is asked for a linear mesh.

This runs once at model build. A cell of a fixed type with distinct nodes is checked by one
compiled call (:mod:`pdem.geometry.cell_planes`, the same normals and offsets); any other
cell, and any cell that call finds wrong, by the per-cell numpy code here, which words the
error.
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Callable, Collection, Mapping
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pdem.geometry.cell_planes import cell_planes, template
from pdem.geometry.errors import GeometryError
from pdem.geometry.polyhedron import ConvexPolyhedron, face_area_vectors

# Relative tolerance: a face node may lie this fraction of the cell's bounding-box diagonal
# off its face plane (or outside another face's plane) and still count as on it. Loose
# enough for coordinates written with ~8 significant digits, tight enough that a visibly
# warped or re-entrant cell is refused.
REL_TOL = 1e-6

# Face lists (node positions within the cell) for meshio's node ordering of each linear type,
# counter-clockwise seen from outside for a positively oriented cell. meshio uses the VTK
# ordering for all of these except the wedge, where it adopts the gmsh/Abaqus prism order
# (VTK's with nodes 1 and 2, 4 and 5 swapped: triangle 0-1-2 is counter-clockwise seen from
# the 3-4-5 side). The face *connectivity* is what matters here: orientation is redone per
# cell, so a cell of either handedness reads the same.
TETRA_FACES: tuple[tuple[int, ...], ...] = ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2))
HEXAHEDRON_FACES: tuple[tuple[int, ...], ...] = (
    (0, 3, 2, 1),  # bottom
    (4, 5, 6, 7),  # top
    (0, 1, 5, 4),
    (1, 2, 6, 5),
    (2, 3, 7, 6),
    (3, 0, 4, 7),
)
WEDGE_FACES: tuple[tuple[int, ...], ...] = (
    (0, 2, 1),  # bottom triangle
    (3, 4, 5),  # top triangle
    (0, 1, 4, 3),
    (1, 2, 5, 4),
    (2, 0, 3, 5),
)
PYRAMID_FACES: tuple[tuple[int, ...], ...] = (
    (0, 3, 2, 1),  # base
    (0, 1, 4),
    (1, 2, 4),
    (2, 3, 4),
    (3, 0, 4),
)
CELL_FACES: dict[str, tuple[tuple[int, ...], ...]] = {
    "tetra": TETRA_FACES,
    "hexahedron": HEXAHEDRON_FACES,
    "wedge": WEDGE_FACES,
    "pyramid": PYRAMID_FACES,
}

# the same faces as CSR arrays, for the compiled check (pdem.geometry.cell_planes)
CELL_TEMPLATES: dict[str, tuple[np.ndarray, np.ndarray]] = {
    kind: template(faces) for kind, faces in CELL_FACES.items()}

# A cell is selected by a callable ``select(index, kind, data) -> bool`` or by a mapping
# ``{cell data name: value or collection of values}`` (every named array must match).
Select = Callable[[int, str, dict], bool] | Mapping[str, object]


@dataclass(frozen=True)
class MeshCell:
    """One 3D cell of a mesh, as a convex block.

    Attributes
    ----------
    index : int
        Cell index in the mesh, counted over all of meshio's cell blocks in order (lower-
        dimensional cells included), i.e. ParaView's cell id for a VTU file without
        polyhedra.
    kind : str
        meshio cell type: ``"tetra"``, ``"hexahedron"``, ``"wedge"``, ``"pyramid"`` or
        ``"polyhedronN"`` (N nodes).
    poly : ConvexPolyhedron
        The cell's geometry; vertices are the cell's distinct nodes in connectivity order.
    data : dict
        This cell's value of every scalar cell-data array, as Python ``int``, ``float`` or
        ``str`` (an integer-valued float stays ``float``).
    """

    index: int
    kind: str
    poly: ConvexPolyhedron
    data: dict[str, float | int | str]


# ---------------------------------------------------------------------------- one cell
def cell_tolerance(points: np.ndarray, rel_tol: float = REL_TOL, coord_eps: float = 0.0) -> float:
    """Distance tolerance for the planarity and convexity checks of one cell.

    ``rel_tol`` times the bounding-box diagonal of ``points``, floored by the round-off the
    coordinates carry: 256 ulps of float64 (as :func:`pdem.geometry.hull.default_tolerance`)
    and 8 ulps of the file's own precision ``coord_eps`` (float32 coordinates far from the
    origin carry far more error than the cell size suggests).

    Parameters
    ----------
    points : (n, 3) float64
        The cell's node coordinates.
    rel_tol : float
        Tolerance relative to the cell's diagonal.
    coord_eps : float
        Machine epsilon of the coordinates as stored in the file (0 if exact).

    Returns
    -------
    float
    """
    diag = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    scale = float(np.abs(points).max())
    return max(rel_tol * diag, (256.0 * np.finfo(float).eps + 8.0 * coord_eps) * scale, 1e-300)


def _merge_repeated(ids: np.ndarray, faces) -> tuple[np.ndarray, list[list[int]]]:
    """Distinct node ids (first-appearance order) and faces over their positions.

    Repeated ids inside a face are merged (a collapsed hexahedron face becomes a triangle)
    and faces left with fewer than 3 nodes are dropped (they collapsed to an edge).
    """
    pos: dict[int, int] = {}
    for i in ids.tolist():
        pos.setdefault(i, len(pos))
    out = []
    for f in faces:
        loop = [pos[int(ids[k])] for k in f]
        # drop cyclically repeated neighbours: (a, b, b, c) -> (a, b, c), (a, b, a) -> (a, b)
        loop = [x for k, x in enumerate(loop) if x != loop[k - 1]] if len(set(loop)) > 1 else []
        if len(loop) >= 3:
            out.append(loop)
    return np.array(list(pos), dtype=np.int64), out


def cell_polyhedron(
    points: np.ndarray,
    node_ids: np.ndarray,
    faces,
    *,
    rel_tol: float = REL_TOL,
    coord_eps: float = 0.0,
) -> ConvexPolyhedron:
    """Convex polyhedron of one mesh cell, after checking planarity and convexity.

    Parameters
    ----------
    points : (n, 3) float64
        All mesh points.
    node_ids : (k,) int
        The cell's point ids; ``faces`` index into this array.
    faces : sequence of int sequences
        The cell's faces as positions in ``node_ids``, either orientation.
    rel_tol, coord_eps : float
        See :func:`cell_tolerance`.

    Returns
    -------
    ConvexPolyhedron
        Vertices are the cell's distinct nodes in ``node_ids`` order; faces in the given
        order (collapsed ones dropped), each turned to face outward.

    Raises
    ------
    GeometryError
        The message names the node (its position in the cell and its point id) or face
        (its position in ``faces`` after collapsed faces are dropped) and the distance: a
        warped face, a node outside a face plane (not convex), a degenerate (zero-volume or
        zero-area) cell, or faces that do not close.
    """
    ids, loops = _merge_repeated(np.asarray(node_ids, dtype=np.int64), faces)
    if len(ids) < 4 or len(loops) < 4:
        raise GeometryError(
            f"degenerate: {len(ids)} distinct nodes and {len(loops)} faces, zero volume"
        )
    v = np.asarray(points[ids], dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise GeometryError("node coordinates contain NaN or inf")
    tol = cell_tolerance(v, rel_tol, coord_eps)
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    # All faces at once (a per-face Python loop cost more than building the polyhedron).
    counts = np.array([len(loop) for loop in loops], dtype=np.int64)
    face_start = np.concatenate([[0], np.cumsum(counts)])
    fv = np.concatenate([np.asarray(loop, dtype=np.int64) for loop in loops])
    face_of = np.repeat(np.arange(len(loops)), counts)
    area_vec = face_area_vectors(v, face_start, fv)  # Newell: 2 * area * unit normal
    area2 = np.linalg.norm(area_vec, axis=1)
    bad = np.flatnonzero(area2 <= 2.0 * tol * diag)  # area below a tol-wide sliver's
    if bad.size:
        raise GeometryError(f"degenerate: face {bad[0]} has zero area (collapsed or self-crossing)")
    n = area_vec / area2[:, None]
    # n . x at each face node, summed in a fixed order (einsum's order follows the CPU's
    # vector width), as pdem.geometry.cell_planes sums it
    p, q = v[fv], n[face_of]
    dots = (p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]) + p[:, 2] * q[:, 2]
    d = np.bincount(face_of, dots) / counts
    # The mean of the nodes is inside a convex cell: it decides which side of a face is out.
    h = n @ v.mean(axis=0) - d
    flat = np.flatnonzero(np.abs(h) <= tol)
    if flat.size:
        # for a convex cell, the mean in a face's plane means every node is: a flat cell
        raise GeometryError(
            f"degenerate: all nodes lie within {tol:.3g} m of the plane of face {flat[0]}, "
            f"zero volume"
        )
    off = np.abs(dots - d[face_of])
    warp = np.maximum.reduceat(off, face_start[:-1])
    bad = np.flatnonzero(warp > tol)
    if bad.size:
        f = int(bad[0])
        k = int(face_start[f] + np.argmax(off[face_start[f] : face_start[f + 1]]))
        raise GeometryError(
            f"face {f} is warped: node {fv[k]} (point {ids[fv[k]]}) lies {off[k]:.3g} m "
            f"off the face's plane (tolerance {tol:.3g} m)"
        )
    flip = h > 0.0  # the inside is in front of these faces: they were numbered clockwise
    n[flip], d[flip] = -n[flip], -d[flip]
    out = v @ n.T - d  # (node, face): positive = outside the face's plane
    j, f = np.unravel_index(int(np.argmax(out)), out.shape)
    if out[j, f] > tol:
        raise GeometryError(
            f"node {j} (point {ids[j]}) lies {out[j, f]:.3g} m outside the plane of face {f}: "
            f"not convex (tolerance {tol:.3g} m)"
        )
    oriented = [loop[::-1] if fl else loop for loop, fl in zip(loops, flip.tolist(), strict=True)]
    used = {i for loop in oriented for i in loop}
    if len(used) != len(ids):
        missing = sorted(set(range(len(ids))) - used)
        raise GeometryError(f"node(s) {missing} are on no face")
    try:
        # the planes just checked become the block's face planes (no second fit)
        poly = ConvexPolyhedron.from_faces(v, oriented, normals=n, offsets=d)
    except GeometryError as exc:
        raise GeometryError(f"faces do not form a closed surface ({exc})") from None
    return poly


def fixed_cell_polyhedron(points: np.ndarray, node_ids: np.ndarray, kind: str,
                          rel_tol: float = REL_TOL, coord_eps: float = 0.0
                          ) -> ConvexPolyhedron | None:
    """:func:`cell_polyhedron` of a cell of a fixed type (``kind`` in :data:`CELL_FACES`) by
    one compiled check (pdem.geometry.cell_planes): the same polyhedron, its arrays in one
    buffer. None for any other cell, a collapsed one, or one a check refuses:
    :func:`cell_polyhedron` then checks it and raises its own message.

    ``points``: all mesh points, float64 (n, 3); ``node_ids``: the cell's point ids, int64,
    in range."""
    faces = CELL_TEMPLATES.get(kind)
    if faces is None or len(node_ids) != faces[1].max() + 1:
        return None
    fs, fv = faces
    ok, v, n, d, oriented = cell_planes(points, node_ids, fs, fv, float(rel_tol),
                                        float(coord_eps))
    if not ok:
        return None
    try:
        return ConvexPolyhedron.from_csr(v, fs, oriented, normals=n, offsets=d, fresh=True)
    except GeometryError:  # the faces do not close: worded by cell_polyhedron
        return None


# ---------------------------------------------------------------------------- cell data
def _python_value(x) -> int | float | str:
    """A numpy scalar as the plain Python value the scene layer compares against."""
    if isinstance(x, np.bool_ | bool):
        return int(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, bytes | np.bytes_):
        return bytes(x).decode(errors="replace")
    return str(x)


def _scalar_cell_data(mesh, blocks: list[int]) -> dict[str, list[np.ndarray]]:
    """Cell-data arrays that are scalar on every 3D block, squeezed to 1D, per block.

    Arrays of shape ``(n, 1)`` count as scalar; vectors and tensors are skipped, as are
    complex and object arrays (no plain Python value to compare against).
    """
    out: dict[str, list[np.ndarray]] = {}
    for name, per_block in mesh.cell_data.items():
        arrays = []
        for b in blocks:
            a = np.asarray(per_block[b])
            if a.ndim == 2 and a.shape[1] == 1:
                a = a[:, 0]
            if a.ndim != 1 or a.dtype.kind not in "biufUS":
                break
            arrays.append(a)
        else:
            out[name] = arrays
    return out


def _matches(value, wanted) -> bool:
    if isinstance(wanted, Collection) and not isinstance(wanted, str | bytes):
        return value in wanted
    return value == wanted


def _selector(select, names: list[str]) -> Callable[[int, str, dict], bool]:
    if select is None:
        return lambda index, kind, data: True
    if callable(select):
        return select
    if isinstance(select, Mapping):
        unknown = [k for k in select if k not in names]
        if unknown:
            raise GeometryError(
                f"select names cell data {unknown} that the mesh does not have as scalars "
                f"(it has {sorted(names)})"
            )
        return lambda index, kind, data: all(_matches(data[k], w) for k, w in select.items())
    raise GeometryError(f"select must be None, a mapping or a callable, got {type(select).__name__}")


# ---------------------------------------------------------------------------- meshio quirks
def _meshio_version() -> tuple[int, ...]:
    import meshio

    parts = []
    for p in meshio.__version__.split(".")[:3]:
        digits = "".join(ch for ch in p if ch.isdigit())
        parts.append(int(digits or 0))
    return tuple(parts)


def _fix_vtu_polyhedron_data(mesh, path: Path) -> None:
    """Undo meshio's cell-data order for VTU polyhedra (up to meshio 5.3.5 at least).

    Its VTU reader groups polyhedra into blocks ``polyhedronN`` in order of first appearance,
    but the matching cell-data blocks in ascending N, so e.g. a mesh whose first cell has 6
    nodes and second 4 gets each cell's data swapped. Reorder the data to the blocks.
    """
    if path.suffix.lower() != ".vtu" or _meshio_version() > (5, 3, 5):
        return
    if not mesh.cells or not all(c.type.startswith("polyhedron") for c in mesh.cells):
        return
    sizes = [int(c.type[len("polyhedron") :]) for c in mesh.cells]
    order = sorted(sizes)
    if order == sizes or len(set(sizes)) != len(sizes):
        return
    for name, per_block in mesh.cell_data.items():
        if len(per_block) == len(sizes):
            mesh.cell_data[name] = [per_block[order.index(s)] for s in sizes]


# ---------------------------------------------------------------------------- the reader
def _read(path: Path):
    """``meshio.read(path)``, with every failure as one GeometryError line.

    meshio 5.3.5 does not raise when a file fails to parse: it prints the reader's error to
    stdout, "Couldn't read file" to stderr and calls ``sys.exit(1)``, which would end a pdem
    run (every MPI rank) without a message. Both streams are captured and, on failure, become
    the reason; on success anything meshio printed (its warnings) is passed on as a warning.
    """
    import meshio

    out, err = io.StringIO(), io.StringIO()
    try:
        with redirect_stdout(out), redirect_stderr(err):
            mesh = meshio.read(path)
    except SystemExit:
        reason = f"{out.getvalue()} {err.getvalue()}"
    except Exception as exc:  # meshio raises ReadError, ValueError, KeyError, OSError, ...
        reason = f"{type(exc).__name__}: {exc}" if not str(exc) else str(exc)
    else:
        printed = " ".join(f"{out.getvalue()} {err.getvalue()}".split())
        if printed:
            warnings.warn(f"meshio, reading {path}: {printed}", stacklevel=3)
        return mesh
    reason = " ".join(reason.split()).removeprefix("Error: ") or "unknown error"
    raise GeometryError(f"cannot read mesh {path}: {reason}") from None


def read_mesh_cells(path, *, select: Select | None = None, rel_tol: float = REL_TOL,
                    share_work=None) -> list[MeshCell]:
    """Read every 3D cell of a volume mesh as a convex block.

    Parameters
    ----------
    path : str or Path
        Any file :func:`meshio.read` reads (format from the extension: ``.vtu``, ``.msh``,
        ``.vtk``, ``.xdmf``, ``.inp``, ...).
    select : mapping or callable, optional
        Which cells to keep, decided before a cell is built or checked (an unwanted zone may
        hold bad cells). A mapping ``{name: value}`` or ``{name: [values]}`` keeps cells whose
        scalar cell data ``name`` equals the value (or is one of them), for every name; a
        callable ``select(index, kind, data) -> bool`` is asked per 3D cell. Default: all.
    rel_tol : float
        Planarity/convexity tolerance relative to the cell's diagonal (:data:`REL_TOL`).
    share_work : callable, optional
        ``share_work(weights, work) -> list``: runs ``work(lo, hi)`` (the polyhedra of the
        selected cells ``[lo, hi)``) over all of them and returns the results in order, e.g.
        each rank making its share (pdem.model.mesh_blocks). Default: here, in one go.

    Returns
    -------
    list of MeshCell
        In mesh order; empty if ``select`` keeps nothing.

    Raises
    ------
    GeometryError
        The file is missing or unreadable (path and meshio's reason); it has no 3D cells; a
        selected cell is higher-order, of an unknown 3D type, warped, not convex or
        degenerate (the message starts ``cell <index> (<kind>):``); ``select`` names data the
        mesh does not have.

    Notes
    -----
    Lower-dimensional cells (vertex, line, triangle, quad, ...) are ignored but counted in
    ``index``. For VTU files with polyhedra meshio groups the cells by node count, so
    ``index`` follows that grouping rather than the file order when node counts differ.
    """
    table = read_cell_table(path, select=select, rel_tol=rel_tol)
    polys = (share_work or (lambda w, work: work(0, len(w))))(np.ones(len(table)),
                                                               table.polyhedra)
    return [MeshCell(index=int(table.index[k]), kind=table.kind(k), poly=poly,
                     data=table.data_of(k)) for k, poly in enumerate(polys)]


@dataclass
class CellTable:
    """The selected 3D cells of a read mesh as columns, one row per cell in mesh order: what
    every rank holds of every cell while the blocks are made (pdem.model.mesh_blocks), no
    Python object a cell (a cell's data dict, name string and node array were ~15 us and a
    few hundred bytes a cell on every rank). ``block[k]``/``row[k]``: selected cell k is row
    ``row[k]`` of meshio's cell block ``blocks[block[k]]``; ``index[k]`` its mesh cell
    index; ``data``: the scalar cell data, whole arrays per entry of ``blocks``."""

    path: Path
    cells: list  # meshio's cell blocks
    blocks: list[int]
    data: dict[str, list[np.ndarray]]
    block: np.ndarray
    row: np.ndarray
    index: np.ndarray
    points: np.ndarray
    coord_eps: float
    rel_tol: float

    def __len__(self) -> int:
        return len(self.index)

    def kind(self, k: int) -> str:
        return self.cells[self.blocks[self.block[k]]].type

    def value(self, name: str, k: int):
        """Cell k's value of the scalar cell data ``name`` (a plain Python value)."""
        return _python_value(self.data[name][self.block[k]][self.row[k]])

    def data_of(self, k: int) -> dict:
        return {name: self.value(name, k) for name in self.data}

    def where(self, k: int) -> str:
        return f"mesh {self.path}: cell {self.index[k]} ({self.kind(k)})"

    def codes(self, name: str, label: Callable) -> tuple[np.ndarray, list[str]]:
        """``(code, labels)``: ``labels[code[k]]`` is ``label(value)`` of cell k's ``name``
        (equal labels one code, whatever the arrays' dtypes), labels in order of first
        appearance by block; label is called once per distinct value of a block."""
        code = np.empty(len(self), np.int64)
        labels: dict[str, int] = {}
        for b, (lo, hi) in self._block_ranges():
            u, inv = np.unique(self.data[name][b][self.row[lo:hi]], return_inverse=True)
            ids = np.array([labels.setdefault(label(_python_value(x)), len(labels))
                            for x in u], np.int64)
            code[lo:hi] = ids[inv.reshape(-1)]
        return code, list(labels)

    def _block_ranges(self):
        """``(b, (lo, hi))``: the selected cells of each entry ``b`` of ``blocks`` with any
        (they are in block order)."""
        edges = np.searchsorted(self.block, np.arange(len(self.blocks) + 1))
        for b in range(len(self.blocks)):
            if edges[b] < edges[b + 1]:
                yield b, (int(edges[b]), int(edges[b + 1]))

    def nodes(self, k: int) -> tuple[np.ndarray, object]:
        """Cell k's point ids and its faces (positions in those ids)."""
        kind = self.kind(k)
        data = self.cells[self.blocks[self.block[k]]].data[self.row[k]]
        if not kind.startswith("polyhedron"):
            return np.asarray(data, dtype=np.int64), CELL_FACES[kind]
        # meshio gives a polyhedron as a list of faces of global point ids.
        cell_faces = [np.asarray(f, dtype=np.int64) for f in data]
        node_ids = np.concatenate(cell_faces) if cell_faces else np.empty(0, np.int64)
        local = {}
        for p in node_ids.tolist():
            local.setdefault(p, len(local))
        node_ids = np.array(list(local), dtype=np.int64)
        return node_ids, [[local[p] for p in f.tolist()] for f in cell_faces]

    def polyhedra(self, lo: int, hi: int) -> list[ConvexPolyhedron]:
        """The polyhedra of the selected cells ``[lo, hi)`` (the work: ~30 us a cell of a
        fixed type, ~0.2 ms another), in order; a bad cell raises, named."""
        out = []
        for k in range(lo, hi):
            node_ids, faces = self.nodes(k)
            try:
                poly = fixed_cell_polyhedron(self.points, node_ids, self.kind(k),
                                             self.rel_tol, self.coord_eps)
                out.append(poly if poly is not None else cell_polyhedron(
                    self.points, node_ids, faces, rel_tol=self.rel_tol,
                    coord_eps=self.coord_eps))
            except GeometryError as exc:
                raise GeometryError(f"{self.where(k)}: {exc}") from None
        return out


def _selected_rows(select, keep, data_arrays, b: int, kind: str, first: int, n: int
                   ) -> np.ndarray:
    """The rows of meshio cell block entry ``b`` (``n`` cells of ``kind``, the first with
    mesh index ``first``) that ``select`` keeps. A mapping is decided once per distinct
    value of each named array (the same test as a cell's, by the same ``_matches``)."""
    if select is None:
        return np.arange(n)
    if not isinstance(select, Mapping):  # a callable: asked per cell, with its data
        return np.array([i for i in range(n) if keep(
            first + i, kind, {name: _python_value(arrs[b][i])
                              for name, arrs in data_arrays.items()})], np.int64)
    mask = np.ones(n, bool)
    for name, wanted in select.items():
        u, inv = np.unique(data_arrays[name][b], return_inverse=True)
        ok = np.array([_matches(_python_value(x), wanted) for x in u], bool)
        mask &= ok[inv.reshape(-1)]
    return np.flatnonzero(mask)


def read_mesh(path):
    """The meshio mesh of ``path`` (pdem's reading: meshio's failures and quirks handled,
    :func:`_read`)."""
    path = Path(path)
    mesh = _read(path)
    _fix_vtu_polyhedron_data(mesh, path)
    return mesh


def read_cell_table(path, *, select: Select | None = None, rel_tol: float = REL_TOL,
                    read: Callable | None = None) -> CellTable:
    """:func:`read_mesh_cells`' reading and checks, its cells as a :class:`CellTable`
    (their polyhedra not made yet: ``CellTable.polyhedra``). The same errors, in the same
    order: the first selected cell of an unsupported type or with a node id out of range,
    in mesh order. ``read(path)`` gives the mesh (default :func:`read_mesh`; under MPI, one
    rank's reading sent to all, pdem.model.mesh_blocks)."""
    path = Path(path)
    rel_tol = float(rel_tol)
    if not (np.isfinite(rel_tol) and rel_tol >= 0.0):
        raise GeometryError(f"rel_tol must be a finite non-negative number, got {rel_tol}")
    mesh = (read or read_mesh)(path)

    # meshio's CellBlock knows its topological dimension (3 for polyhedra too)
    blocks = [b for b, c in enumerate(mesh.cells) if getattr(c, "dim", 0) == 3]
    if not blocks:
        found = sorted({c.type for c in mesh.cells}) or ["no cells"]
        raise GeometryError(f"mesh {path} has no 3D cells (found: {', '.join(found)})")
    pts = np.asarray(mesh.points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise GeometryError(f"mesh {path}: points must be 3D, got shape {pts.shape}")
    coord_eps = float(np.finfo(pts.dtype).eps) if pts.dtype.kind == "f" else 0.0
    points = pts.astype(np.float64)

    data_arrays = _scalar_cell_data(mesh, blocks)
    keep = _selector(select, list(data_arrays))
    first_index = np.concatenate([[0], np.cumsum([len(c) for c in mesh.cells])])

    parts = []
    for k, b in enumerate(blocks):
        block = mesh.cells[b]
        kind = block.type
        rows = _selected_rows(select, keep, data_arrays, k, kind, int(first_index[b]),
                              len(block))
        if len(rows) == 0:
            continue
        at = f"mesh {path}: cell {int(first_index[b] + rows[0])} ({kind})"
        is_poly = kind.startswith("polyhedron")
        if not is_poly and kind not in CELL_FACES:
            if kind.rstrip("0123456789") in CELL_FACES:
                raise GeometryError(
                    f"{at}: higher-order cells are not supported (their mid-side nodes "
                    f"may curve the edges); export a linear mesh, e.g. gmsh -order 1"
                )
            raise GeometryError(
                f"{at}: 3D cell type not supported (supported: "
                f"{', '.join(CELL_FACES)}, polyhedron)"
            )
        if is_poly:  # ragged: cell by cell
            bad = [i for i in rows.tolist()
                   if (ids := np.concatenate([np.asarray(f, np.int64) for f in block.data[i]])
                       if len(block.data[i]) else np.empty(0, np.int64)).size
                   and (ids.min() < 0 or ids.max() >= len(points))]
        else:
            ids = np.asarray(block.data)[rows]
            bad = rows[(ids.min(axis=1) < 0) | (ids.max(axis=1) >= len(points))].tolist()
        if bad:
            raise GeometryError(f"mesh {path}: cell {int(first_index[b] + bad[0])} ({kind}): "
                                f"node id out of range (mesh has {len(points)} points)")
        parts.append((k, rows, first_index[b] + rows))
    cat = (lambda j, dtype: np.concatenate([p[j] for p in parts]).astype(dtype)) if parts \
        else (lambda j, dtype: np.zeros(0, dtype))
    block_of = np.concatenate([np.full(len(p[1]), p[0], np.int64) for p in parts]) if parts \
        else np.zeros(0, np.int64)
    return CellTable(path, mesh.cells, blocks, data_arrays, block_of, cat(1, np.int64),
                     cat(2, np.int64), points, coord_eps, rel_tol)
