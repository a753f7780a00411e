"""The recipe "auto-tune an IMM on your data" (notebook 11) end to end in a fresh kernel on a seed it was not
written on, with what its text says checked on the numbers it computed: the tuned matrix near the generating one,
its held-out scores as the generating matrix's, its mode cross-entropy and accuracy better than the start's with
the intervals apart, and the saved parameters loading back. (The tuner's recovery of a generating matrix within
three standard errors and its agreement with filterpy are ``test_imm_tuner.py``'s.)"""

import json

import numpy as np
from _notebooks import images, run_clean

EPILOGUE = """
import json
print("CHECK " + json.dumps({"tuned": np.asarray(params["transition"]).tolist(), "scores": scores.to_dict("index")}))
"""


def test_tune_imm_recipe_runs_and_its_text_holds_on_a_fresh_seed(python3_kernel, monkeypatch):
    outputs, text = run_clean(
        "11_tune_your_imm.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": "16", "JAXFDI_NB_SEED": "5"},
        epilogue=EPILOGUE,
    )
    assert "16 runs of 300 steps per set, seed 5" in text and "loaded equals tuned: True" in text
    assert len(images(outputs)) == 1
    check = json.loads(text.split("CHECK ", 1)[1].splitlines()[0])
    tuned = np.array(check["tuned"])
    assert (
        np.allclose(tuned.sum(axis=1), 1.0)
        and np.abs(tuned - [[0.96, 0.04], [0.12, 0.88]]).max() < 0.05
    )
    start, best, truth = (check["scores"][k] for k in ("start", "tuned", "generating"))
    assert (
        truth["nll_low"] <= best["nll"] <= truth["nll_high"]
        and abs(best["nll"] - truth["nll"]) < 0.01
    )
    assert best["cross_entropy_high"] < start["cross_entropy_low"]
    assert best["mode_accuracy_low"] > start["mode_accuracy_high"]
