"""Property-based fuzz of the command line (docs/limits.md, "The fuzz").

Valid small scenes are generated, then mutated (wrong types, non-finite and extreme numbers,
missing and unknown keys, degenerate and overlapping shapes, huge counts, garbage text); each
goes through ``pdem check`` and, when accepted, three steps of ``pdem run``. Output files and
checkpoints are damaged (truncated, foreign HDF5, wrong ``format_version``, missing datasets)
and given to ``pdem info`` and ``pdem restart``. The contract: exit status 0, or 1 with a
``pdem`` error on stderr naming what is wrong -- never a traceback, never a hang.

A fixed, derandomized profile keeps CI at ~200 examples in all; ``PDEM_FUZZ_EXAMPLES=N`` runs
N per test (with fresh randomness: ``PDEM_FUZZ_SEED`` or a random seed).
"""

from __future__ import annotations

import copy
import math
import os
import shutil
import signal
import tempfile
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, event, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from pdem.cli import main  # noqa: E402

_N = os.environ.get("PDEM_FUZZ_EXAMPLES")
# per test; the CI profile's counts add up to ~200 (see the @settings below)
settings.register_profile("pdem-ci", derandomize=True, deadline=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.register_profile("pdem-more", derandomize=False, deadline=None, print_blob=True,
                          max_examples=int(_N or 0) or 100,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
PROFILE = "pdem-more" if _N else "pdem-ci"


def _examples(ci: int):
    """``ci`` examples in CI; PDEM_FUZZ_EXAMPLES per test when set."""
    return settings(settings.get_profile(PROFILE),
                    max_examples=int(_N) if _N else ci)


# one example may take this long (a hang is a failure, not a stuck CI job); numba is compiled
# once by the module fixture before any example runs
EXAMPLE_SECONDS = 60


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang(f"no answer within {EXAMPLE_SECONDS} s")


def _cli(argv, capsys):
    """Run ``pdem ARGV`` in-process; check the contract; return (status, stdout, stderr)."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(EXAMPLE_SECONDS)
    try:
        # numpy's RuntimeWarnings (overflow, invalid value) would reach a user's terminal as
        # noise before or instead of a clear message: they fail the contract too
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rc = main(argv)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    noisy = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    out, err = capsys.readouterr()
    assert not noisy, (argv, noisy, out, err)
    assert "Traceback" not in out + err, (argv, out, err)
    assert rc in (0, 1), (argv, rc, out, err)
    if rc == 1:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert lines, (argv, out, err)
        # one `pdem` line; a scene's problems follow it as a list, one "  - key.path: ..." each
        # (a few name no key: "the scene must be a mapping")
        assert lines[0].startswith("pdem"), (argv, err)
        assert all(ln.startswith("  - ") for ln in lines[1:]), (argv, err)
    else:
        assert not err.strip(), (argv, err)
    return rc, out, err


# ------------------------------------------------------------------ scenes
BASE = {
    "name": "fuzz",
    "materials": {"rock": {"density": 2600.0}},
    "joints": {"default": {"kn": 1.0e9, "ks": 5.0e8, "friction": 30.0}},
    "blocks": [{"name": "floor", "material": "rock", "fixed": True,
                "box": {"min": [-10.0, -3.0, -1.0], "max": [20.0, 3.0, 0.0]}}],
    "solve": {"steps": 3},
    "output": {"every_steps": 2},
    # the fuzz tests refusals, not this machine's memory: keep accepted scenes small
    "limits": {"max_blocks": 200},
}


def _entry(kind: str, i: int, size: float, n: int, seed: int) -> dict:
    """Entry ``i`` of ``kind``, in its own 3 m slot along x (no overlaps between entries)."""
    x0 = 3.0 * i
    lo = [x0, -1.0, 0.001]
    if kind == "box":
        shape = {"box": {"min": lo, "max": [x0 + size, -1.0 + size, 0.001 + size]}}
    elif kind == "array":
        shape = {"array": {"box": {"min": lo, "max": [x0 + 0.5, -0.5, 0.501]},
                           "count": [n, 1, 2], "spacing": [0.6, 0.6, 0.6]}}
    elif kind == "random":
        shape = {"random": {"count": n, "region": {"min": lo, "max": [x0 + 2.0, 1.0, 2.0]},
                            "size": [0.4, 0.5], "vertices": 8, "seed": seed}}
    elif kind == "prism":
        shape = {"prism": {"base": [[x0, 0.0, 0.001], [x0 + size, 0.0, 0.001],
                                    [x0, size, 0.001]], "extrude": [0.0, 0.0, size]}}
    elif kind == "planes":  # a cube as six half-spaces
        shape = {"planes": {"normals": [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0],
                                        [0, 0, 1], [0, 0, -1]],
                            "offsets": [x0 + size, -x0, size, 0.0, 0.001 + size, -0.001]}}
    else:  # tetrahedron
        shape = {"polyhedron": {"vertices": [[x0, 0.0, 0.001], [x0 + size, 0.0, 0.001],
                                             [x0, size, 0.001], [x0, 0.0, 0.001 + size]]}}
    return {"name": f"{kind}{i}", "material": "rock", **shape}


@st.composite
def scenes(draw) -> dict:
    s = copy.deepcopy(BASE)
    kinds = draw(st.lists(st.sampled_from(["box", "array", "random", "polyhedron", "prism",
                                           "planes"]),
                          min_size=1, max_size=3))
    for i, kind in enumerate(kinds):
        s["blocks"].append(_entry(kind, i, draw(st.floats(0.3, 1.0)), draw(st.integers(1, 3)),
                                  draw(st.integers(0, 5))))
    s["joints"]["default"]["kn"] = draw(st.sampled_from([1e7, 1e8, 1e9, 1e10]))
    if draw(st.booleans()):
        s["solve"] = {"time": draw(st.sampled_from([1e-4, 1e-3, 0.01]))}
    s["solve"]["damping"] = draw(st.sampled_from(["none", "local", "combined", "adaptive"]))
    if draw(st.booleans()):
        s["solve"]["mass_scaling"] = True
    if draw(st.booleans()):
        s["domain"] = {"min": [-11.0, -4.0, -2.0], "max": [21.0, 4.0, 5.0], "action": "freeze"}
    if draw(st.booleans()):
        s["joints"]["weak"] = {"kn": 1e8, "ks": 1e8, "friction": 20.0, "cohesion": 1e3}
        s["joint_pairs"] = [{"groups": ["default", "default"], "joint": "weak"}]
    if draw(st.booleans()):
        s["contact"] = {"algorithm": draw(st.sampled_from(["fast", "cundall"])),
                        "detect_every": draw(st.integers(1, 5))}
    return s


def _paths(node, prefix=()):
    """Every key path in a scene dict (mapping keys and list indices)."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


def _get(node, path):
    for p in path:
        node = node[p]
    return node


BAD_VALUES = ["abc", "", None, True, [], {}, [1.0, 2.0], -1, 0, 1, 10**7, 10**20, -1.0, 0.0,
              1e308, -1e308, 1e-308, math.nan, math.inf, -math.inf, "auto", [math.nan] * 3,
              [0.0, 0.0, 0.0], [1e308, 1e308, 1e308]]


@st.composite
def mutated(draw) -> dict:
    s = draw(scenes())
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(s) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = _get(s, path[:-1])
        op = draw(st.sampled_from(["value", "value", "value", "delete", "unknown", "degenerate",
                                   "overlap", "huge"]))
        if op == "value":
            parent[path[-1]] = copy.deepcopy(draw(st.sampled_from(BAD_VALUES)))
        elif op == "delete":
            del parent[path[-1]]
        elif op == "unknown" and isinstance(parent, dict):
            parent["colour" if draw(st.booleans()) else "densty"] = 1.0
        elif op == "degenerate":
            boxes = [p for p in _paths(s) if p and p[-1] in ("box", "region")]
            if boxes:
                b = _get(s, draw(st.sampled_from(boxes)))
                if isinstance(b, dict) and isinstance(b.get("min"), list):
                    b["max"] = list(b["min"])  # zero volume
        elif op == "overlap":
            blocks = s.get("blocks")
            if isinstance(blocks, list) and len(blocks) > 1 and isinstance(blocks[-1], dict):
                twin = copy.deepcopy(blocks[-1])
                twin["name"] = "twin"
                blocks.append(twin)  # the same shape twice: overlapping at start
        elif op == "huge":
            for p in _paths(s):
                if p and p[-1] == "count":
                    node = _get(s, p[:-1])
                    node["count"] = [10**5] * 3 if isinstance(node["count"], list) else 10**12
    return s


def _scene_text(s) -> str:
    return yaml.safe_dump(s, sort_keys=False)


@pytest.fixture(scope="module")
def workdir():
    d = Path(tempfile.mkdtemp(prefix="pdem-fuzz-"))
    yield d
    shutil.rmtree(d, ignore_errors=True)


@pytest.fixture(scope="module")
def warm(workdir):
    """Compile numba and write one output and one checkpoint to damage later."""
    s = copy.deepcopy(BASE)
    s["blocks"].append(_entry("box", 0, 1.0, 1, 0))
    s["checkpoint"] = {"every_steps": 2, "file": str(workdir / "ck")}
    s["output"]["file"] = str(workdir / "good.h5")
    (workdir / "good.yaml").write_text(_scene_text(s))
    assert main(["run", str(workdir / "good.yaml"), "-q", "--steps", "3"]) == 0
    ck = sorted(workdir.glob("ck-*.h5"))[-1]
    return workdir / "good.h5", ck


def _check_and_run(text: str, workdir: Path, capsys):
    scene = workdir / "scene.yaml"
    scene.write_text(text) if isinstance(text, str) else scene.write_bytes(text)
    rc, out, err = _cli(["check", str(scene)], capsys)
    event("accepted" if rc == 0 else "refused")  # --hypothesis-show-statistics
    if rc == 0:
        assert "valid;" in out
        rc, out, err = _cli(["run", str(scene), "-q", "--steps", "3", "-o",
                             str(workdir / "out.h5")], capsys)
        # a scene `pdem check` calls valid must start
        assert rc == 0, (text, err)


# ------------------------------------------------------------------ tests
@pytest.mark.timeout(900)
@_examples(40)
@given(scenes())
def test_valid_scenes_check_and_run(warm, workdir, capsys, s):
    _check_and_run(_scene_text(s), workdir, capsys)


def _with(path_values, drop=()):
    s = copy.deepcopy(BASE)
    s["blocks"].append(_entry("box", 0, 1.0, 1, 0))
    for path, v in path_values:
        node = s
        for p in path[:-1]:
            node = node[p]
        node[path[-1]] = v
    for path in drop:
        del _get(s, path[:-1])[path[-1]]
    return s


@pytest.mark.timeout(900)
@_examples(100)
@given(mutated())
# issue 15: a 1e15-block array was built until killed; kn=1e308 gave dt=0 and a
# ZeroDivisionError; kn=1e4 let a 1 m cube sink 2.5 m through the floor
@example(_with([(("blocks", 1), {"name": "a", "material": "rock", "array": {
    "box": {"min": [0, 0, 0.001], "max": [1, 1, 1.001]}, "count": [100000] * 3,
    "spacing": [1.1] * 3}}), (("limits",), {})]))
@example(_with([(("joints", "default", "kn"), 1e308)]))
@example(_with([(("joints", "default", "kn"), 1e4)]))
# a random family in a big region of tiny sites listed every site (1e18) before taking `count`
@example(_with([(("blocks", 1), _entry("random", 0, 1.0, 2, 0)),
                (("blocks", 1, "random", "region", "max"), [1e6, 1e6, 1e6]),
                (("blocks", 1, "random", "size"), [1e-4, 1e-4])]))
# a 1e308 coordinate made the geometry nan (numpy overflow warnings, a misleading message)
@example(_with([(("blocks", 0, "box", "max"), [1e308, 3.0, 0.0])]))
@example(_with([(("blocks", 1, "velocity"), [1e308, 0.0, 0.0])]))
# two errors of the whole-scene check shared one list item, the second without "  - "
@example(_with([(("blocks", 1, "name"), "floor"), (("blocks", 1, "material"), "granite")]))
@example(_with([(("blocks", 1), _entry("random", 0, 1.0, 2, 0)),
                (("blocks", 1, "random", "region", "max"), [1e6, 1e6, 1e6]),
                (("blocks", 1, "random", "size"), [1e-300, 1e-300])]))
def test_mutated_scenes_never_crash(warm, workdir, capsys, s):
    _check_and_run(_scene_text(s), workdir, capsys)


@pytest.mark.timeout(300)
@_examples(20)
@given(st.one_of(st.binary(max_size=200), st.text(max_size=200),
                 st.sampled_from(["", "---\n", "[1, 2]", "blocks: [", "\x00\xff", "a: *b"])))
@example(b"\x80")  # found by the fuzz: UnicodeDecodeError traceback
@example("blocks: [")  # PyYAML's message spans lines: now one line with its line number
def test_garbage_text_is_refused(warm, workdir, capsys, text):
    scene = workdir / "garbage.yaml"
    scene.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    rc, _, _ = _cli(["check", str(scene)], capsys)
    assert rc == 1


def _damage(src: Path, dst: Path, how: str, arg: int):
    shutil.copy(src, dst)
    if how == "truncate":
        data = src.read_bytes()
        dst.write_bytes(data[: arg % max(len(data), 1)])
    elif how == "garbage":
        rng = np.random.default_rng(arg)
        dst.write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    elif how == "foreign":
        with h5py.File(dst, "w") as f:
            f["data"] = np.arange(arg % 10)
            if arg % 2:
                f.attrs["pdem_format"] = "checkpoint" if arg % 4 == 1 else "output"
    elif how == "version":
        with h5py.File(dst, "r+") as f:
            f.attrs["format_version"] = [99, -1, 0, 1][arg % 4] if arg % 5 else "two"
    elif how == "drop":  # a dataset: the arg-th, or the one named by a str arg
        with h5py.File(dst, "r+") as f:
            names = []
            f.visit(names.append)
            del f[arg if isinstance(arg, str) else sorted(names)[arg % len(names)]]
    elif how == "attr":
        with h5py.File(dst, "r+") as f:
            keys = sorted(f.attrs)
            del f.attrs[arg if isinstance(arg, str) else keys[arg % len(keys)]]


@pytest.mark.timeout(900)
@_examples(40)
@given(st.sampled_from(["output", "checkpoint"]),
       st.sampled_from(["truncate", "garbage", "foreign", "version", "drop", "attr"]),
       st.integers(0, 10**6))
# found by the fuzz: restart from a checkpoint without dt/alpha/ratio raised KeyError, without
# a sub-contact dataset KeyError mid-run; the checkpoint reader now refuses them
@example("checkpoint", "attr", "dt")
@example("checkpoint", "attr", "ratio")
@example("checkpoint", "drop", "subcontacts/sc_pa")
@example("checkpoint", "drop", "blocks/q")
@example("checkpoint", "version", 1)
def test_damaged_files_for_info_and_restart(warm, workdir, capsys, which, how, arg):
    good = warm[0] if which == "output" else warm[1]
    bad = workdir / f"damaged-{which}.h5"
    _damage(good, bad, how, arg)
    _cli(["info", str(bad)], capsys)
    _cli(["restart", str(bad), "-q", "--steps", "2", "-o", str(workdir / "restarted.h5")], capsys)
