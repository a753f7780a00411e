"""The benchmark's baseline: seed 000's closed-loop F-16 flight as a straightforward NumPy
loop, one flight at a time, the way Python F-16 simulators are written today (AeroBench
style: the book's Fortran functions ported one by one with its index arithmetic, a NumPy
state vector, an explicit RK4 step, a Python ``for`` loop over time).

It flies exactly the flight of ``jaxfdi.scenarios.f16_flight.run_flight``: the same
tables (``f16_stevens_lewis.json``), RK4 at 0.01 s, the same sensors (noise drawn with
NumPy's generator, so noisy flights differ from jaxfdi's draw for draw but not in law),
the same gust process, controller gains, reference and anti-windup. Written from the
book's equations, independently of jaxfdi's code (which is used only to build the
design: gains and reference); ``bench_f16_flight.py`` checks that the noise-free
trajectories agree.
"""

from __future__ import annotations

import json
import math

import numpy as np

RTOD = 180.0 / math.pi


class Tables:
    """The data file's tables as NumPy arrays (book layout: rows x alpha columns)."""

    def __init__(self, path):
        with open(path) as fh:
            d = json.load(fh)
        t = d["aero_tables"]
        self.cx, self.cz, self.cm = (np.array(t[k]["values"]) for k in ("CX", "CZ", "CM"))
        self.cl, self.cn = np.array(t["CL"]["values"]), np.array(t["CN"]["values"])
        self.dlda, self.dldr = np.array(t["DLDA"]["values"]), np.array(t["DLDR"]["values"])
        self.dnda, self.dndr = np.array(t["DNDA"]["values"]), np.array(t["DNDR"]["values"])
        self.damp = np.array(t["DAMP"]["values"])
        th = d["engine"]["thrust_tables"]
        self.idle, self.mil, self.max = (np.array(th[k]) for k in ("idle", "military", "maximum"))
        mg = d["mass_geometry"]
        self.mass = mg["mass_slug"]["value"]
        self.jxx, self.jyy, self.jzz, self.jxz = (
            mg[k] for k in ("Jxx_slug_ft2", "Jyy_slug_ft2", "Jzz_slug_ft2", "Jxz_slug_ft2")
        )
        self.s, self.b, self.cbar = mg["S_ft2"], mg["b_ft"], mg["cbar_ft"]
        self.xcgr, self.hx, self.g = (
            mg["xcg_ref_frac_cbar"],
            mg["hx_engine_angular_momentum_slug_ft2_s"]["value"],
            mg["g0_ft_s2"]["value"],
        )


def _fix(x):
    """Fortran INT: truncation toward zero."""
    return int(x)


def _alpha_index(alpha):
    s = 0.2 * alpha
    k = _fix(s)
    if k <= -2:
        k = -1
    if k >= 9:
        k = 8
    da = s - k
    l = k + _fix(math.copysign(1.1, da))
    return k + 2, l + 2, da


def damp(T, alpha):
    k, l, da = _alpha_index(alpha)
    return T.damp[:, k] + abs(da) * (T.damp[:, l] - T.damp[:, k])


def _el_table(A, alpha, el):
    k, l, da = _alpha_index(alpha)
    s = el / 12.0
    m = _fix(s)
    if m <= -2:
        m = -1
    if m >= 2:
        m = 1
    de = s - m
    n = m + _fix(math.copysign(1.1, de))
    m, n = m + 2, n + 2
    v = A[m, k] + abs(da) * (A[m, l] - A[m, k])
    w = A[n, k] + abs(da) * (A[n, l] - A[n, k])
    return v + (w - v) * abs(de)


def cx(T, alpha, el):
    return _el_table(T.cx, alpha, el)


def cm(T, alpha, el):
    return _el_table(T.cm, alpha, el)


def cz(T, alpha, beta, el):
    k, l, da = _alpha_index(alpha)
    s = T.cz[k] + abs(da) * (T.cz[l] - T.cz[k])
    return s * (1 - (beta / 57.3) ** 2) - 0.19 * (el / 25.0)


def cy(beta, ail, rdr):
    return -0.02 * beta + 0.021 * (ail / 20.0) + 0.086 * (rdr / 30.0)


def _abs_beta_table(A, alpha, beta):
    k, l, da = _alpha_index(alpha)
    s = 0.2 * abs(beta)
    m = _fix(s)
    if m == 0:
        m = 1
    if m >= 6:
        m = 5
    db = s - m
    n = m + _fix(math.copysign(1.1, db))
    t, u = A[m, k], A[m, l]
    v = t + abs(da) * (u - t)
    w = A[n, k] + abs(da) * (A[n, l] - A[n, k])
    return (v + (w - v) * abs(db)) * math.copysign(1.0, beta)


def _beta_table(A, alpha, beta):
    k, l, da = _alpha_index(alpha)
    s = 0.1 * beta
    m = _fix(s)
    if m <= -3:
        m = -2
    if m >= 3:
        m = 2
    db = s - m
    n = m + _fix(math.copysign(1.1, db))
    m, n = m + 3, n + 3
    t, u = A[m, k], A[m, l]
    v = t + abs(da) * (u - t)
    w = A[n, k] + abs(da) * (A[n, l] - A[n, k])
    return v + (w - v) * abs(db)


def adc(vt, alt):
    tfac = 1.0 - 0.703e-5 * alt
    t = 390.0 if alt >= 35000.0 else 519.0 * tfac
    rho = 2.377e-3 * tfac**4.14
    return vt / math.sqrt(1.4 * 1716.3 * t), 0.5 * rho * vt * vt


def tgear(thtl):
    return 64.94 * thtl if thtl <= 0.77 else 217.38 * thtl - 117.38


def rtau(dp):
    if dp <= 25.0:
        return 1.0
    if dp >= 50.0:
        return 0.1
    return 1.9 - 0.036 * dp


def pdot(p3, p1):
    if p1 >= 50.0:
        if p3 >= 50.0:
            t, p2 = 5.0, p1
        else:
            p2 = 60.0
            t = rtau(p2 - p3)
    else:
        if p3 >= 50.0:
            t, p2 = 5.0, 40.0
        else:
            p2 = p1
            t = rtau(p2 - p3)
    return t * (p2 - p3)


def thrust(T, pow_, alt, rmach):
    h = 0.0001 * alt
    i = _fix(h)
    if i >= 5:
        i = 4
    if i < 0:
        i = 0
    dh = h - i
    rm = 5.0 * rmach
    m = _fix(rm)
    if m >= 5:
        m = 4
    if m < 0:
        m = 0
    dm = rm - m
    cdh = 1.0 - dh
    s = T.mil[m, i] * cdh + T.mil[m, i + 1] * dh
    t = T.mil[m + 1, i] * cdh + T.mil[m + 1, i + 1] * dh
    tmil = s + (t - s) * dm
    if pow_ < 50.0:
        s = T.idle[m, i] * cdh + T.idle[m, i + 1] * dh
        t = T.idle[m + 1, i] * cdh + T.idle[m + 1, i + 1] * dh
        tidl = s + (t - s) * dm
        return tidl + (tmil - tidl) * pow_ * 0.02
    s = T.max[m, i] * cdh + T.max[m, i + 1] * dh
    t = T.max[m + 1, i] * cdh + T.max[m + 1, i + 1] * dh
    tmax = s + (t - s) * dm
    return tmil + (tmax - tmil) * (pow_ - 50.0) * 0.02


def dynamics(T, x, u, xcg, gust):
    """``SUBROUTINE F`` of Stevens & Lewis (2003), App. A, with the gust angles added to
    the aerodynamic alpha and beta."""
    vt = x[0]
    alpha = (x[1] + gust[0]) * RTOD
    beta = (x[2] + gust[1]) * RTOD
    phi, theta, psi, p, q, r = x[3], x[4], x[5], x[6], x[7], x[8]
    alt, power = x[11], x[12]
    thtl, el, ail, rdr = u
    amach, qbar = adc(vt, alt)
    xd = np.empty(13)
    xd[12] = pdot(power, tgear(thtl))
    t = thrust(T, power, alt, amach)
    dail, drdr = ail / 20.0, rdr / 30.0
    cxt = cx(T, alpha, el)
    cyt = cy(beta, ail, rdr)
    czt = cz(T, alpha, beta, el)
    clt = (
        _abs_beta_table(T.cl, alpha, beta)
        + _beta_table(T.dlda, alpha, beta) * dail
        + _beta_table(T.dldr, alpha, beta) * drdr
    )
    cmt = cm(T, alpha, el)
    cnt = (
        _abs_beta_table(T.cn, alpha, beta)
        + _beta_table(T.dnda, alpha, beta) * dail
        + _beta_table(T.dndr, alpha, beta) * drdr
    )
    tvt = 0.5 / vt
    b2v = T.b * tvt
    cq = T.cbar * q * tvt
    d = damp(T, alpha)
    cxt += cq * d[0]
    cyt += b2v * (d[1] * r + d[2] * p)
    czt += cq * d[3]
    clt += b2v * (d[4] * r + d[5] * p)
    cmt += cq * d[6] + czt * (T.xcgr - xcg)
    cnt += b2v * (d[7] * r + d[8] * p) - cyt * (T.xcgr - xcg) * T.cbar / T.b
    cbta = math.cos(x[2])
    u_ = vt * math.cos(x[1]) * cbta
    v_ = vt * math.sin(x[2])
    w_ = vt * math.sin(x[1]) * cbta
    sth, cth = math.sin(theta), math.cos(theta)
    sph, cph = math.sin(phi), math.cos(phi)
    spsi, cpsi = math.sin(psi), math.cos(psi)
    qs = qbar * T.s
    qsb = qs * T.b
    rm = 1.0 / T.mass
    gcth = T.g * cth
    qsph = q * sph
    udot = r * v_ - q * w_ - T.g * sth + rm * (qs * cxt + t)
    vdot = p * w_ - r * u_ + gcth * sph + rm * qs * cyt
    wdot = q * u_ - p * v_ + gcth * cph + rm * qs * czt
    dum = u_ * u_ + w_ * w_
    xd[0] = (u_ * udot + v_ * vdot + w_ * wdot) / vt
    xd[1] = (u_ * wdot - w_ * udot) / dum
    xd[2] = (vt * vdot - v_ * xd[0]) * cbta / dum
    xd[3] = p + (sth / cth) * (qsph + r * cph)
    xd[4] = q * cph - r * sph
    xd[5] = (qsph + r * cph) / cth
    gam = T.jxx * T.jzz - T.jxz**2
    xpq = T.jxz * (T.jxx - T.jyy + T.jzz)
    xqr = T.jzz * (T.jzz - T.jyy) + T.jxz**2
    zpq = (T.jxx - T.jyy) * T.jxx + T.jxz**2
    ypr = T.jzz - T.jxx
    roll, pitch, yaw = qsb * clt, qs * T.cbar * cmt, qsb * cnt
    pq, qr, qhx = p * q, q * r, q * T.hx
    xd[6] = (xpq * pq - xqr * qr + T.jzz * roll + T.jxz * (yaw + qhx)) / gam
    xd[7] = (ypr * p * r - T.jxz * (p * p - r * r) + pitch - r * T.hx) / T.jyy
    xd[8] = (zpq * pq - xpq * qr + T.jxz * roll + T.jxx * (yaw + qhx)) / gam
    t1, t2, t3 = sph * cpsi, cph * sth, sph * spsi
    s1, s2 = cth * cpsi, cth * spsi
    s3, s4 = t1 * sth - cph * spsi, t3 * sth + cph * cpsi
    s5, s6, s7, s8 = sph * cth, t2 * cpsi + t3, t1 - t2 * spsi, cph * cth
    xd[9] = u_ * s1 + v_ * s3 + w_ * s6
    xd[10] = u_ * s2 + v_ * s4 - w_ * s7
    xd[11] = u_ * sth - v_ * s5 - w_ * s8
    return xd


def rk4(T, x, u, xcg, gust, dt):
    k1 = dynamics(T, x, u, xcg, gust)
    k2 = dynamics(T, x + 0.5 * dt * k1, u, xcg, gust)
    k3 = dynamics(T, x + 0.5 * dt * k2, u, xcg, gust)
    k4 = dynamics(T, x + dt * k3, u, xcg, gust)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def fly(T, design: dict, x0, xcg, rng, noise=True):
    """One flight; ``design``: NumPy arrays ``K_lon`` (2, 8), ``K_lat`` (2, 5),
    ``x_ref`` (T, 13), ``u_ref`` (T, 4), ``u0`` (4,), ``H`` (m_r, 3), ``sigma`` (8 + m_r,),
    ``lower``/``upper`` (4,), ``gust_decay``, ``gust_std`` (per-step innovation), ``dt``.
    Returns the true states (T, 13) and the controls (T, 4)."""
    dt = design["dt"]
    H = design["H"]
    pinv = np.linalg.solve(H.T @ H, H.T)
    K_lon, K_lat = design["K_lon"], design["K_lat"]
    lon_idx, lat_idx = [0, 1, 4, 7, 11, 12], [2, 3, 6, 8]
    lower, upper = design["lower"], design["upper"]
    sigma = design["sigma"] if noise else np.zeros_like(design["sigma"])
    gust_std = design["gust_std"] if noise else 0.0
    x = np.array(x0, float)
    gust = np.zeros(2)
    z_lon, z_lat = np.zeros(2), np.zeros(1)
    steps = design["x_ref"].shape[0]
    states, controls = np.empty((steps, 13)), np.empty((steps, 4))
    for k in range(steps):
        # sensors
        y = np.concatenate(
            [x[[0, 1, 2, 3, 4, 5, 11, 12]], H @ x[6:9]]
        ) + sigma * rng.standard_normal(sigma.size)
        rates = pinv @ y[8:]
        x_lon = np.array([y[0], y[1], y[4], rates[1], y[6], y[7]])
        x_lat = np.array([y[2], y[3], rates[0], rates[2]])
        # controller
        x_ref, u_ref = design["x_ref"][k], design["u_ref"][k]
        d_lon = x_lon - x_ref[lon_idx]
        d_lat = x_lat - x_ref[lat_idx]
        u_lon = u_ref[[0, 1]] - K_lon @ np.concatenate([d_lon, z_lon])
        u_lat = u_ref[[2, 3]] - K_lat @ np.concatenate([d_lat, z_lat])
        wanted = np.array([u_lon[0], u_lon[1], u_lat[0], u_lat[1]])
        u = np.clip(wanted, lower, upper)
        if wanted[0] == u[0] and wanted[1] == u[1]:
            z_lon = z_lon - dt * d_lon[[0, 4]]
        if wanted[2] == u[2] and wanted[3] == u[3]:
            z_lat = z_lat - dt * d_lat[[1]]
        states[k], controls[k] = x, u
        # plant
        x = rk4(T, x, np.clip(u, lower, upper), xcg, gust / x[0], dt)
        gust = design["gust_decay"] * gust + gust_std * rng.standard_normal(2)
    return states, controls
