"""Inactive blocks (``solve.inactive``): blocks at rest stop costing motion and joint work.

3DEC spends no time on relatively inactive blocks. pdem already skips their contact geometry
(``contact.refresh_tolerance``); with ``solve.inactive`` a free block that has been at rest for
``steps`` steps (speed bound ``|v| + |w| r`` below ``speed``, unbalanced force below ``force``
times its weight and moment below that times its radius) is *held*: its velocities are zeroed
(the kinetic energy they had is booked as damping dissipation, so the energy budget still
balances), the integrator treats it as fixed, and a contact between two held blocks (or a held
and a fixed one) keeps the force and moment it had instead of updating its joint
(:func:`pdem.contact.forces.contact_forces`). The block's unbalanced force is still summed each
step from all of its contacts; when it (or the moment) exceeds the threshold again, a neighbour
moved or a load changed, and the block wakes.

This trades accuracy for speed: a held block ignores unbalanced forces below the threshold
(docs/fidelity.md measures what that costs on a settled pile). The decisions use only the
block's own state and its ghosts' (``still`` travels with the halo), so results stay
bitwise the same on any rank count and across restarts (both fields are checkpointed).
"""

from __future__ import annotations

import math

from ..jit import access, kernel
from .motion import WORK_DAMPING

NEVER = 2**31 - 1  # ``steps`` when inactive blocks are off: ``calm`` never gets there


@access(reads="x fixed vfix mass mscale force applied_force bforce moment bmoment v w L work radius "
              "calm",
        writes="calm still v w L work")
@kernel
def update_inactive(m, gravity, radius, calm, still, speed, steps, force_frac, ref_force):
    """After a step's contact forces: count each owned free block's steps at rest (``calm``),
    hold it when the count reaches ``steps`` and wake it when its unbalanced force or moment
    exceeds the threshold; ``still`` = fixed or held, for the integrator and the joints.

    ``m``: the owned rows' :data:`pdem.dynamics.motion.Motion` record (with the true ``fixed``).
    """
    g = math.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])
    for i in range(m.x.shape[0]):
        if m.fixed[i] or m.vfix[i]:
            calm[i] = 0
            still[i] = 1 if m.fixed[i] else 0
            continue
        mb = m.mass[i]
        fx = (m.force[i, 0] + (m.applied[i, 0] + m.bforce[i, 0])) + mb * gravity[0]
        fy = (m.force[i, 1] + (m.applied[i, 1] + m.bforce[i, 1])) + mb * gravity[1]
        fz = (m.force[i, 2] + (m.applied[i, 2] + m.bforce[i, 2])) + mb * gravity[2]
        mx = m.moment[i, 0] + m.bmoment[i, 0]
        my = m.moment[i, 1] + m.bmoment[i, 1]
        mz = m.moment[i, 2] + m.bmoment[i, 2]
        f = math.sqrt(fx * fx + fy * fy + fz * fz)
        mm = math.sqrt(mx * mx + my * my + mz * mz)
        lim = force_frac * (mb * g if g > 0.0 else ref_force)
        loaded = f > lim or mm > lim * radius[i]
        if calm[i] >= steps:  # held: wake when loaded
            if loaded:
                calm[i] = 0
                still[i] = 0
            continue
        v, w = m.v, m.w
        s = math.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]) + \
            math.sqrt(w[i, 0] * w[i, 0] + w[i, 1] * w[i, 1] + w[i, 2] * w[i, 2]) * radius[i]
        if loaded or s >= speed:
            calm[i] = 0
            still[i] = 0
            continue
        calm[i] += 1
        if calm[i] >= steps:  # held from the next step: its kinetic energy is dissipated
            L = m.L
            m.work[i, WORK_DAMPING] += 0.5 * mb * m.mscale[i] * (
                v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]) + 0.5 * (
                w[i, 0] * L[i, 0] + w[i, 1] * L[i, 1] + w[i, 2] * L[i, 2])
            for k in range(3):
                v[i, k] = 0.0
                w[i, k] = 0.0
                L[i, k] = 0.0
            still[i] = 1


def hold_fixed(state) -> None:
    """Fixed blocks are still (a block fixed between steps, e.g. frozen on leaving the model
    domain, must not move in the next step); every row, every rank alike."""
    b = state.blocks
    if state.scene.solve.inactive is not None:
        b.still |= b.fixed


def wake_all(state) -> None:
    """Every block awake and every contact's held force void (a stage changed loads, supports
    or joints); every row, every rank alike."""
    if state.scene.solve.inactive is None:
        return
    b = state.blocks
    b.calm[:] = 0
    b.still[:] = b.fixed
    state.contacts.frozen[:] = 0


def inactive_args(scene) -> tuple[float, int, float]:
    """``(speed, steps, force)`` of ``solve.inactive``; ``steps`` is :data:`NEVER` without it."""
    ia = scene.solve.inactive
    if ia is None:
        return math.inf, NEVER, 0.0
    return float(ia.speed), int(ia.steps), float(ia.force)

