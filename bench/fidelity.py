"""The measured speed/accuracy trade (issue 10): pdem's closed-form cases run with one accuracy
knob at a time moved off its default; the error against the closed form next to the cost.

    .venv/bin/python bench/fidelity.py [--quick] [--no-doc] [--knob KEY ...] [--render]

Prints the tables and writes docs/fidelity.md, docs/figures/fidelity-*.png (error against
cost, one figure per knob; tables only if matplotlib is missing) and the rows as
docs/data/fidelity.json. Every number in the page comes from the run: do not edit the page,
re-run this script (~3-5 min on 2 shared cores). ``--quick``: fewer knob values and shorter
cases, a smoke run (~1-2 min) that prints the tables and leaves the page alone; ``--knob``:
those knobs only, tables only; ``--render``: no runs, the page and figures again from
docs/data/fidelity.json (after editing the prose below).

What is data here, easy to extend:

* ``CASES``: a closed-form case = a scene builder (YAML text, from pdem.cases), a measurement
  that runs the simulation and returns the error against the closed form, and the tolerance
  its verification test asserts (tests/verification/);
* ``KNOBS``: a scene key (dotted path, e.g. ``contact.detect_every``), the values to try and
  the cases where it matters;
* ``FEATURE_TOGGLES``: the hook for "Pay only for what the scene uses" (see there).

Cost: model steps, CPU seconds of the run (process time: less disturbed than wall time by
other jobs on a shared machine; JIT compilation excluded by a short warm-up run of the same
scene; steps and updates are exact, CPU time still varies by some 10 %), and
contact geometry updates (contacts re-detected: common plane + sub-contacts, the stepper's
``redetected`` count), plus contacts and sub-contacts held at the end.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from pdem.cases import (  # noqa: E402
    collapse,
    crossing_times,
    fit_acceleration,
    free_row,
    incline,
    make_simulation,
    oscillator,
    rotation_matrix,
    static,
    tipping,
    tumbling,
    wedge,
)

DOC = ROOT / "docs" / "fidelity.md"
FIGURES = ROOT / "docs" / "figures"
DATA = ROOT / "docs" / "data" / "fidelity.json"  # the last full run's rows, for --render


# ------------------------------------------------------------------------------ scene editing
def set_key(text: str, key: str, value) -> str:
    """The scene ``text`` (YAML) with the dotted ``key`` set to ``value``. Missing levels are
    created; ``solve.damping`` given as the mode shorthand (``damping: local``) becomes
    ``{mode: local}`` so its ``alpha`` can be set."""
    scene = yaml.safe_load(text)
    *path, last = key.split(".")
    node = scene
    for part in path:
        child = node.get(part)
        if isinstance(child, str) and part == "damping":
            child = {"mode": child}
        elif child is None:
            child = {}
        node[part] = child
        node = child
    if key == "solve.damping.mode" and value == "none":
        node.pop("alpha", None)
    node[last] = value
    return yaml.safe_dump(scene, sort_keys=False)


def get_key(text: str, key: str):
    """The value of the dotted ``key`` in the parsed scene (defaults filled in by pdem)."""
    from pdem.config import parse_scene

    node = parse_scene(text)
    for part in key.split("."):
        node = getattr(node, part)
    return node


_MINIMAL = """
materials: {rock: {density: 2000}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks: [{name: a, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}]
solve: {steps: 1}
"""


def pdem_default(key: str):
    """pdem's default for ``key`` (from the schema, via a scene that does not set it)."""
    return get_key(_MINIMAL, key)


# ------------------------------------------------------------------------------ the cases
@dataclass(frozen=True)
class Case:
    """A closed-form case: ``scene(quick)`` -> YAML text; ``measure(sim, quick)`` runs the
    simulation and returns ``{"error": ..., other named results}``; ``tolerance``: what its
    verification test asserts on that error."""

    name: str
    what: str  # the closed-form quantity, one line
    error: str  # what the error is, one line
    scene: Callable[[bool], str]
    measure: Callable[[object, bool], dict]
    tolerance: float
    test: str


def _march(sim, steps: int, record: Callable[[], object]) -> list:
    out = []
    for _ in range(steps):
        sim.advance()
        out.append(record())
    return out


# sliding block on the 20 deg incline, phi = 10 deg
INCLINE_PHI = 10.0


def _incline_scene(quick: bool) -> str:
    return incline.incline_scene(INCLINE_PHI, "fast", f"time: {0.4 if quick else 0.6}")


def _incline_measure(sim, quick: bool) -> dict:
    i = free_row(sim)
    b = sim.blocks
    n = int(round((0.4 if quick else 0.6) / sim.dt))
    tx = np.array(_march(sim, n, lambda: (sim.time, b.x[i, 0] - b.x0[i, 0])))
    late = tx[:, 0] >= 0.1
    a = fit_acceleration(tx[late, 0], tx[late, 1])
    exact = incline.sliding_acceleration(INCLINE_PHI)
    return {"error": abs(a / exact - 1.0), "a": a}


# the Hoek-Bray wedge of the 3D-DDA paper sliding at phi = 15 deg (pdem.cases.wedge)
WEDGE_PHI = 15.0


def _wedge_scene(quick: bool) -> str:
    return wedge.wedge_scene(WEDGE_PHI)


def _wedge_measure(sim, quick: bool) -> dict:
    t, u = wedge.displacement_history(sim, 0.3 if quick else 0.5)
    late = t >= 0.1
    a = fit_acceleration(t[late], u[late])
    return {"error": abs(a / wedge.sliding_acceleration(WEDGE_PHI) - 1.0), "a": a}


# a cube on a floor started at twice its static overlap: period of the contact spring
def _oscillator_scene(quick: bool) -> str:
    return oscillator.cube_on_floor(-2.0 * oscillator.static_overlap())


def _oscillator_measure(sim, quick: bool) -> dict:
    i = free_row(sim)
    b = sim.blocks
    T = oscillator.period()
    n = int((12 if quick else 30) * T / sim.dt)
    tv = np.array(_march(sim, n, lambda: (sim.time - 0.5 * sim.dt, b.v[i, 2], b.x[i, 2])))
    tc = crossing_times(tv[:, 0], tv[:, 1])
    if len(tc) < 3:
        return {"error": math.inf}
    measured = (tc[-1] - tc[0]) / (len(tc) - 1)
    # mean overlap over whole periods against the static overlap m g / (kn A)
    whole = (tv[:, 0] >= tc[0]) & (tv[:, 0] < tc[-1])
    overlap = 0.5 - float(np.mean(tv[whole, 2]))
    return {"error": abs(measured / T - 1.0),
            "overlap_err": abs(overlap / oscillator.static_overlap() - 1.0)}


# a cube tipping over the floor edge (contact.point_area 0.1 in the case itself)
def _tipping_scene(quick: bool) -> str:
    return tipping.tipping_scene("fast")


def _tipping_measure(sim, quick: bool) -> dict:
    i = free_row(sim)
    b = sim.blocks
    m = float(b.mass[i])
    stop = math.radians(30.0 if quick else 40.0)
    theta, omega = [], []
    for _ in range(int(1.0 / sim.dt)):
        sim.advance()
        up = rotation_matrix(b.q[i]) @ np.array([0.0, 0.0, 1.0])
        theta.append(math.atan2(up[0], up[2]))
        omega.append(b.w[i, 1])
        if theta[-1] > stop:
            break
    theta, omega = np.array(theta), np.array(omega)
    late = theta > math.radians(10.0)
    if theta[-1] <= stop or not late.any():
        return {"error": math.inf, "note": f"reached {math.degrees(theta.max()):.1f} deg"}
    exact = tipping.angular_velocity(theta[late], m)
    return {"error": float(np.abs(omega[late] / exact - 1.0).max())}


# a two-cube stack relaxed to ratio 1e-5: overlaps 2 m g / (kn A) and m g / (kn A)
def _static_scene(quick: bool) -> str:
    text = static.stack_scene("local", False)
    return set_key(text, "solve.max_steps", 8000 if quick else 30000)


def _static_measure(sim, quick: bool) -> dict:
    sim.run()
    d1, d2 = static.overlaps()
    z = {sim.specs[g].name: sim.blocks.x[i, 2] for i, g in enumerate(sim.blocks.gid)}
    low = 0.5 - z["low"]
    top = 1.5 - z["top"]
    err = max(abs(low / d1 - 1.0), abs((top - low) / d2 - 1.0))
    out = {"error": err}
    if sim.state.ratio > 1e-5:
        out["note"] = f"not converged (ratio {sim.state.ratio:.1e})"
    return out


# the same stack with a small top cube (edge TOP_EDGE): the small block sets the critical step,
# which mass scaling removes; overlaps (m1 + m2) g / (kn A1) and m2 g / (kn A2)
TOP_EDGE = 0.1


def _unequal_scene(quick: bool) -> str:
    e = TOP_EDGE
    text = static.stack_scene("local", False).replace(
        "{min: [-0.5, -0.5, 1], max: [0.5, 0.5, 2]}", f"{{min: [{-e / 2}, {-e / 2}, 1], "
        f"max: [{e / 2}, {e / 2}, {1 + e}]}}")
    return set_key(text, "solve.max_steps", 8000 if quick else 30000)


def _unequal_measure(sim, quick: bool) -> dict:
    sim.run()
    m1, m2 = static.RHO, static.RHO * TOP_EDGE**3
    d1 = (m1 + m2) * static.G / static.KN
    d2 = m2 * static.G / (static.KN * TOP_EDGE**2)
    z = {sim.specs[g].name: sim.blocks.x[i, 2] for i, g in enumerate(sim.blocks.gid)}
    low = 0.5 - z["low"]
    top = 1.0 + 0.5 * TOP_EDGE - z["top"]
    err = max(abs(low / d1 - 1.0), abs((top - low) / d2 - 1.0))
    out = {"error": err}
    if sim.state.ratio > 1e-5:
        out["note"] = f"not converged (ratio {sim.state.ratio:.1e})"
    return out


# torque-free tumbling of an asymmetric block against Euler's equations
def _tumbling_scene(quick: bool) -> str:
    return set_key(tumbling.tumbling_scene("random"), "solve.steps", 2000 if quick else 5000)


def _qmul(a, b):
    return (a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0])


def euler_reference(q0, w0_world, inertia, time_: float, substeps: int) -> np.ndarray:
    """Orientation (unit quaternion w, x, y, z) after ``time_`` of the torque-free rigid body
    with principal moments ``inertia`` (body frame of ``q0``) started at world angular velocity
    ``w0_world``: Euler's equations and dq/dt = q (0, w_body) / 2 by RK4 (``substeps``
    steps), the converged reference the tumbling case is measured against."""
    I1, I2, I3 = (float(x) for x in inertia)
    lb = rotation_matrix(q0).T @ np.asarray(w0_world, float) * np.array([I1, I2, I3])

    def f(y):
        q, (l1, l2, l3) = y[:4], y[4:]
        w1, w2, w3 = l1 / I1, l2 / I2, l3 / I3
        dq = _qmul(q, (0.0, w1, w2, w3))
        # dL_body/dt = L_body x w_body (torque free)
        return (0.5 * dq[0], 0.5 * dq[1], 0.5 * dq[2], 0.5 * dq[3],
                l2 * w3 - l3 * w2, l3 * w1 - l1 * w3, l1 * w2 - l2 * w1)

    y = [float(x) for x in q0] + [float(x) for x in lb]
    h = time_ / substeps
    for _ in range(substeps):
        k1 = f(y)
        k2 = f([a + 0.5 * h * b for a, b in zip(y, k1, strict=True)])
        k3 = f([a + 0.5 * h * b for a, b in zip(y, k2, strict=True)])
        k4 = f([a + h * b for a, b in zip(y, k3, strict=True)])
        y = [a + h / 6.0 * (p + 2.0 * q + 2.0 * r + s)
             for a, p, q, r, s in zip(y, k1, k2, k3, k4, strict=True)]
    q = np.array(y[:4])
    return q / np.linalg.norm(q)


def _tumbling_measure(sim, quick: bool) -> dict:
    b = sim.blocks
    q0 = b.q[0].copy()
    n = int(sim.state.scene.solve.steps)
    sim.run(steps=n)
    q = euler_reference(q0, tumbling.SHAPES["random"][1], b.inertia[0], sim.time, 4 * n)
    d = _qmul((q[0], -q[1], -q[2], -q[3]), tuple(b.q[0]))  # reference^-1 * pdem
    angle = 2.0 * math.atan2(math.sqrt(d[1] ** 2 + d[2] ** 2 + d[3] ** 2), abs(d[0]))
    return {"error": angle, "turned": float(np.linalg.norm(b.w[0])) * sim.time}


# a pile of random polyhedra dropped into a box, undamped: energy balance error
def _pile_scene(quick: bool) -> str:
    return collapse.pile_scene(count=12 if quick else 20, time=0.8 if quick else 1.0)


def _pile_measure(sim, quick: bool) -> dict:
    from pdem.plugins.energy import balance, energy_totals

    sim.run()
    t = energy_totals(sim.state)
    err, put_in = balance(t, sim.runner.plugin("energy").e0)
    return {"error": abs(err) / put_in, "slipped": t["joint_dissipation"] / put_in}


# a 4 x 4 x 4 cube stack settling under local damping: each cube's height against the
# column's elastic rest (the joint under layer k closed by (n - k) m g / (kn A)), relative to
# the column's whole compression; the case where holding blocks at rest pays
SETTLED_N = 4


def _settled_scene(quick: bool) -> str:
    from pdem.cases.stacks import cube_stack_scene

    return cube_stack_scene(SETTLED_N, "fast")


def _settled_measure(sim, quick: bool) -> dict:
    n = SETTLED_N
    sim.run(steps=3000 if quick else 6000)
    b = sim.blocks
    free = b.fixed == 0
    w = 2500.0 * 9.81 / 1.0e9  # the stack's m g / (kn A)
    rest = np.arange(n) + 0.5 - np.cumsum([(n - k) * w for k in range(n)])
    layer = np.round(b.x[free, 2] - 0.5).astype(int)
    err = float(np.abs(b.x[free, 2] - rest[layer]).max()) / (n * (n + 1) / 2 * w)
    return {"error": err, "held": int((b.still[free] == 1).sum())}


CASES = {c.name: c for c in [
    Case("incline", "sliding acceleration g(sin ψ − cos ψ tan φ), ψ = 20°, φ = 10°",
         "|a/a_exact − 1|, a fitted over t ≥ 0.1 s", _incline_scene, _incline_measure, 5e-3,
         "test_incline.py::test_sliding_acceleration"),
    Case("wedge", "Hoek–Bray wedge sliding acceleration along the line of intersection, φ = 15°",
         "|a/a_exact − 1|, a fitted over t ≥ 0.1 s", _wedge_scene, _wedge_measure, 5e-3,
         "test_wedge.py::test_wedge_sliding_acceleration"),
    Case("oscillator", "period 2π√(m/(kn A)) of a cube on a floor, started at 2× its static overlap",
         "|T/T_exact − 1| over 30 periods (12 in --quick)", _oscillator_scene, _oscillator_measure,
         1e-2, "test_oscillator.py::test_vertical_period"),
    Case("tipping", "ω(θ) of a cube pivoting over the floor edge (energy, rigid pivot)",
         "max |ω/ω_exact − 1| for 10° < θ < 40° (30° in --quick)", _tipping_scene, _tipping_measure,
         3e-2, "test_common_plane_motion.py::test_cube_tipping_over_floor_edge"),
    Case("static", "overlaps 2mg/(kn A), mg/(kn A) of a two-cube stack solved to ratio 1e-5",
         "max relative overlap error", _static_scene, _static_measure, 5e-3,
         "test_static.py::test_stack_relaxes_to_elastic_equilibrium"),
    Case("static-unequal", f"the same stack with a {TOP_EDGE} m top cube: (m1 + m2) g/(kn A1), "
         "m2 g/(kn A2)", "max relative overlap error", _unequal_scene, _unequal_measure, 5e-3,
         "(none: this bench's case, test_static's tolerance)"),
    Case("tumbling", "torque-free asymmetric block: orientation from Euler's equations (RK4 reference)",
         "angle (rad) between pdem's and the reference orientation after 5000 steps (2000 in "
         "--quick); tolerance: this bench's, the test asserts H and K", _tumbling_scene,
         _tumbling_measure, 1e-3, "test_tumbling.py::test_free_tumbling_invariants"),
    Case("pile", "20 random polyhedra dropped into a box, undamped: energy balance closes",
         "|balance error| / energy put in, after 1 s (12 blocks, 0.8 s in --quick)",
         _pile_scene, _pile_measure, 1e-2, "test_energy.py::test_undamped_collapses_balance"),
    Case("settled", f"heights of a {SETTLED_N}³ cube stack at elastic rest after 6000 steps of "
         "local damping (3000 in --quick)", "max |z − z_rest| / the column's compression",
         _settled_scene, _settled_measure, 1e-2,
         "test_inactive.py::test_a_settled_stack_is_held_at_its_elastic_rest"),
]}


# ------------------------------------------------------------------------------ the knobs
@dataclass(frozen=True)
class Knob:
    """One accuracy knob: ``key`` (dotted scene key), the ``values`` tried (``quick``: the
    subset for --quick), the ``cases`` where it matters, and why it is there (one line)."""

    key: str
    values: tuple
    cases: tuple[str, ...]
    about: str
    quick: tuple = ()
    default: object = None  # pdem's default when the schema has none (damping alpha)

    def tried(self, quick: bool) -> tuple:
        return self.quick if quick and self.quick else self.values


KNOBS = [
    Knob("solve.timestep.frac", (0.025, 0.05, 0.1, 0.2, 0.4),
         ("oscillator", "incline", "tipping", "pile"),
         "fraction of the critical step 2√(m/k); cost ∝ 1/frac", quick=(0.05, 0.1, 0.4)),
    Knob("contact.detect_every", (1, 3, 10, 30, 100), ("tipping", "wedge", "pile"),
         "steps between contact geometry updates (common plane, sub-contacts)",
         quick=(1, 10, 100)),
    Knob("contact.refresh_tolerance", (0.0, 0.01, 0.1, 0.3, 1.0),
         ("incline", "oscillator", "tipping", "wedge", "pile", "settled"),
         "at an update, re-detect only contacts whose B moved more than this × CTOL relative "
         "to A (or found apart, now pressed)",
         quick=(0.0, 0.01, 1.0)),
    Knob("contact.ctol", ("auto", 0.002, 0.01, 0.05), ("tipping", "pile"),
         "gap (m) up to which a contact is kept; auto = 2 % of the smallest block size",
         quick=("auto", 0.05)),
    Knob("contact.point_area", (0.001, 0.01, 0.1, 0.3), ("tipping", "pile"),
         "area of a vertex/edge sub-contact, fraction of V^(2/3): the stiffness of a point contact",
         quick=(0.01, 0.1)),
    Knob("contact.algorithm", ("fast", "cundall"), ("incline", "wedge", "tipping", "pile"),
         "common-plane search: fast (3D-DDA paper) or Cundall's iteration"),
    Knob("solve.inertia", ("full", "scalar"), ("tumbling", "pile"),
         "full inertia tensor, or the mean principal moment (a sphere's)"),
    Knob("solve.damping.mode", ("none", "local", "combined", "adaptive"),
         ("static", "static-unequal", "incline"),
         "damping law (local/combined alpha 0.8)", quick=("none", "local", "adaptive")),
    Knob("solve.damping.alpha", (0.2, 0.5, 0.8, 0.95), ("static", "static-unequal"),
         "local damping coefficient", quick=(0.5, 0.8), default=0.8),
    Knob("solve.mass_scaling", (False, True), ("static", "static-unequal", "pile"),
         "scale block masses to one critical step (static solves)"),
]


# ------------------------------------------------------------------------------ the hook
@dataclass(frozen=True)
class FeatureToggle:
    """"Pay only for what the scene uses": a solver feature measured on and off.

    ``name``: what it is (e.g. "fused inner loop", "kernel specialisation", "inactive
    blocks"); ``apply(text, on)``: the scene text with the feature on or off (a scene key via
    :func:`set_key`, or an environment switch set in ``apply`` and cleared by ``reset``);
    ``cases``: the case names measured (``CASES`` or new ones added there). Each toggle is run
    like a knob with values (off, on); the page gets a section "Pay only for what the scene
    uses" with a table per toggle (the error must not change, the cost should)."""

    name: str
    about: str
    apply: Callable[[str, bool], str]
    cases: tuple[str, ...]
    reset: Callable[[], None] = field(default=lambda: None)


def _generic_kernels(text: str, on: bool) -> str:
    """Specialised kernels on (the default) or off (``PDEM_GENERIC_KERNELS=1``); the comment
    keeps the two runs apart in the result cache."""
    os.environ["PDEM_GENERIC_KERNELS"] = "0" if on else "1"
    return text + ("" if on else "\n# PDEM_GENERIC_KERNELS=1\n")


def _clear_generic() -> None:
    os.environ.pop("PDEM_GENERIC_KERNELS", None)


INACTIVE = {"speed": 1.0e-4, "steps": 100, "force": 0.01}

FEATURE_TOGGLES: list[FeatureToggle] = [
    FeatureToggle(
        "fused inner loop",
        "`solve.fused` (default on): a serial run marches the steps between Python-level events "
        "in one compiled call (pdem/cycle.py). The result is bitwise the same; the CPU time "
        "is what changes. bench/fused_loop.py measures the small scenes of the issue "
        "(1 and 10 blocks).",
        lambda text, on: set_key(text, "solve.fused", on), ("static", "static-unequal", "pile")),
    FeatureToggle(
        "kernel specialisation",
        "Frictional Coulomb joints (no cohesion, tension or dilation) compile a law without "
        "those branches (default); `PDEM_GENERIC_KERNELS=1` compiles the general one. "
        "Bitwise the same result (tests/unit/test_specialised.py). Damping modes and joint "
        "laws were already compiled per scene (only the used ones).",
        _generic_kernels, ("static", "pile", "settled"), reset=_clear_generic),
    FeatureToggle(
        "inactive blocks",
        "`solve.inactive: {speed: 1.0e-4, steps: 100, force: 0.01}` (default off): blocks "
        "at rest are held and joints "
        "between held or fixed blocks keep their forces (pdem/dynamics/inactive.py). Not "
        "bitwise: a held block ignores an unbalanced force below 1% of its weight; the error "
        "column says what that costs.",
        lambda text, on: set_key(text, "solve.inactive", INACTIVE if on else None),
        ("static", "settled", "pile")),
]


# ------------------------------------------------------------------------------ running
@dataclass
class Row:
    knob: str
    value: object
    case: str
    error: float
    steps: int
    cpu: float
    wall: float
    updates: int | None
    contacts: int
    subcontacts: int
    dt: float
    extra: dict

    @property
    def label(self) -> str:
        return fmt_value(self.value)


def fmt_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


_CACHE: dict = {}


def run_one(case: Case, text: str, quick: bool) -> dict:
    """Warm up (JIT) on a few steps of ``text``, then run and measure it. The same scene is
    run once (a case's own setting appears under every knob)."""
    key = (case.name, text, quick)
    if key in _CACHE:
        return dict(_CACHE[key])
    make_simulation(text).run(steps=20)
    sim = make_simulation(text)
    updates = sim.stepper.redetected  # (the start's update is not counted)
    t0, c0 = time.perf_counter(), time.process_time()
    res = case.measure(sim, quick)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    c = sim.contacts
    _CACHE[key] = out = {"error": float(res.pop("error")), "steps": int(sim.step), "cpu": cpu,
                         "wall": wall,
            "updates": sim.stepper.redetected - updates, "contacts": int(c.n),
            "subcontacts": int(len(c.sc_area)), "dt": float(sim.dt), "extra": res}
    return dict(out)


def run_knob(key: str, values, cases, quick: bool, apply=None) -> list[Row]:
    rows = []
    for name in cases:
        case = CASES[name]
        base = case.scene(quick)
        for v in values:
            text = apply(base, v) if apply is not None else set_key(base, key, v)
            r = run_one(case, text, quick)
            rows.append(Row(key, v, name, **r))
            print(f"  {key} = {fmt_value(v):>8} {name:>10}: error {r['error']:.2e} "
                  f"(tol {case.tolerance:.0e}), {r['steps']} steps, {r['cpu']:.2f} cpu s"
                  + (f", {r['updates']} updates" if r["updates"] is not None else "")
                  + "".join(f", {k} {x}" for k, x in r["extra"].items() if k == "note"),
                  flush=True)
    return rows


# ------------------------------------------------------------------------------ reporting
def g(x: float) -> str:
    if x is None:
        return "n/a"
    if not math.isfinite(x):
        return "∞"
    return f"{x:.2e}"


def case_value(case: str, key: str, quick: bool):
    """The value the case's own scene uses for ``key`` (pdem's default unless it sets it)."""
    try:
        v = get_key(CASES[case].scene(quick), key)
    except (AttributeError, KeyError):
        v = None
    if v is None:
        v = next((k.default for k in KNOBS if k.key == key), None)
    return v


def knob_table(rows: list[Row], key: str, quick: bool) -> str:
    out = ["| case | value | error | tol. | within | steps | cpu s | rel. cpu | updates "
           "| contacts / sub | note |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in dict.fromkeys(r.case for r in rows):
        rs = [r for r in rows if r.case == name]
        base = case_value(name, key, quick)
        ref = next((r for r in rs if r.value == base), rs[0])
        tol = CASES[name].tolerance
        for r in rs:
            mark = " (case)" if r.value == base else ""
            note = "; ".join(f"{k} {_fmt_extra(x)}" for k, x in r.extra.items())
            out.append(f"| {name} | {r.label}{mark} | {g(r.error)} | {tol:.0e} | "
                       f"{'yes' if r.error <= tol else '**no**'} | {r.steps} | {r.cpu:.2f} | "
                       f"{r.cpu / ref.cpu:.2f} | {r.updates if r.updates is not None else 'n/a'} | "
                       f"{r.contacts} / {r.subcontacts} | {note} |")
    return "\n".join(out)


def _fmt_extra(x) -> str:
    return f"{x:.3g}" if isinstance(x, float) else str(x)


def envelope(rows: list[Row]) -> list:
    """Values of a knob for which every case it was tried on stays within tolerance."""
    vals = list(dict.fromkeys(r.value for r in rows))
    return [v for v in vals if all(r.error <= CASES[r.case].tolerance for r in rows if r.value == v)]


def pareto(rows: list[Row]) -> list[Row]:
    """Rows of one case not beaten on both CPU time and error by another row."""
    front = []
    for r in rows:
        if not any((o.cpu <= r.cpu and o.error <= r.error) and (o.cpu < r.cpu or o.error < r.error)
                   for o in rows):
            front.append(r)
    return sorted(front, key=lambda r: r.cpu)


def plot_knob(rows: list[Row], key: str, quick: bool) -> str | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for name in dict.fromkeys(r.case for r in rows):
        rs = [r for r in rows if r.case == name]
        base = case_value(name, key, quick)
        ref = next((r for r in rs if r.value == base), rs[0])
        tol = CASES[name].tolerance
        x = [r.cpu / ref.cpu for r in rs]
        y = [max(min(r.error / tol, 1e6), 1e-9) for r in rs]
        (line,) = ax.plot(x, y, "o-", label=name)
        for r, xi, yi in zip(rs, x, y, strict=True):
            ax.annotate(r.label, (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7,
                        color=line.get_color())
    ax.axhline(1.0, color="k", ls="--", lw=0.8, label="tolerance")
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    ticks = [0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("CPU time relative to the case's own setting")
    ax.set_ylabel("error / verification tolerance")
    ax.set_title(key)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    name = f"fidelity-{key.replace('.', '-').replace('_', '-')}.png"
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURES / name, dpi=110)
    plt.close(fig)
    return name


def knob_summary(rows: list[Row], knob: Knob, quick: bool) -> dict:
    """Numbers for the summary: pdem's default, the envelope, worst error/tol at the default,
    and the cheapest value within the envelope (CPU time relative to the default's)."""
    default = knob.default if knob.default is not None else pdem_default(knob.key)
    env = envelope(rows)
    at_default = [r for r in rows if r.value == default]
    worst = max((r.error / CASES[r.case].tolerance for r in at_default), default=math.nan)

    def mean_rel(v) -> float:
        rel = []
        for name in dict.fromkeys(r.case for r in rows):
            ref = next((r for r in rows if r.case == name and r.value == default), None)
            r = next((r for r in rows if r.case == name and r.value == v), None)
            if ref is not None and r is not None:
                rel.append(r.cpu / ref.cpu)
        return float(np.exp(np.mean(np.log(rel)))) if rel else math.nan

    cheapest = min(env, key=mean_rel) if env else None
    return {"default": default, "envelope": env, "worst": worst,
            "cheapest": cheapest, "cheapest_rel": mean_rel(cheapest) if env else math.nan,
            "rel": {v: mean_rel(v) for v in dict.fromkeys(r.value for r in rows)}}


def auto_ctol(case: str, quick: bool) -> float:
    """The CTOL pdem resolves ``auto`` to in ``case``'s scene (m)."""
    return float(make_simulation(set_key(CASES[case].scene(quick), "contact.ctol", "auto")).state.ctol)


def _cell(text: str) -> str:
    """Text for a markdown table cell (a | would end the cell)."""
    return text.replace("|", "\\|")


def noise_note(results: dict, quick: bool) -> str:
    """How much the CPU time of identical runs varied: each case's own setting is run again
    under every knob that tries it."""
    same: dict[str, list[float]] = {}
    for key, rows in results.items():
        for r in rows:
            if r.value == case_value(r.case, key, quick):
                same.setdefault(r.case, []).append(r.cpu)
    parts = [f"{name} {100 * (max(c) / min(c) - 1):.0f} % ({len(c)} runs)"
             for name, c in same.items() if len(c) > 1 and min(c) > 0]
    return ("Timing noise: each case's own setting is run again under every knob that tries "
            "it; the CPU time of those identical runs varied (max/min − 1) by "
            + ", ".join(parts) + ". Differences of that size in the tables are noise.")


def write_doc(results: dict, toggles: dict, quick: bool, runtime: float, date: str) -> str:
    lines = [
        "# Speed against accuracy: what each knob buys",
        "",
        "<!-- generated by bench/fidelity.py: do not edit, re-run "
        "`.venv/bin/python bench/fidelity.py` -->",
        "",
        f"Generated by `bench/fidelity.py{' --quick' if quick else ''}` on "
        f"{date} ({runtime / 60:.1f} min, "
        "one rank, a shared 2-core machine). Every number below comes from that run."
        + (" **This is a --quick smoke run: fewer values, shorter cases.**" if quick else ""),
        "",
        "Each closed-form case of `tests/verification/` is run with one accuracy knob moved off "
        "the case's own setting, the others left alone. The error is measured against the "
        "closed form, the same quantity the verification test asserts, and set beside the cost: "
        "model steps, CPU seconds of the run (process time, compilation excluded; on a shared "
        "machine it varies between identical runs, see the timing noise below; steps and "
        "updates do not), contact geometry updates "
        "(contacts whose common plane and sub-contacts were re-detected) and the contacts / "
        "sub-contacts held at the end. *within*: the error is inside the verification "
        "tolerance. *(case)*: the value the case's scene uses (pdem's default unless the scene "
        "sets the key).",
        "",
        "## The cases",
        "",
        "| case | closed form | error measured | tolerance | verification test |",
        "|---|---|---|---|---|",
    ]
    used = dict.fromkeys(r.case for rows in results.values() for r in rows)
    for name in used:
        c = CASES[name]
        test = c.test if c.test.startswith("(") else f"`{c.test}`"
        lines.append(f"| {name} | {_cell(c.what)} | {_cell(c.error)} | {c.tolerance:.0e} | {test} |")
    lines += ["", noise_note(results, quick)]
    summaries = {k.key: knob_summary(results[k.key], k, quick) for k in KNOBS if k.key in results}
    lines += ["", "## Summary: choose this when", "",
              "| knob | pdem default | within tolerance on every case tried | cheapest of those "
              "(CPU vs default) | choose |",
              "|---|---|---|---|---|"]
    for k in KNOBS:
        if k.key not in results:
            continue
        s = summaries[k.key]
        env = ", ".join(fmt_value(v) for v in s["envelope"]) or "no single value"
        cheap = (f"{fmt_value(s['cheapest'])} ({s['cheapest_rel']:.2f}×)"
                 if s["cheapest"] is not None else "—")
        lines.append(f"| `{k.key}` | {fmt_value(s['default'])} | {env} | {cheap} | "
                     f"{CHOOSE.get(k.key, '')} |")
    lines += ["", "## Per knob", ""]
    for k in KNOBS:
        if k.key not in results:
            continue
        rows = results[k.key]
        s = summaries[k.key]
        lines += [f"### `{k.key}`", "", f"{k.about[0].upper()}{k.about[1:]}. Tried on: "
                  + ", ".join(k.cases) + ".", ""]
        rel = ", ".join(f"{fmt_value(v)}: {x:.2f}×" for v, x in s["rel"].items()
                        if math.isfinite(x))
        lines.append(
            f"pdem's default is **{fmt_value(s['default'])}**; at it the worst case's error is "
            f"{s['worst']:.2g} × its tolerance. "
            + (f"Every case stays within tolerance for {', '.join(fmt_value(v) for v in s['envelope'])}. "
               if s["envelope"] else "No value keeps every case within tolerance. ")
            + (f"CPU time relative to the default (geometric mean over the cases): {rel}. "
               if rel else "")
            + WHY.get(k.key, ""))
        if k.key == "contact.ctol":
            autos = ", ".join(f"{auto_ctol(name, quick):.3g} m for the {name}"
                              for name in dict.fromkeys(r.case for r in rows))
            lines[-1] += f" (Auto is {autos}.)"
        lines += ["", knob_table(rows, k.key, quick), ""]
        fig = FIGURE_NAMES.get(k.key)
        if fig:
            lines += [f"![error against cost, {k.key}](figures/{fig})", ""]
        elif not HAVE_MPL:
            lines += ["(matplotlib is not installed: no figure; the table holds the data.)", ""]
    lines += ["## Pareto front", "",
              "Per case, the settings no other setting beats on both CPU time and error (one "
              "knob moved at a time, so this is the front of that sample, not of every "
              "combination). Settings within tolerance only; the fastest first.", ""]
    by_case: dict[str, list[Row]] = {}
    for rows in results.values():
        for r in rows:
            by_case.setdefault(r.case, []).append(r)
    for name, rows in by_case.items():
        ok = [r for r in rows if r.error <= CASES[name].tolerance]
        front = pareto(ok)
        lines.append(f"* **{name}**: " + "; ".join(
            f"`{r.knob.split('.')[-1]}={r.label}` ({r.cpu:.2f} s, {g(r.error)})" for r in front))
    lines += ["", PARETO_NOTE, ""]
    if FEATURE_TOGGLES:
        lines += ["## Pay only for what the scene uses", "",
                  "Solver features measured off and on: the error must not move, the cost "
                  "should.", ""]
        for t in FEATURE_TOGGLES:
            lines += [f"### {t.name}", "", t.about, "", knob_table(toggles[t.name], t.name, quick),
                      ""]
    lines += ["## Measured elsewhere", "", ELSEWHERE, ""]
    return "\n".join(lines) + "\n"


# knobs and features whose measurement needs its own scene or a long run (no numbers here:
# they are in the pages named, each from its own script)
ELSEWHERE = """\
* **Partial mass scaling** (`solve.mass_scaling: {timestep: DT}`): a 1 cm pebble beside 1 m \
blocks no longer sets the step of the whole scene; `bench/mass_scaling.py` counts the steps with \
and without it, and docs/validation.md section 11 gives the error it makes (the scaled blocks \
keep their weight but accelerate factor times slower: use it for blocks whose own motion does \
not matter). The start-up log names the block that limits the step and suggests a DT.
* **The compiled loop on small scenes**: `bench/fused_loop.py` (1 and 10 blocks, steps/s off \
and on, and that the states are bitwise equal); the cube stack `bench/cube_stack.py`. Figures \
in docs/validation.md, Benchmarks.
* **The extremes**: what pdem runs and what it refuses (stiffness 1e4-1e14 Pa/m, size ratio \
1:100, mass ratio 1e6, aspect 1:100, 100 m/s impacts, friction 0-89 deg, 100-block columns, \
1e6 undamped steps, gravity 1e-6-1e5 m/s2, coordinates at 1e6 m): docs/limits.md, "The \
envelope", from tests/extremes."""


# Prose per knob: qualitative, no numbers (those come from the tables). Written against the
# results of the full run; re-read them when the numbers change.
WHY: dict[str, str] = {
    "solve.timestep.frac":
        "The step's error grows with the step: the oscillator's period error as frac² (the "
        "leapfrog's (ω dt)²/24), the pile's energy balance error about linearly; the sliding "
        "and tipping cases do not see it (their error comes from the joint, not the step). The "
        "pile's energy balance sets the default: the largest frac that keeps it inside its "
        "tolerance with a margin left for harder scenes.",
    "contact.detect_every":
        "No case's error moved over the whole range: between updates the overlaps still follow "
        "the motion every step, and a block that moves a fraction of CTOL triggers a search "
        "anyway. What changes is the cost: updating more often than the default costs clearly "
        "more; updating less often saves little that stands out of the timing noise here, "
        "the updates being by then a small part of the step. The default stays at 10 because these "
        "cases are gentle (few blocks, slow rotations): the contact normal lags the blocks by up "
        "to detect_every × |ω| dt / 2 (asserted by the tipping test), so fast-spinning blocks "
        "want it small.",
    "contact.refresh_tolerance":
        "It changes how many contacts an update re-detects (column *updates*). On the sliding, "
        "tipping and falling cases it does not move the error: resting and slowly sliding "
        "contacts keep their plane. The settled stack is the sensitive case: its diagonal "
        "neighbours touch along shared edges, whose plane is a tie until they press, and with "
        "0.3 and above the stack settles before a stale plane is replaced (spurious load "
        "through the edges). 0 (every contact at every update) leaves it by more, for a reason "
        "not yet found (the table's error: the heights, off by that fraction of the "
        "compression; before sub-contacts a hair apart were merged its faces carried the "
        "closed form's loads to 0.2 % while the heights were off by 15 %). In these small "
        "cases the updates are a small part of the step, so the CPU time hardly moves; it pays "
        "in large models that mostly rest (bench/cube_stack.py).",
    "contact.ctol":
        "The pile's energy balance is the sensitive case, and its error is U-shaped in CTOL: "
        "well above auto it keeps contacts across wide gaps (column *contacts / sub*) and leaves "
        "the tolerance, well below it the error grows again and the searches get more frequent "
        "(more CPU). Auto lies on the good side of the U, not at its bottom; the tipping cube "
        "does not notice CTOL.",
    "contact.point_area":
        "It is the stiffness of a vertex or edge contact. The tipping cube pivots on an edge: "
        "with small point areas the pivot is soft, the cube sinks into the floor edge and turns "
        "slower than the rigid closed form; the case (and its test) use 0.1, and pdem's default "
        "fails it. The pile's energy balance does not care, but what the pile does does: the "
        "share of the energy its joints dissipate in the fall (column *slipped*: joint "
        "dissipation / energy put in) changes severalfold across the range.",
    "contact.algorithm":
        "The two common-plane searches give the same answers (differences at round-off) at the "
        "same cost within the timing noise here; fast is the default because it needs no "
        "iteration.",
    "solve.inertia":
        "Scalar inertia treats every block as a sphere: an asymmetric block tumbles about the "
        "wrong axis (its orientation error is of the order of the angle turned), and it saved "
        "no measurable time. Full is the default; scalar is there to compare with codes that "
        "use it.",
    "solve.damping.mode":
        "Damping is for static solves: every mode falsifies dynamics (a sliding block under "
        "local damping accelerates at 1 − α of the true rate), and undamped the static stacks "
        "never reach the ratio. For statics every mode reaches the tolerance; local needed the "
        "fewest steps on both stacks, adaptive the most. What is left of the error at the "
        "ratio limit differs between modes, all of it inside the tolerance.",
    "solve.damping.alpha":
        "The coefficient sets how many steps a static solve needs, not its answer: every value "
        "reaches the overlaps within tolerance; the default needed the fewest steps on both "
        "stacks, and both lower and higher values took longer.",
    "solve.mass_scaling":
        "Mass scaling gives every block the critical step of the mean block. On equal blocks it "
        "changes nothing; with a small block on a big one it reaches the same overlaps in far "
        "fewer steps. It changes the dynamics (the pile dissipates a different share of its "
        "energy in the same model time, column *slipped*), so it is for static solves only and "
        "off by default.",
}
CHOOSE: dict[str, str] = {
    "solve.timestep.frac": "0.1 for dynamics; larger only where neither energy accounting nor "
                           "vibration matters (sliding, slow tipping); smaller to converge an "
                           "energy budget or a period",
    "contact.detect_every": "10; larger for slow, sliding or settling models (cheaper, no error "
                            "seen here); small when blocks spin fast",
    "contact.refresh_tolerance": "the default; up to 0.1 for big models that mostly rest "
                                 "(0.3 and above leave the settled stack's tolerance)",
    "contact.ctol": "auto; never far above it (energy balance)",
    "contact.point_area": "0.1 when blocks pivot or rock on edges or vertices (toppling, "
                          "rocking); the default makes such pivots soft",
    "contact.algorithm": "fast; cundall to cross-check",
    "solve.inertia": "full; scalar only to compare with other codes",
    "solve.damping.mode": "none for any dynamics; local for static solves (ratio)",
    "solve.damping.alpha": "the default 0.8 for static solves",
    "solve.mass_scaling": "static solves with blocks of different sizes; never for dynamics",
}
PARETO_NOTE = (
    "Read it with the tables: much of the front is the cheap end of knobs that did not move "
    "the error (detect_every, refresh_tolerance, frac on the sliding cases). That says those "
    "cases do not exercise the knob, not that its cheap end is safe everywhere. Where a knob "
    "moves the error (frac on the oscillator and the pile, point_area on the tipping cube, "
    "damping on anything dynamic, ctol on the pile) the front stops at the envelope above. "
    "Mass scaling on the pile is on the front because its energy balance still closes, yet "
    "the pile does something else (column *slipped*): a balance is no check of the path. "
    "Combinations of knobs were not measured.")

HAVE_MPL = True
FIGURE_NAMES: dict[str, str] = {}


def main(argv=None) -> int:
    global HAVE_MPL
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="fewer values, shorter cases (smoke run); tables only")
    ap.add_argument("--no-doc", action="store_true", help="print the tables only")
    ap.add_argument("--knob", nargs="*", help="only these knobs (dotted keys); tables only")
    ap.add_argument("--render", action="store_true",
                    help=f"no runs: rewrite the page and figures from {DATA.relative_to(ROOT)} "
                         "(after editing the prose in this script)")
    args = ap.parse_args(argv)
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        HAVE_MPL = False
    if args.render:
        saved = json.loads(DATA.read_text())
        results = {k: [Row(**r) for r in rows] for k, rows in saved["knobs"].items()}
        toggles = {k: [Row(**r) for r in rows] for k, rows in saved["toggles"].items()}
        return report(results, toggles, saved["quick"], saved["runtime"], saved["date"], doc=True)
    t0 = time.perf_counter()
    results: dict[str, list[Row]] = {}
    for k in KNOBS:
        if args.knob and k.key not in args.knob:
            continue
        print(f"{k.key}: {k.about}", flush=True)
        results[k.key] = run_knob(k.key, k.tried(args.quick), k.cases, args.quick)
    toggles = {}
    for t in FEATURE_TOGGLES:
        print(f"feature {t.name}", flush=True)
        try:
            toggles[t.name] = run_knob(t.name, (False, True), t.cases, args.quick,
                                       apply=t.apply)
        finally:
            t.reset()
    runtime = time.perf_counter() - t0
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    doc = not (args.no_doc or args.knob or args.quick)  # a partial run leaves the page alone
    if doc:
        DATA.parent.mkdir(parents=True, exist_ok=True)
        DATA.write_text(json.dumps({
            "quick": args.quick, "runtime": runtime, "date": date,
            "knobs": {k: [asdict(r) for r in rows] for k, rows in results.items()},
            "toggles": {k: [asdict(r) for r in rows] for k, rows in toggles.items()}},
            indent=1, default=_json_value))
    return report(results, toggles, args.quick, runtime, date, doc=doc)


def _json_value(x):
    return float(x) if isinstance(x, np.floating) else str(x)


def report(results, toggles, quick: bool, runtime: float, date: str, doc: bool) -> int:
    """Print the tables; with ``doc``, draw the figures and write the page."""
    for k in KNOBS:
        if k.key in results:
            print(f"\n## {k.key}\n\n{knob_table(results[k.key], k.key, quick)}")
            if doc and HAVE_MPL:
                FIGURE_NAMES[k.key] = plot_knob(results[k.key], k.key, quick)
    print(f"\nruntime {runtime:.0f} s")
    if doc:
        DOC.write_text(write_doc(results, toggles, quick, runtime, date))
        print(f"wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
