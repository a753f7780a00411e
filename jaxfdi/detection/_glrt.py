"""Windowed generalised likelihood ratio test for step faults (Willsky & Jones 1976).

A step of unknown size ``nu`` in direction ``i`` from onset ``theta`` adds a signature to the innovations of a
fault-blind steady-state Kalman filter: ``eps_k = eps0_k + G_i[k - theta] nu`` (``G[l] = 0`` for ``l < 0``),
``eps0_k ~ N(0, S)`` white. Over the last ``N`` steps (Willsky & Jones 1976, eqs. 3.10-3.14; Han et al. 2022,
eqs. 14-23)::

    d_i(theta) = sum_j G_i[j - theta]^T S^-1 eps_j
    R_i(theta) = sum_j G_i[j - theta]^T S^-1 G_i[j - theta]
    nu_hat     = d / R,      l_i(theta) = d^2 / R   (chi2(1) under no fault)

and the GLR of direction ``i`` is ``max_theta l_i(theta)``.

Signatures (derived here; Han et al. 2022 eqs. 18-19 are garbled as printed). Plant (their eq. 4,
``jaxfdi.simulate``; ``D`` sees the *commanded* input): ``x[k+1] = Phi x[k] + Gamma (u[k] + f_u[k]) + w``,
``y[k] = C x[k] + D u[k] + f_y[k] + v``. A unit step ``f[k] = 1 (k >= theta)`` in direction ``i`` enters the state
as ``g_i`` and the output as ``h_i`` (``FaultDirections``). Filter (``jaxfdi.filters._kalman``):
``eps_k = y_k - C m_k - D u_k``, ``m_{k+1} = Phi (m_k + K eps_k) + Gamma u_k``; the fault's share of the prediction
error obeys ``e_{k+1} = Phi (I - K C) e_k + (g - Phi K h) f_k``, ``e_theta = 0``, so at lag ``l = k - theta >= 0``::

    G[0] = h,   E[1] = g - Phi K h
    G[l] = C E[l] + h,   E[l+1] = Phi (I - K C) E[l] + g - Phi K h

A sensor fault shows at onset (``G[0] = e_j``), an actuator fault one step later (``G[0] = 0``,
``G[1] = C Gamma_i``) unless it also passes through ``D``.

Steady state required (constant ``K``, ``S``; ``P[k|k-1] = P_ss``, the DARE solution of ``steady_state_kalman``):
``glrt_detector`` (either engine) and ``corrected_glrt`` raise ``ValueError`` (naming ``gain``,
``innovation_cov`` or ``cov`` and the expected ``steady_state_kalman(model)`` field) when a concrete value differs
from it by more than ``steady_state_tolerance(dtype)``; the check is skipped under ``jit``/``vmap`` of the
construction. Another prior: ``transient_glrt_detector`` (time-varying gains and signatures).

Timing: the window ends at step ``k``; onset offset ``o`` in ``0..N-1`` means ``theta = k - o`` (onset estimate
``k - onset_offset``). Shared by the forms: ``detector_setup``, ``GLREngine`` (``windowed_engine``;
``glrt_recursive.recursive_engine``), ``engine_detector``, ``decide``.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi._numerics.riccati import steady_state_kalman
from jaxfdi._simulation.faults import sensor_labels
from jaxfdi.detection._chi2 import (
    Decision,
    Detector,
    _check_representable,
    chi2_threshold,
    flag_dead,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model

#: the threshold Han et al. (2022) use (set by simulation to suppress T4 false alarms, sec. 3.3).
PAPER_USED_THRESHOLD = 200.0


class FaultDirections(NamedTuple):
    """How a unit step fault enters the plant, one column per direction: actuators then sensors
    (direction ``i`` has the simulator's fault label ``1 + i``).

    Attributes:
      state: (n, d) added to x[k+1] = Phi x + Gamma u + ...
      output: (m, d) added to y[k] = C x + D u + ...
    """

    state: Array
    output: Array


class GLRResult(NamedTuple):
    """GLR of each direction, maximised over the onsets in the window.

    Attributes:
      statistic: (d,) max_theta l_i(theta)
      onset_offset: (d,) int, o with theta_hat = k - o (k: last step of the window)
      magnitude: (d,) nu_hat at theta_hat
    """

    statistic: Array
    onset_offset: Array
    magnitude: Array


class OnsetGLR(NamedTuple):
    """GLR for every candidate onset offset ``o`` (rows) and direction (columns).

    Attributes:
      statistic: (N, d) l_i(k - o); -inf for onsets before the data
      magnitude: (N, d) nu_hat_i(k - o); 0 where the window holds no information
    """

    statistic: Array
    magnitude: Array


class GLRTState(NamedTuple):
    """The windowed GLRT's carry: the last ``N`` whitened innovations.

    Attributes:
      window: (N, m) last N whitened innovations L^-1 eps, oldest first
      count: () int32, steps seen (saturates at N)
      onset_offset: () int32, onset offset of the last decision's isolated direction
    """

    window: Array
    count: Array
    onset_offset: Array


def fault_directions(
    model: LinearGaussianModel, actuator_feedthrough: bool = False
) -> FaultDirections:
    """Unit step-fault directions ``(g, h)``: actuators ``1..nu``, then sensors ``1..m``.

    Actuator ``i``: ``g = Gamma[:, i]``, ``h = 0`` (Han et al. 2022 eq. 4 and ``jaxfdi.simulate`` feed the commanded
    input through ``D``), or ``h = D[:, i]`` if ``actuator_feedthrough``. Sensor ``j``: ``g = 0``, ``h = e_j``.

    Returns:
      ``FaultDirections`` of the ``d = nu + m`` directions, in ``Gamma``'s dtype.
    """
    validate_linear_model(model)
    return _directions(model.Gamma, model.D, bool(actuator_feedthrough))


@partial(jax.jit, static_argnums=2)
def _directions(Gamma: Array, D: Array, actuator_feedthrough: bool) -> FaultDirections:
    (n, nu), m = Gamma.shape, D.shape[0]
    output_act = D.astype(Gamma.dtype) if actuator_feedthrough else jnp.zeros((m, nu), Gamma.dtype)
    state = jnp.concatenate([Gamma, jnp.zeros((n, m), Gamma.dtype)], axis=1)
    output = jnp.concatenate([output_act, jnp.eye(m, dtype=Gamma.dtype)], axis=1)
    return FaultDirections(state, output)


def fault_signatures(
    model: LinearGaussianModel, gain: Array, directions: FaultDirections, window: int
) -> Array:
    """(window, m, d) innovation signatures ``G[l]`` of a unit step fault, lag ``l = k - theta``.

    ``G[0] = h``, ``E[1] = g - Phi K h``, ``G[l] = C E[l] + h``, ``E[l+1] = Phi (I - K C) E[l] + g - Phi K h``,
    ``K`` (n, m) the steady-state gain (derivation: module docstring).

    Returns:
      (window, m, d) array in ``gain``'s dtype: ``G[l]``, ``l = 0..window-1``, one column per direction.
    """
    n, _, m = validate_linear_model(model)
    window = _check_window(window)
    checks.check_shape("gain", gain, (n, m), "n states x m outputs, the measurement-update gain")
    _check_directions(directions, n, m)
    dtype = jnp.result_type(gain)
    return step_response(
        *(
            jnp.asarray(a, dtype)
            for a in (model.Phi, model.C, gain, directions.state, directions.output)
        ),
        window,
    )[1]


@partial(jax.jit, static_argnums=5)
def step_response(
    Phi: Array, C: Array, gain: Array, g: Array, h: Array, length: int
) -> tuple[Array, Array]:
    """A unit step's share of the steady-state filter's prediction error ``E[l]`` (length, n, d) and innovation
    ``G[l] = C E[l] + h`` (length, m, d), lags ``0..length-1``: ``E[0] = 0``,
    ``E[l+1] = Phi (I - K C) E[l] + g - Phi K h``."""
    closed_loop = Phi @ (jnp.eye(Phi.shape[0], dtype=Phi.dtype) - gain @ C)
    forcing = g - Phi @ (gain @ h)

    def lag(E, _):
        return closed_loop @ E + forcing, (E, C @ E + h)

    return jax.lax.scan(lag, jnp.zeros_like(g), None, length=length)[1]


def glr_by_onset(
    innovations: Array, signatures: Array, innovation_cov: Array | None = None, num_valid=None
) -> OnsetGLR:
    """GLR ``l_i(theta)`` and ``nu_hat_i(theta)`` for every onset ``theta = k - o`` of the window.

    Args:
      innovations: (N, m) innovations of the last N steps, oldest first (row N-1 is step k).
      signatures: (N, m, d) ``G[l]`` from ``fault_signatures``.
      innovation_cov: (m, m) steady-state ``S``; ``None`` when ``innovations`` and ``signatures`` are already
        whitened (``L^-1 eps``, ``L^-1 G`` with ``S = L L^T``).
      num_valid: () number of most recent rows that are data (older onsets not considered); default N.
    """
    innovations, signatures, innovation_cov = _check_glr_inputs(
        innovations, signatures, innovation_cov
    )
    num_valid = innovations.shape[0] if num_valid is None else num_valid
    return _glr_by_onset(innovations, signatures, innovation_cov, num_valid)


@jax.jit
def _glr_by_onset(innovations, signatures, innovation_cov, num_valid) -> OnsetGLR:
    if innovation_cov is not None:
        whitener = _whitener(innovation_cov)
        innovations, signatures = (
            innovations @ whitener.T,
            jnp.einsum("ab,lbd->lad", whitener, signatures),
        )
    return _glr_core(innovations, *_onset_tensors(signatures), num_valid)


def glr_statistic(
    innovations: Array, signatures: Array, innovation_cov: Array | None = None, num_valid=None
) -> GLRResult:
    """GLR of each direction maximised over the onsets of the window (Willsky & Jones 1976).

    Same arguments as ``glr_by_onset``; returns ``GLRResult`` ((d,) each), ``theta_hat = k - onset_offset``.
    """
    return _maximise(glr_by_onset(innovations, signatures, innovation_cov, num_valid))


def glrt_threshold(pfa, num_directions: int, window: int, method: str = "paper") -> Array:
    """A threshold for the GLR statistic at false-alarm probability ``pfa`` per step.

    ``"paper"``: ``chi2_threshold(num_directions * window, pfa)``, Han et al.'s (2022) theoretical value
    (6 directions x N = 10, pfa = 0.005 -> 91.95; they then use ``PAPER_USED_THRESHOLD = 200``, set by simulation).
    ``"bonferroni"``: ``chi2_threshold(1, pfa / (num_directions * window))``, since each ``l_i(theta)`` is
    ``chi2(1)`` under no fault; bounds the per-step false-alarm probability of the maximum by ``pfa``.

    Returns:
      the threshold, of ``pfa``'s shape (() for a scalar) and float dtype.
    """
    checks.check_choice("method", method, ("paper", "bonferroni"))
    checks.check_probability("pfa", pfa)
    tests = checks.check_int(
        "num_directions", num_directions, minimum=1, meaning="a positive number of directions"
    )
    tests *= _check_window(window)
    dtype = checks.float_dtype(pfa)
    if method == "paper":
        return chi2_threshold(jnp.asarray(tests, dtype), pfa)
    value = checks.concrete(pfa)
    _check_representable(
        None if value is None else value / tests,
        dtype,
        f"the Bonferroni per-test probability pfa / (num_directions * window) = pfa / {tests}",
    )
    return chi2_threshold(jnp.asarray(1, dtype), jnp.asarray(pfa, dtype) / tests)


def whiten_finite(whitener: Array, innovation: Array) -> Array:
    """``L^-1 eps`` with a non-finite component (dead sensor) taken as 0, its fault-free mean, so the statistics
    recover as soon as the sensor does."""
    return whitener @ jnp.where(jnp.isfinite(innovation), innovation, 0.0)


def engine_detector(setup: DetectorSetup, whitener: Array, engine: GLREngine) -> Detector:
    """The online ``Detector`` of an engine (windowed or recursive): whiten, update, decide. A non-finite
    innovation component ``j`` alarms and isolates sensor ``j`` (label ``1 + nu + j``, ``chi2.flag_dead``)."""
    m, dtype = setup.innovation_cov.shape[0], setup.innovation_cov.dtype

    channel_labels = sensor_labels(setup.num_inputs, m)

    def step(state, innovation: Array):
        checks.check_shape(
            "innovation", innovation, (m,), "one step's innovation of the fault-blind filter"
        )
        innovation = jnp.asarray(innovation, dtype)
        state, result = engine.update(state, whiten_finite(whitener, innovation))
        decision, onset_offset = decide(setup, result)
        return state._replace(onset_offset=onset_offset), flag_dead(
            decision, ~jnp.isfinite(innovation), channel_labels
        )

    return Detector(engine.init, step)


class DetectorSetup(NamedTuple):
    """What a GLRT detector is built from (checked by ``detector_setup``).

    Attributes:
      signatures: (N, m, d) fault_signatures, in the detector's dtype
      innovation_cov: (m, m) steady-state innovation covariance S
      threshold: () alarm threshold on the largest GLR
      isolation: "max", "paper" or a () bool array (True: "paper")
      num_inputs: nu: directions 0..nu-1 are actuators
      sensor_t4: direction index of eq. (24)'s T4
    """

    signatures: Array
    innovation_cov: Array
    threshold: Any
    isolation: Any
    num_inputs: int
    sensor_t4: int


def detector_setup(
    model: LinearGaussianModel,
    gain: Array,
    innovation_cov: Array,
    window: int,
    threshold,
    isolation: str,
    actuator_feedthrough: bool,
    overlap_sensor: int,
) -> DetectorSetup:
    """Check a GLRT detector's arguments (``glrt_detector``) and compute its signatures.

    ``gain`` and ``innovation_cov`` must be the model's steady state (``check_steady_state``).

    Returns:
      ``DetectorSetup``: signatures (N, m, d) and ``innovation_cov`` (m, m) in ``gain``'s and ``innovation_cov``'s
      float dtype, ``threshold`` and ``isolation`` as given, ``num_inputs = nu``,
      ``sensor_t4 = nu + overlap_sensor % m``.
    """
    n, nu, m = validate_linear_model(model)
    window = _check_window(window)
    checks.check_shape("gain", gain, (n, m), "n states x m outputs, the measurement-update gain")
    checks.check_covariance("innovation_cov", innovation_cov, m)
    check_steady_state(model, gain=gain, innovation_cov=innovation_cov)
    _check_decision_args(threshold, isolation, overlap_sensor, m)
    dtype = jnp.result_type(gain, innovation_cov)
    signatures = fault_signatures(
        model, jnp.asarray(gain, dtype), fault_directions(model, actuator_feedthrough), window
    )
    return DetectorSetup(
        signatures,
        jnp.asarray(innovation_cov, dtype),
        threshold,
        isolation,
        nu,
        nu + int(overlap_sensor) % m,
    )


def _check_decision_args(threshold, isolation: str, overlap_sensor: int, m: int) -> None:
    value = checks.concrete(threshold)
    if value is not None and not (value.shape == () and np.isfinite(value) and value > 0):
        raise ValueError(f"threshold: expected a positive scalar, got {threshold}")
    if isinstance(isolation, str):
        if isolation not in ("max", "paper"):
            raise ValueError(f"isolation: expected 'max' or 'paper', got {isolation!r}")
    elif not (
        hasattr(isolation, "dtype")
        and jnp.asarray(isolation).dtype == bool
        and jnp.ndim(isolation) == 0
    ):
        raise ValueError(
            f"isolation: expected 'max', 'paper' or a () bool array (True: 'paper'), got {isolation!r}"
        )
    if not -m <= int(overlap_sensor) < m:
        raise ValueError(
            f"overlap_sensor: expected a sensor index in [-{m}, {m}), got {overlap_sensor}"
        )


def decide(setup: DetectorSetup, result: GLRResult) -> tuple[Decision, Array]:
    """The step's decision from the GLR of every direction, and the isolated direction's onset offset."""
    statistic = jnp.max(result.statistic)
    alarm = statistic > setup.threshold
    direction = jnp.argmax(result.statistic)
    if not isinstance(setup.isolation, str):  # data: both rules in one program
        paper = _paper_isolation(
            result.statistic, setup.threshold, setup.num_inputs, setup.sensor_t4, direction
        )
        direction = jnp.where(setup.isolation, paper, direction)
    elif setup.isolation == "paper":
        direction = _paper_isolation(
            result.statistic, setup.threshold, setup.num_inputs, setup.sensor_t4, direction
        )
    decision = Decision(
        statistic, alarm, (1 + direction).astype(jnp.int32), result.magnitude[direction]
    )
    return decision, result.onset_offset[direction]


def steady_state_tolerance(dtype) -> float:
    """Relative Frobenius tolerance of ``check_steady_state``: ``max(1e-6, sqrt(eps))`` (float32: ``3.5e-4``)."""
    return max(1e-6, float(np.sqrt(np.finfo(dtype).eps)))


def check_steady_state(
    model: LinearGaussianModel, gain=None, innovation_cov=None, cov=None
) -> None:
    """Raise ``ValueError`` unless the given filter quantities are the model's steady state.

    ``gain`` (K), ``innovation_cov`` (S), ``cov`` (prior ``P[0|-1]``) vs ``steady_state_kalman(model)``: relative
    Frobenius difference <= ``steady_state_tolerance(dtype)``. Skipped for values unknown at trace time.
    """
    given = {
        name: value
        for name, value in (("gain", gain), ("innovation_cov", innovation_cov), ("cov", cov))
        if value is not None
    }
    values = {name: checks.concrete(value) for name, value in given.items()}
    fixed = [checks.concrete(a) for a in (model.Phi, model.C, model.Q, model.R)]
    if not values or any(v is None for v in values.values()) or any(a is None for a in fixed):
        return
    with jax.ensure_compile_time_eval():  # concrete inputs, also while a caller traces
        steady = steady_state_kalman(model)
    expected = {
        "gain": (steady.gain, "steady_state_kalman(model).gain"),
        "innovation_cov": (steady.innovation_cov, "steady_state_kalman(model).innovation_cov"),
        "cov": (
            steady.predicted_cov,
            "steady_state_kalman(model).predicted_cov (P_ss, the DARE solution)",
        ),
    }
    for name, value in values.items():
        reference, what = expected[name]
        reference = np.asarray(reference, np.float64)
        dtype = value.dtype if np.issubdtype(value.dtype, np.floating) else np.float64
        tol = steady_state_tolerance(dtype)
        scale = max(float(np.linalg.norm(reference)), np.finfo(np.float64).tiny)
        difference = float(np.linalg.norm(value.astype(np.float64) - reference)) / scale
        if not difference <= tol:
            raise ValueError(
                f"{name}: expected {what}: the GLR signatures assume a filter in steady state "
                f"(constant gain, P[k|k-1] = P_ss); got one that differs from it by {difference:.3g} relative "
                f"(Frobenius), over the tolerance {tol:.3g}. Start the filter at "
                "kf.init(mean, steady_state_kalman(model).predicted_cov), or test a filter started from "
                "another prior with transient_glrt_detector(model, prior_cov, ...)"
            )


class GLREngine(NamedTuple):
    """One detector form's GLR window: ``update(state, white (m,)) -> (state, GLRResult)``;
    ``remove(state, direction, offset, size) -> state`` takes a step of ``size`` in ``direction`` with onset
    offset ``offset`` out of the window; ``information`` (N, d) is ``R_i(k - o)``."""

    init: Callable[[], Any]
    update: Callable[[Any, Array], tuple[Any, GLRResult]]
    remove: Callable[[Any, Array, Array, Array], Any]
    information: Array


def windowed_engine(setup: DetectorSetup) -> tuple[Array, GLREngine]:
    """The whitener ``L^-1`` and the windowed (O(N^2) a step) engine of ``glrt_detector``."""
    whitener, onset_signatures, information = _detector_tensors(
        setup.signatures, setup.innovation_cov
    )
    window, m = setup.signatures.shape[:2]
    dtype = setup.innovation_cov.dtype

    def init() -> GLRTState:
        zero = jnp.zeros((), jnp.int32)
        return GLRTState(jnp.zeros((window, m), dtype), zero, zero)

    def update(state: GLRTState, white: Array) -> tuple[GLRTState, GLRResult]:
        buffer = jnp.concatenate([state.window[1:], white[None]], axis=0)
        count = jnp.minimum(state.count + 1, window)
        result = _maximise(_glr_core(buffer, onset_signatures, information, count))
        return state._replace(window=buffer, count=count), result

    def remove(state: GLRTState, direction, offset, size) -> GLRTState:
        return state._replace(
            window=state.window - size * onset_signatures[offset, :, :, direction]
        )

    return whitener, GLREngine(init, update, remove, information)


def glr_sequence(setup: DetectorSetup, innovations: Array) -> GLRResult:
    """Every direction's windowed GLR at every step of ``innovations`` (T, m): the ``GLRResult`` (T, d) that
    ``glrt_detector`` maximises over directions (for figures).

    Returns:
      ``GLRResult`` with a leading time axis: ``statistic`` (T, d), ``onset_offset`` (T, d) int32 and ``magnitude``
      (T, d), the step of the whole window's best onset per direction (a non-finite innovation component taken as 0).
    """
    whitener, engine = windowed_engine(setup)
    _, result = jax.lax.scan(
        lambda state, e: engine.update(state, whiten_finite(whitener, e)),
        engine.init(),
        innovations,
    )
    return result


def _paper_isolation(
    statistic: Array, threshold, nu: int, sensor_t4: int, fallback: Array
) -> Array:
    """Eq. (24) of Han et al. (2022): index of the isolated direction (see ``glrt_detector``)."""
    actuator = jnp.argmax(statistic[:nu])
    sensor = nu + jnp.argmax(statistic[nu:])
    actuator_over = statistic[actuator] > threshold
    sensor_over = statistic[sensor] > threshold
    return jnp.where(
        actuator_over & (statistic[sensor_t4] > threshold),
        actuator,
        jnp.where(sensor_over, sensor, jnp.where(actuator_over, actuator, fallback)),
    )


def _check_window(window) -> int:
    return checks.check_int(
        "window", window, minimum=1, meaning="a positive integer number of steps N"
    )


def _check_directions(directions: FaultDirections, n: int, m: int) -> None:
    """Check ``directions`` against ``n`` states and ``m`` outputs (``d`` columns each)."""
    checks.check_shape("directions.state", directions.state, (n, None), "n states x d directions")
    d = checks.shape_of(directions.state)[1]
    checks.check_shape("directions.output", directions.output, (m, d), "m outputs x d directions")


def _check_glr_inputs(innovations, signatures, innovation_cov):
    checks.check_shape(
        "signatures", signatures, (None, None, None), "(N, m, d) from fault_signatures"
    )
    N, m, _ = checks.shape_of(signatures)
    checks.check_shape("innovations", innovations, (N, m), "N steps x m outputs, oldest first")
    dtype = jnp.result_type(innovations, signatures)
    if innovation_cov is not None:
        checks.check_covariance("innovation_cov", innovation_cov, m)
        innovation_cov = jnp.asarray(innovation_cov, dtype)
    return jnp.asarray(innovations, dtype), jnp.asarray(signatures, dtype), innovation_cov


def _whitener(innovation_cov: Array) -> Array:
    """``L^-1`` with ``S = L L^T``: whitened innovations ``L^-1 eps`` are N(0, I)."""
    chol = jsl.cholesky(
        _linalg.symmetrize(innovation_cov), lower=True
    )  # one-off: LAPACK compiles faster
    return jsl.solve_triangular(
        chol, jnp.eye(innovation_cov.shape[0], dtype=innovation_cov.dtype), lower=True
    )


@jax.jit
def _detector_tensors(signatures: Array, innovation_cov: Array) -> tuple[Array, Array, Array]:
    whitener = _whitener(innovation_cov)
    return (whitener, *_onset_tensors(jnp.einsum("ab,lbd->lad", whitener, signatures)))


def _onset_tensors(white_signatures: Array) -> tuple[Array, Array]:
    """``T[o, p] = Gw[p - (N-1-o)]`` (0 for a negative lag), (N, N, m, d), and the information
    ``I[o] = sum_{l<=o} ||Gw[l]||^2`` per column, (N, d)."""
    N = white_signatures.shape[0]
    offset = jnp.arange(N)[:, None]
    position = jnp.arange(N)[None, :]
    lag = position + offset - (N - 1)
    onset_signatures = jnp.where(
        (lag >= 0)[..., None, None], white_signatures[jnp.maximum(lag, 0)], 0.0
    )
    information = jnp.cumsum(jnp.sum(white_signatures**2, axis=1), axis=0)
    return onset_signatures, information


def _glr_core(
    white_window: Array, onset_signatures: Array, information: Array, num_valid
) -> OnsetGLR:
    """``d[o, i] = sum_p T[o, p]^T w_p``, ``nu_hat = d / I``, ``l = d^2 / I`` for all onsets."""
    correlation = jnp.einsum("opmi,pm->oi", onset_signatures, white_window)
    return glr_from_correlation(correlation, information, num_valid)


def glr_from_correlation(correlation: Array, information: Array, num_valid) -> OnsetGLR:
    """``nu_hat = d / I``, ``l = d^2 / I`` from correlations ``d`` (N, d) and information ``I`` (N, d) of every
    onset offset; offsets ``>= num_valid`` are -inf."""
    N = correlation.shape[0]
    informative = information > 0
    safe = jnp.where(informative, information, 1.0)
    magnitude = jnp.where(informative, correlation / safe, 0.0)
    statistic = magnitude * correlation
    valid = (jnp.arange(N) < num_valid)[:, None]
    return OnsetGLR(jnp.where(valid, statistic, -jnp.inf), jnp.where(valid, magnitude, 0.0))


def _maximise(by_onset: OnsetGLR) -> GLRResult:
    offset = jnp.argmax(by_onset.statistic, axis=0)
    statistic = jnp.take_along_axis(by_onset.statistic, offset[None], axis=0)[0]
    magnitude = jnp.take_along_axis(by_onset.magnitude, offset[None], axis=0)[0]
    return GLRResult(statistic, offset.astype(jnp.int32), magnitude)
