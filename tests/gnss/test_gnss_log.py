"""Android GnssLogger logs (``read_observations`` on ``*_GnssLog.txt``) against the
pseudoranges Google's and gnss_lib_py's pipelines generated from the same records.

- The 2023 Pixel 7 Pro log is the raw form of ``gsdc2023_device_gnss.csv``: every L1/E1/G1
  pseudorange equals the file's ``RawPseudorangeMeters`` up to one term per epoch (spread
  below 1 um: float64 rounding of 2e7 m). Google's pipeline holds the ``FullBiasNanos`` of
  an epoch before the excerpt for the whole log; we take each epoch's own, so that term
  moves from epoch to epoch by exactly ``c`` times the change of ``FullBiasNanos`` (the
  receiver clock's drift; to 1 um).
- The same log through gnss_lib_py 1.1's ``AndroidRawGnss``, which holds the first
  epoch's bias: common per epoch within 2 cm. (It computes in float64 seconds and
  nanoseconds of 1.4e18: the satellite time of 4e5 s is rounded to 0.9 cm, the
  reception time to a common 256 ns; ours keeps the nanoseconds as integers.)
- The 2021 Pixel 4 log's one epoch is the derived file's row one second later (the
  challenge's one-epoch shift, which ``read_android`` undoes): ``rawPrM`` printed to the
  millimetre, so within 1 mm of ours after the epoch's common term.
- Every log parses; damaged copies name the file and line.
"""

import csv
import warnings

import jax
import numpy as np
import pytest
from gnss_lib_py.parsers.android import AndroidRawGnss

from jaxfdi.data import data_path
from jaxfdi.gnss import read_observations

C = 299_792_458.0
LOGS = ["gsdc2021_Pixel4_GnssLog.txt", "gsdc2023_gnss_log.txt"]
L1_SIGNALS = {
    "GPS_L1_CA": "G",
    "GLO_G1_CA": "R",
    "GAL_E1_C_P": "E",
    "QZS_L1_CA": "J",
    "GPS_L1": "G",
    "GLO_G1": "R",
    "GAL_E1": "E",
}


def gps_millis(obs):
    return obs.week * 604_800_000 + np.round(obs.time_of_week * 1e3).astype(np.int64)


def column(obs, satellite):
    return list(obs.satellite).index(satellite)


@pytest.mark.parametrize("name", LOGS)
def test_every_log_parses(name):
    obs = read_observations(data_path(name))
    assert obs.pseudorange.shape == (obs.week.size, obs.satellite.size) == obs.cn0.shape
    assert set(obs.code) == {"C1C"}
    measured = np.isfinite(obs.pseudorange)
    assert measured.mean() > 0.9
    assert np.all(
        (obs.pseudorange[measured] > 1.8e7) & (obs.pseudorange[measured] < 2.9e7)
    )  # 60-100 ms of flight
    assert np.all(np.isfinite(obs.cn0[measured]))


def test_2023_log_is_googles_raw_pseudoranges_up_to_the_epochs_clock():
    obs = read_observations(data_path("gsdc2023_gnss_log.txt"))
    with open(data_path("gsdc2023_device_gnss.csv"), newline="") as handle:
        everything = list(csv.DictReader(handle))
    rows = [r for r in everything if r["SignalType"] in L1_SIGNALS]
    epochs = sorted({int(r["utcTimeMillis"]) for r in rows})
    gps = np.array(epochs) - 315_964_800_000 + 18_000
    tags = gps_millis(obs)
    assert np.all(
        np.abs(obs.week * 604_800_000 + obs.time_of_week * 1e3 - gps) < 1.0
    )  # utcTimeMillis: ms
    difference = np.full((len(epochs), obs.satellite.size), np.nan)
    for r in rows:
        sat = f"{L1_SIGNALS[r['SignalType']]}{int(r['Svid']):02d}"
        e, s = epochs.index(int(r["utcTimeMillis"])), column(obs, sat)
        difference[e, s] = obs.pseudorange[e, s] - float(r["RawPseudorangeMeters"])
    assert tags.size == len(epochs) and np.isfinite(difference).sum() == 105
    # QZSS 195 (J03): time of week known, not decoded, 1 s uncertain: no pseudorange in either
    qzss = [r for r in everything if r["ConstellationType"] == "4"]
    assert qzss and not any(r["RawPseudorangeMeters"] for r in qzss)
    assert {int(r["ReceivedSvTimeUncertaintyNanos"]) for r in qzss} == {1_000_000_000}
    assert np.all(np.isnan(obs.pseudorange[:, column(obs, "J03")]))
    finite = np.isfinite(difference)
    common = np.nanmedian(difference, axis=1)
    np.testing.assert_allclose(
        difference[finite],
        np.broadcast_to(common[:, None], difference.shape)[finite],
        atol=1e-6,
        rtol=0,
    )
    full_bias = {}
    text = data_path("gsdc2023_gnss_log.txt").read_text().splitlines()
    header = next(line[2:].split(",") for line in text if line.startswith("# Raw,"))
    for line in text:
        if line.startswith("Raw,"):
            value = dict(zip(header, line.split(",")))
            full_bias.setdefault(int(value["utcTimeMillis"]), int(value["FullBiasNanos"]))
    drift = np.array([full_bias[t] for t in epochs], dtype=np.int64)
    np.testing.assert_allclose(np.diff(common), -C * 1e-9 * np.diff(drift), atol=1e-6, rtol=0)


def test_2023_log_is_gnss_lib_pys_pseudoranges_up_to_the_epochs_clock():
    obs = read_observations(data_path("gsdc2023_gnss_log.txt"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nav = AndroidRawGnss(str(data_path("gsdc2023_gnss_log.txt")), filter_measurements=False)
    letter = {"gps": "G", "glonass": "R", "galileo": "E"}
    tags = gps_millis(obs)
    difference = np.full(obs.pseudorange.shape, np.nan)
    for gnss, svid, millis, frequency, rho in zip(
        nav["gnss_id"], nav["sv_id"], nav["gps_millis"], nav["CarrierFrequencyHz"], nav["raw_pr_m"]
    ):
        if gnss not in letter or frequency < 1.5e9:
            continue  # QZSS is numbered by vehicle there; L5/E5a is not the code read
        e = int(np.argmin(np.abs(tags - millis)))
        assert abs(tags[e] - millis) < 1.0
        difference[e, column(obs, f"{letter[gnss]}{int(svid):02d}")] = (
            obs.pseudorange[e, column(obs, f"{letter[gnss]}{int(svid):02d}")] - rho
        )
    finite = np.isfinite(difference)
    assert finite.sum() == 105
    common = np.nanmedian(difference, axis=1)
    np.testing.assert_allclose(
        difference[finite],
        np.broadcast_to(common[:, None], difference.shape)[finite],
        atol=0.02,
        rtol=0,
    )


def test_2021_log_is_the_derived_files_row_one_epoch_later():
    obs = read_observations(data_path("gsdc2021_Pixel4_GnssLog.txt"))
    with open(data_path("gsdc2021_Pixel4_derived.csv"), newline="") as handle:
        rows = list(csv.DictReader(handle))
    later = [
        r
        for r in rows
        if int(r["millisSinceGpsEpoch"]) == gps_millis(obs)[0] + 1000
        and r["signalType"] in L1_SIGNALS
    ]
    assert not [r for r in rows if int(r["millisSinceGpsEpoch"]) == gps_millis(obs)[0]]
    letters = {"1": "G", "3": "R", "6": "E"}
    difference = np.array(
        [
            obs.pseudorange[
                0, column(obs, f"{letters[r['constellationType']]}{int(r['svid']):02d}")
            ]
            - float(r["rawPrM"])
            for r in later
        ]
    )
    assert difference.size == 20
    np.testing.assert_allclose(
        difference, np.median(difference), atol=1e-3, rtol=0
    )  # two 0.5 mm roundings


def test_first_gps_fix_is_the_approximate_position_in_float64():
    with jax.enable_x64(False):
        obs = read_observations(data_path("gsdc2021_Pixel4_GnssLog.txt"))
    lat, lon, h = (
        np.radians(37.4235845),
        np.radians(-122.0941221),
        -32.830566,
    )  # the first GPS Fix record
    a, e2 = 6378137.0, 6.69437999014e-3
    n = a / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    expected = [
        (n + h) * np.cos(lat) * np.cos(lon),
        (n + h) * np.cos(lat) * np.sin(lon),
        (n * (1 - e2) + h) * np.sin(lat),
    ]
    np.testing.assert_allclose(obs.approx_position, expected, atol=1e-6, rtol=0)
    assert np.all(np.isnan(read_observations(data_path("gsdc2023_gnss_log.txt")).approx_position))


def damaged(tmp_path, edit):
    """A copy of the 2023 log with ``edit(lines, k)`` applied, ``k`` the first Raw record's
    index; returns the copy and that record's line number."""
    lines = data_path("gsdc2023_gnss_log.txt").read_text().splitlines()
    raw = next(i for i, line in enumerate(lines) if line.startswith("Raw,"))
    path = tmp_path / "log.txt"
    path.write_text("\n".join(edit(lines, raw)) + "\n")
    return path, raw + 1


def field(name, value):
    """An edit that sets one field of the first Raw record."""

    def edit(lines, k):
        header = next(line[2:].split(",") for line in lines if line.startswith("# Raw,"))
        fields = lines[k].split(",")
        fields[header.index(name)] = value
        return lines[:k] + [",".join(fields)] + lines[k + 1 :]

    return edit


@pytest.mark.parametrize(
    "edit, after, message",
    [
        (
            lambda lines, k: lines[:k] + [lines[k].rsplit(",", 5)[0]] + lines[k + 1 :],
            0,
            "expected 37 fields",
        ),
        (field("CarrierFrequencyHz", "1575420000x"), 0, "could not convert string to float"),
        (field("Svid", ""), 0, "invalid literal for int"),
        (field("ConstellationType", "9"), 0, "ConstellationType 9"),
        (
            field("FullBiasNanos", "1378148348376188193"),
            0,
            "FullBiasNanos: expected a negative number",
        ),
        (field("CarrierFrequencyHz", "1300000000"), 0, "CarrierFrequencyHz: expected an L1/E1/G1"),
        (lambda lines, k: lines[:k] + [lines[k]] + lines[k:], 1, "a second record of G02 C1C"),
    ],
)
def test_damaged_log_names_the_file_and_line(tmp_path, edit, after, message):
    path, line = damaged(tmp_path, edit)
    with pytest.raises(ValueError, match=f"log.txt:{line + after}: {message}"):
        read_observations(path)


def test_a_log_without_raw_header_or_records_is_named(tmp_path):
    path, line = damaged(
        tmp_path, lambda lines, k: [line for line in lines if not line.startswith("# Raw")]
    )
    with pytest.raises(
        ValueError, match=f"log.txt:{line - 1}: a Raw record before the '# Raw,' header"
    ):
        read_observations(path)
    path, _ = damaged(
        tmp_path,
        lambda lines, k: [line for line in lines if not line.startswith(("# Raw", "Raw,"))],
    )
    with pytest.raises(ValueError, match="log.txt:1: expected an Android GnssLogger log"):
        read_observations(path)
    path, _ = damaged(
        tmp_path, lambda lines, k: [line for line in lines if not line.startswith("Raw,")]
    )
    with pytest.raises(ValueError, match="log.txt:[0-9]+: no Raw record"):
        read_observations(path)
