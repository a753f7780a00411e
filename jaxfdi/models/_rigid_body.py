"""Rigid-body angular rates (Euler's equations), a small nonlinear model.

``I w' = tau - w x (I w)``, ``I = diag(Ixx, Iyy, Izz)`` (default the F-16's, Stevens & Lewis, kg m^2),
``w = [p, q, r]`` (rad/s), torque ``tau`` (N m), one RK4 step per sample; measured ``y = w``. The
gyroscopic term is quadratic in ``w``, so UKF, EKF and KF differ.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.models._integrate import rk4


class RigidBodyParams(NamedTuple):
    """Rigid-body parameters: principal moments of inertia and the sample period.

    Attributes:
      inertia: (3,) principal moments of inertia
      dt: () sample period
    """

    inertia: Array
    dt: Array


def rigid_body_params(
    dt: float = 0.02, inertia=(12875.0, 75674.0, 85552.0), dtype=None
) -> RigidBodyParams:
    """Principal moments of inertia ``inertia`` (3,) > 0 and the step ``dt`` > 0 (s).

    Returns:
      ``RigidBodyParams(inertia (3,) [kg m^2], dt () [s])`` in ``dtype`` (default: JAX's default float).
    """
    checks.check_positive("dt", dt, "a positive step in seconds")
    checks.check_matrix("inertia", inertia, (3,), "the 3 principal moments of inertia")
    if np.any(np.asarray(inertia) <= 0):
        raise ValueError(
            f"inertia: expected positive principal moments, got {checks.received(inertia)}"
        )
    dtype = dtype or jnp.result_type(float)
    return RigidBodyParams(jnp.asarray(inertia, dtype), jnp.asarray(dt, dtype))


def _rate_derivative(w: Array, tau: Array, inertia: Array) -> Array:
    return (tau - jnp.cross(w, inertia * w)) / inertia


def rigid_body_transition(w: Array, tau: Array, params: RigidBodyParams) -> Array:
    """One RK4 step of Euler's rotation equations."""
    return rk4(lambda x, t: _rate_derivative(x, tau, params.inertia), w, params.dt)


def rigid_body_observation(w: Array, tau: Array, params: RigidBodyParams) -> Array:
    """Rate gyros: ``y = w``."""
    return w
