"""`jaxfdi tune engine-imm` at a reduced size (the CLI defaults are 16 training runs per
fault, 150 steps, 100 held-out runs per fault).

References are the paper's hand-set IMMs run on the same held-out runs (other seeds
than training and validation): for each IMM design the tuned mean per-step mode
cross-entropy is at least 30 % below the paper's, no fault goes undetected and the
fault-free false-alarm rate does not rise; saved parameters are valid and reload."""
import json

import numpy as np
import pytest

from jaxfdi.cli import main
from jaxfdi.scenarios import engine_tuning as et
from jaxfdi.tuning import constrain, load_params

SMALL = ["--steps", "20", "--train-runs", "2", "--runs", "10", "--quiet"]


@pytest.fixture(scope="module")
def imm_tuned(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune-imm")
    assert main(["tune", "engine-imm", *SMALL, "--out", str(out)]) == 0
    return out, json.loads((out / "engine-imm-tuning.json").read_text())


@pytest.mark.parametrize("design", sorted(et.DESIGNS))
def test_each_imm_design_held_out_cross_entropy_at_least_30_percent_lower(imm_tuned, design):
    _, report = imm_tuned
    result = report["designs"][design]
    ce = result["cross_entropy"]
    assert ce["tuned"] <= 0.7 * ce["paper"], ce
    history = result["history"]
    assert history["best_step"] > 0 and min(history["val_loss"]) < history["val_loss"][0]
    paper = {r["fault"]: r for r in result["paper"]}
    tuned = {r["fault"]: r for r in result["tuned"]}
    assert all(tuned[f]["detection_rate"] == 1.0 for f in tuned if f != "none"), result["tuned"]
    assert tuned["none"]["false_alarm_rate"] <= paper["none"]["false_alarm_rate"]
    # the report's list of worse metrics is the comparison of the two tables
    assert result["worse"] == et.worse_metrics(result["paper"], result["tuned"], ce["paper"], ce["tuned"])


@pytest.mark.parametrize("design", sorted(et.DESIGNS))
def test_saved_imm_parameters_are_valid_and_reload(imm_tuned, design):
    out, report = imm_tuned
    result = report["designs"][design]
    raw, parameterization, meta = load_params(out / f"engine-imm-{design}-tuned.npz")
    params = constrain(parameterization, raw)
    pi = np.asarray(params["transition"])
    np.testing.assert_allclose(pi.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(pi[~et.imm_design(design).transition_mask] == 0.0) and np.all(pi >= 0)
    assert 0.0 < float(params["mu_threshold"]) < 1.0
    assert all(np.all(np.asarray(v) > 0) for k, v in params.items() if k not in ("transition", "mu_threshold"))
    for name, value in result["tuned_params"].items():
        np.testing.assert_allclose(np.asarray(params[name]), value, rtol=1e-12)
    assert meta["best_step"] == result["history"]["best_step"] and meta["design"] == design
