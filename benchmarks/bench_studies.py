"""Whole studies, as a user meets them: `jaxfdi run <study>` from a fresh process, with an
empty XLA cache (cold) and again with the cache it filled (warm), compile and run apart.

    python benchmarks/bench_studies.py                       # the engine study, CLI default size
    python benchmarks/bench_studies.py --studies vtol f16 --cold-only  # each CLI default, cold

Each case runs in its own subprocess (`JAXFDI_CACHE_DIR` a new temporary folder for the
cold run, the same folder for the warm run), so nothing is shared with this process.
Per case: wall seconds of the process, and where the study reports them (the study
engine's ``config["seconds"]``) the seconds per structure and the XLA compile seconds.
Results go to ``benchmarks/results_studies.json`` (written whole or not at all).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from jaxfdi._io.files import write_json

TIMEOUT_S = None  # --timeout


def _run(command: list[str], cache: str) -> dict:
    env = {**os.environ, "JAXFDI_CACHE_DIR": cache}
    start = time.perf_counter()
    try:
        proc = subprocess.run(command, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return {"wall_s": None, "timed_out_after_s": TIMEOUT_S, "stdout_tail": ""}
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{proc.stderr[-3000:]}")
    return {"wall_s": wall, "stdout_tail": proc.stdout}


def _study_case(study: str, runs: int | None, cache: str) -> dict:
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-m", "jaxfdi", "run", study, "--quiet", "--out", out]
        if runs is not None:
            command += ["--runs", str(runs)]
        result = _run(command, cache)
        files = list(Path(out).glob("*.json")) if result["wall_s"] is not None else []
        if files:
            data = json.loads(files[0].read_text())
            result["study_seconds"] = data.get("seconds")
            result["structures"] = data.get("config", {}).get("seconds")
    result.pop("stdout_tail")
    return result


def _seconds(case: dict) -> str:
    return (
        f"{case['wall_s']:.1f} s"
        if case["wall_s"] is not None
        else f"> {case['timed_out_after_s']:.0f} s (stopped)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--studies", nargs="+", default=["engine"])
    parser.add_argument(
        "--runs", type=int, default=None, help="--runs for every study (default: the CLI's)"
    )
    parser.add_argument(
        "--cold-only",
        action="store_true",
        help="no warm run (the issue's target for the other studies)",
    )
    parser.add_argument("--out", default=str(HERE / "results_studies.json"))
    parser.add_argument(
        "--timeout", type=float, default=None, help="give a study up after this many seconds"
    )
    args = parser.parse_args()
    global TIMEOUT_S
    TIMEOUT_S = args.timeout
    import jax

    report = {
        "machine": {
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "backend": jax.default_backend(),
            "device": str(jax.devices()[0].device_kind),
        },
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "cases": {},
    }
    for study in args.studies:
        with tempfile.TemporaryDirectory() as cache:
            cold = _study_case(study, args.runs, cache)
            warm = None if args.cold_only else _study_case(study, args.runs, cache)
        report["cases"][study] = {"runs": args.runs, "cold": cold, "warm": warm}
        print(
            f"{study}: cold {_seconds(cold)}"
            + ("" if warm is None else f", warm {_seconds(warm)}"),
            flush=True,
        )
    previous = json.loads(Path(args.out).read_text()) if Path(args.out).exists() else {}
    previous.setdefault("runs", []).append(report)
    write_json(args.out, previous)
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_studies.json")


if __name__ == "__main__":
    main()
