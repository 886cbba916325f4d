"""The run log's load line (pdem.plugins.progress.LoadReport): read with every snapshot, logged
when the ranks' load changed since the last line, not once per snapshot."""

from __future__ import annotations

import logging
from types import SimpleNamespace

from pdem.plugins.progress import LoadReport


class FakeState:
    def __init__(self, size: int):
        self.comm = SimpleNamespace(size=size, rank=0)
        self.step = 0
        self.owned = [5, 5]
        self.rebuilds = 0
        self.reads = 0

    def load_report(self):
        self.reads += 1
        return {"owned": list(self.owned), "ghosts": [1, 1], "contacts": [7, 7],
                "halo_bytes": [64, 64], "imbalance": 1.0, "rebuilds": self.rebuilds}


def load_lines(caplog):
    return [r.getMessage() for r in caplog.records if r.getMessage().startswith("load:")]


def test_a_settled_model_prints_one_load_line(caplog):
    s = FakeState(2)
    report = LoadReport(s, every=10)
    with caplog.at_level(logging.INFO, logger="pdem"):
        report.start(None)
        for step in range(10, 110, 10):
            s.step = step
            report.after_step(None)
    assert s.reads == 11  # read (collectively) at every snapshot step
    assert len(load_lines(caplog)) == 1


def test_a_change_of_load_prints_a_new_line(caplog):
    s = FakeState(2)
    report = LoadReport(s, every=10)
    with caplog.at_level(logging.INFO, logger="pdem"):
        report.start(None)
        s.step = 10
        s.owned = [4, 6]  # a block migrated
        report.after_step(None)
        s.step = 20
        report.after_step(None)
        s.step = 30
        s.rebuilds = 1
        report.after_step(None)
    lines = load_lines(caplog)
    assert len(lines) == 3
    assert "owned [4, 6]" in lines[1] and "rebuilds 1" in lines[2]


def test_one_rank_prints_no_load_line(caplog):
    s = FakeState(1)
    report = LoadReport(s, every=10)
    with caplog.at_level(logging.INFO, logger="pdem"):
        report.start(None)
    assert load_lines(caplog) == []
