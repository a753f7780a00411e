"""mkdocs hook: the executed example copies (docs/examples) against their source notebooks
(notebooks/), by the SHA-256 each copy records.

- ``mkdocs build``: a warning (an error under ``--strict``, as CI builds) for each copy
  older than its source and for each notebook without a copy.
- ``JAXFDI_EXECUTE_NOTEBOOKS=1 mkdocs build``: the build regenerates those copies first
  (``docs/execute_notebooks.py``): a copy whose code cells are unchanged takes the new
  text and keeps its outputs; any other is executed again at its docs size (minutes).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import logging
import os
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.examples")
ROOT = Path(__file__).resolve().parents[1]
REGENERATE = "JAXFDI_EXECUTE_NOTEBOOKS"


def stale_copies(root: Path = ROOT) -> list[str]:
    """The names of the notebooks whose executed copy is missing, or older than the source."""
    stale = []
    for source in sorted((root / "notebooks").glob("*.ipynb")):
        copy = root / "docs" / "examples" / source.name
        meta = (
            json.loads(copy.read_text()).get("metadata", {}).get("jaxfdi_docs", {})
            if copy.exists()
            else {}
        )
        if meta.get("source_sha256") != hashlib.sha256(source.read_bytes()).hexdigest():
            stale.append(source.name)
    return stale


def regenerate(names: list[str], root: Path = ROOT) -> None:
    """Bring the copies of ``names`` up to date: the text alone when the code is unchanged,
    else a fresh execution."""
    spec = importlib.util.spec_from_file_location(
        "execute_notebooks", root / "docs" / "execute_notebooks.py"
    )
    runner = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runner)
    for name in names:
        source = root / "notebooks" / name
        try:
            runner.refresh_text(source)
            log.info("examples: %s: text refreshed, outputs kept", name)
        except (ValueError, FileNotFoundError):
            log.info("examples: %s: executing (its code changed)", name)
            runner.execute(source)


def on_pre_build(config, **kwargs):
    names = stale_copies(ROOT)
    if names and os.environ.get(REGENERATE) == "1":
        regenerate(names, ROOT)
        names = stale_copies(ROOT)
    for name in names:
        log.warning(
            "examples: docs/examples/%s is missing or was executed from an older notebooks/%s: "
            "%s=1 mkdocs build, or python docs/execute_notebooks.py [--text] %s",
            name,
            name,
            REGENERATE,
            name[:2],
        )
    for copy in sorted((ROOT / "docs" / "examples").glob("*.ipynb")):
        if not (ROOT / "notebooks" / copy.name).exists():
            log.warning("examples: %s has no source notebook", copy.name)
