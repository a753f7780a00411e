"""The Stevens & Lewis F-16 data as JAX arrays, and the book's table interpolation.

Data: ``jaxfdi.data.data_path("f16_stevens_lewis.json")``: aerodynamic tables after NASA TP-1538, engine, atmosphere,
mass and geometry of Stevens & Lewis 2003, *Aircraft Control and Simulation*, 2nd ed., App. A (provenance in the data
README). ``values``: the 2nd-edition tables; a profile (``PROFILES``) overrides cells: ``nasa_morelli_tm2003_212145``
(Morelli's NASA TM-2003-212145 / 3rd edition: fixes Cmq at alpha = -5 deg and CYp at 45 deg, other CL cells at alpha
15-25 deg) or ``aerobench_python``.

Interpolation (the book's Fortran, e.g. ``FUNCTION CX``), uniform grid step ``h``:
``i = clip(floor((x - x_0) / h), 0, n - 2)``, ``f = (x - x_0) / h - i``, ``T(x) = (1 - f) T_i + f T_{i+1}``;
beyond the ends (``f < 0`` or ``> 1``) linear extrapolation from the end segment; 2-D bilinear
(``interpolate2``). Each argument's segment is found once (``segment``) and shared; a lookup reads
its 2x2 block with one ``dynamic_slice`` (under ``vmap`` on CPU far faster than a one-hot product, which
reads the whole table per point). ``CL``, ``CN`` are tabulated against ``|beta|`` and multiplied by
``sign(beta)`` (``aero.py``).
"""

from __future__ import annotations

import functools
import json
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.data import data_path

#: cell-override profiles of ``f16_stevens_lewis.json`` (``"stevens_lewis_2nd_ed"`` = the book)
PROFILES = ("stevens_lewis_2nd_ed", "nasa_morelli_tm2003_212145", "aerobench_python")

#: the aerodynamic tables and the breakpoint axis of their rows (columns are alpha)
AERO_TABLES = ("CX", "CZ", "CM", "CL", "CN", "DLDA", "DLDR", "DNDA", "DNDR", "DAMP")


class AeroTables(NamedTuple):
    """Stevens & Lewis aerodynamic tables (rows x alpha columns) and the CY/CZ formula
    constants (``CY = cy_beta beta + cy_ail ail/ail_norm + cy_rdr rdr/rdr_norm``,
    ``CZ = CZ(alpha) (1 - (beta/cz_beta_factor)^2) + cz_el el/el_norm``; angles in deg).

    Attributes:
      alpha_deg: (12,) breakpoints -10..45
      elevator_deg: (5,) elevator breakpoints -24..24
      beta_abs_deg: (7,) |beta| breakpoints 0..30 (CL, CN)
      beta_deg: (7,) beta breakpoints -30..30 (DLDA, DLDR, DNDA, DNDR)
      CX: (5, 12) elevator x alpha
      CZ: (12,) over alpha
      CM: (5, 12) elevator x alpha
      CL: (7, 12) |beta| x alpha
      CN: (7, 12) |beta| x alpha
      DLDA: (7, 12) beta x alpha, per unit ail/20
      DLDR: (7, 12) beta x alpha, per unit rdr/30
      DNDA: (7, 12) beta x alpha, per unit ail/20
      DNDR: (7, 12) beta x alpha, per unit rdr/30
      DAMP: (9, 12) CXq CYr CYp CZq Clr Clp Cmq Cnr Cnp
      cy_beta: () per deg
      cy_ail: () CY per unit ail/ail_norm
      cy_rdr: () CY per unit rdr/rdr_norm
      cz_beta_factor: () deg (57.3)
      cz_el: () CZ per unit el/el_norm
      ail_norm: () deg (20)
      rdr_norm: () deg (30)
      el_norm: () deg (25)
    """

    alpha_deg: Array
    elevator_deg: Array
    beta_abs_deg: Array
    beta_deg: Array
    CX: Array
    CZ: Array
    CM: Array
    CL: Array
    CN: Array
    DLDA: Array
    DLDR: Array
    DNDA: Array
    DNDR: Array
    DAMP: Array
    cy_beta: Array
    cy_ail: Array
    cy_rdr: Array
    cz_beta_factor: Array
    cz_el: Array
    ail_norm: Array
    rdr_norm: Array
    el_norm: Array


class EngineData(NamedTuple):
    """F100 thrust tables (Mach rows x altitude columns), throttle gearing and power lag.

    Attributes:
      mach: (6,) Mach breakpoints 0..1
      altitude_ft: (6,) altitude breakpoints 0..50000 ft
      idle: (6, 6) lbf, idle thrust
      military: (6, 6) lbf, military thrust
      maximum: (6, 6) lbf, maximum (afterburner) thrust
      gear_break: () throttle 0.77
      gear_low: () 64.94 % per unit throttle
      gear_high: () 217.38
      gear_offset: () -117.38
      afterburner: () 50 %
      fast_rate: () 5 1/s
      lit_target: () 60 %
      unlit_target: () 40 %
      rtau: (6,) dp_low, rtau_low, dp_high, rtau_high, intercept, slope
    """

    mach: Array
    altitude_ft: Array
    idle: Array
    military: Array
    maximum: Array
    gear_break: Array
    gear_low: Array
    gear_high: Array
    gear_offset: Array
    afterburner: Array
    fast_rate: Array
    lit_target: Array
    unlit_target: Array
    rtau: Array


class AtmosphereData(NamedTuple):
    """Stevens & Lewis air data computer constants (``atmosphere.py``).

    Attributes:
      rho0: () slug/ft^3
      tfac_slope: () 1/ft
      T0: () deg R
      T_strat: () deg R
      strat_alt: () ft, altitude of the stratosphere's base
      exponent: () 4.14, exponent of tfac in the density rho0 tfac^exponent
      gamma: () ratio of specific heats, 1.4
      gas_constant: () ft lbf / (slug deg R)
    """

    rho0: Array
    tfac_slope: Array
    T0: Array
    T_strat: Array
    strat_alt: Array
    exponent: Array
    gamma: Array
    gas_constant: Array


@functools.lru_cache(maxsize=None)
def _raw(name: str = "f16_stevens_lewis.json") -> dict:
    with open(data_path(name)) as fh:
        return json.load(fh)


def stevens_lewis_data() -> dict:
    """The parsed ``f16_stevens_lewis.json`` (shared, do not mutate)."""
    return _raw("f16_stevens_lewis.json")


def _grid(values, name: str) -> np.ndarray:
    grid = np.asarray(values, np.float64)
    steps = np.diff(grid)
    if (
        grid.ndim != 1
        or grid.size < 2
        or np.any(steps <= 0)
        or np.ptp(steps) > 1e-9 * abs(steps[0])
    ):
        raise ValueError(
            f"{name}: expected a uniform increasing breakpoint grid, got {grid.tolist()}"
        )
    return grid


def table_arrays(profile: str = "stevens_lewis_2nd_ed") -> dict[str, np.ndarray]:
    """Every table as float64 NumPy with ``profile``'s overrides (keys: aero table names, ``thrust_idle``,
    ``thrust_military``, ``thrust_maximum``, breakpoint grids)."""
    if profile not in PROFILES:
        raise ValueError(f"profile: expected one of {list(PROFILES)}, got {profile!r}")
    data = stevens_lewis_data()
    bp = data["breakpoints"]
    out = {name: np.array(data["aero_tables"][name]["values"], np.float64) for name in AERO_TABLES}
    thrust = data["engine"]["thrust_tables"]
    out["thrust_idle"] = np.array(thrust["idle"], np.float64)
    out["thrust_military"] = np.array(thrust["military"], np.float64)
    out["thrust_maximum"] = np.array(thrust["maximum"], np.float64)
    for cell in data["profiles"][profile]["overrides"] or []:
        table = out[cell["table"]]
        index = tuple(cell["index"])
        if not np.isclose(table[index], cell["baseline"]):
            raise ValueError(
                f"profile {profile}: {cell['table']}{list(index)} is {table[index]}, expected the "
                f"baseline {cell['baseline']} before the override"
            )
        table[index] = cell["value"]
    for axis in (
        "alpha_deg",
        "elevator_deg",
        "beta_abs_deg",
        "beta_deg",
        "thrust_mach",
        "thrust_altitude_ft",
    ):
        out[axis] = _grid(bp[axis]["values"], axis)
    return out


def aero_tables(profile: str = "stevens_lewis_2nd_ed", dtype=None) -> AeroTables:
    """The aerodynamic tables of ``profile`` as an ``AeroTables`` pytree in ``dtype``."""
    dtype = dtype or jnp.result_type(float)
    t = table_arrays(profile)
    formulas = stevens_lewis_data()["coefficient_formulas"]
    cy, cz = formulas["CY"], formulas["CZ"]
    a = lambda v: jnp.asarray(v, dtype)
    return AeroTables(
        a(t["alpha_deg"]),
        a(t["elevator_deg"]),
        a(t["beta_abs_deg"]),
        a(t["beta_deg"]),
        *(a(t[name]) for name in AERO_TABLES),
        a(cy["beta_coef_per_deg"]),
        a(cy["ail_coef"]),
        a(cy["rdr_coef"]),
        a(cz["beta_factor_deg"]),
        a(cz["el_coef"]),
        a(cy["ail_norm_deg"]),
        a(cy["rdr_norm_deg"]),
        a(cz["el_norm_deg"]),
    )


def engine_data(profile: str = "stevens_lewis_2nd_ed", dtype=None) -> EngineData:
    """Thrust tables (with ``profile``'s overrides), gearing and lag constants."""
    dtype = dtype or jnp.result_type(float)
    t = table_arrays(profile)
    eng = stevens_lewis_data()["engine"]
    gear, lag = eng["throttle_gearing"], eng["power_lag"]
    r = lag["rtau"]
    a = lambda v: jnp.asarray(v, dtype)
    return EngineData(
        a(t["thrust_mach"]),
        a(t["thrust_altitude_ft"]),
        a(t["thrust_idle"]),
        a(t["thrust_military"]),
        a(t["thrust_maximum"]),
        a(gear["breakpoint_throttle"]),
        a(gear["slope_low"]),
        a(gear["slope_high"]),
        a(gear["offset_high"]),
        a(lag["afterburner_threshold_pct"]),
        a(lag["fast_rate_per_s"]),
        a(lag["lit_target_pct"]),
        a(lag["unlit_target_pct"]),
        a([r["dp_low"], r["rtau_low"], r["dp_high"], r["rtau_high"], r["intercept"], r["slope"]]),
    )


def atmosphere_data(dtype=None) -> AtmosphereData:
    """The air data computer's constants."""
    dtype = dtype or jnp.result_type(float)
    atm = stevens_lewis_data()["atmosphere"]
    keys = (
        "rho0_slug_ft3",
        "tfac_slope_per_ft",
        "T0_rankine",
        "T_strat_rankine",
        "strat_alt_ft",
        "density_exponent",
        "gamma",
        "R_ft_lbf_per_slug_R",
    )
    return AtmosphereData(*(jnp.asarray(atm[k], dtype) for k in keys))


# --- the book's interpolation -----------------------------------------------------


def segment(x: Array, grid: Array) -> tuple[Array, Array]:
    """``(i, f)`` on the uniform ``grid`` (n,): ``i`` (int32) and ``f`` as in the module doc (``f`` outside
    [0, 1] beyond the ends)."""
    n = grid.shape[0]
    position = (x - grid[0]) / (grid[1] - grid[0])
    index = jnp.clip(jnp.floor(position), 0, n - 2)
    return index.astype(jnp.int32), position - index


def interpolate1(values: Array, i: Array, f: Array) -> Array:
    """``(1 - f) T_i + f T_{i+1}`` along the last axis of ``values`` (n,) or (m, n)."""
    lead = values.shape[:-1]
    start = (jnp.zeros((), i.dtype),) * len(lead) + (i,)
    pair = jax.lax.dynamic_slice(values, start, lead + (2,))  # one gather of the two columns
    return pair[..., 0] + f * (pair[..., 1] - pair[..., 0])


def interpolate2(values: Array, i: Array, f: Array, j: Array, g: Array) -> Array:
    """Bilinear ``T(row, col)`` of ``values`` (rows, cols) from segments ``(i, f)``, ``(j, g)``: columns
    first, then rows (the book's order); the 2x2 block is one ``dynamic_slice`` (under ``vmap`` one
    gather instead of four cell gathers, four values instead of whole rows)."""
    block = jax.lax.dynamic_slice(values, (i, j), (2, 2))
    low = block[0, 0] + g * (block[0, 1] - block[0, 0])
    return low + f * (block[1, 0] + g * (block[1, 1] - block[1, 0]) - low)


def _grid_size(name: str, grid: Array) -> int:
    """The number of breakpoints of a 1-D grid of at least 2 (trace time)."""
    shape = checks.shape_of(grid)
    if len(shape) != 1 or shape[0] < 2:
        raise ValueError(
            f"{name}: expected a 1-D grid of at least 2 breakpoints, got shape {shape}"
        )
    return shape[0]


def lookup1(x: Array, grid: Array, values: Array) -> Array:
    """1-D table lookup ``T(x)`` (``values`` (n,) or (m, n): m tables on the same grid)."""
    n = _grid_size("grid", grid)
    shape = checks.shape_of(values)
    if len(shape) not in (1, 2) or shape[-1] != n:
        raise ValueError(
            f"values: expected a table of shape ({n},) or (m, {n}) on the {n}-point grid, got {shape}"
        )
    return interpolate1(values, *segment(x, grid))


def lookup2(row: Array, row_grid: Array, col: Array, col_grid: Array, values: Array) -> Array:
    """2-D table lookup ``T(row, col)``, bilinear, extrapolated from the end segments."""
    checks.check_shape(
        "values",
        values,
        (_grid_size("row_grid", row_grid), _grid_size("col_grid", col_grid)),
        "one row per row_grid point, one column per col_grid point",
    )
    return interpolate2(values, *segment(row, row_grid), *segment(col, col_grid))
