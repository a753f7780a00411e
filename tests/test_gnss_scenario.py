"""The seed-002 GPS scenario end to end (small): the campus case's HDOP > 4 and HPL > 556 m
where the wall hides the eastern sky while the parity test stays quiet, the park case's
Table 2 faults detected, isolated and excluded, JSON-ready rows and the figures."""
import json

import numpy as np
import pytest

from jaxfdi.scenarios.gnss_campus import gnss_campus_study, plot_gnss_campus


@pytest.fixture(scope="module")
def study():
    return gnss_campus_study(runs=2, seed=0, all_satellites=False, beyond=False)


def test_campus_geometry_not_the_statistic(study):
    campus = study.rows[0]
    assert campus["case"] == "campus"
    high, over = set(campus["hdop_over_4_epochs"]), set(campus["hpl_over_556_epochs"])
    assert len(high) >= 10 and len(over) >= 8 and over <= high | {e + 1 for e in high} | {e - 1 for e in high}
    assert {480, 790} <= over                                   # the paper's epochs
    assert campus["alarm_rate_where_hpl_over"] == 0.0           # the parity test cannot see geometry
    assert campus["horizontal_error_p95_where_hpl_over_m"] > 3 * campus["horizontal_error_p95_elsewhere_m"]
    assert campus["unhealthy_epochs"] == 0 and 0.95 < campus["availability_npa"] < 1.0


def test_park_faults_detected_isolated_excluded(study):
    park = [r for r in study.rows if r["case"] == "park"]
    assert len(park) == 3 and all(r["headline"] for r in park)
    by_fault = {r["fault"].split()[0]: r for r in park}
    assert by_fault["impulse"]["detected"] == 1.0 and by_fault["bias"]["detected"] == 1.0
    assert by_fault["impulse"]["excluded"] == 1.0 and by_fault["bias"]["isolated"] == 1.0
    assert by_fault["drift"]["detected"] == 1.0 and 10 <= by_fault["drift"]["delay_median_s"] <= 60
    assert float(np.max(study.park["hdop"])) < 1.8 and float(np.max(study.park["hpl"])) < 556.0
    json.dumps({"config": study.config, "rows": study.rows})      # JSON-ready
    assert "Campus" in study.table() and "impulse 100 m at 100 s" in study.table()


def test_figures(study, tmp_path):
    paths = plot_gnss_campus(study, tmp_path)
    assert len(paths) == 3 and all((tmp_path / p.split("/")[-1]).stat().st_size > 10_000 for p in paths)
