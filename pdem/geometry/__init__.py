"""Convex polyhedra for pdem blocks: hull, half-edges, exact mass properties, builders."""

from pdem.geometry.builders import box, from_planes, from_vertices, prism, tetrahedron
from pdem.geometry.errors import GeometryError
from pdem.geometry.hull import (
    check_convex,
    convex_hull,
    default_tolerance,
    hull_vertex_indices,
    is_convex_point_set,
)
from pdem.geometry.mass import mass_properties
from pdem.geometry.polyhedron import ConvexPolyhedron, face_areas

__all__ = [
    "ConvexPolyhedron",
    "GeometryError",
    "box",
    "check_convex",
    "convex_hull",
    "default_tolerance",
    "face_areas",
    "from_planes",
    "from_vertices",
    "hull_vertex_indices",
    "is_convex_point_set",
    "mass_properties",
    "prism",
    "tetrahedron",
]
