"""Integrity outcomes of a receiver's epochs: the regions of the Stanford diagram.

Each epoch's position error ``E`` against its protection level ``PL`` and the operation's alert limit ``AL``
(RTCA DO-229; Tossavainen, "Stanford-ESA integrity diagram", ESA 2005). An epoch that alarmed warned its user and is
counted apart; of the others:

* nominal: ``E <= PL < AL``;
* misleading information (MI): ``PL < E < AL``;
* hazardously misleading information (HMI): ``PL < AL <= E``;
* unavailable: ``PL >= AL`` and ``E <= PL``; unavailable and misleading: ``AL <= PL < E``.

An infinite level (too few satellites for a test) is unavailable whatever the limit; with no alert limit (``inf``)
every other quiet epoch is nominal or misleading.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxfdi import checks


class IntegrityOutcomes(NamedTuple):
    """Counts of epochs by region of the Stanford diagram (module doc); they sum to ``epochs``.

    Attributes:
      epochs: epochs counted (a finite error and a level, infinite or not)
      alarms: epochs that alarmed (warned: in no region below)
      nominal: ``E <= PL < AL``
      misleading: ``PL < E < AL``
      hazardous: ``PL < AL <= E``
      unavailable: ``E <= PL``, ``PL >= AL``
      unavailable_misleading: ``AL <= PL < E``
      not_finite: epochs left out: a NaN or infinite error, or a NaN level (no fix)
    """

    epochs: int
    alarms: int
    nominal: int
    misleading: int
    hazardous: int
    unavailable: int
    unavailable_misleading: int
    not_finite: int


def integrity_outcomes(
    error, level, alert_limit: float = float("inf"), alarm=None
) -> IntegrityOutcomes:
    """Count a receiver's epochs by region of the Stanford diagram (module doc).

    Args:
      error: (E,) absolute position errors [m] (horizontal or vertical) against the truth.
      level: (E,) the protection levels on the same axis [m].
      alert_limit: the operation's alert limit on that axis [m] (``gnss.ALERT_LIMITS``); ``inf``: none.
      alarm: (E,) bool, the epochs whose integrity test alarmed; ``None``: none did.

    Returns:
      ``IntegrityOutcomes`` of Python ints.
    """
    error, level = np.asarray(error, float), np.asarray(level, float)
    if error.ndim != 1 or level.shape != error.shape:
        raise ValueError(
            f"error, level: expected two (E,) arrays of one value per epoch, got shapes {error.shape}, {level.shape}"
        )
    if np.any(error < 0) or np.any(level < 0):
        raise ValueError(
            "error, level: expected absolute errors and levels >= 0 [m], got a negative value"
        )
    if not isinstance(alert_limit, (int, float, np.floating, np.integer)) or not alert_limit > 0:
        raise ValueError(
            f"alert_limit: expected an alert limit > 0 [m] (inf: none), got {checks.received(alert_limit)}"
        )
    alert_limit = float(alert_limit)
    alarm = np.zeros(error.shape, bool) if alarm is None else np.asarray(alarm)
    if alarm.shape != error.shape or alarm.dtype != bool:
        raise ValueError(
            f"alarm: expected an (E,) = {error.shape} bool array, got {checks.received(alarm)}"
        )
    finite = np.isfinite(error) & ~np.isnan(level)
    quiet = finite & ~alarm
    available = np.isfinite(level) & (level < alert_limit)
    beyond = error > level

    def count(mask):
        return int(np.sum(quiet & mask))

    return IntegrityOutcomes(
        epochs=int(finite.sum()),
        alarms=int(np.sum(finite & alarm)),
        nominal=count(available & ~beyond),
        misleading=count(available & beyond & (error < alert_limit)),
        hazardous=count(available & beyond & (error >= alert_limit)),
        unavailable=count(~available & ~beyond),
        unavailable_misleading=count(~available & beyond),
        not_finite=int((~finite).sum()),
    )
