"""Levenberg-Marquardt (``jaxfdi._numerics.levenberg_marquardt``, the F-16 trim's solver) against closed forms and
SciPy's MINPACK."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import least_squares

from jaxfdi._numerics.levenberg_marquardt import levenberg_marquardt


def rosenbrock(x):
    return jnp.stack([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


T = np.linspace(0.0, 2.0, 25)
Y = 2.5 * np.exp(-1.3 * T) + 0.05 * np.sin(7.0 * T)  # not an exponential: r != 0 at the optimum


def exponential_fit(x, t, y):
    return x[0] * jnp.exp(x[1] * t) - y


def test_zero_residual_and_vmap_over_starts():
    """Rosenbrock's equations ``r = 0`` from four starts at once (one vmapped solve)."""
    starts = jnp.array([[-1.2, 1.0], [2.0, -1.0], [0.0, 0.0], [-3.0, 5.0]])
    solve = jax.jit(jax.vmap(lambda x0: levenberg_marquardt(rosenbrock, x0, max_steps=200)))
    out = solve(starts)
    np.testing.assert_allclose(out.x, np.ones((4, 2)), atol=1e-10)
    assert bool(jnp.all(out.converged)) and float(jnp.max(jnp.abs(out.residual))) < 1e-10
    assert np.all(np.asarray(out.steps) < 200)


def test_nonzero_residual_matches_minpack():
    """A least-squares fit whose optimum has r != 0: same minimiser as SciPy's MINPACK
    Levenberg-Marquardt, gradient ~ 0 there."""
    out = jax.jit(lambda x0: levenberg_marquardt(exponential_fit, x0, (T, Y)))(
        jnp.array([1.0, 0.0])
    )
    ref = least_squares(
        lambda x: x[0] * np.exp(x[1] * T) - Y,
        [1.0, 0.0],
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    np.testing.assert_allclose(out.x, ref.x, rtol=1e-8)
    np.testing.assert_allclose(out.cost, ref.cost, rtol=1e-10)
    assert (
        bool(out.converged)
        and float(jnp.max(jnp.abs(out.gradient))) < 1e-9 * float(out.cost) + 1e-12
    )


def test_float32_and_bad_input():
    out = levenberg_marquardt(rosenbrock, jnp.array([-1.2, 1.0], jnp.float32), max_steps=200)
    assert out.x.dtype == jnp.float32 and bool(out.converged)
    np.testing.assert_allclose(out.x, [1.0, 1.0], atol=1e-3)
    with pytest.raises(ValueError, match="x0"):
        levenberg_marquardt(rosenbrock, jnp.zeros((2, 2)))
    with pytest.raises(ValueError, match="residual"):
        levenberg_marquardt(lambda x: jnp.outer(x, x), jnp.ones(2))
    with pytest.raises(ValueError, match="max_steps"):
        levenberg_marquardt(rosenbrock, jnp.ones(2), max_steps=0)
