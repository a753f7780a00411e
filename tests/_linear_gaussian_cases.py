"""Shared cases for the parallel filter, the smoothers and the square-root filters: a
small model, the engine run through the sequential KF once per process, and the whole
state and measurement sequence of a linear Gaussian model as one joint Gaussian (NumPy,
float64), the independent reference on small cases (conditioning by one dense solve)."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.stats
from _problems import engine_data

from jaxfdi.filters import kalman_filter, run_filter
from jaxfdi.models import LinearGaussianModel


def small_model() -> LinearGaussianModel:
    """3 states, 1 input, 2 outputs with feed-through and correlated noises."""
    Phi = np.array([[0.9, 0.1, 0.0], [0.0, 0.8, 0.2], [0.1, 0.0, 0.7]])
    Q = np.array([[0.05, 0.01, 0.0], [0.01, 0.02, 0.0], [0.0, 0.0, 0.03]])
    return LinearGaussianModel(
        Phi,
        np.array([[0.5], [0.0], [0.3]]),
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]),
        np.array([[0.2], [0.0]]),
        Q,
        np.array([[0.1, 0.02], [0.02, 0.2]]),
    )


@functools.lru_cache(maxsize=1)
def engine_filtered(T: int = 64):
    """``(model, ys, us, m0, P0, (final, info))``: a fault-free engine sequence through the
    sequential ``kalman_filter`` (LAPACK factorisations: the same filter, compiled faster)."""
    model, ys, us, m0, P0 = engine_data(T=T)
    kf = kalman_filter(model, unroll_factorizations=False)
    return model, ys, us, jnp.asarray(m0), jnp.asarray(P0), run_filter(kf, kf.init(m0, P0), ys, us)


class JointGaussian(NamedTuple):
    mean_x: np.ndarray  # (T n,)  X = (x_0..x_{T-1})
    cov_x: np.ndarray  # (T n, T n)
    mean_y: np.ndarray  # (T m,)  Y = (y_0..y_{T-1})
    cov_y: np.ndarray  # (T m, T m)
    cross: np.ndarray  # (T n, T m) Cov(X, Y)
    m: int  # outputs per step


def joint_gaussian(model, m0, P0, us, T: int) -> JointGaussian:
    """``x_{k+1} = Phi x_k + Gamma u_k + w``, ``y_k = C x_k + D u_k + v``, ``x_0 ~ N(m0, P0)``."""
    Phi, Gamma, C, D, Q, R = (np.asarray(a, np.float64) for a in model)
    n, m = Phi.shape[0], C.shape[0]
    us = np.asarray(us, np.float64)
    mean_x = np.zeros((T, n))
    mean_x[0] = m0
    for k in range(1, T):
        mean_x[k] = Phi @ mean_x[k - 1] + Gamma @ us[k - 1]
    # X - mean = L W with W = (x_0 - m0, w_0, ..., w_{T-2}), block-diagonal covariance
    L = np.zeros((T * n, T * n))
    for k in range(T):
        for i in range(k + 1):
            L[k * n : (k + 1) * n, i * n : (i + 1) * n] = np.linalg.matrix_power(Phi, k - i)
    cov_x = L @ scipy.linalg.block_diag(np.asarray(P0, np.float64), *([Q] * (T - 1))) @ L.T
    H = np.kron(np.eye(T), C)
    mean_y = H @ mean_x.ravel() + (us[:T] @ D.T).ravel()
    cov_y = H @ cov_x @ H.T + np.kron(np.eye(T), R)
    return JointGaussian(mean_x.ravel(), cov_x, mean_y, cov_y, cov_x @ H.T, m)


def condition(joint: JointGaussian, ys, steps: int | None = None):
    """``(mean (T n,), cov (T n, T n), log p(y_0..y_{steps-1}))`` of X given the first
    ``steps`` measurements (all by default)."""
    ys = np.asarray(ys, np.float64).ravel()
    rows = ys.size if steps is None else steps * joint.m
    Syy = joint.cov_y[:rows, :rows]
    residual = ys[:rows] - joint.mean_y[:rows]
    cross = joint.cross[:, :rows]
    solved = scipy.linalg.solve(
        Syy, np.concatenate([residual[:, None], cross.T], axis=1), assume_a="pos"
    )
    mean = joint.mean_x + cross @ solved[:, 0]
    cov = joint.cov_x - cross @ solved[:, 1:]
    return mean, cov, scipy.stats.multivariate_normal(joint.mean_y[:rows], Syy).logpdf(ys[:rows])


def scan_steps(filt, init_state, ys, us):
    """The reference recursion of any ``Filter``: a plain ``lax.scan`` of ``filt.step``
    over one sequence (``run_filter`` dispatches a ``vmap`` of itself to the batch kernel,
    so a kernel is checked against a vmap of this instead)."""
    return jax.lax.scan(lambda state, yu: filt.step(state, *yu), init_state, (ys, us))
