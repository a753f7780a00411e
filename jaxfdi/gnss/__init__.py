"""GNSS integrity (Yoo et al. 2010, GPS half), with real receivers' observation files and smartphone traces through the
same chain (one receiver clock per constellation).

Modules: ``yuma``, ``rinex``, ``rinex_obs``, ``gnss_log``, ``android`` (readers), ``orbits`` (IS-GPS-200 broadcast
orbits), ``frames`` (WGS-84), ``atmosphere`` (Klobuchar, Saastamoinen), ``paths`` (UAV circuits), ``measurements``
(simulated pseudoranges: visibility masks, noise, faults, receiver plant), ``least_squares`` (masked Householder QR),
``positioning`` (WLS, DOPs), ``raim`` (parity test, isolation), ``protection`` (slopes, HPL/VPL, availability),
``solution_separation`` (ARAIM's levels), ``integrity`` (one epoch end to end with exclusion, the loop's FDI stage,
availability over grids), ``receiver`` (a real receiver's epochs: observation files, logs and phones), ``stanford``
(epochs by region of the Stanford diagram: nominal, misleading, hazardous, unavailable).

Constants: ``WGS84_A`` the semi-major axis [m], ``WGS84_F`` the flattening, ``WGS84_B`` the
semi-minor axis [m] and ``WGS84_E2`` the first eccentricity squared of the WGS-84 ellipsoid;
``OMEGA_E`` the Earth's rotation rate, 7.2921151467e-5 rad/s (IS-GPS-200); ``ALERT_LIMITS`` the alert limits by
operation, a dict of ``(HAL, VAL)`` [m] (``"npa"`` 556 m, ``"terminal"`` 1852 m, ``"enroute"`` 3704 m, ``"oceanic"``
7408 m with no vertical limit, VAL ``inf``; ``"lnav-vnav"`` 556 m / 50 m, ``"lpv"`` 40 m / 50 m); ``DEFAULT_PFA`` the
RAIM test's false-alarm probability per test, 1/15000 (Brown & Chin 1992); ``DEFAULT_PMD`` the protection level's
missed-detection probability, 1e-3; ``MASK_ANGLE`` the elevation mask of a real receiver's single-point positioning,
15 deg, in rad.
"""

from jaxfdi.gnss._android import PhoneEpochs, read_android
from jaxfdi.gnss._frames import (
    WGS84_A,
    WGS84_B,
    WGS84_E2,
    WGS84_F,
    ecef_to_geodetic,
    ecef_to_ned,
    geodetic_to_ecef,
)
from jaxfdi.gnss._integrity import (
    availability_grid,
    monitor_epoch,
    monitor_epochs,
    raim_fdi,
    raim_output,
)
from jaxfdi.gnss._measurements import (
    ClockModel,
    Wall,
    elevation_sigma,
    receiver_plant,
    sky_geometry,
    visibility,
)
from jaxfdi.gnss._orbits import (
    OMEGA_E,
    OrbitTable,
    almanac_table,
    ephemeris_table,
    orbit_table,
    satellite_position,
    select_orbits,
)
from jaxfdi.gnss._paths import racetrack_ecef
from jaxfdi.gnss._positioning import PositionFix, solve_position
from jaxfdi.gnss._protection import ALERT_LIMITS, protection_levels
from jaxfdi.gnss._raim import DEFAULT_PFA, DEFAULT_PMD, RaimTables, parity_check, raim_tables
from jaxfdi.gnss._receiver import (
    MASK_ANGLE,
    ReceiverEpochs,
    monitor_receiver,
    read_observations,
    receiver_epochs,
)
from jaxfdi.gnss._rinex import read_rinex_nav
from jaxfdi.gnss._solution_separation import separate_epochs
from jaxfdi.gnss._stanford import IntegrityOutcomes, integrity_outcomes
from jaxfdi.gnss._yuma import read_yuma

__all__ = [
    "WGS84_A",
    "WGS84_B",
    "WGS84_E2",
    "WGS84_F",
    "OMEGA_E",
    "OrbitTable",
    "monitor_epoch",
    "raim_output",
    "elevation_sigma",
    "ClockModel",
    "receiver_plant",
    "PositionFix",
    "RaimTables",
    "read_rinex_nav",
    "read_observations",
    "read_android",
    "read_yuma",
    "orbit_table",
    "select_orbits",
    "satellite_position",
    "ecef_to_geodetic",
    "geodetic_to_ecef",
    "solve_position",
    "raim_tables",
    "parity_check",
    "protection_levels",
    "monitor_epochs",
    "monitor_receiver",
    "PhoneEpochs",
    "ecef_to_ned",
    "availability_grid",
    "raim_fdi",
    "Wall",
    "sky_geometry",
    "visibility",
    "almanac_table",
    "ephemeris_table",
    "racetrack_ecef",
    "ALERT_LIMITS",
    "DEFAULT_PFA",
    "DEFAULT_PMD",
    "MASK_ANGLE",
    "ReceiverEpochs",
    "receiver_epochs",
    "separate_epochs",
    "integrity_outcomes",
    "IntegrityOutcomes",
]
