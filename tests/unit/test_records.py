"""History files (pdem.config.records; ``history: {file: ...}``, docs/dynamics.md "History
files"): reading CSV and PEER NGA ``.AT2`` records, integrating an acceleration, the baseline
correction, and the messages a malformed file gets.

Closed forms, computed here:

* ``a = A sin(w t)`` sampled at ``dt`` and integrated by the trapezoid rule is
  ``A (1 - cos w t) / w`` within the composite rule's error bound ``t dt^2 max|a''| / 12 =
  t dt^2 A w^2 / 12`` (asserted at every sample);
* the baseline-corrected velocity and its trapezoid integral (the displacement of the
  piecewise-linear motion the model follows) end at zero to round-off (1e-12 of the peak
  velocity, and of the peak velocity times the duration);
* a record already at rest at its end (a cubic velocity, zero at both ends and of zero mean,
  given as its acceleration) is corrected by at most 17 E, E the trapezoid bound above at
  T: the correction's
  coefficients are ``c1 T = 6 D / T - 2 e``, ``c2 T^2 = 3 e - 6 D / T`` for end errors
  ``|e| <= E``, ``|D| <= E T``;
* a correction of a pure ``c1 t + c2 t^2`` velocity returns its coefficients (to 1e-12).
"""

from __future__ import annotations

import math
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from pdem.boundary import history_velocity
from pdem.config import ConfigError, dump_scene, load_scene, parse_scene
from pdem.config import records as R
from pdem.config.load import _anchor_files

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "configs" / "records"

SCENE = """
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - {{name: b, box: {{min: [0, 0, 0], max: [1, 1, 1]}}, material: rock}}
boundary:
  velocity:
    - names: [b]
      history: {history}
solve: {{steps: 1}}
"""


def scene_with(history: str):
    return parse_scene(SCENE.format(history=history))


def message(history: str) -> str:
    with pytest.raises(ConfigError) as e:
        scene_with(history)
    (msg,) = e.value.messages
    return msg


def at2(tmp_path, header4: str, values: str, name: str = "r.at2") -> Path:
    p = tmp_path / name
    p.write_text(f"PEER NGA STRONG MOTION DATABASE RECORD\nSome quake, 1/1/2000, station, 090\n"
                 f"ACCELERATION TIME SERIES IN UNITS OF G\n{header4}\n{values}")
    return p


SEVEN = " .1000E-01  .2000E-01 -.3000E-01  4.0E-02  -5.0e-2\n 6.0E-02  7.0E-02\n"


@pytest.mark.parametrize("header4", [
    "NPTS=  7, DT=   .0050 SEC",
    "NPTS= 7, DT= 0.005 SEC,",
    "npts=7, dt=.005 sec",
    "NPTS=    7, DT=   .00500 SEC  (filtered, 0.1-25 Hz)",
    "NPTS=7,DT=5.0E-3SEC",
    "    7    .0050    NPTS, DT",
])
@pytest.mark.parametrize("name", ["r.at2", "r.AT2", "r.At2"])
def test_at2_header_variants(tmp_path, header4, name):
    t, a = R.read_series(str(at2(tmp_path, header4, SEVEN, name)))
    assert np.array_equal(t, np.arange(7) * 0.005)
    assert np.array_equal(a, [0.01, 0.02, -0.03, 0.04, -0.05, 0.06, 0.07])


def test_csv_headers_comments_separators(tmp_path):
    p = tmp_path / "v.csv"
    p.write_text("# a velocity pulse\nrecorded at station X\ntime, velocity  # m/s\n\n"
                 "0, 0\n0.1,0.5,\n  0.2\t-0.25   # a comment\n0.3 1e-1\n\n# done\n")
    t, v = R.read_series(str(p))
    assert np.array_equal(t, [0.0, 0.1, 0.2, 0.3])
    assert np.array_equal(v, [0.0, 0.5, -0.25, 0.1])
    p2 = tmp_path / "v.txt"  # not .at2: read as CSV
    p2.write_text("0 1\n1 2\n")
    assert np.array_equal(R.read_series(str(p2))[1], [1.0, 2.0])


def _bad_files(tmp_path):
    """(file, its text, the message after the file name)."""
    head = "h1\nh2\nh3\nNPTS=  8, DT= .005 SEC\n"
    return [
        ("x.at2", head + "1 2 3 4 5\n6 abc 8\n", "line 6: 'abc' is not a number"),
        ("x.at2", head + "1 2 3 4 5\n6 7\n", ": NPTS = 8 but 7 values"),
        ("x.at2", head + "1 2 3 4 5\n6 7 8 9\n", ": NPTS = 8 but 9 values"),
        ("x.at2", head + "1 2 nan 4 5\n6 7 8\n", "line 5: 'nan' is not finite"),
        ("x.at2", head + "1 2 3 4 5\n6 7 1e999\n", "line 6: '1e999' is not finite"),
        ("x.at2", "h1\nh2\nh3\nDT= .005 SEC\n1 2\n", "line 4: no NPTS and DT in 'DT= .005 SEC'"),
        ("x.at2", "h1\nh2\nh3\nNPTS= 2, DT= 0 SEC\n1 2\n", "line 4: DT = 0 must be positive"),
        ("x.at2", "h1\nh2\n", "line 2: ends in the header"),
        ("x.csv", "t,v\n0,0\n0.1,1\n0.3,2\n0.2,3\n", "line 5: times must increase strictly "
         "(t = 0.2 after 0.3, line 4)"),
        ("x.csv", "0,0\n0.1,1\n0.1,2\n", "line 3: times must increase strictly"),
        ("x.csv", "t,v\n0,1\n", ": 2 rows at least (time, value), got 1"),
        ("x.csv", "0,0\n0.1,inf\n", "line 2: 'inf' is not finite"),
        ("x.csv", "0,0\n0.1,1,2\n", "line 2: 3 fields, expected 2 (time, value)"),
        ("x.csv", "0,0\n0.1,1\nend of data\n", "line 3: 3 fields, expected 2"),
        ("x.csv", "0,0\n0.1,1\n0.2,abc\n", "line 3: 'abc' is not a number"),
        ("x.csv", "-0.1,0\n0.1,1\n", "line 1: time -0.1 is negative"),
        ("x.csv", "0,0\n0.1,1_0\n", "line 2: '1_0' is not a number"),
    ]


def test_malformed_files_are_refused_naming_key_file_and_line(tmp_path):
    for k, (name, text, want) in enumerate(_bad_files(tmp_path)):
        p = tmp_path / f"{k}-{name}"
        p.write_text(text)
        msg = message(f"{{file: {p}, direction: [1, 0, 0]}}")
        assert msg.startswith(f"boundary.velocity[0].history.file: {p}"), msg
        assert want in msg, (msg, want)
        assert msg.endswith("[line 9]"), msg  # the scene line of the history
    missing = tmp_path / "nope.at2"
    msg = message(f"{{file: {missing}, direction: [1, 0, 0]}}")
    assert msg.startswith(f"boundary.velocity[0].history.file: {missing}: cannot read: No such "
                          "file"), msg
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"0,0\n\xff\xfe,1\n")
    assert "not a text file" in message(f"{{file: {binary}, direction: [1, 0, 0]}}")


def test_history_keys_are_checked(tmp_path):
    p = tmp_path / "v.csv"
    p.write_text("0,0\n1,3\n")
    f = f"file: {p}"
    for history, want in [
        (f"{{{f}}}", "boundary.velocity[0].history.direction: needed with file"),
        (f"{{{f}, direction: [0, 0, 0]}}", "history.direction: a zero vector has no direction"),
        (f"{{{f}, direction: [1, 0, 0], quantity: displacement}}", "history.quantity: Input "
         "should be 'velocity' or 'acceleration'"),
        (f"{{{f}, direction: [1, 0, .nan]}}", "history.direction"),
        (f"{{{f}, direction: [1, 0, 0], scale: .inf}}", "history.scale"),
        (f"{{{f}, direction: [1, 0, 0], table: [[0, 1, 0, 0]]}}", "history: give exactly one of "
         "table, harmonic, file (got table, file)"),
        ("{table: [[0, 1, 0, 0]], scale: 2.0}", "history.scale: only with file"),
        (f"{{{f}, direction: [1, 0, 0], baseline: true}}", "baseline: needs 3 rows at least"),
        (f"{{{f}, direction: [1, 0, 0], scale: 1000000.0, quantity: acceleration, "
         "baseline: false}", f"history.file: {p}: the velocity reaches 1.5e+06 m/s"),
    ]:
        msg = message(history)
        assert want in msg, (msg, want)


def test_stage_history_errors_name_the_stage(tmp_path):
    text = SCENE.format(history="{table: [[0, 0, 0, 0]]}").replace("solve: {steps: 1}", f"""
solve: {{}}
stages:
  - name: a
    velocity: [{{names: [b], history: {{file: {tmp_path}/no.csv, direction: [0, 0, 1]}}}}]
    solve: {{steps: 1}}
""")
    with pytest.raises(ConfigError) as e:
        parse_scene(text)
    (msg,) = e.value.messages
    assert msg.startswith(f"stages[0].velocity[0].history.file: {tmp_path}/no.csv: cannot read"), msg


def test_trapezoid_integral_of_a_sine_within_its_error_bound():
    A, w, dt, T = 2.0, 2 * math.pi * 3.0, 0.005, 4.0
    t = np.arange(int(round(T / dt)) + 1) * dt
    v = R.trapezoid(t, A * np.sin(w * t))
    exact = A * (1.0 - np.cos(w * t)) / w
    bound = t * dt * dt * A * w * w / 12.0 + 1e-14
    err = np.abs(v - exact)
    print(f"\ntrapezoid: max error {err.max():.3g} m/s, bound at T {bound[-1]:.3g}; "
          f"largest error / bound {(err / bound)[1:].max():.3f}")
    assert (err <= bound).all()


def test_baseline_ends_at_rest_to_round_off():
    A, w, dt, T = 2.0, 2 * math.pi * 3.0, 0.005, 4.1  # not whole cycles: drift in v and d
    t = np.arange(int(round(T / dt)) + 1) * dt
    raw = R.trapezoid(t, A * np.sin(w * t))
    vc = R.corrected(t, raw)
    d = R.trapezoid(t, vc)
    peak = np.abs(vc).max()
    print(f"\nbaseline: v(T) {vc[-1]:.3g} (set), d(T) {d[-1]:.3g} m, raw d(T) "
          f"{R.trapezoid(t, raw)[-1]:.3g} m, peak v {peak:.3g} m/s")
    assert vc[-1] == 0.0 and vc[0] == raw[0] == 0.0
    assert abs(d[-1]) < 1e-12 * peak * T
    # the same without the end set to 0: the equations' own residual
    c1, c2 = R.baseline_coefficients(t, raw)
    assert abs(raw[-1] - c1 * T - c2 * T * T) < 1e-12 * peak
    # a velocity that is a pure c1 t + c2 t^2 is corrected to zero: the coefficients back
    c1, c2 = R.baseline_coefficients(t, 0.3 * t - 0.05 * t * t)
    assert c1 == pytest.approx(0.3, rel=1e-12) and c2 == pytest.approx(-0.05, rel=1e-12)


def test_correction_is_small_for_a_record_ending_at_rest():
    """``v = V s (1 - s) (1 - 2 s)``, ``s = t / T``: at rest at T and back where it began
    (antisymmetric about T / 2), given as its acceleration ``a = V (1 - 6 s + 6 s^2) / T``
    (``a'' = 12 V / T^3``: the trapezoid rule is not exact for it, unlike for a whole cycle
    of a sine)."""
    V, T, dt = 2.0, 2.0, 0.005
    t = np.arange(int(round(T / dt)) + 1) * dt
    s = t / T
    raw = R.trapezoid(t, V * (1.0 - 6.0 * s + 6.0 * s * s) / T)
    exact = V * s * (1.0 - s) * (1.0 - 2.0 * s)
    corr = np.abs(R.corrected(t, raw) - raw)
    E = T * dt * dt * (12.0 * V / T**3) / 12.0
    print(f"\nrecord at rest: end error {raw[-1] - exact[-1]:.3g} m/s (E = {E:.3g}), correction "
          f"{corr.max():.3g} m/s, 17 E = {17 * E:.3g}, peak {np.abs(exact).max():.3g} m/s")
    assert abs(raw[-1] - exact[-1]) <= E * (1 + 1e-9) + 1e-15
    assert 0.0 < corr.max() <= 17 * E


def test_resolved_table_direction_scale_and_defaults(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("0,0\n0.5,1\n1.0,1\n1.5,0\n")
    h = scene_with(f"{{file: {p}, quantity: acceleration, direction: [3, 0, 4], scale: -2.0, "
                   "baseline: false}").boundary.velocity[0].history
    t, v = R.read_series(str(p))
    want = R.trapezoid(t, -2.0 * v)
    rec = h.record
    assert np.array_equal(rec.times, t)
    assert np.allclose(rec.velocity, want[:, None] * np.array([0.6, 0.0, 0.8]), rtol=1e-15,
                       atol=0)
    assert (want[1:] < 0).all() and not np.signbit(rec.velocity[:, 1]).any()  # 0.0, not -0.0
    assert np.array_equal(history_velocity(h, 99.0), rec.velocity[-1])  # held after the end
    assert np.array_equal(history_velocity(h, 0.25), 0.5 * (rec.velocity[0] + rec.velocity[1]))
    # the defaults: velocity, scale 1, baseline true only for an acceleration
    h = scene_with(f"{{file: {p}, direction: [0, 1, 0]}}").boundary.velocity[0].history
    assert (h.quantity, h.scale, h.baseline) == ("velocity", 1.0, False)
    h = scene_with(f"{{file: {p}, quantity: acceleration, direction: [0, 1, 0]}}"
                   ).boundary.velocity[0].history
    assert h.baseline is True and h.record.velocity[-1, 1] == 0.0


def test_velocity_file_gives_the_table_history_bits(tmp_path):
    """A velocity CSV along x is the ``table`` history of the same rows, bit for bit, at any
    time (both interpolate with np.interp); no -0.0 in the components off the direction."""
    rows = [(0.0, 0.0), (0.013, -0.7), (0.05, 0.31), (0.2, 1.0 / 3.0)]
    p = tmp_path / "v.csv"
    p.write_text("".join(f"{t!r},{v!r}\n" for t, v in rows))
    hf = scene_with(f"{{file: {p}, direction: [1, 0, 0]}}").boundary.velocity[0].history
    table = [[t, v, 0.0, 0.0] for t, v in rows]
    ht = scene_with(f"{{table: {table}}}").boundary.velocity[0].history
    for t in np.linspace(-0.1, 0.3, 1001):
        a, b = history_velocity(hf, t), history_velocity(ht, t)
        assert a.tobytes() == b.tobytes(), t


def test_dump_keeps_the_file_not_the_table_and_round_trips(tmp_path):
    scene = load_scene(_scene_file(tmp_path))
    h = scene.boundary.velocity[0].history
    assert Path(h.file).is_absolute() and Path(h.file) == SHIPPED / "synthetic-0.3g.at2"
    text = dump_scene(scene)
    assert len(text) < 3000 and "E-0" not in text and "e-0" not in text
    again = parse_scene(text)  # as a restart: reads the file again, the same bits
    assert again == scene
    assert again.boundary.velocity[0].history.record == h.record
    assert again.boundary.velocity[0].history.record.velocity.tobytes() == \
        h.record.velocity.tobytes()
    assert pickle.loads(pickle.dumps(scene)) == scene
    # a table history dumps as before history files (no file keys)
    d = yaml.safe_load(dump_scene(scene_with("{table: [[0, 1, 0, 0]]}")))
    assert set(d["boundary"]["velocity"][0]["history"]) == {"table", "harmonic"}


def _scene_file(tmp_path) -> Path:
    here = tmp_path / "project"
    here.mkdir()
    (here / "configs").symlink_to(ROOT / "configs")
    text = SCENE.format(history="{file: configs/records/synthetic-0.3g.at2, quantity: "
                        "acceleration, direction: [1, 0, 0], scale: 9.81}")
    p = here / "scene.yaml"
    p.write_text(text)
    return p


def test_relative_history_files_are_anchored_at_the_scene(tmp_path, monkeypatch):
    data = {
        "blocks": [{"mesh": {"file": "m.vtu"}}],
        "boundary": {"velocity": [{"history": {"file": "rec/a.at2"}}, {"velocity": [0, 0, 0]},
                                  {"history": {"file": "/abs/b.csv"}}],
                     "stress": [{"wave": {"file": "rec/p.csv"}}, {"pressure": 1.0}]},
        "stages": [{"velocity": [{"history": {"file": "s.csv"}}],
                    "stress": [{"wave": {"file": "w.csv"}}]}, "junk", {"velocity": 3}],
    }
    _anchor_files(data, tmp_path)
    b = data["boundary"]
    assert b["velocity"][0]["history"]["file"] == str(tmp_path / "rec/a.at2")
    assert b["velocity"][2]["history"]["file"] == "/abs/b.csv"
    assert b["stress"][0]["wave"]["file"] == str(tmp_path / "rec/p.csv")
    assert data["stages"][0]["velocity"][0]["history"]["file"] == str(tmp_path / "s.csv")
    assert data["stages"][0]["stress"][0]["wave"]["file"] == str(tmp_path / "w.csv")
    assert data["blocks"][0]["mesh"]["file"] == str(tmp_path / "m.vtu")
    for odd in ({"boundary": 3, "stages": {"a": 1}}, {"boundary": {"velocity": {"x": 1}}},
                {"boundary": {"stress": [None, 2]}}):
        _anchor_files(odd, tmp_path)  # shapes validation refuses later: no exception here
    # without a base (a YAML string) a relative name is read from the working directory
    monkeypatch.chdir(ROOT)
    h = scene_with("{file: configs/records/ricker-10hz.csv, direction: [1, 0, 0]}"
                   ).boundary.velocity[0].history
    assert h.file == "configs/records/ricker-10hz.csv" and len(h.record.times) == 301


def test_shipped_records_are_as_their_headers_say():
    at2 = SHIPPED / "synthetic-0.3g.at2"
    csv = SHIPPED / "ricker-10hz.csv"
    for p in (at2, csv):
        assert p.stat().st_size < 100_000
    lines = at2.read_text().splitlines()
    assert "SYNTHETIC" in lines[0] and "make_records.py" in lines[0]
    pga = float(re.search(r"PGA ([0-9.]+) g", lines[1]).group(1))
    t, a = R.read_series(str(at2))
    assert len(t) == 1600 and t[1] == 0.005
    assert np.abs(a).max() == pytest.approx(pga, rel=1e-6) and pga == 0.3
    assert abs(a[-1]) < 1e-4 * pga  # tapered to rest
    head = csv.read_text().splitlines()[:2]
    assert "SYNTHETIC" in head[0] and "make_records.py" in head[0]
    t, v = R.read_series(str(csv))
    k = int(np.argmax(v))
    assert v[k] == 0.1 and t[k] == 0.15
    assert abs(R.trapezoid(t, v)[-1]) < 1e-9 * 0.1 * 0.3  # the Ricker pulse ends where it began
    # the shipped record, as an engineer writes it: a velocity at rest at the end
    rec = R.resolve(str(at2), "acceleration", (1, 0, 0), 9.81, True)
    assert rec.velocity[-1, 0] == 0.0
    assert abs(R.trapezoid(rec.times, rec.velocity[:, 0])[-1]) < 1e-12


def test_make_records_writes_the_shipped_files(tmp_path, monkeypatch):
    """The script is deterministic: it writes the shipped files again, byte for byte."""
    import runpy

    mod = runpy.run_path(str(SHIPPED / "make_records.py"))
    t, a = mod["acceleration"]()
    mod["write_at2"](tmp_path / "a.at2", a)
    mod["write_ricker"](tmp_path / "r.csv")
    assert (tmp_path / "a.at2").read_bytes() == (SHIPPED / "synthetic-0.3g.at2").read_bytes()
    assert (tmp_path / "r.csv").read_bytes() == (SHIPPED / "ricker-10hz.csv").read_bytes()


def test_a_long_record_is_cheap_per_step():
    """A record of 1e5 samples: the velocity at a time in a few microseconds (a binary
    search per component), not a pass over the record (a copy of it, as np.interp makes of
    a read-only array, took 4 ms a call). Asserted under 200 us a call, a margin for a
    loaded machine."""
    import time

    t = np.arange(100_000) * 0.005
    rec = R.VelocityRecord(t, np.random.default_rng(1).standard_normal((len(t), 3)))
    n = 2000
    start = time.perf_counter()
    for k in range(n):
        rec.at(0.2 * k)
    per = (time.perf_counter() - start) / n
    print(f"\n{per * 1e6:.1f} us a call")
    assert per < 200e-6
    assert not rec.times.flags.writeable and not rec.velocity.flags.writeable
