"""Strapdown INS (seed 002, INS half): the Earth model against published WGS-84 values and
the ellipsoid's geometry, the attitude algebra against SciPy, the mechanisation with a
perfect IMU (drift over the flight stated), a stationary IMU against its closed form, the
Schuler oscillation against its textbook period, and the EKF's F (jax.jacfwd of the
mechanisation) against finite differences of the strapdown step and against the textbook
blocks."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxfdi import rotation
from jaxfdi.gnss import _frames as frames
from jaxfdi.ins import _earth as earth
from jaxfdi.ins import _error_state as error_state
from jaxfdi.ins import _mechanization as mechanization
from jaxfdi.ins import _trajectory as trajectory

PARK = (37.5684, 126.8851, 70.0)


@pytest.fixture(scope="module")
def park_flight():
    """The first 300 s of the park flight (climb, a straight leg, a turn) at 100 Hz."""
    return trajectory.fly(trajectory.park_legs(300.0), PARK, 12.0)


@pytest.fixture(scope="module")
def run_ins():
    @jax.jit
    def run(nav0, samples, bias, dt):
        def body(nav, sample):
            return mechanization.strapdown_step(
                nav, sample[:3] - bias[:3], sample[3:] - bias[3:], dt
            ), nav.velocity

        return jax.lax.scan(body, nav0, samples)

    return run


def test_normal_gravity_matches_wgs84_published_values():
    # NIMA TR8350.2 Table 3.4: normal gravity at the equator and the pole
    assert float(earth.surface_gravity(jnp.asarray(0.0))) == pytest.approx(9.7803253359, abs=1e-10)
    assert float(earth.surface_gravity(jnp.asarray(1.0))) == pytest.approx(9.8321849378, abs=1e-9)
    # the free-air gradient, -0.3086 mGal/m (Heiskanen & Moritz 1967), within 0.2 %
    s = math.sin(math.radians(45.0))
    gradient = (earth.gravity_ned(s, s, 100.0)[2] - earth.gravity_ned(s, s, 0.0)[2]) / 100.0
    assert float(gradient) == pytest.approx(-3.086e-6, rel=2e-3)


@pytest.mark.parametrize("lat_deg", [0.0, 37.5684, 80.0])
def test_radii_of_curvature_are_the_ellipsoid_metric(lat_deg):
    # independent: |d ECEF / d lat| = R_N + h and |d ECEF / d lon| = (R_E + h) cos L
    lat, lon, h = math.radians(lat_deg), 0.3, 120.0
    d_lat, d_lon = jax.jacfwd(frames.geodetic_to_ecef, argnums=(0, 1))(lat, lon, h)
    meridian, transverse = earth.radii_of_curvature(jnp.sin(lat))
    assert float(jnp.linalg.norm(d_lat)) == pytest.approx(float(meridian) + h, rel=1e-13)
    assert float(jnp.linalg.norm(d_lon)) == pytest.approx(
        (float(transverse) + h) * math.cos(lat), rel=1e-13
    )


def test_attitude_algebra_matches_scipy():
    rng = np.random.default_rng(0)
    for _ in range(5):
        roll, pitch, yaw = rng.uniform(-1.2, 1.2, 3)
        q = rotation.euler_to_quaternion(roll, pitch, yaw)
        reference = Rotation.from_euler("ZYX", [yaw, pitch, roll])
        np.testing.assert_allclose(rotation.quaternion_to_dcm(q), reference.as_matrix(), atol=1e-14)
        np.testing.assert_allclose(rotation.quaternion_to_euler(q), [roll, pitch, yaw], atol=1e-13)
        v = rng.normal(size=3)
        np.testing.assert_allclose(rotation.rotate(q, v), reference.apply(v), atol=1e-14)
        r = rng.normal(size=3)
        np.testing.assert_allclose(
            rotation.rotation_vector(rotation.rotation_quaternion(r)),
            Rotation.from_rotvec(r).as_rotvec(),
            atol=1e-13,
        )
        small = r / np.linalg.norm(r) * 0.1  # the strapdown step's series, at its stated limit
        np.testing.assert_allclose(
            rotation.small_rotation_quaternion(small),
            rotation.rotation_quaternion(small),
            atol=1e-15,
        )


def test_perfect_imu_follows_the_trajectory(park_flight, run_ins):
    """Error-free IMU samples (the exact inverse of the strapdown step) fly the INS along the
    truth: drift after 300 s (climb, straight, turn) below 1e-5 m, 1e-8 m/s, 1e-12 rad."""
    nav, _ = run_ins(park_flight.state(0), park_flight.imu, jnp.zeros(6), park_flight.dt)
    error = error_state.navigation_error(nav, park_flight.state(-1))
    assert float(jnp.max(jnp.abs(error[:3]))) < 1e-5
    assert float(jnp.max(jnp.abs(error[3:6]))) < 1e-8
    assert float(jnp.max(jnp.abs(error[6:9]))) < 1e-12


def test_stationary_imu_reads_gravity_and_earth_rate():
    """At rest the IMU reads -g^n and the Earth rate in body axes (closed form, Titterton &
    Weston 2004 sec. 10.3): f_D = -g(L, h), w = W [cos L, 0, -sin L] rotated by the yaw."""
    yaw = 30.0
    rest = trajectory.stationary(PARK, 1.0, rate=100.0, attitude_deg=(0.0, 0.0, yaw))
    lat = math.radians(PARK[0])
    w_ie = 7.2921151467e-5
    g = (
        9.7803253359
        * (1 + 0.00193185265241 * math.sin(lat) ** 2)
        / math.sqrt(1 - 0.00669437999014 * math.sin(lat) ** 2)
    )
    g *= (
        1
        - 2
        / 6378137.0
        * (
            1
            + 1 / 298.257223563 * (1 - 2 * math.sin(lat) ** 2)
            + w_ie**2 * 6378137.0**2 * 6356752.314245 / 3.986004418e14
        )
        * PARK[2]
    )
    g_north = -8.08e-9 * PARK[2] * math.sin(2 * lat)  # Groves (2013) eq. 2.140
    body = Rotation.from_euler("Z", yaw, degrees=True).inv()
    np.testing.assert_allclose(
        rest.imu[:, :3], np.tile(body.apply([-g_north, 0.0, -g]), (100, 1)), atol=1e-12
    )
    np.testing.assert_allclose(
        rest.imu[:, 3:],
        np.tile(body.apply([w_ie * math.cos(lat), 0.0, -w_ie * math.sin(lat)]), (100, 1)),
        atol=1e-15,
    )


def test_schuler_oscillation_has_the_textbook_period(run_ins):
    """A stationary INS with a 1 mg north accelerometer bias: the north velocity error is
    ``(b / w_s) sin(w_s t)``, zero again after one Schuler period
    ``2 pi sqrt((R_N + h) / g)`` (84.4 min; Titterton & Weston 2004 sec. 12.2.2)."""
    rest = trajectory.stationary(PARK, 5400.0, rate=10.0)
    bias = 9.80665e-3
    _, velocity = run_ins(rest.state(0), rest.imu, jnp.asarray([-bias, 0, 0, 0, 0, 0]), rest.dt)
    north = np.asarray(velocity[:, 0])
    t = np.arange(north.size) * rest.dt
    crossings = t[1:][(north[:-1] > 0) & (north[1:] <= 0)]
    rises = t[1:][(north[:-1] < 0) & (north[1:] >= 0)]
    lat = math.radians(PARK[0])
    meridian = (
        6378137.0 * (1 - 0.00669437999014) / (1 - 0.00669437999014 * math.sin(lat) ** 2) ** 1.5
    )
    period = 2 * math.pi * math.sqrt((meridian + PARK[2]) / 9.7998)
    assert crossings[0] == pytest.approx(period / 2, rel=2e-3)
    assert rises[0] == pytest.approx(period, rel=2e-3)
    assert rises[0] == pytest.approx(84.4 * 60, rel=5e-3)
    omega = 2 * math.pi / period
    assert float(north.max()) == pytest.approx(bias / omega, rel=0.02)


#: perturbation sizes: about one sigma of each error in flight (m, m/s, rad, m/s^2, rad/s)
SCALES = jnp.asarray([1.0] * 3 + [0.01] * 3 + [1e-4] * 3 + [1e-3] * 3 + [1e-6] * 3)


@jax.jit
def _transition_by_differences(nav, samples, dt):
    """Central differences of ``len(samples)`` strapdown steps in the error coordinates:
    column i is d(error after) / d(error before) for a perturbation of state i."""

    def fly(start, bias):
        def body(n, s):
            return mechanization.strapdown_step(n, s[:3] - bias[:3], s[3:] - bias[3:], dt), None

        return jax.lax.scan(body, start, samples)[0]

    reference = fly(nav, jnp.zeros(6))

    def column(e):
        def after(sign):
            moved = fly(error_state.correct(nav, -sign * e[:9]), -sign * e[9:])
            return jnp.concatenate([error_state.navigation_error(moved, reference), sign * e[9:]])

        return (after(1.0) - after(-1.0)) / (2 * jnp.sum(e))

    return jax.vmap(column, out_axes=1)(jnp.diag(SCALES))


def _scaled(matrix):
    """Entries in units of the typical errors: row i over SCALES[i], column j times SCALES[j]."""
    return matrix * SCALES[None, :] / SCALES[:, None]


@pytest.mark.parametrize("index", [2000, 11000, 16000])  # climbing, turning, straight
def test_F_matches_finite_differences_of_the_strapdown_step(park_flight, index):
    """One strapdown step maps errors by ``I + F dt + F^2 dt^2 / 2`` with ``F`` the mean of
    its values at both ends, to O(dt^3): every entry, in units of the typical errors,
    within 1e-7 of central differences of the step."""
    nav, dt = park_flight.state(index), park_flight.dt
    sample = park_flight.imu[index]
    jacobian = jax.jit(error_state.error_jacobian)
    F = 0.5 * (
        jacobian(nav, sample[:3], sample[3:])
        + jacobian(park_flight.state(index + 1), sample[:3], sample[3:])
    )
    expected = jnp.eye(15) + F * dt + F @ F * dt**2 / 2
    measured = _transition_by_differences(nav, park_flight.imu[index : index + 1], dt)
    assert float(jnp.max(jnp.abs(_scaled(measured - expected)))) < 1e-7


@pytest.mark.parametrize("epoch", [20, 110, 160])
def test_epoch_transition_matches_finite_differences_over_one_second(park_flight, epoch):
    """The filter's Phi over a 1 s epoch (F at the epoch's midpoint, third-order series)
    against central differences of the 100 strapdown steps: every entry, in units of the
    typical errors, within 1e-4. (The mid-point F misses how the body axes turn within
    the second, first order in the turn rate: in the turn, an accelerometer bias' effect on
    position is 1 % off, 5e-5 m for 1 mg.)"""
    start = epoch * 100
    samples = park_flight.imu[start : start + 100]
    nav = park_flight.state(start)
    measured = _transition_by_differences(nav, samples, park_flight.dt)
    mid = park_flight.state(start + 50)
    mean = jnp.mean(samples, axis=0)
    transition, _ = error_state.discretize(
        jax.jit(error_state.error_jacobian)(mid, mean[:3], mean[3:]),
        error_state.ImuNoise(1.0, 1.0, 1.0, 1.0),
        1.0,
    )
    worst = np.unravel_index(int(jnp.argmax(jnp.abs(_scaled(transition - measured)))), (15, 15))
    assert float(jnp.max(jnp.abs(_scaled(transition - measured)))) < 1e-4, [
        error_state.STATE_NAMES[i] for i in worst
    ]


def test_F_has_the_textbook_blocks(park_flight):
    """The dominant blocks of Groves (2013) eqs. 14.64-14.66 in these error conventions:
    ``dp' = dv``, ``dv' = -[f^n x] psi + C_b^n db_a``, ``psi' = -[w_in^n x] psi + C_b^n db_g``."""
    index = 11000  # in a turn: f^n has a horizontal part
    nav, sample = park_flight.state(index), park_flight.imu[index]
    F = np.asarray(jax.jit(error_state.error_jacobian)(nav, sample[:3], sample[3:]))
    C = np.asarray(rotation.quaternion_to_dcm(nav.attitude))
    f_n = C @ np.asarray(sample[:3])
    local = earth.local_earth(nav.position)
    w_in = np.asarray(local.earth_rate + earth.transport_rate(nav.velocity, nav.position[2], local))
    skew = np.asarray(rotation.skew(jnp.asarray(f_n)))
    np.testing.assert_allclose(F[0:3, 3:6], np.eye(3), atol=2e-6)
    np.testing.assert_allclose(F[3:6, 6:9], -skew, atol=1e-9 * np.abs(f_n).max())
    np.testing.assert_allclose(F[3:6, 9:12], C, atol=1e-12)
    np.testing.assert_allclose(F[6:9, 12:15], C, atol=1e-12)
    np.testing.assert_allclose(
        F[6:9, 6:9], -np.asarray(rotation.skew(jnp.asarray(w_in))), atol=1e-12
    )
    assert np.all(F[9:] == 0.0)


def test_steady_turn_reads_the_coordinated_load_factor(park_flight):
    """In the park flight's steady level coordinated turn (12 m/s at 0.06 rad/s, 4.2 deg of
    bank, from 110 s; blended in over 5 s) the accelerometers read ``(0, 0, -g / cos(bank))``
    to the Coriolis and transport terms (< 1e-3 m/s^2); the load factor's 0.027 m/s^2 is
    resolved."""
    bank = math.atan(12.0 * 0.06 / trajectory.G0)
    f = np.asarray(park_flight.imu[12000:15000, :3]).mean(axis=0)
    np.testing.assert_allclose(f, [0.0, 0.0, -9.7998 / math.cos(bank)], atol=2e-3)
    assert abs(f[2] + 9.7998) > 0.02
