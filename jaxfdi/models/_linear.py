"""Linear Gaussian state-space models as data, and zero-order-hold discretisation.

``x[k+1] = Phi x[k] + Gamma u[k] + w[k]``, ``y[k] = C x[k] + D u[k] + v[k]``, ``w ~ N(0, Q)``, ``v ~ N(0, R)``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax import Array

from jaxfdi import checks


class LinearGaussianModel(NamedTuple):
    """Discrete linear Gaussian model; a pytree, so it can be vmapped over or tuned.

    Attributes:
      Phi: (n, n) state transition
      Gamma: (n, nu) input matrix
      C: (m, n) output matrix
      D: (m, nu) feed-through
      Q: (n, n) process-noise covariance
      R: (m, m) measurement-noise covariance
    """

    Phi: Array
    Gamma: Array
    C: Array
    D: Array
    Q: Array
    R: Array

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(n, nu, m)``: state, input and output sizes."""
        return self.Phi.shape[-1], self.Gamma.shape[-1], self.C.shape[-2]


def linear_gaussian_model(
    Phi: Array, C: Array, Q: Array, R: Array, Gamma: Array | None = None, D: Array | None = None
) -> LinearGaussianModel:
    """A ``LinearGaussianModel``, with ``Gamma``/``D`` optional for a model without inputs.

    Missing ``Gamma``: zero-width (n, 0) (no inputs: run with ``us=None`` or ``jnp.zeros((T, 0))``);
    missing ``D``: zeros (m, nu). Shapes checked (``validate_linear_model``).

    Returns:
      ``LinearGaussianModel``, every block a JAX array of ``Phi``'s float dtype (``nu = 0`` without ``Gamma``).

    Example::

        model = linear_gaussian_model(Phi, C, Q, R)   # no inputs
        kf = kalman_filter(model)
        _, info = run_filter(kf, kf.init(x0, P0), ys)  # us=None
    """
    n = checks.check_square("Phi", Phi, None, "state transition")
    checks.check_matrix("C", C, (None, n), "m outputs x n states")
    m = checks.shape_of(C)[0]
    dtype = checks.float_dtype(Phi)
    if Gamma is not None:
        checks.check_matrix("Gamma", Gamma, (n, None), "n states x nu inputs")
    Gamma = jnp.zeros((n, 0), dtype) if Gamma is None else jnp.asarray(Gamma, dtype)
    if D is not None:
        checks.check_matrix("D", D, (m, Gamma.shape[1]), "m outputs x nu inputs")
    D = jnp.zeros((m, Gamma.shape[1]), dtype) if D is None else jnp.asarray(D, dtype)
    checks.check_covariance("Q", Q, n)
    checks.check_covariance("R", R, m)
    model = LinearGaussianModel(
        jnp.asarray(Phi, dtype),
        Gamma,
        jnp.asarray(C, dtype),
        D,
        jnp.asarray(Q, dtype),
        jnp.asarray(R, dtype),
    )
    validate_linear_model(model)
    return model


def validate_linear_model(model: LinearGaussianModel, name: str = "model") -> tuple[int, int, int]:
    """Check every block of ``model`` (shapes against ``Phi`` and ``C``, real and finite
    entries, ``Q`` and ``R`` symmetric positive semi-definite); return ``(n, nu, m)``.

    Returns:
      ``(n, nu, m)``: the state, input and measurement sizes.
    """
    if not isinstance(model, LinearGaussianModel):
        raise TypeError(
            f"{name}: expected a LinearGaussianModel (linear_gaussian_model(Phi, C, Q, R, Gamma, D)), "
            f"got {checks.received(model)}"
        )
    n = checks.check_square(f"{name}.Phi", model.Phi, None, "state transition")
    checks.check_matrix(f"{name}.Gamma", model.Gamma, (n, None), "n states x nu inputs")
    nu = checks.shape_of(model.Gamma)[1]
    checks.check_matrix(f"{name}.C", model.C, (None, n), "m outputs x n states")
    m = checks.shape_of(model.C)[0]
    checks.check_matrix(f"{name}.D", model.D, (m, nu), "m outputs x nu inputs")
    checks.check_covariance(f"{name}.Q", model.Q, n)
    checks.check_covariance(f"{name}.R", model.R, m)
    return n, nu, m


def linear_transition(x: Array, u: Array, model: LinearGaussianModel) -> Array:
    """``Phi x + Gamma u``: a linear model written as a nonlinear ``f(x, u, params)``.

    Returns:
      the (n,) next state mean ``Phi x + Gamma u``.
    """
    return model.Phi @ x + model.Gamma @ u


def linear_observation(x: Array, u: Array, model: LinearGaussianModel) -> Array:
    """``C x + D u``: a linear model written as a nonlinear ``h(x, u, params)``.

    Returns:
      the (m,) measurement mean ``C x + D u``.
    """
    return model.C @ x + model.D @ u


def c2d(A: Array, B: Array, Ts: float, dtype=None) -> tuple[Array, Array]:
    """Zero-order-hold discretisation by one matrix exponential.

    ``expm([[A, B], [0, 0]] Ts) = [[Phi, Gamma], [0, I]]`` (Van Loan 1978), as
    ``scipy.signal.cont2discrete(..., method="zoh")``. Concrete inputs (every model constructor): computed
    in float64 whatever the x64 flag, then cast to ``dtype`` (a stiff block, the engine's ``[A, B] Ts``
    with 1-norm ~7e5, overflows float32 scaling and squaring into NaN); a non-finite result raises
    ``ValueError``. Traced inputs (``jit``/``vmap`` over ``A``, ``B``, ``Ts``): the inputs' dtype.

    Args:
      A: (n, n) continuous state matrix.
      B: (n, nu) continuous input matrix.
      Ts: sample period in seconds (> 0).
      dtype: dtype of the result; default that of ``jnp.asarray(A)`` (the default
        float dtype for NumPy float64 input without x64).

    Returns:
      ``(Phi, Gamma)`` of shapes (n, n) and (n, nu).
    """
    n = checks.check_square("A", A, None, "continuous state matrix")
    checks.check_matrix("B", B, (n, None), "n states x nu inputs")
    checks.check_positive("Ts", Ts, "a positive scalar sample period")
    ts = checks.concrete(Ts)
    if dtype is None:
        dtype = jnp.asarray(A).dtype
        dtype = dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.result_type(float)
    A_value, B_value = checks.concrete(A), checks.concrete(B)
    if A_value is None or B_value is None or ts is None:  # traced: stay in the caller's dtype
        A = jnp.asarray(A, dtype)
        return _zoh(A, jnp.asarray(B, dtype=dtype), jnp.asarray(Ts, dtype=dtype))
    Phi, Gamma = zoh_float64(A_value, B_value, ts)
    if not (np.all(np.isfinite(Phi)) and np.all(np.isfinite(Gamma))):
        raise ValueError(
            f"c2d: Phi and Gamma are not finite even in float64 (A Ts has 1-norm "
            f"{np.linalg.norm(A_value * ts, 1):.3g}); check A, B and Ts"
        )
    if max(np.max(np.abs(Phi)), np.max(np.abs(Gamma), initial=0.0)) > np.finfo(dtype).max:
        raise ValueError(
            f"c2d: Phi and Gamma are finite in float64 but overflow {jnp.dtype(dtype).name}; "
            "use dtype=float64 (jaxfdi.enable_x64())"
        )
    return jnp.asarray(Phi, dtype), jnp.asarray(Gamma, dtype)


def zoh_float64(A, B, Ts) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Gamma)`` of concrete ``A``, ``B``, ``Ts`` as float64 NumPy, whatever the x64 flag: JAX's
    ``expm`` (Higham 2005 scaling and squaring) in a scoped ``jax.enable_x64`` context, so under x64 the
    numbers equal ``c2d``'s in float64 exactly (a NumPy Pade would differ in the last bits)."""
    args = (np.asarray(A, np.float64), np.asarray(B, np.float64), np.asarray(Ts, np.float64))
    with jax.ensure_compile_time_eval(), _x64():
        Phi, Gamma = _zoh(*(jnp.asarray(a, jnp.float64) for a in args))
        return np.asarray(Phi), np.asarray(Gamma)


def _x64():
    """A scoped float64 context (``jax.enable_x64(True)``; ``jax.experimental.enable_x64``
    on older JAX): the global flag is left as the caller set it."""
    state = getattr(jax, "enable_x64", None)
    if callable(state):
        return state(True)
    from jax.experimental import enable_x64  # pragma: no cover - JAX < 0.5

    return enable_x64()


@jax.jit
def _zoh(A: Array, B: Array, Ts: Array) -> tuple[Array, Array]:
    """One compiled executable for the whole discretisation (called eagerly, ``expm``
    would otherwise dispatch and compile dozens of small operations one by one)."""
    n, nu = B.shape
    block = jnp.zeros((n + nu, n + nu), A.dtype).at[:n, :n].set(A).at[:n, n:].set(B)
    expm = jsl.expm(block * Ts)
    return expm[:n, :n], expm[:n, n:]
