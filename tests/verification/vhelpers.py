"""Shared helpers of the physics verification tests: build a solver from YAML, format vectors,
turn dip / dip direction into plane normals, fit polynomials in time."""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation


def make_solver(text: str) -> Simulation:
    """A single-rank solver without output files for the scene in ``text`` (YAML)."""
    return Simulation(parse_scene(text), MPI.COMM_SELF, output=False)


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
