"""`jaxfdi tune engine-imm` at full size for the Zhang & Li design (the README's command:
16 training runs per fault, 150 Adam steps, per-mode mu_T chosen on 100 selection runs per
fault, 100 held-out runs per fault; about 3 min on 2 cores).

Reference: the paper's hand-set IMM (transition matrix, inflation factors, mu_T = 0.5) on
the same held-out runs. The tuned IMM must have at least 30 % lower mean per-step mode
cross-entropy and no reported metric worse. Rates move in steps of one run (0.01) and
delays in steps of one sample (0.01 s); the check allows at most that one step, so that
a single run decided differently on another CPU (float rounding in a tuned filter) does
not turn the suite red. At the seeds used, the CLI prints "worse than the paper's: none"
(the issue-4 note gives the table)."""
import json

import numpy as np
import pytest

from jaxfdi.cli import main
from jaxfdi.scenarios import engine_tuning as et

RATES = ("detection_rate", "isolation_rate", "false_alarm_rate")
DELAYS = ("delay_median_s", "delay_p90_s")


@pytest.fixture(scope="module")
def zhang_li_full(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune-imm-full")
    assert main(["tune", "engine-imm", "--design", "zhang-li", "--delay-weight", "20", "--freeze", "mu_threshold",
                 "--select-thresholds", "--quiet", "--out", str(out)]) == 0
    return json.loads((out / "engine-imm-tuning.json").read_text())


def test_zhang_li_full_size_no_reported_metric_worse_than_the_paper(zhang_li_full):
    config = zhang_li_full["config"]
    assert (config["steps"], config["train_runs"], config["test_runs"], config["selection_runs"]) == (150, 16, 100, 100)
    result = zhang_li_full["designs"]["zhang-li"]
    ce = result["cross_entropy"]
    assert ce["tuned"] <= 0.7 * ce["paper"], ce
    assert result["worse"] == et.worse_metrics(result["paper"], result["tuned"], ce["paper"], ce["tuned"])
    excess = {}
    for paper, tuned in zip(result["paper"], result["tuned"]):
        assert paper["fault"] == tuned["fault"]
        for key in RATES + DELAYS:
            if paper[key] is None:  # no delay or isolation for the fault-free runs
                continue
            sign = 1.0 if key in ("detection_rate", "isolation_rate") else -1.0
            excess[f"{paper['fault']} {key}"] = sign * (paper[key] - tuned[key])
    assert len(excess) == 6 * 5 + 1  # six faults x five metrics + the fault-free false-alarm rate
    worst = max(excess, key=excess.get)
    assert excess[worst] <= 0.01 + 1e-9, (worst, excess[worst], result["worse"])
    assert np.all(np.asarray(result["tuned_params"]["transition"]) >= 0)
