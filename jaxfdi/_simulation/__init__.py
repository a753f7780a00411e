"""Simulation: faults as data (``faults``), the open-loop simulator (``simulate``), the
closed-loop stage types and scan (``stages``, ``loop``), the fused open-loop Monte Carlo run
(``monitor``) and the tracking scores of a closed loop (``tracking``). Private: users reach
them through the names ``jaxfdi`` exports."""
