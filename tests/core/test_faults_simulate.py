"""Faults and the scan simulator against closed forms, a NumPy loop and sample statistics."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxfdi
from jaxfdi import FaultKind, Target, fault, fault_label, is_active, stack_faults
from jaxfdi._simulation.faults import apply_fault
from jaxfdi.models import engine_model

STEPS = np.arange(12)
NOMINAL = np.array([2.0, -3.0, 0.5])


def closed_form(kind, k, s, onset, magnitude, slope, end):
    """Component value of a faulty signal written out case by case (the module table)."""
    if kind == "impulse":
        return s + magnitude if k == onset else s
    if not onset <= k < end:
        return s
    return {
        "bias": s + magnitude,
        "ramp": s + magnitude + slope * (k - onset),
        "scale": (1 + magnitude) * s,
        "effectiveness": (1 - magnitude) * s,
    }[kind]


@pytest.mark.parametrize("kind", ["bias", "ramp", "impulse", "scale", "effectiveness"])
@pytest.mark.parametrize("target", ["actuator", "sensor"])
def test_apply_fault_matches_closed_form(kind, target):
    f = fault(kind, target, 1, onset=4, magnitude=0.3, slope=0.05, end=9)
    signal_target = Target[target.upper()]
    other = Target.SENSOR if signal_target == Target.ACTUATOR else Target.ACTUATOR
    for k in STEPS:
        signal = jnp.asarray(NOMINAL * (1 + 0.1 * k))  # time-varying nominal signal
        faulty, _ = apply_fault(f, k, signal, signal_target, jnp.zeros(()))
        expected = np.asarray(signal).copy()
        expected[1] = closed_form(kind, k, float(signal[1]), 4, 0.3, 0.05, 9)
        np.testing.assert_allclose(faulty, expected, rtol=1e-15, err_msg=f"k={k}")
        untouched, _ = apply_fault(f, k, signal, other, jnp.zeros(()))
        np.testing.assert_array_equal(untouched, signal)


def test_stuck_holds_the_value_at_onset_until_end():
    f = fault("stuck", "sensor", 2, onset=3, end=8)
    held = jnp.zeros(())
    for k in STEPS:
        signal = jnp.asarray(NOMINAL + k)
        faulty, held = apply_fault(f, k, signal, Target.SENSOR, held)
        expected = np.asarray(signal).copy()
        if 3 <= k < 8:
            expected[2] = NOMINAL[2] + 3
        np.testing.assert_array_equal(faulty, expected)


def test_labels_and_activity():
    n_inputs = 1
    assert int(fault_label(jaxfdi.no_fault(), n_inputs)) == 0
    assert int(fault_label(fault("bias", "actuator", 0, 5), n_inputs)) == 1
    assert [int(fault_label(fault("bias", "sensor", j, 5), n_inputs)) for j in range(5)] == [
        2,
        3,
        4,
        5,
        6,
    ]
    f = fault("bias", "sensor", 0, onset=5, end=7)
    assert [bool(is_active(f, k)) for k in range(9)] == [False] * 5 + [True, True, False, False]
    assert not any(bool(is_active(jaxfdi.no_fault(), k)) for k in range(9))


def numpy_plant(model, x0, us, faults):
    """Noise-free reference loop: actuator faults on u before f, sensor faults on y."""
    Phi, Gamma, C, D = (np.asarray(a) for a in model[:4])
    x, xs, ys = np.asarray(x0, float), [], []
    stuck = {}
    for k, u in enumerate(us):
        u_applied, y = u.copy(), C @ x + D @ u
        for f in faults:
            sig = u_applied if f["target"] == "actuator" else y
            j = f["component"]
            if f["kind"] == "stuck":
                if k == f["onset"]:
                    stuck[id(f)] = sig[j]
                if f["onset"] <= k < f.get("end", 10**9):
                    sig[j] = stuck[id(f)]
            else:
                sig[j] = closed_form(
                    f["kind"],
                    k,
                    sig[j],
                    f["onset"],
                    f.get("magnitude", 0.0),
                    f.get("slope", 0.0),
                    f.get("end", 10**9),
                )
        xs.append(x.copy())
        ys.append(y)
        x = Phi @ x + Gamma @ u_applied
    return np.array(xs), np.array(ys)


def test_noise_free_simulation_equals_numpy_loop_with_simultaneous_faults():
    model = engine_model()
    model = model._replace(Q=jnp.zeros((7, 7)), R=jnp.zeros((5, 5)))
    T = 60
    us = np.full((T, 1), 0.01) + 0.002 * np.sin(0.3 * np.arange(T))[:, None]
    spec = [
        dict(kind="effectiveness", target="actuator", component=0, onset=10, magnitude=0.4),
        dict(
            kind="ramp", target="sensor", component=3, onset=20, magnitude=0.1, slope=0.02, end=50
        ),
        dict(kind="stuck", target="sensor", component=1, onset=30),
    ]
    faults = stack_faults([fault(**d) for d in spec])
    _, truth, moved = jaxfdi.simulate(
        jaxfdi.linear_simulator(model, faults), jnp.zeros(7), us, jax.random.key(0)
    )
    xs, ys = numpy_plant(model, np.zeros(7), us, spec)
    np.testing.assert_allclose(truth.state, xs, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(truth.measurement, ys, rtol=1e-12, atol=1e-15)
    # labels: mode is the first active fault of the stack, 0 before any onset
    expected_mode = np.where(np.arange(T) >= 10, 1, 0)
    np.testing.assert_array_equal(truth.mode, expected_mode)
    np.testing.assert_array_equal(
        truth.fault_active[:, 1], (np.arange(T) >= 20) & (np.arange(T) < 50)
    )
    np.testing.assert_allclose(moved.actuator_fault[10:, 0], -0.4 * us[10:, 0], rtol=1e-12)
    assert np.all(truth.sensor_fault[:20, 3] == 0) and np.all(truth.sensor_fault[20:50, 3] != 0)


def test_noise_has_the_model_covariances():
    """Sample covariances of w[k] = x[k+1] - Phi x[k] - Gamma u[k] and v[k] = y[k] - C x[k] - D u[k]
    over 4000 steps x 8 runs lie within 5 standard errors of Q and R (entrywise Wishart
    variance (S_ij^2 + S_ii S_jj) / N)."""
    model = engine_model()
    T, runs = 4000, 8
    us = jnp.full((T, 1), 0.01)
    sim = jaxfdi.linear_simulator(model)
    truths = jax.vmap(lambda key: jaxfdi.simulate(sim, jnp.zeros(7), us, key)[1])(
        jax.random.split(jax.random.key(3), runs)
    )
    x, y = np.asarray(truths.state), np.asarray(truths.measurement)
    Phi, Gamma, C, D = (np.asarray(a) for a in model[:4])
    w = (x[:, 1:] - x[:, :-1] @ Phi.T - np.asarray(us)[None, :-1] @ Gamma.T).reshape(-1, 7)
    v = (y - x @ C.T - np.asarray(us)[None] @ D.T).reshape(-1, 5)
    for sample, cov in ((w, np.asarray(model.Q)), (v, np.asarray(model.R))):
        N = sample.shape[0]
        sample_cov = sample.T @ sample / N
        stderr = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / N)
        assert np.all(np.abs(sample_cov - cov) <= 5 * stderr + 1e-30), np.max(
            np.abs(sample_cov - cov) / stderr
        )
        # whiteness across steps: lag-1 correlation of the first component is N(0, 1/N)
        z = sample[:, 0].reshape(runs, -1)
        lag1 = np.mean(z[:, 1:] * z[:, :-1]) / np.mean(z**2)
        assert abs(lag1) < 5 / np.sqrt(z.size)
    assert stats.normaltest(v[:, 0]).pvalue > 1e-4


def test_noise_is_per_step_reproducible():
    """Noise for step k comes from fold_in(key, k): a shorter run is a prefix of a longer one."""
    model = engine_model()
    sim = jaxfdi.linear_simulator(model, fault("bias", "sensor", 0, 5, 10.0))
    key = jax.random.key(11)
    _, long, _ = jaxfdi.simulate(sim, jnp.zeros(7), jnp.full((40, 1), 0.01), key)
    _, short, _ = jaxfdi.simulate(sim, jnp.zeros(7), jnp.full((25, 1), 0.01), key)
    np.testing.assert_array_equal(long.measurement[:25], short.measurement)


def test_fault_batches_vmap_like_data():
    """A batch of faults (kinds, components, magnitudes) vmaps through the simulator and
    each run equals its own un-batched simulation."""
    model = engine_model()
    us = jnp.full((30, 1), 0.01)
    faults = [
        fault("bias", "sensor", 2, 10, 1.5),
        fault("scale", "sensor", 0, 5, 0.2),
        fault("effectiveness", "actuator", 0, 0, 1.0),
        jaxfdi.no_fault(),
    ]
    key = jax.random.key(2)
    run = lambda f: jaxfdi.simulate(jaxfdi.linear_simulator(model, f), jnp.zeros(7), us, key)[1:]
    batched, moved = jax.jit(jax.vmap(run))(stack_faults(faults))
    for i, f in enumerate(faults):
        single, _ = run(f)
        np.testing.assert_allclose(
            batched.measurement[i], single.measurement, rtol=1e-13, atol=1e-13
        )
    assert int(FaultKind.EFFECTIVENESS) == int(faults[2].kind)
    # a total loss of effectiveness means the actuator applies nothing
    np.testing.assert_array_equal(moved.applied_input[2], 0.0)
