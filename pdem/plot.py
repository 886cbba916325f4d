"""``pdem plot FILE.h5``: a run's energy budget, histories or factor-of-safety search, or a
study's outputs and probability of failure, as a PNG (docs/python-api.md, "Plots").
matplotlib is an optional dependency: without it the message says how to install it.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from .errors import UserError
from .io.results import open_results
from .io.study_table import open_study

__all__ = ["KINDS", "plot"]

KINDS = ("energy", "history", "fos", "study")
# the energy columns drawn (the diagnostics contact_work, joint_created, geometry_created not)
_ENERGY = ("kinetic", "strain", "gravity_work", "applied_work", "boundary_work",
           "joint_dissipation", "damping_dissipation", "removed", "zone_strain", "plastic_work",
           "quiet_absorbed", "reinforcement_strain", "reinforcement_dissipation")


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise UserError("plots need matplotlib, an optional dependency: pip install matplotlib "
                        "(into pdem's environment: .venv/bin/python -m pip install "
                        "matplotlib)") from None
    matplotlib.use("Agg")  # files only: no display needed (a cluster node, CI)
    import matplotlib.pyplot as plt

    return plt


def _kind_of(path: Path) -> str:
    with h5py.File(path, "r") as f:
        fmt = f.attrs.get("pdem_format")
        if fmt == "study":
            return "study"
        if fmt != "output":
            raise UserError(f"{path}: not a pdem output or study file")
        return "fos" if "factor_of_safety" in f.attrs else "energy"


def plot(path: str | os.PathLike, what: str | None = None, history: str | None = None,
         out: str | os.PathLike | None = None) -> str:
    """Draw ``what`` (energy, history, fos or study; default from the file) of ``path`` into
    ``out`` (default ``<stem>-<what>.png`` beside it); returns the image's path."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if not h5py.is_hdf5(path):
        raise UserError(f"{path}: not an HDF5 file")
    what = what or _kind_of(path)
    if what not in KINDS:
        raise UserError(f"--what: {what!r} is none of {', '.join(KINDS)}")
    plt = _pyplot()
    out = Path(out) if out else path.with_name(f"{path.stem}-{what}.png")
    if what == "study":
        fig = _study(plt, path)
    else:
        with open_results(path) as r:
            fig = {"energy": _energy, "history": _history, "fos": _fos}[what](plt, r, history)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return str(out)


def _energy(plt, r, _):
    e = r.energy
    if not len(e.time):
        raise UserError(f"{r.path}: the energy budget has no rows yet")
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True,
                                      gridspec_kw={"height_ratios": [3, 1]})
    for col in _ENERGY:
        if col in e.columns and np.any(e[col] != 0):
            top.plot(e.time, e[col], label=col.replace("_", " "))
    top.set_ylabel("energy (J)")
    top.legend(fontsize=8, ncol=2)
    top.set_title(f"{r.scene.get('name', r.path.stem)}: energy budget")
    bottom.plot(e.time, e["balance_error"], color="k")
    bottom.set_ylabel("balance error (J)")
    bottom.set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def _history(plt, r, name):
    hs = {k: h for k, h in r.histories.items() if k != "energy"}
    if name is not None:
        if name not in r.histories:
            raise UserError(f"--history: no history {name!r} in {r.path} (histories: "
                            f"{', '.join(r.histories) or 'none'})")
        hs = {name: r.histories[name]}
    if not hs:
        raise UserError(f"{r.path}: no histories (output.histories in the scene; the energy "
                        "budget: --what energy)")
    fig, axes = plt.subplots(len(hs), 1, figsize=(8, 2.6 * len(hs) + 0.6), sharex=True,
                             squeeze=False)
    for ax, (k, h) in zip(axes[:, 0], hs.items(), strict=True):
        for col in h.columns:
            ax.plot(h.time, h[col], label=col)
        ax.set_ylabel(f"{k} ({h.units})" if h.units else k)
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def _fos(plt, r, _):
    fos = r.factor_of_safety
    if fos is None:
        raise UserError(f"{r.path}: no factor-of-safety search in this run")
    t = fos.trials
    fig, ax = plt.subplots(figsize=(7, 4.5))
    k = np.arange(1, len(t) + 1)
    stable = t[:, 1] > 0.5
    ax.plot(k, t[:, 0], color="0.6", zorder=1)
    ax.scatter(k[stable], t[stable, 0], marker="o", color="tab:green", label="stable", zorder=2)
    ax.scatter(k[~stable], t[~stable, 0], marker="x", color="tab:red", label="unstable",
               zorder=2)
    ax.axhline(fos.value, color="k", ls="--",
               label=f"F = {fos.value:.4g}" + ("" if fos.bounded else " (bound)"))
    ax.set_xlabel("trial")
    ax.set_ylabel("strength reduction factor F")
    ax.set_title(f"factor of safety search (stage {fos.stage})")
    ax.legend()
    fig.tight_layout()
    return fig


def _study(plt, path):
    t = open_study(path)
    names = list(t.outputs)
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 3.6 * len(names) + 0.4), squeeze=False)
    failure = t.summary.get("failure")
    for ax, k in zip(axes[:, 0], names, strict=True):
        v = t.outputs[k][t.done]
        v = v[np.isfinite(v)]
        ax.hist(v, bins=max(5, min(40, int(np.sqrt(len(v))) + 1)), color="tab:blue",
                alpha=0.8)
        ax.set_xlabel(k)
        ax.set_ylabel("cases")
        if failure is not None and failure["output"] == k:
            edge = failure["below"] if failure["below"] is not None else failure["above"]
            ax.axvline(edge, color="tab:red", ls="--")
            cond = "<" if failure["below"] is not None else ">"
            ax.set_title(f"P({k} {cond} {edge:g}) = {failure['probability']:.3g}  "
                         f"[{failure['low']:.3g}, {failure['high']:.3g}] at "
                         f"{100 * failure['confidence']:g}%  ({failure['n']} cases)")
        else:
            ax.set_title(f"{k}: mean {np.mean(v):.4g}, std {np.std(v, ddof=1):.3g}"
                         if len(v) > 1 else k)
    fig.suptitle(f"study {t.name}")
    fig.tight_layout()
    return fig
