"""Arranging redundant two-axis sensors for isolability, by gradient (optax).

Sensor ``i``'s two orthogonal input axes are the first two columns of ``R(q_i)``, ``q_i`` a unit quaternion
(Shuster 1993): any 4-vector (normalised inside) is a valid sensor. Stacked axes: ``H`` ((2S, 3), rows ``a_i1, a_i2``).

Isolability from the projector ``P = I - H (H^T H)^-1 H^T = V^T V`` (no SVD of ``H``: differentiable): sensor
``i``'s fault subspace is ``span(P E_i)`` (``E_i`` its channel columns), Gram ``G_i = E_i^T P E_i = V_i^T V_i``.

- *Fault-plane separation*: principal-angle cosines between subspaces ``i``, ``k`` are the singular values of
  ``G_i^-1/2 E_i^T P E_k G_k^-1/2``. For three 2-DOF sensors (3-D parity space) two planes always share a line
  (cosine 1, the singular direction); the other angle is the dihedral angle. Faults near the shared line are
  ambiguous over a cone of width ~ ``1 / sin(dihedral)``, so the criterion is the smallest dihedral angle
  (``isolability``), at most 90 deg.
- *Detectability*: ``lambda_min(G_i)``, the smallest parity energy of a unit fault of sensor ``i``
  (``||V_i f||^2 >= lambda_min ||f||^2``); ``sum_i trace G_i = trace P = q`` caps the worst case at ``q / (d S)``
  (0.5 for three 2-DOF sensors).
- *Isolation rate* (Monte Carlo surrogate): over fixed-size faults in random directions of random sensors with
  noise, ``sigmoid(FD / sigma^2 - chi2_isf(q, P_fa)) sigmoid((FI_true - max_other FI) / tau)``, smooth "detected,
  and PSA alone picks the faulty sensor" (``parity``'s ``FD``, ``FI``).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import chi2_threshold
from jaxfdi.detection._parity import check_groups


class Isolability(NamedTuple):
    """Geometry of a sensor set's fault subspaces (``isolability``).

    Attributes:
      dihedral: (S, S) largest principal angle between the fault subspaces, rad (0 on the diagonal)
      min_dihedral: () smallest off-diagonal dihedral angle, rad
      detectability: (S,) lambda_min(V_i^T V_i)
      isotropy: () ||H^T H / trace(H^T H) * 3 - I||_F (0: isotropic rate estimate)
    """

    dihedral: Array
    min_dihedral: Array
    detectability: Array
    isotropy: Array


class ConfigurationResult(NamedTuple):
    """``optimize_configuration``'s result (leading axis: the starts).

    Attributes:
      quaternions: (starts, S, 4) final parameters (not normalised)
      axes: (starts, 2S, 3) H of each start
      objective: (starts, steps) objective value per step (to maximise)
      best: () int, the start with the largest final objective
    """

    quaternions: Array
    axes: Array
    objective: Array
    best: Array


def quaternion_axes(quaternion: Array) -> Array:
    """(2, 3): two orthogonal unit input axes, the first two columns of the rotation of ``quaternion`` (4,), scalar
    first, normalised here."""
    w, x, y, z = quaternion / jnp.linalg.norm(quaternion)
    first = jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
    second = jnp.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)])
    return jnp.stack([first, second])


def sensor_axes(quaternions: Array) -> Array:
    """(2S, 3) ``H`` of sensors ``quaternions`` (S, 4)."""
    return jax.vmap(quaternion_axes)(quaternions).reshape(-1, 3)


def _inverse_sqrt(gram: Array) -> Array:
    """``gram^-1/2`` of an SPD matrix; 2 x 2 in closed form, ``adj(M + s I) / (s sqrt(tr M + 2 s))``,
    ``s = sqrt(det M)`` (smooth where ``eigh``'s derivative divides by the eigengap, e.g. at the paper's ``I / 2``)."""
    if gram.shape[-1] != 2:
        values, vectors = jnp.linalg.eigh(gram)
        return (vectors / jnp.sqrt(values)) @ vectors.T
    a, b, c = gram[0, 0], gram[0, 1], gram[1, 1]
    s = jnp.sqrt(a * c - b * b)
    scale = 1.0 / (s * jnp.sqrt(a + c + 2.0 * s))
    return scale * jnp.stack([jnp.stack([c + s, -b]), jnp.stack([-b, a + s])])


def _smallest_eigenvalue(sym: Array) -> Array:
    """Smallest eigenvalue of symmetric (..., d, d); 2 x 2 in closed form, ``(tr - sqrt((a - c)^2 + 4 b^2)) / 2``,
    root kept away from 0 by 1e-30."""
    if sym.shape[-1] != 2:
        return jnp.linalg.eigvalsh(sym)[..., 0]
    a, b, c = sym[..., 0, 0], sym[..., 0, 1], sym[..., 1, 1]
    return 0.5 * (a + c - jnp.sqrt((a - c) ** 2 + 4.0 * b * b + 1e-30))


def _pair_geometry(H: Array, groups: Array) -> tuple[Array, Array, Array]:
    """``(P, G (S, d, d), whitened cross products (S, S, d, d))``."""
    P = jnp.eye(H.shape[0], dtype=H.dtype) - H @ jnp.linalg.solve(H.T @ H, H.T)
    blocks = P[groups[:, None, :, None], groups[None, :, None, :]]  # (S, S, d, d): E_i^T P E_k
    gram = blocks[jnp.arange(groups.shape[0]), jnp.arange(groups.shape[0])]
    root = jax.vmap(_inverse_sqrt)(gram)
    return P, gram, jnp.einsum("iab,ikbc,kcd->ikad", root, blocks, root)


def isolability(H: Array, groups: Array) -> Isolability:
    """Fault-subspace geometry of ``H`` ((m, 3)) with sensor ``groups`` ((S, d)) (module doc).

    Returns:
      ``Isolability`` in ``H``'s float dtype: dihedral angles (S, S) and their off-diagonal minimum () in rad, the
      detectabilities (S,) and the isotropy ().
    """
    checks.check_matrix("H", H, (None, 3), "one input axis per row")
    groups = check_groups(groups, checks.shape_of(H)[0])
    return _isolability(jnp.asarray(H, checks.float_dtype(H)), groups)


@jax.jit
def _isolability(H: Array, groups: Array) -> Isolability:
    """``isolability`` once ``H`` is checked, as one program."""
    _, gram, cross = _pair_geometry(H, groups)
    cos2 = _smallest_eigenvalue(
        jnp.einsum("ikba,ikbc->ikac", cross, cross)
    )  # smallest squared cosine
    sin2 = jnp.clip(1.0 - cos2, 0.0, 1.0)
    dihedral = jnp.arcsin(jnp.sqrt(sin2))
    eye = jnp.eye(groups.shape[0], dtype=bool)
    dihedral = jnp.where(eye, 0.0, dihedral)
    normal = H.T @ H
    isotropy = jnp.linalg.norm(3.0 * normal / jnp.trace(normal) - jnp.eye(3, dtype=H.dtype))
    return Isolability(
        dihedral, jnp.min(jnp.where(eye, jnp.inf, dihedral)), _smallest_eigenvalue(gram), isotropy
    )


def _soft_min(values: Array, temperature: float) -> Array:
    return -temperature * jax.nn.logsumexp(-values / temperature)


def separation_objective(
    H: Array, groups: Array, temperature: float = 0.02, detectability_weight: float = 1.0
) -> Array:
    """Soft min of dihedral angles' ``sin^2`` + ``detectability_weight`` x soft min of detectabilities (maximise)."""
    _, gram, cross = _pair_geometry(H, groups)
    cos2 = _smallest_eigenvalue(jnp.einsum("ikba,ikbc->ikac", cross, cross))
    S = groups.shape[0]
    upper = jnp.triu_indices(S, 1)
    sin2 = 1.0 - cos2[upper]
    return _soft_min(sin2, temperature) + detectability_weight * _soft_min(
        _smallest_eigenvalue(gram), temperature
    )


def _draws(H: Array, groups: Array, sigma: float, fault_to_noise: float, key: Array, samples: int):
    """``(P, sensor (N,), FD / sigma^2 (N,), FI (N, S))`` of ``samples`` random faults with noise."""
    m = H.shape[0]
    S, d = groups.shape
    P, _, _ = _pair_geometry(H, groups)
    k_group, k_dir, k_noise = jax.random.split(key, 3)
    sensor = jax.random.randint(k_group, (samples,), 0, S)
    direction = jax.random.normal(k_dir, (samples, d), H.dtype)
    direction = direction / jnp.linalg.norm(direction, axis=-1, keepdims=True)
    faults = (
        jnp.zeros((samples, m), H.dtype)
        .at[jnp.arange(samples)[:, None], groups[sensor]]
        .set(fault_to_noise * sigma * np.sqrt(d) * direction)
    )
    residual = (
        faults + sigma * jax.random.normal(k_noise, (samples, m), H.dtype)
    ) @ P  # V^T p: ||.|| = ||p||
    statistic = jnp.sum(residual * residual, axis=-1) / sigma**2
    return P, sensor, statistic, _isolation_functions_from_projector(P, groups, residual)


def _threshold(H: Array, pfa) -> Array:
    """``chi2_isf(q, pfa)``, ``q = m - 3``: a trace-time number for a concrete ``pfa`` (no Newton per step)."""
    with jax.ensure_compile_time_eval():
        return chi2_threshold(H.shape[0] - H.shape[1], jnp.asarray(pfa, H.dtype))


def isolation_surrogate(
    H: Array,
    groups: Array,
    sigma: float,
    fault_to_noise: float,
    key: Array,
    samples: int = 4096,
    pfa: float = 1e-6,
    temperature: float = 0.02,
) -> Array:
    """Smooth Monte Carlo rate of "detected, and PSA alone picks the faulty sensor" (module doc): common random
    numbers from ``key``, faults of RMS ``fault_to_noise * sigma`` per axis, detection
    ``FD > sigma^2 chi2_isf(q, pfa)`` smoothed over one unit of ``FD / sigma^2``."""
    S = groups.shape[0]
    _, sensor, statistic, fi = _draws(H, groups, sigma, fault_to_noise, key, samples)
    detected = jax.nn.sigmoid(statistic - _threshold(H, pfa))
    true = jnp.take_along_axis(fi, sensor[:, None], axis=1)[:, 0]
    other = jnp.max(jnp.where(jax.nn.one_hot(sensor, S, dtype=bool), -jnp.inf, fi), axis=1)
    return jnp.mean(detected * jax.nn.sigmoid((true - other) / temperature))


def _isolation_functions_from_projector(P: Array, groups: Array, residual: Array) -> Array:
    """``FI_i`` of parity vectors given as ``V^T p`` (rows of ``residual``, in ``range(P)``); sensor ``i``'s subspace
    ``span(P E_i)`` orthonormalised by ``G_i^-1/2``."""
    cols = P[:, groups]  # (m, S, d)
    gram = jnp.einsum("msa,msb->sab", cols, cols)
    basis = jnp.einsum("msa,sab->smb", cols, jax.vmap(_inverse_sqrt)(gram))  # (S, m, d) orthonormal
    coords = jnp.einsum("smd,nm->nsd", basis, residual)
    away = residual[:, None, :] - jnp.einsum("smd,nsd->nsm", basis, coords)
    size = jnp.linalg.norm(residual, axis=-1, keepdims=True)
    return 1.0 - jnp.linalg.norm(away, axis=-1) / size


@partial(jax.jit, static_argnames=("samples",))
def isolation_rate(
    H: Array,
    groups: Array,
    sigma: float,
    fault_to_noise: float,
    key: Array,
    samples: int = 100_000,
    pfa: float = 1e-6,
) -> Array:
    """Hard Monte Carlo rate of the same draws: detected (``FD > T_D``) and ``argmax FI`` the faulty sensor.

    Returns:
      () the fraction of the ``samples`` draws detected and isolated to the faulty sensor, in [0, 1].
    """
    _, sensor, statistic, fi = _draws(H, groups, sigma, fault_to_noise, key, samples)
    detected = statistic > _threshold(H, pfa)
    return jnp.mean(detected & (jnp.argmax(fi, axis=1) == sensor))


def optimize_configuration(
    key: Array,
    sensors: int = 3,
    starts: int = 16,
    steps: int = 400,
    learning_rate: float = 0.05,
    objective: str = "separation",
    sigma: float = 0.01,
    fault_to_noise: float = 10.0,
    samples: int = 4096,
    pfa: float = 1e-6,
    dtype=None,
) -> ConfigurationResult:
    """Adam (optax) from ``starts`` random quaternions per sensor, vmapped over the starts.

    Args:
      key: PRNG key (starts, and the surrogate's common random numbers).
      sensors: number of 2-DOF sensors S (>= 3 for a parity space with isolation).
      starts, steps, learning_rate: the optimisation (static counts).
      objective: ``"separation"`` (``separation_objective``) or ``"isolation"`` (``isolation_surrogate`` at
        ``sigma``, ``fault_to_noise``, ``samples`` draws, detection at ``pfa``).

    Returns:
      ``ConfigurationResult`` in ``dtype``; ``best`` () int32 by the objective after the last step.
    """
    sensors = checks.check_int("sensors", sensors, 3, meaning="a number of 2-DOF sensors >= 3")
    starts = checks.check_int("starts", starts, 1, meaning="a number of random starts")
    steps = checks.check_int("steps", steps, 1, meaning="a number of optimiser steps")
    checks.check_positive("learning_rate", learning_rate)
    checks.check_choice("objective", objective, ["separation", "isolation"])
    dtype = dtype or jnp.result_type(float)
    return _optimize(
        key,
        sensors,
        starts,
        steps,
        float(learning_rate),
        objective,
        float(sigma),
        float(fault_to_noise),
        int(samples),
        float(pfa),
        jnp.dtype(dtype),
    )


@partial(jax.jit, static_argnums=tuple(range(1, 11)))
def _optimize(
    key,
    sensors,
    starts,
    steps,
    learning_rate,
    objective,
    sigma,
    fault_to_noise,
    samples,
    pfa,
    dtype,
):
    """``optimize_configuration`` as one compiled program (starts, the Adam scan, results)."""
    groups = jnp.arange(2 * sensors, dtype=jnp.int32).reshape(sensors, 2)
    k_start, k_mc = jax.random.split(key)
    if objective == "separation":

        def value(q):
            return separation_objective(sensor_axes(q), groups)
    else:

        def value(q):
            return isolation_surrogate(
                sensor_axes(q), groups, sigma, fault_to_noise, k_mc, samples, pfa
            )

    optimizer = optax.adam(learning_rate)

    def run(q0):
        def body(carry, _):
            q, opt_state = carry
            v, g = jax.value_and_grad(value)(q)
            updates, opt_state = optimizer.update(
                jax.tree_util.tree_map(jnp.negative, g), opt_state, q
            )
            return (optax.apply_updates(q, updates), opt_state), v

        (q, _), values = jax.lax.scan(body, (q0, optimizer.init(q0)), None, length=steps)
        return q, values

    q0 = jax.random.normal(k_start, (starts, sensors, 4), dtype)
    quaternions, values = jax.vmap(run)(q0)
    finals = jax.vmap(value)(quaternions)
    return ConfigurationResult(
        quaternions,
        jax.vmap(sensor_axes)(quaternions),
        values,
        jnp.argmax(finals).astype(jnp.int32),
    )


__all__ = [
    "Isolability",
    "ConfigurationResult",
    "quaternion_axes",
    "sensor_axes",
    "isolability",
    "separation_objective",
    "isolation_surrogate",
    "isolation_rate",
    "optimize_configuration",
]
