"""What a scene's blocks came out as (``pdem check``): counts, volumes, slivers, joint sets.

So a user sees what the cuts produced (a sliver, a set that made nothing, a join) before a run.
"""

from __future__ import annotations

import numpy as np


def rock_mass_report(scene, specs, glob) -> list[str]:
    """Lines describing the expanded blocks ``specs`` and their static store ``glob``."""
    vol = np.array([s.volume for s in specs])
    joined = [s for s in specs if s.n_pieces > 1]
    lines = [f"blocks: {len(specs)} from {len(scene.blocks)} scene entries, "
             f"{glob.n_pieces} convex pieces ({len(joined)} joined blocks), "
             f"{int(glob.fixed.sum())} fixed"]
    med = float(np.median(vol))
    small = int(np.argmin(vol))
    lines.append(f"volume: min {vol.min():.4g} m3 ({specs[small].name}), median {med:.4g}, "
                 f"max {vol.max():.4g}, total {vol.sum():.6g}; smallest / median = "
                 f"{vol.min() / med:.3g} (size ratio {(vol.min() / med) ** (1 / 3):.3g})")
    for i, cut in enumerate(scene.cuts):
        faces = int((glob.face_tag == i).sum())
        blocks = len({int(glob.piece_block[p]) for p in
                      np.searchsorted(glob.face_start, np.nonzero(glob.face_tag == i)[0],
                                      side="right") - 1})
        joint = cut.joint or "joint_pairs/default"
        lines.append(f"cut {cut.name!r}: {faces // 2} joint faces (~{faces} faces on {blocks} "
                     f"blocks), joint {joint}")
    pending = [s for s in specs if s.excavate_at is not None]
    for t in sorted({s.excavate_at for s in pending}):
        now = [s for s in pending if s.excavate_at == t]
        lines.append(f"excavation at t = {t:g} s: {len(now)} blocks, "
                     f"{sum(s.volume for s in now):.6g} m3")
    return lines
