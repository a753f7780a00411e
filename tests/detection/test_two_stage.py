"""``detection.two_stage`` (Choi & Park 2009's two-stage isolation) on a small nonlinear
model ``x' = -p x^3 + u`` (elementwise, so ``det A`` varies with the state), against the
same pieces composed by hand: the nominal EKF and the hypotheses' dual filters, the MM
filter and the isolators run step by step (tolerance 1e-12, float64).

- Until the engaging alarm the banks are the nominal posterior's restart at every step
  and the isolators stay idle (no alarm, fresh state).
- Engaged at the first step (``F_T < 0``, ``engage_on="fdp"``), each hypothesis's dual
  filter then runs on its own from the state left at that step (prediction restarted
  from its own posterior), and the credit isolator decides on its ``F_x`` from the next
  step, started fresh. (Which hypothesis the credits favour on this toy model is not
  tested here: isolation performance is the wheel scenario's tests'.)
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi.detection import dual_filter, two_stage_isolation
from jaxfdi.detection._credits import credit_isolator
from jaxfdi.filters import GaussianState, extended_kalman_filter, multiple_model

DT = 0.05


def field(x, u, p):
    return -p * x**3 + u


def transition(x, u, p):
    return x + DT * field(x, u, p)


def observe(x, u, p):
    return x


def ekf(p, q=1e-3):
    return extended_kalman_filter(transition, observe, q * jnp.eye(2), 1e-2 * jnp.eye(2), p)


HYPOTHESES = jnp.array([0.5, 2.0, 4.0])
MODES = jnp.array([1.0, 0.5, 2.0, 4.0])
ENGAGE = 1e-2 * jnp.eye(2)


def stages(**kw):
    options = dict(
        detection_threshold=1e30,
        nis_threshold=1e30,
        nis_window=3,
        credit_threshold=0.5,
        mode_threshold=0.9,
        mm_floor=1e-6,
        engage_cov=ENGAGE,
        confirm_steps=2,
    )
    options.update(kw)
    return two_stage_isolation(
        ekf(1.0, 1e-2), ekf, transition, field, jnp.asarray(1.0), HYPOTHESES, MODES, **options
    )


def data(steps=40):
    rng = np.random.default_rng(0)
    x, ys = np.array([1.0, -0.8]), []
    for _ in range(steps):
        x = (
            x + DT * (-2.0 * x**3 + 0.3) + 0.01 * rng.standard_normal(2)
        )  # the truth is hypothesis 2 (p = 2)
        ys.append(x + 0.1 * rng.standard_normal(2))
    return jnp.asarray(np.array(ys)), jnp.full((2,), 0.3)


def close(a, b):
    jax.tree_util.tree_map(
        lambda x, y: np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12), a, b
    )


def test_banks_are_slaved_to_the_nominal_posterior_until_engaged():
    fdi, (ys, u) = stages(), data()
    state = fdi.init(jnp.zeros(2), 0.1 * jnp.eye(2), u)
    nominal = dual_filter(ekf(1.0, 1e-2), transition, field, 1.0)
    reference = nominal.init(jnp.zeros(2), 0.1 * jnp.eye(2))
    step, nominal_step = jax.jit(fdi.step), jax.jit(nominal.step)
    for y in ys:
        state, out = step(state, y, u)
        reference, info = nominal_step(reference, y, u)
        start = GaussianState(info.estimator.filtered_mean, info.estimator.filtered_cov + ENGAGE)
        bank_prior = jax.vmap(lambda p: ekf(p).predict(start, u))(HYPOTHESES)
        close(state["bank"].estimator, bank_prior)
        close(state["bank"].prediction, bank_prior.mean)
        mode_prior = jax.vmap(lambda p: ekf(p).predict(start, u))(MODES)
        close(
            state["mm"],
            multiple_model(ekf, MODES, 1e-6).init(
                mode_prior.mean, mode_prior.cov, jnp.full(4, 0.25)
            ),
        )
        assert (
            not bool(out.engaged)
            and not bool(out.decisions[2].alarm)
            and not bool(out.decisions[3].alarm)
        )
        close(
            state["credit"],
            credit_isolator(0.5, relative=True, label_offset=1, confirm_steps=2).init(),
        )
        np.testing.assert_allclose(out.peaks[0], info.detection_parameter, rtol=1e-12)


def test_engaged_banks_run_on_their_own_and_the_credits_decide_from_the_next_step():
    fdi, (ys, u) = (
        stages(detection_threshold=0.0, engage_on="fdp"),
        data(),
    )  # F > 0: engaged at once
    state = fdi.init(jnp.zeros(2), 0.1 * jnp.eye(2), u)
    state, out = fdi.step(state, ys[0], u)
    assert not bool(out.engaged) and bool(state["engaged"])
    bank = state["bank"]  # left by the engaging step: the reference starts here
    credits = credit_isolator(0.5, relative=True, label_offset=1, confirm_steps=2)
    credit_state, credit_step = credits.init(), jax.jit(credits.step)
    step = jax.jit(fdi.step)
    banks = jax.jit(
        lambda b, y: jax.vmap(lambda p, s: dual_filter(ekf(p), transition, field, p).step(s, y, u))(
            HYPOTHESES, b
        )
    )
    for y in ys[1:]:
        state, out = step(state, y, u)
        bank, info = banks(bank, y)
        close(state["bank"], bank)
        close(out.hypothesis_parameter, info.detection_parameter)
        credit_state, decision = credit_step(credit_state, info.detection_parameter)
        assert bool(out.engaged) and bool(out.decisions[2].alarm) == bool(decision.alarm)
        assert int(out.decisions[2].label) == int(decision.label)


def test_bad_engage_choice_is_refused():
    with pytest.raises(ValueError, match="engage_on"):
        stages(engage_on="credit")
