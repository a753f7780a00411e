"""jaxfdi: model-based fault detection and isolation in JAX."""
from jaxfdi.filters import (
    Filter,
    FilterInfo,
    GaussianState,
    extended_kalman_filter,
    kalman_filter,
    run_filter,
    unscented_kalman_filter,
)
from jaxfdi.models import LinearGaussianModel, c2d

__version__ = "0.1.0"


def enable_x64(enable: bool = True) -> None:
    """Switch JAX to float64 (library code never does this by itself)."""
    import jax

    jax.config.update("jax_enable_x64", enable)
