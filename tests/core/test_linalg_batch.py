"""The element-wise small-matrix linear algebra against NumPy/SciPy, and the batch driver
``run_filter`` against the loop over ``run_filter``."""

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from _problems import engine_data, rigid_body_data

import jaxfdi
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._driver import _covariance_sees_data
from jaxfdi.models._rigid_body import rigid_body_observation, rigid_body_transition


def random_spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 5, 8, 11])  # 11 > UNROLL_MAX: the LAPACK path
def test_cholesky_and_solves_equal_scipy(n):
    rng = np.random.default_rng(n)
    A, b, B = random_spd(rng, n), rng.normal(size=n), rng.normal(size=(n, 3))
    L = np.asarray(_linalg.cholesky(jnp.asarray(A)))
    L_ref = np.linalg.cholesky(A)
    np.testing.assert_allclose(L, L_ref, rtol=1e-13, atol=1e-13)
    assert np.all(np.triu(L, 1) == 0)
    np.testing.assert_allclose(
        _linalg.solve_lower(L_ref, b),
        scipy.linalg.solve_triangular(L_ref, b, lower=True),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        _linalg.solve_lower(L_ref, B),
        scipy.linalg.solve_triangular(L_ref, B, lower=True),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        _linalg.solve_lower_transposed(L_ref, B),
        scipy.linalg.solve_triangular(L_ref, B, lower=True, trans="T"),
        rtol=1e-12,
    )
    R = np.ascontiguousarray(L_ref.T)
    np.testing.assert_allclose(
        _linalg.solve_upper(R, b), scipy.linalg.solve_triangular(R, b, lower=False), rtol=1e-12
    )
    np.testing.assert_allclose(
        _linalg.solve_upper(R, B), scipy.linalg.solve_triangular(R, B, lower=False), rtol=1e-12
    )
    np.testing.assert_allclose(_linalg.cho_solve(L_ref, B), np.linalg.solve(A, B), rtol=1e-11)
    np.testing.assert_allclose(_linalg.psd_solve(A, b), np.linalg.solve(A, b), rtol=1e-11)


@pytest.mark.parametrize("n", [1, 2, 7, 11])  # 11 > UNROLL_MAX: LAPACK for the Cholesky stack
def test_stack_forms_equal_numpy(n):
    """``solve_pivoted`` (Gauss-Jordan, partial pivoting), ``stack_cholesky`` and
    ``stack_cho_solve`` on a (4, 3) stack against NumPy; the general matrices have a
    tiny leading pivot, so that only a pivoting elimination is accurate."""
    rng = np.random.default_rng(100 + n)
    M, B = rng.normal(size=(4, 3, n, n)), rng.normal(size=(4, 3, n, 2))
    M[..., 0, 0] = 1e-14
    np.testing.assert_allclose(
        jax.jit(_linalg.solve_pivoted)(M, B), np.linalg.solve(M, B), rtol=1e-9, atol=1e-11
    )
    A = np.stack([[random_spd(rng, n) for _ in range(3)] for _ in range(4)])
    L = np.asarray(jax.jit(_linalg.stack_cholesky)(A))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(
        jax.jit(_linalg.stack_cho_solve)(L, B), np.linalg.solve(A, B), rtol=1e-11, atol=1e-13
    )
    np.testing.assert_allclose(
        jax.jit(_linalg.stack_solve_lower)(L, B),
        np.stack(
            [
                [scipy.linalg.solve_triangular(L[i, j], B[i, j], lower=True) for j in range(3)]
                for i in range(4)
            ]
        ),
        rtol=1e-11,
        atol=1e-13,
    )
    singular = np.zeros((n, n))
    assert not np.all(np.isfinite(np.asarray(_linalg.solve_pivoted(singular, np.ones((n, 1))))))


@pytest.mark.parametrize(
    "shapes",
    [
        ((7, 7), (7, 7)),
        ((7, 5), (5, 7)),
        ((5,), (5, 7)),
        ((7, 5), (5,)),
        ((4,), (4,)),
        ((1, 1), (1, 3)),
        ((13, 5), (5, 13)),
        ((3, 20), (20, 2)),
    ],
)
def test_matmul_equals_numpy_unrolled_or_not(shapes):
    rng = np.random.default_rng(len(shapes[0]) + shapes[0][0])
    a, b = rng.normal(size=shapes[0]), rng.normal(size=shapes[1])
    out = _linalg.matmul(jnp.asarray(a), jnp.asarray(b))
    assert out.shape == (a @ b).shape
    np.testing.assert_allclose(out, a @ b, rtol=1e-13, atol=1e-13)
    batched = jax.vmap(_linalg.matmul)(
        jnp.asarray(np.stack([a, 2 * a])), jnp.asarray(np.stack([b, b]))
    )
    np.testing.assert_allclose(batched[1], 2 * (a @ b), rtol=1e-13, atol=1e-13)


def test_matmul_derivatives_equal_the_closed_form_in_both_modes():
    """The written-out product carries its own tangent rule; reverse mode, forward mode,
    second order and vmapped gradients must equal those of ``a @ b``:
    d/dA sum(W * (A B)) = W B^T, d/dB = A^T W, and the loss is bilinear so the
    Hessian's (A, A) block is zero."""
    rng = np.random.default_rng(3)
    a, b, w = (jnp.asarray(rng.normal(size=s)) for s in ((5, 4), (4, 6), (5, 6)))

    def loss(x, y):
        return jnp.sum(w * _linalg.matmul(x, y))

    ga, gb = jax.grad(loss, argnums=(0, 1))(a, b)
    np.testing.assert_allclose(ga, w @ b.T, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(gb, a.T @ w, rtol=1e-13, atol=1e-13)
    jac = jax.jacfwd(_linalg.matmul)(a, b)  # (5, 6, 5, 4): d(AB)_ij / dA_kl = delta_ik B_lj
    np.testing.assert_allclose(jac, np.einsum("ik,lj->ijkl", np.eye(5), b), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(jax.hessian(loss)(a, b), np.zeros((5, 4, 5, 4)), atol=1e-13)
    cross = jax.jacfwd(jax.grad(loss, argnums=0), argnums=1)(
        a, b
    )  # d(W B^T)_kl / dB_mn = W_kn delta_lm
    np.testing.assert_allclose(
        cross, np.einsum("kn,lm->klmn", w, np.eye(4)), rtol=1e-13, atol=1e-13
    )
    batched = jax.vmap(jax.grad(loss), in_axes=(0, None))(jnp.stack([a, 2 * a]), b)
    np.testing.assert_allclose(batched[1], w @ b.T, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("library", [False, True])
def test_joseph_cov_equals_numpy_for_any_gain(library):
    """Both branches (written out; one block ``M diag(P, R) M^T`` with library calls) equal
    ``(I - K H) P (I - K H)^T + K R K^T`` in NumPy for a gain that is not the optimal one
    (where the standard form ``P - K H P`` differs), and are symmetric positive definite."""
    rng = np.random.default_rng(11)
    P, R, H, K = (
        random_spd(rng, 7),
        random_spd(rng, 5),
        rng.normal(size=(5, 7)),
        rng.normal(size=(7, 5)),
    )
    A = np.eye(7) - K @ H
    expected = A @ P @ A.T + K @ R @ K.T
    with _linalg.library_calls() if library else contextlib.nullcontext():
        out = np.asarray(
            jax.jit(lambda *a: _linalg.joseph_cov(*a))(*map(jnp.asarray, (P, K, H, R)))
        )  # a fresh trace
    np.testing.assert_allclose(out, expected, rtol=1e-12)
    assert np.array_equal(out, out.T) and np.all(np.linalg.eigvalsh(out) > 0)
    assert not np.allclose(expected, P - K @ H @ P)


def test_cholesky_vmapped_and_not_positive_definite_gives_nan():
    rng = np.random.default_rng(0)
    batch = np.stack([random_spd(rng, 5) for _ in range(4)])
    batch[2, 3, 3] = -50.0  # not positive definite
    L = np.asarray(jax.vmap(_linalg.cholesky)(jnp.asarray(batch)))
    for i in (0, 1, 3):
        np.testing.assert_allclose(L[i], np.linalg.cholesky(batch[i]), rtol=1e-13)
    finite = np.asarray(jax.vmap(_linalg.cholesky_is_finite)(jnp.asarray(L)))
    assert finite.tolist() == [True, True, False, True]


@pytest.fixture(scope="module")
def engine_batch():
    model, ys, us, m0, P0 = engine_data(T=60)
    ys_b = np.stack([ys, ys + 3.0, 0.9 * ys])
    return model, ys_b, us, m0, P0


def test_batch_driver_equals_loop_and_shares_the_covariance(engine_batch):
    model, ys_b, us, m0, P0 = engine_batch
    kf = jaxfdi.filters.kalman_filter(model)
    final, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys_b, us)
    assert info.filtered_cov.shape == (60, 7, 7) and final.cov.shape == (7, 7)  # once, no run axis
    assert info.filtered_mean.shape == (3, 60, 7)
    for i in range(3):
        final_i, ref = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys_b[i], us)
        for name in ("filtered_mean", "innovation", "log_likelihood", "nis"):
            np.testing.assert_allclose(
                getattr(info, name)[i], getattr(ref, name), rtol=1e-12, atol=1e-9
            )
        for name in ("filtered_cov", "predicted_cov", "innovation_cov"):
            np.testing.assert_allclose(getattr(info, name), getattr(ref, name), rtol=1e-12)
        np.testing.assert_allclose(final.mean[i], final_i.mean, rtol=1e-12)
    # per-run inputs, and covariances kept per run on request
    _, per_run = jaxfdi.filters.run_filter(
        kf, kf.init(m0, P0), ys_b, np.stack([us] * 3), shared_covariance=False
    )
    assert per_run.filtered_cov.shape == (3, 60, 7, 7)
    np.testing.assert_allclose(per_run.filtered_cov[1], info.filtered_cov, rtol=1e-12)


def test_batch_driver_gradient_with_shared_covariances_equals_the_loops(engine_batch):
    """The shared covariance recursion (traced once, with dot and LAPACK on CPU) differentiates as the loop over
    runs does: d/ds of the summed log-likelihood plus the last covariance, R scaled by s, jitted and not."""
    model, ys_b, us, m0, P0 = engine_batch

    def loss(s, batch):
        kf = jaxfdi.filters.kalman_filter(model._replace(R=model.R * s))
        if batch:
            _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys_b, us)
            return jnp.sum(info.log_likelihood) + jnp.sum(info.filtered_cov[-1])
        runs = [jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)[1] for ys in ys_b]
        return sum(jnp.sum(info.log_likelihood) for info in runs) + jnp.sum(
            runs[0].filtered_cov[-1]
        )

    loop = jax.value_and_grad(loss)(1.3, False)
    for value in (
        jax.value_and_grad(loss)(1.3, True),
        jax.jit(jax.value_and_grad(loss), static_argnums=1)(1.3, True),
    ):
        np.testing.assert_allclose(value, loop, rtol=1e-12)


def test_batch_driver_keeps_data_dependent_covariances_per_run(engine_batch):
    model, ys_b, us, m0, P0 = engine_batch
    kf = jaxfdi.filters.kalman_filter(model, missing_measurements=True)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys_b, us)  # "auto"
    assert info.filtered_cov.shape == (3, 60, 7, 7)
    with pytest.raises(ValueError, match="shared_covariance"):
        jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys_b, us, shared_covariance=True)
    params, Q, R, ys, us_rb, m0_rb, P0_rb = rigid_body_data(T=30)
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params
    )
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0_rb, P0_rb), np.stack([ys, ys]), us_rb)
    _, ref = jaxfdi.filters.run_filter(ukf, ukf.init(m0_rb, P0_rb), ys, us_rb)
    assert info.filtered_cov.shape == (2, 30, 3, 3)
    np.testing.assert_allclose(info.filtered_mean[1], ref.filtered_mean, rtol=1e-9)


def _vmap_batches_covariances(filt, state, y, u, per_run_u):
    """The reference: does ``vmap`` over runs (their mean, ``y`` and maybe ``u``) accept
    the step's covariances as unbatched (``out_axes=None``)?"""
    shared = jaxfdi.filters.FilterInfo(
        *(None if "cov" in name else 0 for name in jaxfdi.filters.FilterInfo._fields)
    )
    step = lambda mean, y, u: filt.step(jaxfdi.filters.GaussianState(mean, state.cov), y, u)
    try:
        jax.vmap(
            step,
            in_axes=(0, 0, 0 if per_run_u else None),
            out_axes=(jaxfdi.filters.GaussianState(0, None), shared),
        )(jnp.stack([state.mean] * 2), jnp.stack([y] * 2), jnp.stack([u] * 2) if per_run_u else u)
    except ValueError:
        return True
    return False


def _engine_ekf(model, **kwargs):
    return jaxfdi.filters.extended_kalman_filter(
        lambda x, u, p: model.Phi @ x + model.Gamma @ u,
        lambda x, u, p: model.C @ x + model.D @ u,
        model.Q,
        model.R,
        **kwargs,
    )


@pytest.mark.parametrize(
    "name, build, per_run_u",
    [
        ("KF", lambda model: jaxfdi.filters.kalman_filter(model), False),
        ("KF, inputs per run", lambda model: jaxfdi.filters.kalman_filter(model), True),
        (
            "KF with missing measurements",
            lambda model: jaxfdi.filters.kalman_filter(model, missing_measurements=True),
            False,
        ),
        (
            "EKF of a linear model",
            _engine_ekf,
            True,
        ),  # constant Jacobians: the covariances are shared
        (
            "EKF with missing measurements",
            lambda model: _engine_ekf(model, missing_measurements=True),
            False,
        ),
        (
            "UKF",
            lambda model: jaxfdi.filters.unscented_kalman_filter(
                lambda x, u, p: model.Phi @ x + model.Gamma @ u,
                lambda x, u, p: model.C @ x + model.D @ u,
                model.Q,
                model.R,
            ),
            False,
        ),
    ],
)
def test_shared_covariance_is_read_from_the_step_as_vmap_batches_it(
    engine_batch, name, build, per_run_u
):
    """``run_filter``'s "auto" reads from the step's jaxpr whether the covariances see the
    data; the reference is ``vmap`` itself, asked to leave them unbatched."""
    model, ys_b, us, m0, P0 = engine_batch
    filt = build(model)
    state = filt.init(m0, P0)
    expected = _vmap_batches_covariances(
        filt, state, jnp.asarray(ys_b[0, 0]), jnp.asarray(us[0]), per_run_u
    )
    assert (
        _covariance_sees_data(filt, state, jnp.asarray(ys_b[0, 0]), jnp.asarray(us[0]), per_run_u)
        == expected
    )
    _, info = jaxfdi.filters.run_filter(filt, state, ys_b, np.stack([us] * 3) if per_run_u else us)
    assert info.filtered_cov.ndim == (4 if expected else 3)


@pytest.mark.parametrize(
    "bad, match",
    [
        (
            dict(ys=np.zeros((2, 3, 60, 5))),
            r"ys: expected shape \(T, m\) for one run or \(N, T, m\) for N runs",
        ),
        (dict(us=np.zeros((2, 60, 1))), r"us: expected 3 runs"),
        (dict(us=np.zeros(60)), r"us: expected shape \(T, nu\)"),
        (dict(shared_covariance="yes"), "shared_covariance"),
    ],
)
def test_batch_driver_bad_input(engine_batch, bad, match):
    model, ys_b, us, m0, P0 = engine_batch
    kf = jaxfdi.filters.kalman_filter(model)
    kwargs = dict(ys=ys_b, us=us) | bad
    with pytest.raises(ValueError, match=match):
        jaxfdi.filters.run_filter(kf, kf.init(m0, P0), **kwargs)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_det_equals_numpy_and_vmaps(n):
    """The written-out determinant (n <= 3; LU past that) against numpy, one matrix and a batch."""
    A = np.random.default_rng(n).normal(size=(6, n, n))
    np.testing.assert_allclose(_linalg.det(jnp.asarray(A[0])), np.linalg.det(A[0]), rtol=1e-13)
    np.testing.assert_allclose(jax.vmap(_linalg.det)(jnp.asarray(A)), np.linalg.det(A), rtol=1e-13)
