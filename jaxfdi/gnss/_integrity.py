"""One epoch of GPS integrity monitoring, and the same as an FDI stage of the loop.

``monitor_epoch`` chains the GPS half of Yoo et al. (2010, Fig. 3): least-squares fix (``positioning``), parity test and
isolation (``raim``), protection levels and availability (``protection``), and on an alarm with an isolated satellite,
exclusion (all again without it). A dead channel (infinite pseudorange) is left out of every fix, alarmed on, and
reported as the excluded slot when the parity test excludes none. Snapshot method: epochs and Monte Carlo runs are
``vmap``s (``monitor_epochs``); ``raim_fdi`` is it as ``loop.FDI``, its ``Decision`` label ``1 + slot`` (the faults'
sensor label in a plant without inputs). ``geometry_fix`` and ``availability_grid``: the same protection levels without
measurements (geometry and noise model only), over receiver/epoch grids.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.stages import FDI
from jaxfdi.detection import Decision, flag_dead
from jaxfdi.gnss._atmosphere import Atmosphere
from jaxfdi.gnss._frames import elevation_azimuth, line_of_sight_ned
from jaxfdi.gnss._least_squares import masked_qr
from jaxfdi.gnss._measurements import check_mask_angle
from jaxfdi.gnss._orbits import OrbitTable, satellite_position, select_orbits
from jaxfdi.gnss._positioning import Dops, PositionFix, dops, solve_position, transmit_states
from jaxfdi.gnss._protection import ProtectionLevels, protection_levels
from jaxfdi.gnss._raim import ParityCheck, RaimTables, parity_check, whitened

#: Gauss-Newton steps of the re-solve without the excluded satellite (from the full fix)
EXCLUSION_ITERATIONS = 3


class EpochIntegrity(NamedTuple):
    """One epoch's integrity: the fix, the parity check, protection levels and the exclusion.

    Attributes:
      fix: the least-squares fix from every usable satellite
      check: the parity test of ``fix``
      protection: the protection levels and availability of ``fix``
      excluded: () int, first excluded slot (-1: none or no ``exclude``): isolated after an alarm, else the
          first dead slot
      fix_excluded: the fix after exclusion (the full fix when none or a dead slot: it lacks it)
      check_excluded: the parity test of ``fix_excluded``
      protection_excluded: the protection levels of ``fix_excluded``
      dead: (S,) bool: a slot with an orbit and an infinite pseudorange (left out; ``raim_output`` alarms)
      exclusions: (S,) bool, every slot ``fix_excluded`` leaves out (one per round) and the dead ones
    """

    fix: PositionFix
    check: ParityCheck
    protection: ProtectionLevels
    excluded: Array
    fix_excluded: PositionFix
    check_excluded: ParityCheck
    protection_excluded: ProtectionLevels
    dead: Array
    exclusions: Array


def exclusion_rounds(exclude: bool | int) -> int:
    """The number of exclusion rounds ``exclude`` asks for (``True``: 1, ``False``: 0)."""
    if isinstance(exclude, (bool, np.bool_)):
        return int(exclude)
    return checks.check_int(
        "exclude", exclude, 0, meaning="the most satellites to exclude (or a bool: 1 or none)"
    )


def assess(
    fix: PositionFix, tables: RaimTables, operation="npa"
) -> tuple[ParityCheck, ProtectionLevels]:
    """Parity check and protection levels of a fix (one QR of the whitened geometry)."""
    h, _ = whitened(fix)
    qr = masked_qr(h, fix.used)
    return parity_check(fix, tables, qr), protection_levels(fix, tables, operation, qr)


def monitor_epoch(
    orbit,
    available: Array,
    t_receive: Array,
    pseudoranges: Array,
    tables: RaimTables,
    sigma: Array | Callable[[Array], Array] | None = None,
    operation="npa",
    exclude: bool | int = True,
    transmit: tuple[Array, Array] | None = None,
    atmosphere: Atmosphere | None = None,
    mask_angle: float | None = None,
    clocks: Array | None = None,
) -> EpochIntegrity:
    """Fix, RAIM, protection levels and exclusion of one epoch (module doc).

    Args:
      orbit: (S,) slot elements at this epoch; available: (S,) slots with a usable orbit.
      t_receive: () time tag; pseudoranges: (S,) [m], NaN where not measured; an infinite
        one is a dead channel (``EpochIntegrity.dead``).
      tables: ``raim.raim_tables``; sigma: as for ``positioning.solve_position``.
      operation: alert limits (``protection.ALERT_LIMITS`` key or (HAL, VAL)).
      exclude: most satellites excluded, greedily (Brown & Chin 1992's FDE iterated: re-solve without the
        isolated satellite while the test alarms and isolates); ``True``: 1, ``False``: none.
      transmit: satellite positions and clocks at transmission (``positioning.transmit_states``), if
        known (``orbit`` then unused).
      atmosphere, mask_angle, clocks: as for ``positioning.solve_position``.

    Returns:
      the epoch's ``EpochIntegrity``: the delivered fix, the parity test, protection levels and
      what was excluded.
    """
    transmit = transmit_states(orbit, t_receive, pseudoranges) if transmit is None else transmit
    fix = solve_position(
        orbit,
        t_receive,
        pseudoranges,
        available,
        sigma,
        transmit=transmit,
        atmosphere=atmosphere,
        mask_angle=mask_angle,
        clocks=clocks,
    )
    check, protection = assess(fix, tables, operation)
    dead = jnp.asarray(available, bool) & jnp.isinf(jnp.asarray(pseudoranges))
    rounds = exclusion_rounds(exclude)
    none = jnp.asarray(-1, jnp.int32)
    if rounds == 0:
        return EpochIntegrity(fix, check, protection, none, fix, check, protection, dead, dead)

    def exclude_one(carry, _):
        """Leave out the slot the current fix's parity test isolates, if it alarms."""
        keep, first, current = carry
        now_fix, now_check = current[0], current[1]
        drop = jnp.where(
            now_check.alarm & (now_check.isolated >= 0), now_check.isolated, -1
        ).astype(jnp.int32)
        keep = keep & (jnp.arange(keep.shape[0]) != drop)
        initial = jnp.concatenate([now_fix.position, jnp.atleast_1d(now_fix.clock_bias)])
        refit = solve_position(
            orbit,
            t_receive,
            pseudoranges,
            keep,
            sigma,
            initial=initial,
            iterations=EXCLUSION_ITERATIONS,
            unweighted_iterations=0,
            transmit=transmit,
            atmosphere=atmosphere,
            mask_angle=mask_angle,
            clocks=clocks,
        )
        refit = (refit,) + assess(refit, tables, operation)
        current = jax.tree_util.tree_map(lambda u, v: jnp.where(drop >= 0, u, v), refit, current)
        return (keep, jnp.where(first >= 0, first, drop), current), None

    keep = jnp.asarray(available, bool)
    (keep, first, (fix_x, check_x, protection_x)), _ = jax.lax.scan(
        exclude_one, (keep, none, (fix, check, protection)), None, length=rounds
    )
    # a dead slot (already left out) is reported when the parity test isolated nothing: detected, isolated, excluded
    excluded = jnp.where(first >= 0, first, jnp.where(jnp.any(dead), jnp.argmax(dead), -1)).astype(
        jnp.int32
    )
    return EpochIntegrity(
        fix,
        check,
        protection,
        excluded,
        fix_x,
        check_x,
        protection_x,
        dead,
        (jnp.asarray(available, bool) & ~keep) | dead,
    )


def monitor_epochs(
    table: OrbitTable,
    times: Array,
    pseudoranges: Array,
    tables: RaimTables,
    sigma=None,
    operation="npa",
    exclude: bool | int = True,
    batch_size: int | None = None,
    atmosphere: Atmosphere | None = None,
    mask_angle: float | None = None,
) -> EpochIntegrity:
    """``monitor_epoch`` vmapped over epochs: ``times`` (T,), ``pseudoranges`` (T, S) (NaN: not measured; a fixed sigma
    array is (T, S)); ``atmosphere`` (one for all) and ``mask_angle`` as ``positioning.solve_position``. ``batch_size``:
    chunks of epochs in sequence (``lax.map``), keeping intermediates in cache (on CPU faster for long runs of epochs,
    e.g. 128 a chunk, ``benchmarks/bench_gnss_raim.py``); ``None``: all at once.

    Returns:
      ``EpochIntegrity`` of the T epochs (each epoch's slot records chosen by ``select_orbits``): every leaf of
      ``monitor_epoch``'s with a leading T axis, e.g. ``fix.position`` (T, 3), ``check.alarm`` (T,), ``protection.hpl``
      (T,), ``excluded`` (T,) int (-1: none), ``dead`` (T, S).
    """
    checks.check_shape("times", times, (None,), "one time tag per epoch")
    epochs = checks.shape_of(times)[0]
    checks.check_shape(
        "pseudoranges",
        pseudoranges,
        (epochs, checks.shape_of(table.prn)[0]),
        "T epochs (times') x S slots (table's)",
    )
    if sigma is not None and not callable(sigma):
        checks.check_shape(
            "sigma", sigma, checks.shape_of(pseudoranges), "one standard deviation per pseudorange"
        )
    if batch_size is not None:
        batch_size = checks.check_int(
            "batch_size", batch_size, 1, meaning="a positive number of epochs per chunk"
        )

    def one(t, rho, sig):
        orbit, available = select_orbits(table, t)
        return monitor_epoch(
            orbit,
            available,
            t,
            rho,
            tables,
            sig if sigma is not None and not callable(sigma) else sigma,
            operation,
            exclude,
            atmosphere=atmosphere,
            mask_angle=mask_angle,
        )

    sig = (
        jnp.zeros(checks.shape_of(pseudoranges))
        if sigma is None or callable(sigma)
        else jnp.asarray(sigma)
    )
    args = (jnp.asarray(times), jnp.asarray(pseudoranges), sig)
    if batch_size is None:
        return jax.vmap(one)(*args)
    return jax.lax.map(lambda a: one(*a), args, batch_size=int(batch_size))


class RaimOutput(NamedTuple):
    """What ``raim_fdi`` reports each step (a lean summary of ``EpochIntegrity``).

    Attributes:
      decision: statistic, alarm, label 1 + isolated slot (0: none), estimate = max |TS_j|; a
          dead slot (infinite pseudorange): alarm, label 1 + slot (chi2.flag_dead)
      threshold: () threshold on the parity statistic
      dof: () int, degrees of freedom of the test
      num_used: () int, satellites in the fix
      dops: the fix's dilutions of precision
      hpl: () m, horizontal protection level
      vpl: () m, vertical protection level
      available: () bool (HPL, VPL within the alert limits)
      position: (3,) ECEF, all satellites
      clock_bias: () m, receiver clock bias
      excluded: () int slot (-1: none): the parity test's isolated one, else a dead one
      position_excluded: (3,) after exclusion (= position when none)
      statistic_excluded: () parity statistic after exclusion
      threshold_excluded: () its threshold
      hpl_excluded: () m, HPL after exclusion
      healthy: () bool: the delivered solution (after exclusion, if any) is finite, converged, finite statistic
    """

    decision: Decision
    threshold: Array
    dof: Array
    num_used: Array
    dops: Dops
    hpl: Array
    vpl: Array
    available: Array
    position: Array
    clock_bias: Array
    excluded: Array
    position_excluded: Array
    statistic_excluded: Array
    threshold_excluded: Array
    hpl_excluded: Array
    healthy: Array


def raim_output(result: EpochIntegrity) -> RaimOutput:
    """The epoch's ``RaimOutput``: the test's ``Decision`` labelled ``1 + slot`` of the isolated satellite (-1:
    alarm, none isolated; a dead slot alarms with its label, ``chi2.flag_dead``) and the delivered solution.

    Returns:
      the ``RaimOutput`` (decision, delivered solution).
    """
    check = result.check
    label = jnp.where(
        check.alarm & (check.isolated >= 0), 1 + check.isolated, jnp.where(check.alarm, -1, 0)
    )
    decision = Decision(
        check.statistic, check.alarm, label.astype(jnp.int32), jnp.max(jnp.abs(check.isolation))
    )
    decision = flag_dead(
        decision, result.dead, 1 + jnp.arange(result.dead.shape[0], dtype=jnp.int32)
    )
    return RaimOutput(
        decision,
        check.threshold,
        check.dof,
        result.fix.num_used,
        result.fix.dops,
        result.protection.hpl,
        result.protection.vpl,
        result.protection.available,
        result.fix.position,
        result.fix.clock_bias,
        result.excluded,
        result.fix_excluded.position,
        result.check_excluded.statistic,
        result.check_excluded.threshold,
        result.protection_excluded.hpl,
        delivered_healthy(result),
    )


def delivered_healthy(result: EpochIntegrity) -> Array:
    """() bool: the delivered solution's numerics: after an exclusion the fix without the satellite (a
    fault of tens of km can stop the full fix converging in its fixed Gauss-Newton steps; that fix is
    evidence, not the answer), else the full fix."""
    excluded = result.excluded >= 0
    return jnp.where(
        excluded,
        result.fix_excluded.healthy & result.check_excluded.healthy,
        result.fix.healthy & result.check.healthy,
    )


def raim_fdi(
    table: OrbitTable,
    t0: float,
    dt: float,
    tables: RaimTables,
    sigma=None,
    operation="npa",
    exclude: bool | int = True,
) -> FDI:
    """``monitor_epoch`` as a stateless ``loop.FDI``; step ``k``'s pseudoranges are tagged ``t0 + k dt``.

    Returns:
      ``FDI`` with ``init() -> None`` and ``step(state, k, y, u) -> (state, RaimOutput)``, no ``observe``: ``state``
      passed through, ``y`` (S,) pseudoranges [m] (NaN: not measured, inf: dead channel), ``u`` unused.
    """
    checks.check_positive("dt", dt, "a positive epoch interval (s)")

    def step(state, k, y, u):
        t = t0 + k * dt
        orbit, available = select_orbits(table, t)
        return state, raim_output(
            monitor_epoch(orbit, available, t, y, tables, sigma, operation, exclude)
        )

    return FDI(lambda: None, step)


# --- geometry-only studies: protection levels without measurements ---------------------


def geometry_fix(
    table: OrbitTable,
    t: Array,
    receiver_ecef: Array,
    mask_angle: float,
    sigma: Callable[[Array], Array],
) -> PositionFix:
    """The error-free fix of a receiver at ``receiver_ecef`` (3,) at ``t``: true position, zero residuals, satellites
    above ``mask_angle`` [rad], ``sigma(elevation)`` weights (DOPs, protection levels and MDBs depend on these only)."""
    checks.check_shape("receiver_ecef", receiver_ecef, (3,), "the receiver's ECEF position [m]")
    orbit, has_orbit = select_orbits(table, t)
    sat = satellite_position(orbit, t)
    receiver_ecef = jnp.asarray(receiver_ecef)
    los = line_of_sight_ned(receiver_ecef, sat)
    elevation, azimuth = elevation_azimuth(receiver_ecef, sat)
    used = has_orbit & (elevation > mask_angle)
    geometry = jnp.where(
        used[:, None], jnp.concatenate([-los, jnp.ones_like(elevation)[:, None]], axis=1), 0.0
    )
    return PositionFix(
        receiver_ecef,
        jnp.zeros((), receiver_ecef.dtype),
        jnp.zeros_like(elevation),
        geometry,
        jnp.where(used, sigma(elevation), 1.0),
        used,
        jnp.sum(used),
        elevation,
        azimuth,
        dops(geometry, used),
        jnp.sum(used) >= 4,
    )


class GridAvailability(NamedTuple):
    """Geometry-only integrity over P receivers x T epochs (leaves (P, T), MDB (P, T, S)).

    Attributes:
      num_visible: (P, T) int, satellites above the mask
      hdop: (P, T) horizontal dilution of precision
      hpl: (P, T) m, horizontal protection level
      vpl: (P, T) m, vertical protection level
      available: (P, T) bool: HPL and VPL within the alert limits
      minimum_detectable_bias: (P, T, S) m (inf where not visible)
    """

    num_visible: Array
    hdop: Array
    hpl: Array
    vpl: Array
    available: Array
    minimum_detectable_bias: Array


def availability_grid(
    table: OrbitTable,
    times: Array,
    receivers_ecef: Array,
    tables: RaimTables,
    mask_angle: float,
    sigma: Callable[[Array], Array],
    operation="npa",
    batch_size: int = 64,
) -> GridAvailability:
    """Protection levels and availability for receivers (P, 3) x epochs (T,): ``geometry_fix`` then
    ``protection_levels``, vmapped over epochs, receivers ``batch_size`` at a time (bounded memory).

    Returns:
      ``GridAvailability`` with leaves (P, T) (receiver by epoch), ``minimum_detectable_bias`` (P, T, S); levels
      and biases in m.
    """
    checks.check_shape(
        "receivers_ecef", receivers_ecef, (None, 3), "P receivers' ECEF positions [m]"
    )
    checks.check_shape("times", times, (None,), "T epochs")
    check_mask_angle(mask_angle)
    batch_size = checks.check_int(
        "batch_size", batch_size, 1, meaning="a positive number of receivers per chunk"
    )
    times = jnp.asarray(times)

    def at(receiver, t):
        fix = geometry_fix(table, t, receiver, mask_angle, sigma)
        _, pl = assess(fix, tables, operation)
        return GridAvailability(
            fix.num_used, fix.dops.hdop, pl.hpl, pl.vpl, pl.available, pl.minimum_detectable_bias
        )

    def receiver_row(receiver):
        return jax.vmap(at, in_axes=(None, 0))(receiver, times)

    return jax.lax.map(receiver_row, jnp.asarray(receivers_ecef), batch_size=int(batch_size))
