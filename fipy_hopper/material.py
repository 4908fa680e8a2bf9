"""Mohr–Coulomb elastoplasticity in the Abaqus form, on arrays of axisymmetric stress states.

Conventions (SI; angles in degrees only in :class:`MohrCoulomb`, radians everywhere else):

* A stress is an array of shape ``(..., 4)`` in the order ``(rr, zz, tt, rz)``, tension positive,
  in Pa.  A strain (increment) has the same layout with the **tensor** shear component
  ``eps_rz`` (half the engineering shear strain ``gamma_rz``).  Inner products of such tensors
  count the ``rz`` entry twice.
* Invariants: ``p = -tr(sigma)/3``, ``S = sigma + p I``, ``q = sqrt(3/2 S:S)``,
  ``r = (9/2 S.S:S)^(1/3)`` and the deviatoric polar angle ``Theta`` with ``cos(3 Theta) = (r/q)^3``,
  ``0 <= Theta <= pi/3``.  ``Theta = 0`` is triaxial extension (one principal stress algebraically
  largest, the other two equal), ``Theta = pi/3`` triaxial compression.
* Yield function ``F = R_mc(Theta, phi) q - p tan(phi) - c``.  With sorted principal stresses
  ``s1 >= s2 >= s3`` it is linear: ``F = [(s1 - s3) + (s1 + s3) sin(phi)] / (2 cos(phi)) - c``.
* Flow potential ``G = sqrt((eps c tan(psi))^2 + (R_mw(Theta, e) q)^2) - p tan(psi)``, hyperbolic in
  the meridional plane and Menetrey–Willam in the deviatoric plane.

The stress update :func:`update` (numba) and its plain-numpy twin :func:`update_reference` perform an
elastic predictor and an implicit (backward-Euler) return in principal space; see
:func:`update_reference` for the algorithm.  The compiled update first tries a faster solve of the
same return, one scalar equation in the Lode angle iterated for a block of points at once
(:func:`_fast_block`), and hands every point it does not accept to the reference's algorithm.
:func:`element_test` drives one material point along the classical laboratory paths with mixed
stress/strain control.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = [
    "MohrCoulomb",
    "invariants",
    "principal_stresses",
    "R_mc",
    "R_mw",
    "yield_function",
    "flow_potential",
    "flow_direction",
    "elastic_stiffness",
    "elastic_trial",
    "plastic_strain_from_stress",
    "update",
    "update_reference",
    "close_loose_volume",
    "separation_strain",
    "equivalent_plastic_strain",
    "ELASTIC",
    "PLASTIC",
    "APEX",
    "ElementTestResult",
    "PATHS",
    "drive",
    "element_test",
]

SQRT3 = math.sqrt(3.0)
PI3 = math.pi / 3.0
TWO_PI3 = 2.0 * math.pi / 3.0

#: Status codes returned by :func:`update` with ``return_status=True``.
ELASTIC, PLASTIC, APEX = 0, 1, 2

_MAXIT = 100  # iteration cap of every scalar solve (bisection fallback makes each one terminate)
_TOL_THETA = 1e-14  # absolute tolerance on angles (rad)
_STEP_THETA = 1e-8  # a Newton step on an angle this small has converged (error ~ 1e-16)
_TOL_T = 1e-15  # tolerance on the return parameter t, relative to its upper bound t*
_TIP_TOL = 1e-6  # largest accepted round-off error estimate of a return into the tip of G (a > 0)

_jit = numba.njit(cache=True, fastmath=False, error_model="numpy")
# small helpers of the vectorised loops are inlined by numba itself (LLVM might keep them as
# calls, which stops the loop vectoriser)
_jit_inline = numba.njit(cache=True, fastmath=False, error_model="numpy", inline="always")


# ---------------------------------------------------------------------------------------------
# Material parameters
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MohrCoulomb:
    """Mohr–Coulomb material (Abaqus ``*MOHR COULOMB``) with linear isotropic elasticity.

    Parameters: ``E`` Young's modulus (Pa), ``nu`` Poisson's ratio, ``rho`` bulk density (kg/m3),
    ``phi`` friction angle (deg), ``psi`` dilation angle (deg), ``c`` cohesion (Pa), ``eps``
    meridional eccentricity of the flow potential, ``e`` deviatoric eccentricity (``None`` gives the
    Abaqus default ``(3 - sin phi)/(3 + sin phi)``, for which the flow potential passes through the
    corners of the Mohr–Coulomb hexagon).  Ranges: ``0 < phi < 90``, ``0 <= psi <= phi``, ``c >= 0``,
    ``E > 0``, ``-1 < nu < 0.5``, ``1/2 < e <= 1``, ``eps > 0``, ``rho > 0``.
    """

    E: float
    nu: float
    rho: float
    phi: float
    psi: float = 0.0
    c: float = 0.0
    eps: float = 0.1
    e: float | None = None

    def __post_init__(self):
        def check(name, ok, allowed, unit=""):
            value = getattr(self, name)
            if not ok(value):
                raise ValueError(
                    f"MohrCoulomb: {name} = {value!r}{unit} is outside the allowed range {allowed}"
                )

        for name in ("E", "nu", "rho", "phi", "psi", "c", "eps"):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"MohrCoulomb: {name} = {value!r} is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"MohrCoulomb: {name} = {value!r} must be finite")
            object.__setattr__(self, name, value)
        check("phi", lambda v: 0.0 < v < 90.0, "0 < phi < 90", " deg")
        check("psi", lambda v: 0.0 <= v <= self.phi, f"0 <= psi <= phi = {self.phi}", " deg")
        check("c", lambda v: v >= 0.0, "c >= 0", " Pa")
        check("E", lambda v: v > 0.0, "E > 0", " Pa")
        check("nu", lambda v: -1.0 < v < 0.5, "-1 < nu < 0.5")
        check("rho", lambda v: v > 0.0, "rho > 0", " kg/m3")
        check("eps", lambda v: v > 0.0, "eps > 0")
        if self.e is None:
            s = math.sin(math.radians(self.phi))
            object.__setattr__(self, "e", (3.0 - s) / (3.0 + s))
        else:
            try:
                object.__setattr__(self, "e", float(self.e))
            except (TypeError, ValueError):
                raise ValueError(f"MohrCoulomb: e = {self.e!r} is not a number") from None
            check("e", lambda v: math.isfinite(v) and 0.5 < v <= 1.0, "1/2 < e <= 1")

    # elastic constants -------------------------------------------------------------------------
    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) (Pa)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def bulk_modulus(self) -> float:
        """K = E / (3 (1 - 2 nu)) (Pa)."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    @property
    def lame_lambda(self) -> float:
        """lambda = E nu / ((1 + nu)(1 - 2 nu)) (Pa)."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def p_wave_modulus(self) -> float:
        """M = lambda + 2 mu = E (1 - nu) / ((1 + nu)(1 - 2 nu)) (Pa)."""
        return self.E * (1.0 - self.nu) / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def p_wave_speed(self) -> float:
        """c_p = sqrt(M / rho) (m/s)."""
        return math.sqrt(self.p_wave_modulus / self.rho)

    # angles and derived strength quantities ------------------------------------------------------
    @property
    def phi_rad(self) -> float:
        return math.radians(self.phi)

    @property
    def psi_rad(self) -> float:
        return math.radians(self.psi)

    @property
    def apex_stress(self) -> float:
        """c cot(phi) (Pa): the isotropic tension s1 = s2 = s3 of the yield-surface apex."""
        return self.c / math.tan(self.phi_rad)

    @property
    def flow_hyperbola(self) -> float:
        """a = eps c tan(psi) (Pa): the meridional rounding of G; a = 0 gives a cone with a vertex."""
        return self.eps * self.c * math.tan(self.psi_rad)

    def kernel_parameters(self) -> np.ndarray:
        """Float array handed to the compiled kernel (layout of :func:`_unpack`)."""
        sp, cp = math.sin(self.phi_rad), math.cos(self.phi_rad)
        return np.array(
            [
                self.lame_lambda,
                self.shear_modulus,
                self.bulk_modulus,
                self.E,
                self.nu,
                sp,
                cp,
                math.tan(self.phi_rad),
                math.tan(self.psi_rad),
                self.c,
                self.flow_hyperbola,
                self.e,
                (3.0 - sp) / (6.0 * cp),
            ]
        )


# ---------------------------------------------------------------------------------------------
# Scalar formulas shared by the numpy functions (on arrays) and the numba kernel (on floats)
# ---------------------------------------------------------------------------------------------
def _mw_radius(theta, e):
    """Menetrey–Willam polar function r_MW(Theta, e) and its first two Theta-derivatives.

    r = [4(1-e^2)C^2 + (2e-1)^2] / [2(1-e^2)C + (2e-1) sqrt(4(1-e^2)C^2 + 5e^2 - 4e)], C = cos(Theta),
    valid for 0 <= Theta <= pi/3, where the root's argument is >= (2e-1)^2 (clamped there against
    round-off); r(0) = 1/e, r(pi/3) = 1 and r' = 0 at both ends (smooth on the meridians).
    """
    C = np.cos(theta)
    S = np.sin(theta)
    A = 1.0 - e * e
    B = 2.0 * e - 1.0
    s2 = np.maximum(4.0 * A * C * C + 5.0 * e * e - 4.0 * e, B * B)  # >= (2e-1)^2 for C >= 1/2
    s = np.sqrt(s2)
    den = 2.0 * A * C + B * s
    r = (4.0 * A * C * C + B * B) / den
    den_C = 2.0 * A + B * 4.0 * A * C / s
    r_C = (8.0 * A * C - r * den_C) / den
    den_CC = B * 4.0 * A * (5.0 * e * e - 4.0 * e) / (s * s2)
    r_CC = (8.0 * A - 2.0 * r_C * den_C - r * den_CC) / den
    return r, -S * r_C, S * S * r_CC - C * r_C


def _mc_radius(theta, sin_phi, cos_phi):
    """R_mc = sin(Theta + pi/3)/(sqrt(3) cos phi) + cos(Theta + pi/3) tan(phi)/3 and dR_mc/dTheta."""
    a = theta + PI3
    sa = np.sin(a)
    ca = np.cos(a)
    return (
        sa / (SQRT3 * cos_phi) + ca * sin_phi / (3.0 * cos_phi),
        ca / (SQRT3 * cos_phi) - sa * sin_phi / (3.0 * cos_phi),
    )


def _radius(x, y):
    """sqrt(x^2 + y^2), bit for bit the same in numpy and numba: the plain formula where neither
    square can overflow or underflow (a quarter of the cost of hypot in the kernel), hypot beyond."""
    big = np.maximum(np.abs(x), np.abs(y))
    safe = (big > 1e-150) & (big < 1e150)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        return np.where(safe, np.sqrt(x * x + y * y), np.hypot(x, y))


def _radius_scalar(x, y):
    """:func:`_radius` of two floats (numba)."""
    big = max(abs(x), abs(y))
    if 1e-150 < big < 1e150:
        return math.sqrt(x * x + y * y)
    return math.hypot(x, y)


def _elastic_trial(rr, zz, tt, rz, drr, dzz, dtt, drz, lam, mu):
    """sigma + lambda tr(d_eps) I + 2 mu d_eps (tensor shear), component by component."""
    lt = lam * (drr + dzz + dtt)
    return (
        rr + (lt + 2.0 * mu * drr),
        zz + (lt + 2.0 * mu * dzz),
        tt + (lt + 2.0 * mu * dtt),
        rz + 2.0 * mu * drz,
    )


def _compliance(drr, dzz, dtt, drz, E, nu, mu):
    """C^-1 d_sigma component by component: ((1 + nu) ds_i - nu tr(ds)) / E, ds_rz / (2 mu)."""
    tr = drr + dzz + dtt
    return (((1.0 + nu) * drr - nu * tr) / E, ((1.0 + nu) * dzz - nu * tr) / E,
            ((1.0 + nu) * dtt - nu * tr) / E, drz / (2.0 * mu))


def _rebuild_inplane(la, lb, cos2w, sin2w):
    """(rr, zz, rz) with in-plane eigenvalues la, lb on the axes given by (cos 2w, sin 2w)."""
    m = 0.5 * (la + lb)
    h = 0.5 * (la - lb)
    return m + h * cos2w, m - h * cos2w, h * sin2w


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


_radius_nb = _jit(_radius_scalar)
_mw_radius_nb = _jit(_mw_radius)
_mc_radius_nb = _jit(_mc_radius)
_elastic_trial_nb = _jit(_elastic_trial)
_compliance_nb = _jit(_compliance)
_rebuild_inplane_nb = _jit(_rebuild_inplane)
_theta_c_residual_nb = _jit(_theta_c_residual)
_inner_residual_nb = _jit(_inner_residual)
_outer_residual_nb = _jit(_outer_residual)
_tip_error_nb = _jit(_tip_error)


# ---------------------------------------------------------------------------------------------
# Invariants, yield function, flow potential (numpy, any leading shape)
# ---------------------------------------------------------------------------------------------
def _inplane(sigma):
    """(rr, zz, rz) block: eigenvalues la >= lb and (cos 2w, sin 2w) of the major eigenvector angle w."""
    rr, zz, rz = sigma[..., 0], sigma[..., 1], sigma[..., 3]
    m = 0.5 * (rr + zz)
    d = 0.5 * (rr - zz)
    rad = _radius(d, rz)
    pos = rad > 0.0
    safe = np.where(pos, rad, 1.0)
    return m + rad, m - rad, np.where(pos, d / safe, 1.0), np.where(pos, rz / safe, 0.0)


def _sort3(la, lb, tt):
    """Sort (la >= lb, tt) descending; returns s1, s2, s3 and the position (0, 1, 2) of tt."""
    pos = np.where(tt >= la, 0, np.where(tt >= lb, 1, 2))
    s1 = np.where(pos == 0, tt, la)
    s2 = np.where(pos == 0, la, np.where(pos == 1, tt, lb))
    s3 = np.where(pos == 2, tt, lb)
    return s1, s2, s3, pos


def _unsort3(s1, s2, s3, pos):
    """Inverse of :func:`_sort3`: returns la, lb, tt."""
    la = np.where(pos == 0, s2, s1)
    lb = np.where(pos == 2, s2, s3)
    tt = np.where(pos == 0, s1, np.where(pos == 1, s2, s3))
    return la, lb, tt


def _rebuild(la, lb, tt, cos2w, sin2w):
    """Tensor (rr, zz, tt, rz) with in-plane eigenvalues la, lb on the axes given by (cos 2w, sin 2w)."""
    rr, zz, rz = _rebuild_inplane(la, lb, cos2w, sin2w)
    return np.stack([rr, zz, tt, rz], axis=-1)


def principal_stresses(sigma):
    """Principal stresses sorted s1 >= s2 >= s3 (tension positive), shape (..., 3).

    sigma_tt is principal; the (rr, zz, rz) block has eigenvalues m +- sqrt(((rr-zz)/2)^2 + rz^2).
    """
    sigma = np.asarray(sigma, dtype=float)
    la, lb, _, _ = _inplane(sigma)
    s1, s2, s3, _ = _sort3(la, lb, sigma[..., 2])
    return np.stack([s1, s2, s3], axis=-1)


def _lode(s1, s2, s3):
    """q and Theta from sorted principal stresses: Theta = atan2(sqrt3 (s2 - s3), 2 s1 - s2 - s3)."""
    x = s1 - 0.5 * (s2 + s3)
    y = 0.5 * SQRT3 * (s2 - s3)
    return np.hypot(x, y), np.minimum(np.arctan2(y, x), PI3)


def invariants(sigma):
    """Invariants (p, q, r, Theta) of stresses of shape (..., 4) (see the module docstring).

    Theta is computed from the sorted principal stresses (``atan2`` form, accurate on the
    meridians); it satisfies cos(3 Theta) = (r/q)^3.  Theta = 0 where q = 0.
    """
    sigma = np.asarray(sigma, dtype=float)
    p = -(sigma[..., 0] + sigma[..., 1] + sigma[..., 2]) / 3.0
    S = np.stack([sigma[..., 0] + p, sigma[..., 1] + p, sigma[..., 2] + p, sigma[..., 3]], -1)
    scale = np.abs(S).max(-1)
    srr, szz, stt, rz = np.moveaxis(S / np.where(scale > 0.0, scale, 1.0)[..., None], -1, 0)
    r = scale * np.cbrt(13.5 * stt * (srr * szz - rz * rz))  # (9/2 S.S:S)^(1/3), S.S:S = 3 det S
    s = principal_stresses(sigma)
    q, theta = _lode(s[..., 0], s[..., 1], s[..., 2])
    return p, q, r, theta


def R_mc(Theta, phi):
    """Mohr–Coulomb deviatoric radius R_mc(Theta, phi), phi in radians."""
    return _mc_radius(np.asarray(Theta, dtype=float), math.sin(phi), math.cos(phi))[0]


def R_mw(Theta, e, phi):
    """Flow-potential deviatoric radius R_mw = r_MW(Theta, e) (3 - sin phi)/(6 cos phi), phi in rad."""
    r = _mw_radius(np.asarray(Theta, dtype=float), float(e))[0]
    return r * (3.0 - math.sin(phi)) / (6.0 * math.cos(phi))


def yield_function(sigma, mat: MohrCoulomb):
    """F = R_mc(Theta, phi) q - p tan(phi) - c (Pa); F <= 0 is admissible."""
    p, q, _, theta = invariants(sigma)
    return R_mc(theta, mat.phi_rad) * q - p * math.tan(mat.phi_rad) - mat.c


def flow_potential(sigma, mat: MohrCoulomb):
    """G = sqrt((eps c tan(psi))^2 + (R_mw q)^2) - p tan(psi) (Pa)."""
    p, q, _, theta = invariants(sigma)
    rw = R_mw(theta, mat.e, mat.phi_rad)
    return np.hypot(mat.flow_hyperbola, rw * q) - p * math.tan(mat.psi_rad)


def flow_direction(sigma, mat: MohrCoulomb):
    """dG/dsigma in the (rr, zz, tt, rz) tensor layout (the rz entry is the tensor component).

    G is isotropic, so dG/dsigma is coaxial with sigma; its principal values (sorted like s) are
    n_i = tan(psi)/3 + h R (R cos(Theta - a_i) - R' sin(Theta - a_i)), a_i = 0, 2pi/3, -2pi/3,
    with R = R_mw, h = q / sqrt(a^2 + R^2 q^2).  At q = 0 with a = eps c tan(psi) = 0 (the vertex
    of G) the deviatoric part is set to zero, giving the subgradient tan(psi)/3 I: never NaN.
    """
    sigma = np.asarray(sigma, dtype=float)
    la, lb, cos2w, sin2w = _inplane(sigma)
    s1, s2, s3, pos = _sort3(la, lb, sigma[..., 2])
    q, theta = _lode(s1, s2, s3)
    r, r1, _ = _mw_radius(theta, mat.e)
    rc3 = (3.0 - math.sin(mat.phi_rad)) / (6.0 * math.cos(mat.phi_rad))
    R, R1 = rc3 * r, rc3 * r1
    g = np.hypot(mat.flow_hyperbola, R * q)
    h = np.where(g > 0.0, q / np.where(g > 0.0, g, 1.0), 0.0)
    third = math.tan(mat.psi_rad) / 3.0
    n = [third + h * R * (R * np.cos(theta - a) - R1 * np.sin(theta - a))
         for a in (0.0, TWO_PI3, -TWO_PI3)]
    na, nb, ntt = _unsort3(*n, pos)
    return _rebuild(na, nb, ntt, cos2w, sin2w)


def elastic_stiffness(mat: MohrCoulomb):
    """4x4 matrix C with dsigma = C d_eps = lambda tr(d_eps) I + 2 mu d_eps (tensor shear layout)."""
    lam, mu = mat.lame_lambda, mat.shear_modulus
    C = np.full((4, 4), 0.0)
    C[:3, :3] = lam
    C[np.arange(4), np.arange(4)] += 2.0 * mu
    return C


def elastic_trial(sigma, d_eps, mat: MohrCoulomb):
    """Elastic predictor sigma + C d_eps, bit-identical to the one inside :func:`update`."""
    sigma, d_eps = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(d_eps, float))
    return np.stack(
        _elastic_trial(*np.moveaxis(sigma, -1, 0), *np.moveaxis(d_eps, -1, 0), mat.lame_lambda,
                       mat.shear_modulus),
        axis=-1,
    )


def plastic_strain_from_stress(d_sigma, mat: MohrCoulomb):
    """C^-1 d_sigma: eps_i = ((1 + nu) ds_i - nu tr(ds)) / E, eps_rz = ds_rz / (2 mu)."""
    d_sigma = np.asarray(d_sigma, dtype=float)
    return np.stack(_compliance(*np.moveaxis(d_sigma, -1, 0), mat.E, mat.nu, mat.shear_modulus), -1)


# ---------------------------------------------------------------------------------------------
# Return mapping, compiled kernel
# ---------------------------------------------------------------------------------------------
@_jit
def _unpack(prm):
    """(lambda, mu, K, E, nu, sin phi, cos phi, tan phi, tan psi, c, a, e, R_mc(pi/3))."""
    return (prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8], prm[9], prm[10],
            prm[11], prm[12])


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
_W_ROWS = 11
_F_VALID, _F_DONE, _F_OK = 0, 1, 2  # rows of the per-block flags


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
        _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, cst, False)
        _fast_final(m, p_tr, q_tr, ct, st, f, tau, valid, done, N1, N2, N3, ok, cst, False)
    else:
        _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, cst, True)
        _fast_final(m, p_tr, q_tr, ct, st, f, tau, valid, done, N1, N2, N3, ok, cst, True)


@_jit
def _fast_sweeps(m, q_tr, ct, st, f, tau, lo, hi, done, cst, hyperbolic):
    """The lockstep Halley sweeps of :func:`_fast_block` (the rows of its work arrays are passed
    one by one: LLVM vectorises the loop only when it can tell them apart; hyperbolic is compiled
    in as a constant).

    Each point iterates until it converges or has had _FAST_MAXIT sweeps, whatever the other
    points of the block do, so its result does not depend on which points share its block.
    When after 6 sweeps only a few points (at most 1/64 of the block) are still open, they are
    gathered and swept on their own (the same iterates, at a fraction of the cost).
    """
    for sweep in range(_FAST_MAXIT):
        n_open = _fast_sweep(m, sweep, q_tr, ct, st, f, tau, lo, hi, done, cst, hyperbolic)
        if n_open == 0:
            return
        if sweep >= 5 and 64 * n_open <= m and sweep + 1 < _FAST_MAXIT:
            break
    else:
        return
    rows = np.empty(n_open, dtype=np.int64)
    k = 0
    for j in range(m):
        if not done[j]:
            rows[k] = j
            k += 1
    sq, sct, sst, sf = q_tr[rows], ct[rows], st[rows], f[rows]
    stau, slo, shi, sdone = tau[rows], lo[rows], hi[rows], done[rows]
    for later in range(sweep + 1, _FAST_MAXIT):
        if _fast_sweep(n_open, later, sq, sct, sst, sf, stau, slo, shi, sdone, cst,
                       hyperbolic) == 0:
            break
    for k in range(n_open):
        j = rows[k]
        tau[j], lo[j], hi[j], done[j] = stau[k], slo[k], shi[k], sdone[k]


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
def _predict_block(sig, deps, b0, b1, prm, sig_out, dep_out, status, idx, pos, trial, S):
    """Pass 1 of :func:`_update_kernel` over the points b0:b1: elastic predictor, principal
    stresses and F.  Elastic points are written out; the plastic ones are gathered (their index,
    position of the hoop stress, trial stress and in-plane axes, sorted principal stresses and
    F_tr).  Returns their number."""
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    m = 0
    for i in range(b0, b1):
        rr, zz, tt, rz = _elastic_trial_nb(sig[i, 0], sig[i, 1], sig[i, 2], sig[i, 3], deps[i, 0],
                                           deps[i, 1], deps[i, 2], deps[i, 3], lam, mu)
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
            sig_out[i, 0], sig_out[i, 1], sig_out[i, 2], sig_out[i, 3] = rr, zz, tt, rz
            dep_out[i, 0] = dep_out[i, 1] = dep_out[i, 2] = dep_out[i, 3] = 0.0
            status[i] = ELASTIC
            continue
        if rad > 0.0:
            cw, sw = d / rad, rz / rad
        else:
            cw, sw = 1.0, 0.0
        idx[m], pos[m] = i, ps
        trial[0, m], trial[1, m], trial[2, m], trial[3, m] = rr, zz, tt, rz
        trial[4, m], trial[5, m] = cw, sw
        S[0, m], S[1, m], S[2, m], S[3, m] = s1, s2, s3, f
        m += 1
    return m


@_jit
def _update_kernel(sig, deps, prm, sig_out, dep_out, status):
    """Loop of :func:`update` over the points (rows) of sig and deps, writing into the outputs.

    Blocks of _BLOCK points: (1) elastic predictor, principal stresses and F; elastic points are
    written out, plastic ones gathered (:func:`_predict_block`); (2) the fast return of the
    gathered points in lockstep (:func:`_fast_block`); (3) each plastic point takes the fast
    result if it was accepted, else the robust :func:`_return_sorted` (the algorithm of
    update_reference), and its stress is rebuilt on the trial axes.
    """
    lam, mu, K, E, nu, sp, cp, tp, tpsi, c, a, e, rc3 = _unpack(prm)
    cst = _fast_constants(prm)
    n = sig.shape[0]
    nb = min(n, _BLOCK)
    idx = np.empty(nb, dtype=np.int64)
    pos = np.empty(nb, dtype=np.int8)
    trial = np.empty((6, nb))  # rr, zz, tt, rz and the in-plane axes (cos 2w, sin 2w)
    S = np.empty((4, nb))
    W = np.empty((_W_ROWS, nb))
    flags = np.empty((3, nb), dtype=np.bool_)
    for b0 in range(0, n, _BLOCK):
        m = _predict_block(sig, deps, b0, min(b0 + _BLOCK, n), prm, sig_out, dep_out, status, idx,
                           pos, trial, S)
        _fast_block(m, S, W, flags, cst)
        for j in range(m):
            i = idx[j]
            if flags[_F_OK, j]:
                n1, n2, n3, status[i] = W[_W_N1, j], W[_W_N2, j], W[_W_N3, j], PLASTIC
            else:
                n1, n2, n3, status[i] = _return_sorted(S[0, j], S[1, j], S[2, j], prm)
            if pos[j] == 0:
                na, nb_, ntt = n2, n3, n1
            elif pos[j] == 1:
                na, nb_, ntt = n1, n3, n2
            else:
                na, nb_, ntt = n1, n2, n3
            rr, zz, tt, rz = trial[0, j], trial[1, j], trial[2, j], trial[3, j]
            nrr, nzz, nrz = _rebuild_inplane_nb(na, nb_, trial[4, j], trial[5, j])
            sig_out[i, 0], sig_out[i, 1], sig_out[i, 2], sig_out[i, 3] = nrr, nzz, ntt, nrz
            dep_out[i, 0], dep_out[i, 1], dep_out[i, 2], dep_out[i, 3] = _compliance_nb(
                rr - nrr, zz - nzz, tt - ntt, rz - nrz, E, nu, mu)


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


# ---------------------------------------------------------------------------------------------
# Dense and loose material: the "disconnected" phase (Dunatunga & Kamrin 2015)
# ---------------------------------------------------------------------------------------------
def close_loose_volume(d_eps, loose):
    """Split a strain increment between closing loose volume and loading the grains.

    ``loose`` (>= 0, per point) is the volumetric strain by which the material is looser than
    dense: material at the stress-free apex that keeps dilating has separated (see
    :func:`separation_strain`), its grains are out of contact and it carries no stress until
    compression has closed that volume again.  A compressive increment (``tr d_eps < 0``) first
    closes ``closed = min(loose, -tr d_eps)``; only the rest, the fraction
    ``s = 1 - closed / (-tr d_eps)`` of the whole increment (volumetric and deviatoric: loose
    grains rearrange freely), loads the skeleton elastically.  Dilation leaves ``loose`` to
    :func:`separation_strain`.  Returns ``(s d_eps, loose - closed)``; arrays (N, 4) and (N,).
    """
    d_eps = np.asarray(d_eps, dtype=float)
    loose = np.asarray(loose, dtype=float)
    volumetric = d_eps[..., 0] + d_eps[..., 1] + d_eps[..., 2]
    compression = np.maximum(-volumetric, 0.0)
    closed = np.minimum(loose, compression)
    share = np.where(closed > 0.0, 1.0 - closed / np.where(closed > 0.0, compression, 1.0), 1.0)
    return d_eps * share[..., None], loose - closed


def separation_strain(d_eps_plastic, status):
    """Volumetric strain (>= 0) by which material separates: ``tr d_eps_p`` at apex returns.

    A return that reaches the apex of the yield surface (``status == APEX``; the stress-free
    state for a cohesionless material) means the increment has taken the grains out of
    contact: the plastic volume increase there, ``tr d_eps_p = tr d_eps - (p_old - p_apex)/K``,
    is loose volume, to be closed by compression before the material carries stress again
    (:func:`close_loose_volume`).  Regular returns (dilatant shear with psi > 0) keep the
    grains in contact and add nothing.
    """
    volumetric = (d_eps_plastic[..., 0] + d_eps_plastic[..., 1] + d_eps_plastic[..., 2])
    return np.where(np.asarray(status) == APEX, np.maximum(volumetric, 0.0), 0.0)


def equivalent_plastic_strain(d_eps_plastic):
    """Equivalent plastic strain increment ``sqrt(2/3 e:e)`` of tensor components (..., 4)."""
    e = np.asarray(d_eps_plastic, dtype=float)
    return np.sqrt(2.0 / 3.0 * (e[..., 0] ** 2 + e[..., 1] ** 2 + e[..., 2] ** 2
                                + 2.0 * e[..., 3] ** 2))


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


# ---------------------------------------------------------------------------------------------
# Element tests: one material point under mixed stress/strain control
# ---------------------------------------------------------------------------------------------
#: Laboratory paths of :func:`element_test`: the strain increment per unit of ``strain`` and the
#: stress-controlled strain modes (rows; see :func:`drive`).  Homogeneous axisymmetric
#: deformation u_r = eps_rr r has eps_tt = eps_rr, so the lateral mode of the triaxial test moves
#: both together and holds their mean stress.
PATHS = {
    "triaxial_compression": ((0.0, -1.0, 0.0, 0.0), ((1.0, 0.0, 1.0, 0.0),)),
    "triaxial_extension": ((0.0, 1.0, 0.0, 0.0), ((1.0, 0.0, 1.0, 0.0),)),
    "simple_shear": ((0.0, 0.0, 0.0, 0.5), ((0.0, 1.0, 0.0, 0.0),)),
    "oedometric": ((0.0, -1.0, 0.0, 0.0), ()),
}


@dataclass(frozen=True)
class ElementTestResult:
    """History of a material-point test; arrays have n_steps + 1 rows (row 0 = initial state).

    strain, plastic_strain: accumulated total and plastic strain (tensor shear layout);
    stress (Pa); status (n_steps,) of each update; residual (n_steps,) the largest violation (Pa)
    of the stress conditions after each step.
    """

    path: str
    strain: np.ndarray
    stress: np.ndarray
    plastic_strain: np.ndarray
    status: np.ndarray
    residual: np.ndarray

    @property
    def invariants(self):
        """(p, q, r, Theta) of every recorded stress."""
        return invariants(self.stress)

    @staticmethod
    def volumetric(eps):
        """tr(eps): positive for a volume increase (dilation)."""
        return eps[..., 0] + eps[..., 1] + eps[..., 2]

    @staticmethod
    def deviatoric(eps):
        """eps_q = sqrt(2/3 e:e), e = dev(eps) (the rz entry counted twice)."""
        e = eps[..., :3] - ElementTestResult.volumetric(eps)[..., None] / 3.0
        return np.sqrt(2.0 / 3.0 * ((e * e).sum(-1) + 2.0 * eps[..., 3] ** 2))


def drive(mat: MohrCoulomb, sigma0, d_eps, control=(), d_sigma=None, path="custom", max_iter=30,
          rtol=1e-13):
    """Drive one material point through strain increments with mixed stress/strain control.

    d_eps (n, 4): prescribed strain increments (tensor shear; normally orthogonal to the modes).
    control (m, 4): stress-controlled strain modes c_j; each step adds sum_j x_j c_j to d_eps and
    solves for x so that
    c_j . sigma = c_j . (sigma0 + accumulated d_sigma) (default d_sigma = 0: held).  E.g.
    c = (0, 1, 0, 0) holds sigma_zz; c = (1, 0, 1, 0) moves eps_rr = eps_tt together and holds
    sigma_rr + sigma_tt.  Newton's method with a forward-difference tangent of :func:`update`
    along the modes (elastic guess first), to |residual| <= rtol * max(|sigma|, 1 Pa).
    One point, not vectorised.
    """
    d_eps = np.atleast_2d(np.asarray(d_eps, dtype=float))
    n = d_eps.shape[0]
    c = np.asarray(control, dtype=float).reshape(-1, 4)
    m = c.shape[0]
    d_sigma = np.zeros((n, 4)) if d_sigma is None else np.broadcast_to(d_sigma, (n, 4))
    C = elastic_stiffness(mat)
    Ce = c @ C @ c.T  # elastic tangent of the conditions with respect to x
    sig = np.broadcast_to(np.asarray(sigma0, dtype=float), (4,)).copy()
    target = c @ sig
    eps, eps_p = np.zeros(4), np.zeros(4)
    hist = {"stress": [sig.copy()], "strain": [eps.copy()], "plastic": [eps_p.copy()]}
    status, residual = np.zeros(n, dtype=np.int8), np.zeros(n)
    for k in range(n):
        target = target + c @ d_sigma[k]
        x = np.linalg.solve(Ce, target - c @ (sig + C @ d_eps[k])) if m else np.zeros(0)
        for _ in range(max_iter):
            de = d_eps[k] + x @ c
            h = 1e-7 * max(np.abs(de).max(), 1e-12)
            s_new, dp_new, st = update(np.tile(sig, (m + 1, 1)), de + np.vstack([0.0 * de, h * c]),
                                       mat, return_status=True)
            r = c @ s_new[0] - target
            if m == 0 or np.abs(r).max() <= rtol * max(np.abs(s_new[0]).max(), 1.0):
                break
            J = (s_new[1:] @ c.T - (c @ s_new[0])[None, :]).T / h
            try:
                x = x - np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                x = x - np.linalg.solve(Ce, r)
        sig, eps, eps_p = s_new[0], eps + de, eps_p + dp_new[0]
        status[k] = st[0]
        residual[k] = np.abs(r).max() if m else 0.0
        hist["stress"].append(sig.copy())
        hist["strain"].append(eps.copy())
        hist["plastic"].append(eps_p.copy())
    return ElementTestResult(path, np.array(hist["strain"]), np.array(hist["stress"]),
                             np.array(hist["plastic"]), status, residual)


def element_test(mat: MohrCoulomb, path: str, sigma0, strain: float, n_steps: int = 100):
    """Classical laboratory path from the initial stress sigma0 (float: isotropic sigma0 I, Pa).

    ``strain`` (> 0) is the magnitude of the controlled strain, applied in n_steps equal steps:
    * triaxial_compression / triaxial_extension: axial strain eps_zz = -strain / +strain, lateral
      stress held (drained, constant confinement; eps_rr = eps_tt), eps_rz = 0;
    * simple_shear: engineering shear strain gamma_rz = 2 eps_rz = strain, sigma_zz held (constant
      normal stress), eps_rr = eps_tt = 0 (no lateral strain; the hoop direction plays the
      out-of-plane direction of plane-strain simple shear);
    * oedometric: eps_zz = -strain, eps_rr = eps_tt = eps_rz = 0 (pure strain control).
    """
    if path not in PATHS:
        raise ValueError(f"unknown element-test path {path!r}; choose one of {sorted(PATHS)}")
    unit, control = PATHS[path]
    sigma0 = np.asarray(sigma0, dtype=float)
    if sigma0.ndim == 0:
        sigma0 = sigma0 * np.array([1.0, 1.0, 1.0, 0.0])
    d_eps = np.tile(np.asarray(unit) * (strain / n_steps), (n_steps, 1))
    return drive(mat, sigma0, d_eps, control, path=path)
