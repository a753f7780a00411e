"""The real-receiver study (``jaxfdi run gnss-real``) at a reduced size: its CSV table is
its JSON rows, no epoch of either GEONET hour is misleading for either protection level, its
fixes are RTKLIB's, RTKLIB's RAIM FDE takes our decision on every injected step, the injected
steps at or above the minimum detectable bias are detected as often as the slope protection
level promises (a binomial test), and on the phone traces gnss_lib_py's fault detection takes
the same decisions and Google's own fix of the Pixel 7 Pro (whose uncertainties are right:
``TS_D / dof`` near 1) is ours.

Notebook 08 runs last, at the CLI run's 60 trials per case (another seed): the study's
programs take their shapes from the number of trials only (not the seed), so its study
cell runs on the programs the CLI run compiled (the run's shared XLA cache, see conftest)
instead of compiling every section again at a smaller size."""

import json
import re
import subprocess
import sys

import _notebooks
import pandas as pd
import pytest
from _frames import assert_table_is_the_json
from _notebooks import images, run_clean, tables
from scipy import stats

from jaxfdi import results_frame, text_table
from jaxfdi.scenarios.gnss_real import PHONE_EXCLUSIONS, PHONES, STEP_SIZES

RUNS = 60
P_MD = 1e-3


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """``jaxfdi run gnss-real --runs 60 --seed 5``: its stdout, rows and output folder."""
    out = tmp_path_factory.mktemp("gnss-real") / "out"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxfdi",
            "run",
            "gnss-real",
            "--runs",
            str(RUNS),
            "--seed",
            "5",
            "--quiet",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout, json.loads((out / "gnss-real.json").read_text()), out


def test_cli_writes_the_table_its_csv_and_the_stanford_diagrams(study):
    stdout, data, out = study
    assert "gnss-real: GPS integrity on real receivers" in stdout
    assert data["config"]["runs"] == RUNS and data["config"]["seed"] == 5
    rows = data["rows"]
    # the printed table is the JSON's frame as text (one source): a block per section, the wide ones transposed
    assert text_table(results_frame(rows), group="section") in stdout
    assert re.search(r"^station +GEONET 0759 +GEONET 3040$", stdout, re.M)
    assert re.search(r"^trace +GSDC 2021 Pixel 4 XL .* GSDC 2023 Pixel 7 Pro$", stdout, re.M)
    assert [r["section"] for r in rows] == (
        ["positions"] * 2
        + ["step"] * len(STEP_SIZES)
        + ["ramp"] * 4
        + ["channel"] * 2
        + ["phones", "phone-peers"] * len(PHONES)
    )
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    assert_table_is_the_json(
        pd.read_csv(out / "gnss-real.csv", **exact), rows
    )  # the CSV is to_frame()
    assert (out / "gnss-real-stanford.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.iterdir()) == [
        "gnss-real-stanford.png",
        "gnss-real.csv",
        "gnss-real.json",
    ]


def test_both_hours_have_no_misleading_epoch_and_rtklibs_fixes(study):
    for row in study[1]["rows"][:2]:
        assert row["scored_epochs"] == 115 and row["parity_alarms"] == 0 and row["ss_alarms"] == 0
        assert row["misleading_slope"] == 0 and row["misleading_ss"] == 0
        assert row["rtklib_max_difference_m"] < 1e-3
        assert row["horizontal_error_median_m"] < 1.0 < row["hpl_median_m"] < row["ss_hpl_median_m"]


def test_steps_at_or_above_the_minimum_detectable_bias_are_detected(study):
    """Pooled over sizes: the misses among trials whose bias is at least that satellite's
    MDB at that epoch are not more than P_md = 1e-3 allows (one-sided binomial test,
    p > 0.01); and the detection rate grows with the bias."""
    steps = [r for r in study[1]["rows"] if r["section"] == "step"]
    trials = sum(r["runs_at_or_above_mdb"] for r in steps)
    misses = sum(
        round(r["runs_at_or_above_mdb"] * (1.0 - r["detection_rate_at_or_above_mdb"]))
        for r in steps
        if r["runs_at_or_above_mdb"]
    )
    assert trials >= RUNS
    assert stats.binomtest(misses, trials, P_MD, alternative="greater").pvalue > 0.01, (
        misses,
        trials,
    )
    rates = [r["detection_rate"] for r in steps]
    assert (
        rates == sorted(rates) and rates[0] < 0.5 and rates[-1] > 0.9
    )  # a 100 m step can hide in a weak geometry
    assert all(
        r["ss_detection_rate"] <= r["detection_rate"] + 0.1 for r in steps
    )  # SS's budgets are stricter


def test_rtklibs_raim_fde_takes_our_decision_on_every_injected_step(study):
    """RTKLIB's pntpos with RAIM FDE (chi-square at 1e-3, then the passing leave-one-out
    fix of smallest residual RMS) on the same faulty epochs: the same outcome in every
    trial (no alarm, the same satellite excluded, or no fix) and the same fix to 1 mm.
    The rules differ (RTKLIB ranks the leave-one-out fixes by their unweighted residual
    RMS, we isolate by the largest weighted normalised residual), so this is measured
    agreement on these trials, not an identity."""
    for row in (r for r in study[1]["rows"] if r["section"] == "step"):
        assert row["rtklib_same_decision"] == RUNS and row["rtklib_max_difference_m"] < 1e-3


def test_phone_rows_agree_with_gnss_lib_py_and_google(study):
    rows = study[1]["rows"]
    phones = {r["trace"]: r for r in rows if r["section"] == "phones"}
    peers = [r for r in rows if r["section"] == "phone-peers"]
    assert sorted(phones) == sorted(PHONES) and len(peers) == len(PHONES)
    for row in peers:
        assert (
            row["wls_max_difference_m"] < 1e-3
            and row["jaxfdi_only"] == 0
            and row["gnss_lib_py_only"] == 0
        )
        assert row["explained"] == row["different_exclusion"]
        # greedy rounds: the same excluded signals but where the first round differs, and on
        # at most 2 % of the epochs more (measured 277 of 281 on the Pixel 4 XL)
        assert (
            row["epochs"] - row["same_exclusion_set"]
            <= row["different_exclusion"] + 0.02 * row["epochs"]
        )
    for row in phones.values():
        assert row["excluded_signals"] <= PHONE_EXCLUSIONS * row["exclusions"]
        assert (
            row["exclusions"] <= row["parity_alarms"]
            and row["alarm_after_exclusion"] <= row["parity_alarms"]
        )
    calibrated = phones["GSDC 2023 Pixel 7 Pro"]
    assert (
        0.5 < calibrated["statistic_per_dof_median"] < 2.0
        and calibrated["google_difference_median_m"] < 0.5
    )
    assert (
        phones["GSDC 2021 Pixel 4"]["truth_epochs"] == 7
        and phones["GSDC 2021 Pixel 4 XL"]["truth_epochs"] == 0
    )


def test_a_stopped_channel_is_caught_and_its_satellite_excluded(study):
    """A dead channel (infinite pseudorange) is flagged at once and excluded in every trial;
    a frozen one is caught at the next epoch in every trial (30 s of range change: far above
    any minimum detectable bias)."""
    channel = {r["kind"]: r for r in study[1]["rows"] if r["section"] == "channel"}
    assert channel["dead"]["detection_rate"] == 1.0 and channel["dead"]["exclusion_rate"] == 1.0
    assert channel["dead"]["delay_median_s"] == 0.0
    assert (
        channel["frozen"]["detection_rate"] == 1.0 and channel["frozen"]["delay_median_s"] == 30.0
    )


def test_real_receivers_notebook(study, python3_kernel, monkeypatch):
    """Notebook 08 (real receivers: GEONET beside RTKLIB, phones beside Google and
    gnss_lib_py) end to end in a fresh kernel at the CLI run's size (``RUNS`` fault trials
    per case), its printed results checked against what the data and the peers fix: no
    GEONET epoch beyond its level, the Pixel 7 Pro's fix within 0.5 m of Google's with its
    uncertainties right, its raw log read, and the study's tables and the Stanford diagrams
    rendered. After ``study`` (the fixture), so that its programs are in the run's XLA cache."""
    # a slack per cell for a cold cache (the test run alone): the study cell compiles every section
    monkeypatch.setattr(_notebooks, "CELL_TIMEOUT_S", 900)
    outputs, text = run_clean(
        "08_real_receivers.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": str(RUNS)}
    )
    assert f"fault trials per step size and ramp rate: {RUNS}" in text
    assert (
        "station 0759: 115 epochs of GDOP <= 30, 0 alarms; every error below its level: True"
        in text
    )
    html = tables(outputs)
    assert "ours - Google&#x27;s [m]" in html or "ours - Google's [m]" in html
    assert "GPS time of week [s]" in html and "J03 [km]" in html  # the raw GnssLogger log's table
    for heading in ("positions", "step", "ramp", "channel", "phones", "phone-peers"):
        assert f"<h4>{heading}</h4>" in html, heading
    assert len(images(outputs)) == 1
