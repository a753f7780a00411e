"""A real receiver's observation file through the snapshot integrity chain.

``read_observations``: RINEX 2/3 observation file or Android GnssLogger log. ``receiver_epochs`` aligns them with a
navigation file (``read_rinex_nav``): a slot per observed GPS satellite, times from the first epoch's week, the header's
broadcast ionosphere, each satellite's URA. ``monitor_receiver`` runs ``monitor_epochs`` with RTKLIB ``pntpos``'s
single-point model (Takasu 2013, RTKLIB manual, E.6), comparable with RTKLIB's fixes: broadcast orbits and clocks
(``T_GD``, L1 C/A), Klobuchar and Saastamoinen, 15 deg mask, weights

``sigma_i^2 = URA_i^2 + 0.3^2 + 0.3^2 (1 + 1 / sin max(E_i, 5 deg)) + var_iono + var_tropo``

(code bias 0.3 m; RTKLIB's default code error ``100 x (3 mm + 3 mm / sqrt(sin E))`` in variance form;
atmosphere model errors: ``atmosphere_corrections``). A smartphone trace (``read_android``) carries
satellite positions and corrected pseudoranges: the same chain without orbits or atmosphere, a clock
per constellation, the phone's pseudorange uncertainty as sigma, padded and chunked
(``positioning.EPOCH_CHUNK``) so every trace of up to 64 signals shares one program.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi.gnss._android import PhoneEpochs
from jaxfdi.gnss._atmosphere import Atmosphere, broadcast_atmosphere
from jaxfdi.gnss._gnss_log import parse_gnss_log
from jaxfdi.gnss._integrity import EpochIntegrity, exclusion_rounds, monitor_epoch, monitor_epochs
from jaxfdi.gnss._orbits import OrbitTable, ephemeris_table
from jaxfdi.gnss._positioning import in_chunks, padded_sizes, padded_to, resized
from jaxfdi.gnss._raim import RaimTables, raim_tables
from jaxfdi.gnss._rinex import SECONDS_PER_WEEK, Ephemerides, read_ascii
from jaxfdi.gnss._rinex_obs import Observations, parse_rinex_obs

#: IS-GPS-200 (20.3.3.3.1.3) URA values [m] of the indices 0-14 (index 15: no accuracy prediction)
URA_VALUES = (
    2.4,
    3.4,
    4.85,
    6.85,
    9.65,
    13.65,
    24.0,
    48.0,
    96.0,
    192.0,
    384.0,
    768.0,
    1536.0,
    3072.0,
    6144.0,
)
#: RTKLIB's single-point model: code bias error, code error at the zenith [m], lowest elevation of the weights
CODE_BIAS_ERROR = 0.3
CODE_ERROR = 0.3
WEIGHT_MIN_ELEVATION = math.radians(5.0)
#: the elevation mask of single-point positioning [rad]
MASK_ANGLE = math.radians(15.0)


class ReceiverEpochs(NamedTuple):
    """A receiver's GPS pseudoranges aligned with broadcast orbits.

    Attributes:
      table: the navigation file's records, one slot per satellite in ``satellite``
      times: (E,) s, the epochs' time tags from the start of ``reference_week``
      pseudoranges: (E, S) m, NaN where not observed
      ura: (S,) m, user range accuracy of each slot (the largest of its records')
      atmosphere: the broadcast ionosphere of the navigation header
      satellite: (S,) str, the slots' satellites (``G05``)
      reference_week: int, GPS week of ``times == 0``
    """

    table: OrbitTable
    times: Array
    pseudoranges: Array
    ura: Array
    atmosphere: Atmosphere
    satellite: np.ndarray
    reference_week: int


def read_observations(path) -> Observations:
    """Read a receiver's observation file: RINEX 2 or 3 (Gurtner & Estey 2007; IGS 2018) or an Android GnssLogger log
    (``# Raw,`` records, pseudoranges from receiver and satellite times: EUSPA 2017), told apart by the first line.

    Returns:
      ``Observations``: (E,) GPS week and time of week, (S,) satellites and code read, (E, S)
      pseudoranges [m] and C/N0 [dB-Hz] (NaN: not measured), approximate ECEF position (header or first fix).

    Raises:
      ValueError: naming the file and the line of the first malformed header or record.
    """
    text = read_ascii(path)
    if text.lstrip().startswith("#"):
        return parse_gnss_log(text, str(path))
    return parse_rinex_obs(text, str(path))


def user_range_accuracy(accuracy) -> np.ndarray:
    """The URA [m] for RINEX's ``SV accuracy`` [m]: smallest ``URA_VALUES`` entry not below it (6144 m
    beyond the table and for NaN).

    Returns:
      float array, the shape of ``accuracy``.
    """
    accuracy = np.asarray(accuracy, float)
    index = np.searchsorted(
        np.asarray(URA_VALUES), np.nan_to_num(accuracy, nan=np.inf), side="left"
    )
    return np.asarray(URA_VALUES + (URA_VALUES[-1],))[np.minimum(index, len(URA_VALUES))]


def receiver_epochs(
    observations: Observations, ephemerides: Ephemerides, dtype=None
) -> ReceiverEpochs:
    """The GPS satellites of ``observations`` as slots of ``ephemerides``' orbits (other systems and
    satellites without a record left out).

    Returns:
      ``ReceiverEpochs``: (E,) times from the first epoch's week, (E, S) pseudoranges.
    """
    gps = [
        k
        for k, sat in enumerate(observations.satellite)
        if sat[0] == "G" and int(sat[1:]) in set(np.asarray(ephemerides.prn).tolist())
    ]
    if not gps:
        raise ValueError(
            "observations: expected GPS satellites that the navigation file has records of, got "
            f"{list(observations.satellite)}"
        )
    prns = np.array([int(observations.satellite[k][1:]) for k in gps])
    week = int(observations.week[0])
    dtype = dtype or jnp.result_type(float)
    ura = np.array(
        [user_range_accuracy(ephemerides.accuracy[ephemerides.prn == p]).max() for p in prns]
    )
    times = (observations.week - week) * SECONDS_PER_WEEK + observations.time_of_week
    return ReceiverEpochs(
        table=ephemeris_table(ephemerides, week, slot_prns=prns, dtype=dtype),
        times=jnp.asarray(times, dtype),
        pseudoranges=jnp.asarray(observations.pseudorange[:, gps], dtype),
        ura=jnp.asarray(ura, dtype),
        atmosphere=broadcast_atmosphere(ephemerides.ion_alpha, ephemerides.ion_beta),
        satellite=observations.satellite[gps],
        reference_week=week,
    )


def code_sigma(ura: Array):
    """RTKLIB's pseudorange standard deviation without the atmosphere's share (module docstring).

    Returns:
      A function of the (S,) elevations [rad] giving the (S,) standard deviations [m].
    """

    def sigma(elevation: Array) -> Array:
        sin_e = jnp.sin(jnp.maximum(elevation, WEIGHT_MIN_ELEVATION))
        return jnp.sqrt(ura**2 + CODE_BIAS_ERROR**2 + CODE_ERROR**2 * (1.0 + 1.0 / sin_e))

    return sigma


def monitor_receiver(
    measurements: Observations | ReceiverEpochs | PhoneEpochs,
    ephemerides: Ephemerides | None = None,
    tables: RaimTables | None = None,
    mask_angle: float | None = None,
    clocks: str = "constellation",
    operation="npa",
    exclude: bool | int = True,
) -> EpochIntegrity:
    """Fix, RAIM, protection levels and exclusion of every epoch of a real receiver (module doc).

    Args:
      measurements: an observation file (``read_observations``, with ``ephemerides`` from ``read_rinex_nav``: GPS only),
        the same aligned (``receiver_epochs``), or a phone trace (``read_android``: every constellation).
      tables: ``raim_tables`` (default: of the slots, ``P_fa = 1e-3``, ``P_md = 1e-3``).
      mask_angle: [rad]; ``None``: 15 deg for a file (RTKLIB's), none for a phone (as Google, gnss_lib_py).
      clocks: a phone's: "constellation" (one each, ``n - 3 - C`` dof with C in view) or "one" (the files'
        inter-signal biases taken as exact).
      operation, exclude: as for ``monitor_epochs``.

    Returns:
      ``EpochIntegrity``, a leading epoch axis on every leaf (a phone's per-constellation
      ``fix.clock_bias`` (T, C), ``PhoneEpochs.clocks`` order).
    """
    if clocks not in ("constellation", "one"):
        raise ValueError(f"clocks: expected 'constellation' or 'one', got {clocks!r}")
    if isinstance(measurements, PhoneEpochs):
        return _monitor_trace(measurements, tables, clocks, mask_angle, operation, exclude)
    if isinstance(measurements, Observations):
        if not isinstance(ephemerides, Ephemerides):
            raise ValueError(
                "ephemerides: expected the navigation file's records (read_rinex_nav) for an observation "
                f"file, got {type(ephemerides).__name__}"
            )
        measurements = receiver_epochs(measurements, ephemerides)
    if not isinstance(measurements, ReceiverEpochs):
        raise TypeError(
            "measurements: expected read_observations's Observations, receiver_epochs' ReceiverEpochs or "
            f"read_android's PhoneEpochs, got {type(measurements).__name__}"
        )
    epochs = measurements
    mask_angle = MASK_ANGLE if mask_angle is None else mask_angle
    slots = int(epochs.pseudoranges.shape[1])
    tables = raim_tables(max(slots, 5), pfa=1e-3, pmd=1e-3) if tables is None else tables
    return _monitor(
        epochs.table,
        epochs.times,
        epochs.pseudoranges,
        epochs.ura,
        epochs.atmosphere,
        tables,
        float(mask_angle),
        operation if isinstance(operation, str) else tuple(operation),
        exclusion_rounds(exclude),
    )


@functools.partial(jax.jit, static_argnames=("mask_angle", "operation", "exclude"))
def _monitor(table, times, pseudoranges, ura, atmosphere, tables, mask_angle, operation, exclude):
    return monitor_epochs(
        table,
        times,
        pseudoranges,
        tables,
        sigma=code_sigma(ura),
        operation=operation,
        exclude=exclude,
        atmosphere=atmosphere,
        mask_angle=mask_angle,
    )


def _monitor_trace(
    phone: PhoneEpochs, tables, clocks, mask_angle, operation, exclude
) -> EpochIntegrity:
    """``monitor_epoch`` vmapped over a phone's epochs (files' positions and corrected pseudoranges,
    phone's uncertainty as weights), padded and chunked (``positioning.EPOCH_CHUNK``), padding cut."""
    epochs, slots = phone.pseudorange.shape
    own = phone.clocks().shape[1] if clocks == "constellation" else 1
    rows, width, wide = padded_sizes(epochs, slots, own)
    dtype = jnp.result_type(float)
    if tables is None:
        tables = raim_tables(width, pfa=1e-3, pmd=1e-3)
    elif tables.threshold.shape[0] < width - 3:  # entries past S - 4 dof are never read
        tables = RaimTables(
            padded_to(tables.threshold, (width - 3,), np.inf),
            padded_to(tables.noncentrality, (width - 3,), np.nan),
        )
    membership = (
        jnp.asarray(padded_to(phone.clocks(), (width, wide), False))
        if clocks == "constellation"
        else None
    )
    satellite = padded_to(np.asarray(phone.satellite, dtype), (rows, width, 3), np.nan)
    pseudoranges = padded_to(np.asarray(phone.pseudorange, dtype), (rows, width), np.nan)
    uncertainty = padded_to(np.asarray(phone.sigma, dtype), (rows, width), np.nan)
    options = (
        None if mask_angle is None else float(mask_angle),
        operation if isinstance(operation, str) else tuple(operation),
        exclusion_rounds(exclude),
    )
    out = in_chunks(
        lambda *chunk: _monitor_phone(*chunk, membership, tables, *options),
        epochs,
        satellite,
        pseudoranges,
        uncertainty,
    )
    return jax.tree_util.tree_map(
        jnp.asarray, resized(out, epochs, slots, own)
    )  # the trace's own slots, clocks


@functools.partial(jax.jit, static_argnames=("mask_angle", "operation", "exclude"))
def _monitor_phone(
    satellite, pseudoranges, uncertainty, membership, tables, mask_angle, operation, exclude
):
    def one(sat, rho, sig):
        # a slot without a satellite position or an uncertainty cannot be used: not measured
        rho = jnp.where(jnp.all(jnp.isfinite(sat), axis=1) & (sig > 0), rho, jnp.nan)
        sat = jnp.where(jnp.isfinite(sat), sat, 0.0)
        sig = jnp.where(jnp.isfinite(rho), sig, 1.0)
        available = ~jnp.isnan(rho)  # an infinite pseudorange is a dead channel (never used)
        return monitor_epoch(
            None,
            available,
            0.0,
            rho,
            tables,
            sig,
            operation,
            exclude,
            transmit=(sat, jnp.zeros_like(rho)),
            mask_angle=mask_angle,
            clocks=membership,
        )

    return jax.vmap(one)(satellite, pseudoranges, uncertainty)
