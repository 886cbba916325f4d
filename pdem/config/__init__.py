"""Scene files: schema, loading and error messages with key paths."""

from .errors import ConfigError
from .load import dump_scene, load_scene, parse_scene, scene_data, validate_scene
from .schema import Scene

__all__ = ["ConfigError", "Scene", "dump_scene", "load_scene", "parse_scene", "scene_data",
           "validate_scene"]
