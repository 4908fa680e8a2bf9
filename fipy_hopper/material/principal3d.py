"""The law's 3D point update: Mohr–Coulomb (Abaqus form) on six stress components.

Stresses ``(..., 6)`` in the order ``(xx, yy, zz, yz, xz, xy)``, tension positive, Pa; strains
in the same layout with the **tensor** shear components (``eps_yz = gamma_yz / 2``).  Inner
products of such tensors count the three shear entries twice.

The update of one point is the axisymmetric one's with a general principal frame:

1. elastic predictor ``sigma_tr = sigma + lambda tr(d_eps) I + 2 mu d_eps``;
2. the principal stresses ``s1 >= s2 >= s3`` and axes ``v_1, v_2, v_3`` of the symmetric 3 x 3
   trial stress (compiled: cyclic Jacobi rotations, the points of a block in lockstep,
   :func:`_eigh3_block`; numpy: ``np.linalg.eigh``);
3. ``F = [(s1 - s3) + (s1 + s3) sin(phi)] / (2 cos(phi)) - c``; ``F <= 0``: elastic, the
   trial stress exactly.  Else the principal-space return of the law, which is dimension-free
   and is **not** re-implemented here: compiled, the blocked fast solve
   :func:`fipy_hopper.material.return_fast._fast_block` with the robust
   :func:`fipy_hopper.material.return_robust._return_sorted` for every point it does not
   accept (as the axisymmetric update does); numpy, the vectorised reference
   ``return_reference._return_sorted_vec``.  Both take the law's ``kernel_parameters()``;
4. the stress is rebuilt coaxially, ``sigma_new = sum_i n_i v_i v_i^T`` (``n_i`` the returned
   sorted principal stresses; at the apex exactly ``c cot(phi) I``), and the plastic strain
   increment is ``d_eps_p = C^-1 (sigma_tr - sigma_new)``
   (``((1 + nu) ds_ii - nu tr(ds)) / E`` on the diagonal, ``ds_ij / (2 mu)`` off it).

The compiled :func:`update6` and its numpy twin :func:`update6_reference` agree to about
1e-12 of the stress, not to the bit: the two eigen-solvers (Jacobi rotations, LAPACK's
tridiagonal QR) are each backward stable, so the principal values agree to a few ulps of the
stress's norm, and the return, a smooth function of them, carries that round-off through.
An axisymmetric state ``(rr, zz, tt, rz)`` rotated into any frame gives the rotated result of
:func:`fipy_hopper.material.update` (the same sorted principal values enter the same return).
"""

from __future__ import annotations

import math

import numpy as np

from . import return_fast as _fast
from .mohr_coulomb import APEX, ELASTIC, PLASTIC, MohrCoulomb, _jit, _unpack
from .return_reference import _return_sorted_vec
from .return_robust import _return_sorted

__all__ = ["COMPONENTS", "update6", "update6_reference", "principal6", "yield_function6",
           "elastic_trial6", "plastic_strain6", "equivalent_plastic_strain6", "to_matrix",
           "from_matrix"]

#: the order of the six components of a stress or strain (tensor shear components)
COMPONENTS = ("xx", "yy", "zz", "yz", "xz", "xy")
#: (row, column) of each component in the 3 x 3 tensor
_INDEX = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
#: sweeps of the Jacobi eigen-solve (3-5 reach round-off; the cap only bounds the loop)
_JACOBI_SWEEPS = 30


# ---------------------------------------------------------------------------------------------
# Layout helpers (numpy)
# ---------------------------------------------------------------------------------------------
def to_matrix(t):
    """Symmetric 3 x 3 tensors ``(..., 3, 3)`` from six components ``(..., 6)``."""
    t = np.asarray(t, dtype=float)
    out = np.empty(t.shape[:-1] + (3, 3))
    for k, (a, b) in enumerate(_INDEX):
        out[..., a, b] = t[..., k]
        out[..., b, a] = t[..., k]
    return out


def from_matrix(m):
    """Six components ``(..., 6)`` of symmetric tensors ``(..., 3, 3)`` (the upper triangle)."""
    m = np.asarray(m, dtype=float)
    return np.stack([m[..., a, b] for a, b in _INDEX], axis=-1)


def elastic_trial6(sigma, d_eps, mat: MohrCoulomb):
    """``sigma + lambda tr(d_eps) I + 2 mu d_eps`` (Pa), component by component, as
    :func:`update6` forms it."""
    sigma, d_eps = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(d_eps, float))
    lam, mu = mat.lame_lambda, mat.shear_modulus
    lt = lam * (d_eps[..., 0] + d_eps[..., 1] + d_eps[..., 2])
    out = sigma + 2.0 * mu * d_eps
    out[..., :3] = sigma[..., :3] + (lt[..., None] + 2.0 * mu * d_eps[..., :3])
    return out


def plastic_strain6(d_sigma, mat: MohrCoulomb):
    """``C^-1 d_sigma``: ``((1 + nu) ds_ii - nu tr(ds)) / E``, ``ds_ij / (2 mu)`` (tensor)."""
    d_sigma = np.asarray(d_sigma, dtype=float)
    tr = d_sigma[..., 0] + d_sigma[..., 1] + d_sigma[..., 2]
    out = d_sigma / (2.0 * mat.shear_modulus)
    out[..., :3] = ((1.0 + mat.nu) * d_sigma[..., :3] - mat.nu * tr[..., None]) / mat.E
    return out


def equivalent_plastic_strain6(d_eps_plastic):
    """``sqrt(2/3 e:e)`` of tensor components ``(..., 6)`` (shear entries counted twice)."""
    e = np.asarray(d_eps_plastic, dtype=float)
    return np.sqrt(2.0 / 3.0 * (e[..., 0] ** 2 + e[..., 1] ** 2 + e[..., 2] ** 2
                                + 2.0 * (e[..., 3] ** 2 + e[..., 4] ** 2 + e[..., 5] ** 2)))


def principal6(sigma):
    """Principal stresses sorted ``s1 >= s2 >= s3`` ``(..., 3)`` and their unit axes as the
    columns of ``(..., 3, 3)`` (``np.linalg.eigh``)."""
    w, v = np.linalg.eigh(to_matrix(sigma))
    return w[..., ::-1], v[..., :, ::-1]


def yield_function6(sigma, mat: MohrCoulomb):
    """``F = [(s1 - s3) + (s1 + s3) sin(phi)] / (2 cos(phi)) - c`` (Pa) of ``(..., 6)``
    stresses (the law's ``R_mc q - p tan(phi) - c``)."""
    s, _ = principal6(sigma)
    sp, cp = math.sin(mat.phi_rad), math.cos(mat.phi_rad)
    return ((s[..., 0] - s[..., 2]) + (s[..., 0] + s[..., 2]) * sp) / (2.0 * cp) - mat.c


# ---------------------------------------------------------------------------------------------
# numpy reference
# ---------------------------------------------------------------------------------------------
def _as_points6(sigma, d_eps):
    sigma, d_eps = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(d_eps, float))
    if sigma.shape[-1:] != (6,):
        raise ValueError(f"stress and strain arrays must have shape (..., 6), got {sigma.shape}")
    shape = sigma.shape[:-1]
    return (np.ascontiguousarray(sigma.reshape(-1, 6)), np.ascontiguousarray(d_eps.reshape(-1, 6)),
            shape)


def update6_reference(sigma, d_eps, mat: MohrCoulomb, return_status: bool = False):
    """Plain-numpy reference of :func:`update6` (the module docstring's steps, vectorised:
    ``np.linalg.eigh`` for the principal frame, the law's numpy return
    ``return_reference._return_sorted_vec``).  Same inputs and outputs as :func:`update6`."""
    sig, dep, shape = _as_points6(sigma, d_eps)
    trial = elastic_trial6(sig, dep, mat)
    s, v = principal6(trial)
    sp, cp = math.sin(mat.phi_rad), math.cos(mat.phi_rad)
    f = ((s[:, 0] - s[:, 2]) + (s[:, 0] + s[:, 2]) * sp) / (2.0 * cp) - mat.c
    pl = np.flatnonzero(f > 0.0)
    out = trial.copy()
    status = np.full(trial.shape[0], ELASTIC, dtype=np.int8)
    n1, n2, n3, status[pl] = _return_sorted_vec(s[pl, 0], s[pl, 1], s[pl, 2],
                                                mat.kernel_parameters())
    n = np.stack([n1, n2, n3], axis=-1)
    rebuilt = from_matrix(np.einsum("pik,pk,pjk->pij", v[pl], n, v[pl]))
    apex = status[pl] == APEX
    rebuilt[apex] = 0.0
    rebuilt[apex, :3] = n1[apex, None]
    out[pl] = rebuilt
    d_eps_p = np.zeros_like(trial)
    d_eps_p[pl] = plastic_strain6(trial[pl] - out[pl], mat)
    res = (out.reshape(shape + (6,)), d_eps_p.reshape(shape + (6,)))
    return res + (status.reshape(shape),) if return_status else res


# ---------------------------------------------------------------------------------------------
# Compiled kernels
# ---------------------------------------------------------------------------------------------
#: rows of the block eigen-solve's matrix work array (the six-component layout's order)
_A00, _A11, _A22, _A12, _A02, _A01 = 0, 1, 2, 3, 4, 5


@_jit
def _jacobi_rotations(n, sweep, app, aqq, apq, arp, arq, p0, p1, p2, q0, q1, q2):
    """One Jacobi rotation in the plane ``(p, q)`` of each of the ``n`` symmetric 3 x 3
    matrices of a block, in lockstep (:func:`_eigh3_block`): ``app, aqq, apq`` the plane's
    entries, ``arp, arq`` the third row's, ``p0 .. p2`` and ``q0 .. q2`` the eigenvector
    matrix's columns ``p`` and ``q``, each a row of a work array (passed one by one: LLVM
    vectorises the loop only when it can tell them apart).

    The rotation annihilating ``a_pq`` is Numerical Recipes' stable ``jacobi``: ``t = sgn(theta)
    / (|theta| + sqrt(theta^2 + 1))``, ``theta = (a_qq - a_pp) / (2 a_pq)`` (``t = a_pq /
    (a_qq - a_pp)`` where ``theta^2`` would overflow), ``c = 1 / sqrt(t^2 + 1)``, ``s = t c``,
    ``tau = s / (1 + c)``.  A matrix with ``a_pq = 0`` is left as it is; after the fourth sweep
    an ``a_pq`` below round-off of both diagonal entries is set to 0 without rotating.  Every
    update is a select, so the loop has no branch; a matrix left as it is keeps its entries to
    the bit."""
    for j in range(n):
        a_pp, a_qq, a_pq = app[j], aqq[j], apq[j]
        small = 100.0 * abs(a_pq)
        skip = sweep > 3 and abs(a_pp) + small == abs(a_pp) and abs(a_qq) + small == abs(a_qq)
        rotate = not skip and a_pq != 0.0
        diff = a_qq - a_pp
        theta = 0.5 * diff / a_pq
        t_theta = 1.0 / (abs(theta) + math.sqrt(abs(theta * theta + 1.0)))
        t_theta = -t_theta if theta < 0.0 else t_theta
        t = a_pq / diff if abs(diff) + small == abs(diff) else t_theta
        t = t if rotate else 0.0
        c = 1.0 / math.sqrt(abs(t * t + 1.0))   # abs: provably >= 0, so LLVM emits (vector) sqrt
        s = t * c
        tau = s / (1.0 + c)
        x, y = arp[j], arq[j]
        app[j] = a_pp - t * a_pq if rotate else a_pp
        aqq[j] = a_qq + t * a_pq if rotate else a_qq
        apq[j] = 0.0 if (skip or rotate) else a_pq
        arp[j] = x - s * (y + tau * x) if rotate else x
        arq[j] = y + s * (x - tau * y) if rotate else y
        x, y = p0[j], q0[j]
        p0[j] = x - s * (y + tau * x) if rotate else x
        q0[j] = y + s * (x - tau * y) if rotate else y
        x, y = p1[j], q1[j]
        p1[j] = x - s * (y + tau * x) if rotate else x
        q1[j] = y + s * (x - tau * y) if rotate else y
        x, y = p2[j], q2[j]
        p2[j] = x - s * (y + tau * x) if rotate else x
        q2[j] = y + s * (x - tau * y) if rotate else y


@_jit
def _eigh3_block(n, A, V):
    """Eigen-decomposition of the ``n`` symmetric 3 x 3 matrices in the columns of ``A`` (rows
    ``_A00 .. _A01``: xx, yy, zz, yz, xz, xy) in place by cyclic Jacobi rotations in lockstep:
    on return ``A[0:3]`` holds each matrix's eigenvalues and ``V[3 r + c]`` the entry ``(r,
    c)`` of its matrix of unit eigenvectors (columns; set to the identity first).  Each sweep
    rotates in the planes (0, 1), (0, 2), (1, 2) (:func:`_jacobi_rotations`); the sweeps stop
    when every matrix's off-diagonal part is 0 (quadratic convergence: 3 to 5 sweeps).  A
    matrix that has converged is left as it is by the sweeps the others still need, so each
    matrix's result is that of rotating it on its own, to the bit, whatever shares its block.
    The iterations of different matrices are independent: in lockstep the loop is vectorised
    and pipelined instead of waiting on one matrix's chain of square roots and divisions."""
    for j in range(n):
        for r in range(9):
            V[r, j] = 1.0 if r == 0 or r == 4 or r == 8 else 0.0
    for sweep in range(_JACOBI_SWEEPS):
        converged = True
        for j in range(n):
            if abs(A[_A01, j]) + abs(A[_A02, j]) + abs(A[_A12, j]) != 0.0:
                converged = False
                break
        if converged:
            return
        _jacobi_rotations(n, sweep, A[_A00], A[_A11], A[_A01], A[_A02], A[_A12],
                          V[0], V[3], V[6], V[1], V[4], V[7])
        _jacobi_rotations(n, sweep, A[_A00], A[_A22], A[_A02], A[_A01], A[_A12],
                          V[0], V[3], V[6], V[2], V[5], V[8])
        _jacobi_rotations(n, sweep, A[_A11], A[_A22], A[_A12], A[_A01], A[_A02],
                          V[1], V[4], V[7], V[2], V[5], V[8])


@_jit
def _eigh3(a, v):
    """:func:`_eigh3_block` of the one symmetric 3 x 3 ``a``, in place: on return the diagonal
    of ``a`` holds the eigenvalues (the off-diagonal part 0) and the columns of ``v`` the unit
    eigenvectors."""
    A = np.empty((6, 1))
    V = np.empty((9, 1))
    A[_A00, 0], A[_A11, 0], A[_A22, 0] = a[0, 0], a[1, 1], a[2, 2]
    A[_A12, 0], A[_A02, 0], A[_A01, 0] = a[1, 2], a[0, 2], a[0, 1]
    _eigh3_block(1, A, V)
    a[0, 0], a[1, 1], a[2, 2] = A[_A00, 0], A[_A11, 0], A[_A22, 0]
    a[1, 2] = a[2, 1] = A[_A12, 0]
    a[0, 2] = a[2, 0] = A[_A02, 0]
    a[0, 1] = a[1, 0] = A[_A01, 0]
    for r in range(3):
        for c in range(3):
            v[r, c] = V[3 * r + c, 0]


@_jit
def _elastic_trial(sig, dep, lam, mu, trial, A, m):
    """The elastic trial of one point (six components) into ``trial[:, m]`` and ``A[:, m]``."""
    lt = lam * (dep[0] + dep[1] + dep[2])
    for k in range(3):
        trial[k, m] = sig[k] + (lt + 2.0 * mu * dep[k])
    for k in range(3, 6):
        trial[k, m] = sig[k] + 2.0 * mu * dep[k]
    for k in range(6):
        A[k, m] = trial[k, m]


@_jit
def _principal_sorted(A, V, j, axes, S, m, sp, cp, c):
    """The decomposed point ``j`` of a block (``A``, ``V`` of :func:`_eigh3_block`): its sorted
    principal stresses into ``S[0:3, m]``, ``F`` into ``S[3, m]`` and the axes (the
    eigenvectors of s1, s2, s3) into ``axes[:, m]`` (9 rows, row-major).  Returns F."""
    d0, d1, d2 = A[_A00, j], A[_A11, j], A[_A22, j]
    # descending order (a stable sort of three)
    i1, i2, i3 = 0, 1, 2
    if d1 > d0:
        i1, i2 = 1, 0
    d = (d0, d1, d2)
    if d2 > d[i1]:
        i1, i2, i3 = 2, i1, i2
    elif d2 > d[i2]:
        i2, i3 = 2, i2
    S[0, m], S[1, m], S[2, m] = d[i1], d[i2], d[i3]
    for r in range(3):
        axes[r, m] = V[3 * r + i1, j]
        axes[3 + r, m] = V[3 * r + i2, j]
        axes[6 + r, m] = V[3 * r + i3, j]
    f = ((S[0, m] - S[2, m]) + (S[0, m] + S[2, m]) * sp) / (2.0 * cp) - c
    S[3, m] = f
    return f


@_jit
def _rebuild6(n1, n2, n3, axes, m, status, out):
    """``sum_i n_i v_i v_i^T`` in the six-component layout into ``out`` (exactly ``n1 I`` at
    the apex, where the three are equal)."""
    if status == APEX:
        out[0], out[1], out[2] = n1, n1, n1
        out[3], out[4], out[5] = 0.0, 0.0, 0.0
        return
    for k in range(6):
        out[k] = 0.0
    for i in range(3):
        n = (n1, n2, n3)[i]
        x, y, z = axes[3 * i, m], axes[3 * i + 1, m], axes[3 * i + 2, m]
        out[0] += n * x * x
        out[1] += n * y * y
        out[2] += n * z * z
        out[3] += n * y * z
        out[4] += n * x * z
        out[5] += n * x * y


@_jit
def _compliance6(d, E, nu, mu, out):
    """``C^-1 d`` (six components, tensor shear) into ``out``."""
    tr = d[0] + d[1] + d[2]
    for k in range(3):
        out[k] = ((1.0 + nu) * d[k] - nu * tr) / E
    for k in range(3, 6):
        out[k] = d[k] / (2.0 * mu)


@_jit
def update6_points(sig, deps, prm, sig_out, dep_out, status):
    """The compiled update of the rows of ``sig``/``deps`` (n, 6) into the outputs: blocks of
    ``return_fast._BLOCK`` points, (1) elastic trial, eigen-solve and F (elastic points
    written out, plastic ones gathered; the eigen-solve of the block's points in lockstep,
    :func:`_eigh3_block`), (2) the law's fast return of the gathered sorted
    principal stresses in lockstep (``return_fast._fast_block``), (3) the robust return
    (``return_robust._return_sorted``) for each point the fast solve did not accept, the
    coaxial rebuild and ``d_eps_p = C^-1 (sigma_tr - sigma_new)``."""
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a_h, e, rc3 = _unpack(prm)
    cst = _fast._fast_constants(prm)
    n = sig.shape[0]
    nb = min(n, _fast._BLOCK)
    idx = np.empty(nb, dtype=np.int64)
    trial = np.empty((6, nb))
    A = np.empty((6, nb))
    V = np.empty((9, nb))
    axes = np.empty((9, nb))
    S = np.empty((4, nb))
    W = np.empty((_fast._W_ROWS, nb))
    flags = np.empty((_fast._F_ROWS, nb), dtype=np.bool_)
    new = np.empty(6)
    diff = np.empty(6)
    for b0 in range(0, n, _fast._BLOCK):
        b1 = min(b0 + _fast._BLOCK, n)
        for i in range(b0, b1):
            _elastic_trial(sig[i], deps[i], lam, mu, trial, A, i - b0)
        _eigh3_block(b1 - b0, A, V)
        m = 0    # the plastic points gathered in place (m <= j: column j is read first)
        for i in range(b0, b1):
            j = i - b0
            f = _principal_sorted(A, V, j, axes, S, m, sp, cp, c)
            if not f > 0.0:
                for k in range(6):
                    sig_out[i, k] = trial[k, j]
                    dep_out[i, k] = 0.0
                status[i] = ELASTIC
                continue
            for k in range(6):
                trial[k, m] = trial[k, j]
            idx[m] = i
            m += 1
        _fast._fast_block(m, S, W, flags, cst)
        for j in range(m):
            i = idx[j]
            if flags[_fast._F_OK, j]:
                n1, n2, n3, st = (W[_fast._W_N1, j], W[_fast._W_N2, j], W[_fast._W_N3, j],
                                  PLASTIC)
            else:
                n1, n2, n3, st = _return_sorted(S[0, j], S[1, j], S[2, j], prm)
            status[i] = st
            _rebuild6(n1, n2, n3, axes, j, st, new)
            for k in range(6):
                sig_out[i, k] = new[k]
                diff[k] = trial[k, j] - new[k]
            _compliance6(diff, E, nu, mu, new)
            for k in range(6):
                dep_out[i, k] = new[k]


def update6(sigma, d_eps, mat: MohrCoulomb, return_status: bool = False):
    """The compiled 3D stress update (module docstring): ``sigma`` ``(..., 6)`` (Pa, tension
    positive), ``d_eps`` ``(..., 6)`` total strain increments (tensor shear).  Returns
    ``(sigma_new, d_eps_plastic)`` (and with ``return_status`` ELASTIC / PLASTIC / APEX per
    point); elastic points get exactly the trial stress."""
    sig, dep, shape = _as_points6(sigma, d_eps)
    sig_out = np.empty_like(sig)
    dep_out = np.empty_like(sig)
    status = np.empty(sig.shape[0], dtype=np.int8)
    update6_points(sig, dep, mat.kernel_parameters(), sig_out, dep_out, status)
    out = (sig_out.reshape(shape + (6,)), dep_out.reshape(shape + (6,)))
    return out + (status.reshape(shape),) if return_status else out
