"""Tests run in float64 unless they test float32 explicitly (they then pass float32
arrays: the library keeps the caller's dtype)."""
import jax

jax.config.update("jax_enable_x64", True)
