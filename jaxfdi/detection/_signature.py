"""Fault signature matrix and isolation by matching the symptom vector (Lee & Lyou, eq. 20, Table 2).

One filter per fault hypothesis: under fault i filter i's statistic stays low, every other grows. Symptom vector
``S``: one bit per filter (statistic over threshold). Signature matrix: a "no fault" column of zeros and, for fault
i, ones with a 0 in row i; isolation returns the column equal to ``S``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks

#: isolation result when the symptom vector matches no column (e.g. a transient in
#: which only some filters have crossed yet, or a fault outside the hypotheses).
UNMATCHED = -1


def signature_matrix(num_filters: int) -> np.ndarray:
    """(F, F + 1) bool: column 0 "no fault", column ``i + 1`` fault i (all ones but row i)."""
    num_filters = checks.check_int(
        "num_filters", num_filters, 1, meaning="a positive number of filters"
    )
    faults = ~np.eye(num_filters, dtype=bool)
    return np.hstack([np.zeros((num_filters, 1), bool), faults])


def isolate(symptoms: Array, matrix: Array | None = None) -> Array:
    """Match the symptom vector(s) ``symptoms`` (..., F) bool against ``matrix`` (F, K).

    Returns:
      int array (...): the index of the (first) matching column: 0 no fault, ``i + 1`` fault
      of filter i for the default matrix, ``UNMATCHED`` (-1) when no column matches.
    """
    symptoms = jnp.asarray(symptoms, bool)
    F = symptoms.shape[-1]
    matrix = jnp.asarray(signature_matrix(F) if matrix is None else matrix, bool)
    if matrix.ndim != 2 or matrix.shape[0] != F:
        raise ValueError(
            f"matrix: expected shape ({F}, K) for {F} filters, got {tuple(matrix.shape)}"
        )
    match = jnp.all(symptoms[..., :, None] == matrix, axis=-2)  # (..., K)
    return jnp.where(jnp.any(match, axis=-1), jnp.argmax(match, axis=-1), UNMATCHED)


def location_symptoms(alarms: Array, location: Array, num_locations: int) -> Array:
    """Per-location symptoms (..., L) from per-filter alarms (..., F) for banks with several filters per location
    (e.g. multiplicative and additive hypotheses): set when every filter of the location alarms, so a fault there
    leaves it clear while one of its hypotheses explains the data.

    Returns:
      (..., L) bool: ``True`` where every filter with ``location[f] == l`` alarms.

    Raises:
      ValueError: naming ``location`` when a location ``0..L-1`` has no filter (its symptom would be set by no
      evidence).
    """
    num_locations = checks.check_int(
        "num_locations", num_locations, 1, meaning="a positive number of locations"
    )
    checks.check_index("location", location, num_locations, "a location index per filter")
    value = checks.concrete(location)
    if value is not None:
        empty = sorted(set(range(num_locations)) - set(np.asarray(value).ravel().tolist()))
        if empty:
            raise ValueError(
                f"location: expected at least one filter at every location 0..{num_locations - 1}, "
                f"got none at {empty}"
            )
    alarms = jnp.asarray(alarms, bool)
    location = jnp.asarray(location, jnp.int32)
    hit = location[:, None] == jnp.arange(num_locations)[None, :]  # (F, L)
    return jnp.all(alarms[..., :, None] | ~hit, axis=-2)
