"""Android GnssLogger logs (``Raw`` records; the format of the Smartphone Decimeter Challenge's ``*_GnssLog.txt`` files)
into ``Observations``: pseudoranges generated from the receiver's clock and the satellite time it received (European
GNSS Agency, "Using GNSS raw measurements on Android devices", white paper, 2017, sec. 2.4):

``t_Rx = TimeNanos + TimeOffsetNanos - (FullBiasNanos + BiasNanos)``  [ns, GPS time]

``rho = c (t_Rx,sys - ReceivedSvTimeNanos)`` wrapped into half the satellite time's period, ``t_Rx,sys`` in
the satellite's frame: GPS, Galileo, QZSS time of week; BeiDou time of week (BDT = GPST - 14 s);
GLONASS time of day (UTC(SU) = GPST - leap seconds + 3 h). Each epoch's own ``FullBiasNanos``: the tag
is GPS time (Google's tools hold the first epoch's bias: a receiver-clock term common to the epoch).

A pseudorange needs an unambiguous satellite time (``State`` TOW_DECODED or TOW_KNOWN; GLONASS GLO_TOD_DECODED or
GLO_TOD_KNOWN) uncertain by < 500 ns (as gps-measurement-tools and gnss_lib_py); otherwise NaN. Code: RINEX 3 (band from
``CarrierFrequencyHz``, attribute from ``CodeType``, or C/A and BeiDou B1I in older logs); per system the first
``CODE_PRIORITY`` code kept (one single-frequency pseudorange per satellite). QZSS PRNs 193-202 read as J01-J10; SBAS,
IRNSS and GLONASS rows without a slot are skipped. ``approx_position``: the first GPS-provider ``Fix``, NaN without one.
A malformed record raises ``ValueError`` naming the file and line.

Not gnss_lib_py's ``AndroidRawGnss``: it raises ``KeyError`` without a ``CodeType`` column (the 2021 Pixel 4
log here) and uses float64 seconds (~1 cm of range); here the nanoseconds stay integers.
"""

from __future__ import annotations

import numpy as np

from jaxfdi.gnss._android import (
    CONSTELLATIONS,
    GPS_EPOCH_UNIX_MS,
    LEAP_SECONDS_MS,
    LEAP_VALID_FROM_UNIX_MS,
    geodetic_ecef64,
)
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT
from jaxfdi.gnss._rinex import SECONDS_PER_WEEK
from jaxfdi.gnss._rinex_obs import CODE_PRIORITY, Observations, _fail

WEEK_NS = int(SECONDS_PER_WEEK) * 10**9
DAY_NS = 86_400 * 10**9
#: Android GnssMeasurement state bits: time of week (or GLONASS time of day) decoded or known
TOW_DECODED, TOW_KNOWN, GLO_TOD_DECODED, GLO_TOD_KNOWN = 0x8, 0x4000, 0x80, 0x8000
#: largest ReceivedSvTimeUncertaintyNanos kept [ns]
MAX_TIME_UNCERTAINTY_NS = 500.0
#: Android constellation codes with no RINEX slot here (SBAS 2, IRNSS 7) or unknown (0)
SKIPPED = (0, 2, 7)
_FIELDS = (
    "TimeNanos",
    "FullBiasNanos",
    "BiasNanos",
    "TimeOffsetNanos",
    "Svid",
    "State",
    "ReceivedSvTimeNanos",
    "ReceivedSvTimeUncertaintyNanos",
    "Cn0DbHz",
    "ConstellationType",
)


def _band(system: str, frequency_hz: float) -> str:
    """RINEX 3 band digit of a carrier (L1/E1/G1/B1C 1, BeiDou B1I 2, L5/E5a/B2a 5)."""
    if np.isnan(frequency_hz):
        return "2" if system == "C" else "1"
    mhz = frequency_hz / 1e6
    if 1590.0 < mhz < 1610.0 and system == "R":
        return "1"
    for band, centre in (
        ("1", 1575.42),
        ("2", 1561.098),
        ("5", 1176.45),
        ("7", 1207.14),
        ("6", 1268.52),
    ):
        if abs(mhz - centre) < 1.0:
            return band
    raise ValueError(
        f"CarrierFrequencyHz: expected an L1/E1/G1, B1I, L5/E5a, E5b or E6 carrier, got {frequency_hz}"
    )


def _frame(system: str) -> tuple[int, int]:
    """``(offset, period)`` [ns] of the satellite time's frame against GPS time."""
    if system == "R":
        return 3 * 3600 * 10**9 - LEAP_SECONDS_MS * 10**6, DAY_NS
    return (-14 * 10**9 if system == "C" else 0), WEEK_NS


def parse_gnss_log(text: str, name: str = "<string>") -> Observations:
    """Parse the text of an Android GnssLogger log (see the module doc).

    Returns:
      ``Observations``: one row per receiver epoch (``TimeNanos``), one column per satellite.

    Raises:
      ValueError: naming ``name`` and the line of a missing ``# Raw`` header, a short record, a value that is not a
        number, an unknown constellation or two records of one signal in an epoch.
    """
    header, fix_header, raw, fix = None, None, [], None
    for line_no, line in enumerate(text.splitlines(), start=1):
        if line.startswith("# Raw,"):
            header = line[2:].split(",")
        elif line.startswith("# Fix,"):
            fix_header = line[2:].split(",")
        elif line.startswith("Raw,"):
            if header is None:
                _fail(name, line_no, "a Raw record before the '# Raw,' header line")
            raw.append((line_no, line.split(",")))
        elif line.startswith("Fix,GPS,") and fix is None and fix_header is not None:
            fix = (line_no, dict(zip(fix_header, line.split(","))))
    if header is None:
        _fail(name, 1, "expected an Android GnssLogger log with a '# Raw,...' header line")
    missing = [f for f in _FIELDS if f not in header]
    if missing:
        _fail(name, 1, f"the '# Raw' header lacks {missing}")
    column = {f: header.index(f) for f in header}
    epochs, records = {}, {}
    for line_no, fields in raw:
        if len(fields) != len(header):
            _fail(
                name,
                line_no,
                f"expected {len(header)} fields as the '# Raw' header, got {len(fields)}",
            )
        value = {f: fields[column[f]] for f in header}
        try:
            code = int(value["ConstellationType"])
            if code in SKIPPED:
                continue
            if code not in CONSTELLATIONS:
                raise ValueError(
                    f"ConstellationType {code} (expected one of {sorted(CONSTELLATIONS)} or "
                    f"{list(SKIPPED)})"
                )
            system, svid = CONSTELLATIONS[code], int(value["Svid"])
            if system == "R" and not 1 <= svid <= 24:
                continue  # a frequency channel, not a slot number
            satellite = f"{system}{svid - 192 if system == 'J' else svid:02d}"
            time_nanos, full_bias = int(value["TimeNanos"]), int(value["FullBiasNanos"])
            bias_ns = float(value["BiasNanos"] or 0.0)
            sub_ns = float(value["TimeOffsetNanos"] or 0.0) - bias_ns
            frequency = (
                float(value["CarrierFrequencyHz"]) if value.get("CarrierFrequencyHz") else np.nan
            )
            attribute = value.get("CodeType") or ("I" if system == "C" else "C")
            rinex = f"C{_band(system, frequency)}{attribute}"
            state, sent = int(value["State"]), int(value["ReceivedSvTimeNanos"])
            uncertainty, cn0 = (
                float(value["ReceivedSvTimeUncertaintyNanos"]),
                float(value["Cn0DbHz"] or "nan"),
            )
        except ValueError as error:
            _fail(name, line_no, str(error))
        if full_bias >= 0:
            _fail(
                name,
                line_no,
                f"FullBiasNanos: expected a negative number (the receiver's clock against GPS "
                f"time), got {full_bias}",
            )
        gps_ns = time_nanos - full_bias  # exact integer nanoseconds since the GPS epoch
        if (gps_ns // 10**6) + GPS_EPOCH_UNIX_MS - LEAP_SECONDS_MS < LEAP_VALID_FROM_UNIX_MS:
            _fail(name, line_no, "expected a log from 2017-01-01 on (GPS - UTC = 18 s)")
        epochs.setdefault(time_nanos, (gps_ns, -bias_ns))
        key = (time_nanos, satellite, rinex)
        if key in records:
            _fail(
                name, line_no, f"a second record of {satellite} {rinex} at TimeNanos {time_nanos}"
            )
        offset, period = _frame(system)
        time_known = state & (
            GLO_TOD_DECODED | GLO_TOD_KNOWN if system == "R" else TOW_DECODED | TOW_KNOWN
        )
        flight = ((gps_ns + offset - sent + period // 2) % period) - period // 2
        valid = bool(time_known) and uncertainty < MAX_TIME_UNCERTAINTY_NS
        records[key] = ((flight + sub_ns) * SPEED_OF_LIGHT * 1e-9 if valid else np.nan, cn0)
    if not records:
        _fail(
            name, len(text.splitlines()), "no Raw record of GPS, GLONASS, QZSS, BeiDou or Galileo"
        )
    times = sorted(epochs)
    satellites = sorted({sat for _, sat, _ in records})
    codes = {}
    for system in {sat[0] for sat in satellites}:
        seen = {code for _, sat, code in records if sat[0] == system}
        codes[system] = next((c for c in CODE_PRIORITY[system] if c in seen), None)
    satellites = [sat for sat in satellites if codes[sat[0]] is not None]
    row, col = {t: i for i, t in enumerate(times)}, {s: i for i, s in enumerate(satellites)}
    pseudorange, cn0 = (
        np.full((len(times), len(satellites)), np.nan),
        np.full((len(times), len(satellites)), np.nan),
    )
    for (time_nanos, sat, code), (rho, strength) in records.items():
        if sat in col and code == codes[sat[0]]:
            pseudorange[row[time_nanos], col[sat]], cn0[row[time_nanos], col[sat]] = rho, strength
    gps_ns = np.array([epochs[t][0] for t in times], np.int64)
    approx = np.full(3, np.nan)
    if fix is not None:
        try:
            lat, lon, height = (
                float(fix[1][f]) for f in ("LatitudeDegrees", "LongitudeDegrees", "AltitudeMeters")
            )
        except (KeyError, ValueError) as error:
            _fail(name, fix[0], f"Fix record: {error}")
        approx = geodetic_ecef64(lat, lon, height)
    return Observations(
        week=gps_ns // WEEK_NS,
        time_of_week=(gps_ns % WEEK_NS) * 1e-9 + np.array([epochs[t][1] for t in times]) * 1e-9,
        satellite=np.array(satellites, dtype="<U3"),
        code=np.array([codes[s[0]] for s in satellites], dtype="<U3"),
        pseudorange=pseudorange,
        cn0=cn0,
        approx_position=approx,
    )
