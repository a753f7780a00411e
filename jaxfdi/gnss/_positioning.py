"""Snapshot positioning: iterated weighted least squares on pseudoranges, and DOPs.

Model (Misra & Enge 2011, ch. 6): ``rho_i = |r_i - x| + b - c dt_i + eps_i``, ``r_i`` the satellite position at
transmission in the ECEF frame of reception (Sagnac rotation), ``b`` the receiver clock bias [m], ``dt_i`` the broadcast
satellite clock; ``t_tx = t_rx - rho_i / c - dt_i`` (``t_rx`` the receiver's time tag), so satellite positions do not
depend on the estimate. Gauss-Newton from the Earth's centre, ``H = [-u_i^T, 1]`` (``u_i`` the unit line of sight),
each step the whitened problem by ``least_squares``' masked Householder QR; unused slots' rows are zero (shapes never
depend on the satellites in view).

Several constellations: one receiver clock each (``clocks``: a slot's clock column),
``rho_i = |r_i - x| + b_c(i) - c dt_i + eps_i``, ``H = [-u_i^T, e_c(i)^T]``; a clock without used satellites stays at
its start value and takes no degree of freedom.

The returned geometry is in local North-East-Down axes at the solution, ``H_ned = [-u_ned^T, e_c^T]`` (RAIM's slopes,
DOPs): ``(H^T H)^{-1}`` gives ``HDOP = sqrt(q_NN + q_EE)``, ``VDOP = sqrt(q_DD)``, ``PDOP``, ``TDOP``, ``GDOP`` (Misra &
Enge 2011, sec. 6.1.3).
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.gnss._atmosphere import Atmosphere, atmosphere_corrections
from jaxfdi.gnss._frames import ecef_to_geodetic, ned_rotation
from jaxfdi.gnss._least_squares import apply_qt, leading, masked_qr
from jaxfdi.gnss._orbits import (
    SPEED_OF_LIGHT,
    Orbit,
    earth_rotation,
    satellite_clock,
    satellite_state,
)

#: Gauss-Newton iterations from the Earth's centre (converged to 1e-8 m after 5 on 3000 epochs of the benchmark's day;
#: one more as margin)
ITERATIONS = 6
#: of which the first ones use unit weights (elevations are meaningless until then)
UNWEIGHTED_ITERATIONS = 3
#: epochs of a recorded trace are solved EPOCH_CHUNK at a time with the slots padded to a multiple of it, and several
#: receiver clocks padded to the seven constellations Android reports (GPS, SBAS, GLONASS, QZSS, BeiDou, Galileo,
#: NavIC): every trace of up to 64 signals shares one compiled program (a padded slot is unused, a padded clock has no
#: satellite)
EPOCH_CHUNK = 64
CONSTELLATIONS = 7


class Dops(NamedTuple):
    """Dilutions of precision: geometric, position, horizontal, vertical and time."""

    gdop: Array
    pdop: Array
    hdop: Array
    vdop: Array
    tdop: Array


class PositionFix(NamedTuple):
    """One epoch's least-squares solution (slot arrays (S,), zero/False at unused slots).

    Attributes:
      position: (3,) ECEF [m]
      clock_bias: () m, receiver clock bias ((C,) with ``clocks``: one per constellation)
      residuals: (S,) measured minus predicted pseudorange at the solution [m]
      geometry: (S, 3 + C) [-u_ned^T, e_c^T] at the solution (C = 1: [-u_ned^T, 1])
      sigma: (S,) pseudorange standard deviations used as weights [m]
      used: (S,) bool, the slots in the solution
      num_used: () int, number of used slots
      elevation: (S,) rad, seen from the solution
      azimuth: (S,) rad, seen from the solution
      dops: dilutions of precision of the used geometry
      healthy: () bool: >= 4 satellites, finite, converged
    """

    position: Array
    clock_bias: Array
    residuals: Array
    geometry: Array
    sigma: Array
    used: Array
    num_used: Array
    elevation: Array
    azimuth: Array
    dops: Dops
    healthy: Array


def padded_to(array, shape: tuple, fill) -> np.ndarray:
    """``array`` (NumPy) padded with ``fill`` at the end of every axis to ``shape``."""
    array = np.asarray(array)
    return np.pad(array, [(0, n - m) for n, m in zip(shape, array.shape)], constant_values=fill)


def padded_sizes(epochs: int, slots: int, clocks: int) -> tuple[int, int, int]:
    """The padded (epochs, slots, clocks) of ``EPOCH_CHUNK`` and ``CONSTELLATIONS``; one clock stays one."""

    def up(n):
        return -(-n // EPOCH_CHUNK) * EPOCH_CHUNK

    return up(epochs), up(max(slots, 5)), max(clocks, CONSTELLATIONS) if clocks > 1 else clocks


#: the leaves of a ``PositionFix`` and of the results built on it with a slot axis (after the epoch axis); ``geometry``
#: also has 3 + C clock columns, a per-constellation ``clock_bias`` C clocks
SLOT_FIELDS = frozenset(
    {
        "residuals",
        "geometry",
        "sigma",
        "used",
        "elevation",
        "azimuth",
        "isolation",
        "slope_horizontal",
        "slope_vertical",
        "minimum_detectable_bias",
        "dead",
        "exclusions",
    }
)


def resized(tree, epochs: int, slots: int, clocks: int, fills: dict | None = None):
    """A fix or a result built on it (NumPy leaves, leading epoch axis) cut or padded to ``epochs``, ``slots`` and
    ``clocks`` (``SLOT_FIELDS``); padding takes the leaf's ``fills`` entry by field name (default 0 / False)."""

    def one(path, leaf):
        name = path[-1].name
        shape = [epochs, *leaf.shape[1:]]
        if name in SLOT_FIELDS:
            shape[1] = slots
        if name == "geometry":
            shape[2] = 3 + clocks
        elif name == "clock_bias" and leaf.ndim == 2:
            shape[1] = clocks
        return padded_to(leaf[tuple(slice(0, n) for n in shape)], shape, (fills or {}).get(name, 0))

    return jax.tree_util.tree_map_with_path(one, tree)


def in_chunks(solve: Callable, epochs: int, *arrays):
    """``solve(*chunk)`` on ``EPOCH_CHUNK`` epochs of ``arrays`` at a time (pytrees, leading axis padded to a multiple),
    joined on the host and cut back to ``epochs``: one program for every padded trace."""
    rows = jax.tree_util.tree_leaves(arrays)[0].shape[0]
    chunks = [
        jax.tree_util.tree_map(
            np.asarray, solve(*jax.tree_util.tree_map(lambda a: a[k : k + EPOCH_CHUNK], arrays))
        )
        for k in range(0, rows, EPOCH_CHUNK)
    ]
    return jax.tree_util.tree_map(lambda *chunk: np.concatenate(chunk)[:epochs], *chunks)


def transmit_states(orbit: Orbit, t_receive: Array, pseudoranges: Array) -> tuple[Array, Array]:
    """``(positions (S, 3), clocks (S,))``: satellite ECEF positions at transmission (frame of transmission) and clock
    offsets [s] for pseudoranges time-tagged ``t_receive``."""
    rho = jnp.where(jnp.isfinite(pseudoranges), pseudoranges, 0.0)
    t_sv = t_receive - rho / SPEED_OF_LIGHT
    return satellite_state(orbit, t_sv - satellite_clock(orbit, t_sv))


def dops(geometry: Array, used: Array) -> Dops:
    """DOPs of an (S, 3 + clocks) NED + clock geometry over the ``used`` rows (unit weights); TDOP is the first clock's;
    a clock column without used rows is left out.

    Returns:
      ``Dops(gdop, pdop, hdop, vdop, tdop)``, each a () dimensionless array from the diagonal ``q`` of ``(H^T H)^{-1}``:
      ``sqrt(trace)``, ``sqrt(q_NN + q_EE + q_DD)``, ``sqrt(q_NN + q_EE)``, ``sqrt(q_DD)`` and ``sqrt(q_tt)`` of the
      first clock column (NaN when the used rows do not determine the unknowns: a singular ``H^T H``).
    """
    checks.check_shape("used", used, checks.shape_of(geometry)[:1], "one flag per geometry row")
    h = jnp.where(used[:, None], geometry, 0.0)
    absent = _absent_columns(h)
    normal = h.T @ h + jnp.diag(absent.astype(h.dtype))
    cov = _linalg.cho_solve(_linalg.cholesky(normal), jnp.eye(h.shape[1], dtype=h.dtype))
    var = jnp.where(absent, 0.0, jnp.diagonal(cov))
    return Dops(
        jnp.sqrt(jnp.sum(var)),
        jnp.sqrt(var[0] + var[1] + var[2]),
        jnp.sqrt(var[0] + var[1]),
        jnp.sqrt(var[2]),
        jnp.sqrt(var[3]),
    )


def _absent_columns(h: Array) -> Array:
    """(u,) bool: clock columns zero on every row (a constellation without used satellites)."""
    return (jnp.arange(h.shape[1]) >= 3) & ~jnp.any(h != 0.0, axis=0)


def _predict(
    sat_tx: Array, sat_clock: Array, state: Array, membership: Array
) -> tuple[Array, Array, Array]:
    """Predicted pseudoranges, ECEF unit lines of sight and satellite positions (reception frame) for
    ``state = [x, y, z, b_1..b_C]`` and the (S, C) clock ``membership``."""
    travel = jnp.linalg.norm(sat_tx - state[:3], axis=-1) / SPEED_OF_LIGHT
    sat = earth_rotation(sat_tx, travel)
    delta = sat - state[:3]
    distance = jnp.linalg.norm(delta, axis=-1)
    return (
        distance + membership @ state[3:] - SPEED_OF_LIGHT * sat_clock,
        delta / distance[:, None],
        sat,
    )


def solve_position(
    orbit: Orbit,
    t_receive: Array,
    pseudoranges: Array,
    available: Array,
    sigma: Array | Callable[[Array], Array] | None = None,
    initial: Array | None = None,
    iterations: int = ITERATIONS,
    unweighted_iterations: int = UNWEIGHTED_ITERATIONS,
    transmit: tuple[Array, Array] | None = None,
    solver: str = "normal",
    atmosphere: Atmosphere | None = None,
    mask_angle: float | None = None,
    clocks: Array | None = None,
) -> PositionFix:
    """Iterated weighted least-squares fix of one epoch.

    Args:
      orbit: (S,) slot elements at this epoch (``orbits.select_orbits``).
      t_receive: () receiver time tag [s from the reference week's start].
      pseudoranges: (S,) [m]; NaN where not measured.
      available: (S,) bool: slots to use (ANDed with a finite pseudorange).
      sigma: (S,) standard deviations [m], or a function of the (S,) elevations [rad] seen from the current estimate
        (applied after ``unweighted_iterations``), or ``None`` (unit weights).
      initial: (3 + C,) ``[x, y, z, b_1..b_C]`` start (default the Earth's centre, clocks 0).
      iterations: Gauss-Newton steps (fixed count, so it jits and vmaps).
      transmit: ``transmit_states(orbit, t_receive, pseudoranges)`` if already computed.
      solver: "normal" (normal equations, written-out 4 x 4 Cholesky: cheapest under ``vmap``) or "qr" (masked
        Householder QR); fixes agree well below a millimetre (RAIM statistics always use the QR).
      atmosphere: broadcast ionosphere (``broadcast_atmosphere``): predictions carry the Klobuchar and Saastamoinen
        delays from the current estimate, weights ``sigma^2 + var`` (``atmosphere_corrections``).
      mask_angle: elevation mask [rad], applied from the second step on from the current estimate (``None``: none).
      clocks: (S, C) bool, slot ``s`` on receiver clock ``c`` (one True per row: its constellation); clock bias then
        (C,); ``None``: one clock.

    Returns:
      ``PositionFix`` after ``iterations`` steps: ``sigma`` 1 at unused slots; ``used``: available, finite, above the
      mask; ``geometry`` zero rows at unused slots; ``healthy``: >= 3 + the clocks in use, finite, last step < 1 cm.
    """
    if solver not in ("normal", "qr"):
        raise ValueError(f"solver: expected 'normal' or 'qr', got {solver!r}")
    slots = checks.shape_of(orbit.toe) if hasattr(orbit, "toe") else checks.shape_of(available)
    checks.check_shape("pseudoranges", pseudoranges, slots, "one pseudorange per satellite slot")
    checks.check_shape("available", available, slots, "one flag per satellite slot")
    if sigma is not None and not callable(sigma):
        checks.check_shape("sigma", sigma, slots, "one standard deviation per satellite slot [m]")
        value = checks.concrete(sigma)
        if value is not None and not np.all(value > 0):
            raise ValueError(
                f"sigma: expected standard deviations > 0 [m], got {checks.received(value)}"
            )
    if mask_angle is not None:
        if not isinstance(mask_angle, (int, float)):
            raise TypeError(
                f"mask_angle: expected a Python float [rad] or None, got {checks.received(mask_angle)}"
            )
        checks.check_angle("mask_angle", mask_angle, -math.pi / 2, math.pi / 2, "an elevation mask")
    if clocks is not None:
        checks.check_shape(
            "clocks", clocks, (slots[0], None), "(S, C) bool: each slot's receiver clock"
        )
    pseudoranges = jnp.asarray(pseudoranges)
    dtype = pseudoranges.dtype
    membership = (
        jnp.ones(slots + (1,), dtype) if clocks is None else jnp.asarray(clocks, bool).astype(dtype)
    )
    unknown = 3 + membership.shape[1]
    if initial is not None:
        checks.check_shape(
            "initial", initial, (unknown,), f"[x, y, z] and {unknown - 3} clock(s) [m]"
        )
    measured = jnp.asarray(available, bool) & jnp.isfinite(pseudoranges)
    rho = jnp.where(measured, pseudoranges, 0.0)
    sat_tx, sat_clock = (
        transmit_states(orbit, t_receive, pseudoranges) if transmit is None else transmit
    )
    state0 = jnp.zeros(unknown, dtype) if initial is None else jnp.asarray(initial, dtype)
    ones = jnp.ones_like(rho)
    local = (
        callable(sigma) or atmosphere is not None or mask_angle is not None
    )  # angles needed every step

    def linearize(state, k):
        """Predicted pseudoranges, ECEF lines of sight, elevations and azimuths, standard deviations and the used slots
        at ``state`` in step ``k``."""
        predicted, los, _ = _predict(sat_tx, sat_clock, state, membership)
        elevation = azimuth = None
        if local:
            elevation, azimuth = _look_angles(state, los)
        std = (
            ones
            if sigma is None
            else jnp.asarray(sigma, dtype)
            if not callable(sigma)
            else jnp.where(k < unweighted_iterations, ones, sigma(elevation))
        )
        used = measured if mask_angle is None else measured & ((k < 1) | (elevation >= mask_angle))
        if atmosphere is not None:
            delay, variance = atmosphere_corrections(
                atmosphere, t_receive, state[:3], elevation, azimuth
            )
            predicted = predicted + delay
            std = jnp.where(k < unweighted_iterations, std, jnp.sqrt(std**2 + variance))
        return predicted, los, elevation, azimuth, std, used

    def gauss_newton(k, carry):
        state, _ = carry
        predicted, los, _, _, std, used = linearize(state, k)
        h = jnp.where(
            used[:, None], jnp.concatenate([-los, membership], axis=1) / std[:, None], 0.0
        )
        y = jnp.where(used, (rho - predicted) / std, 0.0)
        if solver == "qr":
            qr = masked_qr(h, used)
            step = _linalg.solve_upper(qr.r, leading(qr, apply_qt(qr, y)))
        else:  # normal equations, Cholesky written out (element-wise over a batch)
            normal = jnp.einsum("si,sj->ij", h, h) + jnp.diag(_absent_columns(h).astype(dtype))
            step = _linalg.cho_solve(_linalg.cholesky(normal), jnp.einsum("si,s->i", h, y))
        return state + step, step

    state, step = jax.lax.fori_loop(
        0, int(iterations), gauss_newton, (state0, jnp.zeros(unknown, dtype))
    )
    predicted, los, elevation, azimuth, std, used = linearize(state, int(iterations))
    los_ned = los @ _ned_at(state).T
    if not local:
        elevation, azimuth = _look_angles(state, los)
    geometry = jnp.where(used[:, None], jnp.concatenate([-los_ned, membership], axis=1), 0.0)
    num_used = jnp.sum(used)
    clocks_in_use = jnp.sum(jnp.any(used[:, None] & (membership > 0), axis=0))
    healthy = (
        (num_used >= 3 + clocks_in_use)
        & jnp.all(jnp.isfinite(state))
        & (jnp.linalg.norm(step[:3]) < 1e-2)
    )
    return PositionFix(
        position=state[:3],
        clock_bias=state[3] if clocks is None else state[3:],
        residuals=jnp.where(used, rho - predicted, 0.0),
        geometry=geometry,
        sigma=jnp.where(used, std, 1.0),
        used=used,
        num_used=num_used,
        elevation=jnp.where(used, elevation, 0.0),
        azimuth=jnp.where(used, azimuth, 0.0),
        dops=dops(geometry, used),
        healthy=healthy,
    )


def _ned_at(state: Array) -> Array:
    lat, lon, _ = ecef_to_geodetic(state[:3])
    return ned_rotation(lat, lon)


def _look_angles(state: Array, los: Array) -> tuple[Array, Array]:
    """(S,) elevations and azimuths [rad] of the ECEF unit lines of sight ``los`` seen from ``state``."""
    los_ned = los @ _ned_at(state).T
    elevation = jnp.arcsin(jnp.clip(-los_ned[:, 2], -1.0, 1.0))
    return elevation, jnp.mod(jnp.arctan2(los_ned[:, 1], los_ned[:, 0]), 2.0 * jnp.pi)
