"""Tuning an IMM of one's own on labelled or unlabelled runs (Blom & Bar-Shalom 1988 for the filter).

The parameters are a dict of constrained values, each with its ``Transform``: ``"transition"`` (``stochastic_rows``:
the structural zeros of its mask stay zero), optionally ``"mode_prob"`` (``simplex``: ``P(mode at step 0)``) and
``"threshold"`` (``unit_interval``: the alarm level ``mu_T`` of ``max_{j>0} mu_j``), and whatever the user's
``mode_params(params)`` reads (mode noises, biases). The loss per run, averaged over runs and steps:

* ``"likelihood"``: ``-(1/T) sum_k log sum_j P(j | y[:k-1]) N(r_j(k); 0, S_j(k))``, needing no labels;
* ``"cross_entropy"``: ``-(1/T) sum_k log mu_{m_k}(k)``, ``m_k`` the labelled mode;

plus ``detection_weight`` times ``soft_detection_loss`` of ``max_{j>0} mu_j(k)`` against ``"threshold"`` (onset: the
first step with a mode other than 0). Training is ``fit`` on ``fixed_batches`` of the training runs.
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxfdi import checks
from jaxfdi._studies.metrics import mean_interval
from jaxfdi.filters import Filter, interacting_multiple_model, run_filter
from jaxfdi.tuning._losses import mode_cross_entropy, soft_detection_loss
from jaxfdi.tuning._parameterize import Transform, constrain, unconstrain
from jaxfdi.tuning._train import TrainResult, fit, fixed_batches

LOSSES = ("likelihood", "cross_entropy")


class ImmProblem(NamedTuple):
    """An IMM to tune: its mode filters, what its parameters build, and the prior of ``x[0]``.

    Attributes:
      mode_filter: ``mode params -> Filter`` with ``update`` and ``predict`` (``kalman_filter``, a UKF, ...)
      mode_params: ``params -> pytree`` with a leading mode axis ``M`` (the constrained parameters dict in)
      parameterization: parameter name -> ``Transform``; holds ``"transition"`` (``stochastic_rows(mask)``)
      mean0: (n,) prior mean of ``x[0]``
      cov0: (n, n) prior covariance of ``x[0]``
    """

    mode_filter: Callable[[Any], Filter]
    mode_params: Callable[[dict], Any]
    parameterization: dict[str, Transform]
    mean0: Any
    cov0: Any


class ImmData(NamedTuple):
    """Runs to tune or evaluate on, leading run axis ``R``.

    Attributes:
      measurements: (R, T, m) ``y[k]``
      inputs: (R, T, p) ``u[k]``, or ``None``
      modes: (R, T) int, the true mode per step (0: nominal), or ``None`` (unlabelled)
    """

    measurements: Any
    inputs: Any = None
    modes: Any = None


def _check_problem(problem: ImmProblem) -> None:
    if not isinstance(problem, ImmProblem):
        raise TypeError(f"problem: expected an ImmProblem, got {type(problem).__name__}")
    if "transition" not in problem.parameterization:
        raise ValueError(
            "problem.parameterization: expected a 'transition' entry (tuning.stochastic_rows(mask)), got "
            f"{sorted(problem.parameterization)}"
        )


def imm_filter(problem: ImmProblem, params: dict) -> tuple[Filter, Any]:
    """The IMM of constrained ``params`` and its initial state.

    Returns:
      ``(imm, state0)``: ``interacting_multiple_model(mode_filter, mode_params(params), params["transition"])`` and
      ``imm.init(mean0, cov0, mode_prob0 @ transition)`` (``mode_prob0``: ``params["mode_prob"]``, else all in mode 0),
      so that the first step's mixing starts from ``mode_prob0`` as filterpy's ``IMMEstimator(filters, mu, M)`` does.
    """
    _check_problem(problem)
    transition = params["transition"]
    M = transition.shape[0]
    mode_prob = params.get("mode_prob", jnp.zeros(M, transition.dtype).at[0].set(1.0))
    imm = interacting_multiple_model(problem.mode_filter, problem.mode_params(params), transition)
    return imm, imm.init(problem.mean0, problem.cov0, mode_prob @ transition)


def _check_data(data: ImmData, needs_modes: bool) -> None:
    if not isinstance(data, ImmData):
        raise TypeError(f"data: expected an ImmData, got {type(data).__name__}")
    shape = checks.shape_of(data.measurements)
    if len(shape) != 3:
        raise ValueError(f"data.measurements: expected shape (R, T, m), got {shape}")
    if data.inputs is not None and checks.shape_of(data.inputs)[:2] != shape[:2]:
        raise ValueError(
            f"data.inputs: expected shape {shape[:2]} + (p,), got {checks.shape_of(data.inputs)}"
        )
    if needs_modes and data.modes is None:
        raise ValueError("data.modes: expected (R, T) mode labels for this loss, got None")
    if data.modes is not None and checks.shape_of(data.modes) != shape[:2]:
        raise ValueError(
            f"data.modes: expected shape {shape[:2]}, got {checks.shape_of(data.modes)}"
        )


def _run(problem: ImmProblem, params: dict, data: ImmData):
    imm, state0 = imm_filter(problem, params)
    _, info = run_filter(imm, state0, data.measurements, data.inputs)
    return info


def _onset(modes):
    """First step with a mode other than 0 (``T`` when none)."""
    faulty = modes != 0
    return jnp.where(faulty.any(), jnp.argmax(faulty), modes.shape[0])


def imm_loss(
    problem: ImmProblem,
    loss: str = "likelihood",
    detection_weight: float = 0.0,
    temperature: float = 0.05,
) -> Callable[[dict, ImmData], jax.Array]:
    """``loss(raw, data) -> scalar`` of the unconstrained parameters (module doc), for ``fit``.

    ``detection_weight > 0`` adds the soft detection loss of ``max_{j>0} mu_j`` against ``params["threshold"]``
    (``temperature``: the sigmoid's width in probability).

    Returns:
      ``loss(raw, data) -> ()``: the loss of unconstrained ``raw`` on the ``ImmData`` runs ``data``, differentiable.
    """
    _check_problem(problem)
    checks.check_choice("loss", loss, LOSSES)
    checks.check_scalar("detection_weight", detection_weight, 0.0, meaning="a loss weight >= 0")
    checks.check_positive("temperature", temperature, "a positive sigmoid width")
    if detection_weight and "threshold" not in problem.parameterization:
        raise ValueError(
            "detection_weight: a detection loss needs a 'threshold' in problem.parameterization"
        )

    def value(raw: dict, data: ImmData) -> jax.Array:
        params = constrain(problem.parameterization, raw)
        info = _run(problem, params, data)
        if loss == "likelihood":
            total = -jnp.mean(info.log_likelihood)
        else:
            total = jnp.mean(jax.vmap(mode_cross_entropy)(info.log_mode_prob, data.modes))
        if detection_weight:
            fault_mu = info.mode_prob[..., 1:].max(axis=-1)

            def one(statistic, modes):
                return soft_detection_loss(
                    statistic, params["threshold"], _onset(modes), temperature
                )[0]

            total = total + detection_weight * jnp.mean(jax.vmap(one)(fault_mu, data.modes))
        return total

    return value


def tune_imm(
    problem: ImmProblem,
    params0: dict,
    train: ImmData,
    validation: ImmData,
    *,
    loss: str = "likelihood",
    steps: int = 200,
    learning_rate: float = 0.05,
    batch_size: int | None = None,
    trainable: list[str] | None = None,
    detection_weight: float = 0.0,
    seed: int = 0,
    eval_every: int = 10,
    patience: int = 5,
    progress: bool = False,
) -> tuple[dict, TrainResult]:
    """Adam on ``imm_loss`` from the constrained ``params0``, mini-batches of ``train``, early stopping on
    ``validation`` (``fit``).

    Returns:
      ``(params, result)``: the constrained parameters at the lowest validation loss, and ``fit``'s ``TrainResult``
      (``save_params(path, result.raw, problem.parameterization)`` writes them).
    """
    _check_problem(problem)
    needs_modes = loss == "cross_entropy" or bool(detection_weight)
    _check_data(train, needs_modes)
    _check_data(validation, needs_modes)
    missing = sorted(set(problem.parameterization) - set(params0))
    if missing:
        raise ValueError(f"params0: expected a value for every parameter, missing {missing}")
    runs = checks.shape_of(train.measurements)[0]
    batch_size = runs if batch_size is None else batch_size
    objective = imm_loss(problem, loss, detection_weight)
    result = fit(
        objective,
        unconstrain(problem.parameterization, params0),
        optax.adam(learning_rate),
        fixed_batches(train, batch_size, jax.random.key(seed)),
        validation,
        steps,
        trainable=trainable,
        eval_every=eval_every,
        patience=patience,
        progress=progress,
    )
    return constrain(problem.parameterization, result.raw), result


def evaluate_imm(
    problem: ImmProblem, params: dict, data: ImmData, level: float = 0.95
) -> dict[str, float]:
    """Held-out scores of constrained ``params`` on ``data``, each a mean over runs with a ``level`` interval.

    Per run: the mean per-step negative log-likelihood and, with labels, the mean mode cross-entropy and the share of
    steps whose most probable mode is the labelled one. Runs are independent, so each interval is the normal one
    over runs, ``mean +- z sd / sqrt(R)`` (``z`` the ``(1 + level) / 2`` normal quantile; steps within a run are not
    independent and are never counted as trials).

    Returns:
      ``{"runs", "nll", "nll_low", "nll_high"}`` and, with labels, ``"cross_entropy"`` and ``"mode_accuracy"`` with
      their ``_low``/``_high``.
    """
    _check_data(data, False)
    checks.check_probability("level", level)
    info = jax.jit(lambda p, d: _run(problem, p, d))(params, data)
    per_run = {"nll": -np.mean(np.asarray(info.log_likelihood), axis=1)}
    if data.modes is not None:
        modes = np.asarray(data.modes)
        log_mu = np.asarray(info.log_mode_prob)
        picked = np.take_along_axis(log_mu, modes[..., None], -1)[..., 0]
        per_run["cross_entropy"] = -np.mean(
            np.logaddexp(picked, math.log(1e-12)), axis=1
        )  # mode_cross_entropy's
        per_run["mode_accuracy"] = np.mean(np.argmax(log_mu, axis=-1) == modes, axis=1)
    scores: dict[str, float] = {"runs": len(per_run["nll"])}
    for name, values in per_run.items():
        mean, low, high = mean_interval(values, level)
        scores.update({name: mean, f"{name}_low": low, f"{name}_high": high})
    return scores
