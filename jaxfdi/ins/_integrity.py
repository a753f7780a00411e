"""The GPS/INS integrity monitor of Yoo et al. (2010, Fig. 3) as an FDI stage of the foundation's loop.

Each GPS epoch:

1. **RAIM** (``gnss.integrity.monitor_epoch``: fix, parity test, protection levels; no exclusion).
   The fix is used only when RAIM *passes*: ``n >= 5``, no alarm, HPL and VPL within the alert limits,
   fix converged; otherwise the epoch is coasted.
2. **EKF** (``loosely_coupled_filter``): update with the fix (position covariance ``(G^T W G)^-1`` in
   NED, velocity ``velocity_sigma^2 I``), feedback, INS through the epoch's IMU samples.
3. **Windowed chi-square** (Yoo et al. 2010, eq. 1; ``detection.chi2_detector``): NIS summed over the
   last ``window`` updated epochs (10: 60 dof, 91.95 at 0.005); a coasted epoch changes nothing.
4. **SCST** (``scst.state_chi2_test``) on the corrections and covariances, every epoch.
5. **IMU health** (``imu_health_test``, beyond the paper): ``detection.frozen`` on every raw sample
   against its white noise (``imu.sample_sigma``); non-finite = dead (``chi2.flag_dead``); label
   ``1 + channel`` of ``[f_x, f_y, f_z, w_x, w_y, w_z]``. The EKF coasts on a dead channel's last
   finite sample (``loosely_coupled.hold_last_finite``); no IMU channel can be excluded (one sensor
   per axis): the alarm is the whole answer.

The chi-square test sees GPS minus INS, never fused before, so simultaneous GPS and INS faults cannot
cancel (the paper's argument). The INS tests also see satellite faults RAIM has not yet flagged (a 1 m/s
drift reaches the filter 10-25 s before RAIM crosses) and settling after RAIM's exclusion:
``attribute_ins_alarms`` gives an INS alarm near a RAIM alarm to the GPS.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi._simulation.stages import FDI
from jaxfdi.detection import (
    Decision,
    Detector,
    FrozenState,
    WindowState,
    frozen_channel_detector,
    moving_window_sum,
)
from jaxfdi.filters import Filter
from jaxfdi.gnss import (
    OrbitTable,
    PositionFix,
    RaimTables,
    ecef_to_geodetic,
    elevation_sigma,
    monitor_epoch,
    raim_output,
    select_orbits,
)
from jaxfdi.ins import _imu as imu
from jaxfdi.ins._error_state import STATE_SIZE
from jaxfdi.ins._loosely_coupled import GpsFix, InsState
from jaxfdi.ins._mechanization import NavState
from jaxfdi.ins._scst import ScstState, StateChi2Test

#: the IMU health test: samples per window, false-alarm probability per window and channel
#: (union bound per 1200 s flight at 100 Hz: 6 x 1.2e5 windows x 1e-9 < 1e-3)
IMU_HEALTH_WINDOW = 20
IMU_HEALTH_PFA = 1e-9


class GpsInsFdiState(NamedTuple):
    ins: InsState
    chi2: WindowState
    scst: ScstState
    health: FrozenState


class InsTestOutput(NamedTuple):
    """One epoch of the INS tests (``ins_monitor_step``).

    Attributes:
      gps_used: () bool: the EKF was updated
      chi2: windowed NIS (statistic held, alarm False on coasted epochs)
      scst: the state chi-square test's decision
      scst_valid: () bool: the SCST's B passed its checks
      scst_condition: () condition estimate of the SCST's scaled B
      scst_age: () int, age of the tested propagator [epochs]
      imu_health: the epoch's IMU health decision: alarm if a sample alarmed, label 1 + channel
      nis: () normalised innovation squared of the epoch
      nav: the estimate at t_k (after the feedback)
      accel_bias: (3,) accelerometer bias estimate [m/s^2]
      gyro_bias: (3,) gyro bias estimate [rad/s]
      cov: (15, 15) P[k|k]
      healthy: () bool: the filter healthy and both statistics finite
    """

    gps_used: Array
    chi2: Decision
    scst: Decision
    scst_valid: Array
    scst_condition: Array
    scst_age: Array
    imu_health: Decision
    nis: Array
    nav: NavState
    accel_bias: Array
    gyro_bias: Array
    cov: Array
    healthy: Array


class GpsInsOutput(NamedTuple):
    """One epoch of the GPS/INS monitor (stacked over time with ``keep_history``).

    Attributes:
      raim: parity statistic, alarm, label 1 + isolated slot
      raim_threshold: () threshold of the parity test
      hpl: () m, horizontal protection level
      hdop: () horizontal dilution of precision
      num_used: () satellites in the fix
      ins: the INS tests of the epoch
      healthy: () bool: the INS tests' ``healthy``
    """

    raim: Decision
    raim_threshold: Array
    hpl: Array
    hdop: Array
    num_used: Array
    ins: InsTestOutput
    healthy: Array

    # the INS fields at the top level, for scorers and plots
    gps_used = property(lambda self: self.ins.gps_used)
    chi2 = property(lambda self: self.ins.chi2)
    scst = property(lambda self: self.ins.scst)
    scst_valid = property(lambda self: self.ins.scst_valid)
    nav = property(lambda self: self.ins.nav)
    cov = property(lambda self: self.ins.cov)


def fix_covariance(fix: PositionFix) -> Array:
    """(3, 3) NED position covariance [m^2] of a weighted least-squares fix."""
    h = jnp.where(fix.used[:, None], fix.geometry / fix.sigma[:, None], 0.0)
    normal = h.T @ h
    inverse = _linalg.cho_solve(_linalg.cholesky(normal), jnp.eye(4, dtype=h.dtype))
    return _linalg.symmetrize(inverse[:3, :3])


def imu_health_test(
    model: imu.ImuModel, dt: float, window: int = IMU_HEALTH_WINDOW, pfa: float = IMU_HEALTH_PFA
) -> Detector:
    """Step 5: ``detection.frozen_channel_detector`` on a (6,) sample ``dt`` [s] long, noise
    ``imu.sample_sigma``, labels ``1 + channel``.

    Returns:
      ``Detector(init, step)``: ``init()`` an empty ``FrozenState`` (zero (window, 6) buffer); ``step(state,
      sample (6,) [f^b m/s^2, w_ib^b rad/s]) -> (state, Decision)``, label ``1 + channel`` of the most frozen channel.
    """
    return frozen_channel_detector(
        imu.sample_sigma(model, dt), window, pfa, 1 + jnp.arange(6, dtype=jnp.int32)
    )


def _epoch_decision(decisions: Decision) -> Decision:
    """An epoch's decision from per-sample ones (leaves (n,)): the first alarmed, else the last."""
    alarm = jnp.any(decisions.alarm)
    index = jnp.where(alarm, jnp.argmax(decisions.alarm), decisions.alarm.shape[0] - 1)
    return Decision(
        decisions.statistic[index], alarm, decisions.label[index], decisions.estimate[index]
    )


def ins_monitor_step(
    ins_filter: Filter,
    chi2: Detector,
    scst: StateChi2Test,
    health: Detector,
    state: GpsInsFdiState,
    fix: GpsFix,
    samples: Array,
) -> tuple[GpsInsFdiState, InsTestOutput]:
    """Steps 2-5 for one epoch: the EKF with ``fix`` and ``samples`` (n, 6), then the three tests."""
    health_state, verdicts = jax.lax.scan(health.step, state.health, samples)
    ins, info = ins_filter.step(state.ins, fix, samples)
    window, decision = chi2.step(state.chi2, info.nis)
    window = WindowState(
        jnp.where(info.used, window.buffer, state.chi2.buffer),
        jnp.where(info.used, window.index, state.chi2.index),
    )
    held = jnp.sum(state.chi2.buffer)
    dtype = state.ins.cov.dtype
    chi2_decision = Decision(
        jnp.where(info.used, decision.statistic, held),
        info.used & decision.alarm,
        jnp.asarray(-1, jnp.int32),
        jnp.full((), jnp.nan, dtype),
    )
    scst_state, scst_out = scst.step(
        state.scst, info.correction, info.filtered_cov, info.transition, info.process_cov
    )
    healthy = (
        info.healthy
        & jnp.isfinite(chi2_decision.statistic)
        & jnp.isfinite(scst_out.decision.statistic)
    )
    out = InsTestOutput(
        info.used,
        chi2_decision,
        scst_out.decision,
        scst_out.valid,
        scst_out.condition,
        scst_out.age,
        _epoch_decision(verdicts),
        info.nis,
        info.filtered_nav,
        info.accel_bias,
        info.gyro_bias,
        info.filtered_cov,
        healthy,
    )
    return GpsInsFdiState(ins, window, scst_state, health_state), out


def ins_fdi_init(ins_filter: Filter, chi2: Detector, scst: StateChi2Test, health: Detector):
    """The INS monitor's ``init(nav, cov, accel_bias=None, gyro_bias=None) -> GpsInsFdiState``: the EKF's prior
    (``ins_filter.init``) and the three tests' empty states."""
    return lambda *args, **kwargs: GpsInsFdiState(
        ins_filter.init(*args, **kwargs), chi2.init(), scst.init(STATE_SIZE), health.init()
    )


def ins_fdi(ins_filter: Filter, chi2: Detector, scst: StateChi2Test, health: Detector) -> FDI:
    """The INS tests alone as a ``loop.FDI``: step ``k`` takes ``(GpsFix, samples (n, 6))`` (a receiver's
    validated solution, e.g. from a log) and returns an ``InsTestOutput``; ``init`` as ``ins_fdi_init``."""

    def step(state: GpsInsFdiState, k, y, u):
        fix, samples = y
        return ins_monitor_step(ins_filter, chi2, scst, health, state, fix, samples)

    return FDI(ins_fdi_init(ins_filter, chi2, scst, health), step)


def gps_ins_fdi(
    table: OrbitTable,
    t0: float,
    tables: RaimTables,
    ins_filter: Filter,
    chi2: Detector,
    scst: StateChi2Test,
    health: Detector,
    velocity_sigma: float,
    operation="npa",
) -> FDI:
    """The monitor of the module doc as a ``loop.FDI``; ``health``: ``imu_health_test``.

    Returns:
      ``FDI`` with ``step(state, k, y, u) -> (state, GpsInsOutput)``, no ``observe``; ``y`` a
      ``plant.GpsInsMeasurement`` tagged ``t0 + k`` s, ``u`` unused; ``init(nav, cov, ...)`` as ``ins_fdi_init``.
    """
    checks.check_positive("velocity_sigma", velocity_sigma, "a velocity standard deviation (m/s)")

    def step(state: GpsInsFdiState, k, y, u):
        t = t0 + k
        orbit, available = select_orbits(table, t)
        epoch = monitor_epoch(
            orbit, available, t, y.pseudoranges, tables, elevation_sigma, operation, exclude=False
        )
        fix, check, protection = epoch.fix, epoch.check, epoch.protection
        passes = fix.healthy & check.healthy & (check.dof > 0) & ~check.alarm & protection.available
        lat, lon, height = ecef_to_geodetic(fix.position)
        gps = GpsFix(
            jnp.stack([lat, lon, height]),
            y.velocity,
            fix_covariance(fix),
            velocity_sigma**2 * jnp.eye(3, dtype=state.ins.cov.dtype),
            passes,
        )
        state, ins = ins_monitor_step(ins_filter, chi2, scst, health, state, gps, y.imu)
        raim = raim_output(epoch).decision  # label 1 + slot; a dead slot alarms (chi2.flag_dead)
        return state, GpsInsOutput(
            raim, check.threshold, protection.hpl, fix.dops.hdop, fix.num_used, ins, ins.healthy
        )

    return FDI(ins_fdi_init(ins_filter, chi2, scst, health), step)


def initial_covariance(
    position_sigma: float,
    velocity_sigma: float,
    tilt_sigma: float,
    heading_sigma: float,
    accel_bias_sigma: float,
    gyro_bias_sigma: float,
    dtype=None,
) -> Array:
    """(15, 15) diagonal ``P0`` from 1-sigma errors [m, m/s, rad, rad, m/s^2, rad/s].

    Returns:
      (15, 15) ``diag(sigma^2)`` in ``dtype`` (default float) for ``[dp (3), dv (3), psi_N, psi_E (tilt), psi_D
      (heading), db_a (3), db_g (3)]``.
    """
    for name, value in (
        ("position_sigma", position_sigma),
        ("velocity_sigma", velocity_sigma),
        ("tilt_sigma", tilt_sigma),
        ("heading_sigma", heading_sigma),
        ("accel_bias_sigma", accel_bias_sigma),
        ("gyro_bias_sigma", gyro_bias_sigma),
    ):
        checks.check_scalar(name, value, 0.0, meaning="a standard deviation >= 0")
    dtype = dtype or jnp.result_type(float)
    sigmas = jnp.asarray(
        [position_sigma] * 3
        + [velocity_sigma] * 3
        + [tilt_sigma] * 2
        + [heading_sigma]
        + [accel_bias_sigma] * 3
        + [gyro_bias_sigma] * 3,
        dtype,
    )
    return jnp.diag(sigmas**2)


def attribute_ins_alarms(
    ins_alarms: Array, gps_alarms: Array, lookahead: int, holdoff: int
) -> Array:
    """The INS's own alarms ``(..., T)`` of ``(..., T)`` bool arrays: an alarm at ``k`` is the GPS's when
    ``any(gps[k - holdoff : k + lookahead + 1])`` (``detection.chi2.moving_window_sum``, history padded
    with ``lookahead`` alarm-free epochs). A causal monitor decides at ``k + lookahead``; ``holdoff``
    covers the filter and SCST propagators settling after an exclusion.

    Returns:
      (..., T) bool: ``ins_alarms`` with the alarms attributed to the GPS cleared.
    """
    lookahead = checks.check_int("lookahead", lookahead, 0, meaning="a number of epochs >= 0")
    holdoff = checks.check_int("holdoff", holdoff, 0, meaning="a number of epochs >= 0")
    ins_alarms, gps_alarms = jnp.asarray(ins_alarms, bool), jnp.asarray(gps_alarms, bool)
    if ins_alarms.shape != gps_alarms.shape:
        raise ValueError(
            f"gps_alarms: expected the shape of ins_alarms {ins_alarms.shape}, got {gps_alarms.shape}"
        )
    counts = jnp.moveaxis(gps_alarms, -1, 0).astype(jnp.float32)
    padded = jnp.concatenate([counts, jnp.zeros((lookahead,) + counts.shape[1:], counts.dtype)])
    near = moving_window_sum(padded, holdoff + lookahead + 1)[lookahead:] > 0
    return ins_alarms & ~jnp.moveaxis(near, 0, -1)
