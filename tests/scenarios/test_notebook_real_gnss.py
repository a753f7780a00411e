"""Notebook 08 (real receivers: GEONET beside RTKLIB, phones beside Google and gnss_lib_py)
end to end in a fresh kernel at a reduced size (5 fault trials per case), its printed
results checked against what the data and the peers fix: no GEONET epoch beyond its level,
the Pixel 7 Pro's fix within 0.5 m of Google's with its uncertainties right, its raw log
read, and the study's tables and the Stanford diagrams rendered."""

import _notebooks
from _notebooks import images, run_clean, tables


def test_real_receivers_notebook(python3_kernel, monkeypatch):
    monkeypatch.setattr(_notebooks, "CELL_TIMEOUT_S", 900)  # the study cell compiles every section
    outputs, text = run_clean(
        "08_real_receivers.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"}
    )
    assert "fault trials per step size and ramp rate: 5" in text
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
