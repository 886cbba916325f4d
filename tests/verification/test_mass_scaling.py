"""Partial mass scaling (``solve.mass_scaling: {timestep: DT}``, 3DEC's ``mass-scale
timestep``): a 1 m block and a 1 cm pebble (mass ratio 1e6) on one fixed base
(:mod:`pdem.cases.pebble`).

Unscaled, eq. 87 pairs the pebble's mass with the big block's stiffness: dt = 2e-7 s. With
DT = 9e-5 s (just below the big block's own critical step, 9.4e-5 s) only the pebble is
scaled, by s = K DT^2 / (4 frac^2 I_min / r^2) = 91.125, and the scene steps at DT.

Closed forms and tolerances (no damping):

* the big block (not scaled) slides down a 20 deg incline (phi = 10 deg) at
  ``a = g (sin psi - cos psi tan phi)``: fitted ``x0 + v0 t + a t^2/2`` over t in [0.1, 1] s,
  within 1e-6 relative (measured 3e-10);
* the scaled pebble slides at ``a / s`` (gravity and friction act on the true mass, inertia on
  s m), within 1e-6 (measured 1.2e-10);
* the scaled pebble falls at ``g / s``: ``z = z0 - g t^2 / (2 s)`` to 1e-12 m over 0.3 s
  (central differences are exact for a constant acceleration; measured 7e-16 m);
* resting on the base and pushed 1e-7 m into it, the pebble oscillates about the true static
  overlap ``m g / (kn A)`` with the period ``2 pi sqrt(s m / (kn A))`` -- sqrt(s) = 9.55
  times the true one -- within 0.1 % (measured 1.9e-4, the central-difference period error
  at 94 steps a period).
"""

from __future__ import annotations

import logging
import math

import h5py
import numpy as np
import pytest

from pdem.cases import crossing_times, fit_acceleration, make_simulation
from pdem.cases.pebble import (
    PEBBLE,
    G,
    contact_period,
    pebble_scene,
    sliding_acceleration,
    static_overlap,
)
from pdem.dynamics.timestep import critical_steps
from pdem.errors import UserError
from pdem.resolve import MAX_SCALED_MASS_FRACTION

DT = 9.0e-5
PARTIAL = f"{{timestep: {DT!r}}}"
S_PEBBLE = 91.125  # (DT / the pebble's own critical step 9.43e-6 s)^2


def rows(s) -> dict[str, int]:
    return {s.specs[g].name: i for i, g in enumerate(s.blocks.gid)}


def history(s, seconds: float, fn) -> tuple[np.ndarray, np.ndarray]:
    n = int(round(seconds / s.dt))
    t, y = np.empty(n), np.empty(n)
    for k in range(n):
        s.advance()
        t[k], y[k] = s.time, fn()
    return t, y


def test_only_the_pebble_is_scaled_and_the_step_is_dt():
    plain = make_simulation(pebble_scene("time: 0.5"))
    assert plain.dt == pytest.approx(2.0e-7, rel=1e-9)  # eq. 87: pebble mass, big K
    s = make_simulation(pebble_scene("time: 0.5", scaling=PARTIAL))
    r, b = rows(s), s.blocks
    assert s.dt == DT
    assert b.mscale[r["big"]] == 1.0
    assert b.mscale[r["pebble"]] == pytest.approx(S_PEBBLE, rel=1e-12)
    # the per-block criterion the factors meet: every free block is stable at DT
    from pdem.resolve import estimated_stiffness
    from pdem.selection import TIMESTEP_FIELDS

    g = s.state.scene_fields(TIMESTEP_FIELDS)  # every block's, from its owner
    assert g is not s.state.glob and np.array_equal(g.gid, np.arange(len(s.specs)))
    k = estimated_stiffness(s.specs, s.state.joints)
    own = critical_steps(g.mass, k, 0.1, g.inertia, g.radius, g.mscale)[g.fixed == 0]
    assert own.min() >= DT * (1.0 - 1e-12)
    # 0.5 s: 2.5 million steps unscaled, 5556 with partial scaling
    assert round(0.5 / plain.dt) == 2_500_000 and math.ceil(0.5 / s.dt) == 5556


def test_unscaled_block_slides_at_closed_form_scaled_pebble_at_a_over_s():
    s = make_simulation(pebble_scene("time: 1.0", psi=20.0, phi=10.0, scaling=PARTIAL))
    r, b = rows(s), s.blocks
    big, peb = r["big"], r["pebble"]
    xp = []

    def both():
        xp.append(b.x[peb, 0] - b.x0[peb, 0])
        return b.x[big, 0] - b.x0[big, 0]

    t, xb = history(s, 1.0, both)
    xp = np.array(xp)
    late = t >= 0.1
    a = sliding_acceleration(20.0, 10.0)
    err_big = fit_acceleration(t[late], xb[late]) / a - 1.0
    err_peb = fit_acceleration(t[late], xp[late]) * S_PEBBLE / a - 1.0
    print(f"big: rel. err {err_big:.2e}; pebble (a / s): rel. err {err_peb:.2e}")
    assert abs(err_big) < 1e-6
    assert abs(err_peb) < 1e-6


def test_scaled_pebble_falls_at_g_over_s():
    """Gravity acts on the true mass, the inertia is s m: free fall at g / s, not g."""
    s = make_simulation(pebble_scene("time: 0.3", scaling=PARTIAL, lift=0.05))
    r, b = rows(s), s.blocks
    p = r["pebble"]
    z0 = b.x[p, 2]
    t, z = history(s, 0.3, lambda: b.x[p, 2] - z0)
    exact = -0.5 * G / S_PEBBLE * t**2
    print(f"max |z - z_exact| = {np.abs(z - exact).max():.2e} m")
    assert np.abs(z - exact).max() < 1e-12
    assert z[-1] > -0.05  # still in the air


def test_scaled_pebble_contact_period_is_sqrt_s_longer():
    s = make_simulation(pebble_scene("time: 0.1", scaling=PARTIAL, lift=-1.0e-7))
    r, b = rows(s), s.blocks
    p = r["pebble"]
    z_eq = 0.5 * PEBBLE - static_overlap(PEBBLE)  # the true weight sets the static overlap
    t, z = history(s, 0.1, lambda: b.x[p, 2] - z_eq)
    period = float(np.diff(crossing_times(t, z)).mean())
    ratio = period / contact_period(PEBBLE)
    print(f"period {period:.6g} s = {ratio:.5g} x the true one; sqrt(s) = {math.sqrt(S_PEBBLE):.5g}")
    assert ratio / math.sqrt(S_PEBBLE) == pytest.approx(1.0, abs=1e-3)
    assert abs(0.5 * (z.max() + z.min())) < 1e-3 * 1.0e-7  # about the true static overlap
    assert np.abs(z).max() == pytest.approx(1.0e-7, rel=1e-3)  # no energy gained or lost


def test_start_up_log_names_the_limiting_block_and_the_added_inertia(caplog):
    with caplog.at_level(logging.INFO, logger="pdem"):
        make_simulation(pebble_scene("time: 0.5"))
    assert ("block 'pebble' limits the step: its critical step 9.43e-06 s is 10 x below the "
            "median 9.43e-05 s (eq. 87 pairs its mass with the stiffest block's stiffness: "
            "dt = 2e-07 s); consider solve.mass_scaling: {timestep: 9.4e-05}") in caplog.text
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="pdem"):
        make_simulation(pebble_scene("time: 0.5", dt=DT))
    assert ("solve.timestep.dt = 9e-05 s; block 'pebble' has the smallest critical step, "
            "9.43e-06 s, 10 x below the median 9.43e-05 s") in caplog.text
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="pdem"):
        make_simulation(pebble_scene("time: 0.5", scaling=PARTIAL))
    assert ("partial mass scaling to dt = 9e-05 s: 1 of 2 free blocks scaled, added inertia "
            "0.1802 kg (0.00901 % of the free blocks' 2000 kg), largest factor 91.13 on block "
            "'pebble'") in caplog.text


def test_suggested_step_is_accepted():
    """The step the log suggests (the median block's, cut to two digits) scales the pebble
    only."""
    s = make_simulation(pebble_scene("time: 0.5", scaling="{timestep: 9.4e-05}"))
    r = rows(s)
    assert s.blocks.mscale[r["big"]] == 1.0 and s.blocks.mscale[r["pebble"]] > 1.0


def test_scaling_most_of_the_mass_is_refused():
    """DT above the big block's own critical step would scale it too: 100 % of the free mass
    scaled is not partial scaling."""
    assert MAX_SCALED_MASS_FRACTION == 0.5
    with pytest.raises(UserError) as info:
        make_simulation(pebble_scene("time: 0.5", scaling="{timestep: 2.0e-4}"))
    msg = str(info.value)
    assert msg.startswith("solve.mass_scaling.timestep: 0.0002 s would scale 2 of 2 free "
                          "blocks, 100 % of the free mass (more than 50 %; largest factor "), msg
    assert "on block 'pebble'" in msg and "mass_scaling: true for a static solve" in msg


def test_output_records_the_added_inertia(tmp_path):
    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.simulation import Simulation

    text = pebble_scene("steps: 2", scaling=PARTIAL) + f"output: {{file: {tmp_path}/p.h5}}\n"
    s = Simulation(parse_scene(text), MPI.COMM_SELF)
    s.run()
    s.close()
    with h5py.File(tmp_path / "p.h5") as f:
        a = f.attrs
        assert a["dt"] == DT and a["mass_scaling_timestep"] == DT
        assert a["mass_scaled_blocks"] == 1 and a["mass_scaling_max_block"] == "pebble"
        assert a["mass_scaling_max_factor"] == pytest.approx(S_PEBBLE, rel=1e-12)
        added = 2000.0 * PEBBLE**3 * (S_PEBBLE - 1.0)
        assert a["mass_scaling_added_mass"] == pytest.approx(added, rel=1e-12)
        assert a["mass_scaling_added_percent"] == pytest.approx(100.0 * added / 2000.002,
                                                                rel=1e-9)


def test_restart_continues_bitwise(tmp_path):
    """The factors are recomputed from the scene on restart (not stored): the restarted run
    ends where the straight run ends, bit for bit."""
    import glob

    from mpi4py import MPI

    from pdem.config import parse_scene
    from pdem.io.checkpoint import read_checkpoint
    from pdem.simulation import Simulation

    text = pebble_scene("steps: 600", psi=20.0, scaling=PARTIAL, lift=1.0e-4) + (
        f"output: {{file: {tmp_path}/straight.h5, every_steps: 600}}\n"
        f"checkpoint: {{every_steps: 250, keep: 5, file: {tmp_path}/ck}}\n")
    s = Simulation(parse_scene(text), MPI.COMM_SELF)
    s.run()
    s.close()
    ck = read_checkpoint(sorted(glob.glob(f"{tmp_path}/ck-*.h5"))[0])
    scene = parse_scene(ck["attrs"]["scene"])
    out = f"{tmp_path}/again.h5"
    scene = scene.model_copy(update={"output": scene.output.model_copy(update={"file": out}),
                                     "checkpoint": None})
    r = Simulation(scene, MPI.COMM_SELF, checkpoint=ck)
    assert r.dt == DT and np.array_equal(r.state.scene_fields(("mscale",)).mscale,
                                         s.state.scene_fields(("mscale",)).mscale)
    r.run()
    r.close()
    with h5py.File(f"{tmp_path}/straight.h5") as a, h5py.File(out) as b:
        for k in ("centroid", "orientation", "velocity", "angular_velocity"):
            assert np.array_equal(a[f"blocks/{k}"][-1], b[f"blocks/{k}"][-1]), k


def staged_scene(timestep: str) -> str:
    """The pebble scene run in two stages: unscaled, then partially scaled to ``timestep``."""
    text = pebble_scene("steps: 1", scaling="false")
    head = text[:text.index("solve:")]
    return head + f"""solve: {{damping: none}}
stages:
  - name: plain
    solve: {{steps: 3}}
  - name: scaled
    solve: {{steps: 3, mass_scaling: {{timestep: {timestep}}}}}
"""


def test_stage_level_partial_scaling():
    """A stage's ``mass_scaling: {timestep: DT}`` sets the step and the factors at its start;
    a bad one is refused naming the stage's key."""
    s = make_simulation(staged_scene(repr(DT)))
    r = rows(s)
    s.run()
    assert s.dt == DT and s.step == 6
    assert s.blocks.mscale[r["pebble"]] == pytest.approx(S_PEBBLE, rel=1e-12)
    assert s.blocks.mscale[r["big"]] == 1.0
    s = make_simulation(staged_scene("2.0e-4"))
    with pytest.raises(UserError) as info:
        s.run()
    assert str(info.value).startswith("stages[1].solve.mass_scaling.timestep (line "), info.value
