"""What made a run blow up, from its energy budget: the time integration, the contact model,
or the loads. Used by the runaway guard (pdem.stepper) and the energy guard (pdem.plugins)."""

from __future__ import annotations

import math

import numpy as np

from ..mpi import allgather


def deepest_contact(state, gid: int):
    """(block names, overlap) of the most overlapped sub-contact of block ``gid`` on the rank
    that owns it, or None (collective: every rank gets the owner's answer)."""
    mine = None
    row = state.owned_row(gid)
    c = state.contacts
    if row >= 0 and c.n:
        sel = np.nonzero((c.ia == row) | (c.ib == row))[0]
        best = (-math.inf, None)
        for k in sel:
            s0, s1 = c.sc_start[k], c.sc_start[k + 1]
            if s1 > s0:
                un = float(c.sc_un[s0:s1].max())
                if un > best[0]:
                    best = (un, (int(c.ga[k]), int(c.gb[k])))
        if best[1] is not None:
            mine = (best[1], best[0])
    found = [m for m in allgather(state.comm, mine) if m is not None]
    if not found:
        return None
    (ga, gb), un = found[0]
    return state.specs[ga].name, state.specs[gb].name, un


def step_motion(state, gid: int) -> float:
    """Block ``gid``'s motion bound in the last step, |dx| + |dtheta| r, from the rank that owns
    it (collective: every rank gets the owner's answer; 0 if no rank owns it)."""
    row = state.owned_row(gid)
    mine = None
    if row >= 0:
        b = state.blocks
        mine = float(np.linalg.norm(b.dx[row]) + np.linalg.norm(b.dtheta[row]) * b.radius[row])
    found = [m for m in allgather(state.comm, mine) if m is not None]
    return found[0] if found else 0.0


def tunnelling_text(state, gid: int) -> str:
    """A sentence when block ``gid`` moved further in its last step than the contact search can
    follow (``state.max_step``, see pdem.state.max_step_motion and
    pdem.dynamics.motion.motion_bookkeeping), else ''. Collective."""
    step = step_motion(state, gid)
    limit = state.max_step
    if not (math.isfinite(step) and step > limit):
        return ""
    return (f" It moved {step:.3g} m in one step, more than the {limit:.3g} m that contact "
            f"detection can follow: it could pass through a block unseen. Give a "
            f"smaller solve.timestep.dt (at most {state.dt * limit / step:.3g} s at this speed) "
            "or stiffer joints, or keep it from falling so far.")


def explain(state, totals: dict | None, start: tuple[float, float] | None, gid: int) -> str:
    """The probable cause and the knob that helps, told by where the energy came from.

    ``totals``: pdem.plugins.energy.energy_totals now; ``start``: (kinetic, strain) at the
    start of the run. The budget splits into what the integrator made (kinetic energy gained
    beyond the work of all forces) and what the contacts made (their work on the blocks plus
    the change of the energy stored in the joints plus what the joints dissipated)."""
    contact = deepest_contact(state, gid)
    fast = tunnelling_text(state, gid)
    where = ""
    if contact is not None:
        a, b, un = contact
        where = (f" Its deepest contact, {a!r}-{b!r}, overlaps {un:.3g} m "
                 f"({un / state.ctol:.2g} x CTOL).")
    if totals is None or start is None or not all(map(math.isfinite, totals.values())):
        return (f"{fast}{where} Probable cause: timestep {state.dt:.3g} s too large for the joint "
                "stiffness (lower solve.timestep.frac or give a smaller dt) or blocks created "
                "deeply overlapping.")
    ke0, strain0 = start
    t = totals
    put_in = ke0 + strain0 + t["gravity_work"] + t["applied_work"] + t["boundary_work"]
    # (the zoned blocks' zones take work as the joints do: what was done on them)
    integ = t["kinetic"] - ke0 - (t["gravity_work"] + t["applied_work"] + t["contact_work"]
                                  + t["boundary_work"] - t["damping_dissipation"]
                                  - t["zone_strain"] - t["plastic_work"]
                                  - t.get("quiet_absorbed", 0.0))
    err = integ + t["contact_work"] + (t["strain"] - strain0) + t["joint_dissipation"] \
        + t["removed"]
    made = t["geometry_created"]  # measured at each contact geometry update
    stepping = err - made  # what the time stepping (motion and force updates) made
    scale = max(abs(put_in), 1e-300)
    budget = (f" Energy: the balance error is {err:.3g} J ({100 * err / scale:.2g}% of the "
              f"{put_in:.3g} J put in): {made:.3g} J from contact geometry updates, "
              f"{stepping:.3g} J from the time stepping.")
    # a joint that gave back more than it took in a step was integrated with too large a step
    stepping = max(stepping, t["joint_created"])
    if stepping > 0.5 * max(made, 0.0) and stepping > 0.01 * scale:
        cause = (f" Probable cause: timestep {state.dt:.3g} s too large for the joint "
                 "stiffness (lower solve.timestep.frac or give a smaller dt).")
    elif made > 0.01 * scale:
        cause = (" Probable cause: the contact model created energy: blocks moved too far "
                 "into each other between contact updates (contact.detect_every is "
                 f"{state.scene.contact.detect_every}: lower it, down to 1) or vertex/edge "
                 "sub-contacts too small for the impact (raise contact.point_area).")
    else:
        cause = (" The energy balances, so the speed was put in by the loads (gravity, "
                 "applied forces, prescribed velocities): check them.")
    return fast + where + budget + cause
