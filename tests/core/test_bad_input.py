"""Bad input is refused at trace time with a ValueError naming the argument and shape.

Every array case runs under ``jax.eval_shape``, which only traces: an error raised
there is raised before anything is compiled or executed.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi.detection import chi2_detector, chi2_threshold, moving_window_sum
from jaxfdi.models import c2d, engine_model, linear_observation, linear_transition

MODEL = engine_model()  # n = 7, nu = 1, m = 5
T = 6
YS = jnp.zeros((T, 5))
US = jnp.zeros((T, 1))


def _kf_run(model=MODEL, mean=jnp.zeros(7), cov=jnp.eye(7), ys=YS, us=US):
    def go(ys, us):
        filt = jaxfdi.filters.kalman_filter(model)
        return jaxfdi.filters.run_filter(filt, filt.init(mean, cov), ys, us)[1]

    return jax.eval_shape(go, ys, us)


def _ekf_run(Q=MODEL.Q, R=MODEL.R, ys=YS, us=US):
    def go(ys, us):
        filt = jaxfdi.filters.extended_kalman_filter(
            linear_transition, linear_observation, Q, R, MODEL
        )
        return jaxfdi.filters.run_filter(filt, filt.init(jnp.zeros(7), jnp.eye(7)), ys, us)[1]

    return jax.eval_shape(go, ys, us)


def _ukf(**kw):
    return jaxfdi.filters.unscented_kalman_filter(
        linear_transition, linear_observation, MODEL.Q, MODEL.R, MODEL, **kw
    )


def _asymmetric(n):
    a = np.eye(n)
    a[0, 1] = 0.5
    return jnp.asarray(a)


def _simulate(x0=jnp.zeros(7), us=US):
    return jax.eval_shape(
        lambda us: jaxfdi.simulate(jaxfdi.linear_simulator(MODEL), x0, us, jax.random.key(0)), us
    )


CASES = {
    # name: (thunk, regex the message must match: the argument and the expected shape)
    "Phi not square": (
        lambda: _kf_run(MODEL._replace(Phi=jnp.zeros((7, 6)))),
        r"model\.Phi: expected a square matrix of shape \(n, n\).*got \(7, 6\)",
    ),
    "Gamma wrong rows": (
        lambda: _kf_run(MODEL._replace(Gamma=jnp.zeros((6, 1)))),
        r"model\.Gamma: expected shape \(7, \*\)",
    ),
    "C wrong columns": (
        lambda: _kf_run(MODEL._replace(C=jnp.zeros((5, 6)))),
        r"model\.C: expected shape \(\*, 7\)",
    ),
    "D wrong shape": (
        lambda: _kf_run(MODEL._replace(D=jnp.zeros((5, 2)))),
        r"model\.D: expected shape \(5, 1\)",
    ),
    "Q wrong size": (
        lambda: _kf_run(MODEL._replace(Q=jnp.eye(6))),
        r"model\.Q: expected a square matrix of shape \(7, 7\)",
    ),
    "Q not symmetric": (
        lambda: _kf_run(MODEL._replace(Q=_asymmetric(7))),
        r"model\.Q: covariance of shape \(7, 7\) must be symmetric",
    ),
    "R negative variance": (
        lambda: _kf_run(MODEL._replace(R=-jnp.eye(5))),
        r"model\.R: covariance of shape \(5, 5\) has a negative variance",
    ),
    "R not square (EKF)": (
        lambda: _ekf_run(R=jnp.zeros((5, 4))),
        r"R: expected a square matrix of shape \(n, n\).*got \(5, 4\)",
    ),
    "Q not symmetric (EKF)": (
        lambda: _ekf_run(Q=_asymmetric(7)),
        r"Q: covariance of shape \(7, 7\) must be symmetric",
    ),
    "Q not symmetric (UKF)": (
        lambda: jaxfdi.filters.unscented_kalman_filter(
            linear_transition, linear_observation, _asymmetric(7), MODEL.R, MODEL
        ),
        r"Q: .*must be symmetric",
    ),
    "initial mean shape": (lambda: _kf_run(mean=jnp.zeros(6)), r"mean: expected shape \(7,\)"),
    "initial cov shape": (
        lambda: _kf_run(cov=jnp.eye(6)),
        r"cov: expected a square matrix of shape \(7, 7\)",
    ),
    "ys not 2-D": (
        lambda: _kf_run(ys=jnp.zeros(T)),
        r"ys: expected shape \(T, m\) for one run or \(N, T, m\) for N runs, got \(6,\)",
    ),
    "ys wrong width": (lambda: _kf_run(ys=jnp.zeros((T, 4))), r"y: expected shape \(5,\)"),
    "us wrong width": (lambda: _kf_run(us=jnp.zeros((T, 2))), r"u: expected shape \(1,\)"),
    "ys/us lengths differ": (
        lambda: _kf_run(us=jnp.zeros((T + 1, 1))),
        r"ys and us: expected the same number of time steps T along axis 0, got 6 and 7",
    ),
    "ys/us lengths differ (EKF)": (
        lambda: _ekf_run(us=jnp.zeros((T - 1, 1))),
        r"ys and us: .*got 6 and 5",
    ),
    "UKF alpha": (lambda: _ukf(alpha=0.0), r"alpha: expected a positive scalar"),
    "UKF kappa": (
        lambda: _ukf(alpha=1.0, kappa=-7.0),
        r"kappa: expected alpha\^2 \(n \+ kappa\) > 0",
    ),
    "UKF sigma_differences": (
        lambda: _ukf(sigma_differences="exact"),
        r"sigma_differences: expected",
    ),
    "negative pfa": (lambda: chi2_threshold(5, -0.01), r"pfa: expected a probability in \(0, 1\)"),
    "pfa of one": (lambda: chi2_threshold(5, 1.0), r"pfa: expected a probability in \(0, 1\)"),
    "non-positive dof": (
        lambda: chi2_threshold(0, 0.01),
        r"dof: expected positive degrees of freedom",
    ),
    "detector window": (
        lambda: chi2_detector(10.0, window=0),
        r"window: expected a positive integer",
    ),
    "moving window": (
        lambda: moving_window_sum(jnp.ones(5), 0),
        r"window: expected a positive integer",
    ),
    "c2d A not square": (
        lambda: c2d(jnp.zeros((3, 2)), jnp.zeros((3, 1)), 0.1),
        r"A: expected a square matrix of shape \(n, n\)",
    ),
    "c2d B rows": (
        lambda: c2d(jnp.zeros((3, 3)), jnp.zeros((2, 1)), 0.1),
        r"B: expected shape \(3, \*\)",
    ),
    "c2d Ts": (
        lambda: c2d(jnp.zeros((3, 3)), jnp.zeros((3, 1)), -0.1),
        r"Ts: expected a positive scalar",
    ),
    "simulate us 1-D": (lambda: _simulate(us=jnp.zeros(T)), r"us: expected shape \(T, nu\)"),
    "simulate x0 shape": (lambda: _simulate(x0=jnp.zeros(3)), r"x0: expected shape \(7,\)"),
    "fault kind": (
        lambda: jaxfdi.fault(9, "sensor", 0, 10),
        r"kind: expected one of \['none', 'bias'",
    ),
    "fault target": (
        lambda: jaxfdi.fault("bias", 3, 0, 10),
        r"target: expected one of \['actuator', 'sensor'\]",
    ),
    "monte carlo per_run": (
        lambda: jaxfdi.monte_carlo(lambda k, x: x, jax.random.key(0), 4, jnp.zeros((3, 2))),
        r"per_run: every leaf needs leading axis num_runs = 4, got leading sizes \[3\]",
    ),
    "monte carlo num_runs": (
        lambda: jaxfdi.monte_carlo(lambda k, x: x, jax.random.key(0), 0),
        r"num_runs: expected a positive number of runs",
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_raises_value_error_naming_argument(name):
    thunk, pattern = CASES[name]
    with pytest.raises(ValueError) as excinfo:
        thunk()
    assert re.search(pattern, str(excinfo.value)), (
        f"message {str(excinfo.value)!r} does not match {pattern!r}"
    )


def test_good_input_passes_the_same_checks():
    """The valid counterparts of the cases above trace without error (the checks are not
    over-eager), e.g. a symmetric covariance with round-off-level asymmetry."""
    Q = np.asarray(MODEL.Q) + 1e-20 * np.triu(np.ones((7, 7)), 1)
    info = _kf_run(MODEL._replace(Q=jnp.asarray(Q)))
    assert info.filtered_mean.shape == (T, 7)
    assert _ekf_run().innovation_cov.shape == (T, 5, 5)
    assert _simulate()[1].measurement.shape == (T, 5)
