"""The rate dependence above the Mohr–Coulomb limit: the μ(I) overstress, with the grain size d.

The Mohr–Coulomb law in the Abaqus form has no length and no rate.  Dense granular flow has both:
the friction of a flowing layer rises with the inertial number (GDR MiDi 2004; Jop, Forterre &
Pouliquen 2006)

    I = γ̇ d / √(p / ρ_s),        μ(I) = μ_s + Δμ I / (I_0 + I),

with ``γ̇`` the shear rate (1/s), ``d`` the grain diameter (m), ``p`` the pressure (Pa), ``ρ_s``
the grains' density (kg/m³), ``Δμ = μ_2 − μ_s`` the rise of the friction from slow to fast flow
and ``I_0`` the inertial number at which half of it is reached.

Here the quasi-static part ``μ_s`` is the Mohr–Coulomb law itself (its return gives the stress
on the yield surface, rate independent), and only the rise is added, as an *overstress* in the
material that is flowing (whose last return was plastic):

    σ = σ_MC + Δσ,    Δσ = Δμ(I) p · 2 D' / γ̇ = 2 η D',    γ̇ = √(2 D':D'),
    Δμ(I) = Δμ I / (I_0 + I),
    2 η = 2 Δμ(I) p / γ̇ = 2 Δμ d √(ρ_s p) / (I_0 + I)                                   (1)

``D'`` the deviatoric strain rate (1/s), ``p = −tr σ_MC / 3`` the pressure of the rate-independent
stress.  In simple shear at rate γ̇ the overstress is a shear stress ``Δμ(I) p``: the
shear-to-pressure ratio of the flowing material is the Mohr–Coulomb one plus ``Δμ(I)``.  At rest,
in elastic material and as ``γ̇ → 0`` the overstress vanishes, so statics is the plain law's;
for ``I ≪ I_0`` it is a viscosity ``η = Δμ d √(ρ_s p) / I_0`` (Pa s) proportional to the grain
size — the length the plain law lacks; for ``I ≫ I_0`` it saturates at ``Δμ p``.  Where the
stress is zero (loose material, the stress-free apex) there is none.

The overstress is a function of the current strain rate, so it is not stored in the
stress the material carries (which stays on or inside the Mohr–Coulomb surface): the momentum
balance adds it to the stored stress of each flowing cell in the internal forces, each step, from
that step's velocities.  Written once, dimension free: :func:`overstress_factor` (compiled, one
point) gives ``2 η`` from ``p`` and ``γ̇``; :func:`overstress` (numpy) is its reference on arrays
of axisymmetric stresses and strain rates ``(rr, zz, tt, rz)`` (tensor shear).

Default parameters (:class:`InertialRheology`): ``Δμ = 0.26`` and ``I_0 = 0.28``, the fit of
Jop, Forterre & Pouliquen (2006, Nature 441:727) for glass beads (μ_s = tan 20.9°, μ_2 =
tan 32.76°, I_0 = 0.279), the values continuum silo studies use for sand-like materials;
``ρ_s = 2650`` kg/m³ (quartz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numba
import numpy as np

__all__ = ["InertialRheology", "inertial_number", "friction_rise", "overstress",
           "overstress_compiled", "deviatoric_rate",
           "overstress_factor", "RATE_PARAMETERS"]

#: the rate parameters in the order the compiled kernels read them (after the law's own)
RATE_PARAMETERS = ("grain_diameter", "grain_density", "friction_rise", "inertial_number_i0")


@dataclass(frozen=True)
class InertialRheology:
    """The μ(I) rise above the Mohr–Coulomb limit (module docstring, equation (1)).

    ``grain_diameter`` d (m, > 0), ``grain_density`` ρ_s (kg/m³, > 0), ``friction_rise``
    Δμ = μ_2 − μ_s (> 0), ``inertial_number_i0`` I_0 (> 0)."""

    grain_diameter: float = 1.0e-3
    grain_density: float = 2650.0
    friction_rise: float = 0.26
    inertial_number_i0: float = 0.28

    UNITS: ClassVar[dict] = {"grain_diameter": "m", "grain_density": "kg/m3",
                             "friction_rise": "-", "inertial_number_i0": "-"}

    def __post_init__(self):
        for name in RATE_PARAMETERS:
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"InertialRheology: {name} = {value!r} is not a number") \
                    from None
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"InertialRheology: {name} = {value!r} is outside the allowed "
                                 f"range (0, inf)")
            object.__setattr__(self, name, value)

    def kernel_parameters(self) -> np.ndarray:
        """``[d, ρ_s, Δμ, I_0]``, the layout :func:`overstress_factor` reads."""
        return np.array([getattr(self, name) for name in RATE_PARAMETERS])

    def viscosity_bound(self, p: float) -> float:
        """The largest η of equation (1) at pressure ``p`` (Pa): ``Δμ d √(ρ_s p) / I_0`` (Pa s),
        reached as ``γ̇ → 0``."""
        return (self.friction_rise * self.grain_diameter
                * math.sqrt(self.grain_density * max(p, 0.0)) / self.inertial_number_i0)


#: no rate dependence: the kernel parameters of a plain law (``d = 0`` switches it off)
NO_RATE = np.zeros(len(RATE_PARAMETERS))


def inertial_number(gamma_dot, p, d, rho_s):
    """``I = γ̇ d / √(p / ρ_s)`` (numpy; ``inf`` where ``p <= 0`` and ``γ̇ > 0``)."""
    gamma_dot, p = np.asarray(gamma_dot, float), np.asarray(p, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(p > 0.0, gamma_dot * d / np.sqrt(np.where(p > 0.0, p, 1.0) / rho_s),
                        np.where(gamma_dot > 0.0, np.inf, 0.0))


def friction_rise(I, rheology: InertialRheology):
    """``Δμ(I) = Δμ I / (I_0 + I)``: the friction the flow adds to the Mohr–Coulomb law's."""
    I = np.asarray(I, float)
    dmu, i0 = rheology.friction_rise, rheology.inertial_number_i0
    return np.where(np.isinf(I), dmu, dmu * I / (i0 + np.where(np.isinf(I), 0.0, I)))


@numba.njit(cache=True, error_model="numpy", inline="always")
def overstress_factor(p, gamma_dot, rate):
    """``2 η`` (Pa s) of equation (1) at pressure ``p`` (Pa) and shear rate ``γ̇`` (1/s) with the
    rate parameters ``rate = [d, ρ_s, Δμ, I_0]`` (:data:`RATE_PARAMETERS`): ``2 Δμ d √(ρ_s p) /
    (I_0 + I)`` with ``I = γ̇ d √(ρ_s p) / p``; 0 where ``p <= 0`` or ``d = 0`` (no rate
    dependence).  The same arithmetic as :func:`overstress` (numpy)."""
    d = rate[0]
    if not (p > 0.0) or d == 0.0:
        return 0.0
    s = math.sqrt(rate[1] * p)
    inertial = gamma_dot * d * s / p
    return 2.0 * rate[2] * d * s / (rate[3] + inertial)


@numba.njit(cache=True, error_model="numpy", inline="always")
def deviatoric_rate(d_rr, d_zz, d_tt, d_rz):
    """``(D'_rr, D'_zz, D'_tt, γ̇)`` of an axisymmetric strain rate (tensor shear ``d_rz``):
    ``D' = D − tr D / 3 I``, ``γ̇ = √(2 D':D')`` (``rz`` counted twice).  The same arithmetic
    as :func:`overstress`."""
    mean = ((d_rr + d_zz) + d_tt) / 3.0
    a, b, c = d_rr - mean, d_zz - mean, d_tt - mean
    return a, b, c, math.sqrt(2.0 * (a * a + b * b + c * c + 2.0 * (d_rz * d_rz)))


def overstress(sigma, D, flowing, rate):
    """The overstress ``Δσ = 2 η D'`` of equation (1) (Pa, ``(..., 4)``, ``rr, zz, tt, rz``) of
    stresses ``sigma`` (Pa) at strain rates ``D`` (1/s, tensor shear) where ``flowing`` (else 0),
    with ``rate = [d, ρ_s, Δμ, I_0]``: the numpy reference of :func:`overstress_factor` and
    :func:`deviatoric_rate`, the same arithmetic in the same order."""
    sigma, D = np.asarray(sigma, float), np.asarray(D, float)
    d, rho_s, dmu, i0 = (float(x) for x in rate)
    p = -(sigma[..., 0] + sigma[..., 1] + sigma[..., 2]) / 3.0
    mean = ((D[..., 0] + D[..., 1]) + D[..., 2]) / 3.0
    a, b, c = D[..., 0] - mean, D[..., 1] - mean, D[..., 2] - mean
    gamma_dot = np.sqrt(2.0 * (a * a + b * b + c * c + 2.0 * (D[..., 3] * D[..., 3])))
    on = np.asarray(flowing, bool) & (p > 0.0) & (d != 0.0)
    p_safe = np.where(on, p, 1.0)
    s = np.sqrt(rho_s * p_safe)
    inertial = gamma_dot * d * s / p_safe
    with np.errstate(invalid="ignore", divide="ignore"):      # masked where not on
        two_eta = np.where(on, 2.0 * dmu * d * s / (i0 + inertial), 0.0)
    return np.stack([two_eta * a, two_eta * b, two_eta * c, two_eta * D[..., 3]], axis=-1)


@numba.njit(cache=True, error_model="numpy")
def _overstress_points(sigma, D, flowing, rate, out):
    """:func:`overstress_factor` and :func:`deviatoric_rate` over points ``(n, 4)``: the
    compiled overstress the fused step adds, on arrays (for the tests and the drivers)."""
    for k in range(sigma.shape[0]):
        out[k, 0] = out[k, 1] = out[k, 2] = out[k, 3] = 0.0
        if not flowing[k]:
            continue
        p = -(sigma[k, 0] + sigma[k, 1] + sigma[k, 2]) / 3.0
        a, b, c, gamma_dot = deviatoric_rate(D[k, 0], D[k, 1], D[k, 2], D[k, 3])
        f = overstress_factor(p, gamma_dot, rate)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = f * a, f * b, f * c, f * D[k, 3]


def overstress_compiled(sigma, D, flowing, rate):
    """The compiled overstress (Pa, ``(..., 4)``) of :func:`overstress`'s arguments: the same
    point functions the fused step calls (:func:`overstress_factor`, :func:`deviatoric_rate`)."""
    sigma, D = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(D, float))
    shape = sigma.shape
    flowing = np.broadcast_to(np.asarray(flowing, bool), shape[:-1])
    out = np.empty((int(np.prod(shape[:-1], dtype=int)), 4))
    _overstress_points(np.ascontiguousarray(sigma.reshape(-1, 4)),
                       np.ascontiguousarray(D.reshape(-1, 4)),
                       np.ascontiguousarray(flowing.reshape(-1)),
                       np.ascontiguousarray(rate, dtype=float), out)
    return out.reshape(shape)
