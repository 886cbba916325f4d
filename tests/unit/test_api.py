"""The Python API (pdem.api, pdem.io.results, pdem.plot; docs/python-api.md): scenes by key
path with located errors, a run on MPI.COMM_SELF read back as arrays that obey the sliding
block's closed form, the reader's units and tables, plots, and every example of
docs/python-api.md run as written."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

import pdem
from pdem.cases.incline import incline_scene, sliding_acceleration
from pdem.cases.staged import slab_fos, slab_fos_scene
from pdem.config import ConfigError
from pdem.errors import UserError

ROOT = Path(__file__).resolve().parents[2]
PDEM = [sys.executable, "-m", "pdem.cli"]


def test_import_pdem_stays_light():
    out = subprocess.run([sys.executable, "-c", "import sys, pdem; print(sorted(m for m in "
                          "('numba', 'h5py', 'mpi4py') if m in sys.modules)); "
                          "print(callable(pdem.run), pdem.open.__module__)"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    first, second = out.stdout.splitlines()
    assert first == "[]"  # nothing heavy until the API is used
    assert second == "True pdem.api"


def test_scenes_by_key_path_and_their_errors(tmp_path):
    s = pdem.Scene.from_file(ROOT / "configs" / "incline.yaml")
    assert s.name == "incline-slide" and s["joints.default.friction"] == 10.0
    t = s.with_({"joints.default.friction": 12.5, "blocks[1].velocity": [0.1, 0, 0]},
                solve__time=0.2, output=str(tmp_path / "x.h5"))
    assert t["joints.default.friction"] == 12.5 and t.model.blocks[1].velocity == (0.1, 0, 0)
    assert t.model.solve.time == 0.2 and t.output_file == str(tmp_path / "x.h5")
    assert s["joints.default.friction"] == 10.0  # unchanged: a scene never changes
    assert t["blocks.slider.velocity"] == [0.1, 0, 0]  # a list entry by its name
    d = pdem.Scene.from_dict(t.data)
    assert d.model == t.model and pdem.Scene.from_yaml(t.to_yaml()).model == t.model
    with pytest.raises(ConfigError, match=r"joints.default.frictoin: unknown key; did you mean "
                                          r"'friction'"):
        s.with_({"joints.default.frictoin": 3.0})
    with pytest.raises(ConfigError, match=r"blocks.rock.fixed: blocks has no entry named "
                                          r"'rock' \(names: base, slider\)"):
        s.with_({"blocks.rock.fixed": True})
    with pytest.raises(ConfigError, match=r"blocks\[1\].material: unknown material 'granite'"):
        s.with_({"blocks[1].material": "granite"})
    with pytest.raises(ConfigError, match=r"blocks\[5\].fixed: blocks has 2 entries, no \[5\]"):
        s.with_({"blocks[5].fixed": True})
    with pytest.raises(ConfigError, match=r"solve.time: .*\(got -1.0\)"):
        s.with_(solve__time=-1.0)
    with pytest.raises(ConfigError, match="not a key path"):
        s.with_({"joints..default": 1})
    with pytest.raises(TypeError, match="pdem.run: a Scene"):
        pdem.run(42, MPI.COMM_SELF)


def test_a_run_read_back_obeys_the_sliding_block_closed_form(tmp_path):
    """The slider of pdem.cases.incline (phi 10 deg on a 20 deg incline, no damping) run for
    0.5 s through pdem.run; its displacement read through pdem.open is a t^2 / 2."""
    phi = 10.0
    scene = pdem.Scene.from_yaml(incline_scene(phi, "fast", "time: 0.5")).with_(
        {"output.every": 0.05, "output.histories": [{"block": "slider",
                                                     "quantity": "velocity"}]},
        output=str(tmp_path / "slide.h5"))
    r = pdem.run(scene, MPI.COMM_SELF)
    a = sliding_acceleration(phi)
    t = r.time
    # every 0.05 s, and the end (0.5 s, to the step after it)
    assert len(t) >= 11 and t[-1] == pytest.approx(0.5, abs=1.01 * r.attrs["dt"])
    assert r.summary["steps"] > 0 and r.blocks.units["displacement"] == "m"
    x = r.blocks["slider"].displacement[:, 0]
    # x = x0 + v0 t + a t^2 / 2 after the first snapshot (the contact's first steps settle the
    # slider onto the incline): its acceleration is the closed form's
    fit = np.polyfit(t[1:], x[1:], 2)
    assert 2 * fit[0] == pytest.approx(a, rel=5e-3), (2 * fit[0], a)
    assert np.abs(np.polyval(fit, t[1:]) - x[1:]).max() < 1e-5
    v = r.histories["slider.velocity"]
    assert v.units == "m/s" and v.columns == ["x", "y", "z"]
    assert v["x"][-1] == pytest.approx(a * v.time[-1], rel=2e-3)
    assert list(r.blocks.name) == ["base", "slider"] and list(r.blocks.fixed) == [True, False]
    c = r.contacts(-1)
    m = 2000.0  # a 1 m cube
    g = 9.81
    assert c.units["normal_force"] == "N" and set(c.joint) == {"default"}
    assert c.normal_force.sum() == pytest.approx(m * g * math.cos(math.radians(20)), rel=1e-3)
    assert set(c.state) == {"slipping"}
    e = r.energy
    assert e.units == "J" and abs(e.last["balance_error"]) < 1e-3 * e.last["gravity_work"]
    assert r.factor_of_safety is None and r.zones is None
    assert list(r.stage) == [""] * len(t)
    frame = r.blocks.to_pandas()
    assert frame.loc["slider", "ux"] == x[-1]
    assert e.to_pandas().index.name == "time"
    r.close()
    with pytest.raises(IndexError, match="out of range"):
        pdem.open(tmp_path / "slide.h5").contacts(len(t))
    with pytest.raises(KeyError, match="no block 'rock'"):
        pdem.open(tmp_path / "slide.h5").blocks["rock"]


def test_a_factor_of_safety_read_back_and_plotted(tmp_path):
    phi = 25.0
    r = pdem.run(pdem.Scene.from_yaml(slab_fos_scene(phi, 0.0, tolerance=0.01)),
                 MPI.COMM_SELF, output=tmp_path / "fos.h5")
    fos = r.factor_of_safety
    assert fos.bounded and fos.stage == "strength"
    assert fos.value == pytest.approx(slab_fos(phi, 0.0), rel=0.012)
    assert fos.trials.shape[1] == 3 and fos.trials[0, 0] == 1.0 and fos.trials[0, 1] == 1.0
    r.close()
    pytest.importorskip("matplotlib")
    for what in ("fos", "energy", None):
        out = subprocess.run([*PDEM, "plot", str(tmp_path / "fos.h5")]
                             + ([f"--what={what}"] if what else []),
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        png = Path(out.stdout.split()[-1])
        assert png.name == f"fos-{what or 'fos'}.png"
        _assert_png(png)
    out = subprocess.run([*PDEM, "plot", str(tmp_path / "fos.h5"), "--what", "history"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 1 and "no histories" in out.stderr
    out = subprocess.run([*PDEM, "plot", str(tmp_path / "fos.h5"), "--what", "stress"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 1 and "'stress' is none of energy, history, fos, study" in out.stderr


def _assert_png(path: Path) -> None:
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 500
    assert img[..., :3].std() > 0.05  # something drawn, not a blank canvas


def test_plots_say_how_to_get_matplotlib_when_it_is_missing(tmp_path, monkeypatch):
    from pdem.plot import plot

    with h5py.File(tmp_path / "x.h5", "w") as f:
        f.attrs["pdem_format"] = "output"
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib fails
    with pytest.raises(UserError, match="plots need matplotlib.*pip install matplotlib"):
        plot(tmp_path / "x.h5", what="energy")


def test_the_reader_refuses_what_is_not_a_pdem_output(tmp_path):
    with pytest.raises(FileNotFoundError):
        pdem.open(tmp_path / "none.h5")
    (tmp_path / "text.h5").write_text("hello")
    with pytest.raises(ValueError, match="not an HDF5 file"):
        pdem.open(tmp_path / "text.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(ValueError, match="not a pdem output file"):
        pdem.open(tmp_path / "other.h5")


def test_the_examples_of_the_python_api_page_run_as_written(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    text = (ROOT / "docs" / "python-api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 4
    shutil.copytree(ROOT / "configs", tmp_path / "configs")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for code in blocks:
        exec(compile(code, "docs/python-api.md", "exec"), namespace)  # noqa: S102
    assert (tmp_path / "incline-15-energy.png").exists() and (tmp_path / "friction.h5").exists()
    assert namespace["table"].done.all()
