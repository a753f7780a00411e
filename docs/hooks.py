"""mkdocs hook: a warning (an error under ``mkdocs build --strict``, as CI builds) for each
executed example copy (docs/examples) older than its source notebook (notebooks/), by the
SHA-256 the copy records. Re-run ``python docs/execute_notebooks.py <prefix>`` to refresh
one."""
from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.examples")
ROOT = Path(__file__).resolve().parents[1]


def on_pre_build(config, **kwargs):
    for copy in sorted((ROOT / "docs" / "examples").glob("*.ipynb")):
        source = ROOT / "notebooks" / copy.name
        meta = json.loads(copy.read_text()).get("metadata", {}).get("jaxfdi_docs", {})
        if not source.exists():
            log.warning("examples: %s has no source notebook", copy.name)
        elif meta.get("source_sha256") != hashlib.sha256(source.read_bytes()).hexdigest():
            log.warning("examples: %s was executed from an older notebooks/%s: python docs/execute_notebooks.py "
                     "[--text] %s", copy.name, copy.name, copy.name[:2])
