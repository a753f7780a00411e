"""Plant models: linear ones as ``LinearGaussianModel`` data, nonlinear ones as pure ``f(x, u, params)`` /
``h(x, u, params)`` with a params pytree."""

from jaxfdi.models import f16
from jaxfdi.models._engine import engine_model
from jaxfdi.models._linear import LinearGaussianModel, c2d, linear_gaussian_model
from jaxfdi.models._reaction_wheels import kitsat3_params

__all__ = [
    "LinearGaussianModel",
    "linear_gaussian_model",
    "c2d",
    "engine_model",
    "kitsat3_params",
    "f16",
]
