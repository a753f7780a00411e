"""Tuning: parameterisations (round trips, validity at extremes), losses (finite
differences, the hard-decision limit against a brute-force count), the optax loop
(early stopping, save/load) and maximum-likelihood recovery of known Q and R."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from jax.test_util import check_grads

import jaxfdi
from jaxfdi import tuning
from jaxfdi.models import LinearGaussianModel, noise_inflation_modes

PAPER_PI = np.array([[0.94, 0.03, 0.03], [0.05, 0.95, 0.00], [0.01, 0.00, 0.99]])


# ---------------------------------------------------------------- parameterisations
@pytest.mark.parametrize("scale", [1.0, 50.0, 1e3])
def test_stochastic_rows_valid_at_extreme_logits_and_structural_zeros_stay_zero(scale):
    rng = np.random.default_rng(0)
    mask = PAPER_PI > 0
    t = tuning.stochastic_rows(mask)
    pi = np.asarray(t.forward(jnp.asarray(scale * rng.normal(size=(3, 3)))))
    assert np.all(np.isfinite(pi)) and np.all(pi >= 0)
    np.testing.assert_allclose(pi.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(pi[~mask] == 0.0)
    grads = jax.grad(lambda l: jnp.sum(t.forward(l) ** 2))(jnp.asarray(rng.normal(size=(3, 3))))
    assert np.all(np.isfinite(grads)) and np.all(np.asarray(grads)[~mask] == 0.0)
    p = np.asarray(tuning.simplex().forward(jnp.asarray(scale * rng.normal(size=7))))
    assert np.all(np.isfinite(p)) and np.all(p >= 0) and abs(p.sum() - 1.0) < 1e-12


def test_every_transform_round_trips():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(4, 4))
    cov = a @ a.T + 0.1 * np.eye(4)
    cases = [
        (tuning.stochastic_rows(PAPER_PI > 0), PAPER_PI),
        (tuning.stochastic_rows(), np.full((3, 3), 1 / 3)),
        (
            tuning.stochastic_rows(),
            np.array([[0.9, 0.1, 0.0], [0.0, 1.0, 0.0], [0.2, 0.0, 0.8]]),
        ),  # allowed zeros
        (tuning.simplex(), np.array([0.94, 0.01, 0.05, 0.0])),
        (tuning.log_diagonal(), np.diag([1e-8, 1.0, 1e6])),
        (tuning.cholesky_factor(), cov),
        (tuning.positive(), np.array([1e-8, 0.5, 30.0, 1e3])),
        (tuning.positive(floor=1.0), np.array([1.0 + 1e-6, 2.0, 1e4])),
        (jaxfdi.tuning._parameterize.log_scale(), np.array([1e-12, 1.0, 1e4])),
        (jaxfdi.tuning._parameterize.identity(), np.array([-3.0, 4.0])),
        (tuning.unit_interval(), np.array([1e-9, 0.5, 1 - 1e-9])),
    ]
    for t, value in cases:
        np.testing.assert_allclose(
            t.forward(t.inverse(jnp.asarray(value))), value, rtol=1e-9, atol=1e-14, err_msg=t.name
        )
    raw = rng.normal(size=(4, 4))  # unconstrained -> constrained -> unconstrained
    t = tuning.cholesky_factor()
    np.testing.assert_allclose(t.inverse(t.forward(raw)), np.tril(raw), rtol=1e-10, atol=1e-12)
    for t in (tuning.positive(), jaxfdi.tuning._parameterize.log_scale()):
        np.testing.assert_allclose(
            t.inverse(t.forward(jnp.array([-20.0, 0.0, 30.0]))),
            [-20.0, 0.0, 30.0],
            rtol=1e-9,
            err_msg=t.name,
        )


@pytest.mark.parametrize("scale", [1.0, 10.0])
def test_covariance_transforms_give_symmetric_positive_definite_matrices(scale):
    rng = np.random.default_rng(2)
    for t, shape in [(tuning.cholesky_factor(), (5, 5)), (tuning.log_diagonal(), (5,))]:
        cov = np.asarray(t.forward(jnp.asarray(scale * rng.normal(size=shape))))
        np.testing.assert_array_equal(cov, cov.T)
        assert np.linalg.eigvalsh(cov).min() > 0


def test_partition_constrain_and_bad_names():
    parameterization = {"pi": tuning.stochastic_rows(), "h": tuning.positive()}
    raw = tuning.unconstrain(parameterization, {"pi": PAPER_PI, "h": 2.0})
    train, frozen = jaxfdi.tuning._parameterize.partition(raw, ["h"])
    assert list(train) == ["h"] and list(frozen) == ["pi"]
    np.testing.assert_allclose(
        tuning.constrain(parameterization, jaxfdi.tuning._parameterize.merge(train, frozen))["h"],
        2.0,
    )
    with pytest.raises(ValueError, match="trainable: unknown names"):
        jaxfdi.tuning._parameterize.partition(raw, ["nope"])
    with pytest.raises(ValueError, match="no transform for"):
        tuning.constrain({"h": tuning.positive()}, raw)
    with pytest.raises(ValueError, match="mask: expected at least one allowed"):
        tuning.stochastic_rows(np.eye(3, dtype=bool) & False)
    with pytest.raises(ValueError, match="logits"):
        tuning.simplex().forward(jnp.zeros((3, 3)))


# ---------------------------------------------------------------- losses
def small_model():
    return LinearGaussianModel(
        Phi=jnp.array([[0.9, 0.1], [0.0, 0.8]]),
        Gamma=jnp.array([[0.0], [1.0]]),
        C=jnp.eye(2),
        D=jnp.zeros((2, 1)),
        Q=jnp.diag(jnp.array([0.5, 0.2])),
        R=jnp.diag(jnp.array([1.0, 0.3])),
    )


def small_data(num_runs, T, seed):
    model = small_model()
    us = jnp.zeros((T, 1))
    keys = jax.random.split(jax.random.key(seed), num_runs)
    sim = jaxfdi.linear_simulator(model)
    return jax.vmap(lambda k: jaxfdi.simulate(sim, jnp.zeros(2), us, k)[1].measurement)(keys), us


def kf_nll(raw, batch):
    ys, us = batch
    model = small_model()._replace(
        Q=jnp.diag(jnp.exp(raw["log_q"])), R=jnp.diag(jnp.exp(raw["log_r"]))
    )
    kf = jaxfdi.filters.kalman_filter(model)

    def one(y):
        _, info = jaxfdi.filters.run_filter(kf, kf.init(jnp.zeros(2), model.Q), y, us)
        return tuning.innovation_nll(info.log_likelihood)

    return jnp.mean(jax.vmap(one)(ys))


def test_innovation_nll_gradient_matches_finite_differences_and_equals_exact_likelihood():
    ys, us = small_data(2, 30, 0)
    raw = {"log_q": jnp.log(jnp.array([0.3, 0.4])), "log_r": jnp.log(jnp.array([2.0, 0.1]))}
    check_grads(lambda r: kf_nll(r, (ys, us)), (raw,), order=1, modes=["rev"], atol=1e-6, rtol=1e-6)
    # the KF's prediction-error decomposition equals the joint Gaussian density of y[0:T]
    T = 6
    model = small_model()
    blocks = [[None] * T for _ in range(T)]
    Phi, C = np.asarray(model.Phi), np.asarray(model.C)
    covs_x = [np.asarray(model.Q)]
    for k in range(1, T):
        covs_x.append(Phi @ covs_x[-1] @ Phi.T + np.asarray(model.Q))
    for i in range(T):
        for j in range(T):
            lag = np.linalg.matrix_power(Phi, abs(i - j))
            cross = lag @ covs_x[min(i, j)] if i >= j else covs_x[min(i, j)] @ lag.T
            blocks[i][j] = C @ cross @ C.T + (np.asarray(model.R) if i == j else 0.0)
    Sigma = np.block(blocks)
    y = np.asarray(ys[0, :T]).ravel()
    exact = -0.5 * (
        y @ np.linalg.solve(Sigma, y) + np.linalg.slogdet(Sigma)[1] + y.size * np.log(2 * np.pi)
    )
    got = -T * kf_nll(
        {"log_q": jnp.log(jnp.diag(model.Q)), "log_r": jnp.log(jnp.diag(model.R))},
        (ys[:1, :T], us[:T]),
    )
    np.testing.assert_allclose(got, exact, rtol=1e-10)


def test_mode_cross_entropy_matches_direct_formula_and_gradients_through_an_imm():
    model = small_model()
    modes = noise_inflation_modes(model, 100.0, 0.5)  # 1 + 1 + 2 = 4 modes
    mask = np.ones((4, 4), bool)
    pi_t = tuning.stochastic_rows(mask)
    ys, us = small_data(1, 40, 3)
    labels = jnp.concatenate([jnp.zeros(20, jnp.int32), jnp.full(20, 2, jnp.int32)])

    def loss(raw):
        m = noise_inflation_modes(model, jnp.exp(raw["log_inflation"]), 0.5)
        imm = jaxfdi.filters.interacting_multiple_model(
            jaxfdi.filters.kalman_filter, m, pi_t.forward(raw["logits"])
        )
        _, info = jaxfdi.filters.run_filter(
            imm, imm.init(jnp.zeros(2), model.Q, jnp.full(4, 0.25)), ys[0], us
        )
        return tuning.mode_cross_entropy(info.log_mode_prob, labels)

    raw = {
        "logits": jnp.log(jnp.full((4, 4), 0.02) + 0.9 * jnp.eye(4)),
        "log_inflation": jnp.log(100.0),
    }
    check_grads(loss, (raw,), order=1, modes=["rev"], atol=1e-6, rtol=1e-5)
    imm = jaxfdi.filters.interacting_multiple_model(
        jaxfdi.filters.kalman_filter, modes, pi_t.forward(raw["logits"])
    )
    _, info = jaxfdi.filters.run_filter(
        imm, imm.init(jnp.zeros(2), model.Q, jnp.full(4, 0.25)), ys[0], us
    )
    direct = -np.mean(np.log(np.asarray(info.mode_prob)[np.arange(40), np.asarray(labels)] + 1e-12))
    np.testing.assert_allclose(loss(raw), direct, rtol=1e-9)
    with pytest.raises(ValueError, match="true_mode: expected shape"):
        tuning.mode_cross_entropy(info.log_mode_prob, labels[:5])


def brute_force_rates(alarms, onset, wrong_label):
    T = alarms.size
    false_alarm = float(alarms[:onset].any())
    after = np.flatnonzero(alarms[onset:])
    missed = float(after.size == 0) if onset < T else 0.0
    delay = (after[0] if after.size else T - onset) if onset < T else 0.0
    misisolated = float(after.size > 0 and wrong_label[onset + after[0]]) if onset < T else 0.0
    return false_alarm, missed, delay, misisolated


def test_soft_detection_loss_tends_to_the_hard_counts_and_has_correct_gradients():
    rng = np.random.default_rng(4)
    T = 50
    for trial in range(20):
        statistic = rng.normal(size=T) + np.where(np.arange(T) >= 30, rng.uniform(0, 3), 0.0)
        onset = int(rng.choice([30, 10_000]))  # faulty or fault-free
        h = 1.5
        statistic[np.abs(statistic - h) < 1e-3] += 0.01  # keep away from the threshold itself
        margin = rng.normal(size=T)  # the label an alarm would carry is wrong where margin > 0
        margin[np.abs(margin) < 1e-3] += 0.01
        _, parts = tuning.soft_detection_loss(
            jnp.asarray(statistic),
            h,
            onset,
            temperature=1e-6,
            wrong_label_margin=jnp.asarray(margin),
        )
        expected = brute_force_rates(statistic >= h, min(onset, T), margin > 0)
        np.testing.assert_allclose(
            [parts[k] for k in ("false_alarm", "missed", "delay", "misisolated")],
            expected,
            atol=1e-6,
            err_msg=f"trial {trial}",
        )
    s = jnp.asarray(rng.normal(size=T) + np.where(np.arange(T) >= 30, 1.0, 0.0))
    margin = jnp.asarray(rng.normal(size=T))

    def loss(h, temp, s, margin):
        return tuning.soft_detection_loss(s, h, 30, temp, 2.0, 1.0, 0.5, margin, 3.0)[0]

    check_grads(loss, (1.2, 0.7, s, margin), order=1, modes=["rev"], atol=1e-7, rtol=1e-6)


def test_soft_detection_expected_delay_matches_monte_carlo_of_independent_alarms():
    """The surrogate is the exact expectation when the alarms are independent Bernoulli(a_k)."""
    rng = np.random.default_rng(5)
    T, onset, h, temp = 40, 15, 0.5, 0.8
    s = rng.normal(size=T)
    a = 1 / (1 + np.exp(-(s - h) / temp))
    alarms = rng.random((200_000, T)) < a
    fa = alarms[:, :onset].any(axis=1).mean()
    after = alarms[:, onset:]
    first = np.where(after.any(axis=1), after.argmax(axis=1), T - onset)
    _, parts = tuning.soft_detection_loss(jnp.asarray(s), h, onset, temp)
    # 200k samples: standard errors < 0.0012 (probabilities) and < 0.03 steps (delay)
    np.testing.assert_allclose(parts["false_alarm"], fa, atol=0.005)
    np.testing.assert_allclose(parts["missed"], (~after.any(axis=1)).mean(), atol=0.005)
    np.testing.assert_allclose(parts["delay"], first.mean(), atol=0.1)


# ---------------------------------------------------------------- training loop
@pytest.fixture(scope="module")
def ml_fit():
    """Maximum likelihood of log-diagonal Q and R from a wrong start (x10 / x0.1)."""
    train = small_data(16, 500, 10)
    val = small_data(4, 500, 11)
    parameterization = {"Q": tuning.log_diagonal(), "R": tuning.log_diagonal()}
    start = {"Q": 10.0 * small_model().Q, "R": 0.1 * small_model().R}
    raw0 = tuning.unconstrain(parameterization, start)

    def loss(raw, batch):
        return kf_nll({"log_q": raw["Q"], "log_r": raw["R"]}, batch)

    runs = jaxfdi.tuning._train.fixed_batches(
        train[0], 8, jax.random.key(0)
    )  # mini-batches of 8 of the 16 runs
    result = tuning.fit(
        loss,
        raw0,
        optax.adam(0.05),
        lambda step: (runs(step), train[1]),
        val,
        steps=300,
        eval_every=20,
        patience=4,
    )
    return result, parameterization


def test_maximum_likelihood_recovers_q_and_r_within_ten_percent(ml_fit):
    result, parameterization = ml_fit
    tuned = tuning.constrain(parameterization, result.raw)
    true = small_model()
    np.testing.assert_allclose(np.diag(tuned["Q"]), np.diag(true.Q), rtol=0.10)
    np.testing.assert_allclose(np.diag(tuned["R"]), np.diag(true.R), rtol=0.10)
    h = result.history
    assert h.val_loss[0] > h.val_loss.min() and h.best_step > 0


def test_fit_keeps_the_best_validation_step_and_stops_early():
    """A loss whose training batches pull away from the validation optimum: the returned
    parameters are the best-validation ones, and training stops after `patience`."""

    def loss(raw, target):
        return (raw["x"] - target) ** 2

    result = tuning.fit(
        loss,
        {"x": jnp.array(0.0), "fixed": jnp.array(5.0)},
        optax.sgd(0.1),
        lambda step: 3.0,
        1.0,
        steps=200,
        trainable=["x"],
        eval_every=1,
        patience=3,
    )
    h = result.history
    assert h.stopped_early and h.step[-1] < 200
    assert h.val_loss.min() == pytest.approx((float(result.raw["x"]) - 1.0) ** 2)
    assert float(result.raw["fixed"]) == 5.0


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_and_load_round_trip_with_the_parameterisation(tmp_path, suffix):
    parameterization = {
        "pi": tuning.stochastic_rows(PAPER_PI > 0),
        "Q": tuning.cholesky_factor(),
        "h": tuning.positive(floor=1.0),
    }
    params = {"pi": PAPER_PI, "Q": np.array([[2.0, 0.3], [0.3, 1.0]]), "h": np.array(4.0)}
    raw = tuning.unconstrain(parameterization, params)
    path = tuning.save_params(tmp_path / f"tuned{suffix}", raw, parameterization, {"note": "test"})
    raw2, parameterization2, meta = tuning.load_params(path)
    assert meta == {"note": "test"} and parameterization2["h"].options == {"floor": 1.0}
    back = tuning.constrain(parameterization2, raw2)
    for k in params:
        np.testing.assert_allclose(back[k], params[k], rtol=1e-12, atol=1e-15)
    assert not list(tmp_path.glob(".*"))  # no temp file left behind
    with pytest.raises(ValueError, match="expected a .json or .npz"):
        tuning.save_params(tmp_path / "x.txt", raw, parameterization)


def test_a_corrupted_parameter_file_names_the_file_and_the_problem(tmp_path):
    """Truncated, not a zip, a field missing, and a good file renamed to the other format:
    each a ValueError naming the file (never a bare zip, JSON or pickle error)."""
    parameterization = {"h": tuning.positive(floor=1.0)}
    raw = tuning.unconstrain(parameterization, {"h": np.array(4.0)})
    good = tuning.save_params(tmp_path / "good.npz", raw, parameterization)
    cases = {
        "truncated.npz": good.read_bytes()[: len(good.read_bytes()) // 2],
        "text.npz": b"not a zip file",
        "missing.json": b'{"params": {}, "meta": {}}',
        "cut.json": b'{"params": {"h": [1.0',
        "swapped.json": good.read_bytes(),
    }
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(
            ValueError, match=f"{name}: not a parameter file written by save_params"
        ):
            tuning.load_params(path)
    with pytest.raises(ValueError, match="missing field 'parameterization'"):
        tuning.load_params(tmp_path / "missing.json")
    with pytest.raises(FileNotFoundError):
        tuning.load_params(tmp_path / "absent.npz")


def test_fixed_batches_visit_every_run_once_per_epoch():
    data = {"y": jnp.arange(12.0)}
    batch = jaxfdi.tuning._train.fixed_batches(data, 4, jax.random.key(0))
    seen = np.concatenate([np.asarray(batch(s)["y"]) for s in range(3)])
    np.testing.assert_array_equal(np.sort(seen), np.arange(12.0))
    with pytest.raises(ValueError, match="batch_size"):
        jaxfdi.tuning._train.fixed_batches(data, 13, jax.random.key(0))


def test_checkpointed_filter_gives_the_same_gradient():
    ys, us = small_data(1, 50, 7)
    model = small_model()

    def loss(log_q, remat):
        kf = jaxfdi.filters.kalman_filter(model._replace(Q=jnp.diag(jnp.exp(log_q))))
        kf = jaxfdi.tuning._train.checkpointed(kf) if remat else kf
        _, info = jaxfdi.filters.run_filter(kf, kf.init(jnp.zeros(2), model.Q), ys[0], us)
        return tuning.innovation_nll(info.log_likelihood)

    q = jnp.log(jnp.array([0.5, 0.2]))
    np.testing.assert_allclose(jax.grad(loss)(q, True), jax.grad(loss)(q, False), rtol=1e-12)


def test_checkpointed_mode_filters_rematerialise_inside_an_imm():
    """An IMM mixes between its modes' ``update`` and ``predict``, not their ``step``: ``checkpointed`` wraps the
    halves too, so an IMM built from checkpointed modes rematerialises them (a ``checkpoint`` in its step's
    program) and gives the plain IMM's gradient."""
    ys, us = small_data(1, 40, 7)
    model = small_model()
    # two modes, the second with 9x the process noise, stacked on a leading mode axis
    mode_params = jax.tree.map(lambda *m: jnp.stack(m), model, model._replace(Q=9.0 * model.Q))
    pi = jnp.array([[0.95, 0.05], [0.1, 0.9]])
    kf = jaxfdi.filters.kalman_filter
    plain = jaxfdi.filters.interacting_multiple_model(kf, mode_params, pi)
    remat = jaxfdi.filters.interacting_multiple_model(
        lambda p: jaxfdi.tuning.checkpointed(kf(p)), mode_params, pi
    )
    init = (jnp.zeros(2), model.Q, jnp.array([0.5, 0.5]))
    step_program = str(jax.make_jaxpr(remat.step)(remat.init(*init), ys[0, 0], us[0]))
    assert "checkpoint" in step_program or "remat" in step_program
    assert "checkpoint" not in str(jax.make_jaxpr(plain.step)(plain.init(*init), ys[0, 0], us[0]))

    def loss(scale, filt):  # two steps: the second mixes the first's rematerialised posteriors
        state = filt.init(jnp.zeros(2), model.Q * scale, jnp.array([0.5, 0.5]))
        state, first = filt.step(state, ys[0, 0], us[0])
        return first.log_likelihood + filt.step(state, ys[0, 1], us[1])[1].log_likelihood

    grad = jax.jit(jax.grad(loss), static_argnums=1)
    np.testing.assert_allclose(grad(1.5, remat), grad(1.5, plain), rtol=1e-12)
