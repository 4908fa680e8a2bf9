"""Robust implicit return of one stress point (compiled): the reference algorithm of the return.

Backward Euler in principal space on sorted trial principal stresses ``s1 >= s2 >= s3`` (Pa)
with ``F > 0``: the root in the return parameter ``t = 3 mu dlambda w/g`` of the decreasing
``Phi(t) = F(p(t), q(t), Theta(t))``, with the deviatoric maximisation
``q(t) = max_Theta [q_tr cos(Theta - Theta_tr) - t R_mw(Theta)]`` inside, both by safeguarded
Newton with bisection fallback, and the returns to the apex ``s_i = c cot(phi)``
(:func:`_return_sorted`; the algorithm is described in
:func:`fipy_hopper.material.return_reference.update_reference`, its numpy twin).  Also holds the
residuals of those solves, shared with the numpy reference (on arrays) and compiled here
(``*_nb``, on floats), and the solve tolerances.
"""

from __future__ import annotations

import math

import numpy as np

from .mohr_coulomb import (APEX, PI3, PLASTIC, SQRT3, TWO_PI3, _jit, _mc_radius_nb, _mw_radius_nb,
                           _unpack)

_MAXIT = 100  # iteration cap of every scalar solve (bisection fallback makes each one terminate)
_TOL_THETA = 1e-14  # absolute tolerance on angles (rad)
_STEP_THETA = 1e-8  # a Newton step on an angle this small has converged (error ~ 1e-16)
_TOL_T = 1e-15  # tolerance on the return parameter t, relative to its upper bound t*
_TIP_TOL = 1e-6  # largest accepted round-off error estimate of a return into the tip of G (a > 0)


# ---------------------------------------------------------------------------------------------
# Residuals of the return, shared by the numpy reference (on arrays) and the kernel (on floats)
# ---------------------------------------------------------------------------------------------
def _theta_c_residual(theta, theta_tr, r, r1, r2):
    """f = Theta_tr - nu(Theta) and df/dTheta, nu = Theta + atan(r'/r) the polar angle of grad(R_mw q).

    nu increases monotonically (convex section), so f decreases; its root Theta_c is the Lode angle
    at which the normal of G is parallel to the trial deviator.  (r, r1, r2) = r_MW and derivatives.
    """
    return theta_tr - theta - np.arctan(r1 / r), -r * (r + r2) / (r * r + r1 * r1)


def _inner_residual(theta, t, rho_tr, theta_tr, rc3, r, r1, r2):
    """rho(Theta) = rho_tr cos(Theta - Theta_tr) - t R_mw(Theta): returns rho', rho'' and rho."""
    d = theta - theta_tr
    cd = np.cos(d)
    return -rho_tr * np.sin(d) - t * rc3 * r1, -rho_tr * cd - t * rc3 * r2, rho_tr * cd - t * rc3 * r


def _outer_residual(t, theta, rho_tr, theta_tr, p_tr, K, mu, tan_phi, tan_psi, c, a, rc3, mw, mc):
    """Phi(t) = F at the return point of parameter t, dPhi/dt, and the point's p, rho, dTheta/dt.

    Theta must maximise rho(Theta) (the inner solve); mw = (r, r', r'') of _mw_radius and
    mc = (R_mc, R_mc') of _mc_radius at Theta.  With w = R_mw rho and g = sqrt(a^2 + w^2):
    dlambda = t g / (3 mu w), p = p_tr + K tan(psi) dlambda, Phi = R_mc rho - p tan(phi) - c.
    Derivatives: d rho/dt = -R_mw (envelope theorem), dTheta/dt = -R'/(rho + t (R + R'')).
    Valid for rho > 0 only (the caller checks).
    """
    r, r1, r2 = mw
    Rm, Rm1 = mc
    R = rc3 * r
    R1 = rc3 * r1
    R2 = rc3 * r2
    rho = rho_tr * np.cos(theta - theta_tr) - t * R
    w = R * rho
    g = np.hypot(a, w)
    gw = g / w
    p = p_tr + K * tan_psi * t * gw / (3.0 * mu)
    phi_t = Rm * rho - p * tan_phi - c
    dth = -R1 / (rho + t * (R + R2))
    w1 = R1 * dth * rho - R * R
    dlam1 = (gw - (t / w) * (w1 / w) * (a / g) * a) / (3.0 * mu)  # t w1 a^2/(g w^2), no overflow
    dphi_t = Rm1 * rho * dth - Rm * R - tan_phi * K * tan_psi * dlam1
    return phi_t, dphi_t, p, rho, dth


def _tip_error(p, p_tr, pa, rho, rho_tr, a, R):
    """Round-off estimate of the relative error of pa = p + c cot(phi) after a return into the
    rounded tip of G (a > 0): eps (rho_tr/rho) (|p - p_tr|/pa) a^2/(a^2 + (R rho)^2).

    In the tip, dlambda = t g/(3 mu w) depends on w = R rho, which the return resolves only to
    eps rho_tr (rho is a difference of quantities of size rho_tr); p - p_tr = K tan(psi) dlambda
    carries that error into pa.  (Zero for a = 0: then p does not depend on rho.)
    """
    ag = a / np.hypot(a, R * rho)
    return 2.220446049250313e-16 * (rho_tr / rho) * (np.abs(p - p_tr) / pa) * ag * ag


_theta_c_residual_nb = _jit(_theta_c_residual)
_inner_residual_nb = _jit(_inner_residual)
_outer_residual_nb = _jit(_outer_residual)
_tip_error_nb = _jit(_tip_error)


# ---------------------------------------------------------------------------------------------
# Return mapping, compiled kernel (one point at a time)
# ---------------------------------------------------------------------------------------------
@_jit
def _bracket_step(x, f, df, lo, hi, tol, step_tol):
    """One safeguarded Newton step for a decreasing f with f(lo) >= 0 >= f(hi).

    Updates the bracket from the sign of f; converged if f == 0 or the Newton step is <= step_tol
    (quadratic convergence: the error after it is ~ step_tol^2; the result is kept in the
    bracket); takes the Newton step if it stays strictly inside the bracket, else bisects
    (converged when the bracket is <= tol).  Returns (x_new, lo, hi, converged).
    """
    if f > 0.0:
        lo = x
    elif f < 0.0:
        hi = x
    else:
        return x, lo, hi, True
    if df < 0.0:
        xn = x - f / df
        if abs(xn - x) <= step_tol:
            return min(max(xn, lo), hi), lo, hi, True
        if lo < xn < hi:
            return xn, lo, hi, False
    return 0.5 * (lo + hi), lo, hi, hi - lo <= tol


@_jit
def _solve_theta_c(theta_tr, e):
    """Root Theta_c in [Theta_tr, pi/3] of Theta_tr - nu(Theta) (see :func:`_theta_c_residual`)."""
    lo, hi, th = theta_tr, PI3, theta_tr
    for _ in range(_MAXIT):
        r, r1, r2 = _mw_radius_nb(th, e)
        f, df = _theta_c_residual_nb(th, theta_tr, r, r1, r2)
        th, lo, hi, done = _bracket_step(th, f, df, lo, hi, _TOL_THETA, _STEP_THETA)
        if done:
            break
    return th


@_jit
def _solve_inner(t, th, rho_tr, theta_tr, hi, e, rc3):
    """Maximiser of rho(Theta) on [Theta_tr, hi], and whether every evaluated rho was positive.

    rho is strictly concave where positive; the sign of rho' locates the maximiser wherever
    rho > 0, and on [Theta_tr, Theta_c] everywhere (rho' >= 0 where rho <= 0 there).
    """
    lo = theta_tr
    if not hi > lo:
        return lo, True
    th = min(max(th, lo), hi)
    clean = True
    for _ in range(_MAXIT):
        r, r1, r2 = _mw_radius_nb(th, e)
        f, df, rho = _inner_residual_nb(th, t, rho_tr, theta_tr, rc3, r, r1, r2)
        clean = clean and rho > 0.0
        th, lo, hi, done = _bracket_step(th, f, df, lo, hi, _TOL_THETA, _STEP_THETA)
        if done:
            break
    return th, clean


@_jit
def _solve_outer(p_tr, rho_tr, th_tr, th_hi, t_lo, t_hi, th0, strict, prm):
    """Root of Phi(t) on [t_lo, t_hi] (Phi(t_lo) >= 0) with the inner maximisation on
    [Theta_tr, th_hi], starting from t_lo with the angle guess th0.

    Returns (ok, p, Theta, rho) with rho from the inner solve.  ``strict``: give up (ok False) as
    soon as a non-positive rho is met (the fast bracket Theta <= pi/3, t <= q_tr/R_mc(pi/3) is then
    not trustworthy); otherwise a collapsed deviator means t >= t* (Phi < 0 there when a > 0).
    The inner solve is warm-started with the first-order prediction Theta + dTheta/dt dt.
    """
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    lo, hi, t, t_prev = t_lo, t_hi, t_lo, t_lo
    th, dth, p, ok, rho_in = th0, 0.0, p_tr, False, 0.0
    for _ in range(_MAXIT):
        th, clean = _solve_inner(t, th + dth * (t - t_prev), rho_tr, th_tr, th_hi, e, rc3)
        f, df, p_k, rho, dth = _outer_residual_nb(t, th, rho_tr, th_tr, p_tr, K, mu, tp, tpsi, c, a,
                                                  rc3, _mw_radius_nb(th, e), _mc_radius_nb(th, sp, cp))
        ok = rho > 0.0
        if strict and not (ok and clean):
            return False, p, th, rho_in
        if ok:
            p, rho_in = p_k, rho
        else:
            f, df, dth = -1.0, 0.0, 0.0
        t_prev = t
        t, lo, hi, done = _bracket_step(t, f, df, lo, hi, _TOL_T * t_hi, _TOL_T * t_hi)
        if done:
            return ok, p, th, rho_in
    return ok and not strict, p, th, rho_in


@_jit
def _return_sorted(s1, s2, s3, prm):
    """Backward-Euler return of sorted trial principal stresses with F > 0 (see update_reference).

    Returns the returned sorted principal stresses and the status (PLASTIC or APEX).
    """
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    apex = c / tp
    rmc0 = (3.0 + sp) / (6.0 * cp)  # max R_mc (extension meridian)
    p_tr = -(s1 + s2 + s3) / 3.0
    x = s1 - 0.5 * (s2 + s3)
    y = 0.5 * SQRT3 * (s2 - s3)
    rho_tr = math.hypot(x, y)
    if not rho_tr > 0.0:
        return apex, apex, apex, APEX
    th_tr = min(math.atan2(y, x), PI3)
    t_ub = rho_tr / rc3
    f_apex = -p_tr * tp - c  # Phi(t) = f_apex - slope t once the deviator has collapsed (a = 0)
    slope = K * tpsi * tp / (3.0 * mu)
    if a == 0.0 and f_apex - slope * t_ub >= 0.0:
        return apex, apex, apex, APEX
    ok, p, th, rho_in = False, p_tr, th_tr, 0.0
    if f_apex < 0.0:  # p_tr > -c cot(phi): a regular return exists, try the fast bracket
        ok, p, th, rho_in = _solve_outer(p_tr, rho_tr, th_tr, PI3, 0.0, t_ub, th_tr, True, prm)
    if not ok:
        th_c = _solve_theta_c(th_tr, e)
        r_c = rc3 * _mw_radius_nb(th_c, e)[0]
        t_star = rho_tr * math.cos(th_c - th_tr) / r_c
        if a == 0.0 and f_apex - slope * t_star >= 0.0:
            return apex, apex, apex, APEX
        t_lo, th0 = 0.0, th_tr
        t_a = t_star - a / (r_c * r_c)  # about where the return enters the tip of G, R_mw q = a
        if a > 0.0 and t_a > 0.0:
            th_a = _solve_inner(t_a, th_c, rho_tr, th_tr, th_c, e, rc3)[0]
            f, df, p_a, rho_a, dth = _outer_residual_nb(t_a, th_a, rho_tr, th_tr, p_tr, K, mu, tp,
                                                        tpsi, c, a, rc3, _mw_radius_nb(th_a, e),
                                                        _mc_radius_nb(th_a, sp, cp))
            if rho_a > 0.0 and f > 0.0:  # the root lies deeper in the tip, where the error is larger
                if not _tip_error_nb(p_a, p_tr, rmc0 * rho_a / tp, rho_a, rho_tr, a,
                                     rc3 * _mw_radius_nb(th_a, e)[0]) <= _TIP_TOL:
                    return apex, apex, apex, APEX
                t_lo, th0 = t_a, th_a
        ok, p, th, rho_in = _solve_outer(p_tr, rho_tr, th_tr, th_c, t_lo, t_star, th0, False, prm)
    rho = (p * tp + c) / _mc_radius_nb(th, sp, cp)[0]  # land exactly on F = 0 at (p, Theta)
    if not (ok and rho > 0.0):
        return apex, apex, apex, APEX
    if a > 0.0 and not _tip_error_nb(p, p_tr, p + apex, rho_in, rho_tr, a,
                                     rc3 * _mw_radius_nb(th, e)[0]) <= _TIP_TOL:
        return apex, apex, apex, APEX
    k = 2.0 / 3.0 * rho
    return (-p + k * math.cos(th), -p + k * math.cos(th - TWO_PI3), -p + k * math.cos(th + TWO_PI3),
            PLASTIC)
