"""The health invariant of every filter (issue 22): a step whose outputs hold a non-finite
value is flagged, ``healthy == False``; no filter hands a NaN or an infinity downstream
as a sound estimate.

A property test over seeded random models: each case draws a random 3-state, 2-output
model and perturbs it in one way — stable, unstable, explosive (the covariance
overflows), ill-conditioned noise (a variance of 1e-24, a rotated R with condition 1e24),
huge or tiny priors, a singular Q, C = 0, and NaN/inf injected into the measurements,
the inputs, the model and the prior. The models are arguments of one ``jit(vmap)`` per
filter, so the library's trace-time checks see tracers and let everything through, as
they do under a user's ``jit``: the flag is the only line of defence there.

Every filter of the library is run: ``kalman_filter`` (both ``unroll_factorizations``,
``missing_measurements`` on and off), ``extended_kalman_filter``,
``unscented_kalman_filter``, ``interacting_multiple_model`` (its ``vmap`` step and its
structure-of-arrays batch kernel), ``multiple_model``, ``two_stage_kalman_filter``,
``unknown_input_filter`` and ``time_varying``. For each step of each case, every
floating field of the step's info (``FilterInfo``, ``IMMInfo``, ``TSKFInfo``) is
checked; a log mode probability of ``-inf`` is a probability of 0, not a failure.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi.filters import _tskf as tskf
from jaxfdi.filters import time_varying, unknown_input_filter
from jaxfdi.filters._time_varying import model_at

N, M, NU, T = 3, 2, 1, 10


class Case(NamedTuple):
    Phi: np.ndarray  # (n, n)
    Gamma: np.ndarray  # (n, nu)
    C: np.ndarray  # (m, n)
    Q: np.ndarray  # (n, n)
    R: np.ndarray  # (m, m)
    m0: np.ndarray  # (n,)
    P0: np.ndarray  # (n, n)
    ys: np.ndarray  # (T, m)
    us: np.ndarray  # (T, nu)
    Q_scale: np.ndarray  # (T,) per-step factor of Q for the time-varying filter


def _spd(rng, size, scale):
    a = rng.normal(size=(size, size))
    return scale * (a @ a.T / size + 0.5 * np.eye(size))


def _base(rng) -> Case:
    Phi = rng.normal(size=(N, N))
    Phi *= 0.9 / np.max(np.abs(np.linalg.eigvals(Phi)))
    Gamma, C = rng.normal(size=(N, NU)), rng.normal(size=(M, N))
    Q, R = _spd(rng, N, 1e-2), _spd(rng, M, 1e-1)
    us = rng.normal(size=(T, NU))
    x, ys = rng.normal(size=N), []
    for k in range(T):
        ys.append(C @ x + rng.multivariate_normal(np.zeros(M), R))
        x = Phi @ x + Gamma @ us[k] + rng.multivariate_normal(np.zeros(N), Q)
    return Case(
        Phi, Gamma, C, Q, R, np.zeros(N), np.eye(N), np.array(ys), us, 1.0 + rng.uniform(size=T)
    )


def _rotation(rng, size):
    return np.linalg.qr(rng.normal(size=(size, size)))[0]


def _with(case: Case, rng, kind: str) -> Case:
    """One perturbation of a random case (the property's input space)."""
    step, comp = rng.integers(T), rng.integers(M)
    ys = case.ys.copy()
    if kind == "nominal":
        return case
    if kind == "unstable":
        return case._replace(Phi=case.Phi * 1.5 / 0.9)
    if kind == "explosive":  # P grows by ~1e40 per step and overflows
        return case._replace(Phi=case.Phi * 1e20)
    if kind == "R variance 1e-24":
        R = case.R.copy()
        R[comp, :] = R[:, comp] = 0.0
        R[comp, comp] = 1e-24
        return case._replace(R=R)
    if kind == "R condition 1e24":
        U = _rotation(rng, M)
        return case._replace(R=U @ np.diag([1e-20, 1e4]) @ U.T)
    if kind == "P0 1e12":
        return case._replace(P0=1e12 * np.eye(N))
    if kind == "P0 1e200":
        return case._replace(P0=1e200 * np.eye(N))
    if kind == "Q 0, P0 1e-30":
        return case._replace(Q=np.zeros((N, N)), P0=1e-30 * np.eye(N))
    if kind == "C 0":
        return case._replace(C=np.zeros((M, N)))
    if kind == "y NaN":
        ys[step, comp] = np.nan
        return case._replace(ys=ys)
    if kind == "y inf":
        ys[step, comp] = np.inf
        return case._replace(ys=ys)
    if kind == "y 1e250":
        ys[step, comp] = 1e250
        return case._replace(ys=ys)
    if kind == "u NaN":
        us = case.us.copy()
        us[step, 0] = np.nan
        return case._replace(us=us)
    if kind == "Phi NaN":
        Phi = case.Phi.copy()
        Phi[rng.integers(N), rng.integers(N)] = np.nan
        return case._replace(Phi=Phi)
    if kind == "R NaN":
        R = case.R.copy()
        R[comp, comp] = np.nan
        return case._replace(R=R)
    if kind == "Q inf":
        Q = case.Q.copy()
        Q[0, 0] = np.inf
        return case._replace(Q=Q)
    if kind == "P0 NaN":
        P0 = case.P0.copy()
        P0[1, 1] = np.nan
        return case._replace(P0=P0)
    raise AssertionError(kind)


KINDS = (
    "nominal",
    "unstable",
    "explosive",
    "R variance 1e-24",
    "R condition 1e24",
    "P0 1e12",
    "P0 1e200",
    "Q 0, P0 1e-30",
    "C 0",
    "y NaN",
    "y inf",
    "y 1e250",
    "u NaN",
    "Phi NaN",
    "R NaN",
    "Q inf",
    "P0 NaN",
)


def _cases():
    rng = np.random.default_rng(20220)
    names, cases = [], []
    for repeat in range(2):  # two random models per kind
        for kind in KINDS:
            names.append(f"{kind} #{repeat}")
            cases.append(_with(_base(rng), rng, kind))
    return names, Case(*(np.stack(leaves) for leaves in zip(*cases)))


NAMES, CASES = _cases()
#: C of the unknown-input filter: decoupling is checked on a concrete C (not the batch's)
C_FIXED = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, -0.3]])
E = np.array([[1.0], [0.0], [0.0]])


def _model(case: Case, C=None) -> jaxfdi.models.LinearGaussianModel:
    C = case.C if C is None else C
    return jaxfdi.models.LinearGaussianModel(
        case.Phi, case.Gamma, C, jnp.zeros((M, NU)), case.Q, case.R
    )


def _modes(model: jaxfdi.models.LinearGaussianModel) -> jaxfdi.models.LinearGaussianModel:
    stacked = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), model)
    return stacked._replace(Q=jnp.stack([model.Q, 10.0 * model.Q]))


def _f(x, u, model):
    return model.Phi @ x + model.Gamma @ u + 0.05 * jnp.sin(x)


def _h(x, u, model):
    y = model.C @ x
    return y + 0.05 * y**2


def _kalman(unroll: bool, missing: bool):
    def run(case):
        filt = jaxfdi.filters.kalman_filter(
            _model(case), missing_measurements=missing, unroll_factorizations=unroll
        )
        return jaxfdi.filters.run_filter(filt, filt.init(case.m0, case.P0), case.ys, case.us)[1]

    return run


def _ekf(case):
    model = _model(case)
    filt = jaxfdi.filters.extended_kalman_filter(_f, _h, model.Q, model.R, model)
    return jaxfdi.filters.run_filter(filt, filt.init(case.m0, case.P0), case.ys, case.us)[1]


def _ukf(case):
    model = _model(case)
    filt = jaxfdi.filters.unscented_kalman_filter(_f, _h, model.Q, model.R, model)
    return jaxfdi.filters.run_filter(filt, filt.init(case.m0, case.P0), case.ys, case.us)[1]


TRANSITION = np.array([[0.95, 0.05], [0.05, 0.95]])


def _imm(case):
    filt = jaxfdi.filters.interacting_multiple_model(
        jaxfdi.filters.kalman_filter, _modes(_model(case)), TRANSITION
    )
    return jaxfdi.filters.run_filter(
        filt, filt.init(case.m0, case.P0, jnp.array([0.5, 0.5])), case.ys, case.us
    )[1]


def _imm_batch_kernel(case):
    filt = jaxfdi.filters.interacting_multiple_model(
        jaxfdi.filters.kalman_filter, _modes(_model(case)), TRANSITION
    )
    assert filt.batch is not None
    info = jaxfdi.filters.run_filter(
        filt, filt.init(case.m0, case.P0, jnp.array([0.5, 0.5])), case.ys[None], case.us
    )[1]
    return jax.tree_util.tree_map(lambda a: a[0], info)


def _mm(case):
    filt = jaxfdi.filters.multiple_model(
        jaxfdi.filters.kalman_filter, _modes(_model(case)), floor=0.01
    )
    return jaxfdi.filters.run_filter(
        filt, filt.init(case.m0, case.P0, jnp.array([0.5, 0.5])), case.ys, case.us
    )[1]


def _tskf(case):
    model = _model(case)
    filt = tskf.two_stage_kalman_filter(
        model, tskf.sensor_direction(model, 0, "additive"), 1e-4 * jnp.eye(1)
    )
    return jaxfdi.filters.run_filter(
        filt, filt.init(case.m0, case.P0, jnp.zeros(1), 0.1 * jnp.eye(1)), case.ys, case.us
    )[1]


def _unknown_input(case):
    filt = unknown_input_filter(_model(case, C_FIXED), E)
    return jaxfdi.filters.run_filter(filt, filt.init(case.m0, case.P0), case.ys, case.us)[1]


def _time_varying(case):
    at = model_at(_model(case), Q=case.Q_scale[:, None, None] * case.Q[None])
    filt = time_varying(lambda k: jaxfdi.filters.kalman_filter(at(k)))
    return jaxfdi.filters.run_filter(filt, filt.init(case.m0, case.P0), case.ys, case.us)[1]


FILTERS = {
    "kalman unrolled": _kalman(True, False),
    "kalman lapack": _kalman(False, False),
    "kalman unrolled missing": _kalman(True, True),
    "kalman lapack missing": _kalman(False, True),
    "ekf": _ekf,
    "ukf": _ukf,
    "imm": _imm,
    "imm batch kernel": _imm_batch_kernel,
    "mm": _mm,
    "tskf": _tskf,
    "unknown input": _unknown_input,
    "time varying": _time_varying,
}

#: filters whose update keeps a dead channel (non-finite y) out of the state and reports it
DEAD_CHANNEL_FILTERS = (
    "kalman unrolled",
    "kalman lapack",
    "kalman unrolled missing",
    "kalman lapack missing",
    "ekf",
    "ukf",
    "imm",
    "imm batch kernel",
    "mm",
    "time varying",
    "tskf",
    "unknown input",
)

#: fields where -inf is a value (log of a zero probability), not a failure
LOG_PROBABILITIES = ("log_mode_prob",)


def _nonfinite_steps(info, dead: np.ndarray) -> dict[str, np.ndarray]:
    """(cases, T) bool per floating field: the step's value of that field is not finite,
    other than a dead channel's evidence (``filters._base``): NaN in the innovation (the
    TSKF's residual) exactly where ``y`` was not finite (``dead`` (cases, T, m)), ``nis``
    (the TSKF's statistic) ``+inf`` there."""
    bad = {}
    for name, value in info._asdict().items():
        value = np.asarray(value)
        if name == "healthy" or value.dtype.kind != "f":
            continue
        value = np.where(np.isneginf(value), 0.0, value) if name in LOG_PROBABILITIES else value
        if name in ("innovation", "residual") and value.shape == dead.shape:
            value = np.where(dead & np.isnan(value), 0.0, value)
        if name in ("nis", "statistic"):
            value = np.where(dead.any(axis=-1) & np.isposinf(value), 0.0, value)
        bad[name] = ~np.all(np.isfinite(value.reshape(value.shape[:2] + (-1,))), axis=-1)
    return bad


@pytest.mark.parametrize("name", list(FILTERS))
def test_non_finite_output_implies_unhealthy(name):
    info = jax.jit(jax.vmap(FILTERS[name]))(jax.tree_util.tree_map(jnp.asarray, CASES))
    healthy = np.asarray(info.healthy)
    assert healthy.shape == (len(NAMES), T)
    bad = _nonfinite_steps(info, ~np.isfinite(CASES.ys))
    violations = [
        f"{NAMES[i]} step {k}: {', '.join(f for f, b in bad.items() if b[i, k])}"
        for i in range(len(NAMES))
        for k in range(T)
        if healthy[i, k] and any(b[i, k] for b in bad.values())
    ]
    assert not violations, f"{name}: non-finite outputs flagged healthy:\n" + "\n".join(violations)
    # not vacuous: sound cases are healthy throughout, poisoned ones are flagged
    for i, case_name in enumerate(NAMES):
        if case_name.startswith(("nominal", "unstable")):
            assert healthy[i].all(), (
                f"{name}: {case_name} flagged unhealthy at steps {np.flatnonzero(~healthy[i])}"
            )
        if case_name.startswith(("Phi NaN", "P0 NaN", "R NaN")):
            assert not healthy[i].all(), f"{name}: {case_name} never flagged"
        if name in DEAD_CHANNEL_FILTERS and case_name.startswith(("y NaN", "y inf")):
            # a dead sensor is evidence, not ill health: reported, and the state stays sound
            assert healthy[i].all(), (
                f"{name}: {case_name}: a dead channel made the filter unhealthy"
            )
            step = np.flatnonzero(~np.isfinite(CASES.ys[i]).all(axis=-1))[0]
            if hasattr(info, "dead"):
                evidence = np.asarray(info.dead)[i, step].any()
            else:
                evidence = (
                    np.asarray(info.nis if hasattr(info, "nis") else info.statistic)[i, step]
                    == np.inf
                )
            if not (
                name.endswith("missing") and case_name.startswith("y NaN")
            ):  # there NaN is 'not measured'
                assert evidence, (
                    f"{name}: {case_name}: the dead channel at step {step} is not reported"
                )
