"""Simulated GPS pseudoranges: visibility masks, elevation-dependent noise, receiver clock,
satellite faults, as a plant for the foundation's loop.

- **Visibility**: valid healthy ephemeris, above the mask, line of sight not crossing a ``Wall`` (a vertical rectangle
  on the local level: the paper's antenna beside a rooftop structure, Yoo et al. 2010, sec. 3.2).
- **Noise**: ``sigma(el) = sqrt(a^2 + b^2 / sin^2 el)`` [m] (RTKLIB's ``varerr``; Takasu 2013), white;
  iono and tropo residuals are part of it.
- **Clock**: bias ``b`` [m], drift ``d`` [m/s], two-state random walk from Allan coefficients ``h0``
  (white frequency), ``h_-2`` (random-walk frequency) (Brown & Hwang 2012, sec. 9.3):
  ``Q = c^2 [[h0/2 dt + 2 pi^2 h_-2 dt^3/3, pi^2 h_-2 dt^2], [pi^2 h_-2 dt^2, 2 pi^2 h_-2 dt]]``.
- **Pseudorange** at the receiver's tags ``t_k = t0 + k dt`` (true time ``t_k - b/c``):
  ``rho_i = |R(tau) r_i(t_k - b/c - tau) - x| + b - c dt_i + sigma_i n_i`` (``orbits.transmission_geometry``).
- **Faults**: sensor faults (``jaxfdi._simulation.faults``), component = slot: impulse, bias, ramp, frozen
  (STUCK: onset value held), several episodes per run (``concat_faults``).
- **Dead and missing**: NaN = not measured (not visible/tracked, a RINEX blank), no evidence; a DEAD
  fault (any non-finite value) on a tracked slot is ``+inf``, the dead channel ``integrity`` alarms on,
  isolates and leaves out (``EpochIntegrity.dead``), never a silent NaN.

``receiver_plant`` is a ``simulate.Simulator`` for ``simulate.simulate`` and ``loop.run_loop``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import (
    Fault,
    Target,
    active_label,
    apply_faults,
    as_stack,
    is_active,
    no_fault,
)
from jaxfdi._simulation.simulate import (
    Actuated,
    Sensed,
    SimState,
    Simulator,
    check_fault_components,
)
from jaxfdi.gnss._frames import ecef_to_ned, elevation_azimuth, line_of_sight_ned
from jaxfdi.gnss._orbits import (
    SPEED_OF_LIGHT,
    OrbitTable,
    satellite_position,
    select_orbits,
    transmission_geometry,
)


class Wall(NamedTuple):
    """A vertical rectangle: base from ``start`` to ``end`` ((2,) north, east [m] in a local
    NED frame), from the ground up to ``height`` [m above the frame's origin].

    Attributes:
      start: (2,) m, north and east of one end of the base in the walls' NED frame
      end: (2,) m, north and east of the other end of the base
      height: () m, the top above the frame's origin (a ray passing lower is blocked)
    """

    start: Array
    end: Array
    height: Array


class ClockModel(NamedTuple):
    """Receiver oscillator: Allan-variance coefficients (TCXO defaults, Brown & Hwang 2012
    Table 9.1) and the initial bias [m] and drift [m/s].

    Attributes:
      h0: white frequency noise coefficient (Allan variance) [s]
      h_minus2: random-walk frequency noise coefficient [1/s]
      bias: initial clock bias [m]
      drift: initial clock drift [m/s]
    """

    h0: float = 2e-19
    h_minus2: float = 2e-20
    bias: float = 3000.0
    drift: float = 0.5


def elevation_sigma(
    elevation: Array,
    zenith: float = 3.0,
    slant: float = 3.0,
    min_elevation: float = math.radians(2.0),
) -> Array:
    """``sqrt(a^2 + b^2 / sin^2 el)`` [m]: ``a = zenith``, ``b = slant``; elevations below
    ``min_elevation`` are taken at it (the satellite is masked anyway).

    Returns:
      the pseudorange standard deviation [m], ``elevation``'s shape.
    """
    checks.check_scalar("zenith", zenith, 0.0, meaning="a standard deviation >= 0 [m]")
    checks.check_scalar("slant", slant, 0.0, meaning="a standard deviation >= 0 [m]")
    checks.check_scalar(
        "min_elevation",
        min_elevation,
        0.0,
        0.5 * math.pi,
        low_open=True,
        meaning="an elevation in (0, pi/2] rad",
    )
    sin_el = jnp.sin(jnp.maximum(elevation, min_elevation))
    return jnp.sqrt(zenith**2 + (slant / sin_el) ** 2)


def wall_blocks(receiver_ned: Array, line_of_sight: Array, wall: Wall) -> Array:
    """(S,) bool: the ray from ``receiver_ned`` (3,) along unit ``line_of_sight`` (S, 3)
    (both NED) crosses ``wall`` below its top."""
    start, end = jnp.asarray(wall.start), jnp.asarray(wall.end)
    edge = end - start
    offset = start - receiver_ned[:2]
    d = line_of_sight[:, :2]

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    denom = cross(d, edge)
    safe = jnp.where(jnp.abs(denom) > 1e-12, denom, 1.0)
    s = cross(offset, edge) / safe  # along the ray (unit 3-D direction)
    t = cross(offset, d) / safe  # along the wall's base, 0..1
    up_at_wall = -(receiver_ned[2] + s * line_of_sight[:, 2])
    return (jnp.abs(denom) > 1e-12) & (s > 0) & (t >= 0) & (t <= 1) & (up_at_wall <= wall.height)


def sky_geometry(
    table: OrbitTable, t: Array, receiver_ecef: Array
) -> tuple[Array, Array, Array, Array]:
    """``(elevation, azimuth, line_of_sight_ned, has_orbit)`` over S slots from ``receiver_ecef`` (3,) at
    ``t`` (positions at ``t``; light time changes an elevation < 1e-4 rad).

    Returns:
      ``(elevation (S,), azimuth (S,), line_of_sight_ned (S, 3), has_orbit (S,))``: angles in rad (azimuth in
      ``[0, 2 pi)`` clockwise from north), unit receiver-to-satellite vectors, bool slots with a usable orbit.
    """
    orbit, has_orbit = select_orbits(table, t)
    sat = satellite_position(orbit, t)
    elevation, azimuth = elevation_azimuth(receiver_ecef, sat)
    return elevation, azimuth, line_of_sight_ned(receiver_ecef, sat), has_orbit


def check_mask_angle(mask_angle) -> None:
    """An elevation mask: one angle in radians in ``[-pi/2, pi/2]`` (``ValueError`` naming ``mask_angle`` and the unit
    otherwise: a mask of 5 deg passed as 5 is refused with its value in radians)."""
    if np.ndim(mask_angle) != 0:
        raise ValueError(
            f"mask_angle: expected one elevation angle, got {checks.received(mask_angle)}"
        )
    checks.check_angle("mask_angle", mask_angle, -0.5 * math.pi, 0.5 * math.pi, "an elevation mask")


def visibility(
    table: OrbitTable,
    t: Array,
    receiver_ecef: Array,
    mask_angle: float,
    origin_ecef: Array | None = None,
    walls: tuple[Wall, ...] = (),
) -> tuple[Array, Array, Array]:
    """``(visible, elevation, azimuth)`` over the S slots: valid healthy ephemeris, above ``mask_angle`` [rad] and not
    behind any of ``walls`` (whose NED frame is at ``origin_ecef``).

    Returns:
      ``(visible (S,) bool, elevation (S,), azimuth (S,))``, angles in rad (azimuth clockwise from north).
    """
    check_mask_angle(mask_angle)
    if walls and origin_ecef is None:
        raise ValueError(
            "origin_ecef: expected the (3,) ECEF origin of the walls' NED frame, got None"
        )
    return _visibility(table, t, receiver_ecef, mask_angle, origin_ecef, tuple(walls))


@jax.jit
def _visibility(
    table: OrbitTable,
    t: Array,
    receiver_ecef: Array,
    mask_angle: Array,
    origin_ecef: Array | None,
    walls: tuple[Wall, ...],
) -> tuple[Array, Array, Array]:
    """``visibility`` after the checks, one program (a vmapped call outside ``jit`` compiles once)."""
    elevation, azimuth, los, has_orbit = sky_geometry(table, t, receiver_ecef)
    visible = has_orbit & (elevation > mask_angle)
    if walls:
        receiver_ned = ecef_to_ned(receiver_ecef, origin_ecef)
        for wall in walls:
            visible = visible & ~wall_blocks(receiver_ned, los, wall)
    return visible, elevation, azimuth


def clock_process_noise(clock: ClockModel, dt: float, dtype=None) -> Array:
    """(2, 2) process-noise covariance of ``[bias, drift]`` over ``dt`` seconds [m, m/s]."""
    dtype = dtype or jnp.result_type(float)
    c2 = SPEED_OF_LIGHT**2
    qb, qd = 0.5 * clock.h0 * c2, 2.0 * math.pi**2 * clock.h_minus2 * c2
    return jnp.asarray(
        [[qb * dt + qd * dt**3 / 3.0, qd * dt**2 / 2.0], [qd * dt**2 / 2.0, qd * dt]], dtype
    )


def receiver_plant(
    table: OrbitTable,
    t0: float,
    dt: float,
    path_ecef: Array,
    visible: Array,
    sigma: Array,
    clock: ClockModel = ClockModel(),
    fault: Fault | None = None,
) -> Simulator:
    """A GPS receiver on a known path, as a ``Simulator`` over the state ``[b, d]``.

    Args:
      table: orbits of the S slots (``orbits.ephemeris_table`` / ``almanac_table``).
      t0, dt: time tag of step 0 [s from the table's reference week] and the step [s].
      path_ecef: (T, 3) receiver antenna positions at the T time tags.
      visible: (T, S) bool: slots tracked (``visibility``); others NaN; a tracked slot made non-finite
        (DEAD) is ``+inf``.
      sigma: (T, S) pseudorange noise standard deviations [m] (``elevation_sigma``).
      clock: the oscillator (``ClockModel``); ``init`` takes ``[bias, drift]`` anyway.
      fault: sensor ``Fault``(s) on satellite slots (scalar leaves or a stack), or None.

    Returns:
      a ``Simulator`` whose measurement is the (S,) pseudoranges [m] of each step.
    """
    checks.check_positive("dt", dt, "a positive epoch interval (s)")
    value = checks.concrete(sigma)
    if value is not None and np.any(value < 0):
        raise ValueError(
            f"sigma: expected pseudorange standard deviations >= 0 [m], got {checks.received(value)}"
        )
    path_ecef, visible, sigma = (
        jnp.asarray(path_ecef),
        jnp.asarray(visible, bool),
        jnp.asarray(sigma),
    )
    checks.check_shape("path_ecef", path_ecef, (None, 3), "T ECEF receiver positions")
    steps, slots = visible.shape if visible.ndim == 2 else (None, None)
    checks.check_shape(
        "visible", visible, (path_ecef.shape[0], table.prn.shape[0]), "T steps x S slots"
    )
    checks.check_shape("sigma", sigma, (steps, slots), "T steps x S slots")
    faults = as_stack(no_fault() if fault is None else fault)
    check_fault_components(faults, Target.SENSOR, table.prn.shape[0])
    num_faults = faults.kind.shape[0]
    noise_sqrt = jnp.linalg.cholesky(clock_process_noise(clock, dt, path_ecef.dtype))
    transition = jnp.asarray([[1.0, dt], [0.0, 1.0]], path_ecef.dtype)

    def init(x0: Array) -> SimState:
        checks.check_shape("x0", x0, (2,), "receiver clock [bias m, drift m/s]")
        x0 = jnp.asarray(x0, path_ecef.dtype)
        return SimState(x0, jnp.zeros((num_faults,), x0.dtype))

    def measure(sim: SimState, k: Array, u: Array, step_key: Array):
        bias = sim.state[0]
        t_tag = t0 + k * dt
        orbit, _ = select_orbits(table, t_tag)
        _, ranges, _, sat_clock = transmission_geometry(
            orbit, t_tag - bias / SPEED_OF_LIGHT, path_ecef[k]
        )
        clean = ranges + bias - SPEED_OF_LIGHT * sat_clock
        _, key_v = jax.random.split(step_key)
        noisy = clean + sigma[k] * jax.random.normal(key_v, clean.shape, clean.dtype)
        faulty, held = apply_faults(faults, k, noisy, Target.SENSOR, sim.held)
        # NaN: not tracked; a tracked channel gone non-finite (DEAD) is a dead channel, +inf
        measured = jnp.where(visible[k], jnp.where(jnp.isfinite(faulty), faulty, jnp.inf), jnp.nan)
        active = jax.vmap(is_active, in_axes=(0, None))(faults, k)
        return SimState(sim.state, held), Sensed(
            sim.state, measured, faulty - noisy, active, active_label(faults, k, u.shape[0])
        )

    def advance(sim: SimState, k: Array, u: Array, step_key: Array):
        key_w, _ = jax.random.split(step_key)
        w = noise_sqrt @ jax.random.normal(key_w, (2,), sim.state.dtype)
        return SimState(transition @ sim.state + w, sim.held), Actuated(u, jnp.zeros_like(u))

    return Simulator(init, measure, advance, int(visible.shape[0]))
