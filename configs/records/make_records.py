"""Make the history files shipped in configs/records/ (docs/dynamics.md "History files").

Both are synthetic, made here deterministically (a fixed seed); neither is a recorded motion:

* ``synthetic-0.3g.at2``: an acceleration record in the PEER NGA ``.AT2`` layout (values in g,
  DT 0.005 s, 8 s): white noise from a seeded generator, band-passed to 0.5-10 Hz (a cosine
  taper on the spectrum), shaped by an envelope (rise as (t / 1 s)^2 to 1 s, strong to 4 s,
  then decaying as exp(-0.8 (t - 4 s))), the last 0.5 s tapered to zero (a cosine), scaled
  to a PGA of 0.3 g;
* ``ricker-10hz.csv``: a velocity pulse, the Ricker wavelet
  ``v = 0.1 (1 - 2 (pi f tau)^2) exp(-(pi f tau)^2)`` m/s, ``f`` = 10 Hz, ``tau = t - 0.15 s``,
  on 0..0.3 s at 1 ms: peak 0.1 m/s at 0.15 s, zero mean (it ends where it began).

Run ``python configs/records/make_records.py`` (from anywhere) to write them again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SEED = 2026
DT, DURATION, PGA = 0.005, 8.0, 0.3  # s, s, g
BAND = (0.5, 10.0)  # Hz
PER_LINE = 5  # values per line, as PEER writes them


def envelope(t: np.ndarray) -> np.ndarray:
    rise, strong, decay = 1.0, 4.0, 0.8
    e = np.where(t < rise, (t / rise) ** 2, 1.0)
    return np.where(t > strong, np.exp(-decay * (t - strong)), e)


def band_pass(x: np.ndarray, dt: float, lo: float, hi: float) -> np.ndarray:
    """Spectrum kept in [lo, hi] Hz, with half-octave cosine tapers outside the band."""
    f = np.fft.rfftfreq(len(x), dt)
    w = np.zeros_like(f)
    w[(f >= lo) & (f <= hi)] = 1.0
    low = (f > lo / np.sqrt(2.0)) & (f < lo)
    w[low] = 0.5 - 0.5 * np.cos(np.pi * np.log2(f[low] * np.sqrt(2.0) / lo) * 2.0)
    high = (f > hi) & (f < hi * np.sqrt(2.0))
    w[high] = 0.5 + 0.5 * np.cos(np.pi * np.log2(f[high] / hi) * 2.0)
    return np.fft.irfft(np.fft.rfft(x) * w, len(x))


def acceleration() -> tuple[np.ndarray, np.ndarray]:
    n = int(round(DURATION / DT))
    t = np.arange(n) * DT
    noise = np.random.default_rng(SEED).standard_normal(n)
    a = band_pass(noise, DT, *BAND) * envelope(t)
    # the last 0.5 s tapered to zero (a cosine), so that the record ends at rest
    end = t > DURATION - 0.5
    a[end] *= 0.5 + 0.5 * np.cos(np.pi * (t[end] - (DURATION - 0.5)) / 0.5)
    a[0] = 0.0
    a *= PGA / np.abs(a).max()
    return t, a


def write_at2(path: Path, a: np.ndarray) -> None:
    lines = [
        "SYNTHETIC RECORD (not a recorded motion): made by configs/records/make_records.py",
        f"enveloped band-passed ({BAND[0]:g}-{BAND[1]:g} Hz) noise, seed {SEED}, "
        f"PGA {PGA:.3f} g, {DURATION:g} s",
        "ACCELERATION TIME SERIES IN UNITS OF G",
        f"NPTS= {len(a):5d}, DT= {DT:.4f} SEC",
    ]
    for k in range(0, len(a), PER_LINE):
        lines.append("".join(f"{v:15.6E}" for v in a[k:k + PER_LINE]))
    path.write_text("\n".join(lines) + "\n")


def write_ricker(path: Path) -> None:
    f, t0, peak, dt = 10.0, 0.15, 0.1, 0.001
    t = np.arange(301) / 1000.0
    x = (np.pi * f * (t - t0)) ** 2
    v = peak * (1.0 - 2.0 * x) * np.exp(-x)
    rows = [
        "# SYNTHETIC velocity pulse: made by configs/records/make_records.py",
        f"# Ricker wavelet, centre {f:g} Hz, peak {peak:g} m/s at t = {t0:g} s, dt {dt:g} s",
        "time_s,velocity_m_per_s",
    ]
    rows += [f"{ti:.3f},{vi:.9e}" for ti, vi in zip(t, v, strict=True)]
    path.write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    t, a = acceleration()
    write_at2(HERE / "synthetic-0.3g.at2", a)
    write_ricker(HERE / "ricker-10hz.csv")
