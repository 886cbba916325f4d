"""The compiled run of steps (pdem.cycle, ``solve.fused``) changes nothing but the speed: for
scenes that exercise every Python-level event between steps (snapshots, histories sampled in
model time, energy samples, checkpoints, contact searches and updates, blocks leaving the
model domain, an excavation at a time, adaptive damping, Rayleigh damping's joint dashpots, a
ratio end condition), with and without zoned blocks, the output files of a serial run are
bitwise the same with it on and off."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml
from mpi4py import MPI

from pdem.cases.collapse import ledge_scene, pile_scene, zoned_row_scene
from pdem.cases.rock_mass import l_on_stack_scene
from pdem.cases.stacks import cube_stack_scene
from pdem.config import parse_scene
from pdem.simulation import Simulation

# attributes that differ between any two runs
VOLATILE = {"run_id", "wall", "created", "wall_seconds"}


def datasets(path: str) -> dict[str, np.ndarray]:
    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind != "V":
            out[name] = obj[()]

    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return out


def run(text: str, fused: bool, tmp_path, tag: str, **output) -> tuple[str, Simulation]:
    d = yaml.safe_load(text)
    d.setdefault("solve", {})["fused"] = fused
    path = str(tmp_path / f"{tag}-{'fused' if fused else 'steps'}.h5")
    d["output"] = {"file": path, **d.get("output", {}), **output}
    sim = Simulation(parse_scene(yaml.safe_dump(d)), MPI.COMM_SELF, output=True)
    sim.run()
    sim.close()
    return path, sim


def pile_with_histories() -> str:
    d = yaml.safe_load(pile_scene(count=16, time=0.25))
    d["output"] = {"every": 0.05, "energy_every": 7,
                   "histories": [{"block": "rock[3]", "quantity": "velocity", "every": 0.013},
                                 {"block": "rock[5]", "quantity": "position", "every": 0.02}]}
    return yaml.safe_dump(d)


def rayleigh_pile() -> str:
    """The pile under Rayleigh damping: the joints' dashpots in the compiled force step."""
    d = yaml.safe_load(pile_scene(count=12, time=0.15))
    d["solve"]["damping"] = {"mode": "rayleigh", "fraction": 0.05, "frequency": 10.0}
    d["output"] = {"every": 0.05, "energy_every": 7}
    return yaml.safe_dump(d)


def adaptive_stack() -> str:
    d = yaml.safe_load(cube_stack_scene(2, "fast"))
    d["solve"] = {"ratio": 1e-3, "max_steps": 3000, "damping": {"mode": "adaptive"}}
    return yaml.safe_dump(d)


# zoned blocks (pdem.cycle.fused_grid_steps): soft zoned cubes and rigid ones thrown at each
# other (contacts made and updated, grids strained, the energy budget sampled), and a zoned
# column settling on a floor under adaptive damping to a ratio (the grids' ratio ends it)
def zoned_row() -> str:
    d = yaml.safe_load(zoned_row_scene(240))
    d["blocks"][3]["force"] = [-2.0e4, 0.0, 0.0]  # z2 pushed: a load spread on its gridpoints
    d["output"] = {"every_steps": 40, "every": None, "energy_every": 7}
    return yaml.safe_dump(d)


ZONED_SETTLE = """
name: zoned-settle
materials:
  rock: {density: 2000}
  soft: {density: 2000, young: 1.0e8, poisson: 0.25, model: mohr_coulomb, cohesion: 1.0e6,
         friction: 30, tension: 1.0e5}
joints: {default: {kn: 1.0e9, ks: 1.0e9, friction: 30}}
blocks:
  - {name: floor, box: {min: [-1, -1, -1], max: [1, 1, 0]}, material: rock, fixed: true}
  - {name: col, box: {min: [-0.5, -0.5, 0], max: [0.5, 0.5, 2]}, material: soft,
     zones: {size: 0.5}}
solve: {ratio: 1.0e-3, max_steps: 5000, damping: {mode: adaptive}}
output: {every_steps: 50, every: null}
"""

SCENES = {
    "pile-histories": pile_with_histories,
    "ledge-domain": lambda: ledge_scene(time=0.6),
    "excavation-at-time": lambda: l_on_stack_scene(time=0.25, excavate_at=0.1),
    "adaptive-ratio": adaptive_stack,
    "rayleigh-pile": rayleigh_pile,
    "zoned-row": zoned_row,
    "zoned-settle-ratio": lambda: ZONED_SETTLE,
}


@pytest.mark.parametrize("name", SCENES)
def test_fused_output_is_bitwise_the_step_by_step_output(name, tmp_path):
    text = SCENES[name]()
    a, sim_a = run(text, False, tmp_path, name)
    b, sim_b = run(text, True, tmp_path, name)
    assert sim_a.state.step == sim_b.state.step > 100
    if name == "pile-histories":  # searches at step after step: some steps went to Python
        assert sim_b.stepper.python_steps > 0  # (Stepper.advance_many, PYTHON_RUN)
    if name.startswith("zoned"):  # the grids stepped in the compiled loop
        assert "fused" in sim_b.state.timers.report()
        assert "fused" not in sim_a.state.timers.report()
    da, db = datasets(a), datasets(b)
    assert da.keys() == db.keys()
    bad = [k for k in da if not np.array_equal(da[k], db[k], equal_nan=da[k].dtype.kind == "f")]
    assert not bad, f"{name}: fused output differs in {bad}"
    with h5py.File(a) as fa, h5py.File(b) as fb:
        assert int(fa["time"].shape[0]) >= 3  # snapshots were written along the way
        attrs = {k: v for k, v in fa.attrs.items() if k not in VOLATILE}
        other = {k: v for k, v in fb.attrs.items() if k not in VOLATILE}
        # the scene differs only in solve.fused
        attrs.pop("scene", None), other.pop("scene", None)
        assert attrs.keys() == other.keys()


def test_fused_runs_stop_at_the_events_they_must_not_skip(tmp_path):
    """Snapshots every 37 steps and checkpoints every 50: every one is written at its step."""
    text = pile_scene(count=8, time=0.1)
    d = yaml.safe_load(text)
    d["checkpoint"] = {"file": str(tmp_path / "ck"), "every_steps": 50, "keep": 100}
    path, sim = run(yaml.safe_dump(d), True, tmp_path, "events", every_steps=37, every=None)
    with h5py.File(path) as f:
        steps = f["step"][()]
    assert list(steps) == list(range(0, sim.state.step + 1, 37)) + (
        [sim.state.step] if sim.state.step % 37 else [])
    written = sorted(p.name for p in tmp_path.glob("ck-*.h5"))
    assert written == [f"ck-{k:09d}.h5" for k in range(50, sim.state.step + 1, 50)]


def test_compiled_run_does_the_periodic_contact_updates():
    """A compiled run does the periodic contact updates with work itself
    (pdem.contact.update's three calls) and carries on: the stepper's update runs only where a
    compiled run stopped, and the state is bitwise that of the step-by-step run, whose stepper
    updates at every periodic step."""
    import pdem.stepper

    calls = []
    original = pdem.stepper.Stepper.refresh

    def counted(self, all_contacts, periodic=False):
        calls.append(periodic)
        return original(self, all_contacts, periodic)

    sims = {}
    for fused in (False, True):
        d = yaml.safe_load(cube_stack_scene(4, "fast"))
        d.setdefault("solve", {})["fused"] = fused
        sim = Simulation(parse_scene(yaml.safe_dump(d)), MPI.COMM_SELF, output=False)
        calls.clear()
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(pdem.stepper.Stepper, "refresh", counted)
            sim.run(steps=400)
        sims[fused] = (sim, sum(calls))
    (steps, updates_steps), (fused, updates_fused) = sims[False], sims[True]
    periodic = 400 // steps.state.scene.contact.detect_every
    assert updates_steps == periodic  # the stepper updates at every periodic step
    assert updates_fused < periodic // 4  # the compiled runs did nearly all the others
    for name in ("x", "q", "v", "w", "work"):
        assert np.array_equal(getattr(steps.blocks, name), getattr(fused.blocks, name)), name
    for name in steps.contacts.arrays:
        assert np.array_equal(steps.contacts.arrays[name], fused.contacts.arrays[name]), name
    for name in steps.contacts.sub:
        assert np.array_equal(steps.contacts.sub[name], fused.contacts.sub[name]), name
    assert np.array_equal(steps.contacts.sc_start, fused.contacts.sc_start)


def test_compiled_loop_keeps_no_inlining_ir():
    """After its first call the compiled loop's LLVM IR for inlining (~15 MB a version, which
    nothing links: pdem.jit.drop_linking_ir) is freed, and the loop still runs: a second
    simulation of the same scene gives the same bits."""
    from pdem.cycle import fused_steps

    states = []
    for _ in range(2):
        sim = Simulation(parse_scene(cube_stack_scene(3, "fast")), MPI.COMM_SELF, output=False)
        sim.run(steps=60)
        assert "fused" in sim.state.timers.report()
        states.append(sim.blocks.x.copy())
        libraries = [c.library for c in fused_steps.overloads.values()]
        assert libraries and all(lib._shared_module is None for lib in libraries)
    assert np.array_equal(states[0], states[1])
