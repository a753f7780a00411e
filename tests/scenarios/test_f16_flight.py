"""Seed 000's closed-loop F-16 flight: followed, stabilised, float32 = float64.

One compiled flight (4 flights vmapped, with history) serves every test: the setups
differ only in their arrays (noise, gains, reference), not in their shapes.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxfdi.control import LATERAL_TRACKED, LONGITUDINAL_TRACKED, flight_plan, integral_augmentation
from jaxfdi.models.f16 import (
    ALPHA,
    BETA,
    LATERAL_STATES,
    LONGITUDINAL_DESIGN_STATES,
    PHI,
    THETA,
    VT,
    H,
    Q,
    f16_sensors,
    submodel,
)
from jaxfdi.models.f16._linearize import longitudinal
from jaxfdi.scenarios.f16_flight import (
    ERRORS,
    cast_setup,
    dispersions,
    flight_setup,
    nominal_dispersion,
    run_flights,
)

FLIGHTS = 4
FLY = jax.jit(run_flights, static_argnums=3)


def _quiet(setup):
    """The same setup without sensor noise and gusts."""
    zero = jax.tree_util.tree_map(lambda a: 0.0 * a, setup.sensors)._replace(
        rate_axes=setup.sensors.rate_axes
    )
    return setup._replace(sensors=zero, gust_sigma=0.0 * setup.gust_sigma)


@pytest.fixture(scope="module")
def flight():
    setup, design = flight_setup(gust_sigma=3.0)
    keys = jax.random.split(jax.random.key(7), FLIGHTS)
    disp = dispersions(jax.random.key(8), setup, FLIGHTS)
    out, hist = FLY(setup, keys, disp, True)
    return setup, design, keys, disp, out, jax.tree_util.tree_map(np.asarray, hist)


def test_paper_flight_is_followed(flight):
    """Climb at 120 ft/s for 0-5 s, then altitude hold and a 30 deg bank turn to 15 s,
    with sensor noise (0.01 rad/s rate channels), 3 ft/s gusts, c.g. in 0.33-0.37 and
    initial offsets: altitude within 15 ft of the command throughout and 12 ft in the
    hold, bank within 1 deg once rolled in, sideslip under 1 deg."""
    setup, design, _, _, out, hist = flight
    assert bool(jnp.all(out.healthy))
    t = np.arange(hist.state.shape[1]) * 0.01
    h_cmd, phi_cmd = (
        np.asarray(setup.reference.state[:, H]),
        np.asarray(setup.reference.state[:, PHI]),
    )
    h_err = hist.state[:, :, H] - h_cmd
    bank_err = np.degrees(hist.state[:, :, PHI] - phi_cmd)
    climb, hold, banked = t < 3.0, t >= 7.0, t >= 7.0
    assert np.max(np.abs(h_err)) < 15.0
    assert np.max(np.abs(h_err[:, hold])) < 12.0
    assert np.max(np.abs(bank_err[:, banked])) < 1.0
    assert np.max(np.abs(np.degrees(hist.state[:, :, BETA]))) < 1.0
    # the climb is at 120 ft/s: 360 ft in the first 3 s, then 600 ft in all
    np.testing.assert_allclose(h_cmd[300] - h_cmd[0], 360.0, atol=1e-9)
    np.testing.assert_allclose(h_cmd[-1] - h_cmd[0], 600.0, atol=1e-6)
    assert np.max(np.abs(h_err[:, climb])) < 5.0
    assert np.all(np.abs(hist.state[:, -1, H] - 600.0) < 10.0)
    assert np.degrees(phi_cmd[-1]) == pytest.approx(30.0)
    # the run's tracking score (folded inside the scan) equals the errors of the history
    score = jax.tree_util.tree_map(np.asarray, out.tracking)
    index = {name: i for i, name in enumerate(ERRORS)}
    np.testing.assert_allclose(
        score.max_abs[:, index["altitude_ft"]], np.max(np.abs(h_err), axis=1), rtol=1e-12
    )
    np.testing.assert_allclose(
        score.max_abs[:, index["bank_hold_deg"]],
        np.max(np.abs(bank_err[:, banked]), axis=1),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        score.sum_sq[:, index["altitude_hold_ft"]], np.sum(h_err[:, hold] ** 2, axis=1), rtol=1e-10
    )
    assert np.all(score.count[:, index["altitude_climb_ft"]] == np.count_nonzero(climb))


def test_sas_stabilises_the_unstable_mode(flight):
    """At the design trim (502 ft/s, sea level, xcg 0.35) the open loop has a real root
    near +0.1 1/s (mostly pitch attitude and airspeed); the LQR loops put every
    closed-loop eigenvalue inside the unit circle (checked here with SciPy's expm and
    NumPy's eig). In the nonlinear aircraft a start along that mode grows at its rate with
    the trim controls held and dies out with the SAS."""
    setup, design, keys, _, _, _ = flight
    A_lon, _ = longitudinal(design.linear)
    assert np.max(np.linalg.eigvals(np.asarray(A_lon)).real) > 0.05
    for states, inputs, tracked, gain in (
        (
            LONGITUDINAL_DESIGN_STATES,
            (0, 1),
            LONGITUDINAL_TRACKED,
            design.design.gains.longitudinal,
        ),
        (LATERAL_STATES, (2, 3), LATERAL_TRACKED, design.design.gains.lateral),
    ):
        A, B = (np.asarray(m) for m in submodel(design.linear, states, inputs))
        n, m = B.shape
        block = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * 0.01)
        A_bar, B_bar, _ = integral_augmentation(
            block[:n, :n], block[:n, n:], np.eye(n)[list(tracked)], 0.01
        )
        radius = np.max(
            np.abs(np.linalg.eigvals(np.asarray(A_bar) - np.asarray(B_bar) @ np.asarray(gain)))
        )
        assert radius < 0.999
    # nonlinear: level flight at the design trim, started 2 ft/s off along the unstable
    # mode's eigenvector, no noise or gusts; trim controls held (zero gains) or the SAS
    values, vectors = np.linalg.eig(np.asarray(A_lon))
    mode = vectors[:, np.argmax(values.real)].real
    growth = float(np.max(values.real))
    offset = jnp.zeros(13).at[jnp.array([VT, ALPHA, THETA, Q])].set(-2.0 * mode / mode[0])
    level, _ = flight_setup(plan=flight_plan(climb_rate=0.0, bank_angle_deg=0.0, level_off=2.0))
    level = _quiet(level)
    start = nominal_dispersion(level, FLIGHTS)._replace(initial=jnp.tile(offset, (FLIGHTS, 1)))
    _, with_sas = FLY(level, keys, start, True)
    _, held = FLY(
        level._replace(gains=jax.tree_util.tree_map(jnp.zeros_like, level.gains)), keys, start, True
    )
    assert np.all(
        np.asarray(held.control[0]) == np.asarray(level.u0)
    )  # the open loop holds the trim controls
    dv_open = np.asarray(held.state[0, :, VT]) - float(level.x0[VT])
    dv_sas = np.asarray(with_sas.state[0, :, VT]) - float(level.x0[VT])
    # open loop: the airspeed error grows at the linear model's rate (from 5 s to 15 s, 2.7x)
    rate = math.log(dv_open[-1] / dv_open[500]) / (0.01 * (len(dv_open) - 1 - 500))
    assert rate == pytest.approx(growth, rel=0.1) and dv_open[-1] < -5.0
    # with the SAS it is gone, and so is the attitude and altitude disturbance
    assert np.max(np.abs(dv_sas[-200:])) < 0.2
    assert (
        np.max(
            np.abs(np.degrees(np.asarray(with_sas.state[0, -200:, THETA]) - float(level.x0[THETA])))
        )
        < 0.05
    )
    assert abs(float(with_sas.state[0, -1, H])) < 2.0


def test_float32_and_float64_flights_agree(flight):
    """The 15 s flight (noise and gusts off, four dispersed flights) in float32 with the
    float64 design cast: within 0.01 ft/s, 0.05 ft altitude, 1 ft of position, 5e-4 deg of
    attitude and 1e-3 deg/s of rates of the float64 flight (measured: 6e-4 ft/s, 7e-4 ft,
    5e-3 ft, 8e-5 deg, 2e-4 deg/s)."""
    setup, _, keys, disp, _, _ = flight
    quiet = _quiet(setup)
    _, h64 = FLY(quiet, keys, disp, True)
    _, h32 = FLY(
        cast_setup(quiet, jnp.float32),
        keys,
        jax.tree_util.tree_map(lambda a: a.astype(jnp.float32), disp),
        True,
    )
    assert h32.state.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(h32.state)))
    x64, x32 = np.asarray(h64.state), np.asarray(h32.state, np.float64)
    diff = np.max(np.abs(x64 - x32), axis=(0, 1))
    assert diff[VT] < 0.01 and diff[H] < 0.05 and max(diff[9], diff[10]) < 1.0
    assert np.degrees(np.max(diff[1:6])) < 5e-4 and np.degrees(np.max(diff[6:9])) < 1e-3
    assert np.max(np.abs(np.asarray(h64.control) - np.asarray(h32.control))) < 1e-3


def test_bad_input():
    with pytest.raises(ValueError, match="climb_rate"):
        flight_plan(airspeed=100.0, climb_rate=120.0)
    with pytest.raises(ValueError, match="level_off"):
        flight_plan(level_off=12.0)
    with pytest.raises(ValueError, match="rate_axes"):
        f16_sensors(rate_axes=np.ones((6, 2)))


def test_plant_noise_and_faults(flight):
    """The sampled plant's sensor noise has the stated standard deviations (4000 draws,
    sample std within 5 %: its standard error is 1.1 %), a sensor bias on both axes of
    rate sensor 1 (seed 000's fault) appears in ``y`` from its onset on, and a stuck
    elevator takes the value commanded at its onset (``faults`` holds it afterwards)."""
    from jaxfdi import concat_faults, fault, fault_group
    from jaxfdi.control import f16_plant
    from jaxfdi.models.f16 import RATE_OFFSET, measurement_cov

    setup = flight[0]
    bias = fault_group("bias", "sensor", (RATE_OFFSET, RATE_OFFSET + 1), 300, (0.1, 0.1))
    stuck = fault("stuck", "actuator", 1, 300)
    plant = f16_plant(setup.params, setup.sensors, gust_sigma=3.0, fault=concat_faults(bias, stuck))
    x0 = jnp.concatenate([setup.x0, jnp.zeros(2)])

    @jax.jit
    def step(key, k, u):
        state, sensed = plant.measure(plant.init(x0), k, u, key)
        _, moved = plant.advance(state, k, u, key)
        return sensed, moved

    keys = jax.random.split(jax.random.key(3), 4000)
    sensed, _ = jax.vmap(lambda key: step(key, 10, setup.u0))(keys)
    noise = np.asarray(sensed.measurement - sensed.measurement.mean(axis=0))
    sigma = np.sqrt(np.diag(np.asarray(measurement_cov(setup.sensors))))
    np.testing.assert_allclose(noise.std(axis=0), sigma, rtol=0.05)
    before, moved_before = step(keys[0], 299, setup.u0)
    after, moved_after = step(keys[0], 300, setup.u0 + 1.0)
    assert not np.any(np.asarray(before.sensor_fault)) and not np.any(
        np.asarray(before.fault_active)
    )
    np.testing.assert_allclose(after.sensor_fault[RATE_OFFSET : RATE_OFFSET + 2], [0.1, 0.1])
    assert np.count_nonzero(np.asarray(after.sensor_fault)) == 2 and bool(after.fault_active.all())
    assert float(moved_before.applied_input[1]) == float(setup.u0[1])
    assert float(moved_after.applied_input[1]) == pytest.approx(float(setup.u0[1]) + 1.0)
    with pytest.raises(ValueError, match="x0"):
        plant.init(jnp.zeros(13))
