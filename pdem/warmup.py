"""Compile (and cache) the common kernels once by marching a two-block scene a few steps.

``python -m pdem.warmup`` fills the kernel cache (pdem.jit) before a job needs it, e.g. on a
node before a job array's runs start (both common-plane algorithms, local damping). Ranks
started on a cold cache do not need it: one rank of a node compiles each kernel and the others
load it (pdem.jit's compile locks).
"""

from __future__ import annotations

SCENE = """
name: warmup
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock}
solve: {steps: 12, damping: DAMPING}
"""


def warm(damping: str = "local") -> None:
    """Compile the kernels of both common-plane algorithms with ``damping``."""
    from mpi4py import MPI

    from .config import parse_scene
    from .simulation import Simulation

    for algorithm in ("fast", "cundall"):
        text = SCENE.replace("DAMPING", damping)
        scene = parse_scene(text.replace("solve:", f"contact: {{algorithm: {algorithm}}}\nsolve:"))
        Simulation(scene, MPI.COMM_SELF, output=False).run()


if __name__ == "__main__":
    warm()
