"""Lee & Lyou's VTOL example in closed loop: fault detection, isolation and fault-tolerant control (their Fig. 2).

``run_closed_loop`` = ``run_loop(true_plant, tskf_bank_fdi, reconfigurable_pi)``. Step ``k``:

1. the true plant (its own matrices, uncertainty and disturbance states included) is measured, ``y = C_t x_t + v``; a
   sensor fault acts on ``y``;
2. the robust estimator (``unknown_input_filter``) updates with ``y``, compensated ``y_c = y - Fs b`` (eq. 31) once a
   sensor fault is isolated;
3. ``u = -K [x_hat; z]`` (eq. 22), nominal LQR gain, or once an actuator effectiveness loss is isolated the
   eigenstructure-assignment gain for ``B_f = B (I - diag(b))`` at the current ``b`` (eqs. 23-29) from a
   ``GainSchedule`` tabulated once (a solve per step would dominate the loop); an additive actuator fault's estimate is
   added to ``u``;
4. ``z += Ts (r - H x_hat)``; an actuator fault acts on ``u``, the plant moves; the estimator predicts with the input
   the plant is believed to get;
5. the TSKF bank steps on ``(y, u)``; its statistics fill a ``2^M`` block, at whose end the blockwise Haar denoiser
   (soft thresholding) decides, symptoms are matched to the signature matrix, the first isolated fault latched (FTC on:
   the controller switches at that step);
6. a channel-health test on the raw ``y`` (``detection.frozen`` stuck-at per sensor, ``chi2.flag_dead`` for non-finite)
   latches a dead or frozen sensor's location ahead of the bank; with FTC on the estimator leaves it out
   (``missing_measurements=True``, which a NaN sensor gets from its first sample) instead of compensating a bias. A dead
   sensor makes every bank statistic ``+inf``: only this test says which.

Several filters per location (e.g. multiplicative and additive hypotheses): ``location`` maps filter -> location; a
location's symptom is "all its filters alarm"; the kind is its filter with the smaller block statistic. Everything but
the shapes is data: one compiled scan ``vmap``s over faults, keys and FTC switches.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import FDI, Fault, FaultKind, Simulator, run_loop, simulator
from jaxfdi.control import GainSchedule, Reconfiguration, reconfigurable_pi
from jaxfdi.detection import (
    FrozenState,
    frozen_channel_detector,
    haar_denoise,
    isolate,
    location_symptoms,
)
from jaxfdi.filters import (
    FaultDirection,
    GaussianState,
    sensor_matrix,
    two_stage_kalman_filter,
    unknown_input_filter,
)
from jaxfdi.models import LinearGaussianModel


class LoopDesign(NamedTuple):
    """Everything the closed loop needs; build once (concrete arrays).

    Attributes:
      model: nominal model of the estimator and the bank
      unknown_input: (n, q) E, decoupled by the estimator and the bank
      plant_Phi: (nt, nt) true plant (first n states are the model's)
      plant_Gamma: (nt, nu) true plant's input matrix
      plant_C: (m, nt) true plant's output matrix
      plant_x0: (nt,) true plant's initial state
      H: (g, n) tracked outputs
      command: (g,) r, the command of the tracked outputs
      gain: (nu, n + g) nominal K
      schedule: eigenstructure-assignment gains over each input's loss
      directions: bank, leaves (F, ..., 1)
      location: (F,) int: fault location of each filter (0 .. L-1)
      multiplicative: (F,) bool: effectiveness/scaling filter (else additive)
      location_is_actuator: (L,) bool: the location is an actuator (else a sensor)
      location_component: (L,) int: input or output index
      bias_walk: (1, 1) Qb
      init_cov: (n, n) prior covariance of x[0]
      init_bias_cov: (1, 1) prior covariance of each filter's bias
      threshold: (F,) per-filter threshold of the denoised statistic
      detail_sigma: (M,) detail standard deviations for soft thresholding
      c_mult: multiple of each detail's sigma used as the soft threshold
      levels: number of Haar scales of the denoising (blocks of 2^levels steps)
      Ts: sample period [s]
      frozen_window: samples of the channel-health (stuck-at) test
      frozen_pfa: its false-alarm probability per window and sensor (an upper bound)
    """

    model: LinearGaussianModel
    unknown_input: Array
    plant_Phi: Array
    plant_Gamma: Array
    plant_C: Array
    plant_x0: Array
    H: Array
    command: Array
    gain: Array
    schedule: GainSchedule
    directions: FaultDirection
    location: Array
    multiplicative: Array
    location_is_actuator: Array
    location_component: Array
    bias_walk: Array
    init_cov: Array
    init_bias_cov: Array
    threshold: Array
    detail_sigma: Array
    c_mult: float
    levels: int
    Ts: float
    frozen_window: int = 10
    frozen_pfa: float = 1e-6


class BankState(NamedTuple):
    """The FDI's carry: estimator prior, bank, block buffer, latched decision and the step's reconfiguration (set by
    ``observe``, used by ``step``).

    Attributes:
      estimator: prior of the feedback estimator
      bank: the bank's filter states (leaves (F, ...))
      buffer: (2^levels, F) statistics of the current block
      isolated: () int: latched location + 1 (0: none yet)
      kind: () bool: latched fault is multiplicative
      posterior: posterior of the feedback estimator at this step
      reconfiguration: what ``step`` applies (set by ``observe``)
      health: the channel-health test's window
      excluded: (m,) bool: sensors latched dead or frozen (not used by the estimator under FTC)
    """

    estimator: GaussianState
    bank: Any
    buffer: Array
    isolated: Array
    kind: Array
    posterior: GaussianState
    reconfiguration: Reconfiguration
    health: FrozenState
    excluded: Array


class BankOutput(NamedTuple):
    """What the TSKF-bank FDI reports each step.

    Attributes:
      estimate: (n,) x_hat[k|k]
      statistic: (F,) bank statistics lambda
      bias: (F,) bank fault estimates b[k|k]
      isolated: () int: latched location + 1 (0: none yet)
      isolated_kind: () bool: latched fault is multiplicative
      healthy: () bool: every filter healthy
      health_label: () int: location + 1 of a sensor found dead or frozen, 0 none
    """

    estimate: Array
    statistic: Array
    bias: Array
    isolated: Array
    isolated_kind: Array
    healthy: Array
    health_label: Array


class LoopStep(NamedTuple):
    """Per-step record of one closed-loop run.

    Attributes:
      state: (n,) true model states
      control: (nu,) commanded u
      fdi: the FDI's ``BankOutput``, its ``healthy`` also covering the feedback estimator's update
    """

    state: Array
    control: Array
    fdi: BankOutput


def _estimator(design: LoopDesign):
    # NaN: a sensor not used (dead, or excluded once found dead or frozen), left out exactly
    return unknown_input_filter(design.model, design.unknown_input, missing_measurements=True)


def _bank_filter(design: LoopDesign, direction: FaultDirection):
    return two_stage_kalman_filter(design.model, direction, design.bias_walk, design.unknown_input)


def _sensor_locations(design: LoopDesign) -> Array:
    """(m,) int: the fault label (location + 1) of each sensor, 0 for a sensor with no location in the design."""
    m = design.model.C.shape[0]
    match = (~design.location_is_actuator)[None, :] & (
        design.location_component[None, :] == jnp.arange(m)[:, None]
    )
    return jnp.where(jnp.any(match, axis=1), jnp.argmax(match, axis=1) + 1, 0).astype(jnp.int32)


def _channel_health_test(design: LoopDesign):
    """The stuck-at test of step 6 on the raw measurements: noise bound ``sqrt(diag R)`` of the nominal model, labels
    ``_sensor_locations`` (a dead sample: ``flag_dead``)."""
    sigma = jnp.sqrt(jnp.diagonal(design.model.R))
    return frozen_channel_detector(
        sigma, design.frozen_window, design.frozen_pfa, _sensor_locations(design)
    )


def tskf_bank_fdi(design: LoopDesign, ftc: Array) -> FDI:
    """Lee and Lyou's FDD + reconfiguration as a ``loop.FDI`` (module doc, steps 2 and 5); ``ftc`` (bool, traced) turns
    the reconfiguration on."""
    model = design.model
    nu = model.Gamma.shape[1]
    L = design.location_component.shape[0]
    block = 2**design.levels
    dtype = model.Phi.dtype
    estimator = _estimator(design)
    health_test = _channel_health_test(design)
    channels = _sensor_locations(design)

    def observe(state: BankState, k: Array, y: Array):
        isolated, kind, est = state.isolated, state.kind, state.estimator
        location = jnp.maximum(isolated - 1, 0)
        on = ftc & (isolated > 0)
        is_actuator = design.location_is_actuator[location]
        component = design.location_component[location]
        matched = jnp.argmax((design.location == location) & (design.multiplicative == kind))
        b_hat = state.bank.bias_mean[matched, 0]
        # sensor compensation y_c = y - Fs b (eq. 31)
        direction = jax.tree_util.tree_map(lambda leaf: leaf[matched], design.directions)
        Fs = sensor_matrix(direction, model, est.mean, jnp.zeros((nu,), dtype))[:, 0]
        excluded = on & state.excluded
        y_used = jnp.where(on & ~is_actuator & ~jnp.any(excluded), y - Fs * b_hat, y)
        y_used = jnp.where(excluded, jnp.nan, y_used)  # a dead or frozen sensor: not used
        post = estimator.update(est, y_used, jnp.zeros((nu,), dtype))
        loss = jnp.where(on & is_actuator & kind, jnp.clip(b_hat, 0.0, 1.0), 0.0)
        additive = jnp.where(on & is_actuator & ~kind, b_hat, 0.0) * jax.nn.one_hot(
            component, nu, dtype=dtype
        )
        view = Reconfiguration(post.filtered_mean, loss, component, additive)
        posterior = post.posterior
        return state._replace(posterior=posterior, reconfiguration=view), (view, post.healthy)

    def step(state: BankState, k: Array, y: Array, u: Array):
        view = state.reconfiguration
        one_hot = jax.nn.one_hot(view.component, nu, dtype=dtype)
        u_believed = u * (1.0 - view.loss * one_hot) - view.additive
        est_next = estimator.predict(state.posterior, u_believed)
        bank_next, info = jax.vmap(lambda d, s: _bank_filter(design, d).step(s, y, u))(
            design.directions, state.bank
        )
        health, verdict = health_test.step(state.health, y)
        health_label = jnp.where(verdict.alarm, verdict.label, 0)
        buffer = state.buffer.at[k % block].set(info.statistic)
        denoised = haar_denoise(buffer, design.levels, "soft", design.detail_sigma, design.c_mult)
        alarms = jnp.any(denoised >= design.threshold, axis=0)  # (F,)
        label = isolate(location_symptoms(alarms, design.location, L))
        decide = (k % block == block - 1) & (state.isolated == 0) & (label > 0)
        decide_health = (state.isolated == 0) & (health_label > 0)  # every step, ahead of the bank
        of_location = design.location == (label - 1)
        best = jnp.argmin(jnp.where(of_location, jnp.mean(buffer, axis=0), jnp.inf))
        isolated = jnp.where(
            decide_health, health_label, jnp.where(decide, label, state.isolated)
        ).astype(jnp.int32)
        kind = jnp.where(
            decide_health, False, jnp.where(decide, design.multiplicative[best], state.kind)
        )
        excluded = state.excluded | (decide_health & (channels == health_label))
        output = BankOutput(
            state.posterior.mean,
            info.statistic,
            info.bias_mean[:, 0],
            isolated,
            kind,
            jnp.all(info.healthy),
            health_label.astype(jnp.int32),
        )
        return state._replace(
            estimator=est_next,
            bank=bank_next,
            buffer=buffer,
            isolated=isolated,
            kind=kind,
            health=health,
            excluded=excluded,
        ), output

    return FDI(lambda: tskf_bank_init(design), step, observe)


def tskf_bank_init(design: LoopDesign) -> BankState:
    """The FDI's initial state: estimator and bank started at the plant's ``x0``."""
    model = design.model
    n, nu, m = model.Phi.shape[0], model.Gamma.shape[1], model.C.shape[0]
    dtype = model.Phi.dtype
    x0 = design.plant_x0[:n]

    def bank_init(direction):
        return _bank_filter(design, direction).init(
            x0, design.init_cov, jnp.zeros((1,), dtype), design.init_bias_cov
        )

    prior = _estimator(design).init(x0, design.init_cov)
    idle = Reconfiguration(
        x0, jnp.zeros((), dtype), jnp.zeros((), jnp.int32), jnp.zeros((nu,), dtype)
    )
    return BankState(
        prior,
        jax.vmap(bank_init)(design.directions),
        jnp.zeros((2**design.levels, design.location.shape[0]), dtype),
        jnp.zeros((), jnp.int32),
        jnp.zeros((), bool),
        GaussianState(prior.mean, prior.cov),
        idle,
        _channel_health_test(design).init(),
        jnp.zeros((m,), bool),
    )


def true_plant(design: LoopDesign, fault: Fault) -> Simulator:
    """The true plant (uncertainty and disturbance states included) with the nominal model's noise on its first ``n``
    states and on the outputs, and ``fault``."""
    model = design.model
    n = model.Phi.shape[0]
    nt = design.plant_Phi.shape[0]
    G = jnp.eye(nt, n, dtype=model.Phi.dtype)
    return simulator(
        lambda x, u, p: design.plant_Phi @ x + design.plant_Gamma @ u,
        lambda x, u, p: design.plant_C @ x,
        model.Q,
        model.R,
        fault=fault,
        noise_gain=G,
    )


def run_closed_loop(
    design: LoopDesign, key: Array, fault: Fault, ftc: Array, steps: int
) -> LoopStep:
    """Simulate ``steps`` steps of the closed loop under ``fault`` (scalar leaves); ``ftc`` (bool) turns the
    reconfiguration on. Returns the stacked ``LoopStep``."""
    n, nu = design.model.Phi.shape[0], design.model.Gamma.shape[1]
    controller = reconfigurable_pi(
        design.gain, design.schedule, design.H, design.command, design.Ts, design.model.Phi.dtype
    )
    fdi = tskf_bank_fdi(design, ftc)
    result = run_loop(
        true_plant(design, fault),
        fdi,
        controller,
        design.plant_x0,
        fdi.init(),
        key,
        steps,
        u0=jnp.zeros((nu,), design.model.Phi.dtype),
        keep_history=True,
    )
    trace = result.history
    (_, estimator_healthy), out = trace.view, trace.output
    return LoopStep(
        trace.sensed.state[:, :n],
        trace.control,
        out._replace(healthy=out.healthy & estimator_healthy),
    )


def is_multiplicative(fault: Fault) -> Array:
    """Whether the fault scales its signal (effectiveness loss, sensor scaling)."""
    return (fault.kind == FaultKind.EFFECTIVENESS) | (fault.kind == FaultKind.SCALE)
