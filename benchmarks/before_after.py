"""The cost of a change on the studies' fault-free path: a study's run time (compile
excluded where the JSON splits it, ``config.seconds``; else its total ``seconds`` with a
warm compilation cache) with the code of a
git revision and with the working tree, in the same session, alternating, each after a
warm-up run that fills the compilation cache.

    python benchmarks/before_after.py 0091114 --study engine --runs 100 --repeats 3
    python benchmarks/before_after.py 0091114 --study f16 --runs 1 --repeats 2
    python benchmarks/before_after.py 8ee2533 --study f16 --runs 2 --repeats 1 --compile

With ``--compile`` it measures the compilation instead: each run is cold (an empty
compilation cache) and counts the programs XLA compiles and their seconds.

The revision is checked out with ``git worktree`` into a temporary folder and imported
through ``PYTHONPATH``; the JSON of the two must agree (same seed, same tables) to 1e-9
relative, or the script says where they differ.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


#: ``python -c`` body of a ``--compile`` run: the CLI with a listener counting XLA compilations
_COUNTED = """import json, sys
from jax import monitoring
seen = {"programs": 0, "compile_s": 0.0}
def listen(event, duration, **kw):
    if event == "/jax/core/compile/backend_compile_duration":
        seen["programs"] += 1
        seen["compile_s"] += duration
monitoring.register_event_duration_secs_listener(listen)
from jaxfdi.cli import main
main(sys.argv[2:])
open(sys.argv[1], "w").write(json.dumps(seen))
"""


def run(
    study: str, runs: int, out: Path, pythonpath: str | None, compile_counts: bool = False
) -> dict:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    cli = ["run", study, "--runs", str(runs), "--quiet", "--out", str(out)]
    if compile_counts:
        with tempfile.TemporaryDirectory() as cache:
            env["JAXFDI_CACHE_DIR"] = cache
            counts = out.with_suffix(".compile.json")
            subprocess.run(
                [sys.executable, "-c", _COUNTED, str(counts), *cli],
                check=True,
                env=env,
                cwd=tempfile.gettempdir(),
                stdout=subprocess.DEVNULL,
            )
        report = json.loads(next(out.glob("*.json")).read_text())
        report["compilation"] = json.loads(counts.read_text())
        return report
    subprocess.run(
        [sys.executable, "-m", "jaxfdi", *cli],
        check=True,
        env=env,
        cwd=tempfile.gettempdir(),
        stdout=subprocess.DEVNULL,
    )
    return json.loads(next(out.glob("*.json")).read_text())


def run_seconds(report: dict) -> float:
    """Structures minus compile where the study reports them (engine), else its total."""
    seconds = report["config"].get("seconds")
    if isinstance(seconds, dict):
        return sum(seconds["structures"].values()) - sum(seconds["compile"].values())
    return float(report["seconds"])


def differences(a, b, path="") -> list[str]:
    skip = ("seconds", "provenance", "compilation")
    if isinstance(a, dict):
        return [d for k in a if k not in skip for d in differences(a[k], b.get(k), f"{path}/{k}")]
    if isinstance(a, list):
        if not isinstance(b, list) or len(a) != len(b):
            return [path]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float):
        same = (
            a == b or (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-9 * max(abs(a), abs(b))
        )
        return [] if same else [f"{path}: {a} vs {b}"]
    return [] if a == b else [f"{path}: {a} vs {b}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revision")
    parser.add_argument("--study", default="engine")
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--compile", action="store_true", help="cold runs: count compiled programs and seconds"
    )
    args = parser.parse_args()
    if args.compile:
        return compile_cost(args)
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "-f", "-q", str(old), args.revision],
            check=True,
        )
        try:
            times = {"before": [], "after": []}
            reports = {}
            for i in range(args.repeats + 1):  # the first round fills the compilation caches
                for which, path in (("before", str(old)), ("after", None)):
                    out = Path(tmp) / f"{which}{i}"
                    reports[which] = run(args.study, args.runs, out, path)
                    if i:
                        times[which].append(run_seconds(reports[which]))
                        print(f"{which}: {times[which][-1]:.2f} s", flush=True)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], check=True
            )
    before, after = (sorted(times[k])[len(times[k]) // 2] for k in ("before", "after"))
    print(
        f"{args.study} --runs {args.runs}: run (compile excluded), median of {args.repeats}: before "
        f"{args.revision} {before:.2f} s, after {after:.2f} s, ratio {after / before:.3f}"
    )
    diff = differences(reports["before"], reports["after"])
    print("same tables (1e-9 relative)" if not diff else "DIFFERENT: " + "; ".join(diff[:10]))


def compile_cost(args) -> None:
    """``--compile``: cold runs, before and after alternating, each in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "-f", "-q", str(old), args.revision],
            check=True,
        )
        try:
            reports = {}
            for i in range(args.repeats):
                for which, path in (("before", str(old)), ("after", None)):
                    reports[which] = run(
                        args.study, args.runs, Path(tmp) / f"{which}{i}", path, compile_counts=True
                    )
                    c = reports[which]["compilation"]
                    print(
                        f"{which}: {c['programs']} programs compiled in {c['compile_s']:.1f} s",
                        flush=True,
                    )
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], check=True
            )
    diff = differences(reports["before"], reports["after"])
    print("same tables (1e-9 relative)" if not diff else "DIFFERENT: " + "; ".join(diff[:10]))


if __name__ == "__main__":
    main()
