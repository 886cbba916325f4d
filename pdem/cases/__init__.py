"""The case library: verification scenes and their closed-form answers, shared by
tests/verification, bench/ and docs/make_figures.py.

Each topic module holds the scene builders (functions returning scene YAML text) and the
closed forms the runs are checked against:

* :mod:`pdem.cases.incline` -- a block on a 20 deg incline (sliding acceleration);
* :mod:`pdem.cases.oscillator` -- a cube on a floor (contact oscillator, free fall, bounce);
* :mod:`pdem.cases.wedge` -- the sliding rock wedge (limit-equilibrium critical friction);
* :mod:`pdem.cases.static` -- a two-cube stack relaxing to elastic equilibrium;
* :mod:`pdem.cases.tumbling` -- torque-free rotation of an asymmetric block;
* :mod:`pdem.cases.tipping` -- a cube tipping over a floor edge (common-plane motion);
* :mod:`pdem.cases.stacks` -- the n x n x n cube stack of the benchmarks;
* :mod:`pdem.cases.pebble` -- a 1 m block and a 1 cm pebble (partial mass scaling);
* :mod:`pdem.cases.rock_mass` -- rock masses from ``cuts:``/``join:``/``excavate:`` (a wedge cut
  out of a slope by two joint sets, an L-shaped joined block, a tunnel excavated at a time);
* :mod:`pdem.cases.shaking` -- rigid blocks under base motion: Newmark's sliding slab (flat and
  on an incline) and Housner's rocking block;
* :mod:`pdem.cases.runaway` -- solves to a ratio that cannot succeed (a block sliding off its
  base and falling, a block sliding for ever) and one that settles (``solve.no_progress_steps``).

This module holds the helpers they share: build a simulation from YAML, format vectors, turn
dip / dip direction into plane normals, fit polynomials in time, quaternion to matrix.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pdem.simulation import Simulation

__all__ = ["crossing_times", "dip_normal", "fit_acceleration", "free_row", "make_simulation",
           "rotation_matrix", "vec"]


def make_simulation(text: str) -> Simulation:
    """A single-rank simulation without output files for the scene in ``text`` (YAML).

    MPI is imported here, not with the package, so scene builders can be imported by a
    process that must not initialise MPI (bench/scaling.py launches mpiexec itself)."""
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


def free_row(sim: Simulation) -> int:
    """Row of the first free (not fixed) block of ``sim``."""
    return int(np.nonzero(sim.blocks.fixed == 0)[0][0])


def vec(v) -> str:
    """A 3-vector (or any sequence) as a YAML flow list with full float precision."""
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def dip_normal(dip_deg: float, dip_direction_deg: float) -> np.ndarray:
    """Upward unit normal of a plane of dip / dip direction (degrees); x = East, y = North,
    z = up: ``n = (sin(dip) sin(dd), sin(dip) cos(dd), cos(dip))``."""
    d, a = math.radians(dip_deg), math.radians(dip_direction_deg)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def fit_acceleration(t: np.ndarray, x: np.ndarray) -> float:
    """Least-squares ``x = c0 + c1 t + a t^2 / 2``; returns ``a``."""
    c = np.polyfit(t, x, 2)
    return 2.0 * c[0]


def crossing_times(t: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Times where ``s`` crosses zero upwards, linearly interpolated between samples."""
    i = np.nonzero((s[:-1] < 0.0) & (s[1:] >= 0.0))[0]
    return t[i] + (t[i + 1] - t[i]) * (-s[i]) / (s[i + 1] - s[i])


def rotation_matrix(q) -> np.ndarray:
    """Rotation matrix of the unit quaternion ``q = (w, x, y, z)``."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
