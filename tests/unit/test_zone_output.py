"""Zoned (deformable) blocks in the output file: ``zones/`` and the ``-zones.xdmf`` sidecar."""

import json
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.io import OutputWriter, read_xdmf, xdmf, zones_path
from pdem.io.block_series import quat_to_matrix
from pdem.io.layout import h5py_has_mpi
from pdem.io.xdmf import contacts_path
from pdem.io.zone_surfaces import boundary_of
from pdem.io.zones import ZONE_COLUMNS, ZONE_FIELDS, ZONE_VIEWED, zone_layout, zone_values

COMM = MPI.COMM_SELF


def make_scene():
    """Four boxes (blocks 1 and 3 are zoned below: their rigid rows are written too)."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return {"block_names": ["a", "b", "c", "d"], "body_vertices": [v * (i + 1) for i in range(4)],
            "body_faces": [faces] * 4, "scene_yaml": "name: zones\n"}


def rows(centroid, quat, velocity, angular_velocity) -> dict:
    return {"centroid": centroid, "orientation": quat, "velocity": velocity,
            "angular_velocity": angular_velocity}


def contents(path) -> dict:
    """Every dataset (dtype, values) and attribute of a file, by path."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            out[name + "@"] = {k: obj.attrs[k] for k in obj.attrs}
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.dtype, obj[()])
        out["/@"] = {k: f.attrs[k] for k in f.attrs}
        f.visititems(visit)
    return out


def grid(seed, n_points, n_zones):
    """A zoned block's arrays (any numbers: the writer does not look at the physics)."""
    rng = np.random.default_rng(seed)
    x0 = rng.normal(size=(n_points, 3))
    tets = np.stack([rng.choice(n_points, 4, replace=False) for _ in range(n_zones)])
    return SimpleNamespace(nodes0=x0, tets=tets, nodes=x0.copy(), vel=np.zeros((n_points, 3)),
                           stress=np.zeros((n_zones, 6)), plastic=np.zeros(n_zones, np.int32))


def move(body, rng):
    """A new state of a zoned block (in place, as the model updates it)."""
    body.nodes[:] = body.nodes0 + 0.01 * rng.normal(size=body.nodes0.shape)
    body.vel[:] = rng.normal(size=body.vel.shape)
    body.stress[:] = 1e6 * rng.normal(size=body.stress.shape)
    body.plastic[:] = rng.integers(0, 16, len(body.plastic))


# zoned blocks 3 and 1 of the four blocks of make_scene (passed out of gid order)
ZONED = {3: (11, 9, 7), 1: (12, 6, 5)}  # gid: (seed, gridpoints, zones)


def rigid_snapshot(rng, n=4):
    q = rng.normal(size=(n, 4))
    return rows(rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True),
                rng.normal(size=(n, 3)), rng.normal(size=(n, 3)))


def write(path, n_snap=3, zoned=True, **kw):
    """The four blocks of test_output's scene, blocks 1 and 3 zoned; returns the states written
    (per snapshot: gid -> copies of nodes, nodes0, vel, stress, plastic)."""
    bodies = {g: grid(*args) for g, args in ZONED.items()} if zoned else {}
    rng = np.random.default_rng(5)
    states = []
    with OutputWriter(path, COMM, **make_scene(), zones=list(bodies.items()) if zoned else None,
                      **kw) as w:
        for i in range(n_snap):
            for b in bodies.values():
                move(b, rng)
            states.append({g: {k: np.array(getattr(b, k)) for k in
                               ("nodes", "nodes0", "vel", "stress", "plastic")}
                           for g, b in bodies.items()})
            w.write_snapshot(10 * i, 0.5 * i, np.arange(4), rigid_snapshot(rng),
                             zones=list(bodies.items()))
    return states


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    path = tmp_path_factory.mktemp("zones") / "run.h5"
    return path, write(path)


def test_layout_offsets_in_gid_order_whatever_the_ranks():
    # rank 0 owns gids 7 and 2, rank 1 gid 4, rank 2 none: rows go by gid, not by rank
    lay = zone_layout([np.array([[7, 10, 20], [2, 5, 8]]), np.array([[4, 3, 1]]),
                       np.zeros((0, 3), np.int64)])
    assert lay.gid.tolist() == [2, 4, 7]
    assert lay.point_start.tolist() == [0, 5, 8, 18]
    assert lay.zone_start.tolist() == [0, 8, 9, 29]
    p0, pn, z0, zn = lay.runs(np.array([2, 7]))
    assert (p0.tolist(), pn.tolist(), z0.tolist(), zn.tolist()) == ([0, 8], [5, 10], [0, 9], [8, 20])
    # the same blocks owned differently give the same layout
    again = zone_layout([np.array([[4, 3, 1], [7, 10, 20]]), np.array([[2, 5, 8]])])
    assert all(np.array_equal(a, b) for a, b in zip(lay, again, strict=True))
    with pytest.raises(ValueError, match="two ranks"):
        zone_layout([np.array([[4, 3, 1]]), np.array([[4, 3, 1]])])


def test_static_grid(out):
    path, states = out
    with h5py.File(path, "r") as f:
        z = f["zones"]
        assert z["block"][()].tolist() == [1, 3]
        assert z["point_start"][()].tolist() == [0, 6, 15]
        assert z["zone_start"][()].tolist() == [0, 5, 12]
        b1, b3 = states[0][1], states[0][3]
        assert np.array_equal(z["initial_points"][()], np.concatenate([b1["nodes0"], b3["nodes0"]]))
        conn = z["connectivity"][()]
        assert conn.dtype == np.int64 and conn.shape == (12, 4)
        assert np.array_equal(conn[:5], grid(*ZONED[1]).tets)
        assert np.array_equal(conn[5:], grid(*ZONED[3]).tets + 6)
        assert z["zone_block"][()].tolist() == [1] * 5 + [3] * 7
        assert z["point_block"][()].tolist() == [1] * 6 + [3] * 9


def test_series_are_the_state(out):
    path, states = out
    with h5py.File(path, "r") as f:
        z = f["zones"]
        # the positions float64 (the geometry, the state displacements are measured on); the
        # viewer's fields float32, deflated
        for name, shape, dtype in (("points", (3, 15, 3), np.float64),
                                   ("displacement", (3, 15, 3), np.float32),
                                   ("velocity", (3, 15, 3), np.float32),
                                   ("stress", (3, 12, 6), np.float32),
                                   ("plastic", (3, 12), np.uint8),
                                   ("mean_stress", (3, 12), np.float32),
                                   ("von_mises", (3, 12), np.float32),
                                   ("sigma1", (3, 12), np.float32)):
            assert z[name].shape == shape and z[name].dtype == dtype, name
            assert z[name].compression == "gzip" and z[name].shuffle, name
        for i, st in enumerate(states):
            def cat(k, st=st):
                return np.concatenate([st[1][k], st[3][k]])
            assert np.array_equal(z["points"][i], cat("nodes"))
            # float32: the float64 values rounded once (the nearest float32)
            assert np.array_equal(z["displacement"][i],
                                  (cat("nodes") - cat("nodes0")).astype(np.float32))
            assert np.array_equal(z["velocity"][i], cat("vel").astype(np.float32))
            s = cat("stress")
            assert np.array_equal(z["stress"][i], s.astype(np.float32))
            assert np.array_equal(z["plastic"][i], cat("plastic"))
            full = s[:, [0, 3, 5, 3, 1, 4, 5, 4, 2]].reshape(-1, 3, 3)
            lam = np.linalg.eigvalsh(full)
            for k, name in enumerate(("sigma1", "sigma2", "sigma3")):
                np.testing.assert_allclose(z[name][i], lam[:, k], rtol=1e-6, atol=1e-3)
            np.testing.assert_allclose(z["mean_stress"][i], lam.mean(axis=1), rtol=1e-6, atol=1e-3)
            # von Mises from the principal stresses
            vm = np.sqrt(0.5 * ((lam[:, 0] - lam[:, 1]) ** 2 + (lam[:, 1] - lam[:, 2]) ** 2
                                + (lam[:, 2] - lam[:, 0]) ** 2))
            np.testing.assert_allclose(z["von_mises"][i], vm, rtol=1e-5)
        assert z["stress"].attrs["units"] == "Pa" and "tension positive" in z["stress"].attrs["doc"]


def test_zones_sidecar(out):
    path, states = out
    grids = read_xdmf(zones_path(path.with_suffix(".xdmf")))["zones"]
    assert [g["time"] for g in grids] == [0.0, 0.5, 1.0]
    with h5py.File(path, "r") as f:
        for i, g in enumerate(grids):
            assert g["topology_type"] == "Tetrahedron"
            assert np.array_equal(g["topology"], f["zones/connectivity"][()])
            assert np.array_equal(g["geometry"], f["zones/points"][i])
            a = g["attributes"]
            assert a["displacement"][0] == "Node"
            assert np.array_equal(a["displacement"][1], f["zones/displacement"][i])
            assert np.array_equal(a["velocity"][1], f["zones/velocity"][i])
            assert a["stress"][0] == "Cell" and np.array_equal(a["stress"][1], f["zones/stress"][i])
            for name in ("plastic", "mean_stress", "von_mises", "sigma1", "sigma2", "sigma3"):
                assert a[name][0] == "Cell"
                assert np.array_equal(a[name][1], f[f"zones/{name}"][i]), name
            assert np.array_equal(a["block_id"][1], f["zones/zone_block"][()])
        for i in range(3):  # every view the sidecar reads exists
            for p in ZONE_VIEWED:
                assert f"xdmf/{i:06d}{p}" in f


def test_the_zone_output_is_declared_once():
    """The series of ``zones/`` and the sidecar's attributes come from one table
    (pdem.io.zones.ZONE_COLUMNS): every column with a ``view`` is an attribute, in the table's
    order, with its center, components and number type; every column is a value of a zoned
    block and a view the writer makes."""
    attrs = xdmf._ZONE_ATTRS
    shown = [c for c in ZONE_COLUMNS if c.view is not None]
    assert [a[0] for a in attrs] == [c.name for c in shown]
    for (_, center, kind, width, number, precision), c in zip(attrs, shown, strict=True):
        assert (center, kind, width) == (c.center, c.view, c.width)
        assert np.dtype(c.dtype).itemsize == precision
        assert (number == "Float") == np.issubdtype(c.dtype, np.floating)
    assert ZONE_VIEWED == tuple(f"/zones/{c.name}" for c in ZONE_COLUMNS
                                if c.center == "Node") + tuple(
        f"/zones/{c.name}" for c in ZONE_COLUMNS if c.center == "Cell")
    assert {c.center for c in ZONE_COLUMNS} == {"Node", "Cell"}
    body = grid(3, 5, 2)
    values = zone_values(body)
    assert set(values) == {c.name for c in ZONE_COLUMNS}
    for c in ZONE_COLUMNS:
        n = len(body.nodes0) if c.center == "Node" else len(body.tets)
        assert values[c.name].size == n * c.width, c.name


# the datasets of zones/ that are not series
STATIC = {"block", "point_start", "zone_start", "connectivity", "zone_block", "point_block",
          "initial_points"}


def test_zoned_surfaces_are_the_deformed_grids(out):
    """In ``surface/`` (run.xdmf) a zoned block's triangles are its grid's boundary (the tet
    faces used once, in tet order) and their vertices its boundary gridpoints at the snapshot's
    positions, bitwise ``zones/points``; the rigid blocks keep their polyhedra at ``c + R v``."""
    path, states = out
    surface = read_xdmf(path.with_suffix(".xdmf"))["surface"]
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    with h5py.File(path, "r") as f:
        conn, bid = f["surface/connectivity"][()], f["surface/block_id"][()]
        assert np.bincount(bid).tolist() == [12, len(boundary_of(grid(*ZONED[1]).tets)[1]), 12,
                                             len(boundary_of(grid(*ZONED[3]).tets)[1])]
        for i, st in enumerate(states):
            pts = f["surface/points"][i]
            assert np.array_equal(surface[i]["geometry"], pts)
            for g, args in ZONED.items():
                nodes, tris = boundary_of(grid(*args).tets)
                mine = conn[bid == g]
                first = mine.min()
                assert np.array_equal(mine - first, tris)
                assert np.array_equal(pts[first:first + len(nodes)], st[g]["nodes"][nodes])
            c, q = f["blocks/centroid"][i], f["blocks/orientation"][i]
            for g in (0, 2):  # make_scene's cube g, half-width g + 1
                rows = np.unique(conn[bid == g])
                want = c[g] + (v * (g + 1)) @ quat_to_matrix(q[g:g + 1])[0].T
                np.testing.assert_allclose(pts[rows], want, rtol=0, atol=1e-14)


def test_chosen_zone_fields(tmp_path):
    """``zone_fields`` (output.zones.fields): only those series and the positions are written;
    the sidecar, ``pdem info`` and ``pdem export`` show what the file has; an unknown name is
    refused with the valid ones."""
    import meshio

    from pdem.io import summarise
    from pdem.io.export import export

    path = tmp_path / "some.h5"
    states = write(path, zone_fields=["von_mises", "displacement"])
    with h5py.File(path, "r") as f:
        assert set(f["zones"]) - STATIC == {"points", "displacement", "von_mises"}
        assert sorted(f["xdmf/000002/zones"]) == ["displacement", "points", "von_mises"]
        last = states[-1]
        assert np.array_equal(f["zones/points"][2], np.concatenate([last[1]["nodes"],
                                                                    last[3]["nodes"]]))
    grids = read_xdmf(zones_path(path.with_suffix(".xdmf")))["zones"]
    assert set(grids[-1]["attributes"]) == {"block_id", "displacement", "von_mises"}
    text = summarise(path)
    assert "gridpoint displacement max" in text and "sigma1" not in text
    written = export(path, "vtu", out=tmp_path / "x")
    m = meshio.read([w for w in written if "-zones-000002" in w][0])
    assert set(m.cell_data) == {"block_id", "von_mises"}
    assert set(m.point_data) == {"block_id", "displacement"}
    with pytest.raises(ValueError, match="sigma4.*valid: displacement, velocity, stress"):
        OutputWriter(tmp_path / "bad.h5", COMM, **make_scene(), zones=[(1, grid(*ZONED[1]))],
                     zone_fields=["stress", "sigma4"])


def test_scene_chooses_the_zone_fields():
    """``output.zones.fields``: the writer's names, all by default (a scene that keeps the
    default dumps as before the key existed); a bad name is refused at its key, with the valid
    names; a name twice too."""
    import yaml

    from pdem.config import ConfigError, dump_scene, parse_scene
    from pdem.config.schema import ZONE_FIELDS as SCENE_ZONE_FIELDS

    assert SCENE_ZONE_FIELDS == ZONE_FIELDS
    text = ZONED_SCENE.format(out="col.h5")
    scene = parse_scene(text)
    assert scene.output.zones.fields == list(ZONE_FIELDS)
    assert "zones" not in yaml.safe_load(dump_scene(scene))["output"]
    chosen = text.replace("every_steps: 20}",
                          "every_steps: 20, zones: {fields: [sigma1, stress]}}")
    scene = parse_scene(chosen)
    assert scene.output.zones.fields == ["sigma1", "stress"]
    assert parse_scene(dump_scene(scene)).output.zones.fields == ["sigma1", "stress"]
    for fields, message in (("[stress, sigma4]", "output.zones.fields[1]: Input should be "
                             "'displacement', 'velocity', 'stress', 'plastic', 'mean_stress', "
                             "'von_mises', 'sigma1', 'sigma2' or 'sigma3' (got 'sigma4')"),
                            ("[stress, stress]", "output.zones.fields: stress given more than "
                             "once")):
        with pytest.raises(ConfigError) as e:
            parse_scene(text.replace("every_steps: 20}",
                                     f"every_steps: 20, zones: {{fields: {fields}}}}}"))
        assert message in str(e.value)


def test_gather_fallback_writes_the_same_file(tmp_path, out):
    if not h5py_has_mpi():
        pytest.skip("h5py without MPI: the fixture already used the fallback")
    write(tmp_path / "gathered.h5", parallel=False)
    a, b = contents(tmp_path / "gathered.h5"), contents(out[0])
    assert a.keys() == b.keys()
    for key in a:
        if key.endswith("@"):
            assert a[key].keys() == b[key].keys(), key
            assert all(np.array_equal(a[key][k], b[key][k]) for k in a[key]), key
        else:
            assert a[key][0] == b[key][0] and np.array_equal(a[key][1], b[key][1]), key


def test_rigid_scene_has_no_zones(tmp_path):
    write(tmp_path / "rigid.h5", zoned=False, contacts=True)
    with h5py.File(tmp_path / "rigid.h5", "r") as f:
        assert sorted(f) == ["blocks", "contacts", "histories", "stage", "step", "subcontacts",
                             "surface", "time", "xdmf"]
        assert sorted(f["xdmf/000000"]) == ["blocks", "surface"]  # (no contact passed)
    xdmf = tmp_path / "rigid.xdmf"
    assert contacts_path(xdmf).exists() and not zones_path(xdmf).exists()


def test_union_of_runs_leaves_the_rows_between(tmp_path):
    """A rank whose zoned blocks are not next to one another in gid order (the MPI case) writes
    them with one selection; the rows of the blocks between are another rank's, untouched."""
    with OutputWriter(tmp_path / "runs.h5", COMM, **make_scene()) as w:
        d = w._f.create_dataset("t", (2, 10, 3), np.float64, fillvalue=-1.0)
        data = np.arange(15.0).reshape(5, 3)
        w._write_runs(d, (1,), [1, 7], [2, 3], data)
        w._write_runs(d, (0,), [], [], None)  # a rank with none takes part
        got = d[()]
    assert (got[0] == -1).all()
    assert np.array_equal(got[1, 1:3], data[:2]) and np.array_equal(got[1, 7:10], data[2:])
    assert (got[1, [0, 3, 4, 5, 6]] == -1).all()


def test_bad_zones_raise(tmp_path):
    bodies = {g: grid(*args) for g, args in ZONED.items()}
    rng = np.random.default_rng(1)
    with OutputWriter(tmp_path / "bad.h5", COMM, **make_scene(), zones=list(bodies.items())) as w:
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_snapshot(0, 0.0, np.arange(4), rigid_snapshot(rng), zones=[(1, bodies[1])])
        with pytest.raises(ValueError, match="not a zoned block"):
            w.write_snapshot(0, 0.0, np.arange(4), rigid_snapshot(rng),
                             zones=[(0, bodies[1]), (3, bodies[3])])
        short = SimpleNamespace(**{**vars(bodies[3]), "stress": np.zeros((2, 6))})
        with pytest.raises(ValueError, match="stress"):
            w.write_snapshot(0, 0.0, np.arange(4), rigid_snapshot(rng),
                             zones=[(1, bodies[1]), (3, short)])
        assert w.n_snap == 0
    with pytest.raises(ValueError, match="tets"):
        OutputWriter(tmp_path / "bad2.h5", COMM, **make_scene(),
                     zones=[(1, SimpleNamespace(nodes0=np.zeros((3, 3)), tets=np.array([[0, 1, 2, 5]])))])


ZONES_PROBE = Path(__file__).with_name("pv_zones_probe.py")


def test_paraview_reads_the_zones(out, tmp_path):
    """All three ParaView readers open the zones sidecar: tetrahedra, the arrays of the file
    (stress as the 6 components XX YY ZZ XY YZ XZ, pdem's order), silently; the view renders."""
    from test_paraview import BAD_LOG, pvbatch_command, run_pvbatch

    pvbatch_command()  # skip (or fail in CI) before the run
    path, _ = out
    report = tmp_path / "report.json"
    code, log = run_pvbatch([str(ZONES_PROBE), str(zones_path(path.with_suffix(".xdmf"))),
                             str(report), str(tmp_path)], timeout=600)
    assert code == 0, log[-4000:]
    bad = [line for line in log.splitlines() if any(b in line for b in BAD_LOG)]
    assert not bad, "\n".join(bad)
    got = json.loads(report.read_text())
    with h5py.File(path, "r") as f:
        times = f["time"][()].tolist()
        for reader in ("S", "T", "legacy"):
            r = got[reader]
            assert r["times"] == pytest.approx(times), reader
            for key, i in (("first", 0), ("last", len(times) - 1)):
                (grid,) = r[key]
                assert grid["n_points"] == len(f["zones/initial_points"]), reader
                assert grid["n_cells"] == len(f["zones/connectivity"]), reader
                assert grid["cell_types"] == [10], reader  # VTK_TETRA
                assert np.array_equal(grid["points"], f["zones/points"][i]), reader
                cells, points = grid["cell_arrays"], grid["point_arrays"]
                assert cells["stress"]["components"] == 6, reader
                assert np.array_equal(cells["stress"]["values"], f["zones/stress"][i]), reader
                assert np.array_equal(cells["plastic"]["values"], f["zones/plastic"][i]), reader
                for name in ("mean_stress", "von_mises", "sigma1", "sigma2", "sigma3"):
                    assert np.array_equal(cells[name]["values"], f[f"zones/{name}"][i]), name
                assert np.array_equal(cells["block_id"]["values"], f["zones/zone_block"][()])
                assert np.array_equal(points["displacement"]["values"],
                                      f["zones/displacement"][i]), reader
                assert np.array_equal(points["velocity"]["values"], f["zones/velocity"][i])
            assert r["render"]["drawn"] > 0.02 and r["render"]["coloured"] > 0.01, reader


ZONED_SCENE = """
name: zoned-output
materials:
  rock: {{density: 2000}}
  soft: {{density: 2000, young: 1.0e8, poisson: 0.2, model: mohr_coulomb, cohesion: 2.0e3,
         friction: 30, tension: 1.0e3}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 20}}}}
blocks:
  - {{name: floor, box: {{min: [-1, -1, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: col, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: soft, zones: {{size: 0.5}}}}
  - {{name: cap, box: {{min: [0.2, 0.2, 1], max: [0.8, 0.8, 1.3]}}, material: rock}}
solve: {{steps: 40, damping: local}}
output: {{file: {out}, every_steps: 20}}
"""


@pytest.fixture(scope="module")
def zoned_run(tmp_path_factory):
    """A zoned column under a rigid cap, run 40 steps: the file and the final grids."""
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    out = tmp_path_factory.mktemp("zoned-run") / "col.h5"
    sim = Simulation(parse_scene(ZONED_SCENE.format(out=out)), COMM)
    sim.run()
    sim.close()
    return out, sim.state.grids


def test_run_writes_the_grids(zoned_run):
    out, grids = zoned_run
    (body,) = grids.bodies
    with h5py.File(out, "r") as f:
        assert f["step"][()].tolist() == [0, 20, 40]
        z = f["zones"]
        assert z["block"][()].tolist() == [1]  # the column's gid
        assert np.array_equal(z["connectivity"][()], body.tets)
        assert np.array_equal(z["initial_points"][()], body.nodes0)
        assert np.array_equal(z["points"][-1], body.nodes)
        assert np.array_equal(z["displacement"][-1], (body.nodes - body.nodes0).astype(np.float32))
        assert np.array_equal(z["velocity"][-1], body.vel.astype(np.float32))
        assert np.array_equal(z["stress"][-1], body.stress.astype(np.float32))
        assert np.array_equal(z["plastic"][-1], body.plastic)
        assert np.array_equal(z["displacement"][0], np.zeros_like(body.nodes))
        # gravity has begun to load the column: compression (tension positive) below
        assert z["stress"][-1][:, 2].mean() < 0.0 and z["sigma1"][-1].min() < 0.0
    grid = read_xdmf(zones_path(out.with_suffix(".xdmf")))["zones"]
    assert len(grid) == 3 and grid[-1]["topology"].shape == (len(body.tets), 4)


def test_info_and_export_know_the_zones(zoned_run, tmp_path):
    import meshio

    from pdem.io import summarise
    from pdem.io.export import export

    out, grids = zoned_run
    (body,) = grids.bodies
    text = summarise(out)
    assert f"zones:       1 zoned blocks (col): {len(body.nodes)} gridpoints, " \
           f"{len(body.tets)} zones" in text
    written = export(out, "vtu", out=tmp_path / "x")
    names = [Path(w).name for w in written]
    assert names[-4:] == ["x-zones-000000.vtu", "x-zones-000001.vtu", "x-zones-000002.vtu",
                          "x-zones.pvd"]
    m = meshio.read(written[-2])
    assert m.cells[0].type == "tetra" and np.array_equal(m.cells[0].data, body.tets)
    assert np.array_equal(m.cell_data["stress"][0], body.stress.astype(np.float32))
    assert np.array_equal(m.point_data["displacement"], (body.nodes - body.nodes0).astype(np.float32))


def test_run_xdmf_shows_the_deformed_column(zoned_run):
    """A run's ``run.xdmf``: the zoned column's triangles are its mesher's surface
    (``TetMesh.surface``, in order) at the snapshot's gridpoint positions, the first snapshot's
    at the scene's (``nodes0``), the last's at the final state's, bitwise."""
    out, grids = zoned_run
    (body,) = grids.bodies
    assert not np.array_equal(body.nodes, body.nodes0)
    steps = read_xdmf(out.with_suffix(".xdmf"))["surface"]
    with h5py.File(out, "r") as f:
        col = f["surface/block_id"][()] == 1
        for step, x in ((steps[0], body.nodes0), (steps[-1], body.nodes)):
            tri = step["topology"][col]
            assert np.array_equal(step["geometry"][tri], x[body.mesh.surface])
            assert np.array_equal(step["geometry"][np.unique(tri)],
                                  f["zones/points"][0 if x is body.nodes0 else -1][
                                      np.unique(body.mesh.surface)])


def test_run_chooses_the_zone_fields(tmp_path):
    """``output.zones.fields`` reaches the writer: a run writes only the chosen series."""
    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    out = tmp_path / "few.h5"
    text = ZONED_SCENE.format(out=out).replace("steps: 40", "steps: 20").replace(
        "every_steps: 20}", "every_steps: 20, zones: {fields: [stress, plastic]}}")
    sim = Simulation(parse_scene(text), COMM)
    sim.run()
    sim.close()
    (body,) = sim.state.grids.bodies
    with h5py.File(out, "r") as f:
        assert set(f["zones"]) - STATIC == {"points", "stress", "plastic"}
        assert np.array_equal(f["zones/stress"][-1], body.stress.astype(np.float32))


def test_paraview_shows_the_deformed_surface(zoned_run, tmp_path):
    """All three ParaView readers open ``run.xdmf`` of a run with a zoned block: the surfaces'
    points are ``surface/points`` (the column's its gridpoints), triangles only, silently; the
    view renders coloured cells."""
    from test_paraview import BAD_LOG, pvbatch_command, run_pvbatch

    pvbatch_command()
    out, _ = zoned_run
    report = tmp_path / "report.json"
    code, log = run_pvbatch([str(ZONES_PROBE), str(out.with_suffix(".xdmf")), str(report),
                             str(tmp_path), "displacement_magnitude"], timeout=600)
    assert code == 0, log[-4000:]
    bad = [line for line in log.splitlines() if any(b in line for b in BAD_LOG)]
    assert not bad, "\n".join(bad)
    got = json.loads(report.read_text())
    with h5py.File(out, "r") as f:
        n_tri = len(f["surface/connectivity"])
        for reader in ("S", "T", "legacy"):
            r = got[reader]
            for key, i in (("first", 0), ("last", -1)):
                (grid,) = r[key]
                assert grid["n_cells"] == n_tri and grid["cell_types"] == [5], reader  # triangles
                assert np.array_equal(grid["points"], f["surface/points"][i]), reader
                assert np.array_equal(grid["cell_arrays"]["block_id"]["values"],
                                      f["surface/block_id"][()]), reader
            assert r["render"]["drawn"] > 0.02 and r["render"]["coloured"] > 0.01, reader
