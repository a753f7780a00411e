"""VTOL aircraft in the vertical plane (Saif & Guan 1993; seed 001, Section V).

States ``[v_h, v_v, q, theta]``, inputs ``[collective, longitudinal cyclic]``. Open loop
unstable (eigenvalues 0.276 +/- 0.258j). Discretised at ``Ts = 0.1 s``.
"""
from __future__ import annotations

import numpy as np

A = np.array([
    [-0.0366, 0.0271, 0.0188, -0.4555],
    [0.0482, -1.01, 0.0024, -4.0208],
    [0.1002, 0.3681, -0.707, 1.420],
    [0.0, 0.0, 1.0, 0.0],
])
B = np.array([[0.422, 0.1761], [3.5466, -7.5922], [-5.52, 4.49], [0.0, 0.0]])
C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 1.0, 1.0, 1.0]])
TS = 0.1
