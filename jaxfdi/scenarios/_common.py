"""What every scenario study checks before it computes: precision and method names."""
from __future__ import annotations

from typing import Sequence

import jax


def require_x64(study: str) -> None:
    """A clear error, before any compilation, when a study that needs float64 runs without it."""
    if not jax.config.jax_enable_x64:
        raise ValueError(f"{study}: needs float64; call jaxfdi.enable_x64() first (the CLI does)")


def check_methods(methods: Sequence[str] | None, valid: Sequence[str]) -> tuple[str, ...]:
    """The requested subset of ``valid`` in ``valid``'s order (all when ``None``); a
    ``ValueError`` naming the unknown ones and listing the valid names."""
    if methods is None:
        return tuple(valid)
    if isinstance(methods, str):
        methods = [m for m in methods.split(",") if m]
    unknown = [m for m in methods if m not in valid]
    if unknown or not methods:
        raise ValueError(f"methods: expected a non-empty subset of {list(valid)}, got unknown {unknown or 'none'}")
    return tuple(m for m in valid if m in methods)
