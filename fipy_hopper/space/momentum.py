"""Trilinear (8-node) Galerkin momentum on the 3D grid's nodes: the numpy reference.

Cells ``(nz, ny, nx)``, nodes ``(nz + 1, ny + 1, nx + 1)``, velocities ``(3, nz + 1, ny + 1,
nx + 1)`` (``v_x, v_y, v_z``, m/s), stresses ``(nz, ny, nx, 6)`` in the law's order ``(xx, yy,
zz, yz, xz, xy)`` (Pa, tension positive), masses kg, forces N (of the computed part).

The element is the cube of side ``h`` with one-point (centre) quadrature.  Its corners ``a =
di + 2 dj + 4 dk`` (``di, dj, dk`` in {0, 1}) carry the signs ``xi = 2 di - 1``, ``eta = 2 dj -
1``, ``zeta = 2 dk - 1``; at the centre ``N_a = 1/8`` and ``grad N_a = (xi, eta, zeta) / (4 h)``.

* Lumped mass ``m_a = sum_c rho alpha_c w_c / 8``, ``w_c = kappa_c h^3`` the open volume.
* Internal force ``f_a = sum_c w_c s_c . grad N_a`` with ``s = alpha sigma`` the mixture stress
  (``-f`` drives the nodes).
* Hourglass control: one-point quadrature leaves the four modes ``Gamma^1..4 = xi eta, eta
  zeta, xi zeta, xi eta zeta`` (per component) without stiffness; a viscous force acts on them
  only, ``f_a = -C_c sum_m Gamma^m_a (Gamma^m . v_c)``, ``C_c = kappa_hg rho sqrt(g h) alpha_c
  w_c / (4 h)``: the sections' control with its coefficient's ``1/4`` for the eight corners, so
  that each mode (a checkerboard in one plane or in three) decays at the sections' rate
  ``16 kappa_hg sqrt(g / h)`` (tested).
* Strain rate and spin: ``L = grad v = sum_a v_a (x) grad N_a`` at the centre, ``D = (L +
  L^T)/2`` (six components, tensor shear), ``W = (L - L^T)/2`` as ``(W_yz, W_xz, W_xy)`` with
  ``W_ij = (dv_i/dx_j - dv_j/dx_i)/2``; the stress is rotated first with the Jaumann rate,
  ``sigma += (W sigma - sigma W) dt``.
* Open divergence: the net outflow of the face velocities (each face's the mean of its four
  nodes, along the face's axis) through the open face areas over the open volume
  ``kappa h^3``: ``div = sum_axes (a_+ u_+ - a_- u_-) / (kappa h)``; in a full cell the Q1
  ``tr D`` (tested).  It replaces the volumetric part of ``D dt`` in the stress update, as in
  the sections.
"""

from __future__ import annotations

import numpy as np

#: corner offsets (dk, dj, di) of a = di + 2 dj + 4 dk and their signs (xi, eta, zeta)
CORNERS = tuple(((a >> 2) & 1, (a >> 1) & 1, a & 1) for a in range(8))
SIGNS = np.array([[2 * di - 1, 2 * dj - 1, 2 * dk - 1] for dk, dj, di in CORNERS], dtype=float)
#: the four hourglass base vectors (rows) at the corners: xi eta, eta zeta, xi zeta, xi eta zeta
HOURGLASS = np.array([SIGNS[:, 0] * SIGNS[:, 1], SIGNS[:, 1] * SIGNS[:, 2],
                      SIGNS[:, 0] * SIGNS[:, 2], SIGNS[:, 0] * SIGNS[:, 1] * SIGNS[:, 2]])
#: (i, j) of the six components of a symmetric tensor (the law's order) and of the spin's
PAIRS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
SPIN = ((1, 2), (0, 2), (0, 1))


def _corner(arr, dk, dj, di, shape):
    """The view of node array ``arr`` (..., nz + 1, ny + 1, nx + 1) at corner (dk, dj, di)
    of every cell (..., nz, ny, nx)."""
    nz, ny, nx = shape
    return arr[..., dk:dk + nz, dj:dj + ny, di:di + nx]


def scatter_to_nodes(cell_values: np.ndarray) -> np.ndarray:
    """Sum ``cell_values / 8`` onto the eight nodes of each cell, corners in order 0..7."""
    shape = cell_values.shape[-3:]
    out = np.zeros(cell_values.shape[:-3] + tuple(n + 1 for n in shape))
    q = 0.125 * cell_values
    for dk, dj, di in CORNERS:
        _corner(out, dk, dj, di, shape)[...] += q
    return out


def node_mass(rho: float, alpha: np.ndarray, open_volume: np.ndarray) -> np.ndarray:
    """Lumped nodal mass ``m_a = sum_c rho alpha_c w_c / 8`` (kg)."""
    return scatter_to_nodes(rho * alpha * open_volume)


def corner_forces(stress, open_volume, h):
    """``w_c s_c . grad N_a`` of every corner: ``(8, 3, nz, ny, nx)`` (N)."""
    s = stress * open_volume[..., None]
    g = 1.0 / (4.0 * h)
    out = np.empty((8, 3) + open_volume.shape)
    for a in range(8):
        xi, eta, zeta = SIGNS[a] * g
        out[a, 0] = xi * s[..., 0] + eta * s[..., 5] + zeta * s[..., 4]
        out[a, 1] = xi * s[..., 5] + eta * s[..., 1] + zeta * s[..., 3]
        out[a, 2] = xi * s[..., 4] + eta * s[..., 3] + zeta * s[..., 2]
    return out


def gather(contrib):
    """Node sums ``(3, nz + 1, ny + 1, nx + 1)`` of corner values ``(8, 3, nz, ny, nx)``,
    added from 0 in the order of the corners."""
    shape = contrib.shape[-3:]
    out = np.zeros((3,) + tuple(n + 1 for n in shape))
    for a, (dk, dj, di) in enumerate(CORNERS):
        _corner(out, dk, dj, di, shape)[...] += contrib[a]
    return out


def internal_force(stress, open_volume, h):
    """Nodal internal force ``(3, ...)`` of the mixture stress ``stress`` (nz, ny, nx, 6)."""
    return gather(corner_forces(stress, open_volume, h))


def hourglass_modes(v):
    """``Gamma^m . v_c`` of every cell: ``(4, 3, nz, ny, nx)`` (m/s)."""
    shape = tuple(n - 1 for n in v.shape[1:])
    out = np.zeros((4, 3) + shape)
    for a, (dk, dj, di) in enumerate(CORNERS):
        for m in range(4):
            out[m] += HOURGLASS[m, a] * _corner(v, dk, dj, di, shape)
    return out


def hourglass_corner_forces(v, coefficient):
    """``-C_c sum_m Gamma^m_a (Gamma^m . v_c)`` of every corner: ``(8, 3, nz, ny, nx)``;
    ``coefficient`` ``C_c`` (nz, ny, nx) in kg/s."""
    modes = hourglass_modes(v)
    out = np.empty((8, 3) + coefficient.shape)
    for a in range(8):
        total = (HOURGLASS[0, a] * modes[0] + HOURGLASS[1, a] * modes[1]
                 + HOURGLASS[2, a] * modes[2] + HOURGLASS[3, a] * modes[3])
        out[a] = -coefficient * total
    return out


def hourglass_force(v, coefficient):
    """Nodal viscous hourglass force ``(3, ...)`` (module docstring)."""
    return gather(hourglass_corner_forces(v, coefficient))


def velocity_gradient(v, h):
    """``L_ij = dv_i/dx_j`` at every cell centre: ``(3, 3, nz, ny, nx)`` (1/s)."""
    shape = tuple(n - 1 for n in v.shape[1:])
    g = 1.0 / (4.0 * h)
    L = np.zeros((3, 3) + shape)
    for a, (dk, dj, di) in enumerate(CORNERS):
        va = _corner(v, dk, dj, di, shape)
        for j in range(3):
            L[:, j] += (SIGNS[a, j] * g) * va
    return L


def strain_rate(v, h):
    """Cell strain rate ``D`` (nz, ny, nx, 6) (tensor shear) and spin ``(W_yz, W_xz, W_xy)``
    (nz, ny, nx, 3), 1/s."""
    L = velocity_gradient(v, h)
    D = np.stack([0.5 * (L[i, j] + L[j, i]) for i, j in PAIRS], axis=-1)
    W = np.stack([0.5 * (L[i, j] - L[j, i]) for i, j in SPIN], axis=-1)
    return D, W


def jaumann_rotate(sigma, spin, dt):
    """``sigma + (W sigma - sigma W) dt`` (six components), ``W`` from ``spin``."""
    from ..material.principal3d import from_matrix, to_matrix
    w = np.zeros(spin.shape[:-1] + (3, 3))
    for k, (i, j) in enumerate(SPIN):
        w[..., i, j] = spin[..., k]
        w[..., j, i] = -spin[..., k]
    s = to_matrix(sigma)
    return sigma + from_matrix(w @ s - s @ w) * dt


def face_velocities(v):
    """Normal velocities of the z-, y- and x-normal faces ``(nz + 1, ny, nx)``, ``(nz, ny + 1,
    nx)``, ``(nz, ny, nx + 1)``: the mean of each face's four nodes (m/s, along +z, +y, +x)."""
    vz = 0.25 * (v[2, :, :-1, :-1] + v[2, :, :-1, 1:] + v[2, :, 1:, :-1] + v[2, :, 1:, 1:])
    vy = 0.25 * (v[1, :-1, :, :-1] + v[1, :-1, :, 1:] + v[1, 1:, :, :-1] + v[1, 1:, :, 1:])
    vx = 0.25 * (v[0, :-1, :-1, :] + v[0, :-1, 1:, :] + v[0, 1:, :-1, :] + v[0, 1:, 1:, :])
    return vz, vy, vx


def open_divergence(v, aperture_z, aperture_y, aperture_x, kappa, h):
    """Net outflow of the face velocities through the open face areas over the open volume
    (1/s; 0 in closed cells)."""
    vz, vy, vx = face_velocities(v)
    wz, wy, wx = vz * aperture_z, vy * aperture_y, vx * aperture_x
    net = ((wz[1:] - wz[:-1]) + (wy[:, 1:] - wy[:, :-1]) + (wx[:, :, 1:] - wx[:, :, :-1])) / h
    return np.where(kappa > 0, net / np.where(kappa > 0, kappa, 1.0), 0.0)
