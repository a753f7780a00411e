"""The classical RK4 step, unrolled and with its stages as a loop, against closed forms."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import expm

from jaxfdi.models._integrate import rk4

A = np.array([[-0.3, 1.2, 0.0], [-1.1, -0.2, 0.4], [0.1, 0.0, -0.7]])


def _rk4_polynomial(h: float, substeps: int) -> np.ndarray:
    """RK4 on ``x' = A x`` is ``x+ = (I + hA + (hA)^2/2 + (hA)^3/6 + (hA)^4/24) x`` per substep."""
    z = h / substeps * A
    step = sum(np.linalg.matrix_power(z, k) / math.factorial(k) for k in range(5))
    return np.linalg.matrix_power(step, substeps)


@pytest.mark.parametrize("loop_stages", [False, True])
@pytest.mark.parametrize("substeps", [1, 3])
def test_linear_field_gives_the_taylor_polynomial_of_the_exponential(loop_stages, substeps):
    x0 = np.array([1.0, -2.0, 0.5])
    h = 0.2
    got = jax.jit(lambda x: rk4(lambda x, t: jnp.asarray(A) @ x, x, h, substeps, loop_stages))(x0)
    np.testing.assert_allclose(got, _rk4_polynomial(h, substeps) @ x0, rtol=1e-14)
    # and it is a fourth-order method: the local error against expm is O(h^5)
    assert np.max(np.abs(np.asarray(got) - expm(h * A) @ x0)) < 1e-5 / substeps**4


@pytest.mark.parametrize("loop_stages", [False, True])
def test_time_dependent_field_is_simpsons_rule(loop_stages):
    """``x' = c t^3`` depends on ``t`` alone: RK4 is Simpson's rule, exact for a cubic, so
    the stages' times (0, h/2, h/2, h) are checked: ``x(h) = x0 + c h^4 / 4``."""
    h, c = 0.7, 2.5
    got = rk4(lambda x, t: c * t**3 * jnp.ones_like(x), jnp.array([1.0]), h, 2, loop_stages)
    np.testing.assert_allclose(got, [1.0 + c * h**4 / 4.0], rtol=1e-14)


def test_looped_stages_are_the_unrolled_ones_in_value_and_gradient():
    """A nonlinear field (a pendulum with a time-varying torque): both forms give the same
    step and the same gradient to rounding."""

    def field(x, t):
        return jnp.stack([x[1], -jnp.sin(x[0]) - 0.1 * x[1] + jnp.cos(3.0 * t)])

    def flight(x0, loop_stages):
        return jax.lax.fori_loop(0, 50, lambda _, x: rk4(field, x, 0.05, 1, loop_stages), x0)

    x0 = jnp.array([0.4, -0.1])
    np.testing.assert_allclose(flight(x0, True), flight(x0, False), rtol=1e-13)
    g = [jax.grad(lambda x: jnp.sum(flight(x, s) ** 2))(x0) for s in (True, False)]
    np.testing.assert_allclose(g[0], g[1], rtol=1e-12)


def test_float32_state_stays_float32_with_looped_stages():
    x = rk4(lambda x, t: -x, jnp.ones(2, jnp.float32), 0.1, 1, True)
    assert x.dtype == jnp.float32
