"""bench/fidelity.py (docs/fidelity.md) cannot rot silently: its knob machinery still changes
the scene, its cases still run and measure a finite error, and every knob and case it lists
still exists."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench" / "fidelity.py"


@pytest.fixture(scope="module")
def fidelity():
    spec = importlib.util.spec_from_file_location("fidelity_bench", BENCH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop(spec.name, None)


def test_set_key_changes_the_scene(fidelity):
    case = fidelity.CASES["oscillator"]
    text = case.scene(True)
    slow = fidelity.set_key(text, "solve.timestep.frac", 0.05)
    fast = fidelity.set_key(text, "solve.timestep.frac", 0.1)
    assert fidelity.get_key(slow, "solve.timestep.frac") == 0.05
    sims = [fidelity.make_simulation(t) for t in (slow, fast)]
    assert sims[0].dt == pytest.approx(0.5 * sims[1].dt, rel=1e-12)
    # the damping shorthand becomes a mapping so alpha can be set
    damped = fidelity.set_key(fidelity.CASES["static"].scene(True), "solve.damping.alpha", 0.5)
    assert fidelity.get_key(damped, "solve.damping.mode") == "local"
    assert fidelity.get_key(damped, "solve.damping.alpha") == 0.5


def test_knobs_and_cases_exist(fidelity):
    """Every knob is a scene key (its pdem default readable, every value accepted by the
    schema) and names known cases."""
    base = fidelity.CASES["incline"].scene(True)
    for k in fidelity.KNOBS:
        assert set(k.cases) <= set(fidelity.CASES), k.key
        if k.default is None:
            fidelity.pdem_default(k.key)
        for v in k.values:
            assert fidelity.get_key(fidelity.set_key(base, k.key, v), k.key) == v, (k.key, v)
    for t in fidelity.FEATURE_TOGGLES:
        assert set(t.cases) <= set(fidelity.CASES), t.name


def test_a_case_measures_a_finite_error_and_counts_updates(fidelity):
    """The sliding block on the incline: finite error within its tolerance, steps and contact
    updates counted (it slides, so its contact is re-detected; the oscillator's, which only
    presses and lifts, is not)."""
    case = fidelity.CASES["incline"]
    r = fidelity.run_one(case, case.scene(True), True)
    assert math.isfinite(r["error"]) and 0.0 <= r["error"] < case.tolerance
    assert r["steps"] > 100 and r["updates"] > 0 and r["contacts"] == 1
    row = fidelity.Row("solve.timestep.frac", 0.1, "incline", **r)
    assert "incline" in fidelity.knob_table([row], "solve.timestep.frac", True)
