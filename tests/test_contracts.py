"""Contract tests over a registry of every filter: jit == no-jit, the driver traces
once, vmap over a bank / over runs equals the Python loop, float32 in gives float32
out and stays finite, and log-likelihood gradients in Q and R equal finite differences."""
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from _problems import rigid_body_data
from jaxfdi.models import c2d, linear_observation, linear_transition, rigid_body_observation, rigid_body_transition, vtol


class Case(NamedTuple):
    make: object     # (Q, R, params) -> Filter
    Q: np.ndarray
    R: np.ndarray
    params: object
    ys: np.ndarray
    us: np.ndarray
    m0: np.ndarray
    P0: np.ndarray
    # Relative tolerance for comparisons between differently ordered float64 computations
    # (vmap vs loop). The UKF's default alpha = 1e-3 puts weights of size 1/alpha^2 ~ 1e6
    # on sigma-point differences, so reassociated sums differ by ~1e6 * eps ~ 1e-10.
    rtol: float = 1e-12
    # Finite-difference tolerance, relative to sum |dL/dtheta * dtheta|: the UKF's
    # log-likelihood carries ~1e-8 absolute rounding noise (same 1/alpha^2 amplification).
    fd_rtol: float = 1e-7


def _vtol_case():
    Phi, Gamma = c2d(vtol.A, vtol.B, vtol.TS)
    Q, R = 1e-2 * np.eye(4), 1e-1 * np.eye(4)
    model = jaxfdi.LinearGaussianModel(Phi, Gamma, jnp.asarray(vtol.C), jnp.zeros((4, 2)), Q, R)
    T = 40
    us = np.stack([np.sin(0.2 * np.arange(T)), np.cos(0.1 * np.arange(T))], 1)
    _, truth = jaxfdi.simulate(jaxfdi.linear_simulator(model), jnp.array([1.0, 0.5, 0.1, 0.0]), us, jax.random.key(4))
    return model, np.asarray(truth.measurement), us


def _registry():
    model, ys, us = _vtol_case()
    lin = dict(Q=np.asarray(model.Q), R=np.asarray(model.R), params=model, ys=ys, us=us, m0=np.zeros(4), P0=np.eye(4))
    params, Qr, Rr, ysr, usr, m0r, P0r = rigid_body_data(T=40)
    rb = dict(Q=Qr, R=Rr, params=params, ys=ysr, us=usr, m0=m0r, P0=P0r)
    return {
        "kf": Case(lambda Q, R, p: jaxfdi.kalman_filter(p._replace(Q=Q, R=R)), **lin),
        "ekf-linear": Case(lambda Q, R, p: jaxfdi.extended_kalman_filter(linear_transition, linear_observation, Q, R, p), **lin),
        "ukf-linear": Case(lambda Q, R, p: jaxfdi.unscented_kalman_filter(linear_transition, linear_observation, Q, R, p), **lin,
                           rtol=1e-8, fd_rtol=1e-5),
        "ekf-rigid-body": Case(lambda Q, R, p: jaxfdi.extended_kalman_filter(rigid_body_transition, rigid_body_observation, Q, R, p), **rb),
        "ukf-rigid-body": Case(lambda Q, R, p: jaxfdi.unscented_kalman_filter(rigid_body_transition, rigid_body_observation, Q, R, p),
                               **rb, rtol=1e-8, fd_rtol=1e-5),
    }


REGISTRY = _registry()


def total_log_likelihood(case, Q, R, ys):
    filt = case.make(Q, R, case.params)
    _, info = jaxfdi.run_filter(filt, filt.init(jnp.asarray(case.m0), jnp.asarray(case.P0)), ys, jnp.asarray(case.us))
    return jnp.sum(info.log_likelihood)


@pytest.fixture(scope="module", params=sorted(REGISTRY))
def case(request):
    return REGISTRY[request.param]


def run(case, Q, R, ys, us, m0, P0):
    filt = case.make(Q, R, case.params)
    return jaxfdi.run_filter(filt, filt.init(m0, P0), ys, us)[1]


def test_jit_equals_no_jit_and_is_finite(case):
    args = (case.Q, case.R, case.ys, case.us, case.m0, case.P0)
    eager = run(case, *args)
    jitted = jax.jit(lambda *a: run(case, *a))(*args)
    chex.assert_trees_all_close(eager, jitted, rtol=max(case.rtol, 1e-10), atol=case.rtol * _scale(eager))
    chex.assert_tree_all_finite(jitted)
    assert bool(jnp.all(jitted.healthy))
    T, n = case.ys.shape[0], case.m0.shape[0]
    assert jitted.filtered_cov.shape == (T, n, n) and jitted.innovation.shape == case.ys.shape


def _scale(tree):
    return max(float(jnp.max(jnp.abs(leaf))) for leaf in jax.tree_util.tree_leaves(tree)
               if jnp.issubdtype(leaf.dtype, jnp.floating))


def test_driver_traces_once(case):
    chex.clear_trace_counter()  # the counter is keyed on the code location, shared by all cases
    @jax.jit
    @chex.assert_max_traces(n=1)
    def driver(ys, us):
        return run(case, case.Q, case.R, ys, us, case.m0, case.P0).filtered_mean

    driver(case.ys, case.us)
    driver(case.ys + 0.01, case.us * 1.1)
    driver(case.ys * 0.5, case.us)


def test_vmap_over_runs_and_banks_equals_loop(case):
    rng = np.random.default_rng(0)
    ys_batch = case.ys[None] + 0.05 * rng.normal(size=(3,) + case.ys.shape) * np.sqrt(np.diag(case.R))
    R_bank = np.stack([case.R * s for s in (0.5, 1.0, 2.0)])
    batched = jax.vmap(lambda ys, R: run(case, case.Q, R, ys, case.us, case.m0, case.P0))(ys_batch, R_bank)
    run_one = jax.jit(lambda ys, R: run(case, case.Q, R, ys, case.us, case.m0, case.P0))  # one compilation, 3 runs
    for i in range(3):
        single = run_one(ys_batch[i], R_bank[i])
        chex.assert_trees_all_close(jax.tree_util.tree_map(lambda x: x[i], batched), single,
                                    rtol=case.rtol, atol=case.rtol * _scale(single))


def test_float32_in_float32_out_and_finite(case):
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    params32 = jax.tree_util.tree_map(lambda a: f32(a) if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a, case.params)
    filt = case.make(f32(case.Q), f32(case.R), params32)
    _, info = jaxfdi.run_filter(filt, filt.init(f32(case.m0), f32(case.P0)), f32(case.ys), f32(case.us))
    for name, leaf in info._asdict().items():
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert leaf.dtype == jnp.float32, name
    chex.assert_tree_all_finite(info)
    reference = run(case, case.Q, case.R, case.ys, case.us, case.m0, case.P0)
    err = np.max(np.abs(info.filtered_mean - reference.filtered_mean)) / np.max(np.abs(reference.filtered_mean))
    assert err < 1e-3


def test_log_likelihood_gradients_in_Q_and_R_match_finite_differences(case):
    """Reverse- and forward-mode derivatives along random symmetric directions (covariances
    must stay symmetric, so jax.test_util.check_grads' unstructured perturbations do not
    apply) equal fourth-order central differences, and forward equals reverse mode."""
    ys = jnp.asarray(case.ys)
    Q, R = jnp.asarray(case.Q), jnp.asarray(case.R)
    loss = jax.jit(lambda Q, R: total_log_likelihood(case, Q, R, ys))
    grad_Q, grad_R = jax.grad(loss, argnums=(0, 1))(Q, R)
    rng = np.random.default_rng(1)
    for _ in range(3):
        dQ, dR = (_symmetric(rng, Q.shape[0]) * jnp.diag(Q).min(), _symmetric(rng, R.shape[0]) * jnp.diag(R).min())
        eps = 1e-3
        along = lambda t: loss(Q + t * dQ, R + t * dR)  # noqa: E731
        finite_difference = (-along(2 * eps) + 8 * along(eps) - 8 * along(-eps) + along(-2 * eps)) / (12 * eps)
        reverse = jnp.sum(grad_Q * dQ) + jnp.sum(grad_R * dR)
        forward = jax.jvp(loss, (Q, R), (dQ, dR))[1]
        scale = jnp.sum(jnp.abs(grad_Q * dQ)) + jnp.sum(jnp.abs(grad_R * dR))
        np.testing.assert_allclose(reverse, finite_difference, rtol=0, atol=case.fd_rtol * scale)
        np.testing.assert_allclose(forward, reverse, rtol=0, atol=max(case.rtol, 1e-10) * scale)


def _symmetric(rng, n):
    a = rng.normal(size=(n, n))
    return jnp.asarray(0.5 * (a + a.T))
