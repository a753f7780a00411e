"""``benchmarks/RESULTS.md`` is what the benchmarks' JSON renders (``benchmarks/report.py``): a figure on the
page is the one its benchmark last wrote, never one typed in or left from an earlier run."""

import importlib.util
import json
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def _report():
    sys.path.insert(0, str(BENCHMARKS))  # report.py imports tables.py beside it
    try:
        spec = importlib.util.spec_from_file_location("report", BENCHMARKS / "report.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(BENCHMARKS))


def test_results_page_is_the_rendering_of_the_benchmarks_json():
    report = _report()
    assert (BENCHMARKS / "RESULTS.md").read_text() == report.render(), (
        "benchmarks/RESULTS.md is stale: run python benchmarks/report.py"
    )


def test_every_topic_names_an_existing_json_and_renders_a_table_from_it():
    report = _report()
    for topic in report.tables.TOPICS:
        present = [name for name in topic.files if (BENCHMARKS / name).exists()]
        assert present, f"{topic.title}: none of {topic.files} exists"
        tables = topic.render(
            {name: json.loads((BENCHMARKS / name).read_text()) for name in present}
        )
        assert tables and all(t.rows for t in tables), f"{topic.title}: a table without rows"
