"""Unhealthy runs in the engine studies' rows and tables: counted, left out of the rates,
and announced by a WARNING line; a healthy study's table has no such line."""
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi.faults import NEVER
from jaxfdi.metrics import DetectionRecord
from jaxfdi.models import engine_model
from jaxfdi.scenarios.engine import EngineStudy, summarize_method
from jaxfdi.scenarios.engine_chi2 import engine_chi2_study

SMALL = dict(runs=1, seed=0, duration=0.2, onset_time=0.1, chunk_size=8)


@pytest.fixture(scope="module")
def broken_chi2_study():
    """The smallest engine-chi2 study (1 run per fault, 20 steps) with a valid but absurd
    filter Q = 1e300 * ones(7, 7) (rank one, positive semi-definite; the study also starts
    the filter from P0 = Q): the plant's R (~1e-4) is lost in the rounding of 1e300, so the
    first innovation covariance S = C P C^T + R is exactly rank one and its Cholesky factor
    is not finite: every run's filter goes bad at step 0, on any CPU. (Q = 1e300 I, used
    before, overflowed on an Intel VM but gave finite, tiny statistics on an AMD one; an
    indefinite R, used before that, is refused at trace time: issue 22.)"""
    model = engine_model()
    return engine_chi2_study(**SMALL, filter_noise=(1e300 * jnp.ones((7, 7)), model.R))


def test_engine_chi2_table_reports_unhealthy_runs(broken_chi2_study):
    broken = broken_chi2_study
    assert np.all(np.asarray(broken.records.first_unhealthy) == 0)
    assert [r["unhealthy_runs"] for r in broken.rows] == [1] * 7 and [r["runs"] for r in broken.rows] == [1] * 7
    for r in broken.rows:  # never a clean run: no rate, no delay
        assert all(np.isnan(r[k]) for k in ("detection_rate", "false_alarm_rate", "delay_median_s"))
    lines = broken.table().splitlines()
    assert len(lines) == 2 + 7 + 1 and lines[0].startswith("fault      magnitude det. rate")
    assert lines[-1].startswith("WARNING: 7 of 7 runs went numerically bad (filter unhealthy or non-finite "
                                "statistic: actuator 1, RPM 1, P2 1")
    assert "excluded from the rates above" in lines[-1]
    # the same rows with every run healthy: the same table without the line
    clean = broken._replace(rows=[dict(r, unhealthy_runs=0) for r in broken.rows]).table()
    assert "WARNING" not in clean and clean.splitlines() == lines[:-1]


def test_engine_rows_and_table_leave_unhealthy_runs_out():
    """Two runs per case; run 1 of the actuator case and of the fault-free case went bad
    (the bad fault-free run alarmed early, the bad actuator run isolated P2)."""
    runs, onset = 2, 200
    cases = 7
    onsets = np.repeat([onset] * 6 + [NEVER], runs)
    first_unhealthy = np.full(cases * runs, -1)
    first_unhealthy[[1, 13]] = [150, 5]
    isolated = np.repeat(np.arange(1, 8), runs)
    isolated[1] = 3
    records = DetectionRecord(
        onset=onsets, first_alarm=np.where(onsets < NEVER, onset + 2, -1),
        detection_step=np.where(onsets < NEVER, onset + 2, -1),
        false_alarms=np.zeros(cases * runs, int), pre_onset_steps=np.minimum(onsets, 400), isolated=isolated,
        first_label=isolated, estimate=np.full(cases * runs, np.nan), first_unhealthy=first_unhealthy)
    records.first_alarm[13], records.false_alarms[13] = 10, 4
    rows = summarize_method("M", None, records, runs, 400)
    by_fault = {r["fault"]: r for r in rows}
    assert by_fault["actuator"]["unhealthy_runs"] == 1 and by_fault["none"]["unhealthy_runs"] == 1
    assert by_fault["actuator"]["isolation_rate"] == 1.0 and by_fault["actuator"]["runs"] == 2
    assert by_fault["none"]["false_alarm_rate"] == 0.0 and by_fault["none"]["false_alarm_steps_per_run"] == 0.0
    assert sum(r["unhealthy_runs"] for r in rows) == 2
    table = EngineStudy({}, rows, {"M": records}, {}).table()
    assert table.splitlines()[-1].startswith("WARNING: M: 2 of 14 runs went numerically bad")
    assert "statistic: actuator 1, none 1); they are excluded" in table
    clean = EngineStudy({}, [dict(r, unhealthy_runs=0) for r in rows], {"M": records}, {}).table()
    assert "WARNING" not in clean and clean.splitlines() == table.splitlines()[:-1]
