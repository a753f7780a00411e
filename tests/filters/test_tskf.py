"""Two-stage Kalman filter: equals the Kalman filter on the augmented state [x; b]
(filterpy, float64, 1e-9) for actuator and sensor biases with constant and time-varying
distributions; the robust variant equals a NumPy augmented unbiased-minimum-variance
filter (Kitanidis 1987) and its residuals do not see the unknown input."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy import stats

import jaxfdi
from jaxfdi.filters import _tskf as tskf
from jaxfdi.models import _vtol as vtol

T = 60
P0, PB0, QB = 10.0, 10.0, 0.2**2
TOL = 1e-9


@pytest.fixture(scope="module")
def model():
    return vtol.vtol_model()


def _data(model, seed=0, bias_fn=None, d_scale=0.0, E=None):
    """Noisy VTOL data with inputs that excite every direction; an optional fault."""
    rng = np.random.default_rng(seed)
    Phi, Gamma, C = (np.asarray(a) for a in (model.Phi, model.Gamma, model.C))
    us = np.stack(
        [0.3 * np.sin(0.2 * np.arange(T)) + 1.0, 0.2 * np.cos(0.13 * np.arange(T)) - 0.5], axis=1
    )
    x = vtol.X0 * 0.1
    ys = []
    for k in range(T):
        y = C @ x + 0.1 * rng.standard_normal(4)
        if bias_fn is not None:
            y = bias_fn(k, y, x, us[k], "sensor")
        ys.append(y)
        u = us[k] if bias_fn is None else bias_fn(k, us[k], x, us[k], "actuator")
        x = Phi @ x + Gamma @ u + 0.01 * rng.standard_normal(4)
        if E is not None:
            x = x + E @ (d_scale * np.array([np.sin(0.7 * k) + 0.5 * k / T] * E.shape[1]))
    return np.array(ys), us


def _rel_err(ours, ref) -> float:
    """Largest absolute difference relative to max(1, |reference|)."""
    return float(np.max(np.abs(np.asarray(ours) - ref))) / max(1.0, float(np.max(np.abs(ref))))


def _filterpy_augmented(model, direction, ys, us, pb0=PB0):
    """Augmented-state KF with per-step F and H (filterpy), same update/predict order."""
    Phi, Gamma, C, Q, R = (
        np.asarray(a) for a in (model.Phi, model.Gamma, model.C, model.Q, model.R)
    )
    d = jax.tree_util.tree_map(np.asarray, direction)
    n, p = d.state.shape
    kf = KalmanFilter(dim_x=n + p, dim_z=4, dim_u=2)
    kf.x = np.concatenate([0.1 * vtol.X0, np.zeros(p)])
    kf.P = np.diag([P0] * n + [pb0] * p)
    kf.R = R
    kf.Q = np.block([[Q, np.zeros((n, p))], [np.zeros((p, n)), QB * np.eye(p)]])
    kf.B = np.vstack([Gamma, np.zeros((p, 2))])
    out = {k: [] for k in ("mean", "cov", "bias", "nis", "loglik", "W")}
    for k in range(T):
        y_hat = C @ kf.x[:n]
        Fs = d.output + y_hat[:, None] * d.output_scaled
        kf.H = np.hstack([C, Fs])
        kf.update(ys[k])
        out["mean"].append(kf.x[:n].copy())
        out["cov"].append(kf.P[:n, :n].copy())
        out["bias"].append(kf.x[n:].copy())
        out["nis"].append(float(kf.y @ np.linalg.solve(kf.S, kf.y)))
        out["loglik"].append(kf.log_likelihood)
        out["W"].append(R - kf.H @ kf.P @ kf.H.T)  # covariance of y - H z[k|k] (optimal gain)
        Fa = d.state + Gamma @ (d.input_scaled * us[k][:, None])
        kf.F = np.block([[Phi, Fa], [np.zeros((p, n)), np.eye(p)]])
        kf.predict(us[k])
    return {k: np.array(v) for k, v in out.items()}


def _run_tskf(model, direction, ys, us, E=None):
    filt = tskf.two_stage_kalman_filter(model, direction, QB * jnp.eye(direction.state.shape[1]), E)
    p = direction.state.shape[1]
    init = filt.init(jnp.asarray(0.1 * vtol.X0), P0 * jnp.eye(4), jnp.zeros(p), PB0 * jnp.eye(p))
    return filt, jaxfdi.filters.run_filter(filt, init, jnp.asarray(ys), jnp.asarray(us))[1]


def _effectiveness_loss(k, signal, x, u, target):
    return signal * np.array([1.0, 0.5]) if (target == "actuator" and k >= 20) else signal


def _sensor_scaling(k, signal, x, u, target):
    return signal * np.array([1.0, 1.0, 1.3, 1.0]) if (target == "sensor" and k >= 20) else signal


def _sensor_step(k, signal, x, u, target):
    return signal + np.array([0.0, 0.0, 0.7, 0.0]) if (target == "sensor" and k >= 20) else signal


def _actuator_step(k, signal, x, u, target):
    return signal - np.array([0.4, 0.0]) if (target == "actuator" and k >= 20) else signal


CASES = {
    "actuator effectiveness (Fa = -Gamma diag u)": (
        lambda m: tskf.actuator_direction(m, 1, "effectiveness"),
        _effectiveness_loss,
    ),
    "actuator additive (constant Fa)": (
        lambda m: tskf.actuator_direction(m, 0, "additive"),
        _actuator_step,
    ),
    "sensor scaling (Fs = diag C x_hat)": (
        lambda m: tskf.sensor_direction(m, 2, "scaling"),
        _sensor_scaling,
    ),
    "sensor additive (constant Fs)": (
        lambda m: tskf.sensor_direction(m, 2, "additive"),
        _sensor_step,
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_optimal_tskf_equals_augmented_kalman_filter(model, case):
    make_direction, fault = CASES[case]
    direction = make_direction(model)
    ys, us = _data(model, seed=1, bias_fn=fault)
    _, info = _run_tskf(model, direction, ys, us)
    ref = _filterpy_augmented(model, direction, ys, us)
    for name, ours in (
        ("mean", info.filtered_mean),
        ("cov", info.filtered_cov),
        ("bias", info.bias_mean),
        ("nis", info.statistic),
        ("loglik", info.log_likelihood),
    ):
        err = _rel_err(ours, ref[name])
        assert err < TOL, f"{case}: {name} differs from the augmented KF by {err:.2e}"
    assert bool(jnp.all(info.healthy))


def test_tskf_is_a_filter_and_its_bias_prior_defaults_to_a_known_zero(model):
    """``two_stage_kalman_filter`` returns a plain ``Filter``; ``init(mean, cov)`` starts the
    bias at 0 with zero covariance: the augmented KF (filterpy) with that prior."""
    direction = tskf.actuator_direction(model, 0, "additive")
    filt = tskf.two_stage_kalman_filter(model, direction, QB * jnp.eye(1))
    assert type(filt) is jaxfdi.filters.Filter and tskf.tskf_statistic_dof(model) == 4
    ys, us = _data(model, seed=4, bias_fn=_actuator_step)
    _, info = jaxfdi.filters.run_filter(
        filt, filt.init(jnp.asarray(0.1 * vtol.X0), P0 * jnp.eye(4)), ys, us
    )
    ref = _filterpy_augmented(model, direction, ys, us, pb0=0.0)
    for name, ours in (
        ("mean", info.filtered_mean),
        ("bias", info.bias_mean),
        ("nis", info.statistic),
    ):
        err = _rel_err(ours, ref[name])
        assert err < TOL, f"{name} differs from the augmented KF by {err:.2e}"
    assert bool(jnp.all(info.healthy))


def test_two_bias_directions_stack(model):
    """A bias with p = 2 (both actuators, additive) also equals the augmented KF."""
    d0, d1 = (
        tskf.actuator_direction(model, 0, "additive"),
        tskf.actuator_direction(model, 1, "additive"),
    )
    both = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b], axis=1), d0, d1)
    ys, us = _data(model, seed=2, bias_fn=_actuator_step)
    _, info = _run_tskf(model, both, ys, us)
    ref = _filterpy_augmented(model, both, ys, us)
    np.testing.assert_allclose(np.asarray(info.filtered_mean), ref["mean"], atol=TOL * 50, rtol=0)
    np.testing.assert_allclose(np.asarray(info.bias_mean), ref["bias"], atol=TOL, rtol=0)


def _umv_augmented(model, direction, E, ys, us):
    """NumPy reference: unbiased minimum-variance filter (Kitanidis 1987) on [x; b]."""
    Phi, Gamma, C, Q, R = (
        np.asarray(a) for a in (model.Phi, model.Gamma, model.C, model.Q, model.R)
    )
    d = jax.tree_util.tree_map(np.asarray, direction)
    E = np.asarray(E)
    n, p = d.state.shape
    z = np.concatenate([0.1 * vtol.X0, np.zeros(p)])
    P = np.diag([P0] * n + [PB0] * p)
    Ez = np.vstack([E, np.zeros((p, E.shape[1]))])
    Qz = np.block([[Q, np.zeros((n, p))], [np.zeros((p, n)), QB * np.eye(p)]])
    out = {k: [] for k in ("mean", "cov", "bias", "residual", "W", "stat")}
    for k in range(T):
        Fs = d.output + (C @ z[:n])[:, None] * d.output_scaled
        H = np.hstack([C, Fs])
        S = H @ P @ H.T + R
        Si = np.linalg.inv(S)
        K0 = P @ H.T @ Si
        F = H @ Ez
        K = K0 + (np.eye(n + p) - K0 @ H) @ Ez @ np.linalg.solve(F.T @ Si @ F, F.T @ Si)
        nu = ys[k] - H @ z
        z = z + K @ nu
        IKH = np.eye(n + p) - K @ H
        P = IKH @ P @ IKH.T + K @ R @ K.T
        r = ys[k] - H @ z
        W = (np.eye(4) - H @ K) @ S @ (np.eye(4) - H @ K).T
        out["mean"].append(z[:n].copy())
        out["cov"].append(P[:n, :n].copy())
        out["bias"].append(z[n:].copy())
        out["residual"].append(r)
        out["W"].append(W)
        out["stat"].append(float(r @ np.linalg.pinv(W, rcond=1e-10) @ r))
        Fa = d.state + Gamma @ (d.input_scaled * us[k][:, None])
        Phi_z = np.block([[Phi, Fa], [np.zeros((p, n)), np.eye(p)]])
        z = Phi_z @ z + np.concatenate([Gamma @ us[k], np.zeros(p)])
        P = Phi_z @ P @ Phi_z.T + Qz
    return {k: np.array(v) for k, v in out.items()}


@pytest.mark.parametrize(
    "case", ["actuator effectiveness (Fa = -Gamma diag u)", "sensor scaling (Fs = diag C x_hat)"]
)
@pytest.mark.parametrize("q", [1, 2])
def test_robust_tskf_equals_augmented_umv_filter(model, case, q):
    make_direction, fault = CASES[case]
    direction = make_direction(model)
    E = vtol.vtol_unknown_input(include_disturbance=(q == 2))
    ys, us = _data(model, seed=3, bias_fn=fault, d_scale=5.0, E=np.asarray(E))
    filt, info = _run_tskf(model, direction, ys, us, E)
    assert isinstance(filt, jaxfdi.filters.Filter) and tskf.tskf_statistic_dof(model, E) == 4 - q
    ref = _umv_augmented(model, direction, E, ys, us)
    for name, ours in (
        ("mean", info.filtered_mean),
        ("cov", info.filtered_cov),
        ("bias", info.bias_mean),
        ("residual", info.residual),
        ("W", info.residual_cov),
        ("stat", info.statistic),
    ):
        err = _rel_err(ours, ref[name])
        assert err < 1e-8, (
            f"{case}, q={q}: {name} differs from the augmented UMV filter by {err:.2e}"
        )
    # W has rank m - q: the decoupled residual lives in m - q dimensions
    ranks = np.linalg.matrix_rank(np.asarray(info.residual_cov[10:]), tol=1e-10)
    assert np.all(ranks == 4 - q)


def test_optimal_residual_covariance_is_R_minus_HPH(model):
    """Without unknown input ``W = R - H P[k|k] H^T`` (augmented H, P) and
    ``r^T W^-1 r`` equals the innovation's NIS: the paper's posterior residual carries
    the same statistic as the innovation."""
    direction = tskf.sensor_direction(model, 2, "scaling")
    ys, us = _data(model, seed=4, bias_fn=_sensor_scaling)
    _, info = _run_tskf(model, direction, ys, us)
    ref = _filterpy_augmented(model, direction, ys, us)
    W, r = np.asarray(info.residual_cov), np.asarray(info.residual)
    np.testing.assert_allclose(W, ref["W"], atol=1e-11, rtol=0)
    quad = np.einsum("ti,tij,tj->t", r, np.linalg.inv(W), r)
    np.testing.assert_allclose(quad, ref["nis"], rtol=1e-8)


@pytest.fixture(scope="module")
def unknown_input_runs(model):
    """Monte Carlo: 200 runs of the plant with a large unknown input E d, d x1 and x100,
    robust TSKF (q = 1) and the optimal TSKF (blind to d) on the same noise."""
    E = vtol.vtol_unknown_input()
    direction = tskf.actuator_direction(model, 0, "effectiveness")
    robust = tskf.two_stage_kalman_filter(model, direction, QB * jnp.eye(1), E)
    plain = tskf.two_stage_kalman_filter(model, direction, QB * jnp.eye(1))
    us = jnp.stack([jnp.ones(T), -0.5 * jnp.ones(T)], axis=1)
    ks = jnp.arange(T)

    def simulate(key, scale):
        """Exactly the filters' hypothesis: x0 ~ N(m0, P0 I), b a random walk from
        N(0, Pb0) entering as an effectiveness loss of input 0, plus E d."""
        kx, kb, kw, kv, kwb = jax.random.split(key, 5)
        x0 = 0.1 * vtol.X0 + np.sqrt(P0) * jax.random.normal(kx, (4,))
        b0 = np.sqrt(PB0) * jax.random.normal(kb, ())
        w = 0.01 * jax.random.normal(kw, (T, 4))
        wb = np.sqrt(QB) * jax.random.normal(kwb, (T,))
        v = 0.1 * jax.random.normal(kv, (T, 4))
        d = scale * (jnp.sin(0.7 * ks) + 0.3)

        def body(carry, inputs):
            x, b = carry
            u, w_k, wb_k, v_k, d_k = inputs
            y = model.C @ x + v_k
            x_next = (
                model.Phi @ x + model.Gamma @ u - model.Gamma[:, 0] * u[0] * b + E[:, 0] * d_k + w_k
            )
            return (x_next, b + wb_k), y

        return jax.lax.scan(body, (x0, b0), (us, w, wb, v, d))[1]

    def run(filt, ys):
        init = filt.init(
            jnp.asarray(0.1 * vtol.X0), P0 * jnp.eye(4), jnp.zeros(1), PB0 * jnp.eye(1)
        )
        return jaxfdi.filters.run_filter(filt, init, ys, us)[1].statistic

    scales = (0.0, 1.0, 100.0)

    @jax.jit
    def study(keys):
        ys = jax.vmap(lambda s: jax.vmap(simulate, (0, None))(keys, s))(jnp.asarray(scales))
        ys = ys.reshape((-1,) + ys.shape[2:])
        return jax.vmap(lambda y: run(robust, y))(ys), jax.vmap(lambda y: run(plain, y))(ys)

    robust_stat, plain_stat = (
        np.asarray(a).reshape(len(scales), -1, T)
        for a in study(jax.random.split(jax.random.key(7), 200))
    )
    out = {("robust", s): robust_stat[i] for i, s in enumerate(scales)}
    return out | {("plain", s): plain_stat[i] for i, s in enumerate(scales)}


def test_robust_residuals_do_not_see_the_unknown_input(unknown_input_runs):
    runs = unknown_input_runs
    # the unknown input enters exactly along E: the decoupled statistic is unchanged
    np.testing.assert_allclose(runs[("robust", 100.0)], runs[("robust", 1.0)], rtol=1e-6, atol=1e-6)
    # ... and is chi2(m - q) = chi2(3) (KS over 200 runs x 60 steps)
    sample = runs[("robust", 100.0)].ravel()
    assert stats.kstest(sample, stats.chi2(3).cdf).pvalue > 1e-3
    # the optimal TSKF, blind to d, is not: its statistic grows by orders of magnitude
    assert runs[("plain", 100.0)][:, 10:].mean() > 100 * runs[("plain", 1.0)][:, 10:].mean()


def test_optimal_statistic_is_chi2_under_its_hypothesis(unknown_input_runs):
    """No unknown input: the optimal TSKF's lambda ~ chi2(m = 4) (KS, 200 runs x 60 steps)."""
    sample = unknown_input_runs[("plain", 0.0)].ravel()
    assert stats.kstest(sample, stats.chi2(4).cdf).pvalue > 1e-3


def test_decoupling_conditions_are_checked(model):
    direction = tskf.actuator_direction(model, 0)
    with pytest.raises(ValueError, match="full column rank"):
        tskf.two_stage_kalman_filter(model, direction, QB * jnp.eye(1), jnp.zeros((4, 1)))
    blind = model._replace(C=jnp.array([[1.0, 0, 0, 0]]), D=jnp.zeros((1, 2)), R=jnp.eye(1))
    with pytest.raises(ValueError, match=r"rank\(C E\)"):
        tskf.two_stage_kalman_filter(
            blind,
            tskf.actuator_direction(blind, 0),
            QB * jnp.eye(1),
            jnp.array([[0.0], [1.0], [0.0], [0.0]]),
        )
    with pytest.raises(ValueError, match="q = 2 unknown inputs"):
        tskf.two_stage_kalman_filter(
            blind, tskf.actuator_direction(blind, 0), QB * jnp.eye(1), jnp.eye(4)[:, :2]
        )
    with pytest.raises(ValueError, match="bias_walk"):
        tskf.two_stage_kalman_filter(model, direction, jnp.eye(2))
    with pytest.raises(ValueError, match="component"):
        tskf.sensor_direction(model, 4)


def test_bank_is_the_filters_side_by_side(model):
    """The vmapped bank (robust, q = 1): each filter equals the NumPy augmented UMV
    reference for its own fault direction."""
    E = vtol.vtol_unknown_input()
    directions = [tskf.actuator_direction(model, i) for i in range(2)] + [
        tskf.sensor_direction(model, j) for j in range(4)
    ]
    ys, us = _data(model, seed=5, bias_fn=_sensor_step)
    bank = tskf.run_tskf_bank(
        model,
        tskf.stack_directions(directions),
        QB * jnp.eye(1),
        jnp.asarray(0.1 * vtol.X0),
        P0 * jnp.eye(4),
        PB0 * jnp.eye(1),
        jnp.asarray(ys),
        jnp.asarray(us),
        E,
    )
    assert bank.statistic.shape == (6, T)
    for i, direction in enumerate(directions):
        ref = _umv_augmented(model, direction, E, ys, us)
        assert _rel_err(bank.statistic[i], ref["stat"]) < 1e-8
        assert _rel_err(bank.bias_mean[i], ref["bias"]) < 1e-8
        assert _rel_err(bank.filtered_mean[i], ref["mean"]) < 1e-8
    # an s3 step (0.7 from k = 20): the s3 scaling filter absorbs it as a gain error, so
    # its statistic stays lowest while the other five rise
    late = np.asarray(bank.statistic[:, 30:]).mean(axis=1)
    assert np.argmin(late) == 4, late
    with pytest.raises(ValueError, match="stack_directions"):
        tskf.run_tskf_bank(
            model, directions[0], QB * jnp.eye(1), jnp.zeros(4), jnp.eye(4), jnp.eye(1), ys, us
        )
