"""Dense and loose material: the "disconnected" phase (Dunatunga & Kamrin 2015).

A closure of the mixture model around the constitutive law's update (the law itself knows
nothing of it, :mod:`fipy_hopper.material.law`): the models call :func:`close_loose_volume`
before the law's stress update and :func:`separation_strain` after it.

Material returned to the stress-free apex that keeps dilating has separated: the volumetric
plastic strain of apex returns, ``tr d_eps_p`` (:func:`separation_strain`), is loose volume
``e_l >= 0``, and a later compressive increment first closes it (:func:`close_loose_volume`)
before the rest loads the grains.  Strains are dimensionless, tensor shear component.
"""

from __future__ import annotations

import numpy as np

from .material.mohr_coulomb import APEX

__all__ = ["close_loose_volume", "separation_strain"]

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
