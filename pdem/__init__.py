"""pdem: parallel distinct element method for 3D polyhedral blocks."""

__version__ = "0.1.0"
