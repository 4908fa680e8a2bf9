"""The Mohr–Coulomb law in the Abaqus form, on arrays of axisymmetric stress states.

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
* Elasticity: ``dsigma = lambda tr(d_eps) I + 2 mu d_eps``.

Holds the material parameters (:class:`MohrCoulomb`, and the float array of the compiled kernels,
:func:`_unpack`), the scalar formulas shared by the numpy functions and the numba kernels (with
their compiled copies ``*_nb``), the invariants, yield function, flow potential and direction,
the elastic predictor and compliance, the status codes of a return and the equivalent plastic
strain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

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
    "equivalent_plastic_strain",
    "ELASTIC",
    "PLASTIC",
    "APEX",
]

SQRT3 = math.sqrt(3.0)
PI3 = math.pi / 3.0
TWO_PI3 = 2.0 * math.pi / 3.0

#: Status codes returned by :func:`fipy_hopper.material.update` with ``return_status=True``.
ELASTIC, PLASTIC, APEX = 0, 1, 2

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

    ``rate``: the rate dependence above the yield surface, an
    :class:`~fipy_hopper.material.rate.InertialRheology` (the μ(I) overstress with the grain
    size d, :mod:`fipy_hopper.material.rate`), or ``None``: the plain rate-independent law of
    the published method.  It does not change the return (:meth:`update`): the overstress is a
    function of the strain rate that the momentum balance adds in flowing material
    (:meth:`overstress_reference`, :meth:`rate_parameters`).
    """

    E: float
    nu: float
    rho: float
    phi: float
    psi: float = 0.0
    c: float = 0.0
    eps: float = 0.1
    e: float | None = None
    rate: object = None

    #: per-point state carried besides the stress (transported with the material):
    #: the equivalent plastic strain
    internal_variables: ClassVar[tuple] = ("eps_p",)
    #: unit of each parameter
    UNITS: ClassVar[dict] = {"E": "Pa", "nu": "-", "rho": "kg/m3", "phi": "deg", "psi": "deg",
                             "c": "Pa", "eps": "-", "e": "-"}

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
        from .rate import InertialRheology
        if self.rate is not None and not isinstance(self.rate, InertialRheology):
            raise ValueError(f"MohrCoulomb: rate = {self.rate!r} is not an InertialRheology "
                             f"or None")

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
        """c_p = sqrt(M / rho) = sqrt(E (1 - nu) / ((1 + nu)(1 - 2 nu) rho)) (m/s)."""
        E, nu = self.E, self.nu
        return math.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * self.rho))

    # the law's side of the material seam (fipy_hopper.material.law) ----------------------------
    def parameters(self) -> dict:
        """``{name: (value, unit)}`` of every parameter (SI; angles in degrees), the rate
        dependence's included."""
        own = {name: (getattr(self, name), unit) for name, unit in self.UNITS.items()}
        if self.rate is not None:
            own.update({name: (getattr(self.rate, name), unit)
                        for name, unit in self.rate.UNITS.items()})
        return own

    def rate_parameters(self) -> np.ndarray:
        """``[d, rho_s, delta_mu, I_0]`` of the rate dependence for the compiled overstress
        (:func:`fipy_hopper.material.rate.overstress_factor`); zeros (none) for the plain law."""
        from .rate import NO_RATE
        return NO_RATE.copy() if self.rate is None else self.rate.kernel_parameters()

    def overstress_reference(self, sigma, D, flowing):
        """The rate-dependent overstress ``2 eta D'`` (Pa, ``(..., 4)``) of stresses ``sigma``
        at strain rates ``D`` (1/s) where ``flowing``: :func:`fipy_hopper.material.rate.
        overstress` (zero for the plain law)."""
        from .rate import overstress
        return overstress(sigma, D, flowing, self.rate_parameters())

    def stable_time_step(self, h: float, safety: float) -> float:
        """The explicit step ``safety * h / c_p`` (s) on cells of size ``h`` (m)."""
        return safety * h / self.p_wave_speed

    def update(self, sigma, d_eps, return_status: bool = False):
        """The compiled stress update (:func:`fipy_hopper.material.update`)."""
        from .return_fast import update
        return update(sigma, d_eps, self, return_status=return_status)

    def update_reference(self, sigma, d_eps, return_status: bool = False):
        """The numpy reference of the update (:func:`fipy_hopper.material.update_reference`)."""
        from .return_reference import update_reference
        return update_reference(sigma, d_eps, self, return_status=return_status)

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


_radius_nb = _jit(_radius_scalar)
_mw_radius_nb = _jit(_mw_radius)
_mc_radius_nb = _jit(_mc_radius)
_elastic_trial_nb = _jit(_elastic_trial)
_compliance_nb = _jit(_compliance)
_rebuild_inplane_nb = _jit(_rebuild_inplane)


@_jit
def _unpack(prm):
    """(lambda, mu, K, E, nu, sin phi, cos phi, tan phi, tan psi, c, a, e, R_mc(pi/3))."""
    return (prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8], prm[9], prm[10],
            prm[11], prm[12])


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


def equivalent_plastic_strain(d_eps_plastic):
    """Equivalent plastic strain increment ``sqrt(2/3 e:e)`` of tensor components (..., 4)."""
    e = np.asarray(d_eps_plastic, dtype=float)
    return np.sqrt(2.0 / 3.0 * (e[..., 0] ** 2 + e[..., 1] ** 2 + e[..., 2] ** 2
                                + 2.0 * e[..., 3] ** 2))
