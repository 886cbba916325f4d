"""Sampling for parametric and probabilistic studies: distributions drawn by inverse transform
from uniforms in (0, 1), so that plain Monte Carlo and Latin hypercube sampling share one path;
Fisher's distribution of joint-set poles; a probability with its Wilson confidence interval.

Orientation convention (that of the scene file, :func:`pdem.geometry.cutting.dip_normal` and
:mod:`pdem.analysis.wedge`): x east, y north, z up; a plane of dip ``d`` (0..90 degrees below
horizontal) and dip direction ``a`` (degrees clockwise from north, +y) has the upward unit normal
``(sin d sin a, sin d cos a, cos d)``.

numpy and the standard library only (no scipy): the normal quantile is Acklam's rational
approximation polished by one Halley step on ``math.erfc``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import ClassVar

import numpy as np

__all__ = ["Distribution", "Fisher", "LogNormal", "Normal", "Truncated", "Uniform",
           "normal_cdf", "normal_quantile", "plane_normal", "plane_of", "probability_of",
           "uniforms"]

_erfc = np.vectorize(math.erfc, otypes=[float])
_SQRT2 = math.sqrt(2.0)
_TINY = np.finfo(float).tiny
_BELOW_ONE = 1.0 - np.finfo(float).epsneg  # the largest double below 1

# Acklam's coefficients: the central region |u - 1/2| <= 1/2 - _TAIL and the tails
_A = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
      1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00)
_B = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
      6.680131188771972e+01, -1.328068155288572e+01)
_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
      -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00)
_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
      3.754408661907416e+00)
_TAIL = 0.02425


def normal_cdf(x) -> np.ndarray:
    """Φ(x), the standard normal distribution function (through erfc: accurate in the lower
    tail to the smallest doubles; in the upper tail use ``normal_cdf(-x)`` for ``1 - Φ(x)``)."""
    return 0.5 * _erfc(-np.asarray(x, float) / _SQRT2)


def _poly(coef, t):
    out = np.full_like(t, coef[0])
    for c in coef[1:]:
        out = out * t + c
    return out


def normal_quantile(u) -> np.ndarray:
    """Φ⁻¹(u) for u in (0, 1): Acklam's rational approximation (relative error 1.2e-9), then
    one Halley step on Φ, which brings it to round-off (cubic convergence)."""
    u = np.asarray(u, float)
    if np.any(~((u > 0.0) & (u < 1.0))):
        raise ValueError("normal quantile: every u must lie in (0, 1)")
    x = np.empty_like(u)
    tail = np.minimum(u, 1.0 - u)  # 1 - u is exact for u >= 1/2
    mid = tail >= _TAIL
    q = u[mid] - 0.5
    r = q * q
    x[mid] = _poly(_A, r) * q / (_poly(_B, r) * r + 1.0)
    t = np.sqrt(-2.0 * np.log(tail[~mid]))
    z = _poly(_C, t) / (_poly(_D, t) * t + 1.0)
    x[~mid] = np.where(u[~mid] < 0.5, z, -z)
    # Halley on e = Φ(x) - u, with x -= e / (φ (1 + x e / (2 φ))). e from the tail probability
    # Q = Φ(-|x|) (erfc keeps its relative precision there): Φ(x) - u = Q - u for x <= 0 and
    # (1 - u) - Q for x > 0, with no cancellation against a number near 1.
    small = 0.5 * _erfc(np.abs(x) / _SQRT2)
    e = np.where(x > 0.0, (1.0 - u) - small, small - u)
    g = np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    return x - e / (g * (1.0 + x * e / (2.0 * g)))


def uniforms(n: int, dims: int, seed: int, latin: bool = False) -> np.ndarray:
    """(n, dims) uniforms in the open interval (0, 1) from ``np.random.default_rng(seed)``: the
    same seed gives the same bits.

    ``latin``: a Latin hypercube -- each column has exactly one point in each of the n strata
    [k/n, (k+1)/n), placed uniformly at random inside it, the strata of each column in an
    independent random order.
    """
    if n < 0:
        raise ValueError(f"n must not be negative (got {n})")
    if dims < 0:
        raise ValueError(f"dims must not be negative (got {dims})")
    rng = np.random.default_rng(seed)
    if not latin:
        u = rng.random((n, dims))
    else:
        u = np.empty((n, dims))
        for j in range(dims):
            u[:, j] = (rng.permutation(n) + rng.random(n)) / n
    # random() lies in [0, 1) and a stratum's top may round to 1: both ends are infinite
    # quantiles, so they move in by one unit (a probability of ~1e-16 a draw)
    return np.clip(u, _TINY, _BELOW_ONE)


def _finite(name: str, value) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite (got {value})")


def _positive(name: str, value) -> None:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be positive and finite (got {value})")


def _column(u, dims: int, what: str) -> np.ndarray:
    u = np.asarray(u, float)
    if u.ndim != 2 or u.shape[1] != dims:
        raise ValueError(f"{what} takes uniforms of shape (n, {dims}) (got {u.shape})")
    return u


class Distribution:
    """A distribution sampled by inverse transform from ``dims`` uniforms per draw."""

    dims: ClassVar[int] = 1

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        """Draws from uniforms ``u`` of shape (n, dims): (n,) values, (n, 2) for Fisher."""
        raise NotImplementedError

    def describe(self) -> str:
        """The distribution and its parameters, e.g. ``normal(mean=30, std=3)``."""
        raise NotImplementedError


class _Standardised(Distribution):
    """A distribution that is an increasing map of a standard normal z (Truncated's bases)."""

    def to_standard(self, x: float) -> float:
        raise NotImplementedError

    def from_standard(self, z: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def from_uniform(self, u):
        return self.from_standard(normal_quantile(_column(u, 1, self.describe())[:, 0]))


@dataclass(frozen=True)
class Normal(_Standardised):
    mean: float
    std: float

    def __post_init__(self):
        _finite("mean", self.mean)
        _positive("std", self.std)

    def to_standard(self, x):
        return (x - self.mean) / self.std

    def from_standard(self, z):
        return self.mean + self.std * z

    def describe(self):
        return f"normal(mean={self.mean:g}, std={self.std:g})"


@dataclass(frozen=True)
class LogNormal(_Standardised):
    """Given by the variable's own mean and standard deviation (as engineers report them), not
    its logarithm's: ln X is normal with ``σ² = ln(1 + (std/mean)²)``, ``μ = ln(mean) − σ²/2``."""

    mean: float
    std: float

    def __post_init__(self):
        _positive("mean", self.mean)
        _positive("std", self.std)

    @property
    def log_params(self) -> tuple[float, float]:
        """(μ, σ) of ln X."""
        s2 = math.log1p((self.std / self.mean) ** 2)
        return math.log(self.mean) - 0.5 * s2, math.sqrt(s2)

    def to_standard(self, x):
        mu, s = self.log_params
        return (math.log(x) - mu) / s if x > 0 else -math.inf

    def from_standard(self, z):
        mu, s = self.log_params
        return np.exp(mu + s * z)

    def describe(self):
        return f"lognormal(mean={self.mean:g}, std={self.std:g})"


@dataclass(frozen=True)
class Uniform(Distribution):
    low: float
    high: float

    def __post_init__(self):
        _finite("low", self.low)
        _finite("high", self.high)
        if not self.high > self.low:
            raise ValueError(f"high must be above low (got low={self.low}, high={self.high})")

    def from_uniform(self, u):
        return self.low + (self.high - self.low) * _column(u, 1, self.describe())[:, 0]

    def describe(self):
        return f"uniform(low={self.low:g}, high={self.high:g})"


@dataclass(frozen=True)
class Truncated(Distribution):
    """``base`` (Normal or LogNormal) restricted to [low, high] (None: unbounded on that side):
    the inverse transform of ``F(low) + u (F(high) − F(low))``, every value within the bounds.

    Worked on the base's standard normal z in [a, b]; an interval above the median (a > 0) is
    mirrored to [−b, −a], so its probabilities are small numbers that erfc gives to full
    relative precision (1 − Φ(a) would cancel) and a truncation far in the upper tail still
    samples correctly.
    """

    base: Normal | LogNormal
    low: float | None = None
    high: float | None = None

    def __post_init__(self):
        if not isinstance(self.base, _Standardised):
            raise ValueError(f"base must be a Normal or LogNormal (got {self.base!r})")
        for name in ("low", "high"):
            if getattr(self, name) is not None:
                _finite(name, getattr(self, name))
        if self.low is not None and self.high is not None and not self.high > self.low:
            raise ValueError(f"high must be above low (got low={self.low}, high={self.high})")
        if not self._window()[2] > 0.0:
            raise ValueError(f"low={self.low}, high={self.high} hold no probability of "
                             f"{self.base.describe()}")

    def _window(self) -> tuple[float, float, float, bool]:
        """(a, b, mass, mirrored): the bounds on z, the probability between them, and whether
        the sampling runs on −z."""
        a = -math.inf if self.low is None else self.base.to_standard(self.low)
        b = math.inf if self.high is None else self.base.to_standard(self.high)
        mirrored = a > 0.0
        lo, hi = (-b, -a) if mirrored else (a, b)
        p_lo, p_hi = (float(normal_cdf(v)) for v in (lo, hi))
        return a, b, p_hi - p_lo, mirrored

    def from_uniform(self, u):
        u = _column(u, 1, self.describe())[:, 0]
        a, b, mass, mirrored = self._window()
        if mirrored:  # z = −Φ⁻¹(Φ(−a) − u mass): still increasing in u
            z = -normal_quantile(np.clip(float(normal_cdf(-a)) - u * mass, _TINY, _BELOW_ONE))
        else:
            z = normal_quantile(np.clip(float(normal_cdf(a)) + u * mass, _TINY, _BELOW_ONE))
        x = self.base.from_standard(np.clip(z, a, b))
        return np.clip(x, -np.inf if self.low is None else self.low,
                       np.inf if self.high is None else self.high)

    def describe(self):
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        return f"{self.base.describe()} truncated to [{low}, {high}]"


def plane_normal(dip, dip_direction) -> np.ndarray:
    """Upward unit normals (..., 3) of planes of ``dip`` and ``dip_direction`` (degrees):
    ``(sin d sin a, sin d cos a, cos d)``."""
    d, a = np.radians(dip), np.radians(dip_direction)
    return np.stack([np.sin(d) * np.sin(a), np.sin(d) * np.cos(a), np.cos(d)], axis=-1)


def plane_of(normal) -> tuple[np.ndarray, np.ndarray]:
    """(dip in [0, 90], dip direction in [0, 360)) in degrees of the planes with normals
    ``normal`` (n, 3), of either sense and any length: a downward normal is the plane's other
    pole and is flipped first."""
    n = np.asarray(normal, float)
    n = np.where(n[:, 2:3] < 0.0, -n, n)
    horizontal = np.hypot(n[:, 0], n[:, 1])
    dip = np.degrees(np.arctan2(horizontal, n[:, 2]))  # precise near 0 too, unlike arccos
    dd = np.degrees(np.arctan2(n[:, 0], n[:, 1])) % 360.0
    return dip, np.where(dd >= 360.0, 0.0, dd)  # -1e-17 % 360 rounds to 360


@dataclass(frozen=True)
class Fisher(Distribution):
    """Fisher's distribution of a joint set's poles about the pole of its mean plane (``dip``,
    ``dip_direction``, degrees) with concentration ``kappa``.

    The mean pole is the mean plane's upward unit normal ``(sin d sin a, sin d cos a, cos d)``
    (x east, y north, z up). The angle θ of a draw from it has
    ``cos θ = 1 + ln(1 − u₁ (1 − e^{−2κ})) / κ``, its azimuth about it is ``2π u₂``. A draw is
    reported as its plane, (n, 2) of dip in [0, 90] and dip direction in [0, 360): a sampled
    pole on the other side of horizontal (here: pointing down; with lower-hemisphere poles:
    pointing up) is the same plane's other pole, and is flipped.
    """

    dip: float
    dip_direction: float
    kappa: float
    dims: ClassVar[int] = 2

    def __post_init__(self):
        if not (math.isfinite(self.dip) and 0.0 <= self.dip <= 90.0):
            raise ValueError(f"dip must lie in [0, 90] degrees (got {self.dip})")
        _finite("dip_direction", self.dip_direction)
        _positive("kappa", self.kappa)

    def poles(self, u) -> np.ndarray:
        """The sampled unit poles (n, 3) about the mean plane's upward normal, before the
        flip to the upper hemisphere."""
        u = _column(u, 2, self.describe())
        k = self.kappa
        # 1 − cos θ, without the cancellation of 1 + ln(..)/κ for a concentrated set
        w = -np.log1p(u[:, 0] * np.expm1(-2.0 * k)) / k
        cos_t = 1.0 - w
        sin_t = np.sqrt(np.clip(w * (2.0 - w), 0.0, 1.0))
        phi = 2.0 * math.pi * u[:, 1]
        m = plane_normal(self.dip, self.dip_direction)
        # an orthonormal frame (e1, e2, m) about the mean pole
        helper = np.array([1.0, 0.0, 0.0]) if abs(m[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(m, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(m, e1)
        return (cos_t[:, None] * m + (sin_t * np.cos(phi))[:, None] * e1
                + (sin_t * np.sin(phi))[:, None] * e2)

    def from_uniform(self, u):
        dip, dd = plane_of(self.poles(u))
        return np.stack([dip, dd], axis=1)

    def describe(self):
        return f"fisher(dip={self.dip:g}, dip_direction={self.dip_direction:g}, kappa={self.kappa:g})"


def probability_of(failures: int, n: int, confidence: float = 0.95) -> tuple[float, float, float]:
    """``(p, lo, hi)``: the estimate ``p = failures / n`` and its two-sided Wilson score
    interval at ``confidence``, clipped to [0, 1].

    Wilson's interval, not the normal approximation ``p ± z √(p(1−p)/n)``: near p = 0 or 1 (the
    rare failures of a safe design) that one shrinks to zero width at 0 failures and covers far
    less often than it claims, while Wilson's keeps its coverage close to ``confidence``
    there. Its bounds are the two p with ``(failures/n − p)² = z² p (1 − p) / n``.
    """
    if not n > 0:
        raise ValueError(f"n must be positive (got {n})")
    if not 0 <= failures <= n:
        raise ValueError(f"failures must lie in [0, n={n}] (got {failures})")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1) (got {confidence})")
    z = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    z2 = z * z
    centre = (failures + 0.5 * z2) / (n + z2)
    half = z / (n + z2) * math.sqrt(failures * (n - failures) / n + 0.25 * z2)
    # at 0 (or n) failures a bound is exactly 0 (or 1): say so rather than trust the round-off
    lo = 0.0 if failures == 0 else max(0.0, centre - half)
    hi = 1.0 if failures == n else min(1.0, centre + half)
    return failures / n, lo, hi
