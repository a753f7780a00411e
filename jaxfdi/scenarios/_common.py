"""What every scenario study checks before it computes (precision, run counts, seeds and method names), and how its
figures are captioned."""

from __future__ import annotations

from typing import Any, Callable, Sequence

import jax

from jaxfdi import checks
from jaxfdi.plotting import caption_figure


def require_x64(study: str) -> None:
    """A clear error, before any compilation, when a study that needs float64 runs without it."""
    if not jax.config.jax_enable_x64:
        raise ValueError(f"{study}: needs float64; call jaxfdi.enable_x64() first (the CLI does)")


def check_methods(methods: Sequence[str] | None, valid: Sequence[str]) -> tuple[str, ...]:
    """The requested subset of ``valid`` in ``valid``'s order (all when ``None``); a ``ValueError`` naming the unknown
    ones and listing the valid names."""
    if methods is None:
        return tuple(valid)
    if isinstance(methods, str):
        methods = [m for m in methods.split(",") if m]
    unknown = [m for m in methods if m not in valid]
    if unknown or not methods:
        raise ValueError(
            f"methods: expected a non-empty subset of {list(valid)}, got unknown {unknown or 'none'}"
        )
    return tuple(m for m in valid if m in methods)


def check_study(runs: int, seed: int, runs_name: str = "runs", **counts: int) -> None:
    """``runs`` a positive int, ``seed`` an int in [0, ``checks.MAX_SEED``] = [0, 2^32 - 1], and each further keyword a
    positive count (e.g. ``calibration_runs``, ``steps``)."""
    checks.check_int(runs_name, runs, 1, meaning="a positive number of runs")
    checks.check_int("seed", seed, 0, checks.MAX_SEED, "a PRNG seed")
    for name, value in counts.items():
        checks.check_int(name, value, 1, meaning="a positive count")


def figure_collector() -> tuple[Callable[[Any, str, str], None], dict[str, Any]]:
    """``add(fig, name, caption)``, captioning ``fig`` in the house style (``plotting.caption_figure``) under the file
    name ``name``, and the dict it fills, in order (what a study's ``plot_*`` returns; ``plotting.save_figures``
    writes it)."""
    figures: dict[str, Any] = {}

    def add(fig, name: str, caption: str) -> None:
        figures[name] = caption_figure(fig, caption)

    return add, figures
