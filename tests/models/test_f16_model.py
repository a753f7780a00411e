"""The F-16 model against independent NumPy references written here from the book:

- table interpolation: the index arithmetic of the book's Fortran (``S = 0.2*ALPHA``,
  ``K = INT(S)`` clamped, ``L = K + INT(SIGN(1.1, DA))``, ...), on random points inside
  and outside every table, 1e-12;
- the whole state derivative: the aero build-up, ADC, engine and the rigid-body
  equations in vector form (``J w' = M - w x (J w + h)``, the body velocity rotated to
  north-east-down by SciPy's ``Rotation``), 1e-10 relative;
- Morelli's polynomial typed term by term from the paper's structure, 1e-12;
- ``jax.jacfwd`` linearisation against central finite differences.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxfdi.models.f16 import f16_dynamics, f16_params, flight_modes, linearize
from jaxfdi.models.f16._aero import table_coefficients
from jaxfdi.models.f16._dynamics import aero_coefficients, saturate
from jaxfdi.models.f16._engine import power_rate, throttle_gearing, thrust
from jaxfdi.models.f16._linearize import longitudinal
from jaxfdi.models.f16._morelli import polynomial_coefficients
from jaxfdi.models.f16._tables import lookup1, lookup2, stevens_lewis_data, table_arrays

RNG = np.random.default_rng(20231123)
N = 400


# --- the NumPy reference: the book's Fortran index arithmetic ------------------------


def _int(x):
    return np.trunc(x).astype(int)


def ref_alpha(alpha):
    s = 0.2 * alpha
    k = np.clip(_int(s), -1, 8)
    da = s - k
    return k + 2, k + np.where(da >= 0, 1, -1) + 2, np.abs(da)  # array columns, |DA|


def ref_1d(table, alpha):
    k, l, da = ref_alpha(alpha)
    return table[..., k] + da * (table[..., l] - table[..., k])


def ref_el(table, alpha, el):
    k, l, da = ref_alpha(alpha)
    s = el / 12.0
    m = np.clip(_int(s), -1, 1)
    de = s - m
    n = m + np.where(de >= 0, 1, -1)
    v = table[m + 2, k] + da * (table[m + 2, l] - table[m + 2, k])
    w = table[n + 2, k] + da * (table[n + 2, l] - table[n + 2, k])
    return v + (w - v) * np.abs(de)


def ref_abs_beta(table, alpha, beta):
    k, l, da = ref_alpha(alpha)
    s = 0.2 * np.abs(beta)
    m = np.clip(_int(s), 1, 5)  # IF (M.EQ.0) M=1; IF (M.GE.6) M=5
    db = s - m
    n = m + np.where(db >= 0, 1, -1)
    v = table[m, k] + da * (table[m, l] - table[m, k])
    w = table[n, k] + da * (table[n, l] - table[n, k])
    return (v + (w - v) * np.abs(db)) * np.where(beta >= 0, 1.0, -1.0)


def ref_beta(table, alpha, beta):
    k, l, da = ref_alpha(alpha)
    s = 0.1 * beta
    m = np.clip(_int(s), -2, 2)
    db = s - m
    n = m + np.where(db >= 0, 1, -1)
    v = table[m + 3, k] + da * (table[m + 3, l] - table[m + 3, k])
    w = table[n + 3, k] + da * (table[n + 3, l] - table[n + 3, k])
    return v + (w - v) * np.abs(db)


def ref_thrust_table(table, mach, alt):
    h = 1e-4 * alt
    i = np.clip(_int(h), 0, 4)
    dh = h - i
    rm = 5.0 * mach
    m = np.clip(_int(rm), 0, 4)
    dm = rm - m
    s = table[m, i] * (1 - dh) + table[m, i + 1] * dh
    t = table[m + 1, i] * (1 - dh) + table[m + 1, i + 1] * dh
    return s + (t - s) * dm


def ref_coefficients(T, alpha, beta, el, ail, rdr, p, q, r, vt, xcg):
    """The book's aero build-up (FUNCTION CX ... DAMP and SUBROUTINE F), degrees in."""
    d = ref_1d(T["DAMP"], alpha)
    b2v, cq = 30.0 / (2 * vt), 11.32 * q / (2 * vt)
    cx = ref_el(T["CX"], alpha, el) + cq * d[0]
    cy = -0.02 * beta + 0.021 * ail / 20 + 0.086 * rdr / 30 + b2v * (d[1] * r + d[2] * p)
    cz = ref_1d(T["CZ"], alpha) * (1 - (beta / 57.3) ** 2) - 0.19 * el / 25 + cq * d[3]
    cl = (
        ref_abs_beta(T["CL"], alpha, beta)
        + ref_beta(T["DLDA"], alpha, beta) * ail / 20
        + ref_beta(T["DLDR"], alpha, beta) * rdr / 30
        + b2v * (d[4] * r + d[5] * p)
    )
    cm = ref_el(T["CM"], alpha, el) + cq * d[6] + cz * (0.35 - xcg)
    cn = (
        ref_abs_beta(T["CN"], alpha, beta)
        + ref_beta(T["DNDA"], alpha, beta) * ail / 20
        + ref_beta(T["DNDR"], alpha, beta) * rdr / 30
        + b2v * (d[7] * r + d[8] * p)
        - cy * (0.35 - xcg) * 11.32 / 30
    )
    return np.stack([cx, cy, cz, cl, cm, cn])


def ref_derivative(T, x, u, xcg):
    """State derivative from the rigid-body equations in vector form (one state)."""
    vt, alpha, beta, phi, theta, psi, p, q, r, pn, pe, alt, power = x
    thtl, el, ail, rdr = u
    data = stevens_lewis_data()
    mg = data["mass_geometry"]
    mass, g = mg["mass_slug"]["value"], mg["g0_ft_s2"]["value"]
    J = np.array(
        [
            [mg["Jxx_slug_ft2"], 0, -mg["Jxz_slug_ft2"]],
            [0, mg["Jyy_slug_ft2"], 0],
            [-mg["Jxz_slug_ft2"], 0, mg["Jzz_slug_ft2"]],
        ]
    )
    tfac = 1 - 0.703e-5 * alt
    temp = 390.0 if alt >= 35000 else 519.0 * tfac
    rho = 2.377e-3 * tfac**4.14
    mach, qbar = vt / math.sqrt(1.4 * 1716.3 * temp), 0.5 * rho * vt**2
    cpow = 64.94 * thtl if thtl <= 0.77 else 217.38 * thtl - 117.38
    rtau = lambda dp: 1.0 if dp <= 25 else (0.1 if dp >= 50 else 1.9 - 0.036 * dp)
    if cpow >= 50:
        rate, target = (5.0, cpow) if power >= 50 else (rtau(60 - power), 60.0)
    else:
        rate, target = (5.0, 40.0) if power >= 50 else (rtau(cpow - power), cpow)
    tidl, tmil, tmax = (
        ref_thrust_table(T[k], mach, alt)
        for k in ("thrust_idle", "thrust_military", "thrust_maximum")
    )
    thr = (
        tidl + (tmil - tidl) * power / 50
        if power < 50
        else tmil + (tmax - tmil) * (power - 50) / 50
    )
    c = ref_coefficients(T, math.degrees(alpha), math.degrees(beta), el, ail, rdr, p, q, r, vt, xcg)
    V = vt * np.array(
        [math.cos(alpha) * math.cos(beta), math.sin(beta), math.sin(alpha) * math.cos(beta)]
    )
    w = np.array([p, q, r])
    g_body = g * np.array(
        [-math.sin(theta), math.sin(phi) * math.cos(theta), math.cos(phi) * math.cos(theta)]
    )
    force = qbar * 300.0 * c[:3] + np.array([thr, 0, 0])
    V_dot = force / mass + g_body - np.cross(w, V)
    vt_dot = V @ V_dot / vt
    alpha_dot = (V[0] * V_dot[2] - V[2] * V_dot[0]) / (V[0] ** 2 + V[2] ** 2)
    beta_dot = (V_dot[1] * vt - V[1] * vt_dot) / (vt**2 * math.cos(beta))
    moment = qbar * 300.0 * np.array([30.0 * c[3], 11.32 * c[4], 30.0 * c[5]])
    w_dot = np.linalg.solve(J, moment - np.cross(w, J @ w + np.array([160.0, 0, 0])))
    euler_dot = np.linalg.solve(
        np.array(
            [
                [1, 0, -math.sin(theta)],
                [0, math.cos(phi), math.sin(phi) * math.cos(theta)],
                [0, -math.sin(phi), math.cos(phi) * math.cos(theta)],
            ]
        ),
        w,
    )
    ned = Rotation.from_euler("ZYX", [psi, theta, phi]).as_matrix() @ V
    return np.concatenate(
        [
            [vt_dot, alpha_dot, beta_dot],
            euler_dot,
            w_dot,
            [ned[0], ned[1], -ned[2]],
            [rate * (target - power)],
        ]
    )


@pytest.fixture(scope="module")
def params():
    return f16_params()


@pytest.fixture(scope="module")
def tables():
    return table_arrays("stevens_lewis_2nd_ed")


def _points():
    return (
        RNG.uniform(-22, 58, N),
        RNG.uniform(-42, 42, N),
        RNG.uniform(-35, 35, N),
        RNG.uniform(-25, 25, N),
        RNG.uniform(-35, 35, N),
    )


def test_table_lookups_equal_the_books_fortran(params, tables):
    """Every table at random points inside and outside its breakpoints (extrapolation from
    the end segments), 1e-12."""
    alpha, beta, el, _, _ = _points()
    mach, alt = RNG.uniform(-0.1, 1.3, N), RNG.uniform(-5000, 62000, N)
    a = params.aero
    look = jax.jit(
        jax.vmap(
            lambda al, be, e, m, h: (
                lookup2(e, a.elevator_deg, al, a.alpha_deg, a.CX),
                lookup2(e, a.elevator_deg, al, a.alpha_deg, a.CM),
                lookup1(al, a.alpha_deg, a.CZ),
                lookup1(al, a.alpha_deg, a.DAMP),
                jnp.stack(
                    [
                        lookup2(be, a.beta_deg, al, a.alpha_deg, t)
                        for t in (a.DLDA, a.DLDR, a.DNDA, a.DNDR)
                    ]
                ),
                jnp.stack(
                    [
                        lookup2(m, params.engine.mach, h, params.engine.altitude_ft, t)
                        for t in (params.engine.idle, params.engine.military, params.engine.maximum)
                    ]
                ),
            )
        )
    )
    cx, cm, cz, damp, lat, thr = (np.asarray(v) for v in look(alpha, beta, el, mach, alt))
    np.testing.assert_allclose(cx, ref_el(tables["CX"], alpha, el), rtol=0, atol=1e-12)
    np.testing.assert_allclose(cm, ref_el(tables["CM"], alpha, el), rtol=0, atol=1e-12)
    np.testing.assert_allclose(cz, ref_1d(tables["CZ"], alpha), rtol=0, atol=1e-12)
    np.testing.assert_allclose(damp, ref_1d(tables["DAMP"], alpha).T, rtol=0, atol=1e-12)
    for i, name in enumerate(("DLDA", "DLDR", "DNDA", "DNDR")):
        np.testing.assert_allclose(
            lat[:, i], ref_beta(tables[name], alpha, beta), rtol=0, atol=1e-12
        )
    for i, name in enumerate(("thrust_idle", "thrust_military", "thrust_maximum")):
        np.testing.assert_allclose(
            thr[:, i], ref_thrust_table(tables[name], mach, alt), rtol=1e-12, atol=1e-12
        )
    assert (
        np.any(alpha < -10)
        and np.any(alpha > 45)
        and np.any(np.abs(beta) > 30)
        and np.any(np.abs(el) > 24)
    )


def test_coefficient_buildup_equals_the_books(params, tables):
    """CX..Cn with damping, |beta| symmetry of CL/CN and the c.g. shift, 1e-12."""
    alpha, beta, el, ail, rdr = _points()
    beta[:20] = 0.0  # the Fortran SIGN(1.0, 0.0) = +1 branch
    p, q, r = RNG.uniform(-1, 1, (3, N))
    vt, xcg = RNG.uniform(150, 900, N), RNG.uniform(0.25, 0.45, N)
    x = np.zeros((N, 13))
    x[:, 0], x[:, 1], x[:, 2], x[:, 6], x[:, 7], x[:, 8] = (
        vt,
        np.radians(alpha),
        np.radians(beta),
        p,
        q,
        r,
    )
    u = np.stack([np.full(N, 0.5), el, ail, rdr], axis=1)
    ours = jax.jit(
        jax.vmap(lambda x, u, c: jnp.stack(aero_coefficients(params._replace(xcg=c), x, u)))
    )(x, u, xcg)
    ref = ref_coefficients(
        tables, np.degrees(x[:, 1]), np.degrees(x[:, 2]), el, ail, rdr, p, q, r, vt, xcg
    )
    np.testing.assert_allclose(np.asarray(ours), ref.T, rtol=0, atol=1e-12)


def test_state_derivative_equals_vector_rigid_body_equations(params, tables):
    """f16_dynamics against the rigid-body equations written in vector form (moments
    solved with the full inertia matrix, navigation by SciPy's rotation), engine below
    and above 50 % power, 1e-10 relative."""
    cases = []
    for power, thtl in ((9.0, 0.14), (45.0, 0.9), (70.0, 0.3), (80.0, 0.95)):
        x = np.array(
            [
                RNG.uniform(300, 800),
                RNG.uniform(-0.1, 0.6),
                RNG.uniform(-0.3, 0.3),
                RNG.uniform(-1, 1),
                RNG.uniform(-0.8, 0.8),
                RNG.uniform(-3, 3),
                *RNG.uniform(-1, 1, 3),
                100.0,
                -50.0,
                RNG.uniform(0, 40000),
                power,
            ]
        )
        u = np.array([thtl, RNG.uniform(-20, 20), RNG.uniform(-20, 20), RNG.uniform(-25, 25)])
        cases.append((x, u, RNG.uniform(0.3, 0.4)))
    xs, us, xcgs = (np.stack(v) for v in zip(*cases))
    ours = np.asarray(
        jax.jit(jax.vmap(lambda x, u, c: f16_dynamics(x, u, params._replace(xcg=c))))(xs, us, xcgs)
    )
    for i, (x, u, xcg) in enumerate(cases):
        ref = ref_derivative(tables, x, u, xcg)
        np.testing.assert_allclose(ours[i], ref, rtol=1e-10, atol=1e-10 * np.max(np.abs(ref)))


def test_morelli_polynomial_term_by_term(params):
    """Morelli (1998): the 19 coefficient functions typed out here in the paper's
    structure (values from the data file), assembled with the damping counted once."""
    import json

    from jaxfdi.data import data_path

    with open(data_path("f16_morelli.json")) as fh:
        c = {k: v["values"] for k, v in json.load(fh)["coefficients"].items()}
    morelli = f16_params(aero="morelli")
    alpha, beta, el, ail, rdr = (np.radians(v) for v in _points())
    p, q, r = RNG.uniform(-1, 1, (3, N))
    vt = RNG.uniform(200, 900, N)
    a, b, de, da, dr = alpha, beta, el, ail, rdr
    ph, qh, rh = p * 30 / (2 * vt), q * 11.32 / (2 * vt), r * 30 / (2 * vt)
    A, B, C, D, E, F, G, Hc, I, Jc, K, L, M, Nn, O, P_, Q_, R_, S = (
        c[k] for k in "abcdefghijklmnopqrs"
    )
    cx = (
        A[0]
        + A[1] * a
        + A[2] * de**2
        + A[3] * de
        + A[4] * a * de
        + A[5] * a**2
        + A[6] * a**3
        + (B[0] + B[1] * a + B[2] * a**2 + B[3] * a**3 + B[4] * a**4) * qh
    )
    cy = (
        C[0] * b
        + C[1] * da
        + C[2] * dr
        + (D[0] + D[1] * a + D[2] * a**2 + D[3] * a**3) * ph
        + (E[0] + E[1] * a + E[2] * a**2 + E[3] * a**3) * rh
    )
    cz = (
        (F[0] + F[1] * a + F[2] * a**2 + F[3] * a**3 + F[4] * a**4) * (1 - b**2)
        + F[5] * de
        + (G[0] + G[1] * a + G[2] * a**2 + G[3] * a**3 + G[4] * a**4) * qh
    )
    cl = (
        Hc[0] * b
        + Hc[1] * a * b
        + Hc[2] * a**2 * b
        + Hc[3] * b**2
        + Hc[4] * a * b**2
        + Hc[5] * a**3 * b
        + Hc[6] * a**4 * b
        + Hc[7] * a**2 * b**2
        + (I[0] + I[1] * a + I[2] * a**2 + I[3] * a**3) * ph
        + (Jc[0] + Jc[1] * a + Jc[2] * a**2 + Jc[3] * a**3 + Jc[4] * a**4) * rh
        + (K[0] + K[1] * a + K[2] * b + K[3] * a**2 + K[4] * a * b + K[5] * a**2 * b + K[6] * a**3)
        * da
        + (
            L[0]
            + L[1] * a
            + L[2] * b
            + L[3] * a * b
            + L[4] * a**2 * b
            + L[5] * a**3 * b
            + L[6] * b**2
        )
        * dr
    )
    cm = (
        M[0]
        + M[1] * a
        + M[2] * de
        + M[3] * a * de
        + M[4] * de**2
        + M[5] * a**2 * de
        + M[6] * de**3
        + M[7] * a * de**2
        + (Nn[0] + Nn[1] * a + Nn[2] * a**2 + Nn[3] * a**3 + Nn[4] * a**4 + Nn[5] * a**5) * qh
    )
    cn = (
        O[0] * b
        + O[1] * a * b
        + O[2] * b**2
        + O[3] * a * b**2
        + O[4] * a**2 * b
        + O[5] * a**2 * b**2
        + O[6] * a**3 * b
        + (P_[0] + P_[1] * a + P_[2] * a**2 + P_[3] * a**3 + P_[4] * a**4) * ph
        + (Q_[0] + Q_[1] * a + Q_[2] * a**2) * rh
        + (
            R_[0]
            + R_[1] * a
            + R_[2] * b
            + R_[3] * a * b
            + R_[4] * a**2 * b
            + R_[5] * a**3 * b
            + R_[6] * a**2
            + R_[7] * a**3
            + R_[8] * b**3
            + R_[9] * a * b**3
        )
        * da
        + (S[0] + S[1] * a + S[2] * b + S[3] * a * b + S[4] * a**2 * b + S[5] * a**2) * dr
    )
    ours = jax.jit(
        jax.vmap(lambda *args: jnp.stack(polynomial_coefficients(morelli.aero, *args, 30.0, 11.32)))
    )(*(np.degrees(v) for v in (a, b, de, da, dr)), p, q, r, vt)
    np.testing.assert_allclose(
        np.asarray(ours), np.stack([cx, cy, cz, cl, cm, cn]).T, rtol=0, atol=1e-12
    )
    # the fit reproduces the tables it was fitted to, roughly, inside the data range (|beta| < 10 deg)
    x = np.zeros((N, 13))
    x[:, 0], x[:, 1], x[:, 2] = vt, RNG.uniform(-0.15, 0.7, N), RNG.uniform(-0.17, 0.17, N)
    u = np.stack([np.full(N, 0.5), RNG.uniform(-20, 20, N), np.zeros(N), np.zeros(N)], axis=1)
    both = jax.jit(
        jax.vmap(
            lambda x, u: (
                jnp.stack(aero_coefficients(params, x, u)),
                jnp.stack(aero_coefficients(morelli, x, u)),
            )
        )
    )(x, u)
    assert (
        np.max(np.abs(np.asarray(both[0])[:, [0, 2, 4]] - np.asarray(both[1])[:, [0, 2, 4]])) < 0.1
    )


def test_profiles_apply_their_overrides():
    base, nasa = table_arrays("stevens_lewis_2nd_ed"), table_arrays("nasa_morelli_tm2003_212145")
    assert base["DAMP"][6, 1] == -0.54 and nasa["DAMP"][6, 1] == -5.4  # Cmq at alpha -5 deg
    assert base["DAMP"][2, 11] == -2.27 and nasa["DAMP"][2, 11] == -0.227  # CYp at 45 deg
    assert np.count_nonzero(base["CL"] != nasa["CL"]) == 18
    bench = table_arrays("aerobench_python")
    assert bench["CZ"][3] == -0.415 and bench["thrust_idle"][3, 1] == -170.0
    with pytest.raises(ValueError, match="profile"):
        table_arrays("third_edition")


def test_linearisation_matches_central_differences(params):
    """jacfwd A, B at the 502 ft/s trim and at a general point (beta, rates and every
    surface nonzero, away from breakpoints) against central differences."""
    x_trim = np.array([502.0, 0.03691068, 0, 0, 0.03691068, 0, 0, 0, 0, 0, 0, 0, 8.99651])
    u_trim = np.array([0.13853474, -0.75878109, 0, 0])
    x_gen = np.array(
        [610.0, 0.121, 0.052, 0.31, 0.2, 0.7, 0.11, -0.07, 0.05, 10.0, 20.0, 8000.0, 37.0]
    )
    u_gen = np.array([0.4, 3.1, -4.3, 6.7])
    jac = jax.jit(lambda x, u: linearize(params, x, u)[:2])
    f = jax.jit(lambda x, u: f16_dynamics(x, u, params))
    for x, u in ((x_trim, u_trim), (x_gen, u_gen)):
        A, B = (np.asarray(m) for m in jac(x, u))
        for M, base, other, is_x in ((A, x, u, True), (B, u, x, False)):
            fd = np.zeros_like(M)
            for j in range(base.size):
                h = 1e-6 * max(1.0, abs(base[j]))
                plus, minus = base.copy(), base.copy()
                plus[j] += h
                minus[j] -= h
                fp = f(plus, other) if is_x else f(other, plus)
                fm = f(minus, other) if is_x else f(other, minus)
                fd[:, j] = (np.asarray(fp) - np.asarray(fm)) / (2 * h)
            scale = np.maximum(np.abs(M), 1.0)
            assert np.max(np.abs(M - fd) / scale) < 1e-6


def test_modes_at_the_books_trims():
    """Longitudinal and lateral modes named from the 4-state blocks: at xcg 0.30 the short
    period is an oscillation; at 0.35 the two fastest roots are real, -1.91 and +0.098
    1/s, the unstable one mostly pitch attitude and airspeed; at 0.38 the divergence is
    faster (+0.66 1/s); the lateral modes are alike at all three."""
    from jaxfdi.models.f16 import level_flight, trim_batch

    p = f16_params()
    xcgs = jnp.array(
        [0.30, 0.35, 0.38, 0.33]
    )  # four, as the flight's trims: one compiled solve for both
    t = trim_batch(p, level_flight(jnp.full(4, 502.0)), xcgs)
    models = jax.jit(jax.vmap(lambda x, u, c: linearize(p._replace(xcg=c), x, u)))(
        t.state, t.control, xcgs
    )
    out = {}
    for i, xcg in enumerate((0.30, 0.35, 0.38)):
        model = jax.tree_util.tree_map(lambda a: a[i], models)
        modes = {m.name: m for m in flight_modes(model)}
        A_lon, _ = longitudinal(model)
        roots = np.sort_complex(np.linalg.eigvals(np.asarray(A_lon)))
        named = np.sort_complex(np.array(modes["short period"].roots + modes["phugoid"].roots))
        np.testing.assert_allclose(named, roots, atol=1e-9)
        out[xcg] = modes
    sp35 = sorted(r.real for r in out[0.35]["short period"].roots)
    assert sp35[0] < -1.5 and 0.05 < sp35[1] < 0.15 and not out[0.35]["short period"].stable
    assert abs(out[0.35]["phugoid"].roots[0].imag) > 0 and out[0.35]["phugoid"].stable
    sp30 = out[0.30]["short period"]
    assert abs(sp30.roots[0].imag) > 1.0 and 0.5 < sp30.damping_ratio < 0.8
    sp38 = sorted(r.real for r in out[0.38]["short period"].roots)  # pitch divergence, faster
    assert sp38[1] > sp35[1] and not out[0.38]["short period"].stable
    unstable = out[0.35]["short period"].shapes[1]  # the +0.098 root: pitch attitude and speed
    assert unstable[2] == 1.0 and unstable[0] > 0.4 and unstable[1] < 0.2
    for modes in out.values():
        assert modes["roll"].roots[0].real < -3.0 and abs(modes["spiral"].roots[0].real) < 0.05
        assert modes["Dutch roll"].natural_frequency > 2.5 and modes["Dutch roll"].stable


def test_vmap_grad_float32_and_bad_input(params):
    x = jnp.array([502.0, 0.04, 0.01, 0.1, 0.04, 0.0, 0.01, 0.02, 0.01, 0.0, 0.0, 1000.0, 9.0])
    u = jnp.array([0.14, -0.7, 1.0, -1.0])
    f = jax.jit(lambda x, u, xcg: f16_dynamics(x, u, params._replace(xcg=xcg)))
    # vmap over aircraft (states) and parameters (xcg) equals a loop
    xcgs = jnp.array([0.3, 0.35, 0.38])
    batch = jax.vmap(f, in_axes=(None, None, 0))(x, u, xcgs)
    for i, c in enumerate(xcgs):
        np.testing.assert_allclose(batch[i], f(x, u, c), rtol=1e-14)
    # grad of the pitch acceleration with respect to the c.g.: qbar S cbar c7 CZ (d Cm/d xcg = -CZ)
    grad = jax.grad(lambda c: f(x, u, c)[7])(0.35)
    fd = (f(x, u, 0.35 + 1e-6)[7] - f(x, u, 0.35 - 1e-6)[7]) / 2e-6
    np.testing.assert_allclose(grad, fd, rtol=1e-6)
    # float32 in, float32 out, close to float64
    p32 = f16_params(dtype=jnp.float32)
    y32 = jax.jit(f16_dynamics)(x.astype(jnp.float32), u.astype(jnp.float32), p32)
    assert y32.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(y32)))
    y64 = f(x, u, 0.35)
    np.testing.assert_allclose(y32, y64, rtol=2e-4, atol=2e-4 * float(jnp.max(jnp.abs(y64))))
    # limits, gearing, lag and the thrust table's corner (one jitted call)
    limited, gear, lag, mil = jax.jit(
        lambda: (
            saturate(jnp.array([1.5, -40.0, 30.0, 0.0]), params),
            throttle_gearing(0.77, params.engine),
            power_rate(50.0, 80.0, params.engine),
            thrust(50.0, 0.0, 0.0, params.engine),
        )
    )()
    np.testing.assert_allclose(limited, [1.0, -25.0, 21.5, 0.0])
    assert float(gear) == pytest.approx(50.0, abs=0.01)
    assert float(lag) == pytest.approx(5.0 * 30.0)
    assert float(mil) == pytest.approx(12680.0)
    with pytest.raises(ValueError, match="x: expected shape"):
        f16_dynamics(jnp.zeros(12), u, params)
    with pytest.raises(ValueError, match="u: expected shape"):
        f16_dynamics(x, jnp.zeros(3), params)
    with pytest.raises(ValueError, match="aero"):
        f16_params(aero="datcom")


def test_table_coefficients_damping_once(params):
    """Morelli's model carries its own damping; the table model its DAMP terms: at zero
    rates both give their static coefficients, and a pitch rate adds exactly Cmq qhat."""
    a = params.aero
    base = table_coefficients(a, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 500.0, 30.0, 11.32)
    pitching = table_coefficients(a, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 500.0, 30.0, 11.32)
    cmq = float(lookup1(5.0, a.alpha_deg, a.DAMP)[6])
    assert float(pitching.Cm - base.Cm) == pytest.approx(cmq * 11.32 * 0.2 / 1000.0, rel=1e-12)
