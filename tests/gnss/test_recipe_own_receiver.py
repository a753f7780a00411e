"""The recipe "your own receiver through RAIM and protection levels" (notebook 10) end to end in a fresh kernel, with
what its text says checked on the numbers it computed: the GEONET hour has median errors under a metre and no
misleading epoch, every vertical level above LPV-200's 50 m and most horizontal ones above 40 m; the phone's
misleading epochs have a vertical error above 10 m that Google's own fix shares. (The counts are
``gnss.integrity_outcomes``'s, checked region by region in ``test_stanford.py``; the fixes are RTKLIB's, in
``tests/scenarios/test_gnss_real.py``; that it imports only public names, in ``test_docs.py``.)"""

import json

from _notebooks import images, run_clean

EPILOGUE = """
import json
misleading = (phone_v > fix.protection.vpl[truth_epochs]) & ~fix.check.alarm[truth_epochs]
google = np.asarray(gnss.ecef_to_ned(phone.wls_position[truth_epochs], phone.truth[truth_epochs]))[:, 2]
print("CHECK " + json.dumps({
    "h": outcomes["horizontal"]._asdict(), "v": outcomes["vertical"]._asdict(),
    "median_h": float(epochs["horizontal error [m]"].median()),
    "median_v": float(epochs["vertical error [m]"].median()),
    "phone": counts._asdict(),
    "phone_v": phone_v[misleading].tolist(), "google_v": np.abs(google[misleading]).tolist(),
}))
"""


def test_own_receiver_recipe_runs_and_its_text_holds(python3_kernel, monkeypatch):
    outputs, text = run_clean(
        "10_own_receiver.ipynb", python3_kernel, monkeypatch, {}, epilogue=EPILOGUE
    )
    assert (
        "observations: 30400920.05o, navigation: 30400920.05n" in text and len(images(outputs)) == 2
    )
    check = json.loads(text.split("CHECK ", 1)[1].splitlines()[0])
    h, v = check["h"], check["v"]
    assert check["median_h"] < 1 and check["median_v"] < 1
    for counts in (h, v):
        assert counts["misleading"] == counts["hazardous"] == counts["unavailable_misleading"] == 0
    assert v["unavailable"] == v["epochs"] == 120 and h["unavailable"] > h["nominal"]
    phone = check["phone"]
    assert phone["misleading"] == len(check["phone_v"]) >= 1
    assert min(check["phone_v"]) > 10 and min(check["google_v"]) > 10
