"""The INS/GPS EKF with both tests over 100 Monte Carlo flights of 1000 s at 100 Hz:
jaxfdi against the same filter as a NumPy loop.

Workload per flight (both implementations): the park flight of ``scenarios.gps_ins`` for
``--seconds`` s; an HG1900-class IMU simulated at 100 Hz (turn-on biases, white noise,
bias random walks); a GPS fix at 1 Hz (truth plus noise with the covariance of the
receiver's least-squares geometry along the path, velocity noise 0.1 m/s; RAIM and the
pseudorange simulation are not timed here, see ``bench_gnss_raim.py``); per epoch the
15-state error-state EKF's update, feedback, 100 strapdown steps, F and its
discretisation, the covariance prediction, the windowed chi-square test (10 epochs) and
Da's SCST with two propagators (period 60 s).

- jaxfdi: ``loop.run_loop`` of a plant (IMU + fixes) and ``ins.integrity.ins_fdi``,
  ``jit(vmap)`` over the flights, detection scores folded into the carry;
- NumPy loop: the same equations written for one flight with NumPy, looped over epochs
  and IMU samples. NumPy has no ``jacfwd``: each epoch calls the compiled
  ``error_state.error_jacobian`` once for F (about 1 % of its time); everything else is
  NumPy. ``--numpy-flights`` flights are timed and the time scaled to ``--flights``.

Agreement is checked first, on one flight fed the same IMU samples and fixes: the
chi-square and SCST statistics and the INS positions of the two implementations.
Compile time apart from run time; the real-time factor is simulated flight seconds of all
flights per wall second.

Run:  python benchmarks/bench_gps_ins.py                        (~5 minutes on 2 cores)
      python benchmarks/bench_gps_ins.py --flights 20 --seconds 300 --numpy-flights 1   (quick)
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

from jaxfdi import Plant, combine_scorers, detection_scorer, feedforward, run_loop
from jaxfdi._io import files as _io
from jaxfdi.gnss import _integrity as gnss_integrity
from jaxfdi.gnss import _measurements as measurements
from jaxfdi.ins import GpsFix, NavState
from jaxfdi.ins import _error_state as error_state
from jaxfdi.ins import _imu as imu
from jaxfdi.ins import _integrity as integrity
from jaxfdi.ins import _plant as plant
from jaxfdi.ins import _scst as scst
from jaxfdi.ins import _trajectory as trajectory
from jaxfdi.scenarios import gps_ins

VELOCITY_SIGMA = 0.1
MODEL = imu.hg1900()


# --- the shared inputs --------------------------------------------------------------------


def setup(seconds: int):
    """The flight tables and the per-epoch NED covariance of the GPS fix along the path."""
    table = gps_ins._ephemeris()
    traj = trajectory.fly(trajectory.park_legs(float(seconds)), gps_ins.PARK, 12.0)
    flight = plant.flight_tables(traj, seconds)
    from jaxfdi.gnss import _frames as frames

    path = frames.geodetic_to_ecef(
        flight.position[:, 0], flight.position[:, 1], flight.position[:, 2]
    )
    times = gps_ins.START_TOW + jnp.arange(seconds, dtype=float)
    fixes = jax.vmap(
        lambda t, x: gnss_integrity.geometry_fix(
            table, t, x, math.radians(gps_ins.MASK_DEG), measurements.elevation_sigma
        )
    )(times, path)
    return flight, jax.vmap(integrity.fix_covariance)(fixes)


def make_fixes(key, flight, position_cov):
    """One flight's GPS fixes: the truth moved by N(0, R_p) in NED and N(0, 0.1^2 I) in velocity."""
    k1, k2 = jax.random.split(key)
    T = position_cov.shape[0]
    noise = jnp.einsum(
        "tij,tj->ti", jnp.linalg.cholesky(position_cov), jax.random.normal(k1, (T, 3))
    )
    vel_noise = VELOCITY_SIGMA * jax.random.normal(k2, (T, 3))
    truth = NavState(flight.position, flight.velocity, flight.attitude)
    error = jnp.concatenate([noise, vel_noise, jnp.zeros((T, 3))], axis=1)
    fix = jax.vmap(lambda nav, e: error_state.correct(nav, -e))(
        truth, error
    )  # error(fix, truth) = e
    return fix.position, fix.velocity


def design():
    """The study's filter and tests (the IMU health test too: the NumPy peer has none)."""
    return gps_ins.design(MODEL, 1.0 / gps_ins.IMU_RATE)


def initial(flight):
    nav0 = NavState(flight.position[0], flight.velocity[0], flight.attitude[0])
    cov0 = gps_ins.initial_covariance(MODEL)
    return integrity.ins_fdi(*design()).init(nav0, cov0), cov0


# --- jaxfdi ---------------------------------------------------------------------------------


def imu_fix_plant(flight, position_cov, fix_position, fix_velocity, replay=None) -> Plant:
    """IMU samples (simulated, or ``replay`` (T, n, 6)) and the given fixes, one epoch a step."""
    dt = 1.0 / flight.imu.shape[1]

    def measure(errors, k, u, key):
        samples = (
            imu.measure(flight.imu[k], errors, jax.random.fold_in(key, 1), MODEL, dt)
            if replay is None
            else replay[k]
        )
        fix = GpsFix(
            fix_position[k],
            fix_velocity[k],
            position_cov[k],
            VELOCITY_SIGMA**2 * jnp.eye(3),
            jnp.asarray(True),
        )
        return errors, (fix, samples)

    def advance(errors, k, u, key):
        return imu.walk_biases(errors, jax.random.fold_in(key, 2), MODEL, 1.0), None

    return Plant(lambda x0: x0, measure, advance)


def jax_flights(flight, position_cov, keys):
    """All flights: scores of both tests (and the final INS position, to keep it live)."""
    fdi = integrity.ins_fdi(*design())
    T = position_cov.shape[0]

    def one(key):
        k_fix, k_imu, k_loop = jax.random.split(key, 3)
        position, velocity = make_fixes(k_fix, flight, position_cov)
        state0, _ = initial(flight)
        scorer = combine_scorers(
            chi2=detection_scorer(gps_ins.ONSET_S, lambda o: o.chi2, single=True),
            scst=detection_scorer(gps_ins.ONSET_S, lambda o: o.scst, single=True),
        )
        result = run_loop(
            imu_fix_plant(flight, position_cov, position, velocity),
            fdi,
            feedforward(),
            imu.draw_errors(k_imu, MODEL),
            state0,
            k_loop,
            T,
            exogenous=jnp.zeros((T, 0)),
            scorer=scorer,
        )
        return result.score, result.final[1].ins.nav.position

    return jax.vmap(one)(keys)


# --- the NumPy loop ---------------------------------------------------------------------

A, F_FLAT, E2 = 6378137.0, 1.0 / 298.257223563, (1.0 / 298.257223563) * (2 - 1.0 / 298.257223563)
B_AXIS, MU, OMEGA = A * (1 - F_FLAT), 3.986004418e14, 7.2921151467e-5
GE, SOMIGLIANA = 9.7803253359, 0.00193185265241
M_GRAV = OMEGA**2 * A**2 * B_AXIS / MU


def np_radii(s):
    iw = 1.0 / math.sqrt(1.0 - E2 * s * s)
    return A * (1 - E2) * iw**3, A * iw, iw


def np_qmul(p, q):
    return np.array(
        [
            p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
        ]
    )


def np_rotate(q, v):
    t = 2.0 * np.cross(q[1:], v)
    return v + q[0] * t + np.cross(q[1:], t)


def np_small_q(r):
    x2 = r @ r
    return np.concatenate(
        [
            [1 - x2 / 8 + x2 * x2 / 384 - x2**3 / 46080],
            (0.5 - x2 / 48 + x2 * x2 / 3840 - x2**3 / 645120) * r,
        ]
    )


def np_q(r):
    angle = math.sqrt(r @ r)
    if angle < 1e-5:
        return np_small_q(r)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) / angle * r])


def np_log(q):
    q = -q if q[0] < 0 else q
    n = math.sqrt(q[1:] @ q[1:])
    if n * n < 1e-10:
        return 2.0 / q[0] * (1 - n * n / (3 * q[0] ** 2)) * q[1:]
    return 2.0 * math.atan2(n, q[0]) / n * q[1:]


def np_step(pos, vel, q, f, w, dt):
    """``mechanization.strapdown_step`` in NumPy."""
    lat, lon, h = pos
    s, c = math.sin(lat), math.cos(lat)
    rn, re, iw = np_radii(s)
    g_down = (
        GE
        * (1 + SOMIGLIANA * s * s)
        * iw
        * (1 - 2 / A * (1 + F_FLAT * (1 - 2 * s * s) + M_GRAV) * h + 3 * h * h / A**2)
    )
    gravity = np.array([-8.08e-9 * h * 2 * s * c, 0.0, g_down])
    w_ie = OMEGA * np.array([c, 0.0, -s])
    w_en = np.array([vel[1] / (re + h), -vel[0] / (rn + h), -vel[1] * s / (c * (re + h))])
    q_new = np_qmul(np_small_q(-(w_ie + w_en) * dt), np_qmul(q, np_small_q(w * dt)))
    q_new = q_new * (1.5 - 0.5 * (q_new @ q_new))
    f_n = 0.5 * (np_rotate(q, f) + np_rotate(q_new, f))
    v_new = vel + (f_n + gravity - np.cross(2 * w_ie + w_en, vel)) * dt
    h_new = h - 0.5 * dt * (vel[2] + v_new[2])
    lat_new = lat + 0.5 * dt * (vel[0] / (rn + h) + v_new[0] / (rn + h_new))
    d = lat_new - lat
    cd, sd = 1 - 0.5 * d * d, d * (1 - d * d / 6)
    s_new, c_new = s * cd + c * sd, c * cd - s * sd
    _, re_new, _ = np_radii(s_new)
    lon_new = lon + 0.5 * dt * (vel[1] / ((re + h) * c) + v_new[1] / ((re_new + h_new) * c_new))
    return np.array([lat_new, lon_new, h_new]), v_new, q_new


def np_nav_error(pos, vel, q, pos_t, vel_t, q_t):
    rn, re, _ = np_radii(math.sin(pos[0]))
    d = pos - pos_t
    dp = np.array([(rn + pos[2]) * d[0], (re + pos[2]) * math.cos(pos[0]) * d[1], -d[2]])
    psi = np_log(np_qmul(q, q_t * np.array([1, -1, -1, -1])))
    return np.concatenate([dp, vel - vel_t, psi])


def np_correct(pos, vel, q, e):
    rn, re, _ = np_radii(math.sin(pos[0]))
    pos_t = pos - np.array([e[0] / (rn + pos[2]), e[1] / ((re + pos[2]) * math.cos(pos[0])), -e[2]])
    q_t = np_qmul(np_q(-e[6:9]), q)
    return pos_t, vel - e[3:6], q_t / math.sqrt(q_t @ q_t)


def np_discretize(F, T):
    noise = imu.noise_model(MODEL)
    a = F * T
    a2 = a @ a
    phi = np.eye(15) + a + 0.5 * a2 + a2 @ a / 6.0
    white = np.concatenate(
        [
            np.full(3, float(noise.velocity_random_walk) ** 2),
            np.full(3, float(noise.angle_random_walk) ** 2),
        ]
    )
    gain = F[:, 9:]
    q = (gain * white) @ gain.T + np.diag(
        np.concatenate(
            [
                np.zeros(9),
                np.full(3, float(noise.accel_bias_walk) ** 2),
                np.full(3, float(noise.gyro_bias_walk) ** 2),
            ]
        )
    )
    fq = F @ q
    qd = q * T + 0.5 * (fq + fq.T) * T**2 + fq @ F.T * T**3 / 3.0
    return phi, 0.5 * (qd + qd.T)


_JACOBIAN = jax.jit(error_state.error_jacobian)


class NumpyMonitor:
    """One flight's EKF, chi-square test and SCST, in NumPy (module doc)."""

    def __init__(self, nav0, cov0):
        self.pos, self.vel, self.q = (np.array(a, float) for a in nav0)
        self.ba, self.bg = np.zeros(3), np.zeros(3)
        self.P = np.array(cov0, float)
        self.window = []
        self.chi2_limit, self.scst_limit = gps_ins.thresholds()
        self.beta, self.Pm = np.zeros((2, 15)), np.zeros((2, 15, 15))
        self.age, self.epoch = np.array([-1, -1]), 0

    def step(self, fix_pos, fix_vel, R_p, samples, dt):
        z = np_nav_error(self.pos, self.vel, self.q, fix_pos, fix_vel, self.q)[:6]
        R = np.zeros((6, 6))
        R[:3, :3], R[3:, 3:] = R_p, VELOCITY_SIGMA**2 * np.eye(3)
        S = self.P[:6, :6] + R
        L = np.linalg.cholesky(S)
        K = np.linalg.solve(L.T, np.linalg.solve(L, self.P[:6, :])).T  # P H^T S^-1
        dx = K @ z
        IKH = np.eye(15)
        IKH[:, :6] -= K
        P = IKH @ self.P @ IKH.T + K @ R @ K.T
        P = 0.5 * (P + P.T)
        w = np.linalg.solve(L, z)
        nis = w @ w
        self.pos, self.vel, self.q = np_correct(self.pos, self.vel, self.q, dx)
        self.ba, self.bg = self.ba + dx[9:12], self.bg + dx[12:15]
        # chi-square window over the last 10 epochs
        self.window = (self.window + [nis])[-gps_ins.CHI2_WINDOW :]
        chi2 = sum(self.window)
        # SCST (scst.state_chi2_test)
        started = self.age >= 0
        beta = np.where(started[:, None], self.beta + dx, 0.0)
        Pm = np.where(started[:, None, None], self.Pm, P)
        age = np.maximum(self.age, 0)
        used = int(np.argmax(age))
        statistic = self._statistic(beta[used], Pm[used] - P)
        offsets = np.array([0, gps_ins.SCST_PERIOD // 2])
        reset = (
            (self.epoch > 0)
            & ((self.epoch - offsets) % gps_ins.SCST_PERIOD == 0)
            & (self.epoch >= offsets)
        )
        beta[reset], Pm[reset], age[reset] = 0.0, P, 0
        # 100 strapdown steps, F at the midpoint sample, discretisation, prediction
        corrected = samples - np.concatenate([self.ba, self.bg])
        n = corrected.shape[0]
        for i in range(n):
            if i == n // 2:
                mean = corrected.mean(axis=0)
                F = np.asarray(_JACOBIAN(NavState(self.pos, self.vel, self.q), mean[:3], mean[3:]))
            self.pos, self.vel, self.q = np_step(
                self.pos, self.vel, self.q, corrected[i, :3], corrected[i, 3:], dt
            )
        phi, qd = np_discretize(F, n * dt)
        self.P = phi @ P @ phi.T + qd
        self.P = 0.5 * (self.P + self.P.T)
        self.beta = beta @ phi.T
        self.Pm = np.einsum("ij,pjk,lk->pil", phi, Pm, phi) + qd
        self.Pm = 0.5 * (self.Pm + np.swapaxes(self.Pm, 1, 2))
        self.age, self.epoch = age + 1, self.epoch + 1
        return chi2, statistic

    def _statistic(self, beta, B):
        d = np.diag(B)
        if np.any(d <= 0):
            return 0.0
        s = np.sqrt(d)
        try:
            L = np.linalg.cholesky(B / np.outer(s, s))
        except np.linalg.LinAlgError:
            return 0.0
        if (L.diagonal().max() / L.diagonal().min()) ** 2 > scst.DEFAULT_MAX_CONDITION:
            return 0.0
        w = np.linalg.solve(L, beta / s)
        return float(w @ w)


def numpy_flight(flight, position_cov, fix_pos, fix_vel, rng, samples=None):
    """One flight in NumPy: simulated IMU (``rng``) unless ``samples`` are given."""
    state, cov0 = initial(flight)
    nav0 = (flight.position[0], flight.velocity[0], flight.attitude[0])
    monitor = NumpyMonitor(nav0, cov0)
    true = np.asarray(flight.imu)
    R = np.asarray(position_cov)
    fix_pos, fix_vel = np.asarray(fix_pos), np.asarray(fix_vel)
    T, n = true.shape[:2]
    dt = 1.0 / n
    rng = rng if rng is not None else np.random.default_rng(0)
    biases = np.concatenate(
        [
            float(MODEL.accel_bias) * rng.standard_normal(3),
            float(MODEL.gyro_bias) * rng.standard_normal(3),
        ]
    )
    density = np.concatenate(
        [np.full(3, float(MODEL.velocity_random_walk)), np.full(3, float(MODEL.angle_random_walk))]
    ) / math.sqrt(dt)
    walk = np.concatenate(
        [np.full(3, float(MODEL.accel_bias_walk)), np.full(3, float(MODEL.gyro_bias_walk))]
    )
    out = []
    for k in range(T):
        block = (
            samples[k]
            if samples is not None
            else true[k] + biases + density * rng.standard_normal((n, 6))
        )
        out.append(monitor.step(fix_pos[k], fix_vel[k], R[k], block, dt))
        biases = biases + walk * rng.standard_normal(6)
    return np.array(out), monitor.pos


# --- the run -----------------------------------------------------------------------------


def check_agreement(flight, position_cov, epochs: int) -> dict:
    """One flight, the same IMU samples and fixes in both: statistics and positions."""
    flight = plant.FlightTables(*(a[:epochs] for a in flight))
    position_cov = position_cov[:epochs]
    key = jax.random.key(99)
    position, velocity = make_fixes(key, flight, position_cov)
    errors = imu.draw_errors(jax.random.fold_in(key, 1), MODEL)
    samples = jax.vmap(
        lambda k, s: imu.measure(s, errors, jax.random.fold_in(key, k), MODEL, 0.01)
    )(jnp.arange(epochs), flight.imu)
    state0, _ = initial(flight)
    result = run_loop(
        imu_fix_plant(flight, position_cov, position, velocity, replay=samples),
        integrity.ins_fdi(*design()),
        feedforward(),
        errors,
        state0,
        key,
        epochs,
        exogenous=jnp.zeros((epochs, 0)),
        keep_history=True,
    )
    out = result.history.output
    stats_np, final_np = numpy_flight(
        flight, position_cov, position, velocity, None, np.asarray(samples)
    )
    chi2_j, scst_j = np.asarray(out.chi2.statistic), np.asarray(out.scst.statistic)
    return {
        "epochs": epochs,
        "chi2_max_rel_diff": float(
            np.max(np.abs(chi2_j - stats_np[:, 0]) / np.maximum(chi2_j, 1e-9))
        ),
        "scst_max_abs_diff": float(np.max(np.abs(scst_j - stats_np[:, 1]))),
        "scst_max": float(np.max(scst_j)),
        "final_position_diff_m": float(
            np.max(
                np.abs(
                    np.asarray(
                        error_state.navigation_error(
                            NavState(
                                result.final[1].ins.nav.position,
                                jnp.zeros(3),
                                jnp.asarray([1.0, 0, 0, 0]),
                            ),
                            NavState(
                                jnp.asarray(final_np), jnp.zeros(3), jnp.asarray([1.0, 0, 0, 0])
                            ),
                        )
                    )[:3]
                )
            )
        ),
    }


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--flights", type=int, default=100)
    parser.add_argument("--seconds", type=int, default=1000)
    parser.add_argument("--numpy-flights", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--check-epochs", type=int, default=120)
    parser.add_argument(
        "--out", default=os.path.join(os.path.dirname(__file__), "results_gps_ins.json")
    )
    args = parser.parse_args()

    t0 = time.perf_counter()
    flight, position_cov = setup(args.seconds)
    print(
        f"setup (trajectory, IMU table, fix covariances): {time.perf_counter() - t0:.1f} s",
        flush=True,
    )
    agreement = check_agreement(flight, position_cov, min(args.check_epochs, args.seconds))
    print(f"agreement on one flight of {agreement['epochs']} s: {agreement}", flush=True)
    if (
        agreement["chi2_max_rel_diff"] > 1e-6
        or agreement["scst_max_abs_diff"] > 1e-4 * max(1.0, agreement["scst_max"])
        or agreement["final_position_diff_m"] > 1e-6
    ):
        sys.exit("jaxfdi and the NumPy loop disagree; not timing")

    keys = jax.random.split(jax.random.key(0), args.flights)
    t0 = time.perf_counter()
    compiled = jax.jit(jax_flights).lower(flight, position_cov, keys).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(flight, position_cov, keys))
    runs = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        scores, _ = jax.block_until_ready(compiled(flight, position_cov, keys))
        runs.append(time.perf_counter() - t0)
    jax_s = float(np.median(runs))
    fa_chi2 = float(np.mean(np.asarray(scores["chi2"].false_alarms) > 0))
    print(
        f"jaxfdi: {args.flights} flights x {args.seconds} s: compile {compile_s:.1f} s, run {jax_s:.2f} s "
        f"(median of {args.repeats}); flights with a chi2 alarm {fa_chi2:.2f}",
        flush=True,
    )

    rng = np.random.default_rng(0)
    numpy_runs = []
    for i in range(args.numpy_flights):
        position, velocity = make_fixes(
            jax.random.fold_in(jax.random.key(1), i), flight, position_cov
        )
        t0 = time.perf_counter()
        numpy_flight(flight, position_cov, position, velocity, rng)
        numpy_runs.append(time.perf_counter() - t0)
        print(
            f"numpy loop: flight {i + 1}/{args.numpy_flights}: {numpy_runs[-1]:.1f} s", flush=True
        )
    per_flight = float(np.mean(numpy_runs))
    numpy_s = per_flight * args.flights
    ratio = numpy_s / jax_s
    realtime = args.flights * args.seconds / jax_s
    print(
        f"numpy loop: {per_flight:.1f} s per flight -> {numpy_s:.0f} s for {args.flights} flights (scaled)"
    )
    print(
        f"speed-up {ratio:.0f}x (target 200x); real-time factor {realtime:.0f} (simulated s / wall s, all flights); "
        f"per flight-epoch {jax_s / (args.flights * args.seconds) * 1e6:.1f} us vs "
        f"{per_flight / args.seconds * 1e6:.0f} us"
    )
    _io.write_json(
        args.out,
        {
            "date": datetime.date.today().isoformat(),
            "cpu": cpu_model(),
            "cores": os.cpu_count(),
            "load_average": list(os.getloadavg()),
            "jax": jax.__version__,
            "args": vars(args),
            "agreement": agreement,
            "jax_compile_s": compile_s,
            "jax_run_s": jax_s,
            "jax_runs_s": runs,
            "numpy_flight_s": numpy_runs,
            "numpy_scaled_s": numpy_s,
            "speedup": ratio,
            "realtime_factor": realtime,
        },
    )
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_gps_ins.json")


if __name__ == "__main__":
    main()
