"""c2d against scipy.signal.cont2discrete; chi-square thresholds against scipy.stats;
windowed sums and first crossings against brute force."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.signal import cont2discrete
from scipy.stats import chi2

import jaxfdi
from jaxfdi.detection import first_crossing, moving_window_sum
from jaxfdi.detection._chi2 import normalized_innovation_squared
from jaxfdi.models import _engine as engine
from jaxfdi.models import _vtol as vtol
from jaxfdi.models import c2d


@pytest.mark.parametrize(
    "A,B,Ts", [(engine.A, engine.B, engine.TS), (vtol.A, vtol.B, vtol.TS)], ids=["engine", "vtol"]
)
def test_c2d_equals_scipy_zoh(A, B, Ts):
    Phi_ref, Gamma_ref, *_ = cont2discrete(
        (A, B, np.eye(A.shape[0]), np.zeros_like(B)), Ts, method="zoh"
    )
    Phi, Gamma = c2d(A, B, Ts)
    np.testing.assert_allclose(Phi, Phi_ref, rtol=1e-9, atol=1e-12 * np.abs(Phi_ref).max())
    np.testing.assert_allclose(Gamma, Gamma_ref, rtol=1e-9, atol=1e-12 * np.abs(Gamma_ref).max())


def test_engine_discrete_spectral_radius_is_the_papers():
    Phi = jaxfdi.models.engine_model().Phi
    assert abs(np.max(np.abs(np.linalg.eigvals(np.asarray(Phi)))) - 0.9858) < 5e-5


def test_chi2_threshold_reproduces_the_papers_values():
    dofs = np.array([4, 16, 60, 3, 15])
    np.testing.assert_allclose(
        jaxfdi.detection.chi2_threshold(dofs, 0.005), [14.86, 34.27, 91.95, 12.84, 32.80], atol=5e-3
    )


@pytest.mark.parametrize("pfa", [1e-8, 1e-4, 0.005, 0.05, 0.5, 0.95])
def test_chi2_threshold_equals_scipy(pfa):
    dofs = np.array([1, 2, 3, 5, 7, 20, 60, 250, 1000])
    np.testing.assert_allclose(
        jaxfdi.detection.chi2_threshold(dofs, pfa), chi2.isf(pfa, dofs), rtol=1e-6
    )


def test_chi2_threshold_gradient_in_pfa_equals_closed_form():
    """d x / d pfa = -1 / pdf(x) (inverse function rule)."""
    grad = jax.grad(lambda p: jaxfdi.detection.chi2_threshold(5, p))(0.01)
    np.testing.assert_allclose(grad, -1.0 / chi2.pdf(chi2.isf(0.01, 5), 5), rtol=1e-6)


def test_moving_window_sum_and_first_crossing_equal_brute_force():
    rng = np.random.default_rng(0)
    x = rng.chisquare(3, size=(50, 2))
    for window in (1, 3, 7):
        brute = np.stack([x[max(0, k - window + 1) : k + 1].sum(0) for k in range(50)])
        np.testing.assert_allclose(moving_window_sum(x, window), brute, rtol=1e-12)
    threshold, start = 7.0, 10
    brute = [next((k for k in range(start, 50) if x[k, j] > threshold), -1) for j in range(2)]
    np.testing.assert_array_equal(first_crossing(x, threshold, start), brute)
    assert int(first_crossing(x[:, 0], 1e9)) == -1


def test_online_window_detector_equals_offline_window_sum():
    rng = np.random.default_rng(1)
    nis = rng.chisquare(5, size=40)
    det = jaxfdi.detection.chi2_detector(20.0, window=4)
    _, decision = jax.lax.scan(det.step, det.init(), jnp.asarray(nis))
    brute = np.array([nis[max(0, k - 3) : k + 1].sum() for k in range(40)])
    np.testing.assert_allclose(decision.statistic, brute, rtol=1e-12)
    np.testing.assert_array_equal(decision.alarm, brute > 20.0)


def test_nis_equals_explicit_inverse():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(4, 4))
    S = A @ A.T + 4 * np.eye(4)
    r = rng.normal(size=4)
    np.testing.assert_allclose(
        normalized_innovation_squared(r, S), r @ np.linalg.solve(S, r), rtol=1e-12
    )
