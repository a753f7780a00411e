"""The study engine: a Monte Carlo study is data, and one function runs it.

A study names its cases (what each run simulates: a fault, a magnitude), the runs per case, and its methods grouped
by **structure**: methods differing only in numbers (a transition matrix, a threshold, a confirmation length) are
one compiled program with those numbers as arrays. ``run(key, case, *params)`` is one run of one method; the engine
``vmap`` s it over each of ``axes`` (parameter pytrees with a leading axis), outer first, so one program runs the
grid ``axes[0] x axes[1] x ...`` on the same simulated run, computing what does not depend on an axis once for it
(``axes = (filter_params (F,), detector_params (D,))``: the plant once per run, each of F filters once, feeding its
D detectors). A method is a grid cell (``methods``: name -> index tuple).

``run_study(study, runs, seed)`` runs every structure through ``monte_carlo`` on the same keys (every method sees
the same noise), case-major, and returns a ``StudyResult``: per method the runs' outputs (host NumPy, one transfer
per structure) and, for ``averaged`` structures, per-case means of the runs' traces summed on the device
(``monte_carlo``'s ``summary``; mean-history figures without keeping histories). One compiled program per structure
whatever ``runs`` and ``seed``; progress says which structure compiles (k of n) and how fast the runs go.

Example (two thresholds of one chi-square detector on one Kalman filter, one program)::

    structure = Structure("kf-chi2", run, axes=(jnp.array([9.2, 11.3]),),
                          methods={"chi2 1%": (0,), "chi2 0.1%": (1,)})
    study = Study("toy", cases=stack_faults(faults), case_names=names, structures=(structure,))
    result = run_study(study, runs=100, seed=0)
    result.outputs["chi2 1%"]          # (cases * runs, ...) case-major
"""

from __future__ import annotations

import functools
import html
import time
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxfdi import checks
from jaxfdi._io.progress import status
from jaxfdi._studies.frame import RUN_RATES, results_frame, results_html
from jaxfdi._studies.metrics import (
    DetectionRecord,
    fault_row,
    mean_interval,
    rate_bounds,
    rate_interval,
)
from jaxfdi._studies.montecarlo import _num_runs_of, monte_carlo

__all__ = ["Structure", "Study", "StudyResult", "run_study", "grid_run", "case_slices"]


class Structure(NamedTuple):
    """Methods that share one compiled program.

    Attributes:
      name: str, the structure's name (progress messages, ``StudyResult.seconds``)
      run: ``run(key, case, *params[, shared]) -> output`` (or ``(output, trace)``), one run of one method,
        ``params`` one slice of each of ``axes``
      axes: tuple of parameter pytrees, each with a leading axis (the grid's axes, outer first)
      methods: dict, method name -> its cell of the grid (a tuple of one index per axis)
      averaged: bool, ``run`` returns ``(output, trace)`` and ``trace`` (e.g. a mode-probability history) is
        averaged over each case's runs on the device instead of kept (once per axis it does not depend on)
      batched: bool, ``run(keys (B,), cases (B, ...), *params)`` takes and returns a whole chunk of runs (leading
        axis B), e.g. to drive a filter's batch kernel (``run_filter``) instead of ``vmap``
      shared: pytree every run of every cell reads whole (a design, an ephemeris, a flight's tables: not vmapped),
        passed after the parameters; data, not a closure, so other values compile nothing new; or ``None``
    """

    name: str
    run: Callable[..., Any]
    axes: tuple
    methods: dict
    averaged: bool = False
    batched: bool = False
    shared: Any = None


class Study(NamedTuple):
    """A study's specification: its cases, their names, and the structures that run the methods.

    Attributes:
      name: str, the study's name (progress messages, ``StudyResult.name``)
      cases: pytree with a leading case axis C (e.g. a stacked ``Fault``; case ``c``'s runs get slice ``c``), or,
        where runs differ beyond their noise (random onset, dispersion), ``draw(runs, seed)`` returning a pytree with
        a leading axis of all runs (``C * runs`` or the sum of per-case ``runs``), case-major (run ``i``: slice ``i``)
      case_names: tuple of C names, one per case
      structures: tuple of ``Structure``, the methods grouped by compiled program
      horizon: steps per run, or ``None``; where given, ``StudyResult.to_frame`` scores ``DetectionRecord`` outputs
      Ts: the sample period, the unit of the table's delays (1.0: delays in steps)
      labels: each case's fault label (isolation is scored against it), or ``None``
    """

    name: str
    cases: Any
    case_names: tuple
    structures: tuple
    horizon: int | None = None
    Ts: float = 1.0
    labels: tuple | None = None


class StudyResult(NamedTuple):
    """What ``run_study`` returns.

    Attributes:
      name: the study's name
      runs: int, or a tuple of one count per case
      seed: the PRNG seed of the runs
      case_names: the name of each case
      outputs: method -> its output of every run, leading axis ``C * runs`` (or the sum of per-case runs),
        case-major (``case_slices``)
      means: method -> (C, ...) per-case mean of the traces of an ``averaged`` structure
      seconds: structure -> wall time of its Monte Carlo [s], compilation included
      compile_seconds: structure -> compilation time alone [s] (0.0 when the program came from a cache)
    """

    name: str
    runs: Any
    seed: int
    case_names: tuple
    outputs: dict
    means: dict
    seconds: dict
    compile_seconds: dict
    horizon: int | None = None
    Ts: float = 1.0
    labels: tuple | None = None

    def to_frame(self, level: float = 0.95):
        """The result as a pandas DataFrame, one row per method and case (``study_rows``), each run rate beside its
        two-sided ``level`` Clopper-Pearson interval and each mean beside its normal ``level`` interval (``_low``,
        ``_high``)."""
        return results_frame(study_rows(self, level), level)

    def _repr_html_(self) -> str:
        try:
            frame = self.to_frame()
        except ValueError as error:
            return f"<p>{html.escape(str(error))}</p>"
        return results_html(frame, {"runs": self.runs, "seed": self.seed})

    def __repr__(self) -> str:
        return f"StudyResult({self.name!r}, {len(self.outputs)} methods x {len(self.case_names)} cases; .to_frame())"


def _mean_columns(name: str, values: np.ndarray, level: float) -> dict:
    """One case's per-run scalars as columns: bools as the rate ``name`` with its Clopper-Pearson interval, numbers as
    ``name_mean`` with its normal interval ``mean +- z sd / sqrt(n)`` (a non-finite run makes them NaN)."""
    n, nan = values.size, float("nan")
    if values.dtype == bool:
        low, high = rate_interval(int(values.sum()), n, level) if n else (nan, nan)
        return {name: float(values.mean()) if n else nan, f"{name}_low": low, f"{name}_high": high}
    mean, low, high = mean_interval(values, level)
    return {f"{name}_mean": mean, f"{name}_mean_low": low, f"{name}_mean_high": high}


def study_rows(result: StudyResult, level: float = 0.95) -> list[dict]:
    """One row per method and case of ``result``: ``method``, ``case``, then per output leaf: a ``DetectionRecord``
    scored by ``fault_row`` over ``result.horizon`` steps (delays in the unit of ``Ts``, isolation against the case's
    label, NaN for a method that never isolates: ``isolated`` -1 in every run); a per-run bool its rate with the
    ``level`` Clopper-Pearson interval (``rate_interval``, ``_low``, ``_high``); a per-run number its mean with the
    normal ``level`` interval. Leaves with more than a run axis (histories) stay in ``outputs``. Raises
    ``ValueError`` for ``DetectionRecord`` outputs without a horizon.

    Returns:
      list of dicts, method-major.
    """
    slices = case_slices(result.runs, len(result.case_names))
    rows = []
    for method, output in result.outputs.items():
        leaves, _ = jax.tree_util.tree_flatten_with_path(
            output, is_leaf=lambda x: isinstance(x, DetectionRecord)
        )
        for c, (case, part) in enumerate(zip(result.case_names, slices)):
            row = {"method": method, "case": case}
            for path, leaf in leaves:
                name = jax.tree_util.keystr(path, simple=True, separator=".") or "output"
                if isinstance(leaf, DetectionRecord):
                    if result.horizon is None:
                        raise ValueError(
                            f"horizon: expected the runs' length in steps (Study(..., horizon=)) to score "
                            f"{method!r}'s DetectionRecord, got None"
                        )
                    # a detector that only detects leaves isolated at -1 in every run
                    isolates = bool(np.any(np.asarray(leaf.isolated) >= 0))
                    label = None if result.labels is None or not isolates else result.labels[c]
                    record = jax.tree_util.tree_map(lambda x: np.asarray(x)[part], leaf)
                    scored = {}
                    for k, v in fault_row(record, result.horizon, result.Ts, label).items():
                        scored[k] = v
                        if k in RUN_RATES:  # over the healthy runs
                            n = record.onset.size - int(np.sum(record.first_unhealthy >= 0))
                            scored[f"{k}_low"], scored[f"{k}_high"] = rate_bounds(v, n, level)
                    row.update({f"{name}.{k}" if path else k: v for k, v in scored.items()})
                    continue
                values = np.asarray(leaf)
                if values.ndim == 1:
                    row.update(_mean_columns(name, values[part], level))
            rows.append(row)
    return rows


def grid_run(structure: Structure) -> Callable[[jax.Array, Any], Any]:
    """``(key, case) -> output`` with a leading axis per ``structure.axes`` (outer first): ``structure.run``
    vmapped over each axis in turn, key and case shared. A ``batched`` structure gives ``(B, *grid, ...)``."""
    count = len(structure.axes)
    extra = () if structure.shared is None else (structure.shared,)

    def run(key, case):
        fn = structure.run
        for axis in reversed(range(count)):
            fn = jax.vmap(
                fn,
                in_axes=(
                    None,
                    None,
                    *(0 if j == axis else None for j in range(count)),
                    *(None for _ in extra),
                ),
            )
        out = fn(key, case, *structure.axes, *extra)
        if structure.batched:
            out = jax.tree_util.tree_map(lambda leaf: jnp.moveaxis(leaf, count, 0), out)
        return out

    return run


def case_slices(runs, num_cases: int) -> list[slice]:
    """The run ranges of each case in a case-major output (``runs``: per case, or one count for all).

    Returns:
      list of ``num_cases`` slices, consecutive from 0: ``output[slices[i]]`` are case ``i``'s runs.
    """
    num_cases = checks.check_int("num_cases", num_cases, 0, meaning="a number of cases >= 0")
    try:
        counts = np.broadcast_to(np.asarray(runs, int), (num_cases,))
    except ValueError:
        raise ValueError(
            f"runs: expected one count or {num_cases} counts (one per case), got "
            f"{checks.received(runs)}"
        ) from None
    if np.any(counts < 0):
        raise ValueError(f"runs: expected counts >= 0, got {checks.received(runs)}")
    starts = np.concatenate([[0], np.cumsum(counts)])
    return [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:])]


def _run_counts(runs, num_cases: int) -> tuple[int, ...]:
    """``runs`` (one count, or one per case) as a count per case, each checked positive."""
    if np.ndim(runs) == 0:
        return (
            checks.check_int("runs", runs, 1, meaning="a positive number of runs per case"),
        ) * num_cases
    counts = tuple(runs)
    if len(counts) != num_cases:
        raise ValueError(
            f"runs: expected one count or {num_cases} counts (one per case), got {len(counts)}"
        )
    return tuple(
        checks.check_int(f"runs[{i}]", n, 1, meaning="a positive number of runs")
        for i, n in enumerate(counts)
    )


def _check_study(study: Study) -> int:
    if not isinstance(study, Study):
        raise TypeError(f"study: expected a jaxfdi.Study, got {checks.received(study)}")
    if callable(study.cases):
        num_cases = len(study.case_names)
    else:
        sizes = _num_runs_of(study.cases)
        if len(sizes) != 1 or -1 in sizes:
            raise ValueError(
                f"study.cases: expected leaves with one leading case axis, got leading sizes {sorted(sizes)}"
            )
        num_cases = sizes.pop()
    if not num_cases:
        raise ValueError("study.case_names: expected at least one case")
    if len(study.case_names) != num_cases:
        raise ValueError(
            f"study.case_names: expected {num_cases} names (one per case), got {len(study.case_names)}"
        )
    if not study.structures:
        raise ValueError("study.structures: expected at least one Structure")
    if study.horizon is not None:
        checks.check_int(
            "study.horizon", study.horizon, 1, meaning="a positive number of steps per run"
        )
    checks.check_positive("study.Ts", study.Ts, "a positive sample period")
    if study.labels is not None and len(study.labels) != num_cases:
        raise ValueError(
            f"study.labels: expected {num_cases} labels (one per case), got {len(study.labels)}"
        )
    seen = set()
    for s in study.structures:
        if not isinstance(s, Structure):
            raise TypeError(
                f"study.structures: expected Structure entries, got {checks.received(s)}"
            )
        lengths = []
        for a, axis in enumerate(s.axes):
            leading = _num_runs_of(axis)
            if len(leading) != 1 or -1 in leading:
                raise ValueError(
                    f"{s.name}.axes[{a}]: expected leaves with one leading axis, got {sorted(leading)}"
                )
            lengths.append(leading.pop())
        for method, cell in s.methods.items():
            if method in seen:
                raise ValueError(f"{s.name}.methods: method {method!r} named twice in the study")
            seen.add(method)
            if len(cell) != len(lengths) or not all(0 <= i < n for i, n in zip(cell, lengths)):
                raise ValueError(
                    f"{s.name}.methods[{method!r}]: expected one index per axis within {lengths}, "
                    f"got {cell}"
                )
    return num_cases


def run_study(
    study: Study,
    runs,
    seed: int,
    *,
    progress: bool = False,
    chunk_size: int | None = None,
    structures: list[str] | None = None,
    key: jax.Array | None = None,
) -> StudyResult:
    """Run ``runs`` runs of every case of ``study`` through each structure.

    Args:
      study: the ``Study``.
      runs: runs per case: one count for every case, or a sequence of one per case.
      seed: PRNG seed; run ``i`` (case-major) gets ``split(key(seed), total)[i]`` in every structure (``total``:
        ``C * runs``, or the sum of the per-case counts).
      progress: log which structure compiles and show the runs' progress.
      chunk_size: runs per compiled call (default: ``monte_carlo``'s, sized for the backend; no effect on results).
      structures: run only these structures (by name; default all).
      key: PRNG key to split instead of ``jax.random.key(seed)`` (runs from a key derived from the seed).

    Returns:
      ``StudyResult`` of the chosen structures' methods: NumPy outputs, leading case-major run axis.
    """
    num_cases = _check_study(study)
    counts = _run_counts(runs, num_cases)
    runs = counts[0] if np.ndim(runs) == 0 else counts
    seed = checks.check_int("seed", seed, 0, checks.MAX_SEED, "a PRNG seed")
    names = [s.name for s in study.structures]
    if structures is not None and (not structures or set(structures) - set(names)):
        raise ValueError(f"structures: expected names among {names}, got {list(structures)}")
    chosen = [s for s in study.structures if structures is None or s.name in structures]
    total = sum(counts)
    key = jax.random.key(seed) if key is None else key
    per_run = (
        _per_run_cases(study, runs, counts, seed),
        np.repeat(np.arange(num_cases, dtype=np.int32), counts),
    )
    outputs, means, seconds, compile_seconds = {}, {}, {}, {}
    for k, structure in enumerate(chosen, start=1):
        label = f"{study.name}: {structure.name} ({k} of {len(chosen)})"
        program = _program(structure)
        summary = _case_mean_summary(num_cases) if structure.averaged else None
        compile_before = _compile_time_probe()
        start = time.perf_counter()
        result = monte_carlo(
            program,
            key,
            total,
            per_run,
            chunk_size=chunk_size,
            progress=progress,
            summary=summary,
            shared=(structure.axes, structure.shared),
            label=label,
            batched=structure.batched,
        )
        seconds[structure.name] = time.perf_counter() - start
        compile_seconds[structure.name] = _compile_time_probe() - compile_before
        out, sums = result if summary is not None else (result, None)
        for method, cell in structure.methods.items():
            outputs[method] = jax.tree_util.tree_map(
                lambda leaf, c=cell: leaf[(slice(None), *c)], out
            )
            if sums is not None:
                totals, counts = sums
                means[method] = jax.tree_util.tree_map(
                    lambda leaf, c=cell: _per_case_mean(leaf, c, counts), totals
                )
        if progress:
            status(f"{label}: {total} runs in {seconds[structure.name]:.1f} s")
    return StudyResult(
        study.name,
        runs,
        seed,
        tuple(study.case_names),
        outputs,
        means,
        seconds,
        compile_seconds,
        study.horizon,
        study.Ts,
        None if study.labels is None else tuple(study.labels),
    )


def _per_run_cases(study: Study, runs, counts: tuple[int, ...], seed: int):
    """Every run's case: the study's cases repeated ``counts`` times each, or its ``draw``."""
    if not callable(study.cases):
        return jax.tree_util.tree_map(
            lambda leaf: np.repeat(np.asarray(leaf), counts, axis=0), study.cases
        )
    drawn = study.cases(runs, seed)
    sizes = _num_runs_of(drawn)
    if sizes != {sum(counts)}:
        raise ValueError(
            f"study.cases: the draw(runs={runs}, seed={seed}) must give leaves with a leading axis of "
            f"{sum(counts)} (the runs of every case), got leading sizes {sorted(sizes)}"
        )
    return drawn


def _per_case_mean(total, cell: tuple, counts):
    """(C, ...) mean of one grid cell from its per-case ``total`` (C, *grid, ...) and the runs per case."""
    part = total[(slice(None), *cell)]
    return part / counts.reshape((-1,) + (1,) * (part.ndim - 1))


_PROGRAMS: dict = {}


def _program(structure: Structure) -> Callable:
    """``(key, (case, case_index), (axes, shared)) -> output`` of a structure (``grid_run``; ``averaged``:
    ``(output, trace, case_index)``). One function object per ``(run, averaged, batched)``, so another study of the
    structure (other runs, seed, parameters, shared data) reuses ``monte_carlo``'s compiled chunk."""
    signature = (structure.run, structure.averaged, structure.batched)
    if signature not in _PROGRAMS:
        run, averaged, batched = signature

        def one(key, data, arguments):
            case, case_index = data
            axes, shared = arguments
            out = grid_run(Structure("", run, axes, {}, averaged, batched, shared))(key, case)
            return (*out, case_index) if averaged else out

        _PROGRAMS[signature] = one
    return _PROGRAMS[signature]


@functools.lru_cache(maxsize=64)
def _case_mean_summary(num_cases: int):
    """``summary`` for ``monte_carlo``: keep the outputs; total the traces per case and count the runs."""

    def summary(outputs, weight):
        out, values, case_index = outputs
        w = weight.astype(jnp.result_type(float))

        def per_case(leaf):
            weighted = leaf * w.reshape((-1,) + (1,) * (leaf.ndim - 1))
            return jax.ops.segment_sum(weighted, case_index, num_segments=num_cases)

        totals = (
            jax.tree_util.tree_map(per_case, values),
            jax.ops.segment_sum(w, case_index, num_segments=num_cases),
        )
        return out, totals

    return summary


def _compile_time_probe() -> float:
    """Seconds XLA has spent compiling in this process so far (``jax.monitoring``)."""
    return _COMPILE_SECONDS[0]


_COMPILE_SECONDS = [0.0]


def _record_duration(event: str, duration: float, **_: Any) -> None:
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILE_SECONDS[0] += duration


jax.monitoring.register_event_duration_secs_listener(_record_duration)
