"""The law's rate-dependent overstress in 3D: the μ(I) rise of :mod:`fipy_hopper.material.rate`
on six stress components, through the same seam as the sections.

The sections' equation (1): in a flowing cell (its last return was plastic) the momentum
balance adds ``Δσ = 2 η D'`` to the stored stress, ``D'`` the deviatoric strain rate, ``γ̇ =
√(2 D':D')`` and ``2 η`` the law's :func:`fipy_hopper.material.rate.overstress_factor` of the
pressure ``p = -tr σ / 3`` of the stored stress and ``γ̇`` (its rate parameters
``MohrCoulomb.rate_parameters()``: none for the plain law).  In 3D the strain rate has six
components ``(xx, yy, zz, yz, xz, xy)`` (tensor shear), so ``D':D'`` counts each shear term
twice:

    γ̇ = √(2 ((a² + b² + c²) + 2 ((D_yz² + D_xz²) + D_xy²))),  a, b, c = D_ii − tr D / 3.

:func:`deviatoric_rate6` is the compiled point function the 3D step calls,
:func:`overstress6` its numpy reference on arrays (the same arithmetic in the same order), and
:func:`overstress6_compiled` the point functions on arrays (for the tests).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..material.rate import overstress_factor

__all__ = ["deviatoric_rate6", "overstress6", "overstress6_compiled"]


@numba.njit(cache=True, error_model="numpy", inline="always")
def deviatoric_rate6(d0, d1, d2, d3, d4, d5):
    """``(D'_xx, D'_yy, D'_zz, γ̇)`` of a strain rate ``(xx, yy, zz, yz, xz, xy)`` (tensor
    shear): ``D' = D − tr D / 3 I``, ``γ̇ = √(2 D':D')`` (the shear terms counted twice)."""
    mean = ((d0 + d1) + d2) / 3.0
    a, b, c = d0 - mean, d1 - mean, d2 - mean
    return a, b, c, math.sqrt(2.0 * ((a * a + b * b + c * c)
                                     + 2.0 * ((d3 * d3 + d4 * d4) + d5 * d5)))


def overstress6(sigma, D, flowing, rate):
    """The overstress ``Δσ = 2 η D'`` (Pa, ``(..., 6)``) of stresses ``sigma`` (Pa, ``(...,
    6)``) at strain rates ``D`` (1/s, tensor shear) where ``flowing`` (else 0), with the rate
    parameters ``rate = [d, ρ_s, Δμ, I_0]``: the numpy reference of
    :func:`fipy_hopper.material.rate.overstress_factor` and :func:`deviatoric_rate6`, the same
    arithmetic in the same order."""
    sigma, D = np.asarray(sigma, float), np.asarray(D, float)
    d, rho_s, dmu, i0 = (float(x) for x in rate)
    p = -(sigma[..., 0] + sigma[..., 1] + sigma[..., 2]) / 3.0
    mean = ((D[..., 0] + D[..., 1]) + D[..., 2]) / 3.0
    a, b, c = D[..., 0] - mean, D[..., 1] - mean, D[..., 2] - mean
    shear = (D[..., 3] * D[..., 3] + D[..., 4] * D[..., 4]) + D[..., 5] * D[..., 5]
    gamma_dot = np.sqrt(2.0 * ((a * a + b * b + c * c) + 2.0 * shear))
    on = np.asarray(flowing, bool) & (p > 0.0) & (d != 0.0)
    p_safe = np.where(on, p, 1.0)
    s = np.sqrt(rho_s * p_safe)
    inertial = gamma_dot * d * s / p_safe
    with np.errstate(invalid="ignore", divide="ignore"):      # masked where not on
        two_eta = np.where(on, 2.0 * dmu * d * s / (i0 + inertial), 0.0)
    return np.stack([two_eta * a, two_eta * b, two_eta * c, two_eta * D[..., 3],
                     two_eta * D[..., 4], two_eta * D[..., 5]], axis=-1)


@numba.njit(cache=True, error_model="numpy")
def _overstress6_points(sigma, D, flowing, rate, out):
    for k in range(sigma.shape[0]):
        for c in range(6):
            out[k, c] = 0.0
        if not flowing[k]:
            continue
        p = -(sigma[k, 0] + sigma[k, 1] + sigma[k, 2]) / 3.0
        a, b, c_, gamma_dot = deviatoric_rate6(D[k, 0], D[k, 1], D[k, 2], D[k, 3], D[k, 4],
                                               D[k, 5])
        f = overstress_factor(p, gamma_dot, rate)
        out[k, 0], out[k, 1], out[k, 2] = f * a, f * b, f * c_
        out[k, 3], out[k, 4], out[k, 5] = f * D[k, 3], f * D[k, 4], f * D[k, 5]


def overstress6_compiled(sigma, D, flowing, rate):
    """The compiled overstress (Pa, ``(..., 6)``) of :func:`overstress6`'s arguments: the
    point functions the 3D step calls."""
    sigma, D = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(D, float))
    shape = sigma.shape
    flowing = np.broadcast_to(np.asarray(flowing, bool), shape[:-1])
    out = np.empty((int(np.prod(shape[:-1], dtype=int)), 6))
    _overstress6_points(np.ascontiguousarray(sigma.reshape(-1, 6)),
                        np.ascontiguousarray(D.reshape(-1, 6)),
                        np.ascontiguousarray(flowing.reshape(-1)),
                        np.ascontiguousarray(rate, dtype=float), out)
    return out.reshape(shape)
