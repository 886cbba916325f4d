"""The scalars a study measures on each case's results (``outputs:``, pdem.config.study)."""

from __future__ import annotations

import math

import numpy as np

from ..errors import UserError
from ..io.results import Results

__all__ = ["measure"]

_AXIS = {"x": 0, "y": 1, "z": 2}


def _one(r: Results, name: str, out) -> float:
    kind = out.kind
    if kind == "factor_of_safety":
        fos = r.factor_of_safety
        if fos is None:
            raise UserError(f"outputs.{name}: the case made no factor-of-safety search (give "
                            "the scene a stage with factor_of_safety:)")
        return fos.value
    if kind == "displacement":
        try:
            d = r.blocks[out.displacement].displacement[-1]
        except KeyError as exc:
            raise UserError(f"outputs.{name}.displacement: {exc.args[0]}") from None
        return float(np.linalg.norm(d)) if out.component == "magnitude" \
            else float(d[_AXIS[out.component]])
    if kind == "slip":
        try:
            c = r.contacts(-1)
        except KeyError as exc:
            raise UserError(f"outputs.{name}.slip: {exc.args[0]}") from None
        names = [str(x) for x in r.attrs.get("joint_names", [])]
        if out.slip not in names:
            raise UserError(f"outputs.{name}.slip: no joint {out.slip!r} (joints: "
                            f"{', '.join(names)})")
        u = c.shear_displacement[c.joint == out.slip] if len(c) else np.zeros(0)
        if not len(u):
            return 0.0
        return float(u.max() if out.stat == "max" else u.mean())
    if kind == "energy":
        row = r.energy.last
        if out.energy not in r.energy.columns:
            raise UserError(f"outputs.{name}.energy: no column {out.energy!r} (columns: "
                            f"{', '.join(r.energy.columns)})")
        return row.get(out.energy, math.nan)
    h = r.histories.get(out.history)
    if h is None:
        raise UserError(f"outputs.{name}.history: no history {out.history!r} (histories: "
                        f"{', '.join(r.histories)})")
    if not len(h.time):
        return math.nan
    column = out.column if out.column is not None else h.columns[0]
    try:
        return float(h[column][-1])
    except KeyError as exc:
        raise UserError(f"outputs.{name}.column: {exc.args[0]}") from None


def measure(r: Results, outputs: dict) -> dict[str, float]:
    """Each named output of the results ``r``."""
    return {name: _one(r, name, out) for name, out in outputs.items()}
