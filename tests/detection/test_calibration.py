"""Thresholds calibrated on fault-free runs (``jaxfdi.detection._calibration``): the
empirical quantile against the chi-square law it estimates (scipy) and against its
defining counts, and the per-run scaling against the closed form of the smallest factor
(an order statistic of the runs' maxima)."""

import numpy as np
import pytest
from scipy import stats

from jaxfdi.detection import empirical_threshold, scale_to_run_false_alarm


def test_empirical_threshold_estimates_the_laws_quantile_and_keeps_the_floor():
    """On 4e5 chi2(3) draws per column the 1 - 0.005 quantile is within 2 % of scipy's
    isf (its standard error there is about 0.4 %); at most pfa of the samples lie above
    it and at least pfa at or above; a floor above the quantile wins, per column."""
    rng = np.random.default_rng(0)
    pfa, n = 0.005, 400_000
    values = rng.chisquare(3, size=(n, 2))
    threshold = empirical_threshold(values, pfa)
    np.testing.assert_allclose(threshold, stats.chi2.isf(pfa, 3), rtol=0.02)
    assert np.all(np.mean(values > threshold, axis=0) <= pfa)
    assert np.all(np.mean(values >= threshold, axis=0) >= pfa)
    floored = empirical_threshold(values, pfa, floor=np.array([0.0, 100.0]))
    np.testing.assert_array_equal(floored, [threshold[0], 100.0])
    with pytest.raises(ValueError, match="pfa"):
        empirical_threshold(values, 1.5)
    with pytest.raises(ValueError, match="values"):
        empirical_threshold(np.float64(3.0), 0.1)
    dead = values.copy()
    dead[17, 1] = np.nan  # one calibration run's channel went NaN: refused, not a NaN threshold
    with pytest.raises(ValueError, match="values: expected finite .* 1 non-finite"):
        empirical_threshold(dead, pfa)


def test_run_scaling_is_the_smallest_factor_meeting_the_rate():
    """rate(s)[g] = share of runs whose largest statistic exceeds s x threshold. With
    ``j = floor(alpha n)`` allowed alarms the smallest factor is ``max(1, m_(j+1))``,
    the (j+1)-th largest of the runs' maxima over the threshold; bisection returns it to
    within its bracket's width. A group already within the rate keeps 1."""
    rng = np.random.default_rng(1)
    runs, steps, alpha = 200, 50, 0.05
    stat = rng.chisquare(4, size=(3, runs, steps)) * np.array([1.0, 1.6, 0.2])[:, None, None]
    thresholds = np.array([14.86, 14.86, 14.86])
    maxima = stat.max(axis=2) / thresholds[:, None]  # (3, runs)

    def rate(scale):
        return np.mean(maxima > np.asarray(scale)[:, None], axis=1)

    scale = scale_to_run_false_alarm(rate, alpha, 3)
    j = int(np.floor(alpha * runs))
    exact = np.maximum(1.0, -np.sort(-maxima, axis=1)[:, j])
    assert np.all(rate(scale) <= alpha)
    assert np.all(scale >= exact) and np.all(scale - exact <= 15.0 * 2.0**-40 * 2)
    assert scale[2] == 1.0 and np.all(scale[:2] > 1.0)


def test_run_scaling_refuses_what_it_cannot_reach():
    with pytest.raises(ValueError, match="target: 0.01 is not reached"):
        scale_to_run_false_alarm(lambda s: np.full(2, 0.5), 0.01, 2)
    with pytest.raises(ValueError, match="target"):
        scale_to_run_false_alarm(lambda s: np.zeros(2), 1.0, 2)
    with pytest.raises(
        ValueError, match="rate: expected rates in"
    ):  # a NaN rate is not "within the target"
        scale_to_run_false_alarm(lambda s: np.array([0.0, np.nan]), 0.1, 2)
    with pytest.raises(ValueError, match="upper"):
        scale_to_run_false_alarm(lambda s: np.zeros(2), 0.1, 2, upper=1.0)
