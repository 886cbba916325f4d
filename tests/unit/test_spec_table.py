"""After set-up the specs are columns (pdem.model.build.SpecTable): each view reads as the
released spec it came from, and a run keeps no shapes in them."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from pdem.cases.rock_mass import l_on_stack_scene
from pdem.config import parse_scene
from pdem.model.build import SpecTable, expand_blocks
from pdem.simulation import Simulation

FIELDS = ("name", "entry", "parent", "group", "material", "volume", "surface", "n_pieces",
          "excavate_at", "excavate_stage")


def test_views_read_as_the_released_specs():
    """The L block (two pieces, joined) on a cut stack with a block excavated at a time."""
    scene = parse_scene(l_on_stack_scene())
    specs = expand_blocks(scene, 10**6)
    for sp in specs:
        sp.release()
    table = SpecTable(specs, scene.blocks)
    assert len(table) == len(specs)
    assert any(sp.n_pieces == 2 for sp in specs) and any(sp.excavate_at for sp in specs)
    for g, (view, sp) in enumerate(zip(table, specs, strict=True)):
        for k in FIELDS:
            assert getattr(view, k) == getattr(sp, k), (g, k)
        assert view.spec is sp.spec and table[g].pieces is None


def test_a_run_keeps_names_not_shapes():
    """A simulation's specs after set-up are the table; a released spec's shapes are gone and
    asking a released spec for them says so (not a silent empty list)."""
    sim = Simulation(parse_scene(l_on_stack_scene()), MPI.COMM_SELF, output=False)
    assert isinstance(sim.specs, SpecTable)
    assert not sim.state.glob.has_geometry
    assert sim.specs[0].name and sim.specs[0].pieces is None
    spec = expand_blocks(parse_scene(l_on_stack_scene()), 10**6)[0]
    spec.release()
    with pytest.raises(ValueError):
        spec.shape  # noqa: B018


def test_string_column_reads_back_every_string():
    """Names are one UTF-8 buffer with offsets: each reads back as given (empty, non-ASCII,
    negative index), iteration and positions agree, out-of-range is an IndexError."""
    from pdem.model.strings import StringColumn

    texts = ["stack_0_0_0", "", "Blöck ∆", "b[1]", "stack_0_0_0"]
    col = StringColumn(texts)
    assert len(col) == 5 and list(col) == texts
    assert [col[i] for i in range(5)] == texts and col[-3] == "Blöck ∆"
    assert col.lengths().tolist() == [11, 0, 10, 4, 11] and col.max_bytes == 11
    assert col.positions(["stack_0_0_0", "b[1]", "absent"]) == {"stack_0_0_0": 0, "b[1]": 3}
    assert col == StringColumn(texts) and col == texts and col != texts[:4]
    assert col != StringColumn(texts[::-1])
    with pytest.raises(IndexError):
        col[5]  # noqa: B018
    assert len(StringColumn([])) == 0 and StringColumn([]).max_bytes == 0


def test_an_array_keeps_a_few_bytes_not_a_few_a_block():
    """64,000 array blocks on a floor: the names are runs of ``cube[k]`` and every column a
    run per entry, so the whole table keeps under a kilobyte (it was ~62 bytes a block: the
    names' bytes and offsets, 44 bytes of columns); each block still reads back as its spec."""
    import numpy as np

    from pdem.cases.stacks import cube_stack_scene
    from pdem.model.build import geometry_columns

    scene = parse_scene(cube_stack_scene(40, "fast"))
    specs = expand_blocks(scene, 10**7)
    table = SpecTable(specs, scene.blocks, geometry_columns(specs))
    n = len(specs)
    assert n == 64001 and table.parents == [] and (np.asarray(table.parent) == -1).all()
    assert table.names.is_runs and table.nbytes < 1024, table.nbytes
    assert table.excavate_at is None and table[7].excavate_at is None
    for g in (0, 1, 2, 4321, n - 1):
        for k in FIELDS:
            assert getattr(table[g], k) == getattr(specs[g], k), (g, k)
    assert table.parent_names()[n - 1] == specs[n - 1].parent == specs[n - 1].name
    assert table.parent_names().max_bytes == max(len(sp.name) for sp in specs)


def test_a_cut_rock_mass_keeps_its_varying_columns_plain():
    """Cut pieces differ in volume and surface: those columns stay plain arrays (runs would
    not be smaller), the labels still run; the tunnel's cut splits pieces into ``rock[13][0]``,
    ``rock[13][1]``, ... (runs of two), so the names stay plain too. Every view reads as its
    spec."""
    import numpy as np

    from pdem.cases.rock_mass import tunnel_scene

    scene = parse_scene(tunnel_scene(at=1.0, time=0.1))
    specs = expand_blocks(scene, 10**6)
    for sp in specs:
        sp.release()
    table = SpecTable(specs, scene.blocks)
    assert not table.volume.is_runs and table.group.is_runs and not table.names.is_runs
    assert np.array_equal(np.asarray(table.volume), [sp.volume for sp in specs])
    for g, (view, sp) in enumerate(zip(table, specs, strict=True)):
        for k in FIELDS:
            assert getattr(view, k) == getattr(sp, k), (g, k)


NAMES = [
    [f"cube[{k}]" for k in range(1000)],
    ["floor", *(f"cube[{k}]" for k in range(500)), "wall", "a[007]", "a[7]", "a[8]", "rock[3]",
     "rock[4]", "b[-1]", "é[1]", "é[2]", "", "x[99]", "x[100]", "x[9]", "x[10]", "floor"],
    [f"s_{k}" for k in range(100)],  # no counter: stays one plain buffer
    [],
]


@pytest.mark.parametrize("texts", NAMES, ids=["array", "mixed", "plain", "empty"])
def test_name_runs_read_back_as_the_string_column(texts):
    """Runs of ``prefix[k]`` give back every name (non-counted ones, leading zeros, signs,
    non-ASCII, a counter that gains a digit, repeats), with the lengths, longest name and
    first positions of the plain column; they are smaller where names count up."""
    from pdem.model.names import NameColumn
    from pdem.model.strings import StringColumn

    col, plain = NameColumn(texts), StringColumn(texts)
    assert len(col) == len(texts) and list(col) == texts and col == plain and col == texts
    assert [col[i] for i in range(len(texts))] == texts
    assert col.lengths().tolist() == plain.lengths().tolist()
    assert col.max_bytes == plain.max_bytes
    want = [*texts[::7], "absent", "cube[100000]", "a[07]", "x[10]"]
    assert col.positions(want) == plain.positions(want)
    assert col.nbytes <= plain.nbytes
    assert col.is_runs == (texts is not NAMES[2])
    if texts:
        assert col[-1] == texts[-1]
    with pytest.raises(IndexError):
        col[len(texts)]  # noqa: B018


def test_run_column_reads_back_as_the_array():
    """Runs of equal values by their bits (NaN runs, -0.0 is not 0.0): an int, an index
    array (negative too), a mask and a slice read as the array; a column of distinct values
    stays plain."""
    import numpy as np

    from pdem.model.runs import RunColumn

    v = np.array([1.0, 1.0, 1.0, 2.0, 2.0, np.nan, np.nan, -0.0, 0.0] + [3.0] * 100)
    col = RunColumn(v)
    assert col.is_runs and col.nbytes == 6 * 16 and len(col) == len(v)
    assert np.array_equal(np.asarray(col), v, equal_nan=True)
    assert np.array_equal(np.signbit(np.asarray(col)), np.signbit(v))
    rows = np.array([0, 5, 8, 108, -1, 3])
    assert np.array_equal(col[rows], v[rows], equal_nan=True)
    assert col[7] == 0.0 and np.signbit(col[7]) and col[-1] == 3.0
    assert np.array_equal(col[v > 1.0], v[v > 1.0])
    assert np.array_equal(col[2:9], v[2:9], equal_nan=True)
    with pytest.raises(IndexError):
        col[len(v)]  # noqa: B018
    plain = RunColumn(np.arange(100), np.int32)
    assert not plain.is_runs and plain[5] == 5 and plain.nbytes == 400


def _named(view, want) -> bool:
    """A selection's ``names`` taken block by block (the definition)."""
    return view.name in want or view.spec.name in want or view.parent in want


@pytest.mark.parametrize("which", ["tunnel", "l_on_stack", "array"])
def test_selection_by_names_and_groups_is_the_per_block_one(which):
    """``SpecTable.matching`` (from the columns) takes exactly the blocks the per-block
    reading does: own names (plain and run-encoded), scene entries, cut pieces' parents,
    groups, their intersection, names that match nothing, any subset of gids."""
    import numpy as np

    from pdem.cases.rock_mass import tunnel_scene
    from pdem.cases.stacks import cube_stack_scene

    text = {"tunnel": lambda: tunnel_scene(at=1.0, time=0.1), "l_on_stack": l_on_stack_scene,
            "array": lambda: cube_stack_scene(6, "fast")}[which]()
    scene = parse_scene(text)
    specs = expand_blocks(scene, 10**6)
    for sp in specs:
        sp.release()
    for sp in specs[1::7]:  # a parent that is neither an entry's nor a block's name
        sp.parent = "quarry"
    table = SpecTable(specs, scene.blocks)
    n = len(table)
    rng = np.random.default_rng(3)
    # own names, every scene entry's (an array's ``cube`` names no block itself) and every
    # cut piece's parent (``rock[13]`` split into ``rock[13][0]``, ... names no block itself)
    names = sorted({table.names[int(g)] for g in rng.integers(0, n, 5)}
                   | set(table.parents) | {b.name for b in scene.blocks}
                   | {"nothing", "cube[999999]"})
    entry_only = [b.name for b in scene.blocks if b.name not in table.names.positions([b.name])]
    parent_only = [p for p in table.parents if p not in table.names.positions([p])]
    assert "quarry" in parent_only and (entry_only or which != "array")
    groups = sorted({b.group for b in scene.blocks})
    subsets = [np.arange(n), np.sort(rng.choice(n, n // 3, replace=False)), np.zeros(0, int)]
    for want_names in ([names[0]], names, ["nothing"], entry_only, parent_only, None):
        for want_groups in ([groups[0]], groups, ["none"], None):
            if want_names is None and want_groups is None:
                continue
            for gids in subsets:
                got = table.matching(gids, want_names, want_groups)
                ref = np.array([(want_names is None or _named(table[g], set(want_names)))
                                and (want_groups is None or table[g].group in want_groups)
                                for g in gids], bool)
                assert np.array_equal(got, ref), (which, want_names, want_groups)


@pytest.mark.parametrize("parts", [
    [(5, 3), np.array([3, 3, 4]), (0, 9), (2, 4), np.array([4])],  # runs across the parts
    [np.arange(50.0)],  # too varied: plain
    [(1000, np.nan), np.array([np.nan, -0.0, 0.0]), (10, -0.0)],
    [],
], ids=["merged", "plain", "nan-zero", "empty"])
def test_run_column_from_parts_is_the_expanded_column(parts):
    """``RunColumn.from_parts`` (a spec table's column made from an unbuilt family's runs
    without expanding them) is bitwise ``RunColumn`` of the parts expanded."""
    import numpy as np

    from pdem.model.runs import RunColumn

    dtype = np.float64 if any(isinstance(p, np.ndarray) and p.dtype.kind == "f" for p in parts) \
        or any(isinstance(p, tuple) and isinstance(p[1], float) for p in parts) else np.int32
    rows = np.concatenate([np.full(p[0], p[1], dtype) if isinstance(p, tuple)
                           else np.asarray(p, dtype) for p in parts] or [np.zeros(0, dtype)])
    got, ref = RunColumn.from_parts(parts, dtype), RunColumn(rows)
    bits = np.dtype(f"u{np.dtype(dtype).itemsize}")
    assert got.is_runs == ref.is_runs and len(got) == len(rows)
    assert np.array_equal(np.asarray(got).view(bits), rows.view(bits))
    if got.is_runs:
        assert np.array_equal(got._starts, ref._starts)
