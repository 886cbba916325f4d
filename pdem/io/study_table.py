"""A study's record and table (docs/studies.md).

While a study runs, each finished case is one small JSON record in ``<stem>-cases/`` beside the
study file, written whole (a temporary file renamed into place) by the case's first rank: a
study killed at any moment keeps every case it finished, and run again it runs only the others.
The study file ``<stem>.h5`` holds the table of every case (parameters, outputs, status) and the
summary (each output's mean and spread, the probability of failure with its confidence
interval); it is written when the cases are done, from the records.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ..analysis.sampling import probability_of
from ..errors import UserError

__all__ = ["StudyTable", "claim_records", "open_study", "read_records", "records_dir",
           "study_lines", "summarise", "write_record", "write_table"]

DONE, FAILED = 1, 2  # a case's status in the table (0: not run yet)


def records_dir(study_file: str | os.PathLike) -> Path:
    p = Path(study_file)
    return p.with_name(p.stem + "-cases")


def plan_fingerprint(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def claim_records(folder: Path, fingerprint: str, plan_text: str) -> None:
    """Make the record folder, or check that the records there are of this same study (the
    same base scene, parameters and draws): a changed study must not mix its cases with the
    old ones' (rank 0 only)."""
    folder.mkdir(parents=True, exist_ok=True)
    mark = folder / "plan.json"
    if mark.exists():
        old = json.loads(mark.read_text()).get("fingerprint")
        if old != fingerprint:
            raise UserError(f"{folder}: holds the cases of another study (its scene or "
                            "parameters differ from this one's); delete the folder and the "
                            "study file to start again, or give this study another file")
        return
    _write_whole(mark, json.dumps({"fingerprint": fingerprint, "plan": plan_text}))


def _write_whole(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)  # atomic: a reader sees the old file or the whole new one


def write_record(folder: Path, record: dict) -> None:
    _write_whole(folder / f"case-{record['index']:06d}.json", json.dumps(record))


def read_records(folder: Path) -> dict[int, dict]:
    out = {}
    for p in sorted(folder.glob("case-*.json")):
        try:
            rec = json.loads(p.read_text())
        except (OSError, ValueError):  # cannot be torn (written whole), but be safe: rerun it
            continue
        out[int(rec["index"])] = rec
    return out


def _failed(value: float, failure) -> bool:
    return value < failure.below if failure.below is not None else value > failure.above


def summarise(study, records: dict[int, dict], n_cases: int) -> dict:
    """Mean, spread and range of each output over the finished cases, and the probability of
    failure with its Wilson interval at ``study.confidence``."""
    done = [r for r in records.values() if r["status"] == "done"]
    out = {"cases": n_cases, "done": len(done),
           "failed_runs": sum(r["status"] == "failed" for r in records.values()), "outputs": {}}
    for name in study.outputs:
        v = np.array([r["outputs"][name] for r in done], float)
        v = v[np.isfinite(v)]
        out["outputs"][name] = {"n": int(len(v)), "mean": float(v.mean()) if len(v) else math.nan,
                                "std": float(v.std(ddof=1)) if len(v) > 1 else math.nan,
                                "min": float(v.min()) if len(v) else math.nan,
                                "max": float(v.max()) if len(v) else math.nan}
    f = study.failure
    if f is not None and done:
        v = np.array([r["outputs"][f.output] for r in done], float)
        v = v[np.isfinite(v)]
        k = int(sum(_failed(x, f) for x in v))
        if len(v):
            p, lo, hi = probability_of(k, len(v), study.confidence)
            out["failure"] = {"output": f.output, "below": f.below, "above": f.above,
                              "failures": k, "n": int(len(v)), "probability": p, "low": lo,
                              "high": hi, "confidence": study.confidence}
    return out


def summary_lines(name: str, summary: dict) -> list[str]:
    """The summary as printed by ``pdem study`` and ``pdem info``."""
    lines = [f"study {name}: {summary['done']} of {summary['cases']} cases done"
             + (f", {summary['failed_runs']} runs failed" if summary["failed_runs"] else "")]
    for k, s in summary["outputs"].items():
        lines.append(f"  {k}: mean {s['mean']:.6g}, std {s['std']:.4g}, range "
                     f"{s['min']:.6g} .. {s['max']:.6g} ({s['n']} cases)")
    f = summary.get("failure")
    if f is not None:
        cond = f"< {f['below']:g}" if f["below"] is not None else f"> {f['above']:g}"
        lines.append(f"  P({f['output']} {cond}) = {f['probability']:.4g} ({f['failures']} of "
                     f"{f['n']}); {100 * f['confidence']:g}% interval {f['low']:.4g} .. "
                     f"{f['high']:.4g}")
    return lines


def write_table(path: Path, name: str, study_text: str, scene_text: str, plan, records,
                summary: dict) -> None:
    """The study file (rank 0): every case's parameters, outputs and status; the summary."""
    n = len(plan.cases)
    tmp = path.with_name(f".{path.name}.tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs.update({"pdem_format": "study", "format_version": 1, "name": name,
                        "study": study_text, "scene": scene_text,
                        "summary": json.dumps(summary)})
        status = np.zeros(n, np.uint8)
        wall = np.full(n, math.nan)
        errors = [""] * n
        for i, r in records.items():
            status[i] = DONE if r["status"] == "done" else FAILED
            wall[i] = r.get("wall", math.nan)
            errors[i] = r.get("error", "")
        f["index"] = np.arange(n)
        f["status"] = status
        f["status"].attrs["names"] = ["not run", "done", "run failed"]
        f["wall"] = wall
        f["wall"].attrs["units"] = "s"
        f.create_dataset("error", data=np.array(errors, dtype=h5py.string_dtype()))
        g = f.create_group("parameters")
        for col in plan.columns:
            v = [c.values[col] for c in plan.cases]
            if all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
                g[col] = np.array(v, float)
            else:
                g.create_dataset(col, data=np.array([json.dumps(x) if not isinstance(x, str)
                                                     else x for x in v],
                                                    dtype=h5py.string_dtype()))
        g.attrs["order"] = json.dumps(plan.columns)
        g.attrs["distributions"] = json.dumps(plan.described)
        o = f.create_group("outputs")
        for k in summary["outputs"]:
            col = np.full(n, math.nan)
            for i, r in records.items():
                if r["status"] == "done":
                    col[i] = r["outputs"][k]
            o[k] = col
    os.replace(tmp, path)


def study_lines(path) -> list[str]:
    """``pdem info`` of a study file: the summary, each parameter's distribution, the cases."""
    t = open_study(path)
    with h5py.File(path, "r") as f:
        described = json.loads(f["parameters"].attrs.get("distributions", "{}"))
    lines = t.lines()
    lines += [f"  parameter {k}: {d}" for k, d in described.items()]
    if len(t.wall) and np.isfinite(t.wall).any():
        lines.append(f"  wall time per case: mean {np.nanmean(t.wall):.3g} s, max "
                     f"{np.nanmax(t.wall):.3g} s")
    failed = np.nonzero(t.status == FAILED)[0]
    lines += [f"  case {i}: {t.error[i]}" for i in failed[:5]]
    return lines


@dataclass
class StudyTable:
    """A study file, read: ``parameters`` and ``outputs`` (name -> (n_cases,) array),
    ``status`` (0 not run, 1 done, 2 run failed), ``error``, ``wall`` (s), ``summary`` (the
    dict ``pdem study`` prints from), ``name``, ``path``."""

    path: Path
    name: str
    parameters: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    status: np.ndarray
    error: np.ndarray
    wall: np.ndarray
    summary: dict
    study_text: str
    scene_text: str

    @property
    def done(self) -> np.ndarray:
        return self.status == DONE

    def lines(self) -> list[str]:
        return summary_lines(self.name, self.summary)

    def to_pandas(self):
        """The table as a data frame, one row a case."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("to_pandas() needs pandas: pip install pandas") from None
        cols = {**self.parameters, **self.outputs, "status": self.status, "wall": self.wall}
        return pd.DataFrame(cols, index=pd.Index(np.arange(len(self.status)), name="case"))


def open_study(path: str | os.PathLike) -> StudyTable:
    """The study file ``path`` as arrays (``pdem.open_study``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with h5py.File(path, "r") as f:
        if f.attrs.get("pdem_format") != "study":
            raise ValueError(f"{path}: not a pdem study file")
        order = json.loads(f["parameters"].attrs["order"])
        params = {}
        for k in order:
            ds = f["parameters"][k]
            params[k] = ds.asstr()[()] if ds.dtype.kind == "O" else ds[()]
        return StudyTable(path, str(f.attrs["name"]), params,
                          {k: f["outputs"][k][()] for k in f["outputs"]},
                          f["status"][()], f["error"].asstr()[()], f["wall"][()],
                          json.loads(f.attrs["summary"]), str(f.attrs["study"]),
                          str(f.attrs["scene"]))
