"""Pre-flight limits and derived checks (issue 15; docs/limits.md)."""

from __future__ import annotations

import logging
import time

import pytest

from pdem.cli import main
from pdem.config import ConfigError, parse_scene
from pdem.config.sizes import parse_bytes
from pdem.preflight import estimate, preflight

BASE = """
materials: {rock: {density: 2600}}
joints:
  default: {kn: KN, ks: 5.0e8}
blocks:
  - {name: floor, material: rock, fixed: true, box: {min: [-2, -2, -1], max: [2, 2, 0]}}
  - {name: cube, material: rock, box: {min: [0, 0, 0.001], max: [1, 1, 1.001]}}
solve: {time: TIME}
"""


def _scene(kn="1.0e9", t="0.01", extra=""):
    return BASE.replace("KN", kn).replace("TIME", t) + extra


def _check(tmp_path, text, capsys):
    p = tmp_path / "s.yaml"
    p.write_text(text)
    rc = main(["check", str(p)])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return rc, out, err


def test_huge_array_refused_at_once(tmp_path, capsys):
    text = _scene().replace(
        "  - {name: cube,", "  - {name: pile, material: rock, array: {box: {min: [0, 0, 0.001], "
        "max: [1, 1, 1.001]}, count: [100000, 100000, 100000], spacing: [1.1, 1.1, 1.1]}}\n"
        "  - {name: cube,").replace("[0, 0, 0.001], max: [1, 1, 1.001]}}\nsolve",
                                    "[0, 0, 9], max: [1, 1, 10]}}\nsolve")
    t0 = time.perf_counter()
    rc, _, err = _check(tmp_path, text, capsys)
    assert rc == 1 and time.perf_counter() - t0 < 10
    assert "limits.max_memory_per_rank" in err and "100000 x 100000 x 100000 = 1e+15" in err
    assert "'pile'" in err


def test_explicit_limits(tmp_path, capsys):
    rc, _, err = _check(tmp_path, _scene(extra="limits: {max_blocks: 1}\n"), capsys)
    assert rc == 1 and "limits.max_blocks: the scene makes 2 blocks, more than the limit 1" in err
    rc, _, err = _check(tmp_path, _scene(extra="limits: {max_memory_per_rank: 1 KiB}\n"), capsys)
    assert rc == 1 and "limits.max_memory_per_rank" in err and "1 KiB" in err
    rc, _, err = _check(tmp_path, _scene(extra="limits: {max_memory_per_rank: 3 parsecs}\n"), capsys)
    assert rc == 1 and "limits.max_memory_per_rank" in err


def test_parse_bytes():
    assert parse_bytes("8 GiB") == 8 * 2**30
    assert parse_bytes("500MB") == 5e8
    assert parse_bytes(1024) == 1024.0
    for bad in ("-1 GB", "nan GB", "x", True, 0):
        with pytest.raises(ValueError):
            parse_bytes(bad)


def test_estimate_grows_with_blocks():
    small, _ = estimate(parse_scene(_scene()), 1)
    assert small.blocks == 2 and 0 < small.bytes_per_rank < 1e6
    assert small.max_blocks > 1000


def test_absurd_stiffness_refused(tmp_path, capsys, caplog):
    rc, _, err = _check(tmp_path, _scene(kn="1.0e308"), capsys)
    assert rc == 1 and "solve.timestep: the timestep is 0 s" in err and "joints.default" in err
    assert "RuntimeWarning" not in err


def test_soft_joint_refused_by_static_overlap(tmp_path, capsys):
    rc, _, err = _check(tmp_path, _scene(kn="1.0e4"), capsys)
    assert rc == 1
    assert "joints.default.kn: 1e+04 Pa/m is too soft for block 'cube' (blocks[1])" in err
    assert "2.551 m" in err and "more than 0.1" in err


def test_stiffness_outside_band_warns_only(caplog):
    logging.getLogger("pdem").propagate = True
    with caplog.at_level(logging.WARNING, logger="pdem"):
        preflight(parse_scene(_scene(kn="1.0e14")), 1)
    assert "joints.default.kn = 1e+14 Pa/m is outside the usual range" in caplog.text


def test_unreachable_end_time_refused(tmp_path, capsys):
    rc, _, err = _check(tmp_path, _scene(t="1.0e300"), capsys)
    assert rc == 1 and "solve.time: 1e+300 s" in err and "t + dt == t" in err


def test_valid_scene_still_valid(tmp_path, capsys):
    rc, out, _ = _check(tmp_path, _scene(), capsys)
    assert rc == 0 and "valid; 2 blocks" in out and "pre-flight estimate" in out


def test_config_error_is_user_error():
    with pytest.raises(ConfigError, match="limits.max_blocks"):
        preflight(parse_scene(_scene(extra="limits: {max_blocks: 1}\n")), 1)


def test_step_count_beyond_limit_refused(tmp_path, capsys):
    """The implied step count against limits.max_steps, in one `pdem check` line."""
    rc, _, err = _check(tmp_path, _scene(t="100.0", extra="limits: {max_steps: 1000}\n"), capsys)
    assert rc == 1 and "solve.time: 100 s at dt=" in err
    assert "steps, more than limits.max_steps = 1000" in err and "joints.default: kn=1e+09" in err
    rc, _, _ = _check(tmp_path, _scene(t="100.0", extra="limits: {max_steps: 1000}\n").replace(
        "solve: {time: 100.0}", "solve: {time: 100.0, max_steps: 500}"), capsys)
    assert rc == 0


def test_fast_start_refused(tmp_path, capsys):
    """A block started so fast that one step moves it more than CTOL/2."""
    text = _scene().replace("max: [1, 1, 1.001]}}", "max: [1, 1, 1.001]}, velocity: [0, 0, -500]}")
    rc, _, err = _check(tmp_path, text, capsys)
    assert rc == 1 and "blocks[1].velocity: block 'cube' starts at 500 m/s" in err
    assert "CTOL" in err and err.count("\n  - ") == 1
