"""BlockSpec: one expanded block of the scene (name, convex pieces, scene entry), as the
builders make it and the stores read it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config.schema import Block
from ..geometry import ConvexPolyhedron


@dataclass
class BlockSpec:
    """One expanded block of the scene: its name, convex pieces (world frame) and scene entry.

    Most blocks are one convex piece; a joined (concave) block is several, moving as one
    rigid body (3DEC's leader/follower groups). ``parent``: the name of the scene block it was
    cut from (its own name if uncut)."""

    name: str
    entry: int  # index in scene.blocks
    pieces: list[ConvexPolyhedron]
    spec: Block
    parent: str = ""
    # model time at which the block is excavated (None: it stays), see pdem.model.rockmass
    excavate_at: float | None = None
    # index of the stage whose start removes the block (None: no stage does)
    excavate_stage: int | None = None
    # group and material when not the scene entry's (mesh cells carry their own)
    group_name: str | None = None
    material_name: str | None = None
    # a zoned block's (TetMesh, surface node ids), pdem.deformable.zoning.zone_specs
    zoning: tuple | None = None

    def drop_pieces(self) -> None:
        """Drop the pieces unmeasured, keeping their count: a block outside this rank's build
        share in a scene whose cuts, joins, excavations or meshes made every block on every
        rank (pdem.state); its scalars are then the gathered columns' (:class:`SpecTable`)."""
        if self.pieces is not None:
            self._n_pieces = len(self.pieces)
            self.pieces = None

    def release(self) -> None:
        """Drop the pieces (after set-up their geometry lives with the blocks' owners, see
        pdem.distribute.release_scene_geometry), keeping the scalars later stages
        read: volume, surface area, largest face, piece count."""
        if self.pieces is None:
            return
        areas = self.face_areas
        self._volume = self.volume
        self._surface = float(areas.sum())
        self._max_face = float(areas.max())
        self._n_pieces = len(self.pieces)
        self.pieces = None

    @property
    def n_pieces(self) -> int:
        return self._n_pieces if self.pieces is None else len(self.pieces)

    @property
    def surface(self) -> float:
        return self._surface if self.pieces is None else float(self.face_areas.sum())

    @property
    def max_face(self) -> float:
        """The area of the block's largest face."""
        return self._max_face if self.pieces is None else float(self.face_areas.max())

    @property
    def group(self) -> str:
        return self.group_name if self.group_name is not None else self.spec.group

    @property
    def material(self) -> str:
        return self.material_name if self.material_name is not None else self.spec.material

    @property
    def shape(self) -> ConvexPolyhedron:
        """The block's single convex piece (joined blocks have no single shape)."""
        if self.pieces is None:
            raise ValueError(f"block {self.name!r}: its shape was released after set-up (the "
                             "geometry lives in the store of the rank holding the block)")
        if len(self.pieces) != 1:
            raise ValueError(f"block {self.name!r} is joined from {len(self.pieces)} pieces")
        return self.pieces[0]

    @property
    def volume(self) -> float:
        if self.pieces is None:
            return self._volume
        return sum(p.volume for p in self.pieces)

    @property
    def centroid(self) -> np.ndarray:
        return sum(p.volume * np.asarray(p.centroid) for p in self.pieces) / self.volume

    @property
    def face_areas(self) -> np.ndarray:
        return np.concatenate([p.face_areas() for p in self.pieces])

    def principal_frame(self):
        """(body-frame pieces, centroid, R, principal moments per unit density) of the rigid
        body; ``world = R @ body + centroid``. One piece: the piece's own principal frame."""
        if len(self.pieces) == 1:
            body, c, R, moments = self.pieces[0].principal_frame()
            return [body], c, R, moments
        c = self.centroid
        inertia = np.zeros((3, 3))
        for p in self.pieces:  # parallel-axis theorem, per unit density
            d = np.asarray(p.centroid) - c
            inertia += np.asarray(p.inertia) + p.volume * (d @ d * np.eye(3) - np.outer(d, d))
        moments, R = np.linalg.eigh(inertia)
        if np.linalg.det(R) < 0.0:
            R[:, 2] = -R[:, 2]
        return [p.transformed(R.T, -c @ R) for p in self.pieces], c, R, moments


def unbuilt_spec(b: Block, entry: int, k: int) -> BlockSpec:
    """Member ``k`` of family entry ``b`` outside this rank's build share: no pieces (one
    convex piece when built; its geometric scalars come from the rank that builds it)."""
    name = f"{b.name}[{k}]"
    spec = BlockSpec(name, entry, None, b, parent=name)
    spec._n_pieces = 1
    return spec
