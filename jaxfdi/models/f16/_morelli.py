"""Morelli's global polynomial model of the F-16 aerodynamics (Morelli 1998, "Global
nonlinear parametric modeling with application to F-16 aerodynamics", Proc. American
Control Conference; fitted to the NASA TP-1538 / Stevens & Lewis data).

Coefficients ``a`` .. ``s`` (110 numbers) and terms from ``jaxfdi.data.data_path("f16_morelli.json")``: each
function ``sum_i c_i m_i(alpha, beta, de, da, dr)``, ``m_i`` monomials (rad); with ``phat = p b/(2V)``,
``qhat = q cbar/(2V)``, ``rhat = r b/(2V)``::

    Cx = Cx0(alpha, de) + Cxq(alpha) qhat
    Cy = Cy0(beta, da, dr) + Cyp(alpha) phat + Cyr(alpha) rhat
    Cz = Cz0(alpha, beta, de) + Czq(alpha) qhat
    Cl = Cl0(alpha, beta) + Clp phat + Clr rhat + Clda(alpha, beta) da + Cldr(alpha, beta) dr
    Cm = Cm0(alpha, de) + Cmq(alpha) qhat
    Cn = Cn0(alpha, beta) + Cnp phat + Cnr rhat + Cnda(alpha, beta) da + Cndr(alpha, beta) dr

about ``xcg_ref = 0.35 cbar`` (c.g. shift in ``dynamics``). Damping counted once (AeroBench's
``subf16_model`` adds the tables' DAMP on top: twice).
"""

from __future__ import annotations

import functools
import json
import re
from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi.data import data_path
from jaxfdi.models.f16._aero import AeroCoefficients

#: the polynomial's variables, in the order of a term's exponent tuple
VARIABLES = ("alpha", "beta", "de", "da", "dr")
#: coefficient letters of the data file, in order
LETTERS = tuple("abcdefghijklmnopqrs")
_FACTOR = "*(1-beta^2)"


class MorelliCoefficients(NamedTuple):
    """The 19 coefficient vectors ``a`` .. ``s`` (a pytree: the term structure is static)."""

    a: Array
    b: Array
    c: Array
    d: Array
    e: Array
    f: Array
    g: Array
    h: Array
    i: Array
    j: Array
    k: Array
    l: Array
    m: Array
    n: Array
    o: Array
    p: Array
    q: Array
    r: Array
    s: Array


def _parse_term(term: str) -> tuple[tuple[int, ...], bool]:
    """``"alpha^2*beta"`` -> exponents (2, 1, 0, 0, 0); a trailing ``*(1-beta^2)`` -> flag."""
    factor = term.endswith(_FACTOR)
    body = term[: -len(_FACTOR)] if factor else term
    powers = [0] * len(VARIABLES)
    for token in body.split("*"):
        match = re.fullmatch(r"(alpha|beta|de|da|dr)(?:\^(\d+))?|1", token)
        if match is None:
            raise ValueError(f"f16_morelli.json: cannot read the term {term!r} (token {token!r})")
        if match.group(1):
            powers[VARIABLES.index(match.group(1))] += int(match.group(2) or 1)
    return tuple(powers), factor


@functools.lru_cache(maxsize=None)
def _data() -> tuple[dict, dict]:
    with open(data_path("f16_morelli.json")) as fh:
        data = json.load(fh)
    coefficients = data["coefficients"]
    if tuple(coefficients) != LETTERS:
        raise ValueError(
            f"f16_morelli.json: expected coefficients {LETTERS}, got {tuple(coefficients)}"
        )
    terms = {
        letter: tuple(_parse_term(t) for t in coefficients[letter]["terms"]) for letter in LETTERS
    }
    for letter in LETTERS:
        if len(terms[letter]) != len(coefficients[letter]["values"]):
            raise ValueError(
                f"f16_morelli.json: coefficient {letter} has {len(terms[letter])} terms and "
                f"{len(coefficients[letter]['values'])} values"
            )
    return coefficients, terms


def morelli_coefficients_data(dtype=None) -> MorelliCoefficients:
    """The 110 coefficients of the data file as a ``MorelliCoefficients`` pytree."""
    dtype = dtype or jnp.result_type(float)
    coefficients, _ = _data()
    return MorelliCoefficients(
        *(jnp.asarray(coefficients[letter]["values"], dtype) for letter in LETTERS)
    )


def _polynomial(letter: str, values: Array, variables: tuple[Array, ...]) -> Array:
    """``sum_i c_i m_i`` with the monomials written out from the static exponents."""
    _, terms = _data()
    total = 0.0
    for i, (powers, factor) in enumerate(terms[letter]):
        term = values[i]
        for var, power in zip(variables, powers):
            for _ in range(power):
                term = term * var
        if factor:
            term = term * (1.0 - variables[1] * variables[1])
        total = total + term
    return total


def polynomial_coefficients(
    coef: MorelliCoefficients,
    alpha_deg: Array,
    beta_deg: Array,
    el: Array,
    ail: Array,
    rdr: Array,
    p: Array,
    q: Array,
    r: Array,
    vt: Array,
    span: Array,
    chord: Array,
) -> AeroCoefficients:
    """Total coefficients of Morelli's polynomial model (module doc); the same arguments
    as ``aero.table_coefficients`` (angles in degrees, converted here)."""
    to_rad = jnp.pi / 180.0
    variables = tuple(v * to_rad for v in (alpha_deg, beta_deg, el, ail, rdr))
    _, _, _, da, dr = variables
    phat, qhat, rhat = p * span / (2.0 * vt), q * chord / (2.0 * vt), r * span / (2.0 * vt)
    poly = {letter: _polynomial(letter, getattr(coef, letter), variables) for letter in LETTERS}
    Cx = poly["a"] + poly["b"] * qhat
    Cy = poly["c"] + poly["d"] * phat + poly["e"] * rhat
    Cz = poly["f"] + poly["g"] * qhat
    Cl = poly["h"] + poly["i"] * phat + poly["j"] * rhat + poly["k"] * da + poly["l"] * dr
    Cm = poly["m"] + poly["n"] * qhat
    Cn = poly["o"] + poly["p"] * phat + poly["q"] * rhat + poly["r"] * da + poly["s"] * dr
    return AeroCoefficients(Cx, Cy, Cz, Cl, Cm, Cn)
