"""Element tests: one material point under mixed stress/strain control.

:func:`drive` takes a point through prescribed strain increments while holding stress
combinations ``c_j . sigma`` (Newton on the compiled :func:`fipy_hopper.material.update`);
:func:`element_test` runs the classical laboratory paths of :data:`PATHS` (triaxial
compression and extension, simple shear, oedometric).  Stresses in Pa, tension positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .mohr_coulomb import ELASTIC, MohrCoulomb, elastic_stiffness, invariants
from .rate import overstress, overstress_compiled
from .return_fast import update

__all__ = ["ElementTestResult", "PATHS", "ShearLayerResult", "drive", "element_test", "shear_layer",
           "steady_simple_shear"]

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


def steady_simple_shear(mat: MohrCoulomb, normal_stress: float, gamma_dot: float,
                        strain: float = 0.05, n_steps: int = 100, compiled: bool = True) -> dict:
    """Simple shear at the shear rate ``gamma_dot`` (1/s) under a held normal stress
    ``sigma_zz = -normal_stress`` (Pa), from the isotropic state ``-normal_stress I`` to the
    engineering shear strain ``strain`` in ``n_steps`` steps (:func:`element_test`'s
    ``simple_shear``: the rate-independent return), then the law's rate-dependent overstress
    at the last step's strain rate ``D = d_eps / dt``, ``dt = strain / (gamma_dot n_steps)``
    (:func:`fipy_hopper.material.rate.overstress_compiled`, or its numpy reference with
    ``compiled=False``).

    Returns ``{"I", "p", "gamma_dot", "tau_plain", "tau", "mu_plain", "mu"}``: the inertial
    number ``gamma_dot d / sqrt(p / rho_s)`` of the flow (``gamma_dot = sqrt(2 D':D')``; 0
    for a plain law), the pressure ``p = -tr(sigma) / 3`` (Pa) of the rate-independent stress,
    the shear stresses ``|sigma_rz|`` without and with the overstress (Pa) and their ratios to
    ``p``.  In steady flow ``mu - mu_plain`` is the rise ``delta_mu I / (I_0 + I)`` of the
    mu(I) law."""
    res = element_test(mat, "simple_shear", -float(normal_stress), strain, n_steps)
    dt = strain / (gamma_dot * n_steps)
    D = (res.strain[-1] - res.strain[-2]) / dt
    sigma = res.stress[-1]
    flowing = res.status[-1] != ELASTIC
    rate = mat.rate_parameters()
    extra = (overstress_compiled if compiled else overstress)(sigma, D, flowing, rate)
    p = -(sigma[0] + sigma[1] + sigma[2]) / 3.0
    dev = D[:3] - D[:3].sum() / 3.0
    rate_of_shear = float(np.sqrt(2.0 * (dev @ dev + 2.0 * D[3] ** 2)))
    inertial = (rate_of_shear * rate[0] / np.sqrt(p / rate[1])) if rate[0] > 0 else 0.0
    tau_plain, tau = abs(sigma[3]), abs(sigma[3] + extra[3])
    return {"I": float(inertial), "p": float(p), "gamma_dot": rate_of_shear,
            "tau_plain": float(tau_plain), "tau": float(tau),
            "mu_plain": float(tau_plain / p), "mu": float(tau / p)}


@dataclass(frozen=True)
class ShearLayerResult:
    """A plane shear layer driven at its top (:func:`shear_layer`): node heights ``y`` (m,
    from the fixed bottom), node speeds ``u`` (m/s), the cells' pressure ``p`` (Pa) and
    total shear stress ``tau`` (Pa, the overstress included), the time reached (s)."""

    y: np.ndarray
    u: np.ndarray
    p: np.ndarray
    tau: np.ndarray
    t: float

    def band_width(self, fraction: float = 0.05) -> float:
        """The depth (m) below the moving top over which the speed falls to ``fraction`` of
        the top's (linear between nodes): the shear band's width."""
        top = self.u[-1]
        below = np.flatnonzero(self.u < fraction * top)
        if below.size == 0:
            return float(self.y[-1] - self.y[0])
        k = below[-1]                       # the highest node below the fraction
        u0, u1 = self.u[k], self.u[k + 1]
        y = self.y[k] + (fraction * top - u0) / (u1 - u0) * (self.y[k + 1] - self.y[k])
        return float(self.y[-1] - y)


def shear_layer(mat: MohrCoulomb, depth: float, cells: int, speed: float, top_pressure: float,
                gravity: float = 9.81, duration: float = 0.5, dt_safety: float = 0.4,
                compiled: bool = True) -> ShearLayerResult:
    """A horizontal plane layer of the law ``mat`` (depth ``depth`` m, ``cells`` cells) under
    gravity and a top pressure ``top_pressure`` (Pa), its bottom held and its top moved
    sideways at ``speed`` (m/s) for ``duration`` s from rest: the shear band the law forms
    under its moving top.

    One horizontal velocity ``u(y)`` (nodes), simple shear in each cell (``D_xy = du/dy /
    2``, the layout ``(rr, zz, tt, rz)`` read as ``(xx, yy, zz, xy)``, ``zz`` out of the
    plane), the Jaumann rotation, the law's return (:meth:`MohrCoulomb.update` or
    ``update_reference``) and, where the return was plastic, the law's rate-dependent
    overstress (:func:`fipy_hopper.material.rate.overstress_compiled` or its numpy
    reference); ``rho h du/dt = tau_above - tau_below`` with ``tau`` the total shear stress,
    explicit with ``dt = dt_safety h / c_p``.  The initial stress is isotropic,
    ``p(y) = top_pressure + rho g (depth - y)``; with no volume change (``psi = 0``) the
    pressure keeps that profile, so the shear stress that the layer carries in steady flow
    rises above the plain law's yield only near the top, where ``p`` is least: the band.  A
    plain law concentrates it in the top cell; the grain size gives it a width of its own."""
    h = depth / cells
    y = h * np.arange(cells + 1)
    y_c = 0.5 * (y[1:] + y[:-1])
    p0 = top_pressure + mat.rho * gravity * (depth - y_c)
    sigma = np.zeros((cells, 4))
    sigma[:, :3] = -p0[:, None]
    u = np.zeros(cells + 1)
    u[-1] = speed
    flowing = np.zeros(cells, dtype=bool)
    rate = mat.rate_parameters()
    update_fn = mat.update if compiled else mat.update_reference
    over_fn = overstress_compiled if compiled else overstress
    dt = dt_safety * h / mat.p_wave_speed
    steps = int(math.ceil(duration / dt))
    m = mat.rho * h
    D = np.zeros((cells, 4))
    tau = np.zeros(cells)
    for _ in range(steps):
        gamma = np.diff(u) / h                       # du/dy per cell
        D[:, 3] = 0.5 * gamma
        tau = sigma[:, 3] + over_fn(sigma, D, flowing, rate)[:, 3]
        u[1:-1] += dt * (tau[1:] - tau[:-1]) / m
        gamma = np.diff(u) / h
        w = 0.5 * gamma * dt                         # spin W_xy dt
        rotated = sigma.copy()
        rotated[:, 0] += 2.0 * w * sigma[:, 3]
        rotated[:, 1] -= 2.0 * w * sigma[:, 3]
        rotated[:, 3] += w * (sigma[:, 1] - sigma[:, 0])
        d_eps = np.zeros((cells, 4))
        d_eps[:, 3] = 0.5 * gamma * dt
        sigma, _, status = update_fn(rotated, d_eps, return_status=True)
        flowing = status != ELASTIC
    D[:, 3] = 0.5 * np.diff(u) / h
    tau = sigma[:, 3] + over_fn(sigma, D, flowing, rate)[:, 3]
    p = -(sigma[:, 0] + sigma[:, 1] + sigma[:, 2]) / 3.0
    return ShearLayerResult(y=y, u=u.copy(), p=p, tau=tau, t=steps * dt)
