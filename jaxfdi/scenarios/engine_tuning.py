"""The engine of Han et al. (2022): the IMMs tuned by gradient against labelled runs.

The paper sets its IMM by hand (transition matrix "adjusted experimentally", mu_T = 0.5). Here each design is trained
with optax from its hand-set parameters on labelled Monte Carlo runs of the paper's scenario (6 faults + fault-free,
onset 2 s, 4 s at 100 Hz; seeds apart for training, validation, held-out test). Both designs also train the initial
mode probabilities (hand-set: the paper's normal row, as ``jaxfdi run engine``) and mu_T:

* ``zhang-li`` (``noise_inflation_modes``): transition matrix (structural zeros kept), five sensor-mode inflation
  factors, actuator-mode noise;
* ``bias`` (``bias_modes``, 13 states): transition matrix, six bias random-walk and six bias-prior variances; hand-set:
  the paper's matrix (``IMM-bias``), which alarms before the onset in most runs (false-alarm runs; their standing
  "delays" unscored, the reference's delays are over its few clean runs: ``metrics.fault_row``). From jaxfdi's sticky
  matrix (``IMM-bias hand-pi``) tuning lowers the held-out cross-entropy only 25-29 %: what is left is mostly the onset
  step (the actuator fault not yet measured) and a pre-onset leak of about the prior switch rate per step, traded
  against each other through that rate.

Loss per run (``imm_loss``): mode cross-entropy + detection_weight * soft detection loss of max_{j>0} mu_j vs mu_T
(``tuning.soft_detection_loss``: false alarms, misses, delay, misisolation with margin
``max_{j != fault} mu_j - mu_fault``). With ``confirm_steps = c`` the loss sees the surrogate
``confirmed_probabilities``. Held-out comparison: the records and summaries of ``jaxfdi run engine``.

Reference: Han, Kim, Kim & Lee (2022), "Real Time Fault Diagnosis of UAV Engine Using IMM Filter and Generalized
Likelihood Ratio Test" (CITATION.cff).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxfdi import DetectionRecord, monte_carlo, replay_detector, results_frame, tuning
from jaxfdi.detection import mode_probability_detector
from jaxfdi.filters import interacting_multiple_model, kalman_filter, run_filter
from jaxfdi.models import bias_mode_initial_state, bias_modes, engine_model, noise_inflation_modes
from jaxfdi.scenarios.engine import (
    PAPER_TRANSITION,
    EngineSettings,
    LabelledRuns,
    Method,
    _bias_estimates,
    _mode_prob,
    hand_tuned_table,
    labelled_runs,
    run_monitor,
    scenario_runs,
    summarize_method,
    training_data,
)
from jaxfdi.scenarios.engine_chi2 import FUEL_STEP
from jaxfdi.tuning import (
    TrainResult,
    Transform,
    checkpointed,
    constrain,
    fit,
    log_scale,
    simplex,
    stochastic_rows,
    strongly_typed,
    unconstrain,
    unit_interval,
)

TRANSITION_MASK = (PAPER_TRANSITION > 0) | np.eye(len(PAPER_TRANSITION), dtype=bool)
NUM_FAULTS = len(PAPER_TRANSITION) - 1


class ImmDesign(NamedTuple):
    """One engine IMM design: what is tuned, its hand-set values, how to build it.

    Attributes:
      name: the design's name (``imm_design``)
      method: its column in ``jaxfdi run engine``
      transition_mask: (M, M) allowed transitions
      parameterization: parameter name -> its constraining transform
      hand: the paper's / hand-set parameters
      modes: params -> stacked mode models
      initial: params -> (mean, cov) of the state at step 0
      detector_input: ``info -> detector input`` (``monitor``)
      estimate_delay: steps after the detection within which the fault estimate is read (``monitor``)
    """

    name: str
    method: str
    transition_mask: np.ndarray
    parameterization: dict[str, Transform]
    hand: Callable[[], dict[str, Any]]
    modes: Callable[[dict[str, Any]], Any]
    initial: Callable[[dict[str, Any]], tuple]
    detector_input: Callable[[Any], Any]
    estimate_delay: int


def _imm_design(
    name: str,
    method: str,
    tuned: dict[str, Transform],
    hand: Callable[[], dict[str, Any]],
    modes,
    initial,
    detector_input,
    estimate_delay: int,
) -> ImmDesign:
    """A design that also tunes the transition matrix, the initial mode probabilities and mu_T (hand-set: the paper's
    matrix, its normal row and the engine study's mu_T)."""

    def hand_set():
        return {
            "transition": jnp.asarray(PAPER_TRANSITION),
            "initial_mode": jnp.asarray(PAPER_TRANSITION[0]),
            **hand(),
            "mu_threshold": jnp.asarray(EngineSettings().mu_threshold),
        }

    parameterization = {
        "transition": stochastic_rows(TRANSITION_MASK),
        "initial_mode": simplex(),
        **tuned,
        "mu_threshold": unit_interval(),
    }
    return ImmDesign(
        name,
        method,
        TRANSITION_MASK,
        parameterization,
        hand_set,
        modes,
        initial,
        detector_input,
        estimate_delay,
    )


def _zhang_li() -> ImmDesign:
    settings, model = EngineSettings(), engine_model()
    return _imm_design(
        "zhang-li",
        "IMM",
        {"sensor_inflation": log_scale(), "actuator_noise": log_scale()},
        lambda: {
            "sensor_inflation": jnp.full(5, settings.sensor_inflation),
            "actuator_noise": jnp.full(1, settings.actuator_noise),
        },
        lambda p: noise_inflation_modes(model, p["sensor_inflation"], p["actuator_noise"]),
        lambda p: (jnp.zeros(7), model.Q),
        _mode_prob,
        0,
    )


def _bias() -> ImmDesign:
    settings, model = EngineSettings(), engine_model()
    return _imm_design(
        "bias",
        "IMM-bias",
        {"bias_walk": log_scale(), "bias_prior": log_scale()},
        lambda: {
            "bias_walk": jnp.asarray(settings.bias_walk),
            "bias_prior": jnp.asarray(settings.bias_prior),
        },
        lambda p: bias_modes(model, p["bias_walk"], p["bias_prior"]),
        lambda p: bias_mode_initial_state(model, jnp.zeros(7), model.Q, p["bias_prior"]),
        _bias_estimates,
        settings.bias_estimate_delay,
    )


DESIGNS: dict[str, Callable[[], ImmDesign]] = {"zhang-li": _zhang_li, "bias": _bias}


def imm_design(name: str) -> ImmDesign:
    if name not in DESIGNS:
        raise ValueError(f"design: unknown {name!r}; expected one of {sorted(DESIGNS)}")
    return DESIGNS[name]()


def imm_filter(design: ImmDesign, params: dict[str, Any]):
    """``(filter, initial state)`` of the design's IMM with ``params``; the hand-set initial mode probabilities
    (``params['initial_mode']``; files saved before it was tuned lack it) are the paper's normal row, as in
    ``jaxfdi run engine``."""
    filt = interacting_multiple_model(kalman_filter, design.modes(params), params["transition"])
    mean, cov = design.initial(params)
    return filt, filt.init(mean, cov, params.get("initial_mode", jnp.asarray(PAPER_TRANSITION[0])))


def filter_params(params: dict[str, Any]) -> dict[str, Any]:
    """The filter's share of ``params`` (without the detector's ``mu_threshold`` and ``confirm_steps``), strongly typed:
    the key of one compiled ``mode_log_probs`` for the hand-set and the tuned parameters alike."""
    return strongly_typed(
        {k: v for k, v in params.items() if k not in ("mu_threshold", "confirm_steps")}
    )


def mode_log_probs(
    design: ImmDesign, params: dict[str, Any], ys: jax.Array, remat: bool = False
) -> jax.Array:
    """(R, T, M) log mode probabilities of the design's IMM with ``params`` on ``ys`` (R, T, 5)."""
    filt, state0 = imm_filter(design, params)
    filt = checkpointed(filt) if remat else filt
    us = jnp.full((ys.shape[1], 1), FUEL_STEP)
    return jax.vmap(lambda y: run_filter(filt, state0, y, us)[1].log_mode_prob)(ys)


class LossWeights(NamedTuple):
    """Weights of the IMM tuning loss.

    Attributes:
      detection: weight of the soft detection loss against the cross-entropy
      false_alarm: within it: weight of P(alarm before the onset)
      miss: weight of P(no alarm after the onset)
      delay: weight of the expected delay / steps after the onset
      isolation: weight of P(the first alarm names the wrong fault)
      temperature: temperature of the sigmoid alarm, in units of mu
    """

    detection: float = 1.0
    false_alarm: float = 5.0
    miss: float = 1.0
    delay: float = 1.0
    isolation: float = 5.0
    temperature: float = 0.05


def confirmed_probabilities(fault_mu: jax.Array, confirm_steps) -> jax.Array:
    """``min_{0 <= i < c_j} mu_j(k - i)`` per fault mode (R, T, J), 0 for ``k < c_j - 1``: the surrogate of
    ``mode_probability_detector(mu_T, confirm_steps=c)``, whose alarm is ``max_j min_i mu_j(k - i) >= mu_T`` labelled j
    (exact for ``mu_T >= 0.5``: such a mode is the top fault mode). ``confirm_steps``: one ``c``, or (J + 1,) per
    mode, the normal mode's (unused) first."""
    steps = np.asarray(confirm_steps, int)
    steps = np.broadcast_to(steps if steps.ndim == 0 else steps[1:], (fault_mu.shape[-1],))
    confirmed = fault_mu
    for lag in range(1, int(steps.max())):
        shifted = jnp.pad(fault_mu[:, :-lag], ((0, 0), (lag, 0), (0, 0)))
        confirmed = jnp.where(jnp.asarray(lag < steps), jnp.minimum(confirmed, shifted), confirmed)
    return confirmed


def imm_loss(
    design: ImmDesign,
    params: dict[str, Any],
    data: LabelledRuns,
    weights: LossWeights = LossWeights(),
    remat: bool = True,
    confirm_steps=1,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Mean over runs of the mode cross-entropy plus the weighted soft detection loss of the detector with
    ``confirm_steps`` (an int, or (M,) one per mode as the detector takes it; ``confirmed_probabilities``)."""
    log_mu = mode_log_probs(design, params, data.ys, remat)
    cross_entropy = jax.vmap(tuning.mode_cross_entropy)(log_mu, data.modes)
    fault_mu = confirmed_probabilities(jnp.exp(log_mu[..., 1:]), confirm_steps)  # (R, T, 6)
    # eq. 13, with one mu_T per mode allowed: alarm when some mode's excess over its own threshold is >= 0 (for a scalar
    # mu_T: the largest fault-mode probability >= mu_T)
    excess = fault_mu - jnp.broadcast_to(params["mu_threshold"], (NUM_FAULTS + 1,))[1:]
    statistic = jnp.max(excess, axis=-1)
    own = jax.nn.one_hot(data.fault, NUM_FAULTS, dtype=bool)[
        :, None, :
    ]  # all False for fault-free runs
    correct = jnp.sum(jnp.where(own, excess, 0.0), axis=-1)
    wrong = jnp.max(jnp.where(own, -2.0, excess), axis=-1)
    detection, parts = jax.vmap(
        lambda s, o, m: tuning.soft_detection_loss(
            s,
            0.0,
            o,
            weights.temperature,
            weights.false_alarm,
            weights.miss,
            weights.delay,
            wrong_label_margin=m,
            isolation_weight=weights.isolation,
        )
    )(statistic, data.onsets, wrong - correct)
    total = jnp.mean(cross_entropy + weights.detection * detection)
    return total, {
        "cross_entropy": jnp.mean(cross_entropy),
        **{k: jnp.mean(v) for k, v in parts.items()},
    }


def tune_engine_imm(
    design: ImmDesign,
    steps: int = 150,
    train_runs: int = 16,
    val_runs: int = 4,
    batch_runs: int = 4,
    seed: int = 0,
    learning_rate: float = 0.05,
    weights: LossWeights = LossWeights(),
    progress: bool = False,
    confirm_steps=1,
    frozen: tuple[str, ...] = (),
) -> TrainResult:
    """Train ``design`` from its hand-set parameters for the detector with ``confirm_steps``. Training runs come from
    ``seed``, validation from ``seed + 1`` (the CLI tests on ``seed + 1000``). The parameters named in ``frozen`` keep
    their hand-set values."""
    unknown = set(frozen) - set(design.parameterization)
    if unknown:
        raise ValueError(
            f"frozen: unknown parameters {sorted(unknown)}; design {design.name!r} has "
            f"{sorted(design.parameterization)}"
        )
    train_batch, val = training_data(train_runs, val_runs, batch_runs, seed, steps, learning_rate)

    def loss(raw, data):
        return imm_loss(
            design,
            constrain(design.parameterization, raw),
            data,
            weights,
            confirm_steps=confirm_steps,
        )[0]

    raw0 = unconstrain(design.parameterization, design.hand())
    trainable = [name for name in raw0 if name not in frozen]
    return fit(
        loss,
        raw0,
        optax.adam(learning_rate),
        train_batch,
        val,
        steps,
        trainable=trainable,
        eval_every=10,
        patience=4,
        progress=progress,
    )


def evaluate_engine_imm(
    design: ImmDesign, params: dict[str, Any], runs: int, seed: int, confirm_steps=1
) -> tuple[list[dict], float]:
    """Held-out rows (``summarize_method``: rates, delays) of the detector with ``confirm_steps`` (1: the paper's rule)
    and the mean mode cross-entropy. Runs and keys: ``run_method``'s; ``params``, thresholds and ``confirm_steps`` (one
    per mode) are fixed-type data, so hand-set and tuned compile once (across processes with
    ``jaxfdi.enable_compilation_cache``)."""
    model, us, faults, batch, _ = scenario_runs(runs, seed)
    num_runs = len(faults) * runs
    params = strongly_typed(
        dict(
            params,
            mu_threshold=jnp.broadcast_to(params["mu_threshold"], (NUM_FAULTS + 1,)),
            confirm_steps=jnp.broadcast_to(
                jnp.asarray(confirm_steps, jnp.int32), (NUM_FAULTS + 1,)
            ),
        )
    )
    per_run = (
        batch,
        jax.tree.map(lambda p: jnp.broadcast_to(p, (num_runs,) + jnp.shape(p)), params),
    )

    def run_one(key, data):
        f, p = data
        filt, state0 = imm_filter(design, p)
        detector = mode_probability_detector(p["mu_threshold"], confirm_steps=p["confirm_steps"])
        method = Method(filt, state0, detector, design.detector_input, design.estimate_delay, "IMM")
        return run_monitor(method, model, us, key, f).record

    records = monte_carlo(run_one, jax.random.key(seed), num_runs, per_run, chunk_size=1024)
    rows = summarize_method(design.method, "IMM", records, runs, us.shape[0])
    test = labelled_runs(runs, seed + 1)
    log_mu = jax.jit(lambda p, y: mode_log_probs(design, p, y))(filter_params(params), test.ys)
    cross_entropy = float(jnp.mean(jax.vmap(tuning.mode_cross_entropy)(log_mu, test.modes)))
    return rows, cross_entropy


def detector_records(
    mode_prob: jax.Array, onsets: jax.Array, threshold, confirm_steps=1
) -> DetectionRecord:
    """Per-run records of ``mode_probability_detector(threshold, confirm_steps)`` on stored mode probabilities (R, T, M)
    (``monitor.replay_detector``): the records ``run_monitor`` would give without rerunning the filter, for searching
    thresholds."""
    detector = mode_probability_detector(threshold, confirm_steps=confirm_steps)
    return jax.vmap(lambda mu, onset: replay_detector(detector, mu, onset))(mode_prob, onsets)


#: the reported row metrics and which way is better (delays over the runs with no pre-onset alarm, whose share
#: ``false_alarm_rate`` is for a fault's runs; a delay the hand-set design cannot score, no clean run, is not compared)
_BETTER = {
    "detection_rate": 1,
    "isolation_rate": 1,
    "false_alarm_rate": -1,
    "delay_mean_s": -1,
    "delay_median_s": -1,
    "delay_p90_s": -1,
}


def shortfall(hand_rows: list[dict], tuned_rows: list[dict]) -> float:
    """Total amount by which the tuned rows are worse than the hand-set ones, over every reported rate and delay (0
    exactly when ``worse_metrics`` lists no row metric; a missing tuned value where the hand-set one exists counts
    1)."""
    total = 0.0
    for h, t in zip(hand_rows, tuned_rows):
        for key, sign in _BETTER.items():
            hand, tuned = (float("nan") if r.get(key) is None else r[key] for r in (h, t))
            if hand == hand:
                total += 1.0 if tuned != tuned else max(0.0, sign * (hand - tuned))
    return total


def select_mode_thresholds(
    design: ImmDesign,
    params: dict[str, Any],
    runs: int,
    seed: int,
    confirm_steps=1,
    grid=np.round(np.arange(0.30, 0.99, 0.02), 2),
    sweeps: int = 3,
    cost: Callable[[list[dict]], float] | None = None,
) -> tuple[jax.Array, dict]:
    """One ``mu_T`` per fault mode for the tuned ``params`` on selection runs (``runs`` per fault, ``seed``; neither
    training nor test data): no reported metric worse than the hand-set design's, or minimal ``cost`` of the rows.

    Coordinate descent over ``grid`` from the trained ``mu_T``: each sweep sets each mode's threshold to the grid value
    of least cost (default: ``shortfall`` against the hand-set rows; ties keep the current value); the filter runs once,
    the detector is replayed (``detector_records``).

    Returns ``((M,) thresholds, {"shortfall": before, after})`` (cost before, after); the normal mode's (unused) entry
    keeps the trained value.
    """
    data = labelled_runs(runs, seed)
    steps = data.ys.shape[1]
    log_probs = jax.jit(lambda p, y: mode_log_probs(design, p, y))
    if cost is None:
        hand = design.hand()
        hand_records = detector_records(
            jnp.exp(log_probs(filter_params(hand), data.ys)), data.onsets, hand["mu_threshold"]
        )
        hand_rows = summarize_method(design.method, "IMM", hand_records, runs, steps)

        def cost(rows):
            return shortfall(hand_rows, rows)

    mode_prob = jnp.exp(log_probs(filter_params(params), data.ys))
    replay = jax.jit(
        lambda thresholds: detector_records(mode_prob, data.onsets, thresholds, confirm_steps)
    )

    def cost_of(thresholds):
        return cost(summarize_method(design.method, "IMM", replay(thresholds), runs, steps))

    thresholds = np.broadcast_to(
        np.asarray(params["mu_threshold"], float), (NUM_FAULTS + 1,)
    ).copy()
    before = best = cost_of(jnp.asarray(thresholds))
    for _ in range(sweeps):
        for mode in range(1, NUM_FAULTS + 1):
            for value in grid:
                trial = thresholds.copy()
                trial[mode] = value
                value_cost = cost_of(jnp.asarray(trial))
                if value_cost < best - 1e-12:
                    best, thresholds = value_cost, trial
    return jnp.asarray(thresholds), {"shortfall": {"trained": before, "selected": best}}


def worse_metrics(
    hand_rows: list[dict], tuned_rows: list[dict], hand_ce: float, tuned_ce: float
) -> list[str]:
    """The reported metrics on which the tuned design is worse than the hand-set one (rows as ``summarize_method`` makes
    them, or read back from JSON: NaN as ``None``)."""
    worse = [] if tuned_ce <= hand_ce else ["cross-entropy"]
    for h, t in zip(hand_rows, tuned_rows):
        for key, sign in _BETTER.items():
            hand, tuned = (float("nan") if r.get(key) is None else r[key] for r in (h, t))
            if (
                hand == hand and not sign * tuned >= sign * hand
            ):  # a NaN tuned value counts as worse
                worse.append(f"{h['fault']} {key}")
    return worse


def comparison_frame(hand_rows: list[dict], tuned_rows: list[dict], level: float = 0.95):
    """Hand-set (``paper``) beside tuned, per fault, as a pandas DataFrame: the rows of ``evaluate_engine_imm`` with a
    ``settings`` column, every run rate beside its ``level`` Clopper-Pearson interval (``results_frame``).

    Returns:
      ``pandas.DataFrame``, fault by fault, the paper's row before the tuned one.
    """
    rows = [
        {"fault": row["fault"], "settings": label, **row}
        for pair in zip(hand_rows, tuned_rows)
        for label, row in zip(("paper", "tuned"), pair)
    ]
    return results_frame(rows, level)


def comparison_table(hand_rows, hand_ce, tuned_rows, tuned_ce) -> str:
    """Hand-set (``paper``) beside tuned, per fault (``engine.hand_tuned_table``), and the mean mode cross-entropy of
    each."""
    return hand_tuned_table(
        hand_rows,
        tuned_rows,
        ("paper", "tuned"),
        ("paper", "tuned"),
        f"mean per-step mode cross-entropy: paper {hand_ce:.4f}, tuned {tuned_ce:.4f} "
        f"({100 * (1 - tuned_ce / hand_ce):.0f} % lower)",
    )
