"""The package's floors (docs/architecture.md "Layers"): every import of a pdem module points
to the same floor or one below, no modules import each other in a circle, no module imports
another module's private names, and pdem modules are imported inside functions only at the
command-line edge (so ``pdem --help`` does not load numba and h5py).

Read from the source with ``ast``, so a regrown circle fails here before it bites at run time.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "pdem"

# Lowest first. A module belongs to the first floor one of whose prefixes it starts with
# (the most specific prefix wins: see ``floor_of``).
FLOORS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("pdem", "pdem.errors", "pdem.registry", "pdem.strict", "pdem.jit", "pdem.timers",
              "pdem.memory", "pdem.signals", "pdem.mpi")),
    ("kernels", ("pdem.geometry", "pdem.contact", "pdem.dynamics", "pdem.analysis",
                 "pdem.deformable")),
    ("grammar", ("pdem.config",)),
    ("model", ("pdem.model", "pdem.parallel", "pdem.io", "pdem.deformable.store",
               "pdem.deformable.subcontacts", "pdem.deformable.zoning",
               "pdem.deformable.grid_checkpoint",
               "pdem.deformable.columns")),
    ("set-up", ("pdem.resolve", "pdem.preflight")),
    ("run", ("pdem.selection", "pdem.rigid_faces", "pdem.reinforce", "pdem.boundary", "pdem.domain",
             "pdem.insitu",
             "pdem.restart", "pdem.distribute", "pdem.search", "pdem.state", "pdem.cycle",
             "pdem.compiled_runs", "pdem.stepper", "pdem.strength", "pdem.stages", "pdem.plugins",
             "pdem.driver", "pdem.simulation")),
    ("api", ("pdem.api", "pdem.study", "pdem.plot")),
    ("edge", ("pdem.cli", "pdem.warmup", "pdem.cases", "pdem.__main__")),
]
# Modules that may import pdem modules inside functions: the command line loads only what
# the command needs, and the case library and the warm-up import the simulation (which
# initialises MPI through mpi4py and h5py) only when a case is run: bench/scaling.py imports
# the cases in a process that launches mpiexec itself and must not initialise MPI.
LAZY_OK = {"pdem.cli", "pdem.cases", "pdem.warmup"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def floor_of(mod: str) -> int:
    best, level = -1, None
    for k, (_, prefixes) in enumerate(FLOORS):
        for p in prefixes:
            # "pdem" names the package's __init__ only: a module must be on a floor by name
            under = mod.startswith(p + ".") and p != "pdem"
            if (mod == p or under) and len(p) > best:
                best, level = len(p), k
    assert level is not None, f"{mod}: on no floor (add it to FLOORS)"
    return level


def _imports():
    files = {module_name(p): p for p in ROOT.rglob("*.py")}
    out = []  # (module, line, target module, names, inside a function)
    for mod, path in files.items():
        tree = ast.parse(path.read_text(), str(path))
        is_pkg = path.name == "__init__.py"
        inner = {id(x) for f in ast.walk(tree)
                 if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
                 for x in ast.walk(f)}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[:len(base) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                names = [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                target, names = None, []
                for a in node.names:
                    if a.name.split(".")[0] == "pdem":
                        target = a.name
            else:
                continue
            if not target or target.split(".")[0] != "pdem":
                continue
            # ``from pkg import module`` names a module: resolve to it
            for name in names or [None]:
                full = f"{target}.{name}" if name and f"{target}.{name}" in files else target
                while full not in files:
                    full = full.rpartition(".")[0]
                out.append((mod, node.lineno, full, name, id(node) in inner))
    return files, out


FILES, IMPORTS = _imports()


def test_every_module_has_a_floor():
    for mod in FILES:
        floor_of(mod)


def test_imports_point_down():
    up = [f"{m}:{line} imports {t} ({FLOORS[floor_of(t)][0]} above {FLOORS[floor_of(m)][0]})"
          for m, line, t, _, _ in IMPORTS
          if floor_of(t) > floor_of(m) and not m.startswith(t + ".")]
    assert not up, "\n".join(up)


def test_no_circles():
    edges: dict[str, set[str]] = {m: set() for m in FILES}
    for m, _, t, _, _ in IMPORTS:
        # a package's __init__ imported by its own submodule is the package, not a circle
        if t != m and not m.startswith(t + "."):
            edges[m].add(t)
    # Tarjan's strongly connected components
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    circles = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert not circles, circles


def test_no_private_names_of_other_modules():
    bad = [f"{m}:{line} imports {t}.{name}" for m, line, t, name, _ in IMPORTS
           if name and name.startswith("_") and not name.startswith("__") and t != m]
    assert not bad, "\n".join(bad)


def test_function_local_imports_only_at_the_edge():
    local = [f"{m}:{line} imports {t}" for m, line, t, _, inner in IMPORTS
             if inner and m not in LAZY_OK]
    assert not local, f"{len(local)} function-local imports:\n" + "\n".join(local)


@pytest.mark.parametrize("mod", ["pdem.mpi", "pdem.config", "pdem.model.fields"])
def test_floor_table_knows_the_ground(mod):
    # the floor test itself cannot fail silently: these modules are where the docs say
    assert FLOORS[floor_of(mod)][0] in {"base", "grammar", "model"}
