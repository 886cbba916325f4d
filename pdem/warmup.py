"""Compile (and cache) the kernels once by marching a two-block scene a few steps.

``run/demo`` imports this serially before ``mpiexec`` so that the ranks load cached machine
code instead of each compiling it (a cold compile takes ~30 s per process).
"""

from __future__ import annotations

from mpi4py import MPI

from .config import parse_scene
from .solver import Solver

SCENE = """
name: warmup
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock}
solve: {steps: 12, damping: local}
"""


def warm() -> None:
    for algorithm in ("fast", "cundall"):
        scene = parse_scene(SCENE.replace("solve:", f"contact: {{algorithm: {algorithm}}}\nsolve:"))
        Solver(scene, MPI.COMM_SELF, output=False).run()


warm()
