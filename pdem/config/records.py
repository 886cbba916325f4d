"""History files: a recorded motion (CSV or PEER NGA ``.AT2``) resolved to a velocity table.

A scene's ``history: {file: ...}`` (docs/dynamics.md "History files") is read here once, when
the scene is validated: the file's (time, value) series is scaled, integrated from an
acceleration to a velocity (trapezoid rule, ``v = 0`` at the first time), baseline-corrected
on request, and turned along a direction into the table ``times (k,)``, ``velocity (k, 3)``
that :func:`pdem.boundary.history_velocity` interpolates each step. Pure numpy: the same
file gives the same bits on every rank and on a restart.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

# a decimal number as records write them; Python's float() also takes "1_0", "nan",
# "infinity", which no record means
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_NOT_FINITE = {"nan", "+nan", "-nan", "inf", "+inf", "-inf", "infinity", "+infinity",
               "-infinity"}
# line 4 of an AT2 file: "NPTS=  4000, DT=   .0050 SEC" (and its variants), or the older
# PEER layout "  4000   .0050   NPTS, DT"
_NPTS = re.compile(r"npts\s*=\s*(\S+?)\s*(,|\s|$)", re.IGNORECASE)
_DT = re.compile(r"\bdt\s*=\s*(\S+?)\s*(,|\s|sec|$)", re.IGNORECASE)
_OLD = re.compile(r"^\s*(\S+)\s+(\S+)\s+npts\b", re.IGNORECASE)
AT2_HEADER = 4  # lines before the values
QUANTITIES = ("velocity", "acceleration")
TIME_MAX = 1.0e12  # s, as a table's times (pdem.config.schema)
SPEED_MAX = 1.0e6  # m/s, as a prescribed velocity


class RecordError(ValueError):
    """A history file that cannot be used: the file, the line when there is one, and why."""

    def __init__(self, path: str, reason: str, line: int | None = None):
        where = f"{path} line {line}" if line is not None else path
        super().__init__(f"{where}: {reason}")


def _number(token: str, path: str, line: int) -> float:
    if token.lower() in _NOT_FINITE:
        raise RecordError(path, f"{token!r} is not finite", line)
    if not _NUMBER.fullmatch(token):
        raise RecordError(path, f"{token!r} is not a number", line)
    x = float(token)
    if not math.isfinite(x):
        raise RecordError(path, f"{token!r} is not finite", line)
    return x


def _is_number(token: str) -> bool:
    return bool(_NUMBER.fullmatch(token)) or token.lower() in _NOT_FINITE


def _text(path: str) -> str:
    try:
        return Path(path).read_text()
    except OSError as exc:
        raise RecordError(path, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise RecordError(path, f"not a text file (byte {exc.start} is not UTF-8)") from None


def read_at2(path: str, text: str) -> tuple[np.ndarray, np.ndarray]:
    """A PEER NGA ``.AT2`` record: 4 header lines, the 4th giving ``NPTS`` and ``DT``, then
    the values (in g), several a line. Sample ``k`` is at ``t = k DT``."""
    lines = text.splitlines()
    if len(lines) < AT2_HEADER:
        raise RecordError(path, f"ends in the header (an AT2 file has {AT2_HEADER} header "
                          "lines, the 4th like 'NPTS= 4000, DT= .0050 SEC')", len(lines))
    head = lines[AT2_HEADER - 1]
    npts, dt = _NPTS.search(head), _DT.search(head)
    if npts and dt:
        n_text, dt_text = npts.group(1), dt.group(1)
    elif old := _OLD.match(head):
        n_text, dt_text = old.group(1), old.group(2)
    else:
        raise RecordError(path, f"no NPTS and DT in {head.strip()!r} (expected like "
                          "'NPTS= 4000, DT= .0050 SEC')", AT2_HEADER)
    if not n_text.isdigit():
        raise RecordError(path, f"NPTS {n_text!r} is not a whole number", AT2_HEADER)
    n = int(n_text)
    dt = _number(dt_text, path, AT2_HEADER)
    if not dt > 0.0:
        raise RecordError(path, f"DT = {dt:g} must be positive", AT2_HEADER)
    values: list[float] = []
    for k, line in enumerate(lines[AT2_HEADER:], AT2_HEADER + 1):
        values.extend(_number(tok, path, k) for tok in line.replace(",", " ").split())
    if len(values) != n:
        raise RecordError(path, f"NPTS = {n} but {len(values)} values")
    if n < 2:
        raise RecordError(path, f"2 values at least (NPTS = {n})")
    return np.arange(n, dtype=float) * dt, np.array(values, float)


def read_csv(path: str, text: str) -> tuple[np.ndarray, np.ndarray]:
    """Two columns, time (s) and value, comma- or whitespace-separated; ``#`` starts a
    comment; lines before the first row whose first field is not a number are a header."""
    times: list[float] = []
    values: list[float] = []
    last = 0
    for k, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")] if "," in line else line.split()
        while fields and not fields[-1]:  # a trailing comma
            fields.pop()
        if not times and fields and not _is_number(fields[0]):
            continue  # a header line
        if len(fields) != 2:
            raise RecordError(path, f"{len(fields)} fields, expected 2 (time, value)", k)
        t, v = (_number(f, path, k) for f in fields)
        if t < 0.0:
            raise RecordError(path, f"time {t:g} is negative (a history's time starts at 0, "
                              "when its condition is applied)", k)
        if times and not t > times[-1]:
            raise RecordError(path, f"times must increase strictly (t = {t:g} after "
                              f"{times[-1]:g}, line {last})", k)
        times.append(t)
        values.append(v)
        last = k
    if len(times) < 2:
        raise RecordError(path, f"2 rows at least (time, value), got {len(times)}")
    return np.array(times, float), np.array(values, float)


def read_series(path: str) -> tuple[np.ndarray, np.ndarray]:
    """The (time, value) series of the history file ``path``: ``.AT2`` (any case) is read as
    PEER NGA, any other name as CSV."""
    text = _text(path)
    if Path(path).suffix.lower() == ".at2":
        return read_at2(path, text)
    return read_csv(path, text)


def trapezoid(t: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The running integral of ``f`` over ``t`` by the trapezoid rule, 0 at ``t[0]``."""
    out = np.zeros_like(f)
    np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t), out=out[1:])
    return out


def baseline_coefficients(t: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """``(c1, c2)`` such that ``v - c1 tau - c2 tau^2`` (``tau = t - t[0]``) ends at zero
    and so does its trapezoid integral (the displacement of the piecewise-linear velocity
    that the model follows), at the last time: two linear equations,

        c1 T + c2 T^2 = v(T),   c1 I1 + c2 I2 = D(T),

    with ``I1``, ``I2`` the trapezoid integrals of ``tau`` and ``tau^2`` over the record
    (``T^2 / 2`` and ``T^3 / 3 + T dt^2 / 6`` for equal steps) and ``D`` that of ``v``.
    Needs three samples at least (with two the equations are dependent)."""
    tau = t - t[0]
    T = tau[-1]
    i1 = trapezoid(tau, tau)[-1]
    i2 = trapezoid(tau, tau * tau)[-1]
    d = trapezoid(tau, v)[-1]
    det = T * i2 - T * T * i1
    c1 = (v[-1] * i2 - T * T * d) / det
    c2 = (T * d - i1 * v[-1]) / det
    return float(c1), float(c2)


def corrected(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` less its baseline correction (:func:`baseline_coefficients`); the last value is
    set to exactly 0 (it is 0 to round-off), so that the velocity held after the record is
    rest, not a creep of 1e-17 m/s."""
    c1, c2 = baseline_coefficients(t, v)
    tau = t - t[0]
    out = v - (c1 * tau + c2 * tau * tau)
    out[-1] = 0.0
    return out


class VelocityRecord:
    """A history file resolved: ``times (k,)`` and ``velocity (k, 3)`` (m/s), linear
    between samples, the first velocity before the first time and the last after the last.
    Equal when the tables are equal bit for bit (a scene compares its histories)."""

    __slots__ = ("times", "velocity", "_t", "_columns")

    def __init__(self, times: np.ndarray, velocity: np.ndarray):
        self.times = np.array(times, float)
        self.velocity = np.array(velocity, float)
        for a in (self.times, self.velocity):  # part of a frozen scene
            a.flags.writeable = False
        # what np.interp reads: contiguous and writeable, else it copies the whole record on
        # every call (a read-only 1e5-sample record: 1.3 ms a call instead of 1 us)
        self._t = self.times.copy()
        self._columns = np.ascontiguousarray(self.velocity.T).copy()

    def at(self, t: float) -> np.ndarray:
        """The velocity at ``t`` (s since the condition was applied): a binary search per
        component, as a ``table`` history's."""
        return np.array([np.interp(t, self._t, self._columns[k]) for k in range(3)])

    def __eq__(self, other) -> bool:
        return isinstance(other, VelocityRecord) and np.array_equal(
            self.times, other.times) and np.array_equal(self.velocity, other.velocity)

    __hash__ = None

    def __getstate__(self):
        return self.times, self.velocity

    def __setstate__(self, state):
        self.__init__(*state)

    def __repr__(self) -> str:
        return f"VelocityRecord({len(self.times)} samples to t = {self.times[-1]:g} s)"


def resolve(path: str, quantity: str, direction, scale: float, baseline: bool) -> VelocityRecord:
    """Read the history file ``path`` and resolve it to a velocity table: values times
    ``scale`` (m/s, or m/s2 for ``quantity`` acceleration, integrated from 0), less the
    baseline correction when ``baseline``, along the unit vector of ``direction``. Raises
    :class:`RecordError` naming the file (and the line) for every defect."""
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity: {quantity!r} is not one of {', '.join(QUANTITIES)}")
    t, x = read_series(path)
    if t[-1] > TIME_MAX:
        raise RecordError(path, f"time {t[-1]:g} s beyond {TIME_MAX:g} s")
    v = x * scale
    if quantity == "acceleration":
        v = trapezoid(t, v)
    if baseline:
        if len(t) < 3:
            raise RecordError(path, f"baseline: needs 3 rows at least, got {len(t)}")
        v = corrected(t, v)
    d = np.array(direction, float)
    n = math.sqrt(float(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))
    u = d / n
    # + 0.0: a zero component of the direction gives 0.0, never -0.0, whatever the sign of v
    vel = v[:, None] * u[None, :] + 0.0
    peak = float(np.abs(vel).max())
    if not peak <= SPEED_MAX:
        raise RecordError(path, f"the velocity reaches {peak:.3g} m/s, beyond {SPEED_MAX:g} "
                          "(a wrong scale or quantity?)")
    return VelocityRecord(t, vel)
