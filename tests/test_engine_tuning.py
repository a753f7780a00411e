"""`jaxfdi tune engine-imm` at a reduced size (the CLI default is 16 training runs per
fault, 150 steps, 100 held-out runs per fault): the tuned IMM's mean per-step mode
cross-entropy on held-out runs (other seeds than training and validation) is at least
30 % below the paper's hand-set IMM, and the saved parameters are valid and reload."""
import json

import numpy as np
import pytest

from jaxfdi.cli import main
from jaxfdi.scenarios.engine_tuning import TRANSITION_MASK
from jaxfdi.tuning import constrain, load_params


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune")
    assert main(["tune", "engine-imm", "--steps", "20", "--train-runs", "2", "--runs", "10", "--out", str(out),
                 "--quiet"]) == 0
    return out, json.loads((out / "engine-imm-tuning.json").read_text())


def test_held_out_mode_cross_entropy_at_least_30_percent_lower(tuned):
    _, result = tuned
    ce = result["cross_entropy"]
    assert ce["tuned"] <= 0.7 * ce["paper"], ce
    history = result["history"]
    assert history["best_step"] > 0 and min(history["val_loss"]) < history["val_loss"][0]
    # every fault still detected in every held-out run
    assert all(r["detection_rate"] == 1.0 for r in result["tuned"] if r["fault"] != "none")


def test_saved_parameters_are_valid_and_reload(tuned):
    out, result = tuned
    raw, parameterization, meta = load_params(out / "engine-imm-tuned.npz")
    params = constrain(parameterization, raw)
    pi = np.asarray(params["transition"])
    np.testing.assert_allclose(pi.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(pi[~TRANSITION_MASK] == 0.0) and np.all(pi >= 0)
    assert 0.0 < float(params["mu_threshold"]) < 1.0 and np.all(np.asarray(params["sensor_inflation"]) > 1.0)
    for name, value in result["tuned_params"].items():
        np.testing.assert_allclose(np.asarray(params[name]), value, rtol=1e-12)
    assert meta["best_step"] == result["history"]["best_step"]
