"""The papers' studies, one module each, run by ``jaxfdi run`` (``jaxfdi list``):

- ``engine`` (MM, IMM and the windowed GLRT on the turbojet; Table 3), ``engine_chi2`` (the Kalman filter's chi-square
  test), ``engine_tuning`` and ``engine_chi2_tuning`` (gradient tuning of the IMM and of the chi-square test's noise and
  threshold);
- ``vtol`` and ``vtol_loop`` (robust two-stage Kalman filter bank, signature isolation and the reconfiguring LQR-PI
  loop);
- ``reaction_wheels`` (dual filter and credits on a 4-wheel pyramid in closed loop);
- ``f16_flight`` and ``f16_fdi`` (the F-16 trimmed and flown; hybrid parity space with UKF);
- ``gnss_campus`` and ``gps_ins`` (RAIM and protection levels; the loosely coupled GPS/INS).

A study: cases and methods run by ``jaxfdi.run_study``, to read, run and copy (tables and figures on its paper's docs
page). Applications of the API, not part of it: the package exports nothing (``from jaxfdi.scenarios import vtol``).
"""

__all__: list[str] = []
