"""Protection levels by multiple-hypothesis solution separation (the ARAIM user algorithm, Blanch et al. 2015, "Baseline
advanced RAIM user algorithm and possible improvements", IEEE TAES 51(1); EU-U.S. ARAIM ADD v3), for one fix, vmappable
over epochs (``separate_epochs``: a recorded trace's epochs, padded as ``monitor_receiver`` pads a phone's).

Fault modes ``k``: each used satellite (prior ``P_sat``) and each constellation (prior ``P_const`` of its
clock column). Mode ``k`` keeps the other satellites (whitened ``h``, residuals ``y``, 0/1 mask ``D_k``):

``N_k = h^T D_k h``, ``dx_k = N_k^-1 h^T D_k y`` (all-in-view ``N_0^-1 h^T y`` is zero at convergence),
``sigma_k,q^2 = (N_k^-1)_qq``, ``sigma_ss,k,q^2 = (N_k^-1 - N_0^-1)_qq``

(q = N, E, D; a clock column without satellites is dropped; a satellite alone on its clock:
``sigma_ss = 0``, no test). Monitored: modes whose solution exists (>= ``3 + clocks left``
satellites); the others' priors and multiple satellite faults (``(n P_sat)^2 / 2``) make ``P_nm``.
Thresholds ``T_k,q = K_fa,q sigma_ss,k,q``, ``K_fa,q = Q^-1(P_FA,q / (2 N_q))`` (``N_q`` monitored
modes; ``P_FA_H`` shared by two axes); alarm if some ``|dx_k,q| > T_k,q``. Each ``PL_q`` solves

``2 Q(PL_q / sigma_0,q) + sum_k P_k Q((PL_q - T_k,q) / sigma_k,q) = P_HMI,q (1 - P_nm / (P_HMI_V + P_HMI_H))``

by bisection (``P_HMI,q``: ``P_HMI_H / 2`` per horizontal axis, ``P_HMI_V`` down); ``HPL = sqrt(PL_N^2 +
PL_E^2)``, ``VPL = PL_D``; never below the fault-free levels ``sigma_0,q Q^-1(P_HMI,q' / 2)``
(``fault_free_levels``); infinite when the unmonitored probability exceeds the budget.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.scipy.special import ndtr, ndtri

from jaxfdi._numerics import linalg as _linalg
from jaxfdi.gnss._positioning import PositionFix, in_chunks, padded_sizes, padded_to, resized
from jaxfdi.gnss._raim import whitened

#: integrity and continuity budgets of the ARAIM ADD (LPV-200): P_HMI and P_FA, vertical / horizontal
P_HMI_VERTICAL, P_HMI_HORIZONTAL = 9.8e-8, 2e-9
P_FA_VERTICAL, P_FA_HORIZONTAL = 3.9e-6, 9e-8
#: prior probability of a satellite fault, and of a constellation-wide fault (GPS's, per the ADD)
P_SATELLITE, P_CONSTELLATION = 1e-5, 1e-8
#: bisection steps for each protection level (the bracket shrinks 2^-60)
BISECTIONS = 60


class SolutionSeparation(NamedTuple):
    """One epoch's solution-separation test and levels (K = S + C modes: S satellites, then C constellations).

    Attributes:
      hpl: () m, horizontal protection level (inf when unavailable)
      vpl: () m, vertical protection level (inf when unavailable)
      separation: (K, 3) m, fault-tolerant minus all-in-view position, north-east-down (0 where not monitored)
      threshold: (K, 3) m, the test thresholds ``K_fa sigma_ss`` (inf where not monitored)
      sigma: (K, 3) m, standard deviations of the fault-tolerant solutions
      monitored: (K,) bool, modes whose fault-tolerant solution exists
      unmonitored: () probability of the fault modes not monitored
      alarm: () bool, some separation beyond its threshold
      isolated: () int, the mode with the largest separation relative to its threshold (-1: no alarm)
    """

    hpl: Array
    vpl: Array
    separation: Array
    threshold: Array
    sigma: Array
    monitored: Array
    unmonitored: Array
    alarm: Array
    isolated: Array


def _q_inverse(p: Array) -> Array:
    return -ndtri(p)


def _solve_level(
    sigma0: Array, threshold: Array, sigma: Array, prior: Array, budget: Array
) -> Array:
    """The ``PL`` of ``2 Q(PL / sigma0) + sum_k prior_k Q((PL - T_k) / sigma_k) = budget``
    (monitored modes only in ``prior``), by bisection on a bracket from the terms alone."""
    count = jnp.sum(prior > 0) + 1.0
    share = budget / count
    low = sigma0 * _q_inverse(budget / 2.0)
    upper_k = jnp.where(
        prior > 0,
        threshold + sigma * _q_inverse(jnp.minimum(share / jnp.maximum(prior, 1e-300), 0.5)),
        -jnp.inf,
    )
    high = jnp.maximum(sigma0 * _q_inverse(share / 2.0), jnp.max(upper_k))

    def excess(level):
        terms = jnp.where(prior > 0, prior * ndtr(-(level - threshold) / sigma), 0.0)
        return 2.0 * ndtr(-level / sigma0) + jnp.sum(terms) - budget

    def step(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        above = excess(mid) > 0.0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    _, level = jax.lax.fori_loop(0, BISECTIONS, step, (low, high))
    return jnp.where(budget > 0.0, level, jnp.inf)


def solution_separation(
    fix: PositionFix,
    p_satellite: float = P_SATELLITE,
    p_constellation=P_CONSTELLATION,
    p_hmi: tuple[float, float] = (P_HMI_HORIZONTAL, P_HMI_VERTICAL),
    p_fa: tuple[float, float] = (P_FA_HORIZONTAL, P_FA_VERTICAL),
) -> SolutionSeparation:
    """Solution-separation test and protection levels of ``fix`` (module docstring).

    Args:
      fix: a least-squares fix (``solve_position``), its geometry north-east-down plus one
        clock column per constellation (a slot's constellation is its clock column).
      p_satellite: prior of a satellite fault.
      p_constellation: prior of a constellation-wide fault, a scalar or one per clock column.
      p_hmi, p_fa: (horizontal, vertical) integrity risk and false-alarm budgets.

    Returns:
      ``SolutionSeparation`` of the K = S + C modes.
    """
    h, y = whitened(fix)
    slots, unknowns = h.shape
    clocks = unknowns - 3
    dtype = h.dtype
    used = fix.used
    constellation = jnp.argmax(jnp.abs(fix.geometry[:, 3:]), axis=1)
    member = used[:, None] & (constellation[:, None] == jnp.arange(clocks))  # (S, C)
    masks = jnp.concatenate(
        [used[None, :] & ~jnp.eye(slots, dtype=bool), (used[:, None] & ~member).T]
    )  # (K, S)
    present = jnp.concatenate([used, jnp.any(member, axis=0)])  # modes that exist
    prior = jnp.concatenate(
        [
            jnp.full(slots, p_satellite, dtype),
            jnp.broadcast_to(jnp.asarray(p_constellation, dtype), (clocks,)),
        ]
    )
    prior = jnp.where(present, prior, 0.0)

    def normal_inverse(mask):
        kept_clocks = jnp.any(member & mask[:, None], axis=0)
        weights = mask.astype(dtype)
        normal = jnp.einsum("s,si,sj->ij", weights, h, h)
        dropped = jnp.concatenate([jnp.zeros(3, bool), ~kept_clocks])
        normal = normal + jnp.diag(
            jnp.where(dropped, 1.0, 0.0)
        )  # a clock without satellites: unknown removed
        solvable = jnp.sum(mask) >= 3 + jnp.sum(kept_clocks)
        inverse = _linalg.psd_solve(normal, jnp.eye(unknowns, dtype=dtype))
        return inverse, weights, solvable

    inverse0, _, solvable0 = normal_inverse(used)
    inverses, weights, solvable = jax.vmap(normal_inverse)(masks)
    separation = jnp.einsum("kij,ks,sj,s->ki", inverses, weights, h, y)[:, :3]
    sigma = jnp.sqrt(jnp.maximum(jnp.diagonal(inverses, axis1=1, axis2=2)[:, :3], 0.0))
    sigma0 = jnp.sqrt(jnp.diagonal(inverse0)[:3])
    sigma_ss = jnp.sqrt(jnp.maximum(sigma**2 - sigma0**2, 0.0))
    monitored = present & solvable & solvable0
    used_count = jnp.sum(used)
    multiple = 0.5 * (used_count * p_satellite) ** 2
    unmonitored = jnp.sum(jnp.where(present & ~monitored, prior, 0.0)) + multiple
    hmi_h, hmi_v = p_hmi
    fa_h, fa_v = p_fa
    count = jnp.maximum(jnp.sum(monitored), 1)
    k_fa = _q_inverse(jnp.array([fa_h / 4.0, fa_h / 4.0, fa_v / 2.0], dtype) / count)
    threshold = jnp.where(monitored[:, None], k_fa * sigma_ss, jnp.inf)
    # a mode that cannot move the solution (a satellite alone on its clock: sigma_ss = 0) has
    # nothing to test; its threshold 0 stays in the levels, where it is exact
    testable = monitored[:, None] & (sigma_ss > 1e-9 * sigma0)
    ratio = jnp.where(testable, jnp.abs(separation) / jnp.where(testable, threshold, 1.0), 0.0)
    alarm = jnp.any(ratio > 1.0)
    isolated = jnp.where(alarm, jnp.argmax(jnp.max(ratio, axis=1)), -1).astype(jnp.int32)
    scale = jnp.maximum(1.0 - unmonitored / (hmi_h + hmi_v), 0.0)
    prior_monitored = jnp.where(monitored, prior, 0.0)
    budgets = jnp.array([hmi_h / 2.0, hmi_h / 2.0, hmi_v], dtype) * scale  # north, east, down
    levels = jax.vmap(_solve_level, in_axes=(0, 1, 1, None, 0))(
        sigma0, threshold, jnp.where(monitored[:, None], sigma, 1.0), prior_monitored, budgets
    )
    available = solvable0 & (scale > 0.0)
    hpl = jnp.where(available, jnp.hypot(levels[0], levels[1]), jnp.inf)
    vpl = jnp.where(available, levels[2], jnp.inf)
    return SolutionSeparation(
        hpl,
        vpl,
        jnp.where(monitored[:, None], separation, 0.0),
        threshold,
        sigma,
        monitored,
        unmonitored,
        alarm,
        isolated,
    )


_separations = jax.jit(jax.vmap(solution_separation, in_axes=(0, None, None, None, None)))


def separate_epochs(
    fix: PositionFix,
    p_satellite: float = P_SATELLITE,
    p_constellation=P_CONSTELLATION,
    p_hmi: tuple[float, float] = (P_HMI_HORIZONTAL, P_HMI_VERTICAL),
    p_fa: tuple[float, float] = (P_FA_HORIZONTAL, P_FA_VERTICAL),
) -> SolutionSeparation:
    """``solution_separation`` per epoch of a fix with a leading axis (T, ...), ``positioning.EPOCH_CHUNK``
    at a time, padded as a phone trace (unused slots, empty clocks, zero prior): fixes of up to 64 slots
    share one program. Arguments as ``solution_separation``.

    Returns:
      ``SolutionSeparation`` with a leading T axis on every leaf; modes K = S + C as there.
    """
    fix = jax.tree_util.tree_map(np.asarray, fix)
    epochs, slots, columns = fix.geometry.shape
    rows, width, wide = padded_sizes(epochs, slots, columns - 3)
    padded = resized(
        fix, rows, width, wide, fills={"sigma": 1.0}
    )  # unused slots, clocks without satellites
    prior = padded_to(
        np.broadcast_to(np.asarray(p_constellation, fix.residuals.dtype), (columns - 3,)),
        (wide,),
        0.0,
    )
    out = in_chunks(
        lambda chunk: _separations(chunk, p_satellite, prior, p_hmi, p_fa), epochs, padded
    )
    modes = np.r_[0:slots, width : width + columns - 3]  # the satellites', then the constellations'
    isolated = np.where(out.isolated >= width, out.isolated - width + slots, out.isolated)
    return jax.tree_util.tree_map(
        jnp.asarray,
        out._replace(
            separation=out.separation[:, modes],
            threshold=out.threshold[:, modes],
            sigma=out.sigma[:, modes],
            monitored=out.monitored[:, modes],
            isolated=isolated.astype(out.isolated.dtype),
        ),
    )


def fault_free_levels(
    fix: PositionFix, p_hmi: tuple[float, float] = (P_HMI_HORIZONTAL, P_HMI_VERTICAL)
):
    """All-in-view levels ``sigma_0,q Q^-1(P_HMI,q / 2)`` per axis (``P_HMI_H / 2`` on N and E), the floor
    of the solution-separation levels.

    Returns:
      ``(hpl, vpl)`` [m].
    """
    h, _ = whitened(fix)
    inverse0 = _linalg.psd_solve(h.T @ h, jnp.eye(h.shape[1], dtype=h.dtype))
    sigma0 = jnp.sqrt(jnp.diagonal(inverse0)[:3])
    hmi_h, hmi_v = p_hmi
    return (
        jnp.hypot(sigma0[0], sigma0[1]) * _q_inverse(hmi_h / 4.0),
        sigma0[2] * _q_inverse(hmi_v / 2.0),
    )
