"""`jaxfdi tune engine-chi2` at a reduced size (the CLI defaults are 16 training runs per
fault, 150 steps, windows 1, 2, 4, 8 and 100 held-out runs per fault): against the
hand-set test (plant Q and R, L = 4, chi2.isf(0.005, 20)) on the same held-out runs the
tuned test has a lower held-out loss and fewer false alarms; saved parameters are valid
and reload."""

import json
import subprocess
import sys

import numpy as np
import pytest

from jaxfdi.cli import main
from jaxfdi.tuning import constrain, load_params

SMALL = ["--steps", "20", "--train-runs", "2", "--runs", "10", "--quiet"]


@pytest.fixture(scope="module")
def chi2_tuned(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tune-chi2")
    out = tmp / "out"
    # a fresh process (as test_engine_tuning): the CLI's persistent cache (the run's shared
    # one, see conftest) is on from its first compilation
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxfdi",
            "tune",
            "engine-chi2",
            *SMALL,
            "--windows",
            "2,4",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads((out / "engine-chi2-tuning.json").read_text())


def test_tuned_chi2_test_has_lower_held_out_loss_and_fewer_false_alarms(chi2_tuned):
    out, result = chi2_tuned
    assert result["window"] in (2, 4) and set(result["val_loss"]) == {"2", "4"}
    loss = result["held_out_loss"]
    assert loss["tuned"] < loss["hand"], loss
    hand = {r["fault"]: r for r in result["hand"]}
    tuned = {r["fault"]: r for r in result["tuned"]}
    assert tuned["none"]["false_alarm_rate"] < hand["none"]["false_alarm_rate"], (
        hand["none"],
        tuned["none"],
    )
    raw, parameterization, meta = load_params(out / "engine-chi2-tuned.npz")
    params = constrain(parameterization, raw)
    for name in ("Q", "R"):
        cov = np.asarray(params[name])
        np.testing.assert_array_equal(cov, np.diag(np.diag(cov)))
        assert np.all(np.diag(cov) > 0)
        np.testing.assert_allclose(cov, result["tuned_params"][name], rtol=1e-12)
    assert float(params["threshold"]) > 0 and meta["window"] == result["window"]


def test_tune_rejects_bad_windows(capsys):
    assert main(["tune", "engine-chi2", "--windows", "4,0"]) == 2
    assert (
        "--windows: expected integers in [1, 2147483647] separated by commas"
        in capsys.readouterr().err
    )
