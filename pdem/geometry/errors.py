"""The one exception type geometry code raises for bad input."""

from __future__ import annotations


class GeometryError(ValueError):
    """Invalid or degenerate geometry (too few points, zero volume, unbounded half-spaces, ...).

    Subclasses ``ValueError`` so callers validating user input can catch either.
    """
