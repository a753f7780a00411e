"""The aircraft of Park et al. (2004): the Stevens & Lewis F-16 in closed loop, fault-free.

A flight (``run_flight``) is ``loop.run_loop`` of:

- plant ``control.f16_loop.f16_plant``: 13-state F-16 (book tables, xcg per flight), RK4 at
  ``DT`` = 0.01 s, noisy sensors (three 2-DOF rate sensors, sigma = 0.01 rad/s; air data, attitude, altitude,
  engine power), optional gusts, wrapped by ``tracking.tracked_plant`` (keeps tracking errors);
- FDI ``control.f16_loop.rate_passthrough_fdi``: no detection, least-squares body rates of the six
  rate channels (``scenarios.f16_fdi`` puts the parity-space FDI here);
- controller ``control.flight.flight_controller``: LQR SAS with altitude and bank-angle hold on the ``jax.jacfwd``
  linearisation about the level trim at 502 ft/s, sea level, xcg = 0.35 (Stevens & Lewis Table 3.6-3's first case).

Flight (Park, Kim, Park & Roh 2004, Sec. III; shapes in ``control.flight``): trimmed 120 ft/s climb 0-5 s, then altitude
hold and 30 deg bank turn 5-15 s. A study flies ``flights`` vmapped in one scan, each with its own noise, gusts, c.g.
(uniform in ``XCG_RANGE``) and initial offsets (``dispersions``; flight 0 nominal), and reports the book's trims beside
ours (one vmapped solve), open-loop modes, closed-loop poles and tracking errors.

References: Stevens & Lewis (2003) *Aircraft Control and Simulation*, 2nd ed.; Morelli (1998) "Global nonlinear
parametric modeling with application to F-16 aerodynamics"; Park, Kim, Park & Roh (2004).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import (
    Structure,
    Study,
    TrackingScore,
    checks,
    run_loop,
    run_study,
    study_result,
    tracked_plant,
)
from jaxfdi.control import (
    LATERAL_TRACKED,
    LONGITUDINAL_TRACKED,
    FlightGains,
    FlightPlan,
    FlightReference,
    FlightWeights,
    commanded_profile,
    default_weights,
    design_flight_control,
    f16_plant,
    flight_controller,
    flight_plan,
    flight_reference,
    initial_condition,
    integral_augmentation,
    plan_trims,
    rate_passthrough_fdi,
)
from jaxfdi.models import c2d, f16
from jaxfdi.models.f16 import (
    ALPHA,
    BETA,
    CONTROL_NAMES,
    LATERAL_STATES,
    LONGITUDINAL_DESIGN_STATES,
    PHI,
    STATE_NAMES,
    THETA,
    VT,
    F16Params,
    F16Sensors,
    H,
    P,
    Q,
    R,
    f16_params,
    f16_sensors,
    flight_modes,
    linearize,
    submodel,
)
from jaxfdi.plotting import column_figure, column_subplots
from jaxfdi.scenarios._common import check_study, figure_collector, require_x64

#: control period and RK4 step, s
DT = 0.01
#: c.g. range of the dispersed flights (fractions of cbar); the design is at 0.35
XCG_RANGE = (0.33, 0.37)
#: initial offsets of dispersed flights, uniform within +-: VT ft/s, alpha, beta, phi, theta rad, P, Q, R rad/s
INITIAL_SPREAD = {
    VT: 5.0,
    ALPHA: math.radians(0.5),
    BETA: math.radians(0.5),
    PHI: math.radians(2.0),
    THETA: math.radians(0.5),
    P: math.radians(2.0),
    Q: math.radians(1.0),
    R: math.radians(1.0),
}
#: gust velocity standard deviation of the study, ft/s (light turbulence)
GUST_SIGMA = 3.0
#: the tracking errors a run keeps (``TrackingScore`` components)
ERRORS = (
    "altitude_ft",
    "bank_deg",
    "altitude_climb_ft",
    "altitude_hold_ft",
    "bank_hold_deg",
    "sideslip_deg",
)
#: what each error is and when it is scored
ERROR_MEANING = {
    "altitude_ft": "h - h_cmd over the whole flight",
    "bank_deg": "phi - phi_cmd over the whole flight",
    "altitude_climb_ft": "h - h_cmd in the steady climb (before the level-off)",
    "altitude_hold_ft": "h - h_cmd in the altitude hold (after the level-off)",
    "bank_hold_deg": "phi - phi_cmd in the bank hold (after the roll-in)",
    "sideslip_deg": "beta over the whole flight (turn coordination)",
}


class FlightSetup(NamedTuple):
    """Everything a flight needs besides its key and dispersion (a pytree of arrays).

    Attributes:
      params: the aircraft's parameters
      sensors: the sensor layout and noise
      gains: the SAS gains
      reference: (T, ...) the per-step reference
      x0: (13,) initial state (the climb trim)
      u0: (4,) its controls
      gust_sigma: () ft/s, gust intensity
      phases: (3,) s: end of the climb, start of the altitude hold, start of the bank hold
    """

    params: F16Params
    sensors: F16Sensors
    gains: FlightGains
    reference: FlightReference
    x0: Array
    u0: Array
    gust_sigma: Array
    phases: Array


class Dispersion(NamedTuple):
    """One flight's departures from the nominal one (stack them to vmap).

    Attributes:
      xcg: () c.g. of this flight
      initial: (13,) added to the initial state
    """

    xcg: Array
    initial: Array


class FlightHistory(NamedTuple):
    """Per-step signals of a flight (``keep_history``).

    Attributes:
      state: (T, 15) true [x (13), w_g, v_g]
      control: (T, 4) controls [thtl, el, ail, rdr]
      measured_rates: (T, 3) the rates the controller flew on
      measurement: (T, 8 + m_r) y
      fdi: the FDI stage's per-step outputs (None for the rate pass-through)
    """

    state: Array
    control: Array
    measured_rates: Array
    measurement: Any = None
    fdi: Any = None


class Outcome(NamedTuple):
    """What a flight leaves for scoring: tracking errors, final state and health.

    Attributes:
      tracking: the tracking errors, one component per ``ERRORS`` entry
      final_state: (15,) true [x (13), w_g, v_g] at the end
      healthy: () bool: the flight stayed finite
      fdi: the FDI stage's final state (None for the rate pass-through)
    """

    tracking: TrackingScore
    final_state: Array
    healthy: Array
    fdi: Any = None


class Design(NamedTuple):
    """What the setup was built from (concrete, for reports).

    Attributes:
      plan: the flight
      trims: TrimResult (4,): level, climb, turn, pull-up
      linear: LinearF16 at the level trim
      design: FlightDesign, the gains and their checks
      weights: the LQR weights
    """

    plan: FlightPlan
    trims: object
    linear: object
    design: object
    weights: FlightWeights


_linearize = jax.jit(linearize)
_design = jax.jit(design_flight_control, static_argnums=1)
_reference = jax.jit(flight_reference, static_argnums=(1, 3, 4))


def flight_setup(
    plan: FlightPlan | None = None,
    weights: FlightWeights | None = None,
    params: F16Params | None = None,
    sensors: F16Sensors | None = None,
    gust_sigma: float = 0.0,
    dtype=None,
) -> tuple[FlightSetup, Design]:
    """Trims, linearisation, LQR design and reference of the flight (module doc)."""
    checks.check_scalar(
        "gust_sigma", gust_sigma, 0.0, meaning="a gust standard deviation >= 0 (ft/s)"
    )
    dtype = dtype or jnp.result_type(float)
    plan = plan or flight_plan()
    params = params or f16_params(dtype=dtype)
    weights = weights or default_weights(dtype)
    sensors = sensors or f16_sensors(dtype=dtype)
    trims = plan_trims(params, plan)
    # compiled once (eager, the Jacobians and the Riccati solves would dispatch op by op)
    linear = _linearize(params, trims.state[0], trims.control[0])
    design = _design(linear, DT, weights)
    radius = np.asarray(design.spectral_radius)
    if not np.all(radius <= 1.0):
        raise ValueError(
            f"weights: expected LQR weights whose design stabilises both axes, got closed-loop spectral "
            f"radii {radius.tolist()} (longitudinal, lateral)"
        )
    steps = int(round(plan.duration / DT))
    reference = _reference(params, plan, trims, DT, steps)
    x0, u0 = initial_condition(plan, trims)
    phases = jnp.asarray(
        [
            plan.climb_time - 0.5 * plan.level_off,
            plan.climb_time + 0.5 * plan.level_off,
            plan.bank_start + plan.roll_in,
        ],
        dtype,
    )
    setup = FlightSetup(
        params, sensors, design.gains, reference, x0, u0, jnp.asarray(gust_sigma, dtype), phases
    )
    return setup, Design(plan, trims, linear, design, weights)


def cast_setup(setup: FlightSetup, dtype) -> FlightSetup:
    """The setup with every float leaf in ``dtype`` (e.g. a float32 flight with the float64 design)."""
    return jax.tree_util.tree_map(
        lambda a: a.astype(dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a, setup
    )


def run_flight(
    setup: FlightSetup,
    key: Array,
    dispersion: Dispersion,
    keep_history: bool = False,
    fdi=None,
    fdi_state0: Any = None,
    fault=None,
):
    """One closed-loop flight; returns an ``Outcome`` (and a ``FlightHistory``). ``fdi``/``fdi_state0``: a
    ``loop.FDI`` whose ``observe`` returns a ``FlightView``, and its state (default: rate pass-through);
    ``fault``: plant faults (``f16_plant``), e.g. a ``faults.fault_group`` on both axes of a rate sensor."""
    checks.check_shape(
        "dispersion.initial", dispersion.initial, (13,), "an offset of the 13-state initial state"
    )
    checks.check_scalar(
        "dispersion.xcg",
        dispersion.xcg,
        0.0,
        1.0,
        meaning="a centre of gravity in [0, 1] of the mean chord",
    )
    dtype = setup.x0.dtype
    params = setup.params._replace(xcg=dispersion.xcg)
    plant = f16_plant(params, setup.sensors, DT, gust_sigma=setup.gust_sigma, fault=fault)
    if fdi is None:
        fdi = rate_passthrough_fdi(setup.sensors.rate_axes)
        fdi_state0 = fdi.init()
    steps = setup.reference.state.shape[0]
    reference = setup.reference
    degrees = 180.0 / math.pi

    def error(k, sensed):
        x = sensed.state
        h_err = x[H] - reference.state[k, H]
        phi_err = (x[PHI] - reference.state[k, PHI]) * degrees
        return jnp.stack([h_err, phi_err, h_err, h_err, phi_err, x[BETA] * degrees])

    def active(k):
        t = k * DT
        climbing, hold, bank = t < setup.phases[0], t >= setup.phases[1], t >= setup.phases[2]
        on = jnp.ones((), bool)
        return jnp.stack([on, on, climbing, hold, bank, on])

    tracked = tracked_plant(plant, error, len(ERRORS), active, dtype)
    controller = flight_controller(setup.gains, DT, params.control_lower, params.control_upper)
    x0 = jnp.concatenate([setup.x0 + dispersion.initial, jnp.zeros(2, dtype)])
    result = run_loop(
        tracked,
        fdi,
        controller,
        x0,
        fdi_state0,
        key,
        steps,
        exogenous=(reference.state, reference.control),
        u0=setup.u0,
        keep_history=keep_history,
    )
    (sim_state, score), fdi_state, _ = result.final
    outcome = Outcome(score, sim_state.state, jnp.all(jnp.isfinite(sim_state.state)), fdi_state)
    if not keep_history:
        return outcome
    trace = result.history
    return outcome, FlightHistory(
        trace.sensed.state, trace.control, trace.view.rates, trace.sensed.measurement, trace.output
    )


def run_flights(
    setup: FlightSetup, keys: Array, dispersions: Dispersion, keep_history: bool = False
):
    """``run_flight`` vmapped over keys and dispersions (the setup is shared)."""
    return jax.vmap(lambda key, d: run_flight(setup, key, d, keep_history))(keys, dispersions)


def nominal_dispersion(setup: FlightSetup, flights: int = 1) -> Dispersion:
    dtype = setup.x0.dtype
    return Dispersion(
        jnp.full((flights,), setup.params.xcg, dtype), jnp.zeros((flights, 13), dtype)
    )


def dispersions(
    key: Array, setup: FlightSetup, flights: int, xcg_range=XCG_RANGE, spread=None
) -> Dispersion:
    """``flights`` dispersions: c.g. uniform in ``xcg_range``, offsets within ``spread``; flight 0 nominal."""
    low, high = (float(v) for v in xcg_range)
    if not (np.isfinite(low) and np.isfinite(high) and 0.0 <= low <= high <= 1.0):
        raise ValueError(
            f"xcg_range: expected (low, high) with 0 <= low <= high <= 1 (fractions of the mean chord), "
            f"got {tuple(xcg_range)}"
        )
    dtype = setup.x0.dtype
    spread = INITIAL_SPREAD if spread is None else spread
    half = (
        jnp.zeros(13, dtype)
        .at[jnp.asarray(list(spread))]
        .set(jnp.asarray(list(spread.values()), dtype))
    )
    k_xcg, k_init = jax.random.split(key)
    xcg = jax.random.uniform(k_xcg, (flights,), dtype, *xcg_range)
    initial = half * jax.random.uniform(k_init, (flights, 13), dtype, -1.0, 1.0)
    return Dispersion(xcg.at[0].set(setup.params.xcg), initial.at[0].set(0.0))


# --- the study ---------------------------------------------------------------------


@study_result
class F16FlightStudy(NamedTuple):
    """The fault-free F-16 flight study: its settings, table rows and sample flights.

    Attributes:
      config: the study's settings
      rows: the table's rows, one dict each
      history: the sample flights' histories (NumPy), for the figures
    """

    config: dict
    rows: list[dict]
    history: dict

    def table(self) -> str:
        return study_table(self)


def _mode_row(mode, where: str) -> dict:
    names = (
        ("VT/V0", "alpha", "theta", "Q")
        if mode.name in ("short period", "phugoid")
        else ("beta", "phi", "P", "R")
    )
    return {
        "section": "mode",
        "where": where,
        "mode": mode.name,
        "roots": [[r.real, r.imag] for r in mode.roots],
        "natural_frequency_rad_s": mode.natural_frequency,
        "damping_ratio": mode.damping_ratio,
        "time_constant_s": mode.time_constant,
        "stable": mode.stable,
        "eigenvector_magnitudes": {
            "states": list(names),
            "per_root": [list(v) for v in mode.shapes],
        },
        "text": mode.describe(names),
    }


def _closed_loop_rows(design: Design) -> list[dict]:
    """Continuous-equivalent poles ``log(z) / DT`` of the two discrete LQR-PI loops."""
    rows = []
    gains = design.design.gains
    for axis, states, inputs, tracked, gain in (
        (
            "longitudinal",
            LONGITUDINAL_DESIGN_STATES,
            (0, 1),
            LONGITUDINAL_TRACKED,
            gains.longitudinal,
        ),
        ("lateral", LATERAL_STATES, (2, 3), LATERAL_TRACKED, gains.lateral),
    ):
        A, B = submodel(design.linear, states, inputs)
        Phi, Gamma = c2d(A, B, DT)
        H_track = np.eye(len(states))[list(tracked)]
        A_bar, B_bar, _ = integral_augmentation(Phi, Gamma, H_track, DT)
        z = np.linalg.eigvals(np.asarray(A_bar) - np.asarray(B_bar) @ np.asarray(gain))
        s = np.log(z.astype(complex)) / DT
        poles = sorted(s, key=lambda p: p.real)
        rows.append(
            {
                "section": "closed_loop",
                "axis": axis,
                "spectral_radius": float(np.max(np.abs(z))),
                "slowest_pole": float(np.max(s.real)),
                "poles": [[p.real, p.imag] for p in poles],
            }
        )
    return rows


def _tracking_rows(out: Outcome, plan: FlightPlan) -> list[dict]:
    score = jax.tree_util.tree_map(np.asarray, out.tracking)
    healthy = np.asarray(out.healthy)
    rms = np.sqrt(score.sum_sq / np.maximum(score.count, 1))
    rows = []
    for i, name in enumerate(ERRORS):
        peak, root = score.max_abs[healthy, i], rms[healthy, i]
        rows.append(
            {
                "section": "tracking",
                "error": name,
                "flights": int(healthy.sum()),
                "unhealthy_flights": int((~healthy).sum()),
                "nominal_max": float(score.max_abs[0, i]),
                "nominal_rms": float(rms[0, i]),
                "max_median": float(np.median(peak)),
                "max_p95": float(np.percentile(peak, 95)),
                "max_max": float(np.max(peak)),
                "rms_median": float(np.median(root)),
                "steps_scored": int(score.count[0, i]),
            }
        )
    return rows


def _dispersed_flight(key: Array, dispersion: Dispersion, setup: FlightSetup):
    """One flight (``run_flight``) in the study engine's order, the setup shared data."""
    return run_flight(setup, key, dispersion)


def f16_flight_study(
    flights: int = 100,
    seed: int = 0,
    progress: bool = False,
    gust_sigma: float = GUST_SIGMA,
    sample_flights: int = 8,
    chunk_size: int | None = None,
) -> F16FlightStudy:
    """Trims beside the book's, modes, LQR design, ``flights`` closed-loop flights; needs float64
    (``jaxfdi.enable_x64()``)."""
    require_x64("f16_flight_study")
    check_study(flights, seed, runs_name="flights", sample_flights=sample_flights)
    checks.check_scalar(
        "gust_sigma", gust_sigma, 0.0, meaning="a gust standard deviation >= 0 (ft/s)"
    )
    if chunk_size is not None:
        checks.check_int(
            "chunk_size", chunk_size, 1, meaning="a positive number of flights per call"
        )
    setup, design = flight_setup(gust_sigma=gust_sigma)
    params = setup.params
    cases = f16.book_cases()
    book_rows = [
        dict(row, section="trim")
        for row in f16.comparison_rows(f16.trim_book_cases(params, cases), cases)
    ]
    modes = [
        _mode_row(m, "open loop, level 502 ft/s, sea level, xcg 0.35")
        for m in flight_modes(design.linear)
    ]
    key_disp, key_noise = jax.random.split(jax.random.key(seed))
    disp = dispersions(key_disp, setup, int(flights))
    spec = Study(
        "f16-flight",
        lambda runs, seed: disp,
        ("dispersed flights",),
        (Structure("closed loop", _dispersed_flight, (), {"flights": ()}, shared=setup),),
    )
    out = run_study(
        spec, int(flights), seed, key=key_noise, chunk_size=chunk_size, progress=progress
    ).outputs["flights"]
    rows = book_rows + modes + _closed_loop_rows(design) + _tracking_rows(out, design.plan)
    k = min(int(sample_flights), int(flights))
    keys = jax.random.split(key_noise, int(flights))[:k]
    sample_disp = jax.tree_util.tree_map(lambda a: a[:k], disp)
    _, hist = jax.jit(lambda s, keys, d: run_flights(s, keys, d, keep_history=True))(
        setup, keys, sample_disp
    )
    profile = commanded_profile(design.plan, np.arange(setup.reference.state.shape[0]) * DT)
    history = {
        "t": np.arange(setup.reference.state.shape[0]) * DT,
        "state": np.asarray(hist.state),
        "control": np.asarray(hist.control),
        "measured_rates": np.asarray(hist.measured_rates),
        "reference_state": np.asarray(setup.reference.state),
        "altitude_cmd": np.asarray(profile.altitude),
        "bank_cmd": np.asarray(profile.bank),
        "xcg": np.asarray(sample_disp.xcg),
    }
    plan = design.plan
    config = {
        "flights": int(flights),
        "seed": int(seed),
        "dt_s": DT,
        "duration_s": plan.duration,
        "aero": "tables",
        "profile": "stevens_lewis_2nd_ed",
        "design_trim": {
            "airspeed_ft_s": plan.airspeed,
            "altitude_ft": plan.altitude,
            "xcg": float(params.xcg),
            "throttle": float(design.trims.control[0, 0]),
            "elevator_deg": float(design.trims.control[0, 1]),
            "alpha_deg": math.degrees(float(design.trims.state[0, ALPHA])),
        },
        "plan": {
            "climb_rate_ft_s": plan.climb_rate,
            "climb_time_s": plan.climb_time,
            "level_off_s": plan.level_off,
            "bank_angle_deg": math.degrees(plan.bank_angle),
            "bank_start_s": plan.bank_start,
            "roll_in_s": plan.roll_in,
        },
        "turn_trim_bank_deg": math.degrees(float(design.trims.state[2, PHI])),
        "weights": {
            name: np.asarray(getattr(design.weights, name)).tolist()
            for name in FlightWeights._fields
        },
        "sensor_sigma": {
            "rate_rad_s": float(setup.sensors.rate_sigma),
            "air_data_VT_ft_s_alpha_beta_rad": np.asarray(setup.sensors.air_data_sigma).tolist(),
            "attitude_rad": np.asarray(setup.sensors.attitude_sigma).tolist(),
            "altitude_ft": float(setup.sensors.altitude_sigma),
            "power_pct": float(setup.sensors.power_sigma),
        },
        "rate_channels": int(setup.sensors.rate_axes.shape[0]),
        "gust_sigma_ft_s": float(gust_sigma),
        "xcg_range": list(XCG_RANGE),
        "initial_spread": {STATE_NAMES[k]: v for k, v in INITIAL_SPREAD.items()},
        "errors": ERROR_MEANING,
        "spectral_radius": np.asarray(design.design.spectral_radius).tolist(),
        "controls": list(CONTROL_NAMES),
    }
    return F16FlightStudy(config, rows, history)


def study_table(study: F16FlightStudy) -> str:
    """The text the CLI prints: trims beside the book's, modes, closed-loop poles, tracking."""
    lines = ["Trim (ours | book; '*' = beyond half a unit of the book's last printed digit):"]
    for row in (r for r in study.rows if r["section"] == "trim"):
        cells = []
        for name, cell in row["cells"].items():
            if cell["symmetric_zero"]:
                cells.append(f"{name} {cell['ours']:.1e}|{cell['book']:.1e}")
                continue
            mark = "*" if cell["half_units"] > 1.0 else ""
            cells.append(f"{name} {cell['ours']:.6g}|{cell['book']:g}{mark}")
        lines.append(
            f"  {row['table']:<6} {row['case']:<37} "
            + "  ".join(cells)
            + f"  res {row['max_abs_residual']:.0e}"
        )
    lines.append("")
    lines.append("Open-loop modes at the design trim (502 ft/s, sea level, xcg 0.35):")
    lines += ["  " + r["text"] for r in study.rows if r["section"] == "mode"]
    lines.append(
        "Closed loop (LQR SAS + altitude/bank hold, continuous equivalents of the 100 Hz design):"
    )
    for r in (r for r in study.rows if r["section"] == "closed_loop"):
        lines.append(
            f"  {r['axis']:<12} spectral radius {r['spectral_radius']:.4f}, slowest pole "
            f"{r['slowest_pole']:.3f} 1/s ({'stable' if r['spectral_radius'] < 1 else 'UNSTABLE'})"
        )
    lines.append("")
    cfg = study.config
    lines.append(
        f"Tracking over {cfg['flights']} flights (sensor noise, gusts {cfg['gust_sigma_ft_s']} ft/s, xcg "
        f"{cfg['xcg_range'][0]}-{cfg['xcg_range'][1]}, initial offsets; flight 1 nominal):"
    )
    head = f"  {'error':<18} {'nominal max':>11} {'nominal rms':>11} {'max: median':>11} {'p95':>8} {'worst':>8}"
    lines += [head, "  " + "-" * (len(head) - 2)]
    for r in (r for r in study.rows if r["section"] == "tracking"):
        lines.append(
            f"  {r['error']:<18} {r['nominal_max']:>11.2f} {r['nominal_rms']:>11.2f} {r['max_median']:>11.2f} "
            f"{r['max_p95']:>8.2f} {r['max_max']:>8.2f}"
        )
    bad = [r for r in study.rows if r["section"] == "tracking" and r["unhealthy_flights"]]
    if bad:
        lines.append(
            f"WARNING: {bad[0]['unhealthy_flights']} flight(s) went non-finite and are left out"
        )
    return "\n".join(lines)


def plot_f16_flight(study: F16FlightStudy) -> dict[str, Any]:
    """Trajectory and time histories of the sample flights, captioned; returns them by file name
    (``plotting.save_figures`` writes them)."""
    add, figures = figure_collector()
    h = study.history
    t, state, control = h["t"], h["state"], h["control"]

    fig = column_figure(3.6)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax = fig.add_subplot(1, 2, 2)
    for i in range(state.shape[0]):
        style = dict(lw=1.6, color="C0") if i == 0 else dict(lw=0.7, color="grey", alpha=0.6)
        ax3.plot(state[i, :, 10], state[i, :, 9], state[i, :, H], **style)
        ax.plot(state[i, :, 10], state[i, :, 9], **style)
    ax3.set(
        xlabel="east [ft]",
        ylabel="north [ft]",
        zlabel="altitude [ft]",
        title="trajectory (nominal in blue)",
    )
    ax.set(xlabel="east [ft]", ylabel="north [ft]", title="ground track")
    ax.set_aspect("equal", adjustable="datalim")
    add(
        fig,
        "f16-flight-trajectory.png",
        f"{state.shape[0]} sample flights of the study (dispersed c.g., initial offsets and "
        "gusts; the nominal one in blue) flying "
        "the paper's manoeuvre: climb, level-off, 30 deg bank turn. Park et al. (2004) describe the "
        "manoeuvre but show no trajectory.",
    )

    fig, axes = column_subplots(8.5, 4, 2, sharex=True)
    deg = 180.0 / math.pi
    ref = h["reference_state"]
    panels = [  # (axis, label, value of a (T, 15) history, the command or reference)
        (axes[0, 0], "altitude [ft]", lambda x: x[:, H], h["altitude_cmd"]),
        (axes[0, 1], "bank angle [deg]", lambda x: x[:, PHI] * deg, h["bank_cmd"] * deg),
        (axes[1, 0], "airspeed [ft/s]", lambda x: x[:, VT], ref[:, VT]),
        (axes[1, 1], "pitch angle [deg]", lambda x: x[:, THETA] * deg, ref[:, THETA] * deg),
        (axes[2, 0], "angle of attack [deg]", lambda x: x[:, ALPHA] * deg, ref[:, ALPHA] * deg),
        (axes[2, 1], "sideslip [deg]", lambda x: x[:, BETA] * deg, None),
    ]
    for ax, label, value, command in panels:
        for i in range(1, state.shape[0]):
            ax.plot(t, value(state[i]), color="grey", lw=0.5, alpha=0.5)
        ax.plot(t, value(state[0]), color="C0", lw=1.2, label="nominal flight")
        if command is not None:
            ax.plot(t, command, "k--", lw=1, label="command / reference")
        ax.set(ylabel=label)
        ax.legend(fontsize=7)
    nominal = state[0]
    for j, name in enumerate("PQR"):
        axes[3, 0].plot(
            t,
            h["measured_rates"][0, :, j] * deg,
            color=f"C{j}",
            lw=0.4,
            alpha=0.5,
            label=f"{name} flown on",
        )
        axes[3, 0].plot(t, nominal[:, P + j] * deg, color=f"C{j}", lw=1.2, label=f"{name} true")
    axes[3, 0].set(ylabel="body rates [deg/s]", xlabel="time [s]")
    axes[3, 0].legend(fontsize=6, ncol=3)
    for j, name in enumerate(["throttle x 10", "elevator", "aileron", "rudder"]):
        axes[3, 1].plot(t, control[0, :, j] * (10.0 if j == 0 else 1.0), lw=0.7, label=name)
    axes[3, 1].set(ylabel="controls [deg]", xlabel="time [s]")
    axes[3, 1].legend(fontsize=7)
    fig.suptitle("Park et al. (2004): climb 0-5 s, altitude hold, 30 deg bank turn")
    add(
        fig,
        "f16-flight-time-histories.png",
        f"Time histories of the same {state.shape[0]} flights (the nominal one in blue, the others grey) against "
        "the commanded profile (altitude, bank, airspeed, angles, body rates, controls); 'flown on' is the rate the "
        "controller flies on, the least-squares fit of the six sensor channels. Beyond the paper, "
        "which flies its aircraft only to feed the rate sensors.",
    )
    return figures
