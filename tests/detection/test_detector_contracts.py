"""Contract tests over every detector of the library (the filters':
``tests/filters/test_filter_contracts.py``).

Every ``Detector`` factory (``DETECTORS``): a step gives a ``Decision`` of scalars, jit and
vmap over streams under ``lax.scan`` work, a non-finite input alarms, a quiet stream does not."""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

#: steps of every stream
T_STEPS = 12


# ------------------------------------------------------------------ every Detector of the library
# One case per factory of ``jaxfdi.detection`` that returns a ``Detector``: ``make()``, a
# random stream of its inputs ``stream(rng, (B, T))``, a quiet stream (T, ...) far from its
# threshold, and ``dead(value, bad)``: one input with a component replaced by ``bad``.
class DetectorCase(NamedTuple):
    make: object
    stream: object
    quiet: object
    dead: object = lambda value, bad: value.at[0].set(bad)


@functools.lru_cache(maxsize=None)
def _glrt_setup():
    from _linear_gaussian_cases import small_model

    from jaxfdi import steady_state_kalman

    model = small_model()
    steady = steady_state_kalman(model)
    return model, steady.gain, steady.innovation_cov


def _innovations(rng, shape):
    _, _, S = _glrt_setup()
    return jnp.asarray(rng.normal(size=shape + (2,)) @ np.linalg.cholesky(np.asarray(S)).T)


def _detector_registry():
    from jaxfdi.detection import (
        chi2_detector,
        fault_directions,
        fault_signatures,
        frozen_channel_detector,
        glrt_detector,
        known_change_detector,
        mode_probability_detector,
        transient_glrt_detector,
    )
    from jaxfdi.detection._credits import credit_isolator
    from jaxfdi.detection._known_change import known_change_bank

    model, gain, S = _glrt_setup()
    window, zeros = 4, jnp.zeros((T_STEPS, 2))
    signatures = fault_signatures(model, gain, fault_directions(model), window)
    sizes = jnp.asarray([0.5, 2.0, -2.0])
    alternating = jnp.asarray((-1.0) ** np.arange(T_STEPS))[:, None] * jnp.asarray([1.0, 2.0])
    return {
        "chi2_detector": DetectorCase(
            lambda: chi2_detector(20.0, 3),
            lambda rng, shape: jnp.asarray(rng.chisquare(2, size=shape)),
            jnp.full((T_STEPS,), 0.1),
            lambda value, bad: jnp.asarray(bad),
        ),
        # a lower-tail test: the quiet stream is a channel far from frozen (it alternates)
        "frozen_channel_detector": DetectorCase(
            lambda: frozen_channel_detector(
                jnp.asarray([0.1, 0.1]), window, 1e-3, jnp.asarray([3, 4])
            ),
            lambda rng, shape: jnp.asarray(rng.normal(size=shape + (2,))),
            alternating,
        ),
        "glrt_detector": DetectorCase(
            lambda: glrt_detector(model, gain, S, window, 30.0), _innovations, zeros
        ),
        "glrt_detector(recursive=True)": DetectorCase(
            lambda: glrt_detector(model, gain, S, window, 30.0, recursive=True), _innovations, zeros
        ),
        "transient_glrt_detector": DetectorCase(
            lambda: transient_glrt_detector(model, 4.0 * model.Q, window, 30.0), _innovations, zeros
        ),
        "known_change_bank": DetectorCase(
            lambda: known_change_bank(signatures, S, sizes, 10.0, tail=True), _innovations, zeros
        ),
        "known_change_detector": DetectorCase(
            lambda: known_change_detector(model, gain, S, sizes, window, 10.0), _innovations, zeros
        ),
        "mode_probability_detector": DetectorCase(
            lambda: mode_probability_detector(0.9, confirm_steps=2),
            lambda rng, shape: jnp.asarray(rng.dirichlet([4.0, 1.0, 1.0], size=shape)),
            jnp.tile(jnp.asarray([0.98, 0.01, 0.01]), (T_STEPS, 1)),
        ),
        "credit_isolator": DetectorCase(
            lambda: credit_isolator(0.5, label_offset=1),
            lambda rng, shape: jnp.asarray(np.abs(rng.normal(size=shape + (3,)))),
            jnp.ones((T_STEPS, 3)),
        ),
    }


DETECTORS = _detector_registry()


@pytest.fixture(scope="module", params=sorted(DETECTORS))
def detector_case(request):
    return DETECTORS[request.param]


def test_every_detector_steps_to_a_decision_of_scalars(detector_case):
    from jaxfdi.detection import Decision

    detector = detector_case.make()
    value = detector_case.stream(np.random.default_rng(0), (1,))[0]
    _, decision = detector.step(detector.init(), value)
    assert type(decision) is Decision
    assert all(jnp.shape(field) == () for field in decision)
    assert decision.statistic.dtype == decision.estimate.dtype == jnp.float64
    assert decision.alarm.dtype == jnp.bool_ and decision.label.dtype == jnp.int32


def test_every_detector_jits_and_vmaps_over_streams_under_scan(detector_case):
    """jit(vmap over B streams of scan(step)) equals the scans one stream at a time."""
    detector = detector_case.make()
    streams = detector_case.stream(np.random.default_rng(1), (3, T_STEPS))

    def scan(values):
        return jax.lax.scan(detector.step, detector.init(), values)

    batched = jax.jit(jax.vmap(scan))(streams)
    for b in range(3):
        chex.assert_trees_all_close(
            jax.tree_util.tree_map(lambda a: a[b], batched),
            scan(streams[b]),
            rtol=1e-12,
            atol=1e-12,
        )


# the mode-probability detector reads a filter's posterior probabilities, not a sensor: a
# dead sensor reaches it as the filter's dead report (monitor.filter_detector applies
# chi2.flag_dead), and a NaN probability is broken numerics, which the records count as
# unhealthy (metrics.step_health), not as an alarm
@pytest.mark.parametrize("bad", [np.inf, np.nan], ids=["inf", "nan"])
@pytest.mark.parametrize("name", sorted(set(DETECTORS) - {"mode_probability_detector"}))
def test_every_detector_alarms_on_a_dead_input(name, bad):
    """A non-finite input mid-stream alarms at that step: a dead sensor is never silent."""
    case = DETECTORS[name]
    detector = case.make()
    values = case.quiet.at[6].set(case.dead(case.quiet[6], bad))
    _, decisions = jax.lax.scan(detector.step, detector.init(), values)
    assert bool(decisions.alarm[6])


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_every_detector_is_silent_far_below_its_threshold(name):
    case = DETECTORS[name]
    detector = case.make()
    _, decisions = jax.lax.scan(detector.step, detector.init(), case.quiet)
    assert not bool(jnp.any(decisions.alarm))
    assert bool(jnp.all(jnp.isfinite(decisions.statistic)))
