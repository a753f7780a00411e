"""Known-change GLR / CUSUM bank: the step fault's signature *and size* are known, only the onset is not.

A step of known size ``nu_i`` in direction ``i`` from onset ``theta`` adds ``nu_i G_i[j - theta]`` to the
innovations ``eps_j ~ N(0, S)`` of a fault-blind steady-state Kalman filter (``G_i[l]``: ``fault_signatures``, 0 for
``l < 0``). Log-likelihood ratio of "onset ``theta``" vs "no fault" up to step ``k`` (Basseville & Nikiforov 1993,
sec. 2.2, 7.2; Willsky & Jones 1976 with ``nu`` known)::

    Lambda_i(k, theta) = sum_{j=theta..k} llr_i(j, j - theta),
    llr_i(j, l) = nu_i G_i[l]^T S^-1 eps_j - nu_i^2 / 2  G_i[l]^T S^-1 G_i[l]

Windowed statistic over ``N`` onsets the data allow (step 0 first)::

    s_i(k) = max { Lambda_i(k, theta) : k - N + 1 <= theta <= k, theta >= 0 }

carried recursively with offset ``o = k - theta``: ``L_i(k, o) = L_i(k-1, o-1) + llr_i(k, o)``,
``L_i(k, 0) = llr_i(k, 0)``, O(N m d) a step; the onset leaving the window is dropped.

``tail=True`` also keeps every older onset (unwindowed GLR, Lorden 1971), holding the signature at its last lag
(``G_i[l] = G_i[N - 1]`` for ``l >= N - 1``; exact once converged, ``Phi (I - K C)`` being stable)::

    M_i(k) = max(M_i(k-1), L_i(k-1, N-1)) + llr_i(k, N-1),   M_i = -inf until N steps,
    s_i(k) = max(max_o L_i(k, o), M_i(k)).

For a constant signature this is ``max_{theta <= k} sum_{j>=theta} llr_i(j)``, whose positive part is Page's
(1954) CUSUM ``g_k = max(0, g_{k-1} + llr_k)`` (same alarms for ``h > 0``); the CUSUM minimises Lorden's worst-case
mean delay for a given mean time between false alarms for one known change (Lorden 1971; Moustakides 1986).

Decision (bank of ``d`` tests): statistic ``max_i s_i(k)``, alarm above the threshold, label ``1 + argmax_i s_i(k)``,
estimate that direction's known size; the state keeps its onset offset (``-1``: older than the window, ``tail``). Not
isolation-optimal: directions overlapping in the first lags (engine: fuel-flow fault, P4 bias) both gain against
"no fault", and the first to cross need not be the true one.

``isolation="pairwise"``: each direction against every rival, each at its own most likely onset (Nikiforov 1995;
Basseville & Nikiforov 1993 sec. 7.4), ``r_i(k) = s_i(k) - max(0, max_{j != i} s_j(k))``: ``i`` alarms once it beats
no fault *and* every other direction by the threshold. Nikiforov's vector CUSUM, ``max_theta min_j (Lambda_i -
Lambda_j)`` at a common onset, lets the wrong direction win at a shifted onset when the first lags differ; ``r_i`` is
never larger: later alarms, safer isolation.

References: Page (1954), Continuous inspection schemes, Biometrika 41; Lorden (1971), Procedures for reacting to a
change in distribution, Ann. Math. Stat. 42; Basseville & Nikiforov (1993), Detection of Abrupt Changes, ch. 2, 7;
Nikiforov (1995), A generalized change detection problem, IEEE Trans. Inf. Theory 41; Moustakides (1986), Optimal
stopping times for detecting changes in distributions, Ann. Stat. 14; Willsky & Jones (1976), IEEE TAC 21.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi._simulation.faults import sensor_labels
from jaxfdi.detection._chi2 import Decision, Detector, flag_dead
from jaxfdi.detection._glrt import (
    check_steady_state,
    fault_directions,
    fault_signatures,
    whiten_finite,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class KnownChangeState(NamedTuple):
    """The known-change bank's state after step ``k``.

    Attributes:
      log_ratio: (N, d) Lambda_i(k, k - o) for onset offsets o = 0..N-1 (-inf: onset before the data)
      tail: (d,) max over onsets older than the window (-inf without ``tail`` or before N steps)
      count: () int32, steps seen (saturates at N)
      onset_offset: () int32, onset offset of the isolated direction (-1: an older onset, ``tail``)
    """

    log_ratio: Array
    tail: Array
    count: Array
    onset_offset: Array


class KnownChangeTerms(NamedTuple):
    """Whitened per-lag terms: ``llr_i(j, l) = gain[l, :, i] . w_j - drift[l, i]``.

    Attributes:
      whitener: (m, m) L^-1 with S = L L^T
      gain: (N, m, d) nu_i L^-1 G_i[l]
      drift: (N, d) nu_i^2 / 2 ||L^-1 G_i[l]||^2
    """

    whitener: Array
    gain: Array
    drift: Array


def known_change_terms(
    signatures: Array, innovation_cov: Array, magnitudes: Array
) -> KnownChangeTerms:
    """Check the bank's data and whiten it.

    Args:
      signatures: (N, m, d) ``G_i[l]``, lag ``l = 0..N-1`` (``fault_signatures``); N >= 1.
      innovation_cov: (m, m) steady-state innovation covariance ``S`` (positive definite).
      magnitudes: (d,) known fault sizes ``nu_i`` (finite, non-zero; the sign matters).
    """
    checks.check_real("signatures", signatures, "real signatures (N, m, d)")
    checks.check_shape(
        "signatures", signatures, (None, None, None), "(N, m, d) from fault_signatures"
    )
    N, m, d = checks.shape_of(signatures)
    if N < 1:
        raise ValueError(
            f"signatures: expected a window of N >= 1 lags (shape (N, m, d)), got shape "
            f"{checks.shape_of(signatures)}"
        )
    checks.check_finite("signatures", signatures, "fault signatures")
    checks.check_covariance("innovation_cov", innovation_cov, m, definite=True)
    checks.check_real("magnitudes", magnitudes, "known fault sizes")
    checks.check_shape("magnitudes", magnitudes, (d,), "one known size per fault direction")
    checks.check_finite("magnitudes", magnitudes, "known fault sizes")
    value = checks.concrete(magnitudes)
    if value is not None and np.any(value == 0):
        raise ValueError(
            f"magnitudes: expected non-zero known fault sizes, got {checks.received(value)}"
        )
    dtype = checks.float_dtype(signatures, innovation_cov, magnitudes)
    S = _linalg.symmetrize(jnp.asarray(innovation_cov, dtype))
    chol = jsl.cholesky(S, lower=True)
    whitener = jsl.solve_triangular(chol, jnp.eye(m, dtype=dtype), lower=True)
    nu = jnp.asarray(magnitudes, dtype)
    white = jnp.einsum("ab,lbd->lad", whitener, jnp.asarray(signatures, dtype))
    return KnownChangeTerms(whitener, white * nu, 0.5 * nu**2 * jnp.sum(white**2, axis=1))


def known_change_bank(
    signatures: Array,
    innovation_cov: Array,
    magnitudes: Array,
    threshold,
    tail: bool = False,
    isolation: str = "max",
    channel_labels: Array | None = None,
) -> Detector:
    """Online bank of known-change GLR (CUSUM) tests (module docstring) on a fault-blind filter's innovations.

    ``step(state, innovation (m,)) -> (state, Decision)``; jit- and vmap-able. ``signatures``, ``innovation_cov``,
    ``magnitudes``: as ``known_change_terms``; ``threshold`` > 0; ``tail``: also keep onsets older than the window
    (CUSUM form); ``isolation``: ``"max"`` (vs no fault) or ``"pairwise"`` (vs no fault and every other direction);
    ``channel_labels`` (m,): label a step with a non-finite innovation component alarms with (``chi2.flag_dead``;
    ``None``: the bank's own); that component enters as 0, its fault-free mean: recovery with the sensor.
    """
    terms = known_change_terms(signatures, innovation_cov, magnitudes)
    checks.check_positive(
        "threshold", threshold, "a positive threshold on the log-likelihood ratio"
    )
    checks.check_choice("isolation", isolation, ("max", "pairwise"))
    N, m, d = terms.gain.shape
    dtype = terms.drift.dtype
    tail = bool(tail)

    def init() -> KnownChangeState:
        minus_inf = jnp.full((N, d), -jnp.inf, dtype)
        return KnownChangeState(
            minus_inf,
            jnp.full((d,), -jnp.inf, dtype),
            jnp.zeros((), jnp.int32),
            jnp.zeros((), jnp.int32),
        )

    def step(state: KnownChangeState, innovation: Array):
        checks.check_shape(
            "innovation", innovation, (m,), "one step's innovation of the fault-blind filter"
        )
        innovation = jnp.asarray(innovation, dtype)
        white = whiten_finite(terms.whitener, innovation)
        llr = jnp.einsum("lmd,m->ld", terms.gain, white) - terms.drift  # (N, d), lag = offset
        older = jnp.concatenate(
            [jnp.zeros((1, d), dtype), state.log_ratio[:-1]], axis=0
        )  # L(k-1, o-1)
        log_ratio = older + llr
        count = jnp.minimum(state.count + 1, N)
        log_ratio = jnp.where((jnp.arange(N) < count)[:, None], log_ratio, -jnp.inf)
        if tail:
            leaving = jnp.where(state.count >= N, state.log_ratio[-1], -jnp.inf)
            tail_ratio = jnp.maximum(state.tail, leaving) + llr[-1]
        else:
            tail_ratio = state.tail
        in_window = jnp.max(log_ratio, axis=0)
        per_direction = jnp.maximum(in_window, tail_ratio)  # s_i(k)
        if isolation == "pairwise":
            per_direction = _against_rivals(per_direction)
        direction = jnp.argmax(per_direction)
        statistic = per_direction[direction]
        offset = jnp.where(
            in_window[direction] >= tail_ratio[direction], jnp.argmax(log_ratio[:, direction]), -1
        )
        decision = Decision(
            statistic,
            statistic > threshold,
            (1 + direction).astype(jnp.int32),
            jnp.asarray(magnitudes, dtype)[direction],
        )
        decision = flag_dead(decision, ~jnp.isfinite(innovation), channel_labels)
        return KnownChangeState(log_ratio, tail_ratio, count, offset.astype(jnp.int32)), decision

    return Detector(init, step)


def _against_rivals(statistic: Array) -> Array:
    """(d,) ``s_i - max(0, max_{j != i} s_j)``."""
    d = statistic.shape[0]
    rivals = jnp.max(jnp.where(jnp.eye(d, dtype=bool), -jnp.inf, statistic[None, :]), axis=1)
    return statistic - jnp.maximum(rivals, 0.0)


def known_change_detector(
    model: LinearGaussianModel,
    gain: Array,
    innovation_cov: Array,
    magnitudes: Array,
    window: int,
    threshold,
    tail: bool = False,
    actuator_feedthrough: bool = False,
    isolation: str = "max",
) -> Detector:
    """``known_change_bank`` with ``fault_directions(model)``'s signatures for the steady-state filter
    ``(gain, innovation_cov)`` (checked as ``glrt_detector`` does), over ``window`` onsets.

    Args:
      model: the plant the filter assumes.
      gain: (n, m) steady-state gain ``K``; innovation_cov: (m, m) steady-state ``S``.
      magnitudes: (d,) known sizes, actuators then sensors (the directions' order).
      window: N >= 1 onsets (and signature lags).
      threshold: > 0, on the log-likelihood ratio.
      tail, isolation, actuator_feedthrough: see ``known_change_bank`` and ``fault_directions``.

    Returns:
      ``Detector(init, step)``: ``init()`` gives a ``KnownChangeState`` with every log-ratio ``-inf``;
      ``step(state, innovation (m,)) -> (state, Decision)``, estimate the isolated direction's known size; a
      non-finite component alarms and isolates its sensor.
    """
    n, _, m = validate_linear_model(model)
    window = checks.check_int(
        "window", window, minimum=1, meaning="a positive integer number of steps N"
    )
    checks.check_shape("gain", gain, (n, m), "n states x m outputs, the measurement-update gain")
    checks.check_covariance("innovation_cov", innovation_cov, m, definite=True)
    check_steady_state(model, gain=gain, innovation_cov=innovation_cov)
    signatures = fault_signatures(
        model, gain, fault_directions(model, actuator_feedthrough), window
    )
    return known_change_bank(
        signatures,
        innovation_cov,
        magnitudes,
        threshold,
        tail,
        isolation,
        sensor_labels(model.Gamma.shape[1], m),
    )


def known_change_by_onset(
    innovations: Array, signatures: Array, innovation_cov: Array, magnitudes: Array
) -> Array:
    """(N, d) ``Lambda_i(k, k - o)`` for every onset offset of a window of innovations (N, m), oldest first, row
    N-1 = step k (all N onsets allowed): the offline bank statistic (``max`` over axis 0)."""
    terms = known_change_terms(signatures, innovation_cov, magnitudes)
    N, m, d = terms.gain.shape
    checks.check_shape("innovations", innovations, (N, m), "N steps x m outputs, oldest first")
    white = jnp.asarray(innovations, terms.drift.dtype) @ terms.whitener.T  # (N, m) by position p
    lag = jnp.arange(N)[None, :] - (N - 1 - jnp.arange(N))[:, None]  # (o, p): p - theta
    gain = jnp.where(
        (lag >= 0)[..., None, None], terms.gain[jnp.maximum(lag, 0)], 0.0
    )  # (o, p, m, d)
    drift = jnp.where((lag >= 0)[..., None], terms.drift[jnp.maximum(lag, 0)], 0.0)  # (o, p, d)
    return jnp.einsum("opmd,pm->od", gain, white) - jnp.sum(drift, axis=1)
