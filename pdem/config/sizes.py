"""Sizes in a scene file: a number of bytes or text such as ``8 GiB`` or ``500MB``."""

from __future__ import annotations

import math

_UNITS = {"b": 1, "kb": 1e3, "mb": 1e6, "gb": 1e9, "tb": 1e12,
          "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40}


def parse_bytes(value) -> float:
    """``limits.max_memory_per_rank``: a number of bytes or text like ``8 GiB``, ``500MB``."""
    if isinstance(value, bool):
        raise ValueError(f"expected a size like '8 GiB' (got {value!r})")
    if isinstance(value, int | float):
        n = float(value)
    else:
        text = str(value).strip().lower().replace(" ", "")
        num = text.rstrip("kmgtib")
        unit = text[len(num):] or "b"
        if unit not in _UNITS:
            raise ValueError(f"unknown unit {unit!r} (use B, kB, MB, GB, TB, KiB, MiB, GiB, TiB)")
        try:
            n = float(num) * _UNITS[unit]
        except ValueError:
            raise ValueError(f"expected a size like '8 GiB' (got {value!r})") from None
    if not (math.isfinite(n) and n > 0):
        raise ValueError(f"must be a finite size > 0 (got {value!r})")
    return n
