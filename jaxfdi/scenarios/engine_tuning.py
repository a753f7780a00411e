"""Seed 003 engine: the Zhang & Li IMM tuned by gradient against labelled runs.

The paper sets its IMM by hand (transition matrix "adjusted experimentally", mu_T = 0.5).
Here the transition matrix (its structural zeros kept), the sensor-mode inflation
factors, the actuator-mode noise and mu_T are trained with optax on labelled Monte Carlo
runs of the paper's scenario (6 faults + fault-free, onset 2 s, 4 s at 100 Hz), seeds
apart for training, validation and the held-out test. Loss per run:

    mode cross-entropy  +  detection_weight * soft detection loss of max_{j>0} mu_j vs mu_T

(``tuning.mode_cross_entropy``, ``tuning.soft_detection_loss``). The held-out comparison
uses the same records and summaries as ``jaxfdi run engine``.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxfdi.detection.mode_probability import mode_probability_detector
from jaxfdi.filters._base import run_filter
from jaxfdi.filters.imm import interacting_multiple_model
from jaxfdi.filters.kalman import kalman_filter
from jaxfdi.models.engine import TS, engine_model
from jaxfdi.models.fault_modes import noise_inflation_modes
from jaxfdi.scenarios.engine import (
    PAPER_TRANSITION,
    EngineSettings,
    Method,
    _mode_prob,
    run_method,
    scenario_runs,
    summarize_method,
)
from jaxfdi.scenarios.engine_chi2 import FUEL_STEP
from jaxfdi.simulate import linear_simulator, simulate
from jaxfdi.tuning import losses
from jaxfdi.tuning.parameterize import Transform, constrain, positive, stochastic_rows, unconstrain, unit_interval
from jaxfdi.tuning.train import TrainResult, checkpointed, fit, fixed_batches

TRANSITION_MASK = (PAPER_TRANSITION > 0) | np.eye(len(PAPER_TRANSITION), dtype=bool)


class LabelledRuns(NamedTuple):
    ys: jax.Array      # (R, T, 5) measurements
    modes: jax.Array   # (R, T) true mode per step (0 normal, 1 actuator, 2.. sensors)
    onsets: jax.Array  # (R,) fault onset step (NEVER for fault-free)
    fault: jax.Array   # (R,) index into engine_faults (6 = fault-free)


def labelled_runs(runs_per_fault: int, seed: int, duration: float = 4.0, onset_time: float = 2.0) -> LabelledRuns:
    """``runs_per_fault`` simulated runs of each engine case, fault-major."""
    model, us, faults, batch, keys = scenario_runs(runs_per_fault, seed, duration, onset_time)

    @jax.jit
    def one(key, f):
        _, truth = simulate(linear_simulator(model, f), jnp.zeros(7), us, key)
        return truth.measurement, truth.mode

    ys, modes = jax.vmap(one)(keys, batch)
    fault_index = jnp.repeat(jnp.arange(len(faults)), runs_per_fault)
    return LabelledRuns(ys, modes, batch.onset, fault_index)


def imm_parameterization() -> dict[str, Transform]:
    return {
        "transition": stochastic_rows(TRANSITION_MASK),
        "sensor_inflation": positive(floor=1.0),
        "actuator_noise": positive(),
        "mu_threshold": unit_interval(),
    }


def hand_params(settings: EngineSettings = EngineSettings()) -> dict[str, Any]:
    """The paper's IMM: its transition matrix, mu_T = 0.5, the Zhang & Li mode settings."""
    return {
        "transition": jnp.asarray(PAPER_TRANSITION),
        "sensor_inflation": jnp.full(5, settings.sensor_inflation),
        "actuator_noise": jnp.full(1, settings.actuator_noise),
        "mu_threshold": jnp.asarray(settings.mu_threshold),
    }


def imm_filter(params: dict[str, Any]):
    model = engine_model()
    modes = noise_inflation_modes(model, params["sensor_inflation"], params["actuator_noise"])
    return interacting_multiple_model(kalman_filter, modes, params["transition"])


def _initial_state(filt):
    return filt.init(jnp.zeros(7), engine_model().Q, jnp.asarray(PAPER_TRANSITION[0]))


def mode_log_probs(params: dict[str, Any], ys: jax.Array, remat: bool = False) -> jax.Array:
    """(R, T, M) log mode probabilities of the IMM with ``params`` on ``ys`` (R, T, 5)."""
    filt = imm_filter(params)
    filt = checkpointed(filt) if remat else filt
    us = jnp.full((ys.shape[1], 1), FUEL_STEP)
    return jax.vmap(lambda y: run_filter(filt, _initial_state(filt), y, us)[1].log_mode_prob)(ys)


def imm_loss(params: dict[str, Any], data: LabelledRuns, detection_weight: float = 1.0,
             false_alarm_weight: float = 5.0, temperature: float = 0.05,
             remat: bool = True) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Mean over runs of the mode cross-entropy plus the weighted soft detection loss."""
    log_mu = mode_log_probs(params, data.ys, remat)
    cross_entropy = jax.vmap(losses.mode_cross_entropy)(log_mu, data.modes)
    statistic = jnp.max(jnp.exp(log_mu[..., 1:]), axis=-1)  # eq. 13: the largest fault-mode probability
    detection, parts = jax.vmap(lambda s, o: losses.soft_detection_loss(
        s, params["mu_threshold"], o, temperature, false_alarm_weight))(statistic, data.onsets)
    total = jnp.mean(cross_entropy + detection_weight * detection)
    return total, {"cross_entropy": jnp.mean(cross_entropy), **{k: jnp.mean(v) for k, v in parts.items()}}


def tune_engine_imm(steps: int = 150, train_runs: int = 16, val_runs: int = 4, batch_runs: int = 4,
                    seed: int = 0, learning_rate: float = 0.05, detection_weight: float = 1.0,
                    false_alarm_weight: float = 5.0, progress: bool = False) -> tuple[TrainResult, dict[str, Transform]]:
    """Train from the hand-set parameters. Training runs come from ``seed``, validation
    from ``seed + 1`` (the test set uses other seeds, see ``compare_engine_imm``)."""
    parameterization = imm_parameterization()
    batch_runs = min(batch_runs, train_runs)
    train = labelled_runs(train_runs, seed)
    val = labelled_runs(val_runs, seed + 1)
    per_fault = jnp.arange(train.ys.shape[0]) % train_runs
    # mini-batches with every fault: batch_runs runs of each of the 7 cases
    index_batches = fixed_batches(jnp.arange(train_runs), batch_runs, jax.random.key(seed))

    def train_batch(step):
        chosen = index_batches(step)
        take = jnp.flatnonzero(jnp.isin(per_fault, chosen), size=7 * batch_runs)
        return jax.tree.map(lambda leaf: leaf[take], train)

    def loss(raw, data):
        return imm_loss(constrain(parameterization, raw), data, detection_weight, false_alarm_weight)[0]

    raw0 = unconstrain(parameterization, hand_params())
    result = fit(loss, raw0, optax.adam(learning_rate), train_batch, val, steps, eval_every=10, patience=4,
                 progress=progress)
    return result, parameterization


def evaluate_engine_imm(params: dict[str, Any], runs: int, seed: int) -> tuple[list[dict], float]:
    """Held-out rows (``summarize_method``: rates, delays) and the mean mode cross-entropy."""
    filt = imm_filter(params)
    method = Method(filt, _initial_state(filt), mode_probability_detector(float(params["mu_threshold"])),
                    _mode_prob, 0, "IMM")
    records = run_method(method, runs, seed)
    rows = summarize_method("IMM", method, records, runs, int(round(4.0 / TS)))
    test = labelled_runs(runs, seed + 1)
    log_mu = jax.jit(mode_log_probs)(params, test.ys)
    cross_entropy = float(jnp.mean(jax.vmap(losses.mode_cross_entropy)(log_mu, test.modes)))
    return rows, cross_entropy


def comparison_table(hand_rows, hand_ce, tuned_rows, tuned_ce) -> str:
    head = (f"{'fault':<9} {'':<6} {'det':>5} {'iso':>5} {'FA':>5} {'delay med [s]':>13} {'p90 [s]':>8}")
    lines = [head, "-" * len(head)]
    for h, t in zip(hand_rows, tuned_rows):
        for label, r in (("paper", h), ("tuned", t)):
            lines.append(
                f"{r['fault']:<9} {label:<6} {_num(r['detection_rate'], 5, 2)} {_num(r['isolation_rate'], 5, 2)} "
                f"{r['false_alarm_rate']:>5.2f} {_num(r['delay_median_s'], 13)} {_num(r['delay_p90_s'], 8)}")
    lines.append(f"mean per-step mode cross-entropy: paper {hand_ce:.4f}, tuned {tuned_ce:.4f} "
                 f"({100 * (1 - tuned_ce / hand_ce):.0f} % lower)")
    return "\n".join(lines)


def _num(x: float, width: int, digits: int = 3) -> str:
    return f"{'-':>{width}}" if x != x else f"{x:>{width}.{digits}f}"
