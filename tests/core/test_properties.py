"""Property-based checks of the public API on malformed inputs (issue 37 item 5).

Random inputs drawn by hypothesis (derandomised: the same examples on every run, so CI
is reproducible). The property everywhere: a clear error naming the argument, or a
flagged output (an alarm, ``nis = +inf``, a NaN innovation on the dead channel), never
a finite wrong answer and never a silent NaN.

===========================  ==============================================================
module                       classes of input tried
===========================  ==============================================================
``filters``: KF, EKF, UKF,   measurements with NaN, +inf, -inf and finite values in any
square-root KF and UKF,      component (with and without ``missing_measurements``); of
unknown-input filter         the wrong shape, empty, scalar or complex
``detection.chi2``           NIS streams with NaN/inf anywhere; ``chi2_threshold`` with
                             dof and pfa anywhere on the real line, NaN and inf
``detection.glrt``           innovations with NaN/inf in any components of any steps
``detection.parity``         redundant measurements with NaN/inf in any channels
``detection.frozen``         sigma with zeros, negatives, NaN, inf, wrong shapes; data with
                             dead samples anywhere
``faults.fault``             kinds, targets, negative or float components and onsets,
                             non-finite magnitudes, effectiveness outside [0, 1]
===========================  ==============================================================
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from jaxfdi import fault, steady_state_kalman
from jaxfdi.detection import _parity as ps
from jaxfdi.detection import chi2_detector, chi2_threshold, frozen_channel_detector, glrt_detector
from jaxfdi.filters import (
    extended_kalman_filter,
    kalman_filter,
    sqrt_kalman_filter,
    sqrt_unscented_kalman_filter,
    unknown_input_filter,
    unscented_kalman_filter,
)
from jaxfdi.models import LinearGaussianModel, engine_model

SETTINGS = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
#: any float, the bad ones often
ANY = st.one_of(st.floats(-1e3, 1e3), st.sampled_from([np.nan, np.inf, -np.inf]))

MODEL = LinearGaussianModel(
    Phi=jnp.array([[1.0, 0.1], [0.0, 0.95]]),
    Gamma=jnp.zeros((2, 0)),
    C=jnp.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
    D=jnp.zeros((3, 0)),
    Q=0.01 * jnp.eye(2),
    R=0.1 * jnp.eye(3),
)


#: reaches sensors 0 and 2 only: with both missing, nothing left is free of d
UNKNOWN_INPUT = jnp.array([[1.0], [0.0]])


def _filters():
    """One jitted step of each filter from the same prior: ``y -> info``."""
    f, h = (lambda x, u, p: MODEL.Phi @ x), (lambda x, u, p: MODEL.C @ x)
    filters = {
        "kf": kalman_filter(MODEL),
        "kf missing": kalman_filter(MODEL, missing_measurements=True),
        "ekf": extended_kalman_filter(f, h, MODEL.Q, MODEL.R),
        "ukf": unscented_kalman_filter(f, h, MODEL.Q, MODEL.R),
        "sqrt kf": sqrt_kalman_filter(MODEL),
        "sqrt ukf": sqrt_unscented_kalman_filter(f, h, MODEL.Q, MODEL.R),
        "unknown input": unknown_input_filter(MODEL, UNKNOWN_INPUT),
        "unknown input missing": unknown_input_filter(
            MODEL, UNKNOWN_INPUT, missing_measurements=True
        ),
    }

    def stepper(f):
        prior = f.init(jnp.array([0.3, -0.2]), jnp.eye(2))
        return jax.jit(lambda y: f.step(prior, y, jnp.zeros(0))[1])

    return {name: stepper(f) for name, f in filters.items()}


STEPS = _filters()


@SETTINGS
@given(y=hnp.arrays(np.float64, (3,), elements=ANY), name=st.sampled_from(sorted(STEPS)))
def test_a_filter_step_reports_every_dead_component_and_keeps_its_state(y, name):
    info = STEPS[name](jnp.asarray(y))
    dead = np.isinf(y) if name.endswith("missing") else ~np.isfinite(y)
    assert bool(info.healthy)
    assert np.all(np.isfinite(np.asarray(info.filtered_mean))) and np.all(
        np.isfinite(np.asarray(info.filtered_cov))
    )
    np.testing.assert_array_equal(np.isnan(np.asarray(info.innovation)), dead)
    assert (float(info.nis) == np.inf) == bool(dead.any())
    assert not np.isnan(float(info.nis)) and np.isfinite(float(info.log_likelihood))


#: measurements of the wrong shape (empty included) or dtype: refused at trace time, naming ``y``
WRONG_Y = st.one_of(
    hnp.arrays(
        np.float64,
        st.sampled_from([(0,), (2,), (4,), (3, 1), (1, 3), ()]),
        elements=st.floats(-1.0, 1.0),
    ),
    hnp.arrays(np.complex128, (3,), elements=st.complex_numbers(max_magnitude=1.0)),
)  # (bool is real 0/1 for the library's checks: checks.check_real)
FILTERS = {
    "kf": kalman_filter(MODEL),
    "kf missing": kalman_filter(MODEL, missing_measurements=True),
    "sqrt kf": sqrt_kalman_filter(MODEL),
    "unknown input": unknown_input_filter(MODEL, UNKNOWN_INPUT),
    "ukf": unscented_kalman_filter(
        lambda x, u, p: MODEL.Phi @ x, lambda x, u, p: MODEL.C @ x, MODEL.Q, MODEL.R
    ),
}


@SETTINGS
@given(y=WRONG_Y, name=st.sampled_from(sorted(FILTERS)))
def test_a_filter_step_refuses_a_measurement_of_the_wrong_shape_or_dtype_by_name(y, name):
    filt = FILTERS[name]
    prior = filt.init(jnp.array([0.3, -0.2]), jnp.eye(2))
    with pytest.raises((ValueError, TypeError), match=r"^y\b"):
        filt.step(prior, jnp.asarray(y), jnp.zeros(0))


def test_an_unknown_input_filter_that_loses_decoupling_keeps_its_prediction():
    """Sensors 0 and 2 (the only ones the unknown input reaches) missing or dead: the
    update keeps the prior exactly, statistic 0 at 0 degrees of freedom, healthy; with
    one of them back, it updates again (the Kitanidis gain on the sensors left)."""
    filt = unknown_input_filter(MODEL, UNKNOWN_INPUT, missing_measurements=True)
    prior = filt.init(jnp.array([0.3, -0.2]), jnp.eye(2))
    for y in ([np.nan, 1.0, np.nan], [np.inf, 1.0, np.nan]):
        post = filt.update(prior, jnp.asarray(y), jnp.zeros(0))
        np.testing.assert_array_equal(np.asarray(post.filtered_mean), np.asarray(prior.mean))
        np.testing.assert_array_equal(np.asarray(post.filtered_cov), np.asarray(prior.cov))
        assert bool(post.healthy) and int(post.num_observed) == 0
        assert float(post.nis) == (np.inf if np.isinf(y[0]) else 0.0)
    post = filt.update(prior, jnp.asarray([np.nan, 1.0, 0.4]), jnp.zeros(0))
    assert bool(post.healthy) and not np.allclose(
        np.asarray(post.filtered_mean), np.asarray(prior.mean)
    )
    assert int(post.num_observed) == 1


@SETTINGS
@given(
    nis=hnp.arrays(
        np.float64,
        (12,),
        elements=st.one_of(st.floats(0.0, 50.0), st.sampled_from([np.nan, np.inf])),
    ),
    window=st.integers(1, 5),
)
def test_a_chi2_window_alarms_while_it_holds_a_bad_value_and_is_the_sum_otherwise(nis, window):
    detector = chi2_detector(1e9, window)
    _, decision = jax.lax.scan(detector.step, detector.init(), jnp.asarray(nis))
    for k in range(nis.size):
        held = nis[max(0, k - window + 1) : k + 1]
        if np.all(np.isfinite(held)):
            assert not bool(decision.alarm[k])
            assert float(decision.statistic[k]) == pytest.approx(held.sum(), rel=1e-12, abs=1e-12)
        else:
            assert bool(decision.alarm[k]) and float(decision.statistic[k]) == np.inf


@SETTINGS
@given(
    dof=st.one_of(st.floats(-5.0, 200.0), st.sampled_from([np.nan, np.inf, 0.0])),
    pfa=st.one_of(st.floats(-0.5, 1.5), st.sampled_from([np.nan, np.inf, 1e-300, 0.0, 1.0])),
)
def test_chi2_threshold_is_scipys_or_names_the_bad_argument(dof, pfa):
    try:
        value = float(chi2_threshold(dof, pfa))
    except ValueError as error:
        assert str(error).startswith(("dof:", "pfa:")), error
        return
    assert 0 < dof < np.inf and 0 < pfa < 1
    np.testing.assert_allclose(value, scipy.stats.chi2.isf(pfa, dof), rtol=1e-8)


ENGINE = engine_model()
STEADY = steady_state_kalman(ENGINE)
GLRT = glrt_detector(ENGINE, STEADY.gain, STEADY.innovation_cov, 4, 30.0)
GLRT_RUN = jax.jit(lambda e: jax.lax.scan(GLRT.step, GLRT.init(), e)[1])


@SETTINGS
@given(
    innovations=hnp.arrays(
        np.float64,
        (8, 5),
        elements=st.one_of(st.floats(-1.0, 1.0), st.sampled_from([np.nan, np.inf, -np.inf])),
    )
)
def test_the_glrt_alarms_on_every_step_with_a_dead_channel_and_names_the_first(innovations):
    decision = GLRT_RUN(jnp.asarray(innovations))
    for k, row in enumerate(innovations):
        dead = ~np.isfinite(row)
        if dead.any():
            assert bool(decision.alarm[k]) and float(decision.statistic[k]) == np.inf
            assert int(decision.label[k]) == 1 + 1 + int(
                np.argmax(dead)
            )  # nu = 1, then the sensors
        else:
            assert np.isfinite(float(decision.statistic[k]))


SPACE = ps.parity_space(
    jnp.asarray(np.random.default_rng(4).normal(size=(6, 3))), jnp.asarray([[0, 1], [2, 3], [4, 5]])
)
PARITY = jax.jit(lambda m: ps.parity_tests(SPACE, m))


@SETTINGS
@given(measurement=hnp.arrays(np.float64, (6,), elements=ANY))
def test_parity_tests_name_exactly_the_dead_groups(measurement):
    fd, fi = (np.asarray(a) for a in PARITY(jnp.asarray(measurement)))
    dead_groups = ~np.isfinite(measurement).reshape(3, 2).all(axis=1)
    if dead_groups.any():
        assert float(fd) == np.inf and np.array_equal(fi, dead_groups.astype(float))
    else:
        assert np.isfinite(float(fd)) and np.all((fi >= -1e-12) & (fi <= 1 + 1e-12))


@SETTINGS
@given(
    sigma=st.one_of(
        hnp.arrays(np.float64, (2,), elements=ANY),
        hnp.arrays(np.float64, st.sampled_from([(), (2, 1)]), elements=st.floats(0.1, 2.0)),
    ),
    data=hnp.arrays(
        np.float64, (10, 2), elements=st.one_of(st.floats(-5.0, 5.0), st.sampled_from([np.nan]))
    ),
)
def test_the_frozen_test_refuses_a_bad_sigma_and_never_reports_nan(sigma, data):
    try:
        detector = frozen_channel_detector(sigma, 4, 0.01, jnp.array([1, 2]))
    except ValueError as error:
        assert str(error).startswith("sigma:"), error
        assert sigma.shape != (2,) or not np.all(np.isfinite(sigma) & (sigma > 0))
        return
    assert sigma.shape == (2,) and np.all(np.isfinite(sigma) & (sigma > 0))
    _, decision = jax.lax.scan(detector.step, detector.init(), jnp.asarray(data))
    assert not np.any(np.isnan(np.asarray(decision.statistic)))
    dead_steps = ~np.isfinite(data).all(axis=1)
    assert np.all(np.asarray(decision.alarm)[dead_steps])


@SETTINGS
@given(
    kind=st.sampled_from(["bias", "ramp", "stuck", "dead", "effectiveness", "scale"]),
    target=st.sampled_from(["actuator", "sensor"]),
    component=st.one_of(st.integers(-2, 4), st.floats(0.0, 3.0)),
    onset=st.one_of(st.integers(-5, 50), st.just(2.5)),
    magnitude=st.one_of(st.floats(-2.0, 2.0), st.sampled_from([np.nan, np.inf])),
)
def test_a_fault_is_built_or_refused_by_name(kind, target, component, onset, magnitude):
    try:
        f = fault(kind, target, component, onset, magnitude)
    except (ValueError, TypeError) as error:
        assert str(error).split(":")[0] in ("kind", "component", "onset", "magnitude"), error
        return
    assert int(f.component) >= 0 and int(f.onset) >= 0 and np.isfinite(float(f.magnitude))
    assert not (kind == "dead" and target == "actuator")
    assert not (kind == "effectiveness" and not 0.0 <= magnitude <= 1.0)


# --- argument classes of "no wrong answer without a flag": thresholds, index groups, units, horizons ---------------


@SETTINGS
@given(threshold=ANY, window=st.integers(1, 4))
def test_a_chi2_threshold_below_zero_is_refused_by_name(threshold, window):
    """The windowed NIS sum is never negative: a negative threshold would alarm at every step."""
    try:
        chi2_detector(threshold, window)
    except ValueError as error:
        assert str(error).startswith("threshold:") and ">= 0" in str(error), error
        assert not (np.isfinite(threshold) and threshold >= 0)
        return
    assert np.isfinite(threshold) and threshold >= 0


GROUPS = hnp.arrays(
    np.int64, st.tuples(st.integers(1, 4), st.integers(1, 2)), elements=st.integers(-1, 7)
)


@SETTINGS
@given(groups=GROUPS)
def test_sensor_groups_out_of_range_or_overlapping_are_refused_by_name(groups):
    """Six channels: a group naming channel 6, a negative one, or a channel twice is refused by the parity space and
    by the configuration geometry alike; any other grouping is computed."""
    from jaxfdi.detection import isolability, parity_space

    H = np.array(
        [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 1.0],
            [1.0, 0.0, 1.0],
        ]
    )
    good = bool(np.all((groups >= 0) & (groups < 6)) and len(np.unique(groups)) == groups.size)
    for build in (lambda: parity_space(H, groups), lambda: isolability(H, groups)):
        try:
            build()
        except ValueError as error:
            assert str(error).startswith("groups:"), error
            continue
        assert good


@SETTINGS
@given(lat=st.floats(-100.0, 100.0), lon=st.floats(-400.0, 400.0))
def test_an_angle_in_degrees_where_radians_are_expected_is_refused_with_the_unit(lat, lon):
    """Latitude and longitude in radians: a value in degrees (37.57) is refused naming the argument and the unit; a
    value in range gives a point on the ellipsoid."""
    from jaxfdi.gnss import geodetic_to_ecef

    try:
        xyz = np.asarray(geodetic_to_ecef(lat, lon, 0.0))
    except ValueError as error:
        name = str(error).split(":")[0]
        assert name in ("lat", "lon") and "radians" in str(error), error
        assert abs(lat) > np.pi / 2 or abs(lon) > 2 * np.pi
        return
    assert abs(lat) <= np.pi / 2 and abs(lon) <= 2 * np.pi
    assert 6356752.0 - 1.0 <= np.linalg.norm(xyz) <= 6378137.0 + 1.0


@SETTINGS
@given(mask=st.floats(-100.0, 100.0))
def test_an_elevation_mask_outside_radians_is_refused_with_the_unit(mask):
    """A 5 deg mask passed as 5 is refused by every path that takes a mask, with its value in radians."""
    from jaxfdi.gnss import availability_grid
    from jaxfdi.gnss._measurements import check_mask_angle

    try:
        check_mask_angle(mask)
    except ValueError as error:
        assert str(error).startswith("mask_angle:") and "radians" in str(error), error
        assert abs(mask) > np.pi / 2
        with pytest.raises(ValueError, match="mask_angle: expected an elevation mask in radians"):
            availability_grid(None, np.zeros(1), np.zeros((1, 3)), None, mask, None)
        return
    assert abs(mask) <= np.pi / 2


@SETTINGS
@given(components=hnp.arrays(np.int64, st.integers(1, 4), elements=st.integers(0, 3)))
def test_a_fault_group_names_each_component_once(components):
    """A component given twice would be faulted twice: refused by name; distinct components build the group."""
    from jaxfdi import fault_group

    try:
        group = fault_group("bias", "sensor", components, 10, 0.5)
    except ValueError as error:
        assert str(error).startswith("components:") and "once" in str(error), error
        assert len(np.unique(components)) < components.size
        return
    assert np.array_equal(np.asarray(group.component), components)


@SETTINGS
@given(parity=hnp.arrays(np.float64, (4,), elements=ANY), valid=hnp.arrays(bool, (4,)))
def test_a_parity_statistic_with_a_dead_entry_is_inf_never_nan(parity, valid):
    """A non-finite entry among the valid ones is evidence (+inf, alarms at any threshold); the others are left out;
    otherwise the statistic is the sum of squares."""
    from jaxfdi.detection import parity_statistic

    value = float(parity_statistic(parity, valid))
    used = parity[valid]
    if np.all(np.isfinite(used)):
        assert value == pytest.approx(float(np.sum(used**2)), rel=1e-12, abs=0.0)
    else:
        assert value == np.inf


@SETTINGS
@given(steps=st.integers(1, 40), horizon=st.integers(1, 30))
def test_a_plant_is_never_run_past_its_tables(steps, horizon):
    """A simulator replaying ``horizon`` steps of tables refuses a run of more steps, naming ``steps``; shorter runs
    run."""
    import jaxfdi

    sim = jaxfdi.linear_simulator(MODEL)._replace(horizon=horizon)
    kf = kalman_filter(MODEL)
    args = (chi2_detector(9.0), jnp.zeros(2), kf.init(jnp.zeros(2), jnp.eye(2)))
    try:
        out = jaxfdi.monitor(sim, kf, *args, jnp.zeros((steps, 0)), jax.random.key(0), 5)
    except ValueError as error:
        assert str(error).startswith("steps:") and f"plant's {horizon} steps" in str(error), error
        assert steps > horizon
        return
    assert steps <= horizon and int(out.record.onset) == 5
