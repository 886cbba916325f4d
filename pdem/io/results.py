"""The results of a run as NumPy arrays with names, units and time, read from its output file
without knowing the HDF5 layout (docs/output.md has the layout; docs/python-api.md this reader)::

    r = pdem.open("run.h5")
    r.time                               # (n_snap,) s
    r.blocks.displacement[-1]            # (n_blocks, 3) m, at the last snapshot
    r.blocks["crown"].displacement       # (n_snap, 3) m: one block's series
    r.histories["crown.velocity"].values # (n, 3) m/s, at r.histories[...].time
    r.energy["balance_error"]            # (n,) J
    r.contacts(-1).normal_force          # (n_c,) N, the last snapshot's contacts
    r.factor_of_safety.value             # a strength-reduction search's result, or None

Everything is read when first asked for and kept; the file stays open until ``close()`` (or the
end of a ``with`` block). ``to_pandas()`` (where pandas is installed) gives data frames.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import yaml

__all__ = ["BlockTable", "ContactTable", "FactorOfSafety", "History", "Results", "ZoneTable",
           "open_results"]

_HISTORY_UNITS = {"displacement": "m", "position": "m", "velocity": "m/s",
                  "angular_velocity": "rad/s", "acceleration": "m/s^2"}


def _text(value) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _pandas():
    try:
        import pandas  # optional: only to_pandas() needs it
    except ImportError:
        raise ImportError("to_pandas() needs pandas: pip install pandas (the arrays themselves "
                          "need nothing more)") from None
    return pandas


@dataclass
class History:
    """A monitored quantity: ``values`` (n, len(columns)) in ``units`` at ``time`` (n,) s;
    ``attrs``: what it monitors (block, quantity, point, ...). ``h["x"]`` is one column."""

    name: str
    time: np.ndarray
    values: np.ndarray
    columns: list[str]
    units: str
    attrs: dict = field(default_factory=dict)

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"history {self.name!r} has no column {column!r} (it has "
                           f"{', '.join(self.columns)})") from None

    @property
    def last(self) -> dict[str, float]:
        """The last row, by column (empty if no row was written)."""
        if not len(self.time):
            return {}
        return dict(zip(self.columns, map(float, self.values[-1]), strict=True))

    def to_pandas(self):
        """A data frame indexed by time (s), one column per value column."""
        pd = _pandas()
        frame = pd.DataFrame(self.values, columns=self.columns,
                             index=pd.Index(self.time, name="time"))
        frame.attrs["units"] = self.units
        return frame


class _Lazy:
    """Datasets of one HDF5 group read on first access and kept; ``units`` names each one's."""

    units: dict[str, str] = {}

    def __init__(self, group: h5py.Group):
        self._group = group
        self._cache: dict[str, np.ndarray] = {}

    def _read(self, name: str) -> np.ndarray:
        if name not in self._cache:
            if name not in self._group:
                raise AttributeError(f"{type(self).__name__}: no {name!r} in this file")
            ds = self._group[name]
            self._cache[name] = ds.asstr()[()] if ds.dtype.kind == "S" else ds[()]
        return self._cache[name]


class BlockTable(_Lazy):
    """The blocks, rows in gid order (the scene's expanded ``blocks`` list): ``name``,
    ``parent`` (the scene block it was cut from), ``fixed``, ``group`` (names); per snapshot
    ``centroid``, ``velocity``, ``angular_velocity`` (n_snap, n_blocks, 3), ``orientation``
    (n_snap, n_blocks, 4: w, x, y, z), ``removed`` (n_snap, n_blocks), ``displacement``
    (centroid - initial centroid). ``blocks["NAME"]`` is one block's series."""

    units = {"centroid": "m", "initial_centroid": "m", "displacement": "m", "velocity": "m/s",
             "angular_velocity": "rad/s", "orientation": "", "removed": "", "fixed": "",
             "group": "", "name": "", "parent": ""}

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        if name == "displacement":
            return self._read("centroid") - self._read("initial_centroid")[None]
        if name == "group":
            names = [_text(x) for x in self._group["group"].attrs.get("names", [])]
            return np.array(names, dtype=object)[self._read("group")]
        if name == "fixed":
            return self._read("fixed").astype(bool)
        return self._read(name)

    def __len__(self) -> int:
        return len(self.name)

    def index(self, name: str) -> int:
        """The gid of the block called ``name``."""
        hits = np.nonzero(self.name == name)[0]
        if not len(hits):
            raise KeyError(f"no block {name!r} in this run (blocks: {', '.join(self.name[:8])}"
                           f"{', ...' if len(self) > 8 else ''})")
        return int(hits[0])

    def __getitem__(self, name: str) -> _OneBlock:
        return _OneBlock(self, self.index(name))

    def to_pandas(self, snapshot: int = -1):
        """One snapshot (default the last) as a data frame indexed by block name."""
        pd = _pandas()
        c, v = self.centroid[snapshot], self.velocity[snapshot]
        d = self.displacement[snapshot]
        cols = {"x": c[:, 0], "y": c[:, 1], "z": c[:, 2], "ux": d[:, 0], "uy": d[:, 1],
                "uz": d[:, 2], "displacement": np.linalg.norm(d, axis=1),
                "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2], "fixed": self.fixed,
                "group": self.group, "removed": self.removed[snapshot]}
        return pd.DataFrame(cols, index=pd.Index(self.name, name="block"))


@dataclass
class _OneBlock:
    table: BlockTable
    gid: int

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        value = getattr(self.table, name)
        return value[self.gid] if value.ndim == 1 or name == "initial_centroid" \
            else value[:, self.gid]


class ContactTable:
    """One snapshot's contacts (docs/output.md, "Contacts"): ``block`` (n_c, 2) gids, ``joint``
    (the joint's name), ``normal`` (n_c, 3), ``normal_force`` (N, + compression),
    ``shear_force`` (n_c, 3) N, ``normal_stress`` Pa, ``shear_displacement`` m, ``opening`` m,
    ``area`` m², ``state`` (intact, slipping, open, failed)."""

    units = {"point": "m", "normal": "", "normal_force": "N", "shear_force": "N",
             "normal_stress": "Pa", "shear_displacement": "m", "opening": "m", "area": "m^2",
             "block": "", "piece": "", "joint": "", "state": "", "n_sub": ""}

    def __init__(self, f: h5py.File, rows: slice, joint_names: list[str]):
        self._f, self._rows, self._joint_names = f, rows, joint_names

    def __len__(self) -> int:
        return self._rows.stop - self._rows.start

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        path = f"contacts/{name}"
        if path not in self._f:
            raise AttributeError(f"contacts have no {name!r}")
        data = self._f[path][self._rows]
        if name == "joint":
            return np.array(self._joint_names, dtype=object)[data] if len(data) \
                else np.array([], dtype=object)
        if name == "state":
            names = [_text(x) for x in self._f[path].attrs.get(
                "names", ["intact", "slipping", "open", "failed"])]
            return np.array(names, dtype=object)[data] if len(data) else np.array([], object)
        return data

    def to_pandas(self):
        """The contacts as a data frame, one row each (vectors as x, y, z columns)."""
        pd = _pandas()
        cols = {"block_a": self.block[:, 0], "block_b": self.block[:, 1], "joint": self.joint,
                "state": self.state, "normal_force": self.normal_force,
                "shear_force": np.linalg.norm(self.shear_force, axis=1),
                "normal_stress": self.normal_stress,
                "shear_displacement": self.shear_displacement, "opening": self.opening,
                "area": self.area}
        return pd.DataFrame(cols)


class ZoneTable(_Lazy):
    """The zoned blocks' grids: ``initial_points`` (n_gp, 3) m, ``connectivity`` (n_z, 4),
    ``zone_block``/``point_block`` (gids), and per snapshot ``points`` (m), ``displacement``
    (m), ``velocity`` (m/s), ``stress`` (n_snap, n_z, 6: xx yy zz xy yz zx, Pa, tension
    positive), ``sigma1..3``, ``mean_stress``, ``von_mises`` (Pa), ``plastic`` (state bits) —
    the series the scene wrote (``output.zones.fields``)."""

    units = {"initial_points": "m", "points": "m", "displacement": "m", "velocity": "m/s",
             "stress": "Pa", "sigma1": "Pa", "sigma2": "Pa", "sigma3": "Pa",
             "mean_stress": "Pa", "von_mises": "Pa", "plastic": "", "connectivity": "",
             "zone_block": "", "point_block": "", "block": ""}

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return self._read(name)


@dataclass
class FactorOfSafety:
    """A strength-reduction search: ``value``; ``bounded`` False when the model was stable at
    ``high`` (the factor is at least ``value``) or unstable at ``low`` (at most ``value``);
    ``stage`` its stage's name; ``trials`` (m, 3): factor, stable (1/0), steps;
    ``mechanism`` (n_blocks, 3) m: the last unstable trial's displacements."""

    value: float
    bounded: bool
    stage: str
    trials: np.ndarray
    mechanism: np.ndarray | None


class Results:
    """A run's output file, read (docs/python-api.md). Every rank may open it."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path}: no such file")
        if not h5py.is_hdf5(self.path):
            raise ValueError(f"{self.path}: not an HDF5 file")
        self._f = h5py.File(self.path, "r")
        fmt = self._f.attrs.get("pdem_format")
        if fmt is None or _text(fmt) != "output":
            self._f.close()
            raise ValueError(f"{self.path}: not a pdem output file (pdem_format "
                             f"{_text(fmt) if fmt is not None else 'missing'})")
        self.summary: dict = {}  # the run's summary when pdem.run made it (steps, wall, ...)
        self._histories: dict[str, History] | None = None

    # the file
    @property
    def file(self) -> h5py.File:
        """The open HDF5 file, for what this reader does not cover."""
        return self._f

    def close(self) -> None:
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return (f"<pdem results {self.path.name}: {len(self.blocks)} blocks, "
                f"{len(self.time)} snapshots to t = {self.time[-1] if len(self.time) else 0:g} s>")

    # the run
    @property
    def scene_text(self) -> str:
        """The resolved scene (YAML, every default filled in)."""
        return _text(self._f.attrs["scene"])

    @functools.cached_property
    def scene(self) -> dict:
        """The resolved scene as a mapping (parsed once)."""
        return yaml.safe_load(self.scene_text)

    @property
    def attrs(self) -> dict:
        return {k: _text(v) if isinstance(v, bytes) else v for k, v in self._f.attrs.items()}

    @property
    def time(self) -> np.ndarray:
        """(n_snap,) s: each snapshot's model time."""
        return self._f["time"][()]

    @property
    def step(self) -> np.ndarray:
        return self._f["step"][()]

    @property
    def stage(self) -> np.ndarray:
        """(n_snap,) the name of the stage each snapshot belongs to ("" without stages)."""
        index = self._f["stage"][()] if "stage" in self._f else np.zeros(len(self.time), int)
        names = self.stage_names
        return np.array([names[i] if i < len(names) else "" for i in index], dtype=object)

    @property
    def stage_names(self) -> list[str]:
        return [str(st.get("name", k)) for k, st in enumerate(self.scene.get("stages") or [])]

    @property
    def blocks(self) -> BlockTable:
        if not hasattr(self, "_blocks"):
            self._blocks = BlockTable(self._f["blocks"])
        return self._blocks

    def contacts(self, snapshot: int = -1) -> ContactTable:
        """The contacts of snapshot ``snapshot`` (default the last), if the scene wrote them."""
        if "contacts/offset" not in self._f:
            raise KeyError("this run stored no contacts (output.contacts: false)")
        off = self._f["contacts/offset"][()]
        n = len(off) - 1
        i = snapshot + n if snapshot < 0 else snapshot
        if not 0 <= i < n:
            raise IndexError(f"snapshot {snapshot} out of range: the file has {n}")
        names = [_text(x) for x in self._f.attrs.get("joint_names", [])]
        return ContactTable(self._f, slice(int(off[i]), int(off[i + 1])), names)

    @property
    def zones(self) -> ZoneTable | None:
        """The zoned blocks' grids, or None in a scene without zoned blocks."""
        return ZoneTable(self._f["zones"]) if "zones" in self._f else None

    @property
    def histories(self) -> dict[str, History]:
        """Every history by name: the block and station records (``NAME.QUANTITY``,
        ``point-K.QUANTITY``) and the energy budget (``energy``)."""
        if self._histories is None:
            self._histories = {}
            for name, g in (self._f.get("histories") or {}).items():
                attrs = {k: _text(v) if isinstance(v, bytes) else v for k, v in g.attrs.items()}
                values = g["value"][()]
                columns = str(attrs.pop("columns", "")).split(",") if "columns" in attrs \
                    else (["x", "y", "z"] if values.shape[1] == 3 else
                          [f"c{k}" for k in range(values.shape[1])])
                units = str(attrs.pop("units", _HISTORY_UNITS.get(attrs.get("quantity"), "")))
                self._histories[name] = History(name, g["time"][()], values, columns, units,
                                                attrs)
        return self._histories

    @property
    def energy(self) -> History:
        """The energy budget (J; docs/output.md lists its columns)."""
        try:
            return self.histories["energy"]
        except KeyError:
            raise KeyError("this file has no energy budget") from None

    @property
    def factor_of_safety(self) -> FactorOfSafety | None:
        """The strength-reduction search's result, or None if the run made none."""
        a = self._f.attrs
        if "factor_of_safety" not in a:
            return None
        g = self._f.get("factor_of_safety")
        trials = g["trials"][()] if g is not None and "trials" in g else np.zeros((0, 3))
        mech = g["mechanism"][()] if g is not None and "mechanism" in g else None
        return FactorOfSafety(float(a["factor_of_safety"]),
                              bool(a.get("factor_of_safety_bounded", 1)),
                              _text(a.get("factor_of_safety_stage", "")), trials, mech)


def open_results(path: str | os.PathLike) -> Results:
    """The results in the output file ``path`` (``pdem.open``)."""
    return Results(path)
