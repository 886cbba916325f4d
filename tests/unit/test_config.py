"""Scene-file validation: good scenes resolve with defaults, bad ones name key and line."""

from pathlib import Path

import numpy as np
import pytest

from pdem.config import ConfigError, dump_scene, load_scene, parse_scene

ROOT = Path(__file__).resolve().parents[2]

GOOD = """
name: t
materials: {rock: {density: 2000.0}}
joints: {default: {kn: 1.0e9, ks: 1.0e9}}
blocks:
  - {name: base, box: {min: [-1, -1, -1], max: [1, 1, 0]}, material: rock, fixed: true}
  - {name: cube, box: {min: [0, 0, 0], max: [1, 1, 1]}, material: rock}
solve: {steps: 10}
"""


def errors_of(text):
    with pytest.raises(ConfigError) as info:
        parse_scene(text, "s.yaml")
    return info.value.messages


def test_defaults_filled_and_round_trip():
    scene = parse_scene(GOOD)
    assert scene.gravity == (0.0, 0.0, -9.81)
    assert scene.joints["default"].friction == 30.0
    assert scene.solve.damping.mode == "none"
    assert scene.contact.detect_every == 10
    again = parse_scene(dump_scene(scene))
    assert again == scene


@pytest.mark.parametrize("path", sorted((ROOT / "configs").glob("*.yaml")), ids=lambda p: p.name)
def test_shipped_configs_validate(path):
    scene = load_scene(path)
    # the blocks they make too (cuts, joins, excavations): every block a sound size
    from pdem.model.build import expand_blocks

    vol = np.array([s.volume for s in expand_blocks(scene)])
    assert vol.min() > 0.01 * np.median(vol)


def test_unknown_key_suggests_and_gives_line():
    msgs = errors_of(GOOD.replace("fixed: true", "fixd: true"))
    assert msgs == ["blocks[0].fixd: unknown key; did you mean 'fixed'?  [line 6]"]


def test_negative_density_names_key_and_value():
    (msg,) = errors_of(GOOD.replace("density: 2000.0", "density: -2600"))
    assert msg.startswith("materials.rock.density:") and "-2600" in msg and "[line 3]" in msg


def test_wrong_type():
    (msg,) = errors_of(GOOD.replace("steps: 10", "steps: many"))
    assert msg.startswith("solve.steps:") and "'many'" in msg


def test_unknown_material_and_duplicate_name():
    text = GOOD.replace("material: rock}\nsolve", "material: granite}\nsolve").replace(
        "name: cube", "name: base")
    # one list item each (they shared one, the second without its "  - ")
    assert errors_of(text) == ["blocks[1].material: unknown material 'granite' (defined: rock)",
                               "blocks[1].name: 'base' already names blocks[0]"]


def test_one_shape_and_one_end_condition():
    msgs = errors_of(GOOD.replace("box: {min: [0, 0, 0]", "polyhedron: {vertices: [[0,0,0]]}, "
                                  "box: {min: [0, 0, 0]").replace("steps: 10", "steps: 10, time: 1"))
    text = "\n".join(msgs)
    assert "blocks[1]" in text and "exactly one shape" in text or "vertices" in text
    assert "give exactly one of time, steps, ratio" in text


def test_missing_file_and_not_a_mapping(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_scene(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="mapping"):
        parse_scene("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_scene("a: [1,\n")


def test_joint_pairs_reference_checks():
    text = GOOD + "joint_pairs: [{groups: [default, nope], joint: weak}]\n"
    msgs = errors_of(text)
    assert msgs[0] == "joint_pairs[0].joint: unknown joint 'weak'"
    assert msgs[1].startswith("joint_pairs[0].groups: no block has group 'nope'")


def test_mass_scaling_flag_or_partial_mapping():
    """``solve.mass_scaling``: true/false as before, or ``{timestep: DT}`` (partial scaling),
    also per stage; it survives the dump a checkpoint stores; bad values name the key."""
    from pdem.config.schema import MassScaling

    assert parse_scene(GOOD).solve.mass_scaling is False
    assert parse_scene(GOOD.replace("steps: 10", "steps: 10, mass_scaling: true")
                       ).solve.mass_scaling is True
    scene = parse_scene(GOOD.replace("steps: 10", "steps: 10, mass_scaling: {timestep: 1.0e-4}"))
    assert scene.solve.mass_scaling == MassScaling(timestep=1.0e-4)
    assert parse_scene(dump_scene(scene)) == scene
    staged = GOOD.replace("solve: {steps: 10}", "solve: {}\nstages:\n  - name: a\n    solve: "
                          "{steps: 10, mass_scaling: {timestep: 2.0e-4}}")
    assert parse_scene(staged).stages[0].solve.mass_scaling == MassScaling(timestep=2.0e-4)
    for bad in ("-1.0e-4", "0"):
        (msg,) = errors_of(GOOD.replace("steps: 10", f"steps: 10, mass_scaling: {{timestep: {bad}}}"))
        assert msg.startswith("solve.mass_scaling.timestep: Input should be greater than 0"), msg
        (msg,) = errors_of(staged.replace("2.0e-4", bad))
        assert msg.startswith("stages[0].solve.mass_scaling.timestep: Input should be greater"), msg
    msgs = errors_of(GOOD.replace("steps: 10", "steps: 10, mass_scaling: {dt: 1.0e-4}"))
    assert msgs[0].startswith("solve.mass_scaling.timestep: Field required"), msgs
    assert msgs[1].startswith("solve.mass_scaling.dt: unknown key"), msgs
    (msg,) = errors_of(GOOD.replace("steps: 10", "steps: 10, mass_scaling: 3.0"))
    assert msg.startswith("solve.mass_scaling: Input should be a valid boolean"), msg
    (msg,) = errors_of(GOOD.replace(
        "steps: 10", "steps: 10, timestep: {dt: 1.0e-5}, mass_scaling: {timestep: 1.0e-4}"))
    assert msg.startswith("solve: give timestep.dt or mass_scaling.timestep, not both"), msg


@pytest.mark.parametrize("value", ["true", "3", "box", "{a: 1}"])
def test_blocks_not_a_list_is_one_message(value, tmp_path):
    """``blocks:`` given as a scalar or a mapping (a fuzzed scene found ``blocks: true`` raising
    a TypeError while mesh file names were anchored): the scene is refused with one message
    naming the key, through the file loader that anchors relative mesh names."""
    path = tmp_path / "scene.yaml"
    path.write_text("name: s\nmaterials: {rock: {density: 2600}}\n"
                    "joints: {default: {kn: 1.0e9, ks: 1.0e9}}\n"
                    f"blocks: {value}\nsolve: {{steps: 1}}\n")
    with pytest.raises(ConfigError) as e:
        load_scene(path)
    assert "blocks: Input should be a valid list" in str(e.value)
