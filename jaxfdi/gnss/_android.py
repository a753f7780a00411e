"""Smartphone measurements: the Google Smartphone Decimeter Challenge's CSV files (Fu, Khider & van Diggelen 2020,
"Android raw GNSS measurement datasets for precise positioning", ION GNSS+), read into per-epoch slot arrays.

Layouts: 2021 "derived" files (``millisSinceGpsEpoch``, ``rawPrM``, ...) and 2022/2023 ``device_gnss`` files
(``utcTimeMillis``, ``RawPseudorangeMeters``, ..., Google's WLS position ``WlsPosition*EcefMeters``). Both carry the
satellite's ECEF position at transmission (frame of that instant) and the corrections, so no ephemeris is needed:
``rho_c = rho_raw + c dt_sv - ISRB - I - T`` (satellite clock, inter-signal range bias, iono, tropo; the files'
definition). A slot is one signal of one satellite (``"G05 GPS_L1"``; dual-frequency: two per satellite). Rows without a
signal type (2022/2023 rows Google's pipeline did not process) are skipped.

2021 corrections (Kaggle, "Google Smartphone Decimeter Challenge", data page, 2021): a derived row's
``millisSinceGpsEpoch`` is the *next* epoch's of the 1 Hz log, so reception = ``millisSinceGpsEpoch - 1000`` (not the
previous kept time, 5 s in the one-in-five Pixel 4 XL file; with 1000 ms the median flight time is 77 ms, as it must
be); rows whose signal left more than 300 ms before reception (or after it) are dropped as timing outliers.

Constellations: Android ``GnssStatus`` codes (1 GPS, 3 GLONASS, 4 QZSS, 5 BeiDou, 6 Galileo), reported
as RINEX letters. Parsed with the standard ``csv`` (tests check every column against gnss_lib_py, kept
out of the core install: plotting and data-frame dependencies for twenty columns).
"""

from __future__ import annotations

import csv
from typing import NamedTuple

import jax
import numpy as np

from jaxfdi.gnss._frames import geodetic_to_ecef

#: Android GnssStatus constellation codes -> RINEX system letters
CONSTELLATIONS = {1: "G", 3: "R", 4: "J", 5: "C", 6: "E"}
#: GPS epoch (1980-01-06) in Unix milliseconds, and GPS - UTC since 2017-01-01 (IERS Bulletin C)
GPS_EPOCH_UNIX_MS = 315_964_800_000
LEAP_SECONDS_MS = 18_000
LEAP_VALID_FROM_UNIX_MS = 1_483_228_800_000
#: a 2021 derived row's time tag is one epoch of the 1 Hz log late (module doc)
DERIVED_DELAY_MS = 1000
#: the 2021 ground truth's heights are 61 m too high (``read_android_ground_truth``)
HEIGHT_CORRECTION_2021_M = 61.0

_LAYOUTS = {
    "2021": dict(
        time="millisSinceGpsEpoch",
        constellation="constellationType",
        svid="svid",
        signal="signalType",
        position=("xSatPosM", "ySatPosM", "zSatPosM"),
        clock="satClkBiasM",
        raw="rawPrM",
        sigma="rawPrUncM",
        isrb="isrbM",
        iono="ionoDelayM",
        tropo="tropoDelayM",
        cn0=None,
        wls=None,
        sent="receivedSvTimeInGpsNanos",
    ),
    "device_gnss": dict(
        time="utcTimeMillis",
        constellation="ConstellationType",
        svid="Svid",
        signal="SignalType",
        position=("SvPositionXEcefMeters", "SvPositionYEcefMeters", "SvPositionZEcefMeters"),
        clock="SvClockBiasMeters",
        raw="RawPseudorangeMeters",
        sigma="RawPseudorangeUncertaintyMeters",
        isrb="IsrbMeters",
        iono="IonosphericDelayMeters",
        tropo="TroposphericDelayMeters",
        cn0="Cn0DbHz",
        wls=("WlsPositionXEcefMeters", "WlsPositionYEcefMeters", "WlsPositionZEcefMeters"),
        sent=None,
    ),
}


class PhoneEpochs(NamedTuple):
    """A phone trace as T epochs x S signal slots (NaN where a slot has no measurement).

    Attributes:
      gps_millis: (T,) int64, receiver time [ms since the GPS epoch]
      signal: (S,) slot names, ``"<letter><svid> <signal type>"``, e.g. ``"E11 GAL_E1"``
      constellation: (S,) RINEX system letters (G, R, J, C, E)
      pseudorange: (T, S) corrected pseudoranges ``rho_c`` [m]
      sigma: (T, S) the receiver's raw pseudorange uncertainty [m]
      cn0: (T, S) carrier-to-noise density [dB-Hz] (NaN in the 2021 files)
      satellite: (T, S, 3) satellite ECEF position at transmission [m]
      wls_position: (T, 3) Google's weighted-least-squares ECEF position [m] (NaN in 2021 files)
      truth: (T, 3) ECEF ground truth [m] at the epochs (NaN without: no file, or no row at that time)
    """

    gps_millis: np.ndarray
    signal: tuple
    constellation: np.ndarray
    pseudorange: np.ndarray
    sigma: np.ndarray
    cn0: np.ndarray
    satellite: np.ndarray
    wls_position: np.ndarray
    truth: np.ndarray

    def clocks(self) -> np.ndarray:
        """(S, C) bool: each slot on its constellation's receiver clock (C constellations in
        the trace, in the order of ``np.unique``), for ``solve_position(clocks=...)``."""
        systems = np.unique(self.constellation)
        return self.constellation[:, None] == systems[None, :]


def unix_to_gps_millis(unix_ms: np.ndarray) -> np.ndarray:
    """GPS milliseconds of Unix (UTC) milliseconds from 2017 on (18 leap seconds)."""
    unix_ms = np.asarray(unix_ms, np.int64)
    if np.any(unix_ms < LEAP_VALID_FROM_UNIX_MS):
        raise ValueError(
            "utcTimeMillis: expected times from 2017-01-01 on (GPS - UTC = 18 s), got "
            f"{int(unix_ms.min())} ms"
        )
    return unix_ms - GPS_EPOCH_UNIX_MS + LEAP_SECONDS_MS


def geodetic_ecef64(lat_deg, lon_deg, height) -> np.ndarray:
    """(..., 3) float64 ECEF [m] of lat, lon [deg], ellipsoidal height [m], whatever the x64 flag
    (float32 would round a ground truth to 0.5 m)."""
    with jax.enable_x64(True):
        return np.asarray(
            geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), np.asarray(height, float))
        )


def _float(text: str) -> float:
    return float(text) if text.strip() else np.nan


def read_android(path, ground_truth=None) -> PhoneEpochs:
    """Read a Smartphone Decimeter Challenge CSV (2021 ``*_derived.csv`` or 2022/2023 ``device_gnss.csv``),
    with the ground-truth CSV when given (``read_android_ground_truth``; matched by time).

    Returns:
      ``PhoneEpochs`` (NaN where the file or the truth has none).

    Raises:
      ValueError: naming the file and line, for a header of neither layout, a missing
        field, or a value that is not a number.
    """
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(
                f"{path}: empty file, expected a GSDC measurement CSV header"
            ) from None
        layout = next((_LAYOUTS[k] for k in _LAYOUTS if _LAYOUTS[k]["time"] in header), None)
        if layout is None:
            raise ValueError(
                f"{path}:1: expected a GSDC measurement CSV header (millisSinceGpsEpoch or "
                f"utcTimeMillis), got {header[:4]}"
            )
        names = [
            layout[k]
            for k in (
                "time",
                "constellation",
                "svid",
                "signal",
                "clock",
                "raw",
                "sigma",
                "isrb",
                "iono",
                "tropo",
            )
        ] + list(layout["position"])
        names += [layout[k] for k in ("cn0", "sent") if layout[k]] + (
            list(layout["wls"]) if layout["wls"] else []
        )
        missing = [n for n in names if n not in header]
        if missing:
            raise ValueError(f"{path}:1: missing columns {missing}")
        column = {n: header.index(n) for n in names}
        kind = header.index("MessageType") if "MessageType" in header else None
        rows = []
        for line, row in enumerate(reader, start=2):
            if not row or (kind is not None and row[kind] != "Raw"):
                continue  # not a measurement
            try:
                value = {n: row[column[n]] for n in names}
                if not value[layout["signal"]].strip():
                    continue  # a measurement Google's pipeline left without a signal type
                code = int(value[layout["constellation"]])
                if code not in CONSTELLATIONS:
                    raise ValueError(
                        f"constellation type {code} (expected one of {sorted(CONSTELLATIONS)})"
                    )
                time = int(float(value[layout["time"]]))
                numbers = {n: _float(value[n]) for n in names[4:]}
                slot = f"{CONSTELLATIONS[code]}{int(value[layout['svid']]):02d} {value[layout['signal']]}"
            except (ValueError, IndexError) as error:
                raise ValueError(f"{path}:{line}: {error}") from None
            rows.append((time, slot, numbers))
    if not rows:
        raise ValueError(f"{path}: no measurements")
    times = np.array([r[0] for r in rows], np.int64)
    if layout["wls"]:
        times = unix_to_gps_millis(times)
    if layout["sent"]:  # the 2021 corrections (module doc)
        times = times - DERIVED_DELAY_MS
        flight = times - np.array([r[2][layout["sent"]] for r in rows]) / 1e6
        keep = (flight > 0.0) & (flight < 300.0)
        rows, times = [r for r, k in zip(rows, keep) if k], times[keep]
        if not rows:
            raise ValueError(f"{path}: no measurements left after the 2021 timing corrections")
    epochs, epoch_of = np.unique(times, return_inverse=True)
    signal = tuple(sorted({r[1] for r in rows}))
    slot_of = {s: i for i, s in enumerate(signal)}
    seen = set()
    for k, (_, slot, _) in zip(epoch_of, rows):
        if (k, slot) in seen:
            raise ValueError(
                f"{path}: two rows of {slot} at {int(epochs[k])} ms (GPS): expected one per signal and epoch"
            )
        seen.add((k, slot))
    shape = (epochs.size, len(signal))
    pseudorange, sigma, cn0 = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    satellite = np.full(shape + (3,), np.nan)
    wls = np.full((epochs.size, 3), np.nan)
    for k, (_, slot, v) in zip(epoch_of, rows):
        s = slot_of[slot]
        pseudorange[k, s] = (
            v[layout["raw"]]
            + v[layout["clock"]]
            - v[layout["isrb"]]
            - v[layout["iono"]]
            - v[layout["tropo"]]
        )
        sigma[k, s] = v[layout["sigma"]]
        satellite[k, s] = [v[n] for n in layout["position"]]
        if layout["cn0"]:
            cn0[k, s] = v[layout["cn0"]]
        if layout["wls"]:
            wls[k] = [v[n] for n in layout["wls"]]
    truth = np.full((epochs.size, 3), np.nan)
    if ground_truth is not None:
        times, lat_lon_height = read_android_ground_truth(ground_truth)
        at = np.searchsorted(times, epochs)
        found = (at < times.size) & (times[np.minimum(at, times.size - 1)] == epochs)
        if not found.any():
            raise ValueError(f"ground_truth: {ground_truth} has no row at the epochs of {path}")
        truth[found] = geodetic_ecef64(*lat_lon_height[at[found]].T)
    return PhoneEpochs(
        epochs,
        signal,
        np.array([s[0] for s in signal]),
        pseudorange,
        sigma,
        cn0,
        satellite,
        wls,
        truth,
    )


def read_android_ground_truth(path) -> tuple[np.ndarray, np.ndarray]:
    """A GSDC ground-truth CSV: ``(gps_millis (T,) int64, lat_lon_height (T, 3))`` [deg, deg, m above WGS-84],
    sorted by time. 2021: ``millisSinceGpsEpoch``, ``latDeg``, ``lngDeg``, ``heightAboveWgs84EllipsoidM`` less
    61 m (the hosts' correction, Kaggle, "Tips & notes from the competition hosts", 2021); 2022/2023:
    ``UnixTimeMillis``, ``LatitudeDegrees``, ``LongitudeDegrees``, ``AltitudeMeters``."""
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        if "millisSinceGpsEpoch" in header:
            names, unix = (
                ("millisSinceGpsEpoch", "latDeg", "lngDeg", "heightAboveWgs84EllipsoidM"),
                False,
            )
        elif "UnixTimeMillis" in header:
            names, unix = (
                ("UnixTimeMillis", "LatitudeDegrees", "LongitudeDegrees", "AltitudeMeters"),
                True,
            )
        else:
            raise ValueError(
                f"{path}:1: expected a GSDC ground-truth header (millisSinceGpsEpoch or "
                f"UnixTimeMillis), got {header[:4]}"
            )
        times, points = [], []
        for line, row in enumerate(reader, start=2):
            try:
                times.append(int(float(row[names[0]])))
                points.append([float(row[n]) for n in names[1:]])
            except (TypeError, ValueError) as error:
                raise ValueError(f"{path}:{line}: {error}") from None
    times = np.array(times, np.int64)
    points = np.array(points)
    if not unix:
        points[:, 2] -= HEIGHT_CORRECTION_2021_M
    order = np.argsort(times, kind="stable")
    return (unix_to_gps_millis(times) if unix else times)[order], points[order]
