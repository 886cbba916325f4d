"""Per-phase wall-clock timers (search, contacts, forces, motion, halo, I/O)."""

from __future__ import annotations

import time
from contextlib import contextmanager


class Timers:
    def __init__(self):
        self.total: dict[str, float] = {}

    @contextmanager
    def phase(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.total[name] = self.total.get(name, 0.0) + time.perf_counter() - t0

    def reset(self) -> dict[str, float]:
        old, self.total = self.total, {}
        return old

    def report(self) -> str:
        whole = sum(self.total.values()) or 1.0
        return "  ".join(f"{k} {v:.2f}s ({100 * v / whole:.0f}%)"
                         for k, v in sorted(self.total.items(), key=lambda kv: -kv[1]))
