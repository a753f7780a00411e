"""How each benchmark's JSON reads as tables in ``RESULTS.md`` (``report.py``), one ``Topic`` per ``bench_*.py``.

Pure Python, no JAX: a topic's ``render`` takes ``{file name: its JSON}`` (the files present among
``Topic.files``) and returns ``Table`` s. A figure a JSON does not hold is left out, never filled in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

#: a column: (header, key of the row dict or a function of the row, format spec or a function of the value)
Column = tuple[str, Any, Any]


@dataclass(frozen=True)
class Table:
    """A titled table; ``rows`` hold the formatted cells."""

    title: str
    headers: Sequence[str]
    rows: Sequence[Sequence[str]]
    note: str = ""

    def markdown(self) -> str:
        def row(cells: Sequence[str]) -> str:  # a "|" in a cell would end it
            return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

        lines = [f"### {self.title}", ""]
        if self.note:
            lines += [self.note, ""]
        lines.append(row(self.headers))
        lines.append("|" + "|".join("---" for _ in self.headers) + "|")
        lines += [row(cells) for cells in self.rows]
        return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Topic:
    """One benchmark script's section: its title, what it measures, its JSON files and their tables."""

    title: str
    about: str
    files: tuple[str, ...]
    render: Callable[[dict[str, Any]], list[Table]] = field(repr=False)


def cell(value: Any, fmt: Any = "") -> str:
    """A formatted cell; ``None`` and a missing value read as an en dash."""
    if value is None:
        return "–"
    if callable(fmt):
        return fmt(value)
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float) and fmt:
        return format(value, fmt)
    return str(value)


def table(title: str, rows: Sequence[dict], columns: Sequence[Column], note: str = "") -> Table:
    """``rows`` (dicts) as a ``Table`` with one column per ``(header, key, format)``."""

    def get(row: dict, key: Any):
        return key(row) if callable(key) else row.get(key)

    return Table(
        title,
        [header for header, _, _ in columns],
        [[cell(get(row, key), fmt) for _, key, fmt in columns] for row in rows],
        note,
    )


def ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f} ms"


def s(seconds: float) -> str:
    return f"{seconds:.2f} s"


def ratio(x: float) -> str:
    return f"{x:.1f}x"


def sci(x: float) -> str:
    return f"{x:.1e}"


def dur(seconds: float) -> str:
    """A duration in the unit that reads best: us, ms, s."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    if seconds < 100:
        return f"{seconds:.2f} s"
    return f"{seconds:,.0f} s"


def times(x: float) -> str:
    """A ratio with the digits that matter: 0.97x, 8.77x, 85.3x, 8,258x."""
    if x >= 100:
        return f"{x:,.0f}x"
    if x >= 10:
        return f"{x:.1f}x"
    return f"{x:.2f}x"


def count(n: float) -> str:
    """A count or a rate, with thousands separated: 1,000,000."""
    return f"{n:,.0f}"


def rate(x: float) -> str:
    """A rate: three figures below 100 (2.49, 22.6), then a count (25,133)."""
    return f"{x:.3g}" if x < 100 else count(x)


def mib(nbytes: float) -> str:
    """A memory size in MiB, or KiB below one MiB."""
    if nbytes < 2**20:
        return f"{nbytes / 2**10:.0f} KiB"
    return f"{nbytes / 2**20:.1f} MiB"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _machine(value: Any) -> str:
    """A ``machine`` entry as text: a dict's scalars and lists (a load average as 1.6/0.8/0.3)."""
    if not isinstance(value, dict):
        return str(value) if value else ""
    parts = []
    for k, v in value.items():
        if isinstance(v, dict):
            continue
        if isinstance(v, list):
            if not v:
                continue
            v = "/".join(f"{e:.1f}" if isinstance(e, float) else str(e) for e in v)
        parts.append(f"{k.replace('_', ' ')} {v}")
    return ", ".join(parts)


def meta(data: dict) -> dict[str, str]:
    """The command, date and machine of one JSON, from whichever of the scripts' layouts it has: top-level keys,
    a ``meta`` dict, a ``machine`` dict or string, ``provenance`` (``jaxfdi._io.files.write_json``), or a log of
    ``runs`` each with its own ``date`` and ``machine`` (``bench_studies.py``). A command that is not recorded
    reads as a parenthesis (``report.py`` does not quote it)."""
    inner = data.get("meta") if isinstance(data.get("meta"), dict) else {}
    prov = data.get("provenance") if isinstance(data.get("provenance"), dict) else {}
    log = data.get("runs") if isinstance(data.get("runs"), list) else []
    log = [r for r in log if isinstance(r, dict) and r.get("date")]
    machine_entry = data.get("machine")
    command = data.get("command") or inner.get("command")
    date = data.get("date") or inner.get("date_utc")
    if log:  # appended runs: the file's provenance is its first run's
        first = prov.get("command")
        command = (
            f"({len(log)} runs appended, from {log[0]['date']} to {log[-1]['date']}; "
            "each run's options are not recorded"
            + (f", the first was `{first}`)" if first else ")")
        )
        date = log[-1]["date"]
        machine_entry = log[-1].get("machine")
    command = command or prov.get("command") or "(command not recorded)"
    if not date and isinstance(machine_entry, dict):
        date = machine_entry.get("date")
    date = date or prov.get("created") or "(date not recorded)"
    machine = _machine(
        {k: v for k, v in machine_entry.items() if k != "date"}
        if isinstance(machine_entry, dict)
        else machine_entry
    )
    extra = [
        None if machine else data.get("cpu") or inner.get("cpu"),
        (lambda n: f"{n} cores" if n and not machine else None)(
            data.get("cores") or inner.get("cpu_count")
        ),
        (lambda d: f"device {d}" if d and "device" not in machine else None)(
            data.get("device")
            or inner.get("device")
            or inner.get("jax_backend")
            or prov.get("device_kind")
        ),
        (lambda v: f"jax {v}" if v and "jax" not in machine else None)(
            data.get("jax") or inner.get("jax") or prov.get("jax")
        ),
        (lambda v: f"load average {v}" if v else None)(
            _machine({"": data.get("load_average")}).strip() if data.get("load_average") else None
        ),
    ]
    machine = ", ".join(p for p in [machine, *extra] if p) or "(machine not recorded)"
    return {"command": str(command), "date": str(date)[:19], "machine": str(machine)}


# --- bench_filters.py -----------------------------------------------------------------------------


def _filters(results: dict) -> list[Table]:
    data = results["results.json"]
    out = []
    timing = [
        ("case", "case", ""),
        ("implementation", "impl", ""),
        ("run", "run_s", ms),
        ("compile", "compile_s", s),
        ("sequences timed", "sequences_timed", ""),
    ]
    for name, label in (("kf", "Kalman filter, engine"), ("ukf", "UKF, rigid body")):
        part = data.get(name)
        if part:
            out.append(
                table(
                    f"{label} (T = {part['T']}, N = {part['N']})",
                    part["rows"],
                    timing,
                    note="filterpy is timed on its `sequences timed` and its time scaled to N.",
                )
            )
    if data.get("targets"):
        out.append(
            table(
                "Targets: speed-up of jaxfdi over each peer, same run",
                data["targets"],
                [
                    ("filter", "filter", ""),
                    ("peer", "other", ""),
                    ("case", "case", ""),
                    ("jaxfdi driver", "jaxfdi_driver", ""),
                    ("speed-up", "speedup", ratio),
                    ("target", "target_speedup", ratio),
                    ("met", "met", ""),
                ],
            )
        )
    if data.get("driver_compile"):
        out.append(
            table(
                "Compilation of each driver",
                data["driver_compile"],
                [
                    ("driver", "driver", ""),
                    ("trace + lower", "trace_lower_s", s),
                    ("XLA compile", "xla_compile_s", s),
                    ("HLO lines", "hlo_lines", ""),
                ],
            )
        )
    if data.get("oneshot"):
        rows = [{"process": k, **v} for k, v in data["oneshot"].items() if isinstance(v, dict)]
        out.append(
            table(
                "A whole one-shot process (import, build, run), median wall time",
                rows,
                [
                    ("process", "process", ""),
                    ("wall", "wall_s", s),
                    ("import", "import_s", s),
                    ("build and run", "build_and_run_s", s),
                ],
            )
        )
    return out


# --- bench_imm.py ---------------------------------------------------------------------------------


def _imm(results: dict) -> list[Table]:
    data = results["results_imm.json"]
    out = [
        table(
            "Engine IMM (7 modes), 1000 steps: jaxfdi against filterpy's IMMEstimator",
            data.get("imm", []),
            [
                ("design", "design", ""),
                ("jit, 1 sequence", "jaxfdi_1_s", ms),
                ("filterpy, 1 sequence", "filterpy_1_s", s),
                ("speed-up, 1", "speedup_1", ratio),
                ("batch kernel, N", "jaxfdi_batch_N_s", s),
                ("filterpy, N (scaled)", "filterpy_N_s", s),
                ("speed-up, N", "speedup_batch_N", ratio),
                ("N", "sequences", ""),
                ("compile (batch)", "jaxfdi_batch_N_compile_s", s),
                ("max |diff| mode prob.", "agreement_mode_prob", sci),
            ],
            note="filterpy's N-sequence time is its per-sequence time over the sequences it ran, times N.",
        )
    ]
    if data.get("glrt"):
        out.append(
            table(
                "Windowed GLRT detector: cost per step against the window N",
                data["glrt"],
                [
                    ("window N", "window", ""),
                    ("sequences x steps", lambda r: f"{r['sequences']} x {r['steps']}", ""),
                    ("run", "run_s", ms),
                    ("per step and sequence", "per_step_per_sequence_us", lambda v: f"{v:.2f} us"),
                    ("compile", "compile_s", s),
                ],
            )
        )
    return out


# --- bench_tuning.py ------------------------------------------------------------------------------


def _tuning(results: dict) -> list[Table]:
    data = results["results_tuning.json"]
    columns = [
        ("forward", "forward_s", ms),
        ("gradient", "grad_s", ms),
        ("gradient / forward", "grad_over_forward", ratio),
        ("compile forward", "forward_compile_s", s),
        ("compile gradient", "grad_compile_s", s),
        ("gradient temp memory", "grad_temp_bytes", lambda b: f"{b / 2**20:.1f} MiB"),
    ]
    return [
        table(
            "Kalman filter log-likelihood and its gradient in Q, R",
            data.get("kf", []),
            [("implementation", "implementation", ""), *columns],
        ),
        table(
            "Engine IMM tuning loss and its gradient",
            data.get("imm", []),
            [
                ("rematerialised", "remat", ""),
                ("runs x steps", lambda r: f"{r['runs']} x {r['steps']}", ""),
                *columns,
            ],
        ),
    ]


# --- helpers for the topics below ------------------------------------------------------------------


def _each(results: dict, names: Sequence[str]) -> list[tuple[str, dict]]:
    """``(suffix, data)`` for each of ``names`` present; the suffix names the file when a topic has several."""
    present = [(name, results[name]) for name in names if name in results]
    if len(present) == 1:
        return [("", present[0][1])]
    return [(f" (`{name}`)", data) for name, data in present]


def _by(rows: Sequence[dict], *keys: str) -> dict:
    return {tuple(r.get(k) for k in keys): r for r in rows}


def _wall_cpu(wall: float, cpu: float | None) -> str:
    """A wall time with its process CPU time in brackets."""
    return dur(wall) if cpu is None else f"{dur(wall)} ({dur(cpu)})"


# --- bench_monte_carlo.py -------------------------------------------------------------------------

_MC_WORKLOADS = {
    "kf": "Engine KF (7 states, 5 outputs)",
    "ukf": "Rigid-body UKF (3 states), per-run initial state",
    "monitor": "Engine chi-square monitor (plant, KF, 4-step windowed chi-square, detection record)",
}


def _monte_carlo(results: dict) -> list[Table]:
    out = []
    for suffix, data in _each(results, ("montecarlo_h100.json", "montecarlo_results.json")):
        rows = data.get("rows", [])
        base = {(r["workload"], r["runs"]): r["run_s"] for r in rows if r["impl"] == "jaxfdi"}
        chunk = (data.get("meta") or {}).get("args", {}).get("chunk")
        for i, workload in enumerate(dict.fromkeys(r["workload"] for r in rows)):
            part = [r for r in rows if r["workload"] == workload]
            steps = sorted({r["T"] for r in part})
            out.append(
                table(
                    f"{_MC_WORKLOADS.get(workload, workload)}, T = {', '.join(map(str, steps))}{suffix}",
                    part,
                    [
                        ("runs", "runs", count),
                        ("implementation", "impl", ""),
                        ("compile", "compile_s", s),
                        ("run", "run_s", dur),
                        ("runs/s", "runs_per_s", count),
                        (
                            "run / jaxfdi's",
                            lambda r: (
                                r["run_s"] / base[(r["workload"], r["runs"])]
                                if (r["workload"], r["runs"]) in base
                                else None
                            ),
                            times,
                        ),
                        ("max rel. diff. to jaxfdi", "max_rel_diff_vs_jaxfdi", sci),
                        ("agrees", "agrees", ""),
                    ],
                    note=""
                    if i
                    else "Each run simulates and filters its own data in one program"
                    + (f", in chunks of {count(chunk)} runs" if chunk else "")
                    + "; `run / jaxfdi's` > 1: jaxfdi is faster; `simulate_only` is the data "
                    "generation alone. The log-likelihoods (the monitor: detection steps) are compared "
                    "before any time is kept.",
                )
            )
    return out


# --- bench_scale.py -------------------------------------------------------------------------------


def _scale(results: dict) -> list[Table]:
    out = []
    names = (
        "results_scale.json",
        "results_scale_cpu_sweep.json",
        "h200/results_scale_gpu.json",
        "results_scale_startup.json",
    )
    for suffix, data in _each(results, names):
        backend = (data.get("meta") or {}).get("jax_backend", "")
        on = f" on {backend.upper()}" if backend else ""
        if data.get("parallel"):
            rows = data["parallel"]
            by = _by(rows, "batch", "T", "impl")
            cases = sorted(dict.fromkeys((r["batch"], r["T"]) for r in rows))
            eager = any(impl == "sequential KF eager run_filter" for _, _, impl in by)

            def run(case, impl, key="run_s"):
                row = by.get((*case, impl))
                return None if row is None else row.get(key)

            def speedup(case, what):
                seq, par = run(case, f"sequential {what}"), run(case, f"parallel {what}")
                return None if seq is None or par is None else seq / par

            pivot = [
                {
                    "batch": b,
                    "T": t,
                    "eager": run((b, t), "sequential KF eager run_filter"),
                    **{
                        f"{side} {what}": run((b, t), f"{side} {what}")
                        for side in ("sequential", "parallel")
                        for what in ("KF", "KF+RTS")
                    },
                    "up KF": speedup((b, t), "KF"),
                    "up RTS": speedup((b, t), "KF+RTS"),
                    **{
                        f"compile {what}": " / ".join(
                            "–"
                            if run((b, t), f"{side} {what}", "compile_s") is None
                            else f"{run((b, t), f'{side} {what}', 'compile_s'):.1f} s"
                            for side in ("sequential", "parallel")
                        )
                        for what in ("KF", "KF+RTS")
                    },
                    "agreement": run((b, t), "parallel KF+RTS", "agreement"),
                }
                for b, t in cases
            ]
            columns = [
                ("batch", "batch", ""),
                ("T", "T", count),
                *([("sequential KF, eager run_filter", "eager", dur)] if eager else []),
                ("sequential KF", "sequential KF", dur),
                ("parallel KF", "parallel KF", dur),
                ("speed-up", "up KF", times),
                ("sequential KF+RTS", "sequential KF+RTS", dur),
                ("parallel KF+RTS", "parallel KF+RTS", dur),
                ("speed-up", "up RTS", times),
                ("compile KF, seq. / par.", "compile KF", ""),
                ("compile KF+RTS, seq. / par.", "compile KF+RTS", ""),
                ("max rel. diff.", "agreement", sci),
            ]
            out.append(
                table(
                    f"Parallel-in-time (associative scan) against sequential KF and RTS smoother{on}, "
                    f"engine model, float64{suffix}",
                    pivot,
                    columns,
                    note="Sequential: `jit(vmap(run_filter(kalman_filter)))` and `rts_smoother`; parallel: "
                    "`parallel_kalman_filter` and `parallel_rts_smoother`. Speed-up = sequential run time / "
                    "parallel run time (> 1: the parallel form wins). The agreement is of the parallel "
                    "filter and smoother with the sequential ones.",
                )
            )
        if data.get("glrt"):
            by = {}
            for r in data["glrt"]:
                by.setdefault(r["window"], {})[r["impl"]] = r
            pivot = [
                {
                    "window": n,
                    "windowed": v.get("windowed", {}).get("per_step_and_run_us"),
                    "recursive": v.get("recursive", {}).get("per_step_and_run_us"),
                    "agreement": v.get("recursive", {}).get("agreement"),
                    "same": v.get("recursive", {}).get("same_labels"),
                }
                for n, v in by.items()
            ]
            us = lambda v: f"{v:.3f} us"  # noqa: E731
            out.append(
                table(
                    f"Windowed (O(N^2)) against recursive (O(N)) GLRT, per step and run{on}{suffix}",
                    pivot,
                    [
                        ("window N", "window", ""),
                        ("windowed", "windowed", us),
                        ("recursive", "recursive", us),
                        (
                            "windowed / recursive",
                            lambda r: (
                                r["windowed"] / r["recursive"]
                                if r["windowed"] and r["recursive"]
                                else None
                            ),
                            times,
                        ),
                        ("statistic rel. diff.", "agreement", sci),
                        ("same labels", "same", ""),
                    ],
                )
            )
        if data.get("multiprocess"):
            out.append(
                table(
                    f"Monte Carlo over local processes (engine KF + chi-square, one CPU device each){suffix}",
                    data["multiprocess"],
                    [
                        ("processes", "processes", ""),
                        ("runs x steps", lambda r: f"{r['runs']} x {r['T']}", ""),
                        ("first call", "first_call_s", s),
                        ("warm", "warm_s", s),
                        ("runs/s", "runs_per_s", count),
                        ("streaming reduce", "reduce_s", s),
                        ("gather", "gather_s", dur),
                        ("bit-identical to 1 process", "bit_identical_to_one_process", ""),
                    ],
                )
            )
        startup = data.get("startup")
        if startup:
            cpu = lambda v: f"{v:.2f} CPU s"  # noqa: E731
            out.append(
                table(
                    f"Start-up of a one-shot process, user + system CPU seconds{suffix}",
                    [startup],
                    [
                        ("filterpy", "filterpy", cpu),
                        ("jaxfdi, cold cache", "jaxfdi_cold", cpu),
                        ("jaxfdi, warm cache", "jaxfdi_cache_warm", cpu),
                        ("warm / filterpy", "ratio_warm_over_filterpy", times),
                    ],
                    note="Median of the repeats; `bench_scale.py` prints a target of warm / filterpy <= 1.",
                )
            )
            compiles = startup.get("driver_compile_cpu_s") or {}
            out.append(
                table(
                    f"Compilation of each KF driver, CPU seconds{suffix}",
                    [{"driver": k, "cpu": v} for k, v in compiles.items()],
                    [("driver", "driver", ""), ("compile", "cpu", cpu)],
                    note="`bench_scale.py` prints a target of 0.5 CPU s each.",
                )
            )
    return out


# --- bench_loop.py --------------------------------------------------------------------------------


def _loop(results: dict) -> list[Table]:
    data = results["results_loop.json"]
    rows = [{"workload": k, **v} for k, v in (data.get("workloads") or {}).items()]
    return [
        table(
            f"The shared closed-loop scan (new) against commit {data.get('baseline')} (old): "
            f"{count(data['runs'])} runs, best of {data.get('rounds')} rounds of {data.get('repeats')} repeats",
            rows,
            [
                ("workload", "workload", ""),
                ("run, old", lambda r: r["old_run_ms"] / 1e3, dur),
                ("run, new", lambda r: r["new_run_ms"] / 1e3, dur),
                ("run old / new", "run_ratio_old_over_new", times),
                ("compile, old", "old_compile_s", s),
                ("compile, new", "new_compile_s", s),
                ("compile old / new", "compile_ratio_old_over_new", times),
                ("identical results", "identical_results", ""),
            ],
            note="Old and new each run in their own subprocess, alternating; a ratio > 1: the new scan is "
            "faster. The figures are the better of the rounds.",
        )
    ]


# --- bench_studies.py -----------------------------------------------------------------------------


def _study_wall(case: dict | None) -> str | None:
    if not case:
        return None
    if case.get("wall_s") is None and case.get("timed_out_after_s") is not None:
        return f"> {case['timed_out_after_s']:.0f} s (stopped)"
    return None if case.get("wall_s") is None else s(case["wall_s"])


def _studies(results: dict) -> list[Table]:
    data = results["results_studies.json"]
    log = data.get("runs") or []
    latest, measured = {}, {}
    for run in log:
        for study, case in (run.get("cases") or {}).items():
            latest[study] = {**case, "date": run.get("date")}
            measured[study] = measured.get(study, 0) + 1
    whole = [
        {"study": k, "measurements": measured[k], **v}
        for k, v in latest.items()
        if not k.startswith("engine ")
    ]
    out = [
        table(
            "`jaxfdi run <study>` in a fresh process: cold (empty XLA cache) and warm (the cache it filled), "
            "the latest measurement of each study",
            whole,
            [
                ("study", "study", ""),
                ("measured", "date", ""),
                ("runs", lambda r: r.get("runs") or "CLI default", ""),
                ("cold, wall", lambda r: _study_wall(r.get("cold")), ""),
                ("cold, study's own time", lambda r: (r.get("cold") or {}).get("study_seconds"), s),
                ("warm, wall", lambda r: _study_wall(r.get("warm")), ""),
                ("warm, study's own time", lambda r: (r.get("warm") or {}).get("study_seconds"), s),
                ("measurements in the file", "measurements", ""),
            ],
            note="Wall = the whole process (import, compile, run, outputs); a study run `--cold-only` has no "
            "warm figure.",
        )
    ]
    for study, case in latest.items():
        cold = (
            (case.get("cold") or {}).get("structures") or (case.get("cold") or {}).get("seconds")
        ) or {}
        warm = (
            (case.get("warm") or {}).get("structures") or (case.get("warm") or {}).get("seconds")
        ) or {}
        per = cold.get("structures") or {}
        if not per or study.startswith("engine "):
            continue
        out.append(
            table(
                f"`{study}`: seconds per structure (compilation included) and the XLA compile alone, "
                f"measured {case.get('date')}",
                [{"structure": k} for k in per],
                [
                    ("structure", "structure", ""),
                    ("cold", lambda r: cold.get("structures", {}).get(r["structure"]), s),
                    ("cold, XLA compile", lambda r: cold.get("compile", {}).get(r["structure"]), s),
                    ("warm", lambda r: warm.get("structures", {}).get(r["structure"]), s),
                    ("warm, XLA compile", lambda r: warm.get("compile", {}).get(r["structure"]), s),
                ],
            )
        )
    linalg = [
        {"variant": k[len("engine ") :], **v} for k, v in latest.items() if k.startswith("engine ")
    ]
    if linalg:
        out.append(
            table(
                f"The engine study with library-call against written-out factorisations "
                f"(`--linalg`), measured {linalg[-1].get('date')}",
                linalg,
                [
                    ("factorisations", "variant", ""),
                    ("cold, wall", lambda r: _study_wall(r.get("cold")), ""),
                    ("cold, in process", lambda r: r["cold"].get("wall_in_process_s"), s),
                    ("warm, wall", lambda r: _study_wall(r.get("warm")), ""),
                    ("warm, in process", lambda r: r["warm"].get("wall_in_process_s"), s),
                ],
                note="`engine_study(unrolled=...)` in a fresh process, cold and warm cache: the measurement "
                "behind the study's library calls (the option and `--linalg` are gone since).",
            )
        )
    return out


# --- bench_tskf_bank.py ---------------------------------------------------------------------------


def _tskf_bank(results: dict) -> list[Table]:
    data = results["results_tskf_bank.json"]
    numpy = data.get("numpy_loop") or {}
    rows = [
        {
            "impl": f"jaxfdi robust TSKF bank ({data['filters']} filters, jit(vmap) over runs)",
            **data["jaxfdi_robust"],
        },
        {
            "impl": "NumPy loop, same robust bank (run x filter x step)",
            "run_s": numpy.get("all_runs_s_scaled"),
            "how": f"{dur(numpy['per_run_s'])} a run, {numpy.get('runs_timed')} runs timed, scaled"
            if numpy.get("per_run_s")
            else None,
            "peak": numpy.get("peak_bytes_per_run_loop"),
        },
        {"impl": "jaxfdi optimal TSKF bank (no unknown input)", **data["jaxfdi_optimal"]},
        {"impl": "augmented-state KF bank on [x; b], jit(vmap)", **data["augmented_kf"]},
    ]
    agreement, speedup = data.get("agreement") or {}, data.get("speedup") or {}
    return [
        table(
            f"Seed 001's TSKF bank: {count(data['runs'])} runs x {data['steps']} steps, float64",
            rows,
            [
                ("implementation", "impl", ""),
                ("all runs", "run_s", dur),
                ("how timed", lambda r: r.get("how") or f"median of {r.get('repeats')}", ""),
                ("compile", "compile_s", s),
                ("temp memory", "temp_bytes", mib),
                ("output memory", "output_bytes", mib),
                ("peak memory, one run", "peak", mib),
            ],
            note="The JAX memory figures hold all the runs; the NumPy loop's peak (tracemalloc) is one run's.",
        ),
        table(
            "TSKF bank: agreement and speed-up",
            [
                {
                    "pair": "NumPy loop against jaxfdi robust TSKF",
                    "diff": agreement.get("numpy_vs_jaxfdi_robust"),
                    "up": speedup.get("robust_vs_numpy"),
                    "read": "jaxfdi robust's speed-up over the NumPy loop",
                },
                {
                    "pair": "augmented KF against jaxfdi optimal TSKF",
                    "diff": agreement.get("augmented_vs_jaxfdi_optimal"),
                    "up": speedup.get("optimal_vs_augmented"),
                    "read": "jaxfdi optimal's speed-up over the augmented KF",
                },
            ],
            [
                ("pair", "pair", ""),
                ("max diff.", "diff", sci),
                ("speed-up", "up", times),
                ("which", "read", ""),
            ],
        ),
    ]


# --- bench_reaction_wheels.py ---------------------------------------------------------------------


def _reaction_wheels(results: dict) -> list[Table]:
    data = results["results_reaction_wheels.json"]
    ratios = data.get("ratios_vs_detector") or {}
    us = lambda v: f"{v:.2f} us"  # noqa: E731
    cases = [
        {"case": f"({k}) {v['name']}", "filters": v.get("filters"), "key": k, **v}
        for k, v in (data.get("cases") or {}).items()
    ]

    def vs_a(r, which):
        value = ratios.get(f"{r['key']}/a", {}).get(which)
        return None if value is None else times(value)

    out = [
        table(
            f"Seed 004's detector against its hypothesis banks: 1 and {count(data['runs'])} sequences x "
            f"{data['steps']} steps, {data.get('dtype', '')}",
            cases,
            [
                ("case", "case", ""),
                ("filters", "filters", ""),
                ("compile, 1", lambda r: r["one"]["compile_s"], s),
                ("run, 1", lambda r: r["one"]["run_s"], dur),
                ("per step, 1 sequence", lambda r: r["one"]["per_step_per_sequence_us"], us),
                ("compile, N", lambda r: r["batch"]["compile_s"], s),
                ("run, N", lambda r: r["batch"]["run_s"], dur),
                ("per step and sequence, N", lambda r: r["batch"]["per_step_per_sequence_us"], us),
                ("x (a), 1", lambda r: vs_a(r, "one"), ""),
                ("x (a), N", lambda r: vs_a(r, "batch"), ""),
            ],
            note="All filters run on the same gyro data"
            + (f" ({data['data']['fault']})" if (data.get("data") or {}).get("fault") else "")
            + "; `x (a)` = run time / the EKF detector's run time, same number of sequences.",
        )
    ]
    filterpy = data.get("filterpy") or {}
    by_baseline = data.get("speedup_by_baseline") or {}
    out.append(
        table(
            "The EKF dual filter against filterpy's `ExtendedKalmanFilter` in a Python loop",
            [{"baseline": k, **v, "up": by_baseline.get(k, {})} for k, v in filterpy.items()],
            [
                ("filterpy's predict_x", "baseline", ""),
                ("per sequence", "per_sequence_s", dur),
                ("per step", "per_step_per_sequence_us", us),
                ("sequences timed", "sequences_timed", ""),
                (
                    "max diff. F",
                    lambda r: (r.get("agreement") or {}).get("detection_parameter"),
                    sci,
                ),
                ("max diff. x_EKF", lambda r: (r.get("agreement") or {}).get("filtered_mean"), sci),
                ("jaxfdi's speed-up, 1 sequence", lambda r: r["up"].get("one"), times),
                ("jaxfdi's speed-up per step, N", lambda r: r["up"].get("batch"), times),
            ],
            note="`numpy`: a NumPy RK4 with its exact Jacobian; `jax-jit`: jaxfdi's transition and its "
            f"`jacfwd` as one jitted call a step. Reported against `{data.get('filterpy_reported')}`.",
        )
    )
    sanity = data.get("sanity") or {}
    if sanity:
        labels = {
            "mm_final_mode_is_stopped_wheel": "fraction of runs whose MM picks the stopped wheel at the last step",
            "mm_nominal_before_fault": "fraction of runs whose MM is nominal before the stop",
            "median_F_max_2s_after_over_before": "median max F within 2 s after the stop / before it",
            "median_F_max_after_over_before": "median max F after the stop / before it",
        }
        out.append(
            table(
                "Reaction wheels: readings from the same data",
                [{"what": labels.get(k, k), "value": v} for k, v in sanity.items()],
                [("reading", "what", ""), ("value", "value", ".2f")],
            )
        )
    return out


# --- bench_f16_flight.py --------------------------------------------------------------------------

_F16_FLIGHT = (
    "results_f16_flight.json",
    "h200/results_f16_flight_gpu.json",
    "h200/results_f16_gradient_gpu.json",
)


def _f16_flight(results: dict) -> list[Table]:
    out = []
    for suffix, data in _each(results, _F16_FLIGHT):
        numpy = data.get("numpy") or {}
        backend = (data.get("machine") or {}).get("backend", "cpu")
        rows = [
            {
                "impl": "NumPy loop",
                "flights": numpy.get("flights"),
                "per": _wall_cpu(numpy["per_flight_s"], numpy.get("per_flight_cpu_s")),
                "rate": 1 / numpy["per_flight_s"],
                "ratio": "1",
            }
        ] + [
            {
                "impl": f"jaxfdi {r['dtype']}",
                **r,
                "per": _wall_cpu(
                    r["per_flight_s"], r.get("run_cpu_s") and r["run_cpu_s"] / r["flights"]
                ),
                "rate": r.get("flights_per_s"),
                "ratio": f"{times(r['ratio_vs_numpy'])} ({times(r['ratio_vs_numpy_cpu'])})"
                if r.get("ratio_vs_numpy_cpu")
                else times(r["ratio_vs_numpy"]),
            }
            for r in data.get("jaxfdi", [])
        ]
        out.append(
            table(
                f"Seed 000's F-16 closed-loop flight (15 s, 1500 RK4 steps) on {backend.upper()}{suffix}",
                rows,
                [
                    ("implementation", "impl", ""),
                    ("flights", "flights", count),
                    ("compile", "compile_s", s),
                    ("run", "run_s", dur),
                    ("per flight, wall (CPU)", "per", ""),
                    ("flights/s", "rate", rate),
                    ("ratio to NumPy per flight, wall (CPU)", "ratio", ""),
                    ("all healthy", "healthy", ""),
                    (
                        "median max altitude error",
                        "altitude_error_max_ft_median",
                        lambda v: f"{v:.2f} ft",
                    ),
                ],
                note=f"The NumPy loop ({_plural(numpy.get('flights'), 'flight')} timed, one after another) "
                "ran in the same process; on the noise-free nominal flight every state agrees with jaxfdi's to "
                f"{sci(data['agreement_max_relative'])} relative."
                if data.get("agreement_max_relative") is not None
                else "",
            )
        )
    gradients = [
        {"file": name, **results[name]["gradient"]}
        for name in _F16_FLIGHT
        if (results.get(name) or {}).get("gradient")
    ]
    if gradients:
        out.append(
            table(
                "Gradient of the tracking cost in the LQR weights, through the closed loop in reverse mode",
                gradients,
                [
                    ("file", lambda r: f"`{r['file']}`", ""),
                    ("flights", "flights", ""),
                    ("weights", "weights", ""),
                    ("forward", "forward_s", dur),
                    ("gradient", "gradient_s", dur),
                    ("gradient / forward", "gradient_over_forward", times),
                    ("compile forward", "forward_compile_s", s),
                    ("compile gradient", "gradient_compile_s", s),
                    ("directional derivative", "directional_derivative", ".7g"),
                    ("central difference", "central_difference", ".7g"),
                    ("rel. diff.", "relative_difference", sci),
                ],
            )
        )
    return out


# --- bench_f16_fdi.py -----------------------------------------------------------------------------


def _f16_fdi(results: dict) -> list[Table]:
    out = []
    agreement = []
    for suffix, data in _each(results, ("results_f16_fdi.json", "h200/results_f16_fdi_gpu.json")):
        numpy = data.get("numpy") or {}
        backend = (data.get("machine") or {}).get("backend", "cpu")
        rows = [
            {
                "impl": "NumPy FDI loop",
                "flights": numpy.get("flights"),
                "per": _wall_cpu(numpy["per_flight_s"], numpy.get("per_flight_cpu_s")),
                "rate": 1 / numpy["per_flight_s"],
                "ratio": "1",
                "ukf_used": numpy.get("ukf_used"),
            }
        ]
        for r in data.get("jaxfdi", []):
            for part, label in (
                ("fdi", "jaxfdi FDI flight"),
                ("bare", "jaxfdi bare flight (no FDI)"),
            ):
                row = r.get(part)
                if not row:
                    continue
                rows.append(
                    {
                        "impl": label,
                        "flights": r["flights"],
                        **row,
                        "per": _wall_cpu(
                            row["per_flight_s"],
                            row.get("run_cpu_s") and row["run_cpu_s"] / r["flights"],
                        ),
                        "rate": row.get("flights_per_s"),
                        "ratio": (
                            f"{times(r['ratio_vs_numpy'])} ({times(r['ratio_vs_numpy_cpu'])})"
                            if part == "fdi" and r.get("ratio_vs_numpy")
                            else None
                        ),
                        "over_bare": r.get("fdi_over_bare") if part == "fdi" else None,
                    }
                )
        out.append(
            table(
                f"Seed 000's hybrid FDI in the F-16 closed loop on {backend.upper()}{suffix}",
                rows,
                [
                    ("implementation", "impl", ""),
                    ("flights", "flights", count),
                    ("compile", "compile_s", s),
                    ("run", "run_s", dur),
                    ("per flight, wall (CPU)", "per", ""),
                    ("flights/s", "rate", rate),
                    ("ratio to NumPy per flight, wall (CPU)", "ratio", ""),
                    ("FDI / bare, wall", "over_bare", times),
                    ("healthy", "healthy", count),
                    ("UKF ran", "ukf_used", count),
                    ("isolated, hybrid", "isolated", count),
                    ("isolated, PSA alone", "psa_isolated", count),
                ],
                note="The NumPy loop ran in the same process, one flight after another.",
            )
        )
        a = data.get("agreement")
        if a:
            agreement.append({"where": backend.upper() + suffix, **a})
    if agreement:
        out.append(
            table(
                "F-16 FDI: jaxfdi against the NumPy loop on the paper's noise-free case",
                agreement,
                [
                    ("run", "where", ""),
                    ("states, max rel. diff.", "state_max_relative", sci),
                    ("decision, jaxfdi", "decision_jaxfdi", ""),
                    ("decision, NumPy", "decision_numpy", ""),
                    (
                        "suspects equal",
                        lambda r: (
                            r["suspects"][0] == r["suspects"][1]
                            if len(r.get("suspects") or []) == 2
                            else None
                        ),
                        "",
                    ),
                    ("UKF residuals, max diff. / largest", "residual_max_relative", sci),
                ],
            )
        )
    return out


# --- bench_gps_ins.py -----------------------------------------------------------------------------


def _gps_ins(results: dict) -> list[Table]:
    data = results["results_gps_ins.json"]
    args = data.get("args") or {}
    flights, seconds = args.get("flights"), args.get("seconds")
    epochs = flights * seconds if flights and seconds else None
    numpy_runs = data.get("numpy_flight_s") or []
    rows = [
        {
            "impl": "jaxfdi (jit, vmap over flights)",
            "all": data.get("jax_run_s"),
            "how": f"median of {len(data.get('jax_runs_s') or [])}",
            "per": data["jax_run_s"] / epochs if epochs else None,
            "compile_s": data.get("jax_compile_s"),
        },
        {
            "impl": "NumPy loop",
            "all": data.get("numpy_scaled_s"),
            "how": f"{_plural(len(numpy_runs), 'flight')} timed ({', '.join(dur(v) for v in numpy_runs)}), scaled",
            "per": data["numpy_scaled_s"] / epochs
            if epochs and data.get("numpy_scaled_s")
            else None,
        },
    ]
    agreement = data.get("agreement") or {}
    return [
        table(
            f"INS/GPS integrity (15-state EKF, chi-square, SCST): {flights} flights x {seconds} s",
            rows,
            [
                ("implementation", "impl", ""),
                (f"{flights} flights", "all", dur),
                ("how timed", "how", ""),
                ("per flight-second (1 fix, 100 IMU steps)", "per", dur),
                ("compile", "compile_s", s),
            ],
            note=f"Speed-up over the NumPy loop {times(data['speedup'])}; real-time factor "
            f"{count(data['realtime_factor'])} (simulated seconds of all flights per wall second)."
            if data.get("speedup")
            else "",
        ),
        table(
            f"INS/GPS: jaxfdi against the NumPy loop, one flight of {agreement.get('epochs')} s on the same inputs",
            [agreement],
            [
                ("chi-square, max rel. diff.", "chi2_max_rel_diff", sci),
                ("SCST, max abs. diff.", "scst_max_abs_diff", sci),
                ("SCST, largest value", "scst_max", ".1f"),
                ("final position diff.", "final_position_diff_m", lambda v: f"{v:.1e} m"),
            ],
        ),
    ]


# --- bench_gnss_raim.py ---------------------------------------------------------------------------


def _gnss_raim(results: dict) -> list[Table]:
    data = results["results_gnss_raim.json"]
    epochs = data["epochs"]
    peer = data.get("gnss_lib_py") or {}
    us = lambda v: f"{v:,.1f} us"  # noqa: E731
    rows = [
        {
            "impl": f"jaxfdi `integrity.monitor_epoch` ({data.get('channels')} slots, vmap over "
            f"{data.get('batch')}-epoch chunks)",
            "per": data.get("jax_us_per_epoch"),
            "all": data.get("jax_run_s"),
            "how": "all epochs",
            "compile_s": data.get("jax_compile_s"),
            "up": 1.0,
        },
        {
            "impl": "NumPy loop, same algorithm",
            "per": data.get("numpy_us_per_epoch"),
            "all": data["numpy_us_per_epoch"] * epochs * 1e-6
            if data.get("numpy_us_per_epoch")
            else None,
            "how": "scaled",
            "up": data.get("speedup_vs_numpy"),
        },
    ]
    if peer:
        rows.append(
            {
                "impl": f"gnss_lib_py {peer.get('version', '')} `solve_fde` (detection and exclusion only)",
                "per": peer.get("us_per_epoch"),
                "all": peer["us_per_epoch"] * epochs * 1e-6 if peer.get("us_per_epoch") else None,
                "how": f"{peer.get('epochs')} epochs timed, scaled",
                "up": data.get("speedup_vs_gnss_lib_py"),
            }
        )
    agreement = data.get("agreement") or {}
    return [
        table(
            f"Snapshot RAIM with protection levels: {count(epochs)} epochs",
            rows,
            [
                ("implementation", "impl", ""),
                ("per epoch", "per", us),
                (f"{count(epochs)} epochs", "all", dur),
                ("how timed", "how", ""),
                ("compile", "compile_s", s),
                ("jaxfdi's speed-up", "up", times),
            ],
        ),
        table(
            "GNSS RAIM: agreement with the NumPy loop, and detection",
            [
                {
                    **agreement,
                    **data,
                    "peer_flag": peer.get("faulted_epochs_flagging_the_faulty_satellite"),
                    "same": peer.get("jaxfdi_same_epochs_excluding_it"),
                }
            ],
            [
                ("statistic, rel. diff.", "statistic_rel", sci),
                ("HPL, rel. diff.", "hpl_rel", sci),
                ("isolated satellite equal", "isolated_equal", ""),
                ("faulted epochs excluded, jaxfdi", "faulted_epochs_excluded_jax", ".4f"),
                ("fault-free alarm rate, jaxfdi", "fault_free_alarm_rate_jax", sci),
                ("gnss_lib_py flags the faulty satellite", "peer_flag", ".3f"),
                ("jaxfdi excludes it, same epochs", "same", ".3f"),
            ],
            note="Fractions of epochs; gnss_lib_py's on its timed epochs.",
        ),
    ]


# --- bench_gnss_real.py ---------------------------------------------------------------------------


def _gnss_real(results: dict) -> list[Table]:
    data = results["gnss_real.json"]
    out = []
    labels = {
        "jaxfdi": "jaxfdi (fix, parity test, slope and ARAIM levels, exclusion)",
        "rtklib": "RTKLIB postpos",
        "rtklib_raim_fde": "RTKLIB postpos + RAIM FDE",
        "gnss_lib_py": "gnss_lib_py WLS + residual FDE",
    }
    for key, title in (("geonet", "GEONET hour (station 0759)"), ("phone", "Phone trace")):
        part = data.get(key)
        if not part:
            continue
        ours = (part.get("jaxfdi") or {}).get("epochs_per_s")
        rows = [{"impl": labels.get(k, k), **v} for k, v in part.items() if isinstance(v, dict)]
        out.append(
            table(
                f"{title}{': ' + part['trace'] if part.get('trace') else ''}",
                rows,
                [
                    ("implementation", "impl", ""),
                    (
                        "epochs",
                        lambda r: (
                            count(r["epochs"])
                            + (f" ({count(r['solved'])} solved)" if "solved" in r else "")
                        ),
                        "",
                    ),
                    ("first call (compile)", "first_call_s", s),
                    ("run", "run_s", dur),
                    ("epochs/s", "epochs_per_s", count),
                    (
                        "jaxfdi's rate / this",
                        lambda r: ours / r["epochs_per_s"] if ours else None,
                        times,
                    ),
                ],
                note=f"jaxfdi runs the real epochs tiled {data.get('copies')} times."
                if data.get("copies")
                else "",
            )
        )
    return out


#: the sections of RESULTS.md, in order
TOPICS: list[Topic] = [
    Topic(
        "Filters: KF and UKF against filterpy, dynamax and a plain scan",
        "`python benchmarks/bench_filters.py`: one and 100 sequences, per-run P0 and Q, each driver's "
        "compilation, and a whole one-shot process.",
        ("results.json",),
        _filters,
    ),
    Topic(
        "IMM and GLRT",
        "`python benchmarks/bench_imm.py`: the engine's two 7-mode IMM designs against filterpy, and the "
        "windowed GLRT's cost against its window.",
        ("results_imm.json",),
        _imm,
    ),
    Topic(
        "Tuning gradients",
        "`python benchmarks/bench_tuning.py`: the cost of a gradient against its forward pass.",
        ("results_tuning.json",),
        _tuning,
    ),
    Topic(
        "Monte Carlo at scale",
        "`python benchmarks/bench_monte_carlo.py`: 10^3 to 10^6 runs, each simulating and filtering its own "
        "data in one program, jaxfdi against dynamax and a plain vmapped scan (a GPU run).",
        ("montecarlo_h100.json", "montecarlo_results.json"),
        _monte_carlo,
    ),
    Topic(
        "Scale: parallel-in-time KF and RTS smoother, recursive GLRT, start-up",
        "`python benchmarks/bench_scale.py`: the associative-scan filter and smoother against the sequential "
        "ones on CPU and GPU, the windowed against the recursive GLRT, Monte Carlo over local processes, and "
        "the CPU seconds of a one-shot process and of each driver's compilation.",
        (
            "results_scale.json",
            "results_scale_cpu_sweep.json",
            "h200/results_scale_gpu.json",
            "results_scale_startup.json",
        ),
        _scale,
    ),
    Topic(
        "The shared closed-loop scan",
        "`python benchmarks/bench_loop.py`: the studies' closed loops on the shared `loop.run_loop` scan "
        "against a baseline commit's private loops.",
        ("results_loop.json",),
        _loop,
    ),
    Topic(
        "Whole studies",
        "`python benchmarks/bench_studies.py`: `jaxfdi run <study>` as a user meets it, in a fresh process "
        "with a cold and a warm XLA cache.",
        ("results_studies.json",),
        _studies,
    ),
    Topic(
        "TSKF bank",
        "`python benchmarks/bench_tskf_bank.py`: seed 001's six-filter bank against a NumPy loop of the same "
        "recursions, and the optimal TSKF against an augmented-state KF.",
        ("results_tskf_bank.json",),
        _tskf_bank,
    ),
    Topic(
        "Reaction wheels: detector against hypothesis banks",
        "`python benchmarks/bench_reaction_wheels.py`: seed 004's dual-filter detector, its credit and "
        "likelihood banks, and filterpy's EKF running the same dual filter.",
        ("results_reaction_wheels.json",),
        _reaction_wheels,
    ),
    Topic(
        "F-16 closed-loop flight",
        "`python benchmarks/bench_f16_flight.py`: seed 000's F-16 flight, vmapped, against a NumPy loop on "
        "CPU and GPU, and the gradient of its tracking cost in the LQR weights.",
        _F16_FLIGHT,
        _f16_flight,
    ),
    Topic(
        "F-16 hybrid FDI",
        "`python benchmarks/bench_f16_fdi.py`: seed 000's hybrid FDI (parity test, isolation, UKF replay) in "
        "the F-16 closed loop against a NumPy loop, and its cost over the bare flight.",
        ("results_f16_fdi.json", "h200/results_f16_fdi_gpu.json"),
        _f16_fdi,
    ),
    Topic(
        "INS/GPS integrity",
        "`python benchmarks/bench_gps_ins.py`: Monte Carlo flights of the error-state EKF with the chi-square "
        "test and SCST against a NumPy loop.",
        ("results_gps_ins.json",),
        _gps_ins,
    ),
    Topic(
        "GNSS snapshot RAIM",
        "`python benchmarks/bench_gnss_raim.py`: RAIM with protection levels over simulated epochs against a "
        "NumPy loop and gnss_lib_py.",
        ("results_gnss_raim.json",),
        _gnss_raim,
    ),
    Topic(
        "Real GNSS receivers",
        "`python benchmarks/bench_gnss_real.py`: a GEONET hour beside RTKLIB and gnss_lib_py, a phone trace "
        "beside gnss_lib_py.",
        ("gnss_real.json",),
        _gnss_real,
    ),
]
