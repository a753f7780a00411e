"""Parity space of a redundant sensor set, with faults acting on groups of channels (Potter & Deckert 1973;
2-DOF sensors: Park, Kim, Park & Roh 2004, Sec. 2.1).

Measurements ``m = H x + eps + f``: ``H`` (m, n) full column rank, ``m > n``, independent channels of equal noise
``sigma``. A *group* is one sensor's channels (a 2-DOF rate sensor's two axes); a fault acts on them in any direction.

- ``V`` ((q, m), ``q = m - n``): orthonormal rows spanning the left null space of ``H`` (last ``q`` left singular
  vectors), ``V H = 0``, ``V V^T = I_q``. Parity ``p = V m = V eps + V f`` (eq. 4).
- Detection (eq. 8): ``FD = p^T p``; fault-free ``FD / sigma^2 ~ chi2(q)``, ``T_D = sigma^2 chi2_isf(q, P_fa)``.
- Fault subspace ``FS_g = span(V[:, group_g])`` (Park et al.'s fault plane ``FP_i = span(v_ci1, v_ci2)``),
  orthonormal basis ``Q_g`` (``fault_bases``).
- Isolation (eq. 9, with the bars and norm the print lost): ``FI_g = 1 - ||p - Q_g Q_g^T p|| / ||p||``; for a 2-D
  plane in a 3-D parity space this is Park et al.'s ``FI_k = 1 - |p . u_k| / ||p||``, ``u_k`` the unit normal.
  ``FI_g = 1`` when ``p`` lies in ``FS_g``; group ``g`` is a *suspect* when ``FI_g > T_I``.
- Singular directions, where two fault subspaces meet: principal angles (Bjorck & Golub 1973) are the arc cosines
  of the singular values of ``Q_i^T Q_k``; a singular value 1 is a shared direction (a fault along it cannot be
  told between the groups; ``singular_faults``).
- ``T_I`` by Monte Carlo (``isolation_threshold``): the ``P_MI`` quantile of the faulty group's ``FI`` over
  detected random faults.

Array arithmetic only (no scan): vmaps over sensor sets, jits, differentiable in the measurements.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import chi2_threshold


class ParitySpace(NamedTuple):
    """The parity space of a sensor set (a pytree: vmap over sensor sets).

    Attributes:
      H: (m, n) measurement matrix, one row per channel
      V: (q, m) parity matrix: V H = 0, V V^T = I
      groups: (G, d) int: the channels of each sensor
      fault_bases: (G, q, d) orthonormal basis (columns) of each fault subspace
          span(V[:, group])
    """

    H: Array
    V: Array
    groups: Array
    fault_bases: Array


class SingularDirections(NamedTuple):
    """Where two fault subspaces come closest (``singular_directions``).

    Attributes:
      direction: (G, G, q) unit parity direction of group i closest to subspace k
          (0 on the diagonal)
      cosine: (G, G) cosine of the smallest principal angle
          (1: the subspaces share that direction)
    """

    direction: Array
    cosine: Array


class IsolationCalibration(NamedTuple):
    """``isolation_threshold``'s result.

    Attributes:
      threshold: () T_I
      missed_isolation: () fraction of the detected samples with FI of the faulty group <= T_I
      detected: () int, samples detected (FD > T_D) and used
      samples: () int, samples drawn
    """

    threshold: Array
    missed_isolation: Array
    detected: Array
    samples: Array


def check_groups(groups, m: int) -> Array:
    """``groups`` as (G, d) int32 channel indices of ``m`` channels, each channel in at most one group (when
    concrete); ``ValueError`` naming ``groups`` otherwise.

    Returns:
      the int32 array.
    """
    checks.check_int_array(
        "groups", groups, 0, m - 1, f"channel indices of the {m} channels (H's rows)"
    )
    groups = jnp.asarray(groups, jnp.int32)
    if groups.ndim != 2 or groups.shape[0] < 1 or groups.shape[1] < 1:
        raise ValueError(f"groups: expected shape (G, d) with G, d >= 1, got {groups.shape}")
    values = checks.concrete(groups)
    if values is not None and len(np.unique(values)) != values.size:
        raise ValueError(
            f"groups: expected every channel in at most one group, got {checks.received(values)}"
        )
    return groups


def parity_space(H: Array, groups: Array | None = None) -> ParitySpace:
    """The parity space of ``H`` with the sensor ``groups``.

    Args:
      H: (m, n), ``m > n``, full column rank: row ``j`` is channel ``j``'s measurement direction (rate sensors:
        the input axis).
      groups: (G, d) channel indices of each sensor, every channel at most once; default ``[[0], [1], ..., [m - 1]]``.

    Returns:
      ``ParitySpace`` in ``H``'s float dtype, ``q = m - n``, ``groups`` int32.

    Raises:
      ValueError: for a concrete ``H`` without full column rank, a channel index out of range or used twice, or a
        group whose fault subspace has fewer than ``d`` dimensions (a fault along some direction leaves no parity).
    """
    checks.check_matrix("H", H, (None, None), "one measurement row per channel")
    H = jnp.asarray(H, checks.float_dtype(H))
    m, n = H.shape
    if m <= n:
        raise ValueError(
            f"H: expected more channels than states (m > n) for a parity space, got shape {H.shape}"
        )
    groups = check_groups(jnp.arange(m)[:, None] if groups is None else groups, m)
    values = checks.concrete(groups)
    if groups.shape[1] > m - n:
        raise ValueError(
            f"groups: expected at most q = m - n = {m - n} channels per group (a group's fault must be "
            f"able to fill a subspace of the {m - n}-dimensional parity space), got {groups.shape[1]}"
        )
    U, s, _ = jnp.linalg.svd(H, full_matrices=True)
    singular = checks.concrete(s)
    if (
        singular is not None
        and not singular[-1] > 100 * m * np.finfo(singular.dtype).eps * singular[0]
    ):
        raise ValueError(
            f"H: expected full column rank {n}, got singular values {checks.received(singular)}"
        )
    V = U[:, n:].T
    columns = jnp.moveaxis(V[:, groups], 1, 0)  # (G, q, d)
    bases, spans, _ = jnp.linalg.svd(columns, full_matrices=False)
    spans = checks.concrete(spans)
    if spans is not None:
        tiny = 100 * m * np.finfo(spans.dtype).eps
        bad = np.nonzero(spans[:, -1] <= tiny)[0]
        if bad.size:
            raise ValueError(
                f"groups: the fault subspace of group {int(bad[0])} (channels "
                f"{np.asarray(values)[bad[0]].tolist() if values is not None else '?'}) has fewer than "
                f"{groups.shape[1]} dimensions: a fault of that sensor along some direction leaves no "
                f"parity (not enough redundancy); its singular values are {checks.received(spans[bad[0]])}"
            )
    return ParitySpace(H, V, groups, bases)


def parity_vector(space: ParitySpace, measurement: Array) -> Array:
    """``p = V m`` (eq. 4) for ``measurement`` (..., m): (..., q).

    Returns:
      (..., q) parity vector, in the measurement's units (a non-finite channel makes every entry non-finite).
    """
    return jnp.asarray(measurement) @ space.V.T


def parity_statistic(parity: Array, valid: Array | None = None) -> Array:
    """``p^T p`` over the last axis, entries outside the mask ``valid`` (e.g. RAIM's unused satellite slots) left
    out; fault-free and whitened, chi2 with as many dof as valid entries (Potter & Deckert 1973; Brown & Chin 1992).
    A non-finite valid entry (a dead channel's) makes it ``+inf``: evidence that alarms, never a NaN that compares
    false with every threshold.

    Returns:
      the statistic, ``parity``'s shape without its last axis.
    """
    parity = jnp.asarray(parity)
    squares = jnp.where(jnp.isfinite(parity), jnp.square(parity), jnp.inf)
    return jnp.sum(squares if valid is None else jnp.where(valid, squares, 0.0), axis=-1)


def fault_detection_statistic(parity: Array) -> Array:
    """``FD = p^T p`` (eq. 8) over the last axis (``parity_statistic``: ``+inf`` for a non-finite parity)."""
    return parity_statistic(parity)


def dead_groups(space: ParitySpace, measurement: Array) -> Array:
    """(..., G) bool: the groups with a non-finite channel in ``measurement`` (..., m)."""
    return jnp.any(~jnp.isfinite(jnp.asarray(measurement)[..., space.groups]), axis=-1)


def parity_tests(space: ParitySpace, measurement: Array) -> tuple[Array, Array]:
    """``(FD, FI)`` (eqs. 8, 9) of ``measurement`` (..., m), a dead channel being a fault of its group: while one is
    non-finite, ``FD = +inf`` and ``FI`` is 1 for groups holding a dead channel, 0 for the others (the parity mixes
    every channel, so it says nothing else then)."""
    measurement = jnp.asarray(measurement)
    dead = dead_groups(space, measurement)
    parity = parity_vector(space, jnp.where(jnp.isfinite(measurement), measurement, 0.0))
    any_dead = jnp.any(dead, axis=-1)
    fd = jnp.where(any_dead, jnp.inf, fault_detection_statistic(parity))
    fi = jnp.where(
        any_dead[..., None], dead.astype(parity.dtype), isolation_functions(space, parity)
    )
    return fd, fi


def detection_threshold(space: ParitySpace, sigma, pfa) -> Array:
    """``T_D = sigma^2 chi2_isf(q, P_fa)``: fault-free, ``P(FD > T_D) = P_fa`` per sample.

    Returns:
      ``T_D`` in ``space.V``'s dtype, the broadcast shape of ``sigma`` and ``pfa`` (() for scalars), in ``sigma``'s
      units squared.
    """
    checks.check_positive("sigma", sigma, "the channels' noise standard deviation")
    q = space.V.shape[0]
    return jnp.square(jnp.asarray(sigma, space.V.dtype)) * chi2_threshold(
        q, jnp.asarray(pfa, space.V.dtype)
    )


def out_of_subspace(space: ParitySpace, parity: Array) -> Array:
    """``||p - Q_g Q_g^T p||`` (..., G), distance from each fault subspace, as a difference vector (not
    ``sqrt(||p||^2 - ||Q^T p||^2)``, which loses half the digits when ``p`` lies in the subspace)."""
    parity = jnp.asarray(parity)
    coords = jnp.einsum("gqd,...q->...gd", space.fault_bases, parity)
    projected = jnp.einsum("gqd,...gd->...gq", space.fault_bases, coords)
    return jnp.linalg.norm(parity[..., None, :] - projected, axis=-1)


def isolation_functions(space: ParitySpace, parity: Array) -> Array:
    """``FI_g = 1 - ||p - Q_g Q_g^T p|| / ||p||`` (eq. 9), ``parity`` (..., q) -> (..., G). 0 for ``p = 0`` (no
    evidence); NaN for a non-finite ``p`` (``parity_tests`` isolates a dead channel).

    Returns:
      (..., G) ``FI_g`` in ``[0, 1]``, one per group (1: ``p`` lies in the group's fault subspace).
    """
    parity = jnp.asarray(parity)
    size = jnp.linalg.norm(parity, axis=-1)[..., None]
    positive = size > 0
    fi = jnp.where(
        positive, 1.0 - out_of_subspace(space, parity) / jnp.where(positive, size, 1.0), 0.0
    )
    return jnp.where(jnp.isfinite(size), fi, jnp.nan)


def subspace_cosines(space: ParitySpace) -> Array:
    """(G, G, d) principal-angle cosines of every two fault subspaces (singular values of ``Q_i^T Q_k``, largest
    first)."""
    products = jnp.einsum("iqd,kqe->ikde", space.fault_bases, space.fault_bases)
    return jnp.clip(jnp.linalg.svd(products, compute_uv=False), 0.0, 1.0)


def subspace_angles(space: ParitySpace) -> Array:
    """(G, G, d) principal angles (rad, smallest first) between every two fault subspaces; 2-D planes in a 3-D
    parity space: ``[0, dihedral angle]``. ``atan2(sin, cos)``, sines from the singular values of
    ``(I - Q_k Q_k^T) Q_i`` (Knyazev & Argentati 2002): ``arccos`` alone is good to only ``sqrt(eps)`` near 0.

    Returns:
      (G, G, d) angles in ``[0, pi/2]`` rad, ``[i, k]`` between ``FS_i`` and ``FS_k``; 0 on the diagonal and along a
      singular direction.
    """
    Q = space.fault_bases
    cosines = subspace_cosines(space)
    away = Q[:, None] - jnp.einsum("kqe,kre,ird->ikqd", Q, Q, Q)  # (I - Q_k Q_k^T) Q_i
    sines = jnp.clip(jnp.linalg.svd(away, compute_uv=False)[..., ::-1], 0.0, 1.0)
    return jnp.arctan2(sines, cosines)


def singular_directions(space: ParitySpace) -> SingularDirections:
    """Per ordered pair ``(i, k)``: the unit direction of ``FS_i`` closest to ``FS_k`` (``Q_i a``, ``a`` the top
    left singular vector of ``Q_i^T Q_k``) and its cosine to ``FS_k``, 1 for a singular direction (Park et al.
    2004's plane intersections). Diagonal: direction 0, cosine 1."""
    products = jnp.einsum("iqd,kqe->ikde", space.fault_bases, space.fault_bases)
    left, values, _ = jnp.linalg.svd(products)
    direction = jnp.einsum("iqd,ikd->ikq", space.fault_bases, left[..., :, 0])
    eye = jnp.eye(space.groups.shape[0], dtype=bool)
    return SingularDirections(
        jnp.where(eye[..., None], 0.0, direction),
        jnp.where(eye, 1.0, jnp.clip(values[..., 0], 0.0, 1.0)),
    )


def singular_faults(space: ParitySpace) -> Array:
    """(G, G, d): group ``i``'s unit fault (on its ``d`` channels) whose parity lies along the singular direction
    shared with group ``k`` (least squares ``V_i^+ direction``): it cannot be told between ``i`` and ``k``. Sign:
    first nonzero entry positive; diagonal 0.

    Returns:
      (G, G, d) unit fault vectors: ``[i, k]`` acts on group ``i``'s ``d`` channels (``space.groups[i]``).
    """
    columns = jnp.moveaxis(space.V[:, space.groups], 1, 0)  # (G, q, d)
    dirs = singular_directions(space).direction  # (G, G, q)
    faults = jnp.einsum("idq,ikq->ikd", jnp.linalg.pinv(columns), dirs)
    norms = jnp.linalg.norm(faults, axis=-1, keepdims=True)
    faults = faults / jnp.where(norms > 0, norms, 1.0)
    tol = 1e3 * jnp.finfo(faults.dtype).eps
    lead = jnp.argmax(jnp.abs(faults) > tol, axis=-1)
    sign = jnp.where(jnp.take_along_axis(faults, lead[..., None], axis=-1) < 0, -1.0, 1.0)
    return faults * sign


def group_fault(space: ParitySpace, group: Array, fault: Array) -> Array:
    """(m,) the channel fault vector of ``fault`` (d,) acting on ``group``'s channels."""
    m = space.H.shape[0]
    return jnp.zeros((m,), jnp.result_type(fault, space.V.dtype)).at[space.groups[group]].set(fault)


def isolation_threshold(
    space: ParitySpace,
    sigma,
    fault_to_noise,
    missed_isolation,
    detection_threshold: Array,
    key: Array,
    samples: int = 100_000,
) -> IsolationCalibration:
    """``T_I`` by Monte Carlo from a missed-isolation probability (Park et al. 2004, Sec. 2.1).

    Each sample: group ``g`` uniform, fault direction uniform on the unit sphere of its ``d`` channels, RMS size per
    channel ``fault_to_noise * sigma`` (norm ``fault_to_noise * sigma * sqrt(d)``), noise ``N(0, sigma^2 I)``. Among
    detected samples (``FD > detection_threshold``), ``T_I`` makes the faulty group's ``FI_g <= T_I`` (missed
    isolation) in a fraction ``missed_isolation`` (midway between the order statistics around it: not exceeded).

    Args:
      space: ``parity_space(...)``.
      sigma: channel noise standard deviation.
      fault_to_noise: the design fault size (RMS per channel / sigma), > 0.
      missed_isolation: target probability, in (0, 1).
      detection_threshold: ``T_D`` on ``FD``.
      key: PRNG key.
      samples: number of samples (static).

    Returns:
      ``IsolationCalibration``: ``T_I`` (), the achieved missed-isolation fraction (), the number of detected samples
      () and ``samples`` (); ``T_I`` is ``inf`` when no sample is detected.
    """
    checks.check_positive("sigma", sigma, "the channels' noise standard deviation")
    checks.check_positive("fault_to_noise", fault_to_noise, "a fault-to-noise ratio")
    checks.check_probability("missed_isolation", missed_isolation)
    samples = checks.check_int("samples", samples, 2, meaning="a number of Monte Carlo samples")
    dtype = space.V.dtype
    G, d = space.groups.shape
    m = space.H.shape[0]
    k_group, k_dir, k_noise = jax.random.split(key, 3)
    group = jax.random.randint(k_group, (samples,), 0, G)
    direction = jax.random.normal(k_dir, (samples, d), dtype)
    direction = direction / jnp.linalg.norm(direction, axis=-1, keepdims=True)
    size = jnp.asarray(fault_to_noise, dtype) * jnp.asarray(sigma, dtype) * np.sqrt(d)
    faults = jax.vmap(lambda g, f: group_fault(space, g, size * f))(group, direction)
    noise = jnp.asarray(sigma, dtype) * jax.random.normal(k_noise, (samples, m), dtype)
    parity = parity_vector(space, faults + noise)
    detected = fault_detection_statistic(parity) > detection_threshold
    fi_true = jnp.take_along_axis(isolation_functions(space, parity), group[:, None], axis=-1)[:, 0]
    ordered = jnp.sort(jnp.where(detected, fi_true, jnp.inf))
    count = jnp.sum(detected)
    j = jnp.clip(
        jnp.floor(jnp.asarray(missed_isolation, dtype) * count).astype(jnp.int32), 1, samples - 1
    )
    threshold = 0.5 * (ordered[j - 1] + ordered[j])
    missed = jnp.sum(detected & (fi_true <= threshold)) / jnp.maximum(count, 1)
    return IsolationCalibration(threshold, missed, count, jnp.asarray(samples))


__all__ = [
    "ParitySpace",
    "SingularDirections",
    "IsolationCalibration",
    "parity_space",
    "parity_vector",
    "parity_statistic",
    "fault_detection_statistic",
    "detection_threshold",
    "out_of_subspace",
    "isolation_functions",
    "subspace_cosines",
    "subspace_angles",
    "singular_directions",
    "singular_faults",
    "group_fault",
    "isolation_threshold",
]
