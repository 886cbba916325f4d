"""Scene loading: YAML text -> validated ``Scene``, with errors naming key path and line."""

from __future__ import annotations

import difflib
import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from ..contact.laws import JOINT_LAWS
from .errors import ConfigError
from .schema import Scene


def line_index(text: str) -> dict[tuple, int]:
    """Map each key path (tuple of keys/indices) to the 1-based YAML line it starts on."""
    lines: dict[tuple, int] = {}
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return lines

    def walk(node, path):
        lines.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = k.value
                lines[(*path, key)] = k.start_mark.line + 1
                walk(v, (*path, key))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                walk(v, (*path, i))

    if root is not None:
        walk(root, ())
    return lines


def _format_path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The pydantic model class that owns the mapping at ``loc`` (for did-you-mean)."""
    model: Any = Scene
    for part in loc:
        if isinstance(part, int) or model is None:
            continue
        field = model.model_fields.get(part) if hasattr(model, "model_fields") else None
        if field is None:
            return None
        model = _unwrap(field.annotation)
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _unwrap(annotation):
    """First BaseModel class inside Optional[...], list[...], dict[str, ...]."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _unwrap(arg)
        if found is not None:
            return found
    return None


def _law_tag(loc: tuple) -> str | None:
    """The joint-law tag pydantic puts after ``joints.NAME`` (the discriminated union of the
    registered laws' parameters), or None."""
    if len(loc) > 2 and loc[0] == "joints" and loc[2] in JOINT_LAWS:
        return str(loc[2])
    return None


def _clean_loc(loc: tuple) -> tuple:
    # pydantic inserts union-member tags ('float', "literal['auto']", 'function-before[...]',
    # the joint law's name under joints.NAME) into locations; users never wrote them.
    if _law_tag(loc) is not None:
        loc = loc[:2] + loc[3:]
    return tuple(
        p for p in loc if isinstance(p, int) or not any(c in str(p) for c in "[]'(")
    )


def _messages(err: ValidationError, lines: dict[tuple, int]) -> list[str]:
    out: list[str] = []
    seen: set[str] = set()
    for e in err.errors():
        tag = _law_tag(tuple(e["loc"]))
        loc = _clean_loc(tuple(e["loc"]))
        where = _format_path(loc)
        line = lines.get(loc) or lines.get(loc[:-1]) if loc else None
        if e["type"] == "extra_forbidden":
            if tag is not None and len(loc) == 3:
                model = JOINT_LAWS[tag].params
            else:
                model = _model_at(loc[:-1])
            hint = ""
            if model is not None:
                close = difflib.get_close_matches(str(loc[-1]), list(model.model_fields), n=1)
                if close:
                    hint = f"; did you mean {close[0]!r}?"
                else:
                    hint = "; allowed: " + ", ".join(model.model_fields)
            msg = f"{where}: unknown key{hint}"
        else:
            text = e["msg"]
            if text.startswith("Value error, "):
                text = text[len("Value error, ") :]
            got = e.get("input")
            shown = "" if isinstance(got, dict | list) or e["type"] == "missing" else f" (got {got!r})"
            if not loc and _OWN_PATH.match(text):
                # a whole-scene check (Scene._references) names its keys itself, one a line;
                # found by the fuzz: its second and later lines lost the "  - " of the list
                for part in text.split("\n"):
                    if part not in seen:
                        seen.add(part)
                        out.append(part)
                continue
            msg = f"{where}: {text}{shown}" if "\n" not in text else text
        if line and "\n" not in msg:
            msg += f"  [line {line}]"
        if msg not in seen:
            seen.add(msg)
            out.append(msg)
    return out


# "blocks[1].name: ..." -- a message that starts with its own key path
_OWN_PATH = re.compile(r"^[A-Za-z_][\w\[\]\.-]*: ")


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """PyYAML's message on one line, with the line it points at (its own text spans several)."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc)
    where = f"  [line {mark.line + 1}, column {mark.column + 1}]" if mark is not None else ""
    return " ".join(str(problem).split()) + where


def _anchor(holder, base: Path) -> None:
    """``holder['file']`` (a relative name) made absolute from ``base``."""
    if isinstance(holder, dict) and isinstance(holder.get("file"), str):
        f = Path(holder["file"])
        if not f.is_absolute():
            holder["file"] = str((base / f).resolve())


def _anchor_conditions(conditions, base: Path) -> None:
    """The history files of a ``boundary:`` mapping or a stage: ``velocity[].history.file``
    and ``stress[].wave.file`` (a stress wave input takes the same history model)."""
    if not isinstance(conditions, dict):  # not a mapping: validation names the key
        return
    for kind, key in (("velocity", "history"), ("stress", "wave")):
        entries = conditions.get(kind)
        for c in entries if isinstance(entries, list) else ():
            if isinstance(c, dict):
                _anchor(c.get(key), base)


def _anchor_files(data: dict, base: Path) -> None:
    """Files named relative to the scene file (mesh files, history files) are read from
    beside it (made absolute, so the scene stored in outputs and checkpoints still finds
    them)."""
    blocks = data.get("blocks")
    for b in blocks if isinstance(blocks, list) else ():  # not a list: validation names it
        if isinstance(b, dict):
            _anchor(b.get("mesh"), base)
    _anchor_conditions(data.get("boundary"), base)
    stages = data.get("stages")
    for st in stages if isinstance(stages, list) else ():
        _anchor_conditions(st, base)


def scene_data(text: str, source: str = "scene", base: Path | None = None) -> dict:
    """Scene YAML ``text`` as a mapping, its relative file names made absolute from ``base``
    (not validated: :func:`validate_scene`)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError([f"not valid YAML: {_yaml_problem(exc)}"], source) from None
    if not isinstance(data, dict):
        raise ConfigError(["the scene must be a mapping of keys (name, blocks, solve, ...)"], source)
    if base is not None:
        _anchor_files(data, base)
    return data


def validate_scene(data: dict, source: str = "scene", lines: dict | None = None) -> Scene:
    """The scene mapping ``data`` validated; ``ConfigError`` with every problem's key path (and
    its YAML line, from ``lines``: :func:`parse_scene`)."""
    if not isinstance(data, dict):
        raise ConfigError(["the scene must be a mapping of keys (name, blocks, solve, ...)"], source)
    lines = lines or {}
    try:
        scene = Scene.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_messages(exc, lines), source) from None
    scene._lines = lines  # so that errors found while building name the YAML line too
    return scene


def parse_scene(text: str, source: str = "scene", base: Path | None = None) -> Scene:
    """Validate scene YAML ``text``; raise ``ConfigError`` with readable messages. ``base``:
    the directory relative file names in the scene start from."""
    return validate_scene(scene_data(text, source, base), source, line_index(text))


def read_scene_text(path: Path) -> str:
    """The text of the scene file ``path``; a ConfigError naming it if it cannot be read."""
    try:
        return path.read_text()
    except OSError as exc:
        raise ConfigError([f"cannot read: {exc.strerror}"], str(path)) from None
    except UnicodeDecodeError as exc:
        # found by the fuzz: a binary file gave a traceback
        raise ConfigError([f"not a text file (byte {exc.start} is not UTF-8)"], str(path)) from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate the scene file at ``path``."""
    path = Path(path)
    return parse_scene(read_scene_text(path), str(path), path.parent)


def dump_scene(scene: Scene) -> str:
    """The resolved scene (every default filled in) as YAML, stored in outputs/checkpoints."""
    return yaml.safe_dump(scene.model_dump(mode="json", by_alias=True), sort_keys=False)
