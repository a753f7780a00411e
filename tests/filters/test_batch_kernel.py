"""The Kalman filter's structure-of-arrays batch kernel (runs with their own prior or
model): every output equal to vmap(run_filter) and to filterpy, up to 15 states, health
flags, float32, gradients, the Monte Carlo driver's batched mode, and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _linear_gaussian_cases import scan_steps, small_model
from filterpy.kalman import KalmanFilter

import jaxfdi
from jaxfdi.filters import GaussianState, kalman_filter, run_filter
from jaxfdi.models import LinearGaussianModel

N, T = 5, 30


def _vmapped(model, model_axes, mean, cov, ys, us):
    """The reference: vmap of a plain ``lax.scan`` of ``kalman_filter(model_i).step`` with
    the given axes (not ``run_filter``, whose ``vmap`` over runs is the kernel itself)."""
    us_axis = 0 if np.ndim(us) == 3 else None

    def one(mdl, m0, P0, y, u):
        kf = kalman_filter(mdl)
        return scan_steps(kf, kf.init(m0, P0), y, u)

    axes = (
        model_axes,
        0 if np.ndim(mean) == 2 else None,
        0 if np.ndim(cov) == 3 else None,
        0,
        us_axis,
    )
    return jax.jit(jax.vmap(one, in_axes=axes))(model, mean, cov, ys, us)


def _assert_same(got, want, rtol=1e-9):
    final, info = got
    ref_final, ref_info = want
    for name in info._fields:
        a, b = np.asarray(getattr(info, name)), np.asarray(getattr(ref_info, name))
        assert a.shape == b.shape, name
        if a.dtype == bool or a.dtype.kind == "i":
            np.testing.assert_array_equal(a, b, err_msg=name)
        else:
            np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * np.max(np.abs(b)), err_msg=name)
    for a, b in zip(final, ref_final):
        np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * np.max(np.abs(b)))


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    ys, us = rng.normal(size=(N, T, 2)), rng.normal(size=(N, T, 1))
    means = rng.normal(size=(N, 3)) * 0.3
    covs = np.stack([np.diag(rng.uniform(0.1, 2.0, 3)) + 0.05 for _ in range(N)])
    return ys, us, means, covs


def test_per_run_prior_equals_vmap_and_filterpy(data):
    """run_filter with a GaussianState per run takes the kernel; per-run inputs."""
    ys, us, means, covs = data
    model = small_model()
    kf = kalman_filter(model)
    assert kf.batch is not None and kf.batch.per_run_only
    got = run_filter(kf, GaussianState(jnp.asarray(means), jnp.asarray(covs)), ys, us)
    _assert_same(got, _vmapped(model, None, means, covs, ys, us))
    Phi, Gamma, C, D, Q, R = (np.asarray(a) for a in model)
    for run in (0, 3):  # filterpy (Joseph form; no feed-through, so D u is taken off y)
        ref = KalmanFilter(dim_x=3, dim_z=2, dim_u=1)
        ref.F, ref.B, ref.H, ref.Q, ref.R = Phi, Gamma, C, Q, R
        ref.x, ref.P = means[run].copy(), covs[run].copy()
        for k in range(T):
            ref.update(ys[run, k] - D @ us[run, k])
            np.testing.assert_allclose(got[1].filtered_mean[run, k], ref.x, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(got[1].filtered_cov[run, k], ref.P, rtol=1e-9, atol=1e-12)
            ref.predict(u=us[run, k])
    # a shared prior keeps the vmap path: its covariances come back once
    _, shared = run_filter(kf, kf.init(means[0], covs[0]), ys, us)
    assert shared.filtered_cov.shape == (T, 3, 3)


def test_a_model_without_inputs_runs_the_kernel(data):
    """A model with no inputs (``Gamma`` (n, 0), ``us`` (T, 0) or left out): the kernel's ``D u`` and ``Gamma u``
    are empty sums, and every output equals vmap's (it once raised an IndexError inside the kernel)."""
    ys, _, means, covs = data
    model = small_model()
    model = model._replace(Gamma=jnp.zeros((3, 0)), D=jnp.zeros((2, 0)))
    kf = kalman_filter(model)
    prior = GaussianState(jnp.asarray(means), jnp.asarray(covs))
    no_inputs = np.zeros((T, 0))
    _assert_same(run_filter(kf, prior, ys), _vmapped(model, None, means, covs, ys, no_inputs))
    _assert_same(
        run_filter(kf, prior, ys, no_inputs), _vmapped(model, None, means, covs, ys, no_inputs)
    )


def test_per_run_model_equals_vmap(data):
    """run_filter of kalman_filter with Phi, Q and R per run and shared inputs; then Q alone per run,
    a per-run mean with a shared covariance."""
    ys, us, means, covs = data
    model = small_model()
    scale = np.linspace(0.5, 2.0, N)[:, None, None]
    every = model._replace(
        Phi=np.asarray(model.Phi)[None] * (1 - 0.1 * scale),
        Q=np.asarray(model.Q)[None] * scale,
        R=np.asarray(model.R)[None] / scale,
    )
    axes = LinearGaussianModel(0, None, None, None, 0, 0)
    got = run_filter(
        kalman_filter(every), GaussianState(jnp.asarray(means), jnp.asarray(covs)), ys, us[0]
    )
    _assert_same(got, _vmapped(every, axes, means, covs, ys, us[0]))
    only_q = model._replace(Q=np.asarray(model.Q)[None] * scale)
    got = run_filter(
        kalman_filter(only_q), GaussianState(jnp.asarray(means), jnp.asarray(covs[0])), ys, us
    )
    _assert_same(
        got,
        _vmapped(
            only_q, LinearGaussianModel(None, None, None, None, 0, None), means, covs[0], ys, us
        ),
    )


def test_fifteen_states_equal_vmap():
    """A 15-state model (the INS size), Q per run, 3 outputs."""
    rng = np.random.default_rng(1)
    n, m = 15, 3
    Phi = np.linalg.qr(rng.normal(size=(n, n)))[0] * 0.95
    C = rng.normal(size=(m, n))
    model = LinearGaussianModel(
        Phi, np.zeros((n, 1)), C, np.zeros((m, 1)), np.eye(n) * 0.01, np.eye(m) * 0.1
    )
    per_run = model._replace(Q=np.eye(n)[None] * np.linspace(0.005, 0.05, 3)[:, None, None])
    ys = rng.normal(size=(3, 12, m))
    got = run_filter(
        kalman_filter(per_run), GaussianState(jnp.zeros(n), jnp.eye(n)), ys, np.zeros((12, 1))
    )
    _assert_same(
        got,
        _vmapped(
            per_run,
            LinearGaussianModel(None, None, None, None, 0, None),
            np.zeros(n),
            np.eye(n),
            ys,
            np.zeros((12, 1)),
        ),
    )


def test_vmap_of_run_filter_is_the_kernel_and_differentiates_as_the_scan(data, monkeypatch):
    """``jax.vmap(run_filter)`` over runs with their own prior, the path a user writes,
    runs the kernel (once, not per run) and equals a vmapped plain scan; its reverse-mode
    gradient (the scan's) equals the gradient of the loop over runs."""
    from jaxfdi.filters import _driver

    ys, us, means, covs = data
    model = small_model()
    kf = kalman_filter(model)
    calls = []
    kernel = _driver.kernel_scan
    monkeypatch.setattr(_driver, "kernel_scan", lambda *a: (calls.append(1), kernel(*a))[1])
    run = jax.vmap(lambda m0, P0, y, u: run_filter(kf, GaussianState(m0, P0), y, u))
    got = run(jnp.asarray(means), jnp.asarray(covs), ys, us)
    assert len(calls) == 1
    _assert_same(got, _vmapped(model, None, means, covs, ys, us))

    def loss(scale, vmapped):
        one = lambda m0, P0, y, u: run_filter(kf, GaussianState(m0, P0 * scale), y, u)[
            1
        ].log_likelihood.sum()
        if vmapped:
            return jnp.sum(jax.vmap(one)(jnp.asarray(means), jnp.asarray(covs), ys, us))
        return sum(one(means[i], covs[i], ys[i], us[i]) for i in range(N))

    np.testing.assert_allclose(jax.grad(loss)(1.3, True), jax.grad(loss)(1.3, False), rtol=1e-10)


def _primitives(jaxpr) -> set:
    """Every primitive's name in a jaxpr and in the jaxprs it calls."""
    names = set()
    for eqn in jaxpr.eqns:
        names.add(eqn.primitive.name)
        for value in eqn.params.values():
            inner = getattr(value, "jaxpr", value)
            if hasattr(inner, "eqns"):
                names |= _primitives(inner)
    return names


@pytest.mark.parametrize("backend, library", [("cpu", True), ("gpu", False)])
def test_one_sequence_under_jit_uses_lapack_on_cpu_only(data, monkeypatch, backend, library):
    """One sequence under ``jit`` alone: LAPACK factorisations on CPU, the written-out
    algebra on a GPU (where a cuSOLVER call per small matrix is slower); the same numbers
    as a plain scan either way."""
    ys, us, means, covs = data
    kf = kalman_filter(small_model())
    state = kf.init(means[0], covs[0])
    monkeypatch.setattr(jax, "default_backend", lambda: backend)
    run = lambda y: run_filter(kf, state, y, us[0])
    assert ("cholesky" in _primitives(jax.make_jaxpr(run)(ys[0]).jaxpr)) == library
    _assert_same(jax.jit(run)(ys[0]), jax.jit(lambda y: scan_steps(kf, state, y, us[0]))(ys[0]))


def test_health_float32_and_gradient(data):
    ys, us, means, covs = data
    model = small_model()
    bad = ys.copy()
    bad[1, 10, 0] = np.nan
    _, info = run_filter(
        kalman_filter(model), GaussianState(jnp.asarray(means), jnp.asarray(covs)), bad, us
    )
    _, ref = _vmapped(model, None, means, covs, bad, us)
    np.testing.assert_array_equal(
        info.healthy, ref.healthy
    )  # a dead channel: evidence, the same as vmap's
    for name in ("filtered_mean", "filtered_cov", "innovation", "nis", "num_observed"):
        np.testing.assert_allclose(
            getattr(info, name), getattr(ref, name), rtol=1e-9, atol=1e-12, err_msg=name
        )
    assert (
        bool(info.healthy.all())
        and float(info.nis[1, 10]) == np.inf
        and np.isnan(info.innovation[1, 10, 0])
    )
    bad[0, 3, 1] = 1e250  # an overflowing outlier is ill health
    _, info = run_filter(
        kalman_filter(model), GaussianState(jnp.asarray(means), jnp.asarray(covs)), bad, us
    )
    assert (
        not bool(info.healthy[0, 3])
        and bool(info.healthy[0, :3].all())
        and bool(info.healthy[1].all())
    )
    model32 = LinearGaussianModel(*(jnp.asarray(a, jnp.float32) for a in model))
    _, info32 = run_filter(
        kalman_filter(model32),
        GaussianState(jnp.asarray(means, jnp.float32), jnp.asarray(covs, jnp.float32)),
        jnp.asarray(ys, jnp.float32),
        jnp.asarray(us, jnp.float32),
    )
    assert info32.filtered_cov.dtype == jnp.float32 and bool(info32.healthy.all())

    def loss(scale, batched):
        mdl = model._replace(Q=jnp.asarray(model.Q)[None] * scale[:, None, None])
        if batched:
            info = run_filter(
                kalman_filter(mdl), GaussianState(jnp.asarray(means), jnp.asarray(covs)), ys, us
            )[1]
        else:
            info = _vmapped(
                mdl, LinearGaussianModel(None, None, None, None, 0, None), means, covs, ys, us
            )[1]
        return jnp.mean(info.log_likelihood)

    scale = jnp.linspace(0.5, 1.5, N)
    np.testing.assert_allclose(jax.grad(loss)(scale, True), jax.grad(loss)(scale, False), rtol=1e-8)


def test_monte_carlo_batched_runs_the_kernel():
    """monte_carlo(batched=True) hands whole chunks to a batch function: a study whose
    runs differ in Q gives the same log-likelihoods as the vmapped one."""
    model = small_model()
    us = np.zeros((T, 1))

    def data_of(key, q_scale):
        mdl = model._replace(Q=jnp.asarray(model.Q) * q_scale)
        _, truth, _ = jaxfdi.simulate(jaxfdi.linear_simulator(mdl), jnp.zeros(3), us, key)
        return mdl, truth.measurement

    def one(key, q_scale):
        mdl, ys = data_of(key, q_scale)
        kf = kalman_filter(mdl)
        return jnp.sum(run_filter(kf, kf.init(jnp.zeros(3), jnp.eye(3)), ys, us)[1].log_likelihood)

    def batch(keys, q_scales):
        models, ys = jax.vmap(data_of)(keys, q_scales)
        per_run = model._replace(Q=models.Q)
        return jnp.sum(
            run_filter(kalman_filter(per_run), GaussianState(jnp.zeros(3), jnp.eye(3)), ys, us)[
                1
            ].log_likelihood,
            -1,
        )

    scales = np.linspace(0.5, 2.0, 11)
    want = jaxfdi.monte_carlo(one, jax.random.key(4), 11, scales, chunk_size=4)
    got = jaxfdi.monte_carlo(batch, jax.random.key(4), 11, scales, chunk_size=4, batched=True)
    np.testing.assert_allclose(got, want, rtol=1e-10)


def test_bad_input(data):
    ys, us, means, covs = data
    model = small_model()
    with pytest.raises(ValueError, match="model.Q"):
        run_filter(
            kalman_filter(model._replace(Q=np.stack([model.Q] * (N + 1)))),
            GaussianState(jnp.zeros(3), jnp.eye(3)),
            ys,
            us,
        )
    with pytest.raises(ValueError, match="init_state.cov"):
        run_filter(kalman_filter(model), GaussianState(jnp.zeros(3), jnp.asarray(covs[:2])), ys, us)
    with pytest.raises(
        ValueError, match="states"
    ):  # a model per run takes the kernel, up to 16 states
        big = LinearGaussianModel(
            np.eye(17),
            np.zeros((17, 1)),
            np.ones((2, 17)),
            np.zeros((2, 1)),
            np.stack([np.eye(17)] * N),
            np.eye(2),
        )
        kalman_filter(big)
    per_run = model._replace(Q=np.stack([model.Q] * N))
    with pytest.raises(ValueError, match=r"y: expected shape \(2,\)"):
        run_filter(kalman_filter(per_run), GaussianState(jnp.zeros(3), jnp.eye(3)), ys[..., :1], us)
    with pytest.raises(ValueError, match=r"pass ys of shape \(%d, T, m\)" % N):
        run_filter(kalman_filter(per_run), GaussianState(jnp.zeros(3), jnp.eye(3)), ys[0], us[0])
    with pytest.raises(ValueError, match="missing_measurements"):
        kalman_filter(per_run, missing_measurements=True)
    with pytest.raises(ValueError, match="shared_covariance"):
        run_filter(
            kalman_filter(model),
            GaussianState(jnp.zeros(3), jnp.asarray(covs)),
            ys,
            us,
            shared_covariance=True,
        )


def test_imm_kernel_for_ten_states_equals_vmap():
    """The IMM's kernel now takes modes of more than 8 states (materialised
    intermediates): 3 modes of 10 states, every output equal to vmap(run_filter)."""
    rng = np.random.default_rng(2)
    n, m = 10, 2
    Phi = np.linalg.qr(rng.normal(size=(n, n)))[0] * 0.9
    base = LinearGaussianModel(
        Phi,
        rng.normal(size=(n, 1)) * 0.1,
        rng.normal(size=(m, n)),
        np.zeros((m, 1)),
        np.eye(n) * 0.02,
        np.eye(m) * 0.1,
    )
    modes = jax.tree.map(lambda a: jnp.asarray(np.stack([a, a, a])), base)
    modes = modes._replace(
        R=modes.R * np.array([1.0, 30.0, 1.0])[:, None, None],
        Q=modes.Q * np.array([1.0, 1.0, 20.0])[:, None, None],
    )
    transition = np.array([[0.9, 0.05, 0.05], [0.1, 0.85, 0.05], [0.1, 0.05, 0.85]])
    imm = jaxfdi.filters.interacting_multiple_model(kalman_filter, modes, transition)
    assert imm.batch is not None
    init = imm.init(np.zeros(n), np.eye(n), np.ones(3) / 3)
    ys, us = rng.normal(size=(3, 15, m)), rng.normal(size=(15, 1))
    final, info = run_filter(imm, init, ys, us)
    ref_final, ref_info = jax.jit(jax.vmap(lambda y: scan_steps(imm, init, y, us)))(ys)
    for name, got, want in zip(
        info._fields + ("final",) * 3, (*info, *final), (*ref_info, *ref_final)
    ):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("empty", [(0, 6), (3, 0)], ids=["no runs", "no steps"])
@pytest.mark.parametrize("case", ["shared prior", "per-run prior", "imm"])
def test_an_empty_batch_returns_empty_results(case, empty):
    """A batch of zero runs or zero steps returns what a batch of one run returns, with the empty axis: every leaf's
    shape is the one-run leaf's with that axis set to 0 (the batch kernels index their runs, so an empty batch takes
    vmap's path)."""
    model = small_model()
    n, m = model.Phi.shape[0], model.C.shape[0]
    num_runs, steps = empty
    if case == "imm":
        modes = jax.tree.map(lambda *a: jnp.stack(a), model, model._replace(Q=4.0 * model.Q))
        filt = jaxfdi.filters.interacting_multiple_model(
            kalman_filter, modes, jnp.array([[0.9, 0.1], [0.2, 0.8]])
        )
        prior = lambda runs: filt.init(jnp.zeros(n), jnp.eye(n), jnp.array([0.5, 0.5]))
    else:
        filt = kalman_filter(model)
        per_run = case == "per-run prior"
        prior = lambda runs: GaussianState(
            jnp.zeros((runs, n)) if per_run else jnp.zeros(n), jnp.eye(n)
        )

    def run(runs, T):  # every leaf with its run axis (no shared covariances), info (runs, T, ...)
        ys, us = jnp.zeros((runs, T, m)), jnp.zeros((T, model.Gamma.shape[1]))
        return run_filter(filt, prior(runs), ys, us, shared_covariance=False)

    final, info = run(num_runs, steps)
    ref_final, ref_info = run(2, 6)
    assert jax.tree.map(jnp.shape, final) == jax.tree.map(
        lambda leaf: (num_runs,) + leaf.shape[1:], ref_final
    )
    assert jax.tree.map(jnp.shape, info) == jax.tree.map(
        lambda leaf: (num_runs, steps) + leaf.shape[2:], ref_info
    )
