"""Joint state in the output file (docs/output.md, Contacts): contacts and sub-contacts per
snapshot, their summed forces and states, the contact sidecars, ``pdem info`` and ParaView."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases import incline
from pdem.config import parse_scene
from pdem.io import contacts_path, read_xdmf, subcontacts_path, summarise
from pdem.io.contact_series import CONTACT_CHUNK, contact_chunk
from pdem.simulation import Simulation

RHO, KN, G = 2500.0, 1.0e9, 9.81
INTACT, SLIPPING, OPEN, FAILED = 0, 1, 2, 3

CUBE = """
name: cube-at-rest
gravity: [0, 0, -9.81]
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.5, -0.5, {z0}], max: [0.5, 0.5, {z1}]}}, material: rock,
     velocity: [0, 0, {vz}]}}
solve: {{{end}, damping: {damping}}}
output: {{file: {out}, every_steps: {every}{extra}}}
"""


def cube_scene(out, *, z0=0.0, vz=0.0, end="ratio: 1.0e-9, max_steps: 20000",
               damping="local", every=100, extra=""):
    return CUBE.format(z0=repr(z0), z1=repr(z0 + 1.0), vz=repr(vz), end=end, damping=damping,
                       out=out, every=every, extra=extra)


def run(text: str) -> None:
    sim = Simulation(parse_scene(text), MPI.COMM_SELF)
    sim.run()
    sim.close()


def snapshot(f: h5py.File, i: int) -> tuple[dict, dict]:
    """Contacts and sub-contacts of snapshot ``i``."""
    off, soff = f["contacts/offset"][()], f["subcontacts/offset"][()]
    i = i % (len(off) - 1)
    c = {k: f[f"contacts/{k}"][off[i]:off[i + 1]] for k in f["contacts"] if k != "offset"}
    s = {k: f[f"subcontacts/{k}"][soff[i]:soff[i + 1]] for k in f["subcontacts"]
         if k != "offset"}
    return c, s


@pytest.fixture(scope="module")
def cube(tmp_path_factory) -> Path:
    """A cube set down touching a fixed floor, relaxed to equilibrium with local damping."""
    out = tmp_path_factory.mktemp("cube") / "cube.h5"
    run(cube_scene(out))
    return out


def test_cube_at_rest_carries_its_weight(cube):
    with h5py.File(cube, "r") as f:
        n_snap = len(f["time"])
        assert n_snap > 2 and len(f["contacts/offset"]) == n_snap + 1
        c, s = snapshot(f, -1)
        z = f["blocks/centroid"][-1, 1, 2]
        assert np.array_equal(f["subcontacts/offset"][1:] - f["subcontacts/offset"][:-1],
                              [f["contacts/n_sub"][a:b].sum() for a, b in
                               zip(f["contacts/offset"][:-1], f["contacts/offset"][1:],
                                   strict=True)])
    weight = RHO * 1.0 * G
    assert c["block"].tolist() == [[0, 1]] and c["piece"].tolist() == [[0, 1]]
    assert abs(c["normal_force"][0] - weight) <= 1e-6 * weight, c["normal_force"][0] - weight
    assert np.linalg.norm(c["shear_force"][0]) <= 1e-9 * weight
    assert c["state"].tolist() == [INTACT]
    assert np.allclose(c["normal"][0], [0, 0, 1], atol=1e-12)
    assert c["n_sub"][0] == len(s["normal_force"]) >= 3
    assert c["normal_force"][0] == np.sum(s["normal_force"])  # same sum, same order
    assert abs(c["area"][0] - 1.0) < 1e-9
    assert abs(c["normal_stress"][0] - weight / 1.0) <= 1e-6 * weight
    assert c["opening"][0] == 0.0
    # sub-contact points: the cube's bottom corners in the world (the common plane between
    # the floor top and the cube bottom)
    delta = weight / KN
    assert np.allclose(np.sort(np.abs(s["point"][:, :2]), axis=0), 0.5, atol=1e-9)
    assert np.allclose(s["point"][:, 2], 0.0, atol=2 * delta)
    assert abs(z - 0.5 + delta) < 1e-6 * delta + 1e-12  # the cube sits at its static overlap
    assert (s["state"] == 0).all()


def test_contact_sidecars_point_at_the_contacts(cube):
    with h5py.File(cube, "r") as f:
        off, soff = f["contacts/offset"][()], f["subcontacts/offset"][()]
        point, fn = f["contacts/point"][()], f["contacts/normal_force"][()]
        spoint = f["subcontacts/point"][()]
    grids = read_xdmf(contacts_path(cube.with_suffix(".xdmf")))["contacts"]
    subs = read_xdmf(subcontacts_path(cube.with_suffix(".xdmf")))["subcontacts"]
    assert len(grids) == len(off) - 1 == len(subs)
    for i, (g, sg) in enumerate(zip(grids, subs, strict=True)):
        assert g["topology_type"] == "Polyvertex"
        assert np.array_equal(g["geometry"], point[off[i]:off[i + 1]])
        assert np.array_equal(g["attributes"]["normal_force"][1], fn[off[i]:off[i + 1]])
        assert set(g["attributes"]) == {"normal_force", "shear_force", "normal", "state",
                                        "normal_stress", "shear_displacement", "opening"}
        assert np.array_equal(sg["geometry"], spoint[soff[i]:soff[i + 1]])


def test_info_summarises_the_contacts(cube):
    text = summarise(cube)
    assert "contacts:    1 .. 1 per snapshot; last snapshot 1 contacts, 4 sub-contacts" in text
    assert "states:    intact 1, slipping 0, open 0, failed 0" in text
    assert "(floor - cube)" in text
    out = subprocess.run([sys.executable, "-m", "pdem.cli", "info", str(cube)],
                         capture_output=True, text=True, check=True).stdout
    assert "intact 1" in out


def test_sliding_block_slips_at_the_friction_limit(tmp_path):
    phi = 10.0  # below the incline's 20 degrees: the slider slides
    out = tmp_path / "incline.h5"
    run(incline.incline_scene(phi, "fast", "steps: 388")
        + f"output: {{file: {out}, every_steps: 97}}\n")  # not on a geometry update
    with h5py.File(out, "r") as f:
        c, s = snapshot(f, -1)
    assert c["state"].tolist() == [SLIPPING]
    assert (s["state"] & 1).all()  # every sub-contact at the shear limit
    fn, fs = c["normal_force"][0], c["shear_force"][0]
    weight_n = incline.RHO * G * math.cos(math.radians(incline.PSI))
    assert abs(fn - weight_n) < 1e-3 * weight_n
    assert abs(np.linalg.norm(fs) - fn * math.tan(math.radians(phi))) <= 1e-9 * fn
    assert fs[0] < 0 and abs(fs[1]) < 1e-9 * fn  # on the slider (B), against its motion (+x)
    assert c["shear_displacement"][0] > 0


@pytest.fixture(scope="module")
def lifted(tmp_path_factory) -> Path:
    """A cube at its static overlap thrown upward: the contact opens, then is lost."""
    out = tmp_path_factory.mktemp("lift") / "lift.h5"
    delta = RHO * G / KN
    run(cube_scene(out, z0=-delta, vz=2.0, end="steps: 1200", damping="none", every=25))
    return out


def test_separating_block_opens(lifted):
    with h5py.File(lifted, "r") as f:
        states = [snapshot(f, i)[0] for i in range(len(f["time"]))]
    first = states[0]
    assert first["state"].tolist() == [INTACT]
    opened = [c for c in states if len(c["state"]) and c["state"][0] == OPEN]
    assert opened, [c["state"] for c in states]
    c = opened[-1]
    assert c["normal_force"][0] == 0.0 and c["normal_stress"][0] == 0.0
    assert c["opening"][0] > 0.0
    assert np.linalg.norm(c["shear_force"][0]) == 0.0
    assert len(states[-1]["state"]) == 0, "the cube flew off: no contact in the last snapshot"
    # an empty snapshot still has a (empty) grid in the sidecar
    grids = read_xdmf(contacts_path(lifted.with_suffix(".xdmf")))["contacts"]
    assert len(grids[-1]["geometry"]) == 0


def test_contacts_can_be_left_out(tmp_path):
    out = tmp_path / "none.h5"
    run(cube_scene(out, end="steps: 3", extra=", contacts: false"))
    with h5py.File(out, "r") as f:
        assert "contacts" not in f and "subcontacts" not in f
    assert not contacts_path(out.with_suffix(".xdmf")).exists()
    assert "contacts:    not stored" in summarise(out)


PROBE = Path(__file__).with_name("pv_contacts_probe.py")


@pytest.mark.parametrize("which", ["cube", "lifted"])
def test_paraview_reads_the_contact_grids(which, request, tmp_path):
    """The cube: every reader; the lifted cube (snapshots without contacts): the Xdmf3 readers
    (the legacy one cannot read an empty grid, docs/output.md)."""
    from test_paraview import BAD_LOG, pvbatch_command, run_pvbatch

    pvbatch_command()  # skip (or fail in CI) before the run
    out = request.getfixturevalue(which)
    readers = ("S", "T", "legacy") if which == "cube" else ("S", "T")
    report = tmp_path / "report.json"
    code, log = run_pvbatch(
        [str(PROBE), str(contacts_path(out.with_suffix(".xdmf"))),
         str(subcontacts_path(out.with_suffix(".xdmf"))), str(report), str(tmp_path),
         ",".join(readers)], timeout=600)
    assert code == 0, log
    bad = [line for line in log.splitlines() if any(b in line for b in BAD_LOG)]
    assert not bad, "\n".join(bad)
    got = json.loads(report.read_text())
    with h5py.File(out, "r") as f:
        n_c = np.diff(f["contacts/offset"][()])
        n_s = np.diff(f["subcontacts/offset"][()])
        last = slice(f["contacts/offset"][-2], f["contacts/offset"][-1])
        fn_last = f["contacts/normal_force"][last]
        fn0 = f["contacts/normal_force"][0]
    assert n_c[0] > 0
    for reader in readers:
        r = got[reader]
        assert r["contacts"]["points"] == n_c.tolist(), reader
        assert r["subcontacts"]["points"] == n_s.tolist(), reader
        first = r["contacts"]["arrays"]
        for name, comps in (("normal_force", 1), ("shear_force", 3), ("normal", 3),
                            ("state", 1), ("opening", 1)):
            assert first[name]["components"] == comps, (reader, name)
        assert first["normal_force"]["range"] == pytest.approx([fn0, fn0]), reader
        if len(fn_last):
            assert r["contacts"]["last"]["normal_force"]["range"] == pytest.approx(
                [fn_last.min(), fn_last.max()]), reader
        assert r["glyph_points"] > 0, reader
        assert r["drawn"] > 0.001, reader


def test_contact_chunks_grow_with_the_scene_within_their_bounds(cube):
    """Small scenes keep 1,024-row chunks (a larger chunk there only grows the file), a large
    one 16,384 (fewer chunks: less heap left in HDF5 and MPI-IO, a smaller file; docs/parallel.md
    With output)."""
    lo, hi = CONTACT_CHUNK
    sizes = [contact_chunk(n) for n in (1, 1000, 4096, 4097 * 2, 10_648, 64_001, 10**7)]
    assert sizes == [lo, lo, lo, 2048, 4096, hi, hi]
    with h5py.File(cube, "r") as f:
        assert f["contacts/normal_force"].chunks[0] == lo
        assert f["subcontacts/normal_force"].chunks[0] == lo
