"""A scene compiles only the physics it uses: frictional Coulomb joints (no cohesion, tension,
dilation) get a law without those branches, and it gives the general law's bits."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from pdem.cases import make_simulation
from pdem.cases.collapse import pile_scene
from pdem.cases.incline import incline_scene
from pdem.contact.laws import coulomb


def final_state(text: str) -> dict[str, np.ndarray]:
    sim = make_simulation(text)
    sim.run()
    b, c = sim.blocks, sim.contacts
    return {"x": b.x.copy(), "q": b.q.copy(), "v": b.v.copy(), "w": b.w.copy(),
            "work": b.work.copy(), "fs": c.sub["sc_fs"].copy(), "un": c.sub["sc_un"].copy(),
            "state": c.sub["sc_state"].copy(), "law": type(sim.state.joints.kernel_args.laws[0])}


SCENES = {"incline": lambda: incline_scene(20.0, "fast", "time: 0.2"),
          "pile": lambda: pile_scene(count=12, time=0.3)}


@pytest.mark.parametrize("name", SCENES)
def test_frictional_law_is_bitwise_the_general_one(name, monkeypatch):
    text = SCENES[name]()
    special = final_state(text)
    monkeypatch.setenv("PDEM_GENERIC_KERNELS", "1")
    general = final_state(text)
    assert special.pop("law") is coulomb.FrictionTable
    assert general.pop("law") is coulomb.Table
    for k in special:  # the same values and the same signs of zero
        assert np.array_equal(special[k], general[k]), k
        assert np.array_equal(np.signbit(special[k]), np.signbit(general[k])), k


@pytest.mark.parametrize("extra", [{"cohesion": 1.0e4}, {"tension": 1.0e3}, {"dilation": 5.0}])
def test_a_joint_with_strength_or_dilation_keeps_the_general_law(extra):
    d = yaml.safe_load(incline_scene(20.0, "fast", "steps: 1"))
    d["joints"]["default"].update(extra)
    sim = make_simulation(yaml.safe_dump(d))
    assert type(sim.state.joints.kernel_args.laws[0]) is coulomb.Table
