"""What every joint law has: its registry entry type, shared parameters and state bits."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from pydantic import PositiveFloat

from ...strict import Strict

# sub-contact state bits, shared by every law (output and tests read them)
SLIPPING = 1  # at the shear limit this step
FAILED = 2  # tension and cohesion lost, for good
OPEN = 4  # normal force zero: separated


class JointParams(Strict):
    """Parameters every law has: normal and shear stiffness (Pa/m), for the timestep."""

    kn: PositiveFloat
    ks: PositiveFloat


@dataclass(frozen=True)
class JointLaw:
    """A registered joint law.

    ``params``: pydantic model of a ``joints.X`` entry (its ``model`` literal is the name);
    ``history``: names of extra per-sub-contact history columns (``sc_hist``);
    ``table``: list of params -> namedtuple of per-joint arrays (the kernel's ``p``);
    ``update``: the numba kernel, signature documented in :mod:`pdem.contact.laws`;
    ``energy``: the kernel giving a sub-contact's normal force and stored spring energy in a
    given state (the energy budget, pdem.dynamics.energy);
    ``dissipation``: optional kernel giving the energy one step of the joint dissipated
    (signature in :func:`pdem.contact.laws.joint_dissipation`); without one the budget
    evaluates ``energy`` before and after the step;
    ``variants``: ``(applies, law)`` pairs: when ``applies(params)`` holds for every joint of
    the scene using this law, ``law`` (same name, parameters and history, its own table type
    and kernels doing the same arithmetic without the branches those joints cannot take) is
    compiled instead, so a scene pays only for the physics it uses (docs/fidelity.md);
    ``stays_open``: optional kernel ``stays_open(p, j, s, hist, un, dil, area, state) -> bool``,
    True only when ``update`` with these arguments would return ``(0.0, dil, state, 0.0, 0.0,
    0.0)`` whatever the shear force and displacements, and change nothing else: a separated
    sub-contact that stays separated. The force loop then skips the shear carry, the update
    and the force sums for it (pdem.contact.forces); without one it never does.
    """

    name: str
    params: type[JointParams]
    history: tuple[str, ...]
    table: Any
    update: Any
    energy: Any
    variants: tuple = ()
    dissipation: Any = None
    stays_open: Any = None

    def specialised(self, params: list) -> JointLaw:
        """The variant for these joints (unless ``PDEM_GENERIC_KERNELS`` is set), else self."""
        if os.environ.get("PDEM_GENERIC_KERNELS", "") not in ("", "0"):
            return self
        return next((law for applies, law in self.variants if all(map(applies, params))), self)
