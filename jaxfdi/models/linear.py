"""Linear Gaussian state-space models as data, and zero-order-hold discretisation.

``x[k+1] = Phi x[k] + Gamma u[k] + w[k]``, ``y[k] = C x[k] + D u[k] + v[k]``,
``w ~ N(0, Q)``, ``v ~ N(0, R)``.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jax import Array

from jaxfdi import _checks


class LinearGaussianModel(NamedTuple):
    """Discrete linear Gaussian model; a pytree, so it can be vmapped over or tuned."""

    Phi: Array    # (n, n) state transition
    Gamma: Array  # (n, nu) input matrix
    C: Array      # (m, n) output matrix
    D: Array      # (m, nu) feed-through
    Q: Array      # (n, n) process-noise covariance
    R: Array      # (m, m) measurement-noise covariance

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(n, nu, m)``: state, input and output sizes."""
        return self.Phi.shape[-1], self.Gamma.shape[-1], self.C.shape[-2]


def validate_linear_model(model: LinearGaussianModel, name: str = "model") -> tuple[int, int, int]:
    """Check every block's shape against ``Phi`` and ``C``; return ``(n, nu, m)``."""
    n = _checks.check_square(f"{name}.Phi", model.Phi, None, "state transition")
    _checks.check_shape(f"{name}.Gamma", model.Gamma, (n, None), "n states x nu inputs")
    nu = _checks.shape_of(model.Gamma)[1]
    _checks.check_shape(f"{name}.C", model.C, (None, n), "m outputs x n states")
    m = _checks.shape_of(model.C)[0]
    _checks.check_shape(f"{name}.D", model.D, (m, nu), "m outputs x nu inputs")
    _checks.check_covariance(f"{name}.Q", model.Q, n)
    _checks.check_covariance(f"{name}.R", model.R, m)
    return n, nu, m


def linear_transition(x: Array, u: Array, model: LinearGaussianModel) -> Array:
    """``Phi x + Gamma u``: a linear model written as a nonlinear ``f(x, u, params)``."""
    return model.Phi @ x + model.Gamma @ u


def linear_observation(x: Array, u: Array, model: LinearGaussianModel) -> Array:
    """``C x + D u``: a linear model written as a nonlinear ``h(x, u, params)``."""
    return model.C @ x + model.D @ u


def c2d(A: Array, B: Array, Ts: float) -> tuple[Array, Array]:
    """Zero-order-hold discretisation by one matrix exponential.

    ``expm([[A, B], [0, 0]] Ts) = [[Phi, Gamma], [0, I]]`` (Van Loan 1978), the same
    result as ``scipy.signal.cont2discrete(..., method="zoh")``.

    Args:
      A: (n, n) continuous state matrix.
      B: (n, nu) continuous input matrix.
      Ts: sample period in seconds (> 0).

    Returns:
      ``(Phi, Gamma)`` of shapes (n, n) and (n, nu).
    """
    n = _checks.check_square("A", A, None, "continuous state matrix")
    _checks.check_shape("B", B, (n, None), "n states x nu inputs")
    ts = _checks.concrete(Ts)
    if ts is not None and not (ts.shape == () and ts > 0):
        raise ValueError(f"Ts: expected a positive scalar sample period, got {Ts}")
    A = jnp.asarray(A)
    return _zoh(A, jnp.asarray(B, dtype=A.dtype), jnp.asarray(Ts, dtype=A.dtype))


@jax.jit
def _zoh(A: Array, B: Array, Ts: Array) -> tuple[Array, Array]:
    """One compiled executable for the whole discretisation (called eagerly, ``expm``
    would otherwise dispatch and compile dozens of small operations one by one)."""
    n, nu = B.shape
    block = jnp.zeros((n + nu, n + nu), A.dtype).at[:n, :n].set(A).at[:n, n:].set(B)
    expm = jsl.expm(block * Ts)
    return expm[:n, :n], expm[:n, n:]
