"""Dual filter fault detection parameter (Choi & Park 2009, Section II.3, eqs. 7-8).

Two filters share one model: the *prediction filter* runs it on the commanded inputs alone,
``x_PF[k+1] = f(x_PF[k], u[k])``; the *estimation filter* (EKF or UKF) also uses the measurements, so after a fault
the estimate follows the plant and the prediction does not. With ``A = dg/dx`` of the continuous ``x' = g(x, u)``
by ``jax.jacfwd`` (never the paper's printed Jacobians), fault when ``F`` exceeds a threshold calibrated fault-free:

    F[k] = | det A(x_PF[k], u[k]) - det A(x_EKF[k|k], u[k]) |.

Weakness (notebook 05; ``tests/models/test_reaction_wheels_model.py``): for the spacecraft
``A = -I^-1 ([w]x I - [L]x)``, ``L = I w + h_w`` the total body momentum, so ``det A = 0`` whenever ``L = 0`` (or
``w = 0``, or a spherical body). A zero-net-momentum wheel cluster keeps ``L = 0`` whatever the fault (a stop
conserves momentum): ``F`` sees a fault only through the *model's* momentum error with ``x_PF - x_EKF``, a scalar
cubic projection blind where ``grad det A`` is small (stopping the wheel nearest the slew axis leaves ``F``
unchanged for seconds).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters import Filter

#: ``f(x, u, params) -> (n,)``, a model's transition or its state derivative
ModelField = Callable[[Array, Array, Any], Array]


class DualFilterState(NamedTuple):
    """The dual filter's state: the estimation filter's state and the prediction filter's state.

    Attributes:
      estimator: the estimation filter's state (its prior of step k)
      prediction: (n,) the prediction filter's x_PF[k]
    """

    estimator: Any
    prediction: Array


class DualFilterInfo(NamedTuple):
    """Per-step output of the dual filter: estimator info, prediction, both Jacobian determinants and F.

    Attributes:
      estimator: the estimation filter's info of step k (e.g. FilterInfo)
      prediction: (n,) x_PF[k]
      det_prediction: () det A(x_PF[k], u[k])
      det_estimation: () det A(x_EKF[k|k], u[k])
      detection_parameter: () F[k] = |det_prediction - det_estimation|
      healthy: () bool: the estimator healthy, F and x_PF finite
    """

    estimator: Any
    prediction: Array
    det_prediction: Array
    det_estimation: Array
    detection_parameter: Array
    healthy: Array


def system_matrix_det(field: ModelField, x: Array, u: Array, params: Any) -> Array:
    """``det(dg/dx)`` of the continuous model at ``(x, u)`` (eq. 8 of Choi & Park 2009)."""
    return _linalg.det(jax.jacfwd(field)(x, u, params))


def dual_filter(
    estimator: Filter, transition: ModelField, field: ModelField, params: Any = None
) -> Filter:
    """Prediction filter + estimation filter with the fault detection parameter ``F``.

    Args:
      estimator: the estimation filter, a Gaussian ``Filter`` on the same model (``extended_kalman_filter(transition,
        h, Q, R, params)`` or a UKF); its ``info.filtered_mean`` is ``x_EKF[k|k]``.
      transition: the discrete model ``f(x, u, params)`` the prediction filter runs.
      field: the continuous model ``g(x, u, params)`` whose Jacobian is ``A``.
      params: pytree passed to ``transition`` and ``field`` (vmap it for a hypothesis bank).

    Returns:
      ``Filter``: ``init(mean, cov)`` starts both filters at ``mean``;
      ``step(state, y, u) -> (DualFilterState, DualFilterInfo)``.
    """
    if not isinstance(estimator, Filter):
        raise ValueError(
            f"estimator: expected a Filter (e.g. extended_kalman_filter(...)), got {type(estimator).__name__}"
        )

    def init(mean: Array, cov: Array) -> DualFilterState:
        return DualFilterState(estimator.init(mean, cov), jnp.asarray(mean))

    def step(state: DualFilterState, y: Array, u: Array) -> tuple[DualFilterState, DualFilterInfo]:
        n = checks.shape_of(state.prediction)
        for name, fn in (("field(x, u, params)", field), ("transition(x, u, params)", transition)):
            checks.check_shape(
                name, jax.eval_shape(fn, state.prediction, u, params), n, "the state's shape"
            )
        estimator_state, info = estimator.step(state.estimator, y, u)
        det_prediction = system_matrix_det(field, state.prediction, u, params)
        det_estimation = system_matrix_det(field, info.filtered_mean, u, params)
        parameter = jnp.abs(det_prediction - det_estimation)
        next_prediction = transition(state.prediction, u, params)
        healthy = (
            jnp.asarray(getattr(info, "healthy", True))
            & jnp.isfinite(parameter)
            & jnp.all(jnp.isfinite(next_prediction))
        )
        out = DualFilterInfo(
            info, state.prediction, det_prediction, det_estimation, parameter, healthy
        )
        return DualFilterState(estimator_state, next_prediction), out

    return Filter(init, step)
