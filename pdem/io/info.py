"""``pdem info FILE.h5``: a human-readable summary of a pdem output or study file, read through
the results reader (pdem.io.results, ``pdem.open``)."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from .results import Results
from .study_table import study_lines

__all__ = ["summarise"]

_TABLE_MAX = 20
_KNOWN_ATTRS = ("pdem_format", "format_version", "scene")


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return np.array2string(value, separator=", ", threshold=8)
    return str(value)


def _scene_name(scene: str) -> str | None:
    try:
        import yaml

        data = yaml.safe_load(scene)
    except Exception:  # a summary must not fail on an odd scene string
        return None
    return str(data["name"]) if isinstance(data, dict) and "name" in data else None


def _g(x: float) -> str:
    return f"{x:.6g}"


def summarise(path: str | os.PathLike) -> str:
    """Summary of a pdem output file, as printed by ``pdem info``.

    Raises ``FileNotFoundError`` if ``path`` does not exist and ``ValueError`` if it is not
    an HDF5 file written by pdem.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if not h5py.is_hdf5(path):
        raise ValueError(f"{path}: not an HDF5 file")
    with h5py.File(path, "r") as f:
        fmt = f.attrs.get("pdem_format")
        if fmt is None:
            raise ValueError(f"{path}: not a pdem file (no 'pdem_format' attribute)")
        fmt = _text(fmt)
        lines = [f"file:        {path} (pdem {fmt}, format {_text(f.attrs.get('format_version'))})"]
        if fmt == "study":  # its table's summary (the study and scene YAML: pdem.open_study)
            return "\n".join(lines + study_lines(path))
        for key in sorted(k for k in f.attrs if k not in _KNOWN_ATTRS):
            lines.append(f"{key + ':':<13}{_text(f.attrs[key])}")
        if "scene" in f.attrs:
            name = _scene_name(_text(f.attrs["scene"]))
            lines.append(f"scene:       {name if name is not None else '(unnamed)'}")
        if fmt != "output":
            lines.append(f"contents:    {', '.join(sorted(f))}")
            return "\n".join(lines)
    with Results(path) as r:
        lines += _output_summary(r)
    return "\n".join(lines)


def _output_summary(r: Results) -> list[str]:
    f = r.file
    names = r.blocks.name
    n = len(names)
    time, step = r.time, r.step
    n_snap = len(time)
    lines = [f"blocks:      {n}"]
    lines += _viewer_lines(f)
    if "surface/connectivity" in f:
        lines.append(
            f"surface:     {f['surface/points'].shape[1]} vertices, "
            f"{f['surface/connectivity'].shape[0]} triangles"
        )
    lines += _zone_lines(f, names)
    if n_snap == 0:
        lines.append("snapshots:   0")
    else:
        lines.append(
            f"snapshots:   {n_snap}  (steps {step[0]} .. {step[-1]}, "
            f"time {_g(time[0])} .. {_g(time[-1])} s)"
        )
    if r.histories:
        items = [f"{k} ({h.values.shape[0]} rows x {h.values.shape[1]})"
                 for k, h in sorted(r.histories.items())]
        lines.append(f"histories:   {', '.join(items)}")
    else:
        lines.append("histories:   none")
    lines += _energy_lines(r)
    lines += _contact_lines(f, names)
    lines += _reinforcement_lines(f)
    lines += _stage_lines(r, names)
    if n_snap == 0:
        return lines
    c0, c1 = r.blocks.centroid[0], r.blocks.centroid[n_snap - 1]
    speed = np.linalg.norm(r.blocks.velocity[n_snap - 1], axis=1)
    disp = np.linalg.norm(c1 - c0, axis=1)
    if n <= _TABLE_MAX:
        width = max(4, *(len(s) for s in names))
        lines.append(f"final snapshot (t = {_g(time[-1])} s):")
        lines.append(
            f"  {'name':<{width}}  {'x':>12} {'y':>12} {'z':>12}  {'speed':>11}  {'displ.':>11}"
        )
        for j in range(n):
            x, y, z = c1[j]
            lines.append(
                f"  {names[j]:<{width}}  {x:12.6g} {y:12.6g} {z:12.6g}  {speed[j]:11.4g}"
                f"  {disp[j]:11.4g}"
            )
    else:
        lines.append(
            f"displacement (first to last snapshot): mean {_g(disp.mean())} m, "
            f"max {_g(disp.max())} m ({names[int(disp.argmax())]})"
        )
        lines.append(
            f"speed (last snapshot): mean {_g(speed.mean())} m/s, "
            f"max {_g(speed.max())} m/s ({names[int(speed.argmax())]})"
        )
    return lines


def _zone_lines(f: h5py.File, names) -> list[str]:
    """The zoned blocks' grid (zones/) and, in the last snapshot, their stresses and yield."""
    z = f.get("zones")
    if z is None:
        return []
    blocks = ", ".join(names[z["block"][:5]]) + (", ..." if len(z["block"]) > 5 else "")
    lines = [f"zones:       {len(z['block'])} zoned blocks ({blocks}): "
             f"{len(z['initial_points'])} gridpoints, {len(z['connectivity'])} zones"]
    if z["points"].shape[0] == 0:
        return lines
    # each part from its series, if the scene wrote it (output.zones.fields)
    parts = []
    if "sigma1" in z and "sigma3" in z:
        s1, s3 = z["sigma1"][-1], z["sigma3"][-1]
        parts.append(f"sigma1 {_g(s1.min())} .. {_g(s1.max())} Pa, sigma3 {_g(s3.min())} .. "
                     f"{_g(s3.max())} Pa (tension +)")
    if "plastic" in z:
        bits = z["plastic"][-1]
        parts.append(f"yielding now {int(((bits & 3) > 0).sum())} zones, ever "
                     f"{int((bits > 0).sum())}")
    # from the positions (float64, always written): the displacement series is float32
    disp = np.linalg.norm(z["points"][-1] - z["initial_points"][()], axis=1)
    parts.append(f"gridpoint displacement max {_g(disp.max())} m")
    lines.append("  last snapshot: " + "; ".join(parts))
    return lines


def _stage_lines(r: Results, names) -> list[str]:
    """Stages seen in the snapshots and a factor-of-safety result (pdem.stages, strength)."""
    lines = []
    stages = np.unique(r.file["stage"][()]) if "stage" in r.file else []
    if len(stages) > 1:  # a staged run
        lines.append(f"stages:      {len(stages)} in the snapshots ({', '.join(map(str, stages))})")
    fos = r.factor_of_safety
    if fos is not None:
        bound = "" if fos.bounded else ">= " if fos.value > 1 else "<= "
        line = f"factor of safety: {bound}{fos.value:.4g}"
        if fos.mechanism is not None:
            d = np.linalg.norm(fos.mechanism, axis=1)
            moving = np.nonzero(d > 0.1 * d.max())[0] if d.max() > 0 else []
            line += f" (stage {fos.stage}; failure mechanism: {len(moving)} blocks, e.g. " \
                    f"{', '.join(names[moving[:5]])})"
        lines.append(line)
    return lines


def _contact_lines(f: h5py.File, names) -> list[str]:
    """The joint state (contacts/): counts over the run, the last snapshot's states and forces."""
    if "contacts/offset" not in f:
        return ["contacts:    not stored (output.contacts: false)"]
    off, soff = f["contacts/offset"][()], f["subcontacts/offset"][()]
    if len(off) < 2:
        return ["contacts:    stored, no snapshot yet"]
    per = np.diff(off)
    lo, hi = int(off[-2]), int(off[-1])
    lines = [f"contacts:    {int(per.min())} .. {int(per.max())} per snapshot; last snapshot "
             f"{hi - lo} contacts, {int(soff[-1] - soff[-2])} sub-contacts"]
    if hi == lo:
        return lines
    state = f["contacts/state"][lo:hi]
    state_names = [_text(x) for x in f["contacts/state"].attrs.get(
        "names", ["intact", "slipping", "open", "failed"])]
    counts = np.bincount(state, minlength=len(state_names))
    fn = f["contacts/normal_force"][lo:hi]
    fs = np.linalg.norm(f["contacts/shear_force"][lo:hi], axis=1)
    blocks = f["contacts/block"][lo:hi]
    k = int(np.argmax(fn))
    a, b = (names[int(g)] for g in blocks[k])
    lines += [
        "  states:    " + ", ".join(f"{s} {int(c)}" for s, c in zip(state_names, counts,
                                                                 strict=False)),
        f"  forces:    normal total {_g(fn.sum())} N, max {_g(fn[k])} N ({a} - {b}); "
        f"shear max {_g(fs.max())} N; max opening {_g(f['contacts/opening'][lo:hi].max())} m",
    ]
    return lines


def _energy_lines(r: Results) -> list[str]:
    """The last row of the energy budget (histories/energy), if the file has one."""
    e = r.histories.get("energy")
    if e is None or not len(e.time):
        return []
    row = e.last
    t = e.time[-1]
    if "balance_error" not in row:
        return []
    put_in = row["gravity_work"] + row["applied_work"] + row["boundary_work"]
    first = dict(zip(e.columns, e.values[0], strict=False))
    put_in += first["kinetic"] + first["strain"]
    share = 100.0 * abs(row["balance_error"]) / max(abs(put_in), 1e-300)
    zones = ""
    if row.get("zone_strain", 0.0) or row.get("plastic_work", 0.0):  # zoned blocks
        zones = f", in zones {_g(row['zone_strain'])}, plastic {_g(row['plastic_work'])}"
    # (a file from before quiet boundaries has no such column)
    quiet = f", absorbed by quiet boundaries {_g(row['quiet_absorbed'])}" \
        if row.get("quiet_absorbed", 0.0) else ""
    return [
        f"energy (J, t = {_g(t)} s): kinetic {_g(row['kinetic'])}, in joints {_g(row['strain'])}"
        f"{zones};"
        f" work of gravity {_g(row['gravity_work'])}, applied {_g(row['applied_work'])}, "
        f"prescribed {_g(row['boundary_work'])}",
        f"             dissipated in joints {_g(row['joint_dissipation'])}, by damping "
        f"{_g(row['damping_dissipation'])}{quiet}; balance error {_g(row['balance_error'])} "
        f"({share:.2g}% of {_g(put_in)} put in)",
    ] + ([f"             reinforcement: elastic {_g(row['reinforcement_strain'])}, dissipated "
          f"{_g(row['reinforcement_dissipation'])}"]
         if row.get("reinforcement_strain", 0.0) or row.get("reinforcement_dissipation", 0.0)
         else [])


def _reinforcement_lines(f: h5py.File, top: int = 5) -> list[str]:
    """The cables and bolts of the last snapshot that holds them (pdem.io.elements): how
    many, how many segments yielded, slip or broke, and the most loaded elements."""
    g = f.get("reinforcement")
    if g is None or not len(g):
        return []
    last = g[sorted(g)[-1]]
    entries = _text(g.attrs.get("entries", "")).split(",")
    axial, shear = last["axial"][()], last["shear"][()]
    state, element = last["state"][()], last["element"][()]
    n_el = int(element.max()) + 1 if len(element) else 0
    peak = np.zeros(n_el)
    np.maximum.at(peak, element, np.abs(axial))
    order = np.argsort(-peak, kind="stable")[:top]
    first = {int(e): int(np.nonzero(element == e)[0][0]) for e in order}
    lines = [f"reinforcement: {n_el} elements, {len(axial)} segments: {int(((state & 1) != 0).sum())} "
             f"yielded, {int(((state & 2) != 0).sum())} with grout slipping, "
             f"{int(((state & 4) != 0).sum())} broken; largest dowel shear {_g(shear.max())} N"]
    for e in order:
        seg = int(np.argmax(np.where(element == e, np.abs(axial), -1.0)))
        lines.append(f"  {entries[e] if e < len(entries) else '?'}[{int(e)}]: axial "
                     f"{_g(axial[seg])} N at segment {seg - first[int(e)]}")
    return lines


def _viewer_lines(f: h5py.File) -> list[str]:
    """Groups and fixed blocks (format 2), or what a format 1 file lacks for viewing."""
    if "blocks/group" not in f:
        return [
            "viewer:      format 1 file: its XDMF sidecar opens only in ParaView's legacy XDMF "
            "reader and has no displacement/velocity cell arrays (re-run with this pdem for both)"
        ]
    group = f["blocks/group"]
    names = [_text(x) for x in group.attrs.get("names", [])]
    counts = np.bincount(group[()], minlength=len(names))
    items = ", ".join(f"{name} ({c})" for name, c in zip(names, counts, strict=False))
    return [f"groups:      {items}", f"fixed:       {int(f['blocks/fixed'][()].sum())} blocks"]
