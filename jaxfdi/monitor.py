"""One Monte Carlo run as one fused scan: plant -> filter -> detector -> metrics.

Fusing the four in a single ``lax.scan`` means nothing of length T is stored unless
asked (``keep_history=True``): a run costs a ``DetectionRecord`` of five integers, which
is what lets 10^5 runs fit in memory.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi.detection.chi2 import Detector
from jaxfdi.filters._base import Filter, FilterInfo
from jaxfdi.metrics import DetectionRecord, record_init, record_update
from jaxfdi.simulate import SimStep, Simulator


class MonitorHistory(NamedTuple):
    truth: SimStep       # (T, ...) labelled truth
    info: FilterInfo     # (T, ...) filter outputs
    statistic: Array     # (T,) test statistic
    alarm: Array         # (T,) bool decision


class MonitorResult(NamedTuple):
    record: DetectionRecord
    history: MonitorHistory | None


def monitor(
    sim: Simulator,
    filt: Filter,
    detector: Detector,
    x0: Array,
    filter_state0: Any,
    us: Array,
    key: Array,
    onset: Array,
    keep_history: bool = False,
) -> MonitorResult:
    """Simulate, filter and test one run; return its detection record (and history).

    Args:
      sim: the (faulty) plant; filt: the fault-blind filter; detector: fed ``info.nis``.
      x0: (n,) true initial state; filter_state0: ``filt.init(...)``.
      us: (T, nu) commanded inputs; key: PRNG key of the run.
      onset: () fault onset step used for the metrics (``faults.NEVER`` if none).
      keep_history: also return the (T, ...) history (memory grows with T).
    """
    us = jnp.asarray(us)
    if us.ndim != 2:
        raise ValueError(f"us: expected shape (T, nu), got {tuple(us.shape)}")

    def body(carry, ku):
        sim_state, filt_state, det_state, record = carry
        k, u = ku
        sim_state, truth = sim.step(sim_state, k, u, key)
        filt_state, info = filt.step(filt_state, truth.measurement, u)
        det_state, (statistic, alarm) = detector.step(det_state, info.nis)
        record = record_update(record, k, alarm)
        out = MonitorHistory(truth, info, statistic, alarm) if keep_history else None
        return (sim_state, filt_state, det_state, record), out

    carry0 = (sim.init(x0), filter_state0, detector.init(), record_init(onset))
    steps = jnp.arange(us.shape[0])
    (_, _, _, record), history = jax.lax.scan(body, carry0, (steps, us))
    return MonitorResult(record, history)
