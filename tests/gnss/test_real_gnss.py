"""Real receivers: GEONET stations 0759 and 3040 (RINEX 2.10, GPS, one hour at 30 s, the
surveyed positions in their headers) against RTKLIB 2.4.3 (pyrtklib: the C library that
Debian's ``rnx2rtkp`` and ``convbin`` are built from, which give the same files).

- The observation reader against RTKLIB's: RTKLIB's converter rewrites each file as
  RINEX 3.03, and both files read to the same epochs and pseudoranges.
- Single-point positions against RTKLIB's post-processor (``postpos``, what ``rnx2rtkp``
  runs) with the same models: broadcast orbits and clocks, Klobuchar and Saastamoinen,
  15 deg mask, RTKLIB's weights. What it checks: that the measurement model, the
  corrections and the weighting are RTKLIB's, epoch by epoch. The tolerance is 1 mm:
  RTKLIB stops iterating when its step is below 0.1 mm and we run a fixed count, so the
  two solutions of the same equations may differ by a few tenths of a millimetre
  (measured: 0.38 mm at most); any model difference (a 1 cm ionosphere, a weight) moves
  them by centimetres or more.
- RTKLIB refuses exactly the epochs whose GDOP exceeds its limit of 30.
- Damaged copies of the files fail with the file and line named.
"""

import math
import re
from pathlib import Path

import jax
import numpy as np
import pyrtklib as rtk
import pytest

from jaxfdi.data import data_path
from jaxfdi.gnss import monitor_receiver, read_observations, read_rinex_nav, receiver_epochs
from jaxfdi.gnss._receiver import code_sigma, user_range_accuracy
from jaxfdi.gnss._rinex_obs import parse_rinex_obs

STATIONS = {
    "0759": (-3976219.5082, 3382372.5671, 3652512.9849),
    "3040": (-3978242.4348, 3382841.1715, 3649902.7667),
}
SATELLITES = {"0759": 11, "3040": 12}  # GPS satellites seen in the hour
FILES = {"0759": "07590920.05", "3040": "30400920.05"}
MAX_GDOP = 30.0  # RTKLIB's default pos1-maxgdop (valsol)


def observation(station):
    return data_path(FILES[station] + "o")


def navigation(station):
    return data_path(FILES[station] + "n")


def rtklib_positions(station, tmp_path) -> dict[float, np.ndarray]:
    """RTKLIB's single-point solutions of a station ``{time of week: ECEF}``: ``postpos``
    with its default options but GPS, broadcast ionosphere, Saastamoinen troposphere, a
    15 deg mask and ECEF output (``rnx2rtkp -k`` with ``pos1-ionoopt=brdc``,
    ``pos1-tropopt=saas``, ``out-solformat=xyz``)."""
    rtk.resetsysopts()
    popt, sopt, fopt = rtk.prcopt_t(), rtk.solopt_t(), rtk.filopt_t()
    rtk.getsysopts(popt, sopt, fopt)  # RTKLIB's defaults, into structs of our own
    popt.mode, popt.navsys, popt.elmin = rtk.PMODE_SINGLE, rtk.SYS_GPS, math.radians(15.0)
    popt.ionoopt, popt.tropopt, sopt.posf = rtk.IONOOPT_BRDC, rtk.TROPOPT_SAAS, rtk.SOLF_XYZ
    out = tmp_path / f"{station}.pos"
    name = rtk.Arr1Dchar(1024)
    for i, c in enumerate(str(out)):
        name[i] = c
    status = rtk.postpos(
        rtk.gtime_t(),
        rtk.gtime_t(),
        0.0,
        0.0,
        popt,
        sopt,
        fopt,
        [str(observation(station)), str(navigation(station))],
        2,
        name,
        "",
        "",
    )
    assert status == 0, f"RTKLIB postpos returned {status}"
    solutions = {}
    for line in out.read_text().splitlines():
        if line.startswith("%"):
            continue
        fields = line.split()
        hour, minute, second = fields[1].split(":")
        tow = (
            6 * 86400.0 + int(hour) * 3600 + int(minute) * 60 + float(second)
        )  # 2005-04-02 is a Saturday
        solutions[tow] = np.array([float(v) for v in fields[2:5]])
    return solutions


@pytest.fixture(scope="module", params=list(STATIONS))
def station(request):
    obs = read_observations(observation(request.param))
    result = monitor_receiver(receiver_epochs(obs, read_rinex_nav(navigation(request.param))))
    return request.param, obs, jax.tree_util.tree_map(np.asarray, result)


@pytest.mark.parametrize("name", list(STATIONS))
def test_every_real_file_is_read(name):
    obs = read_observations(observation(name))
    eph = read_rinex_nav(navigation(name))
    assert obs.pseudorange.shape == (120, SATELLITES[name]) and obs.week.tolist() == [1316] * 120
    assert obs.time_of_week[0] == 518400.0 and abs(obs.time_of_week[-1] - 521970.0) < 0.01
    assert np.all(np.diff(obs.time_of_week) > 29.99)
    np.testing.assert_array_equal(obs.approx_position, STATIONS[name])
    assert set(obs.code) == {"C1"} and np.all(np.isnan(obs.cn0))  # no S1 in these files
    seen = np.isfinite(obs.pseudorange)
    assert np.all((obs.pseudorange[seen] > 1.9e7) & (obs.pseudorange[seen] < 2.7e7))
    counts = [
        int(line[29:32])
        for line in Path(observation(name)).read_text().splitlines()
        if re.match(r" \d\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d\.\d{7}  0", line)
    ]
    assert seen.sum(axis=1).tolist() == counts  # every satellite of each epoch line has a C1
    assert eph.prn.size > 100 and np.all(np.isfinite(eph.ion_alpha)) and np.all(eph.health == 0)


@pytest.mark.parametrize("name", list(STATIONS))
def test_rtklib_rinex3_copy_reads_the_same(name, tmp_path):
    """RTKLIB's converter (``convbin -r rinex -v 3.03``) rewrites the RINEX 2.10 file as
    RINEX 3.03 (C1 -> C1C); the two read to the same satellites, times and pseudoranges."""
    options = rtk.rnxopt_t()
    for system in range(7):
        for k in range(64):
            options.mask[(system, k)] = "1"
    options.rnxver, options.navsys = 303, rtk.SYS_ALL
    options.obstype, options.freqtype, options.ttol = rtk.OBSTYPE_ALL, rtk.FREQTYPE_ALL, 0.005
    copy = tmp_path / "copy.obs"
    assert (
        rtk.convrnx(rtk.STRFMT_RINEX, options, str(observation(name)), [str(copy)] + [""] * 8) == 1
    )
    assert copy.read_text().startswith("     3.03           OBSERVATION DATA")
    two, three = read_observations(observation(name)), read_observations(copy)
    assert three.satellite.tolist() == two.satellite.tolist() and set(three.code) == {"C1C"}
    np.testing.assert_array_equal(three.week, two.week)
    np.testing.assert_array_equal(three.time_of_week, two.time_of_week)
    np.testing.assert_array_equal(three.pseudorange, two.pseudorange)


def test_single_point_positions_match_rtklib(station, tmp_path):
    name, obs, result = station
    reference = rtklib_positions(name, tmp_path)
    solved, differences = [], []
    for e, tow in enumerate(obs.time_of_week):
        match = [
            t for t in reference if abs(t - tow) < 0.1
        ]  # RTKLIB tags a solution with the corrected time
        if match:
            solved.append(e)
            differences.append(np.linalg.norm(result.fix.position[e] - reference[match[0]]))
    assert len(solved) == len(reference) == 115
    assert max(differences) < 1e-3, f"largest difference from RTKLIB {max(differences):.2e} m"
    # RTKLIB refuses the epochs whose GDOP exceeds 30 (the last five: five satellites in a poor geometry)
    assert (
        sorted(set(range(120)) - set(solved))
        == np.flatnonzero(result.fix.dops.gdop > MAX_GDOP).tolist()
    )
    assert np.all(result.fix.healthy)


def test_errors_from_the_surveyed_position_stay_below_the_protection_levels(station):
    """No misleading information on either hour: the horizontal and vertical errors from
    the surveyed position never exceed HPL/VPL (P_fa = P_md = 1e-3), and no epoch alarms."""
    name, _, result = station
    lat, lon = (math.radians(v) for v in (35.16, 139.61))
    north = np.array(
        [-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)]
    )
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    down = -np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    error = result.fix.position - np.array(STATIONS[name])
    horizontal, vertical = np.hypot(error @ north, error @ east), np.abs(error @ down)
    assert not result.check.alarm.any()
    assert np.all(horizontal < result.protection.hpl) and np.all(vertical < result.protection.vpl)
    assert (
        np.median(horizontal) < 1.5 and np.median(vertical) < 3.0
    )  # metre-level single-point fixes


def test_weights_are_rtklibs_error_model():
    """RTKLIB's URA of the RINEX accuracy (the smallest table value not below it) and its
    code variance at 30 deg: 2.4^2 + 0.3^2 + 0.3^2 (1 + 1 / sin 30 deg)."""
    np.testing.assert_array_equal(
        user_range_accuracy([0.0, 2.0, 2.4, 2.5, 7.0, 1e5, np.nan]),
        [2.4, 2.4, 2.4, 3.4, 9.65, 6144.0, 6144.0],
    )
    sigma = float(code_sigma(np.array([2.4]))(np.radians([30.0]))[0])
    assert sigma == pytest.approx(math.sqrt(2.4**2 + 0.09 + 0.09 * 3.0), rel=1e-14)


# --- damaged files ----------------------------------------------------------------------


def damaged(name: str, line_no: int, new: str | None) -> str:
    lines = Path(observation(name)).read_text().splitlines()
    if new is None:
        return "\n".join(lines[:line_no]) + "\n"  # truncated after line_no
    lines[line_no - 1] = new
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    "line_no, new, message",
    [
        (
            1,
            "     2.10           N: GPS NAV DATA                         RINEX VERSION / TYPE",
            ":1: expected a RINEX 2 or 3 observation file",
        ),
        (
            12,
            "     x    L1    C1    L2    P2                              # / TYPES OF OBSERV",
            ":12: # / TYPES OF OBSERV: expected the number of types",
        ),
        (17, "", ":1091: expected an 'END OF HEADER' line"),
        (
            18,
            " 05 13  2  0  0  0.0000000  0  8G 3G 7G 8G11G19G20G24G28",
            ":18: expected a valid epoch date",
        ),
        (
            18,
            " 05  4  2  0  0  0.0000000  0  8G 3G 7G 8G11G19G20G2x",
            ":18: expected a satellite (A1, I2)",
        ),
        (
            19,
            "  55923622.160    2476x686.375    43647388.2424   24767684.8224",
            ":19: G03 C1: expected a number",
        ),
        (20, None, ":20: the epoch of line 18: G08's 1 observation lines are missing"),
        (
            27,
            " 05  4  2  0  0 30.0000000  x  8G 3G 7G 8G11G19G20G24G28",
            ":27: expected the epoch flag",
        ),
    ],
)
def test_damaged_observation_file_names_the_line(line_no, new, message, tmp_path):
    path = tmp_path / "damaged.05o"
    path.write_text(damaged("0759", line_no, new))
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        read_observations(path)
    assert str(path) in str(info.value)


def test_damaged_rinex3_and_bytes_name_the_line(tmp_path):
    header = (
        "     3.03           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE\n"
        "G    2 C1C S1C                                              SYS / # / OBS TYPES \n"
        "                                                            END OF HEADER       \n"
    )
    good = header + "> 2005 04 02 00 00 00.0000000  0  1\nG03  24767686.375          45.000  \n"
    obs = parse_rinex_obs(good, "good.obs")
    assert (
        obs.satellite.tolist() == ["G03"]
        and obs.pseudorange[0, 0] == 24767686.375
        and obs.cn0[0, 0] == 45.0
    )
    cases = [
        (
            good.replace("0  1\n", "0  2\n"),
            ":5: the epoch of line 4 lists 2 satellites, the file ends after 1",
        ),
        (good.replace("G03  247", "E03  247"), ":5: satellite E03: its system 'E' has no"),
        (good.replace("> 2005", "< 2005"), ":4: expected an epoch line starting with '>'"),
        (
            good
            + "> 2005 04 02 00 00 30.0000000  0  2\nG03  24767686.375\n> 2005 04 02 00 01 00.0000000  0  1\n",
            ":8: the epoch of line 6 lists 2 satellites, found 1 before the next epoch",
        ),
    ]
    for text, message in cases:
        with pytest.raises(ValueError, match=message):
            parse_rinex_obs(text, "bad.obs")
    path = tmp_path / "bytes.obs"
    path.write_bytes(good.encode().replace(b"G03  247", b"G03  2\xe97"))
    with pytest.raises(ValueError, match=r"bytes.obs:5: expected ASCII text, got byte 0xe9"):
        read_observations(path)
