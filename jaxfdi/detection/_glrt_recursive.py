"""The windowed GLRT by running sums: O(N) per step instead of O(N^2) (Willsky & Jones 1976, sec. 3), and the online
``glrt_detector`` on either engine.

``glrt.py`` recomputes at every step ``k`` the correlation of the last ``N`` whitened innovations ``w_j`` with the
whitened signature of every onset ``theta = k - o`` in the window, an (N, N, m, d) contraction::

    d_i(theta) = sum_{j=theta..k} Gw_i[j - theta]^T w_j,        o = k - theta = 0..N-1.

Each sum gains one term a step (``j = k``, lag = offset ``o``), so the N correlations are carried as running sums
(Willsky & Jones 1976, eq. 3.17), an (N, m, d) contraction a step, dropping the onset leaving the window::

    d[o](k) = d[o-1](k-1) + Gw[o]^T w_k   (o >= 1),      d[0](k) = Gw[0]^T w_k.

``R_i(theta) = sum_{l<=o} ||Gw_i[l]||^2`` depends only on the offset; statistic, estimate, isolation and alarms are
the same functions of ``d`` (``glrt.glr_from_correlation``, ``glrt.decide``): the windowed form's, to round-off.
Removing a detected fault (``glrt_correction``) subtracts ``nu_hat Gw_i[j - theta_hat]`` from the window's ``w_j``,
here ``d_i'(k - o') -= nu_hat X[o', o_hat, i', i]``, cross-information
``X[o', o, i', i] = sum_p T[o', p, :, i'] . T[o, p, :, i]`` (N, N, d, d) of the onsets' whitened signatures ``T``
(``glrt._onset_tensors``). Steady state as in ``glrt``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import Detector
from jaxfdi.detection._glrt import (
    DetectorSetup,
    GLREngine,
    GLRResult,
    _maximise,
    _onset_tensors,
    _whitener,
    detector_setup,
    engine_detector,
    glr_from_correlation,
    windowed_engine,
)
from jaxfdi.models import LinearGaussianModel


class RecursiveGLRTState(NamedTuple):
    """The recursive windowed GLRT's state: correlations per onset offset, steps seen, last onset offset.

    Attributes:
      correlation: (N, d) d_i(k - o) for onset offsets o = 0..N-1
      count: () int32, steps seen (saturates at N)
      onset_offset: () int32, onset offset of the last decision's isolated direction
    """

    correlation: Array
    count: Array
    onset_offset: Array


def recursive_engine(setup: DetectorSetup, removable: bool = False) -> tuple[Array, GLREngine]:
    """The whitener ``L^-1`` and the running-sum engine; ``removable`` builds the cross-information ``X``
    (N, N, d, d) that ``remove`` needs (else ``remove`` raises)."""
    whitener, white_signatures, information = _recursive_tensors(
        setup.signatures, setup.innovation_cov
    )
    window, _, num_directions = white_signatures.shape
    dtype = setup.innovation_cov.dtype
    cross = _cross_information(white_signatures) if removable else None

    def init() -> RecursiveGLRTState:
        zero = jnp.zeros((), jnp.int32)
        return RecursiveGLRTState(jnp.zeros((window, num_directions), dtype), zero, zero)

    def update(state: RecursiveGLRTState, white: Array) -> tuple[RecursiveGLRTState, GLRResult]:
        older = jnp.concatenate(
            [jnp.zeros((1, num_directions), dtype), state.correlation[:-1]], axis=0
        )
        correlation = older + jnp.einsum("lmd,m->ld", white_signatures, white)
        count = jnp.minimum(state.count + 1, window)
        result = _maximise(glr_from_correlation(correlation, information, count))
        return state._replace(correlation=correlation, count=count), result

    def remove(state: RecursiveGLRTState, direction, offset, size) -> RecursiveGLRTState:
        if cross is None:
            raise ValueError("remove: build the engine with removable=True")
        return state._replace(correlation=state.correlation - size * cross[:, offset, :, direction])

    return whitener, GLREngine(init, update, remove, information)


@jax.jit
def _cross_information(white_signatures: Array) -> Array:
    """``X[o', o, i', i] = sum_p T[o', p, :, i'] . T[o, p, :, i]`` (N, N, d, d)."""
    onset_signatures, _ = _onset_tensors(white_signatures)
    return jnp.einsum("apmi,bpmj->abij", onset_signatures, onset_signatures)


@jax.jit
def _recursive_tensors(signatures: Array, innovation_cov: Array) -> tuple[Array, Array, Array]:
    """``L^-1``, whitened ``Gw[l] = L^-1 G[l]`` (N, m, d), information ``I[o] = sum_{l<=o} ||Gw[l]||^2`` (N, d)."""
    whitener = _whitener(innovation_cov)
    white = jnp.einsum("ab,lbd->lad", whitener, signatures)
    return whitener, white, jnp.cumsum(jnp.sum(white**2, axis=1), axis=0)


def glrt_detector(
    model: LinearGaussianModel,
    gain: Array,
    innovation_cov: Array,
    window: int,
    threshold,
    isolation: str = "max",
    actuator_feedthrough: bool = False,
    overlap_sensor: int = -1,
    recursive: bool = False,
) -> Detector:
    """Online windowed GLRT on the innovations of a fault-blind steady-state Kalman filter.

    ``step`` at step ``k``: statistic = ``max_i max_theta l_i(theta)`` over the onsets in the data seen, alarm =
    statistic > threshold, label = ``1 + i`` of the isolated direction (every step), estimate = its ``nu_hat``;
    ``theta_hat = k - state.onset_offset``. O(N^2 m d) per step; ``recursive=True``: the running sums (module
    doc), the same decisions to round-off at O(N m d).

    Isolation:
      ``"max"``: the direction with the largest GLR.
      ``"paper"``: Han et al. (2022) eq. (24), read as: actuator if the largest actuator GLR and the
        ``overlap_sensor`` GLR (T4, the last sensor) both exceed the threshold; else the largest sensor if one
        exceeds it; else an actuator if one alone exceeds it; with no alarm, as ``"max"``.

    Args:
      model: the plant the filter assumes (``Phi``, ``Gamma``, ``C``, ``D``).
      gain: (n, m) steady-state measurement-update gain ``K`` (``steady_state_kalman``).
      innovation_cov: (m, m) steady-state ``S``.
      window: N >= 1 steps.
      threshold: > 0, e.g. ``PAPER_USED_THRESHOLD`` or ``glrt_threshold(...)``.
      isolation: ``"max"``, ``"paper"`` or a () bool array (``True``: ``"paper"``; both rules in one program).
      actuator_feedthrough: see ``fault_directions``.
      overlap_sensor: sensor index (into the outputs) of eq. (24)'s T4.
      recursive: the running-sum engine instead of the window's.

    Returns:
      ``Detector(init, step)``: ``init()`` gives an empty ``GLRTState`` (zero (N, m) window), or with ``recursive``
      a zero ``RecursiveGLRTState`` (correlations (N, d), ``d = nu + m``); ``step(state, innovation (m,)) -> (state,
      Decision)``; a non-finite component alarms and isolates its sensor.
    """
    setup = detector_setup(
        model,
        gain,
        innovation_cov,
        window,
        threshold,
        isolation,
        actuator_feedthrough,
        overlap_sensor,
    )
    checks.check_flag("recursive", recursive)
    whitener, engine = recursive_engine(setup) if recursive else windowed_engine(setup)
    return engine_detector(setup, whitener, engine)
