"""Haar multi-scale DWT denoising of a test statistic, block by block (Lee & Lyou, Table 1; Rao & Bopardikar 1998).

``lambda_k`` is cut into blocks of ``2^M`` samples, each decomposed into its approximation ``c`` (block mean,
scale M) and details ``d(j, l)`` at scales ``j = 1..M`` (``2^(M-j)`` at scale j), with the paper's averaging
normalisation ``d = (mean of first half - mean of second half) / 2`` of each length-``2^j`` sub-block: every sample
is ``c + sum_j +-d(j, l)``. Orthonormal Haar (PyWavelets): ``c = cA / 2^(M/2)``, ``d_j = cD_j / 2^(j/2)``.

Denoising thresholds the details and reconstructs:
* ``"hard"`` (HT, the paper's word): every detail dropped, each sample becomes the block mean;
* ``"soft"`` (ST): ``sign(d) max(|d| - t, 0)``, ``t = c_mult * sigma_j``, ``sigma_j`` the scale-j detail standard
  deviation: ``chi2_detail_sigma`` for a chi-square statistic, or, as Lee and Lyou, the details' sample standard
  deviation (``sample_detail_sigma``, from a fault-free calibration window at the run's start, used from the next
  block on, so causal; ``causal_detail_sigma`` gives the per-block sigma).

A block is complete only at its last sample, so decisions are once per block (``block_alarms``): detection lags the
onset by at most ``2^M`` steps; a block uses only its own samples (causal at block resolution).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks

MODES = ("hard", "soft", "none")


def _check(statistic: Array, levels: int) -> Array:
    levels = checks.check_int(
        "levels", levels, 1, meaning="an integer M >= 1 (blocks of 2^M samples)"
    )
    checks.check_real("statistic", statistic, "a real statistic of shape (T, ...)")
    statistic = jnp.asarray(statistic)
    if statistic.ndim < 1 or statistic.shape[0] % (2**levels):
        raise ValueError(
            f"statistic: expected shape (T, ...) with T a multiple of 2^levels = {2**levels}, got "
            f"{tuple(statistic.shape)}"
        )
    return statistic


def haar_decompose(statistic: Array, levels: int) -> tuple[Array, list[Array]]:
    """Blockwise Haar analysis of ``statistic`` (T, ...), T a multiple of ``2^M``.

    Returns ``(approx, details)``: ``approx`` (B, ...) block means, ``details[j - 1]`` (B, 2^(M-j), ...) in time order.
    """
    x = _check(statistic, levels)
    blocks = x.reshape((x.shape[0] // 2**levels, 2**levels) + x.shape[1:])
    details = []
    means = blocks
    for _ in range(levels):
        first, second = means[:, 0::2], means[:, 1::2]
        details.append(0.5 * (first - second))
        means = 0.5 * (first + second)
    return means[:, 0], details


def haar_reconstruct(approx: Array, details: list[Array]) -> Array:
    """Inverse of ``haar_decompose``: the (T, ...) sequence."""
    means = approx[:, None]
    for detail in reversed(details):
        up = jnp.stack([means + detail, means - detail], axis=2)
        means = up.reshape((up.shape[0], -1) + up.shape[3:])
    return means.reshape((-1,) + means.shape[2:])


def chi2_detail_sigma(dof: int, levels: int) -> np.ndarray:
    """(M,) standard deviation of the scale-j detail of i.i.d. chi2(dof) samples: ``var(lambda) = 2 dof``, a detail
    is half a difference of two means of ``2^(j-1)`` samples, so ``sigma_j = sqrt(2 dof / 2^j)``.

    Returns:
      (M,) NumPy float64 ``sigma_j``, ``j = 1..M``, in the statistic's units (``haar_denoise``'s ``sigma``).
    """
    return np.sqrt(2.0 * dof / 2.0 ** np.arange(1, levels + 1))


def sample_detail_sigma(statistic: Array, levels: int, window: int) -> Array:
    """(M, ...) sample standard deviation (``ddof = 1``, about the sample mean) of each scale's details over the
    blocks within the first ``window`` steps of ``statistic`` (T, ...): Lee and Lyou's sigma, from a fault-free
    calibration window."""
    x = _check(statistic, levels)
    window = checks.check_int(
        "window",
        window,
        2**levels,
        x.shape[0],
        meaning=f"a number of steps in [2^levels = {2**levels}, T = {x.shape[0]}]",
    )
    blocks = window // 2**levels
    if blocks < 2:
        raise ValueError(f"window: expected at least two blocks of {2**levels} steps, got {window}")
    _, details = haar_decompose(x[: blocks * 2**levels], levels)
    return jnp.stack([jnp.std(d.reshape((-1,) + d.shape[2:]), axis=0, ddof=1) for d in details])


def causal_detail_sigma(statistic: Array, levels: int, window: int, prior_sigma: Array) -> Array:
    """(B, M, ...) per-block sigma: ``prior_sigma`` (M,) or (M, ...) (e.g. the chi-square value) for blocks ending
    inside the calibration window, the window's ``sample_detail_sigma`` from the first block after it (a block
    never sets its threshold from its own or later samples).

    Returns:
      (B, M, ...) detail standard deviations, ``B = T / 2^M`` blocks, ``...`` the statistic's trailing shape
      (``haar_denoise``'s per-block ``sigma``).
    """
    x = _check(statistic, levels)
    estimate = sample_detail_sigma(x, levels, window)
    size = 2**levels
    B = x.shape[0] // size
    block_end = (jnp.arange(B) + 1) * size  # a block's decision is made at its last step
    shape = tuple(
        jnp.shape(prior_sigma)
    )  # (M,) or (M, ...): padded on the right, broadcast to the details
    if not (
        0 < len(shape) <= estimate.ndim
        and shape[0] == levels
        and all(a in (1, b) for a, b in zip(shape[1:], estimate.shape[1:]))
    ):
        raise ValueError(
            f"prior_sigma: expected shape ({levels},) or ({levels}, ...) broadcasting to the details' "
            f"{tuple(estimate.shape)}, got {shape}"
        )
    prior = jnp.asarray(prior_sigma, estimate.dtype).reshape(
        shape + (1,) * (estimate.ndim - len(shape))
    )
    prior = jnp.broadcast_to(prior, estimate.shape)
    after = (block_end > (window // size) * size).reshape((B,) + (1,) * estimate.ndim)
    return jnp.where(after, estimate[None], prior[None])


def soft_threshold(x: Array, threshold: Array) -> Array:
    """``sign(x) max(|x| - t, 0)``."""
    return jnp.sign(x) * jnp.maximum(jnp.abs(x) - threshold, 0.0)


def haar_denoise(
    statistic: Array,
    levels: int = 2,
    mode: str = "soft",
    sigma: Array | None = None,
    c_mult: float = 2.0,
) -> Array:
    """Denoise ``statistic`` (T, ...) block by block (blocks of ``2^levels``; module docstring).

    Args:
      statistic: (T,) or (T, channels), T a multiple of ``2^levels``.
      levels: M, the number of scales.
      mode: ``"hard"`` (block mean), ``"soft"`` (details shrunk by ``c_mult * sigma_j``) or ``"none"``
        (reconstruction without thresholding: the input).
      sigma: (M,) or (M, channels) detail standard deviations for ``"soft"``, or (B, M) / (B, M, channels) one set
        per block (``causal_detail_sigma``).
      c_mult: the sigma multiple (paper: 2).

    Returns:
      the denoised statistic, of ``statistic``'s shape (T, ...): each sample is its block mean plus the
      (thresholded) details (``"hard"``: the block mean alone).
    """
    checks.check_choice("mode", mode, MODES)
    checks.check_positive("c_mult", c_mult, "a positive multiple of the detail sigma")
    approx, details = haar_decompose(statistic, levels)
    if mode == "hard":
        details = [jnp.zeros_like(d) for d in details]
    elif mode == "soft":
        if sigma is None:
            raise ValueError(
                "sigma: soft thresholding needs the (M,) detail standard deviations (see chi2_detail_sigma)"
            )
        sigma = jnp.asarray(sigma, approx.dtype)
        B = approx.shape[0]
        per_block = (
            sigma.ndim >= 2
            and sigma.shape[:2] == (B, levels)
            and sigma.shape[2:] in ((), approx.shape[1:])
        )
        if not per_block and (
            sigma.shape[:1] != (levels,) or sigma.shape[1:] not in ((), approx.shape[1:])
        ):
            raise ValueError(
                f"sigma: expected shape ({levels},), ({levels}, *{approx.shape[1:]}) or per block "
                f"({B}, {levels}[, *{approx.shape[1:]}]), got {tuple(sigma.shape)}"
            )
        if per_block:  # (B, M, ...) -> scale j's threshold broadcast over that block's details
            details = [
                soft_threshold(d, c_mult * sigma[:, j][:, None]) for j, d in enumerate(details)
            ]
        else:
            details = [soft_threshold(d, c_mult * sigma[j]) for j, d in enumerate(details)]
    return haar_reconstruct(approx, details)


def block_alarms(denoised: Array, threshold: Array, levels: int) -> Array:
    """Once-per-block decisions, (T, ...) like ``denoised``: at each block's last step ``True`` if any reconstructed
    sample of the block reaches ``threshold`` or is not finite (a dead sensor's statistic, spread over its block by
    the transform, is evidence); ``False`` elsewhere.

    Returns:
      (T, ...) bool, ``denoised``'s shape: the block's alarm at each block's last step, ``False`` at the others.
    """
    x = _check(denoised, levels)
    size = 2**levels
    blocks = x.reshape((x.shape[0] // size, size) + x.shape[1:])
    decision = jnp.any((blocks >= threshold) | ~jnp.isfinite(blocks), axis=1)
    out = jnp.zeros_like(blocks, dtype=bool).at[:, -1].set(decision)
    return out.reshape(x.shape)
