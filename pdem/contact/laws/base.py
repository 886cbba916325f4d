"""What every joint law has: its registry entry type, shared parameters and state bits."""

from __future__ import annotations

import math
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
class Strength:
    """Which parameters of a joint law strength reduction (a ``factor_of_safety:`` stage,
    pdem.strength) weakens at a factor F, by name in the law's ``params``: ``angles``
    (friction angles, degrees) through their tangents, ``tan(phi) / F``; ``strengths``
    (cohesion, tension: stresses) divided, ``c / F``. Every other parameter (stiffnesses,
    dilation, length and stress scales) keeps its value. A parameter that may be null (an
    optional angle that defaults to another) is left null. ``Strength()``, nothing declared:
    a law without strength, whose joints a factor-of-safety search refuses."""

    angles: tuple[str, ...] = ()
    strengths: tuple[str, ...] = ()

    def reduced(self, params: JointParams, factor: float) -> dict:
        """The reduced values at ``factor``, as a ``model_copy`` update of ``params``."""
        update = {}
        for key in self.angles:
            value = getattr(params, key)
            if value is not None:
                update[key] = math.degrees(math.atan(math.tan(math.radians(value)) / factor))
        for key in self.strengths:
            value = getattr(params, key)
            if value is not None:
                update[key] = value / factor
        return update


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
    and the force sums for it (pdem.contact.forces); without one it never does;
    ``strength``: the parameters a factor-of-safety search reduces (:class:`Strength`). Every
    registered law must declare it (``Strength()`` for a law without strength): it is not
    guessed from parameter names, and :data:`pdem.contact.laws.JOINT_LAWS` refuses a law
    without it.
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
    strength: Strength | None = None

    def __post_init__(self):
        if self.strength is None:
            return
        fields = self.params.model_fields
        for key in (*self.strength.angles, *self.strength.strengths):
            if key not in fields:
                raise ValueError(f"joint law {self.name!r}: its strength names {key!r}, which is "
                                 f"not a parameter of {self.params.__name__} (parameters: "
                                 f"{', '.join(fields)})")

    def specialised(self, params: list) -> JointLaw:
        """The variant for these joints (unless ``PDEM_GENERIC_KERNELS`` is set), else self."""
        if os.environ.get("PDEM_GENERIC_KERNELS", "") not in ("", "0"):
            return self
        return next((law for applies, law in self.variants if all(map(applies, params))), self)
