"""RINEX 2 GPS navigation-message reader (NumPy): broadcast ephemerides as arrays.

RINEX 2.x ``N`` file (Gurtner & Estey, RINEX 2.11, 2007): a header closed by ``END OF HEADER``, records of 8 lines: PRN
and clock epoch (``yy mm dd hh mm ss``, GPS time) with ``af0, af1, af2``, then 7 lines of 4 numbers (the last may hold
fewer): IODE, Crs, delta n, M0 / Cuc, e, Cus, sqrt(A) / toe, Cic, OMEGA0, Cis / i0, Crc, omega, OMEGA DOT / IDOT, L2
codes, GPS week, L2 P flag / accuracy, health, TGD, IODC / transmission time, fit interval.

Numbers are read as a sequence, not fixed ``D19.12`` columns (the shipped ``gps_nav_rinex2_sugl0010.20n``, by Stanford's
ephVote, writes 20 wide): Fortran ``D`` exponents accepted, adjacent numbers split, any other content rejected. LF and
CRLF accepted; a malformed header or record raises ``ValueError`` naming the file and line.
"""

from __future__ import annotations

import datetime as _dt
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

#: the start of GPS time (week 0)
GPS_EPOCH = _dt.date(1980, 1, 6)
SECONDS_PER_WEEK = 604800.0

_NUMBER = re.compile(r"[+-]?(?:\d+\.\d*|\.\d+|\d+)(?:[EeDd][+-]?\d+)?")

#: the record's fields after the epoch, line by line (7 broadcast-orbit lines)
_ORBIT_LINES = (
    ("iode", "crs", "delta_n", "m0"),
    ("cuc", "eccentricity", "cus", "sqrt_a"),
    ("toe", "cic", "omega0", "cis"),
    ("i0", "crc", "argument_of_perigee", "omega_dot"),
    ("idot", "l2_codes", "week", "l2p_flag"),
    ("accuracy", "health", "tgd", "iodc"),
    ("transmit_time", "fit_interval"),
)
#: numbers a line must hold (the last line's fit interval may be blank)
_REQUIRED = (4, 4, 4, 4, 4, 4, 1)


class Ephemerides(NamedTuple):
    """N broadcast ephemeris records, each field an (N,) NumPy array; radians and seconds (IS-GPS-200).

    Attributes:
      prn: int, PRN number
      toc_week: int, GPS week of the clock epoch
      toc: s of toc_week
      af0: s, clock bias at toc
      af1: s/s, clock drift
      af2: s/s^2, clock drift rate
      iode: int, issue of data, ephemeris
      crs: m, sine harmonic correction to the orbit radius
      delta_n: rad/s, mean motion correction
      m0: rad, mean anomaly at toe
      cuc: rad, cosine harmonic correction to the argument of latitude
      eccentricity: orbital eccentricity (dimensionless)
      cus: rad, sine harmonic correction to the argument of latitude
      sqrt_a: m^0.5, square root of the semi-major axis
      toe: s of week, ephemeris reference time
      cic: rad, cosine harmonic correction to the inclination
      omega0: rad, longitude of the ascending node at the weekly epoch
      cis: rad, sine harmonic correction to the inclination
      i0: rad, inclination at toe
      crc: m, cosine harmonic correction to the orbit radius
      argument_of_perigee: rad, argument of perigee
      omega_dot: rad/s, rate of right ascension
      idot: rad/s, rate of inclination
      l2_codes: codes on L2
      week: int, GPS week of toe (continuous, not mod 1024)
      l2p_flag: L2 P data flag
      accuracy: m (URA)
      health: int, 0 = healthy
      tgd: s, group delay differential
      iodc: int, issue of data, clock
      transmit_time: s of week, transmission time of the message
      fit_interval: h (0: 4 hours, per RINEX 2.11)
      ion_alpha: (4,) Klobuchar alpha from the header, NaN if absent
      ion_beta: (4,) Klobuchar beta, NaN if absent
    """

    prn: np.ndarray
    toc_week: np.ndarray
    toc: np.ndarray
    af0: np.ndarray
    af1: np.ndarray
    af2: np.ndarray
    iode: np.ndarray
    crs: np.ndarray
    delta_n: np.ndarray
    m0: np.ndarray
    cuc: np.ndarray
    eccentricity: np.ndarray
    cus: np.ndarray
    sqrt_a: np.ndarray
    toe: np.ndarray
    cic: np.ndarray
    omega0: np.ndarray
    cis: np.ndarray
    i0: np.ndarray
    crc: np.ndarray
    argument_of_perigee: np.ndarray
    omega_dot: np.ndarray
    idot: np.ndarray
    l2_codes: np.ndarray
    week: np.ndarray
    l2p_flag: np.ndarray
    accuracy: np.ndarray
    health: np.ndarray
    tgd: np.ndarray
    iodc: np.ndarray
    transmit_time: np.ndarray
    fit_interval: np.ndarray
    ion_alpha: np.ndarray
    ion_beta: np.ndarray


def gps_week_seconds(
    year: int, month: int, day: int, hour: int = 0, minute: int = 0, second: float = 0.0
) -> tuple[int, float]:
    """``(week, seconds of week)`` of a GPS-time calendar date (no leap seconds: GPS time)."""
    for name, value, high in (
        ("hour", hour, 24.0),
        ("minute", minute, 60.0),
        ("second", second, 60.0),
    ):
        if not (isinstance(value, (int, float, np.integer, np.floating)) and 0 <= value < high):
            raise ValueError(f"{name}: expected a number in [0, {high:g}), got {value!r}")
    days = (_dt.date(int(year), int(month), int(day)) - GPS_EPOCH).days
    if days < 0:
        raise ValueError(
            f"date: expected a date on or after {GPS_EPOCH} (GPS week 0), got {year}-{month}-{day}"
        )
    week, weekday = divmod(days, 7)
    return week, weekday * 86400.0 + hour * 3600.0 + minute * 60.0 + float(second)


def _numbers(text: str, name: str, line_no: int, what: str) -> list[float]:
    """The numbers of ``text`` in order; anything else on the line is an error."""
    found = _NUMBER.findall(text)
    rest = _NUMBER.sub(" ", text)
    if rest.strip():
        raise ValueError(f"{name}:{line_no}: {what}: expected numbers only, found {rest.strip()!r}")
    return [float(v.replace("D", "E").replace("d", "e")) for v in found]


def _parse_header(lines: list[str], name: str) -> tuple[int, np.ndarray, np.ndarray]:
    """Index of the first record line, and the header's ION ALPHA / ION BETA."""
    if not lines:
        raise ValueError(
            f"{name}:1: expected a 'RINEX VERSION / TYPE' header line, got an empty file"
        )
    first = lines[0]
    if first[60:].strip() != "RINEX VERSION / TYPE":
        raise ValueError(
            f"{name}:1: expected 'RINEX VERSION / TYPE' in columns 61-80, got {first!r}"
        )
    try:
        version = float(first[:9])
    except ValueError:
        raise ValueError(
            f"{name}:1: expected the RINEX version in columns 1-9, got {first[:9]!r}"
        ) from None
    if not 2.0 <= version < 3.0:
        raise ValueError(f"{name}:1: expected a RINEX 2.x file, got version {version}")
    if first[20:21] != "N":
        raise ValueError(
            f"{name}:1: expected file type 'N' (GPS navigation message) in column 21, "
            f"got {first[20:21]!r}"
        )
    alpha = np.full(4, np.nan)
    beta = np.full(4, np.nan)
    for index, line in enumerate(lines[1:], start=1):
        label = line[60:].strip()
        if label == "END OF HEADER":
            return index + 1, alpha, beta
        if label in ("ION ALPHA", "ION BETA"):
            values = _numbers(line[:60], name, index + 1, label)
            if len(values) != 4:
                raise ValueError(
                    f"{name}:{index + 1}: {label}: expected 4 numbers, got {len(values)}"
                )
            (alpha if label == "ION ALPHA" else beta)[:] = values
    raise ValueError(
        f"{name}:{len(lines)}: expected an 'END OF HEADER' line, reached the end of the file"
    )


def parse_rinex_nav(text: str, name: str = "<string>") -> Ephemerides:
    """Parse the text of a RINEX 2 GPS navigation file (see the module doc).

    Raises:
      ValueError: naming ``name`` and the line of the first malformed header or record.
    """
    lines = text.splitlines()
    start, alpha, beta = _parse_header(lines, name)
    body = [(i + 1, line) for i, line in enumerate(lines[start:], start=start)]
    while body and not body[-1][1].strip():
        body.pop()
    records: list[dict] = []
    position = 0
    while position < len(body):
        line_no, epoch = body[position]
        if len(body) - position < 8:
            raise ValueError(
                f"{name}:{line_no}: record starting here has {len(body) - position} lines, expected 8 "
                f"(the epoch line and 7 broadcast-orbit lines)"
            )
        try:
            prn = int(epoch[0:2])
            year, month, day, hour, minute = (int(epoch[i : i + 3]) for i in range(2, 17, 3))
            second = float(epoch[17:22])
        except ValueError:
            raise ValueError(
                f"{name}:{line_no}: expected a record's first line 'PRN yy mm dd hh mm ss.s' "
                f"(I2, 5I3, F5.1), got {epoch!r}"
            ) from None
        if not 1 <= prn <= 32 or not 1 <= month <= 12 or not 1 <= day <= 31 or not 0 <= hour < 24:
            raise ValueError(
                f"{name}:{line_no}: expected PRN 1-32 and a valid date/time, got {epoch[:22]!r}"
            )
        clock = _numbers(epoch[22:], name, line_no, "SV clock bias, drift, drift rate")
        if len(clock) != 3:
            raise ValueError(
                f"{name}:{line_no}: expected 3 numbers (af0, af1, af2) after the epoch, got {len(clock)}"
            )
        year += 2000 if year < 80 else 1900
        try:
            toc_week, toc = gps_week_seconds(year, month, day, hour, minute, second)
        except ValueError:
            raise ValueError(
                f"{name}:{line_no}: expected a valid epoch date, got {epoch[:22]!r}"
            ) from None
        record = {
            "prn": prn,
            "toc_week": toc_week,
            "toc": toc,
            "af0": clock[0],
            "af1": clock[1],
            "af2": clock[2],
        }
        for offset, (fields, required) in enumerate(zip(_ORBIT_LINES, _REQUIRED), start=1):
            orbit_no, orbit = body[position + offset]
            values = _numbers(
                orbit, name, orbit_no, f"broadcast orbit line {offset} of PRN {prn:02d}"
            )
            if not required <= len(values) <= 4:
                raise ValueError(
                    f"{name}:{orbit_no}: broadcast orbit line {offset} of PRN {prn:02d} "
                    f"({', '.join(fields)}): expected {required if required == 4 else f'{required}-4'} "
                    f"numbers, got {len(values)}"
                )
            values += [0.0] * (len(fields) - len(values))
            record.update(zip(fields, values[: len(fields)]))
        records.append(record)
        position += 8
    if not records:
        raise ValueError(f"{name}: no ephemeris record after the header")
    ints = {"prn", "toc_week", "week", "health"}
    columns = {
        field: np.asarray([r[field] for r in records], dtype=int if field in ints else float)
        for field in Ephemerides._fields
        if field not in ("ion_alpha", "ion_beta")
    }
    return Ephemerides(**columns, ion_alpha=alpha, ion_beta=beta)


def read_rinex_nav(path: str | Path) -> Ephemerides:
    """Read a RINEX 2 GPS navigation file (``parse_rinex_nav`` on its ASCII text).

    Returns:
      ``Ephemerides``: (N,) arrays in file order (int PRN, weeks, health; float the rest), header's (4,)
      ``ion_alpha`` / ``ion_beta`` (NaN if absent).
    """
    return parse_rinex_nav(read_ascii(path), str(path))


def read_ascii(path: str | Path) -> str:
    """The text of an ASCII file (LF or CRLF lines).

    Returns:
      ``str``; a byte outside ASCII is a ``ValueError`` naming the file and its line.
    """
    data = Path(path).read_bytes()
    try:
        return data.decode("ascii")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}:{line}: expected ASCII text, got byte {data[err.start]:#04x}"
        ) from None
