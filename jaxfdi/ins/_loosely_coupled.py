"""The 15-state loosely coupled INS/GPS error-state EKF with feedback (Yoo et al. 2010, Appendix).

State: the INS (navigation state, IMU bias estimates) and ``P[k|k-1]``; one ``step`` per GPS epoch:

1. **update** with a valid fix (RAIM passed): ``z = [p_INS - p_GPS; v_INS - v_GPS]`` (NED metres,
   ``error_state.navigation_error``), ``H = [I_6 0]``, ``R = blkdiag(R_p, R_v)`` from the receiver's
   least-squares covariance; Joseph form (``filters.kalman.joseph_update``), NIS ``z^T S^-1 z``;
2. **feedback and reset** (Groves 2013, sec. 14.1.2): INS ``error_state.correct(INS, dx_hat)``, biases
   ``b_hat + db_hat``, error estimate to zero (``P`` kept: first-order reset);
3. **predict** over the epoch's ``n`` samples (``u`` (n, 6), e.g. 100 at 100 Hz): ``n`` strapdown steps
   (``mechanization.strapdown_step``) on bias-corrected samples in ``chunks`` equal chunks; ``F`` by
   ``jax.jacfwd`` (``error_state.error_jacobian``) at each chunk's midpoint state and mean sample, their
   mean discretised (``error_state.discretize``): ``P[k+1|k] = Phi P[k|k] Phi^T + Q_d``.

The 15 x 15 algebra runs at 1 Hz; at 100 Hz only the mechanisation (and ``chunks`` Jacobians). A
non-finite sample (dead channel) is replaced by its channel's last finite one (``hold_last_finite``):
the INS coasts instead of turning NaN; the IMU health test (``ins.integrity.imu_health_test``) alarms.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters import Filter, joseph_update
from jaxfdi.ins import _error_state as error_state
from jaxfdi.ins import _mechanization as mechanization
from jaxfdi.ins._error_state import STATE_SIZE, ImuNoise
from jaxfdi.ins._imu import ImuModel, noise_model
from jaxfdi.ins._mechanization import NavState

MEASUREMENT_SIZE = 6


class InsState(NamedTuple):
    """The filter's state at ``t_k`` before the update: the INS and ``P[k|k-1]``.

    Attributes:
      nav: the INS's navigation state at t_k
      accel_bias: (3,) estimate b_hat_a [m/s^2]
      gyro_bias: (3,) estimate b_hat_g [rad/s]
      cov: (15, 15) P[k|k-1]
      last_sample: (6,) each channel's last finite IMU sample (0 before the first)
    """

    nav: NavState
    accel_bias: Array
    gyro_bias: Array
    cov: Array
    last_sample: Array


class GpsFix(NamedTuple):
    """One epoch's GPS solution as the filter uses it.

    Attributes:
      position: (3,) lat, lon [rad], h [m]
      velocity: (3,) NED [m/s]
      position_cov: (3, 3) NED [m^2]
      velocity_cov: (3, 3) [m^2/s^2]
      valid: () bool: use it (RAIM passed)
    """

    position: Array
    velocity: Array
    position_cov: Array
    velocity_cov: Array
    valid: Array


class InsInfo(NamedTuple):
    """What one step of the loosely coupled EKF reports.

    Attributes:
      innovation: (6,) z (0 when not used)
      innovation_cov: (6, 6) S
      nis: () z^T S^-1 z (0 when not used)
      used: () bool: the GPS fix was used
      correction: (15,) dx_hat[k|k] fed back (0 when not used)
      predicted_cov: (15, 15) P[k|k-1]
      filtered_cov: (15, 15) P[k|k]
      filtered_nav: the INS after the feedback (the estimate at t_k)
      accel_bias: (3,) estimate after the feedback
      gyro_bias: (3,) estimate after the feedback
      transition: (15, 15) Phi from t_k to t_k+1
      process_cov: (15, 15) Q_d
      healthy: () bool: S and P[k|k] positive definite, everything finite
    """

    innovation: Array
    innovation_cov: Array
    nis: Array
    used: Array
    correction: Array
    predicted_cov: Array
    filtered_cov: Array
    filtered_nav: NavState
    accel_bias: Array
    gyro_bias: Array
    transition: Array
    process_cov: Array
    healthy: Array


def hold_last_finite(samples: Array, last: Array) -> tuple[Array, Array]:
    """``samples`` (n, 6), non-finite values replaced by the channel's latest finite one (``last`` (6,)
    before the first), and the new ``last``."""
    finite = jnp.isfinite(samples)
    latest = jax.lax.cummax(jnp.where(finite, jnp.arange(samples.shape[0])[:, None], -1), axis=0)
    filled = jnp.take_along_axis(samples, jnp.maximum(latest, 0), axis=0)
    filled = jnp.where(latest >= 0, filled, last)
    return filled, filled[-1]


def measurement_matrix(dtype) -> Array:
    return jnp.eye(MEASUREMENT_SIZE, STATE_SIZE, dtype=dtype)


def loosely_coupled_filter(imu: ImuModel, dt: float, chunks: int = 1) -> Filter:
    """The error-state EKF (module doc) for IMU samples ``dt`` [s] apart.

    Args:
      imu: the IMU model the filter assumes (e.g. ``hg1900()``): its white-noise and bias random-walk densities.
      dt: IMU sample interval [s]; an epoch is ``u.shape[0]`` samples.
      chunks: Jacobian evaluations per epoch (must divide the samples per epoch; each at its chunk's midpoint).

    Returns:
      ``Filter(init, step)``: ``init(nav, cov, accel_bias=None, gyro_bias=None) -> InsState`` (first
      epoch's ``NavState``, (15, 15) covariance, (3,) biases, default 0); ``step(state, fix, u) ->
      (state, InsInfo)`` with the epoch's ``GpsFix`` and (n, 6) samples ``u``, state at the next epoch.
    """
    checks.check_positive("dt", dt, "the IMU sample interval in seconds")
    chunks = checks.check_int(
        "chunks", chunks, 1, meaning="a positive number of Jacobians per epoch"
    )
    if not isinstance(imu, ImuModel):
        raise TypeError(
            f"imu: expected an ImuModel (e.g. jaxfdi.ins.hg1900()), got {checks.received(imu)}"
        )
    for name in ImuNoise._fields:
        checks.check_scalar(f"imu.{name}", getattr(imu, name), 0.0, meaning="a noise density >= 0")
    noise = noise_model(imu)

    def init(
        nav: NavState, cov: Array, accel_bias: Array | None = None, gyro_bias: Array | None = None
    ) -> InsState:
        checks.check_shape("nav.position", nav.position, (3,), "lat, lon [rad], h [m]")
        checks.check_shape("nav.velocity", nav.velocity, (3,), "NED velocity")
        checks.check_shape("nav.attitude", nav.attitude, (4,), "a unit quaternion")
        checks.check_covariance("cov", cov, STATE_SIZE)
        quaternion = checks.concrete(nav.attitude)
        if quaternion is not None and quaternion.dtype.kind == "f":
            tolerance = float(np.sqrt(np.finfo(quaternion.dtype).eps))
            if not abs(float(np.linalg.norm(quaternion)) - 1.0) <= tolerance:
                raise ValueError(
                    f"nav.attitude: expected a unit quaternion (| |q| - 1 | <= {tolerance:.2g}), got "
                    f"{checks.received(quaternion)} of norm {float(np.linalg.norm(quaternion)):.6g}"
                )
        for name, bias in (("accel_bias", accel_bias), ("gyro_bias", gyro_bias)):
            if bias is not None:
                checks.check_shape(name, bias, (3,), "an IMU bias estimate per axis")
        dtype = checks.float_dtype(nav.position, cov)
        zero = jnp.zeros((3,), dtype)
        return InsState(
            jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), nav),
            zero if accel_bias is None else jnp.asarray(accel_bias, dtype),
            zero if gyro_bias is None else jnp.asarray(gyro_bias, dtype),
            jnp.asarray(cov, dtype),
            jnp.zeros((6,), dtype),
        )

    def update(state: InsState, fix: GpsFix):
        dtype = state.cov.dtype
        reference = NavState(fix.position, fix.velocity, state.nav.attitude)
        z = error_state.navigation_error(state.nav, reference)[:MEASUREMENT_SIZE]
        zero = jnp.zeros((3, 3), dtype)
        R = jnp.block([[fix.position_cov, zero], [zero, fix.velocity_cov]])
        post = joseph_update(
            jnp.zeros((STATE_SIZE,), dtype),
            state.cov,
            z,
            jnp.zeros_like(z),
            measurement_matrix(dtype),
            R,
        )
        used = jnp.asarray(fix.valid, bool) & jnp.all(jnp.isfinite(z))
        correction = jnp.where(used, post.filtered_mean, 0.0)
        cov = jnp.where(used, post.filtered_cov, state.cov)
        return post, used, correction, cov

    def propagate(nav: NavState, samples: Array, accel_bias: Array, gyro_bias: Array):
        """``n`` strapdown steps and the mean ``F`` of the chunks' midpoints."""
        corrected = samples - jnp.concatenate([accel_bias, gyro_bias])
        per_chunk = corrected.shape[0] // chunks
        first = per_chunk // 2

        def strapdown(nav, sample):
            return mechanization.strapdown_step(nav, sample[:3], sample[3:], dt), None

        def chunk(nav, part):
            nav, _ = jax.lax.scan(strapdown, nav, part[:first])
            mean = jnp.mean(part, axis=0)
            jacobian = error_state.error_jacobian(nav, mean[:3], mean[3:])
            nav, _ = jax.lax.scan(strapdown, nav, part[first:])
            return nav, jacobian

        nav, jacobians = jax.lax.scan(chunk, nav, corrected.reshape(chunks, per_chunk, 6))
        return nav, jnp.mean(jacobians, axis=0)

    def step(state: InsState, fix: GpsFix, samples: Array):
        samples = jnp.asarray(samples)
        if (
            samples.ndim != 2
            or samples.shape[1] != 6
            or samples.shape[0] % chunks
            or samples.shape[0] < 2 * chunks
        ):
            raise ValueError(
                f"u: expected (n, 6) IMU samples with n a multiple of chunks = {chunks} and at least "
                f"{2 * chunks}, got shape {tuple(samples.shape)}"
            )
        samples, last_sample = hold_last_finite(samples, state.last_sample)
        post, used, correction, cov = update(state, fix)
        nav = error_state.correct(state.nav, correction)
        accel_bias = state.accel_bias + correction[error_state.ACCEL_BIAS]
        gyro_bias = state.gyro_bias + correction[error_state.GYRO_BIAS]
        next_nav, jacobian = propagate(nav, samples, accel_bias, gyro_bias)
        transition, process = error_state.discretize(jacobian, noise, samples.shape[0] * dt)
        predicted = _linalg.symmetrize(transition @ cov @ transition.T + process)
        chol = jnp.linalg.cholesky(cov)
        healthy = (
            jnp.where(used, post.healthy, True)
            & jnp.all(jnp.isfinite(chol))
            & jnp.all(jnp.isfinite(predicted))
            & jnp.all(jnp.isfinite(next_nav.position))
        )
        info = InsInfo(
            jnp.where(used, post.innovation, 0.0),
            post.innovation_cov,
            jnp.where(used, post.nis, 0.0),
            used,
            correction,
            state.cov,
            cov,
            nav,
            accel_bias,
            gyro_bias,
            transition,
            process,
            healthy,
        )
        return InsState(next_nav, accel_bias, gyro_bias, predicted, last_sample), info

    return Filter(init, step)
