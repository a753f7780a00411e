"""Epochs by region of the Stanford diagram (``gnss.integrity_outcomes``) against a per-epoch classification written
from RTCA DO-229's region definitions, on random errors and levels around an alert limit (ties included), and the
diagram that draws them (``plotting.stanford_diagram``)."""

import numpy as np
import pytest

from jaxfdi import gnss, plotting


def regions_by_hand(error, level, al, alarm):
    out = dict.fromkeys(
        (
            "alarms",
            "nominal",
            "misleading",
            "hazardous",
            "unavailable",
            "unavailable_misleading",
            "not_finite",
        ),
        0,
    )
    for e, pl, a in zip(error, level, alarm):
        if not np.isfinite(e) or np.isnan(pl):
            out["not_finite"] += 1
        elif a:
            out["alarms"] += 1
        elif pl >= al:  # an infinite level too: no test, unavailable whatever the limit
            out["unavailable_misleading" if e > pl else "unavailable"] += 1
        elif e <= pl:
            out["nominal"] += 1
        else:
            out["hazardous" if e >= al else "misleading"] += 1
    return out


@pytest.mark.parametrize("alert_limit", [40.0, np.inf])
def test_counts_equal_the_regions_classified_one_epoch_at_a_time(alert_limit):
    rng = np.random.default_rng(3)
    error = rng.choice([10.0, 40.0, 60.0], 400) * rng.choice(
        [1.0, 0.5, 1.5], 400
    )  # ties with AL and PL
    level = rng.choice([5.0, 20.0, 40.0, 80.0], 400)
    error[:5], level[5:8], level[8] = np.nan, np.inf, np.nan
    alarm = rng.random(400) < 0.1
    counts = gnss.integrity_outcomes(error, level, alert_limit, alarm)
    expected = regions_by_hand(error, level, alert_limit, alarm)
    assert counts._asdict() == {"epochs": 400 - 6, **expected}
    assert counts.unavailable + counts.unavailable_misleading >= 3  # the infinite levels
    assert sum(counts) - counts.epochs - counts.not_finite == counts.epochs
    if alert_limit == np.inf:
        assert counts.hazardous == 0 and counts.unavailable + counts.unavailable_misleading <= 3


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="error, level: expected two"):
        gnss.integrity_outcomes(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="alert_limit: expected an alert limit > 0"):
        gnss.integrity_outcomes(np.ones(3), np.ones(3), alert_limit=-40.0)
    with pytest.raises(ValueError, match="alarm: expected an"):
        gnss.integrity_outcomes(np.ones(3), np.ones(3), alarm=np.ones(3))
    with pytest.raises(ValueError, match=">= 0"):
        gnss.integrity_outcomes(-np.ones(3), np.ones(3))


def test_diagram_draws_the_points_and_titles_the_counts():
    error = np.array([1.0, 2.0, 30.0, 45.0, 3.0])
    level = np.array([10.0, 60.0, 20.0, 30.0, 2.0])
    alarm = np.array([False, False, False, False, True])
    fig = plotting.stanford_diagram(error, level, alert_limit=40.0, alarm=alarm, axis="vertical")
    ax = fig.axes[0]
    assert ax.get_title() == "nominal 1, MI 1, HMI 1, unavailable 1"
    assert ax.get_xscale() == ax.get_yscale() == "log" and ax.get_xlabel() == "vertical error [m]"
    points = next(line for line in ax.lines if line.get_label().startswith("epochs"))
    assert np.array_equal(points.get_xdata(), error) and points.get_label() == "epochs (5)"
    assert ax.get_xlim() == pytest.approx((1.0, 100.0))  # the decades of the data
    assert any(line.get_label() == "alarm (1)" for line in ax.lines)
