"""The noncentral chi-square in JAX against scipy.stats.ncx2 over the range RAIM uses
(1-30 degrees of freedom, noncentrality up to 200, P_fa and P_md down to 1e-9)."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize, stats

from jaxfdi.detection import chi2_threshold, noncentrality_for_missed_detection
from jaxfdi.detection._noncentral_chi2 import ncx2_cdf, ncx2_quantile

DOF = np.array([1, 2, 3, 5, 8, 12, 20, 30])[:, None, None]
LAM = np.array([0.0, 0.3, 4.0, 25.0, 60.0, 120.0, 200.0])[None, :, None]


def scipy_cdf(x, dof, lam):
    return np.where(
        lam == 0, stats.chi2.cdf(x, dof), stats.ncx2.cdf(x, dof, np.where(lam == 0, 1.0, lam))
    )


def test_cdf_matches_scipy():
    x = np.array([0.05, 1.0, 7.0, 25.0, 60.0, 140.0, 300.0])[None, None, :]
    ours = np.asarray(ncx2_cdf(x, DOF, LAM))
    ref = scipy_cdf(x, DOF, LAM)
    np.testing.assert_allclose(ours, ref, atol=1e-13)
    tail = ref > 1e-30  # relative accuracy of the lower tail (missed detections)
    np.testing.assert_allclose(ours[tail], ref[tail], rtol=1e-9)


def test_quantile_matches_scipy():
    p = np.array([1e-7, 1e-3, 0.5, 0.999])[:, None, None, None]
    ours = np.asarray(ncx2_quantile(p, DOF, LAM))
    ref = np.where(
        LAM == 0, stats.chi2.ppf(p, DOF), stats.ncx2.ppf(p, DOF, np.where(LAM == 0, 1.0, LAM))
    )
    np.testing.assert_allclose(ours, ref, rtol=1e-7)


@pytest.mark.parametrize("pfa, pmd", [(1.0 / 15000.0, 1e-3), (1e-7, 1e-7), (1e-2, 1e-9)])
def test_noncentrality_for_missed_detection_matches_scipy(pfa, pmd):
    dof = np.arange(1, 31)
    threshold = np.asarray(chi2_threshold(dof, pfa))
    ours = np.asarray(noncentrality_for_missed_detection(threshold, dof, pmd))
    ref = [
        optimize.brentq(
            lambda lam: stats.ncx2.cdf(t, k, lam) - pmd, 1e-9, 1e3, xtol=1e-13, rtol=1e-14
        )
        for t, k in zip(threshold, dof)
    ]
    np.testing.assert_allclose(ours, ref, rtol=1e-10)
    np.testing.assert_allclose(stats.ncx2.cdf(threshold, dof, ours), pmd, rtol=1e-8)


def test_edge_cases_and_bad_input():
    # a threshold below the central distribution's p_md quantile needs no shift at all ((30,)
    # shapes as above: the compiled program is reused)
    lam = noncentrality_for_missed_detection(
        np.full(30, 0.01), np.arange(1.0, 31.0), np.full(30, 0.2)
    )
    assert np.all(np.asarray(lam)[2:] == 0.0) and np.all(np.asarray(lam) >= 0.0)
    assert float(ncx2_cdf(-1.0, 3, 2.0)) == 0.0
    with pytest.raises(ValueError, match="p_md: expected a probability in \\(0, 1\\)"):
        noncentrality_for_missed_detection(10.0, 2, 1.5)
    with pytest.raises(ValueError, match="p: expected a probability"):
        ncx2_quantile(0.0, 2, 1.0)
    single = ncx2_cdf(jnp.float32(5.0), jnp.float32(2.0), jnp.float32(3.0))
    assert single.dtype == jnp.float32 and float(single) == pytest.approx(
        stats.ncx2.cdf(5.0, 2.0, 3.0), rel=1e-5
    )
