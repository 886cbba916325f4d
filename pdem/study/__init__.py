"""Parametric and probabilistic studies of a scene (docs/studies.md)."""
