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
        lines = [f"### {self.title}", ""]
        if self.note:
            lines += [self.note, ""]
        lines.append("| " + " | ".join(self.headers) + " |")
        lines.append("|" + "|".join("---" for _ in self.headers) + "|")
        lines += ["| " + " | ".join(row) + " |" for row in self.rows]
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


def meta(data: dict) -> dict[str, str]:
    """The command, date and machine of one JSON, from whichever of the scripts' layouts it has."""
    inner = data.get("meta") if isinstance(data.get("meta"), dict) else {}
    command = data.get("command") or inner.get("command") or "(command not recorded)"
    date = data.get("date") or inner.get("date_utc") or "(date not recorded)"
    machine = data.get("machine")
    if isinstance(machine, dict):
        machine = ", ".join(
            f"{k} {v}" for k, v in machine.items() if not isinstance(v, (dict, list))
        )
    if not machine:
        parts = [
            data.get("cpu") or inner.get("cpu"),
            (lambda n: f"{n} cores" if n else None)(data.get("cores") or inner.get("cpu_count")),
            (lambda d: f"device {d}" if d else None)(
                data.get("device") or inner.get("jax_backend")
            ),
            (lambda v: f"jax {v}" if v else None)(data.get("jax") or inner.get("jax")),
        ]
        machine = ", ".join(p for p in parts if p) or "(machine not recorded)"
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
]
