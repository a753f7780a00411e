"""Haar MDWT denoiser against PyWavelets and closed forms; the fault signature matrix
against the paper's Table 2."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
import pywt
from scipy import stats

from jaxfdi.detection import _signature as signature
from jaxfdi.detection import _wavelet as wavelet

M = 3


@pytest.fixture(scope="module")
def sequence():
    return np.random.default_rng(0).chisquare(4, size=(64, 3))


def test_perfect_reconstruction(sequence):
    approx, details = wavelet.haar_decompose(sequence, M)
    np.testing.assert_allclose(wavelet.haar_reconstruct(approx, details), sequence, atol=1e-12)
    np.testing.assert_allclose(wavelet.haar_denoise(sequence, M, mode="none"), sequence, atol=1e-12)
    # soft thresholding with a zero threshold is also the identity
    np.testing.assert_allclose(
        wavelet.haar_denoise(sequence, M, "soft", np.zeros(M)), sequence, atol=1e-12
    )


def test_hard_thresholding_is_the_block_mean(sequence):
    denoised = np.asarray(wavelet.haar_denoise(sequence, M, mode="hard"))
    block_means = sequence.reshape(-1, 2**M, 3).mean(axis=1)
    np.testing.assert_allclose(denoised, np.repeat(block_means, 2**M, axis=0), atol=1e-12)


def test_decomposition_matches_pywavelets_up_to_normalisation(sequence):
    approx, details = wavelet.haar_decompose(sequence, M)
    for b, block in enumerate(sequence.reshape(-1, 2**M, 3)):
        for c in range(3):
            cA, *cDs = pywt.wavedec(block[:, c], "haar", level=M)  # [cA_M, cD_M, ..., cD_1]
            np.testing.assert_allclose(approx[b, c], cA[0] / 2 ** (M / 2), rtol=1e-12)
            for j in range(1, M + 1):
                np.testing.assert_allclose(
                    np.asarray(details[j - 1][b, :, c]),
                    cDs[M - j] / 2 ** (j / 2),
                    rtol=1e-12,
                    atol=1e-12,
                )


def test_soft_thresholding_matches_pywavelets(sequence):
    sigma = wavelet.chi2_detail_sigma(4, M)
    approx, details = wavelet.haar_decompose(sequence, M)
    for j, d in enumerate(details):
        ours = np.asarray(wavelet.soft_threshold(d, 2.0 * sigma[j]))
        np.testing.assert_allclose(
            ours, pywt.threshold(np.asarray(d), 2.0 * sigma[j], mode="soft"), atol=1e-14
        )
    # and the denoiser is that thresholding followed by the inverse transform
    shrunk = [wavelet.soft_threshold(d, 2.0 * sigma[j]) for j, d in enumerate(details)]
    np.testing.assert_allclose(
        wavelet.haar_denoise(sequence, M, "soft", sigma),
        wavelet.haar_reconstruct(approx, shrunk),
        atol=1e-12,
    )


def test_chi2_detail_sigma_matches_monte_carlo():
    sample = np.random.default_rng(1).chisquare(4, size=(2**M * 20000,))
    _, details = wavelet.haar_decompose(sample, M)
    expected = wavelet.chi2_detail_sigma(4, M)
    for j, d in enumerate(details):
        d = np.asarray(d).ravel()
        # sample standard deviation of >= 20000 values: its relative standard error is < 1 %, 3 % is > 3 SE
        assert abs(d.std() / expected[j] - 1) < 0.03
        assert abs(stats.ttest_1samp(d, 0.0).statistic) < 4


def test_block_alarms_once_per_block():
    x = np.zeros(16)
    x[9] = 10.0
    alarms = np.asarray(wavelet.block_alarms(jnp.asarray(x), 5.0, 2))
    assert alarms.tolist() == [False] * 11 + [True] + [False] * 4
    hard = wavelet.haar_denoise(jnp.asarray(x), 2, "hard")  # the block mean 2.5 < 5
    assert not np.asarray(wavelet.block_alarms(hard, 5.0, 2)).any()


def test_bad_arguments():
    with pytest.raises(ValueError, match="multiple of 2\\^levels"):
        wavelet.haar_denoise(np.zeros(10), 2, "hard")
    with pytest.raises(ValueError, match="levels"):
        wavelet.haar_denoise(np.zeros(8), 0, "hard")
    with pytest.raises(ValueError, match="sigma"):
        wavelet.haar_denoise(np.zeros(8), 2, "soft")
    with pytest.raises(ValueError, match="mode"):
        wavelet.haar_denoise(np.zeros(8), 2, "median")


def test_signature_matrix_is_the_papers_table_2():
    table = np.array(
        [  # rows: filters a1, a2, s1..s4; columns: no fault, a1, a2, s1..s4
            [0, 0, 1, 1, 1, 1, 1],
            [0, 1, 0, 1, 1, 1, 1],
            [0, 1, 1, 0, 1, 1, 1],
            [0, 1, 1, 1, 0, 1, 1],
            [0, 1, 1, 1, 1, 0, 1],
            [0, 1, 1, 1, 1, 1, 0],
        ],
        bool,
    )
    np.testing.assert_array_equal(signature.signature_matrix(6), table)


def test_isolation_matches_columns():
    matrix = signature.signature_matrix(6)
    # every column is recognised as itself (batched), and a partial pattern is unmatched
    np.testing.assert_array_equal(signature.isolate(matrix.T), np.arange(7))
    partial = np.array([1, 0, 0, 1, 1, 1], bool)
    assert int(signature.isolate(partial)) == signature.UNMATCHED
    with pytest.raises(ValueError, match="matrix"):
        signature.isolate(partial, np.zeros((5, 6), bool))
