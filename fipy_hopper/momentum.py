"""Axisymmetric Q1 Galerkin momentum on the grid's nodes (explicit, lumped mass).

Cells are ``(nz, nr)`` arrays, nodes ``(nz + 1, nr + 1)`` arrays; velocities are
``(2, nz + 1, nr + 1)`` with components ``(v_r, v_z)`` in m/s.  Every integral is per radian
(the ``2 pi`` of the axisymmetric volume is dropped everywhere, as in FiPy's cylindrical
grids), so nodal masses are kg/rad and forces N/rad.

One-point (cell-centre) quadrature of the bilinear element with nodes ``SW, SE, NE, NW``:
``dN/dr = (-1, 1, 1, -1) / (2 h)``, ``dN/dz = (-1, -1, 1, 1) / (2 h)``, ``N = 1/4``.  The
internal force of node ``a`` is ``f_a = sum_c w_c [dN_a/dr s_rr + dN_a/dz s_rz + s_tt / (4 r_c),
dN_a/dr s_rz + dN_a/dz s_zz]`` with ``w_c = kappa_c r_c h^2`` the open cell volume and
``s = alpha sigma`` the mixture stress.  The discrete divergence of this element,
``D_rr + D_tt + D_zz``, equals the finite-volume divergence of the face velocities that the
transport uses (each face's normal velocity is the mean of its two nodes), so the volumetric
strain of the stress update and the compression of ``alpha`` use one and the same divergence.
"""

from __future__ import annotations

import numpy as np

#: node offsets (dj, di) of SW, SE, NE, NW and the shape-function gradient signs
CORNERS = ((0, 0), (0, 1), (1, 1), (1, 0))
SIGN_R = np.array([-1.0, 1.0, 1.0, -1.0])
SIGN_Z = np.array([-1.0, -1.0, 1.0, 1.0])
HOURGLASS = np.array([1.0, -1.0, 1.0, -1.0])


def scatter_to_nodes(cell_values: np.ndarray) -> np.ndarray:
    """Sum ``cell_values[..., c] / 4`` onto the four nodes of each cell (lumping)."""
    nz, nr = cell_values.shape[-2:]
    out = np.zeros(cell_values.shape[:-2] + (nz + 1, nr + 1))
    q = 0.25 * cell_values
    out[..., :-1, :-1] += q
    out[..., :-1, 1:] += q
    out[..., 1:, :-1] += q
    out[..., 1:, 1:] += q
    return out


def node_mass(rho: float, alpha: np.ndarray, open_volume: np.ndarray) -> np.ndarray:
    """Lumped nodal mass ``m_a = sum_c rho alpha_c w_c / 4`` (kg/rad)."""
    return scatter_to_nodes(rho * alpha * open_volume)


def internal_force(stress: np.ndarray, open_volume: np.ndarray, r_c: np.ndarray, h: float):
    """Nodal internal force ``(2, nz+1, nr+1)`` of the mixture stress ``stress`` (nz, nr, 4).

    ``stress`` is ``alpha sigma`` (Pa), tension positive; ``r_c`` the cell-centre radii (nr,).
    """
    s_rr, s_zz, s_tt, s_rz = (stress[..., k] * open_volume for k in range(4))
    g = 1.0 / (2.0 * h)
    hoop = s_tt / (4.0 * r_c[None, :])
    nz, nr = open_volume.shape
    f = np.zeros((2, nz + 1, nr + 1))
    for (dj, di), sr, sz in zip(CORNERS, SIGN_R, SIGN_Z):
        f[0, dj:dj + nz, di:di + nr] += g * (sr * s_rr + sz * s_rz) + hoop
        f[1, dj:dj + nz, di:di + nr] += g * (sr * s_rz + sz * s_zz)
    return f


def hourglass_force(v: np.ndarray, coefficient: np.ndarray) -> np.ndarray:
    """Viscous hourglass force: ``f_a = -C_c Gamma_a (Gamma . v_c)``, ``Gamma = (1,-1,1,-1)``.

    ``coefficient`` (nz, nr) in kg/(s rad); the model uses ``kappa_hg rho sqrt(g h) alpha w_c /
    h`` (:mod:`fipy_hopper.config`, ``hourglass_coefficient``).  It acts only on the
    checkerboard mode of each cell (zero for rigid motion and linear fields).
    """
    nz, nr = coefficient.shape
    mode = sum(gam * v[:, dj:dj + nz, di:di + nr] for (dj, di), gam in zip(CORNERS, HOURGLASS))
    f = np.zeros_like(v)
    for (dj, di), gam in zip(CORNERS, HOURGLASS):
        f[:, dj:dj + nz, di:di + nr] -= coefficient * gam * mode
    return f


def strain_rate(v: np.ndarray, r_c: np.ndarray, h: float):
    """Cell strain rate ``D`` (nz, nr, 4) as (rr, zz, tt, rz) tensor components, and spin.

    ``D_rr = dv_r/dr``, ``D_zz = dv_z/dz``, ``D_tt = v_r / r`` (cell mean of ``v_r``),
    ``D_rz = (dv_r/dz + dv_z/dr)/2``; spin ``omega = (dv_r/dz - dv_z/dr)/2`` (1/s).
    """
    vr_sw, vr_se, vr_ne, vr_nw = (v[0, dj:dj + v.shape[1] - 1, di:di + v.shape[2] - 1]
                                  for dj, di in CORNERS)
    vz_sw, vz_se, vz_ne, vz_nw = (v[1, dj:dj + v.shape[1] - 1, di:di + v.shape[2] - 1]
                                  for dj, di in CORNERS)
    g = 1.0 / (2.0 * h)
    dvr_dr = g * (vr_se + vr_ne - vr_sw - vr_nw)
    dvr_dz = g * (vr_nw + vr_ne - vr_sw - vr_se)
    dvz_dr = g * (vz_se + vz_ne - vz_sw - vz_nw)
    dvz_dz = g * (vz_nw + vz_ne - vz_sw - vz_se)
    hoop = 0.25 * (vr_sw + vr_se + vr_ne + vr_nw) / r_c[None, :]
    D = np.stack([dvr_dr, dvz_dz, hoop, 0.5 * (dvr_dz + dvz_dr)], axis=-1)
    return D, 0.5 * (dvr_dz - dvz_dr)


def jaumann_rotate(sigma: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Objective (Jaumann) rotation of the stress: ``sigma += (W sigma - sigma W) dt``.

    With the in-plane spin ``omega = W_rz``: ``d s_rr = 2 omega s_rz dt``,
    ``d s_zz = -2 omega s_rz dt``, ``d s_rz = omega (s_zz - s_rr) dt``; ``s_tt`` is unchanged.
    """
    out = sigma.copy()
    w = omega * dt
    out[..., 0] += 2.0 * w * sigma[..., 3]
    out[..., 1] -= 2.0 * w * sigma[..., 3]
    out[..., 3] += w * (sigma[..., 1] - sigma[..., 0])
    return out


def apply_wall_contact(v: np.ndarray, normal: np.ndarray, mask: np.ndarray, mu: float):
    """Impulse Coulomb contact at the ``mask`` nodes against a rigid wall, in place.

    ``normal`` (2, ...) points into the wall.  If ``v_n = v.n > 0`` the normal part is removed
    and the tangential speed reduced by ``mu v_n`` (not below zero): the discrete form of
    ``|impulse_t| <= mu impulse_n``.  Nodes moving away from the wall are left free.
    """
    vn = v[0] * normal[0] + v[1] * normal[1]
    pressing = mask & (vn > 0.0)
    vn_p = np.where(pressing, vn, 0.0)
    vr = v[0] - vn_p * normal[0]
    vz = v[1] - vn_p * normal[1]
    vt_r = vr - (vr * normal[0] + vz * normal[1]) * normal[0]
    vt_z = vz - (vr * normal[0] + vz * normal[1]) * normal[1]
    speed_t = np.hypot(vt_r, vt_z)
    scale = np.where(speed_t > 0.0, np.maximum(0.0, 1.0 - mu * vn_p / np.where(
        speed_t > 0, speed_t, 1.0)), 0.0)
    vn_r = vr - vt_r
    vn_z = vz - vt_z
    v[0] = np.where(pressing, vn_r + scale * vt_r, v[0])
    v[1] = np.where(pressing, vn_z + scale * vt_z, v[1])
    return v


def face_normal_velocity(v: np.ndarray) -> np.ndarray:
    """Normal velocity of every face in FiPy order: z-faces ``(nz+1, nr)`` then r-faces.

    A face's velocity is the mean of its two end nodes (the Q1 edge average); z-faces carry
    ``v_z`` (normal +z), r-faces ``v_r`` (normal +r).  Exterior faces of FiPy point outward: the
    caller's sign convention (``mesh.faceNormals``) is applied by :func:`oriented`.
    """
    vz_faces = 0.5 * (v[1, :, :-1] + v[1, :, 1:])
    vr_faces = 0.5 * (v[0, :-1, :] + v[0, 1:, :])
    return np.concatenate([vz_faces.ravel(), vr_faces.ravel()])


def open_divergence(v: np.ndarray, zface_aperture: np.ndarray, rface_aperture: np.ndarray,
                    kappa: np.ndarray, r_nodes: np.ndarray, h: float) -> np.ndarray:
    """Divergence of the nodal velocity over each cell's open volume (1/s), as transport sees it.

    With the face velocities of :func:`face_normal_velocity` (edge means, ``w`` along +z on
    z-faces, ``u`` along +r on r-faces) and the apertures ``a`` (open fraction of each face),
    ``div = [(a_T w_T - a_B w_B) / h + (a_R r_R u_R - a_L r_L u_L) / (r_c h)] / kappa``: the
    net outflow through the open faces per open volume ``kappa r_c h^2`` (the wall is
    impermeable).  In a full cell it equals the Q1 cell mean ``tr D`` of :func:`strain_rate`;
    closed cells (``kappa = 0``) get 0.
    """
    w = 0.5 * (v[1, :, :-1] + v[1, :, 1:]) * zface_aperture          # (nz + 1, nr)
    u = 0.5 * (v[0, :-1, :] + v[0, 1:, :]) * rface_aperture * r_nodes  # (nz, nr + 1)
    r_c = 0.5 * (r_nodes[1:] + r_nodes[:-1])
    net = (w[1:] - w[:-1]) / h + (u[:, 1:] - u[:, :-1]) / (r_c * h)
    return np.where(kappa > 0, net / np.where(kappa > 0, kappa, 1.0), 0.0)


def dual_momentum_transport(v, mass_old, mass_new, flux_z, flux_r, rho, bottom_outflow=True):
    """Conservative upwind transport of nodal momentum on the dual grid.

    ``flux_z`` (nz+1, nr) and ``flux_r`` (nz, nr+1) are the time-integrated primal transfers of
    ``alpha`` open volume across z-faces (+z) and r-faces (+r) (m^3/rad).  A primal transfer
    ``F`` from cell c1 to c2 changes the lumped masses of the nodes exactly as the transfers
    ``F/4`` across the two dual faces through the centres of c1 and c2, so the dual flux through
    the centre of a cell, between its two nodes of one column, is ``(F_bottom + F_top)/4``
    (summed over the two cells beside the dual face).  The bottom boundary's transfer is
    ``F/2`` out of the bottom node row.  Momentum moves with the donor node's velocity; the new
    velocity is ``P_new / m_new`` where ``m_new`` is the lumped mass of the new cell fields.
    """
    rho_fz = rho * flux_z
    rho_fr = rho * flux_r
    nz1, nr = rho_fz.shape
    nz = nz1 - 1
    # dual z-fluxes between node rows k and k+1 at node column a: (nz, nr+1)
    per_cell = 0.25 * (rho_fz[:-1] + rho_fz[1:])              # (nz, nr)
    gz = np.zeros((nz, nr + 1))
    gz[:, :-1] += per_cell
    gz[:, 1:] += per_cell
    # dual r-fluxes between node columns a and a+1 at node row k: (nz+1, nr)
    per_cell_r = 0.25 * (rho_fr[:, :-1] + rho_fr[:, 1:])      # (nz, nr)
    gr = np.zeros((nz + 1, nr))
    gr[:-1] += per_cell_r
    gr[1:] += per_cell_r
    P = mass_old[None] * v
    # z transfers: positive gz moves momentum from row k to k+1 with the donor's velocity
    donor_z = np.where(gz > 0, v[:, :-1, :], v[:, 1:, :])
    dz = gz[None] * donor_z
    P[:, :-1, :] -= dz
    P[:, 1:, :] += dz
    donor_r = np.where(gr > 0, v[:, :, :-1], v[:, :, 1:])
    dr = gr[None] * donor_r
    P[:, :, :-1] -= dr
    P[:, :, 1:] += dr
    if bottom_outflow:
        out = 0.5 * rho_fz[0]                                   # (nr,), negative = leaving
        node_out = np.zeros(nr + 1)
        node_out[:-1] += out
        node_out[1:] += out
        P[:, 0, :] += node_out[None] * v[:, 0, :]
    safe = np.where(mass_new > 0, mass_new, 1.0)
    return np.where(mass_new[None] > 0, P / safe[None], 0.0)


# ----------------------------------------------------------------------------------------------
# Compiled kernels (numba) of the transport step, the same arithmetic as the numpy functions
# above (the material step's are in fipy_hopper.stepping); tests/test_stepping.py holds them
# to the numpy reference.
# ----------------------------------------------------------------------------------------------
from numba import njit  # noqa: E402


@njit(cache=True, error_model="numpy")
def node_mass_kernel(rho, alpha, open_volume, out):
    """:func:`node_mass` into ``out`` (nz + 1, nr + 1), each node's four cells added in the
    order of :func:`scatter_to_nodes` (so the sums are the same to the last bit)."""
    nz, nr = alpha.shape
    for j in range(nz + 1):
        for i in range(nr + 1):
            m = 0.0
            if j < nz and i < nr:
                m += 0.25 * (rho * alpha[j, i] * open_volume[j, i])
            if j < nz and i > 0:
                m += 0.25 * (rho * alpha[j, i - 1] * open_volume[j, i - 1])
            if j > 0 and i < nr:
                m += 0.25 * (rho * alpha[j - 1, i] * open_volume[j - 1, i])
            if j > 0 and i > 0:
                m += 0.25 * (rho * alpha[j - 1, i - 1] * open_volume[j - 1, i - 1])
            out[j, i] = m


@njit(cache=True, error_model="numpy")
def dual_momentum_kernel(v, mass_old, mass_new, flux_z, flux_r, rho, light_mass, out):
    """:func:`dual_momentum_transport` (with the bottom outflow) into ``out``, the same
    operations in the same order for every node; nodes of mass ``<= light_mass`` get zero.

    Returns the vertical momentum (kg m/s per radian) that the bottom outflow carried into
    the grid (negative: it left) and that stopping the light nodes added."""
    nz1, nr = flux_z.shape
    nz = nz1 - 1
    gz = np.empty((nz, nr + 1))
    for j in range(nz):
        for a in range(nr + 1):
            s = 0.0
            if a < nr:
                s += 0.25 * (rho * flux_z[j, a] + rho * flux_z[j + 1, a])
            if a > 0:
                s += 0.25 * (rho * flux_z[j, a - 1] + rho * flux_z[j + 1, a - 1])
            gz[j, a] = s
    gr = np.empty((nz + 1, nr))
    for k in range(nz + 1):
        for i in range(nr):
            s = 0.0
            if k < nz:
                s += 0.25 * (rho * flux_r[k, i] + rho * flux_r[k, i + 1])
            if k > 0:
                s += 0.25 * (rho * flux_r[k - 1, i] + rho * flux_r[k - 1, i + 1])
            gr[k, i] = s
    outflow = 0.0
    stopped = 0.0
    for c in range(2):
        for k in range(nz + 1):
            for a in range(nr + 1):
                p = mass_old[k, a] * v[c, k, a]
                if k < nz:
                    g = gz[k, a]
                    p -= g * (v[c, k, a] if g > 0 else v[c, k + 1, a])
                if k > 0:
                    g = gz[k - 1, a]
                    p += g * (v[c, k - 1, a] if g > 0 else v[c, k, a])
                if a < nr:
                    g = gr[k, a]
                    p -= g * (v[c, k, a] if g > 0 else v[c, k, a + 1])
                if a > 0:
                    g = gr[k, a - 1]
                    p += g * (v[c, k, a - 1] if g > 0 else v[c, k, a])
                if k == 0:
                    node_out = 0.0
                    if a < nr:
                        node_out += 0.5 * (rho * flux_z[0, a])
                    if a > 0:
                        node_out += 0.5 * (rho * flux_z[0, a - 1])
                    p += node_out * v[c, 0, a]
                    if c == 1:
                        outflow += node_out * v[c, 0, a]
                m = mass_new[k, a]
                out[c, k, a] = p / m if m > 0 else 0.0
                if m <= light_mass:
                    out[c, k, a] = 0.0
                    if c == 1:
                        stopped -= p
    return outflow, stopped


def contact_groups(contact_list, plate_list, n_rows, weights=None):
    """The wall and plate contacts grouped by node for :func:`contact_nodes` and the compiled
    step: ``(row_nodes (n_rows + 1,), node_j, node_i, node_ptr, normal (K, 3), mu, kind,
    entry)``.  Nodes are in row-major order; a node's constraints keep the order of the lists
    (wall entries, then plate entries); ``normal[k]`` is ``(n_r, n_z, w)``: the unit normal
    into the wall and the wall's tributary length at the node, ``weights = (wall weights,
    plate weights)`` (default: 1 for every entry), which shares a corner's impulse among its
    walls (``stepping._contact_node``); ``kind`` is 0 for a wall entry, 1 for a plate entry,
    ``entry`` the index in its list."""
    wj, wi, wn, wmu = contact_list
    pj, pi, pn, pmu = plate_list
    if weights is None:
        weights = (np.ones(len(wj)), np.ones(len(pj)))
    j = np.concatenate([wj, pj])
    i = np.concatenate([wi, pi])
    kind = np.concatenate([np.zeros(len(wj), np.int8), np.ones(len(pj), np.int8)])
    entry = np.concatenate([np.arange(len(wj)), np.arange(len(pj))]).astype(np.int64)
    order = np.lexsort((i, j))                      # stable: list order within a node
    j, i, kind, entry = j[order], i[order], kind[order], entry[order]
    normal = np.concatenate([np.asarray(wn, float).reshape(-1, 2),
                             np.asarray(pn, float).reshape(-1, 2)])
    weight = np.concatenate([np.asarray(weights[0], float), np.asarray(weights[1], float)])
    normal = np.ascontiguousarray(np.column_stack([normal, weight])[order])
    mu = np.ascontiguousarray(np.concatenate([wmu, pmu])[order])
    first = np.concatenate([[True], (j[1:] != j[:-1]) | (i[1:] != i[:-1])])
    starts = np.flatnonzero(first)
    node_ptr = np.concatenate([starts, [len(j)]]).astype(np.int64)
    node_j, node_i = j[starts].astype(np.int64), i[starts].astype(np.int64)
    row_nodes = np.searchsorted(node_j, np.arange(n_rows + 1)).astype(np.int64)
    return row_nodes, node_j, node_i, node_ptr, normal, mu, kind, entry


def _project_rows(vr, vz, n_r, n_z, mu):
    """``stepping._project`` of arrays of nodes, the same operations in the same order (the
    velocity after the one-wall contact, for nodes that press into the wall)."""
    vn = vr * n_r + vz * n_z
    pr = vr - vn * n_r
    pz = vz - vn * n_z
    tn = pr * n_r + pz * n_z
    t_r = pr - tn * n_r
    t_z = pz - tn * n_z
    speed = np.sqrt(t_r * t_r + t_z * t_z)
    moving = speed > 0.0
    scale = np.where(moving, np.maximum(0.0, 1.0 - mu * vn / np.where(moving, speed, 1.0)),
                     0.0)
    return (pr - t_r) + scale * t_r, (pz - t_z) + scale * t_z


def contact_nodes(v, mass, groups, plate_closed, wall_impulse, plate_impulse):
    """Reference (numpy, vectorised over the nodes) of the compiled contact of every node with
    all its walls (``stepping._contact_node``, whose docstring gives the rule: one wall, the
    impulse Coulomb contact; a corner, its walls as one patch whose impulse is shared among
    them by their tributary lengths with the same mobilised friction), in place, with each
    constraint's impulse ``m dv`` added to ``wall_impulse`` / ``plate_impulse``: the same
    operations in the same order as the compiled contact, so the same numbers to the bit.
    ``plate_closed``: whether the plate holds, for all nodes (a bool) or per node of
    ``groups`` (an array: the outlet opening)."""
    _, node_j, node_i, node_ptr, normal, mu, kind, entry = groups
    n_nodes = len(node_j)
    if n_nodes == 0:
        return v
    count = np.diff(node_ptr)
    k_max = int(count.max())
    slot = np.arange(k_max)
    index = node_ptr[:-1, None] + slot[None, :]
    present = slot[None, :] < count[:, None]
    index = np.where(present, index, 0)
    plate_on = np.asarray(plate_closed, dtype=bool)
    active = present & ((kind[index] == 0) | (plate_on[:, None] if plate_on.ndim else plate_on))
    n_r, n_z, w = normal[index, 0], normal[index, 1], normal[index, 2]   # (Q, K)
    m_k = mu[index]
    vel = v[:, node_j, node_i].T                               # (Q, 2)
    vr, vz = vel[:, 0], vel[:, 1]
    m = mass[node_j, node_i]
    rows = np.arange(n_nodes)
    vn = vr[:, None] * n_r + vz[:, None] * n_z                 # (Q, K)
    pressing = active & (vn > 0.0)
    pressed = pressing.any(axis=1)
    new = vel.copy()
    # the patch of the weighted walls, N and T, summed in the constraints' order
    weighted = active & (w > 0.0)
    big_r, big_z = np.zeros(n_nodes), np.zeros(n_nodes)
    fri_r, fri_z = np.zeros(n_nodes), np.zeros(n_nodes)
    last = np.full(n_nodes, -1)
    for k in range(k_max):
        on = weighted[:, k]
        wm = w[:, k] * m_k[:, k]
        big_r = np.where(on, big_r - w[:, k] * n_r[:, k], big_r)
        big_z = np.where(on, big_z - w[:, k] * n_z[:, k], big_z)
        fri_r = np.where(on, fri_r - wm * n_z[:, k], fri_r)
        fri_z = np.where(on, fri_z + wm * n_r[:, k], fri_z)
        last = np.where(on, k, last)
    j0r, j0z = -(m * vr), -(m * vz)
    det = big_r * fri_z - big_z * fri_r
    size = (np.abs(big_r) + np.abs(big_z)) * (np.abs(fri_r) + np.abs(fri_z))
    patch = pressed & (weighted.sum(axis=1) >= 2) & (np.abs(det) > 1e-9 * size)
    safe = np.where(patch, det, 1.0)
    a = np.where(patch, (j0r * fri_z - j0z * fri_r) / safe, 0.0)
    b = np.where(patch, (big_r * j0z - big_z * j0r) / safe, 0.0)
    held = patch & (a >= 0.0) & (np.abs(b) <= a)               # 2: the patch holds the node
    # the old rule's wall: the closest frictionless projection that presses no other wall
    proj_r = vr[:, None] - vn * n_r                            # (Q, K)
    proj_z = vz[:, None] - vn * n_z
    tol = 1e-14 * (np.abs(vr) + np.abs(vz))
    other = proj_r[:, :, None] * n_r[:, None, :] + proj_z[:, :, None] * n_z[:, None, :]
    off = active[:, None, :] & ~np.eye(k_max, dtype=bool)[None]
    feasible = ~np.any(off & (other > tol[:, None, None]), axis=2)
    gap = np.where(pressing & feasible, vn, np.inf)
    best = np.argmin(gap, axis=1)
    single = np.isfinite(gap[rows, best])
    # 3: the slide along that wall with the impulse on the patch cone's edge
    s = np.where(b > 0.0, 1.0, -1.0)
    e_r, e_z = big_r + s * fri_r, big_z + s * fri_z
    bn_r, bn_z = n_r[rows, best], n_z[rows, best]
    push = -(e_r * bn_r + e_z * bn_z)
    tries = (patch & ~held & (b != 0.0) & single & (w[rows, best] > 0.0) & (push > 0.0))
    c = np.where(tries, (vr * bn_r + vz * bn_z) / np.where(tries, push, 1.0), 0.0)
    wr, wz = vr + c * e_r, vz + c * e_z
    u, u_new = vz * bn_r - vr * bn_z, wz * bn_r - wr * bn_z
    after = wr[:, None] * n_r + wz[:, None] * n_z
    others = active & (slot[None, :] != best[:, None])
    slides = (tries & (u * u_new >= 0.0) & (np.abs(u_new) <= np.abs(u))
              & ~np.any(others & (after > tol[:, None]), axis=1))
    # 4: the one-wall contact, or rest pressed from both sides
    one = pressed & single & ~held & ~slides
    corner = pressed & ~single & ~held & ~slides
    p_r, p_z = _project_rows(vr, vz, bn_r, bn_z, mu[index[rows, best]])
    new[one, 0], new[one, 1] = p_r[one], p_z[one]
    new[slides, 0], new[slides, 1] = wr[slides], wz[slides]
    new[held | corner] = 0.0
    impulse = m[:, None] * (new - vel)
    _add_impulse(one, index[rows, best], impulse, kind, entry, wall_impulse, plate_impulse)
    # the patch's shares: w_k (lam (-n_k) + lam_t mu_k t_k), the last weighted wall the rest
    share = held | slides
    lam = np.where(held, a, m * c)
    lam_t = np.where(held, b, s * (m * c))
    rest = np.where(held[:, None], np.stack([j0r, j0z], axis=1), impulse)
    for k in range(k_max):
        on = share & weighted[:, k] & (last != k)
        f = lam_t * m_k[:, k]
        part = np.stack([w[:, k] * (-(lam * n_r[:, k]) - f * n_z[:, k]),
                         w[:, k] * (f * n_r[:, k] - lam * n_z[:, k])], axis=1)
        _add_impulse(on, index[:, k], part, kind, entry, wall_impulse, plate_impulse)
        rest = np.where(on[:, None], rest - part, rest)
    _add_impulse(share, index[rows, np.maximum(last, 0)], rest, kind, entry, wall_impulse,
                 plate_impulse)
    if corner.any():                 # rest, J0 split between the first pair that spans it
        q = np.flatnonzero(corner)
        jq = np.stack([j0r[q], j0z[q]], axis=1)
        tol = -1e-12 * (np.abs(j0r[q]) + np.abs(j0z[q]))
        s_first = np.where(b[q] < 0.0, -1.0, 1.0)
        done = np.zeros(len(q), bool)
        for p in range(3):
            s_p = s_first if p == 0 else (np.zeros(len(q)) if p == 1 else -s_first)
            for a_k in range(k_max):
                fa = s_p * m_k[q, a_k]
                ea_r = -n_r[q, a_k] - fa * n_z[q, a_k]
                ea_z = fa * n_r[q, a_k] - n_z[q, a_k]
                for b_k in range(a_k + 1, k_max):
                    fb = s_p * m_k[q, b_k]
                    eb_r = -n_r[q, b_k] - fb * n_z[q, b_k]
                    eb_z = fb * n_r[q, b_k] - n_z[q, b_k]
                    det2 = ea_r * eb_z - ea_z * eb_r
                    ok = (active[q, a_k] & active[q, b_k] & (np.abs(det2) >= 1e-12) & ~done)
                    safe2 = np.where(ok, det2, 1.0)
                    la = (jq[:, 0] * eb_z - jq[:, 1] * eb_r) / safe2
                    lb = (ea_r * jq[:, 1] - ea_z * jq[:, 0]) / safe2
                    ok &= (la >= tol) & (lb >= tol)
                    part = np.stack([la * ea_r, la * ea_z], axis=1)
                    _add_impulse(ok, index[q, a_k], part, kind, entry, wall_impulse,
                                 plate_impulse)
                    _add_impulse(ok, index[q, b_k], jq - part, kind, entry, wall_impulse,
                                 plate_impulse)
                    done |= ok
        if not done.all():                       # round-off: to the wall pressed hardest
            left = ~done
            hardest = np.argmax(np.where(active[q], vn[q], -np.inf), axis=1)
            _add_impulse(left, index[q, hardest], jq, kind, entry, wall_impulse,
                         plate_impulse)
    v[:, node_j, node_i] = new.T
    return v


def _add_impulse(mask, constraint, impulse, kind, entry, wall_impulse, plate_impulse):
    """Add ``impulse[mask]`` to the entries of the constraints ``constraint[mask]``."""
    c = constraint[mask]
    wall = kind[c] == 0
    np.add.at(wall_impulse, entry[c[wall]], impulse[mask][wall])
    np.add.at(plate_impulse, entry[c[~wall]], impulse[mask][~wall])
