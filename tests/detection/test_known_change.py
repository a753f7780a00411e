"""The known-change GLR / CUSUM bank against independent references: a NumPy double loop
over onsets, Page's CUSUM recursion, the exact Gaussian law of the fault-free statistic
(scipy), and a noise-free engine fault."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxfdi import steady_state_kalman
from jaxfdi.detection import fault_directions, fault_signatures, known_change_detector
from jaxfdi.detection._known_change import known_change_bank, known_change_by_onset
from jaxfdi.models import engine_model

T, N, M, D = 24, 5, 3, 2


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(27)
    A = rng.normal(size=(M, M))
    S = A @ A.T + M * np.eye(M)
    G = rng.normal(size=(N, M, D))
    nu = np.array([1.3, -0.7])
    eps = rng.multivariate_normal(np.zeros(M), S, size=T) + 0.8 * np.concatenate(
        [
            np.zeros((T // 2, M)),
            np.einsum("lmd,d->lm", G[np.minimum(np.arange(T - T // 2), N - 1)], [1.0, 0.0]),
        ]
    )
    return S, G, nu, eps


def _run(det, eps):
    return jax.jit(lambda e: jax.lax.scan(det.step, det.init(), e))(jnp.asarray(eps))


def _brute(S, G, nu, eps, tail, pairwise=False):
    """s_i(k) by a double loop over steps and onsets (signature held at G[N-1] past the
    window); ``pairwise``: s_i minus the best of no fault and the other directions' s_j."""
    Sinv = np.linalg.inv(S)
    out = np.full((len(eps), G.shape[2]), -np.inf)
    for k in range(len(eps)):
        first = 0 if tail else max(0, k - N + 1)
        for theta in range(first, k + 1):
            total = np.zeros(G.shape[2])
            for j in range(theta, k + 1):
                g = G[min(j - theta, N - 1)]
                total += nu * (g.T @ Sinv @ eps[j]) - 0.5 * nu**2 * np.einsum(
                    "md,mn,nd->d", g, Sinv, g
                )
            out[k] = np.maximum(out[k], total)
        if pairwise:
            out[k] = [
                out[k, i] - max([0.0] + [out[k, j] for j in range(len(out[k])) if j != i])
                for i in range(len(out[k]))
            ]
    return out


@pytest.mark.parametrize("tail,isolation", [(False, "max"), (True, "max"), (True, "pairwise")])
def test_statistic_equals_double_loop(case, tail, isolation):
    """Statistic, label and alarm of every step equal the brute force (1e-10)."""
    S, G, nu, eps = case
    det = known_change_bank(G, S, nu, threshold=2.0, tail=tail, isolation=isolation)
    final, decision = _run(det, eps)
    brute = _brute(S, G, nu, eps, tail, isolation == "pairwise")
    np.testing.assert_allclose(decision.statistic, brute.max(axis=1), rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(decision.label, 1 + brute.argmax(axis=1))
    np.testing.assert_array_equal(decision.alarm, brute.max(axis=1) > 2.0)
    np.testing.assert_array_equal(decision.estimate, nu[brute.argmax(axis=1)])
    # the offline form over the last window equals the carried onsets of the last step
    by_onset = known_change_by_onset(eps[-N:], G, S, nu)
    np.testing.assert_allclose(by_onset, final.log_ratio, rtol=1e-10, atol=1e-10)


def test_constant_signature_is_page_cusum(case):
    """G[l] = g for every lag: the positive part of the tail form is Page's recursion
    g_k = max(0, g_{k-1} + llr_k); the windowed form is the max of the last N partial sums."""
    S, G, nu, eps = case
    constant = np.broadcast_to(G[2], G.shape)
    Sinv = np.linalg.inv(S)
    llr = nu * np.einsum("md,mn,kn->kd", G[2], Sinv, eps) - 0.5 * nu**2 * np.einsum(
        "md,mn,nd->d", G[2], Sinv, G[2]
    )
    page = np.zeros_like(llr)
    for k in range(T):
        page[k] = np.maximum(0.0, (page[k - 1] if k else 0.0) + llr[k])
    _, decision = _run(known_change_bank(constant, S, nu, threshold=1.0, tail=True), eps)
    np.testing.assert_allclose(
        np.maximum(decision.statistic, 0.0), page.max(axis=1), rtol=1e-10, atol=1e-12
    )
    partial = np.array(
        [[llr[k - o : k + 1].sum(axis=0) for o in range(min(N, k + 1))] for k in range(T)],
        dtype=object,
    )
    windowed = np.array([np.max(p, axis=0).max() for p in partial])
    _, decision = _run(known_change_bank(constant, S, nu, threshold=1.0), eps)
    np.testing.assert_allclose(decision.statistic, windowed, rtol=1e-10, atol=1e-12)


def test_fault_free_exceedance_matches_gaussian_law():
    """One direction, window 2: at step k >= 1 the two onsets' LLRs are jointly Gaussian
    (means -q/2, covariances from the signatures), so P(s(k) > h) is a bivariate normal
    probability (scipy).
    20,000 independent runs (statistic at their step 2): the exceedance count within the
    exact binomial test's acceptance (p > 1e-4)."""
    rng = np.random.default_rng(5)
    S = np.array([[2.0, 0.3], [0.3, 1.0]])
    G = np.array([[[1.0], [0.5]], [[0.4], [1.2]]])  # (2, 2, 1)
    nu = np.array([0.9])
    Sinv = np.linalg.inv(S)
    q = np.array([G[l, :, 0] @ Sinv @ G[l, :, 0] for l in range(2)]) * nu[0] ** 2
    c = nu[0] ** 2 * G[0, :, 0] @ Sinv @ G[1, :, 0]
    # offset 0: a0 . w_k; offset 1: a0 . w_{k-1} + a1 . w_k (independent steps)
    mean = np.array([-q[0] / 2, -(q[0] + q[1]) / 2])
    cov = np.array([[q[0], c], [c, q[0] + q[1]]])
    h = 0.8
    p_exceed = 1.0 - stats.multivariate_normal(mean, cov).cdf([h, h])
    runs = 20000
    eps = rng.multivariate_normal(np.zeros(2), S, size=(runs, 3))
    det = known_change_bank(G, S, nu, threshold=h)
    statistic = jax.jit(jax.vmap(lambda e: jax.lax.scan(det.step, det.init(), e)[1].statistic))(
        jnp.asarray(eps)
    )
    count = int(np.sum(np.asarray(statistic)[:, 2] > h))
    assert stats.binomtest(count, runs, p_exceed).pvalue > 1e-4, (count / runs, p_exceed)


def test_engine_noise_free_fault_and_transformations():
    """A noise-free known fault's innovations (nu G[k - theta]) give, at the true onset,
    Lambda = nu^2/2 sum_l G[l]^T S^-1 G[l] (the sum of the LLR's drift): the statistic
    and isolation of each direction; vmap over directions; float32 stays float32."""
    model = engine_model()
    steady = steady_state_kalman(model)
    window = 8
    sizes = np.array([0.0005, 135.0, 16.99, 2.21, 8.285, 5.125])
    G = np.asarray(fault_signatures(model, steady.gain, fault_directions(model), window))
    S = np.asarray(steady.innovation_cov)
    det = known_change_detector(
        model, steady.gain, steady.innovation_cov, sizes, window, threshold=10.0
    )
    onset = 3
    eps = np.zeros((6, window + onset, 5))
    for i in range(6):
        eps[i, onset:] = sizes[i] * G[:window, :, i]
    final, decision = jax.jit(jax.vmap(lambda e: jax.lax.scan(det.step, det.init(), e)))(
        jnp.asarray(eps)
    )
    Sinv = np.linalg.inv(S)
    expected = np.array(
        [
            0.5 * sizes[i] ** 2 * sum(G[l, :, i] @ Sinv @ G[l, :, i] for l in range(window))
            for i in range(6)
        ]
    )
    own = np.asarray(final.log_ratio)[
        np.arange(6), window - 1, np.arange(6)
    ]  # onset offset N-1 = true onset
    np.testing.assert_allclose(own, expected, rtol=1e-9)
    np.testing.assert_array_equal(np.asarray(decision.label)[:, -1], np.arange(1, 7))
    det32 = known_change_bank(
        G.astype(np.float32), S.astype(np.float32), sizes.astype(np.float32), 10.0
    )
    _, d32 = jax.lax.scan(det32.step, det32.init(), jnp.asarray(eps[1], jnp.float32))
    assert d32.statistic.dtype == jnp.float32 and np.all(np.isfinite(np.asarray(d32.statistic)))


def test_bad_input_names_the_argument(case):
    S, G, nu, _ = case
    model = engine_model()
    steady = steady_state_kalman(model)
    sizes = np.ones(6)
    with pytest.raises(ValueError, match="window"):
        known_change_detector(model, steady.gain, steady.innovation_cov, sizes, 0, 1.0)
    with pytest.raises(ValueError, match="signatures"):
        known_change_bank(G[0], S, nu, 1.0)
    with pytest.raises(ValueError, match="signatures"):
        known_change_bank(G[:0], S, nu, 1.0)
    with pytest.raises(ValueError, match="magnitudes"):
        known_change_bank(G, S, np.ones(3), 1.0)
    with pytest.raises(ValueError, match="magnitudes"):
        known_change_bank(G, S, np.array([1.0, 0.0]), 1.0)
    with pytest.raises(ValueError, match="innovation_cov"):
        known_change_bank(G, np.eye(2), nu, 1.0)
    with pytest.raises(ValueError, match="threshold"):
        known_change_bank(G, S, nu, 0.0)
    with pytest.raises(ValueError, match="gain"):
        known_change_detector(model, 2 * steady.gain, steady.innovation_cov, sizes, 5, 1.0)
    with pytest.raises(ValueError, match="isolation"):
        known_change_bank(G, S, nu, 1.0, isolation="first")
    det = known_change_bank(G, S, nu, 1.0)
    with pytest.raises(ValueError, match="innovation"):
        det.step(det.init(), jnp.zeros(M + 1))
