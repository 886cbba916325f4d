"""`pdem export`: a real run's output re-read from every exported file equals the HDF5 file."""

import json
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest
from mpi4py import MPI

from pdem import cli
from pdem.config import parse_scene
from pdem.io.export import FORMATS
from pdem.io.xdmf import CELL_FIELDS
from pdem.simulation import Simulation

SCENE = """
name: export-pile
materials: {rock: {density: 2600.0}}
joints: {default: {kn: 1.0e8, ks: 5.0e7, friction: 30.0}}
blocks:
  - {name: floor, box: {min: [-2, -2, -0.5], max: [2, 2, 0.0]}, material: rock, fixed: true}
  - name: rock
    random: {count: 3, region: {min: [-1, -1, 0.05], max: [1, 1, 1.0]}, size: [0.4, 0.5], seed: 3}
    material: rock
    velocity: [0.5, 0.0, -3.0]
solve: {steps: 40, damping: local}
output: {file: OUT, every_steps: 10}
"""
SERIES = tuple(name for name, _, _ in CELL_FIELDS)  # the surface fields of the file


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A tiny run's output file (5 snapshots: steps 0, 10, ..., 40)."""
    path = tmp_path_factory.mktemp("run") / "pile.h5"
    sim = Simulation(parse_scene(SCENE.replace("OUT", str(path))), MPI.COMM_SELF)
    sim.run()
    sim.close()
    return path


def h5(path):
    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in ("time", "surface/points", "surface/connectivity",
                                       "surface/block_id", "surface/group", "surface/fixed",
                                       *(f"surface/{s}" for s in SERIES))}


def test_run_file_moves(run_file):
    d = h5(run_file)
    assert len(d["time"]) == 5 and d["surface/connectivity"].shape[0] > 0
    # the export must follow moving blocks: the points differ between snapshots
    assert not np.array_equal(d["surface/points"][0], d["surface/points"][-1])


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_export_round_trip(run_file, tmp_path, capsys, fmt):
    d = h5(run_file)
    assert cli.main(["export", str(run_file), "--format", fmt, "--out", f"{tmp_path}/"]) == 0
    ext = FORMATS[fmt]
    names = [f"pile-{i:06d}{ext}" for i in range(5)]
    out = capsys.readouterr().out
    assert out.startswith("wrote ") and names[0] in out
    for i, name in enumerate(names):
        m = meshio.read(tmp_path / name)
        tri = np.concatenate([c.data for c in m.cells if c.type == "triangle"])
        assert sum(len(c.data) for c in m.cells) == len(tri)  # triangles only
        assert m.points.shape == d["surface/points"][i].shape
        assert tri.shape == d["surface/connectivity"].shape
        np.testing.assert_array_equal(tri, d["surface/connectivity"])
        np.testing.assert_array_equal(m.points, d["surface/points"][i])
        for key in ("block_id", "group", "fixed"):
            np.testing.assert_array_equal(m.cell_data[key][0], d[f"surface/{key}"], key)
        for key in SERIES:
            np.testing.assert_array_equal(m.cell_data[key][0], d[f"surface/{key}"][i], key)
    collection = {"vtu": "pile.pvd", "vtk": "pile.vtk.series"}.get(fmt)
    if collection:
        assert collection_entries(tmp_path / collection) == list(zip(d["time"], names,
                                                                     strict=True))
        assert out.rstrip().endswith(collection)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*names, *[collection] * bool(
        collection)])


def collection_entries(path):
    """(time, file) of a ParaView .pvd or .series file."""
    if path.suffix == ".pvd":
        sets = ET.parse(path).getroot().findall("Collection/DataSet")
        return [(float(s.get("timestep")), s.get("file")) for s in sets]
    return [(e["time"], e["name"]) for e in json.loads(path.read_text())["files"]]


def test_every_and_stem(run_file, tmp_path):
    from pdem.io.export import export

    files = export(run_file, "vtu", out=tmp_path / "sub" / "series", every=2)
    assert [f.rsplit("/", 1)[1] for f in files] == [
        "series-000000.vtu", "series-000002.vtu", "series-000004.vtu", "series.pvd"]
    times = h5(run_file)["time"]
    assert collection_entries(tmp_path / "sub" / "series.pvd") == [
        (times[i], f"series-{i:06d}.vtu") for i in (0, 2, 4)]


def test_default_beside_input(run_file, tmp_path):
    import shutil

    copy = tmp_path / "copy.h5"
    shutil.copy(run_file, copy)
    assert cli.main(["export", str(copy), "--every", "10"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy-000000.vtu", "copy.h5", "copy.pvd"]


def one_line_error(capsys, argv, *words):
    assert cli.main(argv) == 1
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pdem export: "), cap.err
    for w in words:
        assert w in lines[0]
    return lines[0]


def test_unknown_format(run_file, capsys):
    line = one_line_error(capsys, ["export", str(run_file), "--format", "stl"], "'stl'")
    assert all(fmt in line for fmt in FORMATS)


def test_not_pdem_output(tmp_path, capsys):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    one_line_error(capsys, ["export", str(other)], "not a pdem output file")
    text = tmp_path / "text.h5"
    text.write_text("hello")
    one_line_error(capsys, ["export", str(text)], "not an HDF5 file")


def test_missing_file(tmp_path, capsys):
    one_line_error(capsys, ["export", str(tmp_path / "nope.h5")], "no such file")


def test_no_snapshots(run_file, tmp_path, capsys):
    empty = tmp_path / "empty.h5"
    with h5py.File(run_file, "r") as src, h5py.File(empty, "w") as f:
        for k, v in src.attrs.items():
            f.attrs[k] = v
        f["time"] = np.zeros(0)
        f["surface/points"] = np.zeros((0, 8, 3))
        f["surface/connectivity"] = np.zeros((12, 3), dtype=np.int64)
    one_line_error(capsys, ["export", str(empty)], "no snapshots")


def test_help_names_every_format(capsys):
    with pytest.raises(SystemExit):
        cli.main(["export", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert ", ".join(list(FORMATS)[1:-1]) + " or " + list(FORMATS)[-1] in text


def test_bad_every(run_file, capsys):
    one_line_error(capsys, ["export", str(run_file), "--every", "0"], "--every")


PV_SCRIPT = """
import json, sys
from paraview.simple import OpenDataFile
result = {}
for path in sys.argv[1:-1]:
    r = OpenDataFile(path)
    times = list(r.TimestepValues)
    r.UpdatePipeline(times[-1])
    info = r.GetDataInformation()
    result[path] = {"times": times, "points": info.GetNumberOfPoints(),
                    "cells": info.GetNumberOfCells(), "arrays": sorted(r.CellData.keys()),
                    "block_id": list(r.CellData["block_id"].GetRange())}
open(sys.argv[-1], "w").write(json.dumps(result))
"""


def test_paraview_opens_collections(run_file, tmp_path):
    """ParaView opens the .pvd (vtu) and .vtk.series (vtk) as one series with the model times
    and every cell array, without an error in its log."""

    from test_paraview import BAD_LOG, pvbatch_command, run_pvbatch

    pvbatch_command()  # skip (or fail in CI) before the exports
    collections = []
    for fmt, name in (("vtu", "pile.pvd"), ("vtk", "pile.vtk.series")):
        assert cli.main(["export", str(run_file), "--format", fmt, "--out", f"{tmp_path}/{fmt}/"]) == 0
        collections.append(str(tmp_path / fmt / name))
    script, result = tmp_path / "probe.py", tmp_path / "probe.json"
    script.write_text(PV_SCRIPT)
    code, log = run_pvbatch([str(script), *collections, str(result)])
    assert code == 0, log[-4000:]
    assert not [line for line in log.splitlines() if any(b in line for b in BAD_LOG)], log
    d = h5(run_file)
    for seen in json.loads(result.read_text()).values():
        assert seen["times"] == list(d["time"])
        assert seen["points"] == d["surface/points"].shape[1]
        assert seen["cells"] == d["surface/connectivity"].shape[0]
        assert seen["arrays"] == sorted(["block_id", "group", "fixed", *SERIES])
        assert seen["block_id"] == [d["surface/block_id"].min(), d["surface/block_id"].max()]
