"""Public reference data shipped with jaxfdi (provenance and how to read each file:
``README.md`` beside this module). The files are byte-exact copies of ``shared/data``."""

from __future__ import annotations

from pathlib import Path

__all__ = ["data_path"]

#: the folder of the shipped data files
DATA_DIR = Path(__file__).resolve().parent


def data_path(name: str) -> Path:
    """The path of a shipped data file, e.g. ``data_path("f16_stevens_lewis.json")``.

    Returns:
      ``pathlib.Path``, the absolute path of ``name`` in the package's data folder
      (``ValueError`` when there is no such file).
    """
    path = DATA_DIR / name
    if not path.is_file():
        available = sorted(
            p.name
            for p in DATA_DIR.iterdir()
            if p.suffix in (".json", ".txt", ".20n", ".05o", ".05n")
        )
        raise ValueError(f"name: expected one of {available}, got {name!r}")
    return path
