"""The study engine: detection and isolation metrics (``metrics``), the Monte Carlo driver
(``montecarlo``), studies as data and the function that runs them (``study``), and results
as DataFrames (``frame``). Private: users reach them through the names ``jaxfdi`` exports."""
