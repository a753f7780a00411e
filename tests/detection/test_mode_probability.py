"""Mode-probability decision (seed 003 eq. 13, with optional confirmation) against a
plain Python loop over random probability sequences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi.detection import mode_probability_detector


def _reference(mu, estimates, threshold, confirm, normal=0):
    """Step by step: the top fault mode, how long it has stayed >= its threshold, the alarm."""
    candidate, held, out = -1, 0, []
    for p, e in zip(mu, estimates):
        fault = p.copy()
        fault[normal] = -np.inf
        label = int(np.argmax(fault))
        if fault[label] >= np.broadcast_to(threshold, p.shape)[label]:
            held = held + 1 if label == candidate else 1
            candidate = label
        else:
            held, candidate = 0, -1
        out.append(
            (fault[label], held >= np.broadcast_to(confirm, p.shape)[label], label, e[label])
        )
    return [np.array(column) for column in zip(*out)]


@pytest.mark.parametrize("confirm", [1, 3])
@pytest.mark.parametrize("normal", [0, 2])
def test_equals_reference_loop(confirm, normal):
    rng = np.random.default_rng(confirm + 10 * normal)
    T, M = 300, 5
    # sticky random modes so that runs of the same top mode occur
    logits = np.cumsum(rng.normal(size=(T, M)) * 0.8, axis=0)
    mu = np.exp(logits - logits.max(1, keepdims=True))
    mu /= mu.sum(1, keepdims=True)
    estimates = rng.normal(size=(T, M))
    det = mode_probability_detector(0.5, normal_mode=normal, confirm_steps=confirm)
    _, decision = jax.jit(lambda xs: jax.lax.scan(det.step, det.init(), xs))(
        (jnp.asarray(mu), jnp.asarray(estimates))
    )
    statistic, alarm, label, estimate = _reference(mu, estimates, 0.5, confirm, normal)
    assert alarm.any() and not alarm.all()
    np.testing.assert_allclose(decision.statistic, statistic, rtol=1e-12)
    np.testing.assert_array_equal(decision.alarm, alarm)
    np.testing.assert_array_equal(decision.label, label)
    np.testing.assert_allclose(decision.estimate, estimate, rtol=1e-12)


@pytest.mark.parametrize("confirm", [1, 2])
def test_per_mode_thresholds_equal_reference_loop(confirm):
    rng = np.random.default_rng(confirm)
    T, M = 300, 5
    mu = rng.dirichlet(np.full(M, 0.5), size=T)  # persistent, mid-range probabilities
    for k in range(1, T):
        mu[k] = 0.7 * mu[k - 1] + 0.3 * mu[k]
    estimates = rng.normal(size=(T, M))
    threshold = np.array([1.0, 0.35, 0.6, 0.9, 0.5])  # the normal mode's entry is not used
    det = mode_probability_detector(jnp.asarray(threshold), confirm_steps=confirm)
    _, decision = jax.jit(lambda xs: jax.lax.scan(det.step, det.init(), xs))(
        (jnp.asarray(mu), jnp.asarray(estimates))
    )
    _, alarm, label, _ = _reference(mu, estimates, threshold, confirm)
    scalar = _reference(mu, estimates, 0.5, confirm)[1]
    assert alarm.any() and not np.array_equal(alarm, scalar)  # the per-mode levels matter here
    np.testing.assert_array_equal(decision.alarm, alarm)
    np.testing.assert_array_equal(decision.label, label)


def test_per_mode_confirmation_equals_reference_loop():
    """One confirmation length per mode: mode j alarms once it has led for c_j steps."""
    rng = np.random.default_rng(7)
    T, M = 400, 5
    logits = np.cumsum(rng.normal(size=(T, M)) * 0.8, axis=0)
    mu = np.exp(logits - logits.max(1, keepdims=True))
    mu /= mu.sum(1, keepdims=True)
    estimates = rng.normal(size=(T, M))
    confirm = np.array([1, 4, 1, 2, 3])  # the normal mode's entry is not used
    det = mode_probability_detector(0.5, confirm_steps=confirm)
    _, decision = jax.jit(lambda xs: jax.lax.scan(det.step, det.init(), xs))(
        (jnp.asarray(mu), jnp.asarray(estimates))
    )
    _, alarm, label, _ = _reference(mu, estimates, 0.5, confirm)
    for uniform in (
        1,
        4,
    ):  # neither uniform length gives these decisions: the per-mode lengths matter
        assert not np.array_equal(alarm, _reference(mu, estimates, 0.5, uniform)[1])
    np.testing.assert_array_equal(decision.alarm, alarm)
    np.testing.assert_array_equal(decision.label, label)


@pytest.mark.parametrize("confirm", [0, 1.5, [1, 0, 2], [[1, 2]], []])
def test_bad_confirm_steps_raise(confirm):
    with pytest.raises(
        (ValueError, TypeError), match="confirm_steps: expected an integer >= 1, or one per mode"
    ):
        mode_probability_detector(0.5, confirm_steps=confirm)


def test_per_mode_confirmation_of_the_wrong_length_raises_at_trace_time():
    det = mode_probability_detector(0.5, confirm_steps=[1, 2, 3])
    with pytest.raises(ValueError, match=r"confirm_steps: expected shape \(5,\)"):
        jax.jit(lambda mu: det.step(det.init(), mu))(jnp.full(5, 0.2))


def test_confirmation_delays_and_filters_flicker():
    """A fault mode above mu_T for 2 steps, then another for 3: confirm 3 alarms only on
    the third step of the second, confirm 1 at once."""
    mu = np.full((8, 3), 0.0)
    mu[:, 0] = 1.0
    mu[1:3] = [0.2, 0.8, 0.0]
    mu[3:6] = [0.2, 0.0, 0.8]
    for confirm, first in ((1, 1), (3, 5)):
        det = mode_probability_detector(0.5, confirm_steps=confirm)
        _, decision = jax.lax.scan(det.step, det.init(), jnp.asarray(mu))
        alarm = np.asarray(decision.alarm)
        assert int(np.argmax(alarm)) == first and np.asarray(decision.label)[first] == (
            1 if confirm == 1 else 2
        )
        assert np.isnan(np.asarray(decision.estimate)).all()


def test_bad_input():
    for threshold in (0.0, 1.5, -0.1):
        with pytest.raises(ValueError, match="^threshold:"):
            mode_probability_detector(threshold)
    for confirm in (0, 2.5):
        with pytest.raises((ValueError, TypeError), match="^confirm_steps:"):
            mode_probability_detector(0.5, confirm_steps=confirm)
    with pytest.raises(ValueError, match="^threshold:"):
        mode_probability_detector(np.array([0.5, 0.0, 0.7]))
    det = mode_probability_detector(jnp.full(4, 0.5))
    with pytest.raises(ValueError, match=r"^threshold: expected shape \(3,\)"):
        det.step(det.init(), jnp.ones(3) / 3)
    det = mode_probability_detector(0.5)
    with pytest.raises(ValueError, match="^mode_prob:"):
        det.step(det.init(), jnp.ones((2, 3)) / 3)
    with pytest.raises(ValueError, match="^normal_mode:"):
        det = mode_probability_detector(0.5, normal_mode=4)
        det.step(det.init(), jnp.ones(3) / 3)
