"""Numerics the filters and detectors share: small dense linear algebra written out for
``vmap`` (``linalg``), the discrete algebraic Riccati equation by doubling (``riccati``) and
Levenberg-Marquardt least squares (``levenberg_marquardt``). Private: users reach them
through the names ``jaxfdi`` and its subpackages export."""
