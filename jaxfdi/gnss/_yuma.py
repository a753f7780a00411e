"""YUMA almanac reader (NumPy): one record per satellite, checked field by field.

A YUMA file (US Coast Guard Navigation Center): per satellite a header line of asterisks and 13 ``Key: value`` lines
(ID, Health, Eccentricity, Time of Applicability, Orbital Inclination, Rate of Right Ascen, SQRT(A), Right Ascen at Week
(or "at TOA"), Argument of Perigee, Mean Anom, Af0, Af1, week). Angles in radians (inclination the full angle, not the
offset from 0.3 semicircles of IS-GPS-200 Table 20-VI); the 10-bit week plus ``rollovers`` (1024-week wraps) is the full
GPS week. LF or CRLF; a ``ValueError`` names the file and line of the first malformed, missing or repeated field.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxfdi import checks


class Almanac(NamedTuple):
    """Almanac of N satellites; every field is an (N,) NumPy array.

    Attributes:
      prn: int, PRN number
      health: int, 0 = healthy
      eccentricity: orbital eccentricity (dimensionless)
      toa: s, time of applicability (seconds of ``week``)
      inclination: rad, orbital inclination
      omega_dot: rad/s, rate of right ascension
      sqrt_a: m^0.5, square root of the semi-major axis
      omega0: rad, longitude of the ascending node at the weekly epoch
      argument_of_perigee: rad, argument of perigee
      mean_anomaly: rad, at toa
      af0: s, clock bias
      af1: s/s, clock drift
      week: int, full GPS week (file week + 1024 * rollovers)
    """

    prn: np.ndarray
    health: np.ndarray
    eccentricity: np.ndarray
    toa: np.ndarray
    inclination: np.ndarray
    omega_dot: np.ndarray
    sqrt_a: np.ndarray
    omega0: np.ndarray
    argument_of_perigee: np.ndarray
    mean_anomaly: np.ndarray
    af0: np.ndarray
    af1: np.ndarray
    week: np.ndarray


#: key prefix as written in YUMA files (lower case) -> field
_FIELDS = {
    "id": "prn",
    "health": "health",
    "eccentricity": "eccentricity",
    "time of applicability": "toa",
    "orbital inclination": "inclination",
    "rate of right ascen": "omega_dot",
    "sqrt(a)": "sqrt_a",
    "right ascen at": "omega0",
    "argument of perigee": "argument_of_perigee",
    "mean anom": "mean_anomaly",
    "af0": "af0",
    "af1": "af1",
    "week": "week",
}
#: the fields that are whole numbers
_INTEGER_FIELDS = ("prn", "health", "week")


def _field_of(key: str) -> str | None:
    key = key.strip().lower()
    return next((name for prefix, name in _FIELDS.items() if key.startswith(prefix)), None)


def parse_yuma(text: str, name: str = "<string>", rollovers: int = 0) -> Almanac:
    """Parse the text of a YUMA almanac.

    Args:
      text: the file's contents (LF or CRLF line endings).
      name: what error messages call the source (a file name).
      rollovers: 1024-week rollovers to add to the file's 10-bit week (2 since April 2019: file week 38 is GPS week
        2086).

    Raises:
      ValueError: naming ``name`` and the line of a malformed record.
    """
    rollovers = checks.check_int(
        "rollovers", rollovers, 0, meaning="a number of 1024-week rollovers >= 0"
    )
    records: list[dict] = []
    current: dict | None = None
    header_line = 0

    def close(record, line_no):
        missing = [n for n in _FIELDS.values() if n not in record]
        if missing:
            raise ValueError(
                f"{name}:{line_no}: almanac record starting on this line lacks {missing}"
            )

    for line_no, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("*"):
            if current is not None:
                close(current, header_line)
                records.append(current)
            current, header_line = {}, line_no
            continue
        if current is None:
            raise ValueError(
                f"{name}:{line_no}: expected a '******** ... almanac for PRN-nn ********' header "
                f"before the fields, got {line!r}"
            )
        key, sep, value = line.partition(":")
        field = _field_of(key)
        if not sep or field is None:
            raise ValueError(
                f"{name}:{line_no}: expected 'Key: value' with a YUMA key "
                f"({', '.join(_FIELDS)}), got {line!r}"
            )
        if field in current:
            raise ValueError(
                f"{name}:{line_no}: field {key.strip()!r} repeated in the record starting on line "
                f"{header_line}"
            )
        try:
            number = float(value.strip().replace("D", "E").replace("d", "e"))
            if field in _INTEGER_FIELDS:
                if number != int(number):
                    raise ValueError
                number = int(number)
            elif not np.isfinite(number):
                raise ValueError
        except ValueError:
            wanted = "whole number" if field in _INTEGER_FIELDS else "finite number"
            raise ValueError(
                f"{name}:{line_no}: field {key.strip()!r}: expected a {wanted}, "
                f"got {value.strip()!r}"
            ) from None
        current[field] = number
    if current is not None:
        close(current, header_line)
        records.append(current)
    if not records:
        raise ValueError(f"{name}: no almanac record found")
    prns = [r["prn"] for r in records]
    repeated = sorted({p for p in prns if prns.count(p) > 1})
    if repeated:
        raise ValueError(f"{name}: PRN(s) {repeated} appear in more than one record")
    columns = {
        field: np.asarray(
            [r[field] for r in records], dtype=int if field in _INTEGER_FIELDS else float
        )
        for field in _FIELDS.values()
    }
    columns["week"] = columns["week"] + 1024 * int(rollovers)
    return Almanac(**columns)


def read_yuma(path: str | Path, rollovers: int = 0) -> Almanac:
    """Read a YUMA almanac file (``parse_yuma`` on its ASCII text).

    Returns:
      ``Almanac``: one (N,) NumPy array per field for the file's N satellites, in file order (int PRN, health and full
      GPS week ``file week + 1024 * rollovers``; float the rest).
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("ascii")
    except UnicodeDecodeError as err:
        line = path.read_bytes()[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}:{line}: expected ASCII text, got byte {path.read_bytes()[err.start]:#04x}"
        ) from None
    return parse_yuma(text, str(path), rollovers)
