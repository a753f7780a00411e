"""Thresholds calibrated on fault-free runs, where the statistic's law is only approximate.

A chi-square threshold assumes white Gaussian innovations; a closed loop, an unmodelled disturbance or a wavelet
denoiser makes the fault-free statistic heavier-tailed. Two calibrations:

* per decision, ``T = max(T_law, q_{1 - P_fa})``: the law's threshold raised to the empirical ``1 - P_fa`` quantile of
  fault-free decisions (``empirical_threshold``);
* per run: ``K`` decisions alarm with probability up to ``K P_fa``, so a family-wise rate needs the smallest common
  factor ``s >= 1`` with ``rate(s T) <= alpha`` on calibration runs (bisection, ``scale_to_run_false_alarm``).

Used by the VTOL study (Lee & Lyou): its two-stage filter bank sees the ``3 sin 10 t`` disturbance leak in.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from jaxfdi import checks

__all__ = ["empirical_threshold", "scale_to_run_false_alarm"]


def empirical_threshold(values, pfa: float, floor=None) -> np.ndarray:
    """``max(floor, q_{1 - pfa})``: empirical upper ``pfa`` quantile of fault-free decision ``values`` over their
    leading (sample) axis (``numpy.quantile``'s linear interpolation), raised to ``floor`` (the law's threshold,
    broadcast; ``None``: none). Non-finite values (a bad calibration run) are refused: a NaN threshold never alarms.

    Returns:
      NumPy array of ``values``' trailing shape (``values.shape[1:]`` broadcast with ``floor``): the threshold per
      decision, in the statistic's units.
    """
    checks.check_probability("pfa", pfa)
    values = np.asarray(values)
    if values.ndim == 0 or values.shape[0] < 1:
        raise ValueError(f"values: expected samples along a leading axis, got shape {values.shape}")
    if not np.all(
        np.isfinite(values)
    ):  # a NaN would make the threshold NaN: a detector that never alarms
        raise ValueError(
            f"values: expected finite fault-free decision values, got {int(np.sum(~np.isfinite(values)))} "
            f"non-finite (a calibration run went bad)"
        )
    quantile = np.quantile(values, 1.0 - pfa, axis=0)
    return quantile if floor is None else np.maximum(np.asarray(floor), quantile)


def scale_to_run_false_alarm(
    rate: Callable[[np.ndarray], np.ndarray],
    target: float,
    groups: int,
    upper: float = 16.0,
    iterations: int = 40,
) -> np.ndarray:
    """(groups,) the smallest factors ``s >= 1`` with ``rate(s)[g] <= target``, by bisection.

    ``rate(scales (groups,)) -> (groups,)``: each group's share of fault-free runs with any alarm at thresholds times
    ``scales[g]`` (non-increasing). A group within ``target`` at 1 keeps 1; otherwise ``[1, upper]`` is halved
    ``iterations`` times and its upper end returned (within ``(upper - 1) 2^-iterations`` of the smallest factor, on
    the rate's steps). ``ValueError`` when a group exceeds ``target`` even at ``upper``, or a rate is not in [0, 1] (a
    NaN from a bad run never meets the target).

    Returns:
      (groups,) NumPy float factors in ``[1, upper]`` to multiply each group's thresholds by.
    """
    if not 0.0 <= target < 1.0:
        raise ValueError(f"target: expected a rate in [0, 1), got {target}")
    if not upper > 1.0:
        raise ValueError(f"upper: expected a factor above 1, got {upper}")
    low, high = np.ones(groups), np.full(groups, float(upper))

    def rate(scale, _rate=rate):
        rates = np.asarray(_rate(scale))
        if not np.all(
            (rates >= 0.0) & (rates <= 1.0)
        ):  # NaN included: never read as "within the target"
            raise ValueError(f"rate: expected rates in [0, 1], got {rates}")
        return rates

    at_upper = rate(high)
    if np.any(at_upper > target):
        raise ValueError(
            f"target: {target} is not reached even with the thresholds scaled by {upper} "
            f"(rates {at_upper})"
        )
    high[rate(low) <= target] = 1.0
    for _ in range(int(iterations)):  # invariant: rate(high) <= target < rate(low), where high > 1
        mid = 0.5 * (low + high)
        ok = rate(mid) <= target
        high, low = np.where(ok, mid, high), np.where(ok, low, mid)
    return high
