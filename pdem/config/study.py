"""The grammar of a study (docs/studies.md): a scene run many times with some of its values
varied over a grid or sampled from distributions, each case measured by named outputs.

It is written as ``studies: {NAME: {...}}`` in a scene file, or as a study file of its own
that names its scene (``scene: slope.yaml``); both are validated here, once, at the edge.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, PositiveFloat, PositiveInt, model_validator

from ..strict import Strict

__all__ = ["DISTRIBUTIONS", "Failure", "Parameter", "StudyOutput", "Study", "StudyFile"]

DISTRIBUTIONS = ("normal", "lognormal", "uniform", "fisher", "values")


class MeanStd(Strict):
    """A distribution given by the variable's own mean and standard deviation."""

    mean: float
    std: PositiveFloat


class Range(Strict):
    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self):
        if not self.high > self.low:
            raise ValueError(f"high ({self.high:g}) must be above low ({self.low:g})")
        return self


class FisherSpec(Strict):
    """Fisher scatter of a joint set's pole about its mean orientation: ``kappa`` (the
    concentration; about 81 / kappa^0.5 degrees holds 63 % of the poles), and the mean plane
    (degrees; default: the dip and dip_direction the scene gives at ``at``)."""

    kappa: PositiveFloat
    dip: Annotated[float, Field(ge=0.0, le=90.0)] | None = None
    dip_direction: float | None = None


class Parameter(Strict):
    """One varied value: where it goes (``at``: a key path, or several that take the same
    value; default: the parameter's own name is the path) and exactly one of ``normal``,
    ``lognormal`` (the variable's mean and std), ``uniform`` (low, high), ``fisher`` (a joint
    set's orientation: ``at`` names the mapping that holds its ``dip`` and ``dip_direction``)
    or ``values`` (a grid: every case runs each). ``low``/``high`` truncate a normal or
    lognormal distribution."""

    at: str | list[str] | None = None
    normal: MeanStd | None = None
    lognormal: MeanStd | None = None
    uniform: Range | None = None
    fisher: FisherSpec | None = None
    values: Annotated[list[Any], Field(min_length=1)] | None = None
    low: float | None = None
    high: float | None = None

    @model_validator(mode="after")
    def _one(self):
        given = [k for k in DISTRIBUTIONS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of {', '.join(DISTRIBUTIONS)} (got "
                             f"{', '.join(given) or 'none'})")
        if (self.low is not None or self.high is not None) and given[0] not in ("normal",
                                                                               "lognormal"):
            raise ValueError(f"low/high truncate a normal or lognormal distribution, not "
                             f"{given[0]}")
        if self.low is not None and self.high is not None and not self.high > self.low:
            raise ValueError(f"high ({self.high:g}) must be above low ({self.low:g})")
        if self.lognormal is not None and self.lognormal.mean <= 0:
            raise ValueError(f"lognormal.mean must be positive (got {self.lognormal.mean:g})")
        if self.fisher is not None and isinstance(self.at, list):
            raise ValueError("fisher: at names one joint set (the mapping with dip and "
                             "dip_direction)")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in DISTRIBUTIONS if getattr(self, k) is not None)

    def paths(self, name: str) -> list[str]:
        return [name] if self.at is None else [self.at] if isinstance(self.at, str) \
            else list(self.at)


class StudyOutput(Strict):
    """A scalar measured on each case's results (exactly one): ``factor_of_safety: true`` (a
    strength-reduction stage's result); ``displacement: BLOCK`` (its ``component``: magnitude,
    x, y or z, at the last snapshot); ``slip: JOINT`` (the ``stat``, max or mean, of the shear
    displacement of that joint's contacts at the last snapshot); ``energy: COLUMN`` (the
    energy budget's last row); ``history: NAME`` (its ``column``'s last value)."""

    factor_of_safety: Literal[True] | None = None
    displacement: str | None = None
    component: Literal["magnitude", "x", "y", "z"] = "magnitude"
    slip: str | None = None
    stat: Literal["max", "mean"] = "max"
    energy: str | None = None
    history: str | None = None
    column: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _shorthand(cls, data):
        return {"factor_of_safety": True} if data == "factor_of_safety" else data

    @model_validator(mode="after")
    def _one(self):
        kinds = ("factor_of_safety", "displacement", "slip", "energy", "history")
        given = [k for k in kinds if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of {', '.join(kinds)} (got "
                             f"{', '.join(given) or 'none'})")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("factor_of_safety", "displacement", "slip", "energy", "history")
                    if getattr(self, k) is not None)


class Failure(Strict):
    """A case fails when its ``output`` is below ``below`` (default 1: FS < 1) or above
    ``above``."""

    output: str
    below: float | None = None
    above: float | None = None

    @model_validator(mode="before")
    @classmethod
    def _below_one(cls, data):
        if isinstance(data, dict) and data.get("below") is None and data.get("above") is None:
            return {**data, "below": 1.0}
        return data

    @model_validator(mode="after")
    def _one(self):
        if self.below is not None and self.above is not None:
            raise ValueError("give one of below, above")
        return self


class Study(Strict):
    """A study of a scene (docs/studies.md): ``samples`` cases drawn (``sampling``:
    monte_carlo, or latin_hypercube) with ``seed`` for the sampled ``parameters``, for each
    point of the grid of the ``values`` ones; each case run on ``ranks_per_case`` ranks and
    measured by ``outputs``; ``failure`` names the output whose probability of failure the
    summary gives (with its ``confidence`` interval). ``file``: the study file (default
    ``<name>.h5`` beside the scene); ``keep_outputs``: keep each case's output file."""

    samples: PositiveInt = 1
    sampling: Literal["monte_carlo", "latin_hypercube"] = "monte_carlo"
    seed: Annotated[int, Field(ge=0)] = 0
    ranks_per_case: PositiveInt = 1
    parameters: Annotated[dict[str, Parameter], Field(min_length=1)]
    outputs: Annotated[dict[str, StudyOutput], Field(min_length=1)]
    failure: Failure | None = None
    confidence: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.95
    file: str | None = None
    keep_outputs: bool = False

    @model_validator(mode="before")
    @classmethod
    def _fos_fails_below_one(cls, data):
        """Without ``failure``, a factor-of-safety output's P(FS < 1) is the one summarised."""
        if isinstance(data, dict) and data.get("failure") is None and \
                isinstance(data.get("outputs"), dict):
            for name, out in data["outputs"].items():
                if out == "factor_of_safety" or (isinstance(out, dict) and
                                                 out.get("factor_of_safety") is True):
                    return {**data, "failure": {"output": name}}
        return data

    @model_validator(mode="after")
    def _failure_output(self):
        if self.failure is not None and self.failure.output not in self.outputs:
            raise ValueError(f"failure.output: no output {self.failure.output!r} (outputs: "
                             f"{', '.join(self.outputs)})")
        return self


class StudyFile(Study):
    """A study file of its own: the study, its ``name`` and the ``scene`` file it varies
    (relative to the study file)."""

    name: str
    scene: str
