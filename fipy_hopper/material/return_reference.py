"""Plain-numpy reference of the stress update: :func:`update_reference`.

The algorithm of :func:`fipy_hopper.material.return_robust._return_sorted` vectorised over the
points (no per-point loops), with the same elastic predictor, residuals and tolerances; the
compiled :func:`fipy_hopper.material.update` is held to it.  Stresses in Pa, tension positive;
strains with the tensor shear component.
"""

from __future__ import annotations

import math

import numpy as np

from .mohr_coulomb import (APEX, ELASTIC, PI3, PLASTIC, TWO_PI3, MohrCoulomb, _elastic_trial,
                           _inplane, _lode, _mc_radius, _mw_radius, _rebuild, _sort3, _unsort3,
                           plastic_strain_from_stress)
from .return_fast import _as_points
from .return_robust import (_MAXIT, _STEP_THETA, _TIP_TOL, _TOL_T, _TOL_THETA, _inner_residual,
                            _outer_residual, _theta_c_residual, _tip_error)

__all__ = ["update_reference"]


# ---------------------------------------------------------------------------------------------
# Return mapping, numpy reference (same algorithm, vectorised over points, no per-point loops)
# ---------------------------------------------------------------------------------------------
def _bracket_step_vec(x, f, df, lo, hi, tol, step_tol):
    """Vectorised :func:`_bracket_step` (same rules, elementwise)."""
    lo = np.where(f > 0.0, x, lo)
    hi = np.where(f < 0.0, x, hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = x - f / df
    newton = df < 0.0
    small = newton & (np.abs(xn - x) <= step_tol)
    inside = newton & (lo < xn) & (xn < hi)
    zero = f == 0.0
    x_new = np.where(inside, xn, np.where(small, np.clip(xn, lo, hi), 0.5 * (lo + hi)))
    x_new = np.where(zero, x, x_new)
    done = zero | small | (~inside & (hi - lo <= tol))
    return x_new, lo, hi, done


def _solve_theta_c_vec(theta_tr, e):
    """Vectorised :func:`_solve_theta_c`."""
    th, lo, hi = theta_tr.copy(), theta_tr.copy(), np.full(theta_tr.shape, PI3)
    act = np.arange(th.size)
    for _ in range(_MAXIT):
        if act.size == 0:
            break
        x = th[act]
        f, df = _theta_c_residual(x, theta_tr[act], *_mw_radius(x, e))
        th[act], lo[act], hi[act], done = _bracket_step_vec(x, f, df, lo[act], hi[act], _TOL_THETA,
                                                                   _STEP_THETA)
        act = act[~done]
    return th


def _solve_inner_vec(t, th0, rho_tr, theta_tr, hi, e, rc3):
    """Vectorised :func:`_solve_inner`."""
    lo, hi = theta_tr.copy(), hi.copy()
    th = np.where(hi > lo, np.minimum(np.maximum(th0, lo), hi), lo)
    clean = np.ones(th.size, dtype=bool)
    act = np.nonzero(hi > lo)[0]
    for _ in range(_MAXIT):
        if act.size == 0:
            break
        x = th[act]
        f, df, rho = _inner_residual(x, t[act], rho_tr[act], theta_tr[act], rc3, *_mw_radius(x, e))
        clean[act] &= rho > 0.0
        th[act], lo[act], hi[act], done = _bracket_step_vec(x, f, df, lo[act], hi[act], _TOL_THETA,
                                                                   _STEP_THETA)
        act = act[~done]
    return th, clean


def _solve_outer_vec(p_tr, rho_tr, th_tr, th_hi, t_lo, t_hi, th0, strict, prm):
    """Vectorised :func:`_solve_outer`: returns (ok, p, Theta, rho) arrays."""
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = prm
    n = p_tr.size
    lo, hi, t, t_prev = t_lo.copy(), t_hi.copy(), t_lo.copy(), t_lo.copy()
    th, dth, p, rho_in = th0.copy(), np.zeros(n), p_tr.copy(), np.zeros(n)
    ok, finished = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    act = np.arange(n)
    for _ in range(_MAXIT):
        if act.size == 0:
            break
        ta = t[act]
        tha, clean = _solve_inner_vec(ta, th[act] + dth[act] * (ta - t_prev[act]), rho_tr[act],
                                      th_tr[act], th_hi[act], e, rc3)
        with np.errstate(divide="ignore", invalid="ignore"):
            f, df, pk, rho, dthk = _outer_residual(ta, tha, rho_tr[act], th_tr[act], p_tr[act], K, mu,
                                                   tp, tpsi, c, a, rc3, _mw_radius(tha, e),
                                                   _mc_radius(tha, sp, cp))
        oka = rho > 0.0
        th[act], ok[act] = tha, oka
        p[act] = np.where(oka, pk, p[act])
        rho_in[act] = np.where(oka, rho, rho_in[act])
        dth[act] = np.where(oka, dthk, 0.0)
        t_prev[act] = ta
        t[act], lo[act], hi[act], done = _bracket_step_vec(ta, np.where(oka, f, -1.0),
                                                           np.where(oka, df, 0.0), lo[act], hi[act],
                                                           _TOL_T * t_hi[act], _TOL_T * t_hi[act])
        finished[act] = done
        if strict:
            bad = ~(oka & clean)
            ok[act[bad]], finished[act[bad]] = False, True
            done = done | bad
        act = act[~done]
    return ok & (finished | (not strict)), p, th, rho_in


def _return_sorted_vec(s1, s2, s3, prm):
    """Vectorised :func:`_return_sorted`: returned sorted principal stresses and status."""
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = prm
    apex = c / tp
    rmc0 = (3.0 + sp) / (6.0 * cp)
    p_tr = -(s1 + s2 + s3) / 3.0
    rho_tr, th_tr = _lode(s1, s2, s3)
    t_ub = rho_tr / rc3
    f_apex = -p_tr * tp - c
    slope = K * tpsi * tp / (3.0 * mu)
    is_apex = ~(rho_tr > 0.0)
    if a == 0.0:
        is_apex |= f_apex - slope * t_ub >= 0.0
    n = s1.size
    ok, p, th, rho_in = np.zeros(n, dtype=bool), p_tr.copy(), th_tr.copy(), np.zeros(n)

    def attempt(idx, th_hi, t_lo, t_hi, th0, strict):
        ok[idx], p[idx], th[idx], rho_in[idx] = _solve_outer_vec(p_tr[idx], rho_tr[idx], th_tr[idx],
                                                                 th_hi, t_lo, t_hi, th0, strict, prm)

    idx = np.nonzero(~is_apex & (f_apex < 0.0))[0]  # a regular return exists: fast bracket
    attempt(idx, np.full(idx.size, PI3), np.zeros(idx.size), t_ub[idx], th_tr[idx], True)
    idx = np.nonzero(~is_apex & ~ok)[0]
    th_c = _solve_theta_c_vec(th_tr[idx], e)
    r_c = rc3 * _mw_radius(th_c, e)[0]
    t_star = rho_tr[idx] * np.cos(th_c - th_tr[idx]) / r_c
    t_lo, th0 = np.zeros(idx.size), th_tr[idx].copy()
    if a == 0.0:
        collapsed = f_apex[idx] - slope * t_star >= 0.0
    else:  # the tip shortcut of _return_sorted
        t_a = t_star - a / (r_c * r_c)
        j = np.nonzero(t_a > 0.0)[0]
        th_a = _solve_inner_vec(t_a[j], th_c[j], rho_tr[idx[j]], th_tr[idx[j]], th_c[j], e, rc3)[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            f, _, p_a, rho_a, _ = _outer_residual(t_a[j], th_a, rho_tr[idx[j]], th_tr[idx[j]],
                                                  p_tr[idx[j]], K, mu, tp, tpsi, c, a, rc3,
                                                  _mw_radius(th_a, e), _mc_radius(th_a, sp, cp))
            deeper = (rho_a > 0.0) & (f > 0.0)
            err = _tip_error(p_a, p_tr[idx[j]], rmc0 * rho_a / tp, rho_a, rho_tr[idx[j]], a,
                             rc3 * _mw_radius(th_a, e)[0])
        collapsed = np.zeros(idx.size, dtype=bool)
        collapsed[j] = deeper & ~(err <= _TIP_TOL)
        t_lo[j] = np.where(deeper, t_a[j], 0.0)
        th0[j] = np.where(deeper, th_a, th0[j])
    is_apex[idx[collapsed]] = True
    keep = ~collapsed
    attempt(idx[keep], th_c[keep], t_lo[keep], t_star[keep], th0[keep], False)
    rho = (p * tp + c) / _mc_radius(th, sp, cp)[0]  # land exactly on F = 0 at (p, Theta)
    ok &= ~is_apex & (rho > 0.0)
    if a > 0.0:
        with np.errstate(divide="ignore", invalid="ignore"):
            err = _tip_error(p, p_tr, p + apex, rho_in, rho_tr, a, rc3 * _mw_radius(th, e)[0])
        ok &= err <= _TIP_TOL
    k = 2.0 / 3.0 * rho
    out = [np.where(ok, -p + k * np.cos(th - al), apex) for al in (0.0, TWO_PI3, -TWO_PI3)]
    return out[0], out[1], out[2], np.where(ok, PLASTIC, APEX).astype(np.int8)


def update_reference(sigma, d_eps, mat: MohrCoulomb, return_status: bool = False):
    """Plain-numpy reference of :func:`update` (same inputs, outputs and algorithm; slow).

    Algorithm (backward Euler in principal space; sigma_tt is principal and the (rr, zz, rz) block
    has closed-form eigenvalues and angle):

    1. Trial sigma_tr = sigma + C d_eps; sorted principal s1 >= s2 >= s3; F_tr from the linear form.
       F_tr <= 0: elastic, sigma_new = sigma_tr exactly, d_eps_plastic = 0.
    2. F and G are isotropic, so the return is coaxial with the trial and keeps the order of the
       principal stresses (G is smooth and convex: no corner of the hexagon is ever reached).  In the
       deviatoric plane use X = q (cos Theta, sin Theta) = (s.c0, s.c1), |c0|^2 = |c1|^2 = 3/2; the
       return s = s_tr - dlambda D dG/ds reads X = X_tr - 3 mu dlambda grad g(X) and
       p = p_tr + K tan(psi) dlambda, with g = sqrt(a^2 + w^2), w = R_mw(Theta) q, a = eps c tan(psi).
       With t = 3 mu dlambda w/g the deviatoric part is the proximal point of the convex gauge w,
       X_tr = X + t grad w(X), i.e. q(t) = max_Theta [q_tr cos(Theta - Theta_tr) - t R_mw(Theta)]:
       q is strictly concave in Theta where positive, its maximiser Theta(t) lies in
       [Theta_tr, Theta_c] (Theta_c: where the normal of G is parallel to X_tr), and q collapses to 0
       at t* = q_tr cos(Theta_c - Theta_tr) / R_mw(Theta_c).  The return is the root of the strictly
       decreasing scalar Phi(t) = F(p(t), q(t), Theta(t)) (dlambda = t g/(3 mu w)).
    3. Solves: safeguarded Newton with bisection fallback for the root in t and, at each t, for the
       maximiser Theta(t) (warm-started with dTheta/dt): every solve terminates, none can diverge.
       When p_tr > -c cot(phi) a root exists; it is first sought in the cheap bracket
       Theta <= pi/3, t <= q_tr/R_mw(pi/3) (valid while every evaluated q is positive), else, with
       Theta_c and t*, in the exact bracket.  Tolerances: 1e-14 rad (Newton steps below 1e-8 rad,
       quadratically converged) and 1e-15 t*.
    4. Apex.  a = 0 (c = 0 or psi = 0): G has a vertex; if Phi(t*) >= 0 the deviator collapses
       before F = 0 is reached and the stress returns to the apex s_i = c cot(phi) (exactly zero for
       c = 0).  d_eps_plastic is then in the normal cone of G at its vertex for psi > 0; for psi = 0
       with p_tr < -c cot(phi) (beyond the apex: no backward-Euler solution exists) it is the
       admissible fallback, with plastic volume change.  a > 0: G is smooth and Phi -> -inf at t*,
       so a return exists, but inside the rounded tip of G (R_mw q < a) dlambda ~ t a/(3 mu w)
       depends on q, which the return resolves only to eps q_tr: the result is ill-conditioned,
       with relative error ~ eps (q_tr/q)(|p - p_tr|/(p + c cot(phi))).  Where that estimate
       exceeds 1e-6 the stress goes to the apex (status APEX), an error no larger than the tip of G
       (q < a / R_mw, p + c cot(phi) ~ a / tan(phi)); a bound of the estimate at the tip entry
       t* - a / R_mw(Theta_c)^2 decides this before the (then slow) solve when it can.  At the
       apex d_eps_plastic is not parallel to dG/dsigma = tan(psi)/3 I.
    5. q is set from F = 0 at the converged (p, Theta), the principal stresses are rebuilt on the
       trial axes, and d_eps_plastic = C^-1 (sigma_tr - sigma_new) = dlambda dG/dsigma at the
       returned stress (except at the apex).

    The compiled :func:`update` solves most regular returns another way (:func:`_fast_block`,
    faster and to the same solution, which is unique) and this algorithm for the rest.

    Why not the fixed point on the flow direction (n_k = dG/ds(s_k), dlambda = F_tr/(a.D n_k)):
    its contraction factor grows with the size of the return (~ (q_tr - q)/q times the curvature of
    the section); on random states with strain increments of 1e-4 to 1e-2 (E = 10 MPa) it failed to
    converge in 50 iterations for 25-80 % of the regular returns and broke the principal order in
    10-30 %, whereas the increments of an explicit hopper step reach 1e-3.
    """
    sig, dep, shape = _as_points(sigma, d_eps)
    lam, mu = mat.lame_lambda, mat.shear_modulus
    trial = np.stack(_elastic_trial(*sig.T, *dep.T, lam, mu), axis=-1)
    la, lb, cos2w, sin2w = _inplane(trial)
    s1, s2, s3, pos = _sort3(la, lb, trial[:, 2])
    f = ((s1 - s3) + (s1 + s3) * math.sin(mat.phi_rad)) / (2.0 * math.cos(mat.phi_rad)) - mat.c
    pl = np.nonzero(f > 0.0)[0]
    out = trial.copy()
    status = np.full(trial.shape[0], ELASTIC, dtype=np.int8)
    n1, n2, n3, status[pl] = _return_sorted_vec(s1[pl], s2[pl], s3[pl], mat.kernel_parameters())
    na, nb, ntt = _unsort3(n1, n2, n3, pos[pl])
    out[pl] = _rebuild(na, nb, ntt, cos2w[pl], sin2w[pl])
    d_eps_p = np.zeros_like(trial)
    d_eps_p[pl] = plastic_strain_from_stress(trial[pl] - out[pl], mat)
    res = (out.reshape(shape + (4,)), d_eps_p.reshape(shape + (4,)))
    return res + (status.reshape(shape),) if return_status else res
