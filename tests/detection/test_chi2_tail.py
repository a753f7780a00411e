"""Chi-square thresholds in the far tail (issue 22): finite and equal to SciPy for every
valid pfa, from 1e-1 down to 1e-300 in float64 and down to the dtype's limit,
``np.finfo(float32).tiny``, in float32; below that limit a ``ValueError`` naming ``pfa``
(no NaN threshold, no detector that never alarms).

Reference: ``scipy.stats.chi2.isf`` in float64. Tolerances: 1e-12 relative in float64
(the regularised incomplete gamma's log is evaluated in log space, so the tail loses
nothing); 5e-5 relative in float32 (``log Q`` carries ``~eps32 * lgamma(dof/2)`` absolute
error, largest for large dof).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import chi2

import jaxfdi
from jaxfdi.detection import chi2_detector, chi2_threshold, glrt_threshold

DOFS = np.array([0.5, 1, 2, 3, 5, 20, 60, 250, 1000])
PFAS_64 = np.concatenate([[0.999, 0.5], 10.0 ** -np.arange(1.0, 301.0)])  # 1e-1 .. 1e-300
TINY_32 = np.finfo(np.float32).tiny
PFAS_32 = np.concatenate([[0.99, 0.5], 10.0 ** -np.arange(1.0, 38.0, 0.5), [TINY_32]]).astype(
    np.float32
)


@pytest.fixture(scope="module")
def grid64():
    dof, pfa = np.meshgrid(DOFS, PFAS_64)
    return dof, pfa, np.asarray(chi2_threshold(dof, pfa))


def test_float64_thresholds_equal_scipy_down_to_1e_300(grid64):
    dof, pfa, threshold = grid64
    assert threshold.dtype == np.float64 and np.all(np.isfinite(threshold))
    np.testing.assert_allclose(threshold, chi2.isf(pfa, dof), rtol=1e-12)


def test_the_issue_case_is_finite_and_a_detector_built_on_it_alarms():
    """``chi2_threshold(20, 1e-20)`` was NaN (``ndtri(1 - pfa)`` rounds to ``inf``), so
    ``statistic > threshold`` never held."""
    threshold = chi2_threshold(20, 1e-20)
    np.testing.assert_allclose(threshold, chi2.isf(1e-20, 20), rtol=1e-12)
    detector = chi2_detector(threshold, window=1)
    state, quiet = detector.step(detector.init(), jnp.asarray(10.0))
    _, loud = detector.step(state, jnp.asarray(2.0 * float(threshold)))
    assert not bool(quiet.alarm) and bool(loud.alarm)


def test_float32_thresholds_equal_scipy_down_to_the_smallest_normal():
    dof, pfa = (a.astype(np.float32) for a in np.meshgrid(DOFS, PFAS_32))
    threshold = np.asarray(chi2_threshold(dof, pfa))
    assert threshold.dtype == np.float32 and np.all(np.isfinite(threshold))
    np.testing.assert_allclose(
        threshold, chi2.isf(pfa.astype(np.float64), dof.astype(np.float64)), rtol=5e-5
    )


@pytest.mark.parametrize(
    "call",
    [
        lambda: chi2_threshold(np.float32(4), np.float32(1e-39)),
        lambda: chi2_threshold(4, jnp.asarray([0.01, 1e-40], jnp.float32)),
        lambda: glrt_threshold(np.float32(1e-39), 6, 10),
        lambda: glrt_threshold(
            np.float32(1e-37), 6, 10, "bonferroni"
        ),  # pfa / 60 is below the limit
        lambda: glrt_threshold(1e-307, 6, 10, "bonferroni"),  # float64: 1.7e-309 is subnormal
    ],
    ids=[
        "chi2 float32",
        "chi2 float32 array",
        "glrt paper float32",
        "glrt bonferroni float32",
        "glrt bonferroni float64",
    ],
)
def test_below_the_dtype_limit_is_refused_naming_pfa_and_the_limit(call):
    with pytest.raises(ValueError, match=r"^pfa: .*np\.finfo\(float(32|64)\)\.tiny"):
        call()


def test_glrt_thresholds_in_the_tail_equal_scipy():
    np.testing.assert_allclose(glrt_threshold(1e-300, 6, 10), chi2.isf(1e-300, 60), rtol=1e-12)
    np.testing.assert_allclose(
        glrt_threshold(1e-300, 6, 10, "bonferroni"), chi2.isf(1e-300 / 60, 1), rtol=1e-12
    )


@pytest.mark.parametrize("pfa", [1e-3, 1e-40, 1e-200, 1e-300])
def test_derivatives_in_the_tail(pfa):
    """``dx/dpfa = -1 / pdf(x)`` (inverse function rule, the pdf from SciPy's logpdf, finite
    even where the pdf is 1e-300); ``dx/ddof`` against a central difference of SciPy's
    quantile."""
    dof = 7.0
    x_ref = chi2.isf(pfa, dof)
    grad_pfa, grad_dof = jax.grad(chi2_threshold, argnums=(1, 0))(dof, pfa)
    np.testing.assert_allclose(grad_pfa, -np.exp(-chi2.logpdf(x_ref, dof)), rtol=1e-9)
    step = 1e-4
    central = (chi2.isf(pfa, dof + step) - chi2.isf(pfa, dof - step)) / (2 * step)
    np.testing.assert_allclose(grad_dof, central, rtol=1e-6)


def test_jit_vmap_and_traced_out_of_range_pfa():
    """Under ``jit``/``vmap`` nothing can be raised: the same values as the eager call, and
    NaN (never a finite number) for a pfa the dtype cannot represent."""
    dofs, pfas = jnp.array([1.0, 3.0, 60.0]), jnp.array([1e-5, 1e-150, 1e-310])
    traced = jax.jit(jax.vmap(chi2_threshold))(dofs, pfas)
    np.testing.assert_allclose(
        traced[:2], chi2.isf(np.asarray(pfas[:2]), np.asarray(dofs[:2])), rtol=1e-12
    )
    assert np.isnan(traced[2])


def test_bad_degrees_of_freedom_are_named():
    for dof, error in (
        (np.inf, ValueError),
        (np.nan, ValueError),
        (-1.0, ValueError),
        ("3", TypeError),
    ):
        with pytest.raises(error, match="^dof: "):
            chi2_threshold(dof, 0.01)
    assert jaxfdi.detection.chi2_threshold(np.int64(4), 0.005).dtype == jnp.float64
