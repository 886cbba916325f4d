"""A study's cases: the grid of its ``values`` parameters times ``samples`` draws of its
distributions, each case a set of overrides of the base scene (pdem.config.overrides).

The draws depend only on the study (its seed, sampling and parameters), never on the rank
count or the order cases finish in: case ``g * samples + s`` is grid point ``g`` with draw
``s``, and draw ``s`` is the same at every grid point (common random numbers: the grid's
values are compared on the same samples).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..analysis.sampling import Fisher, LogNormal, Normal, Truncated, Uniform, uniforms
from ..config import ConfigError
from ..config.overrides import get_path

__all__ = ["Case", "Plan", "plan_cases"]


@dataclass(frozen=True)
class Case:
    """One case: its ``index``, the table's parameter ``values`` (column -> value) and the
    scene ``overrides`` (key path -> value) they make."""

    index: int
    values: dict[str, Any]
    overrides: dict[str, Any]


@dataclass(frozen=True)
class Plan:
    columns: list[str]          # the parameter columns of the table, in order
    cases: list[Case]
    described: dict[str, str]   # parameter -> its distribution, for the summary


def _distribution(name: str, p, base: dict):
    """The sampling distribution of parameter ``p`` (a ValueError names the parameter)."""
    where = f"parameters.{name}"
    try:
        if p.kind == "normal":
            d = Normal(p.normal.mean, p.normal.std)
        elif p.kind == "lognormal":
            d = LogNormal(p.lognormal.mean, p.lognormal.std)
        elif p.kind == "uniform":
            return Uniform(p.uniform.low, p.uniform.high)
        else:  # fisher: about the given mean plane, or the scene's own orientation
            at = p.paths(name)[0]
            dip = p.fisher.dip if p.fisher.dip is not None else get_path(base, f"{at}.dip")
            dd = p.fisher.dip_direction if p.fisher.dip_direction is not None \
                else get_path(base, f"{at}.dip_direction")
            return Fisher(float(dip), float(dd), p.fisher.kappa)
        if p.low is not None or p.high is not None:
            d = Truncated(d, p.low, p.high)
        return d
    except (ValueError, TypeError) as exc:
        raise ConfigError([f"{where}: {exc}"]) from None


def plan_cases(study, base: dict) -> Plan:
    """The cases of ``study`` (a validated :class:`pdem.config.study.Study`) on the base scene
    mapping ``base``."""
    grid = {k: p for k, p in study.parameters.items() if p.kind == "values"}
    drawn = {k: _distribution(k, p, base) for k, p in study.parameters.items()
             if p.kind != "values"}
    n = study.samples
    dims = sum(d.dims for d in drawn.values())
    u = uniforms(n, dims, study.seed, latin=study.sampling == "latin_hypercube") if dims \
        else np.zeros((n, 0))
    samples: dict[str, np.ndarray] = {}
    col = 0
    for k, d in drawn.items():
        samples[k] = d.from_uniform(u[:, col:col + d.dims])
        col += d.dims
    columns: list[str] = []
    for k, p in study.parameters.items():
        columns += [f"{k}.dip", f"{k}.dip_direction"] if p.kind == "fisher" else [k]
    cases = []
    points = list(itertools.product(*(p.values for p in grid.values()))) if grid else [()]
    for g, point in enumerate(points):
        chosen = dict(zip(grid, point, strict=True))
        for s in range(n):
            values: dict[str, Any] = {}
            overrides: dict[str, Any] = {}
            for k, p in study.parameters.items():
                paths = p.paths(k)
                if p.kind == "values":
                    v = chosen[k]
                    values[k] = v
                elif p.kind == "fisher":
                    dip, dd = (float(x) for x in samples[k][s])
                    values[f"{k}.dip"], values[f"{k}.dip_direction"] = dip, dd
                    overrides[f"{paths[0]}.dip"], overrides[f"{paths[0]}.dip_direction"] = dip, dd
                    continue
                else:
                    v = float(samples[k][s])
                    values[k] = v
                for path in paths:
                    overrides[path] = v
            cases.append(Case(g * n + s, values, overrides))
    described = {k: (f"grid of {len(p.values)} values" if p.kind == "values"
                     else drawn[k].describe()) for k, p in study.parameters.items()}
    return Plan(columns, cases, described)
