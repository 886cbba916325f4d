"""Zone count, minimum dihedral angle and mesh time of pdem.deformable.mesh.tetrahedralise
on the blocks that set the cost and accuracy of zoned models (docs/deformable.md, "Mesher").

    PYTHONPATH=. .venv/bin/python bench/mesh_quality.py [--save bench/results/mesh_quality.csv]

Cases: a unit cube at 0.25, a 0.1 x 0.1 x 2 bar at 0.1, a 1 x 1 x 10 column at 0.25, a thin
slab 2 x 2 x 0.05 at 0.5, the quarter-Kirsch model's pieces (tests/verification/
test_deformable_kirsch.py: a quarter ring a = 1, R = 3, 0.3 thick, cut by the 32-sided
tunnel) at 0.3 and 0.2, and the pieces of a 3 x 2 x 2.5 box cut by two joint sets (dip 35 and
80; tests/verification/test_rock_mass.py) at 0.3. Every mesh is checked (positive tets,
volumes summing to the block's, conforming) before it is reported; the time is the best of 3.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from pdem.config import parse_scene
from pdem.deformable import zoning
from pdem.deformable.mesh import boundary_triangles, min_dihedral_angles, signed_volumes, tetrahedralise
from pdem.geometry import box
from pdem.model.build import expand_blocks


def kirsch_pieces():
    a, r, h, sides = 1.0, 3.0, 0.3, 16
    arc = [(r * math.cos(math.pi / 2 * i / sides), r * math.sin(math.pi / 2 * i / sides))
           for i in range(sides + 1)]
    verts = [[x, y, z] for y in (0.0, h) for x, z in [(0.0, 0.0), *arc]]
    text = f"""
materials: {{rock: {{density: 2500, young: 1.0e9, poisson: 0.25}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - {{name: rock, polyhedron: {{vertices: {verts}}}, material: rock, zones: {{size: {h}}}}}
stages:
  - name: excavate
    excavate: [{{cylinder: {{start: [0, -1, 0], end: [0, {h + 1}, 0], radius: {a}, sides: 32}}}}]
    solve: {{steps: 1}}
solve: {{steps: 1}}
"""
    # the zoned build cuts the ring into convex pieces and zones them: record the pieces
    got = []
    zoning.tetrahedralise = lambda poly, size: got.append(poly) or tetrahedralise(poly, size)
    try:
        expand_blocks(parse_scene(text))
    finally:
        zoning.tetrahedralise = tetrahedralise
    return got


def jointed_pieces():
    text = """
materials: {rock: {density: 2500}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: rock, box: {min: [0, 0, 0], max: [3, 2, 2.5]}, material: rock}
cuts:
  - {name: J1, dip: 35, dip_direction: 70, origin: [1.1, 0.9, 1.3], spacing: 0.7}
  - {name: J2, dip: 80, dip_direction: 200, origin: [1.6, 1.2, 0.4], spacing: 0.9}
solve: {steps: 1}
"""
    return [s.pieces[0] for s in expand_blocks(parse_scene(text))]


def check(poly, m) -> None:
    v = signed_volumes(m.nodes, m.tets)
    assert v.min() > 0.0, "a zone is not positive"
    assert abs(v.sum() - poly.volume) <= 1e-11 * poly.volume, "volumes do not add up"
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    _, count = np.unique(np.sort(m.tets[:, local].reshape(-1, 3), axis=1), axis=0,
                         return_counts=True)
    assert count.max() == 2 and (count == 1).sum() == len(boundary_triangles(m.tets))
    assert np.allclose(m.nodes[:poly.n_vertices], poly.vertices, rtol=0, atol=0)


def measure(name, polys, size, repeat=3):
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        meshes = [tetrahedralise(p, size) for p in polys]
        best = min(best, time.perf_counter() - t0)
    for p, m in zip(polys, meshes, strict=True):
        check(p, m)
    ang = np.concatenate([min_dihedral_angles(m.nodes, m.tets) for m in meshes])
    zones = sum(len(m.tets) for m in meshes)
    return dict(case=name, pieces=len(polys), size=size, zones=zones,
                min_dihedral=float(ang.min()), p5_dihedral=float(np.percentile(ang, 5)),
                seconds=best)


def cases():
    kirsch, jointed = kirsch_pieces(), jointed_pieces()
    return [
        ("cube 1 m", [box([0, 0, 0], [1, 1, 1])], 0.25),
        ("bar 0.1x0.1x2", [box([0, 0, 0], [0.1, 0.1, 2.0])], 0.1),
        ("column 1x1x10", [box([0, 0, 0], [1, 1, 10])], 0.25),
        ("slab 2x2x0.05", [box([0, 0, 0], [2, 2, 0.05])], 0.5),
        ("kirsch pieces", kirsch, 0.3),
        ("kirsch pieces", kirsch, 0.2),
        ("jointed box pieces", jointed, 0.3),
        ("column 1x1x4 (speed)", [box([0, 0, 0], [1, 1, 4])], 0.1),
    ]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--save", help="append the rows to this csv")
    args = ap.parse_args()
    rows = [measure(*c) for c in cases()]
    head = "case,pieces,size,zones,min_dihedral,p5_dihedral,seconds"
    print(head)
    lines = [f"{r['case']},{r['pieces']},{r['size']},{r['zones']},{r['min_dihedral']:.2f},"
             f"{r['p5_dihedral']:.2f},{r['seconds']:.3f}" for r in rows]
    print("\n".join(lines))
    if args.save:
        with open(args.save, "a") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
