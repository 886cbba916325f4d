"""``pdem warmup``: runs the scenes it is given into a temporary folder, once per cache."""

from __future__ import annotations

import tempfile

from pdem import warmup
from pdem.cli import main


def test_warmup_runs_each_scene_once_per_cache_and_leaves_no_files(tmp_path, monkeypatch,
                                                                    capsys):
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    scene = tmp_path / "two.yaml"
    scene.write_text(warmup.builtin_scenes()[0][1])
    stamp = warmup.stamp_path([scene.read_text()], 3, 1)
    stamp.unlink(missing_ok=True)  # (a stamp of an earlier test run in the same cache)
    try:
        assert main(["warmup", "--once", "--steps", "3", str(scene)]) == 0
        assert stamp.exists()
        assert list(scratch.iterdir()) == []  # its output folder is gone
        assert "warmed for two on 1 rank(s)" in capsys.readouterr().out
        assert main(["warmup", "--once", "--steps", "3", str(scene)]) == 0
        assert "already warm for two" in capsys.readouterr().out
        # another step count (or scene text, or rank count) is another stamp
        assert warmup.stamp_path([scene.read_text()], 4, 1) != stamp
    finally:
        stamp.unlink(missing_ok=True)


def test_warmup_of_a_missing_scene_says_which(tmp_path, capsys):
    assert main(["warmup", str(tmp_path / "nope.yaml")]) == 1
    assert "nope.yaml" in capsys.readouterr().err
