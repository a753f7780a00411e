"""YUMA and RINEX 2 readers: the shipped files against RTKLIB's reader (pyrtklib) and the
values printed in them, both line endings, both number widths, and clear errors naming
the line of a damaged record."""

import re

import numpy as np
import pyrtklib as rtk
import pytest

from jaxfdi.data import data_path
from jaxfdi.gnss import read_rinex_nav, read_yuma
from jaxfdi.gnss._rinex import gps_week_seconds, parse_rinex_nav
from jaxfdi.gnss._yuma import parse_yuma

RINEX = data_path("gps_nav_rinex2_sugl0010.20n")
YUMA = data_path("gps_almanac_2086.yuma.txt")
MOPS = data_path("gps_almanac_0703_rtca_mops24.yuma.txt")


def standard_width_copy(text: str) -> str:
    """The navigation file rewritten with RINEX 2.11's D19.12 fields (3X,4D19.12): the
    shipped file writes 20-character fields, which fixed-column readers (RTKLIB,
    georinex) misread. Plain ``split`` is enough here: its numbers are blank-separated."""
    out, header = [], True
    for line in text.splitlines():
        if header:
            out.append(line)
            header = "END OF HEADER" not in line
            continue
        values = [f"{float(v):19.12E}" for v in line.split()[7 if line[:2].strip() else 0 :]]
        out.append((line[:22] if line[:2].strip() else "   ") + "".join(values))
    return "\n".join(out) + "\n"


@pytest.fixture(scope="module")
def ephemerides():
    return read_rinex_nav(RINEX)


@pytest.fixture(scope="module")
def rtklib_nav(tmp_path_factory):
    path = tmp_path_factory.mktemp("rinex") / "standard.20n"
    path.write_text(standard_width_copy(RINEX.read_bytes().decode("ascii")))
    nav, obs, sta = rtk.nav_t(), rtk.obs_t(), rtk.sta_t()
    assert rtk.readrnx(str(path), 1, "", obs, nav, sta) == 1
    return nav, path


def test_shipped_files_have_crlf_and_are_read():
    assert b"\r\n" in RINEX.read_bytes() and b"\r\n" in YUMA.read_bytes()
    almanac = read_yuma(YUMA, rollovers=2)
    assert almanac.prn.size == 31 and 18 not in almanac.prn  # data README: 31 SVs, PRN 18 absent
    assert almanac.health[almanac.prn == 4][0] == 63 and np.all(
        almanac.health[almanac.prn != 4] == 0
    )
    assert np.all(almanac.week == 2086) and np.all(almanac.toa == 503808.0)
    first = {f: getattr(almanac, f)[0] for f in almanac._fields}
    assert first["eccentricity"] == 0.9250164032e-2 and first["sqrt_a"] == 5153.594238
    assert first["omega0"] == -0.5806106047 and first["af1"] == -0.1091393642e-10
    mops = read_yuma(MOPS)
    assert mops.prn.size == 24 and np.all(mops.eccentricity == 0.0) and np.all(mops.week == 703)
    np.testing.assert_allclose(mops.inclination, 0.9599310886)
    assert len(np.unique(np.round(mops.omega0, 6))) == 6  # 6 planes x 4


def test_line_endings_do_not_matter(ephemerides):
    text = RINEX.read_bytes().decode("ascii")
    lf = parse_rinex_nav(text.replace("\r\n", "\n"))
    for name in ephemerides._fields:
        np.testing.assert_array_equal(getattr(lf, name), getattr(ephemerides, name))
    yuma_lf = parse_yuma(YUMA.read_bytes().decode("ascii").replace("\r\n", "\n"), rollovers=2)
    np.testing.assert_array_equal(yuma_lf.sqrt_a, read_yuma(YUMA, 2).sqrt_a)


def test_rinex_matches_rtklib_reader_and_both_widths(ephemerides, rtklib_nav):
    nav, standard_path = rtklib_nav
    eph = ephemerides
    assert (
        nav.n == eph.prn.size == 418
        and set(eph.prn) == set(range(1, 33))
        and np.all(eph.week == 2086)
    )
    ours = {
        (int(p), float(t), int(i)): k for k, (p, t, i) in enumerate(zip(eph.prn, eph.toe, eph.iode))
    }
    pairs = [
        ("A", lambda e, k: e.sqrt_a[k] ** 2),
        ("e", "eccentricity"),
        ("i0", "i0"),
        ("OMG0", "omega0"),
        ("omg", "argument_of_perigee"),
        ("M0", "m0"),
        ("deln", "delta_n"),
        ("OMGd", "omega_dot"),
        ("idot", "idot"),
        ("crc", "crc"),
        ("crs", "crs"),
        ("cuc", "cuc"),
        ("cus", "cus"),
        ("cic", "cic"),
        ("cis", "cis"),
        ("f0", "af0"),
        ("f1", "af1"),
        ("f2", "af2"),
        ("svh", "health"),
        ("iodc", "iodc"),
    ]
    for r in range(nav.n):
        e = nav.eph[r]
        k = ours[(e.sat, e.toes, e.iode)]
        for theirs, mine in pairs:
            value = mine(eph, k) if callable(mine) else getattr(eph, mine)[k]
            assert getattr(e, theirs) == pytest.approx(value, rel=1e-12, abs=1e-300), (r, theirs)
        assert e.tgd[0] == pytest.approx(eph.tgd[k], rel=1e-12, abs=1e-300)
    standard = read_rinex_nav(standard_path)  # 19-character fields read the same
    for name in eph._fields:
        np.testing.assert_allclose(
            getattr(standard, name), getattr(eph, name), rtol=1e-12, equal_nan=True
        )


def test_calendar_to_gps_week():
    assert gps_week_seconds(2020, 1, 1) == (2086, 259200.0)
    assert gps_week_seconds(1980, 1, 6, 0, 0, 1.5) == (0, 1.5)
    with pytest.raises(ValueError, match="GPS week 0"):
        gps_week_seconds(1979, 12, 31)


def damaged(text: str, line_no: int, new: str | None) -> str:
    lines = text.split("\n")
    if new is None:
        del lines[line_no - 1]
    else:
        lines[line_no - 1] = new
    return "\n".join(lines)


@pytest.mark.parametrize(
    "line_no, new, message",
    [
        (
            4,
            "Eccentricity:               0.92X0164032E-002\r",
            r"bad\.txt:4: field 'Eccentricity': expected a finite number",
        ),
        (
            2,
            "ID:                         1.5\r",
            r"bad\.txt:2: field 'ID': expected a whole number",
        ),
        (
            6,
            "Orbit Inclination(rad):   0.9785563052\r",
            r"bad\.txt:6: expected 'Key: value' with a YUMA key",
        ),
        (7, None, r"bad\.txt:1: almanac record starting on this line lacks \['omega_dot'\]"),
        (5, "Health:                     000\r", r"bad\.txt:5: field 'Health' repeated"),
    ],
)
def test_malformed_yuma_names_the_line(line_no, new, message):
    text = YUMA.read_bytes().decode("ascii")
    with pytest.raises(ValueError, match=message):
        parse_yuma(damaged(text, line_no, new), "bad.txt")


def test_malformed_yuma_file_on_disk(tmp_path):
    path = tmp_path / "alm.txt"
    path.write_bytes(
        YUMA.read_bytes().replace(
            b"Mean Anom(rad):             0.2779790776E+001", b"Mean Anom(rad):             n/a"
        )
    )
    with pytest.raises(ValueError, match=re.escape(f"{path}:11: field 'Mean Anom(rad)'")):
        read_yuma(path)
    path.write_bytes(b"ID: 01\r\n")
    with pytest.raises(ValueError, match=re.escape(f"{path}:1: expected a '******** ... almanac")):
        read_yuma(path)


@pytest.mark.parametrize(
    "line_no, new, message",
    [
        (
            1,
            "     3.04           N: GNSS NAV DATA    G: GPS              RINEX VERSION / TYPE\r",
            r"bad\.20n:1: expected a RINEX 2\.x file, got version 3\.04",
        ),
        (
            1,
            "     2              OBSERVATION DATA                        RINEX VERSION / TYPE\r",
            r"bad\.20n:1: expected file type 'N'",
        ),
        (
            5,
            "     7.200000000000E+01 -1.95625000000OE+01  4.218032840856E-09 -1.483804704890E+00\r",
            r"bad\.20n:5: broadcast orbit line 1 of PRN 01: expected numbers only, found 'OE'",
        ),
        (
            6,
            "    -9.573996067047E-07  9.235781384632E-03  3.913417458534E-06\r",
            r"bad\.20n:6: broadcast orbit line 2 of PRN 01 \(cuc, eccentricity, cus, sqrt_a\): "
            r"expected 4 numbers, got 3",
        ),
        (
            12,
            " 1 20 13  1  2  0  0.0 -2.479893155396E-04 -1.216449163621E-11  0.000000000000E+00\r",
            r"bad\.20n:12: expected PRN 1-32 and a valid date/time",
        ),
        (
            3,
            "                                                            END OF HEADR        \r",
            r"bad\.20n:\d+: expected an 'END OF HEADER' line",
        ),
    ],
)
def test_malformed_rinex_names_the_line(line_no, new, message):
    text = RINEX.read_bytes().decode("ascii")
    with pytest.raises(ValueError, match=message):
        parse_rinex_nav(damaged(text, line_no, new), "bad.20n")


def test_truncated_rinex_record(tmp_path):
    lines = RINEX.read_bytes().split(b"\r\n")
    path = tmp_path / "short.20n"
    path.write_bytes(b"\r\n".join(lines[: 3 + 8 + 5]) + b"\r\n")
    with pytest.raises(
        ValueError, match=re.escape(f"{path}:12: record starting here has 5 lines, expected 8")
    ):
        read_rinex_nav(path)
