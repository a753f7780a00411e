"""The engine of Han et al. (2022): the Kalman-filter chi-square detector tuned by gradient.

Hand-set (``engine_chi2_study``): KF with the plant's ``Q``, ``R``; windowed NIS over ``L = 4`` steps; threshold
``chi2.isf(0.005, 5 L)``. Tuned on labelled runs (training seed, validation seed + 1): diagonal ``Q``, ``R``
(``log_diagonal``) and threshold (``log_scale``) by Adam on the soft detection loss of log(windowed NIS) vs
log(threshold) (``tuning.soft_detection_loss``: false alarms, misses, delay; on the log scale the temperature is
relative, the same for every window). The integer window: by validation loss over a grid. No isolation: the table has
detection, false-alarm and delay columns.

Reference: Han, Kim, Kim & Lee (2022), "Real Time Fault Diagnosis of UAV Engine Using IMM Filter and Generalized
Likelihood Ratio Test" (CITATION.cff).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxfdi import checks, tuning
from jaxfdi.detection import chi2_threshold, moving_window_sum
from jaxfdi.filters import kalman_filter, run_filter
from jaxfdi.models import ENGINE_TS as TS
from jaxfdi.models import engine_model
from jaxfdi.scenarios.engine import LabelledRuns, hand_tuned_table, labelled_runs, training_data
from jaxfdi.scenarios.engine_chi2 import FUEL_STEP, engine_chi2_study
from jaxfdi.tuning import TrainResult, constrain, fit, log_diagonal, log_scale, unconstrain

PARAMETERIZATION = {"Q": log_diagonal(), "R": log_diagonal(), "threshold": log_scale()}
HAND_WINDOW, HAND_PFA = 4, 0.005


class Chi2Weights(NamedTuple):
    """Weights of the chi-square detector's tuning loss.

    Attributes:
      false_alarm: weight of P(alarm before the onset)
      miss: weight of P(no alarm after it)
      delay: weight of the expected delay / remaining horizon
      temperature: temperature of the sigmoid alarm, on log(statistic)
    """

    false_alarm: float = 5.0
    miss: float = 5.0
    delay: float = 1.0
    temperature: float = 0.05


def hand_params(window: int = HAND_WINDOW) -> dict[str, Any]:
    model = engine_model()
    return {
        "Q": model.Q,
        "R": model.R,
        "threshold": chi2_threshold(window * model.C.shape[0], HAND_PFA),
    }


def windowed_nis(params: dict[str, Any], ys: jax.Array, window: int) -> jax.Array:
    """(R, T) windowed NIS sums of the KF with ``params['Q']``, ``params['R']`` on ``ys``."""
    model = engine_model()._replace(Q=params["Q"], R=params["R"])
    kf = kalman_filter(model)
    state0 = kf.init(jnp.zeros(7), params["Q"])
    us = jnp.full((ys.shape[1], 1), FUEL_STEP)
    return jax.vmap(lambda y: moving_window_sum(run_filter(kf, state0, y, us)[1].nis, window))(ys)


def chi2_loss(
    params: dict[str, Any], data: LabelledRuns, window: int, weights: Chi2Weights = Chi2Weights()
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Mean over runs of the soft detection loss of the windowed NIS test."""
    log_stat = jnp.log(windowed_nis(params, data.ys, window))
    loss, parts = jax.vmap(
        lambda s, o: tuning.soft_detection_loss(
            s,
            jnp.log(params["threshold"]),
            o,
            weights.temperature,
            weights.false_alarm,
            weights.miss,
            weights.delay,
        )
    )(log_stat, data.onsets)
    return jnp.mean(loss), {k: jnp.mean(v) for k, v in parts.items()}


class Chi2Tuning(NamedTuple):
    """The tuned chi-square detector: the chosen window and its training.

    Attributes:
      window: chosen by the validation loss
      result: the training result of that window
      val_loss: best validation loss per window tried
    """

    window: int
    result: TrainResult
    val_loss: dict[int, float]


def tune_engine_chi2(
    windows: tuple[int, ...] = (1, 2, 4, 8),
    steps: int = 150,
    train_runs: int = 16,
    val_runs: int = 4,
    batch_runs: int = 4,
    seed: int = 0,
    learning_rate: float = 0.05,
    weights: Chi2Weights = Chi2Weights(),
    progress: bool = False,
) -> Chi2Tuning:
    """For each window, train ``Q``, ``R`` and the threshold from the hand-set values (threshold
    ``chi2.isf(0.005, 5 L)``); keep the window with the lowest validation loss."""
    if not windows:
        raise ValueError(f"windows: expected at least one window length, got {windows!r}")
    steps_per_run = int(round(4.0 / TS))  # labelled_runs' default duration
    for w in windows:
        checks.check_int("windows", w, 1, steps_per_run, "window lengths in steps, within a run")
    train_batch, val = training_data(train_runs, val_runs, batch_runs, seed, steps, learning_rate)
    results, val_loss = {}, {}
    for window in windows:

        def loss(raw, data, window=window):
            return chi2_loss(constrain(PARAMETERIZATION, raw), data, window, weights)[0]

        raw0 = unconstrain(PARAMETERIZATION, hand_params(window))
        results[window] = fit(
            loss,
            raw0,
            optax.adam(learning_rate),
            train_batch,
            val,
            steps,
            eval_every=10,
            patience=4,
            progress=progress,
        )
        history = results[window].history
        val_loss[window] = float(np.min(history.val_loss))
    best = min(val_loss, key=val_loss.get)
    return Chi2Tuning(best, results[best], val_loss)


def evaluate_engine_chi2(
    params: dict[str, Any], window: int, runs: int, seed: int, weights: Chi2Weights = Chi2Weights()
) -> tuple[list[dict], float]:
    """Held-out rows of ``engine_chi2_study`` with the detector set to ``params``, and the tuning loss on labelled runs
    of seed ``seed + 1``."""
    rows = engine_chi2_study(
        runs,
        seed,
        window,
        threshold=float(params["threshold"]),
        filter_noise=(params["Q"], params["R"]),
    ).rows
    test = labelled_runs(runs, seed + 1)
    loss = float(jax.jit(chi2_loss, static_argnums=2)(params, test, window, weights)[0])
    return rows, loss


def comparison_table(
    hand_rows: list[dict],
    tuned_rows: list[dict],
    hand_window: int,
    tuned_window: int,
    hand_loss: float,
    tuned_loss: float,
) -> str:
    """Hand-set beside tuned, per fault (``engine.hand_tuned_table``), and the held-out loss."""
    return hand_tuned_table(
        hand_rows,
        tuned_rows,
        (f"hand L={hand_window}", f"tuned L={tuned_window}"),
        ("hand", "tuned"),
        f"held-out tuning loss: hand {hand_loss:.4f}, tuned {tuned_loss:.4f}",
        isolation=False,
    )
