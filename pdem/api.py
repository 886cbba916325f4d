"""The Python API (docs/python-api.md): scenes as objects, runs on any communicator, results as
arrays. The command line is a shell over these same calls::

    import pdem
    scene = pdem.Scene.from_file("configs/slope.yaml")
    weaker = scene.with_({"joints.bedding.friction": 28.0}, output="slope-28.h5")
    r = pdem.run(weaker)                  # every rank of the communicator calls it
    print(r.factor_of_safety.value, r.blocks["crest"].displacement[-1])
"""

from __future__ import annotations

import contextlib
import copy
import logging
import os
from pathlib import Path
from typing import Any

import yaml
from mpi4py import MPI

from .config import ConfigError, dump_scene, scene_data, validate_scene
from .config.load import line_index, read_scene_text
from .config.overrides import get_path, with_overrides
from .errors import SimulationError, UserError
from .io.results import Results, open_results
from .mpi import abort_with_message
from .simulation import Simulation

__all__ = ["Scene", "open", "run", "simulate"]

log = logging.getLogger("pdem")


class Scene:
    """A validated scene: from a YAML file, YAML text, a mapping, or built in code as a mapping.
    Immutable: :meth:`with_` gives a changed copy, validated again (the same located errors as
    ``pdem check``). ``scene["joints.bedding.friction"]`` reads a value by key path."""

    def __init__(self, data: dict, *, source: str = "scene", base: str | os.PathLike | None = None,
                 _lines: dict | None = None):
        self._data = copy.deepcopy(data)
        self.source = source
        self.base = None if base is None else Path(base)
        self.model = validate_scene(self._data, source, _lines)  # the pydantic scene

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> Scene:
        """Read and validate a scene file; files it names are found beside it."""
        path = Path(path)
        return cls.from_yaml(read_scene_text(path), source=str(path), base=path.parent)

    @classmethod
    def from_yaml(cls, text: str, *, source: str = "scene",
                  base: str | os.PathLike | None = None) -> Scene:
        """Validate scene YAML text (``base``: where relative file names start from)."""
        base = None if base is None else Path(base)
        return cls(scene_data(text, source, base), source=source, base=base,
                   _lines=line_index(text))

    @classmethod
    def from_dict(cls, data: dict, *, base: str | os.PathLike | None = None) -> Scene:
        """Validate a scene mapping (the keys of a scene file: name, blocks, solve, ...)."""
        if not isinstance(data, dict):
            raise ConfigError(["the scene must be a mapping of keys (name, blocks, solve, ...)"])
        text = yaml.safe_dump(data, sort_keys=False)  # relative files anchored as a file's
        return cls(scene_data(text, "scene", None if base is None else Path(base)),
                   base=base)

    def with_(self, overrides: dict[str, Any] | None = None, /, **keys) -> Scene:
        """A copy with values replaced by key path: ``with_({"joints.bedding.friction": 28})``;
        keyword arguments name top-level keys, ``__`` standing for a dot
        (``with_(solve__time=2.0, output="a.h5")``; ``output`` and ``checkpoint`` given as a
        text set the file)."""
        changes = dict(overrides or {})
        for key, value in keys.items():
            path = key.replace("__", ".")
            if path in ("output", "checkpoint") and isinstance(value, str | os.PathLike):
                path, value = f"{path}.file", os.fspath(value)
            changes[path] = value
        data = with_overrides(self._data, changes)
        if "output" in data and "file" in (data["output"] or {}):
            data["output"]["file"] = os.fspath(data["output"]["file"])
        where = f"{self.source} with {', '.join(changes)}" if changes else self.source
        return Scene(data, source=where, base=self.base)

    def __getitem__(self, path: str):
        return get_path(self._data, path)

    @property
    def data(self) -> dict:
        """The scene as given (a deep copy): the keys written, without the defaults."""
        return copy.deepcopy(self._data)

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def output_file(self) -> str:
        return self.model.output.file

    def to_yaml(self, resolved: bool = False) -> str:
        """The scene as YAML: as given, or ``resolved`` (every default filled in)."""
        return dump_scene(self.model) if resolved else yaml.safe_dump(self._data,
                                                                      sort_keys=False)

    def __repr__(self) -> str:
        return f"<pdem.Scene {self.name!r} from {self.source}>"


def _scene(scene) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, dict):
        return Scene.from_dict(scene)
    if isinstance(scene, str | os.PathLike):
        return Scene.from_file(scene)
    raise TypeError(f"pdem.run: a Scene, a mapping or a scene file's path, not "
                    f"{type(scene).__name__}")


def simulate(model, comm, *, output: bool = True, checkpoint: dict | None = None, stop=None,
             time: float | None = None, steps: int | None = None):
    """Build and march the validated scene ``model`` on ``comm`` (collective), its files
    closed; returns the run's summary and the simulation. An error that may have struck one
    rank only aborts a multi-rank job (the others wait in a collective; the output was
    flushed at the last snapshot); an error every rank raises alike propagates."""
    sim = Simulation(model, comm, checkpoint=checkpoint, stop=stop, output=output)
    if checkpoint is not None:
        log.info("restarted run %s from step %d (t=%.6g s) on %d ranks", sim.state.run_id,
                 sim.step, sim.time, comm.size)
    try:
        summary = sim.run(time=time, steps=steps)
        sim.close()
    except Exception as exc:
        if comm.size == 1 or isinstance(exc, SimulationError):
            # serial, or raised by every rank alike: close the files properly (a full disk
            # may refuse the close too: the error already raised is the one that matters)
            with contextlib.suppress(OSError, UserError):
                sim.close()
            raise
        abort_with_message(comm, exc)
    return summary, sim


def run(scene, comm=None, output: str | os.PathLike | None = None, *,
        time: float | None = None, steps: int | None = None, stop=None) -> Results:
    """Run ``scene`` (a :class:`Scene`, a mapping or a scene file) on ``comm`` (default
    ``MPI.COMM_WORLD``; any communicator: ``MPI.COMM_SELF``, a sub-communicator of one case)
    to its end (every stage), or for ``time`` s / ``steps`` steps; ``output``: the output
    file instead of the scene's. Every rank of ``comm`` calls it and gets the results
    (:func:`open`), with the run's summary in ``results.summary``."""
    comm = MPI.COMM_WORLD if comm is None else comm
    scene = _scene(scene)
    if output is not None:
        scene = scene.with_(output=os.fspath(output))
    summary, _ = simulate(scene.model, comm, stop=stop, time=time, steps=steps)
    comm.Barrier()  # the file is closed on every rank before any reads it
    results = open_results(scene.output_file)
    results.summary = summary
    return results


def open(path: str | os.PathLike) -> Results:  # noqa: A001 - pdem.open, as the issue names it
    """The results in a run's output file, as arrays (:class:`pdem.io.results.Results`)."""
    return open_results(path)
