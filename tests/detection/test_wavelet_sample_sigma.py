"""Seed 001's soft-threshold sigma from the details' sample variance (issue 27, item 5):
``sample_detail_sigma`` against NumPy on a hand-rolled Haar decomposition, the causal
per-block sigma, and ``haar_denoise`` with per-block sigma equal to the constant form."""

import numpy as np
import pytest

from jaxfdi.detection import causal_detail_sigma, chi2_detail_sigma, haar_denoise
from jaxfdi.detection._wavelet import sample_detail_sigma


def numpy_details(x, levels):
    """Scale-j details of each block of 2^M samples: (mean of first half - mean of second half) / 2."""
    size = 2**levels
    out = [[] for _ in range(levels)]
    for b in range(x.shape[0] // size):
        block = x[b * size : (b + 1) * size]
        for j in range(1, levels + 1):
            half = 2 ** (j - 1)
            for start in range(0, size, 2**j):
                out[j - 1].append(
                    (
                        block[start : start + half].mean(0)
                        - block[start + half : start + 2 * half].mean(0)
                    )
                    / 2
                )
    return [np.array(d) for d in out]


def test_sample_sigma_equals_numpy_and_estimates_the_chi2_value():
    rng = np.random.default_rng(0)
    x = rng.chisquare(3, size=(4096, 2))
    levels, window = 2, 96
    want = np.stack([d.std(axis=0, ddof=1) for d in numpy_details(x[:window], levels)])
    np.testing.assert_allclose(sample_detail_sigma(x, levels, window), want, rtol=1e-12)
    # on i.i.d. chi2(3) samples a long window recovers chi2_detail_sigma (sd of a sample sd ~ sigma / sqrt(2n))
    long = np.asarray(sample_detail_sigma(x, levels, 4096))
    expected = chi2_detail_sigma(3, levels)[:, None]
    assert np.all(np.abs(long / expected - 1) < 0.08), long / expected


def test_causal_sigma_uses_the_prior_until_the_window_is_complete():
    rng = np.random.default_rng(1)
    x = rng.chisquare(3, size=(40, 3))
    prior = chi2_detail_sigma(3, 2)
    sigma = np.asarray(causal_detail_sigma(x, 2, 16, prior))
    assert sigma.shape == (10, 2, 3)
    np.testing.assert_array_equal(sigma[:4], np.broadcast_to(prior[None, :, None], (4, 2, 3)))
    np.testing.assert_allclose(
        sigma[4:], np.broadcast_to(np.asarray(sample_detail_sigma(x, 2, 16))[None], (6, 2, 3))
    )
    # a constant per-block sigma denoises exactly as the (M, F) form
    np.testing.assert_allclose(
        haar_denoise(x, 2, "soft", np.broadcast_to(sigma[-1], (10, 2, 3))),
        haar_denoise(x, 2, "soft", sigma[-1]),
        rtol=1e-14,
    )
    # and block b only depends on its own sigma
    mixed = np.asarray(haar_denoise(x, 2, "soft", sigma))
    np.testing.assert_allclose(
        mixed[:16], np.asarray(haar_denoise(x, 2, "soft", prior))[:16], rtol=1e-14
    )
    np.testing.assert_allclose(
        mixed[16:], np.asarray(haar_denoise(x, 2, "soft", sigma[-1]))[16:], rtol=1e-14
    )


def test_bad_windows_and_sigma_shapes_are_refused_by_name():
    x = np.ones((16, 2))
    with pytest.raises(ValueError, match="window"):
        sample_detail_sigma(x, 2, 4)  # one block: no sample variance
    with pytest.raises(ValueError, match="window"):
        sample_detail_sigma(x, 2, 32)  # longer than the statistic
    with pytest.raises(ValueError, match="sigma"):
        haar_denoise(x, 2, "soft", np.ones((3, 2, 2)))


def test_causal_sigma_takes_a_per_channel_prior():
    """A prior (M, channels), one sigma per scale and channel (channels of different noise), is what the blocks
    before the window get, channel by channel; a prior of the wrong shape names ``prior_sigma``."""
    rng = np.random.default_rng(2)
    x = rng.chisquare(3, size=(40, 3)) * np.array([1.0, 2.0, 4.0])
    prior = chi2_detail_sigma(3, 2)[:, None] * np.array([1.0, 2.0, 4.0])[None, :]  # (2, 3)
    sigma = np.asarray(causal_detail_sigma(x, 2, 16, prior))
    np.testing.assert_array_equal(sigma[:4], np.broadcast_to(prior[None], (4, 2, 3)))
    np.testing.assert_allclose(
        sigma[4:], np.broadcast_to(np.asarray(sample_detail_sigma(x, 2, 16))[None], (6, 2, 3))
    )
    for bad in (np.ones(3), np.ones((2, 4)), np.ones((2, 3, 1, 1))):
        with pytest.raises(ValueError, match=r"prior_sigma: expected shape \(2,\) or \(2, ...\)"):
            causal_detail_sigma(x, 2, 16, bad)
