"""pdem.analysis.sampling against closed forms: the normal quantile against the standard
library's, each distribution's moments within a few standard errors of a fixed-seed sample,
Latin hypercube strata, Fisher's mean resultant length and cone of confidence, and the Wilson
interval as the roots of its quadratic with its coverage.

A tolerance of "k standard errors" is the closed-form standard error of the statistic for the
sample size used; with fixed seeds the tests are deterministic, and 4 standard errors leaves
each a chance of ~6e-5 of failing for an unlucky seed choice rather than a wrong sampler.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdem.analysis.sampling import (
    Fisher,
    LogNormal,
    Normal,
    Truncated,
    Uniform,
    normal_quantile,
    plane_normal,
    plane_of,
    probability_of,
    uniforms,
)

N = 200_000
STD_NORMAL = NormalDist()


# --- the normal quantile --------------------------------------------------------------------

def test_the_normal_quantile_matches_the_standard_library_to_1e_12():
    u = np.concatenate([np.logspace(-12, -1, 400), np.linspace(0.01, 0.99, 1999),
                        1.0 - np.logspace(-12, -1, 400)])
    want = np.array([STD_NORMAL.inv_cdf(float(v)) for v in u])
    assert np.abs(normal_quantile(u) - want).max() < 1e-12
    # on into the far lower tail (a truncation far out uses it), to 1e-13 relative
    far = np.logspace(-300, -12, 300)
    want = np.array([STD_NORMAL.inv_cdf(float(v)) for v in far])
    assert np.abs(normal_quantile(far) / want - 1.0).max() < 1e-13


@pytest.mark.parametrize("u", [0.0, 1.0, -0.1, math.nan])
def test_the_normal_quantile_refuses_u_outside_the_open_interval(u):
    with pytest.raises(ValueError, match="u must lie in"):
        normal_quantile([0.5, u])


# --- moments ----------------------------------------------------------------------------------

def _lognormal_kurtosis(cv: float) -> float:
    """Non-excess kurtosis of a lognormal variable with coefficient of variation ``cv``."""
    s2 = math.log1p(cv * cv)
    return math.exp(4 * s2) + 2 * math.exp(3 * s2) + 3 * math.exp(2 * s2) - 3


@pytest.mark.parametrize("dist, mean, std, kurtosis", [
    (Normal(30.0, 4.0), 30.0, 4.0, 3.0),
    # the variable's own mean and std, not its logarithm's
    (LogNormal(2.0e9, 5.0e8), 2.0e9, 5.0e8, _lognormal_kurtosis(0.25)),
    (LogNormal(10.0, 8.0), 10.0, 8.0, _lognormal_kurtosis(0.8)),
    (Uniform(10.0, 40.0), 25.0, 30.0 / math.sqrt(12.0), 1.8),
])
def test_sample_mean_and_std_within_four_standard_errors(dist, mean, std, kurtosis):
    x = dist.from_uniform(uniforms(N, 1, seed=7))
    assert x.shape == (N,)
    # standard errors: of the mean std/sqrt(N); of the sample std std sqrt((kurtosis - 1)/(4N))
    assert abs(x.mean() - mean) < 4 * std / math.sqrt(N)
    assert abs(x.std(ddof=1) - std) < 4 * std * math.sqrt((kurtosis - 1.0) / (4 * N))


def test_lognormal_log_parameters_are_the_closed_form_conversion():
    d = LogNormal(50.0, 20.0)
    mu, sigma = d.log_params
    assert sigma ** 2 == pytest.approx(math.log(1 + (20.0 / 50.0) ** 2), rel=1e-14)
    assert mu == pytest.approx(math.log(50.0) - sigma ** 2 / 2, rel=1e-14)
    # the median of a lognormal is exp(mu): u = 1/2 maps to it
    assert d.from_uniform(np.array([[0.5]]))[0] == pytest.approx(math.exp(mu), rel=1e-14)


# --- truncation -------------------------------------------------------------------------------

def _truncated_normal_moments(mu, sigma, lo, hi):
    """Mean and std of N(mu, sigma) restricted to [lo, hi] (closed form)."""
    a, b = (lo - mu) / sigma, (hi - mu) / sigma
    pa, pb = STD_NORMAL.pdf(a) if a > -math.inf else 0.0, STD_NORMAL.pdf(b) if b < math.inf else 0.0
    # Q(a) - Q(b) through erfc: exact in the upper tail, where Phi(b) - Phi(a) would cancel
    mass = 0.5 * (math.erfc(a / math.sqrt(2)) - math.erfc(b / math.sqrt(2)))
    ta = a * pa if a > -math.inf else 0.0
    tb = b * pb if b < math.inf else 0.0
    mean = mu + sigma * (pa - pb) / mass
    var = sigma ** 2 * (1 + (ta - tb) / mass - ((pa - pb) / mass) ** 2)
    return mean, math.sqrt(var)


@pytest.mark.parametrize("lo, hi", [(27.0, 40.0), (20.0, 30.5), (-math.inf, 25.0), (42.0, math.inf)])
def test_a_truncated_normal_stays_in_bounds_with_the_closed_form_mean(lo, hi):
    mu, sigma = 30.0, 5.0
    d = Truncated(Normal(mu, sigma), None if lo == -math.inf else lo, None if hi == math.inf else hi)
    x = d.from_uniform(uniforms(N, 1, seed=3))
    assert x.min() >= lo and x.max() <= hi
    mean, std = _truncated_normal_moments(mu, sigma, lo, hi)
    assert abs(x.mean() - mean) < 4 * std / math.sqrt(N)  # 4 standard errors of the mean


def test_a_truncation_far_in_the_upper_tail_samples_its_closed_form_mean():
    # 1 - Phi(9) = 1e-19 is below the spacing of doubles next to 1: through F(low) = Phi(9),
    # which rounds to 1, the window would hold nothing; mirrored, its probabilities are exact
    x = Truncated(Normal(0.0, 1.0), 9.0, 9.5).from_uniform(uniforms(N, 1, seed=5))
    mean, std = _truncated_normal_moments(0.0, 1.0, 9.0, 9.5)
    assert x.min() >= 9.0 and x.max() <= 9.5
    assert abs(x.mean() - mean) < 4 * std / math.sqrt(N)


def test_a_truncated_lognormal_stays_in_bounds_and_keeps_the_median_when_symmetric_in_probability():
    base = LogNormal(1.0, 0.5)
    x = Truncated(base, None, 1.2).from_uniform(uniforms(20_000, 1, 4))
    assert x.min() > 0.0 and x.max() <= 1.2
    mu, s = base.log_params
    lo, hi = math.exp(mu - s), math.exp(mu + s)  # the 16th and 84th percentiles
    y = Truncated(base, lo, hi).from_uniform(np.array([[1e-300], [0.5], [1.0 - 1e-16]]))
    assert y[0] == pytest.approx(lo, rel=1e-12) and y[2] == pytest.approx(hi, rel=1e-12)
    assert y[1] == pytest.approx(math.exp(mu), rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(mean=st.floats(-100, 100), std=st.floats(0.01, 50), a=st.floats(-9, 9), width=st.floats(0.05, 10),
       log=st.booleans())
def test_any_truncation_is_increasing_in_u_and_within_its_bounds(mean, std, a, width, log):
    if log:
        base = LogNormal(abs(mean) + 1.0, std)
        mu, s = base.log_params
        low, high = math.exp(mu + a * s), math.exp(mu + (a + width) * s)
    else:
        base = Normal(mean, std)
        low, high = mean + a * std, mean + (a + width) * std
    if high <= low:  # the width lost to round-off next to a large mean
        return
    u = np.sort(uniforms(200, 1, seed=0), axis=0)
    x = Truncated(base, low, high).from_uniform(u)
    assert np.all(np.isfinite(x)) and x.min() >= low and x.max() <= high
    assert np.all(np.diff(x) >= 0.0)


# --- Latin hypercube and seeds ----------------------------------------------------------------

def test_latin_hypercube_puts_exactly_one_point_in_each_stratum():
    n, dims = 100, 4
    u = uniforms(n, dims, seed=11, latin=True)
    assert u.shape == (n, dims) and u.min() > 0.0 and u.max() < 1.0
    strata = np.floor(u * n).astype(int)
    for j in range(dims):
        assert sorted(strata[:, j]) == list(range(n))
    # independently permuted columns, jittered inside the strata (not at their centres)
    assert len({tuple(strata[:, j]) for j in range(dims)}) == dims
    assert np.ptp(u * n - strata) > 0.5


def test_latin_hypercube_pins_the_mean_far_inside_three_standard_errors():
    # plain Monte Carlo's mean of n standard normals has standard error 1/sqrt(n); the Latin
    # hypercube's is set by the spread inside the strata (~0.006 at n = 100, the tails' strata)
    n, seeds = 100, 200
    latin = np.array([Normal(0.0, 1.0).from_uniform(uniforms(n, 1, s, latin=True)).mean()
                      for s in range(seeds)])
    plain = np.array([Normal(0.0, 1.0).from_uniform(uniforms(n, 1, s)).mean() for s in range(seeds)])
    se = 1.0 / math.sqrt(n)
    assert np.abs(latin).max() < 0.1 * 3 * se
    # the plain means do spread by their standard error (the RMS of 200 is within 4 of its own
    # relative standard errors, 1/sqrt(2*200) = 5 %), so the comparison above is a fair one
    assert abs(math.sqrt(np.mean(plain ** 2)) / se - 1.0) < 0.2


@pytest.mark.parametrize("latin", [False, True])
def test_the_same_seed_gives_the_same_bits_and_another_seed_others(latin):
    a = uniforms(500, 3, 5, latin=latin)
    assert np.array_equal(a, uniforms(500, 3, 5, latin=latin))
    b = uniforms(500, 3, 6, latin=latin)
    assert not np.any(a == b)
    assert a.min() > 0.0 and a.max() < 1.0
    assert uniforms(0, 3, 5, latin=latin).shape == (0, 3)


def test_from_uniform_checks_the_shape_of_its_uniforms():
    assert Normal(0.0, 1.0).dims == 1 and Fisher(30.0, 0.0, 10.0).dims == 2
    with pytest.raises(ValueError, match=r"shape \(n, 1\)"):
        Normal(0.0, 1.0).from_uniform(uniforms(5, 2, 1))
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        Fisher(30.0, 0.0, 10.0).from_uniform(uniforms(5, 1, 1))


# --- Fisher -----------------------------------------------------------------------------------

def _fisher_mean_cos(kappa: float) -> float:
    """E[cos theta] = coth(kappa) - 1/kappa, the mean resultant length."""
    return 1.0 / math.tanh(kappa) - 1.0 / kappa


def _fisher_within(kappa: float, angle: float) -> float:
    """P(theta <= angle) (radians) = (1 - exp(-kappa (1 - cos angle))) / (1 - exp(-2 kappa))."""
    return -math.expm1(-kappa * (1.0 - math.cos(angle))) / -math.expm1(-2.0 * kappa)


@pytest.mark.parametrize("kappa, dip, dd", [(20.0, 10.0, 200.0), (50.0, 45.0, 300.0)])
def test_fisher_poles_have_the_closed_form_mean_resultant_and_point_at_the_mean_plane(kappa, dip, dd):
    # the mean planes dip little enough that a flipped pole (theta > 90 - dip) is below 1e-6
    s = Fisher(dip, dd, kappa).from_uniform(uniforms(N, 2, seed=2))
    assert s.shape == (N, 2)
    assert s[:, 0].min() >= 0.0 and s[:, 0].max() <= 90.0
    assert s[:, 1].min() >= 0.0 and s[:, 1].max() < 360.0
    resultant = plane_normal(s[:, 0], s[:, 1]).mean(axis=0)
    r = np.linalg.norm(resultant)
    mean_cos = _fisher_mean_cos(kappa)
    var_cos = 1.0 / kappa ** 2 - 1.0 / math.sinh(kappa) ** 2
    assert abs(r - mean_cos) < 4 * math.sqrt(var_cos / N)
    # the mean direction: each transverse component has variance E[sin^2 theta]/2 = mean_cos/kappa,
    # so its angle from the mean pole is Rayleigh with sigma = sqrt(mean_cos/(kappa N)) / mean_cos
    sigma = math.sqrt(mean_cos / (kappa * N)) / mean_cos
    angle = math.acos(min(1.0, float(resultant @ plane_normal(dip, dd)) / r))
    assert angle < 4 * sigma
    # and reported as the mean plane: an angle moves the dip by as much and the dip direction
    # by up to angle / sin(dip)
    mdip, mdd = plane_of(resultant[None])
    bound = math.degrees(4 * sigma)
    assert abs(mdip[0] - dip) < bound and abs(mdd[0] - dd) < bound / math.sin(math.radians(dip))


@pytest.mark.parametrize("kappa", [20.0, 200.0])
def test_fisher_about_a_vertical_plane_fills_its_cone_and_reports_dips_up_to_90(kappa):
    n = 20_000
    d = Fisher(90.0, 90.0, kappa)
    u = uniforms(n, 2, seed=9)
    s = d.from_uniform(u)
    assert s[:, 0].min() >= 0.0 and s[:, 0].max() <= 90.0
    assert s[:, 1].min() >= 0.0 and s[:, 1].max() < 360.0
    # the mean pole is horizontal: half the sampled poles point down and are flipped, the
    # plane then dips the other way (toward 270)
    down = d.poles(u)[:, 2] < 0.0
    assert abs(down.mean() - 0.5) < 4 * math.sqrt(0.25 / n)
    assert np.all(np.abs(s[down, 1] - 270.0) < 90.0) and np.all(np.abs(s[~down, 1] - 90.0) < 90.0)
    # the fraction within the 95 % cone of the closed form, up to the plane's sense
    cone = math.acos(1.0 + math.log(0.05) / kappa)
    assert _fisher_within(kappa, cone) == pytest.approx(0.95, rel=1e-12)
    cos = np.abs(plane_normal(s[:, 0], s[:, 1]) @ plane_normal(90.0, 90.0))
    assert abs(np.mean(cos >= math.cos(cone)) - 0.95) < 4 * math.sqrt(0.95 * 0.05 / n)


def test_fisher_about_a_horizontal_plane_dips_as_theta_in_every_direction():
    n, kappa = 20_000, 100.0
    s = Fisher(0.0, 0.0, kappa).from_uniform(uniforms(n, 2, seed=1))
    # dip = theta: the fraction within each angle is the closed form's (4 binomial standard errors)
    for deg in (3.0, 8.0, 15.0):
        p = _fisher_within(kappa, math.radians(deg))
        assert abs(np.mean(s[:, 0] <= deg) - p) < 4 * math.sqrt(p * (1 - p) / n) + 1e-12
    # dip directions uniform on the circle: mean cos and sin 0 within 4 standard errors sqrt(1/(2n))
    a = np.radians(s[:, 1])
    assert abs(np.cos(a).mean()) < 4 * math.sqrt(0.5 / n) and abs(np.sin(a).mean()) < 4 * math.sqrt(0.5 / n)


def test_a_large_kappa_concentrates_the_poles_about_the_mean_pole():
    n = 2000
    m = plane_normal(60.0, 135.0)
    spread = {}
    for kappa in (10.0, 1000.0):
        s = Fisher(60.0, 135.0, kappa).from_uniform(uniforms(n, 2, seed=4))
        spread[kappa] = np.degrees(np.arccos(np.clip(plane_normal(s[:, 0], s[:, 1]) @ m, -1, 1)))
    # P(theta > 10 deg) = exp(-1000 (1 - cos 10 deg)) = 2.5e-7 at kappa 1000: none of 2000
    assert spread[1000.0].max() < 10.0 and spread[10.0].max() > 30.0
    # the median angle falls as 1/sqrt(kappa): the closed form's ratio within 10 %
    want = math.acos(1.0 + math.log(0.5) / 10.0) / math.acos(1.0 + math.log(0.5) / 1000.0)
    assert np.median(spread[10.0]) / np.median(spread[1000.0]) == pytest.approx(want, rel=0.1)


def test_plane_of_inverts_plane_normal_for_either_sense():
    dip = np.array([0.0, 1e-9, 30.0, 89.0, 90.0, 45.0])
    dd = np.array([0.0, 10.0, 359.5, 180.0, 270.0, 0.0])
    n = plane_normal(dip, dd)
    for sense in (1.0, -1.0):
        got_dip, got_dd = plane_of(sense * n)
        assert np.allclose(got_dip, dip, atol=1e-12)
        keep = dip > 0
        if sense < 0:  # a vertical plane's other pole reports the opposite dip direction
            keep &= dip < 90
        assert np.allclose(got_dd[keep], dd[keep], atol=1e-9)


# --- the probability and its Wilson interval --------------------------------------------------

def _wilson_roots(k: int, n: int, confidence: float) -> tuple[float, float]:
    """The two p with (k/n - p)^2 = z^2 p (1 - p) / n, by the quadratic formula."""
    z = STD_NORMAL.inv_cdf(0.5 + confidence / 2)
    ph = k / n
    a, b, c = 1 + z * z / n, -(2 * ph + z * z / n), ph * ph
    root = math.sqrt(b * b - 4 * a * c)
    return (-b - root) / (2 * a), (-b + root) / (2 * a)


@pytest.mark.parametrize("k, n, confidence", [(30, 200, 0.95), (3, 50, 0.9), (999, 1000, 0.99)])
def test_the_wilson_interval_is_the_roots_of_its_quadratic(k, n, confidence):
    p, lo, hi = probability_of(k, n, confidence)
    want_lo, want_hi = _wilson_roots(k, n, confidence)
    assert p == k / n
    assert lo == pytest.approx(want_lo, rel=1e-12) and hi == pytest.approx(want_hi, rel=1e-12)


def test_no_failures_give_a_zero_lower_bound_and_a_positive_upper_one():
    z = STD_NORMAL.inv_cdf(0.975)
    p, lo, hi = probability_of(0, 200)
    assert p == 0.0 and lo == 0.0 and hi > 0.0
    assert hi == pytest.approx(z * z / (200 + z * z), rel=1e-12)  # the quadratic's root at k = 0
    p, lo, hi = probability_of(200, 200)
    assert p == 1.0 and hi == 1.0 and lo == pytest.approx(200 / (200 + z * z), rel=1e-12)


def test_the_wilson_interval_covers_as_it_claims():
    p, n, draws = 0.1, 200, 2000
    covers = {k: (lambda b: b[1] <= p <= b[2])(probability_of(k, n)) for k in range(n + 1)}
    exact = sum(math.comb(n, k) * p ** k * (1 - p) ** (n - k) for k in range(n + 1) if covers[k])
    assert 0.93 <= exact <= 0.97
    k = np.random.default_rng(1).binomial(n, p, size=draws)
    simulated = np.mean([covers[int(x)] for x in k])
    assert 0.93 <= simulated <= 0.97
    assert abs(simulated - exact) < 4 * math.sqrt(exact * (1 - exact) / draws)


# --- descriptions and bad parameters ----------------------------------------------------------

def test_descriptions_name_the_distribution_and_its_parameters():
    assert Normal(30.0, 3.0).describe() == "normal(mean=30, std=3)"
    assert LogNormal(2e9, 5e8).describe() == "lognormal(mean=2e+09, std=5e+08)"
    assert Uniform(10, 40).describe() == "uniform(low=10, high=40)"
    assert Truncated(Normal(30.0, 3.0), 20.0, None).describe() == \
        "normal(mean=30, std=3) truncated to [20, inf]"
    assert Fisher(60, 135, 25).describe() == "fisher(dip=60, dip_direction=135, kappa=25)"


@pytest.mark.parametrize("make, pattern", [
    (lambda: Normal(1.0, 0.0), r"std .*\(got 0\.0\)"),
    (lambda: Normal(1.0, -2.0), r"std .*\(got -2\.0\)"),
    (lambda: Normal(math.nan, 1.0), r"mean .*\(got nan\)"),
    (lambda: LogNormal(-1.0, 1.0), r"mean .*\(got -1\.0\)"),
    (lambda: LogNormal(0.0, 1.0), r"mean .*\(got 0\.0\)"),
    (lambda: LogNormal(1.0, 0.0), r"std .*\(got 0\.0\)"),
    (lambda: Uniform(2.0, 1.0), r"high must be above low \(got low=2\.0, high=1\.0\)"),
    (lambda: Uniform(1.0, 1.0), r"high must be above low \(got low=1\.0, high=1\.0\)"),
    (lambda: Truncated(Normal(0.0, 1.0), 3.0, 3.0), r"high must be above low \(got low=3\.0, high=3\.0\)"),
    (lambda: Truncated(Normal(0.0, 1.0), 50.0, 60.0), r"low=50\.0, high=60\.0 hold no probability"),
    (lambda: Truncated(Uniform(0.0, 1.0), 0.2, 0.5), r"base must be a Normal or LogNormal"),
    (lambda: Fisher(95.0, 0.0, 10.0), r"dip .*\(got 95\.0\)"),
    (lambda: Fisher(-1.0, 0.0, 10.0), r"dip .*\(got -1\.0\)"),
    (lambda: Fisher(45.0, math.inf, 10.0), r"dip_direction .*\(got inf\)"),
    (lambda: Fisher(45.0, 0.0, 0.0), r"kappa .*\(got 0\.0\)"),
    (lambda: Fisher(45.0, 0.0, -3.0), r"kappa .*\(got -3\.0\)"),
    (lambda: probability_of(0, 0), r"n must be positive \(got 0\)"),
    (lambda: probability_of(11, 10), r"failures .*\(got 11\)"),
    (lambda: probability_of(1, 10, 1.5), r"confidence .*\(got 1\.5\)"),
    (lambda: probability_of(1, 10, 0.0), r"confidence .*\(got 0\.0\)"),
    (lambda: uniforms(-1, 2, 0), r"n must not be negative \(got -1\)"),
])
def test_bad_parameters_raise_naming_the_parameter_and_its_value(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()
