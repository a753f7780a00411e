"""VTOL aircraft in the vertical plane (Saif & Guan 1993; Lee & Lyou, Section V).

States ``[v_h, v_v, q, theta]``, inputs ``[collective, longitudinal cyclic]``. Open loop
unstable (eigenvalues 0.276 +/- 0.258j). Discretised at ``Ts = 0.1 s``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxfdi import checks
from jaxfdi.models._linear import LinearGaussianModel, c2d

A = np.array(
    [
        [-0.0366, 0.0271, 0.0188, -0.4555],
        [0.0482, -1.01, 0.0024, -4.0208],
        [0.1002, 0.3681, -0.707, 1.420],
        [0.0, 0.0, 1.0, 0.0],
    ]
)
B = np.array([[0.422, 0.1761], [3.5466, -7.5922], [-5.52, 4.49], [0.0, 0.0]])
C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 1.0, 1.0, 1.0]])
TS = 0.1

#: model uncertainty of Lee and Lyou, eq. 33: ``E_c d_c(t)`` with ``d_c = [0, 0.5, 0, 1] x``,
#: i.e. ``Delta a32 = 0.5`` and ``Delta a34 = 1.0`` (the pitch-rate row).
UNCERTAINTY_INPUT = np.array([[0.0], [0.0], [1.0], [0.0]])
UNCERTAINTY_GAIN = np.array([[0.0, 0.5, 0.0, 1.0]])
#: unmodelled external disturbance of eq. 34: ``G delta(t)``, ``delta = 3 sin(10 t)``.
DISTURBANCE_INPUT = np.array([[0.0], [1.0], [0.0], [0.0]])
DISTURBANCE_AMPLITUDE = 3.0
DISTURBANCE_FREQUENCY = 10.0  # rad/s
#: noise and initial values of Section V.
PROCESS_NOISE_STD = 0.01
MEASUREMENT_NOISE_STD = 0.1
X0 = np.array([50.0, 1.0, 5.0, 1.0])


def vtol_model(Ts: float = TS, dtype=None):
    """The nominal discrete VTOL model: ``Phi, Gamma`` by zero-order hold, ``C``, ``D = 0``,
    ``Q = 0.01^2 I``, ``R = 0.1^2 I`` (Lee & Lyou, Section V).

    Returns:
      ``LinearGaussianModel`` in ``dtype`` (default float), n = 4, nu = 2, m = 4: ``Phi`` (4, 4), ``Gamma`` (4, 2),
      ``C`` (4, 4), ``D`` (4, 2) zero, ``Q`` and ``R`` (4, 4).
    """
    dtype = dtype or jnp.result_type(float)
    Phi, Gamma = c2d(A, B, Ts, dtype=dtype)  # float64 inside, then cast
    return LinearGaussianModel(
        Phi,
        Gamma,
        jnp.asarray(C, dtype),
        jnp.zeros((4, 2), dtype),
        PROCESS_NOISE_STD**2 * jnp.eye(4, dtype=dtype),
        MEASUREMENT_NOISE_STD**2 * jnp.eye(4, dtype=dtype),
    )


def vtol_unknown_input(Ts: float = TS, include_disturbance: bool = False, dtype=None):
    """Discrete distribution ``E`` (4, q) of the unknown input: the zero-order-hold image
    of ``E_c`` (q = 1), and of ``G`` too with ``include_disturbance`` (q = 2).

    Returns:
      (4, q) ``E`` in ``dtype`` (default float): the uncertainty's column, then the disturbance's.
    """
    dtype = dtype or jnp.result_type(float)
    columns = (
        np.hstack([UNCERTAINTY_INPUT, DISTURBANCE_INPUT])
        if include_disturbance
        else UNCERTAINTY_INPUT
    )
    return c2d(A, columns, Ts, dtype=dtype)[1]


def vtol_true_plant(Ts: float = TS, uncertainty: float = 1.0, disturbance: float = 1.0, dtype=None):
    """The true plant, discretised exactly: ``A + uncertainty E_c d_c``, the disturbance from an oscillator
    ``w' = [[0, f], [-f, 0]] w`` (``w1 = sin f t``) appended; ``(Phi6, Gamma6, C6)`` for ``[x; w]`` (6,), start
    ``[x0; 0, 1]``; ``uncertainty`` and ``disturbance`` scale the two terms.

    Returns:
      ``(Phi6 (6, 6), Gamma6 (6, 2), C6 (4, 6))`` in ``dtype`` (default float), ZOH over ``Ts``; ``C6`` reads ``x``
      only.
    """
    checks.check_scalar("uncertainty", uncertainty, meaning="a real scale of the model uncertainty")
    checks.check_scalar("disturbance", disturbance, meaning="a real scale of the disturbance")
    dtype = dtype or jnp.result_type(float)
    f = DISTURBANCE_FREQUENCY
    A6 = np.zeros((6, 6))
    A6[:4, :4] = A + uncertainty * UNCERTAINTY_INPUT @ UNCERTAINTY_GAIN
    A6[:4, 4:5] = disturbance * DISTURBANCE_AMPLITUDE * DISTURBANCE_INPUT
    A6[4:, 4:] = [[0.0, f], [-f, 0.0]]
    B6 = np.vstack([B, np.zeros((2, 2))])
    Phi6, Gamma6 = c2d(A6, B6, Ts, dtype=dtype)
    C6 = jnp.asarray(np.hstack([C, np.zeros((4, 2))]), dtype)
    return Phi6, Gamma6, C6
