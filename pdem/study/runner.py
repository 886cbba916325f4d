"""Run a study (docs/studies.md): its cases shared out over groups of ranks, one case per group
at a time, each case an ordinary run of the base scene with the case's overrides (pdem.api),
measured, recorded, and the table and summary written when all are done.

Case ``i`` goes to group ``i mod n_groups``: which group runs a case depends only on the rank
count, and a case's results do not depend on it at all (a run is bitwise the same on any
number of ranks), so the table is the same however the study is run, or resumed.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time as wallclock
from pathlib import Path

import yaml
from mpi4py import MPI

from ..api import Scene, simulate
from ..config import ConfigError
from ..config.study import Study, StudyFile
from ..errors import SimulationError, UserError
from ..io.results import open_results
from ..io.study_table import (
    claim_records,
    open_study,
    plan_fingerprint,
    read_records,
    records_dir,
    summarise,
    summary_lines,
    write_record,
    write_table,
)
from ..mpi import on_root
from .measure import measure
from .plan import plan_cases

__all__ = ["load_studies", "run_study"]

log = logging.getLogger("pdem")


def load_studies(path: str | os.PathLike) -> list[tuple[str, Study, Scene, Path]]:
    """The studies of a file: a scene file with ``studies:`` (each run on that scene) or a
    study file of its own (``name``, ``scene: FILE``, the study's keys). Returns
    ``(name, study, base scene, study file)`` each."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError([f"cannot read: {exc.strerror}"], str(path)) from None
    except yaml.YAMLError as exc:
        raise ConfigError([f"not valid YAML: {exc}"], str(path)) from None
    if isinstance(data, dict) and isinstance(data.get("scene"), str) and "blocks" not in data:
        try:
            spec = StudyFile.model_validate(data)
        except Exception as exc:  # pydantic's ValidationError, named by key
            raise ConfigError(_study_messages(exc), str(path)) from None
        scene = Scene.from_file(path.parent / spec.scene)
        study = Study.model_validate(spec.model_dump(exclude={"name", "scene"}))
        return [(spec.name, study, _without_studies(scene), _study_file(spec, path, spec.name))]
    scene = Scene.from_file(path)
    if not scene.model.studies:
        raise UserError(f"{path}: no studies: give the scene a `studies:` mapping, or write a "
                        "study file (name, scene, parameters, outputs: docs/studies.md)")
    base = _without_studies(scene)
    return [(name, st, base, _study_file(st, path, name))
            for name, st in scene.model.studies.items()]


def _study_messages(exc) -> list[str]:
    errors = getattr(exc, "errors", None)
    if errors is None:
        return [str(exc)]
    out = []
    for e in errors():
        where = ".".join(str(p) for p in e["loc"] if "[" not in str(p)) or "(top level)"
        text = e["msg"].removeprefix("Value error, ")
        out.append(f"{where}: {text}" if e["type"] != "extra_forbidden" else f"{where}: unknown key")
    return out


def _without_studies(scene: Scene) -> Scene:
    data = scene.data
    data.pop("studies", None)
    return Scene(data, source=scene.source, base=scene.base)


def _study_file(study, path: Path, name: str) -> Path:
    f = Path(study.file) if study.file else Path(f"{name}.h5")
    return f if f.is_absolute() else path.parent / f


def _case_scene(base: Scene, case, folder: Path) -> Scene:
    """The case's scene: the base with its overrides, its files in the record folder."""
    stem = folder / f"case-{case.index:06d}"
    changes = dict(case.overrides)
    changes["output.file"] = f"{stem}.h5"
    if base.model.checkpoint is not None:
        changes["checkpoint.file"] = f"{stem}-checkpoint.h5"
    try:
        return base.with_(changes)
    except ConfigError as exc:
        raise ConfigError([f"case {case.index} ({_values(case)}): {m}" for m in exc.messages],
                          exc.source) from None


def _values(case) -> str:
    return ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                     for k, v in case.values.items())


def _run_case(scene: Scene, case, study, folder: Path, comm) -> dict:
    """Run and measure one case (its ``scene``) on ``comm`` (its group); the record (every
    rank alike)."""
    t0 = wallclock.perf_counter()
    record = {"index": case.index, "values": case.values, "ranks": comm.size}
    try:
        simulate(scene.model, comm)
        comm.Barrier()
        with open_results(scene.output_file) as r:
            record["outputs"] = measure(r, study.outputs)
        record["status"] = "done"
    except (UserError, SimulationError) as exc:
        # every rank of the group alike (a rank-local error aborts in simulate): the case
        # failed, the study goes on
        record["status"], record["error"] = "failed", str(exc).splitlines()[0]
    record["wall"] = wallclock.perf_counter() - t0
    if not study.keep_outputs and comm.rank == 0:
        for p in folder.glob(f"case-{case.index:06d}*"):
            if p.suffix != ".json":
                with contextlib.suppress(OSError):
                    p.unlink()
    return record


def _quiet_cases():
    """The cases' own log lines (each run's start and end) only at warning level."""
    logger = logging.getLogger("pdem")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    return level


def run_study(source, comm=None, *, only: str | None = None, echo: bool = True):
    """Run the studies of ``source`` (a scene file with ``studies:`` or a study file; every
    rank of ``comm``, default ``MPI.COMM_WORLD``, calls it); cases already recorded are not
    run again. Returns the last study's table (:class:`pdem.study.table.StudyTable`)."""
    comm = MPI.COMM_WORLD if comm is None else comm
    studies = on_root(comm, lambda: load_studies(source))
    if only is not None:
        studies = [s for s in studies if s[0] == only]
        if not studies:
            raise ConfigError([f"studies: no study {only!r}"], str(source))
    table = None
    for name, study, base, path in studies:
        table = _run_one(name, study, base, path, comm, echo)
    return table


def _run_one(name, study, base: Scene, path: Path, comm, echo: bool):
    if comm.size % study.ranks_per_case:
        raise ConfigError([f"ranks_per_case: {study.ranks_per_case} does not divide the "
                           f"{comm.size} ranks the study runs on"], name)
    plan = plan_cases(study, base.data)
    folder = records_dir(path)
    # every case's scene, validated before any runs
    scenes = {case.index: _case_scene(base, case, folder) for case in plan.cases}
    plan_text = json.dumps({"scene": base.to_yaml(resolved=True),
                            "cases": [c.overrides for c in plan.cases],
                            "outputs": list(study.outputs)}, sort_keys=True)

    def claim():
        claim_records(folder, plan_fingerprint(plan_text), plan_text)
        return read_records(folder)

    done = on_root(comm, claim)
    n_groups = comm.size // study.ranks_per_case
    group = comm.rank // study.ranks_per_case
    sub = comm.Split(group, comm.rank)
    todo = [c for c in plan.cases if c.index % n_groups == group and c.index not in done]
    if echo and comm.rank == 0:
        print(f"study {name}: {len(plan.cases)} cases, {len(done)} recorded already; "
              f"{n_groups} at a time on {study.ranks_per_case} rank(s) each", flush=True)
    level = _quiet_cases()
    try:
        for case in todo:
            record = _run_case(scenes[case.index], case, study, folder, sub)
            if sub.rank == 0:
                write_record(folder, record)
                if echo:
                    got = ", ".join(f"{k} {v:.6g}" for k, v in record.get("outputs", {}).items())
                    print(f"study {name}: case {case.index} ({_values(case)}): "
                          f"{got or record.get('error')} [{record['wall']:.1f} s]", flush=True)
    finally:
        logging.getLogger("pdem").setLevel(level)
        sub.Free()
    comm.Barrier()
    if comm.rank == 0:
        records = read_records(folder)
        summary = summarise(study, records, len(plan.cases))
        study_text = yaml.safe_dump(study.model_dump(mode="json", exclude_none=True),
                                    sort_keys=False)
        write_table(path, name, study_text, base.to_yaml(resolved=True), plan, records,
                    summary)
        if echo:
            for line in summary_lines(name, summary):
                print(line, flush=True)
            print(f"study {name}: wrote {path}", flush=True)
    comm.Barrier()
    return open_study(path)

