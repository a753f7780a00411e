"""UAV turbojet engine, linearised about an operating point (Han et al. 2022, Table 1).

States ``[RPM, P2, T2, P3, T3, P4, T4]``, input fuel flow (kg/s), outputs ``[RPM, P2, T2, P4, T4]``. The continuous
model is stiff (eigenvalues -36,360 ... -1.43); it is discretised by zero-order hold at ``Ts = 0.01 s``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxfdi.models._linear import LinearGaussianModel, c2d

STATE_NAMES = ("RPM", "P2", "T2", "P3", "T3", "P4", "T4")
OUTPUT_NAMES = ("RPM", "P2", "T2", "P4", "T4")
#: operating point of each output (RPM, P2, T2 [K], P4, T4 [K]).
OUTPUT_OPERATING_POINT = np.array([27000.0, 3398.0, 442.0, 1657.0, 1025.0])

A = np.array(
    [
        [4.917, -1025.8, 492.3, 1096.0, -55.1, -39.6, -13.3],
        [171.9, 12545.0, -6305.5, -15076.0, 1681.8, 960.8, 214.6],
        [13.7, -134.7, -881.6, 118.2, 13.0, 10.3, 7.8],
        [-240.9, 50836.0, -38773.0, -53241.0, 4494.3, -121.4, 7218.7],
        [-10.6, 4132.8, -2791.6, -4518.2, -241.5, 37.1, 78.3],
        [1099.9, -289410.0, 227480.0, 308400.0, -29097.0, -10735.0, 2011.6],
        [146.1, -39549.0, 32277.0, 41596.0, 3174.6, -456.4, -7663.5],
    ]
)
B = 1e3 * np.array([[-158.1], [724.8], [-9.48], [9164.2], [5106.6], [-51825.0], [-732.2]])
C = np.eye(7)[[0, 1, 2, 5, 6]]
D = np.array([[-0.3], [-0.05], [-0.003], [-0.02], [0.003]])
Q = np.diag([625.0, 25.0, 0.04, 16.0, 4.0, 4.0, 1.0])
R = np.diag([625.0, 25.0, 0.04, 4.0, 1.0])
TS = 0.01


def engine_model(Ts: float = TS, dtype=None) -> LinearGaussianModel:
    """Discrete engine model ``(Phi, Gamma, C, D, Q, R)`` at sample period ``Ts``.

    ``dtype`` default: float64 under x64 (recommended: stiff, states span five orders of magnitude), else float32;
    ``Phi``, ``Gamma`` computed in float64 either way (``c2d``) and cast (float32's exponential of this block is NaN).

    Returns:
      ``LinearGaussianModel``, n = 7, nu = 1, m = 5: ZOH ``Phi``, ``Gamma`` over ``Ts``; ``C`` selects
      ``[RPM, P2, T2, P4, T4]``; ``D`` (5, 1); diagonal ``Q``, ``R`` from the module's tables (same for every
      ``Ts``); all in ``dtype``.
    """
    dtype = dtype or jnp.result_type(float)
    Phi, Gamma = c2d(A, B, Ts, dtype=dtype)
    return LinearGaussianModel(
        Phi,
        Gamma,
        jnp.asarray(C, dtype),
        jnp.asarray(D, dtype),
        jnp.asarray(Q, dtype),
        jnp.asarray(R, dtype),
    )
