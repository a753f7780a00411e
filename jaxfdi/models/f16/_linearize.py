"""Linear models of the F-16 about a trim by ``jax.jacfwd``, its longitudinal and lateral
parts, and their modes (Stevens & Lewis 2003, sec. 3.7 and 4.4).

``A = df/dx``, ``B = df/du`` of ``f16_dynamics`` at the trim: exact derivatives of the piecewise-linear tables (forward
mode), no finite-difference step. About a wings-level trim the states split into longitudinal ``[VT, alpha, theta, Q]``
(+ ``h``, ``pow`` in a design holding altitude with the engine), inputs ``[thtl, el]``, and lateral
``[beta, phi, P, R]``, inputs ``[ail, rdr]`` (``psi``, ``pn``, ``pe`` feed nothing back).

Modes from the 4-state blocks' eigenvalues: longitudinal, the two largest are the short period, the two smallest the
phugoid (a pair each, or two real roots with the c.g. aft of the manoeuvre point); lateral, the pair is the Dutch roll,
the faster real root the roll, the slower the spiral (no pair: fastest roll, slowest spiral, middle two Dutch roll).
Each reports roots, ``|lambda|``, damping ``-Re(lambda)/|lambda|``, real roots' time constant ``-1/lambda`` (negative:
unstable, doubling in ``ln 2 / lambda``) and eigenvector magnitudes (``shapes``): near the neutral point speed-based
names mislead; at xcg = 0.35 the unstable root is mostly pitch attitude and airspeed (``theta`` 1, ``VT/V0`` 0.53,
``alpha`` 0.14, a phugoid-like divergence), the -1.91 root the short period's alpha and pitch rate.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.models.f16._dynamics import (
    AIL,
    ALPHA,
    BETA,
    CONTROL_NAMES,
    EL,
    PHI,
    POW,
    RDR,
    STATE_NAMES,
    THETA,
    THTL,
    VT,
    F16Params,
    H,
    P,
    Q,
    R,
    f16_dynamics,
)

#: the longitudinal and lateral state and input indices (the 4-state blocks of the modes)
LONGITUDINAL_STATES = (VT, ALPHA, THETA, Q)
LONGITUDINAL_INPUTS = (THTL, EL)
LATERAL_STATES = (BETA, PHI, P, R)
LATERAL_INPUTS = (AIL, RDR)
#: the longitudinal states of a design that holds altitude with the engine in the model
LONGITUDINAL_DESIGN_STATES = (VT, ALPHA, THETA, Q, H, POW)


class LinearF16(NamedTuple):
    """``x' = A dx + B du`` about ``(x, u)``.

    Attributes:
      A: (13, 13) state Jacobian
      B: (13, 4) control Jacobian
      x: (13,) the trim state
      u: (4,) the trim controls
    """

    A: Array
    B: Array
    x: Array
    u: Array


class Mode(NamedTuple):
    """A flight mode: name, roots, natural frequency, damping ratio and time constant.

    Attributes:
      name: the mode's name (e.g. short period, phugoid)
      roots: its eigenvalues (one real root, or a pair)
      natural_frequency: rad/s, |lambda| (of the first root for two real roots)
      damping_ratio: -Re/|lambda| (nan for two real roots)
      time_constant: s, -1/lambda of the slowest real root (nan for a complex pair)
      stable: every root has a negative real part
      shapes: per root: |eigenvector| over the block's states, max 1 (VT divided by the trim airspeed)
    """

    name: str
    roots: tuple[complex, ...]
    natural_frequency: float
    damping_ratio: float
    time_constant: float
    stable: bool
    shapes: tuple[tuple[float, ...], ...] = ()

    def describe(self, names: tuple[str, ...] | None = None) -> str:
        """One line: roots, frequency and damping (or time constant), and with ``names``
        (the block's states) the largest components of each root's eigenvector."""
        roots = ", ".join(_fmt_root(r) for r in self.roots)
        if len(self.roots) == 2 and abs(self.roots[0].imag) > 0:
            extra = f"wn {self.natural_frequency:.3f} rad/s, zeta {self.damping_ratio:.3f}"
        else:
            slow = max(self.roots, key=lambda r: r.real).real
            extra = (
                f"time to double {math.log(2) / slow:.1f} s"
                if slow > 0
                else f"time constant {self.time_constant:.2f} s"
            )
        text = f"{self.name:<15} {roots:<36} {extra}{'' if self.stable else '  UNSTABLE'}"
        if names and self.shapes:
            parts = []
            for root, shape in zip(self.roots, self.shapes):
                if root.imag < 0:
                    continue
                top = sorted(zip(shape, names), reverse=True)[:2]
                parts.append(f"{_fmt_root(root)}: " + " ".join(f"{n} {v:.2f}" for v, n in top))
            text += "  [" + "; ".join(parts) + "]"
        return text


def _fmt_root(r: complex) -> str:
    return (
        f"{r.real:.4f}"
        if r.imag == 0
        else f"{r.real:.4f} {'+' if r.imag > 0 else '-'} {abs(r.imag):.4f}j"
    )


def linearize(params: F16Params, x: Array, u: Array) -> LinearF16:
    """Jacobians of ``f16_dynamics`` at ``(x, u)`` (``jax.jacfwd``).

    Returns:
      ``LinearF16(A, B, x, u)`` (``dx' = A dx + B du``).
    """
    checks.check_shape("x", x, (13,), "trim state")
    checks.check_shape("u", u, (4,), "trim controls")
    A, B = jax.jacfwd(f16_dynamics, argnums=(0, 1))(x, u, params)
    return LinearF16(A, B, x, u)


def submodel(
    model: LinearF16, states: tuple[int, ...], inputs: tuple[int, ...]
) -> tuple[Array, Array]:
    """``(A[states, states], B[states, inputs])``.

    Returns:
      ``(A_sub, B_sub)``: the (len(states), len(states)) and (len(states), len(inputs)) blocks.
    """
    s, i = np.asarray(states), np.asarray(inputs)
    return model.A[s[:, None], s[None, :]], model.B[s[:, None], i[None, :]]


def longitudinal(
    model: LinearF16, states: tuple[int, ...] = LONGITUDINAL_STATES
) -> tuple[Array, Array]:
    """The longitudinal block, inputs ``[thtl, el]``."""
    return submodel(model, states, LONGITUDINAL_INPUTS)


def lateral(model: LinearF16, states: tuple[int, ...] = LATERAL_STATES) -> tuple[Array, Array]:
    """The lateral-directional block, inputs ``[ail, rdr]``."""
    return submodel(model, states, LATERAL_INPUTS)


def _mode(name: str, roots, shapes=()) -> Mode:
    roots = tuple(complex(r) for r in roots)
    first = roots[0]
    wn = abs(first)
    complex_pair = len(roots) == 2 and abs(first.imag) > 0
    zeta = -first.real / wn if complex_pair and wn > 0 else float("nan")
    real_parts = [r.real for r in roots]
    tau = -1.0 / max(real_parts) if not complex_pair and max(real_parts) != 0 else float("nan")
    return Mode(name, roots, wn, zeta, tau, all(r.real < 0 for r in roots), tuple(shapes))


def _canonical(roots: np.ndarray) -> np.ndarray:
    """Round-off imaginary parts of real roots to exactly 0."""
    roots = np.asarray(roots, complex)
    scale = np.maximum(np.abs(roots), 1e-300)
    return np.where(np.abs(roots.imag) <= 1e-9 * scale, roots.real + 0j, roots)


def _shapes(A: Array, roots: np.ndarray, scale: np.ndarray) -> list[tuple[float, ...]]:
    """|eigenvector| of each root over the block's states (divided by ``scale``), max 1."""
    values, vectors = np.linalg.eig(np.asarray(A, np.float64))
    out = []
    for r in roots:
        v = np.abs(vectors[:, np.argmin(np.abs(values - r))]) / scale
        out.append(tuple(float(c) for c in v / np.max(v)))
    return out


def longitudinal_modes(A_lon: Array, airspeed: float = 1.0) -> list[Mode]:
    """Short period and phugoid of the ``[VT, alpha, theta, Q]`` block: two pairs, the faster is the short
    period; a pair and two real roots, the pair is the phugoid unless faster than both (then the short
    period); four real roots, the two largest are the short period."""
    checks.check_matrix("A_lon", A_lon, (4, 4), "[VT, alpha, theta, Q] block")
    roots = _canonical(np.linalg.eigvals(np.asarray(A_lon, np.float64)))
    is_complex = np.abs(roots.imag) > 0
    real = roots[~is_complex]
    if np.count_nonzero(is_complex) == 4:
        order = np.argsort(np.abs(roots))
        short, phugoid = roots[order[2:]], roots[order[:2]]
    elif np.count_nonzero(is_complex) == 2:
        pair = roots[is_complex]
        faster = np.abs(pair[0]) > np.max(np.abs(real))
        short, phugoid = (pair, real) if faster else (real, pair)
    else:
        order = np.argsort(np.abs(roots))
        short, phugoid = roots[order[2:]], roots[order[:2]]
    scale = np.array([airspeed, 1.0, 1.0, 1.0])
    short, phugoid = _pair(short), _pair(phugoid)
    return [
        _mode("short period", short, _shapes(A_lon, short, scale)),
        _mode("phugoid", phugoid, _shapes(A_lon, phugoid, scale)),
    ]


def lateral_modes(A_lat: Array) -> list[Mode]:
    """Roll subsidence, spiral and Dutch roll of the (4, 4) ``[beta, phi, P, R]`` block."""
    checks.check_matrix("A_lat", A_lat, (4, 4), "[beta, phi, P, R] block")
    roots = _canonical(np.linalg.eigvals(np.asarray(A_lat, np.float64)))
    is_complex = np.abs(roots.imag) > 0
    if np.count_nonzero(is_complex) == 2:
        dutch = roots[is_complex]
        real = np.sort_complex(roots[~is_complex].real + 0j)
        real = real[np.argsort(np.abs(real))]
        spiral, roll = real[0], real[1]
    else:
        order = np.argsort(np.abs(roots))
        spiral, dutch, roll = roots[order[0]], roots[order[1:3]], roots[order[3]]
    one = np.ones(4)
    dutch = _pair(dutch)
    return [
        _mode("roll", [roll], _shapes(A_lat, [roll], one)),
        _mode("spiral", [spiral], _shapes(A_lat, [spiral], one)),
        _mode("Dutch roll", dutch, _shapes(A_lat, dutch, one)),
    ]


def _pair(roots: np.ndarray) -> np.ndarray:
    """A complex pair with the positive imaginary part first; real roots fastest first."""
    if np.any(np.abs(roots.imag) > 0):
        return roots[np.argsort(-roots.imag)]
    return roots[np.argsort(roots.real)]


def flight_modes(model: LinearF16) -> list[Mode]:
    """The five classical modes about a wings-level trim (module doc).

    Returns:
      list of 5 ``Mode`` in the order short period, phugoid, roll, spiral, Dutch roll (Python numbers: roots
      complex, natural frequencies in rad/s, time constants in s).
    """
    A_lon, _ = longitudinal(model)
    A_lat, _ = lateral(model)
    return longitudinal_modes(A_lon, float(model.x[VT])) + lateral_modes(A_lat)


__all__ = [
    "LinearF16",
    "Mode",
    "linearize",
    "submodel",
    "longitudinal",
    "lateral",
    "longitudinal_modes",
    "lateral_modes",
    "flight_modes",
    "LONGITUDINAL_STATES",
    "LONGITUDINAL_INPUTS",
    "LATERAL_STATES",
    "LATERAL_INPUTS",
    "LONGITUDINAL_DESIGN_STATES",
    "STATE_NAMES",
    "CONTROL_NAMES",
    "AIL",
    "RDR",
    "PHI",
    "POW",
]
