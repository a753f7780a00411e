"""Mode models for multiple-model fault diagnosis of a linear plant.

A ``LinearGaussianModel`` with ``nu`` actuators and ``m`` sensors becomes ``M = 1 + nu + m`` mode models on
a leading axis (0 normal, then actuators, then sensors: the simulator's labels), same state (IMM mixing
defined); a pytree: a bank is ``vmap(kalman_filter)`` over it, tunable.

* ``noise_inflation_modes`` (Zhang & Li 1998): sensor-j mode ``R_jj`` times ``sensor_inflation[j]``;
  actuator-i mode ``Q + s_i^2 Gamma e_i e_i^T Gamma^T``. A fault shows as a likelihood change; the
  estimate stays fault-free and no size is estimated (as Han et al. 2022 report for their IMM).
* ``bias_modes`` (IMM-GLR, ref. [4] of Han et al. 2022): ``z = [x; b]``, one bias per actuator and sensor;
  in mode j only bias j acts and walks (variance ``bias_walk[j]``); the others are reset to
  ``N(0, bias_prior[i])`` every step (the prior on entering their mode): the matching mode estimates size.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.models._linear import LinearGaussianModel, validate_linear_model


def _per_component(name: str, value, size: int, dtype, positive: bool = False) -> Array:
    """() or (size,) real, finite values, ``>= 0`` (``> 0`` with ``positive``) when concrete, as a (size,) array."""
    checks.check_real(name, value, "real values")
    checks.check_finite(name, value)
    concrete = checks.concrete(value)
    if concrete is not None and (np.any(concrete <= 0) if positive else np.any(concrete < 0)):
        bound = "> 0" if positive else ">= 0"
        raise ValueError(
            f"{name}: expected values {bound} (a variance factor or a standard deviation), got "
            f"{checks.received(concrete)}"
        )
    value = (
        jnp.broadcast_to(jnp.asarray(value, dtype), (size,))
        if np.ndim(value) == 0
        else jnp.asarray(value, dtype)
    )
    checks.check_shape(name, value, (size,), "one value per component, or a scalar")
    return value


def noise_inflation_modes(
    model: LinearGaussianModel, sensor_inflation, actuator_noise
) -> LinearGaussianModel:
    """Zhang & Li mode models: ``M = 1 + nu + m`` models stacked on a leading axis.

    Args:
      model: the fault-free plant model.
      sensor_inflation: () or (m,) factor on ``R[j, j]`` in the sensor-j mode (> 0; an inflation is > 1).
      actuator_noise: () or (nu,) standard deviation ``s_i`` of the extra input noise of
        the actuator-i mode (input units per step).

    Returns:
      A ``LinearGaussianModel`` whose leaves have a leading mode axis M.
    """
    n, nu, m = validate_linear_model(model)
    dtype = jnp.result_type(model.Phi)
    model = jax.tree.map(lambda a: jnp.asarray(a, dtype), model)
    inflation = _per_component("sensor_inflation", sensor_inflation, m, dtype, positive=True)
    noise = _per_component("actuator_noise", actuator_noise, nu, dtype)
    input_noise = jnp.einsum(
        "i,ai,bi->iab", noise**2, model.Gamma, model.Gamma
    )  # s_i^2 Gamma e_i e_i^T Gamma^T
    Qs = jnp.concatenate(
        [model.Q[None], model.Q + input_noise, jnp.broadcast_to(model.Q, (m, n, n))]
    )
    sensor_R = model.R + jax.vmap(
        lambda j: jnp.zeros((m, m), dtype).at[j, j].set((inflation[j] - 1) * model.R[j, j])
    )(jnp.arange(m))
    Rs = jnp.concatenate([jnp.broadcast_to(model.R, (1 + nu, m, m)), sensor_R])
    M = 1 + nu + m
    stack = lambda a: jnp.broadcast_to(a, (M,) + a.shape)
    return LinearGaussianModel(
        stack(model.Phi), stack(model.Gamma), stack(model.C), stack(model.D), Qs, Rs
    )


def bias_modes(model: LinearGaussianModel, bias_walk, bias_prior) -> LinearGaussianModel:
    """Augmented-state fault-bias mode models, ``z = [x (n); b (nu + m)]``.

    Mode 0: no bias, all reset to ``N(0, bias_prior)``; mode ``1 + i``: ``x+ = Phi x + Gamma (u + b_i)``,
    ``y = C x + D (u + b_i)``, ``b_i+ = b_i + N(0, bias_walk[i])``; mode ``1 + nu + j``:
    ``y_j = C_j x + D_j u + b_{nu+j}``.

    Args:
      model: the fault-free plant model.
      bias_walk: () or (nu + m,) random-walk variance per step of the active bias.
      bias_prior: () or (nu + m,) variance of a bias when its mode is entered.

    Returns:
      A ``LinearGaussianModel`` with ``n + nu + m`` states, stacked over M modes.
    """
    n, nu, m = validate_linear_model(model)
    dtype = jnp.result_type(model.Phi)
    model = jax.tree.map(lambda a: jnp.asarray(a, dtype), model)
    nb = nu + m
    walk = _per_component("bias_walk", bias_walk, nb, dtype)
    prior = _per_component("bias_prior", bias_prior, nb, dtype)
    bias_input = jnp.concatenate(
        [jnp.eye(nu, dtype=dtype), jnp.zeros((nu, m), dtype)], axis=1
    )  # b -> input bias
    bias_output = jnp.concatenate(
        [jnp.zeros((m, nu), dtype), jnp.eye(m, dtype=dtype)], axis=1
    )  # b -> sensor bias

    def mode(j):
        active = jax.nn.one_hot(j - 1, nb, dtype=dtype)  # zeros for j = 0
        Phi = jnp.block(
            [
                [model.Phi, model.Gamma @ bias_input * active[None, :]],
                [jnp.zeros((nb, n), dtype), jnp.diag(active)],
            ]
        )
        Gamma = jnp.concatenate([model.Gamma, jnp.zeros((nb, nu), dtype)], axis=0)
        C = jnp.concatenate(
            [model.C, (model.D @ bias_input + bias_output) * active[None, :]], axis=1
        )
        Q = jax.scipy.linalg.block_diag(model.Q, jnp.diag(active * walk + (1 - active) * prior))
        return LinearGaussianModel(Phi, Gamma, C, model.D, Q, model.R)

    return jax.vmap(mode)(jnp.arange(1 + nb))


def bias_mode_initial_state(
    model: LinearGaussianModel, mean: Array, cov: Array, bias_prior
) -> tuple[Array, Array]:
    """Prior ``(mean, cov)`` of the augmented state ``[x; b]`` for ``bias_modes``.

    Returns:
      ``(mean (n + nu + m,), cov (n + nu + m, n + nu + m))`` in ``model.Phi``'s dtype: ``mean`` then zero biases,
      ``block_diag(cov, diag(bias_prior))``.
    """
    n, nu, m = validate_linear_model(model)
    dtype = jnp.result_type(model.Phi)
    prior = _per_component("bias_prior", bias_prior, nu + m, dtype)
    return (
        jnp.concatenate([jnp.asarray(mean, dtype), jnp.zeros(nu + m, dtype)]),
        jax.scipy.linalg.block_diag(jnp.asarray(cov, dtype), jnp.diag(prior)),
    )
