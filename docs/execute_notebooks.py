"""Execute the example notebooks and store the executed copies for the documentation.

    python docs/execute_notebooks.py            # every notebook in notebooks/
    python docs/execute_notebooks.py 01 04      # only those whose name starts so
    python docs/execute_notebooks.py --text 02  # only the text changed: copy it, keep the outputs

Each notebook in ``notebooks/`` runs in a fresh ``python3`` Jupyter kernel (cwd
``notebooks/``) at the size in ``SIZES`` (the ``JAXFDI_NB_*`` variables the notebooks
read: smaller than the papers' 100 runs so that the whole set runs in minutes on two
CPU cores) and is written with its outputs and figures to ``docs/examples/<name>``. The
source notebooks stay without outputs (small diffs); the docs show the stored copies,
so ``mkdocs build`` does not need JAX or a kernel. Each copy records the source's
SHA-256, the sizes and the versions in its metadata (``jaxfdi_docs``); re-run this
script after changing a notebook. The notebooks' tests execute them again in CI at
a smaller size.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "notebooks"
TARGET = ROOT / "docs" / "examples"
#: JAXFDI_NB_* sizes per notebook (by name prefix)
SIZES = {
    "01": {"JAXFDI_NB_RUNS": "20"},
    "02": {"JAXFDI_NB_RUNS": "20"},
    "03": {},  # the size its text states (its defaults)
    "04": {"JAXFDI_NB_RUNS": "10"},
    "05": {"JAXFDI_NB_RUNS": "10"},
    "06": {"JAXFDI_NB_RUNS": "4"},
    "07": {"JAXFDI_NB_RUNS": "4"},
    "08": {"JAXFDI_NB_RUNS": "20"},
    "09": {},  # the recipes: the size their text states
    "10": {},
    "11": {},
}


def execute(path: Path, timeout: int = 1800) -> Path:
    """Run ``path`` in a fresh kernel at its size; write the executed copy; return it."""
    source = path.read_bytes()
    nb = nbformat.reads(source.decode(), as_version=4)
    sizes = next((v for k, v in SIZES.items() if path.name.startswith(k)), {})
    saved = {k: os.environ.get(k) for k in sizes}
    os.environ.update(sizes)
    start = time.perf_counter()
    try:
        NotebookClient(
            nb,
            timeout=timeout,
            kernel_name="python3",
            resources={"metadata": {"path": str(SOURCE)}},
        ).execute()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    import jax

    import jaxfdi

    nb.metadata["jaxfdi_docs"] = {
        "source": f"notebooks/{path.name}",
        "source_sha256": hashlib.sha256(source).hexdigest(),
        "sizes": sizes,
        "seconds": round(time.perf_counter() - start, 1),
        "jaxfdi": jaxfdi.__version__,
        "jax": jax.__version__,
        "executed": time.strftime("%Y-%m-%d", time.gmtime()),
    }
    TARGET.mkdir(parents=True, exist_ok=True)
    out = TARGET / path.name
    nbformat.write(nb, out)
    return out


def refresh_text(path: Path) -> Path:
    """Bring the executed copy of ``path`` up to date when only its text (markdown cells)
    changed: the code cells must be the same, in the same order, so the stored outputs
    are still theirs; raises ``ValueError`` otherwise (execute the notebook again)."""
    source = path.read_bytes()
    nb = nbformat.reads(source.decode(), as_version=4)
    out = TARGET / path.name
    copy = nbformat.read(out, as_version=4)
    executed = [c for c in copy.cells if c.cell_type == "code"]
    if [c.source for c in nb.cells if c.cell_type == "code"] != [c.source for c in executed]:
        raise ValueError(f"{path.name}: its code changed since it was executed; run it again")
    code = iter(executed)
    copy.cells = [next(code) if c.cell_type == "code" else c for c in nb.cells]
    copy.metadata["jaxfdi_docs"]["source_sha256"] = hashlib.sha256(source).hexdigest()
    nbformat.write(copy, out)
    return out


def main(prefixes: list[str]) -> int:
    text_only = "--text" in prefixes
    prefixes = [p for p in prefixes if p != "--text"]
    paths = sorted(
        p
        for p in SOURCE.glob("*.ipynb")
        if not prefixes or any(p.name.startswith(x) for x in prefixes)
    )
    for path in paths:
        if text_only:
            print(
                f"{path.name}: text refreshed -> {refresh_text(path).relative_to(ROOT)}", flush=True
            )
            continue
        start = time.perf_counter()
        out = execute(path)
        print(
            f"{path.name}: {time.perf_counter() - start:.0f} s -> {out.relative_to(ROOT)}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
