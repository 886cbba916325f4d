"""The base of every validated input model: unknown keys are errors, values finite, frozen."""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, model_validator


class Strict(BaseModel):
    """Base of every scene model: unknown keys are errors, instances are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @model_validator(mode="after")
    def _finite(self):
        # YAML accepts .nan and .inf; no physical input of ours is meant to be either.
        for name, value in self:
            values = value if isinstance(value, tuple) else (value,)
            for v in values:
                if isinstance(v, float) and not math.isfinite(v) and name != "dilation_limit":
                    raise ValueError(f"{name}: must be finite (got {v})")
        return self
