"""GNSS integrity (Yoo et al. 2010, GPS half), with real receivers' observation files and smartphone traces through the
same chain (one receiver clock per constellation).

Modules: ``yuma``, ``rinex``, ``rinex_obs``, ``gnss_log``, ``android`` (readers), ``orbits`` (IS-GPS-200 broadcast
orbits), ``frames`` (WGS-84), ``atmosphere`` (Klobuchar, Saastamoinen), ``paths`` (UAV circuits), ``measurements``
(simulated pseudoranges: visibility masks, noise, faults, receiver plant), ``least_squares`` (masked Householder QR),
``positioning`` (WLS, DOPs), ``raim`` (parity test, isolation), ``protection`` (slopes, HPL/VPL, availability),
``solution_separation`` (ARAIM's levels), ``integrity`` (one epoch end to end with exclusion, the loop's FDI stage,
availability over grids), ``receiver`` (a real receiver's epochs: observation files, logs and phones).

Constants: ``WGS84_A`` the semi-major axis [m], ``WGS84_F`` the flattening, ``WGS84_B`` the
semi-minor axis [m] and ``WGS84_E2`` the first eccentricity squared of the WGS-84 ellipsoid;
``OMEGA_E`` the Earth's rotation rate, 7.2921151467e-5 rad/s (IS-GPS-200).
"""

from jaxfdi.gnss._android import read_android
from jaxfdi.gnss._frames import (
    WGS84_A,
    WGS84_B,
    WGS84_E2,
    WGS84_F,
    ecef_to_geodetic,
    geodetic_to_ecef,
)
from jaxfdi.gnss._integrity import monitor_epoch, monitor_epochs, raim_output
from jaxfdi.gnss._measurements import ClockModel, elevation_sigma, receiver_plant
from jaxfdi.gnss._orbits import OMEGA_E, OrbitTable, orbit_table, satellite_position, select_orbits
from jaxfdi.gnss._positioning import PositionFix, solve_position
from jaxfdi.gnss._protection import protection_levels
from jaxfdi.gnss._raim import RaimTables, parity_check, raim_tables
from jaxfdi.gnss._receiver import monitor_receiver, read_observations
from jaxfdi.gnss._rinex import read_rinex_nav
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
]
