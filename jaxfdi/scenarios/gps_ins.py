"""Yoo et al. (2010), INS half: the park flight's GPS/INS integrity monitor and Table 3.

- Flight: the GPS half's park case (``scenarios.gnss_campus``: Haneul Park, from 2020-01-01 00:45:00 GPST, its orbits
  and receiver), 1200 s: a 60 m climb, then its racetrack (600 m legs, 200 m turns, 12 m/s) with a climb and a descent
  (``ins._trajectory.park_legs``); HG1900-class IMU (``ins.hg1900``) at 100 Hz, receiver at 1 Hz.
- One run: ``run_loop`` of the plant ``ins._plant.gps_ins_plant`` (pseudoranges with Table 2's satellite faults,
  velocity solution, IMU samples with the IMU fault) and the FDI ``ins._integrity.gps_ins_fdi`` (RAIM -> 15-state
  error-state EKF -> windowed chi-square over 10 epochs at 60 dof, 91.95, and Da's SCST at 15 dof, 32.80, two
  propagators reset every ``SCST_PERIOD`` s); Monte Carlo: a ``vmap`` over keys and faults, one compiled program.
- **Table 3**: roll-gyro bias 30, 60, 90 deg/h from 800 s (``fault("bias", "sensor", 3, 800, ...)``) on top of Table 2's
  satellite faults (impulse, bias, drift on the highest satellite); detection time = first alarm at or after 800 s minus
  800 (mean and std, as the paper's are means; median, 10-90 %), beside the paper's 159/59/44 s (chi-square) and
  149/49/39 s (SCST); RAIM's decisions on the satellite faults in the same runs.
- **Fault-free flights**: both tests' false alarms per epoch and at independent decisions (chi-square: non-overlapping
  windows; SCST: one propagator window in two), binomial intervals; navigation errors.
- **Beyond the paper**: detection time vs roll-gyro and x-accelerometer bias size; a strong-manoeuvre flight (25 m/s,
  S-turns at 20 deg/s with 42 deg of bank, pull-ups, dives; ``ins.trajectory.manoeuvre_legs``) fault-free and with the
  roll-gyro biases (where SCST degrades); the roll gyro dead (NaN) and frozen from the onset (``IMU_HEALTH_CASES``),
  found by the IMU health test (``ins.integrity.imu_health_test``) beside both tests' times, and its fault-free alarms.
- ``StudySize`` shortens flights, moves the onset, lowers the IMU rate (tests, notebook; satellite faults ending after
  the onset are left out); ``PAPER_SIZE`` (1200 s, 800 s, 100 Hz) is the CLI's.

Reference: Yoo, Ahn, Sung, Lee & Chun (2010), "A Realization of Applicable GPS/INS Fault Detection Algorithm for UAV
using Low Grade Processor", J. KSAS 38(8):781, doi:10.5139/JKSAS.2010.38.8.781 (CITATION.cff).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats as _scipy_stats

import jaxfdi.ins
from jaxfdi import (
    NEVER,
    Fault,
    Structure,
    Study,
    as_stack,
    binomial_interval,
    binomial_lower_bound,
    case_slices,
    combine_scorers,
    concat_faults,
    delay_statistics,
    detection_scorer,
    episode_scorer,
    episodes,
    fault,
    feedforward,
    gnss,
    no_fault,
    rate_cell,
    rate_interval,
    record_from_alarms,
    run_loop,
    run_study,
    status,
    study_result,
    summarize_detection,
    summarize_episodes,
)
from jaxfdi.detection import chi2_detector, chi2_threshold
from jaxfdi.ins import NavState, loosely_coupled_filter
from jaxfdi.plotting import column_figure
from jaxfdi.scenarios._common import check_study, figure_collector, require_x64

# Table 2's three episodes only: the GPS half's dead and frozen channels (700-860 s) come after the IMU onset
from jaxfdi.scenarios.gnss_campus import (
    MASK_DEG,
    PARK,
    START_TOW,
    TABLE2_FAULTS,
    WEEK,
    _cell,
    _ephemeris,
)

FLIGHT_S = 1200
IMU_RATE = 100
ONSET_S = 800
ROLL_GYRO = 3  # IMU channel: [f_x, f_y, f_z, w_x, w_y, w_z]
X_ACCEL = 0
TABLE3_DEG_H = (30.0, 60.0, 90.0)
#: Table 3 of Yoo et al. (2010): detection time [s] (chi-square, SCST)
PAPER_TABLE3 = {30.0: (159.0, 149.0), 60.0: (59.0, 49.0), 90.0: (44.0, 39.0)}
CHI2_WINDOW = 10
PFA = 0.005
SCST_PERIOD = 60
VELOCITY_SIGMA = 0.1  # m/s, receiver velocity solution per axis
#: initial INS errors (1 sigma): position m, velocity m/s, tilt deg, heading deg
INITIAL_SIGMA = (3.0, 0.1, 0.05, 0.5)
BEYOND_GYRO_DEG_H = (15.0, 30.0, 45.0, 60.0, 90.0, 120.0, 180.0)
BEYOND_ACCEL_MG = (2.0, 5.0, 10.0, 20.0, 50.0)
#: beyond the paper: the roll gyro dead (NaN) or frozen from the onset, name -> fault kind
IMU_HEALTH_CASES = {"dead": "dead", "frozen": "stuck"}
#: per-epoch false-alarm probabilities of the operating curve: each test's Table 3 detection times at the threshold
#: ``chi2_isf(dof, P_fa)`` of each
OPERATING_PFA = (5e-3, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8, 1e-10, 1e-12, 1e-15)
#: GPS/INS separation (``integrity.attribute_ins_alarms``): an INS-test alarm is the GPS's when RAIM alarmed from
#: HOLDOFF s before it to LOOKAHEAD s after it (a 1 m/s drift reaches the filter 10-25 s before RAIM flags it; the SCST
#: propagators hold an exclusion's transient up to two periods); the INS decision is issued LOOKAHEAD s late
ATTRIBUTION_LOOKAHEAD = 30
ATTRIBUTION_HOLDOFF = 2 * SCST_PERIOD
#: the per-epoch P_fa at which the separation is scored: the design's, and one with about one fault-free flight in a
#: hundred alarming (the operating curve)
SEPARATION_PFA = (PFA, 1e-5)
MANOEUVRE_HEIGHT = 200.0  # m above the park site


class StudySize(NamedTuple):
    """Flight length, IMU-fault onset [s] and IMU rate [Hz]; the paper's: ``PAPER_SIZE`` (the strapdown step is exact at
    any rate: a lower one changes only the cost)."""

    flight_s: int = FLIGHT_S
    onset_s: int = ONSET_S
    imu_rate: int = IMU_RATE


PAPER_SIZE = StudySize()


class World(NamedTuple):
    """What every run of one flight shares (arguments of the compiled program).

    Attributes:
      table: the broadcast orbits
      tables: thresholds and noncentralities per degrees of freedom
      flight: the flight as the plant reads it
      visible: (T, S) bool, satellites in view
      sigma: (T, S) m, pseudorange noise std
    """

    table: gnss.OrbitTable
    tables: gnss.RaimTables
    flight: jaxfdi.ins.FlightTables
    visible: jax.Array
    sigma: jax.Array


class RunCase(NamedTuple):
    """One run's faults: the satellite episodes and the IMU fault.

    Attributes:
      satellite_fault: stack of 3 (Table 2's episodes, or none)
      imu_fault: stack of 1
      onset: () int, the IMU fault's onset (faults.NEVER when none)
    """

    satellite_fault: Fault
    imu_fault: Fault
    onset: jax.Array


class Series(NamedTuple):
    """Per-epoch traces of a run (float32: figures and independent samples).

    Attributes:
      chi2: (T,) windowed chi-square statistic
      scst: (T,) SCST statistic
      scst_valid: (T,) bool, the SCST's B passed its checks
      scst_condition: (T,) condition estimate of the scaled B (inf when not PD)
      gps_used: (T,) bool, the EKF was updated
      raim: (T,) RAIM parity statistic
      raim_threshold: (T,) its threshold
      hpl: (T,) m, horizontal protection level
      hdop: (T,) horizontal dilution of precision
      position_error: (T, 3) NED m
      attitude_error: (T, 3) psi NED deg
      sigma: (T, 6) filter 1-sigma: position m (3), attitude deg (3)
      nees: (T,) normalised estimation error squared of the 15 states
    """

    chi2: jax.Array
    scst: jax.Array
    scst_valid: jax.Array
    scst_condition: jax.Array
    gps_used: jax.Array
    raim: jax.Array
    raim_threshold: jax.Array
    hpl: jax.Array
    hdop: jax.Array
    position_error: jax.Array
    attitude_error: jax.Array
    sigma: jax.Array
    nees: jax.Array


class RunOutput(NamedTuple):
    """What a GPS/INS run leaves: the tests' records and its per-epoch series.

    Attributes:
      chi2: DetectionRecord of the windowed chi-square test
      scst: DetectionRecord of the SCST
      raim: EpisodeRecord of RAIM over the satellite episodes
      health: DetectionRecord of the IMU health test
      series: the run's per-epoch traces
    """

    chi2: object
    scst: object
    raim: object
    health: object
    series: Series


@study_result(group="case")
class GpsInsStudy(NamedTuple):
    """The GPS/INS integrity study: its settings, table rows, series, curves and records.

    Attributes:
      config: the study's settings
      rows: the table's rows, one dict each
      series: case name -> Series of its first run (NumPy), for the figures
      curves: (flight, sensor) -> rows of the detection-time curves
      results: case name -> RunOutput of all its runs (NumPy)
    """

    config: dict
    rows: list[dict]
    series: dict[str, Series]
    curves: dict[tuple[str, str], list[dict]]
    results: dict[str, RunOutput]

    def table(self) -> str:
        return gps_ins_table(self)


def thresholds() -> tuple[float, float]:
    """``(chi2 over 10 epochs at 60 dof, SCST at 15 dof)`` for ``PFA``: 91.95, 32.80."""
    with jax.ensure_compile_time_eval():  # concrete numbers, also while a run is traced
        return (
            float(chi2_threshold(6 * CHI2_WINDOW, PFA)),
            float(chi2_threshold(jaxfdi.ins.STATE_SIZE, PFA)),
        )


def design(model: jaxfdi.ins.ImuModel, dt: float):
    """The filter and the tests of the study: ``(filter, chi2 detector, SCST, IMU health)``."""
    chi2_limit, scst_limit = thresholds()
    return (
        loosely_coupled_filter(model, dt),
        chi2_detector(chi2_limit, CHI2_WINDOW),
        jaxfdi.ins.state_chi2_test(SCST_PERIOD, scst_limit),
        jaxfdi.ins.imu_health_test(model, dt),
    )


def initial_covariance(model: jaxfdi.ins.ImuModel):
    p, v, tilt, heading = INITIAL_SIGMA
    return jaxfdi.ins.initial_covariance(
        p, v, math.radians(tilt), math.radians(heading), model.accel_bias, model.gyro_bias
    )


def _flight(key: jax.Array, case: RunCase, world: World) -> RunOutput:
    """One flight: the loop of plant and FDI, its scores and its traces (the study engine's order: the world is the
    shared data of every run)."""
    model = jaxfdi.ins.hg1900()
    epochs, per_epoch = world.flight.imu.shape[:2]
    ins_filter, chi2, test, health = design(model, 1.0 / per_epoch)
    monitor = jaxfdi.ins.gps_ins_fdi(
        world.table, START_TOW, world.tables, ins_filter, chi2, test, health, VELOCITY_SIGMA
    )
    gps_ins = jaxfdi.ins.gps_ins_plant(
        world.table,
        START_TOW,
        world.flight,
        world.visible,
        world.sigma,
        model,
        VELOCITY_SIGMA,
        satellite_fault=case.satellite_fault,
        imu_fault=case.imu_fault,
    )
    key_loop, key_imu, key_init = jax.random.split(key, 3)
    errors = jaxfdi.ins.draw_errors(key_imu, model)
    cov0 = initial_covariance(model)
    nav_error = jnp.linalg.cholesky(cov0[:9, :9]) @ jax.random.normal(key_init, (9,), cov0.dtype)
    truth0 = NavState(world.flight.position[0], world.flight.velocity[0], world.flight.attitude[0])
    fdi0 = monitor.init(
        jaxfdi.ins.correct(truth0, -nav_error), cov0
    )  # INS = truth + error; biases unknown
    clock = gnss.ClockModel()
    scorer = combine_scorers(
        chi2=detection_scorer(case.onset, lambda o: o.chi2, single=True),
        scst=detection_scorer(case.onset, lambda o: o.scst, single=True),
        health=detection_scorer(case.onset, lambda o: o.ins.imu_health, single=True),
        raim=episode_scorer(episodes(case.satellite_fault, 0), lambda o: o.raim, single=True),
    )
    result = run_loop(
        gps_ins,
        monitor,
        feedforward(),
        (jnp.asarray([clock.bias, clock.drift]), errors),
        fdi0,
        key_loop,
        epochs,
        exogenous=jnp.zeros((epochs, 0)),
        scorer=scorer,
        keep_history=True,
    )
    out, truth = result.history.output, result.history.sensed.state
    errors9 = jax.vmap(jaxfdi.ins.navigation_error)(out.nav, truth.nav)
    errors15 = jnp.concatenate(
        [errors9, truth.accel_bias - out.ins.accel_bias, truth.gyro_bias - out.ins.gyro_bias],
        axis=1,
    )
    nees = jax.vmap(lambda e, p: e @ jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(p), True), e))(
        errors15, out.cov
    )
    sigma = jnp.sqrt(jnp.diagonal(out.cov, axis1=1, axis2=2))
    f32 = jnp.float32
    series = Series(
        out.chi2.statistic.astype(f32),
        out.scst.statistic.astype(f32),
        out.scst_valid,
        out.ins.scst_condition.astype(f32),
        out.gps_used,
        out.raim.statistic.astype(f32),
        out.raim_threshold.astype(f32),
        out.hpl.astype(f32),
        out.hdop.astype(f32),
        errors9[:, :3].astype(f32),
        jnp.degrees(errors9[:, 6:9]).astype(f32),
        jnp.concatenate([sigma[:, :3], jnp.degrees(sigma[:, 6:9])], axis=1).astype(f32),
        nees.astype(f32),
    )
    return RunOutput(
        result.score["chi2"],
        result.score["scst"],
        result.score["raim"],
        result.score["health"],
        series,
    )


def flights_spec(world: World, groups: list[tuple[str, RunCase]], name: str) -> Study:
    """A study of flights over one ``world``: ``groups`` of (name, stacked ``RunCase``, one per run), each a case with
    its own number of runs (run it with those counts); the world is the structure's shared data (one compiled program
    for every world and seed)."""
    names = tuple(group for group, _ in groups)
    stacked = jax.tree_util.tree_map(
        lambda *leaves: np.concatenate(leaves), *(cases for _, cases in groups)
    )
    flights = Structure("flights", _flight, (), {"flights": ()}, shared=world)
    return Study(name, lambda runs, seed: stacked, names, (flights,))


def build_world(
    legs, start, speed: float, blend: float, table: gnss.OrbitTable, size: StudySize = PAPER_SIZE
) -> World:
    """The tables of a flight: truth and IMU per epoch, the sky seen from its path."""
    flight = jaxfdi.ins.flight_tables(
        jaxfdi.ins.fly(legs, start, speed, blend=blend, rate=size.imu_rate), size.flight_s
    )
    path = gnss.geodetic_to_ecef(
        flight.position[:, 0], flight.position[:, 1], flight.position[:, 2]
    )
    times = START_TOW + jnp.arange(size.flight_s, dtype=path.dtype)
    visible, elevation, _ = jax.vmap(
        lambda t, x: gnss.visibility(table, t, x, math.radians(MASK_DEG))
    )(times, path)
    return World(
        table,
        gnss.raim_tables(int(table.prn.shape[0])),
        flight,
        visible,
        gnss.elevation_sigma(elevation),
    )


def receiver_slots(table, flight_s: int = FLIGHT_S) -> gnss.OrbitTable:
    """The table cut to the satellites above the mask less 1 deg seen from the park site in the flights' window (both
    flights stay within a few km: < 0.02 deg of elevation); every world then has the same slots (one program)."""
    site = gnss.geodetic_to_ecef(math.radians(PARK[0]), math.radians(PARK[1]), PARK[2])
    times = START_TOW + jnp.arange(flight_s, dtype=site.dtype)
    seen, _, _ = jax.vmap(lambda t: gnss.visibility(table, t, site, math.radians(MASK_DEG - 1.0)))(
        times
    )
    return jax.tree_util.tree_map(
        lambda leaf: leaf[np.flatnonzero(np.asarray(seen).any(axis=0))], table
    )


#: the two flights: legs, start (lat deg, lon deg, h m), speed m/s, blend s
_FLIGHTS = {
    "park": (jaxfdi.ins.park_legs, PARK, 12.0, 5.0),
    "manoeuvre": (
        jaxfdi.ins.manoeuvre_legs,
        (PARK[0], PARK[1], PARK[2] + MANOEUVRE_HEIGHT),
        25.0,
        2.0,
    ),
}


def flight_world(name: str, table=None, size: StudySize = PAPER_SIZE) -> World:
    """The world of the ``park`` or ``manoeuvre`` flight on the receiver's slots."""
    legs, start, speed, blend = _FLIGHTS[name]
    table = receiver_slots(_ephemeris(), size.flight_s) if table is None else table
    return build_world(legs(size.flight_s), start, speed, blend, table, size)


def headline_slot(world: World) -> int:
    """The satellite of Table 2's faults: the highest at the start among those in view for the whole flight (the GPS
    half's choice)."""
    visible = np.asarray(world.visible)
    candidates = np.flatnonzero(visible.all(axis=0))
    path = world.flight.position[0]
    origin = gnss.geodetic_to_ecef(path[0], path[1], path[2])
    elevation, _ = gnss.sky_geometry(world.table, START_TOW, origin)[:2]
    return int(candidates[np.argmax(np.asarray(elevation)[candidates])])


def satellite_faults(slot: int | None, before: int | None = None) -> Fault:
    """Table 2's three pseudorange episodes on ``slot`` (none when ``None``; only those that end before epoch ``before``
    when given, the others replaced by no fault)."""
    episodes = [
        no_fault()
        if slot is None or (before is not None and end >= before)
        else fault(kind, "sensor", slot, onset, magnitude, slope, end)
        for _, kind, onset, end, magnitude, slope in TABLE2_FAULTS
    ]
    return concat_faults(*episodes)


def imu_fault(
    channel: int | None, magnitude: float, onset_s: int = ONSET_S, kind: str = "bias"
) -> Fault:
    """A fault of ``kind`` (a bias of ``magnitude``; ``"dead"``, ``"stuck"``: the channel NaN or frozen) on one IMU
    channel from ``onset_s`` (none when ``channel`` is ``None``)."""
    if channel is None:
        return as_stack(no_fault())
    return as_stack(fault(kind, "sensor", channel, onset_s, magnitude))


def cases_of(specs, onset_s: int = ONSET_S) -> RunCase:
    """Stack ``(satellite slot or None, IMU channel or None, magnitude[, kind])`` specs as cases (kind ``"bias"`` by
    default); the satellite faults are Table 2's that end before ``onset_s``."""
    built = [
        RunCase(
            satellite_faults(slot, onset_s),
            imu_fault(channel, size, onset_s, *kind),
            jnp.asarray(NEVER if channel is None else onset_s, jnp.int32),
        )
        for slot, channel, size, *kind in specs
    ]
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *built)


def gps_ins_study(
    runs: int = 100,
    seed: int = 0,
    progress: bool = False,
    beyond: bool = True,
    size: StudySize = PAPER_SIZE,
    beyond_runs: int | None = None,
) -> GpsInsStudy:
    """Table 3 and the fault-free false alarms over ``runs`` flights per case, and (with ``beyond``) the detection-time
    curves and the manoeuvre flight over ``beyond_runs`` (default ``max(runs // 4, 2)``) flights per point; see the
    module doc. ``size``: the flights' length, the IMU fault's onset and the IMU rate (``PAPER_SIZE``: 1200 s, 800 s,
    100 Hz)."""
    require_x64("gps-ins")
    check_study(runs, seed)
    size = StudySize(*(int(v) for v in size))
    if not (0 < size.onset_s < size.flight_s and size.imu_rate >= 2):
        raise ValueError(f"size: expected 0 < onset_s < flight_s and imu_rate >= 2, got {size}")
    table = receiver_slots(_ephemeris(), size.flight_s)
    park = flight_world("park", table, size)
    slot = headline_slot(park)
    small = max(int(runs) // 4, 2) if beyond_runs is None else int(beyond_runs)
    groups = [("fault-free", None, None, 0.0, runs)]
    groups += [
        (f"table3 {b:g} deg/h", slot, ROLL_GYRO, b * jaxfdi.ins.DEG_PER_HOUR, runs)
        for b in TABLE3_DEG_H
    ]
    groups += [
        (f"imu roll gyro {name}", None, ROLL_GYRO, 0.0, small, kind)
        for name, kind in IMU_HEALTH_CASES.items()
    ]
    if beyond:
        groups += [
            (f"park gyro {b:g} deg/h", None, ROLL_GYRO, b * jaxfdi.ins.DEG_PER_HOUR, small)
            for b in BEYOND_GYRO_DEG_H
        ]
        groups += [
            (f"park accel {a:g} mg", None, X_ACCEL, a * jaxfdi.ins.MILLI_G, small)
            for a in BEYOND_ACCEL_MG
        ]
    worlds = {"park": park}
    plan = [("park", g) for g in groups]
    if beyond:
        worlds["manoeuvre"] = flight_world("manoeuvre", table, size)
        plan += [("manoeuvre", ("manoeuvre fault-free", None, None, 0.0, small))]
        plan += [
            (
                "manoeuvre",
                (
                    f"manoeuvre gyro {b:g} deg/h",
                    None,
                    ROLL_GYRO,
                    b * jaxfdi.ins.DEG_PER_HOUR,
                    small,
                ),
            )
            for b in TABLE3_DEG_H
        ]
    results = {}
    key = jax.random.key(seed)
    for flight, world in worlds.items():
        mine = [g for f, g in plan if f == flight]
        groups = [
            (name, cases_of([(s, c, m, *kind)] * n, size.onset_s))
            for name, s, c, m, n, *kind in mine
        ]
        counts = tuple(n for _, _, _, _, n, *_ in mine)
        spec = flights_spec(world, groups, f"gps-ins {flight}")
        if progress:
            status(
                f"gps-ins: {sum(counts)} {flight} flights of {size.flight_s} s at {size.imu_rate} Hz"
            )
        result = run_study(
            spec, counts, seed, progress=progress, key=jax.random.fold_in(key, len(results))
        )
        for (name, *_), part in zip(mine, case_slices(counts, len(mine))):
            results[name] = jax.tree_util.tree_map(lambda a: a[part], result.outputs["flights"])
    config = _config(runs, seed, small, beyond, slot, park.table, size)
    rows = _rows(results, size)
    curves = {}
    for row in rows:
        if row["case"] == "curve":
            curves.setdefault((row["flight"], row["sensor"]), []).append(row)
    series = {
        name: jax.tree_util.tree_map(lambda a: a[0], out.series) for name, out in results.items()
    }
    return GpsInsStudy(config, rows, series, curves, results)


def _config(runs, seed, small, beyond, slot, table, size: StudySize = PAPER_SIZE) -> dict:
    model = jaxfdi.ins.hg1900()
    chi2_limit, scst_limit = thresholds()
    return {
        "site_deg_m": PARK,
        "start": "2020-01-01 00:45:00 GPST",
        "week": WEEK,
        "start_tow_s": START_TOW,
        "flight_s": size.flight_s,
        "imu_rate_hz": size.imu_rate,
        "gps_rate_hz": 1,
        "runs": int(runs),
        "seed": int(seed),
        "beyond_runs": int(small) if beyond else None,
        "fault_onset_s": size.onset_s,
        "paper_size": size == PAPER_SIZE,
        "imu": {
            "model": "HG1900 class (Honeywell tactical-grade brochure values; ins.imu)",
            "accel_bias_mg": model.accel_bias / jaxfdi.ins.MILLI_G,
            "gyro_bias_deg_h": model.gyro_bias / jaxfdi.ins.DEG_PER_HOUR,
            "vrw_m_s_sqrt_h": model.velocity_random_walk * 60.0,
            "arw_deg_sqrt_h": math.degrees(model.angle_random_walk) * 60.0,
            "accel_bias_walk_mg_per_h": model.accel_bias_walk * 60.0 / jaxfdi.ins.MILLI_G,
            "gyro_bias_walk_deg_h_per_h": model.gyro_bias_walk * 60.0 / jaxfdi.ins.DEG_PER_HOUR,
            "scale_factors": "none (the 15-state filter does not model them)",
        },
        "velocity_sigma_m_s": VELOCITY_SIGMA,
        "initial_sigma": dict(
            zip(("position_m", "velocity_m_s", "tilt_deg", "heading_deg"), INITIAL_SIGMA)
        ),
        "chi2": {
            "window": CHI2_WINDOW,
            "dof": 6 * CHI2_WINDOW,
            "pfa": PFA,
            "threshold": chi2_limit,
        },
        "scst": {
            "dof": jaxfdi.ins.STATE_SIZE,
            "pfa": PFA,
            "threshold": scst_limit,
            "period_s": SCST_PERIOD,
            "max_condition": jaxfdi.ins.DEFAULT_MAX_CONDITION,
        },
        "raim": {
            "pfa": gnss.DEFAULT_PFA,
            "pmd": gnss.DEFAULT_PMD,
            "mask_deg": MASK_DEG,
            "operation": "npa",
        },
        "satellite_faults_prn": int(table.prn[slot]),
        "satellite_faults": [name for name, *_ in TABLE2_FAULTS],
        "table3_gyro_deg_h": list(TABLE3_DEG_H),
        "paper_table3_s": {f"{k:g}": list(v) for k, v in PAPER_TABLE3.items()},
        "beyond_gyro_deg_h": list(BEYOND_GYRO_DEG_H) if beyond else [],
        "beyond_accel_mg": list(BEYOND_ACCEL_MG) if beyond else [],
        "imu_health": {
            "window_samples": jaxfdi.ins.IMU_HEALTH_WINDOW,
            "pfa_per_window": jaxfdi.ins.IMU_HEALTH_PFA,
            "cases": list(IMU_HEALTH_CASES),
            "runs": int(small),
        },
    }


def _delays(record, name, size: StudySize = PAPER_SIZE) -> dict:
    """Detection time = first alarm at or after the onset minus the onset, over detecting clean runs (healthy, no alarm
    before the onset; an alarm standing at the onset: a false-alarm run, apart): mean, std, median, 10-90 %, range."""
    summary = summarize_detection(record, size.flight_s)
    delays = np.where(
        np.asarray(record.detection_step) >= 0,
        np.asarray(record.detection_step) - size.onset_s,
        np.nan,
    )
    healthy = np.asarray(record.first_unhealthy) < 0
    clean = healthy & (np.asarray(record.false_alarms) == 0)
    found = delays[clean & np.isfinite(delays)]
    pct = lambda q: float(np.percentile(found, q)) if found.size else None
    return {
        f"{name}_detected": summary.detection_rate,
        f"{name}_mean_s": float(found.mean()) if found.size else None,
        f"{name}_std_s": float(found.std(ddof=1)) if found.size > 1 else None,
        f"{name}_median_s": pct(50),
        f"{name}_p10_s": pct(10),
        f"{name}_p90_s": pct(90),
        f"{name}_min_s": float(found.min()) if found.size else None,
        f"{name}_max_s": float(found.max()) if found.size else None,
        f"{name}_false_alarm_runs": int(np.sum(np.asarray(record.false_alarms)[healthy] > 0)),
        f"{name}_clean_runs": int(clean.sum()),
        f"{name}_unhealthy_runs": summary.unhealthy_runs,
    }


def alarms_at(series: Series, test: str, threshold: float) -> np.ndarray:
    """(runs, T) the alarms of ``test`` (``"chi2"`` or ``"scst"``) at ``threshold`` from the stored statistics: the
    monitor's own rule (chi2: an epoch the EKF used; SCST: a valid epoch; statistic above the threshold), so the design
    threshold gives its records."""
    valid = np.asarray(series.gps_used if test == "chi2" else series.scst_valid)
    return valid & (np.asarray(getattr(series, test), np.float64) > threshold)


def _separated_record(out: RunOutput, test: str, size: StudySize, threshold: float | None = None):
    """The ``DetectionRecord`` of ``test``'s INS decisions (``ins_decisions``) at ``threshold`` (default: the design's),
    with the monitor's own health."""
    limit = dict(zip(("chi2", "scst"), thresholds()))[test] if threshold is None else threshold
    decisions = jnp.asarray(ins_decisions(out.series, test, limit))
    record = jax.vmap(record_from_alarms, in_axes=(0, None))(decisions, size.onset_s)
    return jax.tree_util.tree_map(
        np.asarray, record._replace(first_unhealthy=getattr(out, test).first_unhealthy)
    )


def raim_alarms(series: Series) -> np.ndarray:
    """(runs, T) RAIM's alarms (statistic above its threshold; a dead slot's is +inf)."""
    return np.asarray(series.raim) > np.asarray(series.raim_threshold)


def ins_decisions(series: Series, test: str, threshold: float) -> np.ndarray:
    """(runs, T) the INS's alarms of ``test`` at ``threshold`` after the GPS/INS separation
    (``integrity.attribute_ins_alarms``), at the epoch of the alarm (issued ``ATTRIBUTION_LOOKAHEAD`` s later)."""
    return np.asarray(
        jaxfdi.ins.attribute_ins_alarms(
            alarms_at(series, test, threshold),
            raim_alarms(series),
            ATTRIBUTION_LOOKAHEAD,
            ATTRIBUTION_HOLDOFF,
        )
    )


def operating_curve(results: dict, size: StudySize = PAPER_SIZE, pfas=OPERATING_PFA) -> list[dict]:
    """Each test at ``chi2_isf(dof, P_fa)`` for each per-epoch P_fa of ``pfas``, from the stored statistics: fault-free
    alarm rate per epoch and flights with an alarm (99 % interval); Table 3's detection time over clean runs per bias
    (``metrics.delay_statistics``) from the separated INS alarms (``ins_decisions``)."""
    free_out = results["fault-free"]
    rows = []
    for test, dof in (("chi2", 6 * CHI2_WINDOW), ("scst", jaxfdi.ins.STATE_SIZE)):
        # a flight that went numerically bad is counted apart, never as a clean one
        keep = np.asarray(getattr(free_out, test).first_unhealthy) < 0
        free = jax.tree_util.tree_map(lambda a: np.asarray(a)[keep], free_out.series)
        valid = np.asarray(free.gps_used if test == "chi2" else free.scst_valid)
        for pfa in pfas:
            threshold = float(_scipy_stats.chi2.isf(pfa, dof))
            alarms = alarms_at(free, test, threshold)
            flights = int(alarms.shape[0])
            with_alarm = int(np.sum(alarms.any(axis=1)))
            row = {
                "case": "operating-curve",
                "test": test,
                "pfa_per_epoch": pfa,
                "threshold": threshold,
                "fault_free_alarm_rate_per_epoch": float(alarms.sum() / max(valid.sum(), 1)),
                "fault_free_flights": flights,
                "fault_free_flights_with_an_alarm": with_alarm,
                "flight_alarm_interval_99": list(rate_interval(with_alarm, flights, 0.99)),
                "fault_free_unhealthy_flights": int(np.sum(~keep)),
                "table3": {},
            }
            for bias in TABLE3_DEG_H:
                record = _separated_record(results[f"table3 {bias:g} deg/h"], test, size, threshold)
                healthy = record.first_unhealthy < 0
                row["table3"][f"{bias:g}"] = {
                    **delay_statistics(
                        record.onset[healthy],
                        record.first_alarm[healthy],
                        record.detection_step[healthy],
                    ),
                    "unhealthy_runs": int(np.sum(~healthy)),
                }
            rows.append(row)
    return rows


def separation(results: dict, size: StudySize = PAPER_SIZE, pfa: float = PFA) -> dict:
    """GPS/INS separation over the Table 3 flights (Table 2's satellite faults, then the gyro bias) at per-epoch
    ``pfa``. Each fault is "GPS" (RAIM alarmed during it), "INS" (either test's INS decision from its onset to
    ``ATTRIBUTION_HOLDOFF`` s after its end; gyro bias: to the flight's end), both or neither; a flight is separated
    when its satellite faults are GPS only and its gyro bias INS only; numerically bad flights counted apart. Returns
    the confusion counts and the separated flights with their one-sided 95 % lower bound."""
    limits = {
        test: float(_scipy_stats.chi2.isf(pfa, dof))
        for test, dof in (("chi2", 6 * CHI2_WINDOW), ("scst", jaxfdi.ins.STATE_SIZE))
    }
    confusion: dict[str, dict[str, int]] = {}
    separated = flights = unhealthy = 0
    for bias in TABLE3_DEG_H:
        out = results[f"table3 {bias:g} deg/h"]
        # a flight that went numerically bad is counted apart, never as a separated one
        healthy = (np.asarray(out.chi2.first_unhealthy) < 0) & (
            np.asarray(out.scst.first_unhealthy) < 0
        )
        unhealthy += int(np.sum(~healthy))
        series = jax.tree_util.tree_map(lambda a: np.asarray(a)[healthy], out.series)
        ins = ins_decisions(series, "chi2", limits["chi2"]) | ins_decisions(
            series, "scst", limits["scst"]
        )
        gps = raim_alarms(series)
        steps = gps.shape[1]
        ok = np.ones(gps.shape[0], bool)
        episodes = [
            (name, onset, end) for name, _, onset, end, *_ in TABLE2_FAULTS if end < size.onset_s
        ]
        episodes.append((f"gyro bias {bias:g} deg/h", size.onset_s, steps))
        for name, onset, end in episodes:
            is_gps = not name.startswith("gyro")
            said_gps = gps[:, onset : max(end, onset + 1)].any(axis=1)
            said_ins = ins[
                :, onset : min(end + ATTRIBUTION_HOLDOFF, steps) if is_gps else steps
            ].any(axis=1)
            counts = confusion.setdefault(
                name.split(",")[0] if is_gps else "gyro bias",
                dict.fromkeys(("GPS only", "INS only", "both", "neither"), 0),
            )
            for key, sel in (
                ("GPS only", said_gps & ~said_ins),
                ("INS only", ~said_gps & said_ins),
                ("both", said_gps & said_ins),
                ("neither", ~said_gps & ~said_ins),
            ):
                counts[key] += int(sel.sum())
            ok &= (said_gps & ~said_ins) if is_gps else (said_ins & ~said_gps)
        separated += int(ok.sum())
        flights += int(ok.size)
    return {
        "case": "separation",
        "pfa_per_epoch": pfa,
        "lookahead_s": ATTRIBUTION_LOOKAHEAD,
        "holdoff_s": ATTRIBUTION_HOLDOFF,
        "confusion": confusion,
        "flights": flights,
        "unhealthy_flights": unhealthy,
        "separated_flights": separated,
        "separated_rate": separated / flights if flights else float("nan"),
        "lower_bound_95": binomial_lower_bound(separated, flights, 0.95),
    }


def paper_reading(curve: list[dict]) -> list[dict]:
    """For each test, the operating point whose mean detection times (clean runs) are closest to the paper's Table 3
    (least squares of the log ratios over the three biases, points with a mean at every bias only)."""
    rows = []
    for test, column in (("chi2", 0), ("scst", 1)):
        best = None
        for row in (r for r in curve if r["test"] == test):
            means = [row["table3"][f"{b:g}"]["delay_mean"] for b in TABLE3_DEG_H]
            if not all(np.isfinite(means)):
                continue
            misfit = float(
                np.sum(
                    np.log(np.asarray(means) / [PAPER_TABLE3[b][column] for b in TABLE3_DEG_H]) ** 2
                )
            )
            if best is None or misfit < best["log_misfit"]:
                best = {
                    "case": "paper-reading",
                    "test": test,
                    "pfa_per_epoch": row["pfa_per_epoch"],
                    "threshold": row["threshold"],
                    "mean_s": means,
                    "log_misfit": misfit,
                    "paper_s": [PAPER_TABLE3[b][column] for b in TABLE3_DEG_H],
                    "clean_runs": [row["table3"][f"{b:g}"]["clean_runs"] for b in TABLE3_DEG_H],
                }
        if best is not None:
            rows.append(best)
    return rows


def independent_decisions(series: Series) -> tuple[np.ndarray, np.ndarray]:
    """Samples of each statistic that are independent fault-free: the chi-square sum of non-overlapping windows (every
    ``CHI2_WINDOW``-th epoch once the window is full) and the SCST of every second propagator window (the epochs where
    propagator ``a`` is tested at the full age ``SCST_PERIOD``), (runs, samples) each."""
    chi2 = np.asarray(series.chi2)[:, 2 * CHI2_WINDOW - 1 :: CHI2_WINDOW]
    index = np.arange(SCST_PERIOD, np.shape(series.scst)[1], SCST_PERIOD)
    valid = np.asarray(series.scst_valid)[:, index]
    return chi2, np.where(valid, np.asarray(series.scst)[:, index], np.nan)


def _rows(results: dict, size: StudySize = PAPER_SIZE) -> list:
    rows = []
    chi2_limit, scst_limit = thresholds()
    free = results["fault-free"]
    chi2_samples, scst_samples = independent_decisions(free.series)
    for name, samples, limit, dof in (
        ("chi2", chi2_samples, chi2_limit, 6 * CHI2_WINDOW),
        ("scst", scst_samples, scst_limit, jaxfdi.ins.STATE_SIZE),
    ):
        finite = samples[np.isfinite(samples)]
        alarms = int(np.sum(finite > limit))
        low, high = binomial_interval(finite.size, PFA)
        all_epochs = np.asarray(getattr(free.series, name))
        valid = (
            np.asarray(free.series.scst_valid)
            if name == "scst"
            else np.asarray(free.series.gps_used)
        )
        rows.append(
            {
                "case": "false-alarm",
                "test": name,
                "runs": int(all_epochs.shape[0]),
                "independent_decisions": int(finite.size),
                "alarms": alarms,
                "rate": alarms / finite.size,
                "binomial_99_interval": [low, high],
                "design_pfa": PFA,
                "mean_statistic": float(finite.mean()),
                "dof": dof,
                "ks_pvalue_vs_chi2": float(_scipy_stats.kstest(finite, "chi2", args=(dof,)).pvalue),
                "alarms_per_flight": alarms / all_epochs.shape[0],
                "design_alarms_per_flight": finite.size / all_epochs.shape[0] * PFA,
                "alarm_rate_all_epochs": float(np.mean(all_epochs[valid] > limit)),
                "runs_with_an_alarm": int(np.sum(np.any((all_epochs > limit) & valid, axis=1))),
            }
        )
    rows.append(_error_row("fault-free", free.series))
    if any(name.startswith("table3") for name in results):
        curve = operating_curve(results, size)
        rows += curve + paper_reading(curve)
        rows += [separation(results, size, pfa) for pfa in SEPARATION_PFA]
    for name, out in results.items():
        base = {
            "runs": int(np.shape(out.chi2.onset)[0]),
            "scst_invalid_epochs": int(np.sum(~np.asarray(out.series.scst_valid))),
        }
        if name.startswith("imu roll gyro"):
            right = (np.asarray(out.health.detection_step) >= 0) & (
                np.asarray(out.health.isolated) == 1 + ROLL_GYRO
            )
            rows.append(
                {
                    "case": "imu-health",
                    "fault": name.split()[-1],
                    **base,
                    **_delays(out.health, "health", size),
                    "health_isolated": float(np.mean(right)),
                    **_delays(out.chi2, "chi2", size),
                    **_delays(out.scst, "scst", size),
                }
            )
        elif name.startswith("table3"):
            bias = float(name.split()[1])
            row = {
                "case": "table3",
                "gyro_deg_h": bias,
                **base,
                **_delays(_separated_record(out, "chi2", size), "chi2", size),
                **_delays(_separated_record(out, "scst", size), "scst", size),
                "paper_chi2_s": PAPER_TABLE3[bias][0],
                "paper_scst_s": PAPER_TABLE3[bias][1],
            }
            summary = summarize_episodes(out.raim, 1.0)
            row["raim"] = [
                {
                    "fault": fault[0],
                    "detected": float(summary.detection_rate[e]),
                    "isolated": float(summary.isolation_rate[e]),
                    "delay_median_s": float(summary.delay_median[e]),
                }
                for e, fault in enumerate(TABLE2_FAULTS)
                if fault[3] < size.onset_s
            ]
            row["raim_false_alarm_runs"] = int(summary.false_alarm_runs)
            row["ins_alarm_runs_during_gps_faults"] = _alarms_in_gps_windows(
                out.series, size.onset_s
            )
            rows.append(row)
        elif name != "fault-free":
            flight, sensor, *magnitude = name.split()
            if sensor == "fault-free":
                rows.append(
                    {
                        "case": "manoeuvre-false-alarm",
                        "flight": flight,
                        **base,
                        **_false_alarms(out.series, chi2_limit, scst_limit),
                    }
                )
                rows.append(_error_row("manoeuvre fault-free", out.series))
                continue
            rows.append(
                {
                    "case": "curve",
                    "flight": flight,
                    "sensor": sensor,
                    "size": float(magnitude[0]),
                    "unit": "deg/h" if sensor == "gyro" else "mg",
                    **base,
                    **_delays(out.chi2, "chi2", size),
                    **_delays(out.scst, "scst", size),
                }
            )
    return rows


def _false_alarms(series: Series, chi2_limit: float, scst_limit: float) -> dict:
    chi2, scst_samples = independent_decisions(series)
    scst_finite = scst_samples[np.isfinite(scst_samples)]
    return {
        "chi2_independent_rate": float(np.mean(chi2 > chi2_limit)),
        "chi2_decisions": int(chi2.size),
        "scst_independent_rate": float(np.mean(scst_finite > scst_limit)),
        "scst_decisions": int(scst_finite.size),
        "chi2_mean": float(chi2.mean()),
        "scst_mean": float(scst_finite.mean()),
        "chi2_runs_with_an_alarm": int(
            np.sum(np.any(np.asarray(series.chi2) > chi2_limit, axis=1))
        ),
        "scst_runs_with_an_alarm": int(
            np.sum(
                np.any(
                    (np.asarray(series.scst) > scst_limit) & np.asarray(series.scst_valid), axis=1
                )
            )
        ),
    }


def _alarms_in_gps_windows(series: Series, onset_s: int = ONSET_S) -> dict:
    chi2_limit, scst_limit = thresholds()
    found = {}
    for row in TABLE2_FAULTS:
        name, _, onset, end = row[:4]
        if end >= onset_s:  # not flown (a short study)
            continue
        window = slice(onset, min(end + 60, onset_s))  # the fault and the minute after it
        found[name] = {
            "chi2": int(np.sum(np.any(np.asarray(series.chi2)[:, window] > chi2_limit, axis=1))),
            "scst": int(
                np.sum(
                    np.any(
                        (np.asarray(series.scst)[:, window] > scst_limit)
                        & np.asarray(series.scst_valid)[:, window],
                        axis=1,
                    )
                )
            ),
        }
    return found


def _error_row(name: str, series: Series) -> dict:
    settled = slice(60, None)
    position = np.asarray(series.position_error)[:, settled]
    attitude = np.asarray(series.attitude_error)[:, settled]
    return {
        "case": "navigation-error",
        "flight": name,
        "horizontal_rms_m": float(np.sqrt(np.mean(position[..., 0] ** 2 + position[..., 1] ** 2))),
        "vertical_rms_m": float(np.sqrt(np.mean(position[..., 2] ** 2))),
        "tilt_rms_deg": float(np.sqrt(np.mean(attitude[..., 0] ** 2 + attitude[..., 1] ** 2))),
        "heading_rms_deg": float(np.sqrt(np.mean(attitude[..., 2] ** 2))),
        "gps_used_fraction": float(np.mean(np.asarray(series.gps_used))),
        "nees_mean": float(np.mean(np.asarray(series.nees)[:, settled])),
        "nees_dof": jaxfdi.ins.STATE_SIZE,
    }


def gps_ins_table(study: GpsInsStudy) -> str:
    """Table 3 beside the paper's, RAIM's decisions, false alarms, the curves."""
    cfg = study.config
    onset = cfg["fault_onset_s"]
    size_note = (
        ""
        if cfg.get("paper_size", True)
        else (f" [reduced size: {cfg['flight_s']} s flights, IMU {cfg['imu_rate_hz']} Hz]")
    )
    lines = [
        f"Table 3: roll-gyro bias from {onset} s, {cfg['runs']} flights per bias; detection time [s] = first "
        f"INS alarm at or after the onset minus {onset} (INS alarms: those RAIM does not explain, see the "
        f"operating curve), over the clean flights only (no INS alarm before the onset; the others are "
        f"false-alarm flights): mean +- sd (the paper's figure is a mean), median [10-90 %], clean flights; "
        f"paper beside{size_note}",
        f"  {'bias':>9}  {'chi-square mean':>15} {'paper':>6} {'median [10-90]':>16} {'clean':>5}   "
        f"{'SCST mean':>15} {'paper':>6} {'median [10-90]':>16} {'clean':>5}   detected chi2/SCST [95 %]",
    ]
    for row in (r for r in study.rows if r["case"] == "table3"):

        def mean(t):
            return f"{_cell(row[t + '_mean_s'], '.1f')} +- {_cell(row[t + '_std_s'], '.1f')}"

        def spread(t):
            low, high = _cell(row[t + "_p10_s"], ".0f"), _cell(row[t + "_p90_s"], ".0f")
            return f"{_cell(row[t + '_median_s'], '.0f')} [{low}-{high}]"

        healthy = row["runs"] - row["chi2_unhealthy_runs"]
        lines.append(
            f"  {row['gyro_deg_h']:>5g} d/h  {mean('chi2'):>15} {row['paper_chi2_s']:>6g} {spread('chi2'):>16} "
            f"{row['chi2_clean_runs']:>5}   {mean('scst'):>15} {row['paper_scst_s']:>6g} {spread('scst'):>16} "
            f"{row['scst_clean_runs']:>5}   {rate_cell(row['chi2_detected'], healthy, 0)}/"
            f"{rate_cell(row['scst_detected'], healthy, 0)}"
        )
    curve = [r for r in study.rows if r["case"] == "operating-curve"]
    if curve:
        lines.append(
            "Operating curve: each test at the threshold of a per-epoch P_fa, from the same flights' "
            "statistics: fault-free alarm rate per epoch, fault-free flights with an alarm [99 % interval], "
            "and Table 3's mean detection time over the clean flights (clean flights), the INS's alarms only: "
            f"an alarm with a RAIM alarm from {ATTRIBUTION_HOLDOFF} s before to {ATTRIBUTION_LOOKAHEAD} s after "
            f"it is the GPS's, and the INS decision is issued {ATTRIBUTION_LOOKAHEAD} s after the alarm"
        )
        for row in curve:
            cells = "  ".join(
                f"{b}: {_cell(v['delay_mean'], '.1f')} ({v['clean_runs']})"
                for b, v in row["table3"].items()
            )
            lo, hi = row["flight_alarm_interval_99"]
            lines.append(
                f"  {row['test']:<5} P_fa {row['pfa_per_epoch']:<7g} threshold {row['threshold']:7.2f}: "
                f"{row['fault_free_alarm_rate_per_epoch']:.2e}/epoch, flights "
                f"{row['fault_free_flights_with_an_alarm']}/"
                f"{row['fault_free_flights']} [{lo:.2f}, {hi:.2f}];  deg/h: {cells}"
            )
        for row in (r for r in study.rows if r["case"] == "paper-reading"):
            paper = "/".join(f"{v:g}" for v in row["paper_s"])
            ours = "/".join(_cell(v, ".0f") for v in row["mean_s"])
            lines.append(
                f"  the paper's {row['test']} times {paper} s are closest at P_fa {row['pfa_per_epoch']:g} per "
                f"epoch (threshold {row['threshold']:.2f}): ours {ours} s over "
                f"{'/'.join(str(c) for c in row['clean_runs'])} clean flights; the design P_fa is {PFA:g}"
            )
    for row in (r for r in study.rows if r["case"] == "separation"):
        cells = "; ".join(
            f"{name}: " + ", ".join(f"{k} {v}" for k, v in counts.items() if v)
            for name, counts in row["confusion"].items()
        )
        lines.append(
            f"GPS/INS separation at P_fa {row['pfa_per_epoch']:g} per epoch: "
            f"{row['separated_flights']}/{row['flights']} flights separated (>= {row['lower_bound_95']:.3f} "
            f"at 95 %); decided per fault: {cells}"
        )
    first = next(r for r in study.rows if r["case"] == "table3")
    lines.append(
        f"RAIM on Table 2's satellite faults (PRN {cfg['satellite_faults_prn']:02d}), same flights: "
        + (
            "; ".join(
                f"{r['fault']} detected {r['detected']:.2f}, median {_cell(r['delay_median_s'], '.0f')} s"
                for r in first["raim"]
            )
            or "none flown before the onset"
        )
    )
    alarms = "; ".join(
        f"{k}: chi2 {v['chi2']}, SCST {v['scst']}"
        for k, v in first["ins_alarm_runs_during_gps_faults"].items()
    )
    lines.append(
        f"  runs of those {first['runs']} ({first['gyro_deg_h']:g} deg/h) with an INS-test alarm during a satellite "
        f"fault or the minute after: {alarms}"
    )
    health = [r for r in study.rows if r["case"] == "imu-health"]
    if health:
        free = study.results.get("fault-free") if study.results else None
        quiet = (
            ""
            if free is None
            else (
                f"; fault-free flights with an IMU health alarm: "
                f"{int(np.sum(np.asarray(free.health.first_alarm) >= 0))}/"
                f"{np.shape(free.health.first_alarm)[0]}"
            )
        )
        lines.append(
            f"IMU health test (beyond the paper: stuck-at test over {jaxfdi.ins.IMU_HEALTH_WINDOW} samples, "
            f"P_fa {jaxfdi.ins.IMU_HEALTH_PFA:g} per window and channel; a NaN sample is a dead channel), roll "
            f"gyro from {onset} s, {health[0]['runs']} flights each{quiet}:"
        )
        for row in health:
            lines.append(
                f"  {row['fault']:<6}: detected {row['health_detected']:.2f}, isolated (roll gyro) "
                f"{row['health_isolated']:.2f}, median delay {_cell(row['health_median_s'], '.0f')} s; chi2 alone "
                f"detected {row['chi2_detected']:.2f} (median {_cell(row['chi2_median_s'], '.0f')} s), SCST "
                f"{row['scst_detected']:.2f} (median {_cell(row['scst_median_s'], '.0f')} s)"
            )
    lines.append(
        "Fault-free park flights (independent decisions: chi2 every 10th epoch, SCST one propagator window in "
        "two; 99 % binomial interval of the alarm count at P_fa 0.005):"
    )
    for row in (r for r in study.rows if r["case"] == "false-alarm"):
        lines.append(
            f"  {row['test']:<5} {row['alarms_per_flight']:.2f} alarms per flight (design "
            f"{row['design_alarms_per_flight']:.2f}); {row['alarms']:>3} alarms in "
            f"{row['independent_decisions']} decisions "
            f"(interval {row['binomial_99_interval'][0]}-{row['binomial_99_interval'][1]}), mean statistic "
            f"{row['mean_statistic']:.1f} (dof {row['dof']}), KS p {row['ks_pvalue_vs_chi2']:.2f}; all epochs "
            f"{row['alarm_rate_all_epochs']:.4f}, runs with an alarm {row['runs_with_an_alarm']}/{row['runs']}"
        )
    free = study.results.get("fault-free") if study.results else None
    if free is not None:
        valid = np.asarray(free.series.scst_valid)
        condition = np.asarray(free.series.scst_condition)
        lines.append(
            f"  SCST matrix B = P_m - P_f checked every epoch: {int(np.sum(~valid))} of {valid.size} fault-free "
            f"epochs flagged invalid (singular at a reset: {int(np.sum(np.isinf(condition)))}; condition > "
            f"{study.config['scst']['max_condition']:.0e}: {int(np.sum(~valid & np.isfinite(condition)))}); "
            f"no decision there"
        )
    for row in (r for r in study.rows if r["case"] == "navigation-error"):
        lines.append(
            f"  {row['flight']}: RMS horizontal {row['horizontal_rms_m']:.2f} m, vertical "
            f"{row['vertical_rms_m']:.2f} m, tilt {row['tilt_rms_deg']:.4f} deg, heading "
            f"{row['heading_rms_deg']:.3f} deg, mean NEES {row['nees_mean']:.1f} (15 states) after 60 s"
        )
    if study.curves:
        lines.append(
            f"Beyond the paper: detection time [s] vs bias size, median over {cfg['beyond_runs']} flights "
            f"(detected fraction), chi-square / SCST"
        )
        for (flight, sensor), rows in study.curves.items():
            cells = ", ".join(
                f"{r['size']:g}: {_cell(r['chi2_median_s'], '.0f')} ({r['chi2_detected']:.2f}) / "
                f"{_cell(r['scst_median_s'], '.0f')} ({r['scst_detected']:.2f})"
                for r in rows
            )
            lines.append(f"  {flight} {sensor} [{rows[0]['unit']}]: {cells}")
        for row in (r for r in study.rows if r["case"] == "manoeuvre-false-alarm"):
            lines.append(
                f"  manoeuvre flight, fault-free: chi2 false-alarm rate {row['chi2_independent_rate']:.4f} "
                f"(mean {row['chi2_mean']:.1f}), SCST {row['scst_independent_rate']:.4f} "
                f"(mean {row['scst_mean']:.1f}); runs with an alarm chi2 {row['chi2_runs_with_an_alarm']}, "
                f"SCST {row['scst_runs_with_an_alarm']} of {row['runs']}"
            )
    unhealthy = sum(r.get("chi2_unhealthy_runs", 0) for r in study.rows)
    if unhealthy:
        lines.append(
            f"WARNING: {unhealthy} runs went numerically bad; they are left out of the rates above"
        )
    return "\n".join(lines)


def plot_gps_ins(study: GpsInsStudy) -> dict[str, Any]:
    """Statistics vs thresholds (Yoo et al. 2010, Figs. 10-11), RAIM (Figs. 8-9), navigation errors, detection time vs
    bias size, and Table 3 along the threshold (the operating curve), captioned; returns them by file name
    (``plotting.save_figures`` writes them)."""
    add, figures = figure_collector()
    chi2_limit, scst_limit = thresholds()

    t = np.arange(study.config["flight_s"])
    onset = study.config["fault_onset_s"]
    fig = column_figure(5.4)
    for i, (field, limit, title) in enumerate(
        (
            ("chi2", chi2_limit, "windowed chi-square (10 epochs, 60 dof)"),
            ("scst", scst_limit, "SCST (15 dof)"),
        )
    ):
        ax = fig.add_subplot(2, 1, i + 1)
        for b in TABLE3_DEG_H:
            s = study.series[f"table3 {b:g} deg/h"]
            ax.semilogy(
                t,
                np.maximum(getattr(s, field), 1e-2),
                lw=0.8,
                label=f"{b:g} deg/h roll gyro from {onset} s",
            )
        ax.axhline(limit, color="k", lw=1.2, label=f"threshold {limit:.2f}")
        ax.axvline(onset, color="gray", ls=":")
        ax.set_title(f"{title} vs threshold (Yoo et al. 2010, Fig. {10 + i})")
        ax.set_ylabel(f"{field} statistic")
        ax.legend(fontsize=8, loc="upper left")
    ax.set_xlabel("time [s]")
    add(
        fig,
        "gps-ins-statistics.png",
        "One flight per roll-gyro bias: the windowed chi-square and SCST statistics against their thresholds (Yoo "
        "et al. 2010, Figs. 10-11, recorded data there, simulated here). Both also rise during "
        "Table 2's satellite drift "
        "(500-600 s) and after its exclusion: those alarms are the GPS's (the separation), not the INS's.",
    )

    s = study.series[f"table3 {TABLE3_DEG_H[0]:g} deg/h"]
    fig = column_figure(5.4)
    ax = fig.add_subplot(2, 1, 1)
    ax.plot(t, s.hdop, label="HDOP")
    twin = ax.twinx()
    twin.semilogy(t, s.hpl, color="C1", label="HPL")
    twin.axhline(556.0, color="C3", label="NPA HAL 556 m")
    ax.set_ylabel("HDOP")
    twin.set_ylabel("HPL [m]")
    # one legend for both y axes: HDOP (left) and HPL with its alert limit (right)
    handles, labels = [
        sum(pair, [])
        for pair in zip(ax.get_legend_handles_labels(), twin.get_legend_handles_labels())
    ]
    twin.legend(handles, labels, fontsize=8)
    ax.set_title("park flight: HDOP and HPL (Yoo et al. 2010, Fig. 8)")
    ax = fig.add_subplot(2, 1, 2)
    ax.semilogy(t, np.maximum(s.raim, 1e-3), label="TS_D")
    ax.set_ylabel("TS_D = p^T p (chi-square)")
    ax.semilogy(t, s.raim_threshold, color="C3", label="threshold")
    ax.plot(t, np.where(s.gps_used, np.nan, 1e-2), "k|", label="epoch not used by the EKF")
    for _, _, onset, end, _, _ in TABLE2_FAULTS:
        ax.axvspan(onset, max(end, onset + 3), color="gray", alpha=0.2)
    ax.set_title(
        f"RAIM statistic, satellite faults on PRN {study.config['satellite_faults_prn']:02d} "
        "(Yoo et al. 2010, Fig. 9)"
    )
    ax.legend(fontsize=8)
    ax.set_xlabel("time [s]")
    add(
        fig,
        "gps-ins-raim.png",
        "One flight (the 30 deg/h one above): HDOP and HPL (Yoo et al. 2010, Fig. 8) and RAIM's "
        "statistic with the epochs the EKF did not "
        "use (Fig. 9); Table 2's faults shaded. "
        + "; ".join(
            f"{r['fault'].split(',')[0]}: RAIM's median delay {_cell(r['delay_median_s'], '.0f')} s"
            for r in next((row["raim"] for row in study.rows if row["case"] == "table3"), [])
        )
        + f" ({study.config['runs']} flights). A slow fault reaches the filter before RAIM flags it.",
    )

    fig = column_figure(6.0)
    for i, (name, label) in enumerate(
        (("fault-free", "fault-free"), ("table3 60 deg/h", "60 deg/h roll gyro"))
    ):
        s = study.series[name]
        ax = fig.add_subplot(2, 2, 1 + i)
        ax.plot(
            t,
            np.hypot(s.position_error[:, 0], s.position_error[:, 1]),
            lw=0.8,
            label="horizontal error",
        )
        ax.plot(t, np.hypot(s.sigma[:, 0], s.sigma[:, 1]), "k--", lw=0.8, label="filter sigma")
        ax.set_ylabel("horizontal position error [m]")
        ax.set_title(f"position, {label}")
        ax.legend(fontsize=8)
        ax = fig.add_subplot(2, 2, 3 + i)
        for j, axis in enumerate("NED"):
            ax.plot(t, s.attitude_error[:, j], lw=0.8, label=f"psi_{axis}")
        ax.plot(t, s.sigma[:, 3], "k--", lw=0.8, label="sigma psi_N")
        ax.set_ylabel("attitude error [deg]")
        ax.set_xlabel("time [s]")
        ax.set_title(f"attitude error, {label}")
        ax.legend(fontsize=8)
    add(
        fig,
        "gps-ins-errors.png",
        "Position and attitude errors with the filter's 1-sigma over one flight each, fault-free and with the 60 "
        "deg/h gyro bias (beyond "
        "the paper, which shows no navigation errors).",
    )

    fig = column_figure(3.4)
    ax = fig.add_subplot(1, 2, 1)
    sizes = list(TABLE3_DEG_H)
    rows = [r for r in study.rows if r["case"] == "table3"]
    for test, marker, color in (("chi2", "o", "C0"), ("scst", "s", "C1")):
        ax.plot(
            sizes,
            [r[f"{test}_mean_s"] or np.nan for r in rows],
            marker + "-",
            color=color,
            label=f"{test} (mean)",
        )
        ax.plot(
            sizes,
            [r[f"paper_{test}_s"] for r in rows],
            marker + "--",
            mfc="none",
            color=color,
            label=f"{test} paper",
        )
    for (flight, sensor), curve in study.curves.items():
        if sensor == "gyro":
            for test in ("chi2", "scst"):
                ax.plot(
                    [r["size"] for r in curve],
                    [r[f"{test}_median_s"] or np.nan for r in curve],
                    ":",
                    marker=".",
                    label=f"{test}, {flight} curve",
                )
    ax.set_xlabel("roll-gyro bias [deg/h]")
    ax.set_ylabel("detection time [s]")
    ax.set_title("detection time vs gyro bias")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 2, 2)
    for (flight, sensor), curve in study.curves.items():
        if sensor == "accel":
            for test in ("chi2", "scst"):
                ax.plot(
                    [r["size"] for r in curve],
                    [r[f"{test}_median_s"] or np.nan for r in curve],
                    "o-",
                    label=f"{test}, {flight}",
                )
    ax.set_xscale("log")
    ax.set_xticks(BEYOND_ACCEL_MG, [f"{a:g}" for a in BEYOND_ACCEL_MG])
    ax.minorticks_off()
    ax.set_xlabel("x-accelerometer bias [mg]")
    ax.set_title("accelerometer bias (beyond the paper)")
    if study.curves:
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "not computed (beyond=False)", ha="center", transform=ax.transAxes)
    add(
        fig,
        "gps-ins-detection-times.png",
        f"Mean detection time over the clean flights of {study.config['runs']} flights per bias against the gyro bias "
        "beside the paper's Table 3, and, beyond it, the median against gyro and accelerometer "
        "bias sizes. The paper's chi-square times are "
        + ", ".join(
            f"{r['paper_chi2_s'] / r['chi2_mean_s']:.1f}x" for r in rows if r["chi2_mean_s"]
        )
        + " ours; its data were recorded, ours simulated (the operating curve; docs/papers/gnss-ins.md).",
    )

    curve = [r for r in study.rows if r["case"] == "operating-curve"]
    fig = column_figure(3.4)
    ax, right = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for test, style in (("chi2", "-"), ("scst", "--")):
        points = [r for r in curve if r["test"] == test]
        pfa = [r["pfa_per_epoch"] for r in points]
        for j, b in enumerate(TABLE3_DEG_H):
            ax.semilogx(
                pfa,
                [r["table3"][f"{b:g}"]["delay_mean"] for r in points],
                style,
                marker=".",
                color=f"C{j}",
                label=f"{test} {b:g} deg/h",
            )
            ax.axhline(PAPER_TABLE3[b][0 if test == "chi2" else 1], color=f"C{j}", ls=":", lw=0.8)
        right.semilogx(
            pfa,
            [r["fault_free_flights_with_an_alarm"] / r["fault_free_flights"] for r in points],
            style,
            marker=".",
            color="k",
            label=test,
        )
    for a in (ax, right):
        a.axvline(PFA, color="gray", lw=0.8)
        a.invert_xaxis()
        a.set_xlabel("per-epoch false-alarm probability of the threshold (design 0.005: grey)")
    ax.set_ylabel("mean detection time over clean flights [s]")
    reading = {r["test"]: r for r in study.rows if r["case"] == "paper-reading"}
    note = "; ".join(
        f"{t} closest at P_fa {r['pfa_per_epoch']:g}: {'/'.join(_cell(v, '.0f') for v in r['mean_s'])} s"
        for t, r in reading.items()
    )
    ax.set_title(f"Table 3 along the threshold; dotted: the paper's times\n{note}", fontsize=8)
    ax.legend(fontsize=7, ncol=2)
    right.set(
        ylabel="fault-free flights with an alarm",
        ylim=(-0.02, 1.02),
        title=f"false alarms over {study.config['runs']} fault-free flights",
    )
    right.legend(fontsize=8)
    add(
        fig,
        "gps-ins-operating-curve.png",
        f"Table 3 recomputed at thresholds from P_fa {OPERATING_PFA[0]:g} down to {OPERATING_PFA[-1]:g} per epoch "
        "(left, the paper's times dotted) and the fault-free flights with an alarm at each (right). The longest "
        "mean time at 30 deg/h on the curve is "
        + _cell(
            max(
                (
                    r["table3"]["30"]["delay_mean"]
                    for r in curve
                    if r["test"] == "chi2" and np.isfinite(r["table3"]["30"]["delay_mean"])
                ),
                default=None,
            ),
            ".0f",
        )
        + f" s (chi-square), against the paper's {PAPER_TABLE3[30.0][0]:g} s.",
    )
    return figures
