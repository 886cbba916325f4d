"""Scene keys of deformable blocks: material elasticity and ``zones:``; bad input gets one line
that names its key."""

import pytest

from pdem.config import ConfigError, dump_scene, parse_scene

SCENE = """
name: t
materials:
  granite: {density: 2650, young: 40.0e9, poisson: 0.25}
  weak: {density: 2400, young: 5.0e9, poisson: 0.3, model: mohr_coulomb, cohesion: 2.0e6,
         friction: 35, tension: 0.5e6, dilation: 5}
  rock: {density: 2000}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: base, box: {min: [-1, -1, -1], max: [1, 1, 0]}, material: rock, fixed: true}
  - {name: pillar, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: weak, zones: {size: 0.5}}
  - {name: roof, box: {min: [0, 0, 1], max: [1, 1, 2]}, material: granite}
solve: {steps: 10}
"""


def errors_of(text):
    with pytest.raises(ConfigError) as info:
        parse_scene(text, "s.yaml")
    return info.value.messages


def test_contract_scene_parses_with_defaults():
    scene = parse_scene(SCENE)
    assert scene.blocks[1].zones.size == 0.5 and scene.blocks[1].zones.nmd is True
    assert scene.blocks[2].zones is None
    weak = scene.materials["weak"]
    assert weak.deformable and weak.model == "mohr_coulomb" and weak.friction == 35.0
    assert not scene.materials["rock"].deformable
    assert parse_scene(dump_scene(scene)) == scene
    # the zone model takes the material as it is (pdem.deformable.material)
    from pdem.deformable import material

    params, table = material(weak.zone_spec())
    assert params.cohesion == 2.0e6 and type(table).__name__ == "MohrCoulombTable"
    params, _ = material(scene.materials["granite"].zone_spec())
    assert params.model == "elastic" and params.poisson == 0.25


@pytest.mark.parametrize("old, new, expect", [
    ("poisson: 0.25", "poisson: 0.5", "materials.granite.poisson: Input should be less than 0.5"),
    ("poisson: 0.25", "poisson: -1.0", "materials.granite.poisson: Input should be greater than -1"),
    ("young: 40.0e9", "young: -1", "materials.granite.young: Input should be greater than 0"),
    ("model: mohr_coulomb", "model: mohr_colomb", "did you mean 'mohr_coulomb'"),
    ("friction: 35, ", "", "materials.weak: friction: Field required"),
    ("dilation: 5}", "dilation: 40}", "materials.weak: dilation 40.0 exceeds friction 35.0"),
    ("friction: 35", "friction: 95", "materials.weak.friction: Input should be less than 90"),
    ("young: 40.0e9, ", "", "materials.granite: young: needed with poisson"),
    ("young: 40.0e9, poisson: 0.25", "young: 40.0e9", "materials.granite: poisson: needed with young"),
    ("poisson: 0.25}", "poisson: 0.25, cohesion: 1.0}",
     "materials.granite: cohesion: not a parameter of the elastic model"),
    ("material: weak, zones", "material: rock, zones",
     "blocks[1].zones: material 'rock' has no young and poisson"),
    ("zones: {size: 0.5}", "zones: {size: 0}", "blocks[1].zones.size: Input should be greater than 0"),
    ("zones: {size: 0.5}", "zones: {size: 0.5, nmb: false}",
     "blocks[1].zones.nmb: unknown key; did you mean 'nmd'?"),
    ("zones: {size: 0.5}", "zones: {size: 0.5}, velocity_fixed: true, angular_velocity: [0, 0, 1]",
     "blocks[1]: velocity_fixed with angular_velocity: a zoned block's prescribed motion"),
    ("zones: {size: 0.5}", "zones: {}", "blocks[1]: zones.size: Field required"),
])
def test_bad_input_one_line_naming_the_key(old, new, expect):
    assert old in SCENE
    msgs = errors_of(SCENE.replace(old, new))
    assert len(msgs) == 1 and "\n" not in msgs[0], msgs
    assert msgs[0].startswith(expect) or expect in msgs[0], msgs


def test_rigid_scene_dumps_as_before():
    """A scene without zones dumps without the new keys (the text stored in its outputs)."""
    text = dump_scene(parse_scene(SCENE.replace(", zones: {size: 0.5}", "").replace(
        "granite: {density: 2650, young: 40.0e9, poisson: 0.25}", "granite: {density: 2650}").replace(
        "young: 5.0e9, poisson: 0.3, model: mohr_coulomb, cohesion: 2.0e6,\n         friction: 35, "
        "tension: 0.5e6, dilation: 5", "")))
    for key in ("young", "poisson", "zones", "model: null"):
        assert key not in text, key
    assert "zones:\n    size: 0.5" in dump_scene(parse_scene(SCENE))
