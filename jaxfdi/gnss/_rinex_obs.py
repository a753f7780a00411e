"""RINEX 2 and 3 observation-file reader (NumPy): code pseudoranges and C/N0 per epoch.

Format (Gurtner & Estey, RINEX 2.11, 2007; IGS RINEX 3.04, 2018): header closed by ``END OF HEADER``, then
epoch records. RINEX 2: types listed once (``# / TYPES OF OBSERV``); epoch line ``yy mm dd hh mm
ss.sssssss  flag n`` with ``n`` satellites (12 per line), then each satellite's fields, five of 16
characters per line (``F14.3`` value, loss-of-lock and signal-strength digits). RINEX 3: types per
system (``SYS / # / OBS TYPES``); epoch line ``>``, one line per satellite (``G05`` then fields).

Kept per system: the first single-frequency code of ``CODE_PRIORITY`` in the header (GPS, QZSS, GLONASS
``C1``/``C1C``, Galileo E1, BeiDou B1I) and its signal strength (``S1``, ``S1C``, ... dB-Hz) if recorded.
Flags 0 (ok) and 1 (power failure) are observations; events (2-5) and cycle slips (6) are skipped. A
malformed header or record raises ``ValueError`` naming the file and line.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxfdi.gnss._rinex import gps_week_seconds

#: per system, the codes read as its pseudorange, best first (RINEX 2 names, then RINEX 3)
CODE_PRIORITY = {
    "G": ("C1", "P1", "C1C", "C1W", "C1P", "C1X"),
    "J": ("C1", "C1C", "C1X", "C1Z"),
    "R": ("C1", "P1", "C1C", "C1P"),
    "E": ("C1", "C1C", "C1X", "C1B"),
    "C": ("C2", "C2I", "C1I", "C2X"),
    "S": ("C1", "C1C"),
}
#: width of one observation field: F14.3, loss-of-lock digit, signal-strength digit
FIELD = 16


class Observations(NamedTuple):
    """E epochs of S satellites' code observations, dense: NaN where a satellite has none.

    Attributes:
      week: (E,) int, GPS week of each epoch
      time_of_week: (E,) s of the week, the receiver's time tag (GPS time)
      satellite: (S,) str, system letter and number (``G05``, ``E11``), sorted
      code: (S,) str, the observation code read for each satellite (``C1``, ``C1C``, ``C2I``)
      pseudorange: (E, S) m, NaN where not observed
      cn0: (E, S) dB-Hz, carrier-to-noise density (``S`` type of the same band), NaN if not recorded
      approx_position: (3,) m, ECEF ``APPROX POSITION XYZ`` of the header (NaN if absent)
    """

    week: np.ndarray
    time_of_week: np.ndarray
    satellite: np.ndarray
    code: np.ndarray
    pseudorange: np.ndarray
    cn0: np.ndarray
    approx_position: np.ndarray


def _fail(name: str, line_no: int, message: str):
    raise ValueError(f"{name}:{line_no}: {message}")


def _header(lines: list[str], name: str):
    """``(version, first record line, {system: [types]}, approx position)``."""
    if not lines:
        _fail(name, 1, "expected a 'RINEX VERSION / TYPE' header line, got an empty file")
    first = lines[0]
    if first[60:].strip() != "RINEX VERSION / TYPE":
        _fail(name, 1, f"expected 'RINEX VERSION / TYPE' in columns 61-80, got {first!r}")
    try:
        version = float(first[:9])
    except ValueError:
        _fail(name, 1, f"expected the RINEX version in columns 1-9, got {first[:9]!r}")
    if not 2.0 <= version < 4.0 or first[20:21] != "O":
        _fail(
            name,
            1,
            f"expected a RINEX 2 or 3 observation file (type 'O' in column 21), got version "
            f"{version} type {first[20:21]!r}",
        )
    default_system = first[40:41].strip() or "G"
    types: dict[str, list[str]] = {}
    approx = np.full(3, np.nan)
    pending: tuple[str, int] | None = (
        None  # (system, count) of a type list continued on the next line
    )
    for index, line in enumerate(lines[1:], start=2):
        label = line[60:].strip()
        if label == "END OF HEADER":
            if not types:
                _fail(
                    name,
                    index,
                    "expected the observation types ('# / TYPES OF OBSERV' or "
                    "'SYS / # / OBS TYPES') before 'END OF HEADER'",
                )
            return version, index, types, approx
        if label == "APPROX POSITION XYZ":
            try:
                approx = np.array([float(line[i : i + 14]) for i in (0, 14, 28)])
            except ValueError:
                _fail(
                    name,
                    index,
                    f"APPROX POSITION XYZ: expected 3 numbers (3F14.4), got {line[:42]!r}",
                )
            continue
        if label == "# / TYPES OF OBSERV" and version < 3:
            if pending is None:
                count = _count(line[:6], name, index, "# / TYPES OF OBSERV")
                pending = (default_system, count)
                types["*"] = []
            types["*"] += line[6:60].split()
        elif label == "SYS / # / OBS TYPES" and version >= 3:
            if line[0] != " ":
                count = _count(line[3:6], name, index, "SYS / # / OBS TYPES")
                pending = (line[0], count)
                types[line[0]] = []
            elif pending is None:
                _fail(
                    name,
                    index,
                    "SYS / # / OBS TYPES: a continuation line without a system line before it",
                )
            types[pending[0]] += line[7:60].split()
        else:
            continue
        key = "*" if version < 3 else pending[0]
        if len(types[key]) > pending[1]:
            _fail(
                name, index, f"{label}: {len(types[key])} types listed, the count says {pending[1]}"
            )
        if len(types[key]) == pending[1]:
            pending = None
    _fail(name, len(lines), "expected an 'END OF HEADER' line, reached the end of the file")


def _count(text: str, name: str, line_no: int, label: str) -> int:
    try:
        value = int(text)
    except ValueError:
        _fail(name, line_no, f"{label}: expected the number of types, got {text!r}")
    if value < 1:
        _fail(name, line_no, f"{label}: expected at least one observation type, got {value}")
    return value


def _flag_count(line: str, at: int, name: str, line_no: int) -> tuple[int, int]:
    """The epoch flag (column ``at + 1``) and the count after it (I3): an event's date may be blank."""
    try:
        return int(line[at]), int(line[at + 1 : at + 4])
    except (ValueError, IndexError):
        _fail(
            name,
            line_no,
            f"expected the epoch flag (I1) and the number of satellites or records (I3) in "
            f"columns {at + 1}-{at + 4}, got {line!r}",
        )


def _epoch_time(text: str, name: str, line_no: int, two_digit_year: bool) -> tuple[int, float]:
    """``(week, seconds of week)`` of an epoch line's ``year month day hour minute second``."""
    try:
        year, month, day, hour, minute = (int(v) for v in text.split()[:5])
        second = float(text.split()[5])
    except (ValueError, IndexError):
        _fail(name, line_no, f"expected an epoch 'year month day hour minute second', got {text!r}")
    if two_digit_year:
        year += 2000 if year < 80 else 1900
    try:
        return gps_week_seconds(year, month, day, hour, minute, second)
    except ValueError as err:
        _fail(name, line_no, f"expected a valid epoch date and time, got {text!r} ({err})")


def _values(
    text: str, types: list[str], name: str, line_no: int, satellite: str
) -> dict[str, float]:
    """The observation fields of one satellite's record (``text``: its fields only)."""
    out = {}
    for k, kind in enumerate(types):
        field = text[k * FIELD : k * FIELD + 14]
        if field.strip():
            try:
                out[kind] = float(field)
            except ValueError:
                _fail(
                    name,
                    line_no,
                    f"{satellite} {kind}: expected a number (F14.3) in columns "
                    f"{k * FIELD + 1}-{k * FIELD + 14} of its fields, got {field!r}",
                )
    return out


def _records(read_record, lines: list[str], start: int, types: dict, name: str):
    """Yield each epoch's ``(week, tow, {satellite: {type: value}})``; ``read_record(lines, position, types,
    name)`` returns the next record's position and the epoch (``None``: an event); blank lines skipped."""
    position = start
    while position < len(lines):
        if not lines[position].strip():
            position += 1
            continue
        position, record = read_record(lines, position, types, name)
        if record is not None:
            yield record


def _record_v2(lines, position, types, name):
    """A RINEX 2 record: an epoch line, its satellite list continued every 12, and each
    satellite's fields, five to a line."""
    kinds = types["*"]
    per_line = 5
    line_no, line = position + 1, lines[position]
    flag, count = _flag_count(line, 28, name, line_no)
    if flag > 1:  # an event: `count` special records (header lines) follow, or cycle slips (6)
        return position + 1 + (count if flag != 6 else count * -(-len(kinds) // per_line)), None
    week, tow = _epoch_time(line[:26], name, line_no, True)
    satellites, at = [], position
    while len(satellites) < count:
        if at >= len(lines):
            _fail(
                name,
                at,
                f"the epoch of line {line_no} lists {count} satellites, the file ends after "
                f"{len(satellites)}",
            )
        names = lines[at][32:68]
        if at != position and lines[at][:32].strip():
            _fail(
                name,
                at + 1,
                f"expected the satellite list of the epoch of line {line_no} continued in "
                f"columns 33-68, got {lines[at]!r}",
            )
        for k in range(0, min(36, 3 * (count - len(satellites))), 3):
            sat = names[k : k + 3]
            system = sat[0] if sat[0] != " " else "G"
            try:
                satellites.append(f"{system}{int(sat[1:]):02d}")
            except ValueError:
                _fail(
                    name,
                    at + 1,
                    f"expected a satellite (A1, I2) in columns {33 + k}-{35 + k}, got {sat!r}",
                )
        at += 1
    rows = -(-len(kinds) // per_line)
    record = {}
    for sat in satellites:
        if at + rows > len(lines):
            _fail(
                name,
                len(lines),
                f"the epoch of line {line_no}: {sat}'s {rows} observation lines are "
                f"missing (the file ends)",
            )
        text = "".join(
            lines[at + r][: FIELD * per_line].ljust(FIELD * per_line) for r in range(rows)
        )
        record[sat] = _values(text, kinds, name, at + 1, sat)
        at += rows
    return at, (week, tow, record)


def _record_v3(lines, position, types, name):
    """A RINEX 3 record: an epoch line ``>`` and one line per satellite."""
    line_no, line = position + 1, lines[position]
    if line[0] != ">":
        _fail(name, line_no, f"expected an epoch line starting with '>', got {line!r}")
    flag, count = _flag_count(line, 31, name, line_no)
    if flag > 1:
        return position + 1 + count, None
    week, tow = _epoch_time(line[1:29], name, line_no, False)
    if position + count >= len(lines):
        _fail(
            name,
            len(lines),
            f"the epoch of line {line_no} lists {count} satellites, the file ends "
            f"after {len(lines) - 1 - position}",
        )
    record = {}
    for at in range(position + 1, position + 1 + count):
        text = lines[at]
        if text.startswith(">"):
            _fail(
                name,
                at + 1,
                f"the epoch of line {line_no} lists {count} satellites, found "
                f"{at - position - 1} before the next epoch",
            )
        system = text[0]
        try:
            sat = f"{system}{int(text[1:3]):02d}"
        except ValueError:
            _fail(
                name,
                at + 1,
                f"expected a satellite identifier (A1, I2) in columns 1-3, got {text[:3]!r}",
            )
        if system not in types:
            _fail(
                name,
                at + 1,
                f"satellite {sat}: its system {system!r} has no 'SYS / # / OBS TYPES' line",
            )
        record[sat] = _values(text[3:], types[system], name, at + 1, sat)
    return position + 1 + count, (week, tow, record)


def parse_rinex_obs(text: str, name: str = "<string>") -> Observations:
    """Parse the text of a RINEX 2 or 3 observation file (see the module doc).

    Returns:
      ``Observations``: one row per observation epoch, one column per satellite seen.

    Raises:
      ValueError: naming ``name`` and the line of the first malformed header or record.
    """
    lines = text.splitlines()
    version, start, types, approx = _header(lines, name)
    records = list(_records(_record_v2 if version < 3 else _record_v3, lines, start, types, name))
    if not records:
        _fail(name, len(lines), "no observation epoch after the header")
    satellites = sorted({sat for _, _, record in records for sat in record})

    def listed(system):
        return types["*"] if version < 3 else types.get(system, [])

    codes = {}
    for system in {sat[0] for sat in satellites}:
        codes[system] = next(
            (c for c in CODE_PRIORITY.get(system, ()) if c in listed(system)), None
        )
    satellites = [sat for sat in satellites if codes[sat[0]] is not None]
    epochs, count = len(records), len(satellites)
    pseudorange = np.full((epochs, count), np.nan)
    cn0 = np.full((epochs, count), np.nan)
    for e, (_, _, record) in enumerate(records):
        for s, sat in enumerate(satellites):
            values = record.get(sat, {})
            code = codes[sat[0]]
            pseudorange[e, s] = values.get(code, np.nan)
            cn0[e, s] = values.get("S" + code[1:], np.nan)
    return Observations(
        week=np.array([r[0] for r in records], int),
        time_of_week=np.array([r[1] for r in records]),
        satellite=np.array(satellites, dtype="<U3"),
        code=np.array([codes[s[0]] for s in satellites], dtype="<U3"),
        pseudorange=pseudorange,
        cn0=cn0,
        approx_position=approx,
    )
