"""The registries are the extension points: a joint law added from outside pdem's tree is
selected by a scene and runs, with history columns that travel with the sub-contacts."""

from __future__ import annotations

from collections import namedtuple
from typing import Literal

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import ConfigError, parse_scene
from pdem.contact.laws import JOINT_LAWS, JointLaw, JointParams, Strength
from pdem.jit import kernel
from pdem.registry import Registry
from pdem.simulation import Simulation

# --- a complete joint law: parameters, history, table, kernels (what a new law file holds) ---


class GlueParams(JointParams):
    """A linear elastic joint that never slips or opens; counts its loaded steps."""

    model: Literal["glue"] = "glue"


GlueTable = namedtuple("GlueTable", "kn ks")


def glue_table(joints):
    return GlueTable(np.array([j.kn for j in joints], float),
                     np.array([j.ks for j in joints], float))


@kernel
def glue_update(p, j, s, hist, un, dil, fx, fy, fz, dx, dy, dz, area, ux, uy, uz, state):
    hist[s, 0] += 1.0  # steps this sub-contact carried load
    kss = p.ks[j] * area
    return p.kn[j] * area * un, dil, state, fx - kss * dx, fy - kss * dy, fz - kss * dz


@kernel
def glue_energy(p, j, s, hist, un, dil, fx, fy, fz, area, state):
    kna = p.kn[j] * area
    return kna * un, 0.5 * kna * un * un + 0.5 * (fx * fx + fy * fy + fz * fz) / (p.ks[j] * area)


# glue has no strength: a factor-of-safety search over its joints is refused
GLUE = JointLaw("glue", GlueParams, ("loaded_steps",), glue_table, glue_update, glue_energy,
                strength=Strength())

SCENE = """
name: glued
materials: {rock: {density: 2000.0}}
joints:
  default: {model: MODEL, kn: 1.0e9, ks: 1.0e9}
blocks:
  - {name: floor, box: {min: [-2, -2, -1], max: [2, 2, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}, material: rock}
gravity: [0.0, -9.81, 0.0]
solve: {steps: 300}
"""


@pytest.fixture
def glue_registered(monkeypatch):
    """Register the law for one test (the registry line a new law file adds).

    The contact kernels compiled for it are not written to numba's disk cache: a cache index
    would then name this test module, which other processes (MPI ranks) cannot import."""
    from numba.core.caching import NullCache
    from numba.core.dispatcher import Dispatcher

    from pdem import cycle
    from pdem.contact import forces, update

    # every kernel whose argument types include the joint table: the force kernels, the
    # contact update's (its energy booking) and the compiled loop that calls them (pdem.cycle)
    for module in (forces, update, cycle):
        for kernel_ in vars(module).values():
            if isinstance(kernel_, Dispatcher):
                monkeypatch.setattr(kernel_, "_cache", NullCache())
    JOINT_LAWS.register("glue", GLUE)  # the scene grammar follows (pdem.config.schema)
    yield
    JOINT_LAWS.unregister("glue")


def test_a_new_joint_law_is_selected_by_the_scene_and_keeps_history(glue_registered):
    # gravity along the floor: a Coulomb joint would slide (friction 30 deg < 90), glue holds
    sim = Simulation(parse_scene(SCENE.replace("MODEL", "glue")), MPI.COMM_SELF, output=False)
    assert sim.contacts.hist_width == 1
    sim.run()
    cube = sim.blocks.x[1] - sim.blocks.x0[1]
    # elastic shear: 4 corner sub-contacts of 1/4 m2 each carry m g: u = m g / (ks A)
    m_g = 2000.0 * 9.81
    assert abs(cube[1]) < 3 * m_g / 1.0e9  # held (static shear displacement ~2e-5 m)
    hist = sim.contacts.sub["sc_hist"]
    assert hist.shape[1] == 1 and hist[:, 0].max() > 100  # the law's own history advanced


def test_registering_a_law_extends_the_scene_grammar():
    """JOINT_LAWS.register is all a law from outside the tree needs for scenes to select it:
    the schema's union of laws follows the registry (and its errors name the key path)."""
    glued = SCENE.replace("MODEL", "glue")
    with pytest.raises(ConfigError, match="joints.default"):
        parse_scene(glued)
    JOINT_LAWS.register("glue", GLUE)
    try:
        assert type(parse_scene(glued).joints["default"]) is GlueParams
        with pytest.raises(ConfigError, match=r"joints\.default\.kn"):
            parse_scene(glued.replace("kn: 1.0e9", "kn: -1.0"))
        with pytest.raises(ConfigError, match="friction"):  # glue has no friction
            parse_scene(glued.replace("ks: 1.0e9", "ks: 1.0e9, friction: 30.0"))
        coulomb = parse_scene(SCENE.replace("MODEL", "coulomb"))  # the shipped laws still parse
        assert coulomb.joints["default"].model == "coulomb"
    finally:
        JOINT_LAWS.unregister("glue")
    with pytest.raises(ConfigError, match="joints.default"):
        parse_scene(glued)


def test_coulomb_is_the_default_model_and_unknown_models_are_refused():
    sim = Simulation(parse_scene(SCENE.replace("model: MODEL, ", "")), MPI.COMM_SELF,
                     output=False)
    assert [law.name for law in sim.state.joints.laws] == ["coulomb"]
    assert sim.contacts.hist_width == 0
    with pytest.raises(ConfigError, match="joints.default"):
        parse_scene(SCENE.replace("MODEL", "glue"))


def test_registry_names_unknown_entries():
    r: Registry[int] = Registry("thing")
    r.register("alpha", 1)
    with pytest.raises(KeyError, match="unknown thing 'alhpa'.*did you mean 'alpha'"):
        r["alhpa"]
    with pytest.raises(ValueError, match="twice"):
        r.register("alpha", 2)


def test_kernel_records_pickle_by_reference():
    """numba keys its disk cache on argument types; a record type that does not pickle by
    reference (class name != module attribute) silently recompiles the kernel in every
    process (~30 s per rank)."""
    import pickle

    from pdem.contact import algorithms, detect, rigid, update
    from pdem.contact import laws as L
    from pdem.dynamics import damping, motion
    from pdem.model import blocks, contacts

    records = [rigid.Bodies, contacts.Pairs, contacts.Subs, blocks.Shapes, detect.Planes,
               motion.Motion, L.Joints, algorithms.CundallPlane, algorithms.FastPlane,
               update.GeometryUpdate, update.JointSets]
    records += [law.table([]).__class__ for law in L.JOINT_LAWS.values()]
    records += [mode.kernel_args for mode in damping.DAMPING.values()]
    for cls in records:
        assert pickle.loads(pickle.dumps(cls)) is cls, cls
