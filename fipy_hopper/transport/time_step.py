"""Time-step rule of the transport: the CFL condition of the explicit step (2).

``dt sum_out F <= cfl max(kappa, kappa_min) V`` in every open cell (``F`` in m^3/s per radian,
``V`` in m^3 per radian, ``dt`` in s); ``cfl = 0.5`` keeps the ``"axisymmetric"`` update positive
(:mod:`fipy_hopper.transport.vanleer`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["KAPPA_CFL_MIN", "max_stable_dt", "outgoing_volume_flux"]

#: Default guard of ``max_stable_dt``: a cell limits the time step as if it were at least this
#: open (see ``max_stable_dt``).
KAPPA_CFL_MIN = 0.1


# --------------------------------------------------------------------------------------------
# Time-step rule
# --------------------------------------------------------------------------------------------

def outgoing_volume_flux(geom, u_n):
    """Total outgoing volume flux ``sum_faces max(F_out, 0)`` of every cell (m^3/s per rad).

    Counts interior faces and outflow faces only (other exterior faces carry nothing).
    """
    volume_flux = geom.volume_flux(u_n)
    return _outgoing_kernel(geom.face_cell_1, geom.face_cell_2, geom.interior, geom.outflow,
                            volume_flux, geom.n_cells)


@njit(cache=True)
def _outgoing_kernel(face_cell_1, face_cell_2, interior, outflow, volume_flux, n_cells):
    """Compiled sum of ``max(F, 0)`` out of cell 1 and ``max(-F, 0)`` out of cell 2."""
    out = np.zeros(n_cells)
    for f in interior:
        flux = volume_flux[f]
        if flux > 0.0:
            out[face_cell_1[f]] += flux
        else:
            out[face_cell_2[f]] -= flux
    for f in outflow:
        out[face_cell_1[f]] += max(volume_flux[f], 0.0)
    return out


def max_stable_dt(geom, u_n, cfl=0.5, alpha=None, alpha_min=1e-3, kappa_min=KAPPA_CFL_MIN):
    """Largest ``dt`` with ``dt sum_out F <= cfl max(kappa, kappa_min) V`` in every open cell.

    Guard for cut cells: a cell limits ``dt`` as if it were at least ``kappa_min`` open (default
    0.1), so slivers at the wall do not shrink the step; what such a sliver overdraws or
    overfills is put right by ``redistribute_overshoot``.  Solid cells have closed faces and
    never limit.  ``cfl = 0.5`` keeps the ``"axisymmetric"`` update positive
    (:mod:`fipy_hopper.transport.vanleer`).

    Material-weighted variant: given ``alpha`` (nCells), only cells holding material
    (``alpha >= alpha_min``) limit ``dt``; empty cells carry (next to) nothing out, and light
    cells of a falling jet (fast, nearly empty) are left to the boundedness rule.

    Returns ``inf`` if nothing moves.
    """
    out = outgoing_volume_flux(geom, u_n)
    capacity = np.maximum(geom.kappa, kappa_min) * geom.cell_volume
    limiting = out > 0.0
    if alpha is not None:
        limiting &= np.asarray(alpha) >= alpha_min
    if not np.any(limiting):
        return np.inf
    return float(cfl * np.min(capacity[limiting] / out[limiting]))
