"""Nonlinear least squares by Levenberg-Marquardt as one ``lax.while_loop`` (a vmapped batch runs until the last stops).

Minimise ``F(x) = 1/2 ||r(x)||^2``, ``r: R^n -> R^m``; with ``J = dr/dx`` (``jax.jacfwd``), ``A = J^T J``,
``g = J^T r``, each iteration solves, in scaled variables ``x = S z``, ``S = diag(d)^-1/2`` (Marquardt 1963; ``d`` the
running max of ``diag(A)``, as MINPACK, so units of ``x`` do not matter)::

    (S A S + mu I) S^-1 h = -S g

and takes ``x + h`` when ``rho = (F(x) - F(x + h)) / (L(0) - L(h)) > 0``, ``L(0) - L(h) = 1/2 h^T (mu S^-2 h - g)``.
Damping (Nielsen 1999): accepted ``mu *= max(1/3, 1 - (2 rho - 1)^3)``, ``nu = 2``; rejected ``mu *= nu``, ``nu *= 2``
(Madsen, Nielsen & Tingleff 2004, "Methods for non-linear least squares problems", Algorithm 3.16).

Converged: ``max |r| <= residual_tol``, ``max |S g| <= gradient_tol`` or ``||h|| <= step_tol (||x|| + step_tol)``; not
converged: ``max_steps`` or a non-finite damping. A small step also ends at a local minimum with ``r != 0``: equation
solvers (``r = 0``) check ``residual`` themselves (``jaxfdi.models.f16.trim``). Not optimistix, to keep four runtime
dependencies (jax, numpy, optax, chex); the trim problems have 3-6 unknowns (a dense Cholesky suffices).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi._numerics import linalg as _linalg


class LeastSquaresResult(NamedTuple):
    """Levenberg-Marquardt's result: solution, residual, cost, gradient, iterations and flags.

    Attributes:
      x: (n,) the solution
      residual: (m,) r(x)
      cost: () 1/2 ||r(x)||^2
      gradient: (n,) J^T r at x
      steps: () int, iterations taken
      converged: () bool, a tolerance was met before max_steps (module doc)
    """

    x: Array
    residual: Array
    cost: Array
    gradient: Array
    steps: Array
    converged: Array


class _State(NamedTuple):
    """Levenberg-Marquardt's loop carry.

    Attributes:
      x: (n,) the accepted point
      residual: (m,) r(x)
      jacobian: (m, n) J(x)
      cost: () F(x) (inf before the first evaluation)
      scale: (n,) running max of diag(J^T J)
      damping: () mu, the damping of the next step
      nu: () Nielsen's factor for mu after a rejected step
      step: (n,) the step to the candidate x + step, evaluated next
      predicted: () L(0) - L(step)
      steps: () int, iterations taken
      done: () bool, the loop ends
      converged: () bool, a tolerance was met
    """

    x: Array
    residual: Array
    jacobian: Array
    cost: Array
    scale: Array
    damping: Array
    nu: Array
    step: Array
    predicted: Array
    steps: Array
    done: Array
    converged: Array


def levenberg_marquardt(
    residual: Callable[..., Array],
    x0: Array,
    args: tuple = (),
    *,
    max_steps: int = 100,
    residual_tol: float | None = None,
    gradient_tol: float | None = None,
    step_tol: float | None = None,
    initial_damping: float = 1e-3,
) -> LeastSquaresResult:
    """Minimise ``1/2 ||residual(x, *args)||^2`` from ``x0`` (module doc).

    Args:
      residual: ``(x (n,), *args) -> (m,)``, differentiable in ``x`` (forward mode).
      x0: (n,) starting point; its dtype is the dtype of the solve.
      args: extra arguments of ``residual`` (pytrees; vmap over them for a batch).
      max_steps: most iterations (each one evaluates ``residual`` and its Jacobian once).
      residual_tol: stop when ``max |r| <=`` this (default 0: off).
      gradient_tol: stop when the scaled gradient ``max |S J^T r| <=`` this (default 0: off).
      step_tol: relative step tolerance (default ``eps^0.75`` of the dtype: 1.8e-12 in float64, 6.6e-6 in float32).
      initial_damping: ``mu`` of the first iteration, relative to the scaled ``J^T J``.

    Returns:
      ``LeastSquaresResult``.
    """
    x0 = jnp.asarray(x0)
    if x0.ndim != 1 or not jnp.issubdtype(x0.dtype, jnp.floating):
        raise ValueError(
            f"x0: expected a 1-D float array (n,), got shape {tuple(x0.shape)} dtype {x0.dtype}"
        )
    if int(max_steps) < 1:
        raise ValueError(f"max_steps: expected a positive number of iterations, got {max_steps}")
    dtype = x0.dtype
    eps = jnp.finfo(dtype).eps
    tol_r = jnp.asarray(0.0 if residual_tol is None else residual_tol, dtype)
    tol_g = jnp.asarray(0.0 if gradient_tol is None else gradient_tol, dtype)
    tol_x = jnp.asarray(eps**0.75 if step_tol is None else step_tol, dtype)

    def evaluate(x):
        def both(z):
            r = jnp.asarray(residual(z, *args), dtype)
            return r, r

        jacobian, r = jax.jacfwd(both, has_aux=True)(x)
        return r, jacobian

    shape = jax.eval_shape(lambda z: residual(z, *args), x0).shape
    if len(shape) != 1:
        raise ValueError(f"residual: expected a 1-D residual vector (m,), got shape {shape}")
    m, n = shape[0], x0.shape[0]
    eye = jnp.eye(n, dtype=dtype)

    def next_step(x, r, J, scale, damping):
        """The damped Gauss-Newton step from ``x`` in the scaled variables, and ``L(0) - L(h)``."""
        gradient = J.T @ r
        scale = jnp.maximum(scale, jnp.sum(J * J, axis=0))
        scale = jnp.maximum(scale, eps * jnp.max(scale))
        inv_sqrt = 1.0 / jnp.sqrt(scale)
        normal = (J.T @ J) * inv_sqrt[:, None] * inv_sqrt[None, :]
        step = -inv_sqrt * _linalg.psd_solve(normal + damping * eye, inv_sqrt * gradient)
        predicted = 0.5 * step @ (damping * scale * step - gradient)
        small_gradient = jnp.max(jnp.abs(inv_sqrt * gradient)) <= tol_g
        small_step = jnp.linalg.norm(step) <= tol_x * (jnp.linalg.norm(x) + tol_x)
        return step, predicted, scale, small_gradient | small_step

    def body(s: _State) -> _State:
        # evaluate the candidate, then accept or reject it (the first is always accepted)
        candidate = s.x + s.step
        r_new, J_new = evaluate(candidate)
        cost_new = 0.5 * r_new @ r_new
        first = s.steps == 0
        gain = (s.cost - cost_new) / s.predicted
        accept = first | ((gain > 0) & (s.predicted > 0) & jnp.isfinite(cost_new))
        damping = jnp.where(
            first,
            s.damping,
            jnp.where(
                accept,
                s.damping * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3),
                s.damping * s.nu,
            ),
        )
        nu = jnp.where(accept, 2.0, 2.0 * s.nu)
        pick = lambda new, old: jnp.where(accept, new, old)
        x, r, J, cost = (
            pick(candidate, s.x),
            pick(r_new, s.residual),
            pick(J_new, s.jacobian),
            pick(cost_new, s.cost),
        )
        step, predicted, scale, small = next_step(x, r, J, s.scale, damping)
        steps = s.steps + 1
        converged = (jnp.max(jnp.abs(r)) <= tol_r) | small
        done = converged | (steps >= max_steps) | ~jnp.isfinite(damping) | ~jnp.isfinite(cost)
        return _State(x, r, J, cost, scale, damping, nu, step, predicted, steps, done, converged)

    zero = jnp.zeros((), dtype)
    state0 = _State(
        x0,
        jnp.zeros((m,), dtype),
        jnp.zeros((m, n), dtype),
        jnp.asarray(jnp.inf, dtype),
        jnp.zeros((n,), dtype),
        jnp.asarray(initial_damping, dtype),
        jnp.asarray(2.0, dtype),
        jnp.zeros((n,), dtype),
        zero + 1.0,
        jnp.zeros((), jnp.int32),
        jnp.zeros((), bool),
        jnp.zeros((), bool),
    )
    final = jax.lax.while_loop(lambda s: ~s.done, body, state0)
    return LeastSquaresResult(
        final.x,
        final.residual,
        final.cost,
        final.jacobian.T @ final.residual,
        final.steps,
        final.converged,
    )
