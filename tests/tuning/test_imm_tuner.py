"""The generic IMM tuner (``tuning.tune_imm``) on a system that is none of the papers': a scalar AR(1) state seen by
a sensor whose noise switches between a quiet and a noisy mode by a known Markov chain. The likelihood-tuned
transition matrix recovers the generating one; filterpy's ``IMMEstimator`` with the tuned matrix gives the same mode
probabilities; saved and loaded parameters give the same IMM."""

import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

import jaxfdi
from jaxfdi import tuning
from jaxfdi.filters import kalman_filter, run_filter
from jaxfdi.models import LinearGaussianModel

PHI, Q = 0.95, 0.05
R_MODES = (0.05, 5.0)  # quiet and noisy sensor
TRUE = np.array([[0.96, 0.04], [0.12, 0.88]])
RUNS, STEPS = 24, 400


def simulate(seed: int, runs: int = RUNS):
    """Runs of the switching system by NumPy, an independent generator: (y, modes)."""
    rng = np.random.default_rng(seed)
    ys, modes = np.zeros((runs, STEPS, 1)), np.zeros((runs, STEPS), int)
    for r in range(runs):
        x, mode = 0.0, 0
        for k in range(STEPS):
            if k:
                mode = rng.choice(2, p=TRUE[mode])
            modes[r, k] = mode
            ys[r, k, 0] = x + rng.normal(0, np.sqrt(R_MODES[mode]))
            x = PHI * x + rng.normal(0, np.sqrt(Q))
    return ys, modes


def mode_models(params):
    one = jnp.ones((2, 1, 1))
    return LinearGaussianModel(
        PHI * one,
        jnp.zeros((2, 1, 0)),
        one,
        jnp.zeros((2, 1, 0)),
        Q * one,
        params["noise"][:, None, None],
    )


@pytest.fixture(scope="module")
def tuned():
    jaxfdi.enable_x64()
    problem = tuning.ImmProblem(
        kalman_filter,
        mode_models,
        {"transition": tuning.stochastic_rows(np.ones((2, 2), bool)), "noise": tuning.log_scale()},
        jnp.zeros(1),
        jnp.eye(1),
    )
    train, validation, test = (tuning.ImmData(y, None, m) for y, m in map(simulate, (0, 1, 2)))
    start = {"transition": jnp.array([[0.8, 0.2], [0.3, 0.7]]), "noise": jnp.asarray(R_MODES)}
    params, result = tuning.tune_imm(
        problem,
        start,
        train,
        validation,
        steps=150,
        learning_rate=0.1,
        trainable=["transition"],
        eval_every=10,
    )
    return problem, params, result, train, test


def test_likelihood_tuning_recovers_the_generating_transition_matrix(tuned):
    """24 runs x 400 steps (~330 switches out of the quiet mode): each off-diagonal entry within 3 standard errors
    of the complete-data estimate from the true labels (the counts' binomial error; the modes are nearly observed,
    R 0.05 against 5), and within 0.03 of the generating matrix."""
    _, params, result, train, _ = tuned
    pi = np.asarray(params["transition"])
    modes = np.asarray(train.modes)
    prev, nxt = modes[:, :-1].ravel(), modes[:, 1:].ravel()
    for i, j in ((0, 1), (1, 0)):
        n = np.sum(prev == i)
        counted = np.sum((prev == i) & (nxt == j)) / n
        se = np.sqrt(counted * (1 - counted) / n)
        assert abs(pi[i, j] - counted) < 3 * se, (i, j, pi[i, j], counted, se)
        assert abs(pi[i, j] - TRUE[i, j]) < 0.03, (i, j, pi[i, j])
    assert result.history.val_loss[result.history.best_step // 10] < result.history.val_loss[0]


def test_filterpy_imm_with_the_tuned_matrix_gives_the_same_mode_probabilities(tuned):
    problem, params, _, _, test = tuned
    pi = np.asarray(params["transition"], float)
    imm, state0 = tuning.imm_filter(problem, params)
    _, info = run_filter(imm, state0, test.measurements[0])
    filters = []
    for r in R_MODES:
        kf = KalmanFilter(dim_x=1, dim_z=1)
        kf.F, kf.H, kf.Q, kf.R = (
            np.array([[PHI]]),
            np.array([[1.0]]),
            np.array([[Q]]),
            np.array([[r]]),
        )
        kf.x, kf.P = np.zeros((1, 1)), np.eye(1)
        filters.append(kf)
    ref = IMMEstimator(filters, np.array([1.0, 0.0]), pi)
    want = []
    for y in np.asarray(test.measurements[0]):
        ref.update(y)  # y[k] on the prior of x[k] (step 0: cbar = mu @ M, as imm_filter's init)
        want.append(ref.mu.copy())
        ref.predict()
    np.testing.assert_allclose(np.asarray(info.mode_prob), np.array(want), rtol=1e-9, atol=1e-12)


def test_held_out_scores_have_intervals_and_the_tuned_matrix_beats_the_start(tuned):
    problem, params, _, _, test = tuned
    start = dict(params, transition=jnp.array([[0.8, 0.2], [0.3, 0.7]]))
    tuned_scores = tuning.evaluate_imm(problem, params, test)
    start_scores = tuning.evaluate_imm(problem, start, test)
    for name in ("nll", "cross_entropy", "mode_accuracy"):
        assert tuned_scores[f"{name}_low"] <= tuned_scores[name] <= tuned_scores[f"{name}_high"]
    assert tuned_scores["runs"] == RUNS
    assert (
        tuned_scores["nll_high"] < start_scores["nll"]
    )  # held-out runs (seed 2): better beyond its interval
    assert tuned_scores["mode_accuracy"] > 0.9


def test_saved_and_loaded_parameters_give_the_same_imm(tuned, tmp_path):
    problem, params, result, _, test = tuned
    path = tuning.save_params(tmp_path / "imm.json", result.raw, problem.parameterization)
    raw, parameterization, _ = tuning.load_params(path)
    loaded = tuning.constrain(parameterization, raw)
    np.testing.assert_allclose(
        np.asarray(loaded["transition"]), np.asarray(params["transition"]), rtol=1e-12
    )
    a = tuning.evaluate_imm(problem, params, test)
    b = tuning.evaluate_imm(problem, loaded, test)
    assert a["nll"] == pytest.approx(b["nll"], rel=1e-12)


def test_bad_input_names_the_argument(tuned):
    problem, params, _, train, _ = tuned
    with pytest.raises(ValueError, match="loss: expected"):
        tuning.imm_loss(problem, "mse")
    with pytest.raises(ValueError, match="data.modes: expected"):
        tuning.tune_imm(
            problem, params, train._replace(modes=None), train, loss="cross_entropy", steps=1
        )
    with pytest.raises(ValueError, match="params0: expected a value"):
        tuning.tune_imm(problem, {"transition": params["transition"]}, train, train, steps=1)
    with pytest.raises(ValueError, match="'transition'"):
        tuning.imm_filter(problem._replace(parameterization={}), params)
