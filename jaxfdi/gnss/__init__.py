"""GNSS integrity (Yoo et al. 2010, GPS half), with real receivers' observation files and smartphone traces through the
same chain (one receiver clock per constellation).

Modules: ``yuma``, ``rinex``, ``rinex_obs``, ``gnss_log``, ``android`` (readers), ``orbits`` (IS-GPS-200 broadcast
orbits), ``frames`` (WGS-84), ``atmosphere`` (Klobuchar, Saastamoinen), ``paths`` (UAV circuits), ``measurements``
(simulated pseudoranges: visibility masks, noise, faults, receiver plant), ``least_squares`` (masked Householder QR),
``positioning`` (WLS, DOPs), ``raim`` (parity test, isolation), ``protection`` (slopes, HPL/VPL, availability),
``solution_separation`` (ARAIM's levels), ``integrity`` (one epoch end to end with exclusion, the loop's FDI stage,
availability over grids), ``receiver`` (a real receiver's epochs: observation files, logs and phones).
"""

from jaxfdi.gnss._android import read_android
from jaxfdi.gnss._frames import ecef_to_geodetic, geodetic_to_ecef
from jaxfdi.gnss._integrity import monitor_epochs
from jaxfdi.gnss._orbits import orbit_table, satellite_position, select_orbits
from jaxfdi.gnss._positioning import solve_position
from jaxfdi.gnss._protection import protection_levels
from jaxfdi.gnss._raim import parity_check, raim_tables
from jaxfdi.gnss._receiver import monitor_receiver, read_observations
from jaxfdi.gnss._rinex import read_rinex_nav
from jaxfdi.gnss._yuma import read_yuma

__all__ = [
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
