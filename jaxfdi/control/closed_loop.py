"""Closed-loop fault detection, isolation and fault-tolerant control (seed 001, Fig. 2).

One ``lax.scan`` step ``k``:

1. the true plant (its own matrices: uncertainty and disturbance states included) is
   measured, ``y = C_t x_t + v``, and a sensor fault acts on ``y``;
2. a robust state estimator (``unknown_input_filter``) updates with ``y``, after the
   sensor compensation ``y_c = y - Fs b`` (eq. 31) once a sensor fault is isolated;
3. the PI state feedback ``u = K [x_hat; z]`` (eq. 22) with the nominal LQR gain, or,
   once an actuator effectiveness loss is isolated, the eigenstructure-assignment gain
   for ``B_f = B (I - diag(b))`` at the current estimate ``b`` (eqs. 23-29), looked up
   in a ``GainSchedule`` tabulated once (solving the assignment every step would be 8x
   the cost of the whole loop); an additive actuator fault is compensated by adding its
   estimate to ``u``;
4. the integrator ``z += Ts (r - H x_hat)``, an actuator fault acts on ``u`` and the
   plant moves; the estimator predicts with the input the plant is believed to get;
5. the TSKF bank steps on ``(y, u)``; its statistics fill a ``2^M`` block; at each
   block's end the blockwise Haar denoiser (soft thresholding) decides, the symptoms
   are matched against the signature matrix and the first isolated fault is latched
   (with FTC on, the controller switches at that step).

The bank may hold several filters per fault location (e.g. a multiplicative and an
additive hypothesis): ``location`` maps filter -> location, the location's symptom is
"every one of its filters alarms", isolation matches the location symptoms, and the
kind is the location's filter with the smaller block statistic.

Everything is data except the shapes, so ``vmap`` runs Monte Carlo batches with
different faults, keys and FTC switches through one compiled scan.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import _linalg
from jaxfdi.control.eigenstructure import GainSchedule, scheduled_gain
from jaxfdi.detection.signature import isolate, location_symptoms
from jaxfdi.detection.wavelet import haar_denoise
from jaxfdi.faults import Fault, FaultKind, Target, apply_fault
from jaxfdi.filters._base import GaussianState
from jaxfdi.filters.tskf import FaultDirection, sensor_matrix, two_stage_kalman_filter
from jaxfdi.filters.unknown_input import unknown_input_filter
from jaxfdi.models.linear import LinearGaussianModel


class LoopDesign(NamedTuple):
    """Everything the closed loop needs; build once (concrete arrays)."""

    model: LinearGaussianModel   # nominal model of the estimator and the bank
    unknown_input: Array         # (n, q) E, decoupled by the estimator and the bank
    plant_Phi: Array             # (nt, nt) true plant (first n states are the model's)
    plant_Gamma: Array           # (nt, nu)
    plant_C: Array               # (m, nt)
    plant_x0: Array              # (nt,)
    H: Array                     # (g, n) tracked outputs
    command: Array               # (g,) r
    gain: Array                  # (nu, n + g) nominal K
    schedule: GainSchedule       # eigenstructure-assignment gains over each input's loss
    directions: FaultDirection   # bank, leaves (F, ..., 1)
    location: Array              # (F,) int: fault location of each filter (0 .. L-1)
    multiplicative: Array        # (F,) bool: effectiveness/scaling filter (else additive)
    location_is_actuator: Array  # (L,) bool
    location_component: Array    # (L,) int: input or output index
    bias_walk: Array             # (1, 1) Qb
    init_cov: Array              # (n, n) prior covariance of x[0]
    init_bias_cov: Array         # (1, 1)
    threshold: Array             # (F,) per-filter threshold of the denoised statistic
    detail_sigma: Array          # (M,) detail standard deviations for soft thresholding
    c_mult: float
    levels: int
    Ts: float


class LoopStep(NamedTuple):
    """Per-step record of one closed-loop run."""

    state: Array        # (n,) true model states
    estimate: Array     # (n,) x_hat[k|k] of the feedback estimator
    control: Array      # (nu,) commanded u
    statistic: Array    # (F,) bank statistics lambda
    bias: Array         # (F,) bank fault estimates b[k|k]
    isolated: Array     # () int: latched location + 1 (0: none yet)
    isolated_kind: Array  # () bool: latched fault is multiplicative
    healthy: Array      # () bool: every filter healthy


def _noise(key: Array, k: Array, model: LinearGaussianModel) -> tuple[Array, Array]:
    kw, kv = jax.random.split(jax.random.fold_in(key, k))
    n, m = model.Q.shape[0], model.R.shape[0]
    w = _linalg.matmul(_linalg.psd_sqrt(model.Q), jax.random.normal(kw, (n,), model.Q.dtype))
    v = _linalg.matmul(_linalg.psd_sqrt(model.R), jax.random.normal(kv, (m,), model.R.dtype))
    return w, v


def run_closed_loop(design: LoopDesign, key: Array, fault: Fault, ftc: Array, steps: int) -> LoopStep:
    """Simulate ``steps`` steps of the closed loop under ``fault`` (scalar leaves);
    ``ftc`` (bool) turns the reconfiguration on. Returns the stacked ``LoopStep``."""
    model = design.model
    n = model.Phi.shape[0]
    nu = model.Gamma.shape[1]
    g = design.H.shape[0]
    F = design.location.shape[0]
    L = design.location_component.shape[0]
    block = 2**design.levels
    dtype = model.Phi.dtype
    estimator = unknown_input_filter(model, design.unknown_input)
    mm = _linalg.matmul

    def bank_filter(direction):
        return two_stage_kalman_filter(model, direction, design.bias_walk, design.unknown_input)

    def bank_init(direction):
        return bank_filter(direction).init(design.plant_x0[:n], design.init_cov, jnp.zeros((1,), dtype),
                                           design.init_bias_cov)

    def bank_step(direction, state, y, u):
        return bank_filter(direction).step(state, y, u)

    init = (
        design.plant_x0,
        jnp.zeros((g,), dtype),
        estimator.init(design.plant_x0[:n], design.init_cov),
        jax.vmap(bank_init)(design.directions),
        jnp.zeros((block, F), dtype),
        jnp.zeros((), jnp.int32),
        jnp.zeros((), bool),
        jnp.zeros((2,), dtype),
    )

    def step(carry, k):
        x_true, z, est, bank, buffer, isolated, kind, held = carry
        w, v = _noise(key, k, model)
        location = jnp.maximum(isolated - 1, 0)
        on = ftc & (isolated > 0)
        is_actuator = design.location_is_actuator[location]
        component = design.location_component[location]
        matched = jnp.argmax((design.location == location) & (design.multiplicative == kind))
        b_hat = bank.bias_mean[matched, 0]

        # 1. measure (sensor fault on y)
        y, held_s = apply_fault(fault, k, mm(design.plant_C, x_true) + v, Target.SENSOR, held[1])
        # 2. estimator update, with sensor compensation y_c = -Fs b (eq. 31)
        direction = jax.tree_util.tree_map(lambda leaf: leaf[matched], design.directions)
        Fs = sensor_matrix(direction, model, est.mean, jnp.zeros((nu,), dtype))[:, 0]
        y_used = jnp.where(on & ~is_actuator, y - Fs * b_hat, y)
        post = estimator.update(est, y_used, jnp.zeros((nu,), dtype))
        # 3. control: nominal, or reconfigured for an isolated actuator fault
        loss = jnp.where(on & is_actuator & kind, jnp.clip(b_hat, 0.0, 1.0), 0.0)
        one_hot = jax.nn.one_hot(component, nu, dtype=dtype)
        gain = jnp.where(loss > 0, scheduled_gain(design.schedule, component, loss), design.gain)
        u = mm(gain, jnp.concatenate([post.mean, z]))
        additive_fix = jnp.where(on & is_actuator & ~kind, b_hat, 0.0) * one_hot
        u = u + additive_fix
        # 4. integrator, actuator fault, plant, estimator predict
        z_next = z + design.Ts * (design.command - mm(design.H, post.mean))
        u_plant, held_a = apply_fault(fault, k, u, Target.ACTUATOR, held[0])
        w_full = jnp.zeros_like(x_true).at[:n].set(w)
        x_next = mm(design.plant_Phi, x_true) + mm(design.plant_Gamma, u_plant) + w_full
        u_believed = u * (1.0 - loss * one_hot) - additive_fix
        est_next = estimator.predict(GaussianState(post.mean, post.cov), u_believed)
        # 5. bank, block buffer, decision at the block's end
        bank_next, info = jax.vmap(bank_step, in_axes=(0, 0, None, None))(design.directions, bank, y, u)
        buffer = buffer.at[k % block].set(info.statistic)
        denoised = haar_denoise(buffer, design.levels, "soft", design.detail_sigma, design.c_mult)
        alarms = jnp.any(denoised >= design.threshold, axis=0)                       # (F,)
        label = isolate(location_symptoms(alarms, design.location, L))
        decide = (k % block == block - 1) & (isolated == 0) & (label > 0)
        block_mean = jnp.mean(buffer, axis=0)
        of_location = design.location == (label - 1)
        best = jnp.argmin(jnp.where(of_location, block_mean, jnp.inf))
        isolated_next = jnp.where(decide, label, isolated).astype(jnp.int32)
        kind_next = jnp.where(decide, design.multiplicative[best], kind)
        record = LoopStep(x_true[:n], post.mean, u, info.statistic, info.bias_mean[:, 0], isolated_next, kind_next,
                          jnp.all(info.healthy) & post.healthy)
        carry = (x_next, z_next, est_next, bank_next, buffer, isolated_next, kind_next, jnp.stack([held_a, held_s]))
        return carry, record

    _, history = jax.lax.scan(step, init, jnp.arange(steps))
    return history


def is_multiplicative(fault: Fault) -> Array:
    """Whether the fault scales its signal (effectiveness loss, sensor scaling)."""
    return (fault.kind == FaultKind.EFFECTIVENESS) | (fault.kind == FaultKind.SCALE)

