"""The recipe "a Monte Carlo FDI study of your own plant" (notebook 09) end to end in a fresh kernel, on a seed it
was not written on, with what its text says checked statistically: the chi-square test has no isolation, its
per-step design false-alarm probability gives many more false-alarm runs than that, and the GLRT names the attitude
sensor for a gyro bias more often than the gyro. (Its table's numbers are ``StudyResult.to_frame``'s, checked against
brute force in ``test_study.py``; that it imports only public names, in ``test_docs.py``.)"""

import json

from _notebooks import images, run_clean, tables
from scipy import stats

RUNS = 60
EPILOGUE = """
import json
gyro = result.outputs["GLRT 1e-3"]
part = slice(names.index("gyro bias") * RUNS, (names.index("gyro bias") + 1) * RUNS)
named = np.where(gyro.detection_step[part] >= 0, gyro.isolated[part], -1)
chi2_none = frame[(frame.method == "chi2 1e-3") & (frame.case == "none")].iloc[0]
print("CHECK " + json.dumps({
    "chi2_isolation": [float(v) for v in frame[frame.method.str.startswith("chi2")].isolation_rate],
    "false_alarm_runs": int(round(chi2_none.false_alarm_rate * chi2_none.runs)),
    "gyro_as_attitude": int((named == labels[2]).sum()),
    "gyro_as_gyro": int((named == labels[1]).sum()),
}))
"""


def test_own_plant_recipe_runs_and_its_text_holds_on_a_fresh_seed(python3_kernel, monkeypatch):
    outputs, text = run_clean(
        "09_own_plant_study.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": str(RUNS), "JAXFDI_NB_SEED": "7"},
        epilogue=EPILOGUE,
    )
    assert f"runs per fault: {RUNS}, seed 7" in text
    html = tables(outputs)
    assert (
        "detection_rate_low" in html and "<td>GLRT 1e-5</td>" in html and len(images(outputs)) == 1
    )
    check = json.loads(text.split("CHECK ", 1)[1].splitlines()[0])
    assert all(v != v for v in check["chi2_isolation"])  # NaN: the chi-square test never isolates
    # P_fa = 1e-3 per step over the 500 steps of a fault-free run: far more than one run in a thousand alarms
    assert (
        stats.binomtest(check["false_alarm_runs"], RUNS, 1e-3, alternative="greater").pvalue < 1e-6
    )
    # the gyro's step is named as the attitude sensor's more often than as its own (a sign test)
    a, g = check["gyro_as_attitude"], check["gyro_as_gyro"]
    assert a > g and stats.binomtest(a, a + g, 0.5, alternative="greater").pvalue < 1e-3
