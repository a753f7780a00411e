"""Unhealthy runs in the engine studies' rows and tables: counted, left out of the rates,
and announced by a WARNING line; a healthy study's table has no such line."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi import NEVER, DetectionRecord
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
    assert [r["unhealthy_runs"] for r in broken.rows] == [1] * 7 and [
        r["runs"] for r in broken.rows
    ] == [1] * 7
    for r in broken.rows:  # never a clean run: no rate, no delay
        assert all(np.isnan(r[k]) for k in ("detection_rate", "false_alarm_rate", "delay_median_s"))
    lines = broken.table().splitlines()
    assert len(lines) == 2 + 7 + 1 and lines[0].split()[:4] == ["fault", "magnitude", "n", "det."]
    assert all(line.split()[2] == "0" for line in lines[2:-1])  # no healthy run behind any rate
    assert lines[-1].startswith(
        "WARNING: 7 of 7 runs went numerically bad (filter unhealthy or non-finite "
        "statistic: actuator 1, RPM 1, P2 1"
    )
    assert "excluded from the rates above" in lines[-1]
    # the same rows with every run healthy: no warning line, and the run count is the runs'
    clean = (
        broken._replace(rows=[dict(r, unhealthy_runs=0) for r in broken.rows]).table().splitlines()
    )
    assert not any("WARNING" in line for line in clean) and len(clean) == len(lines) - 1
    assert all(line.split()[2] == "1" for line in clean[2:])
    assert [line.split()[:2] for line in clean] == [line.split()[:2] for line in lines[:-1]]


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
        onset=onsets,
        first_alarm=np.where(onsets < NEVER, onset + 2, -1),
        detection_step=np.where(onsets < NEVER, onset + 2, -1),
        false_alarms=np.zeros(cases * runs, int),
        pre_onset_steps=np.minimum(onsets, 400),
        isolated=isolated,
        first_label=isolated,
        estimate=np.full(cases * runs, np.nan),
        first_unhealthy=first_unhealthy,
    )
    records.first_alarm[13], records.false_alarms[13] = 10, 4
    rows = summarize_method("M", None, records, runs, 400)
    by_fault = {r["fault"]: r for r in rows}
    assert by_fault["actuator"]["unhealthy_runs"] == 1 and by_fault["none"]["unhealthy_runs"] == 1
    assert by_fault["actuator"]["isolation_rate"] == 1.0 and by_fault["actuator"]["runs"] == 2
    assert (
        by_fault["none"]["false_alarm_rate"] == 0.0
        and by_fault["none"]["false_alarm_steps_per_run"] == 0.0
    )
    assert sum(r["unhealthy_runs"] for r in rows) == 2
    table = EngineStudy({}, rows, {"M": records}, {}).table()
    assert table.splitlines()[-1].startswith("WARNING: M: 2 of 14 runs went numerically bad")
    assert "statistic: actuator 1, none 1); they are excluded" in table
    # the same rows with every run healthy: no warning line; the rates' run counts are the runs'
    clean = (
        EngineStudy({}, [dict(r, unhealthy_runs=0) for r in rows], {"M": records}, {})
        .table()
        .splitlines()
    )
    lines = table.splitlines()
    assert not any("WARNING" in line for line in clean) and len(clean) == len(lines) - 1
    n = {line.split()[0]: line.split()[1] for line in lines[3:-1]}
    assert n["actuator"] == n["none"] == "1" and n["RPM"] == "2"
    assert all(line.split()[1] == "2" for line in clean[3:])


def test_a_dead_sensor_is_detected_and_isolated_through_the_imm_kernel():
    """The engine study's IMM path (the batch kernel, then the rules replayed with the
    filter's health and its dead channels): a P2 channel that turns NaN at step 30 in
    runs 1 and 3 leaves the IMM healthy (the channel never reaches the state), and those
    runs alarm at exactly that step (the first non-finite measurement, found by brute
    force) with the simulator's label of a P2 sensor fault; the table scores them as
    alarms, not as unhealthy runs. The clean runs' records equal those replayed without
    the dead-channel rule."""
    import jax

    from jaxfdi import fault, fault_row, linear_simulator, replay_detector, sensor_labels, simulate
    from jaxfdi.detection import mode_probability_detector
    from jaxfdi.filters import interacting_multiple_model, kalman_filter, run_filter
    from jaxfdi.models import noise_inflation_modes
    from jaxfdi.scenarios.engine import PAPER_TRANSITION

    model, steps = engine_model(), 80
    us = jnp.full((steps, 1), 0.01)
    keys = jax.random.split(jax.random.key(3), 4)
    ys = jax.vmap(lambda k: simulate(linear_simulator(model), jnp.zeros(7), us, k)[1].measurement)(
        keys
    )
    ys = np.array(ys)
    ys[[1, 3], 30:, 2] = np.nan
    imm = interacting_multiple_model(
        kalman_filter, noise_inflation_modes(model, 1e4, 0.008), PAPER_TRANSITION
    )
    _, info = run_filter(
        imm, imm.init(jnp.zeros(7), model.Q, jnp.asarray(PAPER_TRANSITION[0])), ys, us
    )
    assert np.asarray(info.healthy).all()
    detector = mode_probability_detector(0.5)
    labels = sensor_labels(*model.dims[1:])
    records = jax.vmap(
        lambda mu, ok, dead: replay_detector(detector, mu, NEVER, 0, ok, dead, labels)
    )(info.mode_prob, info.healthy, info.dead)
    blind = jax.vmap(lambda mu, ok: replay_detector(detector, mu, NEVER, 0, ok))(
        info.mode_prob, info.healthy
    )
    first_bad = [
        int(np.argmax(~np.isfinite(y).all(axis=1))) if not np.isfinite(y).all() else -1 for y in ys
    ]
    assert first_bad == [-1, 30, -1, 30]
    np.testing.assert_array_equal(records.first_unhealthy, -1)
    p2_label = int(
        simulate(
            linear_simulator(model, fault("bias", "sensor", 2, 0, 1.0)),
            jnp.zeros(7),
            us[:1],
            keys[0],
        )[1].mode[0]
    )
    for run in (1, 3):
        assert int(records.first_alarm[run]) <= 30 and int(records.false_alarms[run]) >= 1
        assert int(records.first_label[run]) == p2_label or int(blind.first_alarm[run]) < 30
    for run in (0, 2):
        for a, b in zip(records, blind):
            np.testing.assert_array_equal(
                np.asarray(a)[run], np.asarray(b)[run]
            )  # NaN estimates equal
    row = fault_row(jax.tree_util.tree_map(np.asarray, records), steps)
    assert row["unhealthy_runs"] == 0 and row["runs"] == 4
