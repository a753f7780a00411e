"""Chi-square residual tests: thresholds, normalised innovation squared, windows.

Fault-free, a correctly tuned Kalman filter's innovation is white, ``r ~ N(0, S)``, so the NIS ``r^T S^-1 r`` is
``chi2(m)`` and its sum over ``L`` steps ``chi2(L m)`` (Mehra & Peschon 1971; Bar-Shalom, Li & Kirubarajan 2001,
sec. 5.4). A fault is declared when the statistic exceeds ``chi2_threshold(dof, pfa)``.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.scipy.special import gammaincc, gammaln, ndtri

from jaxfdi import checks


def chi2_threshold(dof, pfa) -> Array:
    """Upper quantile ``x`` with ``P(chi2(dof) > x) = pfa``, computed in JAX.

    ``P(chi2(dof) > x) = Q(dof/2, x/2)``, ``Q`` the regularised upper incomplete gamma function. Wilson-Hilferty
    start from ``-ndtri(pfa)`` (``ndtri(1 - pfa)`` rounds to ``inf`` below ``pfa ~ eps``), then Newton on
    ``log Q(dof/2, x/2) = log pfa`` in log space (``log_upper_gamma``): finite for every ``pfa`` down to
    ``finfo(dtype).tiny`` (``2.2e-308`` float64, ``1.2e-38`` float32). Matches ``scipy.stats.chi2.isf`` to ~1e-12
    relative in float64 (``tests/detection/test_chi2_tail.py``). Differentiable in ``pfa`` and ``dof`` (one last
    differentiated Newton step gives the implicit ``dx/dpfa = -1 / pdf(x)``), vmappable, jit-compatible.

    Args:
      dof: degrees of freedom (> 0, finite), scalar or array.
      pfa: false-alarm probability in ``[finfo(dtype).tiny, 1)``, scalar or array.

    Returns:
      the threshold ``x``, broadcast shape of ``dof`` and ``pfa``, in their float dtype (JAX's default float for
      Python numbers); NaN for an out-of-range value under ``jit``/``vmap``.

    Raises:
      ValueError: naming ``dof`` or ``pfa`` for a concrete value out of range (e.g. ``pfa`` below ``tiny``).
    """
    checks.check_real("dof", dof, "degrees of freedom")
    checks.check_finite("dof", dof, "degrees of freedom")
    dof_value = checks.concrete(dof)
    if dof_value is not None and np.any(dof_value <= 0):
        raise ValueError(
            f"dof: expected positive degrees of freedom, got {checks.received(dof_value)}"
        )
    checks.check_probability("pfa", pfa)
    dtype = checks.float_dtype(dof, pfa)
    _check_representable(pfa, dtype)
    return _chi2_isf(jnp.asarray(dof, dtype), jnp.asarray(pfa, dtype))


def _check_representable(pfa, dtype, what: str = "pfa") -> None:
    """A concrete ``pfa`` must be a normal number of ``dtype`` below 1 once cast; ``what`` names the probability
    (e.g. a per-test ``pfa / tests``) in the message."""
    value = checks.concrete(pfa)
    if value is None:
        return
    info, name = np.finfo(dtype), np.dtype(dtype).name
    cast = np.asarray(value, dtype)
    if np.any(cast < info.tiny):
        advice = "; a smaller pfa needs float64 (jaxfdi.enable_x64())" if info.bits < 64 else ""
        raise ValueError(
            f"pfa: expected {what} >= {info.tiny:.4g} (np.finfo({name}).tiny, the smallest normal "
            f"{name}), got {checks.received(value)}{advice}"
        )
    if np.any(cast >= 1):
        raise ValueError(
            f"pfa: expected {what} that stays below 1 in {name}, got {checks.received(value)}"
        )


#: Newton steps on ``log Q`` (quadratic convergence; 30 cover every dof and pfa tested)
_NEWTON_STEPS = 30
#: Lentz steps of the continued fraction, used only far in the tail where it converges fast
_LENTZ_STEPS = 40


def log_upper_gamma(a: Array, x: Array) -> Array:
    """``log Q(a, x)``, ``Q(a, x) = Gamma(a, x) / Gamma(a)``, accurate where ``Q`` underflows.

    ``log(gammaincc(a, x))`` where ``Q`` is normal. Far in the upper tail (``x > a + 1`` and
    ``x^a e^-x / Gamma(a) < tiny^(1/2)``): Legendre's continued fraction
    ``Gamma(a, x) = e^-x x^a / (x + 1 - a - 1 (1 - a) / (x + 3 - a - ...))`` by modified Lentz (Press et al. 2007,
    *Numerical Recipes* 3rd ed., sec. 6.2), ``log Q = a log x - x - lgamma(a) + log CF``.
    """
    dtype = jnp.result_type(a, x)
    tiny = jnp.finfo(dtype).tiny
    log_prefactor = a * jnp.log(x) - x - gammaln(a)
    use_fraction = (x > a + 1.0) & (log_prefactor < 0.5 * jnp.log(tiny))
    x_fraction = jnp.where(use_fraction, x, 2.0 * a + 50.0)  # safe inputs for the branch not taken
    x_series = jnp.where(use_fraction, a, x)
    log_q_fraction = (
        a * jnp.log(x_fraction)
        - x_fraction
        - gammaln(a)
        + jnp.log(_legendre_fraction(a, x_fraction))
    )
    log_q_series = jnp.log(gammaincc(a, x_series))
    return jnp.where(use_fraction, log_q_fraction, log_q_series)


def _legendre_fraction(a: Array, x: Array) -> Array:
    """``Gamma(a, x) e^x x^-a`` by the modified Lentz method (``x > a + 1``)."""
    floor = jnp.finfo(jnp.result_type(a, x)).tiny / jnp.finfo(jnp.result_type(a, x)).eps
    b = x + 1.0 - a
    c = jnp.full_like(b, 1.0 / floor)
    d = 1.0 / b

    def lentz(i, carry):
        b, c, d, h = carry
        an = -i * (i - a)
        b = b + 2.0
        d = an * d + b
        d = 1.0 / jnp.where(jnp.abs(d) < floor, floor, d)
        c = b + an / c
        c = jnp.where(jnp.abs(c) < floor, floor, c)
        return b, c, d, h * d * c

    *_, h = jax.lax.fori_loop(1, _LENTZ_STEPS + 1, lentz, (b, c, d, d))
    return h


@jax.jit
def _chi2_isf(dof: Array, pfa: Array) -> Array:
    """``chi2.isf(pfa, dof)`` for validated arguments of one float dtype (module doc)."""
    dof, pfa = jnp.broadcast_arrays(dof, pfa)
    a = 0.5 * dof
    log_pfa = jnp.log(pfa)
    tiny = jnp.finfo(pfa.dtype).tiny

    def log_q_and_slope(x, a):
        """``log Q(a, x/2)`` and its derivative in ``x``, ``-pdf(x) / Q``."""
        log_q = log_upper_gamma(a, 0.5 * x)
        log_pdf = (a - 1.0) * jnp.log(0.5 * x) - 0.5 * x - gammaln(a) - jnp.log(2.0)
        return log_q, -jnp.exp(log_pdf - log_q)

    def newton(_, x):
        log_q, slope = log_q_and_slope(x, a_fixed)
        return jnp.maximum(x - (log_q - log_pfa_fixed) / slope, 0.5 * x)

    a_fixed, log_pfa_fixed = jax.lax.stop_gradient(a), jax.lax.stop_gradient(log_pfa)
    z = -ndtri(jax.lax.stop_gradient(pfa))  # upper normal quantile, finite for any normal pfa
    c = 2.0 / (9.0 * jax.lax.stop_gradient(dof))
    cube_root = 1.0 - c + z * jnp.sqrt(c)
    # near pfa = 1 (cube_root small) x is small and P(a, x/2) ~ (x/2)^a / Gamma(a + 1)
    small_x = 2.0 * jnp.exp(
        (jnp.log1p(-jax.lax.stop_gradient(pfa)) + gammaln(a_fixed + 1.0)) / a_fixed
    )
    start = jnp.where(cube_root > 0.1, jax.lax.stop_gradient(dof) * cube_root**3, small_x)
    x = jax.lax.stop_gradient(jax.lax.fori_loop(0, _NEWTON_STEPS, newton, jnp.maximum(start, tiny)))
    # one differentiated Newton step: its derivative is the implicit one, -d(log Q - log pfa) / slope
    log_q, slope = log_q_and_slope(x, a)
    x = x - (log_q - log_pfa) / jax.lax.stop_gradient(slope)
    valid = (pfa >= tiny) & (pfa < 1.0) & (dof > 0) & jnp.isfinite(dof)
    return jnp.where(valid, x, jnp.nan)


def normalized_innovation_squared(innovation: Array, innovation_cov: Array) -> Array:
    """``r^T S^-1 r`` by a Cholesky solve; works on (..., m) / (..., m, m) batches."""
    chol = jnp.linalg.cholesky(innovation_cov)
    w = jax.scipy.linalg.solve_triangular(chol, innovation[..., None], lower=True)[..., 0]
    return jnp.sum(w**2, axis=-1)


def moving_window_sum(x: Array, window: int) -> Array:
    """Sum of the last ``window`` values along axis 0 (fewer at the start); ``+inf`` while the window holds a
    non-finite value (a dead sensor's statistic is evidence), finite again once it has left.

    Returns:
      array of ``x``'s shape (T, ...): entry ``k`` is ``sum x[max(0, k-window+1)..k]`` (``+inf`` as above).
    """
    window = checks.check_int(
        "window", window, minimum=1, meaning="a positive integer number of steps"
    )
    checks.check_real("x", x, "real statistics")
    return _moving_window_sum(jnp.asarray(x), window)


@partial(jax.jit, static_argnums=1)
def _moving_window_sum(x: Array, window: int) -> Array:
    """``moving_window_sum`` once checked, as one program."""
    bad = ~jnp.isfinite(x)

    def windowed(values):
        c = jnp.cumsum(values, axis=0)
        shifted = jnp.concatenate(
            [jnp.zeros((window,) + x.shape[1:], c.dtype), c[:-window]], axis=0
        )[: x.shape[0]]
        return c - shifted

    return jnp.where(windowed(bad.astype(jnp.int32)) > 0, jnp.inf, windowed(jnp.where(bad, 0.0, x)))


def first_crossing(statistic: Array, threshold: Array, start: Array | int = 0) -> Array:
    """First index ``k >= start`` with ``statistic[k] > threshold`` along axis 0, else -1.

    Returns:
      int array of shape ``statistic.shape[1:]`` (scalar for (T,)): each column's first crossing, -1 if none.
    """
    k = jnp.arange(statistic.shape[0]).reshape((-1,) + (1,) * (statistic.ndim - 1))
    hit = (statistic > threshold) & (k >= start)
    return jnp.where(jnp.any(hit, axis=0), jnp.argmax(hit, axis=0), -1)


class WindowState(NamedTuple):
    """The moving-window sum's carry: a ring buffer of the last statistics.

    Attributes:
      buffer: (window,) last statistics, ring buffer
      index: () next slot
    """

    buffer: Array
    index: Array


class Decision(NamedTuple):
    """One step's output of an online ``Detector``.

    Attributes:
      statistic: () the detector's test statistic
      alarm: () bool, the statistic crossed its threshold
      label: () int, the isolated fault label (simulator's mode label: 0 none, then actuators, then sensors; -1: the
        detector does not isolate)
      estimate: () the detector's fault estimate (e.g. a magnitude; NaN if none)
    """

    statistic: Array
    alarm: Array
    label: Array
    estimate: Array


def flag_dead(decision: Decision, dead: Array, labels: Array | None = None) -> Decision:
    """The one rule for a dead sensor: a step whose input has a non-finite component (``dead`` (m,) bool, e.g.
    ``isnan(info.innovation)``, ``filters._base``) alarms with ``statistic = +inf``, label ``labels[j]`` of the
    first dead channel ``j`` (``labels`` (m,) int, each channel's fault label; ``None``: the detector's own) and
    estimate NaN. Other steps keep ``decision``.

    Returns:
      the ``Decision`` with its dead steps alarmed (statistic ``+inf``, the dead channel's label,
      estimate NaN).
    """
    dead = jnp.asarray(dead, bool)
    if dead.size == 0:
        return decision
    any_dead = jnp.any(dead)
    label = (
        decision.label
        if labels is None
        else jnp.where(any_dead, jnp.asarray(labels, jnp.int32)[jnp.argmax(dead)], decision.label)
    )
    statistic = jnp.asarray(decision.statistic)
    return Decision(
        jnp.where(any_dead, jnp.inf, statistic),
        decision.alarm | any_dead,
        label.astype(jnp.int32),
        jnp.where(any_dead, jnp.nan, decision.estimate).astype(statistic.dtype),
    )


class Detector(NamedTuple):
    """Online detector: one value (a NIS, an innovation, mode probabilities, ...) in, one ``Decision`` out.

    Attributes:
      init: ``init() -> state``, the detector's initial state
      step: ``step(state, value) -> (state, Decision)`` (statistic, alarm, label, estimate; each ()); a
        non-isolating detector gives ``label = -1``, ``estimate = NaN``
    """

    init: Callable[[], Any]
    step: Callable[[Any, Any], tuple[Any, Decision]]


def chi2_detector(threshold, window: int = 1, dtype=None) -> Detector:
    """Windowed chi-square test on a stream of NIS values.

    ``statistic[k] = sum_{j=k-L+1..k} nis[j]`` (fewer terms in the first ``L - 1`` steps), alarm when it exceeds
    ``threshold``, label -1, estimate NaN; ``chi2_threshold(window * m, pfa)`` gives a design false-alarm rate
    ``pfa``. A non-finite NIS (dead sensor: ``+inf`` from the filters) is ``+inf`` while in the window.

    Returns:
      ``Detector(init, step)``: ``init()`` gives a ``WindowState`` (zero (window,) buffer of ``dtype``);
      ``step(state, nis ()) -> (state, Decision)``.
    """
    window = checks.check_int(
        "window", window, minimum=1, meaning="a positive integer number of steps"
    )
    checks.check_scalar(
        "threshold",
        threshold,
        0.0,
        meaning="a threshold >= 0 on a sum of NIS values (a negative one alarms at every step)",
    )
    dtype = dtype or jnp.result_type(float)

    def init() -> WindowState:
        return WindowState(jnp.zeros((window,), dtype), jnp.zeros((), jnp.int32))

    def step(state: WindowState, nis: Array):
        nis = jnp.asarray(nis)
        buffer = state.buffer.at[state.index].set(jnp.where(jnp.isnan(nis), jnp.inf, nis))
        statistic = jnp.sum(buffer)
        decision = Decision(
            statistic,
            statistic > threshold,
            jnp.asarray(-1, jnp.int32),
            jnp.full((), jnp.nan, statistic.dtype),
        )
        return WindowState(buffer, (state.index + 1) % window), decision

    return Detector(init, step)
