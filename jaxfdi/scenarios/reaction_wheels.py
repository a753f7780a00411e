"""Choi and Park (2009): satellite reaction-wheel fault isolation with a dual filter and a bank of
multi-hypothesis EKFs, in closed loop, Monte Carlo.

A run (``run_wheels``) is ``loop.run_loop`` of the truth ``control.attitude.wheel_plant``, the FDI
``wheel_fdi`` (steps 3-4) and ``control.attitude.wheel_attitude_controller``. Step ``k``, ``t = k dt``:

1. gyros: ``y = w + v``;
2. controller: 10 deg slew about (1, 1, 1) in 40 s, quaternion PD with gyroscopic feed-forward,
   minimum-norm allocation to the four wheels; the commanded torques integrate into the commanded
   speeds; filter input ``u = [Omega_cmd, tau_cmd / I_w]``;
3. the dual filter (nominal model) alarms on ``F > F_T``; beside it a nominal EKF with the banks'
   process noise gives the windowed NIS test (``chi2(3 L)``, ``L = NIS_WINDOW``), which engages the
   banks by default (``engage_on``: ``F`` is blind to some stops, notebook 05);
4. two banks over the stop hypotheses (eq. 9), slaved to the nominal filter (re-initialised from its
   posterior every step) until detection, then on their own (paper Fig. 10): the credit bank (a dual
   filter per hypothesis, credits ``C_x``, eq. 10) and the likelihood bank (static MM over the
   nominal model and the four stops, probabilities from the innovations' likelihoods);
5. the wheels deliver the commanded torques with the fault (``wheel_fault``) and torque noise; the
   truth (quaternion, rates, wheel speeds) moves one RK4 step with a disturbance torque.

Wheel speeds are not measured; the only sensors are the three gyros (``gyro_fault``: x gyro NaN or holding its onset
reading; gyro ``j`` has label ``1 + N + j``, wheel ``i`` ``1 + i``, ``faults.sensor_labels(N, 3)``). The gyro health
test (``loop.FDI.observe``, before the controller) names a frozen or dead gyro; the controller then flies, for a dead
sample or a gyro found frozen (out of service for the rest of the run), on the posterior rate of a nominal filter (EKF,
or UKF with ``estimator="ukf"``) that leaves it out (``missing_measurements``). A frozen gyro's held value still reaches
the controller for at most ``HEALTH_WINDOW - 1`` steps (indistinguishable from a live reading before). The two stages
see the raw readings: a dead gyro makes each decision alarm with the gyro's label
(``two_stage_isolation(channel_labels=...)``, ``chi2.flag_dead``); a frozen gyro is only what their statistics make of
it. Each run records per method the first decision at or after the onset, false alarms before it and the isolated wheel
or gyro (``metrics.DetectionRecord``).

Choices the paper leaves open (documented, tested):

- gyros 10 Hz, noise 3e-4 rad/s (0.017 deg/s, a small satellite's MEMS/FOG class);
- wheel bias speeds 2000 rpm, pattern ``momentum`` (``MOMENTUM_PATTERNS``; ``"zero"`` is the
  headline's second row); the 10 deg slew keeps every wheel within ~45 % of its bias (stops at speed);
- disturbance torque 1e-5 N m, wheel torque noise 2e-5 N m (white, per sample);
- estimation EKF process noise 1e-4 rad/s per step (``F`` sees a fault only if the EKF follows it;
  a matched ``Q`` ~ 1e-6 is as blind as the prediction); the banks' EKFs and the NIS test's 1e-5;
- banks engaged with their prior widened by 2e-3 rad/s (the nominal filter lags a stop's rate jump);
- isolators confirm over ``CONFIRM_STEPS``; onset uniform in 15-25 s.

Reference: Choi & Park (2009), "Design of Fault Isolator of Satellite Reaction Wheel System Using Dual
Filter and Multi-hypothesis Extended Kalman Filter" (CITATION.cff).
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import (
    FDI,
    DetectionRecord,
    Fault,
    FaultKind,
    Structure,
    Study,
    Target,
    binomial_lower_bound,
    cell,
    checks,
    combine_scorers,
    detection_scorer,
    fault,
    fault_label,
    health_scorer,
    no_fault,
    peak_scorer,
    rate_cell,
    run_loop,
    run_study,
    sensor_labels,
    stack_faults,
    study_result,
    unhealthy_warning,
)
from jaxfdi.control import (
    AttitudeGains,
    Slew,
    pd_gains,
    slew,
    slew_reference,
    wheel_attitude_controller,
    wheel_plant,
)
from jaxfdi.detection import (
    Decision,
    chi2_threshold,
    frozen_channel_detector,
    hypothesis_credits,
    two_stage_isolation,
)
from jaxfdi.filters import GaussianState, extended_kalman_filter, unscented_kalman_filter
from jaxfdi.models import (
    SpacecraftParams,
    WheelCommand,
    body_rate_field,
    filter_input,
    gyro_observation,
    kitsat3_params,
    stop_hypotheses,
    wheel_momentum,
    wheel_rate_transition,
)
from jaxfdi.plotting import column_subplots, hypothesis_colors
from jaxfdi.scenarios._common import check_methods, check_study, figure_collector, require_x64

RPM = 2.0 * math.pi / 60.0
#: steps in the NIS window of the chi-square detector
NIS_WINDOW = 10
#: the manoeuvre: a slew about (1, 1, 1) over the first 40 s
SLEW_DEG = 10.0
#: consecutive steps an isolator's decision must hold
CONFIRM_STEPS = 3
#: the isolation deadline (seconds after the onset) of the rates reported
ISOLATION_DEADLINE_S = 2.0
#: samples in the gyro health test's window: a frozen gyro is found at most HEALTH_WINDOW - 1
#: steps after its onset, sometimes earlier (a live sample close to the held value)
HEALTH_WINDOW = 10
#: gyro health test false-alarm probability per window and gyro, an upper bound whatever the plant
#: (``detection.frozen``); a fault-free run of T steps: <= ``3 T HEALTH_PFA`` = 1.8e-4 for 600 (union bound)
HEALTH_PFA = 1e-7
#: the gyro fault kinds of the study and the fault kind each is
GYRO_KINDS = {"dead": FaultKind.DEAD, "frozen": FaultKind.STUCK}
#: the gyro of the study's dead and frozen cases (0: x)
GYRO_AXIS = 0


class WheelDesign(NamedTuple):
    """Everything a run needs besides its key and its fault (a pytree of arrays).

    Attributes:
      params: nominal model (wheel_mask all ones)
      gains: the attitude controller's gains
      profile: the slew to fly
      initial_speeds: (N,) rad/s
      gyro_sigma: () rad/s
      disturbance_sigma: () N m, external torque per axis
      wheel_noise_sigma: () N m, motor torque noise per wheel
      estimator_q: () rad/s per step, the dual filter's EKF process noise
      bank_q: () rad/s per step, the banks' EKF process noise
      initial_sigma: () rad/s, prior std of the rates
      engage_sigma: () rad/s, added to the banks' prior std at engagement
      detection_threshold: () F_T
      nis_threshold: () on the windowed NIS of the nominal EKF
      credit_threshold: () on the relative credit C_x / F_mean
      mode_threshold: () mu_T
      mm_floor: () MM probability floor
    """

    params: SpacecraftParams
    gains: AttitudeGains
    profile: Slew
    initial_speeds: Array
    gyro_sigma: Array
    disturbance_sigma: Array
    wheel_noise_sigma: Array
    estimator_q: Array
    bank_q: Array
    initial_sigma: Array
    engage_sigma: Array
    detection_threshold: Array
    nis_threshold: Array
    credit_threshold: Array
    mode_threshold: Array
    mm_floor: Array


#: wheel bias-speed signs: ``net`` (default) all the same way, net momentum ``I_w H^T Omega`` (+z for the
#: pyramid), ``det A`` not structurally zero, so F's rise at a stop (Choi & Park) can be checked; ``zero`` in
#: the null space of ``H^T``, zero net momentum, ``det A = 0`` on the true trajectory (notebook 05)
MOMENTUM_PATTERNS = {"net": (1.0, 1.0, 1.0, 1.0), "zero": (1.0, -1.0, 1.0, -1.0)}


def wheel_design(
    dt: float = 0.1,
    bias_rpm: float = 2000.0,
    detection_threshold: float = 6e-9,
    nis_pfa: float = 1e-5,
    credit_threshold: float = 0.5,
    mode_threshold: float = 0.9,
    momentum: str = "net",
    dtype=None,
) -> WheelDesign:
    """The scenario's defaults (module doc); ``detection_threshold`` ``F_T`` is a placeholder that
    ``wheel_study`` calibrates on fault-free runs; ``momentum``: a key of ``MOMENTUM_PATTERNS``."""
    checks.check_choice("momentum", momentum, list(MOMENTUM_PATTERNS))
    dtype = dtype or jnp.result_type(float)
    params = kitsat3_params(dt=dt, dtype=dtype)
    null = jnp.asarray(MOMENTUM_PATTERNS[momentum], dtype)
    arr = lambda v: jnp.asarray(v, dtype)
    return WheelDesign(
        params=params,
        gains=pd_gains(params.inertia, natural_frequency=0.1, damping=0.9, max_wheel_torque=0.02),
        profile=slew(
            axis=(1.0, 1.0, 1.0), angle_deg=SLEW_DEG, start=0.0, duration=40.0, dtype=dtype
        ),
        initial_speeds=bias_rpm * RPM * null,
        gyro_sigma=arr(3e-4),
        disturbance_sigma=arr(1e-5),
        wheel_noise_sigma=arr(2e-5),
        estimator_q=arr(1e-4),
        bank_q=arr(1e-5),
        initial_sigma=arr(1e-3),
        engage_sigma=arr(2e-3),
        detection_threshold=arr(detection_threshold),
        nis_threshold=chi2_threshold(3 * NIS_WINDOW, nis_pfa).astype(dtype),
        credit_threshold=arr(credit_threshold),
        mode_threshold=arr(mode_threshold),
        mm_floor=arr(1e-6),
    )


def wheel_fault(kind: str, wheel: int, onset: int, magnitude: float = 0.0) -> Fault:
    """A wheel fault as a ``Fault`` on the motor-torque vector (actuator ``wheel``).

    ========== ============================================================
    ``stop``   speed to 0 at the onset (its momentum goes to the body), no torque after
    ``stuck``  speed frozen at its value at the onset (no torque)
    ``bias``   delivered torque = command + ``magnitude`` (N m)
    ``gain``   delivered torque = (1 - ``magnitude``) command
    ========== ============================================================
    """
    kinds = {
        "stop": FaultKind.STOP,
        "stuck": FaultKind.STUCK,
        "bias": FaultKind.BIAS,
        "gain": FaultKind.EFFECTIVENESS,
    }
    if kind not in kinds:
        raise ValueError(f"kind: expected one of {sorted(kinds)}, got {kind!r}")
    return fault(kinds[kind], Target.ACTUATOR, wheel, onset, magnitude)


def gyro_fault(kind: str, axis: int, onset: int) -> Fault:
    """A gyro fault on ``axis`` (0, 1, 2: x, y, z) from ``onset``: ``dead`` (NaN, ``FaultKind.DEAD``) or
    ``frozen`` (onset reading held, ``FaultKind.STUCK``)."""
    if kind not in GYRO_KINDS:
        raise ValueError(f"kind: expected one of {sorted(GYRO_KINDS)}, got {kind!r}")
    return fault(GYRO_KINDS[kind], Target.SENSOR, axis, onset)


def gyro_labels(params: SpacecraftParams) -> Array:
    """(3,) int: the fault label of each gyro, ``1 + N + j`` (``faults.sensor_labels``)."""
    return sensor_labels(params.wheel_axes.shape[0], 3)


def estimation_filter(
    params: SpacecraftParams,
    q_sigma: Array,
    gyro_sigma: Array,
    kind: str = "ekf",
    missing_measurements: bool = False,
):
    """The estimation filter on the rate model: EKF (Choi & Park 2009) or UKF."""
    eye = jnp.eye(3, dtype=params.inertia.dtype)
    Q, R = q_sigma**2 * eye, gyro_sigma**2 * eye
    if kind == "ukf":
        return unscented_kalman_filter(
            wheel_rate_transition,
            gyro_observation,
            Q,
            R,
            params,
            alpha=0.5,
            missing_measurements=missing_measurements,
        )
    return extended_kalman_filter(
        wheel_rate_transition, gyro_observation, Q, R, params, missing_measurements
    )


class RunOutput(NamedTuple):
    """What a reaction-wheel run leaves: each method's record and the run's peaks.

    Attributes:
      fdp: dual filter: F > F_T (Choi & Park 2009)
      nis: chi-square on the nominal EKF's windowed NIS
      credit: credit isolator, banks engaged on the chosen detector
      likelihood: MM mode probabilities, same engagement
      health: gyro health test (frozen / dead gyro), labels gyro_labels
      max_fault_free_fdp: () max F before the onset
      max_fault_free_nis: () max windowed NIS before the onset
      max_early_fdp: () max F within ISOLATION_DEADLINE_S after the onset
      healthy: () bool: every filter healthy at every step
    """

    fdp: DetectionRecord
    nis: DetectionRecord
    credit: DetectionRecord
    likelihood: DetectionRecord
    health: DetectionRecord
    max_fault_free_fdp: Array
    max_fault_free_nis: Array
    max_early_fdp: Array
    healthy: Array


class WheelHistory(NamedTuple):
    """Per-step signals of one run (for the figures).

    Attributes:
      attitude: (T, 4) true quaternion
      rate: (T, 3) true body rates
      reference_rate: (T, 3) the slew's reference body rates
      measurement: (T, 3) gyro readings
      wheel_speed: (T, N) true
      commanded_speed: (T, N) commanded wheel speeds
      detection_parameter: (T,) F of the nominal dual filter
      windowed_nis: (T,) windowed NIS of the nominal EKF
      hypothesis_parameter: (T, M) F_x of the credit bank
      credit: (T, M) C_x
      mode_prob: (T, M + 1) MM, normal mode first
      engaged: (T,) bool: the banks run on their own
      controller_rate: (T, 3) the rates the controller flew on (``wheel_fdi``'s view)
    """

    attitude: Array
    rate: Array
    reference_rate: Array
    measurement: Array
    wheel_speed: Array
    commanded_speed: Array
    detection_parameter: Array
    windowed_nis: Array
    hypothesis_parameter: Array
    credit: Array
    mode_prob: Array
    engaged: Array
    controller_rate: Array


def wheel_fdi(
    design: WheelDesign,
    estimator: str = "ekf",
    engage_on: str = "nis",
    restart_prediction: bool = True,
    gyro_health: bool = True,
):
    """The two-stage FDI of Choi and Park (2009) (``detection.two_stage``: ``F``, the NIS test, the credit and
    likelihood banks) as a ``loop.FDI`` on the gyro readings and wheel commands (``init()``: the state before step 0).

    ``restart_prediction`` (default): at engagement each hypothesis's prediction filter starts from its own EKF's
    posterior, not the nominal filter's predicted mean, which lags a stop's rate jump (``I^-1 I_w Omega_i a_i``, ~0.017
    rad/s): started there, every ``F_x`` is that lag projected on ``grad det A_x`` and the credits rank by geometry,
    whichever wheel stopped. ``False``: from the nominal predicted mean (comparison).

    ``observe`` runs the gyro health test on the raw rates
    (``frozen_channel_detector(gyro_sigma, HEALTH_WINDOW, HEALTH_PFA, gyro_labels)``; a NaN sample alarms at once) and
    gives the controller an ``AttitudeReading``: the reading where the gyro is in service and finite, else (NaN, or
    found frozen: out of service from then on) the posterior of a nominal ``estimator`` filter with the banks' process
    noise that leaves those gyros out. Output: the two stages' ``TwoStageOutput``, the health decision appended fifth to
    ``decisions``, ``healthy`` also covering that filter. ``gyro_health=False`` drops the test and the view (fifth
    decision never alarms; the controller flies on raw readings, NaN included): for plants with gyro noise below
    ``gyro_sigma`` (noise-free runs),
    where the stuck-at test rightly finds every gyro frozen.
    """
    if estimator not in ("ekf", "ukf"):
        raise ValueError(f"estimator: expected 'ekf' or 'ukf', got {estimator!r}")
    params = design.params
    dtype = params.inertia.dtype
    N = params.wheel_axes.shape[0]
    eye = jnp.eye(3, dtype=dtype)
    labels = gyro_labels(params)
    stages = two_stage_isolation(
        estimation_filter(params, design.estimator_q, design.gyro_sigma, estimator),
        lambda p: estimation_filter(
            p, design.bank_q, design.gyro_sigma, estimator
        ),  # tighter: the NIS test's and banks'
        wheel_rate_transition,
        body_rate_field,
        params,
        stop_hypotheses(params),
        stop_hypotheses(params, include_nominal=True),
        detection_threshold=design.detection_threshold,
        nis_threshold=design.nis_threshold,
        nis_window=NIS_WINDOW,
        credit_threshold=design.credit_threshold,
        mode_threshold=design.mode_threshold,
        mm_floor=design.mm_floor,
        engage_cov=design.engage_sigma**2 * eye,
        confirm_steps=CONFIRM_STEPS,
        engage_on=engage_on,
        restart_prediction=restart_prediction,
        channel_labels=labels,
    )
    health_test = frozen_channel_detector(
        jnp.full((3,), design.gyro_sigma, dtype), HEALTH_WINDOW, HEALTH_PFA, labels
    )
    view_filter = estimation_filter(
        params, design.bank_q, design.gyro_sigma, estimator, missing_measurements=True
    )
    u0 = jnp.concatenate([design.initial_speeds, jnp.zeros(N, dtype)])
    mean0, cov0 = jnp.zeros(3, dtype), design.initial_sigma**2 * eye
    state0 = dict(
        stages=stages.init(mean0, cov0, u0),
        health=health_test.init(),
        verdict=Decision(
            jnp.zeros((), dtype),
            jnp.zeros((), bool),
            jnp.asarray(-1, jnp.int32),
            jnp.full((), jnp.nan, dtype),
        ),
        out=jnp.zeros((3,), bool),
        view=GaussianState(mean0, cov0),
        view_healthy=jnp.ones((), bool),
        u=u0,
    )

    def observe(c, k, reading):
        health, verdict = health_test.step(c["health"], reading.rate)
        frozen = verdict.alarm & jnp.isfinite(
            verdict.statistic
        )  # +inf: a dead sample, not a frozen gyro
        out = c["out"] | (frozen & (labels == verdict.label))
        post = view_filter.update(c["view"], jnp.where(out, jnp.nan, reading.rate), c["u"])
        rate = jnp.where(out | ~jnp.isfinite(reading.rate), post.filtered_mean, reading.rate)
        c = dict(
            c,
            health=health,
            verdict=verdict,
            out=out,
            view=post.posterior,
            view_healthy=post.healthy,
        )
        return c, reading._replace(rate=rate)

    def step(c, k, reading, command):
        u = filter_input(command, params)
        stages_state, output = stages.step(c["stages"], reading.rate, u)
        view = (
            view_filter.predict(c["view"], u) if gyro_health else c["view"]
        )  # observe left step k's posterior
        output = output._replace(
            decisions=output.decisions + (c["verdict"],), healthy=output.healthy & c["view_healthy"]
        )
        return dict(c, stages=stages_state, view=view, u=u), output

    return FDI(lambda: state0, step, observe if gyro_health else None)


def run_wheels(
    design: WheelDesign,
    key: Array,
    f: Fault,
    steps: int = 600,
    estimator: str = "ekf",
    engage_on: str = "nis",
    history: bool = False,
):
    """One closed-loop run ``run_loop(wheel_plant, wheel_fdi, wheel_attitude_controller)``; returns
    ``RunOutput`` (and ``WheelHistory`` if ``history``). ``engage_on``: the detector whose first alarm
    engages the banks, ``"nis"`` (default) or ``"fdp"`` (the paper's ``F``); ``estimator``: ``"ekf"``/``"ukf"``.
    """
    params = design.params
    dtype = params.inertia.dtype
    N = params.wheel_axes.shape[0]
    fdi = wheel_fdi(design, estimator, engage_on)
    plant = wheel_plant(
        params, f, design.gyro_sigma, design.disturbance_sigma, design.wheel_noise_sigma
    )
    controller = wheel_attitude_controller(
        params, design.gains, design.profile, design.initial_speeds
    )

    def early(k):  # within the isolation deadline after the onset
        return (k >= f.onset) & ((k - f.onset) * params.dt < ISOLATION_DEADLINE_S)

    scorer = combine_scorers(
        records=detection_scorer(f.onset, lambda out: out.decisions, dtype=dtype),  # METHODS' order
        peaks=peak_scorer(
            lambda out: jnp.concatenate([out.peaks, out.peaks[:1]]),
            lambda k: jnp.stack([k < f.onset, k < f.onset, early(k)]),
            dtype,
        ),
        healthy=health_scorer(),
    )
    x0 = jnp.concatenate(
        [jnp.array([1.0, 0, 0, 0], dtype), jnp.zeros(3, dtype), design.initial_speeds]
    )
    u0 = WheelCommand(design.initial_speeds, jnp.zeros(N, dtype))
    result = run_loop(
        plant,
        fdi,
        controller,
        x0,
        fdi.init(),
        key,
        steps,
        u0=u0,
        scorer=scorer,
        keep_history=history,
    )
    score = result.score
    out = RunOutput(*score["records"], *score["peaks"], score["healthy"])
    if not history:
        return out
    trace = result.history
    truth, reading, o = trace.sensed.state, trace.sensed.measurement, trace.output
    t = jnp.arange(steps) * params.dt
    reference = jax.vmap(lambda s: slew_reference(s, design.profile)[1])(t)
    return out, WheelHistory(
        truth[:, :4],
        truth[:, 4:7],
        reference,
        reading.rate,
        truth[:, 7:],
        trace.control.speeds,
        o.peaks[:, 0],
        o.peaks[:, 1],
        o.hypothesis_parameter,
        jax.vmap(hypothesis_credits)(o.hypothesis_parameter),
        o.mode_prob,
        o.engaged,
        trace.view.rate,
    )


# --- the Monte Carlo study -------------------------------------------------------

#: fault kinds of the study and their magnitudes (stop and stuck take none)
KINDS = {"stop": 0.0, "stuck": 0.0, "bias": 2e-3, "gain": 0.5}
#: fault onsets are drawn uniformly from these steps (15 s to 25 s at 10 Hz)
ONSET_RANGE = (150, 250)
METHODS = ("fdp", "nis", "credit", "likelihood", "health")
METHOD_NAMES = {
    "fdp": "dual filter F (paper)",
    "nis": "NIS chi-square",
    "credit": "credit isolator (paper)",
    "likelihood": "MM likelihood",
    "health": "gyro health test",
}
#: the methods that name a wheel (F and NIS only detect, the health test names gyros)
WHEEL_ISOLATORS = ("credit", "likelihood")


def study_cases() -> list[tuple[str, int]]:
    """``('none', -1)``, every ``KINDS`` on wheels 0..3, then every ``GYRO_KINDS`` on gyro ``GYRO_AXIS``."""
    return (
        [("none", -1)]
        + [(kind, wheel) for kind in KINDS for wheel in range(4)]
        + [(kind, GYRO_AXIS) for kind in GYRO_KINDS]
    )


def case_name(kind: str, component: int) -> str:
    """``none``, ``<kind> w<i>`` (wheel ``i``, from 1) or ``<kind> g<j>`` (gyro ``j``, from 1: x, y, z)."""
    if kind == "none":
        return "none"
    return f"{kind} {'g' if kind in GYRO_KINDS else 'w'}{component + 1}"


def case_faults(cases: list[tuple[str, int]], runs: int, key: Array) -> Fault:
    """Stacked ``len(cases) * runs`` faults, case-major, random onsets (fault-free: ``faults.NEVER``, the whole run
    counts for false alarms); a case is ``(kind, wheel)`` (``KINDS``) or ``(kind, gyro axis)`` (``GYRO_KINDS``)."""
    onsets = np.asarray(
        jax.random.randint(key, (len(cases), runs), ONSET_RANGE[0], ONSET_RANGE[1] + 1)
    )
    faults = []
    for (kind, component), onset_row in zip(cases, onsets):
        for onset in onset_row:
            faults.append(
                no_fault()
                if kind == "none"
                else gyro_fault(kind, component, int(onset))
                if kind in GYRO_KINDS
                else wheel_fault(kind, component, int(onset), KINDS[kind])
            )
    return stack_faults(faults)


@functools.lru_cache(maxsize=None)
def _closed_loop(steps: int, estimator: str, engage_on: str):
    """``run(key, fault, design)``: ``run_wheels`` with the design as data; one function per option
    set, so one compiled program serves every design, run count and seed."""

    def run(key, f, design):
        return run_wheels(design, key, f, steps, estimator, engage_on)

    return run


def wheel_spec(
    design: WheelDesign,
    cases: Sequence[tuple[str, int]],
    steps: int = 600,
    estimator: str = "ekf",
    engage_on: str = "nis",
    name: str = "reaction-wheels",
) -> Study:
    """The study of ``cases`` (as ``study_cases``) on ``design``: one structure, ``run_wheels`` with the
    design as data; faults ``case_faults(cases, runs, key(seed + 2))``, onsets uniform in
    ``ONSET_RANGE``; every method comes out of the same run (``outputs["closed loop"]``, a ``RunOutput``)."""
    cases = tuple(cases)
    names = tuple(case_name(kind, component) for kind, component in cases)
    loop = Structure(
        "closed loop",
        _closed_loop(steps, estimator, engage_on),
        (),
        {"closed loop": ()},
        shared=design,
    )
    return Study(
        name, lambda runs, seed: case_faults(cases, runs, jax.random.key(seed + 2)), names, (loop,)
    )


#: F_T = FDP_MARGIN x the largest F of the fault-free calibration runs
FDP_MARGIN = 1.5


def calibrate_fdp_threshold(
    design: WheelDesign, runs: int, seed: int, margin: float = FDP_MARGIN, **options
) -> float:
    """``F_T = margin * max F`` over ``runs`` fault-free runs of ``seed`` (the paper sets it by eye; ``F``
    has no known distribution; a new run exceeds the max of ``n`` with probability ``1 / (n + 1)``).
    ``options``: ``steps``, ``estimator``, ``engage_on`` (``wheel_spec``), ``chunk_size``, ``progress``."""
    spec_options = {k: options.pop(k) for k in ("steps", "estimator", "engage_on") if k in options}
    spec = wheel_spec(
        design, [("none", -1)], name="reaction-wheels F_T calibration", **spec_options
    )
    out = run_study(spec, runs, seed, **options).outputs["closed loop"]
    return float(margin * np.max(out.max_fault_free_fdp))


def run_is_healthy(out: RunOutput) -> np.ndarray:
    """(runs,) bool: every filter healthy at every step, no statistic NaN (a dead gyro's +inf is
    evidence, ``metrics.step_health``)."""
    records = (out.fdp, out.nis, out.credit, out.likelihood, out.health)
    return np.asarray(out.healthy) & np.all(
        [np.asarray(r.first_unhealthy) < 0 for r in records], axis=0
    )


def summarize_method(
    record: DetectionRecord,
    wheel: int,
    dt: float,
    isolating: bool,
    label: int | None = None,
    names_it: bool = True,
) -> dict:
    """Rates and delays of one method over one case's runs (``wheel < 0``: fault-free, false alarms only).

    - ``rate``: detected (detectors) or isolated to ``label`` (isolators; default ``wheel + 1``) at or after the onset;
    - ``decided_rate``: a decision at or after the onset; ``isolation_rate``: the first one names ``label``
      (``None`` if ``names_it=False``: F and NIS for a wheel);
    - ``pre_onset_alarm_rate``: a decision before the onset (false-alarm runs); ``clean_runs``: the others;
    - delays (mean, median, p90) and ``rate_within_deadline`` (right within ``ISOLATION_DEADLINE_S``, over
      all runs) count clean runs only."""
    onset = np.asarray(record.onset)
    detection = np.asarray(record.detection_step)
    detected = detection >= 0
    delay = (detection - onset) * dt
    pre_alarm = np.asarray(record.false_alarms) > 0
    false_alarm = float(np.mean(pre_alarm))
    row = {"false_alarm_rate": false_alarm}
    if wheel < 0:
        return row
    label = wheel + 1 if label is None else label
    named = detected & (np.asarray(record.isolated) == label)
    correct = named if isolating else detected
    scored = correct & ~pre_alarm
    in_time = scored & (delay <= ISOLATION_DEADLINE_S + 1e-9)
    nan = float("nan")
    row.update(
        {
            "rate": float(np.mean(correct)),
            "rate_within_deadline": float(np.mean(in_time)),
            "delay_mean_s": float(np.mean(delay[scored])) if scored.any() else nan,
            "delay_median_s": float(np.median(delay[scored])) if scored.any() else nan,
            "delay_p90_s": float(np.percentile(delay[scored], 90)) if scored.any() else nan,
            "decided_rate": float(np.mean(detected)),
            "isolation_rate": float(np.mean(named)) if names_it else None,
            "pre_onset_alarm_rate": false_alarm,
            "clean_runs": int(np.sum(~pre_alarm)),
            "delay_runs": int(np.sum(scored)),
        }
    )
    return row


def summarize_case(part: RunOutput, kind: str, wheel: int, dt: float, methods=METHODS) -> dict:
    """One case's table row; unhealthy runs are counted in ``unhealthy_runs`` and left out of every rate.
    ``wheel``: the wheel, or for ``GYRO_KINDS`` the gyro axis (row: ``wheel = -1``, ``gyro``); right label
    ``wheel + 1`` or ``gyro_labels``'. Isolating methods: credit, MM and the gyro health test."""
    healthy = run_is_healthy(part)
    clean = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[healthy], part)
    gyro = kind in GYRO_KINDS
    row = {
        "case": case_name(kind, wheel),
        "kind": kind,
        "wheel": -1 if gyro else wheel,
        "magnitude": KINDS.get(kind, 0.0),
    }
    if gyro:
        row["gyro"] = wheel
    # the fault's label: fault_label as the simulator derives it (N = 4 wheels before the gyros)
    label = (
        None
        if kind == "none"
        else int(
            fault_label(
                gyro_fault(kind, wheel, 0) if gyro else wheel_fault(kind, wheel, 0, KINDS[kind]), 4
            )
        )
    )
    for method in methods:
        names_it = gyro or method in WHEEL_ISOLATORS
        row[method] = summarize_method(
            getattr(clean, method),
            wheel,
            dt,
            method in (*WHEEL_ISOLATORS, "health"),
            label,
            names_it,
        )
    if kind != "none" and not gyro:
        row["fdp_ratio_median"] = float(np.median(clean.max_early_fdp / clean.max_fault_free_fdp))
    row["healthy_rate"] = float(np.mean(part.healthy))
    row["runs"], row["unhealthy_runs"] = int(healthy.size), int(np.sum(~healthy))
    return row


@study_result(methods=METHODS)
class WheelStudy(NamedTuple):
    """The reaction-wheel study: its settings, table rows and per-run records.

    Attributes:
      config: the study's settings
      rows: the table's rows, one dict each
      outputs: (cases * runs,) per-run records, case-major
    """

    config: dict
    rows: list[dict]
    outputs: RunOutput

    def table(self) -> str:
        """Per case and method (``summarize_method``): ``det``, ``isol`` (``-``: never names that kind of
        fault), ``<=2s`` (clean runs: isolated for isolators and the health test, detected for F and NIS),
        ``FA``, ``clean`` and the delays of the right decision over clean runs. The health test's line only
        for fault-free and gyro cases (it names no wheel). Each rate with its 95 % Clopper-Pearson interval
        (``metrics.rate_interval``) over the ``n`` healthy runs (``<=2s``: the clean runs)."""
        head = (
            f"{'case':<10} {'method':<24} {'det [95 %]':>19} {'isol [95 %]':>19} {'<=2s [95 %]':>19} "
            f"{'FA [95 %]':>19} {'n':>4} {'clean':>5} {'mean [s]':>8} {'med [s]':>8} {'p90 [s]':>8}"
        )
        lines = [head, "-" * len(head)]
        for row in self.rows:
            shown = [
                m
                for m in METHODS
                if m in row and (m != "health" or row["kind"] in ("none", *GYRO_KINDS))
            ]
            n = row["runs"] - row.get("unhealthy_runs", 0)
            for method in shown:
                r = row[method]
                clean = r.get("clean_runs")
                isolation = (
                    None if "rate" not in r else r.get("isolation_rate")
                )  # None: never isolates (blank)
                isolation = (
                    float("nan") if "rate" in r and isolation is None else isolation
                )  # '-': names none
                delays = " ".join(
                    " " * 8 if r.get(k) is None else cell(r[k], ".2f", 8)
                    for k in ("delay_mean_s", "delay_median_s", "delay_p90_s")
                )
                lines.append(
                    f"{row['case']:<10} {METHOD_NAMES[method]:<24} {rate_cell(r.get('decided_rate'), n, 19)} "
                    f"{rate_cell(isolation, n, 19)} {rate_cell(r.get('rate_within_deadline'), clean, 19)} "
                    f"{rate_cell(r['false_alarm_rate'], n, 19)} {n:>4} {'' if clean is None else clean:>5} "
                    f"{delays}"
                )
        bad = [row for row in self.rows if row.get("unhealthy_runs")]
        warning = unhealthy_warning(
            sum(row["unhealthy_runs"] for row in bad),
            sum(row["runs"] for row in self.rows),
            ", ".join(f"{row['case']} {row['unhealthy_runs']}" for row in bad),
        )
        return "\n".join(lines + ([warning] if warning else []))

    def headline(self) -> str:
        """The stop cases beside the paper (qualitative: no numbers there), net momentum then zero; the
        credit rate per wheel with its one-sided 95 % Clopper-Pearson lower bound."""
        lines = [
            "Wheel stops (Choi & Park 2009 report one run: F jumps by orders of magnitude at the stop of wheel 1, and",
            "credit 1 separates from the others immediately):",
        ]
        blocks = [(self.config.get("momentum", "net"), self.rows)]
        zero = self.config.get("zero_momentum")
        if zero:
            blocks.append(("zero", zero["rows"]))
        for momentum, rows in blocks:
            lines.append(
                "  net wheel momentum (all wheels biased +2000 rpm; det A not structurally 0):"
                if momentum == "net"
                else "  zero net momentum (bias speeds in the null space of H^T: det A = 0 on the true trajectory, "
                "so F sees a stop only through the model's momentum error):"
            )
            for row in rows:
                if row["kind"] != "stop" or not all(
                    m in row for m in ("fdp", "credit", "likelihood")
                ):
                    continue
                credit = row["credit"]
                right = round(credit["rate"] * (row["runs"] - row.get("unhealthy_runs", 0)))
                lines.append(
                    f"    wheel {row['wheel'] + 1}: F detects {row['fdp']['rate']:.2f} (median "
                    f"{cell(row['fdp']['delay_median_s'], '.1f', 4).strip()} s, F after/before "
                    f"{row['fdp_ratio_median']:.1f}x), credits isolate {credit['rate']:.2f} (>= "
                    f"{binomial_lower_bound(right, row['runs'] - row.get('unhealthy_runs', 0)):.2f} at 95 %), "
                    f"{credit['rate_within_deadline']:.2f} within 2 s; MM "
                    f"{row['likelihood']['rate_within_deadline']:.2f}"
                    f" within 2 s"
                )
        return "\n".join(lines)


def _cases_study(
    design: WheelDesign, cases, runs: int, seed: int, calibration_runs: int, selected, options
):
    threshold = calibrate_fdp_threshold(design, calibration_runs, seed + 1, **options)
    design = design._replace(
        detection_threshold=jnp.asarray(threshold, design.detection_threshold.dtype)
    )
    spec_options = {k: v for k, v in options.items() if k in ("steps", "estimator", "engage_on")}
    run_options = {k: v for k, v in options.items() if k in ("chunk_size", "progress")}
    out = run_study(wheel_spec(design, cases, **spec_options), runs, seed, **run_options).outputs[
        "closed loop"
    ]
    dt = float(design.params.dt)
    rows = []
    for i, (kind, wheel) in enumerate(cases):
        part = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[i * runs : (i + 1) * runs], out)
        rows.append(summarize_case(part, kind, wheel, dt, selected))
    return threshold, rows, out


def wheel_study(
    runs: int = 100,
    seed: int = 0,
    calibration_runs: int = 200,
    estimator: str = "ekf",
    engage_on: str = "nis",
    steps: int = 600,
    chunk_size: int | None = None,
    progress: bool = False,
    methods: Sequence[str] | None = None,
    momentum: str = "net",
    zero_momentum_row: bool = True,
) -> WheelStudy:
    """Every case of ``study_cases`` with ``runs`` Monte Carlo runs (noise and onset), ``F_T`` calibrated
    first on ``calibration_runs`` fault-free runs of seed ``seed + 1``. Needs float64 (``jaxfdi.enable_x64()``).

    - ``methods``: the subset of ``METHODS`` reported (all run anyway: the detectors engage the banks);
    - ``momentum``: ``MOMENTUM_PATTERNS`` key (default ``"net"``, where Choi & Park's F rise at a stop can be checked);
    - ``zero_momentum_row`` (with ``"net"``): the four stops also with zero net momentum (own ``F_T``,
      ``det A`` ~0 on the true trajectory), in ``config["zero_momentum"]`` and the headline's second row;
    - one compiled program on the study engine (``wheel_spec``, ``run_study``; ``chunk_size``: runs per
      call, default the backend's); unhealthy runs are left out of every rate, counted in ``unhealthy_runs``."""
    selected = check_methods(methods, METHODS)
    require_x64("wheel_study")
    check_study(runs, seed, calibration_runs=calibration_runs, steps=steps)
    checks.check_choice("estimator", estimator, ["ekf", "ukf"])
    checks.check_choice("engage_on", engage_on, ["nis", "fdp"])
    checks.check_choice("momentum", momentum, list(MOMENTUM_PATTERNS))
    design = wheel_design(momentum=momentum)
    kwargs = dict(
        steps=steps,
        estimator=estimator,
        engage_on=engage_on,
        chunk_size=chunk_size,
        progress=progress,
    )
    cases = study_cases()
    threshold, rows, out = _cases_study(
        design, cases, runs, seed, calibration_runs, selected, kwargs
    )
    dt = float(design.params.dt)
    zero = None
    if zero_momentum_row and momentum != "zero":
        zero_threshold, zero_rows, _ = _cases_study(
            wheel_design(momentum="zero"),
            [("stop", w) for w in range(4)],
            runs,
            seed,
            calibration_runs,
            selected,
            kwargs,
        )
        zero = {"fdp_threshold": zero_threshold, "rows": zero_rows}
    config = {
        "runs": runs,
        "seed": seed,
        "calibration_runs": calibration_runs,
        "estimator": estimator,
        "engage_on": engage_on,
        "steps": steps,
        "dt": dt,
        "onset_range_steps": list(ONSET_RANGE),
        "fdp_threshold": threshold,
        "nis_threshold": float(design.nis_threshold),
        "nis_window": NIS_WINDOW,
        "credit_threshold": float(design.credit_threshold),
        "mode_threshold": float(design.mode_threshold),
        "confirm_steps": CONFIRM_STEPS,
        "fdp_margin": FDP_MARGIN,
        "kinds": KINDS,
        "slew_deg": SLEW_DEG,
        "gyro_kinds": list(GYRO_KINDS),
        "gyro_axis": GYRO_AXIS,
        "gyro_labels": [int(v) for v in np.asarray(gyro_labels(design.params))],
        "health_window": HEALTH_WINDOW,
        "health_pfa_per_window": HEALTH_PFA,
        "bias_rpm": float(design.initial_speeds[0] / RPM),
        "momentum": momentum,
        "wheel_bias_speeds_rpm": [float(v) for v in np.asarray(design.initial_speeds) / RPM],
        "net_wheel_momentum_Nms": [
            float(v) for v in np.asarray(wheel_momentum(design.initial_speeds, design.params))
        ],
    }
    if zero is not None:
        config["zero_momentum"] = zero
    return WheelStudy(config, rows, out)


def wheel_examples(
    design: WheelDesign,
    seed: int = 0,
    wheel: int = 0,
    onset: int = 200,
    steps: int = 600,
    estimator: str = "ekf",
    engage_on: str = "nis",
) -> dict[str, WheelHistory]:
    """One fault-free run and one stop of ``wheel`` at ``onset`` (same noise), with histories."""
    run = jax.jit(
        jax.vmap(
            lambda f: run_wheels(
                design, jax.random.key(seed), f, steps, estimator, engage_on, history=True
            )[1]
        )
    )
    both = run(stack_faults([no_fault(), wheel_fault("stop", wheel, onset)]))
    both = jax.tree_util.tree_map(np.asarray, both)
    return {
        name: jax.tree_util.tree_map(lambda leaf: leaf[i], both)
        for i, name in enumerate(["none", "stop"])
    }


def plot_wheels(
    study: WheelStudy, examples: dict[str, WheelHistory], wheel: int = 0, onset: int = 200
) -> dict[str, Any]:
    """Figs. 3-9 of Choi and Park (2009) (attitude, F, F_x, credits) and the MM's mode probabilities;
    captioned; returns them by file name (``plotting.save_figures`` writes them)."""
    add, figures = figure_collector()
    cfg = study.config
    t = np.arange(cfg["steps"]) * cfg["dt"]
    fault_time = onset * cfg["dt"]

    # Figs. 3 and 5: attitude and rates, fault-free and with the stop
    fig, axes = column_subplots(5.0, 2, 2, sharex=True)
    for col, (name, title) in enumerate(
        [
            ("none", "Fig. 3: fault-free"),
            ("stop", f"Fig. 5: wheel {wheel + 1} stops at {fault_time:.0f} s"),
        ]
    ):
        h = examples[name]
        angle = np.degrees(2.0 * np.arccos(np.clip(np.abs(h.attitude[:, 0]), 0.0, 1.0)))
        axes[0, col].plot(t, angle, lw=1)
        axes[0, col].set(ylabel="rotation from start [deg]", title=title)
        axes[1, col].plot(t, h.rate * 1e3, lw=1)
        axes[1, col].plot(t, h.reference_rate[:, 0] * 1e3, "k:", lw=1, label="reference")
        axes[1, col].set(ylabel="body rates [mrad/s]", xlabel="time [s]")
        axes[1, col].legend(["p", "q", "r", "reference"], fontsize=7)
        if name == "stop":
            for ax in axes[:, col]:
                ax.axvline(fault_time, color="grey", ls=":", lw=1)
    add(
        fig,
        "reaction-wheels-fig3-5-attitude.png",
        f"One run each: attitude (rotation from the start) and body rates, fault-free and with wheel {wheel + 1} "
        f"stopping at {fault_time:.0f} s, as Choi & Park (2009), Figs. 3 and 5 (a single run there too).",
    )

    # Figs. 4 and 6: the fault detection parameter, and the NIS test beside it
    fig, axes = column_subplots(5.0, 2, 1, sharex=True)
    for name, label in [("none", "fault-free"), ("stop", f"wheel {wheel + 1} stop")]:
        axes[0].semilogy(
            t, np.maximum(examples[name].detection_parameter, 1e-16), lw=0.8, label=label
        )
        axes[1].plot(t, examples[name].windowed_nis, lw=0.8, label=label)
    axes[0].axhline(
        cfg["fdp_threshold"], color="r", ls="--", lw=1, label=f"F_T = {cfg['fdp_threshold']:.2e}"
    )
    axes[0].set(
        ylabel="F = |det A_PF - det A_EKF|",
        title="Figs. 4 and 6: dual filter fault detection parameter",
        ylim=(1e-14, None),
    )
    axes[1].axhline(
        cfg["nis_threshold"],
        color="r",
        ls="--",
        lw=1,
        label=f"threshold {cfg['nis_threshold']:.1f}",
    )
    axes[1].set(ylabel=f"NIS over {cfg['nis_window']} steps", xlabel="time [s]", yscale="log")
    for ax in axes:
        ax.axvline(fault_time, color="grey", ls=":", lw=1)
        ax.legend(fontsize=7)
    add(
        fig,
        "reaction-wheels-fig4-6-detection.png",
        "The same two runs: the dual filter's fault detection parameter F (Choi & Park 2009, "
        "Figs. 4 and 6) and, beside the "
        "paper, the windowed NIS test that engages the isolators. F jumps by orders of magnitude at the stop, as in "
        "the paper.",
    )

    # Figs. 8 and 9: the hypothesis bank's F_x and credits; the MM's mode probabilities
    h = examples["stop"]
    zoom = (t >= fault_time - 2.0) & (t <= fault_time + 8.0)
    fig, axes = column_subplots(7.0, 3, 1, sharex=True)
    names = [f"H{i + 1}: wheel {i + 1} stopped" for i in range(h.credit.shape[1])]
    engaged = h.engaged[zoom]
    colors = hypothesis_colors(
        ["nominal"] + names
    )  # a hypothesis keeps its colour in the three panels
    for i, label in enumerate(names):
        axes[0].semilogy(
            t[zoom],
            np.where(engaged, np.maximum(h.hypothesis_parameter[zoom, i], 1e-16), np.nan),
            lw=1,
            color=colors[label],
            label=label,
        )
        axes[1].plot(
            t[zoom],
            np.where(engaged, h.credit[zoom, i], np.nan),
            lw=1,
            color=colors[label],
            label=label,
        )
    for i, label in enumerate(["nominal"] + names):
        axes[2].plot(t[zoom], h.mode_prob[zoom, i], lw=1, color=colors[label], label=label)
    axes[0].set(
        ylabel="F_x",
        title=f"Fig. 8: the bank's F_x after wheel {wheel + 1} stops (engaged on detection)",
    )
    axes[1].set(ylabel="credit C_x", title="Fig. 9: credits C_x = max(F_mean - F_x, 0)")
    axes[2].set(
        ylabel="mode probability",
        xlabel="time [s]",
        title="MM over the same hypotheses (likelihood-based)",
    )
    for ax in axes:
        ax.axvline(fault_time, color="grey", ls=":", lw=1)
        ax.legend(fontsize=7)
    end = np.flatnonzero(zoom & h.engaged)
    order = np.argsort(h.credit[end[-1]])[::-1] if end.size else np.zeros(2, int)
    leader, second = int(order[0]) + 1, int(order[1]) + 1
    gap = (
        1.0 - h.credit[end[-1], order[1]] / max(h.credit[end[-1], order[0]], 1e-300)
        if end.size
        else 0.0
    )
    paper = f"the paper's Fig. 9, where credit {wheel + 1} separates from the others at once"
    if leader != wheel + 1:
        agrees = f"the opposite of {paper}"
    elif gap < 0.2:
        agrees = f"only {100 * gap:.0f} % above hypothesis {second}'s, unlike {paper}"
    else:
        agrees = f"as in {paper}"
    leader = leader if end.size else 0
    add(
        fig,
        "reaction-wheels-fig8-9-isolation.png",
        f"One run, the stop of wheel {wheel + 1}: the hypothesis bank's F_x, the credits and the "
        "MM's mode probabilities. In this run "
        f"hypothesis {leader} holds the largest credit 8 s after the stop of wheel {wheel + 1}, {agrees}. The "
        "scalar det A behind F_x discards the direction of the discrepancy; the MM, on the innovation vectors, "
        "keeps it (the isolation rates of both are in the study's table)."
        if leader
        else "The stop run: the bank was not engaged in the window shown.",
    )
    return figures
