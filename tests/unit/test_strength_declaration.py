"""Strength reduction (a ``factor_of_safety:`` stage) weakens what each joint law declares
(``JointLaw.strength``), not what its parameter names suggest: the shipped laws reduce their
declared angles through the tangent and strengths by division, a law added from outside the
tree with other names is reduced by its declaration, and a law that declares nothing is
refused with a message naming the law (at registration) or the joint (at the search)."""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Literal

import numpy as np
import pytest

from pdem.contact.laws import JOINT_LAWS, JointLaw, JointParams, Strength, coulomb
from pdem.contact.laws import continuously_yielding as cy
from pdem.errors import UserError
from pdem.strength import reduced_joints

FACTORS = (1.0, 1.0625, 1.3, 2.0, 3.7)


def reduced_angle(phi: float, factor: float) -> float:
    return math.degrees(math.atan(math.tan(math.radians(phi)) / factor))


def test_the_shipped_laws_declare_their_strength():
    assert JOINT_LAWS["coulomb"].strength == Strength(angles=("friction",),
                                                      strengths=("cohesion", "tension"))
    # the frictional variant compiled in its place has the same parameters and strength
    assert coulomb.FRICTION_LAW.strength == coulomb.LAW.strength
    assert JOINT_LAWS["continuously_yielding"].strength == Strength(
        angles=("friction", "initial_friction"))


@pytest.mark.parametrize("factor", FACTORS)
def test_coulomb_reduces_friction_cohesion_and_tension(factor):
    j = coulomb.Params(kn=1e10, ks=5e9, friction=35.0, dilation=10.0, cohesion=2e5,
                       tension=1e5, dilation_limit=0.01)
    r = reduced_joints({"J": j}, factor)["J"]
    # the closed form: tan(phi)/F, c/F, t/F
    assert math.isclose(math.tan(math.radians(r.friction)),
                        math.tan(math.radians(35.0)) / factor, rel_tol=1e-13)
    assert r.friction == reduced_angle(35.0, factor)
    assert r.cohesion == 2e5 / factor and r.tension == 1e5 / factor
    # everything else as it was: stiffnesses, dilation (as 3DEC), its limit
    assert (r.kn, r.ks, r.dilation, r.dilation_limit) == (1e10, 5e9, 10.0, 0.01)
    assert r.model == "coulomb"


@pytest.mark.parametrize("factor", FACTORS)
def test_continuously_yielding_reduces_both_friction_angles(factor):
    j = cy.Params(kn=1e10, ks=5e9, friction=25.0, initial_friction=40.0, roughness=0.002,
                  normal_exponent=0.5, shear_exponent=0.3, reference_stress=2e6)
    r = reduced_joints({"J": j}, factor)["J"]
    for key, phi in (("friction", 25.0), ("initial_friction", 40.0)):
        assert math.isclose(math.tan(math.radians(getattr(r, key))),
                            math.tan(math.radians(phi)) / factor, rel_tol=1e-13)
        assert getattr(r, key) == reduced_angle(phi, factor)
    assert r.initial_friction >= r.friction  # the law's order of peak and residual holds
    same = ("kn", "ks", "roughness", "normal_exponent", "shear_exponent", "reference_stress",
            "continuous")
    assert all(getattr(r, k) == getattr(j, k) for k in same)
    # initial_friction unset (= friction) stays unset: the table takes the reduced friction
    r = reduced_joints({"J": cy.Params(kn=1e10, ks=5e9, friction=25.0)}, factor)["J"]
    assert r.initial_friction is None and r.friction == reduced_angle(25.0, factor)
    assert cy.table([r]).phim0[0] == math.radians(r.friction)


def _by_name(j, factor):
    """The rule strength reduction used before the declarations (parameter names)."""
    update = {}
    for key, value in j.model_dump().items():
        if key.endswith("friction") and isinstance(value, float):
            update[key] = math.degrees(math.atan(math.tan(math.radians(value)) / factor))
        elif key in ("cohesion", "tension"):
            update[key] = value / factor
    return j.model_copy(update=update)


@pytest.mark.parametrize("factor", (*FACTORS, 0.9, 1.17, 2.5e-3, 41.0))
def test_the_shipped_laws_reduce_bitwise_as_the_former_name_rule(factor):
    joints = {
        "a": coulomb.Params(kn=1e9, ks=1e9),
        "b": coulomb.Params(kn=1e9, ks=2e9, friction=33.3, dilation=5.0, cohesion=1.5e5,
                            tension=7e4, dilation_limit=0.02),
        "c": coulomb.Params(kn=1e9, ks=1e9, friction=0.0, cohesion=1e6),
        "d": cy.Params(kn=1e9, ks=1e9, friction=28.7),
        "e": cy.Params(kn=1e9, ks=1e9, friction=21.0, initial_friction=47.3, roughness=1e-3,
                       continuous=False),
    }
    got = reduced_joints(joints, factor)
    for name, j in joints.items():
        old = _by_name(j, factor)
        assert got[name].model_dump() == old.model_dump(), name
        # and bit for bit (== would take -0.0 for 0.0)
        for key, value in old.model_dump().items():
            if isinstance(value, float):
                assert np.float64(getattr(got[name], key)).tobytes() == \
                    np.float64(value).tobytes(), (name, key)


# --- a law added from outside pdem's tree, its parameters named otherwise ---


class PeakParams(JointParams):
    """Peak and residual friction and a cohesion, under names no rule could guess."""

    model: Literal["peak"] = "peak"
    phi_peak: float = 45.0
    phi_res: float = 30.0
    c0: float = 1e5
    dilation: float = 12.0
    u_scale: float = 1e-3


PeakTable = namedtuple("PeakTable", "kn ks tan_peak tan_res c0")


def peak_table(joints):
    return PeakTable(*(np.array(v, float) for v in zip(
        *((j.kn, j.ks, math.tan(math.radians(j.phi_peak)), math.tan(math.radians(j.phi_res)),
           j.c0) for j in joints), strict=True)))


def _peak_law(strength):
    # kernels are not needed to reduce the parameters (the search compiles them per trial)
    return JointLaw("peak", PeakParams, (), peak_table, None, None, strength=strength)


@pytest.fixture
def registry(monkeypatch):
    """The joint-law registry, restored after the test."""
    monkeypatch.setattr(JOINT_LAWS, "_entries", dict(JOINT_LAWS._entries))
    return JOINT_LAWS


@pytest.mark.parametrize("factor", FACTORS)
def test_a_law_from_outside_is_reduced_by_its_declaration(registry, factor):
    registry.register("peak", _peak_law(Strength(angles=("phi_peak", "phi_res"),
                                                 strengths=("c0",))))
    joints = {"default": PeakParams(kn=1e9, ks=1e9), "J2": coulomb.Params(kn=1e9, ks=1e9)}
    r = reduced_joints(joints, factor)
    p = r["default"]
    assert p.phi_peak == reduced_angle(45.0, factor)
    assert p.phi_res == reduced_angle(30.0, factor)
    assert p.c0 == 1e5 / factor
    assert (p.dilation, p.u_scale, p.kn, p.ks) == (12.0, 1e-3, 1e9, 1e9)
    t = peak_table([p])  # what a trial's joint table holds: tan(phi)/F
    assert math.isclose(t.tan_peak[0], 1.0 / factor, rel_tol=1e-13)
    assert math.isclose(t.tan_res[0], math.tan(math.radians(30.0)) / factor, rel_tol=1e-13)
    assert r["J2"].friction == reduced_angle(30.0, factor)
    # only the named joints
    assert reduced_joints(joints, factor, ["J2"])["default"] is joints["default"]


def test_registering_a_law_without_a_declaration_is_refused(registry):
    with pytest.raises(ValueError, match="joint law 'peak' declares no strength"):
        registry.register("peak", _peak_law(None))
    assert "peak" not in registry


def test_a_declaration_naming_no_parameter_is_refused():
    with pytest.raises(ValueError, match="joint law 'peak'.*'friction'.*not a parameter of "
                                         "PeakParams"):
        _peak_law(Strength(angles=("friction",)))


@pytest.mark.parametrize("strength", [None, Strength()], ids=["undeclared", "empty"])
def test_a_search_over_a_law_without_strength_is_refused(registry, strength):
    # a law put into the registry past ``register`` (undeclared), or one declaring that it
    # has no strength: a search would leave its joints at full strength and report a factor
    # of safety that is not one, so it names the joint and the law instead
    registry._entries["peak"] = _peak_law(strength)
    joints = {"rock": coulomb.Params(kn=1e9, ks=1e9), "glued": PeakParams(kn=1e9, ks=1e9)}
    with pytest.raises(UserError, match=r"joints\.glued: .*its law 'peak' declares no strength"):
        reduced_joints(joints, 1.5)
    # the search over the other joints goes on, that joint at full strength
    r = reduced_joints(joints, 1.5, ["rock"])
    assert r["glued"] is joints["glued"] and r["rock"].friction == reduced_angle(30.0, 1.5)
