"""IMM and static MM filters against filterpy, against each other, and their contracts."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _linear_gaussian_cases import scan_steps
from filterpy.kalman import IMMEstimator, KalmanFilter, MMAEFilterBank

from jaxfdi.filters import (
    interacting_multiple_model,
    kalman_filter,
    multiple_model,
    run_filter,
    unscented_kalman_filter,
)
from jaxfdi.models import LinearGaussianModel, noise_inflation_modes
from jaxfdi.tuning import checkpointed

T = 40
TRANSITION = np.array([[0.90, 0.05, 0.05], [0.10, 0.88, 0.02], [0.05, 0.0, 0.95]])


def small_plant():
    """3 states, 1 input, 2 sensors; D = 0 (filterpy has no feedthrough)."""
    Phi = np.array([[0.9, 0.1, 0.0], [0.0, 0.8, 0.2], [0.1, 0.0, 0.7]])
    Gamma = np.array([[0.5], [0.0], [0.3]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    return LinearGaussianModel(
        Phi, Gamma, C, np.zeros((2, 1)), np.diag([0.05, 0.02, 0.03]), np.diag([0.1, 0.2])
    )


@pytest.fixture(scope="module")
def problem():
    """Modes: normal, actuator (extra input noise), sensor 0 distrusted (inflation 50);
    data with a sensor-0 bias from step 15 so that the probabilities move."""
    plant = small_plant()
    full = noise_inflation_modes(plant, 50.0, 0.8)  # normal, actuator, sensor 0, sensor 1
    modes = jax.tree.map(lambda a: a[:3], full)
    rng = np.random.default_rng(3)
    x = np.zeros(3)
    us = rng.normal(size=(T, 1))
    ys = np.zeros((T, 2))
    for k in range(T):
        ys[k] = (
            plant.C @ x
            + rng.multivariate_normal(np.zeros(2), plant.R)
            + (np.array([2.5, 0]) if k >= 15 else 0)
        )
        x = plant.Phi @ x + plant.Gamma @ us[k] + rng.multivariate_normal(np.zeros(3), plant.Q)
    return modes, ys, us, np.array([0.1, -0.2, 0.3]), np.diag([0.5, 0.4, 0.3])


def filterpy_bank(modes, m0, P0):
    filters = []
    for j in range(3):
        kf = KalmanFilter(dim_x=3, dim_z=2, dim_u=1)
        kf.F, kf.B, kf.H = np.array(modes.Phi[j]), np.array(modes.Gamma[j]), np.array(modes.C[j])
        kf.Q, kf.R = np.array(modes.Q[j]), np.array(modes.R[j])
        kf.x, kf.P = m0.copy(), P0.copy()
        filters.append(kf)
    return filters


def test_imm_equals_filterpy(problem):
    modes, ys, us, m0, P0 = problem
    mu0 = np.array([0.8, 0.1, 0.1])
    ref = IMMEstimator(
        filterpy_bank(modes, m0, P0), mu0, TRANSITION
    )  # first prior: cbar = mu0 @ pi
    ref_mu, ref_x, ref_P, ref_modes = [], [], [], []
    for k in range(T):
        ref.update(ys[k])
        ref_mu.append(ref.mu.copy()), ref_x.append(ref.x.copy()), ref_P.append(ref.P.copy())
        ref_modes.append([f.x.copy() for f in ref.filters])
        ref.predict(us[k])
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    _, info = run_filter(imm, imm.init(m0, P0, mu0 @ TRANSITION), ys, us)
    np.testing.assert_allclose(info.mode_prob, ref_mu, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.mean, ref_x, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.cov, ref_P, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.mode_mean, ref_modes, rtol=1e-8, atol=1e-12)
    assert info.mode_prob[-1, 2] > 0.8 and bool(info.healthy.all())  # the sensor-0 mode won


def test_mm_equals_filterpy(problem):
    modes, ys, us, m0, P0 = problem
    mu0 = np.array([0.6, 0.2, 0.2])
    ref = MMAEFilterBank(filterpy_bank(modes, m0, P0), mu0.copy(), dim_x=3)
    ref_p, ref_x, ref_modes = [], [], []
    for k in range(T):
        ref.update(ys[k])
        (
            ref_p.append(ref.p.copy()),
            ref_x.append(ref.x.copy()),
            ref_modes.append([f.x.copy() for f in ref.filters]),
        )
        ref.predict(us[k])
    mm = multiple_model(kalman_filter, modes, floor=0.0)
    _, info = run_filter(mm, mm.init(m0, P0, mu0), ys, us)
    np.testing.assert_allclose(info.mode_prob, ref_p, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.mean, ref_x, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.mode_mean, ref_modes, rtol=1e-8, atol=1e-12)
    # filterpy's MMAE covariance loop zips over the elements of x (a bug); ours is the
    # moment-matched mixture covariance, checked against the definition instead:
    dev = info.mode_mean - info.mean[:, None, :]
    expect = np.einsum(
        "tj,tjab->tab", info.mode_prob, info.mode_cov + dev[..., :, None] * dev[..., None, :]
    )
    np.testing.assert_allclose(info.cov, expect, rtol=1e-10, atol=1e-14)


def test_one_mode_imm_is_the_kalman_filter(problem):
    modes, ys, us, m0, P0 = problem
    one = jax.tree.map(lambda a: a[:1], modes)
    imm = interacting_multiple_model(kalman_filter, one, np.ones((1, 1)))
    _, info = run_filter(imm, imm.init(m0, P0, np.ones(1)), ys, us)
    kf = kalman_filter(jax.tree.map(lambda a: a[0], modes))
    _, ref = run_filter(kf, kf.init(m0, P0), ys, us)
    np.testing.assert_allclose(info.mean, ref.filtered_mean, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(info.cov, ref.filtered_cov, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(info.log_likelihood, ref.log_likelihood, rtol=1e-12)
    np.testing.assert_allclose(info.mode_prob, 1.0, rtol=1e-15)


def test_identity_transition_imm_is_mm_without_floor(problem):
    modes, ys, us, m0, P0 = problem
    mu0 = np.array([0.5, 0.3, 0.2])
    imm = interacting_multiple_model(kalman_filter, modes, np.eye(3))
    mm = multiple_model(kalman_filter, modes, floor=0.0)
    _, a = run_filter(imm, imm.init(m0, P0, mu0), ys, us)
    _, b = run_filter(mm, mm.init(m0, P0, mu0), ys, us)
    for name in ("mode_prob", "mean", "cov", "mode_mean", "mode_cov", "log_likelihood"):
        np.testing.assert_allclose(
            getattr(a, name), getattr(b, name), rtol=1e-12, atol=1e-14, err_msg=name
        )


def test_imm_with_ukf_modes_equals_imm_with_kf_modes(problem):
    """Any Gaussian filter as the mode filter: a UKF on the linear modes gives the KF's IMM."""
    modes, ys, us, m0, P0 = problem
    f = lambda x, u, p: p.Phi @ x + p.Gamma @ u
    h = lambda x, u, p: p.C @ x + p.D @ u
    ukf_mode = lambda p: unscented_kalman_filter(
        f, h, p.Q, p.R, p, alpha=0.5, sigma_differences="direct"
    )
    mu0 = np.array([0.8, 0.1, 0.1])
    a = interacting_multiple_model(ukf_mode, modes, TRANSITION)
    b = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    _, ia = run_filter(a, a.init(m0, P0, mu0), ys, us)
    _, ib = run_filter(b, b.init(m0, P0, mu0), ys, us)
    np.testing.assert_allclose(ia.mode_prob, ib.mode_prob, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(ia.mean, ib.mean, rtol=1e-8, atol=1e-12)


def test_mm_floor_keeps_modes_alive(problem):
    """Without a floor the sensor-0 mode of a run that starts fault-free underflows and
    the fault is missed for good; the floor lets it come back."""
    modes, ys, us, m0, P0 = problem
    mu0 = np.array([1.0, 0.0, 0.0])
    without = multiple_model(kalman_filter, modes, floor=0.0)
    with_floor = multiple_model(kalman_filter, modes, floor=1e-3)
    _, a = run_filter(without, without.init(m0, P0, mu0), ys, us)
    _, b = run_filter(with_floor, with_floor.init(m0, P0, mu0), ys, us)
    assert np.all(np.asarray(a.mode_prob[:, 2]) == 0.0) and bool(a.healthy.all())
    assert np.all(np.asarray(b.mode_prob) >= 1e-3 * (1 - 1e-12))
    assert np.max(b.mode_prob[15:, 2]) > 0.4  # the bias from step 15 is recognised


def test_extreme_likelihoods_stay_finite(problem):
    """A 1e4-sigma outlier makes every likelihood but one underflow (exp(-5e7)); log space
    keeps the probabilities finite and normalised."""
    modes, ys, us, m0, P0 = problem
    ys = ys.copy()
    ys[20, 0] += 3e3
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    _, info = run_filter(imm, imm.init(m0, P0, np.ones(3) / 3), ys, us)
    assert bool(jnp.all(jnp.isfinite(info.mode_prob)))
    np.testing.assert_allclose(info.mode_prob.sum(-1), 1.0, rtol=1e-12)
    assert info.mode_prob[20, 2] > 0.99


def test_gradient_wrt_transition_logits_and_inflation_matches_finite_differences(problem):
    modes, ys, us, m0, P0 = problem
    plant = small_plant()
    mu0 = np.ones(3) / 3

    @jax.jit  # compiled once for every evaluation chex makes (same shapes)
    def mean_log_likelihood(logits, log_inflation):
        full = noise_inflation_modes(plant, jnp.exp(log_inflation), 0.8)
        modes = jax.tree.map(lambda a: a[:3], full)
        imm = interacting_multiple_model(kalman_filter, modes, jax.nn.softmax(logits, axis=1))
        _, info = run_filter(imm, imm.init(m0, P0, mu0), ys, us)
        return jnp.mean(info.log_likelihood)

    chex.assert_numerical_grads(
        mean_log_likelihood,
        (jnp.log(TRANSITION + 0.02), jnp.log(jnp.array([50.0, 20.0]))),
        order=1,
        atol=1e-6,
        rtol=1e-5,
    )


def test_traces_once_vmap_equals_loop_and_float32(problem):
    modes, ys, us, m0, P0 = problem
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    mu0 = np.ones(3) / 3

    @jax.jit
    @chex.assert_max_traces(n=1)
    def run(ys):
        return run_filter(imm, imm.init(m0, P0, mu0), ys, us)[1].mode_prob

    batch = np.stack([ys, ys[::-1], ys * 0.5])
    for y in batch:
        run(y)
    _, info = run_filter(imm, imm.init(m0, P0, mu0), batch, us)
    loop = np.stack([run(y) for y in batch])
    np.testing.assert_allclose(info.mode_prob, loop, rtol=1e-12, atol=1e-15)

    modes32 = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32), modes)
    imm32 = interacting_multiple_model(kalman_filter, modes32, TRANSITION.astype(np.float32))
    _, info32 = run_filter(
        imm32,
        imm32.init(m0.astype(np.float32), P0.astype(np.float32), mu0.astype(np.float32)),
        ys.astype(np.float32),
        us.astype(np.float32),
    )
    assert info32.mode_prob.dtype == jnp.float32 and info32.mean.dtype == jnp.float32
    np.testing.assert_allclose(info32.mode_prob, loop[0], atol=2e-4)


def test_bad_input(problem):
    modes, ys, us, m0, P0 = problem
    with pytest.raises(ValueError, match="transition"):
        interacting_multiple_model(kalman_filter, modes, np.ones((3, 2)) / 2)
    with pytest.raises(ValueError, match="row-stochastic"):
        interacting_multiple_model(kalman_filter, modes, np.full((3, 3), 0.5))
    with pytest.raises(ValueError, match="mode_params"):
        interacting_multiple_model(kalman_filter, modes, np.eye(4))
    with pytest.raises(ValueError, match="floor"):
        multiple_model(kalman_filter, modes, floor=0.5)
    with pytest.raises(ValueError, match="mode_filter"):
        multiple_model(lambda p: None, modes)
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    with pytest.raises(ValueError, match="mode_prob"):
        imm.init(m0, P0, np.ones(2) / 2)
    with pytest.raises(ValueError, match="mode_prob"):
        imm.init(m0, P0, np.array([0.5, 0.6, 0.1]))
    with pytest.raises(ValueError, match=r"mean"):
        imm.init(np.zeros((2, 3)), P0, np.ones(3) / 3)
    with pytest.raises(ValueError, match=r"y: expected shape \(2,\)"):
        imm.step(imm.init(m0, P0, np.ones(3) / 3), np.zeros(3), us[0])


@pytest.fixture(scope="module")
def batch_problem(problem):
    """Three runs (the data, reversed, halved) with per-run inputs, and the IMM."""
    modes, ys, us, m0, P0 = problem
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    ys_batch = np.stack([ys, ys[::-1], 0.5 * ys])
    us_batch = np.stack([us, -us, us[::-1]])
    return imm, imm.init(m0, P0, np.array([0.8, 0.1, 0.1]) @ TRANSITION), ys_batch, us_batch


def test_batch_kernel_equals_vmap_and_filterpy(problem, batch_problem):
    """run_filter runs the structure-of-arrays kernel (standard-form covariance
    update); every output equals a vmapped plain scan of imm.step (Joseph form) and
    filterpy's IMM."""
    modes, _, _, m0, P0 = problem
    imm, init, ys, us = batch_problem
    assert imm.batch is not None
    final, info = run_filter(imm, init, ys, us)
    ref_final, ref_info = jax.vmap(lambda y, u: scan_steps(imm, init, y, u))(ys, us)
    for name, got, want in zip(
        info._fields + ("final",) * 3, (*info, *final), (*ref_info, *ref_final)
    ):
        assert got.shape == want.shape, name
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12, err_msg=name)
    assert bool(info.healthy.all())
    for run in range(3):
        ref = IMMEstimator(filterpy_bank(modes, m0, P0), np.array([0.8, 0.1, 0.1]), TRANSITION)
        ref_mu, ref_P = [], []
        for k in range(T):
            ref.update(ys[run, k])
            ref_mu.append(ref.mu.copy()), ref_P.append(ref.P.copy())
            ref.predict(us[run, k])
        np.testing.assert_allclose(info.mode_prob[run], ref_mu, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(info.cov[run], ref_P, rtol=1e-8, atol=1e-12)


def test_batch_kernel_shared_inputs_gradient_and_health(problem, batch_problem):
    modes, _, us_shared, m0, P0 = problem
    imm, init, ys, _ = batch_problem
    _, info = run_filter(imm, init, ys, us_shared)  # (T, nu) shared by the runs
    _, ref = jax.vmap(lambda y: scan_steps(imm, init, y, us_shared))(ys)
    np.testing.assert_allclose(info.mode_prob, ref.mode_prob, rtol=1e-9, atol=1e-12)

    bad = ys.copy()
    bad[1, 25, 0] = np.nan  # a dead channel in run 1
    _, info = run_filter(imm, init, bad, us_shared)
    _, ref = jax.vmap(lambda y: scan_steps(imm, init, y, us_shared))(bad)
    np.testing.assert_array_equal(info.healthy, ref.healthy)
    np.testing.assert_array_equal(info.dead, ref.dead)
    np.testing.assert_allclose(info.mode_prob, ref.mode_prob, rtol=1e-9, atol=1e-12)
    assert bool(info.healthy.all()) and np.array_equal(
        np.argwhere(np.asarray(info.dead)), [[1, 25, 0]]
    )
    bad[0, 5, 1] = 1e250  # an overflowing outlier is ill health
    _, info = run_filter(imm, init, bad, us_shared)
    assert (
        not bool(info.healthy[0, 5])
        and bool(info.healthy[0, :5].all())
        and bool(info.healthy[1].all())
    )

    @jax.jit  # compiled once for every evaluation chex makes (same shapes)
    def mean_log_likelihood(logits):
        filt = interacting_multiple_model(kalman_filter, modes, jax.nn.softmax(logits, axis=1))
        return jnp.mean(run_filter(filt, init, ys, us_shared)[1].log_likelihood)

    chex.assert_numerical_grads(
        mean_log_likelihood, (jnp.log(TRANSITION + 0.02),), order=1, atol=1e-6, rtol=1e-5
    )

    def remat_mean_log_likelihood(logits):  # the kernel's step rematerialised: same gradient
        filt = checkpointed(
            interacting_multiple_model(kalman_filter, modes, jax.nn.softmax(logits, axis=1))
        )
        return jnp.mean(run_filter(filt, init, ys, us_shared)[1].log_likelihood)

    logits = jnp.log(TRANSITION + 0.02)
    np.testing.assert_allclose(
        jax.grad(remat_mean_log_likelihood)(logits),
        jax.grad(mean_log_likelihood)(logits),
        rtol=1e-10,
        atol=1e-12,
    )


def test_batch_kernel_only_for_small_kalman_modes(problem):
    modes, *_ = problem
    big = jax.tree.map(lambda a: a, modes)._replace(
        Phi=jnp.broadcast_to(jnp.eye(17) * 0.9, (3, 17, 17)),
        Gamma=jnp.zeros((3, 17, 1)),
        C=jnp.zeros((3, 2, 17)),
        Q=jnp.broadcast_to(jnp.eye(17), (3, 17, 17)),
    )
    assert (
        interacting_multiple_model(kalman_filter, big, TRANSITION).batch is None
    )  # 17 > 16 states
    masked = interacting_multiple_model(
        lambda p: kalman_filter(p, missing_measurements=True), modes, TRANSITION
    )
    assert masked.batch is None  # any other mode filter runs under vmap


def test_batch_kernel_rejects_bad_shapes(batch_problem):
    imm, init, ys, us = batch_problem
    with pytest.raises(ValueError, match=r"y: expected shape \(2,\)"):
        run_filter(imm, init, ys[..., :1], us)
    with pytest.raises(ValueError, match=r"u: expected shape \(1,\)"):
        run_filter(imm, init, ys, np.concatenate([us, us], axis=-1))
