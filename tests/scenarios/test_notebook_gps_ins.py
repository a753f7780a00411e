"""Notebook 07 (seed 002, both halves: GPS RAIM on the campus and in the park, the INS/GPS
EKF with the chi-square test and the SCST, Table 3) end to end in a fresh kernel, at a
reduced size (2 runs per case, 400 s flights with the IMU fault from 200 s, IMU at 20 Hz;
the paper's size is the notebook's default), and its printed results checked."""

import _notebooks
from _notebooks import images, run_clean, tables


def test_gps_ins_integrity_notebook(python3_kernel, monkeypatch, tmp_path):
    # the Table 3 cell compiles the whole monitor (RAIM, EKF, both tests) in a fresh kernel:
    # about 1.5 CPU-minutes, more than the shared 300 s per cell on a loaded 2-core machine
    monkeypatch.setattr(_notebooks, "CELL_TIMEOUT_S", 1200)
    outputs, text = run_clean(
        "07_gps_ins_integrity.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": "2", "JAXFDI_NB_GPS_INS_SIZE": "400,200,20"},
    )
    assert "runs per case: 2; flights of 400 s, IMU fault from 200 s, IMU at 20 Hz" in text
    html = tables(outputs)  # the two studies as DataFrames, a table per case
    assert "<h4>campus</h4>" in html and "<td>impulse 100 m at 100 s</td>" in html
    drift = float(text.split("perfect IMU, 300 s of the park flight: drift ")[1].split()[0])
    assert drift < 1e-5
    assert "dv/dpsi = -[f^n x]: True | dv/db_a = C_b^n: True | dpsi/db_g = C_b^n: True" in text
    assert "<h4>table3</h4>" in html
    for bias, (chi2, scst) in ((30, (159, 149)), (60, (59, 49)), (90, (44, 39))):
        line = next(row for row in text.splitlines() if row.startswith(f"{bias:>5g} deg/h"))
        assert f"({chi2:>3d})" in line and f"({scst:>3d})" in line, line
    assert "<h4>curve</h4>" in html  # beyond the paper: detection time against the bias size
    figures = images(outputs)
    assert len(figures) == 7, (
        f"expected the GPS half's 2 figures and the INS half's 5, got {len(figures)}"
    )
