"""Malformed calls across the public API are refused, never answered (issue 22).

A table of calls a hostile user makes: NaN/inf, complex and string arrays, indefinite
covariances, probabilities out of range, floats where counts are meant, indices out of
range, unknown names, wrong callables. Each case asserts the exception type
(``TypeError`` for the wrong kind of value, ``ValueError`` for a wrong value) and that the
message names the argument. No case may return a result: ``pytest.raises`` fails if the
call returns. Array cases run under ``jax.eval_shape`` where the call would compute, so
an error must come at trace time, before anything is compiled.

The valid counterpart of every family is in ``test_valid_neighbours_pass``: the checks
are not over-eager (a covariance of 1e-24, a singular but semi-definite Q, NaN
measurements in a filter that skips them, an integer initial mean).
"""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import jaxfdi
from jaxfdi import control, detection, models, tuning
from jaxfdi._simulation import loop
from jaxfdi._simulation.monitor import filter_detector
from jaxfdi._studies import metrics
from jaxfdi.control import slew
from jaxfdi.filters import _time_varying
from jaxfdi.filters import _tskf as tskf
from jaxfdi.models import (
    engine_model,
    linear_observation,
    linear_transition,
    vtol_model,
    vtol_true_plant,
)
from jaxfdi.models._rigid_body import rigid_body_params
from jaxfdi.scenarios.engine import engine_study
from jaxfdi.scenarios.engine_chi2 import engine_chi2_study
from jaxfdi.scenarios.engine_chi2_tuning import tune_engine_chi2
from jaxfdi.scenarios.engine_tuning import imm_design, tune_engine_imm
from jaxfdi.scenarios.reaction_wheels import wheel_study
from jaxfdi.scenarios.vtol import vtol_study
from jaxfdi.tuning._parameterize import from_record

MODEL = engine_model()  # n = 7, nu = 1, m = 5
N, NU, M = 7, 1, 5
T = 4
YS, US = jnp.zeros((T, M)), jnp.zeros((T, NU))
NAN_7 = jnp.eye(N).at[2, 3].set(jnp.nan)
INDEFINITE_2 = jnp.array([[1.0, 2.0], [2.0, 1.0]])  # symmetric, eigenvalues -1 and 3
KEY = jax.random.key(0)
SMALL = jaxfdi.models.linear_gaussian_model(
    jnp.array([[0.9, 0.1], [0.0, 0.8]]),
    jnp.eye(2),
    0.01 * jnp.eye(2),
    0.1 * jnp.eye(2),
    Gamma=jnp.array([[0.0], [1.0]]),
)


def indefinite(n: int) -> jnp.ndarray:
    """Symmetric, non-negative diagonal, one negative eigenvalue."""
    a = np.eye(n)
    a[0, 1] = a[1, 0] = 2.0
    return jnp.asarray(a)


def kf_run(model=MODEL, mean=jnp.zeros(N), cov=jnp.eye(N), ys=YS, us=US, filt=None):
    def go(ys, us):
        f = filt or jaxfdi.filters.kalman_filter(model)
        return jaxfdi.filters.run_filter(f, f.init(mean, cov), ys, us)[1]

    return jax.eval_shape(go, ys, us)


def ekf(**kw):
    args = dict(f=linear_transition, h=linear_observation, Q=MODEL.Q, R=MODEL.R, params=MODEL)
    args.update(kw)
    return jaxfdi.filters.extended_kalman_filter(**args)


def ukf(**kw):
    args = dict(f=linear_transition, h=linear_observation, Q=MODEL.Q, R=MODEL.R, params=MODEL)
    args.update(kw)
    return jaxfdi.filters.unscented_kalman_filter(**args)


def two_modes():
    return jax.tree.map(lambda a: jnp.stack([a, a]), SMALL)


def imm(transition=jnp.array([[0.9, 0.1], [0.2, 0.8]]), mode_filter=jaxfdi.filters.kalman_filter):
    return jaxfdi.filters.interacting_multiple_model(mode_filter, two_modes(), transition)


def sim_run(sim=None, x0=jnp.zeros(N), us=US):
    sim = sim or jaxfdi.linear_simulator(MODEL)
    return jax.eval_shape(lambda us: jaxfdi.simulate(sim, x0, us, KEY), us)


def sim_with(fault):
    return sim_run(jaxfdi.linear_simulator(MODEL, fault))


def fault(**kw):
    args = dict(kind="bias", target="sensor", component=0, onset=10, magnitude=1.0)
    args.update(kw)
    return jaxfdi.fault(**args)


def loop_run(steps=T, plant=None, exogenous=None, key=KEY):
    sim = plant or jaxfdi.linear_simulator(SMALL)
    kf = jaxfdi.filters.kalman_filter(SMALL)
    fdi = filter_detector(kf, detection.chi2_detector(10.0))
    return loop.run_loop(
        sim,
        fdi,
        loop.feedforward(),
        jnp.zeros(2),
        kf.init(jnp.zeros(2), jnp.eye(2)),
        key,
        steps,
        exogenous=jnp.zeros((4, 1)) if exogenous is None else exogenous,
    )


def monte(num_runs=2, chunk_size=8192, run_one=lambda key, x: 0.0, key=KEY, progress=False):
    return jaxfdi.monte_carlo(run_one, key, num_runs, chunk_size=chunk_size, progress=progress)


DIRECTION = tskf.actuator_direction(MODEL, 0)

V, T_ = ValueError, TypeError
# id: (thunk, exception type, the argument the message must name)
CASES = {
    # --- models.linear -------------------------------------------------------------
    "model Phi NaN": (
        lambda: jaxfdi.models.linear_gaussian_model(NAN_7, MODEL.C, MODEL.Q, MODEL.R, MODEL.Gamma),
        V,
        "Phi",
    ),
    "model Phi inf": (
        lambda: jaxfdi.models.linear_gaussian_model(
            jnp.eye(N).at[0, 0].set(jnp.inf), MODEL.C, MODEL.Q, MODEL.R, MODEL.Gamma
        ),
        V,
        "Phi",
    ),
    "model Gamma NaN": (
        lambda: jaxfdi.models.linear_gaussian_model(
            MODEL.Phi, MODEL.C, MODEL.Q, MODEL.R, MODEL.Gamma.at[0, 0].set(jnp.nan)
        ),
        V,
        "Gamma",
    ),
    "model C NaN": (
        lambda: jaxfdi.models.linear_gaussian_model(
            MODEL.Phi, MODEL.C.at[1, 1].set(jnp.nan), MODEL.Q, MODEL.R
        ),
        V,
        "C",
    ),
    "model D inf": (
        lambda: jaxfdi.models.linear_gaussian_model(
            MODEL.Phi, MODEL.C, MODEL.Q, MODEL.R, MODEL.Gamma, jnp.full((M, NU), jnp.inf)
        ),
        V,
        "D",
    ),
    "model Q indefinite": (
        lambda: jaxfdi.models.linear_gaussian_model(
            jnp.eye(2), jnp.eye(2), INDEFINITE_2, jnp.eye(2)
        ),
        V,
        "Q",
    ),
    "model R indefinite": (
        lambda: jaxfdi.models.linear_gaussian_model(
            jnp.eye(2), jnp.eye(2), jnp.eye(2), INDEFINITE_2
        ),
        V,
        "R",
    ),
    "model Q complex": (
        lambda: jaxfdi.models.linear_gaussian_model(
            jnp.eye(2), jnp.eye(2), jnp.eye(2) * (1 + 1j), jnp.eye(2)
        ),
        T_,
        "Q",
    ),
    "model Phi complex": (
        lambda: jaxfdi.models.linear_gaussian_model(
            jnp.eye(2) * 1j, jnp.eye(2), jnp.eye(2), jnp.eye(2)
        ),
        T_,
        "Phi",
    ),
    "model Phi strings": (
        lambda: jaxfdi.models.linear_gaussian_model(
            np.array([["a", "b"], ["c", "d"]]), jnp.eye(2), jnp.eye(2), jnp.eye(2)
        ),
        T_,
        "Phi",
    ),
    "model R NaN (replace)": (
        lambda: kf_run(MODEL._replace(R=MODEL.R.at[0, 0].set(jnp.nan))),
        V,
        "model.R",
    ),
    "model Q indefinite (replace)": (lambda: kf_run(MODEL._replace(Q=indefinite(N))), V, "model.Q"),
    "model Phi NaN (replace)": (lambda: kf_run(MODEL._replace(Phi=NAN_7)), V, "model.Phi"),
    "c2d Ts NaN": (
        lambda: jaxfdi.models.c2d(jnp.zeros((2, 2)), jnp.zeros((2, 1)), float("nan")),
        V,
        "Ts",
    ),
    "c2d Ts inf": (
        lambda: jaxfdi.models.c2d(jnp.zeros((2, 2)), jnp.zeros((2, 1)), float("inf")),
        V,
        "Ts",
    ),
    "c2d A NaN": (
        lambda: jaxfdi.models.c2d(jnp.full((2, 2), jnp.nan), jnp.zeros((2, 1)), 0.1),
        V,
        "A",
    ),
    "c2d A complex": (lambda: jaxfdi.models.c2d(1j * jnp.eye(2), jnp.zeros((2, 1)), 0.1), T_, "A"),
    "c2d B inf": (lambda: jaxfdi.models.c2d(jnp.eye(2), jnp.full((2, 1), jnp.inf), 0.1), V, "B"),
    # --- Kalman filter and the drivers --------------------------------------------
    "kf init mean NaN": (lambda: kf_run(mean=jnp.zeros(N).at[0].set(jnp.nan)), V, "mean"),
    "kf init mean complex": (lambda: kf_run(mean=jnp.zeros(N, complex)), T_, "mean"),
    "kf init cov indefinite": (lambda: kf_run(cov=indefinite(N)), V, "cov"),
    "kf init cov NaN": (lambda: kf_run(cov=NAN_7), V, "cov"),
    "run_filter ys complex": (lambda: kf_run(ys=jnp.zeros((T, M), complex)), T_, "ys"),
    "run_filter us complex": (lambda: kf_run(us=jnp.zeros((T, NU), complex)), T_, "us"),
    "run_filter ys strings": (
        lambda: jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(MODEL), None, np.array([["a"] * M] * T), US
        ),
        T_,
        "ys",
    ),
    "run_filter filt not a Filter": (
        lambda: jaxfdi.filters.run_filter(lambda s, y, u: (s, y), None, YS, US),
        T_,
        "filt",
    ),
    "run_filter ys 4-D": (
        lambda: jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(MODEL), None, YS[None, None], US
        ),
        V,
        "ys",
    ),
    "run_filter parallel without an associative scan": (
        lambda: jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(MODEL), None, YS, US, parallel=True
        ),
        V,
        "parallel",
    ),
    "run_filter N runs shared_covariance": (
        lambda: jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(MODEL), None, YS[None], US, shared_covariance="yes"
        ),
        V,
        "shared_covariance",
    ),
    "run_filter N runs ys complex": (
        lambda: jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(MODEL), None, jnp.zeros((2, T, M), complex), US
        ),
        T_,
        "ys",
    ),
    "kalman_filter model not a model": (
        lambda: jaxfdi.filters.kalman_filter((MODEL.Phi, MODEL.C)),
        T_,
        "model",
    ),
    # --- EKF / UKF -----------------------------------------------------------------
    "ekf f not callable": (lambda: ekf(f=MODEL.Phi), T_, "f"),
    "ekf h not callable": (lambda: ekf(h=None), T_, "h"),
    "ekf Q indefinite": (lambda: ekf(Q=indefinite(N)), V, "Q"),
    "ekf R NaN": (lambda: ekf(R=MODEL.R.at[0, 0].set(jnp.nan)), V, "R"),
    "ekf R complex": (lambda: ekf(R=MODEL.R.astype(complex)), T_, "R"),
    "ukf alpha NaN": (lambda: ukf(alpha=float("nan")), V, "alpha"),
    "ukf alpha inf": (lambda: ukf(alpha=float("inf")), V, "alpha"),
    "ukf kappa inf": (lambda: ukf(kappa=float("inf")), V, "kappa"),
    "ukf kappa NaN": (lambda: ukf(kappa=float("nan")), V, "kappa"),
    "ukf beta NaN": (lambda: ukf(beta=float("nan")), V, "beta"),
    "ukf f not callable": (lambda: ukf(f="transition"), T_, "f"),
    "ukf Q indefinite": (lambda: ukf(Q=indefinite(N)), V, "Q"),
    # --- IMM / MM --------------------------------------------------------------------
    "imm rows do not sum to 1": (lambda: imm(jnp.array([[0.9, 0.2], [0.2, 0.8]])), V, "transition"),
    "imm negative transition": (lambda: imm(jnp.array([[1.1, -0.1], [0.2, 0.8]])), V, "transition"),
    "imm NaN transition": (lambda: imm(jnp.array([[jnp.nan, 0.1], [0.2, 0.8]])), V, "transition"),
    "imm complex transition": (lambda: imm(jnp.eye(2, dtype=complex)), T_, "transition"),
    "imm mode_filter not callable": (
        lambda: imm(mode_filter=jaxfdi.filters.kalman_filter(SMALL)),
        T_,
        "mode_filter",
    ),
    "imm init mode_prob sum": (
        lambda: imm().init(jnp.zeros(2), jnp.eye(2), jnp.array([0.7, 0.7])),
        V,
        "mode_prob",
    ),
    "imm init mode_prob negative": (
        lambda: imm().init(jnp.zeros(2), jnp.eye(2), jnp.array([1.5, -0.5])),
        V,
        "mode_prob",
    ),
    "imm init cov indefinite": (
        lambda: imm().init(jnp.zeros(2), INDEFINITE_2, jnp.array([0.5, 0.5])),
        V,
        "cov",
    ),
    "mm floor above 1/M": (
        lambda: jaxfdi.filters.multiple_model(jaxfdi.filters.kalman_filter, two_modes(), 0.6),
        V,
        "floor",
    ),
    "mm floor NaN": (
        lambda: jaxfdi.filters.multiple_model(
            jaxfdi.filters.kalman_filter, two_modes(), float("nan")
        ),
        V,
        "floor",
    ),
    "mm init mode_prob NaN": (
        lambda: jaxfdi.filters.multiple_model(jaxfdi.filters.kalman_filter, two_modes()).init(
            jnp.zeros(2), jnp.eye(2), jnp.array([jnp.nan, 0.5])
        ),
        V,
        "mode_prob",
    ),
    # --- two-stage / unknown-input / time-varying / posterior -----------------------
    "tskf bias_walk indefinite": (
        lambda: jaxfdi.filters.two_stage_kalman_filter(
            MODEL,
            tskf.stack_directions([DIRECTION, DIRECTION])._replace(
                state=jnp.concatenate([DIRECTION.state] * 2, 1),
                input_scaled=jnp.concatenate([DIRECTION.input_scaled] * 2, 1),
                output=jnp.concatenate([DIRECTION.output] * 2, 1),
                output_scaled=jnp.concatenate([DIRECTION.output_scaled] * 2, 1),
            ),
            INDEFINITE_2,
        ),
        V,
        "bias_walk",
    ),
    "tskf bias_walk NaN": (
        lambda: jaxfdi.filters.two_stage_kalman_filter(MODEL, DIRECTION, jnp.full((1, 1), jnp.nan)),
        V,
        "bias_walk",
    ),
    "actuator_direction component": (lambda: tskf.actuator_direction(MODEL, 5), V, "component"),
    "actuator_direction component float": (
        lambda: tskf.actuator_direction(MODEL, 0.0),
        T_,
        "component",
    ),
    "actuator_direction kind": (lambda: tskf.actuator_direction(MODEL, 0, "stuck"), V, "kind"),
    "sensor_direction component negative": (
        lambda: tskf.sensor_direction(MODEL, -1),
        V,
        "component",
    ),
    "unknown_input rank": (
        lambda: jaxfdi.filters.unknown_input_filter(MODEL, jnp.zeros((N, 1))),
        V,
        "unknown_input",
    ),
    "unknown_input NaN": (
        lambda: jaxfdi.filters.unknown_input_filter(MODEL, jnp.full((N, 1), jnp.nan)),
        V,
        "unknown_input",
    ),
    "time_varying not callable": (
        lambda: _time_varying.time_varying(jaxfdi.filters.kalman_filter(MODEL)),
        T_,
        "filter_at",
    ),
    "time_varying start negative": (
        lambda: _time_varying.time_varying(lambda k: jaxfdi.filters.kalman_filter(MODEL), -1),
        V,
        "start",
    ),
    "model_at unknown field": (
        lambda: _time_varying.model_at(MODEL, S=jnp.zeros((T, M, M))),
        V,
        "S",
    ),
    "model_at table NaN": (
        lambda: _time_varying.model_at(MODEL, R=jnp.full((T, M, M), jnp.nan)),
        V,
        "R",
    ),
    "model_at table indefinite": (
        lambda: _time_varying.model_at(SMALL, Q=jnp.stack([jnp.eye(2), INDEFINITE_2])),
        V,
        "Q",
    ),
    "init_from_posterior not Gaussian": (
        lambda: jaxfdi.filters.init_from_posterior(
            jaxfdi.filters.Filter(lambda m, c: (m, c), lambda s, y, u: (s, y)),
            jnp.zeros(N),
            jnp.eye(N),
        ),
        V,
        "filt",
    ),
    "init_from_posterior cov indefinite": (
        lambda: jaxfdi.filters.init_from_posterior(
            jaxfdi.filters.kalman_filter(SMALL), jnp.zeros(2), INDEFINITE_2, jnp.zeros(1)
        ),
        V,
        "cov",
    ),
    # --- fault-mode designs ----------------------------------------------------------
    "noise_inflation negative": (
        lambda: jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, -5.0, 1.0),
        V,
        "sensor_inflation",
    ),
    "noise_inflation zero": (
        lambda: jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, 0.0, 1.0),
        V,
        "sensor_inflation",
    ),
    "noise_inflation NaN": (
        lambda: jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, float("nan"), 1.0),
        V,
        "sensor_inflation",
    ),
    "noise_inflation actuator negative": (
        lambda: jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, 10.0, -1.0),
        V,
        "actuator_noise",
    ),
    "noise_inflation wrong length": (
        lambda: jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, jnp.ones(3) * 10, 1.0),
        V,
        "sensor_inflation",
    ),
    "bias_modes walk negative": (
        lambda: jaxfdi.models._fault_modes.bias_modes(MODEL, -1.0, 1.0),
        V,
        "bias_walk",
    ),
    "bias_modes prior NaN": (
        lambda: jaxfdi.models._fault_modes.bias_modes(MODEL, 1.0, float("nan")),
        V,
        "bias_prior",
    ),
    # --- faults ---------------------------------------------------------------------
    "fault unknown kind name": (lambda: fault(kind="drift"), V, "kind"),
    "fault unknown kind int": (lambda: fault(kind=9), V, "kind"),
    "fault kind float": (lambda: fault(kind=1.0), T_, "kind"),
    "fault unknown target": (lambda: fault(target="both"), V, "target"),
    "fault negative component": (lambda: fault(component=-1), V, "component"),
    "fault component float": (lambda: fault(component=1.5), T_, "component"),
    "fault negative onset": (lambda: fault(kind="stuck", onset=-5), V, "onset"),
    "fault onset float": (lambda: fault(onset=2.5), T_, "onset"),
    "fault magnitude NaN": (lambda: fault(magnitude=float("nan")), V, "magnitude"),
    "fault slope inf": (lambda: fault(kind="ramp", slope=float("inf")), V, "slope"),
    "fault magnitude complex": (lambda: fault(magnitude=1j), T_, "magnitude"),
    "fault effectiveness above 1": (
        lambda: fault(kind="effectiveness", target="actuator", magnitude=3.0),
        V,
        "magnitude",
    ),
    "fault effectiveness negative": (
        lambda: fault(kind="effectiveness", target="actuator", magnitude=-0.5),
        V,
        "magnitude",
    ),
    "fault end before onset": (lambda: fault(onset=10, end=5), V, "end"),
    "fault label below -1": (lambda: fault(label=-2), V, "label"),
    "fault_group no components": (
        lambda: jaxfdi._simulation.faults.fault_group("bias", "sensor", [], 10, 1.0),
        V,
        "components",
    ),
    "fault_group magnitudes length": (
        lambda: jaxfdi._simulation.faults.fault_group(
            "bias", "sensor", [0, 1], 10, [1.0, 2.0, 3.0]
        ),
        V,
        "magnitudes",
    ),
    "fault_group components float": (
        lambda: jaxfdi._simulation.faults.fault_group("bias", "sensor", [0.5, 1.0], 10, 1.0),
        T_,
        "components",
    ),
    "concat_faults none": (lambda: jaxfdi._simulation.faults.concat_faults(), V, "faults"),
    "concat_faults not a Fault": (
        lambda: jaxfdi._simulation.faults.concat_faults(fault(), (1, 2)),
        T_,
        "faults",
    ),
    # --- simulator ------------------------------------------------------------------
    "sim sensor fault component out of range": (lambda: sim_with(fault(component=10)), V, "fault"),
    "sim actuator fault component out of range": (
        lambda: sim_with(fault(target="actuator", component=3)),
        V,
        "fault",
    ),
    "sim Q indefinite": (
        lambda: jaxfdi.simulator(
            linear_transition, linear_observation, indefinite(N), MODEL.R, MODEL
        ),
        V,
        "Q",
    ),
    "sim R NaN": (
        lambda: jaxfdi.simulator(
            linear_transition, linear_observation, MODEL.Q, MODEL.R.at[0, 0].set(jnp.nan), MODEL
        ),
        V,
        "R",
    ),
    "sim per-step Q indefinite": (
        lambda: jaxfdi.simulator(
            linear_transition,
            linear_observation,
            jnp.stack([jnp.eye(2), INDEFINITE_2]),
            jnp.eye(2),
            SMALL,
        ),
        V,
        "Q",
    ),
    "sim f not callable": (
        lambda: jaxfdi.simulator(MODEL.Phi, linear_observation, MODEL.Q, MODEL.R, MODEL),
        T_,
        "f",
    ),
    "sim noise_gain NaN": (
        lambda: jaxfdi.simulator(
            linear_transition,
            linear_observation,
            jnp.eye(1),
            MODEL.R,
            MODEL,
            noise_gain=jnp.full((N, 1), jnp.nan),
        ),
        V,
        "noise_gain",
    ),
    "sim available wrong width": (
        lambda: jaxfdi.linear_simulator(MODEL, available=jnp.ones((T, 3), bool)),
        V,
        "available",
    ),
    "sim input_noise indefinite": (
        lambda: jaxfdi.linear_simulator(SMALL, input_noise=-jnp.eye(1)),
        V,
        "input_noise",
    ),
    "simulate x0 NaN": (lambda: sim_run(x0=jnp.full(N, jnp.nan)), V, "x0"),
    "simulate x0 complex": (lambda: sim_run(x0=jnp.zeros(N, complex)), T_, "x0"),
    "simulate us complex": (lambda: sim_run(us=jnp.zeros((T, NU), complex)), T_, "us"),
    "simulate us NaN": (
        lambda: jaxfdi.simulate(
            jaxfdi.linear_simulator(MODEL), jnp.zeros(N), jnp.full((T, NU), jnp.nan), KEY
        ),
        V,
        "us",
    ),
    "linear_simulator model Q indefinite": (
        lambda: jaxfdi.linear_simulator(MODEL._replace(Q=indefinite(N))),
        V,
        "model.Q",
    ),
    # --- Monte Carlo ------------------------------------------------------------------
    "monte_carlo num_runs float": (lambda: monte(num_runs=4.0), T_, "num_runs"),
    "monte_carlo num_runs negative": (lambda: monte(num_runs=-1), V, "num_runs"),
    "monte_carlo num_runs bool": (lambda: monte(num_runs=True), T_, "num_runs"),
    "monte_carlo chunk_size zero": (lambda: monte(chunk_size=0), V, "chunk_size"),
    "monte_carlo chunk_size float": (lambda: monte(chunk_size=2.5), T_, "chunk_size"),
    "monte_carlo run_one not callable": (lambda: monte(run_one=3), T_, "run_one"),
    "monte_carlo key int": (lambda: monte(key=0), T_, "key"),
    "monte_carlo progress string": (lambda: monte(progress="yes"), T_, "progress"),
    # --- detection --------------------------------------------------------------------
    "chi2_threshold dof NaN": (lambda: detection.chi2_threshold(float("nan"), 0.01), V, "dof"),
    "chi2_threshold dof inf": (lambda: detection.chi2_threshold(float("inf"), 0.01), V, "dof"),
    "chi2_threshold pfa NaN": (lambda: detection.chi2_threshold(4, float("nan")), V, "pfa"),
    "chi2_threshold pfa complex": (lambda: detection.chi2_threshold(4, 0.01j), T_, "pfa"),
    "chi2_detector window float": (lambda: detection.chi2_detector(10.0, window=2.5), T_, "window"),
    "chi2_detector window zero": (lambda: detection.chi2_detector(10.0, window=0), V, "window"),
    "chi2_detector threshold NaN": (lambda: detection.chi2_detector(float("nan")), V, "threshold"),
    "moving_window_sum window bool": (
        lambda: detection.moving_window_sum(jnp.ones(5), True),
        T_,
        "window",
    ),
    "glrt_threshold pfa zero": (lambda: detection.glrt_threshold(0.0, 2, 5), V, "pfa"),
    "glrt_threshold window zero": (lambda: detection.glrt_threshold(0.01, 2, 0), V, "window"),
    "glrt_threshold method": (
        lambda: detection.glrt_threshold(0.01, 2, 5, method="exact"),
        V,
        "method",
    ),
    "mode_probability threshold above 1": (
        lambda: detection.mode_probability_detector(1.5),
        V,
        "threshold",
    ),
    "mode_probability threshold NaN": (
        lambda: detection.mode_probability_detector(float("nan")),
        V,
        "threshold",
    ),
    "mode_probability confirm_steps zero": (
        lambda: detection.mode_probability_detector(0.9, confirm_steps=0),
        V,
        "confirm_steps",
    ),
    "mode_probability confirm_steps float": (
        lambda: detection.mode_probability_detector(0.9, confirm_steps=2.0),
        T_,
        "confirm_steps",
    ),
    "mode_probability normal_mode negative": (
        lambda: detection.mode_probability_detector(0.9, normal_mode=-1),
        V,
        "normal_mode",
    ),
    "credit_isolator confirm_steps zero": (
        lambda: jaxfdi.detection._credits.credit_isolator(0.5, confirm_steps=0),
        V,
        "confirm_steps",
    ),
    "credit_isolator threshold NaN": (
        lambda: jaxfdi.detection._credits.credit_isolator(float("nan")),
        V,
        "threshold",
    ),
    "haar_denoise levels zero": (
        lambda: detection.haar_denoise(jnp.ones(16), levels=0),
        V,
        "levels",
    ),
    "haar_denoise levels float": (
        lambda: detection.haar_denoise(jnp.ones(16), levels=2.0),
        T_,
        "levels",
    ),
    "haar_denoise mode": (lambda: detection.haar_denoise(jnp.ones(16), mode="hard2"), V, "mode"),
    "haar_denoise c_mult NaN": (
        lambda: detection.haar_denoise(jnp.ones(16), c_mult=float("nan")),
        V,
        "c_mult",
    ),
    "signature_matrix zero filters": (
        lambda: jaxfdi.detection._signature.signature_matrix(0),
        V,
        "num_filters",
    ),
    "location_symptoms location with no filter": (
        lambda: jaxfdi.detection.location_symptoms(jnp.ones(4, bool), jnp.array([0, 0, 2, 2]), 3),
        V,
        "location",
    ),
    "location_symptoms num_locations zero": (
        lambda: jaxfdi.detection._signature.location_symptoms(
            jnp.ones(4, bool), jnp.zeros(4, int), 0
        ),
        V,
        "num_locations",
    ),
    # --- metrics ------------------------------------------------------------------------
    "confusion_matrix true label out of range": (
        lambda: metrics.confusion_matrix(jnp.array([0, 3]), jnp.array([0, 1]), 3),
        V,
        "true_labels",
    ),
    "confusion_matrix prediction out of range": (
        lambda: metrics.confusion_matrix(jnp.array([0, 1]), jnp.array([0, 7]), 3),
        V,
        "predicted_labels",
    ),
    "confusion_matrix negative true label": (
        lambda: metrics.confusion_matrix(jnp.array([-1, 1]), jnp.array([0, 1]), 3),
        V,
        "true_labels",
    ),
    "confusion_matrix num_classes zero": (
        lambda: metrics.confusion_matrix(jnp.array([0]), jnp.array([0]), 0),
        V,
        "num_classes",
    ),
    "confusion_matrix float labels": (
        lambda: metrics.confusion_matrix(jnp.array([0.0, 1.0]), jnp.array([0, 1]), 3),
        T_,
        "true_labels",
    ),
    "summarize_detection horizon zero": (
        lambda: metrics.summarize_detection(metrics.record_init(5), 0),
        V,
        "horizon",
    ),
    "summarize_detection Ts NaN": (
        lambda: metrics.summarize_detection(metrics.record_init(5), 10, float("nan")),
        V,
        "Ts",
    ),
    "record_update estimate_delay negative": (
        lambda: metrics.record_update(metrics.record_init(5), 0, True, estimate_delay=-1),
        V,
        "estimate_delay",
    ),
    "episode_record_init grace negative": (
        lambda: metrics.episode_record_init(
            jnp.array([1]), jnp.array([3]), jnp.array([1]), grace=-1
        ),
        V,
        "grace",
    ),
    "summarize_episodes Ts zero": (
        lambda: metrics.summarize_episodes(
            jax.tree.map(
                lambda a: a[None],
                metrics.episode_record_init(jnp.array([1]), jnp.array([3]), jnp.array([1])),
            ),
            Ts=0.0,
        ),
        V,
        "Ts",
    ),
    # --- loop ---------------------------------------------------------------------------
    "run_loop steps zero": (lambda: loop_run(steps=0), V, "steps"),
    "run_loop steps float": (lambda: loop_run(steps=2.5), T_, "steps"),
    "run_loop plant not a plant": (lambda: loop_run(plant=lambda x: x), T_, "plant"),
    "ring_buffer length zero": (lambda: jaxfdi.filters.ring_buffer(0, jnp.zeros(2)), V, "length"),
    "ring_buffer length float": (
        lambda: jaxfdi.filters.ring_buffer(3.0, jnp.zeros(2)),
        T_,
        "length",
    ),
    "state_feedback gain NaN": (lambda: loop.state_feedback(jnp.full((1, 2), jnp.nan)), V, "gain"),
    "detection_scorer estimate_delay negative": (
        lambda: loop.detection_scorer(5, lambda o: o, estimate_delay=-1),
        V,
        "estimate_delay",
    ),
    "episode_scorer grace negative": (
        lambda: loop.episode_scorer(
            (jnp.array([1]), jnp.array([3]), jnp.array([1])), lambda o: o, grace=-1
        ),
        V,
        "grace",
    ),
    "monitor estimate_delay negative": (
        lambda: jaxfdi.monitor(
            jaxfdi.linear_simulator(SMALL),
            jaxfdi.filters.kalman_filter(SMALL),
            detection.chi2_detector(10.0),
            jnp.zeros(2),
            jaxfdi.filters.kalman_filter(SMALL).init(jnp.zeros(2), jnp.eye(2)),
            jnp.zeros((T, 1)),
            KEY,
            2,
            estimate_delay=-2,
        ),
        V,
        "estimate_delay",
    ),
    "monitor us complex": (
        lambda: jaxfdi.monitor(
            jaxfdi.linear_simulator(SMALL),
            jaxfdi.filters.kalman_filter(SMALL),
            detection.chi2_detector(10.0),
            jnp.zeros(2),
            jaxfdi.filters.kalman_filter(SMALL).init(jnp.zeros(2), jnp.eye(2)),
            jnp.zeros((T, 1), complex),
            KEY,
            2,
        ),
        T_,
        "us",
    ),
    # --- Riccati and control --------------------------------------------------------
    "dare A NaN": (
        lambda: jaxfdi.filters.solve_discrete_are(
            jnp.full((2, 2), jnp.nan), jnp.eye(2), jnp.eye(2), jnp.eye(2)
        ),
        V,
        "A",
    ),
    "dare R singular": (
        lambda: jaxfdi.filters.solve_discrete_are(
            jnp.eye(2), jnp.eye(2), jnp.eye(2), jnp.zeros((2, 2))
        ),
        V,
        "R",
    ),
    "dare Q indefinite": (
        lambda: jaxfdi.filters.solve_discrete_are(jnp.eye(2), jnp.eye(2), INDEFINITE_2, jnp.eye(2)),
        V,
        "Q",
    ),
    "lqr not stabilisable": (
        lambda: control.lqr_gain(
            jnp.diag(jnp.array([1.5, 0.5])), jnp.array([[0.0], [1.0]]), jnp.eye(2), jnp.eye(1)
        ),
        V,
        "A",
    ),
    "steady_state_kalman undetectable": (
        lambda: jaxfdi.filters.steady_state_kalman(
            jaxfdi.models.linear_gaussian_model(
                jnp.diag(jnp.array([1.5, 0.5])), jnp.zeros((1, 2)), jnp.eye(2), jnp.eye(1)
            )
        ),
        V,
        "model",
    ),
    "effectiveness_gain_schedule num_losses": (
        lambda: jaxfdi.control._eigenstructure.effectiveness_gain_schedule(
            jnp.eye(2), jnp.eye(2), jnp.array([0.5, 0.4]), jnp.eye(2), num_losses=1
        ),
        V,
        "num_losses",
    ),
    "pd_gains natural_frequency negative": (
        lambda: jaxfdi.control._attitude.pd_gains(jnp.eye(3), natural_frequency=-0.1),
        V,
        "natural_frequency",
    ),
    "pd_gains damping NaN": (
        lambda: jaxfdi.control._attitude.pd_gains(jnp.eye(3), damping=float("nan")),
        V,
        "damping",
    ),
    "pd_gains inertia indefinite": (
        lambda: jaxfdi.control._attitude.pd_gains(-jnp.eye(3)),
        V,
        "inertia",
    ),
    "slew angle NaN": (lambda: slew(angle_deg=float("nan")), V, "angle_deg"),
    "slew duration zero": (lambda: slew(duration=0.0), V, "duration"),
    "slew axis zero": (lambda: slew(axis=(0.0, 0.0, 0.0)), V, "axis"),
    "allocate wheel_axes shape": (
        lambda: jaxfdi.control._attitude.allocate_wheel_torques(
            jnp.zeros(3), jnp.zeros((4, 2)), 0.1
        ),
        V,
        "wheel_axes",
    ),
    # --- model constructors ---------------------------------------------------------
    "engine_model Ts negative": (lambda: engine_model(Ts=-0.01), V, "Ts"),
    "engine_model Ts NaN": (lambda: engine_model(Ts=float("nan")), V, "Ts"),
    "vtol_model Ts zero": (lambda: vtol_model(Ts=0.0), V, "Ts"),
    "vtol_true_plant uncertainty NaN": (
        lambda: vtol_true_plant(uncertainty=float("nan")),
        V,
        "uncertainty",
    ),
    "kitsat3_params dt zero": (lambda: models.kitsat3_params(dt=0.0), V, "dt"),
    "kitsat3_params inertia negative": (
        lambda: models.kitsat3_params(inertia=(3.0, -1.0, 4.0)),
        V,
        "inertia",
    ),
    "kitsat3_params wheel_inertia NaN": (
        lambda: models.kitsat3_params(wheel_inertia=float("nan")),
        V,
        "wheel_inertia",
    ),
    "pyramid_axes beta NaN": (
        lambda: jaxfdi.models._reaction_wheels.pyramid_axes(beta_deg=float("nan")),
        V,
        "beta_deg",
    ),
    "rigid_body_params dt negative": (lambda: rigid_body_params(dt=-0.02), V, "dt"),
    "rigid_body_params inertia zero": (
        lambda: rigid_body_params(inertia=(0.0, 1.0, 1.0)),
        V,
        "inertia",
    ),
    # --- tuning --------------------------------------------------------------------------
    "positive floor negative": (lambda: tuning.positive(floor=-1.0), V, "floor"),
    "stochastic_rows empty row": (
        lambda: jaxfdi.tuning._parameterize.stochastic_rows(
            jnp.array([[True, False], [False, False]])
        ),
        V,
        "mask",
    ),
    "fit steps negative": (
        lambda: tuning.fit(
            lambda raw, b: 0.0,
            {"a": jnp.zeros(1)},
            optax.adam(1e-2),
            lambda i: None,
            None,
            steps=-1,
        ),
        V,
        "steps",
    ),
    "fit eval_every zero": (
        lambda: tuning.fit(
            lambda raw, b: 0.0,
            {"a": jnp.zeros(1)},
            optax.adam(1e-2),
            lambda i: None,
            None,
            steps=3,
            eval_every=0,
        ),
        V,
        "eval_every",
    ),
    "fixed_batches batch_size zero": (
        lambda: jaxfdi.tuning._train.fixed_batches(jnp.zeros((4, 2)), 0, KEY),
        V,
        "batch_size",
    ),
    "mode_cross_entropy floor zero": (
        lambda: tuning.mode_cross_entropy(jnp.zeros((3, 2)), jnp.zeros(3, int), 0.0),
        V,
        "floor",
    ),
    "soft_detection temperature zero": (
        lambda: tuning.soft_detection_loss(jnp.ones(5), 2.0, 3, temperature=0.0),
        V,
        "temperature",
    ),
    "soft_detection weight NaN": (
        lambda: tuning.soft_detection_loss(jnp.ones(5), 2.0, 3, false_alarm_weight=float("nan")),
        V,
        "false_alarm_weight",
    ),
    "constrain missing key": (
        lambda: tuning.constrain(
            {"a": jaxfdi.tuning._parameterize.identity()}, {"b": jnp.zeros(1)}
        ),
        V,
        "raw",
    ),
    "from_record unknown transform": (lambda: from_record("exp_map", {}), V, "name"),
    # --- scenario studies (refused before any computation) ---------------------
    "engine_study runs zero": (lambda: engine_study(runs=0), V, "runs"),
    "engine_study seed negative": (lambda: engine_study(runs=2, seed=-1), V, "seed"),
    "engine_study seed too large": (lambda: engine_study(runs=2, seed=2**64), V, "seed"),
    "engine_study unknown method": (
        lambda: engine_study(runs=2, methods=["IMM-magic"]),
        V,
        "methods",
    ),
    "engine_chi2_study pfa zero": (lambda: engine_chi2_study(runs=2, pfa=0.0), V, "pfa"),
    "engine_chi2_study window float": (lambda: engine_chi2_study(runs=2, window=2.0), T_, "window"),
    "engine_chi2_study onset after the end": (
        lambda: engine_chi2_study(runs=2, onset_time=5.0),
        V,
        "onset_time",
    ),
    "engine_chi2_study window longer than a run": (
        lambda: engine_chi2_study(runs=2, window=500),
        V,
        "window",
    ),
    "tune_engine_chi2 window longer than a run": (
        lambda: tune_engine_chi2(windows=(1, 1000)),
        V,
        "windows",
    ),
    "tune_engine_chi2 learning_rate NaN": (
        lambda: tune_engine_chi2(learning_rate=float("nan")),
        V,
        "learning_rate",
    ),
    "tune_engine_imm train_runs zero": (
        lambda: tune_engine_imm(imm_design("bias"), train_runs=0),
        V,
        "train_runs",
    ),
    "vtol_study runs float": (lambda: vtol_study(runs=2.5), T_, "runs"),
    "vtol_study unknown method": (lambda: vtol_study(runs=2, methods=["kalman"]), V, "methods"),
    "wheel_study estimator": (lambda: wheel_study(runs=2, estimator="pf"), V, "estimator"),
    "wheel_study calibration_runs zero": (
        lambda: wheel_study(runs=2, calibration_runs=0),
        V,
        "calibration_runs",
    ),
    # --- physical boundaries (issue 37 item 4) ------------------------------------------
    "f16_params mass negative": (lambda: _f16().dynamics.f16_params(mass=-600.0), V, "mass"),
    "f16_params xcg outside the chord": (lambda: _f16().dynamics.f16_params(xcg=1.4), V, "xcg"),
    "f16_params aileron limit negative": (
        lambda: _f16().dynamics.f16_params(aileron_limit=-21.5),
        V,
        "aileron_limit",
    ),
    "level_flight airspeed negative": (lambda: _f16().trim.level_flight(-502.0), V, "airspeed"),
    "level_flight altitude below sea level": (
        lambda: _f16().trim.level_flight(502.0, -100.0),
        V,
        "altitude",
    ),
    "level_flight altitude beyond the tables": (
        lambda: _f16().trim.level_flight(502.0, 6e4),
        V,
        "altitude",
    ),
    "flight_controller dt negative": (lambda: _flight_controller(dt=-0.01), V, "dt"),
    "flight_controller inverted limits": (
        lambda: _flight_controller(lower=jnp.ones(4), upper=-jnp.ones(4)),
        V,
        "lower",
    ),
    "raim_fdi dt zero": (lambda: _raim_fdi(dt=0.0), V, "dt"),
    # --- second audit of issue 37 item 4: shapes, ranges and boundaries that were silent or cryptic -------
    # F-16 model
    "f16_params jxz beyond sqrt(Jxx Jzz)": (lambda: _f16().dynamics.f16_params(jxz=1e5), V, "jxz"),
    "f16_dynamics x complex": (
        lambda: _f16().dynamics.f16_dynamics(jnp.zeros(13, complex), jnp.zeros(4), _f16p()),
        T_,
        "x",
    ),
    "f16_dynamics gust (3,)": (
        lambda: _f16().dynamics.f16_dynamics(jnp.zeros(13), jnp.zeros(4), _f16p(), jnp.zeros(3)),
        V,
        "gust",
    ),
    "saturate u (3,)": (lambda: _f16().dynamics.saturate(jnp.zeros(3), _f16p()), V, "u"),
    "trim_condition shapes that do not broadcast": (
        lambda: _f16().trim.trim_condition([500.0, 600.0], [0.0] * 3),
        V,
        "altitude",
    ),
    "climb angle beyond vertical": (lambda: _f16().trim.climb(502.0, 2.0), V, "climb_angle"),
    "trim_batch xcg length": (
        lambda: _f16().trim.trim_batch(
            _f16p(), _f16().trim.level_flight([500.0, 600.0]), jnp.full(3, 0.35)
        ),
        V,
        "xcg",
    ),
    "longitudinal_modes NaN": (
        lambda: _f16lin().longitudinal_modes(jnp.eye(4).at[0, 0].set(jnp.nan)),
        V,
        "A_lon",
    ),
    "lateral_modes complex": (lambda: _f16lin().lateral_modes(jnp.eye(4) * (1 + 1j)), T_, "A_lat"),
    "f16_sensors negative sigma": (
        lambda: _f16plant().f16_sensors(rate_sigma=-0.01),
        V,
        "rate_sigma",
    ),
    "f16_sensors NaN sigma": (
        lambda: _f16plant().f16_sensors(altitude_sigma=float("nan")),
        V,
        "altitude_sigma",
    ),
    "f16_plant dt zero": (
        lambda: _f16loop().f16_plant(_f16p(), _f16plant().f16_sensors(), dt=0.0),
        V,
        "dt",
    ),
    "f16_plant substeps float": (
        lambda: _f16loop().f16_plant(_f16p(), _f16plant().f16_sensors(), substeps=2.5),
        T_,
        "substeps",
    ),
    "f16_plant gust_sigma negative": (
        lambda: _f16loop().f16_plant(_f16p(), _f16plant().f16_sensors(), gust_sigma=-3.0),
        V,
        "gust_sigma",
    ),
    "f16_plant gust_length negative": (
        lambda: _f16loop().f16_plant(_f16p(), _f16plant().f16_sensors(), gust_length=-1750.0),
        V,
        "gust_length",
    ),
    "f16_plant fault on y[20]": (
        lambda: _f16loop().f16_plant(
            _f16p(), _f16plant().f16_sensors(), fault=fault(component=20, onset=0)
        ),
        V,
        "fault",
    ),
    "rate_model_input y (5,)": (
        lambda: _f16rates().rate_model_input(jnp.zeros(5), jnp.zeros(4)),
        V,
        "y",
    ),
    "rate_model_input u (3,)": (
        lambda: _f16rates().rate_model_input(jnp.zeros(14), jnp.zeros(3)),
        V,
        "u",
    ),
    "rate_passthrough_fdi axes (6, 2)": (
        lambda: _f16loop().rate_passthrough_fdi(jnp.eye(6)[:, :2]),
        V,
        "rate_axes",
    ),
    "lookup1 table shorter than its grid": (
        lambda: _f16tables().lookup1(3.5, jnp.arange(5.0), jnp.arange(3.0)),
        V,
        "values",
    ),
    "lookup2 table rows != row grid": (
        lambda: _f16tables().lookup2(1.0, jnp.arange(5.0), 1.0, jnp.arange(5.0), jnp.ones((4, 5))),
        V,
        "values",
    ),
    # flight control
    "flight_controller gains shape": (
        lambda: _flight_ctrl().flight_controller(
            _flight_ctrl().FlightGains(jnp.zeros((2, 7)), jnp.zeros((2, 5))),
            0.01,
            -jnp.ones(4),
            jnp.ones(4),
        ),
        V,
        "gains.longitudinal",
    ),
    "flight_controller limits (3,)": (
        lambda: _flight_ctrl().flight_controller(
            _flight_ctrl().FlightGains(jnp.zeros((2, 8)), jnp.zeros((2, 5))),
            0.01,
            -jnp.ones(3),
            jnp.ones(3),
        ),
        V,
        "lower",
    ),
    "measured_state rates (2,)": (
        lambda: _flight_ctrl().measured_state(_flight_view(rates=jnp.zeros(2))),
        V,
        "view.rates",
    ),
    "flight_plan climb_time NaN": (
        lambda: _flight_ctrl().flight_plan(climb_time=float("nan")),
        V,
        "climb_time",
    ),
    "flight_plan bank_start inf": (
        lambda: _flight_ctrl().flight_plan(bank_start=float("inf")),
        V,
        "bank_start",
    ),
    "design_flight_control negative weights": (
        lambda: _flight_ctrl().design_flight_control(
            None, 0.01, _flight_ctrl().default_weights()._replace(longitudinal=-jnp.ones(8))
        ),
        V,
        "weights.longitudinal",
    ),
    "flight_reference three trims": (
        lambda: _flight_ctrl().flight_reference(None, None, _trims(3), 0.01, 10),
        V,
        "trims.state",
    ),
    "initial_condition one trim": (
        lambda: _flight_ctrl().initial_condition(None, _trims(1)),
        V,
        "trims.state",
    ),
    # F-16 scenarios
    "flight_setup gust_sigma negative": (
        lambda: _f16flight().flight_setup(gust_sigma=-3.0),
        V,
        "gust_sigma",
    ),
    "f16_flight_study chunk_size zero": (
        lambda: _f16flight().f16_flight_study(flights=2, chunk_size=0),
        V,
        "chunk_size",
    ),
    "f16_fdi_study gust_sigma negative": (
        lambda: _f16fdi().f16_fdi_study(runs=1, gust_sigma=-3.0),
        V,
        "gust_sigma",
    ),
    "f16_fdi_study chunk_size zero": (
        lambda: _f16fdi().f16_fdi_study(runs=1, chunk_size=0),
        V,
        "chunk_size",
    ),
    "run_flight xcg outside the chord": (
        lambda: _f16flight().run_flight(
            None, KEY, _f16flight().Dispersion(jnp.asarray(1.5), jnp.zeros(13))
        ),
        V,
        "dispersion.xcg",
    ),
    "run_flight initial (12,)": (
        lambda: _f16flight().run_flight(
            None, KEY, _f16flight().Dispersion(jnp.asarray(0.35), jnp.zeros(12))
        ),
        V,
        "dispersion.initial",
    ),
    "dispersions xcg_range reversed": (
        lambda: _f16flight().dispersions(KEY, None, 5, xcg_range=(0.37, 0.33)),
        V,
        "xcg_range",
    ),
    "dispersions xcg_range beyond the chord": (
        lambda: _f16flight().dispersions(KEY, None, 5, xcg_range=(0.2, 1.4)),
        V,
        "xcg_range",
    ),
    "fdi_setup samples float": (
        lambda: _f16fdi().fdi_setup(_ns(sensors=None, x0=jnp.zeros(13)), samples=2000.5),
        T_,
        "samples",
    ),
    "fault_case unknown kind": (lambda: _f16fdi().fault_case(kind="drift2"), V, "kind"),
    "fault_case sensor 3": (lambda: _f16fdi().fault_case(sensor=3), V, "sensor"),
    "fault_case sensor -1": (lambda: _f16fdi().fault_case(sensor=-1), V, "sensor"),
    "fault_case onset negative": (lambda: _f16fdi().fault_case(onset_s=-1.0), V, "onset_s"),
    "analytic_residual_trace restart -1": (
        lambda: _f16fdi().analytic_residual_trace(
            None, jnp.zeros((20, 14)), jnp.zeros((20, 4)), -1, jnp.ones(6, bool), 3
        ),
        V,
        "restart",
    ),
    "analytic_residual_trace restart past the record": (
        lambda: _f16fdi().analytic_residual_trace(
            None, jnp.zeros((20, 14)), jnp.zeros((20, 4)), 30, jnp.ones(6, bool), 3
        ),
        V,
        "restart",
    ),
    "analytic_residual_trace trusted (5,)": (
        lambda: _f16fdi().analytic_residual_trace(
            _ns(hybrid=_ns(space=_ns(H=jnp.zeros((6, 3))))),
            jnp.zeros((20, 14)),
            jnp.zeros((20, 4)),
            2,
            jnp.ones(5, bool),
            3,
        ),
        V,
        "trusted",
    ),
    # GNSS
    "parse_yuma rollovers float": (lambda: _gnss().parse_yuma("", rollovers=1.5), T_, "rollovers"),
    "gps_week_seconds hour 30": (lambda: _gnss().gps_week_seconds(2020, 1, 4, hour=30), V, "hour"),
    "gps_week_seconds minute negative": (
        lambda: _gnss().gps_week_seconds(2020, 1, 1, minute=-5),
        V,
        "minute",
    ),
    "transmission_geometry receiver (2,)": (
        lambda: _gnss().transmission_geometry(None, 0.0, jnp.ones(2)),
        V,
        "receiver_ecef",
    ),
    "ecef_to_geodetic point (2,)": (lambda: _gnss().ecef_to_geodetic(jnp.ones(2) * 7e6), V, "ecef"),
    "ecef_to_ned origin (2,)": (
        lambda: _gnss().ecef_to_ned(jnp.ones(3) * 7e6, jnp.ones(2) * 7e6),
        V,
        "origin_ecef",
    ),
    "geodetic_to_ecef shapes that do not broadcast": (
        lambda: _gnss().geodetic_to_ecef(jnp.zeros(2), jnp.zeros(3), 0.0),
        V,
        "lat",
    ),
    "solve_position pseudoranges (31,) for 32 slots": (
        lambda: _gnss().solve_position(
            _ns(toe=jnp.zeros(32)), 0.0, jnp.zeros(31), jnp.ones(32, bool)
        ),
        V,
        "pseudoranges",
    ),
    "solve_position sigma negative": (
        lambda: _gnss().solve_position(
            _ns(toe=jnp.zeros(32)), 0.0, jnp.zeros(32), jnp.ones(32, bool), -jnp.ones(32)
        ),
        V,
        "sigma",
    ),
    "dops used (31,)": (lambda: _gnss().dops(jnp.ones((32, 4)), jnp.ones(31, bool)), V, "used"),
    "protection_levels operation (556,)": (
        lambda: _gnss().protection_levels(None, None, (556.0,)),
        V,
        "operation",
    ),
    "protection_levels negative HAL": (
        lambda: _gnss().protection_levels(None, None, (-1.0, 50.0)),
        V,
        "operation",
    ),
    "monitor_epochs pseudoranges (4, 32) for 5 epochs": (
        lambda: _gnss().monitor_epochs(
            _ns(prn=jnp.zeros(32)), jnp.zeros(5), jnp.zeros((4, 32)), None
        ),
        V,
        "pseudoranges",
    ),
    "monitor_epochs batch_size zero": (
        lambda: _gnss().monitor_epochs(
            _ns(prn=jnp.zeros(32)), jnp.zeros(5), jnp.zeros((5, 32)), None, batch_size=0
        ),
        V,
        "batch_size",
    ),
    "geometry_fix receiver (2,)": (
        lambda: _gnss().geometry_fix(None, 0.0, jnp.ones(2), 0.1, None),
        V,
        "receiver_ecef",
    ),
    "availability_grid receivers (3,)": (
        lambda: _gnss().availability_grid(None, jnp.zeros(2), jnp.ones(3), None, 0.1, None),
        V,
        "receivers_ecef",
    ),
    "raim_tables num_slots float": (lambda: _gnss().raim_tables(32.7), T_, "num_slots"),
    "paper_threshold sigma negative": (lambda: _gnss().paper_threshold(6, 0.01, -3.0), V, "sigma"),
    "visibility mask in degrees": (
        lambda: _gnss().visibility(None, 0.0, jnp.ones(3), 5.0),
        V,
        "mask_angle",
    ),
    "elevation_sigma zenith negative": (
        lambda: _gnss().elevation_sigma(jnp.asarray(0.5), zenith=-3.0),
        V,
        "zenith",
    ),
    "elevation_sigma min_elevation zero": (
        lambda: _gnss().elevation_sigma(jnp.asarray(0.0), min_elevation=0.0),
        V,
        "min_elevation",
    ),
    "receiver_plant dt zero": (lambda: _receiver(dt=0.0), V, "dt"),
    "receiver_plant sigma negative": (lambda: _receiver(sigma=-jnp.ones((3, 32))), V, "sigma"),
    "receiver_plant fault on slot 40": (
        lambda: _receiver(fault=fault(component=40, onset=0)),
        V,
        "fault",
    ),
    "racetrack_ned speed NaN": (
        lambda: _gnss().racetrack_ned(jnp.zeros(3), 600.0, 200.0, float("nan"), 30.0),
        V,
        "speed",
    ),
    # INS
    "imu sample_sigma dt negative": (
        lambda: _ins().imu.sample_sigma(_ins().imu.hg1900(), -0.01),
        V,
        "dt",
    ),
    "imu walk_biases interval negative": (
        lambda: _ins().imu.walk_biases(None, KEY, _ins().imu.hg1900(), -1.0),
        V,
        "interval",
    ),
    "imu measure samples (10, 5)": (
        lambda: _ins().imu.measure(jnp.zeros((10, 5)), None, KEY, _ins().imu.hg1900(), 0.01),
        V,
        "true_samples",
    ),
    "loosely_coupled_filter negative random walk": (
        lambda: _ins().loosely_coupled.loosely_coupled_filter(
            _ins().imu.hg1900()._replace(velocity_random_walk=-1e-3), 0.1
        ),
        V,
        "imu.velocity_random_walk",
    ),
    "loosely_coupled_filter noise densities instead of an ImuModel": (
        lambda: _ins().loosely_coupled.loosely_coupled_filter(
            _ins().imu.noise_model(_ins().imu.hg1900()), 0.1
        ),
        T_,
        "imu",
    ),
    "ins init attitude not unit": (
        lambda: _ins_init(attitude=2.0 * jnp.array([1.0, 0.0, 0.0, 0.0])),
        V,
        "nav.attitude",
    ),
    "ins init accel_bias (2,)": (lambda: _ins_init(accel_bias=jnp.zeros(2)), V, "accel_bias"),
    "scst step correction (14,)": (lambda: _scst_step(jnp.zeros(14)), V, "correction"),
    "ins initial_covariance sigma negative": (
        lambda: _ins().integrity.initial_covariance(-3.0, 0.1, 0.01, 0.05, 1e-2, 1e-5),
        V,
        "position_sigma",
    ),
    "gps_ins_fdi velocity_sigma negative": (
        lambda: _ins().integrity.gps_ins_fdi(None, 0.0, None, None, None, None, None, -0.1),
        V,
        "velocity_sigma",
    ),
    "fly blend negative": (
        lambda: _ins().trajectory.fly(
            [(2.0, 0.0, 0.0, 0.0)], (37.5, 126.9, 100.0), 12.0, blend=-5.0
        ),
        V,
        "blend",
    ),
    "fly latitude 95 deg": (
        lambda: _ins().trajectory.fly([(2.0, 0.0, 0.0, 0.0)], (95.0, 0.0, 100.0), 12.0),
        V,
        "start",
    ),
    "stationary duration negative": (
        lambda: _ins().trajectory.stationary((37.5, 126.9, 100.0), -5.0),
        V,
        "duration",
    ),
    "park_legs duration NaN": (lambda: _ins().trajectory.park_legs(float("nan")), V, "duration"),
    "quaternion_to_euler q (3,)": (
        lambda: _ins().rotation.quaternion_to_euler(jnp.array([1.0, 0.0, 0.0])),
        V,
        "q",
    ),
    "strapdown step specific force (2,)": (
        lambda: _ins().mechanization.strapdown_step(None, jnp.zeros(2), jnp.zeros(3), 0.01),
        V,
        "specific_force",
    ),
    "discretize F (14, 14)": (
        lambda: _ins().error_state.discretize(jnp.zeros((14, 14)), None, 1.0),
        V,
        "jacobian",
    ),
    # streaming, tuning, metrics, loop, study
    "detection_counts horizon shorter than the runs": (
        lambda: _streaming().detection_counts(_late_records(), 20),
        V,
        "horizon",
    ),
    "detection_summary horizon shorter than the runs": (
        lambda: (lambda s: s.counts(s.summary(_late_records(), jnp.ones(2))[1]))(
            _streaming().detection_summary(20)
        ),
        V,
        "horizon",
    ),
    "merge_counts not counts": (
        lambda: _streaming().merge_counts(_streaming().empty_counts(10), None),
        T_,
        "parts",
    ),
    "fit loss not scalar": (
        lambda: tuning.fit(
            lambda raw, b: raw["a"] ** 2,
            {"a": jnp.ones(2)},
            optax.adam(1e-2),
            lambda i: None,
            None,
            steps=1,
        ),
        V,
        "loss",
    ),
    "mode_cross_entropy float labels": (
        lambda: tuning.mode_cross_entropy(jnp.zeros((3, 2)), jnp.full(3, 0.7)),
        T_,
        "true_mode",
    ),
    "mode_cross_entropy label out of range": (
        lambda: tuning.mode_cross_entropy(jnp.zeros((3, 2)), jnp.full(3, 5)),
        V,
        "true_mode",
    ),
    "soft_detection_loss onset negative": (
        lambda: tuning.soft_detection_loss(jnp.ones(5), 2.0, -3),
        V,
        "onset",
    ),
    "record_init onset negative": (lambda: metrics.record_init(-5), V, "onset"),
    "record_init onset float": (lambda: metrics.record_init(2.5), T_, "onset"),
    "record_from_alarms healthy longer": (
        lambda: metrics.record_from_alarms(jnp.zeros(5, bool), 2, jnp.ones(6, bool)),
        V,
        "healthy",
    ),
    "record_from_alarms float alarms": (
        lambda: metrics.record_from_alarms(jnp.array([0.1, 5.0, 0.2]), 1),
        T_,
        "alarms",
    ),
    "episode_record_init onset negative": (
        lambda: metrics.episode_record_init(jnp.array([-4]), jnp.array([3]), jnp.array([1])),
        V,
        "onsets",
    ),
    "binomial_interval p above 1": (lambda: metrics.binomial_interval(10, 1.5), V, "p"),
    "binomial_interval trials negative": (lambda: metrics.binomial_interval(-5, 0.1), V, "trials"),
    "binomial_lower_bound more successes than trials": (
        lambda: metrics.binomial_lower_bound(5, 3),
        V,
        "successes",
    ),
    "binomial_lower_bound confidence 1.5": (
        lambda: metrics.binomial_lower_bound(1, 3, 1.5),
        V,
        "confidence",
    ),
    "rate_interval trials negative": (lambda: metrics.rate_interval(0, -1), V, "trials"),
    "run_loop exogenous scalar leaf": (lambda: loop_run(exogenous=jnp.zeros(())), V, "exogenous"),
    "run_loop a batch of keys": (lambda: loop_run(key=jax.random.split(KEY, 3)), T_, "key"),
    "run_loop key int": (lambda: loop_run(key=0), T_, "key"),
    "peak_scorer values not callable": (
        lambda: loop.peak_scorer(3.0, lambda k: True),
        T_,
        "values",
    ),
    "case_slices counts for 2 of 3 cases": (lambda: _case_slices([1, 2], 3), V, "runs"),
    "case_slices negative runs": (lambda: _case_slices(-2, 2), V, "runs"),
}


def _f16():
    import types

    from jaxfdi.models.f16 import _dynamics as dynamics
    from jaxfdi.models.f16 import _trim as trim

    return types.SimpleNamespace(dynamics=dynamics, trim=trim)


def _flight_controller(dt=0.01, lower=-jnp.ones(4), upper=jnp.ones(4)):
    from jaxfdi.control import FlightGains, flight_controller

    gains = FlightGains(jnp.zeros((2, 8)), jnp.zeros((2, 5)))
    return flight_controller(gains, dt, lower, upper)


def _raim_fdi(dt=1.0):
    from jaxfdi.data import data_path
    from jaxfdi.gnss import ephemeris_table, raim_fdi, raim_tables, read_rinex_nav

    table = ephemeris_table(read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n")), 2086)
    return raim_fdi(table, 0.0, dt, raim_tables(32))


def _ns(**fields):
    """A stand-in with only the fields a check reads before it refuses the call."""
    import types

    return types.SimpleNamespace(**fields)


def _f16p():
    return _f16().dynamics.f16_params()


def _f16lin():
    from jaxfdi.models.f16 import _linearize as linearize

    return linearize


def _f16plant():
    from jaxfdi.models.f16 import _plant as plant

    return plant


def _f16loop():
    from jaxfdi.control import _f16_loop as f16_loop

    return f16_loop


def _f16rates():
    from jaxfdi.models.f16 import _rates as rates

    return rates


def _f16tables():
    from jaxfdi.models.f16 import _tables as tables

    return tables


def _flight_ctrl():
    from jaxfdi.control import _flight as flight

    return flight


def _flight_view(rates=jnp.zeros(3)):
    from jaxfdi.models.f16 import FlightView

    return FlightView(jnp.zeros(3), jnp.zeros(3), jnp.zeros(()), jnp.zeros(()), rates)


def _trims(n):
    return _ns(state=jnp.zeros((n, 13)), control=jnp.zeros((n, 4)))


def _f16flight():
    from jaxfdi.scenarios import f16_flight

    return f16_flight


def _f16fdi():
    from jaxfdi.scenarios import f16_fdi

    return f16_fdi


def _gnss():
    """Every function and class of ``jaxfdi.gnss``'s modules by name, public or not."""
    import types

    from jaxfdi.gnss import _frames as frames
    from jaxfdi.gnss import _integrity as integrity
    from jaxfdi.gnss import _measurements as measurements
    from jaxfdi.gnss import _orbits as orbits
    from jaxfdi.gnss import _paths as paths
    from jaxfdi.gnss import _positioning as positioning
    from jaxfdi.gnss import _protection as protection
    from jaxfdi.gnss import _raim as raim
    from jaxfdi.gnss import _rinex as rinex
    from jaxfdi.gnss import _yuma as yuma

    modules = (
        frames,
        integrity,
        measurements,
        orbits,
        paths,
        positioning,
        protection,
        raim,
        rinex,
        yuma,
    )
    return types.SimpleNamespace(
        **{
            name: obj
            for module in modules
            for name, obj in vars(module).items()
            if getattr(obj, "__module__", None) == module.__name__
        }
    )


def _receiver(dt=1.0, sigma=jnp.ones((3, 32)), fault=None):
    return _gnss().receiver_plant(
        _ns(prn=jnp.zeros(32)),
        0.0,
        dt,
        jnp.ones((3, 3)) * 7e6,
        jnp.ones((3, 32), bool),
        sigma,
        fault=fault,
    )


def _ins():
    import types

    from jaxfdi import rotation
    from jaxfdi.ins import _error_state as error_state
    from jaxfdi.ins import _imu as imu
    from jaxfdi.ins import _integrity as integrity
    from jaxfdi.ins import _loosely_coupled as loosely_coupled
    from jaxfdi.ins import _mechanization as mechanization
    from jaxfdi.ins import _scst as scst
    from jaxfdi.ins import _trajectory as trajectory

    return types.SimpleNamespace(
        error_state=error_state,
        imu=imu,
        integrity=integrity,
        loosely_coupled=loosely_coupled,
        mechanization=mechanization,
        rotation=rotation,
        scst=scst,
        trajectory=trajectory,
    )


def _ins_init(attitude=jnp.array([1.0, 0.0, 0.0, 0.0]), accel_bias=None):
    from jaxfdi.ins import NavState

    filt = _ins().loosely_coupled.loosely_coupled_filter(_ins().imu.hg1900(), 0.1)
    nav = NavState(jnp.array([0.6, 2.2, 100.0]), jnp.zeros(3), attitude)
    return filt.init(nav, jnp.eye(15), accel_bias=accel_bias)


def _scst_step(correction):
    test = _ins().scst.state_chi2_test(10, 32.8)
    return test.step(test.init(15), correction, jnp.eye(15), jnp.eye(15), jnp.eye(15))


def _streaming():
    from jaxfdi import streaming

    return streaming


def _late_records():
    """Records of runs 100 steps long: one with its onset at 150 (fault-free within them)."""
    a = lambda v: jnp.asarray(v, jnp.int32)
    return metrics.DetectionRecord(a([150, 5]), a([-1, 7]), a([-1, 7]), a([0, 0]), a([100, 5]))


def _case_slices(runs, num_cases):
    from jaxfdi import case_slices

    return case_slices(runs, num_cases)


def test_at_least_100_cases():
    assert len(CASES) >= 100


@pytest.mark.parametrize("name", sorted(CASES))
def test_malformed_call_is_refused(name):
    thunk, error, argument = CASES[name]
    with pytest.raises((ValueError, TypeError)) as excinfo:
        thunk()
    message = str(excinfo.value)
    assert type(excinfo.value) is error or isinstance(excinfo.value, error), (
        f"raised {type(excinfo.value).__name__}, expected {error.__name__}: {message}"
    )
    assert re.search(rf"(^|[^\w.]){re.escape(argument)}([^\w]|$)", message), (
        f"message does not name {argument!r}: {message!r}"
    )


def test_valid_neighbours_pass():
    """The checks are not over-eager: valid values at the edge of each family trace."""
    tiny = jaxfdi.models.linear_gaussian_model(
        jnp.eye(2), jnp.eye(2), jnp.zeros((2, 2)), 1e-24 * jnp.eye(2)
    )
    assert kf_run(
        tiny, jnp.zeros(2), jnp.eye(2), jnp.zeros((T, 2)), jnp.zeros((T, 0))
    ).nis.shape == (T,)
    info = kf_run(mean=jnp.zeros(N, int))  # an integer mean is promoted, not the cov demoted
    assert info.filtered_cov.dtype == jnp.result_type(float)
    skipping = jaxfdi.filters.kalman_filter(MODEL, missing_measurements=True)
    assert kf_run(ys=YS.at[1, 2].set(jnp.nan), filt=skipping).nis.shape == (
        T,
    )  # NaN = missing is valid there
    assert jaxfdi.models._fault_modes.noise_inflation_modes(MODEL, 1.0, 0.0).Q.shape == (
        1 + NU + M,
        N,
        N,
    )
    assert jaxfdi.fault("stuck", "sensor", 4, 0).onset == 0
    assert jaxfdi.fault("effectiveness", "actuator", 0, 3, 1.0).magnitude == 1.0
    assert sim_with(fault(component=M - 1))[1].measurement.shape == (T, M)
    assert int(metrics.confusion_matrix(jnp.array([0, 2]), jnp.array([-1, 2]), 3).sum()) == 2
    assert jaxfdi.monte_carlo(lambda key, x: x, KEY, 2, jnp.arange(2), chunk_size=1).shape == (2,)
    assert float(detection.chi2_threshold(np.int64(4), 0.005)) == pytest.approx(14.86, abs=5e-3)


def test_second_audit_valid_neighbours_pass():
    """The checks of the second audit are not over-eager: batched and edge values still pass."""
    params = _f16p()
    assert _f16().dynamics.saturate(jnp.zeros((5, 4)), params).shape == (
        5,
        4,
    )  # a (T, 4) batch of controls
    assert _f16tables().lookup1(1.5, jnp.arange(5.0), jnp.ones((2, 5))).shape == (
        2,
    )  # m tables on one grid
    assert _f16().trim.trim_condition([500.0, 600.0], 0.0, climb_angle=1.5).airspeed.shape == (2,)
    points = jnp.ones((4, 3)) * 4e6
    assert _gnss().ecef_to_ned(points, points + 10.0).shape == (4, 3)  # one origin per point
    assert _gnss().raim_tables(np.int64(32)).threshold.shape == (29,)
    assert _gnss().gps_week_seconds(2020, 1, 4, 23, 59, 59.5) == (2086, 604799.5)
    assert np.isfinite(float(_gnss().elevation_sigma(jnp.asarray(0.0))))
    quaternion = _ins().rotation.euler_to_quaternion(0.1, -0.05, 2.0).astype(jnp.float32)
    assert _ins_init(attitude=quaternion).nav.attitude.shape == (4,)  # float32 round-off passes
    assert (
        int(metrics.record_init(jaxfdi._simulation.faults.NEVER).onset)
        == jaxfdi._simulation.faults.NEVER
    )
    assert (
        int(metrics.record_from_alarms(jnp.array([0, 1, 1]), 1).detection_step) == 1
    )  # 0/1 integer alarms
    assert _case_slices([0, 2], 2) == [slice(0, 0), slice(0, 2)]
    assert _f16fdi().fault_case(["bias", "none"], [0, 2], 10.0, 45.0).kind.shape == (2,)
