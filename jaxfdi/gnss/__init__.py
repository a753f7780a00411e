"""GNSS integrity (Yoo et al. 2010, GPS half): almanac and RINEX readers, broadcast orbits,
WGS-84 frames, simulated pseudoranges with masks and faults, snapshot least squares,
parity RAIM with isolation and exclusion, protection levels and availability.

Modules: ``yuma`` and ``rinex`` (readers), ``orbits`` (IS-GPS-200), ``frames``
(WGS-84), ``paths`` (UAV circuits), ``measurements`` (visibility, noise, receiver
plant), ``least_squares`` (masked Householder QR), ``positioning`` (WLS, DOPs),
``raim`` (parity test, isolation), ``protection`` (slopes, HPL/VPL, availability),
``integrity`` (one epoch end to end, the loop's FDI stage, availability over grids).
"""
from jaxfdi.gnss.frames import ecef_to_geodetic, ecef_to_ned, elevation_azimuth, geodetic_to_ecef, ned_to_ecef
from jaxfdi.gnss.integrity import (
    EpochIntegrity,
    RaimOutput,
    availability_grid,
    geometry_fix,
    monitor_epoch,
    monitor_epochs,
    raim_fdi,
)
from jaxfdi.gnss.measurements import ClockModel, Wall, elevation_sigma, receiver_plant, visibility, wall_blocks
from jaxfdi.gnss.orbits import (
    Orbit,
    OrbitTable,
    almanac_table,
    ephemeris_table,
    satellite_clock,
    satellite_position,
    satellite_velocity,
    select_orbits,
    transmission_geometry,
)
from jaxfdi.gnss.paths import racetrack_ecef, racetrack_ned
from jaxfdi.gnss.positioning import Dops, PositionFix, dops, solve_position
from jaxfdi.gnss.protection import ALERT_LIMITS, ProtectionLevels, protection_levels
from jaxfdi.gnss.raim import ParityCheck, RaimTables, paper_threshold, parity_check, parity_matrix, raim_tables
from jaxfdi.gnss.rinex import Ephemerides, gps_week_seconds, parse_rinex_nav, read_rinex_nav
from jaxfdi.gnss.yuma import Almanac, parse_yuma, read_yuma

__all__ = [
    "ALERT_LIMITS", "Almanac", "ClockModel", "Dops", "Ephemerides", "EpochIntegrity", "Orbit", "OrbitTable",
    "ParityCheck", "PositionFix", "ProtectionLevels", "RaimOutput", "RaimTables", "Wall", "almanac_table",
    "availability_grid", "dops", "ecef_to_geodetic", "ecef_to_ned", "elevation_azimuth", "elevation_sigma",
    "ephemeris_table", "geodetic_to_ecef", "geometry_fix", "gps_week_seconds", "monitor_epoch", "monitor_epochs",
    "ned_to_ecef", "paper_threshold", "parity_check", "parity_matrix", "parse_rinex_nav", "parse_yuma",
    "protection_levels", "racetrack_ecef", "racetrack_ned", "raim_fdi", "raim_tables", "read_rinex_nav",
    "read_yuma", "receiver_plant", "satellite_clock", "satellite_position", "satellite_velocity", "select_orbits",
    "solve_position", "transmission_geometry", "visibility", "wall_blocks",
]
