"""Contract tests over every ``Filter`` of the library (the detectors':
``tests/detection/test_detector_contracts.py``): finite outputs of the documented shapes
and dtypes, jit == eager and the jitted driver traces once, ``run_filter`` on (N, T, m) ==
the loop over runs, vmap over a parameter bank, float32 kept (and within 1e-3 of float64
where float32 resolves the output), the likelihood's gradient == a finite difference, and
for the Gaussian filters (also on a nonlinear rigid body) gradients along full symmetric Q
and R directions, in forward and reverse mode, == finite differences."""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import rigid_body_data

import jaxfdi
from jaxfdi.models import linear_observation, linear_transition
from jaxfdi.models._rigid_body import rigid_body_observation, rigid_body_transition

# ------------------------------------------------------------------ every Filter of the library
# One small problem per filter (float64; the conftest enables x64): ``build(theta, dtype)``
# gives the filter and its initial state for a scalar model parameter ``theta`` (a scale
# of the measurement noise, or of the prior for the INS) in ``dtype``. Each case lists
# every leaf of its step's info with its documented per-step shape and kind ('f' float of
# the filter's dtype, 'b' bool, 'i' int32).
T_STEPS, N_RUNS = 12, 3
F = "f"
FILTER_INFO = {
    "predicted_mean": ((3,), F),
    "predicted_cov": ((3, 3), F),
    "filtered_mean": ((3,), F),
    "filtered_cov": ((3, 3), F),
    "innovation": ((2,), F),
    "innovation_cov": ((2, 2), F),
    "log_likelihood": ((), F),
    "nis": ((), F),
    "num_observed": ((), "i"),
    "healthy": ((), "b"),
}
RIGID_BODY_INFO = {**FILTER_INFO, "innovation": ((3,), F), "innovation_cov": ((3, 3), F)}
IMM_INFO = {
    "mode_prob": ((2,), F),
    "log_mode_prob": ((2,), F),
    "mean": ((3,), F),
    "cov": ((3, 3), F),
    "mode_mean": ((2, 3), F),
    "mode_cov": ((2, 3, 3), F),
    "mode_log_likelihood": ((2,), F),
    "log_likelihood": ((), F),
    "healthy": ((), "b"),
    "dead": ((2,), "b"),
}
TSKF_INFO = {
    "filtered_mean": ((3,), F),
    "filtered_cov": ((3, 3), F),
    "bias_mean": ((1,), F),
    "bias_cov": ((1, 1), F),
    "residual": ((2,), F),
    "residual_cov": ((2, 2), F),
    "statistic": ((), F),
    "log_likelihood": ((), F),
    "healthy": ((), "b"),
}
DUAL_INFO = {
    **{f"estimator.{name}": spec for name, spec in FILTER_INFO.items()},
    "prediction": ((3,), F),
    "det_prediction": ((), F),
    "det_estimation": ((), F),
    "detection_parameter": ((), F),
    "healthy": ((), "b"),
}
CORRECTED_INFO = {
    "decision.statistic": ((), F),
    "decision.alarm": ((), "b"),
    "decision.label": ((), "i"),
    "decision.estimate": ((), F),
    "onset": ((), "i"),
    "information": ((), F),
    "confirmed": ((), "b"),
    "innovation": ((2,), F),
    "predicted_mean": ((3,), F),
    "fault": ((3,), F),
    "healthy": ((), "b"),
}
INS_INFO = {
    "innovation": ((6,), F),
    "innovation_cov": ((6, 6), F),
    "nis": ((), F),
    "used": ((), "b"),
    "correction": ((15,), F),
    "predicted_cov": ((15, 15), F),
    "filtered_cov": ((15, 15), F),
    "filtered_nav.position": ((3,), F),
    "filtered_nav.velocity": ((3,), F),
    "filtered_nav.attitude": ((4,), F),
    "accel_bias": ((3,), F),
    "gyro_bias": ((3,), F),
    "transition": ((15, 15), F),
    "process_cov": ((15, 15), F),
    "healthy": ((), "b"),
}


class FilterCase(NamedTuple):
    build: object  # (theta, dtype) -> (Filter, initial state)
    info: dict  # leaf path -> (per-step shape, kind)
    ys: object = None  # (T, m), or a pytree for ``scan_only``
    us: object = None  # (T, nu), or a pytree for ``scan_only``
    #: info -> (T,) log-likelihoods; None: no gradient check (reason at the case)
    log_likelihood: object = None
    #: measurements are a pytree: driven by lax.scan, not run_filter (reason at the case)
    scan_only: bool = False
    rtol: float = 1e-9  # batch / vmap against the loop over runs
    jit_rtol: float = 1e-10  # jit against eager
    #: (Q, R) -> (Filter, initial state) of a Gaussian filter; None: no Q, R gradient check
    noise: object = None
    noise_QR: tuple = ()  # the nominal (Q, R) of ``noise``
    #: Q, R gradient against the finite difference, relative to sum |dL/dtheta dtheta|
    fd_rtol: float = 1e-7
    #: float32 against float64, relative to each output's largest magnitude
    float32_atol: float | None = 1e-3
    #: the largest |weight| a sum of the filter's step carries: 1, or a UKF's largest sigma-point
    #: weight (``_unscented_weight``); it sets the rounding level of forward against reverse mode
    weight: float = 1.0


def _unscented_weight(n: int, alpha: float = 1e-3, beta: float = 2.0, kappa: float = 0.0) -> float:
    """The largest |weight| of the unscented transform (Julier 2002): ``lambda = alpha^2 (n + kappa) - n``,
    ``W_0^m = lambda / (n + lambda)``, ``W_0^c = W_0^m + 1 - alpha^2 + beta``, ``W_i = 1 / (2 (n + lambda))``
    (~1e6 for alpha = 1e-3: a sum over sigma points cancels six digits)."""
    lam = alpha**2 * (n + kappa) - n
    w0 = lam / (n + lam)
    return max(abs(w0), abs(w0 + 1 - alpha**2 + beta), 1 / (2 * (n + lam)))


def _cast(tree, dtype):
    """Float leaves in ``dtype``; concrete ones stay concrete (NumPy) inside a trace, as
    filters that check a matrix at build time (the unknown-input filter's ``C E``) need."""

    def cast(a):
        if not jnp.issubdtype(jnp.result_type(a), jnp.floating):
            return a
        return jnp.asarray(a, dtype) if isinstance(a, jax.core.Tracer) else np.asarray(a, dtype)

    return jax.tree_util.tree_map(cast, tree)


@functools.lru_cache(maxsize=None)
def _linear_problem():
    from _linear_gaussian_cases import small_model

    model = small_model()
    us = np.sin(0.3 * np.arange(T_STEPS))[:, None]
    _, truth, _ = jaxfdi.simulate(
        jaxfdi.linear_simulator(model),
        jnp.array([0.5, -0.2, 0.1]),
        jnp.asarray(us),
        jax.random.key(3),
    )
    return model, np.asarray(truth.measurement), us


class RigidBody(NamedTuple):
    """The nonlinear rigid-body rates (Euler's equations) with their noise covariances."""

    params: object
    Q: np.ndarray
    R: np.ndarray


@functools.lru_cache(maxsize=None)
def _rigid_body_problem():
    params, Q, R, ys, us, _, _ = rigid_body_data(T=T_STEPS)
    return RigidBody(params, Q, R), ys, us


def _gaussian(make, info=None, problem=_linear_problem, m0=np.zeros(3), P0=np.eye(3), **kw):
    """The case of a Gaussian filter with ``init(mean, cov)``, ``make(model)``: ``build`` scales the model's
    measurement noise by theta, ``noise`` sets both of its covariances."""
    model, ys, us = problem()

    def noise(Q, R, dtype=jnp.float64):
        filt = make(_cast(model, dtype)._replace(Q=Q, R=R))
        return filt, filt.init(jnp.asarray(m0, dtype), jnp.asarray(P0, dtype))

    def build(theta, dtype):
        scaled = _cast(model, dtype)
        return noise(scaled.Q, scaled.R * theta, dtype)

    return FilterCase(
        build,
        info or FILTER_INFO,
        ys,
        us,
        log_likelihood=lambda info: info.log_likelihood,
        noise=noise,
        noise_QR=(np.asarray(model.Q), np.asarray(model.R)),
        **kw,
    )


def _modes(model):
    """Two kalman_filter modes: nominal, and the measurement noise x 4."""
    stacked = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), model)
    return stacked._replace(R=stacked.R * jnp.asarray([1.0, 4.0], model.R.dtype)[:, None, None])


def _bank_build(make):
    model, _, _ = _linear_problem()

    def build(theta, dtype):
        scaled = _cast(model, dtype)
        filt = make(_modes(scaled._replace(R=scaled.R * theta)))
        return filt, filt.init(
            jnp.zeros(3, dtype), jnp.eye(3, dtype=dtype), jnp.asarray([0.9, 0.1], dtype)
        )

    return build


def _time_varying_build(theta, dtype):
    from jaxfdi.filters._time_varying import model_at, time_varying

    model, _, _ = _linear_problem()
    scaled = _cast(model, dtype)
    wobble = 1.0 + 0.5 * jnp.sin(jnp.arange(T_STEPS, dtype=dtype))
    at = model_at(scaled, R=scaled.R[None] * theta * wobble[:, None, None])
    filt = time_varying(lambda k: jaxfdi.filters.kalman_filter(at(k)))
    return filt, filt.init(jnp.zeros(3, dtype), jnp.eye(3, dtype=dtype))


def _dual_field(x, u, model):
    """A continuous-time field with a state-dependent Jacobian (its determinant varies)."""
    return model.Phi @ x - x + 0.1 * jnp.sin(x) + model.Gamma @ u


def _dual_build(theta, dtype):
    from jaxfdi.detection import dual_filter

    model, _, _ = _linear_problem()
    scaled = _cast(model, dtype)
    ekf = jaxfdi.filters.extended_kalman_filter(
        linear_transition, linear_observation, scaled.Q, scaled.R * theta, scaled
    )
    filt = dual_filter(ekf, linear_transition, _dual_field, scaled)
    return filt, filt.init(jnp.zeros(3, dtype), jnp.eye(3, dtype=dtype))


def _corrected_glrt_build(theta, dtype):
    from jaxfdi.detection import corrected_glrt

    model, _, _ = _linear_problem()
    scaled = _cast(model, dtype)
    filt = corrected_glrt(scaled._replace(R=scaled.R * theta), 4, 30.0)
    return filt, filt.init(jnp.zeros(3, dtype))


@functools.lru_cache(maxsize=None)
def _ins_problem():
    """Four GPS epochs of a level INS moving north-east, four IMU samples 0.01 s apart each."""
    from jaxfdi.ins import GpsFix, NavState

    epochs, per_epoch = 4, 4
    nav = NavState(
        jnp.asarray([0.6547, 2.2146, 130.0]),
        jnp.asarray([11.0, -3.0, 0.4]),
        jnp.asarray([1.0, 0.0, 0.0, 0.0]),
    )
    rng = np.random.default_rng(8)
    k = np.arange(1, epochs + 1)[:, None] * per_epoch * 0.01
    position = np.asarray(nav.position) + np.concatenate(
        [11.0 * k / 6.37e6, -3.0 * k / 5.1e6, -0.4 * k], 1
    )
    fixes = GpsFix(
        jnp.asarray(position + rng.normal(size=(epochs, 3)) * [1e-7, 1e-7, 1.0]),
        jnp.asarray(np.asarray(nav.velocity) + 0.05 * rng.normal(size=(epochs, 3))),
        jnp.tile(4.0 * jnp.eye(3), (epochs, 1, 1)),
        jnp.tile(0.01 * jnp.eye(3), (epochs, 1, 1)),
        jnp.ones(epochs, bool),
    )
    samples = np.tile([0.0, 0.0, -9.8, 0.0, 0.0, 0.0], (epochs, per_epoch, 1)) + 1e-3 * rng.normal(
        size=(epochs, per_epoch, 6)
    )
    return nav, fixes, jnp.asarray(samples)


def _ins_build(theta, dtype):
    from jaxfdi.ins import _imu as imu
    from jaxfdi.ins import loosely_coupled_filter

    nav, _, _ = _ins_problem()
    filt = loosely_coupled_filter(imu.hg1900(), 0.01)
    prior = jnp.diag(
        jnp.asarray(
            [4, 4, 9, 0.01, 0.01, 0.01, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 1e-4, 1e-11, 1e-11, 1e-11]
        )
    )
    return filt, filt.init(_cast(nav, dtype), jnp.asarray(theta * prior, dtype))


def _filter_registry():
    from jaxfdi.filters import (
        interacting_multiple_model,
        multiple_model,
        sensor_direction,
        sqrt_kalman_filter,
        sqrt_unscented_kalman_filter,
        two_stage_kalman_filter,
        unknown_input_filter,
    )
    from jaxfdi.tuning import checkpointed

    _, ys, us = _linear_problem()
    linear = dict(ys=ys, us=us)
    own = lambda info: info.log_likelihood

    def nonlinear(kind):  # an EKF / UKF on the linear model
        return lambda model: kind(linear_transition, linear_observation, model.Q, model.R, model)

    def rigid_body(kind):  # an EKF / UKF on Euler's equations
        return lambda body: kind(
            rigid_body_transition, rigid_body_observation, body.Q, body.R, body.params
        )

    def tskf(model):
        walk = 1e-4 * np.eye(1, dtype=model.R.dtype)
        return two_stage_kalman_filter(model, sensor_direction(model, 0, "additive"), walk)

    _, fixes, samples = _ins_problem()
    return {
        "kalman_filter": _gaussian(jaxfdi.filters.kalman_filter),
        "extended_kalman_filter": _gaussian(nonlinear(jaxfdi.filters.extended_kalman_filter)),
        # the UKFs' default alpha = 1e-3 puts weights ~1/alpha^2 ~ 1e6 on sigma-point differences: reassociated
        # sums (jit, vmap) differ by ~1e6 eps, and the log-likelihood carries ~1e-8 of rounding (fd_rtol)
        "unscented_kalman_filter": _gaussian(
            nonlinear(jaxfdi.filters.unscented_kalman_filter),
            jit_rtol=1e-9,
            fd_rtol=1e-5,
            weight=_unscented_weight(3),
        ),
        "extended_kalman_filter on a rigid body": _gaussian(
            rigid_body(jaxfdi.filters.extended_kalman_filter),
            RIGID_BODY_INFO,
            _rigid_body_problem,
            P0=0.1 * np.eye(3),
        ),
        "unscented_kalman_filter on a rigid body": _gaussian(
            rigid_body(jaxfdi.filters.unscented_kalman_filter),
            RIGID_BODY_INFO,
            _rigid_body_problem,
            P0=0.1 * np.eye(3),
            rtol=1e-8,
            jit_rtol=1e-9,
            fd_rtol=1e-5,
            float32_atol=1e-2,  # P[k|k] 1.2e-3 off in float32
            weight=_unscented_weight(3),
        ),
        "sqrt_kalman_filter": _gaussian(sqrt_kalman_filter),
        "sqrt_unscented_kalman_filter": _gaussian(
            nonlinear(sqrt_unscented_kalman_filter),
            jit_rtol=1e-9,
            fd_rtol=1e-5,
            weight=_unscented_weight(3),
        ),
        "interacting_multiple_model": FilterCase(
            _bank_build(
                lambda modes: interacting_multiple_model(
                    jaxfdi.filters.kalman_filter, modes, jnp.asarray([[0.95, 0.05], [0.05, 0.95]])
                )
            ),
            IMM_INFO,
            log_likelihood=own,
            **linear,
        ),
        "multiple_model": FilterCase(
            _bank_build(lambda modes: multiple_model(jaxfdi.filters.kalman_filter, modes, 1e-3)),
            IMM_INFO,
            log_likelihood=own,
            **linear,
        ),
        # tuning.train.checkpointed: any filter with its step (and batch kernel) rematerialised
        "checkpointed": FilterCase(
            _bank_build(
                lambda modes: checkpointed(
                    interacting_multiple_model(
                        jaxfdi.filters.kalman_filter,
                        modes,
                        jnp.asarray([[0.95, 0.05], [0.05, 0.95]]),
                    )
                )
            ),
            IMM_INFO,
            log_likelihood=own,
            **linear,
        ),
        "two_stage_kalman_filter": _gaussian(tskf, TSKF_INFO),
        "unknown_input_filter": _gaussian(
            lambda model: unknown_input_filter(
                model, np.asarray([[0.0], [1.0], [0.0]], model.R.dtype)
            )
        ),
        "time_varying": FilterCase(_time_varying_build, FILTER_INFO, log_likelihood=own, **linear),
        "dual_filter": FilterCase(
            _dual_build,
            DUAL_INFO,
            log_likelihood=lambda info: info.estimator.log_likelihood,
            **linear,
        ),
        # no gradient check: the corrected GLRT reports no likelihood, and its corrections are
        # discrete decisions (a confirmed alarm), not a smooth function of the model
        "corrected_glrt": FilterCase(_corrected_glrt_build, CORRECTED_INFO, **linear),
        # the INS's measurement is a GpsFix pytree and its input (n, 6) IMU samples an epoch:
        # run_filter takes (T, m) arrays, so it is driven by lax.scan and has no (N, T, m) form;
        # no gradient check: it reports no likelihood (its outputs are the NIS and the correction)
        # float32 not compared with float64: its latitude and longitude in radians resolve ~1e-7 rad (~0.6 m) in
        # float32, which moves its metre-scale innovations by up to their own size
        "loosely_coupled_filter": FilterCase(
            _ins_build, INS_INFO, fixes, samples, scan_only=True, float32_atol=None
        ),
    }


FILTERS = _filter_registry()


def drive(case, filt, state, ys, us):
    """``run_filter`` (one run or a batch), or a ``lax.scan`` of ``step`` for ``scan_only``."""
    if case.scan_only:
        return jax.lax.scan(lambda s, yu: filt.step(s, *yu), state, (ys, us))
    return jaxfdi.filters.run_filter(filt, state, ys, us)


def _run_case(case, theta, ys, dtype=jnp.float64):
    filt, state = case.build(theta, dtype)
    return drive(case, filt, state, _cast(ys, dtype), _cast(case.us, dtype))


def _leaves(info):
    return {
        jax.tree_util.keystr(path)[1:]: leaf
        for path, leaf in jax.tree_util.tree_flatten_with_path(info)[0]
    }


def _perturbed(case, rng):
    """Another run: ``case.ys`` plus noise (5 % of each channel's spread; for the INS's
    fixes, about a metre and 5 cm/s)."""
    if case.scan_only:
        fixes = case.ys
        position = fixes.position + rng.normal(size=fixes.position.shape) * np.array(
            [1e-7, 1e-7, 1.0]
        )
        return fixes._replace(
            position=position,
            velocity=fixes.velocity + 0.05 * rng.normal(size=fixes.velocity.shape),
        )
    return jnp.asarray(case.ys + 0.05 * rng.normal(size=case.ys.shape) * np.std(case.ys, axis=0))


def _steps(case):
    return jax.tree_util.tree_leaves(case.ys)[0].shape[0]


@pytest.fixture(scope="module", params=sorted(FILTERS))
def filter_case(request):
    return FILTERS[request.param]


def test_every_filter_is_finite_with_its_documented_shapes_and_jit_equals_eager(filter_case):
    case = filter_case
    eager_final, eager = _run_case(case, 1.0, case.ys)
    leaves = _leaves(eager)
    assert set(leaves) == set(case.info), "the info's leaves are not the documented ones"
    for name, (shape, kind) in case.info.items():
        leaf = leaves[name]
        assert leaf.shape == (_steps(case),) + shape, name
        assert leaf.dtype == {"f": jnp.float64, "b": jnp.bool_, "i": jnp.int32}[kind], name
    chex.assert_tree_all_finite((eager_final, eager))
    assert bool(jnp.all(leaves["healthy"]))
    chex.clear_trace_counter()  # the counter is keyed on the code location, shared by all cases

    @jax.jit
    @chex.assert_max_traces(n=1)
    def jitted_run(theta, ys):
        return _run_case(case, theta, ys)

    jitted_final, jitted = jitted_run(1.0, case.ys)
    chex.assert_trees_all_close(
        (jitted_final, jitted),
        (eager_final, eager),
        rtol=case.jit_rtol,
        atol=case.jit_rtol * _scale((eager_final, eager)),
    )
    jitted_run(0.5, _perturbed(case, np.random.default_rng(0)))  # new values, the same trace


def test_every_filter_keeps_float32(filter_case):
    """float32 in, float32 out, finite, and every float output within ``float32_atol`` (1e-3)
    of its float64 run, relative to the output's largest magnitude."""
    case = filter_case
    final, info = _run_case(case, 1.0, case.ys, jnp.float32)
    reference = _leaves(_run_case(case, 1.0, case.ys)[1])
    for name, leaf in _leaves((final, info)).items():
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert leaf.dtype == jnp.float32, name
    chex.assert_tree_all_finite((final, info))
    assert bool(jnp.all(_leaves(info)["healthy"]))
    for name, leaf in _leaves(info).items():
        if jnp.issubdtype(leaf.dtype, jnp.floating) and case.float32_atol is not None:
            scale = float(jnp.max(jnp.abs(reference[name])))
            np.testing.assert_allclose(
                leaf, reference[name], rtol=0, atol=case.float32_atol * scale, err_msg=name
            )


@pytest.mark.parametrize(
    "name", sorted(n for n, c in FILTERS.items() if not c.scan_only)
)  # INS: see its case
def test_every_filter_run_on_a_batch_equals_the_loop_over_runs(name):
    """``run_filter`` on (N, T, m) (a batch kernel, a vmap, covariances shared when the
    filter shares them) equals one run at a time."""
    case = FILTERS[name]
    ys_batch = jnp.stack([_perturbed(case, np.random.default_rng(i)) for i in range(N_RUNS)])
    filt, state = case.build(1.0, jnp.float64)
    batch = jaxfdi.filters.run_filter(filt, state, ys_batch, case.us)
    for i in range(N_RUNS):
        single = jaxfdi.filters.run_filter(filt, state, ys_batch[i], case.us)
        run_i = jax.tree_util.tree_map(
            lambda b, s: b[i] if b.shape != s.shape else b, batch, single
        )
        chex.assert_trees_all_close(run_i, single, rtol=case.rtol, atol=case.rtol * _scale(single))


def test_every_filter_vmaps_over_a_parameter_bank_and_runs(filter_case):
    case = filter_case
    thetas = jnp.asarray([0.5, 1.0, 2.0])
    ys_batch = jax.tree_util.tree_map(
        lambda *a: jnp.stack(a),
        *[_perturbed(case, np.random.default_rng(10 + i)) for i in range(3)],
    )
    batched = jax.jit(jax.vmap(lambda theta, ys: _run_case(case, theta, ys)))(thetas, ys_batch)
    one = jax.jit(lambda theta, ys: _run_case(case, theta, ys))
    for i in range(3):
        single = one(thetas[i], jax.tree_util.tree_map(lambda a: a[i], ys_batch))
        chex.assert_trees_all_close(
            jax.tree_util.tree_map(lambda a: a[i], batched),
            single,
            rtol=case.rtol,
            atol=case.rtol * _scale(single),
        )


@pytest.mark.parametrize(
    "name",
    sorted(n for n, c in FILTERS.items() if c.log_likelihood is not None and c.noise is None),
)
def test_every_likelihood_filter_has_the_finite_difference_gradient(name):
    """d/dtheta of the summed log-likelihood (theta: the measurement noise scale) by
    reverse mode equals a fourth-order central difference (rtol 1e-4); the Gaussian
    filters' gradient is checked along every symmetric Q and R direction below."""
    case = FILTERS[name]
    loss = jax.jit(lambda theta: jnp.sum(case.log_likelihood(_run_case(case, theta, case.ys)[1])))
    theta, eps = 1.0, 1e-3
    gradient = jax.grad(loss)(theta)
    along = [loss(theta + step * eps) for step in (2, 1, -1, -2)]
    difference = (-along[0] + 8 * along[1] - 8 * along[2] + along[3]) / (12 * eps)
    assert np.isfinite(float(gradient))
    np.testing.assert_allclose(float(gradient), float(difference), rtol=1e-4)


@pytest.mark.parametrize("name", sorted(n for n, c in FILTERS.items() if c.noise is not None))
def test_gaussian_filter_gradients_in_full_Q_and_R_equal_finite_differences(name):
    """Reverse- and forward-mode derivatives of the summed log-likelihood along random
    symmetric directions of Q and R (covariances must stay symmetric, so
    jax.test_util.check_grads' unstructured perturbations do not apply) equal fourth-order
    central differences, and forward equals reverse mode.

    Forward and reverse mode evaluate the same derivative in two orders, so they differ by
    rounding alone: each of the T steps' sums carries a relative error of about ``eps`` times the
    largest weight in it (``FilterCase.weight``), so the two agree to ``4 T weight eps`` of
    ``scale = sum |dL/dtheta dtheta|`` (4: the few roundings of one weighted sum). Measured:
    3e-16 of the scale for the KF and EKF (bound 1.1e-14), 7e-11 and 3e-10 for the UKFs on two
    machines (bound 1.1e-8); an error in either mode's derivative is of the order of the scale.
    """
    case = FILTERS[name]

    def total_log_likelihood(Q, R):
        filt, state = case.noise(Q, R)
        return jnp.sum(jaxfdi.filters.run_filter(filt, state, case.ys, case.us)[1].log_likelihood)

    Q, R = (jnp.asarray(a) for a in case.noise_QR)
    loss = jax.jit(total_log_likelihood)
    grad_Q, grad_R = jax.grad(loss, argnums=(0, 1))(Q, R)
    rng = np.random.default_rng(1)
    for _ in range(3):
        dQ, dR = (
            _symmetric(rng, Q.shape[0]) * jnp.diag(Q).min(),
            _symmetric(rng, R.shape[0]) * jnp.diag(R).min(),
        )
        eps = 1e-3
        along = lambda t: loss(Q + t * dQ, R + t * dR)
        finite_difference = (
            -along(2 * eps) + 8 * along(eps) - 8 * along(-eps) + along(-2 * eps)
        ) / (12 * eps)
        reverse = jnp.sum(grad_Q * dQ) + jnp.sum(grad_R * dR)
        forward = jax.jvp(loss, (Q, R), (dQ, dR))[1]
        scale = jnp.sum(jnp.abs(grad_Q * dQ)) + jnp.sum(jnp.abs(grad_R * dR))
        np.testing.assert_allclose(reverse, finite_difference, rtol=0, atol=case.fd_rtol * scale)
        rounding = 4 * len(case.ys) * case.weight * np.finfo(np.float64).eps
        np.testing.assert_allclose(forward, reverse, rtol=0, atol=rounding * scale)


def _scale(tree):
    return max(
        float(jnp.max(jnp.abs(leaf)))
        for leaf in jax.tree_util.tree_leaves(tree)
        if jnp.issubdtype(leaf.dtype, jnp.floating)
    )


def _symmetric(rng, n):
    a = rng.normal(size=(n, n))
    return jnp.asarray(0.5 * (a + a.T))
