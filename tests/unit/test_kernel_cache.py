"""The kernel cache (pdem.jit): keyed on the sources' content, not on where they are checked
out; never stale after an edit; one process per node compiles a kernel, the others load it."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pdem.jit

# compiles one small kernel and prints which kernels this process compiled (numba's compile
# events fire only for a compile, not for a load from the cache)
PROBE = """
import numpy as np
import numba.core.event as ev
compiled = []
class Seen(ev.Listener):
    def on_start(self, event):
        compiled.append(event.data["dispatcher"].py_func.__name__)
    def on_end(self, event):
        pass
ev.register("numba:compile", Seen())
import pdem.jit
from pdem.dynamics.kinematics import rotation_matrices
R = np.zeros((3, 3, 3))
rotation_matrices(np.tile([1.0, 0.0, 0.0, 0.0], (3, 1)), R)
assert (R[:, 0, 0] == 1.0).all()
print("COMPILED", ",".join(compiled), "DIR", pdem.jit.CACHE_DIR)
"""


def checkout(tmp_path: Path, name: str) -> Path:
    """A copy of the package at another path (new modification times, same content)."""
    root = tmp_path / name
    shutil.copytree(pdem.jit.ROOT, root / "pdem",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return root


def probe(root: Path, cache: Path, wait: bool = True):
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.Popen([sys.executable, "-c", PROBE], env=env, cwd=root,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return finish(proc) if wait else proc


def finish(proc) -> tuple[list[str], str]:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err[-2000:]
    line = next(ln for ln in out.splitlines() if ln.startswith("COMPILED"))
    _, names, _, where = line.split(" ")
    return [n for n in names.split(",") if n], where


def test_a_fresh_checkout_of_the_same_sources_loads_the_compiled_kernels(tmp_path):
    cache = tmp_path / "cache"
    first, where_a = probe(checkout(tmp_path, "a"), cache)
    again, where_b = probe(checkout(tmp_path, "b"), cache)
    assert "rotation_matrices" in first
    assert again == [] and where_a == where_b


def test_an_edit_anywhere_in_the_package_compiles_afresh(tmp_path):
    a, b = checkout(tmp_path, "a"), checkout(tmp_path, "b")
    # an edit in a file the probed kernel does not live in: its callees might
    with open(b / "pdem" / "geometry" / "polyhedron.py", "a") as f:
        f.write("\n# an edit\n")
    assert pdem.jit.source_key(a / "pdem") != pdem.jit.source_key(b / "pdem")
    cache = tmp_path / "cache"
    probe(a, cache)
    again, _ = probe(b, cache)
    assert "rotation_matrices" in again


def test_processes_started_together_compile_a_kernel_once(tmp_path):
    root, cache = checkout(tmp_path, "a"), tmp_path / "cache"
    procs = [probe(root, cache, wait=False) for _ in range(3)]
    compiled = [finish(p)[0] for p in procs]
    assert sum("rotation_matrices" in c for c in compiled) == 1, compiled
