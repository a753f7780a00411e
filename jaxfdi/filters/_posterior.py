"""Start a filter from a posterior: the predict-first convention of filterpy and most textbooks (``x0, P0`` describe
``x[-1]`` given no data; the first step predicts, then updates with ``y[0]``).

jaxfdi's filters carry the *prior* of the current step (``_base.py``), so a posterior ``N(x0, P0)`` of step -1 becomes
the step-0 prior by one time update with ``u[-1]``: ``x[0|-1] = Phi x0 + Gamma u[-1]``, ``P[0|-1] = Phi P0 Phi^T +
Q`` for a KF. For an IMM (per-mode posterior, mode probabilities ``mu0``): mixing and mode-matched predictions
(Bar-Shalom, Li & Kirubarajan 2001, sec. 11.6.6, steps 1 and 4), as filterpy's ``IMMEstimator.predict`` first does.
"""

from __future__ import annotations

import inspect
from typing import Any

import jax.numpy as jnp
from jax import Array

from jaxfdi.filters._base import Filter, GaussianState


def init_from_posterior(
    filt: Filter, mean: Array, cov: Array, u: Array | None = None, mode_prob: Array | None = None
) -> Any:
    """The prior of step 0 from a posterior ``N(mean, cov)`` of step -1.

    Args:
      filt: a Gaussian filter (``kalman_filter``, ``extended_kalman_filter``, ``unscented_kalman_filter``,
        ``unknown_input_filter``: anything with ``predict``), or an ``interacting_multiple_model`` (then
        ``mode_prob`` is required).
      mean: (n,) posterior mean; for an IMM (n,) shared or (M, n) per mode.
      cov: (n, n) posterior covariance; for an IMM (n, n) or (M, n, n).
      u: (nu,) input applied between the posterior and ``y[0]``; ``None`` for a model without inputs.
      mode_prob: (M,) posterior mode probabilities ``mu0`` (IMM only).

    Returns:
      The state to pass to ``run_filter`` with ``ys[0]`` the first measurement.

    Example::

        kf = kalman_filter(model)
        _, info = run_filter(kf, init_from_posterior(kf, x0, P0, u0), ys, us)
    """
    if mode_prob is not None:
        if "posterior" not in inspect.signature(filt.init).parameters:
            raise ValueError(
                "mode_prob: only given for a multiple-model filter that starts from a posterior "
                "(interacting_multiple_model); this filter's init has no posterior option"
            )
        return filt.init(mean, cov, mode_prob, posterior=True, u=u)
    if filt.predict is None:
        raise ValueError(
            "filt: expected a Gaussian filter with predict (kalman_filter, extended_kalman_filter, "
            "unscented_kalman_filter), or an interacting_multiple_model with mode_prob"
        )
    posterior = filt.init(mean, cov)  # validates the shapes and takes the mean's dtype
    if not isinstance(posterior, GaussianState):
        raise ValueError(
            f"filt: expected init(mean, cov) to give a GaussianState, got {type(posterior).__name__}"
        )
    return filt.predict(posterior, posterior_input(u, posterior.mean.dtype))


def posterior_input(u: Array | None, dtype) -> Array:
    """``u`` as an array, or the empty input (0,) of a model without inputs."""
    return jnp.zeros((0,), dtype) if u is None else jnp.asarray(u, dtype)
