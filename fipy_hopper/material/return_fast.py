"""The stress update :func:`update` (numba): elastic predictor and implicit return, in blocks.

sigma_new = sigma_tr - dlambda D dG/dsigma with F(sigma_new) = 0 (backward Euler; stresses in Pa,
tension positive, strains with the tensor shear component).  The plastic points of a block are
first returned by a faster solve of the same equations, one scalar equation in the Lode angle
iterated for the whole block at once (:func:`_fast_block`); every point it does not accept goes
to the robust return :func:`fipy_hopper.material.return_robust._return_sorted`.
"""

from __future__ import annotations

import math

import numpy as np

from .mohr_coulomb import (ELASTIC, PLASTIC, SQRT3, MohrCoulomb, _compliance_nb,
                           _elastic_trial_nb, _jit, _jit_inline, _radius_nb, _rebuild_inplane_nb,
                           _unpack)
from .return_robust import _TIP_TOL, _TOL_THETA, _return_sorted

__all__ = ["update"]


# ---------------------------------------------------------------------------------------------
# Return mapping, compiled fast path (one scalar equation in the Lode angle, solved in lockstep)
# ---------------------------------------------------------------------------------------------
_BLOCK = 512  # points per block of the kernel; the fast returns of a block iterate in lockstep
_FAST_MAXIT = 16  # sweeps of the fast solve before the points still open go to _return_sorted
_FAST_STEP = 1e-6  # a Halley step in tau this small has converged (the final test checks it)
_FAST_INNER = 2  # Newton steps of the multiplier at a fixed angle (a > 0 only)
_FAST_QMIN = 1e-6  # the fast path accepts a return only if q >= _FAST_QMIN q_tr (else: robust)
_FAST_TIP = 1e-2 * _TIP_TOL  # ... and, for a > 0, a tip error estimate this far below _TIP_TOL
# rows of the per-block work array of the fast path
_W_PTR, _W_QTR, _W_CT, _W_ST, _W_F = 0, 1, 2, 3, 4  # p_tr, q_tr, trial direction, F_tr
_W_TAU, _W_LO, _W_HI = 5, 6, 7  # iterate tau = tan(Theta - Theta_tr) and its bracket
_W_N1, _W_N2, _W_N3 = 8, 9, 10  # the returned sorted principal stresses
_W_GATHERED = 11  # 11-17: the points still open, gathered (rows as _W_QTR ... _W_HI)
_W_ROWS = 18
_F_VALID, _F_DONE, _F_OK, _F_GATHERED = 0, 1, 2, 3  # rows of the per-block flags
_F_ROWS = 4


@_jit
def _fast_constants(prm):
    """Per-material constants of the fast path: (1 - e^2, 2e - 1, 5e^2 - 4e, R_mc(pi/3), the
    gradient (alpha_x, alpha_y) of the linear R_mc q in X, K tan(psi)/(3 mu), tan phi, c, a)."""
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    return (1.0 - e * e, 2.0 * e - 1.0, 5.0 * e * e - 4.0 * e, rc3, (3.0 + sp) / (6.0 * cp),
            (1.0 - sp) / (2.0 * SQRT3 * cp), K * tpsi / (3.0 * mu), tp, c, a)


@_jit_inline
def _mw_cs(C, S, A, B, E5):
    """r_MW and its first three Theta-derivatives from C = cos(Theta), S = sin(Theta) (as
    :func:`_mw_radius` with A = 1 - e^2, B = 2e - 1, E5 = 5e^2 - 4e, without trigonometric
    functions): r = N/D with N = 4AC^2 + B^2, D = 2AC + B s, s = sqrt(4AC^2 + E5), differentiated
    in C through r D = N, then in Theta (dC/dTheta = -S)."""
    s2 = max(4.0 * A * C * C + E5, B * B)
    s = math.sqrt(abs(s2))  # abs: provably >= 0, so LLVM emits (vector) sqrt
    i_s = 1.0 / s
    i_den = 1.0 / (2.0 * A * C + B * s)
    r = (4.0 * A * C * C + B * B) * i_den
    s_C = 4.0 * A * C * i_s
    s_CC = 4.0 * A * E5 * i_s * i_s * i_s
    den_C = 2.0 * A + B * s_C
    r_C = (8.0 * A * C - r * den_C) * i_den
    r_CC = (8.0 * A - 2.0 * r_C * den_C - r * B * s_CC) * i_den
    r_CCC = -(3.0 * r_CC * den_C + 3.0 * r_C * B * s_CC - r * B * 3.0 * s_CC * s_C * i_s) * i_den
    return (r, -S * r_C, S * S * r_CC - C * r_C,
            S * (r_C + 3.0 * C * r_CC - S * S * r_CCC))


@_jit_inline
def _fast_multiplier(t, f_tr, qc, Y, R, R1, An, An1, kap, a):
    """Return parameter t at a fixed Lode angle for a > 0, with its Theta-derivative.

    t solves phi(t) = t (An + kap gamma) - F_tr = 0, gamma = g/w = sqrt(1 + (a/(R q))^2),
    q = qc - t R (F = 0 at the point X_tr - t dw/dX of the angle).  phi is convex and increasing
    on [0, qc/R) (gamma -> inf as q -> 0) and phi >= 0 at the a = 0 value t given, so Newton's
    iterates from there decrease monotonically to the root: _FAST_INNER steps, ok if the last
    was below 1e-9 t (and the start lay below qc/R).
    Returns (t, dt/dTheta, P = t gamma, dP/dTheta, ok).
    """
    ok = t < qc / R
    step = 0.0
    for _ in range(_FAST_INNER):
        q = qc - t * R
        z = a / (R * q)
        z2 = z * z
        gam = math.sqrt(1.0 + z2)
        step = (t * (An + kap * gam) - f_tr) / (An + kap * gam + t * kap * z2 * R / (gam * q))
        t -= step
    q = qc - t * R
    z = a / (R * q)
    z2 = z * z
    gam = math.sqrt(1.0 + z2)
    dg_t = z2 * R / (gam * q)  # d gamma/dt at a fixed angle
    dg_th = -z2 / (gam * R * q) * (R1 * q + R * (Y - t * R1))  # d gamma/dTheta at a fixed t
    t1 = -t * (An1 + kap * dg_th) / (An + kap * gam + t * kap * dg_t)
    ok = ok & (abs(step) <= 1e-9 * t) & (q > 0.0)
    return t, t1, t * gam, t1 * gam + t * (dg_th + dg_t * t1), ok


@_jit_inline
def _fast_eval(tau, q_tr, ct, st, f_tr, cst, hyperbolic):
    """Residual of the fast return at tau = tan(Theta - Theta_tr) (see :func:`_fast_block`).

    Returns (h, dh/dTheta, d2h/dTheta2, 1 + tau^2, P, dP/dTheta, q_dev, R_mw, ok) with
    P = 3 mu dlambda, so p = p_tr + K tan(psi) P/(3 mu), q_dev = X.e_r the deviator's length and ok
    False if the multiplier did not converge.  hyperbolic: a > 0 (a compile-time constant of the
    loops, so that the cone's loops carry no multiplier solve); then d2h/dTheta2 neglects the
    second derivative of gamma = g/w (about 1 outside the tip of G), which only affects the speed
    of the Halley iteration.
    """
    A, B, E5, rc3, ax, ay, kp, tp, c, a = cst
    kap = kp * tp
    w2 = 1.0 + tau * tau
    iw = 1.0 / math.sqrt(w2)
    C = (ct - tau * st) * iw
    S = (st + tau * ct) * iw
    qc = q_tr * iw  # X_tr.e_r
    Y = -tau * qc  # X_tr.e_Theta
    r, r1, r2, r3 = _mw_cs(C, S, A, B, E5)
    R = rc3 * r
    R1 = rc3 * r1
    R2 = rc3 * r2
    R3 = rc3 * r3
    Rm = ax * C + ay * S  # R_mc = alpha.e_r (R_mc'' = -R_mc)
    Rm1 = ay * C - ax * S  # R_mc'
    An = R * Rm + R1 * Rm1  # alpha.n
    An1 = Rm1 * (R + R2)  # d(alpha.n)/dTheta
    An2 = Rm1 * (R1 + R3) - Rm * (R + R2)
    i_d = 1.0 / (An + kap)
    t = f_tr * i_d
    if hyperbolic:
        t, t1, P, P1, ok = _fast_multiplier(t, f_tr, qc, Y, R, R1, An, An1, kap, a)
        i_d = t / f_tr  # 1/(alpha.n + kap gamma)
    else:
        t1 = -t * An1 * i_d
        P, P1, ok = t, t1, True
    t2 = -(2.0 * t1 * An1 + t * An2) * i_d  # from t D = F_tr (gamma frozen if hyperbolic)
    h = Y - t * R1
    h1 = -qc - t1 * R1 - t * R2
    h2 = -Y - t2 * R1 - 2.0 * t1 * R2 - t * R3
    return h, h1, h2, w2, P, P1, qc - t * R, R, ok


@_jit
def _fast_block(m, S, W, flags, cst):
    """Fast implicit return of the m sorted trial stresses S[0:3, :m] with F_tr = S[3, :m] > 0.

    In the deviatoric plane X = q (cos Theta, sin Theta) the return is X = X_tr - t n(Theta),
    n = grad(R_mw q) = R e_r + R' e_Theta, t = 3 mu dlambda w/g (= 3 mu dlambda for a = 0), and F is
    linear: F = alpha.X - p tan(phi) - c with alpha.e_r = R_mc.  Given Theta, F = 0 fixes t: for
    a = 0 (psi = 0 or c = 0) t = F_tr/(alpha.n + K tan(psi) tan(phi)/(3 mu)) in closed form, for
    a > 0 by a 1-D convex solve (:func:`_fast_multiplier`).  Theta is then the root of
    h(Theta) = X.e_Theta = q_tr sin(Theta_tr - Theta) - t R'(Theta) in [Theta_tr, pi/3]: h >= 0 at
    Theta_tr (R' <= 0) and h <= 0 at pi/3 (R' = 0).  The unknown is tau = tan(Theta - Theta_tr), a
    rotation of the unit trial direction (no trigonometric function), solved by Halley's method
    (h is strongly curved near pi/3, where the normal of G turns fast: Newton's method needed
    30-40 % more iterations) kept in the bracket: a step that leaves it goes 0.9 (first sweep) or
    0.5 of the way to the end it overshot.  Any root with q > 0 is the backward-Euler solution,
    which is unique, and the final test of :func:`_fast_final` makes sure it was reached.

    The points iterate in lockstep sweeps over the block: the iterations of different points are
    independent, so the loop is vectorised and pipelined instead of waiting on the latency of one
    point's chain of square roots and divisions (about 10x faster than point by point).  A point
    that has converged keeps its angle.  A last pass evaluates every point at its final angle.

    Writes W (rows _W_*) and flags: _F_VALID False: not tried (apex, magnitudes out of range);
    _F_DONE False: not converged in _FAST_MAXIT sweeps; _F_OK: the return W[_W_N1:_W_N3 + 1] is
    accepted (:func:`_fast_final`), else the point is for :func:`_return_sorted`.
    """
    A, B, E5, rc3, ax, ay, kp, tp, c, a = cst
    kap = kp * tp
    p_tr, q_tr, ct, st, f = W[_W_PTR], W[_W_QTR], W[_W_CT], W[_W_ST], W[_W_F]
    tau, lo, hi = W[_W_TAU], W[_W_LO], W[_W_HI]
    valid, done = flags[_F_VALID], flags[_F_DONE]
    for j in range(m):
        s1, s2, s3 = S[0, j], S[1, j], S[2, j]
        p = -(s1 + s2 + s3) / 3.0
        x = s1 - 0.5 * (s2 + s3)
        y = 0.5 * SQRT3 * (s2 - s3)
        q = math.sqrt(x * x + y * y)
        ok = 1e-100 < q < 1e100 and abs(p) < 1e100 and S[3, j] < 1e100
        # the apex: for a = 0 the return goes there if even the deviator's collapse (at most
        # t = q_tr/R_mc(pi/3)) leaves F >= 0 (as in _return_sorted); for a > 0 the return then
        # lives on the extra dilatancy of the rounded tip of G (g/w > 1) and mostly ends in the
        # tip or at the apex: left to the robust return as well
        ok = ok and -p * tp - c - kap * q / rc3 < 0.0
        if not ok:
            x, y, q = 1.0, 0.0, 1.0
        p_tr[j], q_tr[j], ct[j], st[j], f[j] = p, q, x / q, y / q, S[3, j]
        tau[j], lo[j] = 0.0, 0.0
        hi[j] = max(0.5 * SQRT3 * ct[j] - 0.5 * st[j], 0.0) / (0.5 * ct[j] + 0.5 * SQRT3 * st[j])
        valid[j], done[j] = ok, not ok
    N1, N2, N3, ok = W[_W_N1], W[_W_N2], W[_W_N3], flags[_F_OK]
    if a == 0.0:
        _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, W, flags, cst, False)
        _fast_final(m, p_tr, q_tr, ct, st, f, tau, valid, done, N1, N2, N3, ok, cst, False)
    else:
        _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, W, flags, cst, True)
        _fast_final(m, p_tr, q_tr, ct, st, f, tau, valid, done, N1, N2, N3, ok, cst, True)


@_jit
def _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, W, flags, cst, hyperbolic):
    """The lockstep Halley sweeps of :func:`_fast_block` (the rows of its work arrays are passed
    one by one: LLVM vectorises the loop only when it can tell them apart; hyperbolic is compiled
    in as a constant).

    Each point iterates until it converges or has had _FAST_MAXIT sweeps, whatever the other
    points of the block do, so its result does not depend on which points share its block.
    Whenever at most half of the points swept are still open, they are gathered (into the rows
    from _W_GATHERED of W and _F_GATHERED of flags; the points left behind go back to their
    places in the block) and swept on their own: the same iterates, since a point's sweep is
    its own arithmetic, at the cost of the points still open (most converge in three or four
    sweeps, a few take more).
    """
    g = _W_GATHERED
    gq, gct, gst, gf = W[g], W[g + 1], W[g + 2], W[g + 3]
    gtau, glo, ghi, gdone = W[g + 4], W[g + 5], W[g + 6], flags[_F_GATHERED]
    rows = np.empty(m, dtype=np.int64)  # the block's index of each gathered point
    n = m                               # the points swept: the block's, or the gathered n
    for sweep in range(_FAST_MAXIT):
        if n == m:
            n_open = _fast_sweep(m, sweep, q_tr, ct, st, f, tau, lo, hi, done, cst, hyperbolic)
        else:
            n_open = _fast_sweep(n, sweep, gq, gct, gst, gf, gtau, glo, ghi, gdone, cst,
                                 hyperbolic)
        if n_open == 0 or sweep + 1 == _FAST_MAXIT:
            break
        if 2 * n_open <= n:
            k = 0
            for j in range(n):
                if n == m:      # from the block
                    if not done[j]:
                        rows[k] = j
                        gq[k], gct[k], gst[k], gf[k] = q_tr[j], ct[j], st[j], f[j]
                        gtau[k], glo[k], ghi[k], gdone[k] = tau[j], lo[j], hi[j], False
                        k += 1
                elif gdone[j]:  # done: back to its place (k <= j: compacted in place)
                    i = rows[j]
                    tau[i], lo[i], hi[i], done[i] = gtau[j], glo[j], ghi[j], True
                else:
                    rows[k] = rows[j]
                    gq[k], gct[k], gst[k], gf[k] = gq[j], gct[j], gst[j], gf[j]
                    gtau[k], glo[k], ghi[k], gdone[k] = gtau[j], glo[j], ghi[j], False
                    k += 1
            n = k
    if n < m:
        for j in range(n):
            i = rows[j]
            tau[i], lo[i], hi[i], done[i] = gtau[j], glo[j], ghi[j], gdone[j]


@_jit
def _fast_sweep(m, sweep, q_tr, ct, st, f, tau, lo, hi, done, cst, hyperbolic):
    """Sweep number ``sweep`` of the Halley iteration over the points 0..m-1; returns the number
    still open."""
    n_open = 0
    for j in range(m):
        t0 = tau[j]
        h, h1, h2, w2 = _fast_eval(t0, q_tr[j], ct[j], st[j], f[j], cst, hyperbolic)[:4]
        l = t0 if h > 0.0 else lo[j]
        u = t0 if h < 0.0 else hi[j]
        # Halley step in tau (dTheta/dtau = 1/w2, d2Theta/dtau2 = -2 tau/w2^2), at most twice
        # the Newton step; converged when the Newton step is small (the error after the
        # Halley step is then of the order of its cube)
        newton = -h * w2 / h1
        tn = t0 + newton / max(1.0 - h * (h2 - 2.0 * t0 * h1) / (2.0 * h1 * h1), 0.5)
        small = abs(newton) <= _FAST_STEP
        inside = (h1 < 0.0) & (l < tn) & (tn < u)
        # a step out of the bracket: 0.9 (first sweep: typically a first step from Theta_tr
        # over a root near pi/3) or 0.5 of the way to the end it overshot
        frac = 0.9 if sweep == 0 else 0.5
        alt = t0 + frac * ((u if tn >= u else l) - t0)
        alt = alt if (l < alt) & (alt < u) else 0.5 * (l + u)
        tn = min(max(tn, l), u) if small | inside else alt
        conv = small | (h == 0.0) | (u - l <= _TOL_THETA)
        fin = done[j]
        tau[j] = t0 if fin | (h == 0.0) else tn
        lo[j] = lo[j] if fin else l
        hi[j] = hi[j] if fin else u
        done[j] = fin | conv
        n_open += 0 if fin | conv else 1
    return n_open


@_jit
def _fast_final(m, p_tr, q_tr, ct, st, f, tau, valid, done, N1, N2, N3, ok, cst, hyperbolic):
    """Last pass of :func:`_fast_block`: evaluation of every point at its final angle, the returned
    sorted principal stresses (N1, N2, N3) and their acceptance (ok).

    q is set from F = 0 at the converged (p, Theta), as in _return_sorted.  The residual at the
    final angle, h = X.e_Theta (the distance of the constructed point X_tr - t n(Theta) from the
    ray Theta), and the Newton step dTheta = -h/h' it still implies bound the error of that stress:
    |h| + q_tr |dTheta| in the deviator and |dp| = K tan(psi)/(3 mu) |dP/dTheta dTheta| in p (and
    in q through F = 0).  ok requires them to be at most 1e-12 of the trial's largest principal
    stress (where dP/dTheta or h'' is huge, as for e -> 1/2 near the compression meridian, the
    robust return takes over), a converged multiplier (a > 0), a positive multiplier,
    q >= _FAST_QMIN q_tr and a positive deviator (not (nearly) reversed: no apex), and for a > 0 a
    return outside the rounded tip of G (tip error estimate of :func:`_tip_error` at most
    _FAST_TIP).
    """
    A, B, E5, rc3, ax, ay, kp, tp, c, a = cst
    apex = c / tp
    amp = 1.0 + tp / min(ax, rc3)  # 1 + tan(phi)/min R_mc: |dsigma| per |dp| through F = 0
    for j in range(m):
        t0 = tau[j]
        h, h1, h2, w2, P, P1, qd, R, ok_t = _fast_eval(t0, q_tr[j], ct[j], st[j], f[j], cst,
                                                       hyperbolic)
        dth = abs(h / h1)
        err = abs(h) + q_tr[j] * dth + abs(kp * P1) * dth * amp
        iw = 1.0 / math.sqrt(w2)
        C = (ct[j] - t0 * st[j]) * iw
        S = (st[j] + t0 * ct[j]) * iw
        p = p_tr[j] + kp * P
        rho = (p * tp + c) / (ax * C + ay * S)  # land exactly on F = 0 at (p, Theta)
        w = R * qd
        tip = 2.220446049250313e-16 * (q_tr[j] / qd) * (abs(p - p_tr[j]) / (p + apex)) * (
            a * a / (a * a + w * w))
        ok[j] = (valid[j] & done[j] & ok_t & (err <= 1e-12 * (abs(p_tr[j]) + q_tr[j]))
                 & (P > 0.0) & (rho >= _FAST_QMIN * q_tr[j]) & (rho < 1e100) & (qd > 0.0)
                 & ((a == 0.0) | (tip <= _FAST_TIP)))
        k = 2.0 / 3.0 * rho
        u = 0.5 * SQRT3 * k * S
        v = -p - 0.5 * k * C
        N1[j], N2[j], N3[j] = -p + k * C, v + u, v - u


@_jit
def update_points(points, n, prm, cst, out, status):
    """The law's compiled point update of ``n <= _BLOCK`` points, in place into ``out``.

    ``points`` (at least 8 rows, ``n`` columns): rows 0-3 the stress before the increment
    (``rr, zz, tt, rz``, Pa), rows 4-7 the strain increment (tensor shear).  Writes ``out``
    (8 rows): rows 0-3 the new stress, rows 4-7 the plastic strain increment ``C^-1 (sigma_tr -
    sigma_new)``, and ``status`` (``ELASTIC``, ``PLASTIC``, ``APEX``).  ``cst``:
    :func:`_fast_constants` of ``prm``.

    (1) the elastic predictor, the principal stresses and F of every point; elastic points are
    written out, plastic ones gathered; (2) the fast return of the gathered points in lockstep
    (:func:`_fast_block`); (3) each plastic point takes the fast result if it was accepted,
    else the robust :func:`_return_sorted` (the algorithm of update_reference), and its stress
    is rebuilt on the trial axes.  The stand-alone :func:`update` and the fused step of the
    Eulerian model (:mod:`fipy_hopper.stepping`) both call this function: the one place the
    compiled Mohr–Coulomb update is written.
    """
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    idx = np.empty(n, dtype=np.int64)
    pos = np.empty(n, dtype=np.int8)
    trial = np.empty((6, n))  # rr, zz, tt, rz and the in-plane axes (cos 2w, sin 2w)
    S = np.empty((4, n))
    m = 0
    for q in range(n):
        rr, zz, tt, rz = _elastic_trial_nb(points[0, q], points[1, q], points[2, q],
                                           points[3, q], points[4, q], points[5, q],
                                           points[6, q], points[7, q], lam, mu)
        mid = 0.5 * (rr + zz)
        d = 0.5 * (rr - zz)
        rad = _radius_nb(d, rz)
        la, lb = mid + rad, mid - rad
        if tt >= la:
            ps, s1, s2, s3 = 0, tt, la, lb
        elif tt >= lb:
            ps, s1, s2, s3 = 1, la, tt, lb
        else:
            ps, s1, s2, s3 = 2, la, lb, tt
        f = ((s1 - s3) + (s1 + s3) * sp) / (2.0 * cp) - c
        if not f > 0.0:
            out[0, q], out[1, q], out[2, q], out[3, q] = rr, zz, tt, rz
            out[4, q] = out[5, q] = out[6, q] = out[7, q] = 0.0
            status[q] = ELASTIC
            continue
        if rad > 0.0:
            cw, sw = d / rad, rz / rad
        else:
            cw, sw = 1.0, 0.0
        idx[m], pos[m] = q, ps
        trial[0, m], trial[1, m], trial[2, m], trial[3, m] = rr, zz, tt, rz
        trial[4, m], trial[5, m] = cw, sw
        S[0, m], S[1, m], S[2, m], S[3, m] = s1, s2, s3, f
        m += 1
    W = np.empty((_W_ROWS, m))
    flags = np.empty((_F_ROWS, m), dtype=np.bool_)
    _fast_block(m, S, W, flags, cst)
    for j in range(m):
        q = idx[j]
        if flags[_F_OK, j]:
            n1, n2, n3, status[q] = W[_W_N1, j], W[_W_N2, j], W[_W_N3, j], PLASTIC
        else:
            n1, n2, n3, status[q] = _return_sorted(S[0, j], S[1, j], S[2, j], prm)
        if pos[j] == 0:
            na, nb_, ntt = n2, n3, n1
        elif pos[j] == 1:
            na, nb_, ntt = n1, n3, n2
        else:
            na, nb_, ntt = n1, n2, n3
        rr, zz, tt, rz = trial[0, j], trial[1, j], trial[2, j], trial[3, j]
        nrr, nzz, nrz = _rebuild_inplane_nb(na, nb_, trial[4, j], trial[5, j])
        out[0, q], out[1, q], out[2, q], out[3, q] = nrr, nzz, ntt, nrz
        out[4, q], out[5, q], out[6, q], out[7, q] = _compliance_nb(
            rr - nrr, zz - nzz, tt - ntt, rz - nrz, E, nu, mu)


@_jit
def _update_kernel(sig, deps, prm, sig_out, dep_out, status):
    """Loop of :func:`update` over the points (rows) of sig and deps, writing into the outputs:
    :func:`update_points` on blocks of _BLOCK points."""
    cst = _fast_constants(prm)
    n = sig.shape[0]
    nb = min(n, _BLOCK)
    points = np.empty((8, nb))
    out = np.empty((8, nb))
    for b0 in range(0, n, _BLOCK):
        b1 = min(b0 + _BLOCK, n)
        for i in range(b0, b1):
            for k in range(4):
                points[k, i - b0] = sig[i, k]
                points[4 + k, i - b0] = deps[i, k]
        update_points(points, b1 - b0, prm, cst, out, status[b0:b1])
        for i in range(b0, b1):
            for k in range(4):
                sig_out[i, k] = out[k, i - b0]
                dep_out[i, k] = out[4 + k, i - b0]


def _as_points(sigma, d_eps):
    sigma, d_eps = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(d_eps, float))
    if sigma.shape[-1:] != (4,):
        raise ValueError(f"stress and strain arrays must have shape (..., 4), got {sigma.shape}")
    shape = sigma.shape[:-1]
    return np.ascontiguousarray(sigma.reshape(-1, 4)), np.ascontiguousarray(d_eps.reshape(-1, 4)), shape


def update(sigma, d_eps, mat: MohrCoulomb, return_status: bool = False):
    """Stress update: elastic predictor + implicit return (compiled; one core; any leading shape).

    sigma: stresses (..., 4) (rr, zz, tt, rz), tension positive, Pa.  d_eps: total strain
    increments (..., 4) with the TENSOR shear component eps_rz.  Returns (sigma_new, d_eps_plastic)
    with d_eps_plastic = C^-1 (sigma_trial - sigma_new) in the same tensor layout, and with
    ``return_status`` also the status per point (ELASTIC, PLASTIC, APEX).  Same results as
    :func:`update_reference` (to round-off); elastic points get exactly the trial stress.  Never NaN
    for inputs whose elastic trial stress is finite.

    Plastic points are returned in blocks by a fast solve of the same backward-Euler equations
    (:func:`_fast_block`: for G a cone, a = 0, the multiplier is explicit given the Lode angle and
    the return is one scalar equation in that angle, solved by safeguarded Newton for the whole
    block in vectorised lockstep); it accepts a point only when its own error estimate is below
    1e-12 of the trial stress and the return is regular (no apex, not near it, not in the rounded
    tip of G), and the other points get :func:`update_reference`'s algorithm (_return_sorted).
    About 0.1 us per plastic point instead of 1 us.
    """
    sig, dep, shape = _as_points(sigma, d_eps)
    sig_out = np.empty_like(sig)
    dep_out = np.empty_like(sig)
    status = np.empty(sig.shape[0], dtype=np.int8)
    _update_kernel(sig, dep, mat.kernel_parameters(), sig_out, dep_out, status)
    out = (sig_out.reshape(shape + (4,)), dep_out.reshape(shape + (4,)))
    return out + (status.reshape(shape),) if return_status else out
