"""OutputWriter, XDMF sidecar and summary on one rank (MPI.COMM_SELF)."""

import itertools
import warnings
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pdem.io import OutputWriter, centroids_path, read_xdmf, summarise
from pdem.io import layout as row_layout
from pdem.io.xdmf import CELL_FIELDS, VIEWED_SERIES, view_path
from pdem.model.fields import BLOCK


def rows(centroid, quat, velocity, angular_velocity) -> dict:
    """A snapshot's rows by output name, as the Snapshots plugin passes them."""
    return {"centroid": centroid, "orientation": quat, "velocity": velocity,
            "angular_velocity": angular_velocity}

COMM = MPI.COMM_SELF
SCENE = "name: two-shapes\nblocks: []\n"
ATTRS = {"pdem_version": "0.1.0", "run_id": "test-run", "n_ranks": 1}


def box(a, b, c):
    v = np.array([[sx * a, sy * b, sz * c] for sx, sy, sz in itertools.product((-1, 1), repeat=3)])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return v, faces


def tet():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    return v - v.mean(axis=0), [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def rodrigues(axis, angle):
    """Rotation matrix from axis-angle, independent of the writer's quaternion formula."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def quat(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * k])


def make_scene():
    shapes = [box(1.0, 0.5, 0.25), tet(), box(0.3, 0.3, 0.3), tet()]
    return {
        "block_names": ["slab", "tet-a", "cube", "tét-β"],
        "body_vertices": [s[0] for s in shapes],
        "body_faces": [s[1] for s in shapes],
        "scene_yaml": SCENE,
        "attrs": ATTRS,
    }


def make_snapshots(n=4, n_snap=3, seed=1):
    """Per snapshot: step, time, centroid, (axis, angle), quaternion, velocity, omega."""
    rng = np.random.default_rng(seed)
    snaps = []
    for s in range(n_snap):
        axes = rng.normal(size=(n, 3))
        angles = rng.uniform(-np.pi, np.pi, n)
        snaps.append(
            {
                "step": 100 * s,
                "time": 0.01 * s,
                "centroid": rng.normal(size=(n, 3)) * 10,
                "axes": axes,
                "angles": angles,
                "quat": np.array([quat(a, t) for a, t in zip(axes, angles, strict=True)]),
                "velocity": rng.normal(size=(n, 3)),
                "angular_velocity": rng.normal(size=(n, 3)),
            }
        )
    return snaps


def write_file(path, snaps, order=None, **kw):
    scene = make_scene()
    n = len(scene["block_names"])
    order = np.arange(n) if order is None else np.asarray(order)
    with OutputWriter(path, COMM, **scene, **kw) as w:
        w.add_history("top_z", 1, {"block": "cube", "quantity": "z", "units": "m"})
        w.add_history("slab_v", 3, {"block": "slab", "quantity": "velocity"})
        for s in snaps:
            w.write_snapshot(s["step"], s["time"], order,
                             rows(s["centroid"][order], s["quat"][order], s["velocity"][order],
                                  s["angular_velocity"][order]))
            w.write_history("top_z", s["time"], s["centroid"][2, 2:3])
            w.write_history("slab_v", s["time"], s["velocity"][0])
    return path


def h5_contents(path):
    """Every dataset and attribute of a file, keyed by path."""
    out = {}
    with h5py.File(path, "r") as f:
        out["/@"] = {k: f.attrs[k] for k in f.attrs}

        def visit(name, obj):
            out[name + "@"] = {k: obj.attrs[k] for k in obj.attrs}
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.dtype, obj[()])

        f.visititems(visit)
    return out


def assert_same_contents(a, b):
    ca, cb = h5_contents(a), h5_contents(b)
    assert ca.keys() == cb.keys()
    for key in ca:
        if key.endswith("@"):
            assert ca[key].keys() == cb[key].keys(), key
            for k in ca[key]:
                assert np.array_equal(ca[key][k], cb[key][k]), (key, k)
        else:
            assert ca[key][0] == cb[key][0], key
            assert ca[key][1].shape == cb[key][1].shape, key
            assert np.array_equal(ca[key][1], cb[key][1]), key


@pytest.fixture
def snaps():
    return make_snapshots()


@pytest.fixture
def out(tmp_path, snaps):
    return write_file(tmp_path / "run.h5", snaps, order=[2, 0, 3, 1])


def test_layout_shapes_and_dtypes(out):
    with h5py.File(out, "r") as f:
        expect = {
            "time": ((3,), np.float64),
            "step": ((3,), np.int64),
            "blocks/gid": ((4,), np.int64),
            "blocks/centroid": ((3, 4, 3), np.float64),
            "blocks/orientation": ((3, 4, 4), np.float64),
            "blocks/velocity": ((3, 4, 3), np.float64),
            "blocks/angular_velocity": ((3, 4, 3), np.float64),
            # two boxes: 6 quads -> 12 triangles each; two tets: 4 triangles each
            "surface/connectivity": ((32, 3), np.int64),
            "surface/block_id": ((32,), np.int64),
            "surface/points": ((3, 24, 3), np.float64),
            "histories/top_z/time": ((3,), np.float64),
            "histories/top_z/value": ((3, 1), np.float64),
            "histories/slab_v/value": ((3, 3), np.float64),
        }
        for name, (shape, dtype) in expect.items():
            assert f[name].shape == shape, name
            assert f[name].dtype == dtype, name
        for name in ("time", "blocks/centroid", "surface/points"):
            assert f[name].maxshape[0] is None
            assert f[name].chunks is not None
        assert f["surface/connectivity"].maxshape == (32, 3)


def test_values_round_trip(out, snaps):
    with h5py.File(out, "r") as f:
        assert f["time"][()].tolist() == [0.0, 0.01, 0.02]
        assert f["step"][()].tolist() == [0, 100, 200]
        for i, s in enumerate(snaps):
            assert np.array_equal(f["blocks/centroid"][i], s["centroid"])
            assert np.array_equal(f["blocks/orientation"][i], s["quat"])
            assert np.array_equal(f["blocks/velocity"][i], s["velocity"])
            assert np.array_equal(f["blocks/angular_velocity"][i], s["angular_velocity"])
        assert np.array_equal(f["blocks/gid"][()], np.arange(4))
        assert list(f["blocks/name"].asstr()[()]) == ["slab", "tet-a", "cube", "tét-β"]
        assert f.attrs["pdem_format"] == "output"
        assert f.attrs["format_version"] == 2
        assert f.attrs["scene"] == SCENE
        for k, v in ATTRS.items():
            assert f.attrs[k] == v
        assert f["blocks/velocity"].attrs["units"] == "m/s"


def test_surface_points_are_rotated_body_vertices(out, snaps):
    scene = make_scene()
    with h5py.File(out, "r") as f:
        pts = f["surface/points"][()]
        conn = f["surface/connectivity"][()]
        bid = f["surface/block_id"][()]
    starts = np.cumsum([0] + [len(v) for v in scene["body_vertices"]])
    for i, s in enumerate(snaps):
        for b, v in enumerate(scene["body_vertices"]):
            R = rodrigues(s["axes"][b], s["angles"][b])
            world = s["centroid"][b] + v @ R.T
            np.testing.assert_allclose(pts[i, starts[b] : starts[b + 1]], world, atol=1e-12)
    # triangles stay within their block and face outward (CCW seen from outside)
    assert np.bincount(bid).tolist() == [12, 4, 12, 4]
    for t, b in zip(conn, bid, strict=True):
        assert starts[b] <= t.min() and t.max() < starts[b + 1]
        p = pts[0][t]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        assert np.linalg.norm(normal) > 1e-9
        assert normal @ (p.mean(axis=0) - snaps[0]["centroid"][b]) > 0


def test_histories(out, snaps):
    with h5py.File(out, "r") as f:
        h = f["histories/top_z"]
        assert dict(h.attrs) == {"block": "cube", "quantity": "z", "units": "m"}
        assert np.array_equal(h["time"][()], [s["time"] for s in snaps])
        assert np.array_equal(h["value"][:, 0], [s["centroid"][2, 2] for s in snaps])
        assert np.array_equal(f["histories/slab_v/value"][()], [s["velocity"][0] for s in snaps])


def test_gather_fallback_writes_the_same_file(tmp_path, snaps, out):
    other = write_file(tmp_path / "gathered.h5", snaps, order=[3, 1, 0, 2], parallel=False)
    assert_same_contents(out, other)


def test_input_order_does_not_matter(tmp_path, snaps, out):
    other = write_file(tmp_path / "ordered.h5", snaps)
    assert_same_contents(out, other)


def test_fallback_warns_once_when_h5py_lacks_mpi(tmp_path, snaps, monkeypatch):
    monkeypatch.setattr(row_layout, "h5py_has_mpi", lambda: False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_file(tmp_path / "nompi.h5", snaps)
    msgs = [str(w.message) for w in caught]
    assert len(msgs) == 1 and "gathered on rank 0" in msgs[0]
    with pytest.raises(RuntimeError, match="without MPI"):
        OutputWriter(tmp_path / "x.h5", COMM, **make_scene(), parallel=True)


def test_xdmf_references_resolve(out, snaps):
    xdmf = out.with_suffix(".xdmf")
    # one temporal collection per sidecar (Xdmf3 Reader S would join two into one mesh)
    for path, name in ((xdmf, "surface"), (out.with_name("run-centroids.xdmf"), "blocks")):
        root = ET.parse(path).getroot()
        colls = root.find("Domain").findall("Grid")
        assert [(c.get("Name"), c.get("CollectionType")) for c in colls] == [(name, "Temporal")]
        # the HDF5 file is referenced by its bare name so the files can move together
        for item in root.iter("DataItem"):
            if item.get("Format") == "HDF":
                assert item.text.startswith("run.h5:/")
    grids = {**read_xdmf(xdmf), **read_xdmf(centroids_path(xdmf))}
    with h5py.File(out, "r") as f:
        for i, step in enumerate(grids["surface"]):
            assert step["time"] == snaps[i]["time"]
            assert step["topology_type"] == "Triangle"
            assert np.array_equal(step["topology"], f["surface/connectivity"][()])
            assert np.array_equal(step["geometry"], f["surface/points"][i])
            assert np.array_equal(step["attributes"]["block_id"][1], f["surface/block_id"][()])
            for name, _, _ in CELL_FIELDS:
                center, value = step["attributes"][name]
                assert center == "Cell" and np.array_equal(value.ravel(), f[f"surface/{name}"][i].ravel())
        assert len(grids["surface"]) == 3
        for i, step in enumerate(grids["blocks"]):
            assert step["topology_type"] == "Polyvertex"
            assert np.array_equal(step["geometry"], snaps[i]["centroid"])
            assert np.array_equal(step["attributes"]["velocity"][1], snaps[i]["velocity"])
            # the cloud's series attributes are the block fields declared ``view``
            # (pdem.model.fields: a field's one line puts it in ParaView), each snapshot's
            viewed = {fd.output: fd for fd in BLOCK if fd.view}
            assert set(step["attributes"]) == {"gid", "group", "fixed", *viewed}
            for name, fd in viewed.items():
                assert np.array_equal(step["attributes"][name][1], snaps[i][name])
                assert step["attributes"][name][1].shape[1:] == fd.shape
        assert len(grids["blocks"]) == 3


VIEWER = {"initial_centroid": np.arange(12.0).reshape(4, 3), "group": [1, 0, 0, 1],
          "group_names": ["soft", "hard"], "fixed": [True, False, False, False]}


def test_viewer_fields(tmp_path, snaps):
    """Per-triangle copies of each block's displacement, velocity, ... and their views."""
    path = write_file(tmp_path / "v.h5", snaps, order=[3, 1, 0, 2], **VIEWER)
    with h5py.File(path, "r") as f:
        tb = f["surface/block_id"][()]
        x0 = VIEWER["initial_centroid"]
        assert np.array_equal(f["blocks/initial_centroid"][()], x0)
        assert np.array_equal(f["blocks/group"][()], VIEWER["group"])
        assert list(f["blocks/group"].attrs["names"]) == ["soft", "hard"]
        assert np.array_equal(f["surface/group"][()], np.array(VIEWER["group"])[tb])
        assert np.array_equal(f["surface/fixed"][()], np.array(VIEWER["fixed"], int)[tb])
        for i, s in enumerate(snaps):
            d = s["centroid"] - x0
            expect = {"displacement": d, "displacement_magnitude": np.linalg.norm(d, axis=1),
                      "velocity": s["velocity"], "speed": np.linalg.norm(s["velocity"], axis=1),
                      "angular_velocity": s["angular_velocity"],
                      "removed": np.zeros(len(d)),  # not passed: every block in the model
                      "stage_displacement": d}  # no stages: from the start
            for name, _, _ in CELL_FIELDS:
                got = f[f"surface/{name}"][i]
                assert got.dtype == np.float32
                assert np.allclose(got, expect[name][tb], rtol=1e-6, atol=1e-6), name
            for path_ in VIEWED_SERIES:
                view = f[view_path(path_, i)]
                assert view.is_virtual and np.array_equal(view[()], f[path_][i]), path_


def test_displacement_defaults_to_first_snapshot(out, snaps):
    with h5py.File(out, "r") as f:
        assert np.array_equal(f["blocks/initial_centroid"][()], snaps[0]["centroid"])
        assert not f["surface/displacement"][0].any()
        assert np.array_equal(f["blocks/fixed"][()], np.zeros(4))
        assert list(f["blocks/group"].attrs["names"]) == ["default"]


@pytest.mark.parametrize(
    "bad",
    [{"group": [0, 1, 0, 0]}, {"fixed": [True]}, {"initial_centroid": np.zeros((4, 2))},
     {"group": [0, 0, 0, 2], "group_names": ["a", "b"]}],
)
def test_bad_viewer_fields_raise(tmp_path, bad):
    with pytest.raises(ValueError, match="OutputWriter"):
        OutputWriter(tmp_path / "bad.h5", COMM, **make_scene(), **bad)


def test_read_xdmf_reads_format_1_hyperslabs(out, snaps):
    """Format 1 sidecars selected a snapshot with a HyperSlab item; read_xdmf still reads them."""
    with h5py.File(out, "r") as f:
        n_snap, n_pts, _ = f["surface/points"].shape
        n_tri = len(f["surface/connectivity"])
    i = 2
    slab = (
        f'<DataItem ItemType="HyperSlab" Dimensions="1 {n_pts} 3" Type="HyperSlab">'
        f'<DataItem Dimensions="3 3" NumberType="Int" Format="XML">{i} 0 0 1 1 1 1 {n_pts} 3</DataItem>'
        f'<DataItem Dimensions="{n_snap} {n_pts} 3" NumberType="Float" Precision="8" Format="HDF">'
        f"run.h5:/surface/points</DataItem></DataItem>"
    )
    old = out.with_name("old.xdmf")
    old.write_text(
        '<Xdmf Version="3.0"><Domain><Grid Name="surface" GridType="Collection" '
        'CollectionType="Temporal"><Grid Name="s" GridType="Uniform"><Time Value="0.02"/>'
        f'<Topology TopologyType="Triangle" NumberOfElements="{n_tri}"><DataItem Dimensions="{n_tri} 3" '
        'NumberType="Int" Format="HDF">run.h5:/surface/connectivity</DataItem></Topology>'
        f'<Geometry GeometryType="XYZ">{slab}</Geometry></Grid></Grid></Domain></Xdmf>'
    )
    (step,) = read_xdmf(old)["surface"]
    with h5py.File(out, "r") as f:
        assert np.array_equal(step["geometry"], f["surface/points"][i])


def test_xdmf_written_after_every_snapshot(tmp_path, snaps):
    path = tmp_path / "live.h5"
    w = OutputWriter(path, COMM, **make_scene())
    s = snaps[0]
    for k in range(2):
        w.write_snapshot(k, k * 0.5, np.arange(4), rows(s["centroid"], s["quat"], s["velocity"],
                                                        s["angular_velocity"]))
        root = ET.parse(path.with_suffix(".xdmf")).getroot()
        assert len(root.find("Domain").find("Grid").findall("Grid")) == k + 1
    w.close()
    w.close()  # idempotent
    assert len(read_xdmf(path.with_suffix(".xdmf"))["surface"]) == 2


def test_bad_input_raises(tmp_path, snaps):
    s = snaps[0]
    with OutputWriter(tmp_path / "bad.h5", COMM, **make_scene()) as w:
        args = (s["centroid"], s["quat"], s["velocity"], s["angular_velocity"])
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_snapshot(0, 0.0, [0, 1, 1, 3], rows(*args))
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_snapshot(0, 0.0, [0, 1, 2], rows(*(a[:3] for a in args)))
        with pytest.raises(ValueError, match="orientation has shape"):
            w.write_snapshot(0, 0.0, [0, 1, 2, 3], rows(s["centroid"], s["quat"][:, :3],
                                                        s["velocity"], s["angular_velocity"]))
        with pytest.raises(ValueError, match="no orientation rows"):
            w.write_snapshot(0, 0.0, [0, 1, 2, 3], {"centroid": s["centroid"]})
        with pytest.raises(ValueError, match="outside"):
            w.write_snapshot(0, 0.0, [0, 1, 2, 4], rows(*args))
        w.add_history("h", 2)
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_history("h", 0.0, None)
        with pytest.raises(ValueError, match="exactly one rank"):
            w.write_history("h", 0.0, [1.0, 2.0, 3.0])
        with pytest.raises(ValueError, match="no history"):
            w.write_history("nope", 0.0, [1.0])
        with pytest.raises(ValueError, match="duplicate"):
            w.add_history("h", 2)
    with h5py.File(tmp_path / "bad.h5", "r") as f:
        assert f["time"].shape == (0,)
        assert f["histories/h/value"].shape == (0, 2)
    for faces in ([[0, 1]], [[0, 1, 2], [0, 1, 4]], [[0, 1, 2], []]):
        bad = make_scene()
        bad["body_faces"][1] = faces
        with pytest.raises(ValueError, match=r"body_faces\[1\]\[\d\]"):
            OutputWriter(tmp_path / "bad2.h5", COMM, **bad)


def test_large_scene_attribute(tmp_path):
    scene = make_scene()
    scene["scene_yaml"] = "name: big\n" + "# padding line for a long scene\n" * 5000
    with OutputWriter(tmp_path / "big.h5", COMM, **scene):
        pass
    with h5py.File(tmp_path / "big.h5", "r") as f:
        assert f.attrs["scene"] == scene["scene_yaml"]


def test_summarise_small(out):
    text = summarise(out)
    assert "blocks:      4" in text
    assert "snapshots:   3" in text
    assert "steps 0 .. 200" in text
    assert "two-shapes" in text and "test-run" in text and "0.1.0" in text
    assert "top_z (3 rows x 1)" in text and "slab_v (3 rows x 3)" in text
    for name in ("slab", "tet-a", "cube", "tét-β"):
        assert f"\n  {name} " in text


def test_summarise_reads_format_1(tmp_path, snaps):
    """A format 1 file (no viewer fields) is still summarised, with a note on viewing it."""
    path = write_file(tmp_path / "old.h5", snaps)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 1
        for name in ("xdmf", "blocks/group", "blocks/fixed", "blocks/initial_centroid",
                     "surface/group", "surface/fixed", *(f"surface/{c[0]}" for c in CELL_FIELDS)):
            del f[name]
    text = summarise(path)
    assert "format 1" in text and "legacy XDMF reader" in text
    assert "snapshots:   3" in text
    assert "groups:      default (4)" in summarise(write_file(tmp_path / "new.h5", snaps))


def test_summarise_many_blocks(tmp_path):
    n = 25
    v, faces = box(0.5, 0.5, 0.5)
    scene = {"block_names": [f"b{i}" for i in range(n)], "body_vertices": [v] * n,
             "body_faces": [faces] * n, "scene_yaml": "name: many\n", "attrs": {}}
    c0 = np.zeros((n, 3))
    c1 = c0.copy()
    c1[7, 2] = -2.0
    vel = np.zeros((n, 3))
    vel[3] = [3.0, 4.0, 0.0]
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    with OutputWriter(tmp_path / "many.h5", COMM, **scene) as w:
        w.write_snapshot(0, 0.0, np.arange(n), rows(c0, q, vel * 0, vel * 0))
        w.write_snapshot(10, 1.0, np.arange(n), rows(c1, q, vel, vel * 0))
    text = summarise(tmp_path / "many.h5")
    assert "blocks:      25" in text and "snapshots:   2" in text
    assert "max 2 m (b7)" in text
    assert "max 5 m/s (b3)" in text
    assert "\n  b0 " not in text


def test_summarise_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        summarise(tmp_path / "missing.h5")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(ValueError, match="not an HDF5 file"):
        summarise(tmp_path / "notes.txt")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(ValueError, match="not a pdem file"):
        summarise(tmp_path / "other.h5")


def test_hundreds_of_snapshots(tmp_path, snaps):
    """Parallel HDF5 takes a communicator per snapshot view until the file closes; a long run
    (here 300 snapshots, ~2700 views) must not run out of them, and every view reads back."""
    s = snaps[0]
    path = tmp_path / "long.h5"
    with OutputWriter(path, COMM, **make_scene()) as w:
        for k in range(300):
            w.write_snapshot(k, 0.01 * k, np.arange(4), rows(s["centroid"], s["quat"],
                                                             s["velocity"], s["angular_velocity"]))
    with h5py.File(path, "r") as f:
        assert f["time"].shape == (300,)
        np.testing.assert_array_equal(f["xdmf/000299/surface/points"][()],
                                      f["surface/points"][299])
