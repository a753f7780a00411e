"""Spacecraft with a cluster of reaction wheels (Choi & Park 2009, eqs. 1-6).

Euler's equations with wheel momentum (Wie 2008, sec. 7.3; Choi & Park 2009, eq. 1):

    I w' + w x (I w + h_w) + h_w' = T_ext,    h_w = I_w sum_i Omega_i a_i = I_w H^T Omega,

``w`` body rates, ``Omega`` wheel spin rates (rad/s), ``a_i`` spin axes (rows of ``H``, eq. 4),
``I_w Omega_i' = tau_i`` motor torque. With ``T_ext = 0``, ``I w + h_w`` is conserved inertially; in the
body frame ``(I w + h_w)' = -w x (I w + h_w)`` (norm conserved).

* filters' model (Choi & Park's EKF): state ``w`` (3,), input ``u = [Omega (N), Omega' (N)]`` (commanded speeds and
  accelerations), one RK4 step per sample with ``Omega(t) = Omega + t Omega'`` (``wheel_rate_transition``);
  ``params.wheel_mask`` (N,) switches wheels off: stop hypothesis ``Omega_i = 0`` (eq. 9);
* truth (``spacecraft_step``): ``[q (4, scalar first), w (3), Omega (N)]``, driven by the delivered
  wheel torques and an external torque (wheel faults change wheel speeds physically).

Jacobians by ``jax.jacfwd``; the closed form ``A = dw'/dw = -I^-1 ([w]x I - [I w + h_w]x)``
(``rate_jacobian``) is for tests only: the paper's eqs. 3, 5 and 9 have wrong indices and signs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import FaultKind, Target, apply_fault, is_active
from jaxfdi.models._integrate import rk4
from jaxfdi.rotation import quaternion_multiply, rotate, skew


class SpacecraftParams(NamedTuple):
    """Rigid body and wheel cluster (a pytree: vmap over ``wheel_mask`` for a bank).

    Attributes:
      inertia: (3, 3) body inertia, kg m^2
      wheel_inertia: () spin-axis inertia of one wheel I_w, kg m^2
      wheel_axes: (N, 3) spin axes a_i (rows), the H of Choi & Park 2009, eq. 4
      wheel_mask: (N,) 1: the wheel acts as commanded; 0: stopped (a hypothesis)
      dt: () sample period, s
    """

    inertia: Array
    wheel_inertia: Array
    wheel_axes: Array
    wheel_mask: Array
    dt: Array


def pyramid_axes(beta_deg: float = 45.0, sigma_deg: float = 45.0, dtype=None) -> Array:
    """Eq. 4 of Choi & Park (2009): four wheels on a cone of half-angle ``beta`` about body z, at
    azimuths ``+/-sigma``, ``180 -/+ sigma``; rows are the spin axes."""
    checks.check_scalar("beta_deg", beta_deg, meaning="a cone half-angle in degrees")
    checks.check_scalar("sigma_deg", sigma_deg, meaning="an azimuth in degrees")
    dtype = dtype or jnp.result_type(float)
    sb, cb = math.sin(math.radians(beta_deg)), math.cos(math.radians(beta_deg))
    cs, ss = math.cos(math.radians(sigma_deg)), math.sin(math.radians(sigma_deg))
    return jnp.asarray(
        [
            [sb * cs, sb * ss, cb],
            [-sb * cs, sb * ss, cb],
            [-sb * cs, -sb * ss, cb],
            [sb * cs, -sb * ss, cb],
        ],
        dtype,
    )


def kitsat3_params(
    dt: float = 0.1,
    wheel_axes=None,
    inertia=(3.118, 3.050, 4.055),
    wheel_inertia: float = 0.000239,
    dtype=None,
) -> SpacecraftParams:
    """KITSAT-3 (Choi & Park 2009, Table 1): ``I = diag(3.118, 3.050, 4.055)`` kg m^2, ``I_w = 0.000239`` kg m^2, the
    45/45 deg pyramid unless ``wheel_axes`` (N, 3) is given (rows normalised); a (3,) ``inertia`` is its diagonal.

    Returns:
      ``SpacecraftParams`` in ``dtype``, unit ``wheel_axes`` (N = 4 for the pyramid), ``wheel_mask`` ones.
    """
    checks.check_positive("dt", dt, "a positive sample period in seconds")
    checks.check_positive("wheel_inertia", wheel_inertia, "a positive wheel inertia in kg m^2")
    dtype = dtype or jnp.result_type(float)
    if wheel_axes is not None:
        checks.check_matrix("wheel_axes", wheel_axes, (None, 3), "one spin axis per row")
        if np.any(np.linalg.norm(np.asarray(wheel_axes, float), axis=1) == 0):
            raise ValueError(
                f"wheel_axes: expected non-zero spin axes, got {checks.received(wheel_axes)}"
            )
    axes = pyramid_axes(dtype=dtype) if wheel_axes is None else jnp.asarray(wheel_axes, dtype)
    axes = axes / jnp.linalg.norm(axes, axis=1, keepdims=True)
    checks.check_real("inertia", inertia, "a real body inertia")
    if np.ndim(inertia) == 1:
        checks.check_matrix("inertia", inertia, (3,), "the 3 principal moments of inertia")
        inertia = np.diag(np.asarray(inertia, float))
    checks.check_covariance("inertia", inertia, 3, definite=True)  # symmetric positive definite
    inertia = jnp.asarray(inertia, dtype)
    return SpacecraftParams(
        inertia,
        jnp.asarray(wheel_inertia, dtype),
        axes,
        jnp.ones(axes.shape[0], dtype),
        jnp.asarray(dt, dtype),
    )


def stop_hypotheses(params: SpacecraftParams, include_nominal: bool = False) -> SpacecraftParams:
    """The bank's models: hypothesis ``i`` has wheel ``i`` stopped (Choi & Park 2009, eq. 9).

    Returns ``params`` with a leading hypothesis axis (N, ...), or with ``include_nominal`` (N + 1, ...),
    fault-free first (mode ``1 + i`` = wheel ``i`` stopped, the simulator's label order).

    Returns:
      ``SpacecraftParams`` whose leaves have a leading hypothesis axis, (N, ...) or (N + 1, ...): ``wheel_mask``
      ``1 - e_i`` per hypothesis (all ones for the nominal), the other leaves repeated.
    """
    N = params.wheel_axes.shape[0]
    masks = 1.0 - jnp.eye(N, dtype=params.wheel_mask.dtype)
    if include_nominal:
        masks = jnp.concatenate([jnp.ones((1, N), masks.dtype), masks], axis=0)
    stacked = jax.tree_util.tree_map(
        lambda leaf: jnp.broadcast_to(leaf, (masks.shape[0],) + jnp.shape(leaf)), params
    )
    return stacked._replace(wheel_mask=masks)


def wheel_momentum(speeds: Array, params: SpacecraftParams) -> Array:
    """``h_w = I_w H^T (mask * Omega)`` (3,).

    Returns:
      the (3,) wheel angular momentum in body axes [N m s].
    """
    return params.wheel_inertia * (params.wheel_mask * speeds) @ params.wheel_axes


def rate_derivative(
    w: Array,
    speeds: Array,
    accelerations: Array,
    params: SpacecraftParams,
    external_torque: Array | float = 0.0,
) -> Array:
    """``w' = I^-1 (T_ext - w x (I w + h_w) - h_w')`` (Choi & Park 2009, eq. 1, any wheel geometry)."""
    momentum = params.inertia @ w + wheel_momentum(speeds, params)
    wheel_torque_on_body = wheel_momentum(accelerations, params)  # h_w'
    return jnp.linalg.solve(
        params.inertia, external_torque - jnp.cross(w, momentum) - wheel_torque_on_body
    )


def split_input(u: Array, params: SpacecraftParams) -> tuple[Array, Array]:
    """``u = [Omega (N), Omega' (N)]`` -> ``(Omega, Omega')``."""
    N = params.wheel_axes.shape[0]
    checks.check_shape("u", u, (2 * N,), f"[wheel speeds ({N}), wheel accelerations ({N})]")
    return u[:N], u[N:]


def body_rate_field(w: Array, u: Array, params: SpacecraftParams) -> Array:
    """The filters' ``w' = g(w, u)`` at the start of a step; ``dg/dw`` is ``A`` of Choi & Park (2009, eq. 8).

    Returns:
      (3,) body angular acceleration ``w'`` [rad/s^2], without external torque.
    """
    speeds, accelerations = split_input(u, params)
    return rate_derivative(w, speeds, accelerations, params)


def wheel_rate_transition(w: Array, u: Array, params: SpacecraftParams) -> Array:
    """The filters' ``f``: one RK4 step of the rates with ``Omega(t) = Omega + t Omega'``.

    Returns:
      (3,) body rates ``w`` [rad/s] one sample ``params.dt`` later.
    """
    speeds, accelerations = split_input(u, params)
    return rk4(
        lambda x, t: rate_derivative(x, speeds + t * accelerations, accelerations, params),
        w,
        params.dt,
    )


def gyro_observation(w: Array, u: Array, params: SpacecraftParams) -> Array:
    """Three rate gyros on the body axes, ``z = w`` (Choi & Park 2009, eq. 6).

    Returns:
      (3,) the noise-free gyro reading, ``w`` itself [rad/s].
    """
    return w


def rate_jacobian(w: Array, speeds: Array, params: SpacecraftParams) -> Array:
    """Closed form ``A = -I^-1 ([w]x I - [I w + h_w]x)`` (for tests; the library uses AD)."""
    momentum = params.inertia @ w + wheel_momentum(speeds, params)
    return -jnp.linalg.solve(params.inertia, skew(w) @ params.inertia - skew(momentum))


# --- the truth: attitude, rates and wheel speeds -------------------------------------


def spacecraft_field(
    state: Array, wheel_torque: Array, external_torque: Array, params: SpacecraftParams
) -> Array:
    """``[q', w', Omega']`` of the truth state ``[q (4), w (3), Omega (N)]``."""
    q, w, speeds = state[:4], state[4:7], state[7:]
    accelerations = wheel_torque / params.wheel_inertia
    q_dot = 0.5 * quaternion_multiply(q, jnp.concatenate([jnp.zeros(1, w.dtype), w]))
    w_dot = rate_derivative(w, speeds, accelerations, params, external_torque)
    return jnp.concatenate([q_dot, w_dot, accelerations])


def spacecraft_step(
    state: Array,
    wheel_torque: Array,
    external_torque: Array,
    params: SpacecraftParams,
    substeps: int = 4,
) -> Array:
    """Truth over one sample: torques held, ``substeps`` RK4 steps, quaternion renormalised.

    Returns:
      the truth state one sample later (quaternion, body rates, wheel speeds).
    """
    nxt = rk4(
        lambda x, t: spacecraft_field(x, wheel_torque, external_torque, params),
        state,
        params.dt,
        substeps,
    )
    return nxt.at[:4].set(nxt[:4] / jnp.linalg.norm(nxt[:4]))


def total_momentum(state: Array, params: SpacecraftParams) -> Array:
    """Inertial-frame angular momentum ``R(q) (I w + h_w)`` (3,): constant without ``T_ext``."""
    q, w, speeds = state[:4], state[4:7], state[7:]
    return rotate(q, params.inertia @ w + wheel_momentum(speeds, params))


# --- sensors, commands and faults of the truth (its loop.Plant: control.attitude.wheel_plant) ---


class AttitudeReading(NamedTuple):
    """The attitude sensors at step ``k``: attitude (taken as exact) and gyro rates.

    Attributes:
      quaternion: (4,) true attitude, scalar first
      rate: (3,) gyro reading w + v, rad/s
    """

    quaternion: Array
    rate: Array


class WheelCommand(NamedTuple):
    """The flight software's command at step ``k``: wheel speeds (integral of the torques) and torques.

    Attributes:
      speeds: (N,) rad/s
      torque: (N,) N m
    """

    speeds: Array
    torque: Array


def filter_input(command: WheelCommand, params: SpacecraftParams) -> Array:
    """The filters' input ``u = [Omega_cmd, tau_cmd / I_w]`` (``wheel_rate_transition``).

    Returns:
      (2N,) ``[Omega_cmd (N) rad/s, Omega'_cmd (N) rad/s^2]``.
    """
    return jnp.concatenate([command.speeds, command.torque / params.wheel_inertia])


def delivered_torque(f, k: Array, command: Array) -> Array:
    """Torques delivered under fault ``f`` (scalar leaves): bias and gain loss act on the command; STOP or
    STUCK deliver none; sensor faults leave the wheels alone.

    Returns:
      the (4,) torques the wheels deliver [N m].
    """
    faulty, _ = apply_fault(f, k, command, Target.ACTUATOR, jnp.zeros((), command.dtype))
    no_torque = (
        is_active(f, k)
        & (f.target == Target.ACTUATOR)
        & ((f.kind == FaultKind.STOP) | (f.kind == FaultKind.STUCK))
    )
    wheel = jax.nn.one_hot(f.component, command.shape[0], dtype=bool)
    return jnp.where(no_torque & wheel, 0.0, faulty)


def stop_transfer(state: Array, f, k: Array, params: SpacecraftParams) -> Array:
    """At a stop's onset: the wheel's speed -> 0 and its momentum to the body rates.

    Returns:
      the state with the stopped wheel's momentum moved to the body.
    """
    speeds = state[7:]
    stopped = (f.kind == FaultKind.STOP) & (f.target == Target.ACTUATOR) & (k == f.onset)
    new_speeds = jnp.where(
        stopped & jax.nn.one_hot(f.component, speeds.shape[0], dtype=bool), 0.0, speeds
    )
    body_momentum = params.inertia @ state[4:7] + wheel_momentum(speeds, params)
    w = jnp.linalg.solve(params.inertia, body_momentum - wheel_momentum(new_speeds, params))
    return jnp.where(stopped, jnp.concatenate([state[:4], w, new_speeds]), state)
