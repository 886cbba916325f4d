"""Joint laws: the registry, the scene's joint table and the statically dispatched update.

A joint law is one module exposing ``LAW = JointLaw(name, params, history, table, update,
energy, strength=Strength(...))`` plus one line in :data:`JOINT_LAWS` below. ``strength``
declares which parameters a factor-of-safety search reduces (:class:`.base.Strength`: angles
through their tangents, strengths divided); :data:`JOINT_LAWS` refuses a law without it.
``update`` is a numba kernel with the signature

    update(p, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz, state)
        -> (fn, dil, state, fx, fy, fz)

``p`` is the law's table (a namedtuple of per-joint arrays) and ``j`` the contact's row in it;
``s`` the sub-contact index and ``hist`` the ``sc_hist`` columns (the law's ``history`` names,
in order, from column 0); ``un`` the overlap (+ closing), ``dil`` the dilation; ``fx, fy, fz``
the shear force on B carried from the last step, already turned into the current plane;
``dx, dy, dz`` this step's shear displacement increment and ``ux, uy, uz`` the total; ``area``
the sub-contact's area; ``state`` its bits (:mod:`.base`). It returns the new normal force
(> 0 compression), dilation, state and shear force. Laws never see block kinematics. A law
sets SLIPPING in every step in which it yields: the energy budget evaluates a joint's
dissipation only in such steps or when its state or dilation changes (an elastic step of
linear springs dissipates exactly nothing).

A scene compiles only the laws its joints use: the force kernel receives a tuple of the used
laws' tables and :func:`apply_law` is resolved per tuple type at compile time (no runtime
dispatch on names, numba's disk cache keyed on that type).

A law may also give ``stays_open`` (:class:`.base.JointLaw`): whether a sub-contact is
separated and stays so this step, when the update is known to return zero forces and the same
state; the force loop then does only the kinematics for it (:func:`law_stays_open`).
"""

from __future__ import annotations

import functools
from collections import namedtuple

import numpy as np
from numba.extending import overload

from ...jit import inline_kernel
from ...registry import Registry
from . import continuously_yielding, coulomb
from .base import FAILED, OPEN, SLIPPING, JointLaw, JointParams, Strength

__all__ = ["FAILED", "JOINT_LAWS", "OPEN", "SLIPPING", "JointLaw", "JointParams", "JointTable",
           "Strength", "apply_law", "joint_dissipation", "joint_table", "law_energy",
           "law_stays_open"]


class _JointLaws(Registry[JointLaw]):
    """The joint-law registry: a law must say what strength reduction weakens (its
    ``strength``), so that a factor of safety never silently leaves a law at full strength."""

    def register(self, name: str, entry: JointLaw) -> JointLaw:
        if entry.strength is None:
            raise ValueError(
                f"joint law {name!r} declares no strength: give JointLaw(..., "
                "strength=Strength(angles=(...), strengths=(...))) the friction angles and the "
                "strengths (cohesion, tension) of its Params that a factor-of-safety search "
                "reduces, or strength=Strength() for a law without strength")
        return super().register(name, entry)


JOINT_LAWS: Registry[JointLaw] = _JointLaws("joint law")
JOINT_LAWS.register("coulomb", coulomb.LAW)
JOINT_LAWS.register("continuously_yielding", continuously_yielding.LAW)

# What the force kernel reads: for each scene joint (row), the slot of its law in ``laws`` and
# its row in that law's table; ``dash`` (rows, 2): the joint's dashpot constants per unit area,
# ``beta kn`` and ``beta ks`` (Rayleigh damping's stiffness term at the contacts,
# pdem.contact.forces), or an empty 1-d array where the scene has none (beta = 0: a type of its
# own, so the force loops compile without the dashpots' code, pdem.contact.forces.has_dashpots).
Joints = namedtuple("Joints", "slot row laws dash")


class JointTable:
    """The scene's joints resolved: per-law tables, stiffnesses, the group-pair map."""

    def __init__(self, names, params, pair, cut_joint=None, beta: float = 0.0):
        self.names = list(names)
        self.params = list(params)
        self.pair = pair
        # per cut (``cuts:``), the joint row its faces use, -1 where the cut names none
        self.cut_joint = np.zeros(0, np.int32) if cut_joint is None else cut_joint
        self.by_set = bool((self.cut_joint >= 0).any())
        used = [law.specialised([p for p in self.params if p.model == law.name])
                for law in JOINT_LAWS.values() if any(p.model == law.name for p in self.params)]
        self.laws = tuple(used)
        slot = np.zeros(len(self.params), np.int32)
        row = np.zeros(len(self.params), np.int32)
        tables = []
        for k, law in enumerate(used):
            mine = [i for i, p in enumerate(self.params) if p.model == law.name]
            slot[mine] = k
            row[mine] = np.arange(len(mine), dtype=np.int32)
            tables.append(law.table([self.params[i] for i in mine]))
        self.kn = np.array([p.kn for p in self.params], float)
        self.ks = np.array([p.ks for p in self.params], float)
        # Rayleigh damping's stiffness-proportional constant (s) and the joints' dashpots
        self.beta = float(beta)
        dash = np.stack([self.beta * self.kn, self.beta * self.ks], axis=1) if self.beta > 0.0 \
            else np.zeros(0)
        self.kernel_args = Joints(slot, row, tuple(tables), dash)
        self.hist_width = max((len(law.history) for law in used), default=0)


def joint_table(scene, group_names: list[str]) -> JointTable:
    """The scene's joints (rows in ``scene.joints`` order) and the group-pair -> row map;
    their dashpots from ``scene.solve.damping`` (Rayleigh's ``beta``, 0 for every other
    mode): pass a stage's scene (pdem.config.stages.stage_scene) for the stage's."""
    names = list(scene.joints)
    rows = {name: i for i, name in enumerate(names)}
    ng = len(group_names)
    pair = np.full((ng, ng), rows.get("default", 0), dtype=np.int32)
    gidx = {g: i for i, g in enumerate(group_names)}
    for jp in scene.joint_pairs:
        a, b = gidx[jp.groups[0]], gidx[jp.groups[1]]
        pair[a, b] = pair[b, a] = rows[jp.joint]
    cut_joint = np.array([rows[c.joint] if c.joint is not None else -1 for c in scene.cuts],
                         np.int32)
    return JointTable(names, [scene.joints[k] for k in names], pair, cut_joint,
                      scene.solve.damping.rayleigh[1])


def apply_law(laws, slot, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz,
              state):
    """Update one sub-contact with the law in ``laws[slot]`` (compiled, see module doc)."""
    raise NotImplementedError("apply_law is only callable from numba kernels")


def law_energy(laws, slot, j, s, hist, un, dil, fx, fy, fz, area, state):
    """(normal force, stored spring energy) of one sub-contact by the law in ``laws[slot]``."""
    raise NotImplementedError("law_energy is only callable from numba kernels")


def joint_dissipation(laws, slot, j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz,
                      st0, un, dil, fn, fx, fy, fz, st):
    """The energy sub-contact s's joint dissipated in a step that took it from the state
    ``(un0, dil0, g, st0)`` to ``(un, dil, f, st)`` with the normal force ``fn`` (the law's
    update), the normal and shear displacement increments ``dun`` and ``ds``: the work done on
    it over the step (trapezoid) less the change of its stored energy."""
    raise NotImplementedError("joint_dissipation is only callable from numba kernels")


def law_stays_open(laws, slot, j, s, hist, un, dil, area, state):
    """Whether the law in ``laws[slot]`` would leave sub-contact s separated with zero forces
    and its state unchanged (:class:`.base.JointLaw`'s ``stays_open``; False for a law
    without one)."""
    raise NotImplementedError("law_stays_open is only callable from numba kernels")


@inline_kernel
def _never_open(p, j, s, hist, un, dil, area, state):
    """``stays_open`` of a law without one: never, so the force loop always updates it."""
    return False


_DISSIPATION_ARGS = ("j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz, st0, un, dil, "
                     "fn, fx, fy, fz, st")


def _law_of(table_type) -> JointLaw:
    for registered in JOINT_LAWS.values():
        for law in (registered, *(v for _, v in registered.variants)):
            if law.table([]).__class__ is table_type.instance_class:
                return law
    raise KeyError(f"no registered joint law has the table type {table_type}")


@functools.cache
def _energy_difference(energy):
    """A law's ``dissipation`` from its ``energy`` kernel: the stored energy evaluated before
    and after the step (for laws without a kernel of their own)."""

    def dissipation(p, j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz, st0, un,
                    dil, fn, fx, fy, fz, st):
        fn0, e0 = energy(p, j, s, hist, un0, dil0, gx, gy, gz, area, st0)
        _, e1 = energy(p, j, s, hist, un, dil, fx, fy, fz, area, st)
        return -0.5 * ((fn0 + fn) * dun + (gx + fx) * dsx + (gy + fy) * dsy
                       + (gz + fz) * dsz) - (e1 - e0)

    return inline_kernel(dissipation)


def _dissipation_of(law):
    return law.dissipation if law.dissipation is not None else _energy_difference(law.energy)


def _dispatch(laws, attr: str, args: str):
    """``impl(laws, slot, args...)`` calling ``getattr(law, attr)`` of the law in the slot
    (``attr`` a callable: ``attr(law)``): one branch per used law, resolved at compile
    time."""
    kernels = [attr(_law_of(t)) if callable(attr) else getattr(_law_of(t), attr)
               for t in laws.types]
    src = [f"def impl(laws, slot, {args}):"]
    for k in range(1, len(kernels)):
        src.append(f"    if slot == {k}:\n        return k{k}(laws[{k}], {args})")
    src.append(f"    return k0(laws[0], {args})")
    scope = {f"k{k}": fn for k, fn in enumerate(kernels)}
    exec("\n".join(src), scope)
    return scope["impl"]


@overload(apply_law, inline="always")
def _apply_law(laws, slot, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz,
               state):
    return _dispatch(laws, "update", "j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, "
                                     "uy, uz, state")


@overload(law_stays_open, inline="always")
def _law_stays_open(laws, slot, j, s, hist, un, dil, area, state):
    return _dispatch(laws, lambda law: law.stays_open or _never_open,
                     "j, s, hist, un, dil, area, state")


@overload(law_energy, inline="always")
def _law_energy(laws, slot, j, s, hist, un, dil, fx, fy, fz, area, state):
    return _dispatch(laws, "energy", "j, s, hist, un, dil, fx, fy, fz, area, state")


@overload(joint_dissipation, inline="always")
def _joint_dissipation(laws, slot, j, s, hist, dun, dsx, dsy, dsz, area, un0, dil0, gx, gy, gz,
                       st0, un, dil, fn, fx, fy, fz, st):
    return _dispatch(laws, _dissipation_of, _DISSIPATION_ARGS)
