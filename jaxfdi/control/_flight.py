"""F-16 flight control for the flight of Park et al. (2004): LQR stability augmentation with altitude and bank-angle
hold on the linearised model (Park, Kim, Park & Roh 2004, Sec. III; Stevens & Lewis 2003, ch. 4 and 5).

Design (``design_flight_control``): the linear model about a wings-level trim
(``models.f16.linearize``), zero-order hold at ``dt`` (``models.c2d``), one LQR-PI per axis
(``control.lqr_pi``: ``u = -K [dx; z]``, ``z[k+1] = z[k] + dt (r - H x)``, Lee & Lyou eqs. 21-22;
diagonal ``FlightWeights``), keeping the two SAS separate as the paper does:

- longitudinal ``x_lon = [VT, alpha, theta, Q, h, pow]``, ``u_lon = [thtl, el]``, integral on ``[VT, h]``;
- lateral ``x_lat = [beta, phi, P, R]``, ``u_lat = [ail, rdr]``, integral on ``phi``.

Feedback on ``(alpha, Q)``, ``(beta, P, R)`` is the SAS; on ``h``, ``phi`` and integrals the holds.

Law (``flight_controller``): ``u = clip(u_ref - K (x_meas - x_ref) - K_I z)`` (throttle 0-1, surfaces in deg) about
``flight_reference``; ``x_meas`` from the ``FlightView``, ``P, Q, R`` from ``view.rates`` (the FDI stage's selected
rate, so a missed rate-sensor fault reaches the aircraft). Integrators stop while their axis's controls are at a limit
(conditional integration: no wind-up of a saturated throttle in the climb).

Flight (``FlightPlan``): 502 ft/s from sea level, xcg = 0.35 (the book's trim), starting trimmed in a
120 ft/s climb for 0-5 s, then altitude hold and a bank turn 5-15 s. Smoothstep ``S(s) = 3 s^2 - 2 s^3``
shapes the level-off (120 -> 0 ft/s over ``level_off`` s centred on t = 5 s; 600 ft gained) and the
roll-in (to 30 deg over ``roll_in`` s from t = 5 s). Peak normal-load change ``1.5 x 120 / (g T)``
for a level-off in ``T`` s: 1.4 g for T = 4 s, whatever the airspeed (the paper's flight is brisk).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.stages import Controller
from jaxfdi.control._lqr import lqr_pi
from jaxfdi.models import c2d
from jaxfdi.models.f16 import (
    AIL,
    ALPHA,
    EL,
    LATERAL_STATES,
    LONGITUDINAL_DESIGN_STATES,
    PHI,
    RDR,
    THETA,
    THTL,
    F16Params,
    FlightView,
    H,
    LinearF16,
    P,
    Q,
    TrimResult,
    climb,
    coordinated_turn,
    level_flight,
    pull_up,
    submodel,
    trim_batch,
)

#: tracked outputs of each axis (indices into its design states)
LONGITUDINAL_TRACKED = (0, 4)  # VT, h
LATERAL_TRACKED = (1,)  # phi


class FlightWeights(NamedTuple):
    """Diagonal LQR weights (a pytree: differentiate the flight with respect to it).

    Attributes:
      longitudinal: (8,) VT, alpha, theta, Q, h, pow, int VT, int h
      longitudinal_input: (2,) thtl, el
      lateral: (5,) beta, phi, P, R, int phi
      lateral_input: (2,) ail, rdr
    """

    longitudinal: Array
    longitudinal_input: Array
    lateral: Array
    lateral_input: Array


class FlightGains(NamedTuple):
    """The F-16 SAS gains: longitudinal and lateral LQR gains with integral states.

    Attributes:
      longitudinal: (2, 8) u_lon = -K [dx_lon (6); z_lon (2)]
      lateral: (2, 5) u_lat = -K [dx_lat (4); z_lat (1)]
    """

    longitudinal: Array
    lateral: Array


class FlightDesign(NamedTuple):
    """An F-16 flight-control design: gains, closed-loop spectral radii and Riccati convergence flags.

    Attributes:
      gains: the longitudinal and lateral LQR gains
      spectral_radius: (2,) max |eig| of the discrete closed loops (lon, lat): < 1 is stable
      converged: (2,) Riccati solver flags
    """

    gains: FlightGains
    spectral_radius: Array
    converged: Array


class FlightPlan(NamedTuple):
    """The flight of Park et al. (2004) (defaults of ``flight_plan``).

    Attributes:
      airspeed: ft/s, trim airspeed
      altitude: ft, initial
      climb_rate: ft/s, rate of the initial climb
      climb_time: s, end of the climb (middle of the level-off)
      level_off: s, duration of the level-off (climb rate 120 -> 0 ft/s)
      bank_angle: rad, bank angle of the turn
      bank_start: s, start of the roll-in
      roll_in: s, duration of the roll-in
      duration: s, length of the flight
    """

    airspeed: float
    altitude: float
    climb_rate: float
    climb_time: float
    level_off: float
    bank_angle: float
    bank_start: float
    roll_in: float
    duration: float


class FlightReference(NamedTuple):
    """Per-step reference (T rows): the state and controls the flight should have.

    Attributes:
      state: (T, 13) reference state
      control: (T, 4) reference controls
    """

    state: Array
    control: Array


class FlightControllerState(NamedTuple):
    """The SAS controller's carry: its integrator states.

    Attributes:
      longitudinal_integral: (2,) int (VT_ref - VT), int (h_ref - h) dt
      lateral_integral: (1,) int (phi_ref - phi) dt
    """

    longitudinal_integral: Array
    lateral_integral: Array


def flight_plan(
    airspeed: float = 502.0,
    altitude: float = 0.0,
    climb_rate: float = 120.0,
    climb_time: float = 5.0,
    level_off: float = 4.0,
    bank_angle_deg: float = 30.0,
    bank_start: float = 5.0,
    roll_in: float = 2.0,
    duration: float = 15.0,
) -> FlightPlan:
    """The flight of Park et al. (2004) at the book's 502 ft/s sea-level trim (module doc).

    Returns:
      ``FlightPlan`` of Python floats: speeds in ft/s, altitude in ft, times in s, ``bank_angle`` in rad.
    """
    for name, value in (
        ("airspeed", airspeed),
        ("altitude", altitude),
        ("climb_rate", climb_rate),
        ("climb_time", climb_time),
        ("level_off", level_off),
        ("bank_angle_deg", bank_angle_deg),
        ("bank_start", bank_start),
        ("roll_in", roll_in),
        ("duration", duration),
    ):
        checks.check_scalar(name, value, meaning="a real number")
    if not (airspeed > 0 and duration > 0 and level_off > 0 and roll_in > 0):
        raise ValueError(
            "airspeed, duration, level_off, roll_in: expected positive values, got "
            f"{airspeed}, {duration}, {level_off}, {roll_in}"
        )
    if not abs(climb_rate) < airspeed:
        raise ValueError(
            f"climb_rate: expected |climb_rate| < airspeed {airspeed}, got {climb_rate}"
        )
    if not 0.5 * level_off <= climb_time:
        raise ValueError(
            f"level_off: expected at most 2 climb_time = {2 * climb_time} s, got {level_off}"
        )
    return FlightPlan(
        float(airspeed),
        float(altitude),
        float(climb_rate),
        float(climb_time),
        float(level_off),
        math.radians(bank_angle_deg),
        float(bank_start),
        float(roll_in),
        float(duration),
    )


def bryson_weights(
    longitudinal, longitudinal_input, lateral, lateral_input, dtype=None
) -> FlightWeights:
    """Bryson's rule: weight ``1 / (largest acceptable value)^2`` (angles in rad, surfaces in deg)."""
    dtype = dtype or jnp.result_type(float)
    inv_sq = lambda v: 1.0 / jnp.asarray(v, dtype) ** 2
    return FlightWeights(
        inv_sq(longitudinal), inv_sq(longitudinal_input), inv_sq(lateral), inv_sq(lateral_input)
    )


def default_weights(dtype=None) -> FlightWeights:
    """``bryson_weights`` of: VT 10 ft/s, alpha 2 deg, theta 5 deg, Q 20 deg/s, h 20 ft, pow 30 %, int VT 20 ft, int h
    20 ft s; thtl 0.3, el 5 deg; beta 2 deg, phi 5 deg, P 45 deg/s, R 20 deg/s, int phi 5 deg s; ail 15 deg, rdr 20 deg.
    Chosen on 64 dispersed flights (noise, gusts) for altitude errors < 10 ft, bank errors < 1 deg once rolled in,
    control noise ~1 deg per sample.

    Returns:
      ``FlightWeights`` in ``dtype`` (default float): longitudinal (8,), longitudinal_input (2,), lateral (5,),
      lateral_input (2,).
    """
    deg = math.pi / 180.0
    return bryson_weights(
        [10.0, 2 * deg, 5 * deg, 20 * deg, 20.0, 30.0, 20.0, 20.0],
        [0.3, 5.0],
        [2 * deg, 5 * deg, 45 * deg, 20 * deg, 5 * deg],
        [15.0, 20.0],
        dtype,
    )


def design_flight_control(linear: LinearF16, dt: float, weights: FlightWeights) -> FlightDesign:
    """LQR-PI gains of both axes at the trim of ``linear`` (module doc); differentiable in ``weights``
    (forward mode through the Riccati solver).

    Returns:
      ``FlightDesign``: ``FlightGains`` (lon (2, 8), lat (2, 5)), each closed loop's spectral radius (2,)
      (< 1 is stable) and the Riccati ``converged`` flags (2,).
    """
    checks.check_positive("dt", dt, "a positive sample period (s)")
    checks.check_shape(
        "weights.longitudinal",
        weights.longitudinal,
        (8,),
        "VT, alpha, theta, Q, h, pow, int VT, int h",
    )
    checks.check_shape("weights.longitudinal_input", weights.longitudinal_input, (2,), "thtl, el")
    checks.check_shape("weights.lateral", weights.lateral, (5,), "beta, phi, P, R, int phi")
    checks.check_shape("weights.lateral_input", weights.lateral_input, (2,), "ail, rdr")
    for name, low_open in (
        ("longitudinal", False),
        ("longitudinal_input", True),
        ("lateral", False),
        ("lateral_input", True),
    ):
        value = checks.concrete(getattr(weights, name))  # traced when differentiated: unchecked
        if value is not None and not (
            np.all(np.isfinite(value)) and np.all(value > 0 if low_open else value >= 0)
        ):
            raise ValueError(
                f"weights.{name}: expected finite LQR weights {'> 0' if low_open else '>= 0'}, got "
                f"{checks.received(value)}"
            )
    dtype = weights.longitudinal.dtype
    designs = []
    for states, inputs, tracked, q, r in (
        (
            LONGITUDINAL_DESIGN_STATES,
            (THTL, EL),
            LONGITUDINAL_TRACKED,
            weights.longitudinal,
            weights.longitudinal_input,
        ),
        (LATERAL_STATES, (AIL, RDR), LATERAL_TRACKED, weights.lateral, weights.lateral_input),
    ):
        A, B = submodel(linear, states, inputs)
        Phi, Gamma = c2d(A, B, dt, dtype=dtype)
        H = jnp.eye(len(states), dtype=dtype)[jnp.asarray(tracked)]
        designs.append(lqr_pi(Phi, Gamma, H, jnp.diag(q), jnp.diag(r), dt))
    lon, lat = designs
    return FlightDesign(
        FlightGains(lon.gain, lat.gain),
        jnp.stack([lon.spectral_radius, lat.spectral_radius]),
        jnp.stack([lon.converged, lat.converged]),
    )


#: load factor of the pull-up trim that gives the controls per g (``plan_trims``)
PULL_UP_LOAD = 2.0


def plan_trims(params: F16Params, plan: FlightPlan) -> TrimResult:
    """The reference's trims, stacked (4,): level at the initial altitude; climb ``gamma =
    asin(climb_rate / VT)`` half-way up; coordinated turn at the final altitude, rate ``g tan(phi) / VT``;
    wings-level pull-up at ``PULL_UP_LOAD`` g (pitch rate ``g (n - 1) / VT``), giving alpha and elevator per g.

    Returns:
      ``TrimResult`` stacked over the 4 trims (level, climb, turn, pull-up), ``state`` (4, 13) and ``control`` (4, 4),
      all at ``params.xcg`` (``trim_batch``).
    """
    dtype = params.mass.dtype
    top = plan.altitude + plan.climb_rate * plan.climb_time
    gamma = math.asin(plan.climb_rate / plan.airspeed)
    turn_rate = float(params.gravity) * math.tan(plan.bank_angle) / plan.airspeed
    conditions = [
        level_flight(plan.airspeed, plan.altitude, dtype),
        climb(plan.airspeed, gamma, 0.5 * (plan.altitude + top), dtype),
        coordinated_turn(plan.airspeed, turn_rate, top, dtype=dtype),
        pull_up(
            plan.airspeed,
            float(params.gravity) * (PULL_UP_LOAD - 1.0) / plan.airspeed,
            plan.altitude,
            dtype=dtype,
        ),
    ]
    stacked = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *conditions)
    return trim_batch(params, stacked, jnp.full((len(conditions),), params.xcg, dtype))


def _check_trims(trims: TrimResult) -> None:
    """``trims`` must be ``plan_trims``' stack of 4 (fewer rows would be silently clamped to the last)."""
    checks.check_shape(
        "trims.state", trims.state, (4, 13), "plan_trims' level, climb, turn and pull-up trims"
    )
    checks.check_shape(
        "trims.control", trims.control, (4, 4), "plan_trims' level, climb, turn and pull-up trims"
    )


def initial_condition(plan: FlightPlan, trims: TrimResult) -> tuple[Array, Array]:
    """``(x0 (13,), u0 (4,))``: the climb trim at the plan's initial altitude.

    Returns:
      ``(x0, u0)``: the climb trim's state (13,) with ``h`` set to ``plan.altitude`` [ft], and its controls (4,)
      ``[thtl, el, ail, rdr]``.
    """
    _check_trims(trims)
    return trims.state[1].at[H].set(plan.altitude), trims.control[1]


def _smoothstep(s: Array) -> Array:
    s = jnp.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _smoothstep_rate(s: Array) -> Array:
    """``dS/ds``."""
    inside = (s > 0.0) & (s < 1.0)
    return jnp.where(inside, 6.0 * s * (1.0 - s), 0.0)


def _smoothstep_integral(t: Array, width: float) -> Array:
    """``int_0^t S(tau / width) dtau`` (0 for ``t <= 0``)."""
    s = jnp.clip(t / width, 0.0, 1.0)
    return width * (s**3 - 0.5 * s**4) + jnp.maximum(t - width, 0.0)


class Profile(NamedTuple):
    """The commanded flight at times ``t`` (``commanded_profile``).

    Attributes:
      climb_weight: share of the climb segment (1 -> 0 over the level-off)
      bank_weight: share of the turn segment (0 -> 1 over the roll-in)
      climb_rate: d climb_weight / dt
      bank_rate: d bank_weight / dt
      altitude: commanded h
      bank: commanded phi
    """

    climb_weight: Array
    bank_weight: Array
    climb_rate: Array
    bank_rate: Array
    altitude: Array
    bank: Array


def commanded_profile(plan: FlightPlan, t: Array) -> Profile:
    """Commanded climb and bank at ``t``: level-off over ``climb_time -/+ level_off/2`` (gaining
    ``climb_rate x climb_time`` ft in all), roll-in over ``[bank_start, bank_start + roll_in]``.

    Returns:
      ``Profile`` with ``t``'s shape: segment weights (0-1) and their rates [1/s], commanded altitude [ft] and
      bank angle [rad].
    """
    t = jnp.asarray(t)
    start = plan.climb_time - 0.5 * plan.level_off
    s_climb = (t - start) / plan.level_off
    s_bank = (t - plan.bank_start) / plan.roll_in
    climb_weight = 1.0 - _smoothstep(s_climb)
    bank_weight = _smoothstep(s_bank)
    climbed = t - _smoothstep_integral(t - start, plan.level_off)
    return Profile(
        climb_weight,
        bank_weight,
        -_smoothstep_rate(s_climb) / plan.level_off,
        _smoothstep_rate(s_bank) / plan.roll_in,
        plan.altitude + plan.climb_rate * climbed,
        plan.bank_angle * bank_weight,
    )


def flight_reference(
    params: F16Params, plan: FlightPlan, trims: TrimResult, dt: float, steps: int
) -> FlightReference:
    """``x_ref``/``u_ref`` at ``t = k dt``: level trim + climb and turn trims' departures weighted by
    ``commanded_profile``; ``h_ref``, ``phi_ref`` commanded; ``Q += cos(phi) theta_ref'``,
    ``P += phi_ref'``; the level-off's load ``dn = h_cmd'' / (g cos(gamma))`` added to alpha (and theta,
    ``theta = gamma + alpha``) and to the controls at the pull-up trim's rate per g.

    Returns:
      ``FlightReference(state (T, 13), control (T, 4))``, ``T = steps``, in ``trims``' dtype.
    """
    checks.check_positive("dt", dt, "a positive sample period (s)")
    checks.check_int("steps", steps, minimum=1, meaning="a positive number of steps")
    _check_trims(trims)
    dtype = trims.state.dtype
    t = jnp.arange(int(steps), dtype=dtype) * dt
    prof = commanded_profile(plan, t)
    level, climbing, turning, pulling = (trims.state[i] for i in range(4))
    c, b = prof.climb_weight[:, None], prof.bank_weight[:, None]
    state = level + c * (climbing - level) + b * (turning - level)
    theta_rate = prof.climb_rate * (climbing[THETA] - level[THETA]) + prof.bank_rate * (
        turning[THETA] - level[THETA]
    )
    gamma = jnp.arcsin(plan.climb_rate * prof.climb_weight / plan.airspeed)
    load = plan.climb_rate * prof.climb_rate / (params.gravity * jnp.cos(gamma))
    extra_alpha = load / (PULL_UP_LOAD - 1.0) * (pulling[ALPHA] - level[ALPHA])
    state = (
        state.at[:, H]
        .set(prof.altitude)
        .at[:, PHI]
        .set(prof.bank)
        .at[:, Q]
        .add(jnp.cos(prof.bank) * theta_rate)
        .at[:, P]
        .add(plan.bank_angle * prof.bank_rate)
        .at[:, ALPHA]
        .add(extra_alpha)
        .at[:, THETA]
        .add(jnp.cos(prof.bank) * extra_alpha)
    )
    u_level, u_climb, u_turn, u_pull = (trims.control[i] for i in range(4))
    control = (
        u_level
        + c * (u_climb - u_level)
        + b * (u_turn - u_level)
        + (load / (PULL_UP_LOAD - 1.0))[:, None] * (u_pull - u_level)
    )
    return FlightReference(state, control)


def measured_state(view: FlightView) -> tuple[Array, Array]:
    """``(x_lon (6,), x_lat (4,))`` as the controller reads them from the view."""
    for name in ("air_data", "attitude", "rates"):
        checks.check_shape(f"view.{name}", getattr(view, name), (3,), "a FlightView field")
    vt, alpha, beta = view.air_data[0], view.air_data[1], view.air_data[2]
    phi, theta = view.attitude[0], view.attitude[1]
    p, q, r = view.rates[0], view.rates[1], view.rates[2]
    return jnp.stack([vt, alpha, theta, q, view.altitude, view.power]), jnp.stack([beta, phi, p, r])


def flight_controller(gains: FlightGains, dt: float, lower: Array, upper: Array) -> Controller:
    """The SAS and autopilot as a ``loop.Controller`` on a ``FlightView``; step ``k``'s exogenous input
    is ``(x_ref[k], u_ref[k])`` (a ``FlightReference`` row); ``lower``/``upper`` (4,): control limits.

    Returns:
      ``Controller(init, step)`` (not feed-forward): ``init()`` a zero ``FlightControllerState``;
      ``step(state, k, view, (x_ref, u_ref)) -> (state, u)``, ``u`` (4,) ``[thtl, el, ail, rdr]`` in ``[lower, upper]``.
    """
    checks.check_positive("dt", dt, "a positive sample period (s)")
    checks.check_shape(
        "gains.longitudinal", gains.longitudinal, (2, 8), "u_lon = -K [dx_lon (6); z_lon (2)]"
    )
    checks.check_shape("gains.lateral", gains.lateral, (2, 5), "u_lat = -K [dx_lat (4); z_lat (1)]")
    checks.check_shape("lower", lower, (4,), "control limits thtl, el, ail, rdr")
    checks.check_shape("upper", upper, (4,), "control limits thtl, el, ail, rdr")
    low, high = checks.concrete(lower), checks.concrete(upper)
    if low is not None and high is not None and np.any(np.asarray(low) > np.asarray(high)):
        raise ValueError(
            f"lower: expected control limits below upper (thtl, el, ail, rdr), got lower "
            f"{checks.received(low)} and upper {checks.received(high)}"
        )

    lon_idx = jnp.asarray(LONGITUDINAL_DESIGN_STATES)
    lat_idx = jnp.asarray(LATERAL_STATES)
    lon_track = jnp.asarray(LONGITUDINAL_TRACKED)
    lat_track = jnp.asarray(LATERAL_TRACKED)
    K_lon, K_lat = gains.longitudinal, gains.lateral

    def init() -> FlightControllerState:
        dtype = K_lon.dtype
        return FlightControllerState(jnp.zeros((2,), dtype), jnp.zeros((1,), dtype))

    def step(state: FlightControllerState, k, view: FlightView, reference):
        x_ref, u_ref = reference
        x_lon, x_lat = measured_state(view)
        d_lon = x_lon - x_ref[lon_idx]
        d_lat = x_lat - x_ref[lat_idx]
        u_lon = u_ref[jnp.array([THTL, EL])] - K_lon @ jnp.concatenate(
            [d_lon, state.longitudinal_integral]
        )
        u_lat = u_ref[jnp.array([AIL, RDR])] - K_lat @ jnp.concatenate(
            [d_lat, state.lateral_integral]
        )
        wanted = jnp.stack([u_lon[0], u_lon[1], u_lat[0], u_lat[1]])
        u = jnp.clip(wanted, lower, upper)
        # conditional integration (anti-windup): an axis integrates only while its controls are inside the limits
        free = wanted == u
        lon_free, lat_free = free[0] & free[1], free[2] & free[3]
        new = FlightControllerState(
            jnp.where(
                lon_free,
                state.longitudinal_integral - dt * d_lon[lon_track],
                state.longitudinal_integral,
            ),
            jnp.where(
                lat_free, state.lateral_integral - dt * d_lat[lat_track], state.lateral_integral
            ),
        )
        return new, u

    return Controller(init, step)


__all__ = [
    "FlightWeights",
    "FlightGains",
    "FlightDesign",
    "FlightPlan",
    "FlightReference",
    "FlightControllerState",
    "flight_plan",
    "bryson_weights",
    "default_weights",
    "design_flight_control",
    "plan_trims",
    "initial_condition",
    "Profile",
    "commanded_profile",
    "flight_reference",
    "measured_state",
    "flight_controller",
    "LONGITUDINAL_TRACKED",
    "LATERAL_TRACKED",
]
